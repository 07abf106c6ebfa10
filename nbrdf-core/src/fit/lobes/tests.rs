use super::one_lobe::{quadrature, second_moment};
use super::two_lobes::mixture_second_moment;
use super::*;
use crate::coords::{from_rusinkiewicz, to_rusinkiewicz, RusinkiewiczAngles};
use crate::fit::phong::FitConfig;
use crate::sampling::SamplingStrategy;
use crate::train::dataset::TargetFn;
use glam::Vec3;
use std::f64::consts::PI;

/// `kd / pi` plus a normalised Blinn-Phong lobe, in Rusinkiewicz angles.
pub(crate) fn blinn_phong(
    kd: f64,
    ks: f64,
    n: f64,
) -> impl Fn(&RusinkiewiczAngles) -> Option<[f64; 3]> {
    move |a: &RusinkiewiczAngles| {
        let cos_h = a.theta_h.cos().max(0.0);
        let f = kd / PI + ks * (n + 2.0) / (2.0 * PI) * cos_h.powf(n);
        Some([f; 3])
    }
}

/// `nbrdf fit-phong` promises the same file for any thread count: the strategy score is
/// bitwise the in-order mean over the views, whatever the pool (rayon's own parallel sum
/// grouped the additions by the split and changed the 15th digit).
#[test]
fn strategy_variance_does_not_depend_on_the_thread_count() {
    let config = LobeFitConfig {
        view_thetas: (0..48).map(|k| 0.02 + 0.032 * k as f64).collect(),
        s_bins: 24,
        phi_bins: 12,
        ..LobeFitConfig::default()
    };
    let quadrature = LobeQuadrature::new(&blinn_phong(0.3, 0.6, 80.0), &config).unwrap();
    for strategy in [
        SamplingStrategy::Cosine,
        SamplingStrategy::Phong {
            exponent: 30.0,
            specular_weight: 0.4,
        },
        SamplingStrategy::Phong {
            exponent: 300.0,
            specular_weight: 0.9,
        },
    ] {
        same_for_any_pool(&quadrature, &strategy);
    }
}

fn same_for_any_pool(quadrature: &LobeQuadrature, strategy: &SamplingStrategy) {
    let in_order: f64 = quadrature
        .views
        .iter()
        .map(|q| {
            q.terms
                .relative_second_moment(|i| strategy.pdf_f64(q.view, q.lights[i]))
        })
        .sum::<f64>()
        / quadrature.views.len() as f64
        - 1.0;
    for threads in [1, 2, 3, 4, 9] {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        for _ in 0..3 {
            let got = pool.install(|| quadrature.strategy_relative_variance(strategy));
            assert_eq!(got.to_bits(), in_order.to_bits(), "{threads} threads");
        }
    }
}

#[test]
fn a_lambertian_material_is_cosine_sampled_with_zero_variance() {
    let fit = fit_lobe(&blinn_phong(0.7, 0.0, 1.0), &LobeFitConfig::default()).unwrap();
    assert_eq!(fit.specular_weight, 0.0);
    // g / p is constant for cosine sampling: no variance, up to quadrature error.
    assert!(fit.relative_variance.abs() < 1e-4, "{fit:?}");
}

#[test]
fn a_black_material_gives_a_valid_lobe() {
    let black = |_: &RusinkiewiczAngles| Some([0.0; 3]);
    let fit = fit_lobe(&black, &LobeFitConfig::default()).unwrap();
    assert!(fit.exponent >= 0.0 && (0.0..=1.0).contains(&fit.specular_weight));
}

#[test]
fn a_glossy_lobe_is_found_and_beats_cosine_sampling() {
    let n = 300.0;
    let fit = fit_lobe(&blinn_phong(0.05, 0.9, n), &LobeFitConfig::default()).unwrap();
    assert!(
        fit.exponent > n / 3.0 && fit.exponent < n * 3.0,
        "exponent {}",
        fit.exponent
    );
    assert!(fit.specular_weight > 0.5, "{fit:?}");
    assert!(fit.relative_variance < 0.05 * fit.cosine_relative_variance);
}

