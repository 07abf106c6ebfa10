//! Batched forward and backward passes of the NBRDF network for training.
//!
//! The network is `y = exp(W3 relu(W2 relu(W1 x + b1) + b2) + b3) - 1` (docs/design.md section 4),
//! trained on `|ln(1 + f_true cos) - ln(1 + y cos)|` averaged over samples and channels. The
//! output count is the sample type's ([`TrainingSample::OUTPUTS`]): 3 for RGB networks, a
//! spectral network's coefficient count ([`super::spectral`]); the 3-output path keeps its
//! specialised transposes, so RGB training is bit for bit what it was.
//!
//! Work is done on chunks of [`LANES`] samples, sample-major (`[lane][feature]`), with the
//! hidden width padded to a multiple of 8 by zero weights so that every product is a
//! register-blocked [`gemm`]. Padding is exact: padded units have zero weights and bias, so they
//! are 0 forward and get 0 gradient backward, and Adam leaves zero-gradient parameters at 0.
//! A chunk's gradient depends only on its samples, which is what makes training independent of
//! the thread count (see [`crate::train`]).
//!
//! The forward pass here is a deliberate second copy of the network's definition (the reference
//! is [`crate::network::Layer::affine_into`] with [`crate::fastmath`]'s `relu` and `expm1`), laid
//! out for gradients; `tests::outputs_match_the_network_evaluator` holds the two together.

use super::dataset::Sample;
use super::gemm::{column_sums, gemm, Init, Post, Strided, VEC};
use crate::fastmath::{self, Fused, MulAdd, Unfused};
use crate::network::{Layer, INPUTS, OUTPUTS};

/// Samples per chunk, the unit of parallel work and of deterministic gradient summation.
pub const LANES: usize = 64;
/// Padded width of the input rows (6 used).
const XW: usize = VEC;

/// A sample the kernels train on: the network input, one log-space target per output and the
/// light's cosine. RGB samples ([`Sample`]) and spectral ones ([`super::spectral`]) differ only
/// in their number of targets.
pub trait TrainingSample: Copy + Default + Send + Sync {
    /// Targets per sample, the network's outputs.
    const OUTPUTS: usize;
    fn input(&self) -> &[f32; INPUTS];
    /// `ln(1 + c_k cos_light)` per output, [`TrainingSample::OUTPUTS`] of them.
    fn log_targets(&self) -> &[f32];
    fn cos_light(&self) -> f32;
    /// `out = [samples[i] for i in order]`, the epoch's shuffled copy.
    fn gather(samples: &[Self], order: &[u32], out: &mut Vec<Self>);
}

impl TrainingSample for Sample {
    const OUTPUTS: usize = OUTPUTS;

    #[inline(always)]
    fn input(&self) -> &[f32; INPUTS] {
        &self.x
    }

    #[inline(always)]
    fn log_targets(&self) -> &[f32] {
        &self.log_target
    }

    #[inline(always)]
    fn cos_light(&self) -> f32 {
        self.cos_light
    }

    fn gather(samples: &[Self], order: &[u32], out: &mut Vec<Self>) {
        super::dataset::gather(samples, order, out, 1 << 14)
    }
}

/// Offsets of the padded parameters `W1 [6][hp], b1 [hp], W2 [hp][hp], b2 [hp], W3 [hp][yw],
/// b3 [yw]` in one flat vector (the order of docs/design.md section 7).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Layout {
    pub hidden: usize,
    pub hp: usize,
    /// The network's outputs and their padded width (8 for RGB's 3).
    pub outputs: usize,
    pub yw: usize,
    pub w1: usize,
    pub b1: usize,
    pub w2: usize,
    pub b2: usize,
    pub w3: usize,
    pub b3: usize,
    pub len: usize,
}

impl Layout {
    /// The layout of an RGB network (3 outputs).
    pub fn new(hidden: usize) -> Self {
        Self::with_outputs(hidden, OUTPUTS)
    }

