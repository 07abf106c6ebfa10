//! Choosing the Blinn-Phong sampling lobe `(n, w)` of a material for the lowest variance of
//! BSDF sampling.
//!
//! The 7-parameter model fit of [`crate::phong_fit`] (docs/design.md section 6) matches the BRDF's
//! shape in log space, which is the right label for a predictor but often a poor sampling
//! density: on materials with a weak, very sharp spike over a diffuse base it returns
//! `n ~ 1e4..1e5` with `w ~ 0.01`, so almost no samples go where most of the reflected energy is,
//! and renders are no better than cosine sampling. Here the lobe is chosen for what sampling
//! needs. With `g(l) = f_r(l, v) cos(theta_l)` (mean over RGB) and the mixture density `p`, the
//! estimator `g / p` of `I = int g` has the relative second moment
//!
//! `R(v) = int g^2 / p  /  I^2`   (`R - 1` is its relative variance; 1 means zero variance),
//!
//! which is also the mean second moment of BSDF sampling towards a small light at a random
//! direction. `R` is computed by quadrature over the half vector (`theta_h = pi/2 s^2`, dense
//! near the normal like the MERL grid, so lobes of `n ~ 1e5` are resolved), averaged over view
//! elevations, and minimised over a grid of `(n, w)`.
//!
//! [`LobeChoice`] names the two candidates (this search and the model fit's lobe);
//! [`choose_lobe`] and [`LobeAnalysis::lobe`] are where one of them is picked.

use crate::coords::to_rusinkiewicz;
use crate::error::{NbrdfError, Result};
use crate::phong_fit::{self, FitConfig, PhongFit, PhongParams};
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

/// Quadrature points of one view with what the candidate densities need.
struct ViewQuadrature {
    /// `g^2 dω_l` of each point where `g > 0`.
    g2_dw: Vec<f64>,
    ln_cos_h: Vec<f64>,
    /// `1 / (4 v.h)`: the Jacobian from half-vector to light density.
    inv_jacobian: Vec<f64>,
    /// Cosine density `l.z / pi`.
    cosine_pdf: Vec<f64>,
    /// `(int g)^2`.
    integral_sq: f64,
}

/// Relative second moment `R` of the lobe `(n, w)` for a view.
fn second_moment(q: &ViewQuadrature, exponent: f64, weight: f64) -> f64 {
    if q.integral_sq <= 0.0 {
        return 1.0;
    }
    let norm = (exponent + 1.0) * 0.5 * FRAC_1_PI;
    let mut sum = 0.0;
    for i in 0..q.g2_dw.len() {
        let specular = norm * (exponent * q.ln_cos_h[i]).exp() * q.inv_jacobian[i];
        let pdf = weight * specular + (1.0 - weight) * q.cosine_pdf[i];
        if pdf <= 0.0 {
            return f64::INFINITY;
        }
        sum += q.g2_dw[i] / pdf;
    }
    sum / q.integral_sq
}

fn quadrature(target: &TargetFn<'_>, view_theta: f64, config: &LobeFitConfig) -> ViewQuadrature {
    let view = DVec3::new(view_theta.sin(), 0.0, view_theta.cos());
    let ds = 1.0 / config.s_bins as f64;
    let dphi = PI / config.phi_bins as f64;
    let mut q = ViewQuadrature {
        g2_dw: Vec::new(),
        ln_cos_h: Vec::new(),
        inv_jacobian: Vec::new(),
        cosine_pdf: Vec::new(),
        integral_sq: 0.0,
    };
    let mut integral = 0.0;
    for i in 0..config.s_bins {
        let s = (i as f64 + 0.5) * ds;
        let theta_h = FRAC_PI_2 * s * s;
        let (sin_h, cos_h) = theta_h.sin_cos();
        // dω_h = sin(theta_h) dtheta_h dphi_h, dtheta_h = pi s ds; phi_h over [0, pi] counts twice
        // (the view lies in the xz plane and the material is isotropic).
        let dw_h = 2.0 * sin_h * PI * s * ds * dphi;
        for j in 0..config.phi_bins {
            let phi_h = (j as f64 + 0.5) * dphi;
            let half = DVec3::new(sin_h * phi_h.cos(), sin_h * phi_h.sin(), cos_h);
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
            let dw_l = 4.0 * v_dot_h * dw_h;
            integral += g * dw_l;
            q.g2_dw.push(g * g * dw_l);
            q.ln_cos_h.push(cos_h.max(1e-300).ln());
            q.inv_jacobian.push(0.25 / v_dot_h);
            q.cosine_pdf.push(light.z * FRAC_1_PI);
        }
    }
    q.integral_sq = integral * integral;
    q
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
mod tests {
    use super::*;
    use crate::coords::from_rusinkiewicz;
    use crate::coords::RusinkiewiczAngles;
    use crate::sampling::SamplingStrategy;
    use glam::Vec3;

    fn blinn_phong(kd: f64, ks: f64, n: f64) -> impl Fn(&RusinkiewiczAngles) -> Option<[f64; 3]> {
        move |a: &RusinkiewiczAngles| {
            let cos_h = a.theta_h.cos().max(0.0);
            let f = kd / PI + ks * (n + 2.0) / (2.0 * PI) * cos_h.powf(n);
            Some([f; 3])
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
    #[test]
    fn quadrature_second_moment_matches_monte_carlo() {
        let target = blinn_phong(0.2, 0.6, 60.0);
        let config = LobeFitConfig::default();
        let theta_v = 35f64.to_radians();
        let q = quadrature(&target, theta_v, &config);
        let (n, w) = (40.0, 0.6);
        let quad = second_moment(&q, n, w);
        let strategy = SamplingStrategy::BlinnPhong {
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
        let (mut m1, mut m2, count) = (0.0, 0.0, 400_000);
        for _ in 0..count {
            let s = strategy.sample(view, [uniform(), uniform(), uniform()]);
            if s.pdf <= 0.0 {
                continue;
            }
            let (l, v) = (s.light.as_dvec3(), view.as_dvec3());
            let a = to_rusinkiewicz(v, l);
            let (_, l2) = from_rusinkiewicz(&a);
            let g = target(&a).unwrap()[0] * l2.z;
            let ratio = g / s.pdf as f64;
            m1 += ratio;
            m2 += ratio * ratio;
        }
        let (m1, m2) = (m1 / count as f64, m2 / count as f64);
        let mc = m2 / (m1 * m1);
        assert!(
            (quad - mc).abs() < 0.03 * mc,
            "quadrature {quad} vs Monte Carlo {mc}"
        );
        // And the integral itself: the mean of g/p is int g.
        assert!((m1 - q.integral_sq.sqrt()).abs() < 0.01 * m1);
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
}
