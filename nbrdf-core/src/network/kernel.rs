//! Batched evaluation of a network, the renderer's hot loop. It works on structure-of-arrays
//! chunks of [`LANES`] lanes so that every inner loop runs over lanes and vectorises; on x86 it
//! runs an AVX2+FMA copy of the same kernel when the CPU has those features, and rayon splits
//! large batches across threads. The single-input path ([`Nbrdf::eval_input`]) runs the
//! reference layers ([`Layer::affine_into`]) with the same arithmetic; the batched kernel restates
//! them on lanes, and `tests::batched_eval_matches_f64_reference_and_eval_input` holds the two together.

use super::format::shape_problem;
use super::output_activation;
use super::{Layer, Nbrdf};
use crate::brdf::{common_len, Directions, RgbMut};
use crate::coords::network_input_components_for;
#[cfg(any(target_arch = "x86", target_arch = "x86_64"))]
use crate::fastmath::Fused;
use crate::fastmath::{relu, MulAdd, Unfused};
use crate::spectral_basis::MAX_COUNT;
use rayon::prelude::*;

/// Lanes per structure-of-arrays chunk: 8 AVX registers per accumulator row, enough to hide the
/// FMA latency, small enough that the accumulators stay in registers.
pub const LANES: usize = 64;

/// Lanes per rayon task: large enough that the per-task scratch set-up is noise, small enough
/// for load balancing on a 1M-lane batch.
pub(super) const TASK_LANES: usize = 8192;

/// Hidden widths up to this use stack scratch; wider networks allocate once per rayon task.
pub(super) const MAX_STACK_HIDDEN: usize = 64;

impl Nbrdf {
    /// The raw network on one input vector: `f_r` in linear RGB, clamped at 0. Same arithmetic
    /// as the batched kernel (float32, fused multiply-adds where the CPU has them, the same exp
    /// approximation; the output is `max(expm1(min(z, 80)), 0)`, always finite). A network whose layer shapes
    /// were broken through the public fields evaluates to 0 rather than panicking.
    /// A spectral network gives the sRGB projection of its spectrum ([`super::Spectral::project`]).
    pub fn eval_input(&self, x: [f32; 6]) -> [f32; 3] {
        let Some(spectral) = &self.spectral else {
            let mut rgb = [0.0; 3];
            self.eval_outputs(x, &mut rgb);
            return rgb;
        };
        let mut coefficients = [0.0f32; MAX_COUNT];
        let coefficients = &mut coefficients[..spectral.count()];
        self.eval_outputs(x, coefficients);
        spectral.project(coefficients)
    }

    /// The raw outputs on one input vector (RGB, or a spectral network's coefficients), with the
    /// arithmetic of [`Nbrdf::eval_input`]; all 0 when `out` is not as long as the outputs.
    pub fn eval_outputs(&self, x: [f32; 6], out: &mut [f32]) {
        if shape_problem(&self.layers, self.output_count()).is_some()
            || out.len() != self.layers[2].outputs
        {
            out.fill(0.0);
            return;
        }
        let widest = self.layers[0].outputs.max(self.layers[1].outputs);
        if widest <= MAX_STACK_HIDDEN {
            let mut h1 = [0.0f32; MAX_STACK_HIDDEN];
            let mut h2 = [0.0f32; MAX_STACK_HIDDEN];
            self.eval_input_with(&x, &mut h1, &mut h2, out)
        } else {
            let mut h1 = vec![0.0f32; widest];
            let mut h2 = vec![0.0f32; widest];
            self.eval_input_with(&x, &mut h1, &mut h2, out)
        }
    }

    fn eval_input_with(&self, x: &[f32; 6], h1: &mut [f32], h2: &mut [f32], out: &mut [f32]) {
        #[cfg(any(target_arch = "x86", target_arch = "x86_64"))]
        if has_avx2_fma() {
            // SAFETY: the CPU supports AVX2 and FMA (checked just above), which is all that
            // `eval_input_avx2` requires; it has no other preconditions.
            return unsafe { eval_input_avx2(&self.layers, x, h1, h2, out) };
        }
        eval_input_generic::<Unfused>(&self.layers, x, h1, h2, out)
    }

