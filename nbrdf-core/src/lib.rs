//! Neural BRDFs (Sztrajman et al., CGF 2021) for Mitsuba 3: the math and learning core.
//!
//! Module map (one concept each):
//! * [`coords`]   – Rusinkiewicz half/difference angles and the network input encoding.
//! * [`merl`]     – MERL-format tables: read, write, validate, nearest and trilinear lookup.
//! * [`analytic`] – the published SGD and ABC fits of the 100 MERL materials, tabulated to tables.
//! * [`network`]  – the NBRDF multilayer perceptron, its JSON file format and batched evaluation.
//! * [`sampling`] – cosine, uniform and Blinn-Phong-mixture importance sampling with pdfs.
//! * [`train`]    – training an NBRDF on a table: samples, batched gradients, Adam, early stopping.
//! * [`phong_fit`] – fitting the 7-parameter Blinn-Phong model of a material (log loss).
//! * [`lobe_fit`] – choosing the Blinn-Phong sampling lobe `(n, w)` for the lowest variance.
//! * [`metrics`]  – image-space and log-space comparison of two materials.
//! * [`brdf`]     – the [`brdf::Brdf`] trait shared by tables and networks, SoA batch types.
//! * [`error`]    – the crate's error type.
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

pub mod analytic;
pub mod brdf;
pub mod coords;
pub mod error;
pub mod fastmath;
pub mod latent;
pub mod lobe_fit;
pub mod merl;
pub mod metrics;
pub mod network;
pub mod phong_fit;
pub mod rng;
pub mod sampling;
pub mod train;

pub use brdf::{Brdf, Directions, DirectionsMut, RgbMut};
pub use error::{NbrdfError, Result};
pub use merl::MerlTable;
pub use network::Nbrdf;
pub use sampling::SamplingStrategy;
