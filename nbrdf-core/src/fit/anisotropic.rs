//! Choosing the anisotropic Blinn-Phong sampling lobe `(n_u, n_v, w)` of an anisotropic
//! material ([`SamplingStrategy::AnisotropicPhong`]) for the lowest variance of BSDF
//! sampling: the objective of [`crate::fit::lobes`] (mean relative second moment `R` of `g / p`,
//! `g = f_r cos(theta_l)`), on a quadrature that no longer assumes isotropy: views at several
//! azimuths as well as elevations, half vectors over the whole circle of `phi_h`.
//!
//! The search starts from the best isotropic lobe on this quadrature (the grid of
//! [`LobeFitConfig`], `n_u = n_v`), then scores every `(n_u, n_v)` pair of a log grid at that
//! weight, and refines `(ln(1 + n_u), ln(1 + n_v), w)` by a pattern search with halving steps.
//! The isotropic start is a candidate, so the result never samples worse than it on the
//! quadrature.

use crate::error::{NbrdfError, Result};
use crate::fit::lobes::{LobeFitConfig, LobeTerms};
use crate::fit::pattern_search::{PatternSearch, SearchPoint};
use crate::sampling::{SamplingStrategy, MAX_EXPONENT};
use crate::train::dataset::TargetFn;
use glam::DVec3;
use rayon::prelude::*;
use std::f64::consts::{FRAC_1_PI, PI, TAU};

/// Settings of the anisotropic search.
#[derive(Clone, Debug, PartialEq)]
pub struct AnisotropicLobeFitConfig {
    /// Elevations, bins and the isotropic start's candidates (its `phi_bins` now span
    /// `[0, 2 pi)`).
    pub base: LobeFitConfig,
    /// View azimuths (radians) measured from the tangent.
    pub view_phis: Vec<f64>,
    /// Candidate exponents of the `(n_u, n_v)` grid.
    pub grid_exponents: Vec<f64>,
    /// Halvings of the pattern search's steps.
    pub refine_levels: usize,
}

impl Default for AnisotropicLobeFitConfig {
    fn default() -> Self {
        let base = LobeFitConfig {
            s_bins: 120,
            phi_bins: 96,
            ..LobeFitConfig::default()
        };
        AnisotropicLobeFitConfig {
            base,
            view_phis: (0..4).map(|k| k as f64 * PI / 4.0).collect(),
            grid_exponents: std::iter::once(0.0)
                .chain((0..=20).map(|k| 10f64.powf(k as f64 / 4.0)))
                .collect(),
            refine_levels: 6,
        }
    }
}

/// The chosen lobe and how well it samples (mean `R - 1` over the views).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AnisotropicLobeFit {
    /// Along the tangent x.
    pub exponent_u: f64,
    /// Across it (y).
    pub exponent_v: f64,
    pub specular_weight: f64,
    pub relative_variance: f64,
    /// The best isotropic lobe `(n, w)` on the same quadrature, and its `R - 1`.
    pub isotropic: (f64, f64),
    pub isotropic_relative_variance: f64,
    pub cosine_relative_variance: f64,
}

impl AnisotropicLobeFit {
    pub fn strategy(&self) -> SamplingStrategy {
        SamplingStrategy::anisotropic(self.exponent_u, self.exponent_v, self.specular_weight)
    }
}

/// Quadrature points of one view.
struct ViewQuadrature {
    terms: LobeTerms,
    /// `cos^2 phi_h`: the share of `n_u` in the exponent at the point.
    cos2_phi_h: Vec<f64>,
}

/// The quadrature of a material over all views (evaluated once, then scored per lobe).
pub struct AnisotropicLobeQuadrature {
    views: Vec<ViewQuadrature>,
}

fn view_quadrature(
    target: &TargetFn<'_>,
    theta_v: f64,
    phi_v: f64,
    config: &LobeFitConfig,
) -> ViewQuadrature {
    let view = DVec3::new(
        theta_v.sin() * phi_v.cos(),
        theta_v.sin() * phi_v.sin(),
        theta_v.cos(),
    );
    let mut cos2_phi_h = Vec::new();
    // That of crate::fit::lobes, without the isotropic fold of phi_h.
    let bins = (config.s_bins, config.phi_bins);
    let terms = LobeTerms::collect(target, view, bins, TAU, 1.0, |p| {
        cos2_phi_h.push(p.cos_phi_h * p.cos_phi_h);
    });
    ViewQuadrature { terms, cos2_phi_h }
}

