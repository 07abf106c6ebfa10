//! The Blinn-Phong parameter predictor (docs/design.md section 7): a shallow MLP from the
//! 32-value code to the sampling lobe `(n, w)`, supervised by the lobe fits of the training split.
//!
//! Network: linear `32 -> 2` with weight decay by default (`32 -> H (tanh) -> 2` optional) on
//! standardised codes, an ensemble of 8. Output 0 is `ln n`, clamped so that `n` lies in
//! `(0, MAX_EXPONENT]`; output 1 goes through a logistic so that `w` lies in `[0, 1]`: every
//! output is a valid lobe. Loss (full-batch Adam), one of:
//! * labels: `(o0 - ln max(n, 1e-3))^2 + 25 (w_pred - w)^2` (a weight error of 0.2 costs as
//!   much as a factor e in the exponent);
//! * variance (the CLI's default): the lobe search's objective ([`crate::fit::lobes`]) at the
//!   predicted lobe, `ln(R - 1)` interpolated on its grid minus its value at the label, plus
//!   0.05 x the label loss. It tells a material whose variance barely depends on the exponent
//!   from a sharp metal, which the label loss cannot.

use super::mlp::Mlp;
use crate::coords::{network_input_from_angles, RusinkiewiczAngles};
use crate::error::{NbrdfError, Result};
use crate::fit::lobes::{choose_lobe, LobeChoice, LobeFitConfig};
use crate::fit::phong::{FitConfig, MAX_EXPONENT};
use crate::fit::target::network_target;
use crate::network::Nbrdf;
use crate::train::adam::{Adam, AdamConfig};
use serde::{Deserialize, Serialize};

pub const FORMAT_NAME: &str = "nbrdf-phong-predictor";
const LN_N_MIN: f32 = -6.907_755; // ln 1e-3
const WEIGHT_LOSS: f32 = 25.0;

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PhongPredictor {
    pub format: String,
    pub version: u32,
    pub code_mean: Vec<f32>,
    pub code_std: Vec<f32>,
    pub mlp: Mlp,
    /// Further members of the ensemble (trained from other seeds): the prediction averages
    /// `ln n` and `w` over `mlp` and these. With 80 labelled materials a single network's
    /// predictions swing with its seed; the mean does not.
    #[serde(default)]
    pub ensemble: Vec<Mlp>,
    /// Refinement iterations of the codes it was trained on ([`super::autoencoder::AutoEncoder::refine_code`]):
    /// codes to predict from must be found the same way.
    #[serde(default)]
    pub refine_steps: usize,
    /// Whether the inputs are the code followed by the network's [`highlight_profile`]
    /// (the default of `predictor train`; files written before it existed are code-only).
    #[serde(default)]
    pub highlight_profile: bool,
    #[serde(default)]
    pub provenance: serde_json::Value,
}

/// Half-vector elevations (degrees) of [`highlight_profile`]; the last is the reference.
const PROFILE_THETA_H_DEG: [f64; 9] = [0.0, 0.25, 0.5, 1.0, 2.0, 4.0, 8.0, 16.0, 32.0];
/// Difference elevations (degrees) of [`highlight_profile`].
const PROFILE_THETA_D_DEG: [f64; 3] = [10.0, 30.0, 50.0];
/// Floor of the profile's logarithms (a BRDF value, 1/sr): far below any visible highlight,
/// it keeps black regions finite.
const PROFILE_FLOOR: f32 = 1e-4;
/// Length of [`highlight_profile`].
pub const PROFILE_LEN: usize = PROFILE_THETA_H_DEG.len() * PROFILE_THETA_D_DEG.len();

