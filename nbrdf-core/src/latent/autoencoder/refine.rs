//! Refining a code by analysis by synthesis: Levenberg-Marquardt on the image loss against the
//! material's own sphere, from the encoder's code and the closest training codes; and the
//! refined validation loss that chooses between trained autoencoders.

use super::data::find_network;
use super::{AutoEncoder, REFINE_STARTS, SCREEN_ITERATIONS, SCREEN_STARTS};
use crate::error::{NbrdfError, Result};
use crate::latent::sphere::{Scratch, SphereRenderer};
use crate::network::Nbrdf;
use rayon::prelude::*;

impl AutoEncoder {
    /// Refines a code by analysis by synthesis: Levenberg-Marquardt on the tone-mapped pixel
    /// residuals of the decoded network's sphere against the input network's own (the image
    /// loss is their mean square), from the encoder's code and from the [`SCREEN_STARTS`]` - 1`
    /// recorded training codes ([`AutoEncoder::anchors`]) whose spheres are closest to the
    /// target: each start gets [`SCREEN_ITERATIONS`] iterations, the [`REFINE_STARTS`] best go
    /// on for the rest, the best result wins. 0 iterations return the encoder's code. This closes the
    /// gap between what the encoder predicts for an unseen material and the best the decoder
    /// can express.
    /// With 32 unknowns the Jacobian costs 32 extra renders (forward differences) and the
    /// damped normal equations are a 32 x 32 solve, so each iteration is cheap and
    /// converges where first-order steps crawl along the loss's ill-conditioned valleys.
    /// Returns the best code visited (the start if nothing improves).
    pub fn refine_code(&self, flat: &[f32], code: &[f32], iterations: usize) -> Vec<f32> {
        if iterations == 0 {
            return code.to_vec();
        }
        let renderer = self.sphere();
        let target = renderer.render_toned(flat, &mut renderer.scratch());
        // Local search can stall in a poor valley of the decoder's manifold; starting also
        // from the training codes that already look most like the target avoids most stalls.
        let mut ranked: Vec<(f64, &Vec<f32>)> = self
            .anchors
            .par_iter()
            .filter(|a| a.len() == code.len())
            .map(|a| {
                let r = self.residual(&renderer, &target, a, &mut renderer.scratch());
                (r.iter().map(|v| v * v).sum::<f64>(), a)
            })
            .filter(|(c, _)| c.is_finite())
            .collect();
        ranked.sort_by(|a, b| a.0.total_cmp(&b.0));
        // The closest sphere is not always the closest valley: a short screen of several
        // starts finds the basins worth the full budget (one material in twenty stalled 10x
        // above the rest's error with three full-length starts and no screen).
        let screen = iterations.min(SCREEN_ITERATIONS);
        let mut screened: Vec<(Vec<f32>, f64)> = std::iter::once(code)
            .chain(ranked.iter().map(|(_, a)| a.as_slice()))
            .take(SCREEN_STARTS)
            .map(|z| self.levenberg_marquardt(&renderer, &target, z, screen))
            .collect();
        screened.sort_by(|a, b| a.1.total_cmp(&b.1));
        screened.truncate(REFINE_STARTS);
        screened
            .into_iter()
            .map(|(z, cost)| {
                if iterations > screen {
                    self.levenberg_marquardt(&renderer, &target, &z, iterations - screen)
                } else {
                    (z, cost)
                }
            })
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .map_or_else(|| code.to_vec(), |(z, _)| z)
    }

    /// Tone-mapped pixel residuals of the sphere decoded from `z` against `target`.
    fn residual(
        &self,
        renderer: &SphereRenderer,
        target: &[f32],
        z: &[f32],
        scratch: &mut Scratch,
    ) -> Vec<f64> {
        renderer
            .render_toned(&self.decode_flat(z), scratch)
            .iter()
            .zip(target)
            .map(|(a, b)| f64::from(a - b))
            .collect()
    }