    /// The layout of a network with `outputs` outputs.
    pub fn with_outputs(hidden: usize, outputs: usize) -> Self {
        let hp = hidden.div_ceil(VEC) * VEC;
        let yw = outputs.div_ceil(VEC) * VEC;
        let w1 = 0;
        let b1 = w1 + INPUTS * hp;
        let w2 = b1 + hp;
        let b2 = w2 + hp * hp;
        let w3 = b2 + hp;
        let b3 = w3 + hp * yw;
        Layout {
            hidden,
            hp,
            outputs,
            yw,
            w1,
            b1,
            w2,
            b2,
            w3,
            b3,
            len: b3 + yw,
        }
    }

    /// Padded parameters of three layers `6 -> hidden -> hidden -> outputs` (shapes checked by
    /// the caller).
    pub fn pad(&self, layers: &[Layer; 3]) -> Vec<f32> {
        let mut p = vec![0.0; self.len];
        let spec = self.blocks();
        for (layer, (w_at, b_at, ld)) in layers.iter().zip(spec) {
            for i in 0..layer.inputs {
                for o in 0..layer.outputs {
                    p[w_at + i * ld + o] = layer.weights[i * layer.outputs + o];
                }
            }
            p[b_at..b_at + layer.outputs].copy_from_slice(&layer.bias);
        }
        p
    }

    /// The three dense layers of padded parameters `p`, in the network file's layout.
    pub fn unpad(&self, p: &[f32]) -> [Layer; 3] {
        let dims = [
            (INPUTS, self.hidden),
            (self.hidden, self.hidden),
            (self.hidden, self.outputs),
        ];
        let spec = self.blocks();
        std::array::from_fn(|k| {
            let (inputs, outputs) = dims[k];
            let (w_at, b_at, ld) = spec[k];
            let mut weights = Vec::with_capacity(inputs * outputs);
            for i in 0..inputs {
                weights.extend_from_slice(&p[w_at + i * ld..w_at + i * ld + outputs]);
            }
            Layer {
                inputs,
                outputs,
                weights,
                bias: p[b_at..b_at + outputs].to_vec(),
            }
        })
    }

    /// `(weights offset, bias offset, row stride)` of each layer.
    fn blocks(&self) -> [(usize, usize, usize); 3] {
        [
            (self.w1, self.b1, self.hp),
            (self.w2, self.b2, self.hp),
            (self.w3, self.b3, self.yw),
        ]
    }
}

/// Parameters plus the transposed weight copies the backward pass multiplies with.
#[derive(Clone, Debug)]
pub struct Weights {
    pub layout: Layout,
    pub p: Vec<f32>,
    /// `W2^T`, `[hp][hp]`.
    w2t: Vec<f32>,
    /// `W3^T`, `[yw][hp]`.
    w3t: Vec<f32>,
}

impl Weights {
    pub fn new(layout: Layout, p: Vec<f32>) -> Self {
        assert_eq!(p.len(), layout.len);
        let (hp, yw) = (layout.hp, layout.yw);
        let mut w = Weights {
            layout,
            p,
            w2t: vec![0.0; hp * hp],
            w3t: vec![0.0; yw * hp],
        };
        w.refresh_transposes();
        w
    }

    /// Call after every change of `p`.
    pub fn refresh_transposes(&mut self) {
        let l = &self.layout;
        let hp = l.hp;
        for i in 0..hp {
            for j in 0..hp {
                self.w2t[j * hp + i] = self.p[l.w2 + i * hp + j];
            }
            for k in 0..l.yw {
                self.w3t[k * hp + i] = self.p[l.w3 + i * l.yw + k];
            }
        }
    }
}

/// Per-chunk working memory, allocated once and reused for every batch.
pub struct ChunkScratch {
    /// The layout's `outputs` and `yw`.
    outputs: usize,
    yw: usize,
    x: Vec<f32>,
    /// `ln(1 + f cos)`, `[channel][lane]`.
    target: Vec<f32>,
    /// `cos(theta_light)` per lane, 0 for unused lanes.
    cos: Vec<f32>,
    a1: Vec<f32>,
    a2: Vec<f32>,
    z3: Vec<f32>,
    g3: Vec<f32>,
    g2: Vec<f32>,
    g1: Vec<f32>,
    /// Output pre-activations, their loss gradients and absolute errors, `[channel][lane]`.
    z_out: Vec<f32>,
    g_out: Vec<f32>,
    err: Vec<f32>,
}

