//! Choosing the Blinn-Phong sampling lobe `(n, w)` of a material for the lowest variance of
//! BSDF sampling (docs/design.md section 6), rather than the model fit's shape-matching lobe
//! ([`crate::phong_fit`]), which on a weak sharp spike over a diffuse base sends almost no
//! samples where the energy is. With `g(l) = f_r(l, v) cos(theta_l)` (mean over RGB) and the
//! mixture density `p`, the estimator `g / p` has the relative second moment
//!
//! `R(v) = int g^2 / p  /  I^2`,  `I = int g`   (`R - 1` is its relative variance),
//!
//! computed by quadrature over the half vector (`theta_h = pi/2 s^2`, dense near the normal),
//! averaged over view elevations and minimised over a grid of `(n, w)`. [`LobeChoice`] names the
//! two candidates; [`choose_lobe`] and [`LobeAnalysis::lobe`] pick one.
//!
//! Two lobes ([`LobeQuadrature::fit_two_lobes`]): the same objective for
//! `w1 phong(n1) + w2 phong(n2) + (1 - w1 - w2) cosine`, a coarse grid then a pattern search
//! from the better of its best and the one-lobe lobe, so never worse than one lobe.

use crate::coords::to_rusinkiewicz;
use crate::error::{NbrdfError, Result};
use crate::pattern_search::{PatternSearch, SearchPoint};
use crate::phong_fit::{self, FitConfig, PhongFit, PhongParams};
use crate::sampling::{SamplingStrategy, MAX_EXPONENT};
use crate::train::dataset::TargetFn;
use glam::DVec3;
use rayon::prelude::*;
use std::f64::consts::{FRAC_1_PI, FRAC_PI_2, PI};

/// Settings of the lobe search.
#[derive(Clone, Debug, PartialEq)]
pub struct LobeFitConfig {
    /// View elevations (radians) over which `R` is averaged.
    pub view_thetas: Vec<f64>,
    /// Quadrature bins in `s = sqrt(theta_h / (pi/2))` and in `phi_h` over `[0, pi]`.
    pub s_bins: usize,
    pub phi_bins: usize,
    /// Candidate exponents and specular weights.
    pub exponents: Vec<f64>,
    pub weights: Vec<f64>,
}

impl Default for LobeFitConfig {
    fn default() -> Self {
        let exponents = std::iter::once(0.0)
            .chain((0..=40).map(|k| 10f64.powf(k as f64 / 8.0)))
            .collect();
        let weights = (0..=20)
            .map(|k| k as f64 / 20.0)
            .chain([0.98, 0.99])
            .collect();
        LobeFitConfig {
            view_thetas: (0..9)
                .map(|k| (5.0 + 10.0 * k as f64).to_radians())
                .collect(),
            s_bins: 160,
            phi_bins: 64,
            exponents,
            weights,
        }
    }
}

/// The chosen lobe and how well it samples, as relative variances averaged over the views.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LobeFit {
    pub exponent: f64,
    pub specular_weight: f64,
    /// Mean `R - 1` with the chosen lobe.
    pub relative_variance: f64,
    /// Mean `R - 1` of cosine sampling (`w = 0`), for comparison.
    pub cosine_relative_variance: f64,
}

/// What a lobe mixture's second moment needs at each quadrature point of one view where
/// `g = f_r cos` is positive; the isotropic and the anisotropic lobe searches share it.
#[derive(Default)]
pub(crate) struct LobeTerms {
    /// `g^2 dω_l` of each point.
    pub g2_dw: Vec<f64>,
    pub ln_cos_h: Vec<f64>,
    /// `1 / (4 v.h)`: the Jacobian from half-vector to light density.
    pub inv_jacobian: Vec<f64>,
    /// Cosine density `l.z / pi`.
    pub cosine_pdf: Vec<f64>,
    /// `(int g)^2`.
    pub integral_sq: f64,
}

