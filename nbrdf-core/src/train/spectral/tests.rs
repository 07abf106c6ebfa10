use super::*;
use crate::brdf::Directions;
use crate::fit::phong::PhongParams;
use crate::train::arrays::sample_directions;
use crate::train::tests::{log_error_on_fresh_directions, small_config};
use crate::train::{dataset::AngularSampling, TrainConfig};

/// Every 10 nm over 360-830 nm, as the distiller samples.
fn wavelengths() -> Vec<f32> {
    (0..48).map(|j| 360.0 + 10.0 * j as f32).collect()
}

/// A smooth spectral Blinn-Phong: diffuse `0.3 + 0.25 sin((l - 360) / 75)`, specular rising
/// towards the red (a gold-like tint), exponent 8.
fn spectral_phong(view: Vec3, light: Vec3, lambda: f64) -> f64 {
    let h = (view.as_dvec3() + light.as_dvec3()).normalize();
    let t = (lambda - 360.0) / 470.0;
    let kd = 0.3 + 0.25 * ((lambda - 360.0) / 75.0).sin();
    let ks = 0.15 + 0.35 * t;
    let p = PhongParams {
        kd: [kd; 3],
        ks: [ks; 3],
        exponent: 8.0,
    };
    p.eval(h.z)[0]
}

struct Owned {
    view: Vec<Vec3>,
    light: Vec<Vec3>,
    wavelengths: Vec<f32>,
    eval_cos: Vec<f32>,
    swapped: Vec<f32>,
    validation: usize,
}

impl Owned {
    fn arrays(&self, swapped: bool) -> SampledSpectra<'_> {
        SampledSpectra {
            view: &self.view,
            light: &self.light,
            wavelengths: &self.wavelengths,
            eval_cos: &self.eval_cos,
            swapped_eval_cos: swapped.then_some(&self.swapped[..]),
            validation: self.validation,
        }
    }
}

/// `f(view, light, l) cos_light` (and swapped) at the trainer's directions, `[j n + i]`.
fn sampled(config: &TrainConfig, f: impl Fn(Vec3, Vec3, f64) -> f64) -> Owned {
    let (pairs, validation) = sample_directions(config).unwrap();
    let wavelengths = wavelengths();
    let value =
        |v: Vec3, l: Vec3, lambda: f32| (f(v, l, f64::from(lambda)) * f64::from(l.z)) as f32;
    let planar = |swap: bool| -> Vec<f32> {
        wavelengths
            .iter()
            .flat_map(|&lambda| {
                pairs.iter().map(move |&(v, l)| {
                    if swap {
                        value(l, v, lambda)
                    } else {
                        value(v, l, lambda)
                    }
                })
            })
            .collect()
    };
    Owned {
        view: pairs.iter().map(|p| p.0).collect(),
        light: pairs.iter().map(|p| p.1).collect(),
        eval_cos: planar(false),
        swapped: planar(true),
        wavelengths,
        validation,
    }
}

/// Mean `|ln(1 + f cos) - ln(1 + f_net cos)|` of a spectral network against `f` on fresh uniform
/// pairs, at wavelengths between the training ones and the knots (independent of both).
fn per_wavelength_log_error(
    net: &crate::network::Nbrdf,
    f: impl Fn(Vec3, Vec3, f64) -> f64,
) -> f64 {
    let test = TrainConfig {
        sampling: AngularSampling::Uniform,
        samples: 2000,
        seed: 99,
        ..small_config()
    };
    let (pairs, _) = sample_directions(&test).unwrap();
    let n = pairs.len();
    let lambdas = [403.0f32, 455.5, 517.0, 588.0, 631.5, 702.0, 777.0];
    let planar = |pick: fn(&(Vec3, Vec3)) -> Vec3| -> [Vec<f32>; 3] {
        std::array::from_fn(|axis| pairs.iter().map(|p| pick(p)[axis]).collect())
    };
    let (view, light) = (planar(|p| p.0), planar(|p| p.1));
    let wl: Vec<f32> = lambdas
        .iter()
        .flat_map(|&l| std::iter::repeat_n(l, n))
        .collect();
    let mut out = vec![0.0f32; wl.len()];
    fn dirs(a: &[Vec<f32>; 3]) -> Directions<'_> {
        Directions {
            x: &a[0][..],
            y: &a[1][..],
            z: &a[2][..],
        }
    }
    net.eval_spectral_cos_batch(dirs(&view), dirs(&light), &wl, &mut out)
        .unwrap();
    let mut sum = 0.0;
    for (j, &lambda) in lambdas.iter().enumerate() {
        for (i, &(v, l)) in pairs.iter().enumerate() {
            let want = f(v, l, f64::from(lambda)) * f64::from(l.z);
            sum += (want.ln_1p() - f64::from(out[j * n + i]).ln_1p()).abs();
        }
    }
    sum / (lambdas.len() * n) as f64
}

