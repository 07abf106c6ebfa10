//! Neural BRDFs (Sztrajman et al., CGF 2021) for Mitsuba 3: the math and learning core.
//!
//! # Where each concept lives
//!
//! Rendering (always built; all that `nbrdf-ffi` links):
//! * [`brdf`]     – the [`Brdf`] trait shared by tables and networks, SoA batch types.
//! * [`coords`]   – Rusinkiewicz half/difference angles and the network input encoding.
//! * [`merl`]     – MERL-format tables: file I/O (read, write, validate) and lookup (nearest,
//!   trilinear, the `phi_d` folds).
//! * [`network`]  – the NBRDF multilayer perceptron: its JSON file format and the batched
//!   evaluation kernel (scalar and AVX2).
//! * [`rng`], [`fastmath`] – the seeded SplitMix64 streams and the `exp`/`ln` approximations
//!   shared by evaluation and training.
//! * [`rgl`]      – RGL `.bsdf` measurements (Dupuy and Jakob 2018): the tensor file, the
//!   Marginal2D warp and `f_r` evaluated exactly as Mitsuba's `measured` plugin does.
//! * [`sampling`] – cosine, uniform and Blinn-Phong-mixture importance sampling with pdfs.
//! * [`error`]    – the crate's error type.
//!
//! Training and analysis (feature `train`, on by default):
//! * [`train`]    – training an NBRDF on a table: samples, batched gradients, Adam, early stopping.
//! * [`analytic`] – the published SGD and ABC fits of the 100 MERL materials, tabulated to tables.
//! * [`target`]   – `f_r` by Rusinkiewicz angles of a network, what fits and searches read.
//! * [`phong_fit`] – fitting the 7-parameter Blinn-Phong model of a material (log loss).
//! * [`lobe_fit`] – choosing the Blinn-Phong sampling lobe `(n, w)`: lowest variance or model fit
//!   ([`lobe_fit::LobeChoice`]).
//! * [`metrics`]  – image-space and log-space comparison of two materials.
//! * [`latent`]   – the latent space: the autoencoder (data preparation, weight-space warm start,
//!   image phase, code refinement), the predictor of sampling lobes from codes, the PCA baseline.
//! * [`ops`]      – what each `nbrdf` command does, one function per command, with serialisable
//!   reports: the command-line tool only parses arguments, calls one of them and prints.
//!
//! The `nbrdf` command-line tool itself (`src/bin/nbrdf/`) needs the feature `cli`.
//!
//! Conventions: local shading frame with z = normal; `view` is the direction towards the viewer
//! (Mitsuba's `si.wi`), `light` towards the light (Mitsuba's `wo`). Every function that takes or
//! returns both directions does so in Mitsuba's order, **view first, then light**:
//! [`Brdf::eval`]`(view, light)`, [`Brdf::eval_cos_batch`]`(view, light, out)`,
//! [`coords::to_rusinkiewicz`]`(view, light)`, [`coords::from_rusinkiewicz`] returns
//! `(view, light)`, [`sampling::SamplingStrategy::pdf`]`(view, light)`, and the C ABI's
//! `*_eval(handle, view, light, ...)`. Both are plain vectors, so a swap compiles: name
//! arguments `view`/`light` (or `v`/`l`) at call sites. Batches are structure-of-arrays: x, y
//! and z (or r, g and b) each in their own slice.

pub mod brdf;
pub mod coords;
pub mod error;
pub mod fastmath;
pub mod merl;
pub mod network;
pub mod rgl;
pub mod rng;
pub mod sampling;
pub mod source;
pub mod tabulated;

#[cfg(feature = "train")]
pub mod analytic;
#[cfg(feature = "train")]
pub mod anisotropic_lobe_fit;
#[cfg(feature = "train")]
pub mod latent;
#[cfg(feature = "train")]
pub mod lobe_fit;
#[cfg(feature = "train")]
pub mod metrics;
#[cfg(feature = "train")]
pub mod ops;
#[cfg(feature = "train")]
mod pattern_search;
#[cfg(feature = "train")]
pub mod phong_fit;
#[cfg(feature = "train")]
pub mod target;
#[cfg(feature = "train")]
pub mod train;

pub use brdf::{Brdf, Directions, DirectionsMut, RgbMut};
pub use error::{NbrdfError, Result};
pub use merl::MerlTable;
pub use network::Nbrdf;
pub use sampling::SamplingStrategy;
