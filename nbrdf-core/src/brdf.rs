//! The interface every reflectance representation offers (tables, analytic fits, networks), and
//! the structure-of-arrays batch types the hot loops and the C ABI use.

use glam::Vec3;
use rayon::prelude::*;

/// `len`, `is_empty` and `min_len` of a planar batch type with components `$a, $b, $c`.
macro_rules! planar_lanes {
    ($ty:ident, $a:ident, $b:ident, $c:ident) => {
        impl $ty<'_> {
            /// The length of the first component.
            pub fn len(&self) -> usize {
                self.$a.len()
            }

            pub fn is_empty(&self) -> bool {
                self.$a.is_empty()
            }

            /// The length of the shortest component: the lanes a batch call processes.
            pub fn min_len(&self) -> usize {
                self.$a.len().min(self.$b.len()).min(self.$c.len())
            }
        }
    };
}

/// `from_planar` of a mutable planar batch type with components `$a, $b, $c`.
macro_rules! planar_from_mut_buffer {
    ($ty:ident, $a:ident, $b:ident, $c:ident) => {
        impl<'a> $ty<'a> {
            /// Splits a planar buffer `[a0..an, b0..bn, c0..cn]` of length `3 n`.
            pub fn from_planar(buffer: &'a mut [f32]) -> Option<Self> {
                if buffer.len() % 3 != 0 {
                    return None;
                }
                let n = buffer.len() / 3;
                let ($a, rest) = buffer.split_at_mut(n);
                let ($b, $c) = rest.split_at_mut(n);
                Some($ty { $a, $b, $c })
            }
        }
    };
}

/// A batch of directions in the local shading frame, one slice per component.
#[derive(Clone, Copy, Debug)]
pub struct Directions<'a> {
    pub x: &'a [f32],
    pub y: &'a [f32],
    pub z: &'a [f32],
}

impl<'a> Directions<'a> {
    /// Splits a planar buffer `[x0..xn, y0..yn, z0..zn]` of length `3 n`.
    pub fn from_planar(buffer: &'a [f32]) -> Option<Self> {
        if buffer.len() % 3 != 0 {
            return None;
        }
        let n = buffer.len() / 3;
        Some(Directions {
            x: &buffer[..n],
            y: &buffer[n..2 * n],
            z: &buffer[2 * n..],
        })
    }

    pub fn get(&self, i: usize) -> Vec3 {
        Vec3::new(self.x[i], self.y[i], self.z[i])
    }

    /// The sub-batch `range`, for splitting work across threads.
    pub fn slice(&self, start: usize, end: usize) -> Directions<'a> {
        Directions {
            x: &self.x[start..end],
            y: &self.y[start..end],
            z: &self.z[start..end],
        }
    }
}

/// Output directions, planar like [`Directions`].
#[derive(Debug)]
pub struct DirectionsMut<'a> {
    pub x: &'a mut [f32],
    pub y: &'a mut [f32],
    pub z: &'a mut [f32],
}

impl<'a> DirectionsMut<'a> {
    pub fn set(&mut self, i: usize, v: Vec3) {
        self.x[i] = v.x;
        self.y[i] = v.y;
        self.z[i] = v.z;
    }
}

/// RGB output, one slice per channel.
#[derive(Debug)]
pub struct RgbMut<'a> {
    pub r: &'a mut [f32],
    pub g: &'a mut [f32],
    pub b: &'a mut [f32],
}

impl<'a> RgbMut<'a> {
    pub fn set(&mut self, i: usize, rgb: [f32; 3]) {
        self.r[i] = rgb[0];
        self.g[i] = rgb[1];
        self.b[i] = rgb[2];
    }
}

planar_lanes!(Directions, x, y, z);
planar_lanes!(DirectionsMut, x, y, z);
planar_lanes!(RgbMut, r, g, b);
planar_from_mut_buffer!(DirectionsMut, x, y, z);
planar_from_mut_buffer!(RgbMut, r, g, b);