    /// `f_r * cos(theta_l)` for a batch, vectorised and threaded. Lanes with either direction at
    /// or below the horizon, or with non-finite components, give 0. If the slices differ in
    /// length only the common prefix is evaluated.
    pub fn eval_cos_batch_impl(
        &self,
        view: Directions<'_>,
        light: Directions<'_>,
        out: RgbMut<'_>,
    ) {
        if let Some(spectral) = &self.spectral {
            return self.eval_spectral_rgb(spectral, view, light, out);
        }
        let n = common_len(&[view.min_len(), light.min_len(), out.min_len()]);
        let (r, g, b) = (&mut out.r[..n], &mut out.g[..n], &mut out.b[..n]);
        let Some(packed) = Packed::new(self) else {
            for c in [r, g, b] {
                c.fill(0.0);
            }
            return;
        };
        let (view, light) = (view.slice(0, n), light.slice(0, n));
        if n <= TASK_LANES {
            eval_task(&packed, view, light, &mut RgbSink::new([r, g, b]));
            return;
        }
        r.par_chunks_mut(TASK_LANES)
            .zip(g.par_chunks_mut(TASK_LANES))
            .zip(b.par_chunks_mut(TASK_LANES))
            .enumerate()
            .for_each(|(k, ((r, g), b))| {
                let (start, end) = (k * TASK_LANES, k * TASK_LANES + r.len());
                eval_task(
                    &packed,
                    view.slice(start, end),
                    light.slice(start, end),
                    &mut RgbSink::new([r, g, b]),
                );
            });
    }

    /// The raw outputs times `cos(theta_l)` for a batch, pair-major (`out[i * outputs + k]`,
    /// `outputs` the last layer's width: a spectral network's coefficients), with the kernel of
    /// [`Nbrdf::eval_cos_batch_impl`]; 0 where it gives 0. Evaluates the common prefix of the
    /// directions and `out.len() / outputs` pairs.
    pub fn eval_outputs_cos_batch(
        &self,
        view: Directions<'_>,
        light: Directions<'_>,
        out: &mut [f32],
    ) {
        let outputs = self.layers[2].outputs.max(1);
        let n = common_len(&[view.min_len(), light.min_len(), out.len() / outputs]);
        let out = &mut out[..n * outputs];
        let Some(packed) = Packed::new(self) else {
            out.fill(0.0);
            return;
        };
        out.par_chunks_mut(TASK_LANES * outputs)
            .enumerate()
            .for_each(|(k, chunk)| {
                let start = k * TASK_LANES;
                let end = start + chunk.len() / outputs;
                let mut sink = RowsSink {
                    out: chunk,
                    outputs,
                };
                eval_task(
                    &packed,
                    view.slice(start, end),
                    light.slice(start, end),
                    &mut sink,
                );
            });
    }
}

/// The network on one input vector, with the batched kernel's arithmetic (`M`); shapes are
/// checked by the caller and `h1`, `h2` are at least as long as the hidden widths.
#[inline(always)]
pub(super) fn eval_input_generic<M: MulAdd>(
    layers: &[Layer; 3],
    x: &[f32; 6],
    h1: &mut [f32],
    h2: &mut [f32],
    out: &mut [f32],
) {
    let [l1, l2, l3] = layers;
    let h1 = &mut h1[..l1.outputs];
    let h2 = &mut h2[..l2.outputs];
    l1.affine_into::<M>(x, h1);
    h1.iter_mut().for_each(|v| *v = relu(*v));
    l2.affine_into::<M>(h1, h2);
    h2.iter_mut().for_each(|v| *v = relu(*v));
    l3.affine_into::<M>(h2, out);
    out.iter_mut().for_each(|z| *z = output_activation::<M>(*z));
}

/// [`eval_input_generic`] compiled with AVX2 and FMA: the loops over outputs vectorise 8 wide.
#[cfg(any(target_arch = "x86", target_arch = "x86_64"))]
#[target_feature(enable = "avx2,fma")]
unsafe fn eval_input_avx2(
    layers: &[Layer; 3],
    x: &[f32; 6],
    h1: &mut [f32],
    h2: &mut [f32],
    out: &mut [f32],
) {
    eval_input_generic::<Fused>(layers, x, h1, h2, out)
}

// ---------------------------------------------------------------------------------------------
// Batched kernel.

/// Rows of a structure-of-arrays chunk: one array of lanes per feature.
type Row = [f32; LANES];

/// The weights transposed to `outputs x inputs` so that each output's weights are contiguous,
/// with the always-zero input `x[1]` of isotropic networks dropped from the first layer.
pub(super) struct Packed {
    anisotropic: bool,
    w1: Vec<f32>,
    b1: Vec<f32>,
    w2: Vec<f32>,
    b2: Vec<f32>,
    w3: Vec<f32>,
    b3: Vec<f32>,
    hidden1: usize,
    hidden2: usize,
}