impl LobeTerms {
    /// The terms of the half-vector quadrature of `view` (`visit_half_vectors`'s `phi_range`
    /// and `weight`); `extra` sees each point too, for what only one search keeps.
    pub(crate) fn collect(
        target: &TargetFn<'_>,
        view: DVec3,
        bins: (usize, usize),
        phi_range: f64,
        weight: f64,
        mut extra: impl FnMut(&HalfVectorPoint),
    ) -> Self {
        let mut terms = LobeTerms::default();
        let mut integral = 0.0;
        visit_half_vectors(target, view, bins, phi_range, weight, |p| {
            integral += p.g * p.dw_l;
            terms.g2_dw.push(p.g * p.g * p.dw_l);
            terms.ln_cos_h.push(p.cos_h.max(1e-300).ln());
            terms.inv_jacobian.push(0.25 / p.v_dot_h);
            terms.cosine_pdf.push(p.light.z * FRAC_1_PI);
            extra(p);
        });
        terms.integral_sq = integral * integral;
        terms
    }

    /// Relative second moment `R = sum(g^2 dω / pdf) / (int g)^2` of the density `pdf(i)` at
    /// point `i`; 1 where `g` vanishes, infinite where the density misses a point. The lobe
    /// searches (one lobe, several, anisotropic, any strategy) differ only in `pdf`.
    pub(crate) fn relative_second_moment(&self, pdf: impl Fn(usize) -> f64) -> f64 {
        if self.integral_sq <= 0.0 {
            return 1.0;
        }
        let mut sum = 0.0;
        for (i, &g2) in self.g2_dw.iter().enumerate() {
            let p = pdf(i);
            if p <= 0.0 {
                return f64::INFINITY;
            }
            sum += g2 / p;
        }
        sum / self.integral_sq
    }

    /// The Blinn-Phong lobe of exponent `n` (normalised `norm`) at point `i`, as a light density.
    pub(crate) fn lobe_density(&self, i: usize, n: f64, norm: f64) -> f64 {
        norm * (n * self.ln_cos_h[i]).exp() * self.inv_jacobian[i]
    }
}

/// Quadrature points of one view with what the candidate densities need.
struct ViewQuadrature {
    terms: LobeTerms,
    /// The view and the light direction of each point, for densities other than lobes.
    view: DVec3,
    lights: Vec<DVec3>,
}

/// Relative second moment `R` of the lobe `(n, w)` for a view.
fn second_moment(q: &ViewQuadrature, exponent: f64, weight: f64) -> f64 {
    let norm = (exponent + 1.0) * 0.5 * FRAC_1_PI;
    let t = &q.terms;
    t.relative_second_moment(|i| {
        weight * t.lobe_density(i, exponent, norm) + (1.0 - weight) * t.cosine_pdf[i]
    })
}

/// A point of the half-vector quadrature of one view where `g = f_r cos(theta_l)` (mean over
/// RGB) is positive.
pub(crate) struct HalfVectorPoint {
    pub light: DVec3,
    pub g: f64,
    /// The light directions' solid angle of the point, `4 (v.h) dω_h`.
    pub dw_l: f64,
    pub cos_h: f64,
    pub cos_phi_h: f64,
    pub v_dot_h: f64,
}

