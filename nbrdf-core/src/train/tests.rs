use super::*;
use crate::fit::phong::PhongParams;
use crate::merl::{self, cell_coordinates, CELLS, SCALE};

/// The plateau rule as `TrainConfig` documents it: `patience` epochs without a relative
/// improvement of `min_improvement` decay the rate, `lr_decays` times, then stop; nothing
/// before `min_epochs`; the target loss stops at once after `min_epochs`.
#[test]
fn schedule_decays_on_plateaus_then_stops() {
    use Step::{Continue as C, DecayLearningRate as D, Stop as S};
    let config = TrainConfig {
        patience: 2,
        lr_decays: 1,
        min_epochs: 3,
        min_improvement: 0.1,
        target_loss: 0.5,
        ..TrainConfig::default()
    };
    let mut schedule = Schedule::new(&config);
    // 0.95 is within 10 % of 1.0: not an improvement.
    let losses = [1.0, 0.95, 0.95, 0.95, 0.8, 0.8, 0.8, 0.8];
    let steps: Vec<Step> = losses
        .iter()
        .enumerate()
        .map(|(i, &loss)| {
            schedule.observe(loss, config.min_improvement);
            schedule.next_step(&config, i + 1, 0.8)
        })
        .collect();
    // Epoch 3 is the second without improvement and the first allowed to act; epoch 5
    // improves on 0.95 by more than 10 %; epochs 6-7 are its plateau with no decay left.
    assert_eq!(steps, [C, C, D, C, C, C, S, S]);
    assert_eq!(
        Schedule::new(&config).next_step(&config, 3, 0.5),
        Step::Stop,
        "the target loss stops once min_epochs are done"
    );
    assert_eq!(Schedule::new(&config).next_step(&config, 2, 0.1), C);
}

/// A glossy Blinn-Phong material (smooth enough for a short test run).
fn glossy(a: &RusinkiewiczAngles) -> Option<[f64; 3]> {
    let p = PhongParams {
        kd: [0.5, 0.3, 0.2],
        ks: [0.3, 0.3, 0.3],
        exponent: 8.0,
    };
    Some(p.eval(a.theta_h.cos()))
}

/// A quick training run (also the arrays tests', so both train alike).
/// Mean log-space error of a trained network against `target` on 2,000 fresh uniform
/// directions (the validation stream, a seed no training run here uses).
pub(super) fn log_error_on_fresh_directions(target: &TargetFn<'_>, layers: &[Layer; 3]) -> f64 {
    let test = dataset::draw(
        target,
        AngularSampling::Uniform,
        false,
        2000,
        99,
        Stream::ValidationSamples,
    )
    .unwrap();
    Trainer::from_layers(layers, 64, AdamConfig::default()).validation_loss(&test.samples)
}

pub(super) fn small_config() -> TrainConfig {
    TrainConfig {
        samples: 4000,
        max_epochs: 25,
        hidden: 12,
        batch: 64,
        patience: 25,
        seed: 3,
        ..TrainConfig::fixed_budget()
    }
}

#[test]
fn the_target_loss_stops_training_once_reached_after_min_epochs() {
    let full = train(&glossy, &small_config(), "a", &mut |_| {})
        .unwrap()
        .report;
    // A target the full run reaches at some epoch k: a run with it stops at max(k, 5).
    let k = 12;
    let target = full.history[..k]
        .iter()
        .map(|h| h.1)
        .fold(f64::INFINITY, f64::min);
    let reached = full.history.iter().position(|h| h.1 <= target).unwrap() + 1;
    let config = TrainConfig {
        target_loss: target,
        min_epochs: 5,
        ..small_config()
    };
    let stopped = train(&glossy, &config, "b", &mut |_| {}).unwrap().report;
    assert_eq!(stopped.epochs_run, reached.max(5), "{:?}", full.history);
    assert!(stopped.stopped_early);
    assert_eq!(&stopped.history[..], &full.history[..stopped.epochs_run]);
    let bad = TrainConfig {
        target_loss: f64::NAN,
        ..small_config()
    };
    assert!(train(&glossy, &bad, "c", &mut |_| {}).is_err());
}

