//! Importance sampling of the reflected direction (docs/design.md section 6). Each strategy
//! family has its file, its sampler and density side by side: `hemisphere.rs` (uniform,
//! cosine), `phong.rs` (one Blinn-Phong lobe mixed with cosine), `two_lobe.rs`,
//! `anisotropic.rs` and `tabulated.rs` (the data-driven half-vector table); `kind.rs` names
//! them. This file dispatches over [`SamplingStrategy`] and holds the batched entry points.
//!
//! Every strategy takes three uniforms in `[0, 1]` (inclusive) and the view direction; the
//! pdf is per unit solid angle of the light direction. Internally float64, so that exponents up to
//! 1e6 and uniforms at the interval ends stay finite. The pdf a sample reports is computed from
//! the float32 direction it returns, by the same function as [`SamplingStrategy::pdf`], so the
//! two agree exactly (what MIS needs).

mod anisotropic;
mod hemisphere;
mod kind;
mod phong;
pub mod tabulated;
#[cfg(test)]
pub(crate) mod tests;
mod two_lobe;

use crate::brdf::{common_len, Brdf, Directions, DirectionsMut, RgbMut};
use crate::error::{NbrdfError, Result};
use glam::{DVec3, Vec3};
use rayon::prelude::*;
use std::sync::Arc;

pub use anisotropic::{anisotropic_half_vector, anisotropic_lobe_density};
pub use hemisphere::{cosine_hemisphere, uniform_hemisphere};
pub use kind::{ParsedKind, SamplingKind, UnknownSamplingCode, UnknownSamplingKind};
pub use phong::{phong_half_vector, phong_lobe_density};
pub use tabulated::TabulatedSampler;
pub use two_lobe::two_lobe_density;

/// Lanes per rayon task in the batched functions.
const TASK_LANES: usize = 4096;

/// The largest Blinn-Phong exponent accepted (docs/design.md promises stable sampling up to
/// here; docs/hardening.md). The plugin's `jit/sampling.py` and `validation.py` use the same figure.
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
    /// Mixture of a Blinn-Phong lobe (exponent `n >= 0`) with weight `w` in `[0, 1]` and a
    /// cosine lobe ([`phong_lobe_density`]).
    Phong {
        exponent: f64,
        specular_weight: f64,
    },
    /// Mixture of two Blinn-Phong lobes and a cosine lobe,
    /// `w1 phong(n1) + w2 phong(n2) + (1 - w1 - w2) cosine` ([`two_lobe_density`]). Weights in
    /// `[0, 1]` with `w1 + w2 <= 1`, exponents in `[0, MAX_EXPONENT]`; by convention (that of
    /// the lobe fit) `exponent1 >= exponent2`, though the density does not depend on the order.
    TwoLobe {
        exponent1: f64,
        weight1: f64,
        exponent2: f64,
        weight2: f64,
    },
    /// Mixture of an anisotropic Blinn-Phong lobe (exponent `exponent_u` along the tangent x
    /// and `exponent_v` along y) with weight `w` and a cosine lobe
    /// ([`anisotropic_lobe_density`]), for anisotropic networks. With equal exponents it is
    /// [`SamplingStrategy::Phong`].
    AnisotropicPhong {
        exponent_u: f64,
        exponent_v: f64,
        specular_weight: f64,
    },
    /// The data-driven half-vector table of a material with a defensive cosine component
    /// ([`tabulated`]).
    Tabulated(Arc<TabulatedSampler>),
}