/// Visits the points of the midpoint quadrature of `view` over the half vector:
/// `s = sqrt(theta_h / (pi/2))` in `s_bins` bins (dense near the normal like the MERL grid, so
/// lobes of `n ~ 1e5` are resolved) and `phi_h` in `phi_bins` bins over `[0, phi_span)`, each
/// point counting `multiplicity` times (2 where `phi_h` over `[0, pi]` stands for the whole
/// circle of an isotropic material seen from the xz plane). Points whose light is at or below
/// the horizon, or where `g` is not positive, are skipped. The one quadrature of
/// [`LobeQuadrature`] and [`crate::anisotropic_lobe_fit`].
pub(crate) fn visit_half_vectors(
    target: &TargetFn<'_>,
    view: DVec3,
    (s_bins, phi_bins): (usize, usize),
    phi_span: f64,
    multiplicity: f64,
    mut visit: impl FnMut(&HalfVectorPoint),
) {
    let ds = 1.0 / s_bins as f64;
    let dphi = phi_span / phi_bins as f64;
    for i in 0..s_bins {
        let s = (i as f64 + 0.5) * ds;
        let theta_h = FRAC_PI_2 * s * s;
        let (sin_h, cos_h) = theta_h.sin_cos();
        // dω_h = sin(theta_h) dtheta_h dphi_h, dtheta_h = pi s ds.
        let dw_h = multiplicity * sin_h * PI * s * ds * dphi;
        for j in 0..phi_bins {
            let phi_h = (j as f64 + 0.5) * dphi;
            let (sin_p, cos_p) = phi_h.sin_cos();
            let half = DVec3::new(sin_h * cos_p, sin_h * sin_p, cos_h);
            let v_dot_h = view.dot(half);
            if v_dot_h <= 0.0 {
                continue;
            }
            let light = 2.0 * v_dot_h * half - view;
            if light.z <= 0.0 {
                continue;
            }
            let f = target(&to_rusinkiewicz(view, light)).unwrap_or([0.0; 3]);
            let f_mean = f.iter().map(|x| x.max(0.0)).sum::<f64>() / 3.0;
            let g = f_mean * light.z;
            if !(g.is_finite() && g > 0.0) {
                continue;
            }
            visit(&HalfVectorPoint {
                light,
                g,
                dw_l: 4.0 * v_dot_h * dw_h,
                cos_h,
                cos_phi_h: cos_p,
                v_dot_h,
            });
        }
    }
}

fn quadrature(target: &TargetFn<'_>, view_theta: f64, config: &LobeFitConfig) -> ViewQuadrature {
    let view = DVec3::new(view_theta.sin(), 0.0, view_theta.cos());
    let mut lights = Vec::new();
    // phi_h over [0, pi] counts twice: the view lies in the xz plane and the material is
    // isotropic.
    let bins = (config.s_bins, config.phi_bins);
    let terms = LobeTerms::collect(target, view, bins, PI, 2.0, |p| lights.push(p.light));
    ViewQuadrature {
        terms,
        view,
        lights,
    }
}

/// The quadrature of a material over all views, built once (it evaluates the material) and
/// then scored for any number of lobes.
pub struct LobeQuadrature {
    views: Vec<ViewQuadrature>,
}

impl LobeQuadrature {
    /// Evaluates `target` (a table or a network, `f_r` by Rusinkiewicz angles) on the
    /// quadrature points of every view of `config`.
    pub fn new(target: &TargetFn<'_>, config: &LobeFitConfig) -> Result<Self> {
        if config.view_thetas.is_empty() || config.s_bins == 0 || config.phi_bins == 0 {
            return Err(NbrdfError::InvalidArgument(
                "lobe fit: needs views and quadrature bins".into(),
            ));
        }
        let views = config
            .view_thetas
            .par_iter()
            .map(|&theta| quadrature(target, theta, config))
            .collect();
        Ok(LobeQuadrature { views })
    }

    /// Mean relative variance `R - 1` over the views of sampling with the lobe `(n, w)`.
    pub fn relative_variance(&self, exponent: f64, specular_weight: f64) -> f64 {
        self.mean_second_moment(exponent, specular_weight) - 1.0
    }

    /// Mean relative variance `R - 1` over the views of sampling with any strategy (its
    /// [`SamplingStrategy::pdf_f64`]): how `nbrdf fit-phong` scores the tabulated sampler
    /// against the lobes on the same quadrature.
    ///
    /// The views run in parallel but their moments are added in view order: a parallel sum
    /// would group the additions by how the work was split, which changes the last digits with
    /// the thread count.
    pub fn strategy_relative_variance(&self, strategy: &SamplingStrategy) -> f64 {
        let moments: Vec<f64> = self
            .views
            .par_iter()
            .map(|q| {
                q.terms
                    .relative_second_moment(|i| strategy.pdf_f64(q.view, q.lights[i]))
            })
            .collect();
        moments.iter().sum::<f64>() / self.views.len() as f64 - 1.0
    }

