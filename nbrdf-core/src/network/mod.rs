//! The NBRDF network (docs/design.md section 4): `y = exp(W3 relu(W2 relu(W1 x + b1) + b2) + b3) - 1`,
//! clamped at 0, with `x` the Rusinkiewicz input of [`crate::coords::network_input_for`]
//! (isotropic, `phi_h = 0`, unless the network is anisotropic).
//! Any hidden width.
//!
//! * this file: the [`Nbrdf`] type, its [`Layer`]s (the one dense-layer definition of the crate,
//!   [`Layer::affine_into`]), [`paper_init`], flat parameter vectors and single evaluation;
//! * `format.rs`: the versioned `*.nbrdf.json` file format, reading, writing and validation;
//! * `kernel.rs`: the batched, vectorised and threaded evaluation, the renderer's hot loop;
//! * `pruning.rs`: the hidden units no pair of directions above the horizon can activate, and
//!   the narrower network without them that renderers evaluate;
//! * `spectral.rs`: spectral networks (format version 3), whose outputs are the coefficients of
//!   a [`crate::spectral_basis::SpectralBasis`]: evaluation per wavelength and their RGB value.

mod format;
mod kernel;
mod pruning;
pub(crate) mod spectral;
#[cfg(test)]
mod tests;

pub(crate) use format::{describe_json_error, file_version, value_problem};
pub use format::{
    FORMAT_NAME, FORMAT_VERSION, FORMAT_VERSION_ANISOTROPIC, FORMAT_VERSION_ISOTROPIC,
    FORMAT_VERSION_TEXTURED,
};
#[cfg(any(target_arch = "x86", target_arch = "x86_64"))]
pub(crate) use kernel::has_avx2_fma;
pub use kernel::LANES;
pub use pruning::{active_units, ActiveUnits};
pub(crate) use spectral::check_spectral_batch;
pub use spectral::Spectral;

use crate::brdf::{Brdf, Directions, RgbMut};
use crate::coords::network_input_for;
use crate::error::{NbrdfError, Result};
use crate::fastmath::{expm1_with, relu, MulAdd};
use crate::rng::{SplitMix64, Stream};
use crate::sampling::tabulated::TableConfig;
use crate::sampling::{SamplingKind, SamplingStrategy};
use glam::{DVec3, Vec3};
use serde::{Deserialize, Deserializer, Serialize};

pub const INPUTS: usize = 6;
/// Outputs of an RGB network; a spectral network has its basis' count
/// ([`Nbrdf::output_count`]).
pub const OUTPUTS: usize = 3;
pub const DEFAULT_HIDDEN: usize = 21;

/// The only importance-sampling model the file format defines.
pub const SAMPLING_MODEL_BLINN_PHONG: &str = "blinn-phong";

/// The output activation of the networks, `max(exp(z) - 1, 0)` with the exponent's argument
/// clamped ([`expm1_with`]): finite and non-negative for every `z`, NaN included. The one
/// definition, shared by the homogeneous kernels and the spatially varying decoder.
#[inline(always)]
pub fn output_activation<M: MulAdd>(z: f32) -> f32 {
    relu(expm1_with::<M>(z))
}

/// One dense layer, `y = x W + b` with `W` row-major `inputs x outputs`: the NBRDF's layers and
/// those of the latent-space MLPs ([`crate::latent::mlp`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Layer {
    pub inputs: usize,
    pub outputs: usize,
    pub weights: Vec<f32>,
    pub bias: Vec<f32>,
}

