//! Choosing the Blinn-Phong sampling lobe `(n, w)` of a material for the lowest variance of
//! BSDF sampling (docs/design.md section 6), rather than the model fit's shape-matching lobe
//! ([`super::phong`]), which on a weak sharp spike over a diffuse base sends almost no
//! samples where the energy is. With `g(l) = f_r(l, v) cos(theta_l)` (mean over RGB) and the
//! mixture density `p`, the estimator `g / p` has the relative second moment
//!
//! `R(v) = int g^2 / p  /  I^2`,  `I = int g`   (`R - 1` is its relative variance),
//!
//! computed by quadrature over the half vector (`theta_h = pi/2 s^2`, dense near the normal),
//! averaged over view elevations and minimised over a grid of `(n, w)`. [`LobeChoice`] names the
//! two candidates; [`choose_lobe`] and [`LobeAnalysis::lobe`] pick one.
//!
//! Two lobes ([`LobeQuadrature::fit_two_lobes`]): the same objective for
//! `w1 phong(n1) + w2 phong(n2) + (1 - w1 - w2) cosine`, a coarse grid then a pattern search
//! from the better of its best and the one-lobe lobe, so never worse than one lobe.
//!
//! Files: `half_vector` (the quadrature and the terms every lobe search scores), `one_lobe`,
//! `two_lobes`, `choice` (which of the two one-lobe candidates a material gets).

mod choice;
mod half_vector;
mod one_lobe;
#[cfg(test)]
pub(crate) mod tests;
mod two_lobes;

pub use choice::{choose_lobe, model_lobe, LobeAnalysis, LobeChoice};
pub(crate) use half_vector::LobeTerms;
pub use one_lobe::{fit_lobe, LobeFit, LobeFitConfig, LobeQuadrature};
pub use two_lobes::{fit_two_lobes, TwoLobeFit};
