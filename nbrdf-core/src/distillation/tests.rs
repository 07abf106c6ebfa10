//! The distillation on a synthetic textured source: a blend, by a weight `p` per texel, of a
//! Lambertian and a diffuse + normalised Blinn-Phong BRDF written here in closed form.

use super::joint::{JointTrainer, JointWeights};
use super::samples::Rows;
use super::*;
use crate::brdf::Directions;
use crate::network::{INPUTS, OUTPUTS};
use crate::rng::SplitMix64;
use crate::textured::sampling_tests::{chi2_test, hemisphere_integral, lobes_of};
use crate::textured::{SamplingChannels, TexturedNbrdf};
use crate::train::adam::AdamConfig;
use glam::{DVec3, Vec3};
use std::f64::consts::PI;

/// `f_r` of the source with blend weight `p`.
fn source(p: f64, view: DVec3, light: DVec3) -> [f64; 3] {
    let cos_h = (view + light).normalize().z.max(0.0);
    let (n, ks) = (30.0, 0.6);
    let spec = ks * (n + 2.0) / (2.0 * PI) * cos_h.powf(n);
    let (a, b) = ([0.8, 0.5, 0.2], [0.05, 0.05, 0.05]);
    std::array::from_fn(|c| (1.0 - p) * a[c] / PI + p * (b[c] / PI + spec))
}

/// The training texture: a gradient of `p` over 8 x 8 texels.
fn training_weight(texel: usize) -> f32 {
    texel as f32 / 63.0
}

/// A uniform direction on the upper hemisphere.
fn direction(rng: &mut SplitMix64) -> DVec3 {
    crate::sampling::uniform_hemisphere(rng.next_f64(), rng.next_f64())
}

/// Owned structure-of-arrays samples of the source at random texels of the training texture.
struct Owned {
    params: Vec<Vec<f32>>,
    dirs: [Vec<f32>; 6],
    target: [Vec<f32>; 3],
}

impl Owned {
    fn draw(n: usize, seed: u64) -> Self {
        let mut rng = SplitMix64::from_state(seed);
        let mut out = Owned {
            params: vec![Vec::new()],
            dirs: Default::default(),
            target: Default::default(),
        };
        for _ in 0..n {
            let p = training_weight(rng.below(64) as usize);
            let (view, light) = (direction(&mut rng), direction(&mut rng));
            let f = source(f64::from(p), view, light);
            out.params[0].push(p);
            for (d, v) in out
                .dirs
                .iter_mut()
                .zip(view.to_array().iter().chain(&light.to_array()))
            {
                d.push(*v as f32);
            }
            for (t, f) in out.target.iter_mut().zip(f) {
                t.push((f * light.z) as f32);
            }
        }
        out
    }

    fn samples<'a>(&'a self, params: &'a [&'a [f32]]) -> TexturedSamples<'a> {
        let d = &self.dirs;
        TexturedSamples {
            params,
            view: Directions {
                x: &d[0],
                y: &d[1],
                z: &d[2],
            },
            light: Directions {
                x: &d[3],
                y: &d[4],
                z: &d[5],
            },
            target: TargetValues::Rgb([&self.target[0], &self.target[1], &self.target[2]]),
            target_kind: TargetKind::BrdfCos,
        }
    }
}

fn train_on(n: usize, config: &TexturedTrainConfig) -> TexturedModel {
    let owned = Owned::draw(n, 5);
    let params: Vec<&[f32]> = owned.params.iter().map(Vec::as_slice).collect();
    train_textured(&owned.samples(&params), config, &mut |_| {}).unwrap()
}

fn small_config() -> TexturedTrainConfig {
    TexturedTrainConfig {
        channels: 4,
        encoder_hidden: vec![16],
        decoder_hidden: vec![24, 24],
        epochs: 24,
        batch: 256,
        seed: 7,
        ..TexturedTrainConfig::default()
    }
}

/// The held-out texture: weights between the training ones, in a checker of two gradients.
fn held_out_weights() -> Vec<f32> {
    (0..64)
        .map(|t| {
            let (x, y) = (t % 8, t / 8);
            let k = if (x + y) % 2 == 0 { t } else { 63 - t };
            (k as f32 + 0.5) / 64.0
        })
        .collect()
}