impl Layer {
    /// `y = x W + b` for one input vector, the reference definition of a dense layer (the
    /// batched kernels restate it on lanes). `y` is as long as the outputs used; the loop over
    /// outputs is innermost, over contiguous weights.
    #[inline(always)]
    pub fn affine_into<M: MulAdd>(&self, x: &[f32], y: &mut [f32]) {
        y.copy_from_slice(&self.bias[..y.len()]);
        for (row, &xi) in self.weights.chunks_exact(self.outputs).zip(x) {
            for (yo, &w) in y.iter_mut().zip(row) {
                *yo = M::mul_add(w, xi, *yo);
            }
        }
    }
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
    /// A second, broader Blinn-Phong lobe: the mixture becomes
    /// `w1 phong(n1) + w2 phong(n2) + (1 - w1 - w2) cosine` ([`SamplingStrategy::TwoLobe`]).
    /// Optional, so version-1 files without it load and sample as before; readers that predate
    /// it ignore it and sample the first lobe with cosine, a valid (if weaker) density.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub second_lobe: Option<SecondLobe>,
    /// The exponent across the tangent of an anisotropic lobe: `exponent` becomes `n_u`
    /// (along the tangent x) and this `n_v` ([`SamplingStrategy::AnisotropicPhong`]).
    /// Optional and only for anisotropic networks (`nbrdf fit-phong` stores it); readers that
    /// predate it sample the isotropic lobe of exponent `n_u`, a valid (if weaker) density.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub exponent_v: Option<f32>,
    /// What the lobe search measured when it chose these parameters (informational).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub relative_variance: Option<SamplingVariances>,
    /// The strategy that sampled this material with the lowest measured variance; the plugin
    /// uses it when a scene gives no `sampling`. Optional: files without it sample as before.
    /// Old spellings (`two-lobe`, `blinn_phong`, ...) load as their canonical kind.
    #[serde(
        default,
        skip_serializing_if = "Option::is_none",
        deserialize_with = "deserialize_default_kind"
    )]
    pub default: Option<SamplingKind>,
    /// Weight of the defensive cosine component of the tabulated sampler
    /// ([`Nbrdf::table_config`]), in `(0, 1)`: the lowest-variance
    /// candidate of `nbrdf fit-phong`. Optional: files without it mix 0.1.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub table_cosine_weight: Option<f32>,
}

/// [`SamplingParams::default`] from its name, canonical or deprecated.
fn deserialize_default_kind<'de, D: Deserializer<'de>>(
    deserializer: D,
) -> std::result::Result<Option<SamplingKind>, D::Error> {
    let Some(name) = Option::<String>::deserialize(deserializer)? else {
        return Ok(None);
    };
    SamplingKind::parse_lenient(&name)
        .map(|parsed| Some(parsed.kind))
        .map_err(|_| {
            serde::de::Error::custom(format!(
                "unknown sampling default '{name}' (one of {})",
                SamplingKind::canonical_names()
            ))
        })
}

/// The second lobe of a two-lobe sampling mixture.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct SecondLobe {
    pub exponent: f32,
    pub specular_weight: f32,
}

/// Mean relative variance `R - 1` of BSDF sampling ([`crate::fit::lobes`]) of each strategy the
/// fit compared; `nbrdf fit-phong` stores the lowest.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct SamplingVariances {
    pub one_lobe: f64,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub two_lobe: Option<f64>,
    /// The anisotropic lobe's, for anisotropic networks; there `one_lobe` is the best
    /// isotropic lobe's on the same (all view azimuths) quadrature.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub anisotropic: Option<f64>,
    pub cosine: f64,
    /// The tabulated sampler's ([`crate::sampling::tabulated`]), when it was measured.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tabulated: Option<f64>,
}

impl SamplingParams {
    /// The first reason these parameters are unusable, if any.
    fn problem(&self) -> Option<String> {
        if self.model != SAMPLING_MODEL_BLINN_PHONG {
            return Some(format!(
                "unknown sampling model '{}' (only '{SAMPLING_MODEL_BLINN_PHONG}' is defined)",
                self.model
            ));
        }
        if !crate::sampling::exponent_in_range(f64::from(self.exponent)) {
            return Some(format!(
                "sampling exponent {} must be in [0, 1e6] (MAX_EXPONENT)",
                self.exponent
            ));
        }
        if !(0.0..=1.0).contains(&self.specular_weight) {
            return Some(format!(
                "sampling specular_weight {} must be in [0, 1]",
                self.specular_weight
            ));
        }
        if let Some(nv) = self.exponent_v {
            if !crate::sampling::exponent_in_range(f64::from(nv)) {
                return Some(format!(
                    "sampling exponent_v {nv} must be in [0, 1e6] (MAX_EXPONENT)"
                ));
            }
            if self.second_lobe.is_some() {
                return Some(
                    "sampling: exponent_v (an anisotropic lobe) and second_lobe do not combine"
                        .into(),
                );
            }
        }
        if let Some(c) = self.table_cosine_weight {
            if !(c > 0.0 && c < 1.0) {
                return Some(format!(
                    "sampling table_cosine_weight {c} must be in (0, 1)"
                ));
            }
        }
        match self.default {
            Some(SamplingKind::TwoLobe) if self.second_lobe.is_none() => {
                return Some("sampling default 'two_lobe' needs a second_lobe".to_string());
            }
            Some(SamplingKind::AnisotropicPhong) if self.exponent_v.is_none() => {
                return Some(
                    "sampling default 'anisotropic_phong' needs an exponent_v".to_string(),
                );
            }
            _ => {}
        }
        if self.second_lobe.is_some() {
            if let Err(NbrdfError::InvalidArgument(message)) = self.two_lobe_strategy().validated()
            {
                return Some(format!("sampling second_lobe: {message}"));
            }
        }
        None
    }