/// The input features the kernel uses for an isotropic network: `x` without the constant
/// `x[1] = 0`.
const USED_INPUTS: [usize; 5] = [0, 2, 3, 4, 5];
/// An anisotropic network uses all six (`x[1] = sin theta_h sin phi_h`).
const ALL_INPUTS: [usize; 6] = [0, 1, 2, 3, 4, 5];

/// The input features of the first layer.
#[inline(always)]
fn used_inputs(anisotropic: bool) -> &'static [usize] {
    if anisotropic {
        &ALL_INPUTS
    } else {
        &USED_INPUTS
    }
}

impl Packed {
    pub(super) fn new(net: &Nbrdf) -> Option<Self> {
        if shape_problem(&net.layers, net.output_count()).is_some() {
            return None;
        }
        let [l1, l2, l3] = &net.layers;
        let transpose = |layer: &Layer, rows: &[usize]| -> Vec<f32> {
            (0..layer.outputs)
                .flat_map(|o| {
                    rows.iter()
                        .map(move |&i| layer.weights[i * layer.outputs + o])
                })
                .collect()
        };
        let all = |layer: &Layer| (0..layer.inputs).collect::<Vec<_>>();
        Some(Packed {
            anisotropic: net.anisotropic,
            w1: transpose(l1, used_inputs(net.anisotropic)),
            b1: l1.bias.clone(),
            w2: transpose(l2, &all(l2)),
            b2: l2.bias.clone(),
            w3: transpose(l3, &all(l3)),
            b3: l3.bias.clone(),
            hidden1: l1.outputs,
            hidden2: l2.outputs,
        })
    }
}

/// Whether this CPU can run the AVX2+FMA kernel (cached by the standard library).
#[cfg(any(target_arch = "x86", target_arch = "x86_64"))]
pub(crate) fn has_avx2_fma() -> bool {
    is_x86_feature_detected!("avx2") && is_x86_feature_detected!("fma")
}

/// One rayon task: picks the kernel for this CPU.
fn eval_task<S: OutputSink>(
    packed: &Packed,
    view: Directions<'_>,
    light: Directions<'_>,
    out: &mut S,
) {
    #[cfg(any(target_arch = "x86", target_arch = "x86_64"))]
    if has_avx2_fma() {
        // SAFETY: the CPU supports AVX2 and FMA (checked just above), which is all that
        // `eval_task_avx2` requires; it has no other preconditions.
        unsafe { eval_task_avx2(packed, view, light, out) };
        return;
    }
    eval_task_generic::<Unfused, S>(packed, view, light, out);
}

/// The generic kernel compiled with AVX2 and FMA enabled (everything below is inlined into it).
#[cfg(any(target_arch = "x86", target_arch = "x86_64"))]
#[target_feature(enable = "avx2,fma")]
unsafe fn eval_task_avx2<S: OutputSink>(
    packed: &Packed,
    view: Directions<'_>,
    light: Directions<'_>,
    out: &mut S,
) {
    eval_task_generic::<Fused, S>(packed, view, light, out);
}

/// Scratch for the hidden activations, on the stack for the usual widths.
#[inline(always)]
pub(super) fn eval_task_generic<M: MulAdd, S: OutputSink>(
    packed: &Packed,
    view: Directions<'_>,
    light: Directions<'_>,
    out: &mut S,
) {
    if packed.hidden1.max(packed.hidden2) <= MAX_STACK_HIDDEN {
        let mut h1 = [[0.0f32; LANES]; MAX_STACK_HIDDEN];
        let mut h2 = [[0.0f32; LANES]; MAX_STACK_HIDDEN];
        let (h1, h2) = (&mut h1[..packed.hidden1], &mut h2[..packed.hidden2]);
        // The input layout is a compile-time constant of each kernel copy, so that the lane
        // loop of `build_inputs` has no branch on it.
        if packed.anisotropic {
            eval_chunks::<M, true, S>(packed, view, light, out, h1, h2);
        } else {
            eval_chunks::<M, false, S>(packed, view, light, out, h1, h2);
        }
    } else {
        let mut h1 = vec![[0.0f32; LANES]; packed.hidden1];
        let mut h2 = vec![[0.0f32; LANES]; packed.hidden2];
        if packed.anisotropic {
            eval_chunks::<M, true, S>(packed, view, light, out, &mut h1, &mut h2);
        } else {
            eval_chunks::<M, false, S>(packed, view, light, out, &mut h1, &mut h2);
        }
    }
}

