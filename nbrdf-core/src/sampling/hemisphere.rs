//! The hemisphere strategies and the cosine component of every mixture: uniform,
//! `pdf = 1 / (2 pi)`, and cosine-weighted, `pdf = max(l.z, 0) / pi`.

use glam::DVec3;
use std::f64::consts::{FRAC_1_PI, TAU};

/// Direction with polar cosine `cos_theta` and azimuth `2 pi u` (z = normal).
pub(super) fn spherical(cos_theta: f64, sin_theta: f64, u: f64) -> DVec3 {
    let (sin_phi, cos_phi) = (TAU * u).sin_cos();
    DVec3::new(sin_theta * cos_phi, sin_theta * sin_phi, cos_theta)
}

/// Uniform on the upper hemisphere, `pdf = 1 / (2 pi)` ([`uniform_density`]).
pub fn uniform_hemisphere(u1: f64, u2: f64) -> DVec3 {
    let z = u1.clamp(0.0, 1.0);
    spherical(z, ((1.0 - z) * (1.0 + z)).max(0.0).sqrt(), u2)
}

/// Density of [`uniform_hemisphere`] on the upper hemisphere.
pub(super) fn uniform_density() -> f64 {
    0.5 * FRAC_1_PI
}

/// Cosine-weighted on the upper hemisphere, `pdf = cos(theta) / pi` ([`cosine_density`]).
pub fn cosine_hemisphere(u1: f64, u2: f64) -> DVec3 {
    let u1 = u1.clamp(0.0, 1.0);
    spherical((1.0 - u1).sqrt(), u1.sqrt(), u2)
}

/// Density of [`cosine_hemisphere`], 0 below the horizon.
pub(super) fn cosine_density(l: DVec3) -> f64 {
    with_cosine(l, 1.0, 0.0)
}

/// A lobe mixture's density: its lobes' part plus `cosine_weight cos(theta_l) / pi`.
pub(super) fn with_cosine(l: DVec3, cosine_weight: f64, lobes: f64) -> f64 {
    lobes + cosine_weight * l.z.max(0.0) * FRAC_1_PI
}