impl ChunkScratch {
    pub fn new(layout: &Layout) -> Self {
        let h = LANES * layout.hp;
        let v = LANES * layout.yw;
        let channels = layout.outputs * LANES;
        ChunkScratch {
            outputs: layout.outputs,
            yw: layout.yw,
            x: vec![0.0; LANES * XW],
            target: vec![0.0; channels],
            cos: vec![0.0; LANES],
            a1: vec![0.0; h],
            a2: vec![0.0; h],
            z3: vec![0.0; v],
            g3: vec![0.0; v],
            g2: vec![0.0; h],
            g1: vec![0.0; h],
            z_out: vec![0.0; channels],
            g_out: vec![0.0; channels],
            err: vec![0.0; channels],
        }
    }

    /// Loads the samples `indices` of `samples` (at most [`LANES`]); unused lanes get zero
    /// inputs and a zero cosine, which makes their loss and gradient exactly 0.
    pub fn load_indexed<S: TrainingSample>(&mut self, samples: &[S], indices: &[u32]) {
        debug_assert!(indices.len() <= LANES);
        for lane in 0..LANES {
            let s = indices.get(lane).map(|&i| &samples[i as usize]);
            self.load_lane(lane, s);
        }
    }

    /// Loads consecutive samples (at most [`LANES`]).
    pub fn load_slice<S: TrainingSample>(&mut self, samples: &[S]) {
        debug_assert!(samples.len() <= LANES);
        for lane in 0..LANES {
            self.load_lane(lane, samples.get(lane));
        }
    }

    fn load_lane<S: TrainingSample>(&mut self, lane: usize, sample: Option<&S>) {
        debug_assert_eq!(S::OUTPUTS, self.outputs);
        let x = &mut self.x[lane * XW..(lane + 1) * XW];
        x.fill(0.0);
        match sample {
            Some(s) => {
                x[..INPUTS].copy_from_slice(s.input());
                for (k, &t) in s.log_targets().iter().enumerate() {
                    self.target[k * LANES + lane] = t;
                }
                self.cos[lane] = s.cos_light();
            }
            None => {
                for k in 0..self.outputs {
                    self.target[k * LANES + lane] = 0.0;
                }
                self.cos[lane] = 0.0;
            }
        }
    }
}

/// Raw access for losses other than training's (the autoencoder's image loss): load inputs,
/// run [`Kernel::forward_raw`], read the output pre-activations, set their gradients, run
/// [`Kernel::backward_raw`].
impl ChunkScratch {
    /// Loads raw network inputs (at most [`LANES`]); unused lanes get zero inputs.
    pub fn load_inputs(&mut self, inputs: &[[f32; INPUTS]]) {
        debug_assert!(inputs.len() <= LANES);
        for lane in 0..LANES {
            let x = &mut self.x[lane * XW..(lane + 1) * XW];
            x.fill(0.0);
            if let Some(v) = inputs.get(lane) {
                x[..INPUTS].copy_from_slice(v);
            }
        }
    }

    /// Output pre-activation `z` (so `f = expm1(z)`) of `lane`, channel `k`, after a forward pass.
    #[inline]
    pub fn output_pre_activation(&self, lane: usize, k: usize) -> f32 {
        self.z3[lane * self.yw + k]
    }

    /// Sets `d loss / d z` of `lane`, channel `k` (below the output count) for
    /// [`Kernel::backward_raw`].
    #[inline]
    pub fn set_output_gradient(&mut self, lane: usize, k: usize, g: f32) {
        debug_assert!(k < self.outputs);
        self.g3[lane * self.yw + k] = g;
    }
}

/// Which compiled copy of the kernels runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kernel {
    Portable,
    #[cfg(target_arch = "x86_64")]
    Avx2Fma,
}

impl Kernel {
    /// The fastest copy this CPU supports.
    pub fn detect() -> Self {
        #[cfg(target_arch = "x86_64")]
        if is_x86_feature_detected!("avx2") && is_x86_feature_detected!("fma") {
            return Kernel::Avx2Fma;
        }
        Kernel::Portable
    }

