//! Mitsuba's `Marginal2D<Float, Dimension, Continuous = true>` (`include/mitsuba/core/distr_2d.h`,
//! Mitsuba 3.9): a bilinearly interpolated 2D density on `[0, 1]^2`, linearly interpolated in up
//! to three conditioning parameters, with the inverse of its continuous marginal/conditional
//! sampling map. The `measured` BSDF evaluates its tables through `eval` and `invert` only.
//!
//! This is a deliberate second copy of Mitsuba's arithmetic, in float32 and in the same order of
//! operations, with Dr.Jit's `fmadd` as a fused multiply-add (the Linux wheels are built with FMA
//! enabled; `f32::mul_add`), so that results agree with Mitsuba's scalar variants to the last bit
//! almost everywhere. The test that holds the two together is `tests/test_rgl_reader.py`.

use crate::error::{NbrdfError, Result};

/// At most this many conditioning parameters (Mitsuba instantiates 0 to 3).
pub const MAX_PARAMS: usize = 3;

/// Interpolation of the conditioning parameters: the first slice and the two weights per
/// parameter (Mitsuba's `interpolate_weights`).
#[derive(Clone, Copy, Debug, Default)]
pub struct SliceWeights {
    offset: usize,
    weights: [[f32; 2]; MAX_PARAMS],
}

/// A conditional 2D density on a `width x height` grid (x contiguous), with `slices` copies, one
/// per combination of parameter values (the first parameter varies slowest).
#[derive(Clone, Debug)]
pub struct Marginal2D {
    width: usize,
    height: usize,
    param_values: Vec<Vec<f32>>,
    /// Stride of each parameter in slices (0 for a parameter with one value).
    param_strides: Vec<usize>,
    patch_size: [f32; 2],
    inv_patch_size: [f32; 2],
    data: Vec<f32>,
    /// Per slice: `height - 1` running integrals over rows (empty without sampling tables).
    marg_cdf: Vec<f32>,
    /// Per slice: `height * (width - 1)` running integrals along each row.
    cond_cdf: Vec<f32>,
    normalized: bool,
}

/// `a + (b - a) t` as Dr.Jit computes it: `fmadd(b, t, fnmadd(a, t, a))`.
#[inline(always)]
fn lerp(a: f32, b: f32, t: f32) -> f32 {
    b.mul_add(t, (-a).mul_add(t, a))
}

fn invalid<T>(message: String) -> Result<T> {
    Err(NbrdfError::InvalidArgument(format!(
        "Marginal2D: {message}"
    )))
}

/// Per parameter its stride in slices (0 for a parameter with one value; the first parameter
/// varies slowest), and the number of slices.
fn param_strides(param_values: &[Vec<f32>]) -> Result<(Vec<usize>, usize)> {
    if param_values.len() > MAX_PARAMS {
        return invalid(format!(
            "{} parameters, at most {MAX_PARAMS}",
            param_values.len()
        ));
    }
    let mut param_strides = vec![0; param_values.len()];
    let mut slices = 1usize;
    for (i, values) in param_values.iter().enumerate().rev() {
        if values.is_empty() {
            return invalid(format!("parameter {i} has no values"));
        }
        if !values.windows(2).all(|w| w[0] < w[1]) {
            return invalid(format!("parameter {i} values are not strictly increasing"));
        }
        param_strides[i] = if values.len() > 1 { slices } else { 0 };
        slices *= values.len();
    }
    Ok((param_strides, slices))
}

/// Appends the running integrals of a `w x h` slice (trapezoids, summed in float64 as Mitsuba
/// does) to the CDFs: `w - 1` along each row, `h - 1` over rows. With `normalize` they are scaled
/// to end at one and the scale is returned (else 1).
fn push_cdfs(
    slice: &[f32],
    [w, h]: [usize; 2],
    normalize: bool,
    marg_cdf: &mut Vec<f32>,
    cond_cdf: &mut Vec<f32>,
) -> f32 {
    let scale_x = 0.5 / (w - 1) as f64;
    let scale_y = 0.5 / (h - 1) as f64;
    let cond_start = cond_cdf.len();
    let marg_start = marg_cdf.len();
    let mut row_sums = Vec::with_capacity(h);
    for row in slice.chunks_exact(w) {
        let mut accum = 0.0f64;
        for x in 0..w - 1 {
            accum += scale_x * (row[x] as f64 + row[x + 1] as f64);
            cond_cdf.push(accum as f32);
        }
        row_sums.push(accum);
    }
    let mut accum = 0.0f64;
    for y in 0..h - 1 {
        accum += scale_y * (row_sums[y] + row_sums[y + 1]);
        marg_cdf.push(accum as f32);
    }
    let norm = if normalize { (1.0 / accum) as f32 } else { 1.0 };
    cond_cdf[cond_start..].iter_mut().for_each(|v| *v *= norm);
    marg_cdf[marg_start..].iter_mut().for_each(|v| *v *= norm);
    debug_assert_eq!(cond_cdf.len() - cond_start, (w - 1) * h);
    debug_assert_eq!(marg_cdf.len() - marg_start, h - 1);
    norm
}

