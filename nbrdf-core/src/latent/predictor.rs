//! The Blinn-Phong parameter predictor (DESIGN.md section 7): a shallow MLP from the 32-value
//! code to the sampling parameters `(n, w)`, supervised by Blinn-Phong fits of the training
//! split.
//!
//! Network: `32 -> 16 (tanh) -> 2` on standardised codes. Output 0 is `ln n`, clamped to
//! `[ln 1e-3, ln MAX_EXPONENT]` so that `n = e^o0` lies in `(0, 1e6]`; output 1 goes through a
//! logistic so that `w` lies in `[0, 1]`: every output is a valid sampling lobe by construction.
//! Loss: `(o0 - ln max(n, 1e-3))^2 + 25 (w_pred - w)^2` (a weight error of 0.2 costs as much as
//! a factor e in the exponent), full-batch Adam.

use super::mlp::Mlp;
use crate::error::{NbrdfError, Result};
use crate::phong_fit::MAX_EXPONENT;
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
    #[serde(default)]
    pub provenance: serde_json::Value,
}

/// A training example: code, fitted exponent, fitted specular weight.
pub type Example = (Vec<f32>, f64, f64);

fn sigmoid(x: f32) -> f32 {
    1.0 / (1.0 + (-x).exp())
}

impl PhongPredictor {
    fn raw(&self, code: &[f32]) -> Vec<f32> {
        let x: Vec<f32> = code
            .iter()
            .zip(self.code_mean.iter().zip(&self.code_std))
            .map(|(c, (m, s))| (c - m) / s)
            .collect();
        self.mlp.eval(&x)
    }

    /// `(exponent, specular_weight)` for a code: exponent in `(0, 1e6]`, weight in `[0, 1]`
    /// whatever the code (non-finite inputs give the most diffuse lobe).
    pub fn predict(&self, code: &[f32]) -> (f32, f32) {
        let o = self.raw(code);
        let ln_n = if o[0].is_finite() { o[0] } else { LN_N_MIN };
        let n = ln_n.clamp(LN_N_MIN, (MAX_EXPONENT as f32).ln()).exp();
        let w = if o[1].is_finite() { sigmoid(o[1]) } else { 0.0 };
        (n.clamp(0.0, MAX_EXPONENT as f32), w.clamp(0.0, 1.0))
    }

    pub fn train(
        examples: &[Example],
        hidden: usize,
        iterations: usize,
        seed: u64,
    ) -> Result<Self> {
        if examples.is_empty() {
            return Err(NbrdfError::InvalidArgument("no training examples".into()));
        }
        let dims = examples[0].0.len();
        let n = examples.len() as f64;
        let mut mean = vec![0.0f32; dims];
        let mut std = vec![0.0f32; dims];
        for d in 0..dims {
            let m = examples.iter().map(|e| e.0[d] as f64).sum::<f64>() / n;
            let v = examples
                .iter()
                .map(|e| (e.0[d] as f64 - m).powi(2))
                .sum::<f64>()
                / n;
            mean[d] = m as f32;
            std[d] = (v.sqrt() as f32).max(1e-6);
        }
        let mut p = PhongPredictor {
            format: FORMAT_NAME.into(),
            version: 1,
            code_mean: mean,
            code_std: std,
            mlp: Mlp::new(&[dims, hidden, 2], seed, 3 << 32),
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
            loss = 0.0;
            for (x, e) in xs.iter().zip(examples) {
                let acts = p.mlp.forward(x);
                let o = acts.last().cloned().unwrap_or_default();
                let ln_n = (e.1.max(1e-3)).ln() as f32;
                let w = sigmoid(o[1]);
                let (d0, d1) = (o[0] - ln_n, w - e.2 as f32);
                loss += (d0 * d0 + WEIGHT_LOSS * d1 * d1) as f64;
                let inv = 1.0 / n as f32;
                let g = [2.0 * d0 * inv, 2.0 * WEIGHT_LOSS * d1 * w * (1.0 - w) * inv];
                p.mlp.backward(&acts, &g, &mut grad);
            }
            adam.step(&mut params, &grad, 3e-3);
            p.mlp.set_flat(&params);
        }
        p.provenance = serde_json::json!({
            "architecture": format!("{dims}-{hidden}-2, tanh hidden; ln n clamped, w logistic"),
            "examples": examples.len(),
            "iterations": iterations,
            "final_loss": loss / n,
            "seed": seed,
        });
        Ok(p)
    }

    pub fn load(path: impl AsRef<std::path::Path>) -> Result<Self> {
        let path = path.as_ref();
        let p: PhongPredictor = super::read_json(path)?;
        if p.format != FORMAT_NAME {
            return Err(NbrdfError::InvalidArgument(format!(
                "{}: not a Phong predictor",
                path.display()
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
        let p = PhongPredictor::train(&examples, 16, 1500, 0).unwrap();
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