    /// Forward, loss and backward on the loaded chunk: writes the gradient of
    /// `scale * sum |ln(1 + f cos) - ln(1 + y cos)|` into `grad` (padded layout; entries that
    /// are always zero are left untouched) and returns the unscaled loss sum.
    pub fn gradient(self, w: &Weights, s: &mut ChunkScratch, scale: f32, grad: &mut [f32]) -> f64 {
        match self {
            Kernel::Portable => gradient_impl::<Unfused>(w, s, scale, grad),
            // SAFETY: `detect` chose this variant only where the CPU has AVX2 and FMA.
            #[cfg(target_arch = "x86_64")]
            Kernel::Avx2Fma => unsafe { gradient_avx2(w, s, scale, grad) },
        }
    }

    /// Forward pass only: fills the output pre-activations of the loaded chunk.
    pub fn forward_raw(self, w: &Weights, s: &mut ChunkScratch) {
        match self {
            Kernel::Portable => forward::<Unfused>(w, s),
            // SAFETY: `detect` chose this variant only where the CPU has AVX2 and FMA.
            #[cfg(target_arch = "x86_64")]
            Kernel::Avx2Fma => unsafe { forward_avx2(w, s) },
        }
    }

    /// Backward pass from the output gradients set with
    /// [`ChunkScratch::set_output_gradient`], after [`Kernel::forward_raw`] on the same chunk:
    /// writes (not adds) the parameter gradient into `grad` (padded layout).
    pub fn backward_raw(self, w: &Weights, s: &mut ChunkScratch, grad: &mut [f32]) {
        match self {
            Kernel::Portable => backward::<Unfused>(w, s, grad),
            // SAFETY: as in `forward_raw`.
            #[cfg(target_arch = "x86_64")]
            Kernel::Avx2Fma => unsafe { backward_avx2(w, s, grad) },
        }
    }

