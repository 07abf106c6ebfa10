//! Evaluation of an [`RglMeasurement`] as Mitsuba 3's `measured` BSDF (`src/bsdfs/measured.cpp`)
//! does in an RGB variant, in float32 and in the order of operations of Mitsuba 3.9's compiled
//! scalar plugin, fused multiply-adds and Dr.Jit's own `atan2`/`asin` included (a deliberate
//! second copy of that plugin, held to it by `tests/test_rgl_reader.py`: the two agree to the
//! last bit on all but a few in ten thousand direction pairs, and within 10 ulp on those).
//!
//! Directions are in the local shading frame (z = normal). `view` is Mitsuba's `si.wi`, `light`
//! its `wo`. Mitsuba's `eval` returns `f_r(view, light) cos(theta_light)`: the stored tables
//! already carry the cosine, so [`RglMeasurement::eval`] divides it out.

use super::warp::SliceWeights;
use super::RglMeasurement;
use crate::brdf::{par_eval_pairs, Brdf, Directions, RgbMut};
use crate::error::{NbrdfError, Result};
use glam::Vec3;
use std::f32::consts::PI;

/// `measured.cpp`'s `theta2u`: the square-root warp of the elevation.
#[inline(always)]
fn theta2u(theta: f32) -> f32 {
    (theta * (2.0 / PI)).sqrt()
}

/// `measured.cpp`'s `phi2u`: `[-pi, pi] -> [0, 1]`.
#[inline(always)]
fn phi2u(phi: f32) -> f32 {
    (phi + PI) * (0.5 * std::f32::consts::FRAC_1_PI)
}

/// The elevation of a unit vector, accurate near the pole (`measured.cpp`'s `elevation`).
#[inline(always)]
fn elevation(d: Vec3) -> f32 {
    let dz = d.z - 1.0;
    // Mitsuba's build fuses this sum as fma(dz, dz, fma(x, x, y * y)).
    let sq = dz.mul_add(dz, d.x.mul_add(d.x, d.y * d.y));
    let dist = sq.sqrt();
    2.0 * asin((0.5 * dist).clamp(-1.0, 1.0))
}

/// Dr.Jit's polynomial evaluation (Estrin's scheme; `drjit/math.h`), `c[0] + c[1] x + ...`.
#[inline(always)]
fn estrin<const N: usize>(x: f32, mut coeffs: [f32; N]) -> f32 {
    let (mut n, mut x) = (N, x);
    while n > 1 {
        let pairs = n / 2;
        for i in 0..pairs {
            coeffs[i] = x.mul_add(coeffs[2 * i + 1], coeffs[2 * i]);
        }
        if n % 2 == 1 {
            coeffs[pairs] = coeffs[n - 1];
        }
        n = n.div_ceil(2);
        x *= x;
    }
    coeffs[0]
}

/// Dr.Jit's single-precision `asin` (CEPHES-based, `drjit/math.h`), which Mitsuba's scalar
/// variants use: libm's `asinf` rounds differently, and the elevation feeds a square-root warp
/// that amplifies the difference near the pole. Coefficients as Dr.Jit writes them.
#[inline(always)]
#[allow(clippy::excessive_precision)]
fn asin(x: f32) -> f32 {
    let xa = x.abs();
    let big = xa > 0.5;
    let x1 = 0.5 * (1.0 - xa);
    let x3 = if big { x1 } else { x * x };
    let x4 = if big { x1.sqrt() } else { xa };
    let mut z = estrin(
        x3,
        [
            1.666_675_2e-1,
            7.495_300_3e-2,
            4.547_002_6e-2,
            2.418_131_1e-2,
            4.216_32e-2,
        ],
    );
    z = z.mul_add(x3 * x4, x4);
    let r = if big { 0.5 * PI - (z + z) } else { z };
    r.copysign(x)
}

