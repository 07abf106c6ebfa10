//! The spectral output of a spectral network (docs/design.md section 9, file format version 3):
//! a clamped uniform cubic B-spline over `[min_nm, max_nm]`, `f_r(l) = sum_k c_k B_k(l)` with
//! the network's `count` outputs `c_k`. Knots `[min]*3 + linspace(min, max, count - 2) +
//! [max]*3`, the basis `python/nbrdf_tools/spectral_basis.py::_bspline_basis` measured
//! (scipy's `BSpline.design_matrix`): four functions are non-zero at any wavelength, they sum to
//! 1, and the last one is 1 at `max_nm` (the right end belongs to the last interval).
//!
//! Also here, computed once per basis: the exact linear sRGB value of each basis function under
//! D65 ([`SpectralBasis::srgb_matrix`], the same integral as [`crate::spectrum::SrgbProjection`])
//! and the least-squares coefficients of a piecewise-linear spectrum
//! ([`SpectralBasis::least_squares`], the training target of spectral networks).

use crate::error::{NbrdfError, Result};
use crate::spectrum::{cie_grid, srgb_of_weighted_integral, weighted_cmf, CIE_MAX, CIE_MIN};
use serde::{Deserialize, Serialize};

/// The only basis the file format defines.
pub const BASIS_CUBIC_BSPLINE: &str = "cubic_bspline";
/// Degree of the B-spline: four basis functions overlap each wavelength.
const DEGREE: usize = 3;
/// The representation chosen by docs/results/spectral-basis.md: 16 coefficients over the
/// observer's range.
pub const DEFAULT_COUNT: usize = 16;
/// The range of `count` a file may give.
pub const MIN_COUNT: usize = 4;
pub const MAX_COUNT: usize = 64;

/// Four-point Gauss-Legendre nodes on [0, 1] and weights (exact to degree 7: a cubic basis
/// function times a cubic, or times a linear hat and a linear colour-matching piece).
const GAUSS_NODES: [f64; 4] = [
    0.069_431_844_202_973_71,
    0.330_009_478_207_571_9,
    0.669_990_521_792_428_1,
    0.930_568_155_797_026_3,
];
const GAUSS_WEIGHTS: [f64; 4] = [
    0.173_927_422_568_726_9,
    0.326_072_577_431_273_1,
    0.326_072_577_431_273_1,
    0.173_927_422_568_726_9,
];

/// The `"spectral"` object of a version-3 network file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SpectralBasis {
    /// Only `"cubic_bspline"` is defined.
    pub basis: String,
    /// Number of coefficients (the network's outputs), in `[4, 64]`.
    pub count: usize,
    pub min_nm: f64,
    pub max_nm: f64,
}

impl Default for SpectralBasis {
    /// 16 coefficients over 360-830 nm, what `nbrdf train` writes.
    fn default() -> Self {
        SpectralBasis {
            basis: BASIS_CUBIC_BSPLINE.to_string(),
            count: DEFAULT_COUNT,
            min_nm: CIE_MIN,
            max_nm: CIE_MAX,
        }
    }
}

impl SpectralBasis {
    /// The first reason this basis is unusable, naming the field, if any.
    pub fn problem(&self) -> Option<String> {
        if self.basis != BASIS_CUBIC_BSPLINE {
            return Some(format!(
                "spectral basis '{}' is unknown (only '{BASIS_CUBIC_BSPLINE}' is defined)",
                self.basis
            ));
        }
        if !(MIN_COUNT..=MAX_COUNT).contains(&self.count) {
            return Some(format!(
                "spectral count {} must be in [{MIN_COUNT}, {MAX_COUNT}]",
                self.count
            ));
        }
        let finite = self.min_nm.is_finite() && self.max_nm.is_finite();
        if !finite || self.min_nm >= self.max_nm {
            return Some(format!(
                "spectral min_nm {} and max_nm {} must be finite with min_nm < max_nm",
                self.min_nm, self.max_nm
            ));
        }
        None
    }

    /// Number of knot intervals, `count - 3`.
    fn intervals(&self) -> usize {
        self.count - DEGREE
    }

    fn spacing(&self) -> f64 {
        (self.max_nm - self.min_nm) / self.intervals() as f64
    }

    /// Knot `i` of the clamped knot vector (`count + 4` knots).
    fn knot(&self, i: usize) -> f64 {
        let inner = i.saturating_sub(DEGREE).min(self.intervals());
        if inner == self.intervals() {
            self.max_nm
        } else {
            self.min_nm + inner as f64 * self.spacing()
        }
    }