/// The scale that makes a `w x h` slice integrate to one over its bilinear patches.
fn slice_norm(slice: &[f32], [w, h]: [usize; 2]) -> f32 {
    let scale_x = 0.5 / (w - 1) as f64;
    let scale_y = 0.5 / (h - 1) as f64;
    let mut sum = 0.0f64;
    for y in 0..h - 1 {
        for x in 0..w - 1 {
            let i = y * w + x;
            sum += slice[i] as f64
                + slice[i + 1] as f64
                + slice[i + w] as f64
                + slice[i + w + 1] as f64;
        }
    }
    (1.0 / (scale_x * scale_y * sum)) as f32
}

impl Marginal2D {
    /// Builds the density from `data` (`slices * height * width` values, row-major) and the
    /// parameter grids `param_values` (each sorted ascending; their lengths multiply to `slices`).
    ///
    /// `normalize` scales each slice to integrate to one; `enable_sampling` builds the CDFs that
    /// [`Marginal2D::invert`] needs (it implies `normalize` for the inversion to be meaningful,
    /// as in Mitsuba). The caller has validated values (finite); structural mismatches are
    /// reported as [`NbrdfError::InvalidArgument`].
    pub fn new(
        data: &[f32],
        width: usize,
        height: usize,
        param_values: Vec<Vec<f32>>,
        normalize: bool,
        enable_sampling: bool,
    ) -> Result<Marginal2D> {
        if width < 2 || height < 2 {
            return invalid(format!(
                "resolution {width} x {height}, must be at least 2 x 2"
            ));
        }
        let (param_strides, slices) = param_strides(&param_values)?;
        let n_data = width * height;
        if data.len() != slices * n_data {
            return invalid(format!(
                "{} values, expected {slices} slices of {width} x {height}",
                data.len()
            ));
        }
        let (w, h) = (width, height);
        let mut data_out = Vec::with_capacity(data.len());
        let (mut marg_cdf, mut cond_cdf) = (Vec::new(), Vec::new());
        for slice in data.chunks_exact(n_data) {
            let norm = if enable_sampling {
                push_cdfs(slice, [w, h], normalize, &mut marg_cdf, &mut cond_cdf)
            } else if normalize {
                slice_norm(slice, [w, h])
            } else {
                1.0
            };
            if !norm.is_finite() {
                return invalid("a slice integrates to zero and cannot be normalised".into());
            }
            data_out.extend(slice.iter().map(|v| v * norm));
        }
        let n_patches = [(w - 1) as u32, (h - 1) as u32];
        Ok(Marginal2D {
            width,
            height,
            param_values,
            param_strides,
            // Mitsuba: `1.f / n_patches` and `n_patches` as float vectors.
            patch_size: [1.0 / n_patches[0] as f32, 1.0 / n_patches[1] as f32],
            inv_patch_size: [n_patches[0] as f32, n_patches[1] as f32],
            data: data_out,
            marg_cdf,
            cond_cdf,
            normalized: normalize,
        })
    }

    pub fn width(&self) -> usize {
        self.width
    }

    pub fn height(&self) -> usize {
        self.height
    }

    /// Weights of the parameter values `param` (one per parameter; extra entries are ignored).
    pub fn weights(&self, param: &[f32]) -> SliceWeights {
        let mut out = SliceWeights::default();
        for (dim, values) in self.param_values.iter().enumerate() {
            if values.len() == 1 {
                out.weights[dim] = [1.0, 0.0];
                continue;
            }
            let p = param[dim];
            // math::find_interval: the last index i in [0, n - 2] with values[i] < p (0 if none).
            let below = values[1..values.len() - 1].partition_point(|&v| v < p);
            let index = below;
            let (p0, p1) = (values[index], values[index + 1]);
            let w1 = ((p - p0) / (p1 - p0)).clamp(0.0, 1.0);
            out.weights[dim] = [1.0 - w1, w1];
            out.offset += self.param_strides[dim] * index;
        }
        out
    }