    fn two_lobe_strategy(&self) -> SamplingStrategy {
        let second = self.second_lobe.unwrap_or(SecondLobe {
            exponent: 0.0,
            specular_weight: 0.0,
        });
        SamplingStrategy::TwoLobe {
            exponent1: f64::from(self.exponent),
            weight1: f64::from(self.specular_weight),
            exponent2: f64::from(second.exponent),
            weight2: f64::from(second.specular_weight),
        }
    }

    /// The sampling strategy these parameters describe: the one-lobe Blinn-Phong mixture, the
    /// two-lobe one when a second lobe is stored, the anisotropic one with `exponent_v`.
    pub fn strategy(&self) -> Result<SamplingStrategy> {
        if let Some(message) = self.problem() {
            return Err(NbrdfError::InvalidArgument(message));
        }
        if let Some(nv) = self.exponent_v {
            return SamplingStrategy::anisotropic(
                f64::from(self.exponent),
                f64::from(nv),
                f64::from(self.specular_weight),
            )
            .validated();
        }
        if self.second_lobe.is_some() {
            return self.two_lobe_strategy().validated();
        }
        SamplingStrategy::Phong {
            exponent: f64::from(self.exponent),
            specular_weight: f64::from(self.specular_weight),
        }
        .validated()
    }
}

/// A neural BRDF: three dense layers plus optional sampling parameters and provenance.
#[derive(Clone, Debug, PartialEq)]
pub struct Nbrdf {
    pub name: String,
    pub layers: [Layer; 3],
    /// Whether the input carries the half vector's azimuth `phi_h`
    /// ([`crate::coords::network_input_for`]): an anisotropic network, file format version 2.
    /// Isotropic networks (the paper's, every version-1 file) see `phi_h = 0`.
    pub anisotropic: bool,
    /// The spectral basis whose coefficients the network outputs (file format version 3), or
    /// `None` for an RGB network.
    pub spectral: Option<Spectral>,
    pub sampling: Option<SamplingParams>,
    /// An analytic BSDF the network is a residual on (`f_r = base + network`): a Mitsuba 3 BSDF
    /// dictionary (`mi.load_dict`) with a string `type`, kept as written. The library evaluates
    /// and samples the network alone; a renderer adds the base (the Mitsuba plugin does).
    pub base: Option<serde_json::Value>,
    pub provenance: serde_json::Value,
}

fn empty_object() -> serde_json::Value {
    serde_json::Value::Object(serde_json::Map::new())
}

/// Half-width of the uniform weight initialisation.
const INIT_RANGE: f32 = 0.05;

/// How [`paper_init`] draws, for provenance records.
pub const INITIALISATION: &str =
    "uniform(-0.05, 0.05) weights in file order, zero biases, splitmix64 stream Init";

/// Dense layers of the given widths (`widths[k]` inputs to layer `k`) with Glorot-uniform
/// weights `U(-a, a)`, `a = sqrt(6 / (inputs + outputs))`, drawn in file order from `rng`, and
/// zero biases: the latent-space MLPs' and the spatially varying trainer's initialisation.
pub fn glorot_uniform(widths: &[usize], rng: &mut SplitMix64) -> Vec<Layer> {
    widths
        .windows(2)
        .map(|w| {
            let a = (6.0 / (w[0] + w[1]) as f64).sqrt();
            Layer {
                inputs: w[0],
                outputs: w[1],
                weights: (0..w[0] * w[1])
                    .map(|_| ((rng.next_f64() * 2.0 - 1.0) * a) as f32)
                    .collect(),
                bias: vec![0.0; w[1]],
            }
        })
        .collect()
}

