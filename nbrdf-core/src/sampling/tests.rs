//! The strategies against quadrature: densities integrate to 1, samples follow the pdf.

use super::*;
use crate::network::Nbrdf;
use crate::rng::SplitMix64;
use std::f64::consts::{FRAC_PI_2, PI, TAU};

const EXPONENTS: [f64; 7] = [0.0, 1.0, 10.0, 100.0, 1e3, 1e4, 1e5];

fn dir(theta_deg: f64, phi: f64) -> DVec3 {
    crate::coords::spherical_direction(theta_deg.to_radians(), phi)
}

fn mirror(v: DVec3) -> DVec3 {
    DVec3::new(-v.x, -v.y, v.z)
}

/// Integral of `f` over the spherical cap of angular radius `alpha_max` around `centre`, in
/// spherical coordinates centred there with `alpha = alpha_max s^2` (s uniform): the grid is
/// dense near the centre, where sharp lobes live. Midpoint rule in `s` and in the periodic
/// azimuth.
fn cap_integral(
    centre: DVec3,
    alpha_max: f64,
    ns: usize,
    nb: usize,
    f: impl Fn(DVec3) -> f64 + Sync,
) -> f64 {
    let c = centre.normalize();
    let (t1, t2) = c.any_orthonormal_pair();
    (0..ns)
        .into_par_iter()
        .map(|i| {
            let s = (i as f64 + 0.5) / ns as f64;
            let alpha = alpha_max * s * s;
            let d_alpha = 2.0 * alpha_max * s / ns as f64;
            let (sin_a, cos_a) = alpha.sin_cos();
            let ring: f64 = (0..nb)
                .map(|j| {
                    let (sin_b, cos_b) = (TAU * (j as f64 + 0.5) / nb as f64).sin_cos();
                    f(cos_a * c + sin_a * (cos_b * t1 + sin_b * t2))
                })
                .sum();
            ring * sin_a * d_alpha * TAU / nb as f64
        })
        .sum()
}

fn sphere_integral(centre: DVec3, ns: usize, nb: usize, f: impl Fn(DVec3) -> f64 + Sync) -> f64 {
    cap_integral(centre, PI, ns, nb, f)
}

/// Smooth (C1) weight, 1 within `radius / 2` of `centre`, 0 beyond `radius`.
fn bump(centre: DVec3, radius: f64, l: DVec3) -> f64 {
    let t = (l.dot(centre).clamp(-1.0, 1.0).acos() / radius - 0.5) * 2.0;
    let t = t.clamp(0.0, 1.0);
    1.0 - t * t * (3.0 - 2.0 * t)
}

/// Integral over the sphere of a lobe density at view `v`: the specular terms have an
/// integrable `1 / |l + v|` singularity at `l = -v`, so a partition of unity integrates a
/// neighbourhood of `-v` on a grid centred there (where the singularity is harmless in polar
/// coordinates) and the rest on a grid centred on the mirror direction, where sharp lobes are.
fn density_integral(v: DVec3, density: impl Fn(DVec3) -> f64 + Sync) -> f64 {
    let radius = 0.08;
    let near = cap_integral(-v, radius, 400, 128, |l| density(l) * bump(-v, radius, l));
    let far = sphere_integral(mirror(v), 1500, 256, |l| {
        density(l) * (1.0 - bump(-v, radius, l))
    });
    near + far
}

/// [`density_integral`] of the Blinn-Phong mixture.
fn lobe_integral(v: DVec3, n: f64, w: f64) -> f64 {
    density_integral(v, |l| phong_lobe_density(v, l, n, w))
}

#[test]
fn validated_rejects_bad_parameters() {
    let bp = |exponent, specular_weight| SamplingStrategy::Phong {
        exponent,
        specular_weight,
    };
    assert!(bp(10.0, 0.5).validated().is_ok());
    assert!(bp(0.0, 0.0).validated().is_ok() && bp(1e6, 1.0).validated().is_ok());
    for bad in [
        bp(-1.0, 0.5),
        bp(f64::NAN, 0.5),
        bp(f64::INFINITY, 0.5),
        bp(MAX_EXPONENT * (1.0 + 1e-12), 0.5),
        bp(3.4e38, 0.5),
        bp(1.0, -0.1),
        bp(1.0, 1.5),
        bp(1.0, f64::NAN),
    ] {
        assert!(
            matches!(bad.clone().validated(), Err(NbrdfError::InvalidArgument(_))),
            "{bad:?}"
        );
        // Unvalidated bad parameters still give finite output.
        let s = bad.sample(Vec3::Z, [0.5; 3]);
        assert_eq!(s.pdf, 0.0);
        assert!(s.light.is_finite());
        assert_eq!(bad.pdf(Vec3::Z, Vec3::Z), 0.0);
    }
    assert!(
        SamplingStrategy::Cosine.validated().is_ok()
            && SamplingStrategy::Uniform.validated().is_ok()
    );
}

