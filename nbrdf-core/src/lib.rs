//! Neural BRDFs (Sztrajman et al., CGF 2021) for Mitsuba 3: the math and learning core.
//!
//! Two layers. Rendering, always built and all that `nbrdf-ffi` links: [`brdf`], [`coords`],
//! [`merl`], [`network`], [`textured`] (spatially varying materials), [`rgl`], [`spectrum`],
//! [`sampling`], [`source`], [`rng`], [`fastmath`], [`error`].
//! Training and analysis (feature `train`, on by default): [`train`], [`distillation`] (spatially
//! varying materials from textured sources), [`analytic`], [`fit`] (the Blinn-Phong model fit and
//! the sampling lobe searches), [`metrics`], [`latent`] and [`ops`],
//! what each `nbrdf` command does (the CLI, feature `cli`, only parses and prints). Arrows run
//! from training to rendering only, and no two modules depend on each other (`tests/layers.rs`).
//!
//! Conventions: z = normal; `view` points towards the viewer (Mitsuba's `si.wi`), `light`
//! towards the light (`wo`). Functions taking both take **view first, then light**
//! ([`Brdf::eval`], [`coords::to_rusinkiewicz`], [`sampling::SamplingStrategy::pdf`], the C ABI's
//! `*_eval`); both are plain vectors, so a swap compiles: name arguments `view`/`light` at call
//! sites. Batches are structure-of-arrays: x, y and z (or r, g and b) each in their own slice.

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
pub mod spectral_basis;
pub mod spectrum;
pub mod textured;

#[cfg(feature = "train")]
pub mod analytic;
#[cfg(feature = "train")]
pub mod distillation;
#[cfg(feature = "train")]
pub mod fit;
#[cfg(feature = "train")]
pub mod latent;
#[cfg(feature = "train")]
pub mod metrics;
#[cfg(feature = "train")]
pub mod ops;
#[cfg(feature = "train")]
pub mod train;

pub use brdf::{Brdf, Directions, DirectionsMut, RgbMut};
pub use error::{NbrdfError, Result};
pub use merl::MerlTable;
pub use network::Nbrdf;
pub use sampling::SamplingStrategy;