/// A cheap lobe search for tests.
fn coarse_bake(name: &str, sampling: SamplingChannels, representatives: usize) -> BakeConfig {
    let mut config = BakeConfig::new(name);
    config.sampling = sampling;
    config.representatives = representatives;
    config.lobe_fit.s_bins = 40;
    config.lobe_fit.phi_bins = 16;
    config.lobe_fit.view_thetas = vec![0.3, 0.9, 1.3];
    config
}

fn bake_held_out(model: &TexturedModel, config: &BakeConfig) -> TexturedNbrdf {
    let weights = held_out_weights();
    let image = ParameterImage {
        width: 8,
        height: 8,
        channels: 1,
        values: &weights,
    };
    bake(model, &image, config, &mut |_| {}).unwrap()
}

/// Mean log-space error `|ln(1 + f cos) - ln(1 + f_baked cos)|` over channels, at the centre
/// of every texel of the held-out texture, on fresh uniform directions.
fn held_out_error(material: &TexturedNbrdf) -> f64 {
    let weights = held_out_weights();
    let mut rng = SplitMix64::from_state(99);
    let (mut sum, mut count) = (0.0, 0);
    for (t, &p) in weights.iter().enumerate() {
        let uv = [((t % 8) as f32 + 0.5) / 8.0, ((t / 8) as f32 + 0.5) / 8.0];
        for _ in 0..40 {
            let (view, light) = (direction(&mut rng), direction(&mut rng));
            let want = source(f64::from(p), view, light);
            let got = material.eval_cos(uv, view.as_vec3(), light.as_vec3());
            for c in 0..3 {
                sum += ((want[c] * light.z).ln_1p() - f64::from(got[c]).ln_1p()).abs();
                count += 1;
            }
        }
    }
    sum / f64::from(count)
}

/// The model before training: the initial weights.
fn untrained(config: &TexturedTrainConfig, trained: &TexturedModel) -> TexturedModel {
    let (encoder, decoder) = config.initial_layers(1, OUTPUTS);
    TexturedModel {
        encoder,
        decoder: crate::textured::Decoder::new(decoder, config.channels, false, None).unwrap(),
        report: trained.report.clone(),
    }
}

#[test]
fn a_distilled_blend_matches_its_source_at_held_out_texels_and_directions() {
    let config = small_config();
    let start = std::time::Instant::now();
    let model = train_on(24_000, &config);
    let seconds = start.elapsed().as_secs_f64();
    let bake_config = coarse_bake("blend", SamplingChannels::one_lobe(), 8);
    let material = bake_held_out(&model, &bake_config);
    let error = held_out_error(&material);
    let before = held_out_error(&bake_held_out(&untrained(&config, &model), &bake_config));
    eprintln!("trained in {seconds:.2} s: held-out error {error:.5}, untrained {before:.5}");
    assert!(
        error < 0.01,
        "error {error}, history {:?}",
        model.report.history
    );
    assert!(
        before > 0.01,
        "the untrained model already passes: {before}"
    );
}

fn bits(material: &TexturedNbrdf) -> Vec<u32> {
    let decoder = material.decoder().layers().iter();
    let weights = decoder.flat_map(|l| l.weights.iter().chain(&l.bias));
    weights
        .chain(material.texture().texels())
        .map(|v| v.to_bits())
        .collect()
}

#[test]
fn training_and_baking_are_deterministic_for_a_seed_and_any_thread_count() {
    let config = TexturedTrainConfig {
        epochs: 2,
        ..small_config()
    };
    let run = |threads: usize, config: &TexturedTrainConfig| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            let model = train_on(3000, config);
            bake_held_out(&model, &coarse_bake("d", SamplingChannels::one_lobe(), 4))
        })
    };
    let (a, b) = (run(1, &config), run(2, &config));
    assert_eq!(bits(&a), bits(&b));
    let other = TexturedTrainConfig { seed: 8, ..config };
    assert_ne!(bits(&a), bits(&run(2, &other)));
}

