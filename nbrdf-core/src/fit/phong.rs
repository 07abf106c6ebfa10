//! Fitting the 7-parameter Blinn-Phong model (docs/design.md section 6) that labels a material's
//! importance-sampling lobe:
//!
//! `f = kd / pi + ks (n + 2) / (2 pi) cos(theta_h)^n`, RGB `kd`, `ks`, scalar `n` in `[0, 1e6]`,
//! and the sampling weight `w = mean(ks) / (mean(kd) + mean(ks))`.
//!
//! The loss is the training loss of the network, `|ln(1 + f_true cos) - ln(1 + f cos)|` averaged
//! over adaptively sampled directions and channels, so the lobe is judged where the network is.
//! Parameters live in log space (`ln kd`, `ln ks`, `ln(1 + n)`), which makes the scales of a dull
//! and a mirror-like material alike; full-batch Adam with a decaying step size is run from
//! several deterministic starting exponents and the best result is refined. Adam only needs the
//! sign-like gradient of the L1 loss, and its steps are bounded, so a stiff lobe cannot blow up.

use crate::error::{NbrdfError, Result};
use crate::train::dataset::{self, AngularSampling, Sample, TargetFn};
use crate::train::rng::Stream;
use rayon::prelude::*;
use std::f64::consts::PI;

/// Largest exponent the fit returns: the largest the samplers accept.
pub use crate::sampling::MAX_EXPONENT;
/// Bounds of `ln kd` and `ln ks`: below `e^-30` a lobe is absent, above `e^12` not physical.
const LN_MIN: f64 = -30.0;
const LN_MAX: f64 = 12.0;
/// `cos(theta_h)` is clamped to at least this before its logarithm, so that `0^0 = 1`.
const COS_MIN: f64 = 1e-12;

/// A Blinn-Phong reflectance.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PhongParams {
    pub kd: [f64; 3],
    pub ks: [f64; 3],
    pub exponent: f64,
}

impl PhongParams {
    /// `f_r` at `cos(theta_h)`.
    pub fn eval(&self, cos_theta_h: f64) -> [f64; 3] {
        let lobe = (self.exponent + 2.0) / (2.0 * PI)
            * (self.exponent * cos_theta_h.max(COS_MIN).ln()).exp();
        std::array::from_fn(|c| self.kd[c] / PI + self.ks[c] * lobe)
    }

    /// `mean(ks) / (mean(kd) + mean(ks))`, 0 for a black material.
    pub fn specular_weight(&self) -> f64 {
        let (d, s) = (self.kd.iter().sum::<f64>(), self.ks.iter().sum::<f64>());
        if d + s > 0.0 {
            s / (d + s)
        } else {
            0.0
        }
    }
}

/// Settings of a fit.
#[derive(Clone, Debug, PartialEq)]
pub struct FitConfig {
    pub samples: usize,
    pub seed: u64,
    /// Starting exponents, one restart each.
    pub start_exponents: Vec<f64>,
    pub iterations_per_restart: usize,
    pub refine_iterations: usize,
}

impl Default for FitConfig {
    fn default() -> Self {
        FitConfig {
            samples: 10_000,
            seed: 0,
            start_exponents: vec![1.0, 10.0, 100.0, 1e3, 1e4, 1e5],
            iterations_per_restart: 300,
            refine_iterations: 600,
        }
    }
}

/// The fitted parameters and their loss.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PhongFit {
    pub params: PhongParams,
    pub loss: f64,
}

/// Fits the model to `target`.
pub fn fit(target: &TargetFn<'_>, config: &FitConfig) -> Result<PhongFit> {
    if config.samples == 0 || config.start_exponents.is_empty() {
        return Err(NbrdfError::InvalidArgument(
            "the fit needs samples and at least one start".into(),
        ));
    }
    let set = dataset::draw(
        target,
        AngularSampling::Adaptive,
        false,
        config.samples,
        config.seed,
        Stream::FitSamples,
    )?;
    let data = FitData::new(&set.samples);
    let mut best: Option<(f64, [f64; 7])> = None;
    for &n0 in &config.start_exponents {
        let theta = optimise(
            &data,
            data.start(n0),
            config.iterations_per_restart,
            0.1,
            2e-3,
        );
        let loss = data.loss_and_gradient(&theta).0;
        if best.map_or(true, |(l, _)| loss < l) {
            best = Some((loss, theta));
        }
    }
    let (_, theta) = best.expect("at least one start");
    let theta = optimise(&data, theta, config.refine_iterations, 0.02, 5e-4);
    let loss = data.loss_and_gradient(&theta).0;
    Ok(PhongFit {
        params: from_theta(&theta),
        loss,
    })
}

