//! The NBRDF network (DESIGN.md section 4): `y = exp(W3 relu(W2 relu(W1 x + b1) + b2) + b3) - 1`,
//! clamped at 0, with `x` the isotropic Rusinkiewicz input of [`crate::coords::network_input`].
//! Any hidden width; the versioned `*.nbrdf.json` format; single and batched evaluation.
//!
//! The batched path is the renderer's hot loop. It works on structure-of-arrays chunks of
//! [`LANES`] lanes so that every inner loop runs over lanes and vectorises; on x86 it runs an
//! AVX2+FMA copy of the same kernel when the CPU has those features, and rayon splits large
//! batches across threads.

use crate::brdf::{Brdf, Directions, RgbMut};
use crate::coords::{network_input, network_input_components};
use crate::error::{NbrdfError, Result};
#[cfg(any(target_arch = "x86", target_arch = "x86_64"))]
use crate::fastmath::Fused;
use crate::fastmath::{expm1_with, relu, MulAdd, Unfused};
use crate::rng::{SplitMix64, Stream};
use crate::sampling::SamplingStrategy;
use glam::{DVec3, Vec3};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::path::Path;

pub const FORMAT_NAME: &str = "nbrdf";
pub const FORMAT_VERSION: u32 = 1;
pub const INPUTS: usize = 6;
pub const OUTPUTS: usize = 3;
pub const DEFAULT_HIDDEN: usize = 21;

/// The only importance-sampling model the file format defines.
pub const SAMPLING_MODEL_BLINN_PHONG: &str = "blinn-phong";

/// Lanes per structure-of-arrays chunk: 8 AVX registers per accumulator row, enough to hide the
/// FMA latency, small enough that the accumulators stay in registers.
pub const LANES: usize = 64;

/// Lanes per rayon task: large enough that the per-task scratch set-up is noise, small enough
/// for load balancing on a 1M-lane batch.
const TASK_LANES: usize = 8192;

/// Hidden widths up to this use stack scratch; wider networks allocate once per rayon task.
const MAX_STACK_HIDDEN: usize = 64;

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
        if !(self.exponent.is_finite() && self.exponent >= 0.0) {
            return Some(format!(
                "sampling exponent {} must be finite and >= 0",
                self.exponent
            ));
        }
        if !(0.0..=1.0).contains(&self.specular_weight) {
            return Some(format!(
                "sampling specular_weight {} must be in [0, 1]",
                self.specular_weight
            ));
        }
        None
    }

    /// The sampling strategy these parameters describe.
    pub fn strategy(&self) -> Result<SamplingStrategy> {
        if let Some(message) = self.problem() {
            return Err(NbrdfError::InvalidArgument(message));
        }
        SamplingStrategy::BlinnPhong {
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
    pub sampling: Option<SamplingParams>,
    pub provenance: serde_json::Value,
}

/// What is read from a file once `format` and `version` have been checked.
#[derive(Deserialize)]
struct FileIn {
    name: String,
    layers: Vec<Layer>,
    #[serde(default)]
    sampling: Option<SamplingParams>,
    #[serde(default)]
    provenance: serde_json::Value,
}

#[derive(Serialize)]
struct FileOut<'a> {
    format: &'a str,
    version: u32,
    name: &'a str,
    layers: &'a [Layer; 3],
    #[serde(skip_serializing_if = "Option::is_none")]
    sampling: &'a Option<SamplingParams>,
    provenance: &'a serde_json::Value,
}

fn empty_object() -> serde_json::Value {
    serde_json::Value::Object(serde_json::Map::new())
}

/// Half-width of the uniform weight initialisation.
const INIT_RANGE: f32 = 0.05;

/// How [`paper_init`] draws, for provenance records.
pub const INITIALISATION: &str =
    "uniform(-0.05, 0.05) weights in file order, zero biases, splitmix64 stream Init";

/// The paper's initialisation of a `6 -> hidden -> hidden -> 3` network: weights
/// `U(-0.05, 0.05)` drawn in file order from the seed's [`Stream::Init`] stream, biases 0. The
/// one initialisation of the crate: `nbrdf train` starts from it, so a seed names the weights.
pub fn paper_init(hidden: usize, seed: u64) -> [Layer; 3] {
    let mut rng = SplitMix64::new(seed, Stream::Init, 0);
    let dims = [(INPUTS, hidden), (hidden, hidden), (hidden, OUTPUTS)];
    dims.map(|(inputs, outputs)| Layer {
        inputs,
        outputs,
        weights: (0..inputs * outputs)
            .map(|_| INIT_RANGE * (2.0 * rng.next_f64() as f32 - 1.0))
            .collect(),
        bias: vec![0.0; outputs],
    })
}

/// Number of parameters of a `6 -> hidden -> hidden -> 3` network.
pub fn parameter_count_for(hidden: usize) -> usize {
    hidden * hidden + 11 * hidden + 3
}

/// Checks the `format` and `version` fields before anything else, so that a file of another
/// kind or version is reported as such rather than as a missing field further in.
fn check_header(root: &serde_json::Value) -> std::result::Result<(), String> {
    let object = root
        .as_object()
        .ok_or("the top level is not a JSON object")?;
    match object.get("format") {
        None => {
            return Err(format!(
                "missing field \"format\" (expected \"{FORMAT_NAME}\")"
            ))
        }
        Some(serde_json::Value::String(s)) if s == FORMAT_NAME => {}
        Some(other) => return Err(format!("format is {other}, expected \"{FORMAT_NAME}\"")),
    }
    match object.get("version") {
        None => Err("missing field \"version\"".to_string()),
        Some(v) if v.as_u64() == Some(u64::from(FORMAT_VERSION)) => Ok(()),
        Some(v) => Err(format!(
            "unsupported version {v} (this build reads version {FORMAT_VERSION})"
        )),
    }
}