/// The anisotropic lobe integrates to 1 over the sphere of light directions, also stiff
/// (`n_u = 1e4`, `n_v = 10`) and at grazing views. Where the light-space lobe is too
/// distorted for the grid (stiff and grazing: thousands of times narrower across than
/// along), the integral is taken over half vectors instead, with the Jacobian
/// `dl = 4 |v . h| dh` of the reflection, on a grid centred on the normal.
#[test]
fn anisotropic_density_integrates_to_one_over_the_sphere() {
    let views = [dir(0.0, 0.0), dir(60.0, 0.4), dir(85.0, 2.0)];
    for exponents in [[100.0, 10.0], [1e4, 10.0], [0.0, 300.0]] {
        let density = |v: DVec3, l: DVec3| anisotropic_lobe_density(v, l, exponents, 0.7);
        let v = views[0];
        let radius = 0.08;
        let near = cap_integral(-v, radius, 400, 128, |l| {
            density(v, l) * bump(-v, radius, l)
        });
        let far = sphere_integral(mirror(v), 1500, 2048, |l| {
            density(v, l) * (1.0 - bump(-v, radius, l))
        });
        let total = near + far;
        // (A zero exponent makes a band around a great circle, which the grid cannot
        // follow; the half-vector integral below covers it.)
        if exponents[0] > 0.0 {
            assert!((total - 1.0).abs() < 1e-4, "{exponents:?} v {v}: {total}");
        }
        for v in views {
            let specular = cap_integral(DVec3::Z, 0.5 * PI, 1500, 2048, |h| {
                let l = 2.0 * v.dot(h) * h - v;
                anisotropic_lobe_density(v, l, exponents, 1.0) * 4.0 * v.dot(h).abs()
            });
            assert!(
                (specular - 1.0).abs() < 1e-4,
                "{exponents:?} v {v}: {specular}"
            );
        }
    }
}

/// With equal exponents the anisotropic lobe is the isotropic Blinn-Phong lobe; with
/// different ones it is stretched along the axis of the smaller exponent.
#[test]
fn anisotropic_density_reduces_to_blinn_phong_and_orients_by_axis() {
    let mut rng = SplitMix64::from_state(12);
    for _ in 0..500 {
        let v = uniform_hemisphere(rng.next_f64(), rng.next_f64());
        let l = uniform_hemisphere(rng.next_f64(), rng.next_f64());
        let want = phong_lobe_density(v, l, 40.0, 0.6);
        let got = anisotropic_lobe_density(v, l, [40.0, 40.0], 0.6);
        assert!((got - want).abs() <= 1e-12 * want, "{got} vs {want}");
    }
    // Half vectors tilted by 0.15 rad along x and along y, view at the normal.
    let v = DVec3::Z;
    let tilted = |phi: f64| {
        let h = crate::coords::spherical_direction(0.15, phi);
        2.0 * v.dot(h) * h - v
    };
    let density = |l| anisotropic_lobe_density(v, l, [1000.0, 10.0], 1.0);
    assert!(density(tilted(0.0)) < 1e-3 * density(tilted(FRAC_PI_2)));
}

#[test]
fn hemisphere_pdfs_integrate_to_one() {
    let v = Vec3::new(0.3, -0.2, 0.9);
    for strategy in [SamplingStrategy::Uniform, SamplingStrategy::Cosine] {
        let total = cap_integral(DVec3::Z, 0.5 * PI, 800, 64, |l| {
            f64::from(strategy.pdf(v, l.as_vec3()))
        });
        assert!((total - 1.0).abs() < 1e-5, "{strategy:?}: {total}");
    }
}