    /// Loss sum of the loaded chunk for the network as evaluated (output clamped at 0).
    pub fn loss(self, w: &Weights, s: &mut ChunkScratch) -> f64 {
        match self {
            Kernel::Portable => loss_impl::<Unfused>(w, s),
            // SAFETY: as in `gradient`.
            #[cfg(target_arch = "x86_64")]
            Kernel::Avx2Fma => unsafe { loss_avx2(w, s) },
        }
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn gradient_avx2(w: &Weights, s: &mut ChunkScratch, scale: f32, grad: &mut [f32]) -> f64 {
    gradient_impl::<Fused>(w, s, scale, grad)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn loss_avx2(w: &Weights, s: &mut ChunkScratch) -> f64 {
    loss_impl::<Fused>(w, s)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn forward_avx2(w: &Weights, s: &mut ChunkScratch) {
    forward::<Fused>(w, s)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn backward_avx2(w: &Weights, s: &mut ChunkScratch, grad: &mut [f32]) {
    backward::<Fused>(w, s, grad)
}

#[inline(always)]
fn gradient_impl<M: MulAdd>(
    w: &Weights,
    s: &mut ChunkScratch,
    scale: f32,
    grad: &mut [f32],
) -> f64 {
    forward::<M>(w, s);
    let loss = loss_and_output_gradient(s, scale, false, true);
    backward::<M>(w, s, grad);
    loss
}

#[inline(always)]
fn loss_impl<M: MulAdd>(w: &Weights, s: &mut ChunkScratch) -> f64 {
    forward::<M>(w, s);
    loss_and_output_gradient(s, 0.0, true, false)
}

/// `a1`, `a2` (after relu) and the pre-activation `z3` of the output.
#[inline(always)]
fn forward<M: MulAdd>(w: &Weights, s: &mut ChunkScratch) {
    let l = &w.layout;
    let (h, hp, yw, p) = (l.hidden, l.hp, l.yw, &w.p[..]);
    let x = Strided {
        data: &s.x,
        row_stride: XW,
        col_stride: 1,
    };
    let b1 = Init::Row(&p[l.b1..l.b1 + hp]);
    gemm::<M>(
        LANES,
        hp,
        INPUTS,
        x,
        &p[l.w1..],
        hp,
        &mut s.a1,
        hp,
        b1,
        Post::Relu,
    );
    let a1 = Strided {
        data: &s.a1,
        row_stride: hp,
        col_stride: 1,
    };
    let b2 = Init::Row(&p[l.b2..l.b2 + hp]);
    gemm::<M>(
        LANES,
        hp,
        h,
        a1,
        &p[l.w2..],
        hp,
        &mut s.a2,
        hp,
        b2,
        Post::Relu,
    );
    let a2 = Strided {
        data: &s.a2,
        row_stride: hp,
        col_stride: 1,
    };
    let b3 = Init::Row(&p[l.b3..l.b3 + yw]);
    gemm::<M>(
        LANES,
        yw,
        h,
        a2,
        &p[l.w3..],
        yw,
        &mut s.z3,
        yw,
        b3,
        Post::None,
    );
}

/// The loss sum, and (if `with_gradient`) `g3 = scale * d loss / d z3`.
///
/// `p = ln(1 + y cos)` with `y = e^z - 1`, so `dp/dz = cos e^z / (1 + y cos)`, which lies in
/// `[0, 1]`: the gradient stays bounded however large the target (mirror-like materials). Where
/// the evaluator clamps `z` (outside `[EXP_ARG_MIN, EXP_ARG_MAX]` of [`network`]) the gradient
/// is 0, as the derivative of the clamp is.
/// Training uses the unclamped `y` (it can dip below 0, as in the authors' Keras model, which
/// keeps the gradient alive for dark channels); the evaluator clamps `y` at 0, which can only
/// lower the loss against a non-negative target, and `clamp_output` measures exactly that.
#[inline(always)]
fn loss_and_output_gradient(
    s: &mut ChunkScratch,
    scale: f32,
    clamp_output: bool,
    with_gradient: bool,
) -> f64 {
    outputs_to_channel_major(s);
    for k in 0..s.outputs {
        let range = k * LANES..(k + 1) * LANES;
        let (z, t, c) = (
            &s.z_out[range.clone()],
            &s.target[range.clone()],
            &s.cos[..LANES],
        );
        let (err, g) = (&mut s.err[range.clone()], &mut s.g_out[range]);
        for lane in 0..LANES {
            let (error, slope) = log_space_loss(z[lane], t[lane], c[lane], clamp_output);
            err[lane] = error;
            if with_gradient {
                g[lane] = slope * scale;
            }
        }
    }
    if with_gradient {
        gradients_to_lane_major(s);
    }
    let mut sums = [0.0f32; VEC];
    for group in s.err.chunks_exact(VEC) {
        for q in 0..VEC {
            sums[q] += group[q];
        }
    }
    sums.iter().map(|&v| v as f64).sum()
}

/// The loss of one output, `|ln(1 + y cos) - target|` with `y = e^z - 1` (clamped at 0 with
/// `clamp_output`), and its derivative in `z` (see [`loss_and_output_gradient`]): the one
/// definition of the log-space loss, shared by every trainer.
#[inline(always)]
pub(crate) fn log_space_loss(z: f32, target: f32, cos: f32, clamp_output: bool) -> (f32, f32) {
    // The evaluator's activation, so that the loss measures the network as saved.
    let y_raw = fastmath::fast_expm1(z);
    let y = if clamp_output { y_raw.max(0.0) } else { y_raw };
    let u = y * cos;
    let d = fastmath::ln_1p(u) - target;
    let sign = (d > 0.0) as i32 as f32 - (d < 0.0) as i32 as f32;
    let slope = (cos * (y_raw + 1.0) / (1.0 + u).max(1e-30)).min(1.0);
    let live = z > fastmath::EXP_ARG_MIN && z < fastmath::EXP_ARG_MAX;
    (d.abs(), if live { sign * slope } else { 0.0 })
}

/// Channel-major copies of the used output columns, so that the transcendental work runs on
/// full vectors of lanes instead of 3-of-8-used rows; RGB's 3 columns have their own loop.
#[inline(always)]
fn outputs_to_channel_major(s: &mut ChunkScratch) {
    if s.outputs == OUTPUTS {
        let (z0, rest) = s.z_out.split_at_mut(LANES);
        let (z1, z2) = rest.split_at_mut(LANES);
        for (((row, z0), z1), z2) in s.z3.chunks_exact(s.yw).zip(z0).zip(z1).zip(z2) {
            (*z0, *z1, *z2) = (row[0], row[1], row[2]);
        }
        return;
    }
    for (lane, row) in s.z3.chunks_exact(s.yw).enumerate() {
        for (k, &z) in row[..s.outputs].iter().enumerate() {
            s.z_out[k * LANES + lane] = z;
        }
    }
}

/// The output gradients back into the lane-major rows of `g3` (padding columns stay 0).
#[inline(always)]
fn gradients_to_lane_major(s: &mut ChunkScratch) {
    if s.outputs == OUTPUTS {
        let (g0, rest) = s.g_out.split_at(LANES);
        let (g1, g2) = rest.split_at(LANES);
        for (((row, g0), g1), g2) in s.g3.chunks_exact_mut(s.yw).zip(g0).zip(g1).zip(g2) {
            (row[0], row[1], row[2]) = (*g0, *g1, *g2);
        }
        return;
    }
    for (lane, row) in s.g3.chunks_exact_mut(s.yw).enumerate() {
        for (k, g) in row[..s.outputs].iter_mut().enumerate() {
            *g = s.g_out[k * LANES + lane];
        }
    }
}

#[inline(always)]
fn backward<M: MulAdd>(w: &Weights, s: &mut ChunkScratch, grad: &mut [f32]) {
    let l = &w.layout;
    let (h, hp, yw) = (l.hidden, l.hp, l.yw);
    let (zero, none) = (Init::Zero, Post::None);

    // Output layer.
    gemm::<M>(
        h,
        yw,
        LANES,
        transposed(&s.a2, hp),
        &s.g3,
        yw,
        &mut grad[l.w3..],
        yw,
        zero,
        none,
    );
    column_sums(LANES, yw, &s.g3, yw, &mut grad[l.b3..]);
    let g3 = Strided {
        data: &s.g3,
        row_stride: yw,
        col_stride: 1,
    };
    let active2 = Post::MaskPositive(&s.a2);
    gemm::<M>(
        LANES, hp, l.outputs, g3, &w.w3t, hp, &mut s.g2, hp, zero, active2,
    );

    // Second hidden layer.
    gemm::<M>(
        h,
        hp,
        LANES,
        transposed(&s.a1, hp),
        &s.g2,
        hp,
        &mut grad[l.w2..],
        hp,
        zero,
        none,
    );
    column_sums(LANES, hp, &s.g2, hp, &mut grad[l.b2..]);
    let g2 = Strided {
        data: &s.g2,
        row_stride: hp,
        col_stride: 1,
    };
    let active1 = Post::MaskPositive(&s.a1);
    gemm::<M>(LANES, hp, h, g2, &w.w2t, hp, &mut s.g1, hp, zero, active1);

    // First hidden layer.
    gemm::<M>(
        INPUTS,
        hp,
        LANES,
        transposed(&s.x, XW),
        &s.g1,
        hp,
        &mut grad[l.w1..],
        hp,
        zero,
        none,
    );
    column_sums(LANES, hp, &s.g1, hp, &mut grad[l.b1..]);
}

/// The transpose of a sample-major matrix with row stride `ld`: `A(feature, lane)`.
#[inline(always)]
fn transposed(m: &[f32], ld: usize) -> Strided<'_> {
    Strided {
        data: m,
        row_stride: 1,
        col_stride: ld,
    }
}

/// Network outputs `f_r` (clamped at 0, as evaluated) of the loaded chunk, `[lane][channel]`,
/// `outputs` channels a lane. For diagnostics and tests: the portable kernel copy, no dispatch.
pub fn outputs(w: &Weights, s: &mut ChunkScratch) -> Vec<Vec<f32>> {
    forward::<Unfused>(w, s);
    (0..LANES)
        .map(|lane| {
            let row = &s.z3[lane * s.yw..lane * s.yw + s.outputs];
            row.iter()
                .map(|&z| fastmath::fast_expm1(z).max(0.0))
                .collect()
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::super::adam::AdamConfig;
    use super::super::spectral::SpectralSample;
    use super::super::Trainer;
    use super::*;
    use crate::rng::{SplitMix64, Stream};

    fn random_layers(hidden: usize, seed: u64) -> [Layer; 3] {
        random_layers_with(hidden, OUTPUTS, seed)
    }

    fn random_layers_with(hidden: usize, outputs: usize, seed: u64) -> [Layer; 3] {
        let mut rng = SplitMix64::new(seed, Stream::Init, 0);
        let dims = [(INPUTS, hidden), (hidden, hidden), (hidden, outputs)];
        dims.map(|(inputs, outputs)| Layer {
            inputs,
            outputs,
            weights: (0..inputs * outputs)
                .map(|_| rng.next_f64() as f32 - 0.5)
                .collect(),
            bias: (0..outputs)
                .map(|_| 0.2 * rng.next_f64() as f32 - 0.1)
                .collect(),
        })
    }

    fn random_samples(n: usize, seed: u64) -> Vec<Sample> {
        let mut rng = SplitMix64::new(seed, Stream::TrainSamples, 0);
        (0..n)
            .map(|_| {
                let mut x = [0.0f32; INPUTS];
                for v in x.iter_mut() {
                    *v = 2.0 * rng.next_f64() as f32 - 1.0;
                }
                x[1] = 0.0;
                let log_target = std::array::from_fn(|_| 2.0 * rng.next_f64() as f32);
                Sample {
                    x,
                    log_target,
                    cos_light: 0.05 + 0.95 * rng.next_f64() as f32,
                }
            })
            .collect()
    }

    /// Spectral samples: the same inputs and cosines, 16 random targets each.
    fn random_spectral_samples(n: usize, seed: u64) -> Vec<SpectralSample> {
        let mut rng = SplitMix64::new(seed, Stream::ValidationSamples, 0);
        random_samples(n, seed)
            .into_iter()
            .map(|s| SpectralSample {
                x: s.x,
                log_target: std::array::from_fn(|_| 2.0 * rng.next_f64() as f32),
                cos_light: s.cos_light,
            })
            .collect()
    }

    /// The mean loss in float64, straight from the definition.
    fn reference_loss<S: TrainingSample>(layers: &[Layer; 3], samples: &[S]) -> f64 {
        let dense = |layer: &Layer, x: &[f64], relu: bool| -> Vec<f64> {
            (0..layer.outputs)
                .map(|o| {
                    let z = layer.bias[o] as f64
                        + (0..layer.inputs)
                            .map(|i| x[i] * layer.weights[i * layer.outputs + o] as f64)
                            .sum::<f64>();
                    if relu {
                        z.max(0.0)
                    } else {
                        z
                    }
                })
                .collect()
        };
        let mut sum = 0.0;
        for s in samples {
            let x: Vec<f64> = s.input().iter().map(|&v| v as f64).collect();
            let a1 = dense(&layers[0], &x, true);
            let a2 = dense(&layers[1], &a1, true);
            let z3 = dense(&layers[2], &a2, false);
            assert_eq!(z3.len(), s.log_targets().len());
            for (z, &t) in z3.iter().zip(s.log_targets()) {
                let y = z.exp() - 1.0;
                sum += ((y * s.cos_light() as f64).ln_1p() - t as f64).abs();
            }
        }
        sum / (S::OUTPUTS * samples.len()) as f64
    }

    fn check_gradient(kernel: Kernel) {
        check_gradient_of(kernel, &random_samples(100, 12));
    }

    fn check_gradient_of<S: TrainingSample>(kernel: Kernel, samples: &[S]) {
        let hidden = 5;
        let layers = random_layers_with(hidden, S::OUTPUTS, 11);
        let indices: Vec<u32> = (0..samples.len() as u32).collect();
        let mut trainer =
            Trainer::<S>::from_layers(&layers, 128, AdamConfig::default()).with_kernel(kernel);
        let loss_sum = trainer.compute_gradient(samples, &indices);
        let reference = reference_loss(&layers, samples);
        let count = (S::OUTPUTS * samples.len()) as f64;
        assert!(
            (loss_sum / count - reference).abs() < 1e-5 * reference.max(1.0),
            "{loss_sum} vs {reference}"
        );
        let layout = Layout::with_outputs(hidden, S::OUTPUTS);
        let analytic = layout.unpad(trainer.gradient());
        let h = 1e-3;
        let mut worst: f64 = 0.0;
        for k in 0..3 {
            let n_w = layers[k].weights.len();
            for idx in 0..n_w + layers[k].bias.len() {
                let nudge = |delta: f32| {
                    let mut l = layers.clone();
                    if idx < n_w {
                        l[k].weights[idx] += delta
                    } else {
                        l[k].bias[idx - n_w] += delta
                    }
                    reference_loss(&l, samples)
                };
                let numeric = (nudge(h) - nudge(-h)) / (2.0 * h as f64);
                let a = if idx < n_w {
                    analytic[k].weights[idx]
                } else {
                    analytic[k].bias[idx - n_w]
                } as f64;
                worst = worst.max((a - numeric).abs());
                assert!(
                    (a - numeric).abs() < 2e-4,
                    "layer {k} parameter {idx}: analytic {a} numeric {numeric}"
                );
            }
        }
        assert!(worst < 2e-4);
    }

    #[test]
    fn gradient_matches_central_differences_portable() {
        check_gradient(Kernel::Portable);
    }

    #[test]
    fn gradient_matches_central_differences_detected_kernel() {
        check_gradient(Kernel::detect());
    }

    /// 16 outputs (two padded output blocks): the general transposes and widths.
    #[test]
    fn spectral_gradient_matches_central_differences() {
        let samples = random_spectral_samples(40, 13);
        check_gradient_of(Kernel::Portable, &samples);
        check_gradient_of(Kernel::detect(), &samples);
    }

    #[test]
    fn padding_round_trips_and_outputs_match_the_definition() {
        let layers = random_layers(21, 5);
        let layout = Layout::new(21);
        assert_eq!(layout.hp, 24);
        assert_eq!(layout.unpad(&layout.pad(&layers)), layers);
        let weights = Weights::new(layout, Layout::new(21).pad(&layers));
        let samples = random_samples(10, 6);
        let mut scratch = ChunkScratch::new(&weights.layout);
        scratch.load_slice(&samples);
        let out = outputs(&weights, &mut scratch);
        for (s, o) in samples.iter().zip(out) {
            let a1: Vec<f32> = (0..21)
                .map(|j| {
                    (layers[0].bias[j]
                        + (0..6)
                            .map(|i| s.x[i] * layers[0].weights[i * 21 + j])
                            .sum::<f32>())
                    .max(0.0)
                })
                .collect();
            let a2: Vec<f32> = (0..21)
                .map(|j| {
                    (layers[1].bias[j]
                        + (0..21)
                            .map(|i| a1[i] * layers[1].weights[i * 21 + j])
                            .sum::<f32>())
                    .max(0.0)
                })
                .collect();
            for k in 0..3 {
                let z = layers[2].bias[k]
                    + (0..21)
                        .map(|i| a2[i] * layers[2].weights[i * 3 + k])
                        .sum::<f32>();
                let y = (z.exp() - 1.0).max(0.0);
                assert!((o[k] - y).abs() <= 1e-5 * y.max(1.0), "{o:?} vs {y}");
            }
        }
    }

    #[test]
    fn outputs_match_the_network_evaluator() {
        let layers = random_layers(21, 8);
        let net = crate::network::Nbrdf {
            name: "t".into(),
            layers: layers.clone(),
            anisotropic: false,
            spectral: None,
            sampling: None,
            base: None,
            provenance: serde_json::Value::Null,
        };
        let layout = Layout::new(21);
        let weights = Weights::new(layout.clone(), layout.pad(&layers));
        let samples = random_samples(LANES, 9);
        let mut scratch = ChunkScratch::new(&layout);
        scratch.load_slice(&samples);
        for (s, o) in samples.iter().zip(outputs(&weights, &mut scratch)) {
            let e = net.eval_input(s.x);
            for k in 0..3 {
                assert!(
                    (o[k] - e[k]).abs() <= 2e-6 * e[k].max(1.0),
                    "{o:?} vs {e:?}"
                );
            }
        }
    }
}