/// The hand-written gradient of both networks against central differences of the loss.
#[test]
fn the_joint_gradient_matches_central_differences() {
    let owned = Owned::draw(100, 11);
    let params: Vec<&[f32]> = owned.params.iter().map(Vec::as_slice).collect();
    let rows = Rows::from_samples(&owned.samples(&params), false).unwrap();
    let config = TexturedTrainConfig {
        channels: 3,
        encoder_hidden: vec![5],
        decoder_hidden: vec![6],
        ..small_config()
    };
    let (encoder, decoder) = config.initial_layers(1, OUTPUTS);
    let weights = JointWeights::new(&encoder, &decoder);
    let mut trainer = JointTrainer::new(weights.clone(), 128, AdamConfig::default());
    let scale = 1.0 / (OUTPUTS * rows.len()) as f64;
    trainer.compute_gradient(&rows);
    let (ge, gd) = (trainer.gradient().0.to_vec(), trainer.gradient().1.to_vec());
    let mut loss_at = |which: usize, i: usize, delta: f32| {
        let mut w = weights.clone();
        let p = if which == 0 {
            &mut w.encoder.p
        } else {
            &mut w.decoder.p
        };
        p[i] += delta;
        trainer.set_weights(w);
        trainer.compute_gradient(&rows) * scale
    };
    let h = 1e-2;
    let mut checked = 0;
    for (which, grad) in [(0, &ge), (1, &gd)] {
        for (i, &g) in grad.iter().enumerate() {
            let numeric = (loss_at(which, i, h) - loss_at(which, i, -h)) / (2.0 * f64::from(h));
            assert!(
                (f64::from(g) - numeric).abs() < 2e-3,
                "network {which} parameter {i}: analytic {g} numeric {numeric}"
            );
            checked += usize::from(g != 0.0);
        }
    }
    assert!(checked > 50, "{checked}");
}

/// The training forward pass is the decoder's evaluation (its twin).
#[test]
fn the_baked_decoder_evaluates_what_was_trained() {
    let config = small_config();
    let (encoder, decoder) = config.initial_layers(1, OUTPUTS);
    let weights = JointWeights::new(&encoder, &decoder);
    let layout = &weights.decoder.layout;
    assert_eq!(layout.unpad(&weights.decoder.p), decoder);
    let code = super::joint::encode(&weights, &[0.3], 1);
    let d = crate::textured::Decoder::new(decoder, config.channels, false, None).unwrap();
    // The encoder's code, recomputed from the layers with the crate's dense layer.
    let mut x = vec![0.3f32];
    for (k, layer) in encoder.iter().enumerate() {
        let mut y = vec![0.0; layer.outputs];
        layer.affine_into::<crate::fastmath::Unfused>(&x, &mut y);
        if k + 1 < encoder.len() {
            y.iter_mut().for_each(|v| *v = v.max(0.0));
        }
        x = y;
    }
    for (a, b) in code.iter().zip(&x) {
        assert!(
            (a - b).abs() <= 1e-6 * b.abs().max(1.0),
            "{code:?} vs {x:?}"
        );
    }
    let mut rng = SplitMix64::from_state(3);
    for _ in 0..20 {
        let (view, light) = (direction(&mut rng).as_vec3(), direction(&mut rng).as_vec3());
        let features: [f32; INPUTS] = crate::coords::network_input_for(false, view, light);
        let want = d.forward::<crate::fastmath::Unfused>(&features, &code);
        let rows = Rows {
            parameters: 1,
            inputs: vec![features],
            params: vec![0.3],
            outputs: OUTPUTS,
            log_targets: vec![0.0; OUTPUTS],
            cos_light: vec![1.0],
            ..Rows::default()
        };
        // With a zero target and cos 1, the clamped loss is ln(1 + f) summed over channels.
        let trainer = JointTrainer::new(weights.clone(), 64, AdamConfig::default());
        let got = trainer.loss(&rows) * 3.0;
        let expect: f64 = want.iter().map(|&f| f64::from(f).ln_1p()).sum();
        assert!(
            (got - expect).abs() < 1e-5 * expect.max(1.0),
            "{got} vs {expect}"
        );
    }
}