#[test]
fn blinn_phong_density_integrates_to_one_over_the_sphere() {
    let views = [dir(0.0, 0.0), dir(60.0, 0.4), dir(85.0, 2.0)];
    for n in EXPONENTS {
        for w in [0.25, 1.0] {
            for v in views {
                let total = lobe_integral(v, n, w);
                assert!((total - 1.0).abs() < 1e-4, "n {n} w {w} v {v}: {total}");
            }
        }
    }
    let total = cap_integral(DVec3::Z, 0.5 * PI, 800, 64, |l| {
        phong_lobe_density(DVec3::Z, l, 50.0, 0.0)
    });
    assert!((total - 1.0).abs() < 1e-5, "{total}");
}

#[test]
fn pdf_is_the_lobe_density_above_the_horizon_and_zero_below() {
    let mut rng = SplitMix64::from_state(5);
    let strategy = SamplingStrategy::Phong {
        exponent: 30.0,
        specular_weight: 0.6,
    };
    for _ in 0..1000 {
        let v = uniform_hemisphere(rng.next_f64(), rng.next_f64());
        let l = DVec3::new(
            rng.next_f64() - 0.5,
            rng.next_f64() - 0.5,
            rng.next_f64() - 0.5,
        );
        let p = strategy.pdf_f64(v, l);
        if l.z <= 0.0 {
            assert_eq!(p, 0.0);
            assert_eq!(strategy.pdf_f64(-v, -l), 0.0);
        } else {
            let want = phong_lobe_density(v, l, 30.0, 0.6);
            assert!((p - want).abs() <= 1e-12 * want, "{p} vs {want}");
        }
    }
}

#[test]
fn sampled_pdf_equals_pdf() {
    let mut rng = SplitMix64::from_state(1);
    let strategies = [
        SamplingStrategy::Uniform,
        SamplingStrategy::Cosine,
        SamplingStrategy::Phong {
            exponent: 20.0,
            specular_weight: 0.5,
        },
        SamplingStrategy::Phong {
            exponent: 1e6,
            specular_weight: 0.9,
        },
        SamplingStrategy::anisotropic(100.0, 10.0, 0.5),
        SamplingStrategy::anisotropic(1e4, 10.0, 0.9),
    ];
    for strategy in strategies {
        let mut valid = 0;
        for _ in 0..2000 {
            let v = uniform_hemisphere(rng.next_f64(), rng.next_f64()).as_vec3() * 2.0;
            let u = [rng.next_f32(), rng.next_f32(), rng.next_f32()];
            let s = strategy.sample(v, u);
            assert_eq!(s.pdf, strategy.pdf(v, s.light), "{strategy:?} {v} {u:?}");
            assert!((s.light.length() - 1.0).abs() < 1e-6);
            valid += usize::from(s.pdf > 0.0);
        }
        assert!(valid > 1000, "{strategy:?}: only {valid} valid samples");
    }
}

/// Mean of `g` over `samples` draws of `strategy` at `v` (0 for invalid draws), with its
/// standard error.
pub(crate) fn sample_mean(
    strategy: &SamplingStrategy,
    v: DVec3,
    g: &dyn Fn(DVec3) -> f64,
    samples: usize,
    seed: u64,
) -> (f64, f64) {
    let mut rng = SplitMix64::from_state(seed);
    let (mut sum, mut sum2) = (0.0, 0.0);
    for _ in 0..samples {
        let s = strategy.sample(
            v.as_vec3(),
            [rng.next_f32(), rng.next_f32(), rng.next_f32()],
        );
        let x = if s.pdf > 0.0 {
            g(s.light.as_dvec3())
        } else {
            0.0
        };
        sum += x;
        sum2 += x * x;
    }
    let mean = sum / samples as f64;
    (
        mean,
        ((sum2 / samples as f64 - mean * mean) / samples as f64).sqrt(),
    )
}