/// `R` of the lobe for a view; the density is that of
/// [`crate::sampling::anisotropic_lobe_density`] on the quadrature's half vectors.
fn second_moment(q: &ViewQuadrature, nu: f64, nv: f64, w: f64) -> f64 {
    let norm = ((nu + 1.0) * (nv + 1.0)).sqrt() * 0.5 * FRAC_1_PI;
    let t = &q.terms;
    t.relative_second_moment(|i| {
        let exponent = nu * q.cos2_phi_h[i] + nv * (1.0 - q.cos2_phi_h[i]);
        w * t.lobe_density(i, exponent, norm) + (1.0 - w) * t.cosine_pdf[i]
    })
}

/// A candidate: `(R - 1, n_u, n_v, w)`.
type Candidate = (f64, f64, f64, f64);

fn best(candidates: impl Iterator<Item = Candidate>, start: Candidate) -> Candidate {
    candidates
        .filter(|c| c.0.is_finite())
        .fold(start, |acc, c| if c.0 < acc.0 { c } else { acc })
}

impl AnisotropicLobeQuadrature {
    pub fn new(target: &TargetFn<'_>, config: &AnisotropicLobeFitConfig) -> Result<Self> {
        let base = &config.base;
        if base.view_thetas.is_empty()
            || config.view_phis.is_empty()
            || base.s_bins == 0
            || base.phi_bins == 0
        {
            return Err(NbrdfError::InvalidArgument(
                "anisotropic lobe fit: needs views and quadrature bins".into(),
            ));
        }
        let views: Vec<(f64, f64)> = base
            .view_thetas
            .iter()
            .flat_map(|&t| config.view_phis.iter().map(move |&p| (t, p)))
            .collect();
        let views = views
            .par_iter()
            .map(|&(t, p)| view_quadrature(target, t, p, base))
            .collect();
        Ok(AnisotropicLobeQuadrature { views })
    }

    /// Mean relative variance `R - 1` over the views of the lobe `(n_u, n_v, w)`.
    pub fn relative_variance(&self, exponent_u: f64, exponent_v: f64, weight: f64) -> f64 {
        self.views
            .iter()
            .map(|q| second_moment(q, exponent_u, exponent_v, weight))
            .sum::<f64>()
            / self.views.len() as f64
            - 1.0
    }

    fn score(&self, nu: f64, nv: f64, w: f64) -> Candidate {
        (self.relative_variance(nu, nv, w), nu, nv, w)
    }

    /// The lowest-variance lobe: isotropic grid, `(n_u, n_v)` grid, pattern search.
    pub fn fit(&self, config: &AnisotropicLobeFitConfig) -> Result<AnisotropicLobeFit> {
        check_config(config)?;
        let cosine = self.relative_variance(0.0, 0.0, 0.0);
        let iso = self.isotropic_start(&config.base, cosine);
        let start = self.grid_start(&config.grid_exponents, iso);
        let end = self.refine(start, config.refine_levels);
        Ok(AnisotropicLobeFit {
            exponent_u: end.1,
            exponent_v: end.2,
            specular_weight: end.3,
            relative_variance: end.0,
            isotropic: (iso.1, iso.3),
            isotropic_relative_variance: iso.0,
            cosine_relative_variance: cosine,
        })
    }

    /// The best isotropic lobe of the `(n, w)` grid of `base`; the cosine (variance `cosine`)
    /// when no lobe scores finitely.
    fn isotropic_start(&self, base: &LobeFitConfig, cosine: f64) -> Candidate {
        let no_lobe = (f64::INFINITY, 0.0, 0.0, 0.0);
        let isotropic: Vec<Candidate> = base
            .exponents
            .iter()
            .flat_map(|&n| base.weights.iter().map(move |&w| (n, w)))
            .collect::<Vec<_>>()
            .par_iter()
            .map(|&(n, w)| self.score(n, n, w))
            .collect();
        let iso = best(isotropic.into_iter(), no_lobe);
        if iso.0.is_finite() {
            iso
        } else {
            (cosine, 0.0, 0.0, 0.0)
        }
    }