#[test]
fn a_weak_sharp_spike_still_gets_a_useful_lobe() {
    // A weak sharp spike over a diffuse base, where the model fit's weight is near 0: most of
    // the reflected energy towards a small light is in the spike, so the lobe must carry weight.
    let fit = fit_lobe(&blinn_phong(0.3, 0.2, 20_000.0), &LobeFitConfig::default()).unwrap();
    assert!(fit.specular_weight >= 0.2, "{fit:?}");
    assert!(
        fit.relative_variance < 0.1 * fit.cosine_relative_variance,
        "{fit:?}"
    );
}

/// The quadrature's second moment against Monte Carlo with the sampler itself: draw from the
/// mixture, average (g/p)^2 and g/p.
/// Monte Carlo estimates of `E[g/p]` and `E[(g/p)^2]` with `g = f_r cos(theta_l)` (red
/// channel of `target`) and `p` the pdf of `strategy`, from `count` samples at `view` drawn
/// with the uniforms of `uniform`; the independent check of the quadrature's moments.
fn sampled_moments(
    strategy: &SamplingStrategy,
    view: Vec3,
    target: &TargetFn<'_>,
    count: usize,
    uniform: &mut dyn FnMut() -> f32,
) -> (f64, f64) {
    let (mut m1, mut m2) = (0.0, 0.0);
    for _ in 0..count {
        let s = strategy.sample(view, [uniform(), uniform(), uniform()]);
        if s.pdf <= 0.0 {
            continue;
        }
        let a = to_rusinkiewicz(view.as_dvec3(), s.light.as_dvec3());
        let (_, l) = from_rusinkiewicz(&a);
        let ratio = target(&a).unwrap()[0] * l.z / s.pdf as f64;
        m1 += ratio;
        m2 += ratio * ratio;
    }
    (m1 / count as f64, m2 / count as f64)
}

#[test]
fn quadrature_second_moment_matches_monte_carlo() {
    let target = blinn_phong(0.2, 0.6, 60.0);
    let config = LobeFitConfig::default();
    let theta_v = 35f64.to_radians();
    let q = quadrature(&target, theta_v, &config);
    let (n, w) = (40.0, 0.6);
    let quad = second_moment(&q, n, w);
    let strategy = SamplingStrategy::Phong {
        exponent: n,
        specular_weight: w,
    };
    let view = Vec3::new(theta_v.sin() as f32, 0.0, theta_v.cos() as f32);
    let mut state = 0x9e37_79b9_7f4a_7c15u64;
    let mut uniform = || {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((state >> 11) as f64 / (1u64 << 53) as f64) as f32
    };
    let (m1, m2) = sampled_moments(&strategy, view, &target, 400_000, &mut uniform);
    let mc = m2 / (m1 * m1);
    assert!(
        (quad - mc).abs() < 0.03 * mc,
        "quadrature {quad} vs Monte Carlo {mc}"
    );
    // And the integral itself: the mean of g/p is int g.
    assert!((m1 - q.terms.integral_sq.sqrt()).abs() < 0.01 * m1);
}

#[test]
fn both_choices_agree_with_the_analysis() {
    let target = blinn_phong(0.3, 0.4, 200.0);
    let fit_config = FitConfig {
        samples: 2000,
        ..FitConfig::default()
    };
    let lobe_config = LobeFitConfig::default();
    let analysis = LobeAnalysis::new(&target, &fit_config, &lobe_config).unwrap();
    for choice in [LobeChoice::LowestVariance, LobeChoice::Model] {
        let chosen = choose_lobe(&target, choice, &fit_config, &lobe_config).unwrap();
        assert_eq!(chosen, analysis.lobe(choice), "{choice:?}");
    }
}

#[test]
fn invalid_candidates_are_rejected() {
    let config = LobeFitConfig {
        weights: vec![1.5],
        ..LobeFitConfig::default()
    };
    assert!(fit_lobe(&blinn_phong(0.5, 0.5, 10.0), &config).is_err());
}