/// For each function `g` of `tests`, its mean over `samples` draws of `strategy` at `v`
/// (seeded `seed + index`) against the quadrature of `g * pdf` over the sphere around `r`:
/// the sampler must draw from the density that `pdf` reports.
fn assert_sample_means_match_pdf(
    strategy: &SamplingStrategy,
    v: DVec3,
    r: DVec3,
    tests: &[&(dyn Fn(DVec3) -> f64 + Sync)],
    samples: usize,
    seed: u64,
) {
    for (t, g) in tests.iter().enumerate() {
        let exact = sphere_integral(r, 1500, 256, |l| g(l) * strategy.pdf_f64(v, l));
        let (mean, sigma) = sample_mean(strategy, v, g, samples, seed + t as u64);
        assert!(
            (mean - exact).abs() < 5.0 * sigma + 1e-4,
            "{strategy:?} test {t}: MC {mean} +- {sigma} vs quadrature {exact}"
        );
    }
}

/// Monte Carlo means under the sampler against quadrature of the same function times the pdf:
/// checks that the sampler draws from the density that `pdf` reports.
#[test]
fn sample_histogram_matches_pdf() {
    let cases = [
        (SamplingStrategy::Uniform, dir(30.0, 0.0)),
        (SamplingStrategy::Cosine, dir(30.0, 0.0)),
        (
            SamplingStrategy::Phong {
                exponent: 10.0,
                specular_weight: 0.5,
            },
            dir(45.0, 1.0),
        ),
        (
            SamplingStrategy::Phong {
                exponent: 1000.0,
                specular_weight: 0.8,
            },
            dir(70.0, -2.0),
        ),
    ];
    let samples = 200_000;
    for (strategy, v) in cases {
        let r = mirror(v);
        // A smooth function and a histogram bin (a cone around the mirror direction).
        let tests: [&(dyn Fn(DVec3) -> f64 + Sync); 2] =
            [&|l: DVec3| l.z + 0.5 * l.x * l.x, &|l: DVec3| {
                f64::from(u8::from(l.dot(r) > 0.995))
            }];
        assert_sample_means_match_pdf(&strategy, v, r, &tests, samples, 17);
    }
}

/// The anisotropic sampler draws from the density its pdf reports (Monte Carlo means
/// against quadrature), also stiff (`n_u = 1e4`, `n_v = 10`) and at grazing incidence; the
/// test functions tell the x and y spreads apart.
#[test]
fn anisotropic_samples_match_pdf() {
    let cases = [
        (
            SamplingStrategy::anisotropic(100.0, 10.0, 0.6),
            dir(40.0, 0.7),
        ),
        (
            SamplingStrategy::anisotropic(1e4, 10.0, 0.8),
            dir(30.0, -1.0),
        ),
        (
            SamplingStrategy::anisotropic(1e4, 10.0, 0.8),
            dir(85.0, 2.5),
        ),
    ];
    for (strategy, v) in cases {
        let r = mirror(v);
        let tests: [&(dyn Fn(DVec3) -> f64 + Sync); 3] = [
            &|l: DVec3| l.z + 0.5 * l.x * l.x,
            &|l: DVec3| f64::from(u8::from(l.dot(r) > 0.995)),
            &|l: DVec3| 10.0 * (l - r).x.powi(2) + (l - r).y.powi(2),
        ];
        assert_sample_means_match_pdf(&strategy, v, r, &tests, 200_000, 23);
    }
}