/// Per-sample quantities that do not depend on the parameters.
struct FitData {
    ln_cos_h: Vec<f64>,
    cos_l: Vec<f64>,
    log_target: Vec<[f64; 3]>,
}

/// `theta = [ln kd (3), ln ks (3), ln(1 + n)]`.
fn from_theta(theta: &[f64; 7]) -> PhongParams {
    PhongParams {
        kd: std::array::from_fn(|c| theta[c].exp()),
        ks: std::array::from_fn(|c| theta[3 + c].exp()),
        exponent: theta[6].exp_m1().clamp(0.0, MAX_EXPONENT),
    }
}

fn clamp_theta(theta: &mut [f64; 7]) {
    for t in theta[..6].iter_mut() {
        *t = t.clamp(LN_MIN, LN_MAX);
    }
    theta[6] = theta[6].clamp(0.0, MAX_EXPONENT.ln_1p());
}

impl FitData {
    fn new(samples: &[Sample]) -> Self {
        FitData {
            ln_cos_h: samples
                .iter()
                .map(|s| (s.x[2] as f64).max(COS_MIN).ln())
                .collect(),
            cos_l: samples.iter().map(|s| s.cos_light as f64).collect(),
            log_target: samples
                .iter()
                .map(|s| s.log_target.map(|t| t as f64))
                .collect(),
        }
    }

    /// A start with exponent `n0`: `kd` from the median reflectance, `ks` so that the lobe
    /// reaches the brightest sample.
    fn start(&self, n0: f64) -> [f64; 7] {
        let mut theta = [0.0; 7];
        for c in 0..3 {
            let mut f: Vec<f64> = self
                .log_target
                .iter()
                .zip(&self.cos_l)
                .map(|(t, &cl)| t[c].exp_m1() / cl)
                .collect();
            f.sort_by(f64::total_cmp);
            let median = f[f.len() / 2].max(1e-6);
            let peak = f[f.len() - 1].max(median);
            let kd = 0.5 * PI * median;
            let ks = ((peak - 0.5 * median) * 2.0 * PI / (n0 + 2.0)).max(1e-6);
            theta[c] = kd.ln();
            theta[3 + c] = ks.ln();
        }
        theta[6] = n0.ln_1p();
        clamp_theta(&mut theta);
        theta
    }

    /// Mean loss and its gradient in `theta`. Chunks are summed in order: deterministic.
    fn loss_and_gradient(&self, theta: &[f64; 7]) -> (f64, [f64; 7]) {
        const CHUNK: usize = 2048;
        let p = from_theta(theta);
        let n = p.exponent;
        let dn_ds = n + 1.0;
        let parts: Vec<(f64, [f64; 7])> = (0..self.cos_l.len().div_ceil(CHUNK))
            .into_par_iter()
            .map(|chunk| {
                let mut loss = 0.0;
                let mut g = [0.0; 7];
                for i in chunk * CHUNK..((chunk + 1) * CHUNK).min(self.cos_l.len()) {
                    let (lc, cl) = (self.ln_cos_h[i], self.cos_l[i]);
                    let e = (n * lc).exp();
                    let lobe = (n + 2.0) / (2.0 * PI) * e;
                    let d_lobe_ds = e / (2.0 * PI) * (1.0 + (n + 2.0) * lc) * dn_ds;
                    for c in 0..3 {
                        let f = p.kd[c] / PI + p.ks[c] * lobe;
                        let u = f * cl;
                        let r = u.ln_1p() - self.log_target[i][c];
                        loss += r.abs();
                        let dl_df = r.signum() * (r != 0.0) as i32 as f64 * cl / (1.0 + u);
                        g[c] += dl_df * p.kd[c] / PI;
                        g[3 + c] += dl_df * p.ks[c] * lobe;
                        g[6] += dl_df * p.ks[c] * d_lobe_ds;
                    }
                }
                (loss, g)
            })
            .collect();
        let count = (3 * self.cos_l.len()) as f64;
        let mut loss = 0.0;
        let mut grad = [0.0; 7];
        for (l, g) in parts {
            loss += l;
            for k in 0..7 {
                grad[k] += g[k];
            }
        }
        (loss / count, grad.map(|g| g / count))
    }
}