#[test]
fn the_defaults_are_the_adaptive_budget() {
    let (adaptive, fixed) = (TrainConfig::default(), TrainConfig::fixed_budget());
    assert_eq!((fixed.adam.learning_rate, fixed.max_epochs), (5e-4, 100));
    assert_eq!((fixed.lr_decays, fixed.target_loss), (0, 0.0));
    assert!(adaptive.max_epochs > fixed.max_epochs && adaptive.lr_decays > 0);
    assert!(adaptive.target_loss > 0.0);
    assert_eq!(
        (adaptive.samples, adaptive.hidden, adaptive.batch),
        (fixed.samples, fixed.hidden, fixed.batch)
    );
}

#[test]
fn training_lowers_the_loss_and_fits_the_target() {
    let config = small_config();
    let mut epochs = Vec::new();
    let outcome = train(&glossy, &config, "glossy", &mut |e| epochs.push(*e)).unwrap();
    let report = &outcome.report;
    assert_eq!(epochs.len(), report.epochs_run);
    let first = report.history[0].1;
    assert!(
        report.best_validation_loss < 0.05 * first,
        "{:?}",
        report.history
    );
    // Log-space error of the saved network against the target on fresh directions.
    let error = log_error_on_fresh_directions(&glossy, &outcome.network.layers);
    assert!(
        error < 5e-3,
        "log-space error {error}, history {:?}",
        report.history
    );
    assert!((report.best_validation_loss - report.history[report.best_epoch - 1].1).abs() < 1e-12);
}

/// A closed-form anisotropic test oracle: a diffuse base and an elliptical Gaussian highlight
/// of the half vector's slopes, `exp(-((h.x / a_x)^2 + (h.y / a_y)^2) / h.z^2)`, stretched
/// along y (`a_x = 0.15`, `a_y = 0.5`): its value depends on `phi_h`.
fn anisotropic_oracle(a: &RusinkiewiczAngles) -> Option<[f64; 3]> {
    let (sin_th, cos_th) = a.theta_h.sin_cos();
    let (sin_ph, cos_ph) = a.phi_h.sin_cos();
    let (hx, hy) = (sin_th * cos_ph / 0.15, sin_th * sin_ph / 0.5);
    let peak = 3.0 * (-(hx * hx + hy * hy) / (cos_th * cos_th).max(1e-6)).exp();
    Some([0.2 + peak, 0.1 + peak, 0.05 + peak])
}

/// Mean log-space error of `net` against the oracle over all four angles (adaptive in
/// theta, uniform in phi_h and phi_d), from its own random stream.
fn error_over_phi_h(net: &Nbrdf) -> f64 {
    let (mut sum, mut kept) = (0.0, 0);
    for k in 0..4000u64 {
        let mut rng = SplitMix64::new(77, Stream::Metrics, k);
        let u = [0; 4].map(|_| rng.next_f64());
        let (view, light, angles) = dataset::directions(AngularSampling::Adaptive, true, u);
        if view.z <= 0.01 || light.z <= 0.01 {
            continue;
        }
        let want = anisotropic_oracle(&angles).unwrap();
        let got = net.eval_at_angles(&angles);
        for c in 0..3 {
            sum += ((want[c] * light.z).ln_1p() - (got[c] * light.z).ln_1p()).abs();
        }
        kept += 3;
    }
    sum / f64::from(kept)
}