#[test]
fn extreme_inputs_stay_finite() {
    let views = [
        Vec3::Z,
        dir(89.9999, 0.3).as_vec3(),
        Vec3::new(1.0, 0.0, 1e-6),
        Vec3::new(0.0, 0.0, -1.0),
        Vec3::new(0.5, 0.5, -1e-7),
        Vec3::ZERO,
        Vec3::new(f32::NAN, 0.0, 1.0),
        Vec3::new(0.0, 0.0, f32::INFINITY),
        Vec3::new(3e-30, 0.0, 4e-30),
        Vec3::new(3e30, 0.0, 4e30),
    ];
    let us = [0.0, 1e-30, 1e-7, 0.5, 1.0 - 1e-7, 1.0, -1.0, 2.0, f32::NAN];
    let mut strategies = vec![SamplingStrategy::Uniform, SamplingStrategy::Cosine];
    for exponent in [0.0, 1e-3, 1.0, 1e6] {
        for specular_weight in [0.0, 0.5, 1.0] {
            strategies.push(SamplingStrategy::Phong {
                exponent,
                specular_weight,
            });
        }
    }
    for strategy in strategies {
        for v in views {
            for u0 in us {
                for u1 in us {
                    for u2 in [0.0, 0.3, 1.0] {
                        let s = strategy.sample(v, [u0, u1, u2]);
                        assert!(
                            s.light.is_finite() && s.pdf.is_finite() && s.pdf >= 0.0,
                            "{strategy:?} {v} {s:?}"
                        );
                        assert_eq!(s.pdf, strategy.pdf(v, s.light));
                        if !(v.z > 0.0 && v.is_finite()) {
                            assert_eq!(s.pdf, 0.0);
                        }
                    }
                }
            }
            for l in views {
                let p = strategy.pdf(v, l);
                assert!(p.is_finite() && p >= 0.0);
            }
        }
    }
    // The sharpest lobe with the extreme uniforms lands on the mirror direction.
    let bp = SamplingStrategy::Phong {
        exponent: 1e6,
        specular_weight: 1.0,
    };
    let v = dir(40.0, 0.0).as_vec3();
    let s = bp.sample(v, [0.0, 1.0, 0.0]);
    assert!(
        (s.light - Vec3::new(-v.x, -v.y, v.z)).length() < 1e-6 && s.pdf > 1e4,
        "{s:?}"
    );
    assert_eq!(bp.sample(v, [0.0, 0.0, 0.0]).pdf, 0.0); // half vector on the horizon
}

#[test]
fn batches_match_single_lanes() {
    let net = Nbrdf::random("n", 21, 3);
    let strategy = SamplingStrategy::Phong {
        exponent: 40.0,
        specular_weight: 0.7,
    };
    let n = 3 * TASK_LANES + 17;
    let mut rng = SplitMix64::from_state(9);
    let mut view = vec![0.0f32; 3 * n];
    let mut u = vec![0.0f32; 3 * n];
    for i in 0..n {
        let v = uniform_hemisphere(rng.next_f64(), rng.next_f64()).as_vec3();
        for k in 0..3 {
            view[k * n + i] = v[k];
            u[k * n + i] = rng.next_f32();
        }
    }
    view[5] = -0.5; // one view below the horizon (x of lane 5 is fine; make z negative)
    view[2 * n + 5] = -0.5;
    let (mut light, mut weight, mut pdf) =
        (vec![0.0f32; 3 * n], vec![0.0f32; 3 * n], vec![0.0f32; n]);
    let view_d = Directions::from_planar(&view).unwrap();
    let u_d = Directions::from_planar(&u).unwrap();
    sample_batch(
        &strategy,
        &net,
        view_d,
        u_d,
        DirectionsMut::from_planar(&mut light).unwrap(),
        RgbMut::from_planar(&mut weight).unwrap(),
        &mut pdf,
    );
    let mut pdf2 = vec![0.0f32; n];
    pdf_batch(
        &strategy,
        view_d,
        Directions::from_planar(&light).unwrap(),
        &mut pdf2,
    );
    assert_eq!(pdf, pdf2);
    let mut invalid = 0;
    for i in 0..n {
        let v = view_d.get(i);
        let s = strategy.sample(v, [u[i], u[n + i], u[2 * n + i]]);
        assert_eq!(s.light, Vec3::new(light[i], light[n + i], light[2 * n + i]));
        assert_eq!(s.pdf, pdf[i]);
        let f = net.eval(v, s.light);
        let cos = crate::brdf::cos_theta_light(s.light);
        for c in 0..3 {
            let want = if s.pdf > 0.0 { f[c] * cos / s.pdf } else { 0.0 };
            let got = weight[c * n + i];
            assert!(
                (got - want).abs() <= 1e-4 * want.abs() + 1e-9,
                "lane {i}: {got} vs {want}"
            );
        }
        invalid += usize::from(s.pdf == 0.0);
    }
    assert!(pdf[5] == 0.0 && weight[5] == 0.0);
    assert!(invalid > 0 && invalid < n / 4);
}

fn two_lobe(n1: f64, w1: f64, n2: f64, w2: f64) -> SamplingStrategy {
    SamplingStrategy::TwoLobe {
        exponent1: n1,
        weight1: w1,
        exponent2: n2,
        weight2: w2,
    }
}

/// [`density_integral`] of the two-lobe mixture.
fn two_lobe_integral(v: DVec3, exponents: [f64; 2], weights: [f64; 2]) -> f64 {
    density_integral(v, |l| two_lobe_density(v, l, exponents, weights))
}