/// One sampled light direction; `pdf == 0` marks an invalid sample (below the horizon).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DirectionSample {
    pub light: Vec3,
    pub pdf: f32,
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

    /// Checks the parameters (exponents in [0, [`MAX_EXPONENT`]], weights in [0, 1] and, for
    /// two lobes, summing to at most 1).
    pub fn validated(self) -> Result<Self> {
        match self.problem() {
            Some(problem) => Err(NbrdfError::InvalidArgument(problem)),
            None => Ok(self),
        }
    }

    /// Why the parameters are unusable, if they are (allocates only then).
    fn problem(&self) -> Option<String> {
        match *self {
            SamplingStrategy::Phong {
                exponent,
                specular_weight,
            } => phong::problem(exponent, specular_weight),
            SamplingStrategy::TwoLobe {
                exponent1,
                weight1,
                exponent2,
                weight2,
            } => two_lobe::problem([exponent1, exponent2], [weight1, weight2]),
            SamplingStrategy::AnisotropicPhong {
                exponent_u,
                exponent_v,
                specular_weight,
            } => anisotropic::problem(exponent_u, exponent_v, specular_weight),
            SamplingStrategy::Uniform
            | SamplingStrategy::Cosine
            | SamplingStrategy::Tabulated(_) => None,
        }
    }

    /// Whether the parameters are usable; unusable ones give pdf 0 everywhere instead of NaN.
    fn params_ok(&self) -> bool {
        self.problem().is_none()
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
    fn sample_direction(&self, v: DVec3, u: [f64; 3]) -> DVec3 {
        let [_, u1, u2] = u;
        match *self {
            SamplingStrategy::Uniform => uniform_hemisphere(u1, u2),
            SamplingStrategy::Cosine => cosine_hemisphere(u1, u2),
            SamplingStrategy::Tabulated(ref table) => table.sample_direction(v, u),
            SamplingStrategy::Phong {
                exponent,
                specular_weight,
            } => phong::sample(v, exponent, specular_weight, u),
            SamplingStrategy::TwoLobe {
                exponent1,
                weight1,
                exponent2,
                weight2,
            } => two_lobe::sample(v, [exponent1, exponent2], [weight1, weight2], u),
            SamplingStrategy::AnisotropicPhong {
                exponent_u,
                exponent_v,
                specular_weight,
            } => anisotropic::sample(v, [exponent_u, exponent_v], specular_weight, u),
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
        match *self {
            SamplingStrategy::Uniform => hemisphere::uniform_density(),
            SamplingStrategy::Cosine => hemisphere::cosine_density(l),
            SamplingStrategy::Tabulated(ref table) => table.density_f64(v, l),
            SamplingStrategy::Phong {
                exponent,
                specular_weight,
            } => phong::density(v, l, exponent, specular_weight),
            SamplingStrategy::TwoLobe {
                exponent1,
                weight1,
                exponent2,
                weight2,
            } => two_lobe::density(v, l, [exponent1, exponent2], [weight1, weight2]),
            SamplingStrategy::AnisotropicPhong {
                exponent_u,
                exponent_v,
                specular_weight,
            } => anisotropic::density(v, l, [exponent_u, exponent_v], specular_weight),
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

/// The mirror image of unit `v` about the half vector `h`.
fn reflect(v: DVec3, h: DVec3) -> DVec3 {
    2.0 * v.dot(h) * h - v
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

/// Splits equally long slices into aligned chunks of `chunk` lanes, for parallel iteration over
/// several outputs at once.
pub(crate) fn split_chunks<const K: usize>(
    mut rest: [&mut [f32]; K],
    chunk: usize,
) -> Vec<[&mut [f32]; K]> {
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

/// The outputs of one task of a batched sampling call: its lanes' light directions, weights and
/// pdfs.
pub(crate) struct SampleOut<'a> {
    pub(crate) light: DirectionsMut<'a>,
    pub(crate) weight: RgbMut<'a>,
    pub(crate) pdf: &'a mut [f32],
}

/// The first `n` lanes of a batched sampling call's outputs, split in order into tasks of
/// `lanes` lanes (the last may be shorter): task `k` starts at lane `k * lanes`.
pub(crate) fn sample_tasks<'a>(
    light: DirectionsMut<'a>,
    weight: RgbMut<'a>,
    pdf: &'a mut [f32],
    n: usize,
    lanes: usize,
) -> Vec<SampleOut<'a>> {
    let outputs = [
        &mut light.x[..n],
        &mut light.y[..n],
        &mut light.z[..n],
        &mut weight.r[..n],
        &mut weight.g[..n],
        &mut weight.b[..n],
        &mut pdf[..n],
    ];
    split_chunks(outputs, lanes)
        .into_iter()
        .map(|[x, y, z, r, g, b, pdf]| SampleOut {
            light: DirectionsMut { x, y, z },
            weight: RgbMut { r, g, b },
            pdf,
        })
        .collect()
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
    sample_tasks(light, weight, pdf, n, TASK_LANES)
        .into_par_iter()
        .enumerate()
        .for_each(|(k, out)| {
            let SampleOut {
                mut light,
                weight,
                pdf,
            } = out;
            let start = k * TASK_LANES;
            let end = start + pdf.len();
            for (i, p) in pdf.iter_mut().enumerate() {
                let s = strategy.sample(view.get(start + i), u.get(start + i).to_array());
                light.set(i, s.light);
                *p = s.pdf;
            }
            // One batched BRDF call per task keeps the network on its vectorised path.
            let sampled = Directions {
                x: light.x,
                y: light.y,
                z: light.z,
            };
            let RgbMut { r, g, b } = weight;
            brdf.eval_cos_batch(
                view.slice(start, end),
                sampled,
                RgbMut {
                    r: &mut *r,
                    g: &mut *g,
                    b: &mut *b,
                },
            );
            for (i, &pdf) in pdf.iter().enumerate() {
                for c in [&mut r[i], &mut g[i], &mut b[i]] {
                    *c = sample_weight(*c, pdf);
                }
            }
        });
}

/// `f cos / pdf`, 0 for invalid samples and where a tiny pdf would overflow the quotient.
pub(crate) fn sample_weight(f_cos: f32, pdf: f32) -> f32 {
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
