//! Two Blinn-Phong lobes mixed with cosine sampling,
//! `w1 phong(n1) + w2 phong(n2) + (1 - w1 - w2) cosine`: a sharp peak over a broader glossy
//! halo or a diffuse base.

use super::hemisphere::{cosine_hemisphere, with_cosine};
use super::phong::{phong_half_vector, specular_density};
use super::{exponent_in_range, reflect, weighted, SamplingStrategy, MAX_EXPONENT};
use glam::DVec3;

/// Slack on `w1 + w2 <= 1` for weights that went through float32 (0.7f32 + 0.3f32 > 1 in f64).
pub(super) const WEIGHT_SUM_TOLERANCE: f64 = 1e-6;

/// Why the parameters are unusable, if they are.
pub(super) fn problem(
    [exponent1, exponent2]: [f64; 2],
    [weight1, weight2]: [f64; 2],
) -> Option<String> {
    for (k, n) in [(1, exponent1), (2, exponent2)] {
        if !exponent_in_range(n) {
            return Some(format!(
                "two-lobe exponent{k} {n} must be finite, in [0, {MAX_EXPONENT:e}] (MAX_EXPONENT)"
            ));
        }
    }
    for (k, w) in [(1, weight1), (2, weight2)] {
        if !(0.0..=1.0).contains(&w) {
            return Some(format!("two-lobe weight{k} {w} must be in [0, 1]"));
        }
    }
    if weight1 + weight2 > 1.0 + WEIGHT_SUM_TOLERANCE {
        return Some(format!(
            "two-lobe weights {weight1} + {weight2} must sum to at most 1"
        ));
    }
    None
}

/// Which component of a two-lobe mixture the uniform `u0` picks: `Some(1)`, `Some(2)` for the
/// Blinn-Phong lobes, `None` for cosine. `u0 = 1` with no cosine weight left (`w1 + w2 >= 1`)
/// still picks a lobe of positive weight.
fn two_lobe_component(u0: f64, weight1: f64, weight2: f64) -> Option<u8> {
    if u0 < weight1 {
        Some(1)
    } else if u0 < weight1 + weight2 {
        Some(2)
    } else if weight1 + weight2 >= 1.0 {
        Some(if weight2 > 0.0 { 2 } else { 1 })
    } else {
        None
    }
}

/// A direction of the mixture (`v` unit, `u` in `[0, 1]`).
pub(super) fn sample(
    v: DVec3,
    [exponent1, exponent2]: [f64; 2],
    [weight1, weight2]: [f64; 2],
    [u0, u1, u2]: [f64; 3],
) -> DVec3 {
    match two_lobe_component(u0, weight1, weight2) {
        Some(lobe) => {
            let exponent = if lobe == 1 { exponent1 } else { exponent2 };
            reflect(v, phong_half_vector(exponent, u1, u2))
        }
        None => cosine_hemisphere(u1, u2),
    }
}

/// The mixture's density for unit `v`, `l` (the lobes over the whole sphere).
pub(super) fn density(
    v: DVec3,
    l: DVec3,
    [exponent1, exponent2]: [f64; 2],
    [weight1, weight2]: [f64; 2],
) -> f64 {
    let phong = |n: f64, w: f64| weighted(w, || specular_density(v, l, n));
    with_cosine(
        l,
        (1.0 - weight1 - weight2).max(0.0), // float32 weights may sum to 1 + ulp
        phong(exponent1, weight1) + phong(exponent2, weight2),
    )
}

/// The two-lobe mixture's density over the whole sphere of light directions (the two-lobe
/// counterpart of [`super::phong_lobe_density`]): integrates to 1 for every view when the
/// weights sum to at most 1; 0 for invalid parameters or directions.
pub fn two_lobe_density(view: DVec3, light: DVec3, exponents: [f64; 2], weights: [f64; 2]) -> f64 {
    SamplingStrategy::TwoLobe {
        exponent1: exponents[0],
        weight1: weights[0],
        exponent2: exponents[1],
        weight2: weights[1],
    }
    .sphere_density(view, light)
}