    /// The best of `iso` and every `(n_u, n_v)` pair of `exponents` at `iso`'s weight.
    fn grid_start(&self, exponents: &[f64], iso: Candidate) -> Candidate {
        let pairs: Vec<(f64, f64)> = exponents
            .iter()
            .flat_map(|&nu| exponents.iter().map(move |&nv| (nu, nv)))
            .collect();
        let grid: Vec<Candidate> = pairs
            .par_iter()
            .map(|&(nu, nv)| self.score(nu, nv, iso.3))
            .collect();
        best(grid.into_iter(), iso)
    }

    /// Pattern search from `start` in `(ln(1 + n_u), ln(1 + n_v), w)`, `levels` halvings of
    /// steps that start at a grid spacing.
    fn refine(&self, start: Candidate, levels: usize) -> Candidate {
        let step_log = 0.5 * 10f64.ln() / 4.0;
        let search = PatternSearch {
            moves: vec![
                [1.0, 0.0, 0.0],
                [-1.0, 0.0, 0.0],
                [0.0, 1.0, 0.0],
                [0.0, -1.0, 0.0],
                [1.0, 1.0, 0.0],
                [-1.0, -1.0, 0.0],
                [0.0, 0.0, 1.0],
                [0.0, 0.0, -1.0],
            ],
            steps: [step_log, step_log, 0.05],
            levels,
            max_passes: usize::MAX,
        };
        let coordinates = |(nu, nv, w): (f64, f64, f64)| [nu.ln_1p(), nv.ln_1p(), w];
        let max_log = MAX_EXPONENT.ln_1p();
        let end = search.minimise(
            SearchPoint {
                score: start.0,
                params: (start.1, start.2, start.3),
                x: coordinates((start.1, start.2, start.3)),
            },
            // Moves are clamped into the domain.
            |y| {
                let lobe = (
                    y[0].clamp(0.0, max_log).exp_m1().min(MAX_EXPONENT),
                    y[1].clamp(0.0, max_log).exp_m1().min(MAX_EXPONENT),
                    y[2].clamp(0.0, 1.0),
                );
                Some((lobe, coordinates(lobe)))
            },
            |&(nu, nv, w)| self.relative_variance(nu, nv, w),
        );
        (end.score, end.params.0, end.params.1, end.params.2)
    }
}

/// Rejects exponents outside `[0, MAX_EXPONENT]`, weights outside `[0, 1]` and an empty
/// isotropic grid.
fn check_config(config: &AnisotropicLobeFitConfig) -> Result<()> {
    let base = &config.base;
    let exponents_ok = |e: &[f64]| e.iter().all(|n| (0.0..=MAX_EXPONENT).contains(n));
    if !exponents_ok(&base.exponents)
        || !exponents_ok(&config.grid_exponents)
        || base.weights.iter().any(|w| !(0.0..=1.0).contains(w))
        || base.exponents.is_empty()
        || base.weights.is_empty()
    {
        return Err(NbrdfError::InvalidArgument(
            "anisotropic lobe fit: exponents must be in [0, MAX_EXPONENT], weights in [0, 1]"
                .into(),
        ));
    }
    Ok(())
}