/// The shape of a network's specular peak: `ln(f + 1e-4) - ln(f_ref + 1e-4)` of the mean over
/// RGB of `f(theta_h, theta_d)` at `theta_h` = 0 to 16 degrees against `f_ref` at 32 degrees,
/// for three `theta_d` (`phi_h = phi_d = 0`); [`PROFILE_LEN`] values.
///
/// Why the predictor reads it besides the code: the 64 x 64 sphere of the autoencoder's loss
/// samples the half vector about every 2 degrees, so a peak of `n = 2e4` lights one or two
/// pixels about as brightly as a dimmer one of `n = 1e3`, and the code cannot hold what the
/// loss does not see (README). 27 evaluations of the network can.
pub fn highlight_profile(net: &Nbrdf) -> Vec<f32> {
    let mut out = Vec::with_capacity(PROFILE_LEN);
    for theta_d in PROFILE_THETA_D_DEG {
        let value = |theta_h: f64| {
            let rgb = net.eval_input(network_input_from_angles(&RusinkiewiczAngles {
                theta_h: theta_h.to_radians(),
                phi_h: 0.0,
                theta_d: theta_d.to_radians(),
                phi_d: 0.0,
            }));
            let mean = rgb.iter().sum::<f32>() / 3.0;
            // A network may dip below zero or overflow; the profile stays finite.
            (if mean.is_finite() {
                mean.clamp(0.0, f32::MAX)
            } else {
                0.0
            } + PROFILE_FLOOR)
                .ln()
        };
        let reference = value(PROFILE_THETA_H_DEG[PROFILE_THETA_H_DEG.len() - 1]);
        out.extend(PROFILE_THETA_H_DEG.iter().map(|&t| value(t) - reference));
    }
    out
}

/// The fitted lobe `(n, w)` that labels a network: its own "fit" sampling (what `nbrdf
/// fit-phong` stored, the lowest-variance lobe unless run with `--lobe model`), or, for a network
/// without one or with `refit`, the lobe [`LobeChoice::Model`] of a fresh 7-parameter fit.
///
/// Why the model lobe there: it needs no quadrature (the lowest-variance search evaluates each
/// network ~10^6 times), and it is what these labels have been since the predictor was written,
/// so refitted label sets and the predictors trained on them stay as they were. The networks of
/// the latent-space report all carry fit-phong's lowest-variance lobe, so there the labels are
/// that lobe. The labels are the regression target of `--loss labels`, the small pull towards
/// the label of `--loss variance` (whose main term is the variance objective of
/// [`crate::fit::lobes`] itself, through a [`VarianceGrid`], whatever the label), the reference
/// lobe of the RMSE ratios of `predictor eval` and the cross-validation, and the targets of the
/// autoencoder's auxiliary lobe loss (`ae train --lobe-weight`).
pub fn lobe_label(net: &Nbrdf, refit: bool) -> Result<(f64, f64)> {
    if let Some(s) = &net.sampling {
        // A two-lobe fit is no one-lobe label: its first lobe goes with a second one.
        if s.source == "fit" && !refit && s.second_lobe.is_none() {
            return Ok((s.exponent as f64, s.specular_weight as f64));
        }
    }
    choose_lobe(
        &network_target(net),
        LobeChoice::Model,
        &FitConfig::default(),
        &LobeFitConfig::default(),
    )
}

/// A training example: code, fitted exponent, fitted specular weight.
pub type Example = (Vec<f32>, f64, f64);

/// Training settings of the predictor.
#[derive(Clone, Debug, PartialEq)]
pub struct PredictorConfig {
    /// Width of the tanh hidden layer; 0 for a linear map from the code.
    pub hidden: usize,
    /// Full-batch Adam iterations.
    pub iterations: usize,
    pub seed: u64,
    /// Networks in the ensemble (seeds `seed`, `seed + 1`, ...).
    pub members: usize,
    /// L2 penalty `weight_decay/2 |W|^2` on the weights (not the biases), per example.
    pub weight_decay: f32,
}

impl Default for PredictorConfig {
    fn default() -> Self {
        // Chosen by 5-fold cross-validation over the SGD set's training split with the highlight
        // profile (`predictor train --cross-validate 5`, README): a tanh layer of 32 with decay
        // 0.1 had the lowest geometric mean of the held-out RMSE ratios (1.46; linear with
        // decay 0.01: 2.13).
        PredictorConfig {
            hidden: 32,
            iterations: 3000,
            seed: 0,
            members: 8,
            weight_decay: 0.1,
        }
    }
}

fn sigmoid(x: f32) -> f32 {
    1.0 / (1.0 + (-x).exp())
}

/// Exponent axis of [`VarianceGrid`]: `n = 10^(k / EXPONENT_STEPS_PER_DECADE)`, `k` in
/// `0..=EXPONENT_STEPS` (1 to 1e5, the lobe search's grid without its `n = 0`).
pub const EXPONENT_STEPS_PER_DECADE: f32 = 8.0;
pub const EXPONENT_STEPS: usize = 40;
/// Weight axis: `w = j / WEIGHT_STEPS`, `j` in `0..=WEIGHT_STEPS`.
pub const WEIGHT_STEPS: usize = 20;
/// Share of the label loss in the variance loss.
const LABEL_SHARE: f32 = 0.05;