/// Dr.Jit's single-precision `atan2` (minimax fit, `drjit/math.h`), as Mitsuba's scalar variants
/// compute the azimuths.
#[inline(always)]
fn atan2(y: f32, x: f32) -> f32 {
    let (abs_x, abs_y) = (x.abs(), y.abs());
    let min_val = if abs_y < abs_x { abs_y } else { abs_x };
    let max_val = if abs_x > abs_y { abs_x } else { abs_y };
    if max_val == 0.0 {
        return 0.0;
    }
    let scaled_min = min_val / max_val;
    let z = scaled_min * scaled_min;
    #[allow(clippy::excessive_precision)]
    let mut t = estrin(
        z,
        [
            0.999_999_341_666_839_660_09,
            -0.333_264_975_187_736_069_76,
            0.198_813_423_884_390_135_52,
            -0.134_867_089_384_569_731_85,
            0.083_863_120_428_809_689_910,
            -0.037_006_525_670_417_265_220,
            0.007_861_379_371_319_815_025_2,
        ],
    );
    t *= scaled_min;
    if abs_y > abs_x {
        t = 0.5 * PI - t;
    }
    if x < 0.0 {
        t = PI - t;
    }
    if y < 0.0 {
        -t
    } else {
        t
    }
}

/// drjit's `mulsign_neg(a, b)`: `a` with its sign flipped unless `b` has its sign bit set.
#[inline(always)]
fn mulsign_neg(a: f32, b: f32) -> f32 {
    if b.is_sign_negative() {
        a
    } else {
        -a
    }
}

/// drjit's `normalize`: `v * (1 / sqrt(|v|^2))`.
#[inline(always)]
fn normalize(v: Vec3) -> Vec3 {
    // The horizontal sum of Mitsuba's build: y^2 + (x^2 + z^2), not fused.
    let squared = (v.x * v.x + v.z * v.z) + v.y * v.y;
    v * (1.0 / squared.sqrt())
}

/// Where a direction pair reads the reflectance tables: the position in their sample space, the
/// incident angles they are interpolated in, and the Jacobian factor (files with the flag).
struct Lookup {
    sample: [f32; 2],
    phi_i: f32,
    theta_i: f32,
    scale: Option<f32>,
}

impl RglMeasurement {
    /// The directions' [`Lookup`], `None` where Mitsuba's `measured` returns zero (a direction
    /// at or below the horizon, or no half vector).
    fn lookup(&self, view: Vec3, light: Vec3) -> Option<Lookup> {
        let (mut wi, mut wo) = (view, light);
        if !(wi.z > 0.0 && wo.z > 0.0) {
            return None;
        }
        if self.reduction >= 2 {
            let sy = wi.y;
            let sx = if self.reduction == 4 { wi.x } else { sy };
            wi.x = mulsign_neg(wi.x, sx);
            wi.y = mulsign_neg(wi.y, sy);
            wo.x = mulsign_neg(wo.x, sx);
            wo.y = mulsign_neg(wo.y, sy);
        }
        let m = normalize(wo + wi);
        // Grazing directions on opposite sides: the half vector's squared length underflows and
        // normalising it gives NaN (in Mitsuba too); there is no reflection to measure there.
        if !m.is_finite() {
            return None;
        }
        let theta_i = elevation(wi);
        let phi_i = atan2(wi.y, wi.x);
        let theta_m = elevation(m);
        let phi_m = atan2(m.y, m.x);

        let u_wi = [theta2u(theta_i), phi2u(phi_i)];
        let mut u_m = [
            theta2u(theta_m),
            phi2u(if self.isotropic { phi_m - phi_i } else { phi_m }),
        ];
        u_m[1] -= u_m[1].floor();

        let params = [phi_i, theta_i];
        let (sample, _) = self.vndf.invert(u_m, &self.vndf.weights(&params));
        let scale = self.jacobian.then(|| {
            let none = self.ndf.weights(&[]);
            self.ndf.eval(u_m, &none) / (4.0 * self.sigma.eval(u_wi, &none))
        });
        Some(Lookup {
            sample,
            phi_i,
            theta_i,
            scale,
        })
    }

