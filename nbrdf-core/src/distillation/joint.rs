//! The encoder and the decoder trained as one network: parameters `p` -> encoder -> code, then
//! (direction features, code) -> decoder -> `f_r`, on the homogeneous trainer's log-space loss
//! ([`log_space_loss`]). A chunk's gradient depends only on its samples and a batch sums its
//! chunks in order, so the weights are the same for any thread count (as in [`crate::train`]).

use super::dense::{backward, forward, DenseLayout, DenseScratch, DenseWeights};
use super::samples::Rows;
use crate::fastmath::{Fused, MulAdd, Unfused};
use crate::network::{Layer, INPUTS};
use crate::train::adam::{Adam, AdamConfig};
use crate::train::mlp_grad::{log_space_loss, Kernel, LANES};
use rayon::prelude::*;

/// The two networks' weights.
#[derive(Clone, Debug)]
pub(crate) struct JointWeights {
    pub encoder: DenseWeights,
    pub decoder: DenseWeights,
}

impl JointWeights {
    pub fn new(encoder: &[Layer], decoder: &[Layer]) -> Self {
        let widths = |layers: &[Layer]| {
            std::iter::once(layers[0].inputs)
                .chain(layers.iter().map(|l| l.outputs))
                .collect::<Vec<_>>()
        };
        let (el, dl) = (
            DenseLayout::new(&widths(encoder)),
            DenseLayout::new(&widths(decoder)),
        );
        let (ep, dp) = (el.pad(encoder), dl.pad(decoder));
        JointWeights {
            encoder: DenseWeights::new(el, ep),
            decoder: DenseWeights::new(dl, dp),
        }
    }

    /// `C`, the code's channels.
    pub fn channels(&self) -> usize {
        self.encoder.layout.outputs()
    }

    /// The decoder's outputs: 3, or a spectral basis' count.
    pub fn outputs(&self) -> usize {
        self.decoder.layout.outputs()
    }

    fn refresh(&mut self) {
        self.encoder.refresh_transposes();
        self.decoder.refresh_transposes();
    }
}

/// One chunk's working memory: both networks' activations, targets and cosines.
pub(crate) struct JointScratch {
    encoder: DenseScratch,
    decoder: DenseScratch,
    /// `[output][lane]`.
    target: Vec<f32>,
    cos: Vec<f32>,
}

impl JointScratch {
    pub fn new(w: &JointWeights) -> Self {
        JointScratch {
            encoder: DenseScratch::new(&w.encoder.layout),
            decoder: DenseScratch::new(&w.decoder.layout),
            target: vec![0.0; w.outputs() * LANES],
            cos: vec![0.0; LANES],
        }
    }

    /// Loads rows `first..first + LANES` of `rows` (fewer at the end); unused lanes get zero
    /// inputs and a zero cosine, which makes their loss and gradient exactly 0.
    fn load(&mut self, w: &JointWeights, rows: &Rows, first: usize) {
        let (pe, pd) = (w.encoder.layout.padded[0], w.decoder.layout.padded[0]);
        for lane in 0..LANES {
            let i = first + lane;
            let used = i < rows.len();
            let x = self.encoder.input_mut(lane, pe);
            x.fill(0.0);
            if used {
                x[..rows.parameters].copy_from_slice(rows.params_of(i));
            }
            let d = self.decoder.input_mut(lane, pd);
            d.fill(0.0);
            if used {
                d[..INPUTS].copy_from_slice(&rows.inputs[i]);
            }
            for k in 0..rows.outputs {
                self.target[k * LANES + lane] = if used { rows.log_targets_of(i)[k] } else { 0.0 };
            }
            self.cos[lane] = if used { rows.cos_light[i] } else { 0.0 };
        }
    }

    /// Loads parameter rows (at most [`LANES`] of `parameters` values) for encoding alone.
    fn load_params(&mut self, w: &JointWeights, params: &[f32], parameters: usize) {
        let pe = w.encoder.layout.padded[0];
        for lane in 0..LANES {
            let x = self.encoder.input_mut(lane, pe);
            x.fill(0.0);
            if let Some(row) = params.get(lane * parameters..(lane + 1) * parameters) {
                x[..parameters].copy_from_slice(row);
            }
        }
    }
}

/// The code of each loaded lane into the decoder's inputs, after `INPUTS` direction features.
#[inline(always)]
fn codes_to_decoder(w: &JointWeights, s: &mut JointScratch) {
    let (c, pc, pd) = (
        w.channels(),
        w.encoder.layout.padded[w.encoder.layout.layers()],
        w.decoder.layout.padded[0],
    );
    let codes = &s.encoder.acts[w.encoder.layout.layers()];
    for lane in 0..LANES {
        s.decoder.acts[0][lane * pd + INPUTS..][..c].copy_from_slice(&codes[lane * pc..][..c]);
    }
}