#[inline(always)]
fn eval_chunks<M: MulAdd, const ANISO: bool, S: OutputSink>(
    packed: &Packed,
    view: Directions<'_>,
    light: Directions<'_>,
    out: &mut S,
    h1: &mut [Row],
    h2: &mut [Row],
) {
    let n = view.len();
    let sources = [light.x, light.y, light.z, view.x, view.y, view.z];
    // Per-task buffers, reused by every chunk.
    let mut padded = [[0.0f32; LANES]; 6];
    let mut x = [[0.0f32; LANES]; 6];
    let inputs = used_inputs(ANISO).len();
    let mut cos = [0.0f32; LANES];
    let mut start = 0;
    while start < n {
        let m = LANES.min(n - start);
        let end = start + m;
        // Full chunks are read in place; the tail, and chunks with vectors too long or short to
        // normalise in float32, go through padded copies (zero vectors are invalid and give 0),
        // so the lane loops always have a constant trip count.
        let in_place = full_rows(&sources, start);
        let done = in_place.is_some_and(|rows| build_inputs::<ANISO>(rows, &mut x, &mut cos));
        if !done {
            for (row, src) in padded.iter_mut().zip(sources) {
                row.fill(0.0);
                row[..m].copy_from_slice(&src[start..end]);
            }
            rescale_out_of_range(&mut padded);
            build_inputs::<ANISO>(padded.each_ref(), &mut x, &mut cos);
        }
        dense_relu_chunk::<M>(&packed.w1, &packed.b1, &x[..inputs], h1);
        dense_relu_chunk::<M>(&packed.w2, &packed.b2, h1, h2);
        out.put::<M>(packed, h2, &cos, start, end);
        start = end;
    }
}

/// The six direction rows of the chunk at `start` as fixed-size arrays, if it is a full chunk.
#[inline(always)]
fn full_rows<'a>(sources: &[&'a [f32]; 6], start: usize) -> Option<[&'a Row; 6]> {
    let rows = sources.map(|s| {
        s.get(start..start + LANES)
            .and_then(|s| <&Row>::try_from(s).ok())
    });
    match rows {
        [Some(a), Some(b), Some(c), Some(d), Some(e), Some(f)] => Some([a, b, c, d, e, f]),
        _ => None,
    }
}

/// Squared lengths in this range normalise accurately in float32; others are rescaled first.
#[inline(always)]
fn len2_in_range(len2: f32) -> bool {
    (len2 > 1e-30) & (len2 < 1e30)
}

/// Network inputs and `cos(theta_l)` (0 for invalid lanes) of a chunk of direction pairs.
/// Returns false, with the outputs incomplete, when some vector's squared length is outside
/// the range where float32 normalisation is accurate (the caller rescales and retries).
// Lane-indexed loops over several rows at once are the shape that vectorises here.
#[allow(clippy::needless_range_loop)]
#[inline(always)]
fn build_inputs<const ANISO: bool>(dirs: [&Row; 6], x: &mut [Row; 6], cos: &mut Row) -> bool {
    let mut out_of_range = 0u32;
    for j in 0..LANES {
        let [lx, ly, lz, vx, vy, vz] = dirs.map(|row| row[j]);
        let input = network_input_components_for(ANISO, vx, vy, vz, lx, ly, lz);
        for (row, &k) in x.iter_mut().zip(used_inputs(ANISO)) {
            row[j] = input[k];
        }
        let l_len2 = lx * lx + ly * ly + lz * lz;
        let v_len2 = vx * vx + vy * vy + vz * vz;
        let in_range = len2_in_range(l_len2) & len2_in_range(v_len2);
        out_of_range += u32::from(!in_range);
        let valid = (lz > 0.0) & (vz > 0.0) & in_range;
        let c = lz * (1.0 / l_len2.sqrt());
        cos[j] = if valid { c } else { 0.0 };
    }
    out_of_range == 0
}

/// Brings each vector whose squared length would overflow or underflow float32 to a length near
/// 1 (dividing by its largest component); non-finite or zero vectors become zero (invalid).
#[allow(clippy::needless_range_loop)]
#[cold]
fn rescale_out_of_range(dirs: &mut [Row; 6]) {
    for base in [0, 3] {
        for j in 0..LANES {
            let v = [dirs[base][j], dirs[base + 1][j], dirs[base + 2][j]];
            let len2 = v[0] * v[0] + v[1] * v[1] + v[2] * v[2];
            if len2_in_range(len2) {
                continue;
            }
            let m = v[0].abs().max(v[1].abs()).max(v[2].abs());
            let scaled = if v.iter().all(|c| c.is_finite()) && m > 0.0 {
                v.map(|c| c / m)
            } else {
                [0.0; 3]
            };
            for (k, c) in scaled.into_iter().enumerate() {
                dirs[base + k][j] = c;
            }
        }
    }
}