/// The first structural problem of a layer stack (counts, dimensions, lengths), if any.
fn shape_problem(layers: &[Layer]) -> Option<String> {
    if layers.len() != 3 {
        return Some(format!("expected 3 layers, found {}", layers.len()));
    }
    if layers[0].inputs != INPUTS {
        return Some(format!(
            "layer 1 has {} inputs, expected {INPUTS} (the Rusinkiewicz input)",
            layers[0].inputs
        ));
    }
    if layers[2].outputs != OUTPUTS {
        return Some(format!(
            "layer 3 has {} outputs, expected {OUTPUTS} (RGB)",
            layers[2].outputs
        ));
    }
    for k in 1..3 {
        if layers[k].inputs != layers[k - 1].outputs {
            return Some(format!(
                "layer dimensions do not chain: layer {} has {} outputs but layer {} has {} inputs",
                k,
                layers[k - 1].outputs,
                k + 1,
                layers[k].inputs
            ));
        }
    }
    for (k, layer) in layers.iter().enumerate() {
        if layer.outputs == 0 {
            return Some(format!("layer {} has 0 outputs", k + 1));
        }
        let expected = layer.inputs.checked_mul(layer.outputs);
        if expected != Some(layer.weights.len()) {
            return Some(format!(
                "layer {} has {} weights, expected inputs * outputs = {} * {}",
                k + 1,
                layer.weights.len(),
                layer.inputs,
                layer.outputs
            ));
        }
        if layer.bias.len() != layer.outputs {
            return Some(format!(
                "layer {} has {} bias values, expected {} (its outputs)",
                k + 1,
                layer.bias.len(),
                layer.outputs
            ));
        }
    }
    None
}

/// The first non-finite parameter, if any.
fn value_problem(layers: &[Layer]) -> Option<String> {
    for (k, layer) in layers.iter().enumerate() {
        if let Some(i) = layer.weights.iter().position(|w| !w.is_finite()) {
            return Some(format!(
                "layer {} weight {} is not finite ({}); values must fit in float32",
                k + 1,
                i,
                layer.weights[i]
            ));
        }
        if let Some(i) = layer.bias.iter().position(|b| !b.is_finite()) {
            return Some(format!(
                "layer {} bias {} is not finite ({}); values must fit in float32",
                k + 1,
                i,
                layer.bias[i]
            ));
        }
    }
    None
}

impl Nbrdf {
    /// Loads and validates an `*.nbrdf.json` file.
    pub fn load(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref();
        let text = std::fs::read_to_string(path).map_err(|e| NbrdfError::io(path, e))?;
        Self::from_json_str(&text, path)
    }

    /// Parses and validates the JSON text of a network; `origin` names the source in errors.
    pub fn from_json_str(text: &str, origin: &Path) -> Result<Self> {
        let fail = |message: String| NbrdfError::format(origin, message);
        let root: serde_json::Value = serde_json::from_str(text)
            .map_err(|e| fail(format!("not valid JSON (truncated or corrupt?): {e}")))?;
        check_header(&root).map_err(fail)?;
        let file: FileIn = serde_json::from_value(root)
            .map_err(|e| fail(format!("not a valid NBRDF network: {e}")))?;
        if let Some(message) = shape_problem(&file.layers) {
            return Err(fail(message));
        }
        if let Some(message) = file.sampling.as_ref().and_then(SamplingParams::problem) {
            return Err(fail(message));
        }
        let layers: [Layer; 3] = file
            .layers
            .try_into()
            .map_err(|_| fail("expected 3 layers".to_string()))?;
        let net = Nbrdf {
            name: file.name,
            layers,
            sampling: file.sampling,
            provenance: if file.provenance.is_null() {
                empty_object()
            } else {
                file.provenance
            },
        };
        if let Some(message) = value_problem(&net.layers) {
            return Err(fail(message));
        }
        Ok(net)
    }

    pub fn to_json_string(&self) -> String {
        let out = FileOut {
            format: FORMAT_NAME,
            version: FORMAT_VERSION,
            name: &self.name,
            layers: &self.layers,
            sampling: &self.sampling,
            provenance: &self.provenance,
        };
        // Plain structs and a JSON value with string keys: serde_json cannot fail on these.
        serde_json::to_string_pretty(&out).expect("serialising an NBRDF cannot fail")
    }

    pub fn save(&self, path: impl AsRef<Path>) -> Result<()> {
        let path = path.as_ref();
        std::fs::write(path, self.to_json_string()).map_err(|e| NbrdfError::io(path, e))
    }

    /// Checks an in-memory network (shapes, finite values, sampling parameters), e.g. after
    /// training or decoding; files are checked by [`Nbrdf::load`] already.
    pub fn validate(&self) -> Result<()> {
        let problem = shape_problem(&self.layers)
            .or_else(|| value_problem(&self.layers))
            .or_else(|| self.sampling.as_ref().and_then(SamplingParams::problem));
        match problem {
            Some(message) => Err(NbrdfError::InvalidArgument(format!(
                "network '{}': {message}",
                self.name
            ))),
            None => Ok(()),
        }
    }

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
            sampling: None,
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
            sampling: None,
            provenance: serde_json::json!({
                "initialisation": INITIALISATION,
                "seed": seed,
            }),
        }
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
            self.eval_input(crate::coords::network_input_from_angles(angles))
                .map(f64::from)
        })
    }

    /// The raw network on one input vector: `f_r` in linear RGB, clamped at 0. Same arithmetic
    /// as the batched kernel (float32, fused multiply-adds where the CPU has them, the same exp
    /// approximation; the output is `max(expm1(min(z, 80)), 0)`, always finite). A network whose layer shapes
    /// were broken through the public fields evaluates to 0 rather than panicking.
    pub fn eval_input(&self, x: [f32; 6]) -> [f32; 3] {
        if shape_problem(&self.layers).is_some() {
            return [0.0; 3];
        }
        let widest = self.layers[0].outputs.max(self.layers[1].outputs);
        if widest <= MAX_STACK_HIDDEN {
            let mut h1 = [0.0f32; MAX_STACK_HIDDEN];
            let mut h2 = [0.0f32; MAX_STACK_HIDDEN];
            self.eval_input_with(&x, &mut h1, &mut h2)
        } else {
            let mut h1 = vec![0.0f32; widest];
            let mut h2 = vec![0.0f32; widest];
            self.eval_input_with(&x, &mut h1, &mut h2)
        }
    }

    fn eval_input_with(&self, x: &[f32; 6], h1: &mut [f32], h2: &mut [f32]) -> [f32; 3] {
        #[cfg(any(target_arch = "x86", target_arch = "x86_64"))]
        if has_avx2_fma() {
            // SAFETY: the CPU supports AVX2 and FMA (checked just above), which is all that
            // `eval_input_avx2` requires; it has no other preconditions.
            return unsafe { eval_input_avx2(&self.layers, x, h1, h2) };
        }
        eval_input_generic::<Unfused>(&self.layers, x, h1, h2)
    }

    /// `f_r * cos(theta_l)` for a batch, vectorised and threaded. Lanes with either direction at
    /// or below the horizon, or with non-finite components, give 0. If the slices differ in
    /// length only the common prefix is evaluated.
    pub fn eval_cos_batch_impl(
        &self,
        view: Directions<'_>,
        light: Directions<'_>,
        out: RgbMut<'_>,
    ) {
        let n = [
            view.x.len(),
            view.y.len(),
            view.z.len(),
            light.x.len(),
            light.y.len(),
            light.z.len(),
            out.r.len(),
            out.g.len(),
            out.b.len(),
        ]
        .into_iter()
        .min()
        .unwrap_or(0);
        let (r, g, b) = (&mut out.r[..n], &mut out.g[..n], &mut out.b[..n]);
        let Some(packed) = Packed::new(self) else {
            for c in [r, g, b] {
                c.fill(0.0);
            }
            return;
        };
        let (view, light) = (view.slice(0, n), light.slice(0, n));
        if n <= TASK_LANES {
            eval_task(&packed, view, light, [r, g, b]);
            return;
        }
        r.par_chunks_mut(TASK_LANES)
            .zip(g.par_chunks_mut(TASK_LANES))
            .zip(b.par_chunks_mut(TASK_LANES))
            .enumerate()
            .for_each(|(k, ((r, g), b))| {
                let (start, end) = (k * TASK_LANES, k * TASK_LANES + r.len());
                eval_task(
                    &packed,
                    view.slice(start, end),
                    light.slice(start, end),
                    [r, g, b],
                );
            });
    }
}