/// Sampling the baked material: its pdf integrates to 1 (with the mass rejected below the
/// horizon), samples follow it, and a sample reports the pdf of its direction.
#[test]
fn the_baked_lobes_sample_with_an_exact_pdf() {
    let model = train_on(
        4000,
        &TexturedTrainConfig {
            epochs: 3,
            ..small_config()
        },
    );
    for sampling in [SamplingChannels::one_lobe(), SamplingChannels::two_lobes()] {
        let m = bake_held_out(&model, &coarse_bake("s", sampling, 3));
        let mut distinct: Vec<Vec<u32>> = (0..64)
            .map(|t| {
                let texel = m.texture().texel(t % 8, t / 8);
                texel[4..].iter().map(|v| v.to_bits()).collect()
            })
            .collect();
        distinct.sort();
        distinct.dedup();
        assert!(
            distinct.len() <= 3,
            "{} lobes for 3 representatives",
            distinct.len()
        );
        let mut rng = SplitMix64::from_state(21);
        for (k, uv) in [[0.1f32, 0.2], [0.55, 0.9], [0.93, 0.4]]
            .into_iter()
            .enumerate()
        {
            let rejected: f64 = lobes_of(&m.sampling_strategy(uv))
                .into_iter()
                .map(|(n, w)| w * 0.5f64.powf(0.5 * (n + 1.0)))
                .sum();
            let total = hemisphere_integral(2000, 8, |l| f64::from(m.pdf(uv, Vec3::Z, l)));
            assert!(
                (total + rejected - 1.0).abs() < 1e-4,
                "uv {uv:?}: {total} + {rejected}"
            );
            let view = direction(&mut rng).as_vec3();
            chi2_test(&m, uv, view, 20_000, 40 + k as u64);
            for _ in 0..200 {
                let s = m.sample(uv, view, [rng.next_f32(), rng.next_f32(), rng.next_f32()]);
                assert_eq!(s.pdf, m.pdf(uv, view, s.light));
            }
        }
    }
}

#[test]
fn bad_inputs_are_errors_that_say_what_is_wrong() {
    let owned = Owned::draw(10, 13);
    let config = small_config();
    let message = |params: &[&[f32]], owned: &Owned| {
        train_textured(&owned.samples(params), &config, &mut |_| {})
            .unwrap_err()
            .to_string()
    };
    assert!(message(&[], &owned).contains("no textures"));
    let mut nan = owned.params[0].clone();
    nan[4] = f32::NAN;
    assert!(message(&[&nan], &owned).contains("parameter 0 of sample 4"));
    let short = &owned.params[0][..9];
    assert!(message(&[short], &owned).contains("params[0] has 9 values"));
    let bad_config = TexturedTrainConfig {
        channels: 0,
        ..small_config()
    };
    let params: Vec<&[f32]> = vec![&owned.params[0]];
    assert!(train_textured(&owned.samples(&params), &bad_config, &mut |_| {}).is_err());

    let model = untrained(
        &config,
        &train_on(
            200,
            &TexturedTrainConfig {
                epochs: 1,
                ..config.clone()
            },
        ),
    );
    let bake_error = |width: usize, channels: usize, values: &[f32], reps: usize| {
        let image = ParameterImage {
            width,
            height: 2,
            channels,
            values,
        };
        let bake_config = coarse_bake("e", SamplingChannels::cosine(), reps);
        bake(&model, &image, &bake_config, &mut |_| {})
            .unwrap_err()
            .to_string()
    };
    let mut values = vec![0.5f32; 6];
    assert!(bake_error(3, 0, &[], 1).contains("no textures"));
    assert!(bake_error(3, 2, &values, 1).contains("2 channels"));
    assert!(bake_error(2, 1, &values, 1).contains("needs 4 values, got 6"));
    assert!(bake_error(3, 1, &values, 0).contains("representatives"));
    values[5] = f32::INFINITY;
    assert!(bake_error(3, 1, &values, 1).contains("texel (x 2, y 1)"));
}
