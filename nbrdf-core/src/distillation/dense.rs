//! A stack of dense layers of any widths, trained on chunks of [`LANES`] samples: the encoder and
//! the decoder of a spatially varying material. ReLU between layers, the last layer linear (the
//! caller applies the output activation in its loss). The same register-blocked products
//! ([`gemm`]) and padding as the homogeneous trainer's fixed-shape network
//! ([`crate::train::mlp_grad`]): every width is padded to a multiple of [`VEC`] with zero weights,
//! which stay 0 forward and get 0 gradient backward.
//!
//! The forward pass is a second copy, laid out for gradients, of the decoder's
//! ([`crate::textured::Decoder::forward`], [`crate::network::Layer::affine_into`]); the tests
//! hold the two together.

use crate::fastmath::MulAdd;
use crate::network::Layer;
use crate::train::gemm::{column_sums, gemm, Init, Post, Strided, VEC};
use crate::train::mlp_grad::LANES;

/// Where each layer's padded weights `[inputs][padded outputs]` and bias `[padded outputs]` lie
/// in one flat parameter vector.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) struct DenseLayout {
    /// `widths[k]`: the inputs of layer `k`; the last, the outputs.
    pub widths: Vec<usize>,
    /// The widths padded to a multiple of [`VEC`]: the row strides of the activations.
    pub padded: Vec<usize>,
    weight_at: Vec<usize>,
    bias_at: Vec<usize>,
    pub len: usize,
}

impl DenseLayout {
    pub fn new(widths: &[usize]) -> Self {
        let padded: Vec<usize> = widths.iter().map(|w| w.div_ceil(VEC) * VEC).collect();
        let (mut weight_at, mut bias_at, mut len) = (Vec::new(), Vec::new(), 0);
        for k in 0..widths.len() - 1 {
            weight_at.push(len);
            len += widths[k] * padded[k + 1];
            bias_at.push(len);
            len += padded[k + 1];
        }
        DenseLayout {
            widths: widths.to_vec(),
            padded,
            weight_at,
            bias_at,
            len,
        }
    }

    pub fn layers(&self) -> usize {
        self.widths.len() - 1
    }

    pub fn outputs(&self) -> usize {
        self.widths[self.layers()]
    }

    /// The padded parameters of layers of this layout's widths (checked by the caller).
    pub fn pad(&self, layers: &[Layer]) -> Vec<f32> {
        let mut p = vec![0.0; self.len];
        for (k, layer) in layers.iter().enumerate() {
            let ld = self.padded[k + 1];
            for i in 0..layer.inputs {
                let row = &layer.weights[i * layer.outputs..(i + 1) * layer.outputs];
                p[self.weight_at[k] + i * ld..][..layer.outputs].copy_from_slice(row);
            }
            p[self.bias_at[k]..][..layer.outputs].copy_from_slice(&layer.bias);
        }
        p
    }

    /// The layers of padded parameters `p`, in the file's layout.
    pub fn unpad(&self, p: &[f32]) -> Vec<Layer> {
        (0..self.layers())
            .map(|k| {
                let (inputs, outputs, ld) =
                    (self.widths[k], self.widths[k + 1], self.padded[k + 1]);
                let weights = (0..inputs)
                    .flat_map(|i| &p[self.weight_at[k] + i * ld..][..outputs])
                    .copied()
                    .collect();
                Layer {
                    inputs,
                    outputs,
                    weights,
                    bias: p[self.bias_at[k]..][..outputs].to_vec(),
                }
            })
            .collect()
    }
}

/// Parameters and the transposed weights the backward pass multiplies with.
#[derive(Clone, Debug)]
pub(crate) struct DenseWeights {
    pub layout: DenseLayout,
    pub p: Vec<f32>,
    /// `W_k^T`, `[outputs][padded inputs]` per layer.
    transposed: Vec<Vec<f32>>,
}

impl DenseWeights {
    pub fn new(layout: DenseLayout, p: Vec<f32>) -> Self {
        let transposed = (0..layout.layers())
            .map(|k| vec![0.0; layout.widths[k + 1] * layout.padded[k]])
            .collect();
        let mut w = DenseWeights {
            layout,
            p,
            transposed,
        };
        w.refresh_transposes();
        w
    }