/// The sampling objective of one material, `ln(R - 1)` of [`crate::fit::lobes`], on the grid of
/// exponents and weights above, and its minimum.
#[derive(Clone, Debug, PartialEq)]
pub struct VarianceGrid {
    ln_variance: Vec<f32>,
    minimum: f32,
}

impl VarianceGrid {
    /// Builds the grid from `relative_variance(n, w)` (`R - 1`, e.g.
    /// [`crate::fit::lobes::LobeQuadrature::relative_variance`]).
    pub fn new(relative_variance: impl Fn(f64, f64) -> f64 + Sync) -> Self {
        use rayon::prelude::*;
        let ln_variance: Vec<f32> = (0..(EXPONENT_STEPS + 1) * (WEIGHT_STEPS + 1))
            .into_par_iter()
            .map(|i| {
                let (k, j) = (i / (WEIGHT_STEPS + 1), i % (WEIGHT_STEPS + 1));
                let n = 10f64.powf(k as f64 / EXPONENT_STEPS_PER_DECADE as f64);
                let r = relative_variance(n, j as f64 / WEIGHT_STEPS as f64);
                // Zero variance (a Lambertian under cosine sampling) and non-finite values
                // (a lobe that misses the material) stay finite.
                (if r.is_finite() { r.max(1e-6) } else { 1e6 }).ln() as f32
            })
            .collect();
        let minimum = ln_variance.iter().copied().fold(f32::INFINITY, f32::min);
        VarianceGrid {
            ln_variance,
            minimum,
        }
    }

    /// `ln(R - 1)` minus its minimum at `(ln n, w)`, and its derivatives in `ln n` and `w`
    /// (bilinear; 0 in `ln n` beyond the grid's ends).
    pub fn excess(&self, ln_n: f32, w: f32) -> (f32, f32, f32) {
        let per_ln = EXPONENT_STEPS_PER_DECADE / std::f32::consts::LN_10;
        let k_raw = ln_n * per_ln;
        let k = k_raw.clamp(0.0, EXPONENT_STEPS as f32);
        let j = (w * WEIGHT_STEPS as f32).clamp(0.0, WEIGHT_STEPS as f32);
        let (k0, j0) = (
            (k.floor() as usize).min(EXPONENT_STEPS - 1),
            (j.floor() as usize).min(WEIGHT_STEPS - 1),
        );
        let (fk, fj) = (k - k0 as f32, j - j0 as f32);
        let at = |k: usize, j: usize| self.ln_variance[k * (WEIGHT_STEPS + 1) + j];
        let (a, b, c, d) = (
            at(k0, j0),
            at(k0, j0 + 1),
            at(k0 + 1, j0),
            at(k0 + 1, j0 + 1),
        );
        let value =
            a * (1.0 - fk) * (1.0 - fj) + b * (1.0 - fk) * fj + c * fk * (1.0 - fj) + d * fk * fj;
        let d_k = (c - a) * (1.0 - fj) + (d - b) * fj;
        let d_j = (b - a) * (1.0 - fk) + (d - c) * fk;
        let inside = k_raw > 0.0 && k_raw < EXPONENT_STEPS as f32;
        (
            value - self.minimum,
            if inside { d_k * per_ln } else { 0.0 },
            d_j * WEIGHT_STEPS as f32,
        )
    }
}

/// The summed loss of the examples (standardised codes `xs`) and its gradient, added into
/// `grad`, of the mean loss: the label loss, or with `grids` the variance loss.
fn loss_and_gradient(
    mlp: &Mlp,
    xs: &[Vec<f32>],
    examples: &[Example],
    grids: Option<&[&VarianceGrid]>,
    grad: &mut [f32],
) -> f64 {
    let n = examples.len() as f64;
    let mut loss = 0.0;
    for (i, (x, e)) in xs.iter().zip(examples).enumerate() {
        let acts = mlp.forward(x);
        let o = acts.last().cloned().unwrap_or_default();
        let ln_n = (e.1.max(1e-3)).ln() as f32;
        let w = sigmoid(o[1]);
        let (d0, d1) = (o[0] - ln_n, w - e.2 as f32);
        let inv = 1.0 / n as f32;
        let label_loss = d0 * d0 + WEIGHT_LOSS * d1 * d1;
        let (mut g0, mut g1) = (2.0 * d0, 2.0 * WEIGHT_LOSS * d1);
        match grids {
            Some(grids) => {
                let (excess, d_ln_n, d_w) = grids[i].excess(o[0], w);
                loss += (excess + LABEL_SHARE * label_loss) as f64;
                g0 = d_ln_n + LABEL_SHARE * g0;
                g1 = d_w + LABEL_SHARE * g1;
            }
            None => loss += label_loss as f64,
        }
        let g = [g0 * inv, g1 * w * (1.0 - w) * inv];
        mlp.backward(&acts, &g, grad);
    }
    loss
}

