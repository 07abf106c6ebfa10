//! Importance sampling of the reflected direction (DESIGN.md section 6): uniform hemisphere,
//! cosine hemisphere and the Blinn-Phong mixture
//! `pdf(l) = w (n + 1)/(2 pi) cos(theta_h)^n / (4 |v . h|) + (1 - w) max(l.z, 0)/pi`.
//!
//! Every strategy takes three uniforms in `[0, 1]` (inclusive) and the view direction; the
//! pdf is per unit solid angle of the light direction. Internally float64, so that exponents up to
//! 1e6 and uniforms at the interval ends stay finite.

use crate::brdf::{Brdf, Directions, DirectionsMut, RgbMut};
use crate::error::Result;
use glam::Vec3;

/// A sampling strategy for the light direction given the view direction.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum SamplingStrategy {
    Uniform,
    Cosine,
    /// Mixture of a Blinn-Phong lobe (exponent `n >= 0`) with weight `w` in `[0, 1]` and a cosine lobe.
    BlinnPhong { exponent: f64, specular_weight: f64 },
}

/// One sampled light direction; `pdf == 0` marks an invalid sample (below the horizon).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DirectionSample {
    pub light: Vec3,
    pub pdf: f32,
}

impl SamplingStrategy {
    /// Checks the parameters (finite exponent >= 0, weight in [0, 1]).
    pub fn validated(self) -> Result<Self> {
        todo!()
    }

    /// Draws a light direction for `view` from uniforms `u = [u0 (lobe choice), u1, u2]`.
    pub fn sample(&self, view: Vec3, u: [f32; 3]) -> DirectionSample {
        todo!()
    }

    /// Density of `light` given `view`, per unit solid angle (0 at or below the horizon).
    pub fn pdf(&self, view: Vec3, light: Vec3) -> f32 {
        todo!()
    }
}

/// Batched sampling: for each lane draws a light direction, its pdf, and the weight
/// `f_r cos / pdf` of `brdf` (0 for invalid samples). All slices have the same length.
pub fn sample_batch(
    strategy: &SamplingStrategy,
    brdf: &dyn Brdf,
    view: Directions<'_>,
    u: Directions<'_>,
    light: DirectionsMut<'_>,
    weight: RgbMut<'_>,
    pdf: &mut [f32],
) {
    todo!()
}

/// Batched pdf of `light` given `view`.
pub fn pdf_batch(strategy: &SamplingStrategy, view: Directions<'_>, light: Directions<'_>, pdf: &mut [f32]) {
    todo!()
}