impl Brdf for Nbrdf {
    fn eval(&self, view: Vec3, light: Vec3) -> [f32; 3] {
        // Normalise in float64 so that very long or very short vectors keep their direction.
        let (Some(l), Some(v)) = (normalized(light.as_dvec3()), normalized(view.as_dvec3())) else {
            return [0.0; 3];
        };
        if l.z <= 0.0 || v.z <= 0.0 {
            return [0.0; 3];
        }
        self.eval_input(network_input(v.as_vec3(), l.as_vec3()))
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

/// The network on one input vector, with the batched kernel's arithmetic (`M`); shapes are
/// checked by the caller and `h1`, `h2` are at least as long as the hidden widths.
#[inline(always)]
fn eval_input_generic<M: MulAdd>(
    layers: &[Layer; 3],
    x: &[f32; 6],
    h1: &mut [f32],
    h2: &mut [f32],
) -> [f32; 3] {
    let [l1, l2, l3] = layers;
    let h1 = &mut h1[..l1.outputs];
    let h2 = &mut h2[..l2.outputs];
    l1.affine_into::<M>(x, h1);
    h1.iter_mut().for_each(|v| *v = relu(*v));
    l2.affine_into::<M>(h1, h2);
    h2.iter_mut().for_each(|v| *v = relu(*v));
    let mut z = [0.0f32; 3];
    l3.affine_into::<M>(h2, &mut z);
    z.map(|z| relu(expm1_with::<M>(z)))
}

/// [`eval_input_generic`] compiled with AVX2 and FMA: the loops over outputs vectorise 8 wide.
#[cfg(any(target_arch = "x86", target_arch = "x86_64"))]
#[target_feature(enable = "avx2,fma")]
unsafe fn eval_input_avx2(
    layers: &[Layer; 3],
    x: &[f32; 6],
    h1: &mut [f32],
    h2: &mut [f32],
) -> [f32; 3] {
    eval_input_generic::<Fused>(layers, x, h1, h2)
}

// ---------------------------------------------------------------------------------------------
// Batched kernel.

/// Rows of a structure-of-arrays chunk: one array of lanes per feature.
type Row = [f32; LANES];

/// The weights transposed to `outputs x inputs` so that each output's weights are contiguous,
/// with the always-zero input `x[1]` dropped from the first layer.
struct Packed {
    w1: Vec<f32>,
    b1: Vec<f32>,
    w2: Vec<f32>,
    b2: Vec<f32>,
    w3: Vec<f32>,
    b3: Vec<f32>,
    hidden1: usize,
    hidden2: usize,
}

/// The input features the kernel uses: `x` without the constant `x[1] = 0`.
const USED_INPUTS: [usize; 5] = [0, 2, 3, 4, 5];

impl Packed {
    fn new(net: &Nbrdf) -> Option<Self> {
        if shape_problem(&net.layers).is_some() {
            return None;
        }
        let [l1, l2, l3] = &net.layers;
        let transpose = |layer: &Layer, rows: &[usize]| -> Vec<f32> {
            (0..layer.outputs)
                .flat_map(|o| {
                    rows.iter()
                        .map(move |&i| layer.weights[i * layer.outputs + o])
                })
                .collect()
        };
        let all = |layer: &Layer| (0..layer.inputs).collect::<Vec<_>>();
        Some(Packed {
            w1: transpose(l1, &USED_INPUTS),
            b1: l1.bias.clone(),
            w2: transpose(l2, &all(l2)),
            b2: l2.bias.clone(),
            w3: transpose(l3, &all(l3)),
            b3: l3.bias.clone(),
            hidden1: l1.outputs,
            hidden2: l2.outputs,
        })
    }
}

/// Whether this CPU can run the AVX2+FMA kernel (cached by the standard library).
#[cfg(any(target_arch = "x86", target_arch = "x86_64"))]
fn has_avx2_fma() -> bool {
    is_x86_feature_detected!("avx2") && is_x86_feature_detected!("fma")
}

/// One rayon task: picks the kernel for this CPU.
fn eval_task(packed: &Packed, view: Directions<'_>, light: Directions<'_>, out: [&mut [f32]; 3]) {
    #[cfg(any(target_arch = "x86", target_arch = "x86_64"))]
    if has_avx2_fma() {
        // SAFETY: the CPU supports AVX2 and FMA (checked just above), which is all that
        // `eval_task_avx2` requires; it has no other preconditions.
        unsafe { eval_task_avx2(packed, view, light, out) };
        return;
    }
    eval_task_generic::<Unfused>(packed, view, light, out);
}

/// The generic kernel compiled with AVX2 and FMA enabled (everything below is inlined into it).
#[cfg(any(target_arch = "x86", target_arch = "x86_64"))]
#[target_feature(enable = "avx2,fma")]
unsafe fn eval_task_avx2(
    packed: &Packed,
    view: Directions<'_>,
    light: Directions<'_>,
    out: [&mut [f32]; 3],
) {
    eval_task_generic::<Fused>(packed, view, light, out);
}

/// Scratch for the hidden activations, on the stack for the usual widths.
#[inline(always)]
fn eval_task_generic<M: MulAdd>(
    packed: &Packed,
    view: Directions<'_>,
    light: Directions<'_>,
    out: [&mut [f32]; 3],
) {
    if packed.hidden1.max(packed.hidden2) <= MAX_STACK_HIDDEN {
        let mut h1 = [[0.0f32; LANES]; MAX_STACK_HIDDEN];
        let mut h2 = [[0.0f32; LANES]; MAX_STACK_HIDDEN];
        eval_chunks::<M>(
            packed,
            view,
            light,
            out,
            &mut h1[..packed.hidden1],
            &mut h2[..packed.hidden2],
        );
    } else {
        let mut h1 = vec![[0.0f32; LANES]; packed.hidden1];
        let mut h2 = vec![[0.0f32; LANES]; packed.hidden2];
        eval_chunks::<M>(packed, view, light, out, &mut h1, &mut h2);
    }
}

#[inline(always)]
fn eval_chunks<M: MulAdd>(
    packed: &Packed,
    view: Directions<'_>,
    light: Directions<'_>,
    out: [&mut [f32]; 3],
    h1: &mut [Row],
    h2: &mut [Row],
) {
    let n = view.len();
    let sources = [light.x, light.y, light.z, view.x, view.y, view.z];
    let [r, g, b] = out;
    // Per-task buffers, reused by every chunk.
    let mut padded = [[0.0f32; LANES]; 6];
    let mut x = [[0.0f32; LANES]; 5];
    let mut cos = [0.0f32; LANES];
    let mut rgb = [[0.0f32; LANES]; 3];
    let mut start = 0;
    while start < n {
        let m = LANES.min(n - start);
        let end = start + m;
        // Full chunks are read in place; the tail, and chunks with vectors too long or short to
        // normalise in float32, go through padded copies (zero vectors are invalid and give 0),
        // so the lane loops always have a constant trip count.
        let in_place = full_rows(&sources, start);
        let done = in_place.is_some_and(|rows| build_inputs(rows, &mut x, &mut cos));
        if !done {
            for (row, src) in padded.iter_mut().zip(sources) {
                row.fill(0.0);
                row[..m].copy_from_slice(&src[start..end]);
            }
            rescale_out_of_range(&mut padded);
            build_inputs(padded.each_ref(), &mut x, &mut cos);
        }
        dense_relu_chunk::<M>(&packed.w1, &packed.b1, &x, h1);
        dense_relu_chunk::<M>(&packed.w2, &packed.b2, h1, h2);
        let direct =
            [&mut *r, &mut *g, &mut *b].map(|c| <&mut Row>::try_from(&mut c[start..end]).ok());
        if let [Some(r), Some(g), Some(b)] = direct {
            output_chunk::<M>(&packed.w3, &packed.b3, h2, &cos, [r, g, b]);
        } else {
            output_chunk::<M>(&packed.w3, &packed.b3, h2, &cos, rgb.each_mut());
            for (dst, row) in [&mut *r, &mut *g, &mut *b].into_iter().zip(&rgb) {
                dst[start..end].copy_from_slice(&row[..m]);
            }
        }
        start = end;
    }
}

/// The six direction rows of the chunk at `start` as fixed-size arrays, if it is a full chunk.
#[inline(always)]
fn full_rows<'a>(sources: &[&'a [f32]; 6], start: usize) -> Option<[&'a Row; 6]> {
    let rows = sources.map(|s| {
        s.get(start..start + LANES)
            .and_then(|s| <&Row>::try_from(s).ok())
    });
    match rows {
        [Some(a), Some(b), Some(c), Some(d), Some(e), Some(f)] => Some([a, b, c, d, e, f]),
        _ => None,
    }
}

