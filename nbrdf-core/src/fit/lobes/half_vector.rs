//! The midpoint quadrature over the half vector of one view, and the terms of a lobe mixture's
//! relative second moment on it: what the isotropic ([`super::LobeQuadrature`]) and the
//! anisotropic ([`crate::fit::anisotropic`]) lobe searches score.

use crate::coords::to_rusinkiewicz;
use crate::train::dataset::TargetFn;
use glam::DVec3;
use std::f64::consts::{FRAC_1_PI, FRAC_PI_2, PI};

/// What a lobe mixture's second moment needs at each quadrature point of one view where
/// `g = f_r cos` is positive; the isotropic and the anisotropic lobe searches share it.
#[derive(Default)]
pub(crate) struct LobeTerms {
    /// `g^2 dω_l` of each point.
    pub g2_dw: Vec<f64>,
    pub ln_cos_h: Vec<f64>,
    /// `1 / (4 v.h)`: the Jacobian from half-vector to light density.
    pub inv_jacobian: Vec<f64>,
    /// Cosine density `l.z / pi`.
    pub cosine_pdf: Vec<f64>,
    /// `(int g)^2`.
    pub integral_sq: f64,
}

impl LobeTerms {
    /// The terms of the half-vector quadrature of `view` (`visit_half_vectors`'s `phi_range`
    /// and `weight`); `extra` sees each point too, for what only one search keeps.
    pub(crate) fn collect(
        target: &TargetFn<'_>,
        view: DVec3,
        bins: (usize, usize),
        phi_range: f64,
        weight: f64,
        mut extra: impl FnMut(&HalfVectorPoint),
    ) -> Self {
        let mut terms = LobeTerms::default();
        let mut integral = 0.0;
        visit_half_vectors(target, view, bins, phi_range, weight, |p| {
            integral += p.g * p.dw_l;
            terms.g2_dw.push(p.g * p.g * p.dw_l);
            terms.ln_cos_h.push(p.cos_h.max(1e-300).ln());
            terms.inv_jacobian.push(0.25 / p.v_dot_h);
            terms.cosine_pdf.push(p.light.z * FRAC_1_PI);
            extra(p);
        });
        terms.integral_sq = integral * integral;
        terms
    }

    /// Relative second moment `R = sum(g^2 dω / pdf) / (int g)^2` of the density `pdf(i)` at
    /// point `i`; 1 where `g` vanishes, infinite where the density misses a point. The lobe
    /// searches (one lobe, several, anisotropic, any strategy) differ only in `pdf`.
    pub(crate) fn relative_second_moment(&self, pdf: impl Fn(usize) -> f64) -> f64 {
        if self.integral_sq <= 0.0 {
            return 1.0;
        }
        let mut sum = 0.0;
        for (i, &g2) in self.g2_dw.iter().enumerate() {
            let p = pdf(i);
            if p <= 0.0 {
                return f64::INFINITY;
            }
            sum += g2 / p;
        }
        sum / self.integral_sq
    }

    /// The Blinn-Phong lobe of exponent `n` (normalised `norm`) at point `i`, as a light density.
    pub(crate) fn lobe_density(&self, i: usize, n: f64, norm: f64) -> f64 {
        norm * (n * self.ln_cos_h[i]).exp() * self.inv_jacobian[i]
    }
}

/// A point of the half-vector quadrature of one view where `g = f_r cos(theta_l)` (mean over
/// RGB) is positive.
pub(crate) struct HalfVectorPoint {
    pub light: DVec3,
    pub g: f64,
    /// The light directions' solid angle of the point, `4 (v.h) dω_h`.
    pub dw_l: f64,
    pub cos_h: f64,
    pub cos_phi_h: f64,
    pub v_dot_h: f64,
}

/// Visits the points of the midpoint quadrature of `view` over the half vector:
/// `s = sqrt(theta_h / (pi/2))` in `s_bins` bins (dense near the normal like the MERL grid, so
/// lobes of `n ~ 1e5` are resolved) and `phi_h` in `phi_bins` bins over `[0, phi_span)`, each
/// point counting `multiplicity` times (2 where `phi_h` over `[0, pi]` stands for the whole
/// circle of an isotropic material seen from the xz plane). Points whose light is at or below
/// the horizon, or where `g` is not positive, are skipped. The one quadrature of
/// [`super::LobeQuadrature`] and [`crate::fit::anisotropic`].
pub(crate) fn visit_half_vectors(
    target: &TargetFn<'_>,
    view: DVec3,
    (s_bins, phi_bins): (usize, usize),
    phi_span: f64,
    multiplicity: f64,
    mut visit: impl FnMut(&HalfVectorPoint),
) {
    let ds = 1.0 / s_bins as f64;
    let dphi = phi_span / phi_bins as f64;
    for i in 0..s_bins {
        let s = (i as f64 + 0.5) * ds;
        let theta_h = FRAC_PI_2 * s * s;
        let (sin_h, cos_h) = theta_h.sin_cos();
        // dω_h = sin(theta_h) dtheta_h dphi_h, dtheta_h = pi s ds.
        let dw_h = multiplicity * sin_h * PI * s * ds * dphi;
        for j in 0..phi_bins {
            let phi_h = (j as f64 + 0.5) * dphi;
            let (sin_p, cos_p) = phi_h.sin_cos();
            let half = DVec3::new(sin_h * cos_p, sin_h * sin_p, cos_h);
            let v_dot_h = view.dot(half);
            if v_dot_h <= 0.0 {
                continue;
            }
            let light = 2.0 * v_dot_h * half - view;
            if light.z <= 0.0 {
                continue;
            }
            let f = target(&to_rusinkiewicz(view, light)).unwrap_or([0.0; 3]);
            let f_mean = f.iter().map(|x| x.max(0.0)).sum::<f64>() / 3.0;
            let g = f_mean * light.z;
            if !(g.is_finite() && g > 0.0) {
                continue;
            }
            visit(&HalfVectorPoint {
                light,
                g,
                dw_l: 4.0 * v_dot_h * dw_h,
                cos_h,
                cos_phi_h: cos_p,
                v_dot_h,
            });
        }
    }
}