    /// The value at slice-relative index `i` of `table` (a per-slice table of `size` entries),
    /// interpolated over the parameters (Mitsuba's recursive `lookup`, last parameter outermost).
    #[inline(always)]
    fn lookup(&self, table: &[f32], i: usize, size: usize, w: &SliceWeights) -> f32 {
        self.lookup_dim(table, i, size, w, self.param_values.len())
    }

    fn lookup_dim(
        &self,
        table: &[f32],
        i0: usize,
        size: usize,
        w: &SliceWeights,
        dim: usize,
    ) -> f32 {
        if dim == 0 {
            return table[i0];
        }
        let stride = self.param_strides[dim - 1];
        let [w0, w1] = w.weights[dim - 1];
        if stride == 0 {
            // One parameter value: Mitsuba computes v * 1 + v * 0, which is v for finite v.
            return self.lookup_dim(table, i0, size, w, dim - 1);
        }
        let v0 = self.lookup_dim(table, i0, size, w, dim - 1);
        let v1 = self.lookup_dim(table, i0 + stride * size, size, w, dim - 1);
        v0.mul_add(w0, v1 * w1)
    }

    /// Cell of `pos` (already scaled to patch units) and the fractional position inside it.
    #[inline(always)]
    fn cell(&self, pos: [f32; 2]) -> ([usize; 2], [f32; 2]) {
        let mut cell = [0usize; 2];
        let mut frac = [0f32; 2];
        let limits = [self.width - 2, self.height - 2];
        for k in 0..2 {
            let clipped = pos[k].clamp(0.0, 1.0);
            let scaled = clipped * self.inv_patch_size[k];
            // Point2u(Point2i(x)): truncation; x is in [0, n_patches].
            let c = (scaled as i32 as u32 as usize).min(limits[k]);
            cell[k] = c;
            frac[k] = scaled - c as f32;
        }
        (cell, frac)
    }

    /// The interpolated density at `pos` (Mitsuba's `eval`).
    pub fn eval(&self, pos: [f32; 2], w: &SliceWeights) -> f32 {
        let (cell, t) = self.cell(pos);
        let n_data = self.width * self.height;
        let i = w.offset * n_data + cell[1] * self.width + cell[0];
        let v00 = self.lookup(&self.data, i, n_data, w);
        let v10 = self.lookup(&self.data, i + 1, n_data, w);
        let v01 = self.lookup(&self.data, i + self.width, n_data, w);
        let v11 = self.lookup(&self.data, i + self.width + 1, n_data, w);
        lerp(lerp(v00, v10, t[0]), lerp(v01, v11, t[0]), t[1])
    }

    /// The inverse of the continuous sampling map at `sample` and the density there (Mitsuba's
    /// `invert_continuous`). Needs the sampling tables (`enable_sampling`).
    pub fn invert(&self, sample: [f32; 2], w: &SliceWeights) -> ([f32; 2], f32) {
        debug_assert!(
            !self.marg_cdf.is_empty(),
            "Marginal2D::invert without sampling tables"
        );
        let (width, height) = (self.width, self.height);
        let n_cond = height * (width - 1);
        let n_marg = height - 1;
        let n_data = width * height;
        let ([px, py], [mut sx, mut sy]) = self.cell(sample);

        let offset_data = w.offset * n_data + py * width + px;
        let v00 = self.lookup(&self.data, offset_data, n_data, w);
        let v10 = self.lookup(&self.data, offset_data + 1, n_data, w);
        let v01 = self.lookup(&self.data, offset_data + width, n_data, w);
        let v11 = self.lookup(&self.data, offset_data + width + 1, n_data, w);
        let c0 = lerp(v00, v01, sy);
        let c1 = lerp(v10, v11, sy);
        let pdf = lerp(c0, c1, sx);

        let offset_cond = w.offset * n_cond + py * (width - 1);
        let mut prev = 0.0;
        if px > 0 {
            let idx = offset_cond + px - 1;
            let a = self.lookup(&self.cond_cdf, idx, n_cond, w);
            let b = self.lookup(&self.cond_cdf, idx + width - 1, n_cond, w);
            prev = lerp(a, b, sy);
        }
        sx = invert_segment(sx, self.patch_size[0], c0, c1) + prev;
        let r0 = self.lookup(&self.cond_cdf, offset_cond + (width - 1) - 1, n_cond, w);
        let r1 = self.lookup(&self.cond_cdf, offset_cond + 2 * (width - 1) - 1, n_cond, w);
        // Real measurements have VNDF rows without density (cc_ibiza_sunset_rgb); where the
        // interpolated row total is zero, Mitsuba divides 0 by 0 (NaN) and the position within
        // the row is taken as 0 here.
        sx = divide_or_zero(sx, lerp(r0, r1, sy));

        let offset_marg = w.offset * n_marg;
        let mut prev = 0.0;
        if py > 0 {
            prev = self.lookup(&self.marg_cdf, offset_marg + py - 1, n_marg, w);
        }
        sy = invert_segment(sy, self.patch_size[1], r0, r1) + prev;
        if !self.normalized {
            sy = divide_or_zero(
                sy,
                self.lookup(&self.marg_cdf, offset_marg + n_marg - 1, n_marg, w),
            );
        }
        ([sx, sy], pdf)
    }
}

