//! Sampling at texels: the strategy is that of the filtered lobe parameters (a float64 oracle),
//! its pdf integrates to 1 together with the mass the sampler rejects below the horizon, the
//! sampled directions follow the pdf (chi-square), and bad parameters sample the cosine lobe.

use super::tests::{mapping, material, oracle_lookup, uniform};
use super::*;
use crate::rng::SplitMix64;
use std::f64::consts::{FRAC_PI_2, PI, TAU};

fn materials() -> [TexturedNbrdf; 3] {
    [
        material(
            8,
            8,
            4,
            SamplingChannels::one_lobe(),
            UvMapping::default(),
            31,
        ),
        material(
            8,
            8,
            4,
            SamplingChannels::two_lobes(),
            mapping(WrapMode::Clamp, FilterMode::Bilinear),
            32,
        ),
        material(
            5,
            3,
            4,
            SamplingChannels::one_lobe(),
            mapping(WrapMode::Mirror, FilterMode::Nearest),
            33,
        ),
    ]
}

/// The lobes `(exponent, weight)` the float64 oracle lookup gives at `uv`: exponents `exp(code)
/// - 1` of the filtered codes.
fn oracle_lobes(m: &TexturedNbrdf, uv: [f32; 2]) -> Vec<(f64, f64)> {
    let values = oracle_lookup(m.texture(), m.mapping(), uv).unwrap();
    values[m.decoder().latent_channels()..]
        .chunks(2)
        .map(|pair| (pair[0].exp() - 1.0, pair[1]))
        .collect()
}

/// The lobes `(exponent, weight)` of a strategy.
pub(crate) fn lobes_of(strategy: &SamplingStrategy) -> Vec<(f64, f64)> {
    match *strategy {
        SamplingStrategy::Phong {
            exponent,
            specular_weight,
        } => vec![(exponent, specular_weight)],
        SamplingStrategy::TwoLobe {
            exponent1,
            weight1,
            exponent2,
            weight2,
        } => vec![(exponent1, weight1), (exponent2, weight2)],
        _ => vec![],
    }
}

#[test]
fn the_strategy_is_that_of_the_filtered_lobe_parameters() {
    let mut rng = SplitMix64::from_state(34);
    for m in materials() {
        for _ in 0..300 {
            let uv = [
                uniform(&mut rng, -2.0, 3.0) as f32,
                uniform(&mut rng, -2.0, 3.0) as f32,
            ];
            let got = lobes_of(&m.sampling_strategy(uv));
            let want = oracle_lobes(&m, uv);
            assert_eq!(got.len(), want.len(), "uv {uv:?}");
            for ((n, w), (n_want, w_want)) in got.into_iter().zip(want) {
                assert!(
                    (n - n_want).abs() <= 1e-4 * n_want,
                    "uv {uv:?}: n {n} vs {n_want}"
                );
                assert!((w - w_want).abs() <= 1e-6, "uv {uv:?}: w {w} vs {w_want}");
            }
        }
    }
}

/// Integral of `f` over the upper hemisphere on a polar grid about the normal, `theta =
/// (pi/2) s^2` (dense near the normal), midpoint rule in `s` and azimuth.
pub(crate) fn hemisphere_integral(ns: usize, nb: usize, f: impl Fn(Vec3) -> f64) -> f64 {
    let mut total = 0.0;
    for i in 0..ns {
        let s = (i as f64 + 0.5) / ns as f64;
        let (theta, d_theta) = (FRAC_PI_2 * s * s, PI * s / ns as f64);
        let ring: f64 = (0..nb)
            .map(|j| {
                f(
                    crate::coords::spherical_direction(theta, TAU * (j as f64 + 0.5) / nb as f64)
                        .as_vec3(),
                )
            })
            .sum();
        total += ring * theta.sin() * d_theta * TAU / nb as f64;
    }
    total
}

