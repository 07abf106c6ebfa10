//! C ABI of nbrdf: one handle for a material (a neural BRDF, a spatially varying neural material
//! or a MERL table) and one for an importance sampler (any strategy, the data-driven table
//! included), with one entry point per operation: load, info, eval, sample, pdf, eval and sample
//! at texture coordinates, the network's parameters and active units.
//!
//! The header `include/nbrdf.h` is generated from this crate by cbindgen (see `cbindgen.toml`;
//! `NBRDF_BLESS=1 cargo test -p nbrdf-ffi --test header` regenerates it). The crate is a thin
//! shell around `nbrdf-core`: it checks pointers and lengths, turns errors and panics into status
//! codes with a thread-local message, and hands planar slices to the core.
//!
//! Conventions: every array is planar (structure of arrays): a batch of `n` directions is `3 n`
//! floats `[x0..x(n-1), y0..y(n-1), z0..z(n-1)]`, uniforms are `[u0.., u1.., u2..]`, colours are
//! `[r.., g.., b..]`, pdfs are `n` floats, texture coordinates `[u0.., v0..]`. Directions live
//! in the local shading frame (z = normal); `view` points towards the viewer (Mitsuba's
//! `si.wi`), `light` towards the light (Mitsuba's `wo`). Output arrays must not overlap the
//! inputs.
//!
//! Modules: [`status`] (status codes, last error, version), [`vocabulary`] (the sampling
//! strategy codes and their names), [`handles`] (what `NbrdfMaterial` and `NbrdfSampler` hold
//! and how each is made), [`material`] and [`sampler`] (the functions of each handle, which
//! build on `handles`, not on each other), [`uv`] (a material's functions at texture
//! coordinates, on `handles` too); `args` holds the argument checks they share.

#![deny(unsafe_op_in_unsafe_fn)]

mod args;
pub mod handles;
pub mod material;
pub mod sampler;
pub mod status;
pub mod uv;
pub mod vocabulary;

pub use handles::*;
pub use material::*;
pub use sampler::*;
pub use status::*;
pub use uv::*;
pub use vocabulary::*;