/// A short run on a smooth spectral target reaches a per-wavelength log error comparable to an
/// RGB network's on an RGB target of the same kind with the same settings.
#[test]
fn a_short_spectral_run_fits_the_spectrum_as_well_as_an_rgb_run_fits_rgb() {
    let config = small_config();
    let owned = sampled(&config, spectral_phong);
    let outcome = train_spectral_arrays(
        &owned.arrays(false),
        RglFold::AsMeasured,
        &config,
        "s",
        &mut |_| {},
    )
    .unwrap();
    let net = &outcome.network;
    assert_eq!(net.output_count(), SPECTRAL_OUTPUTS);
    assert_eq!(
        net.spectral.as_ref().unwrap().basis(),
        &SpectralBasis::default()
    );
    let spectral_error = per_wavelength_log_error(net, spectral_phong);
    // The RGB reference: the same material at three wavelengths as R, G and B.
    let rgb_target = |a: &crate::coords::RusinkiewiczAngles| {
        let (v, l) = crate::coords::from_rusinkiewicz(a);
        let (v, l) = (v.as_vec3(), l.as_vec3());
        Some([610.0, 550.0, 465.0].map(|lambda| spectral_phong(v, l, lambda)))
    };
    let rgb = crate::train::train(&rgb_target, &config, "r", &mut |_| {}).unwrap();
    let rgb_error = log_error_on_fresh_directions(&rgb_target, &rgb.network.layers);
    assert!(
        spectral_error < 2.0 * rgb_error.max(1e-3),
        "spectral {spectral_error} vs RGB {rgb_error}, history {:?}",
        outcome.report.history
    );
    assert!(spectral_error < 1e-2, "{spectral_error}");
    // The file round-trips as a version-3 network.
    let text = net.to_json_string();
    assert!(
        text.contains("\"version\": 3") || text.contains("\"version\":3"),
        "{text:.200}"
    );
    let back = crate::network::Nbrdf::from_json_str(&text, std::path::Path::new("s")).unwrap();
    assert_eq!(back.output_count(), SPECTRAL_OUTPUTS);
}

/// The target of a constant spectrum is that constant in every coefficient (the basis sums to
/// 1), and a spectrum whose least-squares fit rings below 0 has those coefficients clamped.
#[test]
fn targets_are_the_clamped_least_squares_coefficients() {
    let wl = wavelengths();
    let target = SpectralTarget::new(&wl).unwrap();
    let constant = target.coefficients(&vec![0.4; wl.len()]);
    assert!(
        constant.iter().all(|c| (c - 0.4).abs() < 1e-9),
        "{constant:?}"
    );
    let mut spike = vec![0.0; wl.len()];
    spike[20] = 1.0;
    let wl64: Vec<f64> = wl.iter().map(|&l| f64::from(l)).collect();
    let raw = SpectralBasis::default().least_squares(&wl64).unwrap();
    let unclamped: Vec<f64> = (0..SPECTRAL_OUTPUTS)
        .map(|k| raw[k * wl.len() + 20])
        .collect();
    assert!(unclamped.iter().any(|&c| c < -1e-4), "{unclamped:?}");
    let clamped = target.coefficients(&spike);
    for (c, u) in clamped.iter().zip(&unclamped) {
        assert_eq!(*c, u.max(0.0));
    }
    let (v, l) = (Vec3::new(0.0, 0.6, 0.8), Vec3::new(0.6, 0.0, 0.8));
    let s = target.sample(false, v, l, &vec![0.4 * 0.8; wl.len()]);
    assert_eq!(s.cos_light, 0.8);
    for t in s.log_target {
        assert!((f64::from(t) - (0.4f64 * 0.8).ln_1p()).abs() < 1e-6);
    }
}

