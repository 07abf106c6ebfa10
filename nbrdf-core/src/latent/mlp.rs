//! A small fully connected network in `f32` for the autoencoder and the predictor: `tanh`
//! hidden layers, a linear output layer, `y = x W + b` with `W` row-major `inputs x outputs`.
//! One sample at a time (the batches are small and parallelised over samples by the callers).
//! The layers are the NBRDF's [`Layer`], evaluated by its [`Layer::affine_into`].

use crate::fastmath::Unfused;
use crate::network::{glorot_uniform, Layer};
use crate::rng::{SplitMix64, Stream};
use serde::{Deserialize, Serialize};

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Mlp {
    pub layers: Vec<Layer>,
}

/// The activations of one forward pass: `acts[0]` is the input, `acts[i + 1]` the output of
/// layer `i` (after `tanh` for hidden layers).
pub type Activations = Vec<Vec<f32>>;

impl Mlp {
    /// Glorot-uniform weights, zero biases, deterministic for `(seed, counter)`.
    pub fn new(widths: &[usize], seed: u64, counter: u64) -> Self {
        let mut rng = SplitMix64::new(seed, Stream::Latent, counter);
        Mlp {
            layers: glorot_uniform(widths, &mut rng),
        }
    }

    pub fn inputs(&self) -> usize {
        self.layers.first().map_or(0, |l| l.inputs)
    }

    pub fn outputs(&self) -> usize {
        self.layers.last().map_or(0, |l| l.outputs)
    }

    pub fn parameter_count(&self) -> usize {
        self.layers
            .iter()
            .map(|l| l.weights.len() + l.bias.len())
            .sum()
    }

    pub fn forward(&self, x: &[f32]) -> Activations {
        let mut acts = vec![x.to_vec()];
        let last = self.layers.len().saturating_sub(1);
        for (i, l) in self.layers.iter().enumerate() {
            let mut y = vec![0.0f32; l.outputs];
            l.affine_into::<Unfused>(&acts[i], &mut y);
            if i < last {
                y.iter_mut().for_each(|v| *v = v.tanh());
            }
            acts.push(y);
        }
        acts
    }

    pub fn eval(&self, x: &[f32]) -> Vec<f32> {
        self.forward(x).pop().unwrap_or_default()
    }

    /// Back-propagates `g_out = d loss / d output`: adds the parameter gradient to `grad`
    /// (flat, layer by layer `W, b`) and returns `d loss / d input`.
    pub fn backward(&self, acts: &Activations, g_out: &[f32], grad: &mut [f32]) -> Vec<f32> {
        let mut offsets = Vec::with_capacity(self.layers.len());
        let mut at = 0;
        for l in &self.layers {
            offsets.push(at);
            at += l.weights.len() + l.bias.len();
        }
        let last = self.layers.len().saturating_sub(1);
        let mut g = g_out.to_vec();
        for i in (0..self.layers.len()).rev() {
            let l = &self.layers[i];
            if i < last {
                // tanh' = 1 - y^2 on this layer's output.
                for (gv, &y) in g.iter_mut().zip(&acts[i + 1]) {
                    *gv *= 1.0 - y * y;
                }
            }
            let input = &acts[i];
            let (gw, gb) = grad[offsets[i]..offsets[i] + l.weights.len() + l.bias.len()]
                .split_at_mut(l.weights.len());
            let mut g_in = vec![0.0f32; l.inputs];
            for (k, &xk) in input.iter().enumerate() {
                let row = &l.weights[k * l.outputs..(k + 1) * l.outputs];
                let grow = &mut gw[k * l.outputs..(k + 1) * l.outputs];
                let mut acc = 0.0f32;
                for ((gwo, &w), &go) in grow.iter_mut().zip(row).zip(&g) {
                    *gwo += xk * go;
                    acc += w * go;
                }
                g_in[k] = acc;
            }
            for (b, &go) in gb.iter_mut().zip(&g) {
                *b += go;
            }
            g = g_in;
        }
        g
    }

    pub fn to_flat(&self) -> Vec<f32> {
        let mut v = Vec::with_capacity(self.parameter_count());
        for l in &self.layers {
            v.extend_from_slice(&l.weights);
            v.extend_from_slice(&l.bias);
        }
        v
    }

    pub fn set_flat(&mut self, flat: &[f32]) {
        let mut at = 0;
        for l in &mut self.layers {
            let n = l.weights.len();
            l.weights.copy_from_slice(&flat[at..at + n]);
            at += n;
            let n = l.bias.len();
            l.bias.copy_from_slice(&flat[at..at + n]);
            at += n;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn backward_matches_finite_differences() {
        let mlp = Mlp::new(&[5, 7, 3], 1, 0);
        let x = [0.3f32, -0.2, 0.5, 0.1, -0.7];
        let loss = |m: &Mlp| m.eval(&x).iter().map(|v| (v * v) as f64).sum::<f64>();
        let acts = mlp.forward(&x);
        let out = acts.last().unwrap().clone();
        let g_out: Vec<f32> = out.iter().map(|v| 2.0 * v).collect();
        let mut grad = vec![0.0; mlp.parameter_count()];
        mlp.backward(&acts, &g_out, &mut grad);
        let flat = mlp.to_flat();
        for i in [0, 10, 34, 40, flat.len() - 1] {
            let mut m = mlp.clone();
            let mut p = flat.clone();
            p[i] += 1e-3;
            m.set_flat(&p);
            let lp = loss(&m);
            p[i] -= 2e-3;
            m.set_flat(&p);
            let lm = loss(&m);
            let fd = (lp - lm) / 2e-3;
            assert!(
                (fd - grad[i] as f64).abs() < 1e-3 + 1e-2 * fd.abs(),
                "{i}: {fd} {}",
                grad[i]
            );
        }
    }
}