    fn mean_second_moment(&self, exponent: f64, weight: f64) -> f64 {
        self.views
            .iter()
            .map(|q| second_moment(q, exponent, weight))
            .sum::<f64>()
            / self.views.len() as f64
    }

    /// The candidate of `config` with the lowest mean relative variance.
    pub fn fit(&self, config: &LobeFitConfig) -> Result<LobeFit> {
        if config
            .exponents
            .iter()
            .any(|n| !(n.is_finite() && *n >= 0.0))
            || config.weights.iter().any(|w| !(0.0..=1.0).contains(w))
            || config.exponents.is_empty()
            || config.weights.is_empty()
        {
            return Err(NbrdfError::InvalidArgument(
                "lobe fit: candidate exponents must be finite and >= 0, weights in [0, 1]".into(),
            ));
        }
        let cosine = self.relative_variance(0.0, 0.0);
        let candidates: Vec<(f64, f64)> = config
            .exponents
            .iter()
            .flat_map(|&n| config.weights.iter().map(move |&w| (n, w)))
            .collect();
        let scored: Vec<(f64, f64, f64)> = candidates
            .par_iter()
            .map(|&(n, w)| (self.relative_variance(n, w), n, w))
            .collect();
        // Ties (e.g. a black material, R = 1 everywhere) go to the earliest candidate, the
        // gentlest; if no candidate is finite, cosine sampling is the fallback.
        let (relative_variance, exponent, specular_weight) =
            scored.into_iter().filter(|(r, _, _)| r.is_finite()).fold(
                (f64::INFINITY, 0.0, 0.0),
                |acc, c| if c.0 < acc.0 { c } else { acc },
            );
        Ok(LobeFit {
            exponent,
            specular_weight,
            relative_variance: if relative_variance.is_finite() {
                relative_variance
            } else {
                cosine
            },
            cosine_relative_variance: cosine,
        })
    }
}

/// The two-lobe sampling mixture `w1 phong(n1) + w2 phong(n2) + (1 - w1 - w2) cosine` chosen
/// for the lowest mean relative variance on the same quadrature as the one-lobe search.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TwoLobeFit {
    /// `[n1, n2]` with `n1 >= n2` (the sharp lobe first).
    pub exponents: [f64; 2],
    pub weights: [f64; 2],
    /// Mean `R - 1` with the two lobes; never above `one_lobe.relative_variance`.
    pub relative_variance: f64,
    /// The one-lobe search the two-lobe one starts from (its candidate with `w2 = 0`).
    pub one_lobe: LobeFit,
}

impl TwoLobeFit {
    /// The sampling strategy of this fit.
    pub fn strategy(&self) -> SamplingStrategy {
        SamplingStrategy::TwoLobe {
            exponent1: self.exponents[0],
            weight1: self.weights[0],
            exponent2: self.exponents[1],
            weight2: self.weights[1],
        }
    }
}

/// Exponents of the coarse two-lobe grid: 0 and `10^(k/4)` up to 1e5 (every other exponent of
/// the one-lobe grid).
fn two_lobe_grid_exponents() -> Vec<f64> {
    std::iter::once(0.0)
        .chain((0..=20).map(|k| 10f64.powf(k as f64 / 4.0)))
        .collect()
}

/// Weights of the coarse two-lobe grid (pairs with `w1 + w2 <= 1` are used).
const TWO_LOBE_GRID_WEIGHTS: [f64; 12] =
    [0.05, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 0.95, 1.0];

/// Halvings of the pattern search's steps after the grid.
const TWO_LOBE_REFINE_LEVELS: usize = 7;