/// At normal incidence a Blinn-Phong lobe reflects below the horizon exactly when
/// `theta_h > pi/4`, which has probability `cos(pi/4)^(n + 1) = 2^(-(n + 1)/2)`: that mass
/// (an invalid sample) plus the hemisphere integral of the pdf is 1.
#[test]
fn the_pdf_integrates_to_one_with_the_rejected_mass() {
    let mut rng = SplitMix64::from_state(35);
    for m in materials() {
        for _ in 0..4 {
            let uv = [rng.next_f32(), rng.next_f32()];
            let rejected: f64 = oracle_lobes(&m, uv)
                .into_iter()
                .map(|(n, w)| w * 0.5f64.powf(0.5 * (n + 1.0)))
                .sum();
            let total = hemisphere_integral(2000, 8, |l| f64::from(m.pdf(uv, Vec3::Z, l)));
            assert!(
                (total + rejected - 1.0).abs() < 1e-4,
                "uv {uv:?}: {total} + {rejected}"
            );
        }
    }
}

/// The chi-square quantile of `dof` degrees of freedom at the normal quantile `z`
/// (Wilson-Hilferty).
fn chi2_quantile(dof: f64, z: f64) -> f64 {
    let a = 2.0 / (9.0 * dof);
    dof * (1.0 - a + z * a.sqrt()).powi(3)
}

/// Pearson's chi-square of samples drawn at `uv` and `view` against the pdf, over bins of equal
/// solid angle (10 in `cos theta`, 16 in azimuth) and one bin for invalid samples; bins expecting
/// fewer than 5 samples are pooled. The expected counts come from quadrature of the pdf.
pub(crate) fn chi2_test(m: &TexturedNbrdf, uv: [f32; 2], view: Vec3, samples: usize, seed: u64) {
    const NZ: usize = 10;
    const NP: usize = 16;
    const SUB: usize = 12;
    let mut expected = vec![0.0; NZ * NP + 1];
    for (bin, p) in expected.iter_mut().take(NZ * NP).enumerate() {
        let (iz, ip) = (bin / NP, bin % NP);
        for a in 0..SUB {
            for b in 0..SUB {
                let z = (iz as f64 + (a as f64 + 0.5) / SUB as f64) / NZ as f64;
                let phi = TAU * (ip as f64 + (b as f64 + 0.5) / SUB as f64) / NP as f64;
                let r = (1.0 - z * z).sqrt();
                let l = glam::DVec3::new(r * phi.cos(), r * phi.sin(), z).as_vec3();
                *p += f64::from(m.pdf(uv, view, l));
            }
        }
        *p *= TAU / (NZ * NP * SUB * SUB) as f64;
    }
    expected[NZ * NP] = (1.0 - expected.iter().sum::<f64>()).max(0.0);
    let mut observed = vec![0.0; NZ * NP + 1];
    let mut rng = SplitMix64::from_state(seed);
    for _ in 0..samples {
        let s = m.sample(uv, view, [rng.next_f32(), rng.next_f32(), rng.next_f32()]);
        let bin = if s.pdf > 0.0 {
            let l = s.light.as_dvec3();
            let iz = ((l.z * NZ as f64) as usize).min(NZ - 1);
            let ip = ((l.y.atan2(l.x).rem_euclid(TAU) / TAU * NP as f64) as usize).min(NP - 1);
            iz * NP + ip
        } else {
            NZ * NP
        };
        observed[bin] += 1.0;
    }
    let n = samples as f64;
    let (mut chi2, mut dof, mut pooled) = (0.0, -1.0, (0.0, 0.0));
    for (o, e) in observed.iter().zip(&expected) {
        if e * n < 5.0 {
            pooled = (pooled.0 + o, pooled.1 + e * n);
        } else {
            chi2 += (o - e * n).powi(2) / (e * n);
            dof += 1.0;
        }
    }
    if pooled.1 > 0.0 {
        chi2 += (pooled.0 - pooled.1).powi(2) / pooled.1.max(5.0);
        dof += 1.0;
    }
    let limit = chi2_quantile(dof, 4.265); // p = 1e-5
    assert!(
        chi2 < limit,
        "uv {uv:?} view {view}: chi2 {chi2} over {limit} ({dof} dof)"
    );
}

#[test]
fn sampled_directions_follow_the_pdf() {
    let views = [
        crate::coords::spherical_direction(0.0, 0.0),
        crate::coords::spherical_direction(0.8, 1.0),
        crate::coords::spherical_direction(1.3, -2.0),
    ];
    let mut rng = SplitMix64::from_state(36);
    for (k, m) in materials().iter().enumerate() {
        for (j, view) in views.into_iter().enumerate() {
            let uv = [rng.next_f32(), rng.next_f32()];
            chi2_test(
                m,
                uv,
                view.as_vec3(),
                40_000,
                100 + 10 * k as u64 + j as u64,
            );
        }
    }
}