/// Squared lengths in this range normalise accurately in float32; others are rescaled first.
#[inline(always)]
fn len2_in_range(len2: f32) -> bool {
    (len2 > 1e-30) & (len2 < 1e30)
}

/// Network inputs and `cos(theta_l)` (0 for invalid lanes) of a chunk of direction pairs.
/// Returns false, with the outputs incomplete, when some vector's squared length is outside
/// the range where float32 normalisation is accurate (the caller rescales and retries).
// Lane-indexed loops over several rows at once are the shape that vectorises here.
#[allow(clippy::needless_range_loop)]
#[inline(always)]
fn build_inputs(dirs: [&Row; 6], x: &mut [Row; 5], cos: &mut Row) -> bool {
    let mut out_of_range = 0u32;
    for j in 0..LANES {
        let [lx, ly, lz, vx, vy, vz] = dirs.map(|row| row[j]);
        let input = network_input_components(vx, vy, vz, lx, ly, lz);
        for (row, value) in x.iter_mut().zip(USED_INPUTS.map(|k| input[k])) {
            row[j] = value;
        }
        let l_len2 = lx * lx + ly * ly + lz * lz;
        let v_len2 = vx * vx + vy * vy + vz * vz;
        let in_range = len2_in_range(l_len2) & len2_in_range(v_len2);
        out_of_range += u32::from(!in_range);
        let valid = (lz > 0.0) & (vz > 0.0) & in_range;
        let c = lz * (1.0 / l_len2.sqrt());
        cos[j] = if valid { c } else { 0.0 };
    }
    out_of_range == 0
}

/// Brings each vector whose squared length would overflow or underflow float32 to a length near
/// 1 (dividing by its largest component); non-finite or zero vectors become zero (invalid).
#[allow(clippy::needless_range_loop)]
#[cold]
fn rescale_out_of_range(dirs: &mut [Row; 6]) {
    for base in [0, 3] {
        for j in 0..LANES {
            let v = [dirs[base][j], dirs[base + 1][j], dirs[base + 2][j]];
            let len2 = v[0] * v[0] + v[1] * v[1] + v[2] * v[2];
            if len2_in_range(len2) {
                continue;
            }
            let m = v[0].abs().max(v[1].abs()).max(v[2].abs());
            let scaled = if v.iter().all(|c| c.is_finite()) && m > 0.0 {
                v.map(|c| c / m)
            } else {
                [0.0; 3]
            };
            for (k, c) in scaled.into_iter().enumerate() {
                dirs[base + k][j] = c;
            }
        }
    }
}

/// `y = relu(W x + b)` over a chunk; `w` is `outputs x inputs`. The lane loop is innermost and
/// the accumulator row (8 AVX registers) stays in registers across the input loop. (Computing
/// three outputs per pass, 12 accumulators on 32 lanes, measured slower on the Zen 3 target.)
#[inline(always)]
fn dense_relu_chunk<M: MulAdd>(w: &[f32], b: &[f32], x: &[Row], y: &mut [Row]) {
    for ((w_row, &bias), y_row) in w.chunks_exact(x.len()).zip(b).zip(y.iter_mut()) {
        let acc = affine_chunk::<M>(w_row, bias, x);
        for j in 0..LANES {
            y_row[j] = relu(acc[j]);
        }
    }
}