    /// The distinct knots, `min_nm` to `max_nm`.
    fn breakpoints(&self) -> impl Iterator<Item = f64> + '_ {
        (0..=self.intervals()).map(|i| self.knot(i + DEGREE))
    }

    /// The four basis functions non-zero at `lambda`: the index of the first and their values
    /// (de Boor's recurrence, "BasisFuns" of The NURBS Book). `None` outside `[min_nm, max_nm]`
    /// and at non-finite wavelengths, where the spectrum is 0.
    pub fn eval(&self, lambda: f64) -> Option<(usize, [f64; 4])> {
        if !(self.min_nm..=self.max_nm).contains(&lambda) {
            return None;
        }
        let span = (((lambda - self.min_nm) / self.spacing()) as usize).min(self.intervals() - 1);
        // The knot vector's index of the interval holding lambda.
        let mu = span + DEGREE;
        let mut n = [1.0, 0.0, 0.0, 0.0];
        let mut left = [0.0; DEGREE + 1];
        let mut right = [0.0; DEGREE + 1];
        for j in 1..=DEGREE {
            left[j] = lambda - self.knot(mu + 1 - j);
            right[j] = self.knot(mu + j) - lambda;
            let mut saved = 0.0;
            for r in 0..j {
                let temp = n[r] / (right[r + 1] + left[j - r]);
                n[r] = saved + right[r + 1] * temp;
                saved = left[j - r] * temp;
            }
            n[j] = saved;
        }
        Some((span, n))
    }

    /// `sum_k c_k B_k(lambda)`: 0 outside the range and at non-finite wavelengths. Coefficients
    /// beyond `count` are ignored, missing ones count as 0.
    pub fn value(&self, coefficients: &[f32], lambda: f32) -> f32 {
        let Some((first, basis)) = self.eval(f64::from(lambda)) else {
            return 0.0;
        };
        let sum: f64 = basis
            .iter()
            .zip(coefficients.iter().skip(first))
            .map(|(b, &c)| b * f64::from(c))
            .sum();
        sum as f32
    }

    /// Per basis function, the linear sRGB value of `B_k` under D65 (`spectrum.rs`'s projection,
    /// exact: Gauss-Legendre on the intervals between the 5 nm tables and the knots, where the
    /// integrand is a polynomial of degree 5). `rgb = sum_k c_k M[k]`; the columns of the
    /// 3 x count matrix of `nbrdf_material_spectral_srgb`.
    pub fn srgb_matrix(&self) -> Vec<[f64; 3]> {
        let (lo, hi) = (self.min_nm.max(CIE_MIN), self.max_nm.min(CIE_MAX));
        let mut xyz = vec![[0.0f64; 3]; self.count];
        let points: Vec<f64> = cie_grid().chain(self.breakpoints()).collect();
        for (a, b) in intervals_within(points, lo, hi) {
            for (t, w) in GAUSS_NODES.iter().zip(GAUSS_WEIGHTS) {
                let l = a + t * (b - a);
                let Some((first, basis)) = self.eval(l) else {
                    continue;
                };
                let cmf = weighted_cmf(l);
                for (k, v) in basis.iter().enumerate() {
                    for c in 0..3 {
                        xyz[first + k][c] += w * (b - a) * v * cmf[c];
                    }
                }
            }
        }
        xyz.into_iter().map(srgb_of_weighted_integral).collect()
    }

    /// The least-squares coefficients of the piecewise-linear spectrum through samples at
    /// `wavelengths` (zero outside them), in L2 over `[min_nm, max_nm]`: the `count x m`
    /// row-major matrix `P = G^-1 H`, `G` the basis' Gram matrix and `H[k][j]` the integral of
    /// `B_k` times the hat function of sample `j` (both exact, Gauss-Legendre between knots and
    /// samples). `c = P s` for samples `s`. The wavelengths must be finite, strictly increasing
    /// and overlap `[min_nm, max_nm]`.
    pub fn least_squares(&self, wavelengths: &[f64]) -> Result<Vec<f64>> {
        crate::spectrum::check_wavelengths(wavelengths, self.min_nm, self.max_nm)?;
        if let Some(message) = self.problem() {
            return Err(NbrdfError::InvalidArgument(message));
        }
        let gram = self.gram();
        let hats = self.hat_integrals(wavelengths);
        let m = wavelengths.len();
        let factor = cholesky(&gram, self.count).ok_or_else(|| {
            NbrdfError::InvalidArgument("the spectral basis' Gram matrix is singular".into())
        })?;
        let mut out = vec![0.0; self.count * m];
        for j in 0..m {
            let column: Vec<f64> = (0..self.count).map(|k| hats[k * m + j]).collect();
            for (k, v) in cholesky_solve(&factor, self.count, column)
                .into_iter()
                .enumerate()
            {
                out[k * m + j] = v;
            }
        }
        Ok(out)
    }

    /// `G[k][l] = int B_k B_l` over the range, row-major.
    fn gram(&self) -> Vec<f64> {
        let count = self.count;
        let mut gram = vec![0.0; count * count];
        let knots: Vec<f64> = self.breakpoints().collect();
        for span in knots.windows(2) {
            let (a, b) = (span[0], span[1]);
            for (t, w) in GAUSS_NODES.iter().zip(GAUSS_WEIGHTS) {
                let Some((first, basis)) = self.eval(a + t * (b - a)) else {
                    continue;
                };
                for (p, bp) in basis.iter().enumerate() {
                    for (q, bq) in basis.iter().enumerate() {
                        gram[(first + p) * count + first + q] += w * (b - a) * bp * bq;
                    }
                }
            }
        }
        gram
    }

    /// `H[k][j] = int B_k hat_j` over the range, row-major `count x m`.
    fn hat_integrals(&self, wavelengths: &[f64]) -> Vec<f64> {
        let m = wavelengths.len();
        let lo = self.min_nm.max(wavelengths[0]);
        let hi = self.max_nm.min(wavelengths[m - 1]);
        let points: Vec<f64> = self
            .breakpoints()
            .chain(wavelengths.iter().copied())
            .collect();
        let mut hats = vec![0.0; self.count * m];
        let mut s = 0;
        for (a, b) in intervals_within(points, lo, hi) {
            // The sample interval [l_s, l_{s+1}] holding [a, b].
            while wavelengths[s + 1] < b {
                s += 1;
            }
            let (l0, l1) = (wavelengths[s], wavelengths[s + 1]);
            for (t, w) in GAUSS_NODES.iter().zip(GAUSS_WEIGHTS) {
                let l = a + t * (b - a);
                let Some((first, basis)) = self.eval(l) else {
                    continue;
                };
                let u = (l - l0) / (l1 - l0);
                for (k, v) in basis.iter().enumerate() {
                    hats[(first + k) * m + s] += w * (b - a) * v * (1.0 - u);
                    hats[(first + k) * m + s + 1] += w * (b - a) * v * u;
                }
            }
        }
        hats
    }
}