/// The paper's initialisation of a `6 -> hidden -> hidden -> 3` network: weights
/// `U(-0.05, 0.05)` drawn in file order from the seed's [`Stream::Init`] stream, biases 0. The
/// one initialisation of the crate: `nbrdf train` starts from it, so a seed names the weights.
pub fn paper_init(hidden: usize, seed: u64) -> [Layer; 3] {
    paper_init_with_outputs(hidden, OUTPUTS, seed)
}

/// [`paper_init`] of a `6 -> hidden -> hidden -> outputs` network (a spectral network's
/// coefficient count); the same draws in the same order, so 3 outputs are [`paper_init`].
pub fn paper_init_with_outputs(hidden: usize, outputs: usize, seed: u64) -> [Layer; 3] {
    let mut rng = SplitMix64::new(seed, Stream::Init, 0);
    let dims = [(INPUTS, hidden), (hidden, hidden), (hidden, outputs)];
    dims.map(|(inputs, outputs)| Layer {
        inputs,
        outputs,
        weights: (0..inputs * outputs)
            .map(|_| INIT_RANGE * (2.0 * rng.next_f64() as f32 - 1.0))
            .collect(),
        bias: vec![0.0; outputs],
    })
}

/// Number of parameters of a `6 -> hidden -> hidden -> 3` network, `hidden^2 + 11 hidden + 3`.
/// Saturates at `usize::MAX` for widths whose count overflows (no slice is that long, so a
/// length compared with it never matches).
pub fn parameter_count_for(hidden: usize) -> usize {
    hidden
        .saturating_mul(hidden)
        .saturating_add(hidden.saturating_mul(11))
        .saturating_add(3)
}

impl Nbrdf {
    /// Builds a `6 -> hidden -> hidden -> 3` network from the flat parameter vector
    /// `W1, b1, W2, b2, W3, b3` (each `W` row-major `inputs x outputs`).
    pub fn from_flat(name: &str, hidden: usize, params: &[f32]) -> Result<Self> {
        if hidden == 0 {
            return Err(NbrdfError::InvalidArgument(
                "hidden width must be at least 1".into(),
            ));
        }
        let expected = parameter_count_for(hidden);
        if params.len() != expected {
            return Err(NbrdfError::InvalidArgument(format!(
                "expected {expected} parameters for hidden width {hidden}, got {}",
                params.len()
            )));
        }
        let mut rest = params;
        let mut take = |n: usize| {
            let (head, tail) = rest.split_at(n);
            rest = tail;
            head.to_vec()
        };
        let mut layer = |inputs: usize, outputs: usize| Layer {
            inputs,
            outputs,
            weights: take(inputs * outputs),
            bias: take(outputs),
        };
        let layers = [
            layer(INPUTS, hidden),
            layer(hidden, hidden),
            layer(hidden, OUTPUTS),
        ];
        let net = Nbrdf {
            name: name.to_string(),
            layers,
            anisotropic: false,
            spectral: None,
            sampling: None,
            base: None,
            provenance: empty_object(),
        };
        net.validate()?;
        Ok(net)
    }

    /// The parameters as `W1, b1, W2, b2, W3, b3` (the autoencoder's view of a network).
    pub fn to_flat(&self) -> Vec<f32> {
        let mut flat = Vec::with_capacity(self.parameter_count());
        for layer in &self.layers {
            flat.extend_from_slice(&layer.weights);
            flat.extend_from_slice(&layer.bias);
        }
        flat
    }

    /// A freshly initialised network, [`paper_init`]. A `hidden` of 0 is raised to 1 (a network
    /// needs a width).
    pub fn random(name: &str, hidden: usize, seed: u64) -> Self {
        Nbrdf {
            name: name.to_string(),
            layers: paper_init(hidden.max(1), seed),
            anisotropic: false,
            spectral: None,
            sampling: None,
            base: None,
            provenance: serde_json::json!({
                "initialisation": INITIALISATION,
                "seed": seed,
            }),
        }
    }