    /// `iterations` Levenberg-Marquardt steps from `start`: the best code visited and its
    /// sum of squared residuals.
    fn levenberg_marquardt(
        &self,
        renderer: &SphereRenderer,
        target: &[f32],
        start: &[f32],
        iterations: usize,
    ) -> (Vec<f32>, f64) {
        let mut scratch = renderer.scratch();
        let residual =
            |z: &[f32], scratch: &mut Scratch| self.residual(renderer, target, z, scratch);
        let sum_sq = |r: &[f64]| r.iter().map(|v| v * v).sum::<f64>();
        let dims = start.len();
        let mut z = start.to_vec();
        let mut r = residual(&z, &mut scratch);
        let mut cost = sum_sq(&r);
        let mut lambda = 1e-3;
        for _ in 0..iterations {
            // Jacobian columns by forward differences, in parallel.
            let columns: Vec<Vec<f64>> = (0..dims)
                .into_par_iter()
                .map(|k| {
                    let h = 1e-3 * z[k].abs().max(1.0);
                    let mut zk = z.clone();
                    zk[k] += h;
                    let rk = residual(&zk, &mut renderer.scratch());
                    let step = f64::from(zk[k] - z[k]);
                    rk.iter().zip(&r).map(|(a, b)| (a - b) / step).collect()
                })
                .collect();
            let mut jtj = vec![0.0f64; dims * dims];
            let mut jtr = vec![0.0f64; dims];
            for a in 0..dims {
                jtr[a] = columns[a].iter().zip(&r).map(|(j, r)| j * r).sum();
                for b in a..dims {
                    let v: f64 = columns[a].iter().zip(&columns[b]).map(|(x, y)| x * y).sum();
                    jtj[a * dims + b] = v;
                    jtj[b * dims + a] = v;
                }
            }
            let mut improved = false;
            for _ in 0..8 {
                let mut m = jtj.clone();
                for a in 0..dims {
                    m[a * dims + a] += lambda * jtj[a * dims + a].max(1e-12);
                }
                let Some(delta) = solve_spd(&m, &jtr, dims) else {
                    lambda *= 4.0;
                    continue;
                };
                let candidate: Vec<f32> =
                    z.iter().zip(&delta).map(|(z, d)| z - *d as f32).collect();
                let rc = residual(&candidate, &mut scratch);
                let c = sum_sq(&rc);
                if c.is_finite() && c < cost {
                    (z, r, cost) = (candidate, rc, c);
                    lambda = (lambda / 3.0).max(1e-9);
                    improved = true;
                    break;
                }
                lambda *= 4.0;
            }
            if !improved {
                break;
            }
        }
        (z, cost)
    }

    /// Mean image loss (the training loss, on the 64 x 64 sphere) of the validation
    /// materials reconstructed from codes refined by `iterations` iterations. The validation
    /// materials are training materials held out of every update, so this chooses between
    /// autoencoders (seeds, settings) without looking at the test split. Refined rather than
    /// encoder codes: what the decoder can express is what reconstructions and interpolation
    /// use, and the encoder's own error ranks decoders poorly.
    pub fn refined_validation_loss(
        &self,
        materials: &[(String, Vec<f32>)],
        iterations: usize,
    ) -> Result<f64> {
        let renderer = self.sphere();
        let flats = self
            .split
            .validation
            .iter()
            .map(|name| find_network(materials, name))
            .collect::<Result<Vec<_>>>()?;
        if flats.is_empty() {
            return Err(NbrdfError::InvalidArgument(
                "the autoencoder has no validation materials".into(),
            ));
        }
        let total: f64 = flats
            .iter()
            .map(|flat| {
                let mut scratch = renderer.scratch();
                let target = renderer.render_toned(flat, &mut scratch);
                let code = self.refine_code(flat, &self.encode_flat(flat), iterations);
                renderer.loss(&self.decode_flat(&code), &target, &mut scratch, None)
            })
            .sum();
        Ok(total / flats.len() as f64)
    }

    /// Encoder code, then [`AutoEncoder::refine_code`] with `iterations` iterations.
    pub fn encode_refined(&self, net: &Nbrdf, iterations: usize) -> Result<Vec<f32>> {
        let code = self.encode(net)?;
        Ok(self.refine_code(&net.to_flat(), &code, iterations))
    }
}

/// Solves `m x = b` for a symmetric positive definite `m` (`n x n`, row-major) by Cholesky;
/// `None` if `m` is not numerically positive definite.
fn solve_spd(m: &[f64], b: &[f64], n: usize) -> Option<Vec<f64>> {
    let mut l = vec![0.0f64; n * n];
    for i in 0..n {
        for j in 0..=i {
            let s: f64 = (0..j).map(|k| l[i * n + k] * l[j * n + k]).sum();
            if i == j {
                let d = m[i * n + i] - s;
                // Also rejects NaN.
                if d.is_nan() || d <= 0.0 {
                    return None;
                }
                l[i * n + i] = d.sqrt();
            } else {
                l[i * n + j] = (m[i * n + j] - s) / l[j * n + j];
            }
        }
    }
    let mut y = vec![0.0f64; n];
    for i in 0..n {
        y[i] = (b[i] - (0..i).map(|k| l[i * n + k] * y[k]).sum::<f64>()) / l[i * n + i];
    }
    let mut x = vec![0.0f64; n];
    for i in (0..n).rev() {
        x[i] = (y[i] - (i + 1..n).map(|k| l[k * n + i] * x[k]).sum::<f64>()) / l[i * n + i];
    }
    Some(x)
}