/// An anisotropic network learns the phi_h dependence that an isotropic one cannot: trained
/// alike on the oracle, its error over all four angles is well below the isotropic network's.
#[test]
fn an_anisotropic_network_learns_what_an_isotropic_one_cannot() {
    let config = TrainConfig {
        samples: 12_000,
        max_epochs: 30,
        hidden: 16,
        adam: AdamConfig {
            learning_rate: 2e-3,
            ..AdamConfig::default()
        },
        ..small_config()
    };
    let aniso = train(
        &anisotropic_oracle,
        &config.clone().for_anisotropy(true, false),
        "a",
        &mut |_| {},
    )
    .unwrap()
    .network;
    let iso = train(&anisotropic_oracle, &config, "i", &mut |_| {})
        .unwrap()
        .network;
    assert!(aniso.anisotropic && !iso.anisotropic);
    let (ea, ei) = (error_over_phi_h(&aniso), error_over_phi_h(&iso));
    assert!(ea < 0.5 * ei, "anisotropic {ea} vs isotropic {ei}");
    // The trained network's sampling lobe is anisotropic the oracle's way: its peak is
    // narrow along x (tangent width 0.15 vs 0.5, i.e. n_u ~ 44, n_v ~ 4), and the lobe
    // samples it better than the best isotropic one.
    let mut lobe_config = crate::fit::anisotropic::AnisotropicLobeFitConfig::default();
    lobe_config.base.s_bins = 60;
    lobe_config.base.phi_bins = 48;
    lobe_config.base.view_thetas = vec![0.3, 0.8, 1.2];
    lobe_config.refine_levels = 3;
    let target = crate::fit::target::network_target(&aniso);
    let lobe = crate::fit::anisotropic::fit_anisotropic_lobe(&target, &lobe_config).unwrap();
    assert!(lobe.exponent_u > 2.0 * lobe.exponent_v, "{lobe:?}");
    assert!(
        lobe.relative_variance < lobe.isotropic_relative_variance,
        "{lobe:?}"
    );
}

#[test]
fn anisotropy_resolves_from_the_source_and_scales_default_samples() {
    assert!(Anisotropy::Auto.resolve(false) && !Anisotropy::Auto.resolve(true));
    assert!(Anisotropy::On.resolve(true) && !Anisotropy::Off.resolve(false));
    let base = TrainConfig::default();
    let scaled = base.clone().for_anisotropy(true, true);
    assert_eq!(scaled.samples, ANISOTROPIC_SAMPLE_FACTOR * base.samples);
    assert_eq!(
        base.clone().for_anisotropy(true, false).samples,
        base.samples
    );
    assert_eq!(base.clone().for_anisotropy(false, true), base);
}

#[test]
fn learning_rate_decay_continues_past_the_plateau() {
    // Same seed, so both runs are identical up to the first plateau; the decayed run goes on
    // from there and can only keep or improve the best validation loss.
    let plain = TrainConfig {
        patience: 2,
        min_epochs: 1,
        max_epochs: 60,
        min_improvement: 0.05,
        ..small_config()
    };
    let decayed = TrainConfig {
        lr_decays: 2,
        ..plain.clone()
    };
    let a = train(&glossy, &plain, "a", &mut |_| {}).unwrap().report;
    let b = train(&glossy, &decayed, "b", &mut |_| {}).unwrap().report;
    assert!(a.stopped_early, "{:?}", a.history);
    assert!(b.epochs_run > a.epochs_run);
    assert_eq!(&b.history[..a.epochs_run], &a.history[..]);
    assert!(b.best_validation_loss <= a.best_validation_loss);
    let bad = TrainConfig {
        lr_decay_factor: 1.0,
        ..plain
    };
    assert!(train(&glossy, &bad, "c", &mut |_| {}).is_err());
}

fn weights_bits(outcome: &TrainOutcome) -> Vec<u32> {
    outcome
        .network
        .layers
        .iter()
        .flat_map(|l| l.weights.iter().chain(&l.bias))
        .map(|w| w.to_bits())
        .collect()
}

#[test]
fn training_is_deterministic_for_a_seed_and_any_thread_count() {
    let config = TrainConfig {
        samples: 1500,
        max_epochs: 2,
        batch: 200,
        ..small_config()
    };
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| train(&glossy, &config, "g", &mut |_| {}).unwrap())
    };
    let a = run(1);
    let b = run(2);
    let c = run(2);
    assert_eq!(weights_bits(&a), weights_bits(&b));
    assert_eq!(weights_bits(&b), weights_bits(&c));
    assert_eq!(a.report.history, c.report.history);
    let other = TrainConfig {
        seed: 4,
        ..config.clone()
    };
    let d = train(&glossy, &other, "g", &mut |_| {}).unwrap();
    assert_ne!(weights_bits(&a), weights_bits(&d));
}