/// The consecutive pairs of the sorted, distinct `points` within `[lo, hi]`, ends included.
fn intervals_within(points: Vec<f64>, lo: f64, hi: f64) -> Vec<(f64, f64)> {
    let mut points: Vec<f64> = points
        .into_iter()
        .filter(|l| (lo..=hi).contains(l))
        .chain([lo, hi])
        .collect();
    points.sort_by(f64::total_cmp);
    points.dedup();
    points.windows(2).map(|w| (w[0], w[1])).collect()
}

/// The lower Cholesky factor of a symmetric positive definite `n x n` matrix, row-major.
fn cholesky(a: &[f64], n: usize) -> Option<Vec<f64>> {
    let mut l = vec![0.0; n * n];
    for i in 0..n {
        for j in 0..=i {
            let dot: f64 = (0..j).map(|k| l[i * n + k] * l[j * n + k]).sum();
            let v = a[i * n + j] - dot;
            if i == j {
                if v <= 0.0 {
                    return None;
                }
                l[i * n + i] = v.sqrt();
            } else {
                l[i * n + j] = v / l[j * n + j];
            }
        }
    }
    Some(l)
}

/// Solves `L L^T x = b` with the factor of [`cholesky`].
fn cholesky_solve(l: &[f64], n: usize, mut b: Vec<f64>) -> Vec<f64> {
    for i in 0..n {
        let dot: f64 = (0..i).map(|k| l[i * n + k] * b[k]).sum();
        b[i] = (b[i] - dot) / l[i * n + i];
    }
    for i in (0..n).rev() {
        let dot: f64 = (i + 1..n).map(|k| l[k * n + i] * b[k]).sum();
        b[i] = (b[i] - dot) / l[i * n + i];
    }
    b
}

#[cfg(test)]
mod tests {
    use super::*;

    fn basis() -> SpectralBasis {
        SpectralBasis::default()
    }

    fn dense(b: &SpectralBasis, lambda: f64) -> Vec<f64> {
        let mut out = vec![0.0; b.count];
        if let Some((first, values)) = b.eval(lambda) {
            out[first..first + 4].copy_from_slice(&values);
        }
        out
    }

    #[test]
    fn the_basis_is_a_partition_of_unity_and_zero_outside() {
        let b = basis();
        for i in 0..=470 {
            let l = 360.0 + i as f64;
            let sum: f64 = dense(&b, l).iter().sum();
            assert!((sum - 1.0).abs() < 1e-12, "{l}: {sum}");
            assert!(dense(&b, l).iter().all(|v| *v >= 0.0));
        }
        for l in [359.999, 830.001, f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
            assert!(b.eval(l).is_none(), "{l}");
            assert_eq!(b.value(&[1.0; 16], l as f32), 0.0);
        }
    }