/// Relative second moment `R` of a mixture of Blinn-Phong lobes `(n, w)` and cosine (weight
/// `1 - sum w`, at least 0) for a view: [`second_moment`] with more lobes. Lobes of weight 0
/// are skipped, so a second lobe of weight 0 scores exactly as the one-lobe mixture.
fn mixture_second_moment(q: &ViewQuadrature, lobes: &[(f64, f64)]) -> f64 {
    let cosine_weight = (1.0 - lobes.iter().map(|l| l.1).sum::<f64>()).max(0.0);
    let t = &q.terms;
    t.relative_second_moment(|i| {
        let mut pdf = cosine_weight * t.cosine_pdf[i];
        for &(n, w) in lobes {
            if w > 0.0 {
                pdf += w * t.lobe_density(i, n, (n + 1.0) * 0.5 * FRAC_1_PI);
            }
        }
        pdf
    })
}

/// The light densities of one Blinn-Phong lobe at every quadrature point of a view.
fn lobe_densities(q: &ViewQuadrature, n: f64) -> Vec<f64> {
    let norm = (n + 1.0) * 0.5 * FRAC_1_PI;
    (0..q.terms.g2_dw.len())
        .map(|i| q.terms.lobe_density(i, n, norm))
        .collect()
}

/// A candidate of the two-lobe search: `(R - 1, [n1, n2], [w1, w2])`.
type TwoLobeCandidate = (f64, [f64; 2], [f64; 2]);

fn better(a: TwoLobeCandidate, b: TwoLobeCandidate) -> TwoLobeCandidate {
    if b.0 < a.0 {
        b
    } else {
        a
    }
}

impl LobeQuadrature {
    /// Mean relative variance `R - 1` over the views of the two-lobe mixture.
    pub fn two_lobe_relative_variance(&self, exponents: [f64; 2], weights: [f64; 2]) -> f64 {
        let lobes = [(exponents[0], weights[0]), (exponents[1], weights[1])];
        self.views
            .iter()
            .map(|q| mixture_second_moment(q, &lobes))
            .sum::<f64>()
            / self.views.len() as f64
            - 1.0
    }

    /// The best weights of the coarse grid for each exponent pair: the lobe densities are
    /// computed once per pair, the weights only rescale them.
    fn two_lobe_grid(&self) -> Option<TwoLobeCandidate> {
        let exponents = two_lobe_grid_exponents();
        let pairs: Vec<[f64; 2]> = exponents
            .iter()
            .enumerate()
            .flat_map(|(i, &n1)| exponents[..i].iter().map(move |&n2| [n1, n2]))
            .collect();
        let weight_pairs: Vec<[f64; 2]> = TWO_LOBE_GRID_WEIGHTS
            .iter()
            .flat_map(|&w1| TWO_LOBE_GRID_WEIGHTS.iter().map(move |&w2| [w1, w2]))
            .filter(|w| w[0] + w[1] <= 1.0 + 1e-12)
            .collect();
        pairs
            .par_iter()
            .map(|&pair| {
                let mut sums = vec![0.0; weight_pairs.len()];
                for q in &self.views {
                    let t = &q.terms;
                    if t.integral_sq <= 0.0 {
                        // R = 1 whatever the weights: skip the densities.
                        sums.iter_mut().for_each(|s| *s += 1.0);
                        continue;
                    }
                    let (d1, d2) = (lobe_densities(q, pair[0]), lobe_densities(q, pair[1]));
                    for (sum, w) in sums.iter_mut().zip(&weight_pairs) {
                        let cosine_weight = (1.0 - w[0] - w[1]).max(0.0);
                        *sum += t.relative_second_moment(|i| {
                            w[0] * d1[i] + w[1] * d2[i] + cosine_weight * t.cosine_pdf[i]
                        });
                    }
                }
                let views = self.views.len() as f64;
                sums.iter()
                    .zip(&weight_pairs)
                    .map(|(s, &w)| (s / views - 1.0, pair, w))
                    .filter(|c| c.0.is_finite())
                    .reduce(better)
            })
            .flatten()
            .reduce_with(better)
    }

