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
//! Conventions (see DESIGN.md section 2): local shading frame with z = normal; `light` is the
//! direction towards the light (Mitsuba's `wo`), `view` towards the viewer (Mitsuba's `si.wi`).
//! Batches are structure-of-arrays: x, y and z (or r, g and b) each in their own slice.

pub mod analytic;
pub mod brdf;
pub mod coords;
pub mod error;
pub mod latent;
pub mod lobe_fit;
pub mod merl;
pub mod metrics;
pub mod network;
pub mod phong_fit;
pub mod rgl;
pub mod sampling;
pub mod train;

pub use brdf::{Brdf, Directions, DirectionsMut, RgbMut};
pub use error::{NbrdfError, Result};
pub use merl::MerlTable;
pub use network::Nbrdf;
pub use sampling::SamplingStrategy;
