//! Importance sampling of the reflected direction (docs/design.md section 6): uniform hemisphere,
//! cosine hemisphere and the Blinn-Phong mixture
//! `pdf(l) = w (n + 1)/(2 pi) cos(theta_h)^n / (4 |v . h|) + (1 - w) max(l.z, 0)/pi`, and its
//! two-lobe extension `w1 phong(n1) + w2 phong(n2) + (1 - w1 - w2) cosine`.
//!
//! Every strategy takes three uniforms in `[0, 1]` (inclusive) and the view direction; the
//! pdf is per unit solid angle of the light direction. Internally float64, so that exponents up to
//! 1e6 and uniforms at the interval ends stay finite.
//!
//! The pdf a sample reports is computed from the float32 direction it returns, by the same
//! function as [`SamplingStrategy::pdf`], so the two agree exactly (what MIS needs).

use crate::brdf::{common_len, Brdf, Directions, DirectionsMut, RgbMut};
use crate::error::{NbrdfError, Result};
use glam::{DVec3, Vec3};
use rayon::prelude::*;
use std::f64::consts::{FRAC_1_PI, TAU};
use std::sync::Arc;

mod kind;

pub use crate::tabulated::TabulatedSampler;
pub use kind::{ParsedKind, SamplingKind, UnknownSamplingCode, UnknownSamplingKind};

/// Lanes per rayon task in the batched functions.
const TASK_LANES: usize = 4096;

/// The largest Blinn-Phong exponent accepted (docs/design.md promises stable sampling up to
/// here; docs/hardening.md). The plugin's `jit.py`/`bsdf.py` use the same figure.
pub const MAX_EXPONENT: f64 = 1e6;

/// Whether `n` is a usable Blinn-Phong exponent: finite, in `[0, MAX_EXPONENT]`.
pub fn exponent_in_range(n: f64) -> bool {
    (0.0..=MAX_EXPONENT).contains(&n)
}

/// A sampling strategy for the light direction given the view direction.
#[derive(Clone, Debug, PartialEq)]
pub enum SamplingStrategy {
    Uniform,
    Cosine,
    /// Mixture of a Blinn-Phong lobe (exponent `n >= 0`) with weight `w` in `[0, 1]` and a cosine lobe.
    Phong {
        exponent: f64,
        specular_weight: f64,
    },
    /// Mixture of two Blinn-Phong lobes and a cosine lobe,
    /// `w1 phong(n1) + w2 phong(n2) + (1 - w1 - w2) cosine` ([`two_lobe_density`]): a sharp peak
    /// over a broader glossy halo or a diffuse base. Weights in `[0, 1]` with `w1 + w2 <= 1`,
    /// exponents in `[0, MAX_EXPONENT]`; by convention (that of the lobe fit)
    /// `exponent1 >= exponent2`, though the density does not depend on the order.
    TwoLobe {
        exponent1: f64,
        weight1: f64,
        exponent2: f64,
        weight2: f64,
    },
    /// Mixture of an anisotropic Blinn-Phong lobe (Ashikhmin and Shirley's half-vector
    /// distribution, exponent `exponent_u` along the tangent x and `exponent_v` along y) with
    /// weight `w` and a cosine lobe ([`anisotropic_lobe_density`]), for anisotropic networks.
    /// With equal exponents it is [`SamplingStrategy::Phong`].
    AnisotropicPhong {
        exponent_u: f64,
        exponent_v: f64,
        specular_weight: f64,
    },
    /// The data-driven half-vector table of a material with a defensive cosine component
    /// ([`crate::tabulated`]).
    Tabulated(Arc<TabulatedSampler>),
}

impl SamplingStrategy {
    /// The strategy's family, without its parameters.
    pub fn kind(&self) -> SamplingKind {
        match self {
            SamplingStrategy::Uniform => SamplingKind::Uniform,
            SamplingStrategy::Cosine => SamplingKind::Cosine,
            SamplingStrategy::Phong { .. } => SamplingKind::Phong,
            SamplingStrategy::TwoLobe { .. } => SamplingKind::TwoLobe,
            SamplingStrategy::AnisotropicPhong { .. } => SamplingKind::AnisotropicPhong,
            SamplingStrategy::Tabulated(_) => SamplingKind::Tabulated,
        }
    }

    /// An anisotropic Blinn-Phong mixture ([`SamplingStrategy::AnisotropicPhong`]).
    pub fn anisotropic(exponent_u: f64, exponent_v: f64, specular_weight: f64) -> Self {
        SamplingStrategy::AnisotropicPhong {
            exponent_u,
            exponent_v,
            specular_weight,
        }
    }
}

/// Slack on `w1 + w2 <= 1` for weights that went through float32 (0.7f32 + 0.3f32 > 1 in f64).
const WEIGHT_SUM_TOLERANCE: f64 = 1e-6;

/// One sampled light direction; `pdf == 0` marks an invalid sample (below the horizon).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DirectionSample {
    pub light: Vec3,
    pub pdf: f32,
}

impl SamplingStrategy {
    /// Checks the parameters (exponent in [0, [`MAX_EXPONENT`]], weight in [0, 1]).
    pub fn validated(self) -> Result<Self> {
        if let SamplingStrategy::Phong {
            exponent,
            specular_weight,
        } = self
        {
            if !exponent_in_range(exponent) {
                return Err(NbrdfError::InvalidArgument(format!(
                    "Blinn-Phong exponent {exponent} must be in [0, 1e6] (MAX_EXPONENT)"
                )));
            }
            if !(0.0..=1.0).contains(&specular_weight) {
                return Err(NbrdfError::InvalidArgument(format!(
                    "Blinn-Phong specular weight {specular_weight} must be in [0, 1]"
                )));
            }
        }
        if let Some(problem) = self.two_lobe_problem() {
            return Err(NbrdfError::InvalidArgument(problem));
        }
        if let SamplingStrategy::AnisotropicPhong {
            exponent_u,
            exponent_v,
            specular_weight,
        } = self
        {
            if !(exponent_in_range(exponent_u) && exponent_in_range(exponent_v)) {
                return Err(NbrdfError::InvalidArgument(format!(
                    "anisotropic Blinn-Phong exponents {exponent_u}, {exponent_v} must be in \
                     [0, 1e6] (MAX_EXPONENT)"
                )));
            }
            if !(0.0..=1.0).contains(&specular_weight) {
                return Err(NbrdfError::InvalidArgument(format!(
                    "anisotropic Blinn-Phong specular weight {specular_weight} must be in [0, 1]"
                )));
            }
        }
        Ok(self)
    }

