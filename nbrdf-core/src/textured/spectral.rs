//! A spectral material's value per wavelength: the decoder's coefficients times
//! `cos(theta_light)` at each hit, then `sum_k c_k B_k(lambda)` with the basis of spectral
//! networks ([`crate::network::Spectral`]), in the layout of
//! [`crate::Nbrdf::eval_spectral_cos_batch`]. Its RGB value (`eval_cos`, sampling weights) is the
//! sRGB projection of the same coefficients ([`super::Decoder::rgb_of`]).

use super::{Lanes, TexturedNbrdf, Uvs, TASK_LANES};
use crate::brdf::{common_len, Directions};
use crate::error::{NbrdfError, Result};
#[cfg(any(target_arch = "x86", target_arch = "x86_64"))]
use crate::fastmath::Fused;
use crate::fastmath::{MulAdd, Unfused};
use crate::network::check_spectral_batch;
use rayon::prelude::*;

impl TexturedNbrdf {
    /// `f_r(view_i, light_i, lambda) cos(theta_light)` of a spectral material at `n` hits (the
    /// common length of `uv`, `view` and `light`) and `m = wavelengths.len() / n` wavelengths per
    /// hit: wavelength `j` of hit `i` at `wavelengths[j n + i]`, its value written to
    /// `out[j n + i]`. 0 where [`TexturedNbrdf::eval_cos`] is (bad texels, at or below the
    /// horizon) and at wavelengths outside the basis' range or not finite. An error for an RGB
    /// material, or when `wavelengths` and `out` do not both hold `m n` values.
    pub fn eval_spectral_cos_batch(
        &self,
        uv: Uvs<'_>,
        view: Directions<'_>,
        light: Directions<'_>,
        wavelengths: &[f32],
        out: &mut [f32],
    ) -> Result<()> {
        let Some(spectral) = self.decoder.spectral() else {
            return Err(NbrdfError::InvalidArgument(format!(
                "material '{}' is an RGB spatially varying material, not a spectral one (its \
                 file has no \"spectral\" object)",
                self.name
            )));
        };
        let n = common_len(&[uv.min_len(), view.min_len(), light.min_len()]);
        check_spectral_batch(n, wavelengths, out)?;
        if n == 0 {
            return Ok(());
        }
        let count = spectral.count();
        let mut coefficients = vec![0.0f32; n * count];
        coefficients
            .par_chunks_mut(TASK_LANES * count)
            .enumerate()
            .for_each(|(k, chunk)| {
                self.coefficients_chunk(Lanes::new(k * TASK_LANES, uv, view), light, chunk);
            });
        spectral.values_into(&coefficients, wavelengths, out);
        Ok(())
    }

    /// One task's coefficients times `cos(theta_light)`, `count` a lane, with the kernel for
    /// this CPU.
    fn coefficients_chunk(&self, lanes: Lanes<'_>, light: Directions<'_>, out: &mut [f32]) {
        #[cfg(any(target_arch = "x86", target_arch = "x86_64"))]
        if crate::network::has_avx2_fma() {
            // SAFETY: the CPU has AVX2 and FMA (checked just above), all it requires.
            return unsafe { self.coefficients_chunk_avx2(lanes, light, out) };
        }
        self.coefficients_chunk_with::<Unfused>(lanes, light, out)
    }

    #[cfg(any(target_arch = "x86", target_arch = "x86_64"))]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn coefficients_chunk_avx2(
        &self,
        lanes: Lanes<'_>,
        light: Directions<'_>,
        out: &mut [f32],
    ) {
        self.coefficients_chunk_with::<Fused>(lanes, light, out)
    }

    #[inline(always)]
    fn coefficients_chunk_with<M: MulAdd>(
        &self,
        lanes: Lanes<'_>,
        light: Directions<'_>,
        out: &mut [f32],
    ) {
        let count = self.decoder.output_count();
        for (i, row) in out.chunks_exact_mut(count).enumerate() {
            let j = lanes.start + i;
            let footprint = self.footprint(lanes.uv.get(j));
            let view = lanes.view.get(j);
            let written =
                self.outputs_cos_at::<M, _>(footprint.as_ref(), view, light.get(j), |c| {
                    row.copy_from_slice(c)
                });
            if written.is_none() {
                row.fill(0.0);
            }
        }
    }
}
