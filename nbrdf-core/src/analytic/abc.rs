//! ABC model (Löw et al. 2012).
//!
//! Per channel, with `c = l . h`: `f = kd/pi + F(c) D G / (pi l.z v.z)`,
//! `D = A / (1 + B (1 - cos theta_h))^C`, `G = min(1, 2 h.z l.z / c, 2 h.z v.z / c)`, `F` the
//! unpolarised Fresnel reflectance of a dielectric with index `ior`.

use super::{finite_non_negative, geometry, Geometry};
use glam::DVec3;
use std::f64::consts::PI;

/// The parameters of one fit; field names as in the embedded `data/merl_fits.json`.
#[derive(Clone, Debug, PartialEq, serde::Deserialize)]
pub struct AbcParams {
    pub kd: [f64; 3],
    #[serde(rename = "A")]
    pub a: [f64; 3],
    #[serde(rename = "B")]
    pub b: f64,
    #[serde(rename = "C")]
    pub c: f64,
    pub ior: f64,
}

impl AbcParams {
    /// `f_r(view, light)`, zero at or below the horizon, finite and non-negative.
    pub fn eval_f64(&self, view: DVec3, light: DVec3) -> [f64; 3] {
        let Some(g) = geometry(view, light) else {
            return [0.0; 3];
        };
        // Everything but A and kd is shared by the channels.
        let fresnel = fresnel_unpolarised(self.ior, g.c);
        let lobe = (1.0 + self.b * (1.0 - g.h.z)).powf(self.c);
        let specular = fresnel * masking(&g) / (PI * g.cos_product());
        std::array::from_fn(|ch| {
            finite_non_negative(self.kd[ch] / PI + self.a[ch] / lobe * specular)
        })
    }
}

/// Cook-Torrance's V-groove masking-shadowing.
fn masking(g: &Geometry) -> f64 {
    // c > 0 whenever both directions are above the horizon; a c that rounds to 0 makes the
    // ratios infinite, and min() then picks 1 as it should.
    let two_hz_over_c = 2.0 * g.h.z / g.c;
    1.0f64.min(two_hz_over_c * g.l.z).min(two_hz_over_c * g.v.z)
}

/// Unpolarised Fresnel reflectance at `cos = c` for relative index `ior`.
pub fn fresnel_unpolarised(ior: f64, c: f64) -> f64 {
    let g2 = ior * ior + c * c - 1.0;
    if g2 < 0.0 {
        return 1.0; // total internal reflection (ior < 1 only)
    }
    let g = g2.sqrt();
    let ratio = (g - c) / (g + c);
    let tail = (c * (g + c) - 1.0) / (c * (g - c) + 1.0);
    let f = 0.5 * ratio * ratio * (1.0 + tail * tail);
    // 0/0 only for ior = 0 or ior = 1 at grazing, where the limit is total reflection.
    if f.is_nan() {
        1.0
    } else {
        f
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fresnel_limits() {
        // Normal incidence: ((n - 1) / (n + 1))^2.
        assert!((fresnel_unpolarised(1.5, 1.0) - 0.04).abs() < 1e-15);
        // Grazing incidence reflects everything; a matched index nothing.
        assert!((fresnel_unpolarised(1.5, 0.0) - 1.0).abs() < 1e-15);
        assert!(fresnel_unpolarised(1.0, 0.7).abs() < 1e-15);
        assert_eq!(fresnel_unpolarised(0.5, 0.1), 1.0);
        // 45 degrees, n = 1.5: Rs = 0.0920, Rp = 0.00847 (textbook values), mean 0.0502.
        let f = fresnel_unpolarised(1.5, std::f64::consts::FRAC_1_SQRT_2);
        assert!((f - 0.050_2).abs() < 1e-4, "{f}");
    }
}
