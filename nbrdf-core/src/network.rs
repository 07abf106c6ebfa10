//! The NBRDF network (DESIGN.md section 4): `y = exp(W3 relu(W2 relu(W1 x + b1) + b2) + b3) - 1`,
//! clamped at 0, with `x` the isotropic Rusinkiewicz input of [`crate::coords::network_input`].
//! Any hidden width; the versioned `*.nbrdf.json` format; single and batched evaluation.

use crate::brdf::{Brdf, Directions, RgbMut};
use crate::error::Result;
use glam::Vec3;
use serde::{Deserialize, Serialize};
use std::path::Path;

pub const FORMAT_NAME: &str = "nbrdf";
pub const FORMAT_VERSION: u32 = 1;
pub const INPUTS: usize = 6;
pub const OUTPUTS: usize = 3;
pub const DEFAULT_HIDDEN: usize = 21;

/// One dense layer, `y = x W + b` with `W` row-major `inputs x outputs`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Layer {
    pub inputs: usize,
    pub outputs: usize,
    pub weights: Vec<f32>,
    pub bias: Vec<f32>,
}

/// Importance-sampling parameters stored with a network.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SamplingParams {
    /// Only "blinn-phong" is defined.
    pub model: String,
    pub exponent: f32,
    pub specular_weight: f32,
    /// Where the figures come from: "fit", "predicted" or "manual".
    pub source: String,
}

/// A neural BRDF: three dense layers plus optional sampling parameters and provenance.
#[derive(Clone, Debug, PartialEq)]
pub struct Nbrdf {
    pub name: String,
    pub layers: [Layer; 3],
    pub sampling: Option<SamplingParams>,
    pub provenance: serde_json::Value,
}

impl Nbrdf {
    /// Loads and validates an `*.nbrdf.json` file.
    pub fn load(path: impl AsRef<Path>) -> Result<Self> {
        todo!()
    }

    /// Parses and validates the JSON text of a network; `origin` names the source in errors.
    pub fn from_json_str(text: &str, origin: &Path) -> Result<Self> {
        todo!()
    }

    pub fn to_json_string(&self) -> String {
        todo!()
    }

    pub fn save(&self, path: impl AsRef<Path>) -> Result<()> {
        todo!()
    }

    /// Width of the two hidden layers.
    pub fn hidden_width(&self) -> usize {
        self.layers[0].outputs
    }

    /// Number of weights and biases (675 for width 21).
    pub fn parameter_count(&self) -> usize {
        self.layers.iter().map(|l| l.weights.len() + l.bias.len()).sum()
    }

    /// The raw network on one input vector: `f_r` in linear RGB, clamped at 0.
    pub fn eval_input(&self, x: [f32; 6]) -> [f32; 3] {
        todo!()
    }

    /// `f_r * cos(theta_l)` for a batch, vectorised and threaded.
    pub fn eval_cos_batch_impl(&self, view: Directions<'_>, light: Directions<'_>, out: RgbMut<'_>) {
        todo!()
    }
}

impl Brdf for Nbrdf {
    fn eval(&self, light: Vec3, view: Vec3) -> [f32; 3] {
        todo!()
    }

    fn eval_cos_batch(&self, view: Directions<'_>, light: Directions<'_>, out: RgbMut<'_>) {
        self.eval_cos_batch_impl(view, light, out)
    }
}
