//! Fitting Blinn-Phong lobes to a material (docs/design.md section 6): the 7-parameter model fit
//! ([`phong`]), the sampling lobes of lowest variance of BSDF sampling, one or two
//! ([`lobes`]) or anisotropic ([`anisotropic`]), and the reflectance they read ([`target`]).
//! The `nbrdf fit-phong` command that runs them and stores the result is
//! [`crate::ops::fit_phong`].
//!
//! Arrows: `anisotropic -> lobes -> phong`; both lobe searches refine with `pattern_search`.

pub mod anisotropic;
pub mod lobes;
mod pattern_search;
pub mod phong;
pub mod target;