/// The cosine schedule depends on the batch's place in the run only: any thread count gives
/// the same weights, and they differ from the constant rate's.
#[test]
fn a_cosine_schedule_is_deterministic_for_any_thread_count() {
    let cosine = TrainConfig {
        lr_schedule: LrSchedule::COSINE,
        adam: AdamConfig {
            learning_rate: 2e-3,
            ..AdamConfig::default()
        },
        ..small_config()
    };
    let run = |threads: usize, config: &TrainConfig| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| train(&glossy, config, "g", &mut |_| {}).unwrap())
    };
    let (a, b) = (run(1, &cosine), run(2, &cosine));
    assert_eq!(weights_bits(&a), weights_bits(&b));
    assert_eq!(a.report.history, b.report.history);
    let constant = TrainConfig {
        lr_schedule: LrSchedule::Constant,
        ..cosine.clone()
    };
    let c = run(2, &constant);
    assert_ne!(weights_bits(&a), weights_bits(&c));
    let bad = TrainConfig {
        lr_schedule: LrSchedule::Cosine {
            warmup_epochs: 1.0,
            final_fraction: 0.0,
        },
        ..small_config()
    };
    assert!(train(&glossy, &bad, "x", &mut |_| {}).is_err());
}

#[test]
fn invalid_cells_never_become_samples() {
    // Reflectance 0.25 everywhere, except: no data at all for theta_d index >= 60, and the
    // red channel alone unmeasured for theta_h index 30..40 (any channel invalidates a cell).
    let mut stored = vec![0.0; 3 * CELLS];
    for cell in 0..CELLS {
        let (h, d, _) = cell_coordinates(cell);
        for c in 0..3 {
            let unmeasured = d >= 60 || (c == 0 && (30..40).contains(&h));
            stored[c * CELLS + cell] = if unmeasured {
                merl::NOT_MEASURED
            } else {
                0.25 / SCALE[c]
            };
        }
    }
    let table = MerlTable::from_stored(stored).unwrap();
    let target = table_target(&table);
    let set = dataset::draw(
        &target,
        AngularSampling::Adaptive,
        false,
        20_000,
        1,
        Stream::TrainSamples,
    )
    .unwrap();
    assert!(set.invalid > 1000, "{}", set.invalid);
    for s in &set.samples {
        // Every target is the valid value: an unmeasured neighbour never leaks in.
        let expect = (0.25 * s.cos_light as f64).ln_1p() as f32;
        assert!(
            (s.log_target[0] - expect).abs() <= 1e-6 * expect.max(1.0),
            "{s:?}"
        );
        // And no sample lies where all neighbours are unmeasured.
        let theta_d_index =
            90.0 * (s.x[5] as f64).clamp(-1.0, 1.0).acos() / std::f64::consts::FRAC_PI_2;
        assert!(theta_d_index < 60.5 + 1e-3, "{s:?}");
        let theta_h_index =
            90.0 * ((s.x[2] as f64).clamp(-1.0, 1.0).acos() / std::f64::consts::FRAC_PI_2).sqrt();
        assert!(
            !(30.5 + 1e-3..39.5 - 1e-3).contains(&theta_h_index),
            "{s:?}"
        );
    }
}

#[test]
fn bad_configs_are_errors() {
    for config in [
        TrainConfig {
            samples: 0,
            ..TrainConfig::default()
        },
        TrainConfig {
            batch: 0,
            ..TrainConfig::default()
        },
        TrainConfig {
            adam: AdamConfig {
                learning_rate: f32::NAN,
                ..AdamConfig::default()
            },
            ..TrainConfig::default()
        },
        TrainConfig {
            validation_fraction: 0.0,
            ..TrainConfig::default()
        },
    ] {
        assert!(train(&glossy, &config, "x", &mut |_| {}).is_err());
    }
}