/// `y = relu(W x + b)` over a chunk; `w` is `outputs x inputs`. The lane loop is innermost and
/// the accumulator row (8 AVX registers) stays in registers across the input loop. (Computing
/// three outputs per pass, 12 accumulators on 32 lanes, was slower.)
#[inline(always)]
fn dense_relu_chunk<M: MulAdd>(w: &[f32], b: &[f32], x: &[Row], y: &mut [Row]) {
    for ((w_row, &bias), y_row) in w.chunks_exact(x.len()).zip(b).zip(y.iter_mut()) {
        let acc = affine_chunk::<M>(w_row, bias, x);
        for j in 0..LANES {
            y_row[j] = relu(acc[j]);
        }
    }
}

#[inline(always)]
fn affine_chunk<M: MulAdd>(w_row: &[f32], bias: f32, x: &[Row]) -> Row {
    let mut acc = [bias; LANES];
    for (&w, x_row) in w_row.iter().zip(x) {
        for j in 0..LANES {
            acc[j] = M::mul_add(w, x_row[j], acc[j]);
        }
    }
    acc
}

/// Where a chunk's last layer goes: the RGB kernel's three planar rows, or the pair-major rows
/// of any number of outputs (a spectral network's coefficients). A type parameter of the
/// kernel, so that the RGB copy compiles to the same code as before it existed.
pub(super) trait OutputSink {
    /// Last layer, output activation and cosine factor for the pairs `start..end` of the task.
    fn put<M: MulAdd>(&mut self, packed: &Packed, h2: &[Row], cos: &Row, start: usize, end: usize);
}

/// Planar RGB rows, written in place for full chunks.
pub(super) struct RgbSink<'a> {
    out: [&'a mut [f32]; 3],
    scratch: [Row; 3],
}

impl<'a> RgbSink<'a> {
    pub(super) fn new(out: [&'a mut [f32]; 3]) -> Self {
        RgbSink {
            out,
            scratch: [[0.0; LANES]; 3],
        }
    }
}

impl OutputSink for RgbSink<'_> {
    #[inline(always)]
    fn put<M: MulAdd>(&mut self, packed: &Packed, h2: &[Row], cos: &Row, start: usize, end: usize) {
        let [r, g, b] = &mut self.out;
        let direct =
            [&mut **r, &mut **g, &mut **b].map(|c| <&mut Row>::try_from(&mut c[start..end]).ok());
        if let [Some(r), Some(g), Some(b)] = direct {
            output_chunk::<M>(&packed.w3, &packed.b3, h2, cos, [r, g, b]);
        } else {
            output_chunk::<M>(&packed.w3, &packed.b3, h2, cos, self.scratch.each_mut());
            for (dst, row) in [&mut **r, &mut **g, &mut **b]
                .into_iter()
                .zip(&self.scratch)
            {
                dst[start..end].copy_from_slice(&row[..end - start]);
            }
        }
    }
}

/// Pair-major rows of `outputs` values (`out[i * outputs + k]`).
struct RowsSink<'a> {
    out: &'a mut [f32],
    outputs: usize,
}

impl OutputSink for RowsSink<'_> {
    #[inline(always)]
    fn put<M: MulAdd>(&mut self, packed: &Packed, h2: &[Row], cos: &Row, start: usize, end: usize) {
        let rows = packed.w3.chunks_exact(h2.len()).zip(&packed.b3);
        for (k, (w_row, &bias)) in rows.enumerate() {
            let acc = affine_chunk::<M>(w_row, bias, h2);
            for (j, i) in (start..end).enumerate() {
                self.out[i * self.outputs + k] = output_activation::<M>(acc[j]) * cos[j];
            }
        }
    }
}

/// Last layer, output activation and cosine factor.
#[inline(always)]
fn output_chunk<M: MulAdd>(w: &[f32], b: &[f32], x: &[Row], cos: &Row, rgb: [&mut Row; 3]) {
    for ((w_row, &bias), out) in w.chunks_exact(x.len()).zip(b).zip(rgb) {
        let acc = affine_chunk::<M>(w_row, bias, x);
        for j in 0..LANES {
            out[j] = output_activation::<M>(acc[j]) * cos[j];
        }
    }
}