/// A sharp peak over a broader glossy lobe over a diffuse base.
fn two_lobe_material(
    kd: f64,
    sharp: (f64, f64),
    broad: (f64, f64),
) -> impl Fn(&RusinkiewiczAngles) -> Option<[f64; 3]> {
    move |a: &RusinkiewiczAngles| {
        let cos_h = a.theta_h.cos().max(0.0);
        let lobe = |(ks, n): (f64, f64)| ks * (n + 2.0) / (2.0 * PI) * cos_h.powf(n);
        Some([kd / PI + lobe(sharp) + lobe(broad); 3])
    }
}

#[test]
fn two_lobes_are_never_worse_than_one() {
    let config = LobeFitConfig::default();
    let materials: Vec<Box<TargetFn<'static>>> = vec![
        Box::new(blinn_phong(0.7, 0.0, 1.0)),
        Box::new(blinn_phong(0.05, 0.9, 300.0)),
        Box::new(blinn_phong(0.3, 0.2, 20_000.0)),
        Box::new(|_: &RusinkiewiczAngles| Some([0.0; 3])),
    ];
    for (k, material) in materials.iter().enumerate() {
        let quadrature = LobeQuadrature::new(&**material, &config).unwrap();
        let fit = quadrature.fit_two_lobes(&config).unwrap();
        assert!(
            fit.relative_variance <= fit.one_lobe.relative_variance,
            "material {k}: {fit:?}"
        );
        assert_eq!(fit.one_lobe, quadrature.fit(&config).unwrap());
        assert!(fit.strategy().validated().is_ok(), "{fit:?}");
        assert!(fit.exponents[0] >= fit.exponents[1]);
        // The reported variance is that of the stored parameters.
        let again = quadrature.two_lobe_relative_variance(fit.exponents, fit.weights);
        assert!(
            (again - fit.relative_variance).abs() <= 1e-9 * again.abs().max(1e-9),
            "material {k}: {again} vs {fit:?}"
        );
    }
}

#[test]
fn a_sharp_peak_over_a_broad_lobe_gets_two_lobes() {
    let target = two_lobe_material(0.1, (0.3, 5_000.0), (0.5, 30.0));
    let config = LobeFitConfig::default();
    let fit = fit_two_lobes(&target, &config).unwrap();
    assert!(
        fit.relative_variance < 0.5 * fit.one_lobe.relative_variance,
        "{fit:?}"
    );
    // The lobes land near the material's: one sharp, one broad, both carrying weight.
    assert!(
        fit.exponents[0] > 5_000.0 / 4.0 && fit.exponents[0] < 5_000.0 * 4.0,
        "{fit:?}"
    );
    assert!(
        fit.exponents[1] > 30.0 / 4.0 && fit.exponents[1] < 30.0 * 4.0,
        "{fit:?}"
    );
    assert!(fit.weights[0] > 0.1 && fit.weights[1] > 0.1, "{fit:?}");
}

/// The two-lobe objective against Monte Carlo with the two-lobe sampler itself.
#[test]
fn two_lobe_second_moment_matches_monte_carlo() {
    let target = two_lobe_material(0.2, (0.3, 2_000.0), (0.4, 20.0));
    let config = LobeFitConfig::default();
    let theta_v = 50f64.to_radians();
    let q = quadrature(&target, theta_v, &config);
    let (exponents, weights) = ([1_500.0, 25.0], [0.3, 0.5]);
    let quad = mixture_second_moment(
        &q,
        &[(exponents[0], weights[0]), (exponents[1], weights[1])],
    );
    let strategy = SamplingStrategy::TwoLobe {
        exponent1: exponents[0],
        weight1: weights[0],
        exponent2: exponents[1],
        weight2: weights[1],
    };
    let view = Vec3::new(theta_v.sin() as f32, 0.0, theta_v.cos() as f32);
    let mut rng = crate::rng::SplitMix64::from_state(77);
    let (m1, m2) = sampled_moments(&strategy, view, &target, 400_000, &mut || rng.next_f32());
    let mc = m2 / (m1 * m1);
    assert!(
        (quad - mc).abs() < 0.03 * mc,
        "quadrature {quad} vs Monte Carlo {mc}"
    );
}