/// Loss sum of the loaded chunk and, with `grads`, the gradients of
/// `scale * loss` for both networks (written, not added).
#[inline(always)]
fn chunk_pass<M: MulAdd>(
    w: &JointWeights,
    s: &mut JointScratch,
    scale: f32,
    grads: Option<(&mut [f32], &mut [f32])>,
) -> f64 {
    forward::<M>(&w.encoder, &mut s.encoder);
    codes_to_decoder(w, s);
    forward::<M>(&w.decoder, &mut s.decoder);
    let last = w.decoder.layout.layers();
    let yw = w.decoder.layout.padded[last];
    let clamp_output = grads.is_none();
    let mut sum = 0.0f64;
    {
        let (z, g) = (&s.decoder.acts[last], &mut s.decoder.grads[last]);
        g.fill(0.0);
        for lane in 0..LANES {
            for k in 0..w.outputs() {
                let (t, c) = (s.target[k * LANES + lane], s.cos[lane]);
                let (error, slope) = log_space_loss(z[lane * yw + k], t, c, clamp_output);
                sum += f64::from(error);
                g[lane * yw + k] = slope * scale;
            }
        }
    }
    let Some((grad_encoder, grad_decoder)) = grads else {
        return sum;
    };
    backward::<M>(&w.decoder, &mut s.decoder, grad_decoder, true);
    let (c, pc, pd) = (
        w.channels(),
        w.encoder.layout.padded[w.encoder.layout.layers()],
        w.decoder.layout.padded[0],
    );
    let g_code = &mut s.encoder.grads[w.encoder.layout.layers()];
    g_code.fill(0.0);
    for lane in 0..LANES {
        g_code[lane * pc..][..c].copy_from_slice(&s.decoder.grads[0][lane * pd + INPUTS..][..c]);
    }
    backward::<M>(&w.encoder, &mut s.encoder, grad_encoder, false);
    sum
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn chunk_pass_avx2(
    w: &JointWeights,
    s: &mut JointScratch,
    scale: f32,
    grads: Option<(&mut [f32], &mut [f32])>,
) -> f64 {
    chunk_pass::<Fused>(w, s, scale, grads)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn encode_avx2(w: &JointWeights, s: &mut JointScratch) {
    forward::<Fused>(&w.encoder, &mut s.encoder)
}

/// [`chunk_pass`] with the kernel copy `kernel`.
fn dispatch(
    kernel: Kernel,
    w: &JointWeights,
    s: &mut JointScratch,
    scale: f32,
    grads: Option<(&mut [f32], &mut [f32])>,
) -> f64 {
    match kernel {
        Kernel::Portable => chunk_pass::<Unfused>(w, s, scale, grads),
        // SAFETY: `Kernel::detect` chose this variant only where the CPU has AVX2 and FMA.
        #[cfg(target_arch = "x86_64")]
        Kernel::Avx2Fma => unsafe { chunk_pass_avx2(w, s, scale, grads) },
    }
}

/// The optimisation state of both networks.
pub(crate) struct JointTrainer {
    kernel: Kernel,
    pub weights: JointWeights,
    adam: (Adam, Adam),
    scratches: Vec<JointScratch>,
    /// One gradient per chunk of a batch and network, reduced in chunk order.
    chunk_grads: (Vec<f32>, Vec<f32>),
    chunk_losses: Vec<f64>,
    grad: (Vec<f32>, Vec<f32>),
}

impl JointTrainer {
    pub fn new(weights: JointWeights, batch: usize, adam: AdamConfig) -> Self {
        let chunks = batch.div_ceil(LANES);
        let (le, ld) = (weights.encoder.layout.len, weights.decoder.layout.len);
        JointTrainer {
            kernel: Kernel::detect(),
            adam: (Adam::new(adam, le), Adam::new(adam, ld)),
            scratches: (0..chunks).map(|_| JointScratch::new(&weights)).collect(),
            chunk_grads: (vec![0.0; chunks * le], vec![0.0; chunks * ld]),
            chunk_losses: vec![0.0; chunks],
            grad: (vec![0.0; le], vec![0.0; ld]),
            weights,
        }
    }

    /// One Adam step at rate `lr` on the batch `rows` (at most the batch size); returns its loss
    /// sum before the step.
    pub fn step(&mut self, rows: &Rows, lr: f32) -> f64 {
        let loss = self.compute_gradient(rows);
        self.adam
            .0
            .step(&mut self.weights.encoder.p, &self.grad.0, lr);
        self.adam
            .1
            .step(&mut self.weights.decoder.p, &self.grad.1, lr);
        self.weights.refresh();
        loss
    }

    /// The gradient of the mean loss (output not clamped) over the batch `rows` into
    /// [`JointTrainer::gradient`]; returns the loss sum.
    pub fn compute_gradient(&mut self, rows: &Rows) -> f64 {
        let n = rows.len();
        let chunks = n.div_ceil(LANES);
        let (le, ld) = (
            self.weights.encoder.layout.len,
            self.weights.decoder.layout.len,
        );
        let scale = 1.0 / (self.weights.outputs() * n.max(1)) as f32;
        let (kernel, weights) = (self.kernel, &self.weights);
        self.scratches[..chunks]
            .par_iter_mut()
            .zip(self.chunk_grads.0.par_chunks_mut(le))
            .zip(self.chunk_grads.1.par_chunks_mut(ld))
            .zip(self.chunk_losses.par_iter_mut())
            .enumerate()
            .for_each(|(k, (((scratch, ge), gd), loss))| {
                scratch.load(weights, rows, k * LANES);
                *loss = dispatch(kernel, weights, scratch, scale, Some((ge, gd)));
            });
        reduce_in_order(&self.chunk_grads.0, chunks, &mut self.grad.0);
        reduce_in_order(&self.chunk_grads.1, chunks, &mut self.grad.1);
        self.chunk_losses[..chunks].iter().sum()
    }

    /// The encoder's and the decoder's gradients of the last
    /// [`JointTrainer::compute_gradient`] (padded layouts).
    #[cfg(test)]
    pub fn gradient(&self) -> (&[f32], &[f32]) {
        (&self.grad.0, &self.grad.1)
    }

    /// Sets the weights (for tests of the gradient).
    #[cfg(test)]
    pub fn set_weights(&mut self, weights: JointWeights) {
        self.weights = weights;
        self.weights.refresh();
    }

    /// Mean loss over `rows` of the networks as evaluated (output clamped at 0).
    pub fn loss(&self, rows: &Rows) -> f64 {
        let (kernel, weights) = (self.kernel, &self.weights);
        let chunks = rows.len().div_ceil(LANES);
        let sums: Vec<f64> = (0..chunks)
            .into_par_iter()
            .map_init(
                || JointScratch::new(weights),
                |scratch, k| {
                    scratch.load(weights, rows, k * LANES);
                    dispatch(kernel, weights, scratch, 0.0, None)
                },
            )
            .collect();
        sums.iter().sum::<f64>() / (weights.outputs() * rows.len().max(1)) as f64
    }
}

/// `out = sum_k chunk k of grads`, in chunk order.
fn reduce_in_order(grads: &[f32], chunks: usize, out: &mut [f32]) {
    let len = out.len();
    out.copy_from_slice(&grads[..len]);
    for chunk in grads[len..chunks * len].chunks_exact(len) {
        for (g, &c) in out.iter_mut().zip(chunk) {
            *g += c;
        }
    }
}

/// The codes of texels' parameters (`parameters` values a texel, texel-major), `C` values a
/// texel, on all cores with the detected kernel copy.
pub(crate) fn encode(w: &JointWeights, params: &[f32], parameters: usize) -> Vec<f32> {
    let (c, layers) = (w.channels(), w.encoder.layout.layers());
    let pc = w.encoder.layout.padded[layers];
    let texels = params.len() / parameters;
    let mut codes = vec![0.0f32; texels * c];
    let kernel = Kernel::detect();
    codes
        .par_chunks_mut(LANES * c)
        .zip(params.par_chunks(LANES * parameters))
        .for_each_init(
            || JointScratch::new(w),
            |scratch, (out, rows)| {
                scratch.load_params(w, rows, parameters);
                match kernel {
                    Kernel::Portable => forward::<Unfused>(&w.encoder, &mut scratch.encoder),
                    // SAFETY: as in `dispatch`.
                    #[cfg(target_arch = "x86_64")]
                    Kernel::Avx2Fma => unsafe { encode_avx2(w, scratch) },
                }
                let acts = &scratch.encoder.acts[layers];
                for (lane, code) in out.chunks_exact_mut(c).enumerate() {
                    code.copy_from_slice(&acts[lane * pc..][..c]);
                }
            },
        );
    codes
}