/// The lanes every slice of a batch call has: batch functions process this common prefix
/// when their slices differ in length.
pub fn common_len(lengths: &[usize]) -> usize {
    lengths.iter().copied().min().unwrap_or(0)
}

/// Lanes per rayon task of [`par_eval_pairs`]: large enough to amortise scheduling, small
/// enough to balance a few thousand directions over all cores.
const PAIR_CHUNK: usize = 1024;

/// `out[i] = eval(view[i], light[i])` on all cores, one pair at a time: the loop behind the batch
/// evaluations of the tables and analytic models (the network has its own, wider kernel). Only
/// the common prefix of the slices (components included) is written, so mismatched lengths are
/// not a reason to panic in a renderer callback.
pub(crate) fn par_eval_pairs(
    view: Directions<'_>,
    light: Directions<'_>,
    out: RgbMut<'_>,
    eval: impl Fn(Vec3, Vec3) -> [f32; 3] + Sync,
) {
    let n = common_len(&[view.min_len(), light.min_len(), out.min_len()]);
    let RgbMut { r, g, b } = out;
    r[..n]
        .par_chunks_mut(PAIR_CHUNK)
        .zip(g[..n].par_chunks_mut(PAIR_CHUNK))
        .zip(b[..n].par_chunks_mut(PAIR_CHUNK))
        .enumerate()
        .for_each(|(chunk, ((r, g), b))| {
            let start = chunk * PAIR_CHUNK;
            for i in 0..r.len() {
                let value = eval(view.get(start + i), light.get(start + i));
                (r[i], g[i], b[i]) = (value[0], value[1], value[2]);
            }
        });
}

/// An isotropic reflectance function `f_r(view, light)` in linear RGB.
pub trait Brdf: Send + Sync {
    /// `f_r(view, light)` (not cosine weighted). Zero when either direction is at or below the
    /// horizon; finite and non-negative for every input, unit length or not.
    fn eval(&self, view: Vec3, light: Vec3) -> [f32; 3];

    /// `f_r(view, light) * cos(theta_light)` for a batch (what Mitsuba's `BSDF.eval` returns).
    /// If the slices (components included) differ in length, only their common prefix is
    /// evaluated and the rest of `out` is left as it is. Implementations override this with a
    /// vectorised, multi-threaded version.
    fn eval_cos_batch(&self, view: Directions<'_>, light: Directions<'_>, out: RgbMut<'_>) {
        let mut out = out;
        for i in 0..common_len(&[view.min_len(), light.min_len(), out.min_len()]) {
            let l = light.get(i);
            let cos = cos_theta_light(l);
            let f = self.eval(view.get(i), l);
            out.set(i, [f[0] * cos, f[1] * cos, f[2] * cos]);
        }
    }
}

/// `cos(theta)` of a possibly non-normalised direction, 0 for zero-length vectors.
pub fn cos_theta_light(light: Vec3) -> f32 {
    let len = light.length();
    if len > 0.0 && len.is_finite() {
        (light.z / len).max(0.0)
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The trait's own batch loop, on a reflectance that is 1 everywhere.
    struct One;

    impl Brdf for One {
        fn eval(&self, _: Vec3, _: Vec3) -> [f32; 3] {
            [1.0; 3]
        }
    }

    #[test]
    fn the_default_batch_evaluates_the_common_prefix_of_uneven_components() {
        let up = [0.0, 0.0, 1.0, 1.0, 1.0];
        let zeros = [0.0; 5];
        let view = Directions {
            x: &zeros,
            y: &zeros[..3],
            z: &up,
        };
        let light = Directions {
            x: &zeros,
            y: &zeros,
            z: &up[..4],
        };
        let mut out = [[-1.0f32; 5], [-1.0; 5], [-1.0; 5]];
        let [r, g, b] = &mut out;
        One.eval_cos_batch(view, light, RgbMut { r, g, b });
        // Lanes 0-1 have the light at z = 0 (cos 0), lane 2 at z = 1; 3-4 are past the prefix.
        assert_eq!(out[0], [0.0, 0.0, 1.0, -1.0, -1.0]);
        assert_eq!(out[2], out[0]);
    }
}