/// `x / total`, or 0 where the total is not positive (a region without density).
#[inline(always)]
fn divide_or_zero(x: f32, total: f32) -> f32 {
    if total > 0.0 {
        x / total
    } else {
        0.0
    }
}

#[inline(always)]
fn invert_segment(sample: f32, width: f32, v0: f32, v1: f32) -> f32 {
    sample * lerp(v0, v1, 0.5 * sample) * width
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A separable density `f(x, y) = g(x) h(y)` with piecewise linear g and h has a closed-form
    /// continuous CDF; the inverse map must reproduce it.
    #[test]
    fn invert_matches_closed_form_cdf_of_a_linear_ramp() {
        // f(x, y) = (1 + x) (1 + 2 y) on a 2 x 2 grid: bilinear, exactly representable.
        let data = [1.0, 2.0, 3.0, 6.0];
        let m = Marginal2D::new(&data, 2, 2, vec![], true, true).unwrap();
        let w = m.weights(&[]);
        for &(x, y) in &[
            (0.0f32, 0.0f32),
            (0.25, 0.5),
            (0.7, 0.1),
            (1.0, 1.0),
            (0.5, 0.9),
        ] {
            let ([u, v], pdf) = m.invert([x, y], &w);
            // Normalised: integral of (1 + x)(1 + 2y) over the square = 1.5 * 2 = 3.
            let expected_pdf = (1.0 + x) * (1.0 + 2.0 * y) / 3.0;
            let expected_v = (y + y * y) / 2.0; // marginal CDF in y
            let expected_u = (x + 0.5 * x * x) / 1.5; // conditional CDF in x
            assert!(
                (pdf - expected_pdf).abs() < 1e-6,
                "pdf {pdf} vs {expected_pdf}"
            );
            assert!((v - expected_v).abs() < 1e-6, "v {v} vs {expected_v}");
            assert!((u - expected_u).abs() < 1e-6, "u {u} vs {expected_u}");
            assert!((m.eval([x, y], &w) - expected_pdf).abs() < 1e-6);
        }
    }

    #[test]
    fn parameters_interpolate_linearly_and_clamp() {
        // Two slices of constant value 1 and 3 at parameter values 0 and 2; not normalised.
        let data = [1.0, 1.0, 1.0, 1.0, 3.0, 3.0, 3.0, 3.0];
        let m = Marginal2D::new(&data, 2, 2, vec![vec![0.0, 2.0]], false, false).unwrap();
        for &(p, expected) in &[
            (-1.0f32, 1.0f32),
            (0.0, 1.0),
            (0.5, 1.5),
            (2.0, 3.0),
            (5.0, 3.0),
        ] {
            let value = m.eval([0.3, 0.6], &m.weights(&[p]));
            assert!(
                (value - expected).abs() < 1e-6,
                "param {p}: {value} vs {expected}"
            );
        }
    }

    #[test]
    fn rejects_bad_structure() {
        assert!(Marginal2D::new(&[1.0; 2], 2, 1, vec![], true, true).is_err());
        assert!(Marginal2D::new(&[1.0; 4], 2, 2, vec![vec![1.0, 0.0]], true, true).is_err());
        assert!(Marginal2D::new(&[1.0; 4], 2, 2, vec![vec![0.0, 1.0]], true, true).is_err());
        assert!(Marginal2D::new(&[0.0; 4], 2, 2, vec![], true, true).is_err());
    }
}
