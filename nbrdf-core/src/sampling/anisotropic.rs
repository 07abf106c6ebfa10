//! An anisotropic Blinn-Phong lobe mixed with cosine sampling: Ashikhmin and Shirley's
//! half-vector distribution
//! `p(h) = sqrt((n_u + 1)(n_v + 1)) / (2 pi) cos(theta_h)^(n_u cos^2 phi + n_v sin^2 phi)`,
//! `n_u` along the tangent x, `n_v` along y. With equal exponents it is the Blinn-Phong lobe.

use super::hemisphere::{cosine_hemisphere, with_cosine};
use super::phong::{
    cos_power_from_one_minus, half_vector, half_vector_elevation, one_minus_cos_theta, picks_lobe,
};
use super::{exponent_in_range, reflect, weighted, SamplingStrategy};
use glam::DVec3;
use std::f64::consts::{FRAC_1_PI, PI, TAU};

/// Checks both exponents in `[0, MAX_EXPONENT]` and `w` in `[0, 1]`.
pub(super) fn problem(exponent_u: f64, exponent_v: f64, specular_weight: f64) -> Option<String> {
    if !(exponent_in_range(exponent_u) && exponent_in_range(exponent_v)) {
        return Some(format!(
            "anisotropic Blinn-Phong exponents {exponent_u}, {exponent_v} must be in \
             [0, 1e6] (MAX_EXPONENT)"
        ));
    }
    if !(0.0..=1.0).contains(&specular_weight) {
        return Some(format!(
            "anisotropic Blinn-Phong specular weight {specular_weight} must be in [0, 1]"
        ));
    }
    None
}

/// A direction of the mixture (`v` unit, `u` in `[0, 1]`).
pub(super) fn sample(
    v: DVec3,
    exponents: [f64; 2],
    specular_weight: f64,
    [u0, u1, u2]: [f64; 3],
) -> DVec3 {
    if picks_lobe(u0, specular_weight) {
        reflect(
            v,
            anisotropic_half_vector(exponents[0], exponents[1], u1, u2),
        )
    } else {
        cosine_hemisphere(u1, u2)
    }
}

/// The mixture's density for unit `v`, `l` (the lobe over the whole sphere).
pub(super) fn density(v: DVec3, l: DVec3, exponents: [f64; 2], specular_weight: f64) -> f64 {
    let lobe = weighted(specular_weight, || {
        anisotropic_specular_density(v, l, exponents)
    });
    with_cosine(l, 1.0 - specular_weight, lobe)
}

/// Half vector of the distribution (module docs):
/// `phi = atan(sqrt((n_u + 1)/(n_v + 1)) tan(pi xi / 2))` in each quadrant (`u1` picks the quadrant
/// and `xi`; the density is symmetric under `phi -> pi - phi, -phi`), then
/// `cos(theta_h) = u2^(1 / (n(phi) + 1))` as for the isotropic lobe.
pub fn anisotropic_half_vector(exponent_u: f64, exponent_v: f64, u1: f64, u2: f64) -> DVec3 {
    let scaled = 4.0 * u1.clamp(0.0, 1.0);
    let quadrant = scaled.floor().min(3.0);
    let xi = scaled - quadrant;
    let ratio = ((exponent_u + 1.0) / (exponent_v + 1.0)).sqrt();
    let phi0 = (ratio * (0.5 * PI * xi).tan()).atan();
    let phi = match quadrant as u8 {
        0 => phi0,
        1 => PI - phi0,
        2 => PI + phi0,
        _ => TAU - phi0,
    };
    let (sin_phi, cos_phi) = phi.sin_cos();
    let exponent = exponent_u * cos_phi * cos_phi + exponent_v * sin_phi * sin_phi;
    let (cos, sin) = half_vector_elevation(exponent, u2);
    DVec3::new(sin * cos_phi, sin * sin_phi, cos)
}

/// Density of the reflected direction under [`anisotropic_half_vector`], over the whole sphere
/// of `l` (`v`, `l` unit), as the isotropic lobe's.
fn anisotropic_specular_density(v: DVec3, l: DVec3, [nu, nv]: [f64; 2]) -> f64 {
    let Some((h, v_dot_h)) = half_vector(v, l) else {
        return 0.0;
    };
    let sin2 = h.x * h.x + h.y * h.y;
    let cos2_phi = if sin2 > 0.0 { h.x * h.x / sin2 } else { 1.0 };
    let exponent = nu * cos2_phi + nv * (1.0 - cos2_phi);
    ((nu + 1.0) * (nv + 1.0)).sqrt()
        * 0.5
        * FRAC_1_PI
        * cos_power_from_one_minus(one_minus_cos_theta(h), exponent)
        / (4.0 * v_dot_h)
}

/// The anisotropic mixture's density over the whole sphere of light directions (the anisotropic
/// counterpart of [`super::phong_lobe_density`]): integrates to 1 for every view; 0 for
/// invalid parameters or directions.
pub fn anisotropic_lobe_density(
    view: DVec3,
    light: DVec3,
    exponents: [f64; 2],
    specular_weight: f64,
) -> f64 {
    SamplingStrategy::anisotropic(exponents[0], exponents[1], specular_weight)
        .sphere_density(view, light)
}
