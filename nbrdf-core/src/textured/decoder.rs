//! The decoder of a spatially varying material: a stack of dense layers ([`Layer::affine_into`])
//! reading the six direction features of [`crate::coords::network_input_for`] followed by the
//! `C` channels of the latent code, ReLU between layers and the networks' output activation
//! ([`output_activation`]) at the end, giving `f_r` in linear RGB or, for a spectral decoder,
//! the coefficients of `f_r`'s spectrum in a [`Spectral`] basis (as a version-3 network's).

use crate::error::{NbrdfError, Result};
use crate::fastmath::{relu, MulAdd};
use crate::network::{output_activation, value_problem, Layer, Spectral, INPUTS, OUTPUTS};

/// The most latent channels a material may have (docs/formats.md).
pub const MAX_LATENT_CHANNELS: usize = 32;
/// The most dense layers of a decoder.
pub const MAX_DECODER_LAYERS: usize = 8;
/// The widest layer of a decoder: the forward pass keeps its activations on the stack.
pub const MAX_DECODER_WIDTH: usize = 256;

/// A validated decoder: `layers[0]` has `6 + latent_channels` inputs, the last layer 3 outputs
/// (RGB) or a spectral basis' count.
#[derive(Clone, Debug, PartialEq)]
pub struct Decoder {
    layers: Vec<Layer>,
    latent_channels: usize,
    anisotropic: bool,
    spectral: Option<Spectral>,
}

impl Decoder {
    /// Checks the shapes (chaining from `6 + latent_channels` inputs to 3 outputs, or to
    /// `spectral`'s count, within the limits above) and that every parameter is finite.
    /// `anisotropic` feeds the half vector's azimuth as [`crate::network::Nbrdf::anisotropic`]
    /// does.
    pub fn new(
        layers: Vec<Layer>,
        latent_channels: usize,
        anisotropic: bool,
        spectral: Option<Spectral>,
    ) -> Result<Self> {
        let outputs = spectral.as_ref().map_or(OUTPUTS, Spectral::count);
        let problem =
            shape_problem(&layers, latent_channels, outputs).or_else(|| value_problem(&layers));
        if let Some(problem) = problem {
            return Err(NbrdfError::InvalidArgument(problem));
        }
        Ok(Decoder {
            layers,
            latent_channels,
            anisotropic,
            spectral,
        })
    }

    pub fn layers(&self) -> &[Layer] {
        &self.layers
    }

    /// `C`, the channels of the latent code.
    pub fn latent_channels(&self) -> usize {
        self.latent_channels
    }

    pub fn anisotropic(&self) -> bool {
        self.anisotropic
    }

    /// The spectral basis whose coefficients the decoder outputs, `None` for RGB.
    pub fn spectral(&self) -> Option<&Spectral> {
        self.spectral.as_ref()
    }

    /// The last layer's width: 3, or the spectral basis' count.
    pub fn output_count(&self) -> usize {
        self.spectral.as_ref().map_or(OUTPUTS, Spectral::count)
    }

    /// `f_r` in linear RGB (not cosine weighted) of the direction features and a latent code of
    /// [`Decoder::latent_channels`] values (shorter codes are padded with 0, longer ones cut):
    /// the outputs, or a spectral decoder's sRGB projection `M c` ([`Decoder::rgb_of`]).
    /// Finite and non-negative for finite inputs.
    #[inline(always)]
    pub fn forward<M: MulAdd>(&self, features: &[f32; INPUTS], code: &[f32]) -> [f32; OUTPUTS] {
        self.forward_with::<M, _>(features, code, |outputs| self.rgb_of(outputs))
    }

    /// The RGB value of outputs of this decoder: themselves, or `M c` for a spectral decoder
    /// ([`Spectral::project`]).
    #[inline(always)]
    pub fn rgb_of(&self, outputs: &[f32]) -> [f32; OUTPUTS] {
        match &self.spectral {
            None => [outputs[0], outputs[1], outputs[2]],
            Some(spectral) => spectral.project(outputs),
        }
    }

    /// `finish` of the decoder's [`Decoder::output_count`] outputs (RGB `f_r`, or its spectral
    /// coefficients), which it may change in place; the activations stay on the stack.
    #[inline(always)]
    pub fn forward_with<M: MulAdd, R>(
        &self,
        features: &[f32; INPUTS],
        code: &[f32],
        finish: impl FnOnce(&mut [f32]) -> R,
    ) -> R {
        let mut a = [0.0f32; MAX_DECODER_WIDTH];
        let mut b = [0.0f32; MAX_DECODER_WIDTH];
        let inputs = INPUTS + self.latent_channels;
        a[..INPUTS].copy_from_slice(features);
        let latent = code.len().min(self.latent_channels);
        a[INPUTS..INPUTS + latent].copy_from_slice(&code[..latent]);
        let (mut x, mut y) = (&mut a, &mut b);
        let mut width = inputs;
        let last = self.layers.len() - 1;
        for (k, layer) in self.layers.iter().enumerate() {
            let out = &mut y[..layer.outputs];
            layer.affine_into::<M>(&x[..width], out);
            if k < last {
                out.iter_mut().for_each(|v| *v = relu(*v));
            } else {
                out.iter_mut().for_each(|v| *v = output_activation::<M>(*v));
            }
            width = layer.outputs;
            std::mem::swap(&mut x, &mut y);
        }
        finish(&mut x[..width])
    }
}

/// The first structural problem of a decoder's layers whose last layer must have `outputs`
/// outputs (3, or the spectral count), if any, naming the layer (from 1).
fn shape_problem(layers: &[Layer], latent_channels: usize, outputs: usize) -> Option<String> {
    if !(1..=MAX_LATENT_CHANNELS).contains(&latent_channels) {
        return Some(format!(
            "latent.channels {latent_channels} must be in [1, {MAX_LATENT_CHANNELS}]"
        ));
    }
    if !(1..=MAX_DECODER_LAYERS).contains(&layers.len()) {
        return Some(format!(
            "layers: {} layers, expected 1 to {MAX_DECODER_LAYERS}",
            layers.len()
        ));
    }
    let mut inputs = INPUTS + latent_channels;
    for (k, layer) in layers.iter().enumerate() {
        let n = k + 1;
        if layer.inputs != inputs {
            let what = if k == 0 {
                format!("6 direction features + latent.channels = {inputs}")
            } else {
                format!("{inputs}, the outputs of layer {k}")
            };
            return Some(format!(
                "layers: layer {n} has {} inputs, expected {what}",
                layer.inputs
            ));
        }
        let last = k + 1 == layers.len();
        if last && layer.outputs != outputs {
            let what = if outputs == OUTPUTS {
                "RGB"
            } else {
                "spectral.count"
            };
            return Some(format!(
                "layers: layer {n}, the last, has {} outputs, expected {outputs} ({what})",
                layer.outputs
            ));
        }
        if !(1..=MAX_DECODER_WIDTH).contains(&layer.outputs) {
            return Some(format!(
                "layers: layer {n} has {} outputs, expected 1 to {MAX_DECODER_WIDTH}",
                layer.outputs
            ));
        }
        if layer.weights.len() != layer.inputs * layer.outputs {
            return Some(format!(
                "layers: layer {n} has {} weights, expected inputs * outputs = {} * {}",
                layer.weights.len(),
                layer.inputs,
                layer.outputs
            ));
        }
        if layer.bias.len() != layer.outputs {
            return Some(format!(
                "layers: layer {n} has {} bias values, expected {} (its outputs)",
                layer.bias.len(),
                layer.outputs
            ));
        }
        inputs = layer.outputs;
    }
    None
}