    /// The two-lobe mixture of lowest mean relative variance: the one-lobe search of `config`
    /// (its lobe with `w2 = 0` is a candidate, so the result is never worse), a coarse grid over
    /// both exponents and weights, then a pattern search in `(log10(1 + n1), log10(1 + n2), w1,
    /// w2)` with halving steps from the better of the two.
    pub fn fit_two_lobes(&self, config: &LobeFitConfig) -> Result<TwoLobeFit> {
        let one_lobe = self.fit(config)?;
        let mut best: TwoLobeCandidate = (
            self.two_lobe_relative_variance(
                [one_lobe.exponent, 0.0],
                [one_lobe.specular_weight, 0.0],
            ),
            [one_lobe.exponent, 0.0],
            [one_lobe.specular_weight, 0.0],
        );
        if let Some(grid) = self.two_lobe_grid() {
            best = better(best, grid);
        }
        if best.0.is_finite() {
            best = self.refine_two_lobes(best);
        }
        let (mut relative_variance, mut exponents, mut weights) = best;
        if relative_variance.is_nan() || relative_variance > one_lobe.relative_variance {
            (relative_variance, exponents, weights) = (
                one_lobe.relative_variance,
                [one_lobe.exponent, 0.0],
                [one_lobe.specular_weight, 0.0],
            );
        }
        if exponents[1] > exponents[0] {
            exponents.swap(0, 1);
            weights.swap(0, 1);
        }
        Ok(TwoLobeFit {
            exponents,
            weights,
            relative_variance,
            one_lobe,
        })
    }

    /// Coordinate pattern search from `start` in `(log10(1 + n1), log10(1 + n2), w1, w2)`;
    /// moves stay in the valid domain.
    fn refine_two_lobes(&self, start: TwoLobeCandidate) -> TwoLobeCandidate {
        let to_t = |n: f64| (1.0 + n).log10();
        let to_n = |t: f64| (10f64.powf(t) - 1.0).clamp(0.0, MAX_EXPONENT);
        let t_max = to_t(MAX_EXPONENT);
        let search = PatternSearch {
            moves: PatternSearch::<4>::axis_moves(),
            steps: [0.125, 0.125, 0.025, 0.025],
            levels: TWO_LOBE_REFINE_LEVELS,
            // At most a few passes per level: each accepted move restarts the pass.
            max_passes: 8,
        };
        let start = SearchPoint {
            score: start.0,
            params: (start.1, start.2),
            x: [to_t(start.1[0]), to_t(start.1[1]), start.2[0], start.2[1]],
        };
        let in_domain = |y: &[f64; 4]| {
            (0.0..=t_max).contains(&y[0])
                && (0.0..=t_max).contains(&y[1])
                && y[2] >= 0.0
                && y[3] >= 0.0
                && y[2] + y[3] <= 1.0
        };
        let end = search.minimise(
            start,
            |y| in_domain(&y).then(|| (([to_n(y[0]), to_n(y[1])], [y[2], y[3]]), y)),
            |&(n, w)| self.two_lobe_relative_variance(n, w),
        );
        (end.score, end.params.0, end.params.1)
    }
}

/// Chooses the two-lobe mixture for `target` (a table or a network, `f_r` by Rusinkiewicz
/// angles).
pub fn fit_two_lobes(target: &TargetFn<'_>, config: &LobeFitConfig) -> Result<TwoLobeFit> {
    LobeQuadrature::new(target, config)?.fit_two_lobes(config)
}

/// Chooses the lobe for `target` (a table or a network, `f_r` by Rusinkiewicz angles).
pub fn fit_lobe(target: &TargetFn<'_>, config: &LobeFitConfig) -> Result<LobeFit> {
    LobeQuadrature::new(target, config)?.fit(config)
}

/// Which Blinn-Phong lobe `(n, w)` a material is sampled with.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum LobeChoice {
    /// The candidate of lowest variance of BSDF sampling ([`LobeQuadrature::fit`]): what
    /// `nbrdf fit-phong` stores by default.
    #[default]
    LowestVariance,
    /// `n` and `w = mean(ks) / (mean(kd) + mean(ks))` of the 7-parameter model fit
    /// ([`crate::phong_fit`], docs/design.md section 6): the shape of the BRDF in log space, which can
    /// be a poor sampler for weak sharp spikes but needs no quadrature.
    Model,
}