    /// Why the parameters of a [`SamplingStrategy::TwoLobe`] are unusable, if they are.
    fn two_lobe_problem(&self) -> Option<String> {
        let SamplingStrategy::TwoLobe {
            exponent1,
            weight1,
            exponent2,
            weight2,
        } = *self
        else {
            return None;
        };
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

    /// Whether the parameters are usable; unusable ones give pdf 0 everywhere instead of NaN.
    fn params_ok(&self) -> bool {
        match *self {
            SamplingStrategy::Phong {
                exponent,
                specular_weight,
            } => exponent_in_range(exponent) && (0.0..=1.0).contains(&specular_weight),
            SamplingStrategy::TwoLobe { .. } => self.two_lobe_problem().is_none(),
            SamplingStrategy::AnisotropicPhong {
                exponent_u,
                exponent_v,
                specular_weight,
            } => {
                exponent_in_range(exponent_u)
                    && exponent_in_range(exponent_v)
                    && (0.0..=1.0).contains(&specular_weight)
            }
            _ => true,
        }
    }

    /// Draws a light direction for `view` from uniforms `u = [u0 (lobe choice), u1, u2]`.
    /// Uniforms outside `[0, 1]` are clamped (NaN counts as 0). The pdf is 0 when the view is at
    /// or below the horizon, when the specular lobe reflects below the horizon, and for invalid
    /// parameters.
    pub fn sample(&self, view: Vec3, u: [f32; 3]) -> DirectionSample {
        let u = u.map(unit_interval);
        let light = normalized(view.as_dvec3())
            .filter(|_| self.params_ok())
            .map(|v| self.sample_direction(v, u))
            .and_then(normalized)
            .map_or(Vec3::Z, |l| l.as_vec3());
        DirectionSample {
            light,
            pdf: self.pdf(view, light),
        }
    }

    /// The direction before rounding to float32; `v` is unit length.
    fn sample_direction(&self, v: DVec3, [u0, u1, u2]: [f64; 3]) -> DVec3 {
        match *self {
            SamplingStrategy::Uniform => uniform_hemisphere(u1, u2),
            SamplingStrategy::Cosine => cosine_hemisphere(u1, u2),
            SamplingStrategy::Tabulated(ref table) => table.sample_direction(v, [u0, u1, u2]),
            SamplingStrategy::Phong {
                exponent,
                specular_weight,
            } => {
                if u0 < specular_weight || specular_weight >= 1.0 {
                    let h = blinn_phong_half_vector(exponent, u1, u2);
                    2.0 * v.dot(h) * h - v
                } else {
                    cosine_hemisphere(u1, u2)
                }
            }
            SamplingStrategy::TwoLobe {
                exponent1,
                weight1,
                exponent2,
                weight2,
            } => match two_lobe_component(u0, weight1, weight2) {
                Some(lobe) => {
                    let exponent = if lobe == 1 { exponent1 } else { exponent2 };
                    let h = blinn_phong_half_vector(exponent, u1, u2);
                    2.0 * v.dot(h) * h - v
                }
                None => cosine_hemisphere(u1, u2),
            },
            SamplingStrategy::AnisotropicPhong {
                exponent_u,
                exponent_v,
                specular_weight,
            } => {
                if u0 < specular_weight || specular_weight >= 1.0 {
                    let h = anisotropic_half_vector(exponent_u, exponent_v, u1, u2);
                    2.0 * v.dot(h) * h - v
                } else {
                    cosine_hemisphere(u1, u2)
                }
            }
        }
    }

    /// Density of `light` given `view`, per unit solid angle (0 at or below the horizon).
    pub fn pdf(&self, view: Vec3, light: Vec3) -> f32 {
        to_f32_saturating(self.pdf_f64(view.as_dvec3(), light.as_dvec3()))
    }

    /// [`SamplingStrategy::pdf`] in float64 (inputs need not be unit length).
    pub fn pdf_f64(&self, view: DVec3, light: DVec3) -> f64 {
        if !self.params_ok() {
            return 0.0;
        }
        let (Some(v), Some(l)) = (normalized(view), normalized(light)) else {
            return 0.0;
        };
        if v.z <= 0.0 || l.z <= 0.0 {
            return 0.0;
        }
        self.unit_density(v, l)
    }

    /// The density for unit `v`, `l` with valid parameters. For the lobe mixtures it holds over
    /// the whole sphere of `l`: the Blinn-Phong lobes also below the horizon (where the sampler
    /// rejects them, so that a mixture integrates to 1 for every view), the cosine part on the
    /// upper hemisphere.
    fn unit_density(&self, v: DVec3, l: DVec3) -> f64 {
        let phong = |n: f64, w: f64| weighted(w, || specular_density(v, l, n));
        match *self {
            SamplingStrategy::Uniform => 0.5 * FRAC_1_PI,
            SamplingStrategy::Cosine => l.z.max(0.0) * FRAC_1_PI,
            SamplingStrategy::Tabulated(ref table) => table.density_f64(v, l),
            SamplingStrategy::Phong {
                exponent,
                specular_weight,
            } => with_cosine(l, 1.0 - specular_weight, phong(exponent, specular_weight)),
            SamplingStrategy::TwoLobe {
                exponent1,
                weight1,
                exponent2,
                weight2,
            } => with_cosine(
                l,
                (1.0 - weight1 - weight2).max(0.0), // float32 weights may sum to 1 + ulp
                phong(exponent1, weight1) + phong(exponent2, weight2),
            ),
            SamplingStrategy::AnisotropicPhong {
                exponent_u,
                exponent_v,
                specular_weight,
            } => {
                let lobe = weighted(specular_weight, || {
                    anisotropic_specular_density(v, l, [exponent_u, exponent_v])
                });
                with_cosine(l, 1.0 - specular_weight, lobe)
            }
        }
    }

    /// [`SamplingStrategy::unit_density`] for any inputs: 0 for invalid parameters or
    /// directions.
    fn sphere_density(&self, view: DVec3, light: DVec3) -> f64 {
        match (self.params_ok(), normalized(view), normalized(light)) {
            (true, Some(v), Some(l)) => self.unit_density(v, l),
            _ => 0.0,
        }
    }
}

/// `w density()`, with `density` left unevaluated for `w = 0` (a lobe of weight 0 may carry any
/// exponent).
fn weighted(w: f64, density: impl FnOnce() -> f64) -> f64 {
    if w > 0.0 {
        w * density()
    } else {
        0.0
    }
}

/// A lobe mixture's density: its lobes' part plus `cosine_weight cos(theta_l) / pi`.
fn with_cosine(l: DVec3, cosine_weight: f64, lobes: f64) -> f64 {
    lobes + cosine_weight * l.z.max(0.0) * FRAC_1_PI
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

/// The two-lobe mixture's density over the whole sphere of light directions (the two-lobe
/// counterpart of [`blinn_phong_lobe_density`]): integrates to 1 for every view when the
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

/// Clamps a uniform into `[0, 1]`; NaN becomes 0.
fn unit_interval(u: f32) -> f64 {
    if u >= 0.0 {
        f64::from(u.min(1.0))
    } else {
        0.0
    }
}

/// Unit vector of a finite, non-zero vector.
fn normalized(v: DVec3) -> Option<DVec3> {
    let len = v.length();
    (v.is_finite() && len > 0.0 && len.is_finite()).then(|| v / len)
}

fn to_f32_saturating(p: f64) -> f32 {
    // `as` would turn densities beyond float32 into infinity.
    p.min(f64::from(f32::MAX)) as f32
}

/// Direction with polar cosine `cos_theta` and azimuth `2 pi u` (z = normal).
fn spherical(cos_theta: f64, sin_theta: f64, u: f64) -> DVec3 {
    let (sin_phi, cos_phi) = (TAU * u).sin_cos();
    DVec3::new(sin_theta * cos_phi, sin_theta * sin_phi, cos_theta)
}

/// Uniform on the upper hemisphere, `pdf = 1 / (2 pi)`.
pub fn uniform_hemisphere(u1: f64, u2: f64) -> DVec3 {
    let z = u1.clamp(0.0, 1.0);
    spherical(z, ((1.0 - z) * (1.0 + z)).max(0.0).sqrt(), u2)
}

/// Cosine-weighted on the upper hemisphere, `pdf = cos(theta) / pi`.
pub fn cosine_hemisphere(u1: f64, u2: f64) -> DVec3 {
    let u1 = u1.clamp(0.0, 1.0);
    spherical((1.0 - u1).sqrt(), u1.sqrt(), u2)
}

/// Half vector with `cos(theta_h) = u1^(1/(n+1))`. `1 - cos` comes from `expm1` so that sharp
/// lobes (n up to 1e6), where `cos` rounds to 1, keep their angular spread.
pub fn blinn_phong_half_vector(exponent: f64, u1: f64, u2: f64) -> DVec3 {
    let one_minus_cos = (-(u1.clamp(0.0, 1.0).ln() / (exponent + 1.0)).exp_m1()).clamp(0.0, 1.0);
    let cos = 1.0 - one_minus_cos;
    let sin = (one_minus_cos * (1.0 + cos)).sqrt();
    spherical(cos, sin, u2)
}

/// `cos^n` from `1 - cos` in `[0, 1]`, with `cos^0 = 1` (also for `cos = 0`) and no NaN for any
/// `n >= 0`. Taking `1 - cos` rather than `cos` keeps sharp lobes exact: near the mirror
/// direction `cos` rounds to 1 while `1 - cos` (from `|h_xy|^2`) keeps its relative precision.
/// Twin: `jit.py` `_cos_power_from_one_minus` (held together by `tests/test_backends.py`).
fn cos_power_from_one_minus(one_minus_cos: f64, n: f64) -> f64 {
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
fn one_minus_cos_theta(h: DVec3) -> f64 {
    (h.x * h.x + h.y * h.y) / (1.0 + h.z.abs())
}

/// Density of the reflected direction when the half vector has density
/// `(n + 1)/(2 pi) cos(theta_h)^n` on the upper hemisphere, over the whole sphere of `l`
/// (`v`, `l` unit). A half vector below the horizon is the mirror image of one above, so
/// `|h.z|` is used; 0 where `l = -v` (a single direction, no mass).
fn specular_density(v: DVec3, l: DVec3, n: f64) -> f64 {
    let Some(h) = normalized(l + v) else {
        return 0.0;
    };
    let v_dot_h = v.dot(h).abs();
    if v_dot_h <= 0.0 {
        return 0.0;
    }
    (n + 1.0) * 0.5 * FRAC_1_PI * cos_power_from_one_minus(one_minus_cos_theta(h), n)
        / (4.0 * v_dot_h)
}

/// Half vector of Ashikhmin and Shirley's anisotropic Blinn-Phong distribution,
/// `p(h) = sqrt((n_u + 1)(n_v + 1)) / (2 pi) cos(theta_h)^(n_u cos^2 phi + n_v sin^2 phi)`:
/// `phi = atan(sqrt((n_u + 1)/(n_v + 1)) tan(pi xi / 2))` in each quadrant (`u1` picks the quadrant
/// and `xi`; the density is symmetric under `phi -> pi - phi, -phi`), then
/// `cos(theta_h) = u2^(1 / (n(phi) + 1))` as for the isotropic lobe.
pub fn anisotropic_half_vector(exponent_u: f64, exponent_v: f64, u1: f64, u2: f64) -> DVec3 {
    let scaled = 4.0 * u1.clamp(0.0, 1.0);
    let quadrant = scaled.floor().min(3.0);
    let xi = scaled - quadrant;
    let ratio = ((exponent_u + 1.0) / (exponent_v + 1.0)).sqrt();
    let phi0 = (ratio * (0.5 * std::f64::consts::PI * xi).tan()).atan();
    let phi = match quadrant as u8 {
        0 => phi0,
        1 => std::f64::consts::PI - phi0,
        2 => std::f64::consts::PI + phi0,
        _ => TAU - phi0,
    };
    let (sin_phi, cos_phi) = phi.sin_cos();
    let exponent = exponent_u * cos_phi * cos_phi + exponent_v * sin_phi * sin_phi;
    let one_minus_cos = (-(u2.clamp(0.0, 1.0).ln() / (exponent + 1.0)).exp_m1()).clamp(0.0, 1.0);
    let cos = 1.0 - one_minus_cos;
    let sin = (one_minus_cos * (1.0 + cos)).sqrt();
    DVec3::new(sin * cos_phi, sin * sin_phi, cos)
}

/// Density of the reflected direction under [`anisotropic_half_vector`], over the whole sphere
/// of `l` (`v`, `l` unit), as [`specular_density`] for the isotropic lobe.
fn anisotropic_specular_density(v: DVec3, l: DVec3, [nu, nv]: [f64; 2]) -> f64 {
    let Some(h) = normalized(l + v) else {
        return 0.0;
    };
    let v_dot_h = v.dot(h).abs();
    if v_dot_h <= 0.0 {
        return 0.0;
    }
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
/// counterpart of [`blinn_phong_lobe_density`]): integrates to 1 for every view; 0 for invalid
/// parameters or directions.
pub fn anisotropic_lobe_density(
    view: DVec3,
    light: DVec3,
    exponents: [f64; 2],
    specular_weight: f64,
) -> f64 {
    SamplingStrategy::anisotropic(exponents[0], exponents[1], specular_weight)
        .sphere_density(view, light)
}

/// The Blinn-Phong mixture's density over the whole sphere of light directions: the specular
/// term for any `l` (also below the horizon, where the sampler rejects it), the cosine term on
/// the upper hemisphere. It integrates to 1 for every view; [`SamplingStrategy::pdf`] is this
/// restricted to both directions above the horizon. Inputs need not be unit length; invalid
/// parameters or directions give 0.
pub fn blinn_phong_lobe_density(
    view: DVec3,
    light: DVec3,
    exponent: f64,
    specular_weight: f64,
) -> f64 {
    SamplingStrategy::Phong {
        exponent,
        specular_weight,
    }
    .sphere_density(view, light)
}

/// Splits equally long slices into aligned chunks of `chunk` lanes, for parallel iteration over
/// several outputs at once.
fn split_chunks<const K: usize>(mut rest: [&mut [f32]; K], chunk: usize) -> Vec<[&mut [f32]; K]> {
    let mut chunks = Vec::new();
    while !rest[0].is_empty() {
        let m = chunk.min(rest[0].len());
        chunks.push(std::array::from_fn(|k| {
            let (head, tail) = std::mem::take(&mut rest[k]).split_at_mut(m);
            rest[k] = tail;
            head
        }));
    }
    chunks
}

/// Batched sampling: for each lane draws a light direction, its pdf, and the weight
/// `f_r cos / pdf` of `brdf` (0 for invalid samples). All slices have the same length; if they
/// do not, only the common prefix is processed.
pub fn sample_batch(
    strategy: &SamplingStrategy,
    brdf: &dyn Brdf,
    view: Directions<'_>,
    u: Directions<'_>,
    light: DirectionsMut<'_>,
    weight: RgbMut<'_>,
    pdf: &mut [f32],
) {
    let n = common_len(&[
        view.min_len(),
        u.min_len(),
        light.min_len(),
        weight.min_len(),
        pdf.len(),
    ]);
    let outputs = [
        &mut light.x[..n],
        &mut light.y[..n],
        &mut light.z[..n],
        &mut weight.r[..n],
        &mut weight.g[..n],
        &mut weight.b[..n],
        &mut pdf[..n],
    ];
    split_chunks(outputs, TASK_LANES)
        .into_par_iter()
        .enumerate()
        .for_each(|(k, [lx, ly, lz, r, g, b, p])| {
            let start = k * TASK_LANES;
            let end = start + lx.len();
            for i in 0..lx.len() {
                let j = start + i;
                let s = strategy.sample(view.get(j), [u.x[j], u.y[j], u.z[j]]);
                (lx[i], ly[i], lz[i], p[i]) = (s.light.x, s.light.y, s.light.z, s.pdf);
            }
            // One batched BRDF call per task keeps the network on its vectorised path.
            let sampled = Directions {
                x: lx,
                y: ly,
                z: lz,
            };
            brdf.eval_cos_batch(
                view.slice(start, end),
                sampled,
                RgbMut {
                    r: &mut *r,
                    g: &mut *g,
                    b: &mut *b,
                },
            );
            for (i, &pdf) in p.iter().enumerate() {
                for c in [&mut r[i], &mut g[i], &mut b[i]] {
                    *c = sample_weight(*c, pdf);
                }
            }
        });
}

/// `f cos / pdf`, 0 for invalid samples and where a tiny pdf would overflow the quotient.
fn sample_weight(f_cos: f32, pdf: f32) -> f32 {
    if pdf > 0.0 {
        let w = f_cos / pdf;
        if w.is_finite() {
            return w;
        }
    }
    0.0
}

/// Batched pdf of `light` given `view`.
pub fn pdf_batch(
    strategy: &SamplingStrategy,
    view: Directions<'_>,
    light: Directions<'_>,
    pdf: &mut [f32],
) {
    let n = common_len(&[view.min_len(), light.min_len(), pdf.len()]);
    pdf[..n]
        .par_chunks_mut(TASK_LANES)
        .enumerate()
        .for_each(|(k, p)| {
            let start = k * TASK_LANES;
            for (i, out) in p.iter_mut().enumerate() {
                *out = strategy.pdf(view.get(start + i), light.get(start + i));
            }
        });
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::network::Nbrdf;
    use crate::rng::SplitMix64;
    use std::f64::consts::{FRAC_PI_2, PI};

    const EXPONENTS: [f64; 7] = [0.0, 1.0, 10.0, 100.0, 1e3, 1e4, 1e5];

    fn dir(theta_deg: f64, phi: f64) -> DVec3 {
        crate::coords::spherical_direction(theta_deg.to_radians(), phi)
    }

    fn mirror(v: DVec3) -> DVec3 {
        DVec3::new(-v.x, -v.y, v.z)
    }

    /// Integral of `f` over the spherical cap of angular radius `alpha_max` around `centre`, in
    /// spherical coordinates centred there with `alpha = alpha_max s^2` (s uniform): the grid is
    /// dense near the centre, where sharp lobes live. Midpoint rule in `s` and in the periodic
    /// azimuth.
    fn cap_integral(
        centre: DVec3,
        alpha_max: f64,
        ns: usize,
        nb: usize,
        f: impl Fn(DVec3) -> f64 + Sync,
    ) -> f64 {
        let c = centre.normalize();
        let (t1, t2) = c.any_orthonormal_pair();
        (0..ns)
            .into_par_iter()
            .map(|i| {
                let s = (i as f64 + 0.5) / ns as f64;
                let alpha = alpha_max * s * s;
                let d_alpha = 2.0 * alpha_max * s / ns as f64;
                let (sin_a, cos_a) = alpha.sin_cos();
                let ring: f64 = (0..nb)
                    .map(|j| {
                        let (sin_b, cos_b) = (TAU * (j as f64 + 0.5) / nb as f64).sin_cos();
                        f(cos_a * c + sin_a * (cos_b * t1 + sin_b * t2))
                    })
                    .sum();
                ring * sin_a * d_alpha * TAU / nb as f64
            })
            .sum()
    }

    fn sphere_integral(
        centre: DVec3,
        ns: usize,
        nb: usize,
        f: impl Fn(DVec3) -> f64 + Sync,
    ) -> f64 {
        cap_integral(centre, PI, ns, nb, f)
    }

    /// Smooth (C1) weight, 1 within `radius / 2` of `centre`, 0 beyond `radius`.
    fn bump(centre: DVec3, radius: f64, l: DVec3) -> f64 {
        let t = (l.dot(centre).clamp(-1.0, 1.0).acos() / radius - 0.5) * 2.0;
        let t = t.clamp(0.0, 1.0);
        1.0 - t * t * (3.0 - 2.0 * t)
    }

    /// Integral over the sphere of a lobe density at view `v`: the specular terms have an
    /// integrable `1 / |l + v|` singularity at `l = -v`, so a partition of unity integrates a
    /// neighbourhood of `-v` on a grid centred there (where the singularity is harmless in polar
    /// coordinates) and the rest on a grid centred on the mirror direction, where sharp lobes are.
    fn density_integral(v: DVec3, density: impl Fn(DVec3) -> f64 + Sync) -> f64 {
        let radius = 0.08;
        let near = cap_integral(-v, radius, 400, 128, |l| density(l) * bump(-v, radius, l));
        let far = sphere_integral(mirror(v), 1500, 256, |l| {
            density(l) * (1.0 - bump(-v, radius, l))
        });
        near + far
    }

    /// [`density_integral`] of the Blinn-Phong mixture.
    fn lobe_integral(v: DVec3, n: f64, w: f64) -> f64 {
        density_integral(v, |l| blinn_phong_lobe_density(v, l, n, w))
    }

    #[test]
    fn validated_rejects_bad_parameters() {
        let bp = |exponent, specular_weight| SamplingStrategy::Phong {
            exponent,
            specular_weight,
        };
        assert!(bp(10.0, 0.5).validated().is_ok());
        assert!(bp(0.0, 0.0).validated().is_ok() && bp(1e6, 1.0).validated().is_ok());
        for bad in [
            bp(-1.0, 0.5),
            bp(f64::NAN, 0.5),
            bp(f64::INFINITY, 0.5),
            bp(MAX_EXPONENT * (1.0 + 1e-12), 0.5),
            bp(3.4e38, 0.5),
            bp(1.0, -0.1),
            bp(1.0, 1.5),
            bp(1.0, f64::NAN),
        ] {
            assert!(
                matches!(bad.clone().validated(), Err(NbrdfError::InvalidArgument(_))),
                "{bad:?}"
            );
            // Unvalidated bad parameters still give finite output.
            let s = bad.sample(Vec3::Z, [0.5; 3]);
            assert_eq!(s.pdf, 0.0);
            assert!(s.light.is_finite());
            assert_eq!(bad.pdf(Vec3::Z, Vec3::Z), 0.0);
        }
        assert!(
            SamplingStrategy::Cosine.validated().is_ok()
                && SamplingStrategy::Uniform.validated().is_ok()
        );
    }

    /// The anisotropic lobe integrates to 1 over the sphere of light directions, also stiff
    /// (`n_u = 1e4`, `n_v = 10`) and at grazing views. Where the light-space lobe is too
    /// distorted for the grid (stiff and grazing: thousands of times narrower across than
    /// along), the integral is taken over half vectors instead, with the Jacobian
    /// `dl = 4 |v . h| dh` of the reflection, on a grid centred on the normal.
    #[test]
    fn anisotropic_density_integrates_to_one_over_the_sphere() {
        let views = [dir(0.0, 0.0), dir(60.0, 0.4), dir(85.0, 2.0)];
        for exponents in [[100.0, 10.0], [1e4, 10.0], [0.0, 300.0]] {
            let density = |v: DVec3, l: DVec3| anisotropic_lobe_density(v, l, exponents, 0.7);
            let v = views[0];
            let radius = 0.08;
            let near = cap_integral(-v, radius, 400, 128, |l| {
                density(v, l) * bump(-v, radius, l)
            });
            let far = sphere_integral(mirror(v), 1500, 2048, |l| {
                density(v, l) * (1.0 - bump(-v, radius, l))
            });
            let total = near + far;
            // (A zero exponent makes a band around a great circle, which the grid cannot
            // follow; the half-vector integral below covers it.)
            if exponents[0] > 0.0 {
                assert!((total - 1.0).abs() < 1e-4, "{exponents:?} v {v}: {total}");
            }
            for v in views {
                let specular = cap_integral(DVec3::Z, 0.5 * PI, 1500, 2048, |h| {
                    let l = 2.0 * v.dot(h) * h - v;
                    anisotropic_lobe_density(v, l, exponents, 1.0) * 4.0 * v.dot(h).abs()
                });
                assert!(
                    (specular - 1.0).abs() < 1e-4,
                    "{exponents:?} v {v}: {specular}"
                );
            }
        }
    }

    /// With equal exponents the anisotropic lobe is the isotropic Blinn-Phong lobe; with
    /// different ones it is stretched along the axis of the smaller exponent.
    #[test]
    fn anisotropic_density_reduces_to_blinn_phong_and_orients_by_axis() {
        let mut rng = SplitMix64::from_state(12);
        for _ in 0..500 {
            let v = uniform_hemisphere(rng.next_f64(), rng.next_f64());
            let l = uniform_hemisphere(rng.next_f64(), rng.next_f64());
            let want = blinn_phong_lobe_density(v, l, 40.0, 0.6);
            let got = anisotropic_lobe_density(v, l, [40.0, 40.0], 0.6);
            assert!((got - want).abs() <= 1e-12 * want, "{got} vs {want}");
        }
        // Half vectors tilted by 0.15 rad along x and along y, view at the normal.
        let v = DVec3::Z;
        let tilted = |phi: f64| {
            let h = crate::coords::spherical_direction(0.15, phi);
            2.0 * v.dot(h) * h - v
        };
        let density = |l| anisotropic_lobe_density(v, l, [1000.0, 10.0], 1.0);
        assert!(density(tilted(0.0)) < 1e-3 * density(tilted(FRAC_PI_2)));
    }

    #[test]
    fn hemisphere_pdfs_integrate_to_one() {
        let v = Vec3::new(0.3, -0.2, 0.9);
        for strategy in [SamplingStrategy::Uniform, SamplingStrategy::Cosine] {
            let total = cap_integral(DVec3::Z, 0.5 * PI, 800, 64, |l| {
                f64::from(strategy.pdf(v, l.as_vec3()))
            });
            assert!((total - 1.0).abs() < 1e-5, "{strategy:?}: {total}");
        }
    }

    #[test]
    fn blinn_phong_density_integrates_to_one_over_the_sphere() {
        let views = [dir(0.0, 0.0), dir(60.0, 0.4), dir(85.0, 2.0)];
        for n in EXPONENTS {
            for w in [0.25, 1.0] {
                for v in views {
                    let total = lobe_integral(v, n, w);
                    assert!((total - 1.0).abs() < 1e-4, "n {n} w {w} v {v}: {total}");
                }
            }
        }
        let total = cap_integral(DVec3::Z, 0.5 * PI, 800, 64, |l| {
            blinn_phong_lobe_density(DVec3::Z, l, 50.0, 0.0)
        });
        assert!((total - 1.0).abs() < 1e-5, "{total}");
    }

    #[test]
    fn pdf_is_the_lobe_density_above_the_horizon_and_zero_below() {
        let mut rng = SplitMix64::from_state(5);
        let strategy = SamplingStrategy::Phong {
            exponent: 30.0,
            specular_weight: 0.6,
        };
        for _ in 0..1000 {
            let v = uniform_hemisphere(rng.next_f64(), rng.next_f64());
            let l = DVec3::new(
                rng.next_f64() - 0.5,
                rng.next_f64() - 0.5,
                rng.next_f64() - 0.5,
            );
            let p = strategy.pdf_f64(v, l);
            if l.z <= 0.0 {
                assert_eq!(p, 0.0);
                assert_eq!(strategy.pdf_f64(-v, -l), 0.0);
            } else {
                let want = blinn_phong_lobe_density(v, l, 30.0, 0.6);
                assert!((p - want).abs() <= 1e-12 * want, "{p} vs {want}");
            }
        }
    }

    #[test]
    fn sampled_pdf_equals_pdf() {
        let mut rng = SplitMix64::from_state(1);
        let strategies = [
            SamplingStrategy::Uniform,
            SamplingStrategy::Cosine,
            SamplingStrategy::Phong {
                exponent: 20.0,
                specular_weight: 0.5,
            },
            SamplingStrategy::Phong {
                exponent: 1e6,
                specular_weight: 0.9,
            },
            SamplingStrategy::anisotropic(100.0, 10.0, 0.5),
            SamplingStrategy::anisotropic(1e4, 10.0, 0.9),
        ];
        for strategy in strategies {
            let mut valid = 0;
            for _ in 0..2000 {
                let v = uniform_hemisphere(rng.next_f64(), rng.next_f64()).as_vec3() * 2.0;
                let u = [rng.next_f32(), rng.next_f32(), rng.next_f32()];
                let s = strategy.sample(v, u);
                assert_eq!(s.pdf, strategy.pdf(v, s.light), "{strategy:?} {v} {u:?}");
                assert!((s.light.length() - 1.0).abs() < 1e-6);
                valid += usize::from(s.pdf > 0.0);
            }
            assert!(valid > 1000, "{strategy:?}: only {valid} valid samples");
        }
    }

    /// Mean of `g` over `samples` draws of `strategy` at `v` (0 for invalid draws), with its
    /// standard error.
    pub(crate) fn sample_mean(
        strategy: &SamplingStrategy,
        v: DVec3,
        g: &dyn Fn(DVec3) -> f64,
        samples: usize,
        seed: u64,
    ) -> (f64, f64) {
        let mut rng = SplitMix64::from_state(seed);
        let (mut sum, mut sum2) = (0.0, 0.0);
        for _ in 0..samples {
            let s = strategy.sample(
                v.as_vec3(),
                [rng.next_f32(), rng.next_f32(), rng.next_f32()],
            );
            let x = if s.pdf > 0.0 {
                g(s.light.as_dvec3())
            } else {
                0.0
            };
            sum += x;
            sum2 += x * x;
        }
        let mean = sum / samples as f64;
        (
            mean,
            ((sum2 / samples as f64 - mean * mean) / samples as f64).sqrt(),
        )
    }

    /// For each function `g` of `tests`, its mean over `samples` draws of `strategy` at `v`
    /// (seeded `seed + index`) against the quadrature of `g * pdf` over the sphere around `r`:
    /// the sampler must draw from the density that `pdf` reports.
    fn assert_sample_means_match_pdf(
        strategy: &SamplingStrategy,
        v: DVec3,
        r: DVec3,
        tests: &[&(dyn Fn(DVec3) -> f64 + Sync)],
        samples: usize,
        seed: u64,
    ) {
        for (t, g) in tests.iter().enumerate() {
            let exact = sphere_integral(r, 1500, 256, |l| g(l) * strategy.pdf_f64(v, l));
            let (mean, sigma) = sample_mean(strategy, v, g, samples, seed + t as u64);
            assert!(
                (mean - exact).abs() < 5.0 * sigma + 1e-4,
                "{strategy:?} test {t}: MC {mean} +- {sigma} vs quadrature {exact}"
            );
        }
    }

    /// Monte Carlo means under the sampler against quadrature of the same function times the pdf:
    /// checks that the sampler draws from the density that `pdf` reports.
    #[test]
    fn sample_histogram_matches_pdf() {
        let cases = [
            (SamplingStrategy::Uniform, dir(30.0, 0.0)),
            (SamplingStrategy::Cosine, dir(30.0, 0.0)),
            (
                SamplingStrategy::Phong {
                    exponent: 10.0,
                    specular_weight: 0.5,
                },
                dir(45.0, 1.0),
            ),
            (
                SamplingStrategy::Phong {
                    exponent: 1000.0,
                    specular_weight: 0.8,
                },
                dir(70.0, -2.0),
            ),
        ];
        let samples = 200_000;
        for (strategy, v) in cases {
            let r = mirror(v);
            // A smooth function and a histogram bin (a cone around the mirror direction).
            let tests: [&(dyn Fn(DVec3) -> f64 + Sync); 2] =
                [&|l: DVec3| l.z + 0.5 * l.x * l.x, &|l: DVec3| {
                    f64::from(u8::from(l.dot(r) > 0.995))
                }];
            assert_sample_means_match_pdf(&strategy, v, r, &tests, samples, 17);
        }
    }

    /// The anisotropic sampler draws from the density its pdf reports (Monte Carlo means
    /// against quadrature), also stiff (`n_u = 1e4`, `n_v = 10`) and at grazing incidence; the
    /// test functions tell the x and y spreads apart.
    #[test]
    fn anisotropic_samples_match_pdf() {
        let cases = [
            (
                SamplingStrategy::anisotropic(100.0, 10.0, 0.6),
                dir(40.0, 0.7),
            ),
            (
                SamplingStrategy::anisotropic(1e4, 10.0, 0.8),
                dir(30.0, -1.0),
            ),
            (
                SamplingStrategy::anisotropic(1e4, 10.0, 0.8),
                dir(85.0, 2.5),
            ),
        ];
        for (strategy, v) in cases {
            let r = mirror(v);
            let tests: [&(dyn Fn(DVec3) -> f64 + Sync); 3] = [
                &|l: DVec3| l.z + 0.5 * l.x * l.x,
                &|l: DVec3| f64::from(u8::from(l.dot(r) > 0.995)),
                &|l: DVec3| 10.0 * (l - r).x.powi(2) + (l - r).y.powi(2),
            ];
            assert_sample_means_match_pdf(&strategy, v, r, &tests, 200_000, 23);
        }
    }

    #[test]
    fn extreme_inputs_stay_finite() {
        let views = [
            Vec3::Z,
            dir(89.9999, 0.3).as_vec3(),
            Vec3::new(1.0, 0.0, 1e-6),
            Vec3::new(0.0, 0.0, -1.0),
            Vec3::new(0.5, 0.5, -1e-7),
            Vec3::ZERO,
            Vec3::new(f32::NAN, 0.0, 1.0),
            Vec3::new(0.0, 0.0, f32::INFINITY),
            Vec3::new(3e-30, 0.0, 4e-30),
            Vec3::new(3e30, 0.0, 4e30),
        ];
        let us = [0.0, 1e-30, 1e-7, 0.5, 1.0 - 1e-7, 1.0, -1.0, 2.0, f32::NAN];
        let mut strategies = vec![SamplingStrategy::Uniform, SamplingStrategy::Cosine];
        for exponent in [0.0, 1e-3, 1.0, 1e6] {
            for specular_weight in [0.0, 0.5, 1.0] {
                strategies.push(SamplingStrategy::Phong {
                    exponent,
                    specular_weight,
                });
            }
        }
        for strategy in strategies {
            for v in views {
                for u0 in us {
                    for u1 in us {
                        for u2 in [0.0, 0.3, 1.0] {
                            let s = strategy.sample(v, [u0, u1, u2]);
                            assert!(
                                s.light.is_finite() && s.pdf.is_finite() && s.pdf >= 0.0,
                                "{strategy:?} {v} {s:?}"
                            );
                            assert_eq!(s.pdf, strategy.pdf(v, s.light));
                            if !(v.z > 0.0 && v.is_finite()) {
                                assert_eq!(s.pdf, 0.0);
                            }
                        }
                    }
                }
                for l in views {
                    let p = strategy.pdf(v, l);
                    assert!(p.is_finite() && p >= 0.0);
                }
            }
        }
        // The sharpest lobe with the extreme uniforms lands on the mirror direction.
        let bp = SamplingStrategy::Phong {
            exponent: 1e6,
            specular_weight: 1.0,
        };
        let v = dir(40.0, 0.0).as_vec3();
        let s = bp.sample(v, [0.0, 1.0, 0.0]);
        assert!(
            (s.light - Vec3::new(-v.x, -v.y, v.z)).length() < 1e-6 && s.pdf > 1e4,
            "{s:?}"
        );
        assert_eq!(bp.sample(v, [0.0, 0.0, 0.0]).pdf, 0.0); // half vector on the horizon
    }

    #[test]
    fn batches_match_single_lanes() {
        let net = Nbrdf::random("n", 21, 3);
        let strategy = SamplingStrategy::Phong {
            exponent: 40.0,
            specular_weight: 0.7,
        };
        let n = 3 * TASK_LANES + 17;
        let mut rng = SplitMix64::from_state(9);
        let mut view = vec![0.0f32; 3 * n];
        let mut u = vec![0.0f32; 3 * n];
        for i in 0..n {
            let v = uniform_hemisphere(rng.next_f64(), rng.next_f64()).as_vec3();
            for k in 0..3 {
                view[k * n + i] = v[k];
                u[k * n + i] = rng.next_f32();
            }
        }
        view[5] = -0.5; // one view below the horizon (x of lane 5 is fine; make z negative)
        view[2 * n + 5] = -0.5;
        let (mut light, mut weight, mut pdf) =
            (vec![0.0f32; 3 * n], vec![0.0f32; 3 * n], vec![0.0f32; n]);
        let view_d = Directions::from_planar(&view).unwrap();
        let u_d = Directions::from_planar(&u).unwrap();
        sample_batch(
            &strategy,
            &net,
            view_d,
            u_d,
            DirectionsMut::from_planar(&mut light).unwrap(),
            RgbMut::from_planar(&mut weight).unwrap(),
            &mut pdf,
        );
        let mut pdf2 = vec![0.0f32; n];
        pdf_batch(
            &strategy,
            view_d,
            Directions::from_planar(&light).unwrap(),
            &mut pdf2,
        );
        assert_eq!(pdf, pdf2);
        let mut invalid = 0;
        for i in 0..n {
            let v = view_d.get(i);
            let s = strategy.sample(v, [u[i], u[n + i], u[2 * n + i]]);
            assert_eq!(s.light, Vec3::new(light[i], light[n + i], light[2 * n + i]));
            assert_eq!(s.pdf, pdf[i]);
            let f = net.eval(v, s.light);
            let cos = crate::brdf::cos_theta_light(s.light);
            for c in 0..3 {
                let want = if s.pdf > 0.0 { f[c] * cos / s.pdf } else { 0.0 };
                let got = weight[c * n + i];
                assert!(
                    (got - want).abs() <= 1e-4 * want.abs() + 1e-9,
                    "lane {i}: {got} vs {want}"
                );
            }
            invalid += usize::from(s.pdf == 0.0);
        }
        assert!(pdf[5] == 0.0 && weight[5] == 0.0);
        assert!(invalid > 0 && invalid < n / 4);
    }

    fn two_lobe(n1: f64, w1: f64, n2: f64, w2: f64) -> SamplingStrategy {
        SamplingStrategy::TwoLobe {
            exponent1: n1,
            weight1: w1,
            exponent2: n2,
            weight2: w2,
        }
    }

    /// [`density_integral`] of the two-lobe mixture.
    fn two_lobe_integral(v: DVec3, exponents: [f64; 2], weights: [f64; 2]) -> f64 {
        density_integral(v, |l| two_lobe_density(v, l, exponents, weights))
    }

    #[test]
    fn two_lobe_density_integrates_to_one_over_the_sphere() {
        let views = [dir(0.0, 0.0), dir(60.0, 0.4), dir(85.0, 2.0)];
        let cases = [
            ([1e4, 30.0], [0.3, 0.5]),
            ([1e5, 1e3], [0.6, 0.4]),
            ([100.0, 1.0], [0.1, 0.2]),
            ([1e6, 0.0], [0.5, 0.25]),
        ];
        for (exponents, weights) in cases {
            for v in views {
                let total = two_lobe_integral(v, exponents, weights);
                assert!(
                    (total - 1.0).abs() < 1e-4,
                    "{exponents:?} {weights:?} v {v}: {total}"
                );
            }
        }
    }

    #[test]
    fn two_lobe_validation_and_one_lobe_equivalence() {
        assert!(two_lobe(1e4, 0.3, 50.0, 0.5).validated().is_ok());
        assert!(two_lobe(1e6, 0.7f32 as f64, 0.0, 0.3f32 as f64)
            .validated()
            .is_ok());
        for bad in [
            two_lobe(-1.0, 0.3, 10.0, 0.3),
            two_lobe(10.0, 0.3, 2e6, 0.3),
            two_lobe(f64::NAN, 0.3, 10.0, 0.3),
            two_lobe(10.0, 0.6, 1.0, 0.5),
            two_lobe(10.0, -0.1, 1.0, 0.5),
            two_lobe(10.0, 0.1, 1.0, f64::NAN),
        ] {
            assert!(
                matches!(bad.clone().validated(), Err(NbrdfError::InvalidArgument(_))),
                "{bad:?}"
            );
            let s = bad.sample(Vec3::Z, [0.5; 3]);
            assert_eq!(s.pdf, 0.0);
            assert!(s.light.is_finite());
        }
        // A second lobe of weight 0 is the one-lobe mixture, sample for sample.
        let one = SamplingStrategy::Phong {
            exponent: 300.0,
            specular_weight: 0.6,
        };
        let two = two_lobe(300.0, 0.6, 7.0, 0.0);
        let mut rng = SplitMix64::from_state(3);
        for _ in 0..2000 {
            let v = uniform_hemisphere(rng.next_f64(), rng.next_f64()).as_vec3();
            let u = [rng.next_f32(), rng.next_f32(), rng.next_f32()];
            let (a, b) = (one.sample(v, u), two.sample(v, u));
            assert_eq!(a.light, b.light);
            assert!((a.pdf - b.pdf).abs() <= 1e-6 * a.pdf, "{a:?} {b:?}");
        }
    }

    #[test]
    fn two_lobe_sampled_pdf_equals_pdf_and_histogram_matches() {
        let mut rng = SplitMix64::from_state(11);
        let strategies = [
            two_lobe(1e4, 0.4, 30.0, 0.4),
            two_lobe(1e6, 0.5, 1e3, 0.5),
            two_lobe(50.0, 0.2, 5.0, 0.1),
        ];
        for strategy in strategies {
            for _ in 0..2000 {
                let v = uniform_hemisphere(rng.next_f64(), rng.next_f64()).as_vec3();
                let s = strategy.sample(v, [rng.next_f32(), rng.next_f32(), rng.next_f32()]);
                assert_eq!(s.pdf, strategy.pdf(v, s.light), "{strategy:?}");
                assert!(s.light.is_finite() && s.pdf.is_finite() && s.pdf >= 0.0);
            }
        }
        let samples = 200_000;
        for (strategy, v) in [
            (two_lobe(1e4, 0.3, 40.0, 0.5), dir(45.0, 1.0)),
            (two_lobe(2e3, 0.5, 20.0, 0.2), dir(80.0, -2.0)),
        ] {
            let r = mirror(v);
            let tests: [&(dyn Fn(DVec3) -> f64 + Sync); 3] = [
                &|l: DVec3| l.z + 0.5 * l.x * l.x,
                &|l: DVec3| f64::from(u8::from(l.dot(r) > 0.995)),
                &|l: DVec3| f64::from(u8::from(l.dot(r) > 0.9999)),
            ];
            assert_sample_means_match_pdf(&strategy, v, r, &tests, samples, 29);
        }
    }
}