    /// The closed form of the uniform cubic B-spline at interior knots, 1/6, 2/3, 1/6, away
    /// from the clamped ends; at the ends the first and last functions are 1.
    #[test]
    fn known_values_at_the_knots() {
        let b = basis();
        let h = 470.0 / 13.0;
        // Knot 360 + 6 h is interior: B_6, B_7, B_8 are the uniform B-spline there.
        let v = dense(&b, 360.0 + 6.0 * h);
        for (k, expected) in [(6, 1.0 / 6.0), (7, 2.0 / 3.0), (8, 1.0 / 6.0)] {
            assert!((v[k] - expected).abs() < 1e-12, "{v:?}");
        }
        assert!((dense(&b, 360.0)[0] - 1.0).abs() < 1e-15);
        assert!((dense(&b, 830.0)[15] - 1.0).abs() < 1e-12);
        // The uniform cubic's value at a span's midpoint: 1/48, 23/48, 23/48, 1/48.
        let v = dense(&b, 360.0 + 6.5 * h);
        for (k, expected) in [(6, 1.0), (7, 23.0), (8, 23.0), (9, 1.0)] {
            assert!((v[k] - expected / 48.0).abs() < 1e-12, "{v:?}");
        }
    }

    #[test]
    fn a_constant_spectrum_projects_to_the_constant() {
        let b = basis();
        let wavelengths = [300.0, 412.5, 555.0, 700.0, 900.0];
        let p = b.least_squares(&wavelengths).unwrap();
        for k in 0..b.count {
            let c: f64 = (0..5).map(|j| p[k * 5 + j] * 2.5).sum();
            assert!((c - 2.5).abs() < 1e-9, "coefficient {k}: {c}");
        }
    }

    /// A spline in the span is reproduced exactly: samples of a spline on a fine grid give a
    /// piecewise-linear spectrum within the interpolation error of the spline.
    #[test]
    fn least_squares_recovers_a_spline() {
        let b = basis();
        let coefficients: Vec<f32> = (0..16).map(|k| 0.2 + 0.05 * (k as f32).sin()).collect();
        let wavelengths: Vec<f64> = (0..=940).map(|i| 360.0 + 0.5 * i as f64).collect();
        let samples: Vec<f64> = wavelengths
            .iter()
            .map(|&l| f64::from(b.value(&coefficients, l as f32)))
            .collect();
        let p = b.least_squares(&wavelengths).unwrap();
        let m = wavelengths.len();
        for (k, &c) in coefficients.iter().enumerate() {
            let fit: f64 = (0..m).map(|j| p[k * m + j] * samples[j]).sum();
            assert!((fit - f64::from(c)).abs() < 1e-5, "{k}: {fit} vs {c}");
        }
    }

    #[test]
    fn all_ones_is_white() {
        let m = basis().srgb_matrix();
        for c in 0..3 {
            let sum: f64 = m.iter().map(|row| row[c]).sum();
            assert!((sum - 1.0).abs() < 3e-4, "{c}: {sum}");
        }
    }

    /// The matrix against the sample projection of `spectrum.rs` applied to each basis function
    /// sampled every 0.25 nm (linear interpolation error ~1e-6 at that step).
    #[test]
    fn srgb_matrix_matches_the_sampled_projection() {
        let b = basis();
        let wavelengths: Vec<f64> = (0..=1880).map(|i| 360.0 + 0.25 * i as f64).collect();
        let projection = crate::spectrum::SrgbProjection::new(&wavelengths).unwrap();
        let m = b.srgb_matrix();
        for k in [0, 5, 15] {
            let samples: Vec<f32> = wavelengths
                .iter()
                .map(|&l| dense(&b, l)[k] as f32)
                .collect();
            let rgb = projection.project(&samples);
            for c in 0..3 {
                assert!(
                    (rgb[c] - m[k][c]).abs() < 1e-5,
                    "{k} {c}: {rgb:?} {:?}",
                    m[k]
                );
            }
        }
    }

    #[test]
    fn refusals_name_the_field() {
        let with = |f: &dyn Fn(&mut SpectralBasis)| {
            let mut b = basis();
            f(&mut b);
            b.problem().unwrap_or_default()
        };
        assert!(with(&|b| b.basis = "fourier".into()).contains("basis"));
        assert!(with(&|b| b.count = 3).contains("count"));
        assert!(with(&|b| b.count = 65).contains("count"));
        assert!(with(&|b| b.max_nm = f64::NAN).contains("max_nm"));
        assert!(with(&|b| b.min_nm = 900.0).contains("min_nm"));
        assert!(basis().problem().is_none());
        let message = basis().least_squares(&[500.0, 400.0]).unwrap_err();
        assert!(message.to_string().contains("strictly increasing"));
    }
}
