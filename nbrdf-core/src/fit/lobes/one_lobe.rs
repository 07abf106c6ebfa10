//! The one-lobe search: the quadrature of a material over its views ([`LobeQuadrature`]),
//! scored for the grid of `(n, w)` candidates of [`LobeFitConfig`].

use super::half_vector::LobeTerms;
use crate::error::{NbrdfError, Result};
use crate::sampling::SamplingStrategy;
use crate::train::dataset::TargetFn;
use glam::DVec3;
use rayon::prelude::*;
use std::f64::consts::{FRAC_1_PI, PI};

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

/// Quadrature points of one view with what the candidate densities need.
pub(super) struct ViewQuadrature {
    pub(super) terms: LobeTerms,
    /// The view and the light direction of each point, for densities other than lobes.
    pub(super) view: DVec3,
    pub(super) lights: Vec<DVec3>,
}

/// Relative second moment `R` of the lobe `(n, w)` for a view.
pub(super) fn second_moment(q: &ViewQuadrature, exponent: f64, weight: f64) -> f64 {
    let norm = (exponent + 1.0) * 0.5 * FRAC_1_PI;
    let t = &q.terms;
    t.relative_second_moment(|i| {
        weight * t.lobe_density(i, exponent, norm) + (1.0 - weight) * t.cosine_pdf[i]
    })
}

pub(super) fn quadrature(
    target: &TargetFn<'_>,
    view_theta: f64,
    config: &LobeFitConfig,
) -> ViewQuadrature {
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
    pub(super) views: Vec<ViewQuadrature>,
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

/// Chooses the lobe for `target` (a table or a network, `f_r` by Rusinkiewicz angles).
pub fn fit_lobe(target: &TargetFn<'_>, config: &LobeFitConfig) -> Result<LobeFit> {
    LobeQuadrature::new(target, config)?.fit(config)
}

impl LobeFit {
    /// The chosen lobe `(n, w)`.
    pub fn lobe(&self) -> (f64, f64) {
        (self.exponent, self.specular_weight)
    }
}