impl LobeChoice {
    /// The name `nbrdf fit-phong --lobe` takes and its JSON reports.
    pub fn as_str(self) -> &'static str {
        match self {
            LobeChoice::LowestVariance => "variance",
            LobeChoice::Model => "model",
        }
    }
}

/// The lobe `(n, w)` of the model fit: its exponent and `mean(ks) / (mean(kd) + mean(ks))`.
pub fn model_lobe(params: &PhongParams) -> (f64, f64) {
    (params.exponent, params.specular_weight())
}

impl LobeFit {
    /// The chosen lobe `(n, w)`.
    pub fn lobe(&self) -> (f64, f64) {
        (self.exponent, self.specular_weight)
    }
}

/// Both candidate lobes of a material, and how well each samples it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LobeAnalysis {
    /// The 7-parameter model fit.
    pub model: PhongFit,
    /// The lowest-variance search.
    pub lowest_variance: LobeFit,
    /// Mean `R - 1` of sampling with the model fit's lobe.
    pub model_relative_variance: f64,
}

impl LobeAnalysis {
    /// Fits the model and searches the lowest-variance lobe of `target`.
    pub fn new(
        target: &TargetFn<'_>,
        fit_config: &FitConfig,
        lobe_config: &LobeFitConfig,
    ) -> Result<Self> {
        let model = phong_fit::fit(target, fit_config)?;
        let quadrature = LobeQuadrature::new(target, lobe_config)?;
        let lowest_variance = quadrature.fit(lobe_config)?;
        let model_relative_variance =
            quadrature.relative_variance(model.params.exponent, model.params.specular_weight());
        Ok(LobeAnalysis {
            model,
            lowest_variance,
            model_relative_variance,
        })
    }

    /// [`LobeAnalysis::new`] plus the two-lobe search ([`LobeQuadrature::fit_two_lobes`]) on
    /// the same quadrature, which is built once.
    pub fn with_two_lobes(
        target: &TargetFn<'_>,
        fit_config: &FitConfig,
        lobe_config: &LobeFitConfig,
    ) -> Result<(Self, TwoLobeFit)> {
        let model = phong_fit::fit(target, fit_config)?;
        let quadrature = LobeQuadrature::new(target, lobe_config)?;
        let two_lobes = quadrature.fit_two_lobes(lobe_config)?;
        let model_relative_variance =
            quadrature.relative_variance(model.params.exponent, model.params.specular_weight());
        let analysis = LobeAnalysis {
            model,
            lowest_variance: two_lobes.one_lobe,
            model_relative_variance,
        };
        Ok((analysis, two_lobes))
    }

    /// The lobe `(n, w)` of `choice` (as [`choose_lobe`] would compute it).
    pub fn lobe(&self, choice: LobeChoice) -> (f64, f64) {
        match choice {
            LobeChoice::LowestVariance => self.lowest_variance.lobe(),
            LobeChoice::Model => model_lobe(&self.model.params),
        }
    }
}

/// The lobe `(n, w)` of `choice` for `target`, computing only that candidate: the
/// lowest-variance search with `lobe_config`, or the model fit with `fit_config`.
pub fn choose_lobe(
    target: &TargetFn<'_>,
    choice: LobeChoice,
    fit_config: &FitConfig,
    lobe_config: &LobeFitConfig,
) -> Result<(f64, f64)> {
    match choice {
        LobeChoice::LowestVariance => Ok(fit_lobe(target, lobe_config)?.lobe()),
        LobeChoice::Model => Ok(model_lobe(&phong_fit::fit(target, fit_config)?.params)),
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::coords::from_rusinkiewicz;
    use crate::coords::RusinkiewiczAngles;
    use glam::Vec3;

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
        // The case where the model fit gives n ~ 7e4, w ~ 0.005 (gray-plastic-like): most of the
        // reflected energy towards a small light is in the spike, so the lobe must carry weight.
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
}