/// Adds `decay w` to the gradient of each weight (not the biases) of the flat `params`.
fn add_weight_decay(mlp: &Mlp, params: &[f32], decay: f32, grad: &mut [f32]) {
    // Each layer's weights come before its biases in the flat vector.
    let mut at = 0;
    for layer in &mlp.layers {
        let weights = at..at + layer.weights.len();
        for (g, w) in grad[weights.clone()].iter_mut().zip(&params[weights]) {
            *g += decay * w;
        }
        at += layer.weights.len() + layer.bias.len();
    }
}

impl PhongPredictor {
    /// The predictor's input for a network and its code: the code, followed by the network's
    /// [`highlight_profile`] where the predictor was trained with it.
    pub fn inputs(&self, code: &[f32], net: &Nbrdf) -> Vec<f32> {
        let mut x = code.to_vec();
        if self.highlight_profile {
            x.extend(highlight_profile(net));
        }
        x
    }

    /// `(ln n, w)` of one member, each within its valid range.
    fn member(mlp: &Mlp, x: &[f32]) -> (f32, f32) {
        let o = mlp.eval(x);
        let ln_n = if o[0].is_finite() { o[0] } else { LN_N_MIN };
        let w = if o[1].is_finite() { sigmoid(o[1]) } else { 0.0 };
        (
            ln_n.clamp(LN_N_MIN, (MAX_EXPONENT as f32).ln()),
            w.clamp(0.0, 1.0),
        )
    }

    /// `(exponent, specular_weight)` for an input ([`PhongPredictor::inputs`]): exponent in
    /// `(0, 1e6]`, weight in `[0, 1]` whatever the input (non-finite inputs give the most
    /// diffuse lobe).
    pub fn predict(&self, input: &[f32]) -> (f32, f32) {
        let x: Vec<f32> = input
            .iter()
            .zip(self.code_mean.iter().zip(&self.code_std))
            .map(|(c, (m, s))| (c - m) / s)
            .collect();
        let members = std::iter::once(&self.mlp).chain(&self.ensemble);
        let count = 1 + self.ensemble.len();
        let (sum_ln_n, sum_w) = members
            .map(|m| Self::member(m, &x))
            .fold((0.0, 0.0), |(a, b), (ln_n, w)| (a + ln_n, b + w));
        let ln_n = (sum_ln_n / count as f32).clamp(LN_N_MIN, (MAX_EXPONENT as f32).ln());
        let w = (sum_w / count as f32).clamp(0.0, 1.0);
        (ln_n.exp().clamp(0.0, MAX_EXPONENT as f32), w)
    }

    /// [`PhongPredictor::train`] of `config.members` networks from seeds `seed`, `seed + 1`,
    /// ... in parallel, combined into one ensemble.
    pub fn train_ensemble(
        examples: &[Example],
        grids: Option<&[&VarianceGrid]>,
        config: &PredictorConfig,
    ) -> Result<Self> {
        use rayon::prelude::*;
        let members = config.members.max(1);
        let mut trained: Vec<PhongPredictor> = (0..members as u64)
            .into_par_iter()
            .map(|k| {
                let member = PredictorConfig {
                    seed: config.seed + k,
                    ..config.clone()
                };
                Self::train(examples, grids, &member)
            })
            .collect::<Result<_>>()?;
        let mut first = trained.remove(0);
        first.ensemble = trained.into_iter().map(|p| p.mlp).collect();
        if let Some(o) = first.provenance.as_object_mut() {
            o.insert("members".into(), members.into());
        }
        Ok(first)
    }