#[inline(always)]
fn affine_chunk<M: MulAdd>(w_row: &[f32], bias: f32, x: &[Row]) -> Row {
    let mut acc = [bias; LANES];
    for (&w, x_row) in w_row.iter().zip(x) {
        for j in 0..LANES {
            acc[j] = M::mul_add(w, x_row[j], acc[j]);
        }
    }
    acc
}

/// Last layer, output activation and cosine factor.
#[inline(always)]
fn output_chunk<M: MulAdd>(w: &[f32], b: &[f32], x: &[Row], cos: &Row, rgb: [&mut Row; 3]) {
    for ((w_row, &bias), out) in w.chunks_exact(x.len()).zip(b).zip(rgb) {
        let acc = affine_chunk::<M>(w_row, bias, x);
        for j in 0..LANES {
            out[j] = relu(expm1_with::<M>(acc[j])) * cos[j];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;
    use std::path::PathBuf;

    /// Unit roundoff of float32.
    const U32: f64 = 1.0 / (1u64 << 24) as f64;

    /// Independent float64 reference: plain loops over the row-major file layout, std exp. Also
    /// returns, per channel, a rigorous bound on the rounding error any float32 evaluation of
    /// the same sums can make (`(n + 1) u` times the sum of absolute terms, propagated through
    /// the layers and through exp): where an output is a cancellation of O(1) terms (a value of
    /// 1e-6 from terms of size 1), no float32 kernel can reach 1e-5 relative accuracy.
    fn reference_f64(net: &Nbrdf, x: [f32; 6]) -> Reference {
        let mut a: Vec<f64> = x.iter().map(|&v| f64::from(v)).collect();
        let mut e = vec![0.0f64; a.len()];
        let mut out = Reference {
            value: [0.0; 3],
            rounding: [0.0; 3],
        };
        for (k, layer) in net.layers.iter().enumerate() {
            let (mut y, mut ey) = (vec![0.0f64; layer.outputs], vec![0.0f64; layer.outputs]);
            for o in 0..layer.outputs {
                let mut s = f64::from(layer.bias[o]);
                let mut magnitude = s.abs();
                let mut propagated = 0.0;
                for i in 0..layer.inputs {
                    let w = f64::from(layer.weights[i * layer.outputs + o]);
                    s += w * a[i];
                    magnitude += (w * a[i]).abs();
                    propagated += w.abs() * e[i];
                }
                let err = propagated + (layer.inputs + 1) as f64 * U32 * (magnitude + propagated);
                if k < 2 {
                    (y[o], ey[o]) = (s.max(0.0), err);
                } else {
                    out.value[o] = s.exp_m1().max(0.0);
                    out.rounding[o] = s.min(80.0).exp() * err;
                }
            }
            (a, e) = (y, ey);
        }
        out
    }

    struct Reference {
        value: [f64; 3],
        rounding: [f64; 3],
    }

    impl Reference {
        fn scaled(self, factor: f64) -> Self {
            Reference {
                value: self.value.map(|v| v * factor),
                rounding: self.rounding.map(|v| v * factor),
            }
        }

        /// 1e-5 relative plus a 1e-7 floor plus the float32 rounding bound of the sums.
        fn tolerance(&self, c: usize) -> f64 {
            1e-5 * self.value[c].abs() + 1e-7 + self.rounding[c]
        }
    }

    /// Counts values that miss plain `1e-5 relative + 1e-7` (allowed only where the sums are
    /// ill-conditioned, and then rarely).
    #[derive(Default)]
    struct Tally {
        checked: usize,
        beyond_plain: usize,
    }

    impl Tally {
        fn check(&mut self, got: f32, want: &Reference, c: usize, context: &dyn std::fmt::Display) {
            let (got, value) = (f64::from(got), want.value[c]);
            assert!(got.is_finite() && got >= 0.0, "{context}: {got}");
            assert!(
                (got - value).abs() <= want.tolerance(c),
                "{context}: channel {c}: {got} vs {value}"
            );
            self.checked += 1;
            self.beyond_plain += usize::from((got - value).abs() > 1e-5 * value.abs() + 1e-7);
        }

        fn assert_rare(&self) {
            assert!(
                self.beyond_plain * 200 <= self.checked,
                "{} of {} values miss 1e-5 relative",
                self.beyond_plain,
                self.checked
            );
        }
    }

    /// Reference `f_r cos` of a direction pair: float64 normalisation and cosine, network input
    /// from the documented encoding (whose float32 accuracy `coords` tests).
    fn reference_cos(net: &Nbrdf, v: Vec3, l: Vec3) -> Reference {
        let (l64, v64) = (l.as_dvec3(), v.as_dvec3());
        let (ln, vn) = (l64 / l64.length(), v64 / v64.length());
        if !(ln.z > 0.0 && vn.z > 0.0) {
            return Reference {
                value: [0.0; 3],
                rounding: [0.0; 3],
            };
        }
        reference_f64(net, network_input(v, l)).scaled(ln.z)
    }

    /// A network with weights like a trained one: fan-in scaled, biases non-zero, outputs from
    /// ~1e-3 to ~10 so that exp and the clamp at 0 are both exercised.
    fn test_net(hidden: usize, seed: u64) -> Nbrdf {
        let mut rng = SplitMix64::from_state(seed);
        let mut net = Nbrdf::random("test", hidden, seed);
        for layer in net.layers.iter_mut() {
            let scale = 1.5 / (layer.inputs as f32).sqrt();
            for w in layer.weights.iter_mut() {
                *w = (rng.next_f32() * 2.0 - 1.0) * scale;
            }
            for b in layer.bias.iter_mut() {
                *b = (rng.next_f32() * 2.0 - 1.0) * 0.5;
            }
        }
        net.layers[2].bias = vec![0.3, -0.2, 1.5];
        net
    }

    fn hemisphere(theta: f64, phi: f64) -> Vec3 {
        DVec3::new(
            theta.sin() * phi.cos(),
            theta.sin() * phi.sin(),
            theta.cos(),
        )
        .as_vec3()
    }

    /// Random pairs over the whole hemisphere plus grazing, mirror and degenerate ones.
    fn direction_pairs(count: usize, seed: u64) -> Vec<(Vec3, Vec3)> {
        let mut rng = SplitMix64::from_state(seed);
        let mut pairs = Vec::new();
        for _ in 0..count {
            let dir =
                |rng: &mut SplitMix64| hemisphere(rng.next_f64().acos(), 2.0 * PI * rng.next_f64());
            let (l, v) = (dir(&mut rng), dir(&mut rng));
            pairs.push((l, v));
            // Grazing: 1e-6 .. 1e-2 above the horizon.
            let t = 0.5 * PI - 10f64.powf(-6.0 + 4.0 * rng.next_f64());
            pairs.push((hemisphere(t, 2.0 * PI * rng.next_f64()), v));
            pairs.push((l, hemisphere(t, 1.0)));
            pairs.push((l, Vec3::new(-l.x, -l.y, l.z))); // mirror: theta_h = 0
            pairs.push((l * 3.0, v * 0.25)); // not unit length
        }
        pairs.extend([
            (Vec3::Z, Vec3::Z),
            (Vec3::X, Vec3::Z),
            (Vec3::new(0.0, 0.0, -1.0), Vec3::Z),
            (Vec3::ZERO, Vec3::Z),
            (Vec3::new(f32::NAN, 0.0, 1.0), Vec3::Z),
            (Vec3::new(f32::INFINITY, 0.0, 1.0), Vec3::Z),
            (Vec3::Z, Vec3::new(0.0, f32::NEG_INFINITY, 1.0)),
        ]);
        pairs
    }

    fn eval_batch(net: &Nbrdf, pairs: &[(Vec3, Vec3)]) -> Vec<[f32; 3]> {
        let n = pairs.len();
        let mut view = vec![0.0f32; 3 * n];
        let mut light = vec![0.0f32; 3 * n];
        for (i, (l, v)) in pairs.iter().enumerate() {
            for k in 0..3 {
                light[k * n + i] = l[k];
                view[k * n + i] = v[k];
            }
        }
        let mut out = vec![0.0f32; 3 * n];
        net.eval_cos_batch(
            Directions::from_planar(&view).unwrap(),
            Directions::from_planar(&light).unwrap(),
            RgbMut::from_planar(&mut out).unwrap(),
        );
        (0..n)
            .map(|i| [out[i], out[n + i], out[2 * n + i]])
            .collect()
    }

    #[test]
    fn eval_input_matches_f64_reference() {
        for hidden in [4, 21, 40, 100] {
            let net = test_net(hidden, 7 + hidden as u64);
            let mut tally = Tally::default();
            for (l, v) in direction_pairs(300, hidden as u64) {
                let x = network_input(v, l);
                if !x.iter().all(|c| c.is_finite()) {
                    // Non-finite directions are rejected before the network (tested below).
                    continue;
                }
                let got = net.eval_input(x);
                let want = reference_f64(&net, x);
                let context = format!("width {hidden} {x:?}");
                for (c, &g) in got.iter().enumerate() {
                    tally.check(g, &want, c, &context);
                }
            }
            tally.assert_rare();
        }
    }

    #[test]
    fn tabulation_holds_the_network_at_cell_centres_and_nothing_below_the_horizon() {
        let net = test_net(21, 11);
        let table = net.tabulate();
        let mut tally = Tally::default();
        let (mut valid, mut invalid) = (0, 0);
        for cell in (0..crate::merl::CELLS).step_by(997) {
            let (h, d, p) = crate::merl::cell_coordinates(cell);
            let angles = crate::merl::cell_centre_angles(h, d, p);
            let (v, l) = crate::coords::from_rusinkiewicz(&angles);
            match table.cell(cell) {
                None => {
                    assert!(
                        l.z <= 0.0 || v.z <= 0.0,
                        "cell {cell} invalid above the horizon"
                    );
                    invalid += 1;
                }
                Some(rgb) => {
                    assert!(
                        l.z > 0.0 && v.z > 0.0,
                        "cell {cell} valid below the horizon"
                    );
                    // The input written out from the angles (phi_h = 0), in float64.
                    let (st, ct) = angles.theta_h.sin_cos();
                    let (sd, cd) = angles.theta_d.sin_cos();
                    let (sp, cp) = angles.phi_d.sin_cos();
                    let x = [st, 0.0, ct, sd * cp, sd * sp, cd].map(|v| v as f32);
                    let want = reference_f64(&net, x);
                    for (c, &got) in rgb.iter().enumerate() {
                        // The table stores float64 of the float32 value: compare as float32.
                        tally.check(got as f32, &want, c, &format!("cell {cell}"));
                    }
                    valid += 1;
                }
            }
        }
        assert!(
            valid > 1000 && invalid > 100,
            "{valid} valid, {invalid} invalid"
        );
        tally.assert_rare();
    }

    #[test]
    fn batched_eval_matches_f64_reference_and_eval_input() {
        for hidden in [4, 21, 40, 100] {
            let net = test_net(hidden, 11 + hidden as u64);
            // More lanes than one rayon task so that the threaded split and the tail both run.
            let mut pairs = direction_pairs(1700, 3 * hidden as u64);
            pairs.truncate(TASK_LANES + LANES + 13);
            let got = eval_batch(&net, &pairs);
            let mut nonzero = 0;
            let (mut tally, mut tally_single) = (Tally::default(), Tally::default());
            for ((l, v), g) in pairs.iter().zip(&got) {
                let want = reference_cos(&net, *v, *l);
                // Same input vector: the scalar path must agree with the batched one.
                let single = net.eval_input(network_input(*v, *l));
                let cos = crate::brdf::cos_theta_light(*l);
                let context = format!("width {hidden} l={l} v={v}: {g:?} vs {:?}", want.value);
                for c in 0..3 {
                    tally.check(g[c], &want, c, &context);
                    tally_single.check(single[c] * cos, &want, c, &context);
                    nonzero += usize::from(g[c] > 0.0);
                }
            }
            tally.assert_rare();
            tally_single.assert_rare();
            assert!(
                nonzero > pairs.len(),
                "the test network should mostly be non-zero"
            );
        }
    }

    /// On an AVX2 machine the public entry points take the FMA kernels; the portable ones (used
    /// elsewhere) are checked here directly.
    #[test]
    fn portable_kernels_match_reference() {
        for hidden in [4, 21, 100] {
            let net = test_net(hidden, 5 + hidden as u64);
            let packed = Packed::new(&net).unwrap();
            let mut pairs = direction_pairs(60, hidden as u64);
            pairs.push((Vec3::new(1e-25, 0.0, 2e-25), Vec3::new(3e20, 0.0, 1e25)));
            let n = pairs.len();
            let mut planar = vec![0.0f32; 6 * n];
            for (i, (l, v)) in pairs.iter().enumerate() {
                for k in 0..3 {
                    planar[k * n + i] = l[k];
                    planar[(3 + k) * n + i] = v[k];
                }
            }
            let (light, view) = planar.split_at(3 * n);
            let mut out = vec![0.0f32; 3 * n];
            let [r, g, b] = {
                let (r, rest) = out.split_at_mut(n);
                let (g, b) = rest.split_at_mut(n);
                [r, g, b]
            };
            eval_task_generic::<Unfused>(
                &packed,
                Directions::from_planar(view).unwrap(),
                Directions::from_planar(light).unwrap(),
                [&mut *r, &mut *g, &mut *b],
            );
            let widest = hidden.max(1);
            let (mut h1, mut h2) = (vec![0.0; widest], vec![0.0; widest]);
            let mut tally = Tally::default();
            for (i, (l, v)) in pairs.iter().enumerate() {
                let context = format!("width {hidden} l={l} v={v}");
                if i + 1 == n {
                    // Extreme lengths: rescaled, so compare with the normalising scalar eval.
                    let want = net.eval(*v, *l).map(|f| f64::from(f) * 2.0 / 5f64.sqrt());
                    let got = [r[i], g[i], b[i]].map(f64::from);
                    assert!(
                        (0..3).all(|c| (got[c] - want[c]).abs() <= 1e-4 * want[c] + 1e-7),
                        "{context}"
                    );
                    continue;
                }
                let want = reference_cos(&net, *v, *l);
                for (c, got) in [r[i], g[i], b[i]].into_iter().enumerate() {
                    tally.check(got, &want, c, &context);
                }
                let x = network_input(*v, *l);
                if x.iter().all(|c| c.is_finite()) {
                    let single = eval_input_generic::<Unfused>(&net.layers, &x, &mut h1, &mut h2);
                    let want = reference_f64(&net, x);
                    for (c, got) in single.into_iter().enumerate() {
                        tally.check(got, &want, c, &context);
                    }
                }
            }
            tally.assert_rare();
        }
    }

    #[test]
    fn horizon_and_bad_input_give_zero() {
        let net = test_net(21, 1);
        let cases = [
            (Vec3::new(1.0, 0.0, 0.0), Vec3::Z),
            (Vec3::new(0.3, 0.0, -0.1), Vec3::Z),
            (Vec3::Z, Vec3::new(0.5, 0.0, -1e-3)),
            (Vec3::ZERO, Vec3::Z),
            (Vec3::new(f32::NAN, 0.0, 1.0), Vec3::Z),
            (Vec3::Z, Vec3::new(0.0, 0.0, f32::INFINITY)),
        ];
        for (l, v) in cases {
            assert_eq!(net.eval(v, l), [0.0; 3], "{l} {v}");
        }
        for g in eval_batch(&net, &cases) {
            assert_eq!(g, [0.0; 3]);
        }
        // Huge weights cannot produce inf or NaN.
        let mut hot = net.clone();
        hot.layers[2].bias = vec![1e30, -1e30, 0.0];
        hot.layers[1].weights.iter_mut().for_each(|w| *w *= 1e20);
        for g in eval_batch(&hot, &direction_pairs(50, 5)) {
            assert!(g.iter().all(|c| c.is_finite() && *c >= 0.0), "{g:?}");
        }
    }

    #[test]
    fn extreme_lengths_are_normalised_like_unit_vectors() {
        let net = test_net(21, 4);
        let (l, v) = (hemisphere(0.7, 0.3), hemisphere(0.4, 2.5));
        let want = net.eval(v, l).map(|f| f64::from(f) * f64::from(l.z));
        assert!(want.iter().any(|&f| f > 1e-3));
        let scales = [1e-25f32, 1e-18, 1e-3, 1.0, 7.0, 1e18, 1e25];
        let pairs: Vec<_> = scales
            .iter()
            .flat_map(|&a| scales.map(|b| (l * a, v * b)))
            .collect();
        for (pair, g) in pairs.iter().zip(eval_batch(&net, &pairs)) {
            let single = net
                .eval(pair.1, pair.0)
                .map(|f| f64::from(f) * f64::from(l.z));
            for c in 0..3 {
                let tol = 1e-4 * want[c] + 1e-7;
                assert!(
                    (f64::from(g[c]) - want[c]).abs() <= tol,
                    "{pair:?}: {g:?} vs {want:?}"
                );
                assert!(
                    (single[c] - want[c]).abs() <= tol,
                    "{pair:?}: {single:?} vs {want:?}"
                );
            }
        }
    }

    #[test]
    fn broken_shapes_evaluate_to_zero_without_panicking() {
        let mut net = test_net(21, 1);
        net.layers[1].weights.pop();
        assert_eq!(net.eval(Vec3::Z, Vec3::Z), [0.0; 3]);
        assert_eq!(eval_batch(&net, &[(Vec3::Z, Vec3::Z)]), vec![[0.0; 3]]);
        assert!(net.validate().is_err());
    }

    #[test]
    fn flat_round_trip_and_parameter_count() {
        let net = Nbrdf::random("r", DEFAULT_HIDDEN, 42);
        assert_eq!(net.parameter_count(), 675);
        assert_eq!(parameter_count_for(21), 675);
        let flat = net.to_flat();
        assert_eq!(flat.len(), 675);
        assert!(flat.iter().all(|w| (-0.05..0.05).contains(w)));
        assert_eq!(&flat[..126], &net.layers[0].weights[..]);
        assert_eq!(&flat[126..147], &[0.0; 21]);
        let back = Nbrdf::from_flat("r", 21, &flat).unwrap();
        assert_eq!(back.layers, net.layers);
        assert_eq!(back.to_flat(), flat);
        assert!(Nbrdf::from_flat("r", 21, &flat[1..]).is_err());
        assert!(Nbrdf::from_flat("r", 0, &[]).is_err());
        let mut bad = flat.clone();
        bad[300] = f32::NAN;
        assert!(Nbrdf::from_flat("r", 21, &bad).is_err());
        for hidden in [1, 4, 40, 100] {
            let n = Nbrdf::random("r", hidden, 1);
            assert_eq!(n.parameter_count(), parameter_count_for(hidden));
            assert_eq!(
                Nbrdf::from_flat("r", hidden, &n.to_flat()).unwrap().layers,
                n.layers
            );
        }
        // Deterministic per seed, different across seeds.
        assert_eq!(Nbrdf::random("r", 21, 42).layers, net.layers);
        assert_ne!(Nbrdf::random("r", 21, 43).layers, net.layers);
    }

    fn temp_path(tag: &str) -> PathBuf {
        std::env::temp_dir().join(format!(
            "nbrdf-net-test-{}-{tag}.nbrdf.json",
            std::process::id()
        ))
    }

    #[test]
    fn json_round_trip_is_exact() {
        let mut net = test_net(21, 3);
        // Values whose shortest decimal forms are long or extreme.
        net.layers[0].weights[0] = f32::MIN_POSITIVE;
        net.layers[0].weights[1] = 1.0e-45;
        net.layers[0].weights[2] = f32::MAX;
        net.layers[0].weights[3] = -0.1;
        net.layers[0].weights[4] = 16_777_217.0;
        net.sampling = Some(SamplingParams {
            model: "blinn-phong".into(),
            exponent: 210.0,
            specular_weight: 0.31,
            source: "fit".into(),
        });
        net.provenance = serde_json::json!({"epochs": 12, "loss": 0.0123, "table": "gold.binary"});
        let path = temp_path("roundtrip");
        net.save(&path).unwrap();
        let back = Nbrdf::load(&path).unwrap();
        std::fs::remove_file(&path).ok();
        assert_eq!(back, net);
        let text = net.to_json_string();
        assert!(text.contains("\"format\": \"nbrdf\"") && text.contains("\"version\": 1"));
        // Sampling and provenance are optional.
        let mut plain: serde_json::Value = serde_json::from_str(&text).unwrap();
        plain.as_object_mut().unwrap().remove("sampling");
        plain.as_object_mut().unwrap().remove("provenance");
        let back = Nbrdf::from_json_str(&plain.to_string(), Path::new("p")).unwrap();
        assert_eq!(back.sampling, None);
        assert_eq!(back.provenance, serde_json::json!({}));
        assert_eq!(back.layers, net.layers);
        assert_eq!(
            net.sampling_strategy(),
            Some(SamplingStrategy::BlinnPhong {
                exponent: 210.0,
                specular_weight: f64::from(0.31f32)
            })
        );
    }

    #[test]
    fn malformed_files_are_rejected_with_the_file_name() {
        let good: serde_json::Value = serde_json::from_str(&{
            let mut n = test_net(4, 1);
            n.sampling = Some(SamplingParams {
                model: "blinn-phong".into(),
                exponent: 10.0,
                specular_weight: 0.5,
                source: "manual".into(),
            });
            n.to_json_string()
        })
        .unwrap();
        type Edit = fn(&mut serde_json::Value);
        let cases: Vec<(&str, Edit)> = vec![
            ("format is \"keras\"", |v| v["format"] = "keras".into()),
            ("missing field \"format\"", |v| {
                v.as_object_mut().unwrap().remove("format");
            }),
            ("unsupported version 2", |v| v["version"] = 2.into()),
            ("unsupported version \"1\"", |v| v["version"] = "1".into()),
            ("expected 3 layers, found 2", |v| {
                v["layers"].as_array_mut().unwrap().pop();
            }),
            ("layer 1 has 5 inputs", |v| {
                v["layers"][0]["inputs"] = 5.into()
            }),
            ("layer 3 has 4 outputs", |v| {
                v["layers"][2]["outputs"] = 4.into()
            }),
            ("do not chain", |v| v["layers"][1]["inputs"] = 5.into()),
            ("layer 2 has 15 weights", |v| {
                v["layers"][1]["weights"].as_array_mut().unwrap().pop();
            }),
            ("layer 3 has 2 bias values", |v| {
                v["layers"][2]["bias"].as_array_mut().unwrap().pop();
            }),
            ("layer 1 weight 3 is not finite", |v| {
                v["layers"][0]["weights"][3] = serde_json::json!(1e39)
            }),
            ("layer 2 bias 1 is not finite", |v| {
                v["layers"][1]["bias"][1] = serde_json::json!(-1e300)
            }),
            ("invalid type", |v| {
                v["layers"][0]["weights"][0] = "x".into()
            }),
            ("missing field `name`", |v| {
                v.as_object_mut().unwrap().remove("name");
            }),
            ("exponent -1 must be", |v| {
                v["sampling"]["exponent"] = (-1.0).into()
            }),
            ("exponent inf must be", |v| {
                v["sampling"]["exponent"] = serde_json::json!(1e40)
            }),
            ("specular_weight 1.5", |v| {
                v["sampling"]["specular_weight"] = 1.5.into()
            }),
            ("unknown sampling model 'ggx'", |v| {
                v["sampling"]["model"] = "ggx".into()
            }),
            ("top level is not a JSON object", |v| {
                *v = serde_json::json!([1, 2])
            }),
        ];
        let origin = Path::new("materials/broken.nbrdf.json");
        for (needle, edit) in cases {
            let mut v = good.clone();
            edit(&mut v);
            let err = Nbrdf::from_json_str(&v.to_string(), origin).unwrap_err();
            let text = err.to_string();
            assert!(
                matches!(&err, NbrdfError::Format { path, .. } if path == origin),
                "{needle}: {err:?}"
            );
            assert!(text.starts_with("materials/broken.nbrdf.json: "), "{text}");
            assert!(text.contains(needle), "expected '{needle}' in: {text}");
        }
        // Truncated and non-JSON text, through a real file.
        let text = serde_json::to_string(&good).unwrap();
        let path = temp_path("truncated");
        for body in [&text[..text.len() / 2], "not json at all", ""] {
            std::fs::write(&path, body).unwrap();
            let err = Nbrdf::load(&path).unwrap_err().to_string();
            assert!(
                err.contains(&*path.to_string_lossy()) && err.contains("not valid JSON"),
                "{err}"
            );
        }
        std::fs::remove_file(&path).ok();
        let missing = temp_path("missing");
        let err = Nbrdf::load(&missing).unwrap_err();
        assert!(matches!(err, NbrdfError::Io { .. }) && err.to_string().contains("missing"));
        // The unmodified file loads.
        assert!(Nbrdf::from_json_str(&text, origin).is_ok());
    }

    #[test]
    fn wide_and_narrow_networks_use_the_right_scratch() {
        // Width above the stack limit, and unequal hidden widths (allowed by the format).
        let net = test_net(MAX_STACK_HIDDEN + 1, 9);
        let pairs = direction_pairs(20, 1);
        for ((l, v), g) in pairs.iter().zip(eval_batch(&net, &pairs)) {
            let want = reference_cos(&net, *v, *l);
            (0..3).for_each(|c| Tally::default().check(g[c], &want, c, &"wide"));
        }
        let mut uneven = test_net(5, 2);
        let other = test_net(8, 3);
        uneven.layers[1] = Layer {
            inputs: 5,
            outputs: 8,
            weights: other.layers[1].weights[..40].to_vec(),
            bias: other.layers[1].bias.clone(),
        };
        uneven.layers[2] = other.layers[2].clone();
        uneven.validate().unwrap();
        for ((l, v), g) in pairs.iter().zip(eval_batch(&uneven, &pairs)) {
            let want = reference_cos(&uneven, *v, *l);
            (0..3).for_each(|c| Tally::default().check(g[c], &want, c, &"uneven"));
        }
    }
}
