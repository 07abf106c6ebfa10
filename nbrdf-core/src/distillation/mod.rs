//! Distilling a textured source into a spatially varying material ([`crate::textured`],
//! docs/textured.md, "Distillation"), after Zeltner et al. 2023: the cost does not grow
//! with the texture's size.
//!
//! Each texel of the source has `P` parameters (every texture its BSDF reads, at that texel).
//! The caller evaluates the source at random texels and directions ([`TexturedSamples`]); an
//! encoder MLP (`P -> C`) and the decoder (`6 + C -> RGB`, or to the coefficients of a spectral
//! basis when the samples are spectra) are trained jointly on those samples with the homogeneous
//! trainer's log-space loss, Adam and learning-rate schedule ([`train_textured`]). [`bake`] then
//! writes the encoder's code of every texel's parameters into the latent texture, and each
//! texel's sampling lobes: those of its nearest of at most `K` representative codes, fitted to
//! the decoder (its RGB value) with the homogeneous lobe fitter.
//!
//! * `samples.rs`: the samples as given and as trained on;
//! * `dense.rs`: a trainable stack of dense layers of any widths;
//! * `joint.rs`: the encoder and decoder's joint gradient, and encoding texels;
//! * `trainer.rs`: the settings and the training run;
//! * `representatives.rs`: clustering the codes and fitting their lobes;
//! * `bake.rs`: the material from a model and a parameter image.

mod bake;
mod dense;
mod joint;
mod representatives;
mod samples;
#[cfg(test)]
mod tests;
mod trainer;

pub use bake::{bake, BakeConfig, BakeStage, ParameterImage};
pub use representatives::{MAX_CLUSTERED_CODES, MAX_REPRESENTATIVES};
pub use samples::{TargetKind, TargetValues, TexturedSamples};
pub use trainer::{train_textured, TexturedModel, TexturedTrainConfig};