    /// Trains one network (`config.members` is ignored) on `examples` with the label loss, or
    /// with the variance loss where `grids` gives each example's [`VarianceGrid`] (`grids[i]`
    /// for `examples[i]`).
    pub fn train(
        examples: &[Example],
        grids: Option<&[&VarianceGrid]>,
        config: &PredictorConfig,
    ) -> Result<Self> {
        let PredictorConfig {
            hidden,
            iterations,
            seed,
            ..
        } = *config;
        if examples.is_empty() {
            return Err(NbrdfError::InvalidArgument("no training examples".into()));
        }
        if grids.is_some_and(|g| g.len() != examples.len()) {
            return Err(NbrdfError::InvalidArgument(
                "one variance grid per example".into(),
            ));
        }
        let dims = examples[0].0.len();
        let n = examples.len() as f64;
        let codes: Vec<&[f32]> = examples.iter().map(|e| e.0.as_slice()).collect();
        let (mean, std) = super::column_mean_std(&codes, 1e-6);
        let mut p = PhongPredictor {
            format: FORMAT_NAME.into(),
            version: 1,
            code_mean: mean,
            code_std: std,
            mlp: if hidden == 0 {
                Mlp::new(&[dims, 2], seed, 3 << 32)
            } else {
                Mlp::new(&[dims, hidden, 2], seed, 3 << 32)
            },
            ensemble: Vec::new(),
            refine_steps: 0,
            highlight_profile: false,
            provenance: serde_json::Value::Null,
        };
        let xs: Vec<Vec<f32>> = examples
            .iter()
            .map(|e| {
                e.0.iter()
                    .zip(p.code_mean.iter().zip(&p.code_std))
                    .map(|(c, (m, s))| (c - m) / s)
                    .collect()
            })
            .collect();
        let mut params = p.mlp.to_flat();
        let mut adam = Adam::new(AdamConfig::default(), params.len());
        let mut loss = 0.0;
        for _ in 0..iterations {
            let mut grad = vec![0.0f32; params.len()];
            loss = loss_and_gradient(&p.mlp, &xs, examples, grids, &mut grad);
            if config.weight_decay > 0.0 {
                add_weight_decay(&p.mlp, &params, config.weight_decay, &mut grad);
            }
            adam.step(&mut params, &grad, 3e-3);
            p.mlp.set_flat(&params);
        }
        p.provenance = serde_json::json!({
            "architecture": if hidden == 0 {
                format!("{dims}-2, linear; ln n clamped, w logistic")
            } else {
                format!("{dims}-{hidden}-2, tanh hidden; ln n clamped, w logistic")
            },
            "weight_decay": config.weight_decay,
            "loss": if grids.is_some() { "variance" } else { "labels" },
            "examples": examples.len(),
            "iterations": iterations,
            "final_loss": loss / n,
            "seed": seed,
        });
        Ok(p)
    }

    pub fn load(path: impl AsRef<std::path::Path>) -> Result<Self> {
        let path = path.as_ref();
        Self::checked(super::read_json(path)?, &path.display().to_string())
    }

    /// A predictor from the text of a P.json file (e.g. one embedded in a program); errors
    /// name `origin`.
    pub fn from_json(text: &str, origin: &str) -> Result<Self> {
        Self::checked(super::parse_json(text, origin)?, origin)
    }

    fn checked(p: PhongPredictor, origin: &str) -> Result<Self> {
        if p.format != FORMAT_NAME {
            return Err(NbrdfError::InvalidArgument(format!(
                "{origin}: not a Phong predictor"
            )));
        }
        Ok(p)
    }

