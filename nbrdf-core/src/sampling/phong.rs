//! The Blinn-Phong lobe mixed with cosine sampling:
//! `pdf(l) = w (n + 1)/(2 pi) cos(theta_h)^n / (4 |v . h|) + (1 - w) max(l.z, 0)/pi`.
//! The half-vector helpers here serve the two-lobe and anisotropic mixtures too.

use super::hemisphere::{cosine_hemisphere, spherical, with_cosine};
use super::{exponent_in_range, normalized, reflect, weighted, SamplingStrategy};
use glam::DVec3;
use std::f64::consts::FRAC_1_PI;

/// Checks `n` in `[0, MAX_EXPONENT]` and `w` in `[0, 1]`.
pub(super) fn problem(exponent: f64, specular_weight: f64) -> Option<String> {
    if !exponent_in_range(exponent) {
        return Some(format!(
            "Blinn-Phong exponent {exponent} must be in [0, 1e6] (MAX_EXPONENT)"
        ));
    }
    if !(0.0..=1.0).contains(&specular_weight) {
        return Some(format!(
            "Blinn-Phong specular weight {specular_weight} must be in [0, 1]"
        ));
    }
    None
}

/// Whether `u0` picks the lobe of weight `w` over the cosine component (always at `w >= 1`, so
/// that `u0 = 1` does too).
pub(super) fn picks_lobe(u0: f64, specular_weight: f64) -> bool {
    u0 < specular_weight || specular_weight >= 1.0
}

/// A direction of the mixture (`v` unit, `u` in `[0, 1]`).
pub(super) fn sample(
    v: DVec3,
    exponent: f64,
    specular_weight: f64,
    [u0, u1, u2]: [f64; 3],
) -> DVec3 {
    if picks_lobe(u0, specular_weight) {
        reflect(v, phong_half_vector(exponent, u1, u2))
    } else {
        cosine_hemisphere(u1, u2)
    }
}

/// The mixture's density for unit `v`, `l` (the lobe over the whole sphere, module docs of
/// [`super`]).
pub(super) fn density(v: DVec3, l: DVec3, exponent: f64, specular_weight: f64) -> f64 {
    let lobe = weighted(specular_weight, || specular_density(v, l, exponent));
    with_cosine(l, 1.0 - specular_weight, lobe)
}

/// `(cos theta_h, sin theta_h)` of a half vector drawn with `cos(theta_h) = u^(1/(n+1))`. `1 -
/// cos` comes from `expm1` so that sharp lobes (n up to 1e6), where `cos` rounds to 1, keep
/// their angular spread.
pub(super) fn half_vector_elevation(exponent: f64, u: f64) -> (f64, f64) {
    let one_minus_cos = (-(u.clamp(0.0, 1.0).ln() / (exponent + 1.0)).exp_m1()).clamp(0.0, 1.0);
    let cos = 1.0 - one_minus_cos;
    (cos, (one_minus_cos * (1.0 + cos)).sqrt())
}

/// Half vector with `cos(theta_h) = u1^(1/(n+1))` and azimuth `2 pi u2`.
pub fn phong_half_vector(exponent: f64, u1: f64, u2: f64) -> DVec3 {
    let (cos, sin) = half_vector_elevation(exponent, u1);
    spherical(cos, sin, u2)
}

/// `cos^n` from `1 - cos` in `[0, 1]`, with `cos^0 = 1` (also for `cos = 0`) and no NaN for any
/// `n >= 0`. Taking `1 - cos` rather than `cos` keeps sharp lobes exact: near the mirror
/// direction `cos` rounds to 1 while `1 - cos` (from `|h_xy|^2`) keeps its relative precision.
/// Twin: `jit/sampling.py` `_cos_power_from_one_minus` (held together by `tests/test_backends.py`).
pub(super) fn cos_power_from_one_minus(one_minus_cos: f64, n: f64) -> f64 {
    if n == 0.0 {
        1.0
    } else if one_minus_cos >= 1.0 {
        0.0
    } else {
        (n * (-one_minus_cos.max(0.0)).ln_1p()).exp()
    }
}

/// `1 - cos(theta_h)` of a unit half vector from its tangential part, `|h_xy|^2 / (1 + |h.z|)`,
/// which does not cancel as `1 - h.z` does.
pub(super) fn one_minus_cos_theta(h: DVec3) -> f64 {
    (h.x * h.x + h.y * h.y) / (1.0 + h.z.abs())
}

/// The half vector of unit `v`, `l` and `|v . h|`, or `None` where `l = -v` or `v . h = 0`
/// (no mass there).
pub(super) fn half_vector(v: DVec3, l: DVec3) -> Option<(DVec3, f64)> {
    let h = normalized(l + v)?;
    let v_dot_h = v.dot(h).abs();
    (v_dot_h > 0.0).then_some((h, v_dot_h))
}

/// Density of the reflected direction when the half vector has density
/// `(n + 1)/(2 pi) cos(theta_h)^n` on the upper hemisphere, over the whole sphere of `l`
/// (`v`, `l` unit). A half vector below the horizon is the mirror image of one above, so
/// `|h.z|` is used; 0 where `l = -v` (a single direction, no mass).
pub(super) fn specular_density(v: DVec3, l: DVec3, n: f64) -> f64 {
    let Some((h, v_dot_h)) = half_vector(v, l) else {
        return 0.0;
    };
    (n + 1.0) * 0.5 * FRAC_1_PI * cos_power_from_one_minus(one_minus_cos_theta(h), n)
        / (4.0 * v_dot_h)
}

/// The Blinn-Phong mixture's density over the whole sphere of light directions: the specular
/// term for any `l` (also below the horizon, where the sampler rejects it), the cosine term on
/// the upper hemisphere. It integrates to 1 for every view; [`SamplingStrategy::pdf`] is this
/// restricted to both directions above the horizon. Inputs need not be unit length; invalid
/// parameters or directions give 0.
pub fn phong_lobe_density(view: DVec3, light: DVec3, exponent: f64, specular_weight: f64) -> f64 {
    SamplingStrategy::Phong {
        exponent,
        specular_weight,
    }
    .sphere_density(view, light)
}