/// Full-batch Adam from `theta` with the step size decaying geometrically from `lr0` to `lr1`;
/// returns the best parameters seen.
fn optimise(
    data: &FitData,
    mut theta: [f64; 7],
    iterations: usize,
    lr0: f64,
    lr1: f64,
) -> [f64; 7] {
    let (b1, b2, eps) = (0.9, 0.999, 1e-12);
    let mut m = [0.0; 7];
    let mut v = [0.0; 7];
    let mut best = (f64::INFINITY, theta);
    for t in 0..iterations {
        let (loss, g) = data.loss_and_gradient(&theta);
        if loss < best.0 {
            best = (loss, theta);
        }
        let lr = lr0 * (lr1 / lr0).powf(t as f64 / iterations.max(1) as f64);
        let step = (t + 1) as f64;
        for k in 0..7 {
            m[k] = b1 * m[k] + (1.0 - b1) * g[k];
            v[k] = b2 * v[k] + (1.0 - b2) * g[k] * g[k];
            let m_hat = m[k] / (1.0 - b1.powf(step));
            let v_hat = v[k] / (1.0 - b2.powf(step));
            theta[k] -= lr * m_hat / (v_hat.sqrt() + eps);
        }
        clamp_theta(&mut theta);
    }
    let (loss, _) = data.loss_and_gradient(&theta);
    if loss < best.0 {
        theta
    } else {
        best.1
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::coords::RusinkiewiczAngles;
    use crate::merl::MerlTable;

    fn check_recovery(truth: PhongParams) {
        let table = MerlTable::tabulate(|a: &RusinkiewiczAngles| truth.eval(a.theta_h.cos()));
        let target = |a: &RusinkiewiczAngles| table.lookup_valid(a);
        let config = FitConfig {
            samples: 2000,
            iterations_per_restart: 150,
            refine_iterations: 300,
            ..FitConfig::default()
        };
        let fit = fit(&target, &config).unwrap();
        let p = fit.params;
        let n_err = (p.exponent - truth.exponent).abs() / truth.exponent;
        assert!(
            n_err < 0.05,
            "exponent {} vs {} ({fit:?})",
            p.exponent,
            truth.exponent
        );
        for c in 0..3 {
            assert!(
                (p.kd[c] / truth.kd[c] - 1.0).abs() < 0.03,
                "kd {c}: {fit:?}"
            );
            assert!(
                (p.ks[c] / truth.ks[c] - 1.0).abs() < 0.03,
                "ks {c}: {fit:?}"
            );
        }
        assert!((p.specular_weight() - truth.specular_weight()).abs() < 0.03);
        assert!(fit.loss < 5e-3, "{fit:?}");
    }

    #[test]
    fn recovers_a_glossy_blinn_phong_table() {
        check_recovery(PhongParams {
            kd: [0.3, 0.2, 0.1],
            ks: [0.2, 0.25, 0.3],
            exponent: 80.0,
        });
    }

    #[test]
    fn recovers_a_sharp_blinn_phong_table() {
        check_recovery(PhongParams {
            kd: [0.05, 0.05, 0.08],
            ks: [0.6, 0.5, 0.4],
            exponent: 3000.0,
        });
    }

    #[test]
    fn exponent_and_weight_are_finite_for_black_and_constant_targets() {
        for value in [0.0, 0.2] {
            let target = move |_: &RusinkiewiczAngles| Some([value; 3]);
            let config = FitConfig {
                samples: 500,
                iterations_per_restart: 50,
                refine_iterations: 50,
                ..FitConfig::default()
            };
            let fit = fit(&target, &config).unwrap();
            let p = fit.params;
            assert!((0.0..=MAX_EXPONENT).contains(&p.exponent), "{fit:?}");
            assert!((0.0..=1.0).contains(&p.specular_weight()), "{fit:?}");
            assert!(fit.loss.is_finite() && fit.loss < 2e-2, "{fit:?}");
        }
    }
}