    pub fn save(&self, path: impl AsRef<std::path::Path>) -> Result<()> {
        super::write_json(self, path.as_ref())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::train::rng::{SplitMix64, Stream};

    /// A material's landscape: `R - 1 = exp(0.5 (ln n - a)^2 + 6 (w - b)^2)`, minimum at
    /// `(e^a, b)`.
    fn landscape(a: f64, b: f64) -> VarianceGrid {
        VarianceGrid::new(move |n, w| (0.5 * (n.ln() - a).powi(2) + 6.0 * (w - b).powi(2)).exp())
    }

    #[test]
    fn variance_grid_is_exact_at_nodes_and_its_slopes_match_finite_differences() {
        let g = landscape(4.0, 0.3);
        // At a node: k = 16 (n = 100), j = 6 (w = 0.3).
        let (v, _, _) = g.excess(100f32.ln(), 0.3);
        let want = 0.5 * (100f64.ln() - 4.0).powi(2) - g.minimum as f64;
        assert!((v as f64 - want).abs() < 1e-4, "{v} vs {want}");
        assert!(g.excess(4.0 + 1e-3, 0.3).0 >= 0.0);
        for &(ln_n, w) in &[(2.1f32, 0.42f32), (6.3, 0.77), (9.9, 0.07)] {
            let (_, d_n, d_w) = g.excess(ln_n, w);
            let h = 1e-3;
            let fd_n = (g.excess(ln_n + h, w).0 - g.excess(ln_n - h, w).0) / (2.0 * h);
            let fd_w = (g.excess(ln_n, w + h).0 - g.excess(ln_n, w - h).0) / (2.0 * h);
            assert!(
                (fd_n - d_n).abs() < 2e-2 * (1.0 + d_n.abs()),
                "{fd_n} vs {d_n}"
            );
            assert!(
                (fd_w - d_w).abs() < 2e-2 * (1.0 + d_w.abs()),
                "{fd_w} vs {d_w}"
            );
        }
        // Beyond the grid the exponent has no slope and the value is the edge's.
        assert_eq!(g.excess(20.0, 0.3).1, 0.0);
        assert_eq!(
            g.excess(20.0, 0.3).0,
            g.excess(EXPONENT_STEPS as f32 / 8.0 * std::f32::consts::LN_10, 0.3)
                .0
        );
    }

    #[test]
    fn variance_loss_finds_each_landscape_minimum_despite_wrong_labels() {
        let mut rng = SplitMix64::new(5, Stream::Latent, 0);
        let mut examples = Vec::new();
        let mut grids = Vec::new();
        for _ in 0..24 {
            let code: Vec<f32> = (0..32).map(|_| rng.next_f64() as f32 * 2.0 - 1.0).collect();
            let (a, b) = (5.0 + 3.0 * code[0] as f64, 0.5 + 0.4 * code[1] as f64);
            // Labels off by a factor e^2 in n and 0.2 in w: only the landscape says where to go.
            examples.push((code, (a + 2.0).exp(), (b - 0.2).clamp(0.0, 1.0)));
            grids.push(landscape(a, b));
        }
        let refs: Vec<&VarianceGrid> = grids.iter().collect();
        let config = PredictorConfig {
            hidden: 16,
            iterations: 2000,
            ..PredictorConfig::default()
        };
        let p = PhongPredictor::train(&examples, Some(&refs), &config).unwrap();
        let label_only = PhongPredictor::train(&examples, None, &config).unwrap();
        let mean_excess = |p: &PhongPredictor| {
            examples
                .iter()
                .zip(&grids)
                .map(|(e, g)| {
                    let (n, w) = p.predict(&e.0);
                    g.excess(n.ln(), w).0 as f64
                })
                .sum::<f64>()
                / examples.len() as f64
        };
        let (with_variance, with_labels) = (mean_excess(&p), mean_excess(&label_only));
        assert!(
            with_variance < 0.25,
            "variance loss leaves ln(R - 1) {with_variance} above the minimum"
        );
        assert!(
            with_variance < 0.5 * with_labels,
            "{with_variance} vs labels {with_labels}"
        );
        assert_eq!(p.provenance["loss"], "variance");
    }

    /// `f(theta_h) = expm1(sharpness (cos theta_h - cos 35deg) - 5)` on every channel,
    /// whatever `theta_d`: a one-unit network (hidden width 1) with a closed-form profile.
    fn peak_network(sharpness: f32) -> Nbrdf {
        let c0 = 35f32.to_radians().cos();
        #[rustfmt::skip]
        let flat = [
            0.0, 0.0, sharpness, 0.0, 0.0, 0.0, -sharpness * c0, // W1 (6 x 1), b1
            1.0, 0.0,                                           // W2 (1 x 1), b2
            1.0, 1.0, 1.0, -5.0, -5.0, -5.0,                    // W3 (1 x 3), b3
        ];
        Nbrdf::from_flat("peak", 1, &flat).unwrap()
    }

    #[test]
    fn highlight_profile_matches_the_closed_form_of_a_peak() {
        let c0 = 35f64.to_radians().cos();
        for sharpness in [30.0f32, 400.0] {
            let profile = highlight_profile(&peak_network(sharpness));
            assert_eq!(profile.len(), PROFILE_LEN);
            let ln_f = |deg: f64| {
                let z = sharpness as f64 * (deg.to_radians().cos() - c0) - 5.0;
                (z.exp_m1().max(0.0) + PROFILE_FLOOR as f64).ln()
            };
            for (row, _) in PROFILE_THETA_D_DEG.iter().enumerate() {
                for (k, &deg) in PROFILE_THETA_H_DEG.iter().enumerate() {
                    let got = profile[row * PROFILE_THETA_H_DEG.len() + k] as f64;
                    let want = ln_f(deg) - ln_f(32.0);
                    assert!(
                        (got - want).abs() < 2e-3 * (1.0 + want.abs()),
                        "sharpness {sharpness}, theta_h {deg}: {got} vs {want}"
                    );
                }
            }
        }
        // The sharper peak rises higher above its flank.
        let (broad, sharp) = (
            highlight_profile(&peak_network(30.0)),
            highlight_profile(&peak_network(400.0)),
        );
        assert!(sharp[0] > broad[0] + 10.0, "{} vs {}", sharp[0], broad[0]);
    }

    #[test]
    fn highlight_profile_stays_finite_and_is_appended_only_when_enabled() {
        for scale in [0.0f32, 1e3, 1e30] {
            let mut rng = SplitMix64::new(7, Stream::Latent, 0);
            let flat: Vec<f32> = (0..crate::network::parameter_count_for(21))
                .map(|_| (rng.next_f64() as f32 * 2.0 - 1.0) * scale)
                .collect();
            let net = Nbrdf::from_flat("x", 21, &flat).unwrap();
            let profile = highlight_profile(&net);
            assert!(
                profile.iter().all(|v| v.is_finite()),
                "{scale}: {profile:?}"
            );
            // The reference angle is the last of each row: 0 by construction.
            for row in profile.chunks(PROFILE_THETA_H_DEG.len()) {
                assert_eq!(row[PROFILE_THETA_H_DEG.len() - 1], 0.0);
            }
        }
        let examples: Vec<Example> = (0..4)
            .map(|k| (vec![k as f32; 3 + PROFILE_LEN], 10.0, 0.5))
            .collect();
        let config = PredictorConfig {
            iterations: 5,
            members: 1,
            ..PredictorConfig::default()
        };
        let mut p = PhongPredictor::train(&examples, None, &config).unwrap();
        let net = peak_network(100.0);
        assert_eq!(p.inputs(&[1.0, 2.0, 3.0], &net), vec![1.0, 2.0, 3.0]);
        p.highlight_profile = true;
        let x = p.inputs(&[1.0, 2.0, 3.0], &net);
        assert_eq!(&x[..3], &[1.0, 2.0, 3.0]);
        assert_eq!(&x[3..], highlight_profile(&net).as_slice());
        let (n, w) = p.predict(&x);
        assert!(n > 0.0 && (0.0..=1.0).contains(&w));
    }

    #[test]
    fn fits_labels_and_outputs_are_always_valid() {
        let mut rng = SplitMix64::new(4, Stream::Latent, 0);
        let examples: Vec<Example> = (0..40)
            .map(|_| {
                let code: Vec<f32> = (0..32).map(|_| rng.next_f64() as f32 * 2.0 - 1.0).collect();
                let n = (code[0] as f64 * 4.0 + 5.0).exp();
                let w = 0.5 + 0.4 * code[1] as f64;
                (code, n, w)
            })
            .collect();
        let config = PredictorConfig {
            hidden: 16,
            iterations: 1500,
            members: 3,
            ..PredictorConfig::default()
        };
        let p = PhongPredictor::train_ensemble(&examples, None, &config).unwrap();
        assert_eq!(p.ensemble.len(), 2);
        let (n, w) = p.predict(&examples[3].0);
        assert!(
            (n as f64 / examples[3].1).ln().abs() < 0.5,
            "{n} vs {}",
            examples[3].1
        );
        assert!(
            (w as f64 - examples[3].2).abs() < 0.1,
            "{w} vs {}",
            examples[3].2
        );
        // Validity for arbitrary, extreme and non-finite codes.
        for scale in [0.0f32, 1.0, 1e3, 1e30, f32::INFINITY, f32::NAN, -1e30] {
            for _ in 0..20 {
                let code: Vec<f32> = (0..32)
                    .map(|_| (rng.next_f64() as f32 * 2.0 - 1.0) * scale)
                    .collect();
                let (n, w) = p.predict(&code);
                assert!(n.is_finite() && n >= 0.0 && n as f64 <= MAX_EXPONENT, "{n}");
                assert!((0.0..=1.0).contains(&w), "{w}");
            }
        }
    }
}