    /// Call after every change of `p`.
    pub fn refresh_transposes(&mut self) {
        let l = &self.layout;
        for (k, t) in self.transposed.iter_mut().enumerate() {
            let (inputs, outputs) = (l.widths[k], l.widths[k + 1]);
            let (ld_in, ld_out) = (l.padded[k], l.padded[k + 1]);
            for i in 0..inputs {
                for o in 0..outputs {
                    t[o * ld_in + i] = self.p[l.weight_at[k] + i * ld_out + o];
                }
            }
        }
    }
}

/// One chunk's activations and their gradients, `[lane][padded width]` per layer boundary:
/// `acts[0]` is the input, `acts[k + 1]` the output of layer `k`.
pub(crate) struct DenseScratch {
    pub acts: Vec<Vec<f32>>,
    pub grads: Vec<Vec<f32>>,
}

impl DenseScratch {
    pub fn new(layout: &DenseLayout) -> Self {
        let buffers = || layout.padded.iter().map(|w| vec![0.0; LANES * w]).collect();
        DenseScratch {
            acts: buffers(),
            grads: buffers(),
        }
    }

    /// The input row of `lane` (padded width).
    pub fn input_mut(&mut self, lane: usize, stride: usize) -> &mut [f32] {
        &mut self.acts[0][lane * stride..(lane + 1) * stride]
    }
}

/// The forward pass of the loaded inputs: `acts[k + 1] = relu(acts[k] W_k + b_k)`, the last
/// layer without the ReLU.
#[inline(always)]
pub(crate) fn forward<M: MulAdd>(w: &DenseWeights, s: &mut DenseScratch) {
    let l = &w.layout;
    for k in 0..l.layers() {
        let (before, after) = s.acts.split_at_mut(k + 1);
        let (ld_in, ld_out) = (l.padded[k], l.padded[k + 1]);
        let input = Strided {
            data: &before[k],
            row_stride: ld_in,
            col_stride: 1,
        };
        let post = if k + 1 < l.layers() {
            Post::Relu
        } else {
            Post::None
        };
        gemm::<M>(
            LANES,
            ld_out,
            l.widths[k],
            input,
            &w.p[l.weight_at[k]..],
            ld_out,
            &mut after[0],
            ld_out,
            Init::Row(&w.p[l.bias_at[k]..][..ld_out]),
            post,
        );
    }
}

/// The backward pass from `grads[last]` (the loss gradient of the last layer's outputs, padded
/// columns 0), after [`forward`] on the same chunk: writes (not adds) the parameter gradient
/// into `grad`, and with `input_gradient` the gradient of the inputs into `grads[0]`.
#[inline(always)]
pub(crate) fn backward<M: MulAdd>(
    w: &DenseWeights,
    s: &mut DenseScratch,
    grad: &mut [f32],
    input_gradient: bool,
) {
    let l = &w.layout;
    for k in (0..l.layers()).rev() {
        let (ld_in, ld_out) = (l.padded[k], l.padded[k + 1]);
        let (below, above) = s.grads.split_at_mut(k + 1);
        let g_out = &above[0];
        let input_t = Strided {
            data: &s.acts[k],
            row_stride: 1,
            col_stride: ld_in,
        };
        gemm::<M>(
            l.widths[k],
            ld_out,
            LANES,
            input_t,
            g_out,
            ld_out,
            &mut grad[l.weight_at[k]..],
            ld_out,
            Init::Zero,
            Post::None,
        );
        column_sums(LANES, ld_out, g_out, ld_out, &mut grad[l.bias_at[k]..]);
        if k == 0 && !input_gradient {
            break;
        }
        let post = if k > 0 {
            Post::MaskPositive(&s.acts[k])
        } else {
            Post::None
        };
        let g = Strided {
            data: g_out,
            row_stride: ld_out,
            col_stride: 1,
        };
        gemm::<M>(
            LANES,
            ld_in,
            l.widths[k + 1],
            g,
            &w.transposed[k],
            ld_in,
            &mut below[k],
            ld_in,
            Init::Zero,
            post,
        );
    }
}