#[test]
fn bad_spectral_arrays_are_errors_naming_the_problem() {
    let config = TrainConfig {
        samples: 200,
        ..small_config()
    };
    let owned = sampled(&config, spectral_phong);
    let train = |owned: &Owned, swapped: bool, fold: RglFold, validation: usize| {
        train_spectral_arrays(
            &SampledSpectra {
                validation,
                ..owned.arrays(swapped)
            },
            fold,
            &TrainConfig {
                max_epochs: 1,
                ..config.clone()
            },
            "x",
            &mut |_| {},
        )
        .map(|_| ())
        .unwrap_err()
        .to_string()
    };
    let v = owned.validation;
    let with_wavelengths = |wavelengths: Vec<f32>| Owned {
        wavelengths,
        ..sampled(&config, spectral_phong)
    };
    let mut decreasing = wavelengths();
    decreasing.swap(3, 4);
    let e = train(&with_wavelengths(decreasing), false, RglFold::AsMeasured, v);
    assert!(e.contains("strictly increasing"), "{e}");
    let mut nan = wavelengths();
    nan[5] = f32::NAN;
    let e = train(&with_wavelengths(nan), false, RglFold::AsMeasured, v);
    assert!(e.contains("not finite"), "{e}");
    let infrared: Vec<f32> = wavelengths().iter().map(|l| l + 1000.0).collect();
    let e = train(&with_wavelengths(infrared), false, RglFold::AsMeasured, v);
    assert!(e.contains("overlap"), "{e}");
    let mut short = sampled(&config, spectral_phong);
    short.eval_cos.pop();
    let e = train(&short, false, RglFold::AsMeasured, v);
    assert!(e.contains("values for"), "{e}");
    let mut bad_value = sampled(&config, spectral_phong);
    let n = bad_value.view.len();
    bad_value.eval_cos[3 * n + 7] = f32::INFINITY;
    let e = train(&bad_value, false, RglFold::AsMeasured, v);
    assert!(e.contains("pair 7"), "{e}");
    let e = train(&owned, false, RglFold::ReciprocalMean, v);
    assert!(e.contains("swapped"), "{e}");
    for validation in [0, n] {
        let e = train(&owned, false, RglFold::AsMeasured, validation);
        assert!(e.contains("validation"), "{e}");
    }
}

/// The reciprocal mean of a non-reciprocal spectrum folds each wavelength as the RGB arrays do.
#[test]
fn the_reciprocal_mean_folds_every_wavelength() {
    let config = TrainConfig {
        samples: 500,
        sampling: AngularSampling::Uniform,
        ..small_config()
    };
    let lopsided = |v: Vec3, l: Vec3, lambda: f64| {
        (0.2 + 0.3 * f64::from(l.z) + 0.1 * f64::from(v.x).abs()) * (lambda / 600.0)
    };
    let owned = sampled(&config, lopsided);
    let target = SpectralTarget::new(&owned.wavelengths).unwrap();
    let set = spectral_set(
        &owned.arrays(true),
        &target,
        0..500,
        RglFold::ReciprocalMean,
        false,
    )
    .unwrap();
    assert_eq!(
        set.samples.len() as u64 + set.invalid + set.below_horizon,
        500
    );
    let kept = (0..500).filter(|&i| {
        f64::from(owned.view[i].z) >= crate::source::GRAZING_COS
            && f64::from(owned.light[i].z) >= crate::source::GRAZING_COS
    });
    for (i, s) in kept.zip(&set.samples) {
        let (v, l) = (owned.view[i], owned.light[i]);
        let mean: Vec<f64> = owned
            .wavelengths
            .iter()
            .map(|&lambda| {
                let lambda = f64::from(lambda);
                0.5 * (lopsided(v, l, lambda) + lopsided(l, v, lambda)) * f64::from(l.z)
            })
            .collect();
        let want = target.coefficients(&mean);
        for (t, c) in s.log_target.iter().zip(want) {
            assert!((f64::from(*t) - c.ln_1p()).abs() < 1e-5, "pair {i}");
        }
    }
}