    /// What Mitsuba's `measured` BSDF returns from `eval(ctx, si, wo)` with `si.wi = view` and
    /// `wo = light` in an RGB variant: `f_r cos(theta_light)`, zero unless both directions are
    /// above the horizon. Directions must be unit vectors (as Mitsuba assumes). Values can be
    /// slightly negative where the RGB fit of the spectral measurement is out of gamut, as in
    /// Mitsuba. For a spectral file, the sRGB projection of its spectrum (Mitsuba's RGB variants
    /// refuse those files).
    pub fn eval_cos_f32(&self, view: Vec3, light: Vec3) -> [f32; 3] {
        let Some(at) = self.lookup(view, light) else {
            return [0.0; 3];
        };
        let mut rgb = [0.0f32; 3];
        for (channel, value) in rgb.iter_mut().enumerate() {
            let weights: SliceWeights = self.rgb.weights(&[at.phi_i, at.theta_i, channel as f32]);
            *value = self.rgb.eval(at.sample, &weights);
        }
        if let Some(scale) = at.scale {
            rgb.iter_mut().for_each(|v| *v *= scale);
        }
        rgb
    }

    /// What Mitsuba's `measured` BSDF returns in a spectral variant, `f_r cos(theta_light)`, at
    /// each of `wavelengths` (nm), written to `out` (the common prefix of the two slices).
    /// Wavelengths that are not finite or lie outside the measured range give 0: Mitsuba
    /// extends the first and last spectra there (its interpolation clamps), which only matters
    /// for files measured over less than the 360-830 nm it samples (docs/design.md section 9).
    /// An RGB file has no spectra: an error, and `out` is left untouched.
    pub fn eval_spectrum_cos_f32(
        &self,
        view: Vec3,
        light: Vec3,
        wavelengths: &[f32],
        out: &mut [f32],
    ) -> Result<()> {
        let Some(spectra) = &self.spectra else {
            return Err(NbrdfError::InvalidArgument(format!(
                "{}: an RGB measurement has no spectra (a spectral file has a \"wavelengths\" field)",
                self.path.display()
            )));
        };
        let measured = spectra.wavelengths();
        let (first, last) = (measured[0], measured[measured.len() - 1]);
        let at = self.lookup(view, light);
        for (value, &wavelength) in out.iter_mut().zip(wavelengths) {
            *value = match &at {
                Some(at) if (first..=last).contains(&wavelength) => {
                    let weights = spectra.table.weights(&[at.phi_i, at.theta_i, wavelength]);
                    let v = spectra.table.eval(at.sample, &weights);
                    at.scale.map_or(v, |scale| v * scale)
                }
                _ => 0.0,
            };
        }
        Ok(())
    }

    /// `f_r(view, light)` (not cosine weighted) in linear RGB: Mitsuba's `eval` divided by
    /// `cos(theta_light)`. Zero unless both unit directions are above the horizon; can be
    /// slightly negative (see [`RglMeasurement::eval_cos_f32`]).
    pub fn eval(&self, view: Vec3, light: Vec3) -> [f64; 3] {
        let value = self.eval_cos_f32(view, light);
        if light.z > 0.0 {
            value.map(|v| v as f64 / light.z as f64)
        } else {
            [0.0; 3]
        }
    }

    /// [`RglMeasurement::eval_cos_f32`] for a batch, in parallel: the common prefix of the
    /// slices (components included); outputs past it are left untouched.
    pub fn eval_cos_batch_f32(&self, view: Directions<'_>, light: Directions<'_>, out: RgbMut<'_>) {
        par_eval_pairs(view, light, out, |v, l| self.eval_cos_f32(v, l));
    }
}

/// The measurement as a reflectance function: directions are normalised first and negative
/// (out-of-gamut) values clamped to zero, as the trait requires. `f = f cos / cos` grows without
/// bound as the light approaches the horizon (cosines down to 1e-45 in float32), so it saturates
/// at `f32::MAX` rather than becoming infinite; `f cos` itself is always finite (the loader
/// checks the tables' range).
impl Brdf for RglMeasurement {
    fn eval(&self, view: Vec3, light: Vec3) -> [f32; 3] {
        let (view, light) = (view.normalize_or_zero(), light.normalize_or_zero());
        RglMeasurement::eval(self, view, light).map(|v| v.clamp(0.0, f64::from(f32::MAX)) as f32)
    }

    fn eval_cos_batch(&self, view: Directions<'_>, light: Directions<'_>, out: RgbMut<'_>) {
        par_eval_pairs(view, light, out, |v, l| {
            self.eval_cos_f32(v.normalize_or_zero(), l.normalize_or_zero())
                .map(|x| x.max(0.0))
        });
    }
}
