//! Shifted gamma distribution model (Bagher et al. 2012).
//!
//! Per channel, with `c = l . h`:
//! `f = (rho_d + rho_s F(c) D(theta_h) G1(l) G1(v) / (l.z v.z)) / pi`,
//! `F(c) = f0 - c f1 + (1 - c)^5 (1 - f0)`,
//! `D = kap exp(-a) / (pi a^p cos^4 theta_h)`, `a = alpha + tan^2(theta_h) / alpha`,
//! `G1(k) = clamp(1 + lambda (1 - exp(c_ max(0, theta_k - theta0)^k_)), 0, 1)`.

use super::{finite_non_negative, geometry, Geometry};
use glam::DVec3;
use std::f64::consts::PI;

/// The parameters of one fit; field names as in the embedded `data/merl_fits.json`.
#[derive(Clone, Debug, PartialEq, serde::Deserialize)]
pub struct SgdParams {
    pub rho_d: [f64; 3],
    pub rho_s: [f64; 3],
    pub alpha: [f64; 3],
    pub p: [f64; 3],
    pub f0: [f64; 3],
    pub f1: [f64; 3],
    pub kap: [f64; 3],
    pub lambda: [f64; 3],
    pub c: [f64; 3],
    pub k: [f64; 3],
    pub theta0: [f64; 3],
}

impl SgdParams {
    /// `f_r(view, light)`, zero at or below the horizon, finite and non-negative.
    pub fn eval_f64(&self, view: DVec3, light: DVec3) -> [f64; 3] {
        match geometry(view, light) {
            Some(g) => std::array::from_fn(|ch| self.channel(ch, &g)),
            None => [0.0; 3],
        }
    }

    fn channel(&self, ch: usize, g: &Geometry) -> f64 {
        let f = fresnel(self.f0[ch], self.f1[ch], g.c);
        let d = distribution(self.kap[ch], self.alpha[ch], self.p[ch], g.h.z);
        let shadow = |k: DVec3| {
            shadowing(
                self.lambda[ch],
                self.c[ch],
                self.k[ch],
                self.theta0[ch],
                k.z,
            )
        };
        let specular = self.rho_s[ch] * f * d * shadow(g.l) * shadow(g.v) / g.cos_product();
        finite_non_negative((self.rho_d[ch] + specular) / PI)
    }
}

/// The fitted Fresnel term; the fit may make it negative, which the caller clamps in the sum.
fn fresnel(f0: f64, f1: f64, c: f64) -> f64 {
    f0 - c * f1 + (1.0 - c).powi(5) * (1.0 - f0)
}

/// The shifted gamma distribution `kap exp(-a) / (pi a^p cos^4)` of `cos theta_h`.
fn distribution(kap: f64, alpha: f64, p: f64, cos_h: f64) -> f64 {
    let cos2 = cos_h * cos_h;
    if cos2 <= 0.0 {
        return 0.0;
    }
    let tan2 = (1.0 - cos2).max(0.0) / cos2;
    let a = alpha + tan2 / alpha;
    let decay = (-a).exp();
    // Near grazing half vectors exp(-tan^2/alpha) underflows long before cos^4 does; returning
    // its limit avoids 0/0.
    if decay == 0.0 {
        return 0.0;
    }
    kap * decay / (PI * a.powf(p) * cos2 * cos2)
}

/// `G1` of a direction with `cos theta = cos_k`.
fn shadowing(lambda: f64, c: f64, k: f64, theta0: f64, cos_k: f64) -> f64 {
    if lambda == 0.0 {
        // Also avoids 0 * inf when c x^k overflows the exponential.
        return 1.0;
    }
    let x = (cos_k.clamp(-1.0, 1.0).acos() - theta0).max(0.0);
    // 1 + lambda (1 - exp(e)) = 1 - lambda expm1(e), accurate for the tiny e of most fits.
    let g = 1.0 - lambda * (c * x.powf(k)).exp_m1();
    if g.is_nan() {
        0.0
    } else {
        g.clamp(0.0, 1.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn terms_match_their_formulas() {
        assert!((fresnel(0.3, 0.1, 1.0) - 0.2).abs() < 1e-15);
        assert!((fresnel(0.3, 0.1, 0.0) - 1.0).abs() < 1e-15);
        // theta_h = 0: a = alpha.
        let d = distribution(2.0, 0.2, 0.5, 1.0);
        assert!((d - 2.0 * (-0.2f64).exp() / (PI * 0.2f64.sqrt())).abs() < 1e-14);
        // Below theta0 nothing is shadowed; beyond it the exponential bites.
        assert_eq!(shadowing(3.0, 1.0, 2.0, 0.5, 0.95), 1.0);
        let theta: f64 = 1.2;
        let expect = 1.0 + 0.5 * (1.0 - (0.8 * (theta - 0.5f64).powi(2)).exp());
        assert!((shadowing(0.5, 0.8, 2.0, 0.5, theta.cos()) - expect).abs() < 1e-14);
        assert_eq!(shadowing(1e7, 1e38, 800.0, 0.6, 1e-9), 0.0);
        assert_eq!(shadowing(0.0, 1e38, 800.0, 0.6, 1e-9), 1.0);
        assert_eq!(distribution(5.0, 0.1, 0.7, 1e-200), 0.0);
    }
}