/// Builds the quadrature of `target` and fits its lobe.
pub fn fit_anisotropic_lobe(
    target: &TargetFn<'_>,
    config: &AnisotropicLobeFitConfig,
) -> Result<AnisotropicLobeFit> {
    AnisotropicLobeQuadrature::new(target, config)?.fit(config)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::coords::{to_rusinkiewicz, RusinkiewiczAngles};
    use crate::rng::SplitMix64;
    use crate::sampling::anisotropic_lobe_density;

    /// A diffuse base plus a normalised Ashikhmin-Shirley-like lobe, narrow along x.
    fn oracle(nu: f64, nv: f64) -> impl Fn(&RusinkiewiczAngles) -> Option<[f64; 3]> + Sync {
        move |a: &RusinkiewiczAngles| {
            let (cos_p, sin_p) = (a.phi_h.cos(), a.phi_h.sin());
            let n = nu * cos_p * cos_p + nv * sin_p * sin_p;
            let lobe = ((nu + 1.0) * (nv + 1.0)).sqrt() / (8.0 * PI) * a.theta_h.cos().powf(n);
            Some([0.05 / PI + 0.6 * lobe; 3])
        }
    }

    fn small_config() -> AnisotropicLobeFitConfig {
        let mut config = AnisotropicLobeFitConfig::default();
        config.base.s_bins = 80;
        config.base.phi_bins = 64;
        config.base.view_thetas = vec![0.3, 0.8, 1.2];
        config.refine_levels = 3;
        config
    }

    #[test]
    fn the_narrow_axis_gets_the_larger_exponent_and_beats_isotropic() {
        for (nu, nv) in [(400.0, 20.0), (20.0, 400.0)] {
            let fit = fit_anisotropic_lobe(&oracle(nu, nv), &small_config()).unwrap();
            let ratio = fit.exponent_u / fit.exponent_v;
            let want = nu / nv;
            assert!(
                ratio / want > 0.3 && ratio / want < 3.0,
                "{nu} {nv}: {fit:?}"
            );
            assert!(
                fit.relative_variance < 0.8 * fit.isotropic_relative_variance,
                "{fit:?}"
            );
            assert!(fit.strategy().validated().is_ok());
        }
    }

    #[test]
    fn an_isotropic_material_gets_a_nearly_isotropic_lobe() {
        let fit = fit_anisotropic_lobe(&oracle(100.0, 100.0), &small_config()).unwrap();
        let ratio = fit.exponent_u / fit.exponent_v;
        assert!(ratio > 0.7 && ratio < 1.4, "{fit:?}");
        assert!(fit.relative_variance <= fit.isotropic_relative_variance);
        // Lambertian: cosine sampling, zero variance (up to the quadrature's error).
        let lambert = |_: &RusinkiewiczAngles| Some([0.3; 3]);
        let fit = fit_anisotropic_lobe(&lambert, &small_config()).unwrap();
        assert!(fit.specular_weight == 0.0, "{fit:?}");
        assert!(fit.relative_variance.abs() < 1e-3, "{fit:?}");
    }

    /// The quadrature's `R` against a Monte Carlo estimate with the sampler itself: sample
    /// `l ~ p` with the library's strategy, average `(g / p)^2 / I^2`.
    #[test]
    fn quadrature_second_moment_matches_monte_carlo() {
        let (nu, nv, w) = (300.0, 30.0, 0.7);
        let target = oracle(300.0, 30.0);
        let mut config = small_config();
        config.base.s_bins = 200;
        config.base.phi_bins = 160;
        config.base.view_thetas = vec![0.6];
        config.view_phis = vec![0.7];
        let quad = AnisotropicLobeQuadrature::new(&target, &config).unwrap();
        let r_quad = quad.relative_variance(nu, nv, w) + 1.0;
        let view = DVec3::new(
            0.6f64.sin() * 0.7f64.cos(),
            0.6f64.sin() * 0.7f64.sin(),
            0.6f64.cos(),
        );
        let strategy = SamplingStrategy::anisotropic(nu, nv, w);
        let mut rng = SplitMix64::from_state(7);
        let (mut m1, mut m2, count) = (0.0, 0.0, 400_000);
        for _ in 0..count {
            let u = [rng.next_f32(), rng.next_f32(), rng.next_f32()];
            let s = strategy.sample(view.as_vec3(), u);
            if s.pdf <= 0.0 {
                continue;
            }
            let l = s.light.as_dvec3();
            let p = anisotropic_lobe_density(view, l, [nu, nv], w);
            let f = target(&to_rusinkiewicz(view, l)).unwrap()[0];
            let x = f * l.z / p;
            m1 += x;
            m2 += x * x;
        }
        let (m1, m2) = (m1 / count as f64, m2 / count as f64);
        let r_mc = m2 / (m1 * m1);
        assert!((r_mc / r_quad - 1.0).abs() < 0.03, "{r_mc} vs {r_quad}");
    }
}
