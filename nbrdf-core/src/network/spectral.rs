//! Spectral networks (file format version 3): the network's outputs are the coefficients `c_k`
//! of a [`SpectralBasis`], `f_r(lambda) = sum_k c_k B_k(lambda)`; their RGB value is the linear
//! sRGB projection of that spectrum under D65, `rgb = M c` with the basis' fixed matrix
//! ([`SpectralBasis::srgb_matrix`]), so every RGB path (eval, sample, tables, fits) works on
//! them unchanged.

use super::Nbrdf;
use super::OUTPUTS;
use crate::brdf::{common_len, Directions, RgbMut};
use crate::error::{NbrdfError, Result};
use crate::spectral_basis::SpectralBasis;
use rayon::prelude::*;

/// A validated spectral basis and its sRGB matrix, computed once.
#[derive(Clone, Debug, PartialEq)]
pub struct Spectral {
    basis: SpectralBasis,
    /// Per coefficient, the linear sRGB value of its basis function.
    srgb: Vec<[f64; 3]>,
}

impl Spectral {
    /// Checks the basis ([`SpectralBasis::problem`]) and computes its sRGB matrix.
    pub fn new(basis: SpectralBasis) -> Result<Self> {
        if let Some(message) = basis.problem() {
            return Err(NbrdfError::InvalidArgument(message));
        }
        let srgb = basis.srgb_matrix();
        Ok(Spectral { basis, srgb })
    }

    pub fn basis(&self) -> &SpectralBasis {
        &self.basis
    }

    /// Number of coefficients, the network's outputs.
    pub fn count(&self) -> usize {
        self.basis.count
    }

    /// The 3 x count matrix `M` (`rgb = M c`), row-major.
    pub fn srgb_matrix(&self) -> Vec<f64> {
        (0..3)
            .flat_map(|c| self.srgb.iter().map(move |column| column[c]))
            .collect()
    }

    /// The RGB value `M c` of the coefficients `c` (float64 sums).
    pub fn project(&self, coefficients: &[f32]) -> [f32; 3] {
        let mut rgb = [0.0f64; 3];
        for (column, &c) in self.srgb.iter().zip(coefficients) {
            for (sum, m) in rgb.iter_mut().zip(column) {
                *sum += m * f64::from(c);
            }
        }
        rgb.map(|v| v as f32)
    }

    /// `out[j n + i] = sum_k c_ik B_k(wavelengths[j n + i])` for the `n` pairs' coefficients
    /// (`coefficients[i count + k]`, `n = coefficients.len() / count`); the layout is checked
    /// by [`check_spectral_batch`].
    pub(crate) fn values_into(&self, coefficients: &[f32], wavelengths: &[f32], out: &mut [f32]) {
        let count = self.count();
        let n = coefficients.len() / count;
        out.par_chunks_mut(n)
            .zip(wavelengths.par_chunks(n))
            .for_each(|(values, lambdas)| {
                for (i, (v, &l)) in values.iter_mut().zip(lambdas).enumerate() {
                    *v = self
                        .basis
                        .value(&coefficients[i * count..(i + 1) * count], l);
                }
            });
    }
}

impl Nbrdf {
    /// The last layer's width the network must have: 3, or a spectral network's count.
    pub fn output_count(&self) -> usize {
        self.spectral.as_ref().map_or(OUTPUTS, Spectral::count)
    }

    /// The RGB value of a spectral network's batch: its coefficients, then `M c` per pair.
    pub(super) fn eval_spectral_rgb(
        &self,
        spectral: &Spectral,
        view: Directions<'_>,
        light: Directions<'_>,
        out: RgbMut<'_>,
    ) {
        let count = spectral.count();
        let n = common_len(&[view.min_len(), light.min_len(), out.min_len()]);
        let mut coefficients = vec![0.0f32; n * count];
        self.eval_outputs_cos_batch(view, light, &mut coefficients);
        let rows = out.r[..n]
            .par_iter_mut()
            .zip(&mut out.g[..n])
            .zip(&mut out.b[..n])
            .zip(coefficients.par_chunks(count));
        rows.for_each(|(((r, g), b), c)| {
            [*r, *g, *b] = spectral.project(c);
        });
    }

    /// `f_r(view_i, light_i, lambda) cos(theta_light)` of a spectral network for `n` direction
    /// pairs (the common length of `view` and `light`) and `m = wavelengths.len() / n`
    /// wavelengths per pair: wavelength `j` of pair `i` at `wavelengths[j n + i]`, its value
    /// written to `out[j n + i]`. 0 below the horizon and at wavelengths outside the basis'
    /// range or not finite. An error for an RGB network, or when `wavelengths` and `out` do not
    /// both hold `m n` values.
    pub fn eval_spectral_cos_batch(
        &self,
        view: Directions<'_>,
        light: Directions<'_>,
        wavelengths: &[f32],
        out: &mut [f32],
    ) -> Result<()> {
        let Some(spectral) = &self.spectral else {
            return Err(NbrdfError::InvalidArgument(format!(
                "network '{}' is an RGB network, not a spectral one (file format version 3)",
                self.name
            )));
        };
        let n = common_len(&[view.min_len(), light.min_len()]);
        check_spectral_batch(n, wavelengths, out)?;
        if n == 0 {
            return Ok(());
        }
        let count = spectral.count();
        let mut coefficients = vec![0.0f32; n * count];
        self.eval_outputs_cos_batch(view, light, &mut coefficients);
        spectral.values_into(&coefficients, wavelengths, out);
        Ok(())
    }
}

/// The layout of a spectral batch of `n` pairs: `wavelengths` and `out` must both hold `m n`
/// values; an error naming the lengths otherwise.
pub(crate) fn check_spectral_batch(n: usize, wavelengths: &[f32], out: &[f32]) -> Result<()> {
    if wavelengths.len() != out.len() || (n == 0 && !out.is_empty()) || out.len() % n.max(1) != 0 {
        return Err(NbrdfError::InvalidArgument(format!(
            "{} wavelengths and {} outputs for {n} direction pairs: both must be m n",
            wavelengths.len(),
            out.len()
        )));
    }
    Ok(())
}

#[cfg(test)]
#[path = "spectral_tests.rs"]
pub(crate) mod tests;