#[test]
fn a_sample_reports_the_pdf_of_its_direction() {
    let mut rng = SplitMix64::from_state(37);
    for m in materials() {
        let mut valid = 0;
        for _ in 0..2000 {
            let uv = [
                uniform(&mut rng, -1.0, 2.0) as f32,
                uniform(&mut rng, -1.0, 2.0) as f32,
            ];
            let view =
                crate::sampling::uniform_hemisphere(rng.next_f64(), rng.next_f64()).as_vec3();
            let s = m.sample(uv, view, [rng.next_f32(), rng.next_f32(), rng.next_f32()]);
            assert_eq!(s.pdf, m.pdf(uv, view, s.light), "uv {uv:?} view {view}");
            valid += usize::from(s.pdf > 0.0);
        }
        assert!(valid > 1500, "{valid}");
    }
}

/// A one-texel material (nearest filtering) whose lobe channels hold `lobe`.
fn one_texel(lobe: &[f32]) -> TexturedNbrdf {
    let sampling = if lobe.len() == 2 {
        SamplingChannels::one_lobe()
    } else {
        SamplingChannels::two_lobes()
    };
    let names = TexturedNbrdf::channel_names_for(1, &sampling);
    let texels = [&[0.5], lobe].concat();
    let texture = LatentTexture::new(1, 1, names, texels).unwrap();
    let decoder = super::tests::decoder(1, &[4], false, 1);
    let mapping = mapping(WrapMode::Repeat, FilterMode::Nearest);
    TexturedNbrdf::new("one", decoder, texture, mapping, sampling, "one.exr").unwrap()
}

#[test]
fn bad_lobe_parameters_sample_the_cosine_lobe() {
    let n = encode_exponent(20.0);
    let too_sharp = (MAX_EXPONENT_CODE * 1.001) as f32;
    let bad: [&[f32]; 9] = [
        &[f32::NAN, 0.5],
        &[n, f32::NAN],
        &[f32::NEG_INFINITY, 0.5],
        &[-0.1, 0.5],
        &[too_sharp, 0.5],
        &[n, 1.5],
        &[n, -0.2],
        &[n, 0.7, n, 0.6],
        &[n, 0.5, f32::INFINITY, 0.1],
    ];
    let (view, light) = (Vec3::new(0.3, 0.0, 0.95), Vec3::new(-0.3, 0.1, 0.9));
    for lobe in bad {
        let m = one_texel(lobe);
        assert_eq!(
            m.sampling_strategy([0.5, 0.5]),
            SamplingStrategy::Cosine,
            "{lobe:?}"
        );
        let cosine = light.normalize().z / std::f32::consts::PI;
        assert!(
            (m.pdf([0.5, 0.5], view, light) - cosine).abs() <= 1e-6,
            "{lobe:?}"
        );
    }
    // Just past the range by float32 rounding: clamped into it.
    let m = one_texel(&[n, 1.0 + 1e-7]);
    assert_eq!(
        lobes_of(&m.sampling_strategy([0.5, 0.5])),
        [(decode_exponent(f64::from(n)), 1.0)]
    );
    let m = one_texel(&[n, 0.6, n, 0.4 + 1e-7]);
    let weights: f64 = lobes_of(&m.sampling_strategy([0.5, 0.5]))
        .iter()
        .map(|l| l.1)
        .sum();
    assert!(weights <= 1.0 && weights > 1.0 - 1e-6, "{weights}");
    // The sharpest lobe stays a lobe, its code rounded to float32 either way.
    let m = one_texel(&[encode_exponent(crate::sampling::MAX_EXPONENT), 0.5]);
    let sharpest = lobes_of(&m.sampling_strategy([0.5, 0.5]))[0].0;
    assert!(
        (sharpest / crate::sampling::MAX_EXPONENT - 1.0).abs() < 1e-6,
        "{sharpest}"
    );
}

/// The code of the largest exponent, `ln(1 + 1e6)`.
const MAX_EXPONENT_CODE: f64 = 13.815511557963774;