#[test]
fn two_lobe_density_integrates_to_one_over_the_sphere() {
    let views = [dir(0.0, 0.0), dir(60.0, 0.4), dir(85.0, 2.0)];
    let cases = [
        ([1e4, 30.0], [0.3, 0.5]),
        ([1e5, 1e3], [0.6, 0.4]),
        ([100.0, 1.0], [0.1, 0.2]),
        ([1e6, 0.0], [0.5, 0.25]),
    ];
    for (exponents, weights) in cases {
        for v in views {
            let total = two_lobe_integral(v, exponents, weights);
            assert!(
                (total - 1.0).abs() < 1e-4,
                "{exponents:?} {weights:?} v {v}: {total}"
            );
        }
    }
}

#[test]
fn two_lobe_validation_and_one_lobe_equivalence() {
    assert!(two_lobe(1e4, 0.3, 50.0, 0.5).validated().is_ok());
    assert!(two_lobe(1e6, 0.7f32 as f64, 0.0, 0.3f32 as f64)
        .validated()
        .is_ok());
    for bad in [
        two_lobe(-1.0, 0.3, 10.0, 0.3),
        two_lobe(10.0, 0.3, 2e6, 0.3),
        two_lobe(f64::NAN, 0.3, 10.0, 0.3),
        two_lobe(10.0, 0.6, 1.0, 0.5),
        two_lobe(10.0, -0.1, 1.0, 0.5),
        two_lobe(10.0, 0.1, 1.0, f64::NAN),
    ] {
        assert!(
            matches!(bad.clone().validated(), Err(NbrdfError::InvalidArgument(_))),
            "{bad:?}"
        );
        let s = bad.sample(Vec3::Z, [0.5; 3]);
        assert_eq!(s.pdf, 0.0);
        assert!(s.light.is_finite());
    }
    // A second lobe of weight 0 is the one-lobe mixture, sample for sample.
    let one = SamplingStrategy::Phong {
        exponent: 300.0,
        specular_weight: 0.6,
    };
    let two = two_lobe(300.0, 0.6, 7.0, 0.0);
    let mut rng = SplitMix64::from_state(3);
    for _ in 0..2000 {
        let v = uniform_hemisphere(rng.next_f64(), rng.next_f64()).as_vec3();
        let u = [rng.next_f32(), rng.next_f32(), rng.next_f32()];
        let (a, b) = (one.sample(v, u), two.sample(v, u));
        assert_eq!(a.light, b.light);
        assert!((a.pdf - b.pdf).abs() <= 1e-6 * a.pdf, "{a:?} {b:?}");
    }
}

#[test]
fn two_lobe_sampled_pdf_equals_pdf_and_histogram_matches() {
    let mut rng = SplitMix64::from_state(11);
    let strategies = [
        two_lobe(1e4, 0.4, 30.0, 0.4),
        two_lobe(1e6, 0.5, 1e3, 0.5),
        two_lobe(50.0, 0.2, 5.0, 0.1),
    ];
    for strategy in strategies {
        for _ in 0..2000 {
            let v = uniform_hemisphere(rng.next_f64(), rng.next_f64()).as_vec3();
            let s = strategy.sample(v, [rng.next_f32(), rng.next_f32(), rng.next_f32()]);
            assert_eq!(s.pdf, strategy.pdf(v, s.light), "{strategy:?}");
            assert!(s.light.is_finite() && s.pdf.is_finite() && s.pdf >= 0.0);
        }
    }
    let samples = 200_000;
    for (strategy, v) in [
        (two_lobe(1e4, 0.3, 40.0, 0.5), dir(45.0, 1.0)),
        (two_lobe(2e3, 0.5, 20.0, 0.2), dir(80.0, -2.0)),
    ] {
        let r = mirror(v);
        let tests: [&(dyn Fn(DVec3) -> f64 + Sync); 3] = [
            &|l: DVec3| l.z + 0.5 * l.x * l.x,
            &|l: DVec3| f64::from(u8::from(l.dot(r) > 0.995)),
            &|l: DVec3| f64::from(u8::from(l.dot(r) > 0.9999)),
        ];
        assert_sample_means_match_pdf(&strategy, v, r, &tests, samples, 29);
    }
}