    /// The same network (shape, anisotropy, spectral basis, sampling) with the parameters
    /// `params`, `W1, b1, W2, b2, W3, b3` as [`Nbrdf::to_flat`] gives them.
    pub fn with_parameters(&self, params: &[f32]) -> Result<Self> {
        if params.len() != self.parameter_count() {
            return Err(NbrdfError::InvalidArgument(format!(
                "expected {} parameters, got {}",
                self.parameter_count(),
                params.len()
            )));
        }
        let mut net = self.clone();
        let mut rest = params;
        for layer in &mut net.layers {
            let (weights, tail) = rest.split_at(layer.weights.len());
            let (bias, tail) = tail.split_at(layer.bias.len());
            layer.weights.copy_from_slice(weights);
            layer.bias.copy_from_slice(bias);
            rest = tail;
        }
        net.validate()?;
        Ok(net)
    }

    /// Width of the two hidden layers.
    pub fn hidden_width(&self) -> usize {
        self.layers[0].outputs
    }

    /// Number of weights and biases (675 for width 21).
    pub fn parameter_count(&self) -> usize {
        self.layers
            .iter()
            .map(|l| l.weights.len() + l.bias.len())
            .sum()
    }

    /// `f_r` at a set of angles (`phi_h` ignored by isotropic networks) through the float32
    /// directions a renderer would hand the network, so that it equals [`Brdf::eval`] there.
    /// (Tabulation uses [`crate::coords::network_input_from_angles`] instead, exact where
    /// `theta_h` is tiny.)
    pub fn eval_at_angles(&self, angles: &crate::coords::RusinkiewiczAngles) -> [f64; 3] {
        let (view, light) = crate::coords::from_rusinkiewicz(angles);
        self.eval_input(network_input_for(
            self.anisotropic,
            view.as_vec3(),
            light.as_vec3(),
        ))
        .map(f64::from)
    }

    /// The tabulated sampler's settings, with the cosine weight the file stores, if any.
    pub fn table_config(&self) -> TableConfig {
        TableConfig::with_stored_cosine_weight(
            self.sampling.as_ref().and_then(|s| s.table_cosine_weight),
        )
    }

    /// The stored sampling strategy, if the file has one and it is valid.
    pub fn sampling_strategy(&self) -> Option<SamplingStrategy> {
        self.sampling.as_ref().and_then(|s| s.strategy().ok())
    }

    /// The MERL-format table of this network at cell-centre angles: cells whose centre has a
    /// direction at or below the horizon are marked not measured, as in the tables synthesised
    /// from analytic fits, so a network trained on the result never learns from them. This is
    /// how a network of another origin (the authors' Keras files) is distilled into a table that
    /// `nbrdf train` can learn again, e.g. from the common initialisation of the latent space.
    pub fn tabulate(&self) -> crate::merl::MerlTable {
        crate::merl::MerlTable::tabulate(|angles| {
            let (view, light) = crate::coords::from_rusinkiewicz(angles);
            if light.z <= 0.0 || view.z <= 0.0 {
                return [f64::NAN; 3];
            }
            // MERL angles have phi_h = 0: an anisotropic network is tabulated along that azimuth.
            self.eval_input(crate::coords::network_input_from_angles_for(
                self.anisotropic,
                angles,
            ))
            .map(f64::from)
        })
    }
}

impl Brdf for Nbrdf {
    fn eval(&self, view: Vec3, light: Vec3) -> [f32; 3] {
        // Normalise in float64 so that very long or very short vectors keep their direction.
        let (Some(l), Some(v)) = (normalized(light.as_dvec3()), normalized(view.as_dvec3())) else {
            return [0.0; 3];
        };
        // The horizon test in float32, the precision the batched kernel tests it in: a z that
        // underflows there (a grazing direction with huge x, y) is at the horizon in both.
        let (v, l) = (v.as_vec3(), l.as_vec3());
        if l.z <= 0.0 || v.z <= 0.0 {
            return [0.0; 3];
        }
        self.eval_input(network_input_for(self.anisotropic, v, l))
    }

    fn eval_cos_batch(&self, view: Directions<'_>, light: Directions<'_>, out: RgbMut<'_>) {
        self.eval_cos_batch_impl(view, light, out)
    }
}

/// Unit vector of a finite, non-zero vector.
fn normalized(v: DVec3) -> Option<DVec3> {
    let len = v.length();
    (v.is_finite() && len > 0.0 && len.is_finite()).then(|| v / len)
}
