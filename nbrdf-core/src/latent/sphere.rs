//! The differentiable sphere renderer of the autoencoder's image loss (docs/design.md section 7).
//!
//! A `size x size` orthographic sphere seen from `+z`, lit by a directional light of unit
//! irradiance at `theta_l` (45 degrees by default) in the `xz` plane, exactly the geometry of
//! [`crate::metrics::render_sphere`]. Radiance is `f_r cos(theta_l)`; the tone map is
//! `max(x, 1e-12)^(1/2.2)`; the loss is the mean squared difference of tone-mapped pixels over
//! the whole square image and the three channels.
//!
//! Only pixels on the disk with the light above their horizon can be non-black, so the pixel
//! set and the network inputs of those pixels are computed once. The forward pass is a batched
//! network evaluation over them (the training kernels of [`crate::train::mlp_grad`]); the
//! backward pass pushes `d loss / d pixel` through the tone map and `expm1` and then through the
//! same MLP backward to the 675 (at width 21) network parameters. Chunk gradients are summed in
//! chunk order, so the result is deterministic.

use crate::coords::network_input;
use crate::metrics;
use crate::network::{self, Layer, INPUTS, OUTPUTS};
use crate::train::mlp_grad::{ChunkScratch, Kernel, Layout, Weights, LANES};

/// The tone map's floor.
pub const FLOOR: f32 = 1e-12;
/// The tone map's exponent.
pub const GAMMA_INV: f32 = 1.0 / 2.2;
/// The default image: 64 x 64 pixels, light 45 degrees from the view direction.
pub const SIZE: usize = 64;
pub const LIGHT_THETA_DEG: f64 = 45.0;

/// `max(x, 1e-12)^(1/2.2)`.
#[inline]
pub fn tone(x: f32) -> f32 {
    x.max(FLOOR).powf(GAMMA_INV)
}

/// A fixed sphere image: which pixels are lit and their network inputs.
#[derive(Clone, Debug)]
pub struct SphereRenderer {
    pub size: usize,
    pub hidden: usize,
    /// Pixel index `py * size + px` of each lit pixel.
    pixels: Vec<usize>,
    inputs: Vec<[f32; INPUTS]>,
    cos: Vec<f32>,
    layout: Layout,
    /// Padded-layout index of each flat (`W1 b1 W2 b2 W3 b3`) parameter.
    flat_to_padded: Vec<usize>,
    kernel: Kernel,
    /// 0: the exact gradient. Positive `r0`: the training surrogate of [`SphereRenderer::loss`].
    pub surrogate_floor: f32,
}

/// Per-thread working memory of the renderer.
pub struct Scratch {
    chunk: ChunkScratch,
    grad_chunk: Vec<f32>,
    grad_padded: Vec<f32>,
}

impl SphereRenderer {
    pub fn new(size: usize, light_theta: f64, hidden: usize) -> Self {
        Self::window(size, light_theta, hidden, (0.0, 0.0), 1.0)
    }

    /// The same view zoomed on the mirror direction's point of the sphere (the normal halfway
    /// between light and view), `half_width` of the sphere's radius on each side: a 64 x 64
    /// image of half width 0.1 resolves the highlight ten times finer than the whole sphere,
    /// where lobes sharper than `n ~ 1000` are a pixel or less.
    pub fn highlight(size: usize, light_theta: f64, hidden: usize, half_width: f32) -> Self {
        let centre = ((light_theta / 2.0).sin() as f32, 0.0);
        Self::window(size, light_theta, hidden, centre, half_width)
    }

    /// A `size x size` image of a window of the view ([`metrics::sphere_pixels_window`]).
    pub fn window(
        size: usize,
        light_theta: f64,
        hidden: usize,
        centre: (f32, f32),
        half_width: f32,
    ) -> Self {
        let (mut pixels, mut inputs, mut cos) = (Vec::new(), Vec::new(), Vec::new());
        for p in metrics::sphere_pixels_window(size, light_theta, centre, half_width) {
            if p.light.z <= 0.0 || p.view.z <= 0.0 {
                continue;
            }
            pixels.push(p.index);
            inputs.push(network_input(p.view, p.light));
            cos.push(p.light.z);
        }
        let layout = Layout::new(hidden);
        let flat_to_padded = flat_to_padded(&layout);
        SphereRenderer {
            size,
            hidden,
            pixels,
            inputs,
            cos,
            layout,
            flat_to_padded,
            kernel: Kernel::detect(),
            surrogate_floor: 0.0,
        }
    }

    /// The autoencoder's image: 64 x 64, light at 45 degrees, width-21 networks.
    pub fn standard() -> Self {
        Self::new(SIZE, LIGHT_THETA_DEG.to_radians(), network::DEFAULT_HIDDEN)
    }

    /// The portable kernel copy (for tests comparing against other code paths).
    pub fn with_kernel(mut self, kernel: Kernel) -> Self {
        self.kernel = kernel;
        self
    }

    pub fn parameter_count(&self) -> usize {
        self.flat_to_padded.len()
    }

    /// Number of values of an image (`3 size^2`), the loss's denominator.
    pub fn image_len(&self) -> usize {
        3 * self.size * self.size
    }

    pub fn scratch(&self) -> Scratch {
        Scratch {
            chunk: ChunkScratch::new(&self.layout),
            grad_chunk: vec![0.0; self.layout.len],
            grad_padded: vec![0.0; self.layout.len],
        }
    }

    fn weights(&self, flat: &[f32]) -> Weights {
        assert_eq!(flat.len(), self.flat_to_padded.len(), "parameter count");
        let mut p = vec![0.0; self.layout.len];
        for (&v, &i) in flat.iter().zip(&self.flat_to_padded) {
            p[i] = v;
        }
        Weights::new(self.layout.clone(), p)
    }

    /// Linear radiance, planar `[channel][py * size + px]`, as the evaluator computes it
    /// (`max(expm1(z), 0) cos`).
    pub fn render(&self, flat: &[f32], s: &mut Scratch) -> Vec<f32> {
        let w = self.weights(flat);
        let n = self.size * self.size;
        let mut out = vec![0.0f32; 3 * n];
        for (c, chunk) in self.inputs.chunks(LANES).enumerate() {
            s.chunk.load_inputs(chunk);
            self.kernel.forward_raw(&w, &mut s.chunk);
            for lane in 0..chunk.len() {
                let i = c * LANES + lane;
                for k in 0..OUTPUTS {
                    let y = crate::fastmath::fast_expm1(s.chunk.output_pre_activation(lane, k))
                        .max(0.0);
                    out[k * n + self.pixels[i]] = y * self.cos[i];
                }
            }
        }
        out
    }

    /// Tone-mapped image (`max(x, 1e-12)^(1/2.2)`) of [`SphereRenderer::render`].
    pub fn render_toned(&self, flat: &[f32], s: &mut Scratch) -> Vec<f32> {
        self.render(flat, s).into_iter().map(tone).collect()
    }

    /// Sum of squared differences to `target` of the pixels no sample covers, which stay at
    /// the tone map's floor whatever the network: a constant of the loss.
    fn unlit_loss(&self, target: &[f32]) -> f64 {
        let n = self.size * self.size;
        let floor_tone = tone(0.0);
        let mut lit = vec![false; n];
        for &p in &self.pixels {
            lit[p] = true;
        }
        let mut loss = 0.0f64;
        for k in 0..OUTPUTS {
            for (p, &is_lit) in lit.iter().enumerate() {
                if !is_lit {
                    let d = (floor_tone - target[k * n + p]) as f64;
                    loss += d * d;
                }
            }
        }
        loss
    }

    /// Loss `mean (tone(render(flat)) - target)^2` over the whole image (`target` tone-mapped,
    /// planar, e.g. from [`SphereRenderer::render_toned`]) and, if `grad` is given, its gradient
    /// with respect to the flat parameters, written into `grad`.
    ///
    /// With `surrogate_floor == 0` the gradient is that of the function as evaluated: 0 where
    /// `expm1(z)` is clamped at 0 or `z` is clamped to the exp range, and 0 below the tone map's
    /// floor. Such pixels never recover once a decoded network turns a region black, and the
    /// slope `r^(1/2.2 - 1)` explodes near 0; training therefore uses a surrogate gradient
    /// (`surrogate_floor = r0 > 0`): the tone-map slope at `max(r, r0)` and the `max(., 0)` clamp
    /// passed straight through. The loss value is exact either way.
    pub fn loss(
        &self,
        flat: &[f32],
        target: &[f32],
        s: &mut Scratch,
        grad: Option<&mut [f32]>,
    ) -> f64 {
        let w = self.weights(flat);
        let n = self.size * self.size;
        assert_eq!(target.len(), 3 * n, "target image size");
        let inv = 1.0 / (3 * n) as f32;
        let mut loss = self.unlit_loss(target);
        if grad.is_some() {
            s.grad_padded.fill(0.0);
        }
        for (c, chunk) in self.inputs.chunks(LANES).enumerate() {
            s.chunk.load_inputs(chunk);
            self.kernel.forward_raw(&w, &mut s.chunk);
            let mut chunk_loss = 0.0f64;
            for lane in 0..LANES {
                for k in 0..OUTPUTS {
                    if lane >= chunk.len() {
                        s.chunk.set_output_gradient(lane, k, 0.0);
                        continue;
                    }
                    let i = c * LANES + lane;
                    let z = s.chunk.output_pre_activation(lane, k);
                    let y_raw = crate::fastmath::fast_expm1(z);
                    let cos = self.cos[i];
                    let r = y_raw.max(0.0) * cos;
                    let t = tone(r);
                    let d = t - target[k * n + self.pixels[i]];
                    chunk_loss += (d as f64) * (d as f64);
                    let pixel = PixelValue {
                        z,
                        y_raw,
                        cos,
                        r,
                        t,
                    };
                    let g = pixel_gradient(&pixel, 2.0 * d * inv, self.surrogate_floor);
                    s.chunk.set_output_gradient(lane, k, g);
                }
            }
            loss += chunk_loss;
            if grad.is_some() {
                self.kernel
                    .backward_raw(&w, &mut s.chunk, &mut s.grad_chunk);
                for (a, b) in s.grad_padded.iter_mut().zip(&s.grad_chunk) {
                    *a += b;
                }
            }
        }
        if let Some(g) = grad {
            for (out, &i) in g.iter_mut().zip(&self.flat_to_padded) {
                *out = s.grad_padded[i];
            }
        }
        loss * inv as f64
    }
}

/// One output of one lit pixel as [`SphereRenderer::loss`] evaluates it: the network's
/// pre-activation `z`, `y_raw = expm1(z)`, the cosine, the radiance `r = max(y_raw, 0) cos` and
/// its tone-mapped value `t`.
struct PixelValue {
    z: f32,
    y_raw: f32,
    cos: f32,
    r: f32,
    t: f32,
}

/// Gradient of the loss with respect to the pixel's `z`, given `d_loss_d_t` (`2 d / (3 n)`):
/// the exact one for `surrogate_floor == 0`, else the surrogate of [`SphereRenderer::loss`].
fn pixel_gradient(p: &PixelValue, d_loss_d_t: f32, surrogate_floor: f32) -> f32 {
    let in_range = p.z > crate::fastmath::EXP_ARG_MIN && p.z < crate::fastmath::EXP_ARG_MAX;
    if surrogate_floor > 0.0 {
        // Surrogate: the tone map's slope taken at `max(r, r0)` and the clamp of `expm1` at 0
        // passed through, so that pixels decoded too dark (or black) still pull their network
        // output up.
        let r_eff = p.r.max(surrogate_floor);
        let slope = GAMMA_INV * tone(r_eff) / r_eff;
        if in_range {
            d_loss_d_t * slope * p.cos * (p.y_raw + 1.0)
        } else {
            0.0
        }
    } else if p.y_raw > 0.0 && p.r > FLOOR && in_range {
        // d t / d r = t / (2.2 r); d r / d z = cos e^z.
        d_loss_d_t * GAMMA_INV * p.t / p.r * p.cos * (p.y_raw + 1.0)
    } else {
        0.0
    }
}

/// The padded index of each parameter of the flat order `W1 b1 W2 b2 W3 b3`.
fn flat_to_padded(layout: &Layout) -> Vec<usize> {
    let h = layout.hidden;
    let mut layers = [
        Layer {
            inputs: INPUTS,
            outputs: h,
            weights: vec![0.0; INPUTS * h],
            bias: vec![0.0; h],
        },
        Layer {
            inputs: h,
            outputs: h,
            weights: vec![0.0; h * h],
            bias: vec![0.0; h],
        },
        Layer {
            inputs: h,
            outputs: OUTPUTS,
            weights: vec![0.0; h * OUTPUTS],
            bias: vec![0.0; OUTPUTS],
        },
    ];
    // Tag every parameter with its flat index + 1, pad, and read the tags back.
    let mut tag = 1.0f32;
    for layer in &mut layers {
        for v in layer.weights.iter_mut().chain(layer.bias.iter_mut()) {
            *v = tag;
            tag += 1.0;
        }
    }
    let padded = layout.pad(&layers);
    let mut map = vec![0usize; (tag - 1.0) as usize];
    for (i, &v) in padded.iter().enumerate() {
        if v > 0.0 {
            map[v as usize - 1] = i;
        }
    }
    map
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::metrics::render_sphere;
    use crate::network::Nbrdf;

    /// A network with visible output everywhere: random weights and a positive output bias.
    fn material(seed: u64) -> Vec<f32> {
        let mut net = Nbrdf::random("m", 21, seed);
        for v in &mut net.layers[0].weights {
            *v *= 20.0;
        }
        for v in &mut net.layers[1].weights {
            *v *= 10.0;
        }
        for v in &mut net.layers[2].weights {
            *v *= 20.0;
        }
        net.layers[0].bias.iter_mut().for_each(|b| *b = 0.1);
        net.layers[2].bias = vec![0.3, 0.0, -0.3];
        net.to_flat()
    }

    #[test]
    fn forward_matches_the_metrics_renderer() {
        let flat = material(3);
        let r = SphereRenderer::new(16, 45f64.to_radians(), 21);
        let img = r.render(&flat, &mut r.scratch());
        let net = Nbrdf::from_flat("m", 21, &flat).unwrap();
        let reference = render_sphere(&net, 16, 45f64.to_radians());
        let n = 16 * 16;
        for k in 0..3 {
            for p in 0..n {
                let (a, b) = (img[k * n + p], reference.rgb[k][p]);
                assert!(
                    (a - b).abs() <= 1e-4 * (1.0 + b.abs()),
                    "{k} {p}: {a} vs {b}"
                );
            }
        }
        assert!(img.iter().any(|&v| v > 1e-3));
    }

    #[test]
    fn gradient_matches_finite_differences() {
        let r = SphereRenderer::new(24, 45f64.to_radians(), 21).with_kernel(Kernel::Portable);
        let mut s = r.scratch();
        let target = r.render_toned(&material(5), &mut s);
        let flat = material(9);
        let mut grad = vec![0.0; flat.len()];
        let loss = r.loss(&flat, &target, &mut s, Some(&mut grad));
        assert!(loss > 1e-4, "{loss}");
        // Directional derivatives along a few random directions (central differences; the
        // loss is piecewise smooth, so a small step stays mostly within one piece).
        let mut rng = crate::rng::SplitMix64::new(1, crate::rng::Stream::Latent, 0);
        for trial in 0..4 {
            let dir: Vec<f32> = (0..flat.len())
                .map(|_| rng.next_f64() as f32 * 2.0 - 1.0)
                .collect();
            let h = 1e-3f32;
            let shifted = |sign: f32| -> Vec<f32> {
                flat.iter()
                    .zip(&dir)
                    .map(|(p, d)| p + sign * h * d)
                    .collect()
            };
            let (lp, lm) = (
                r.loss(&shifted(1.0), &target, &mut s, None),
                r.loss(&shifted(-1.0), &target, &mut s, None),
            );
            let fd = (lp - lm) / (2.0 * h as f64);
            let analytic: f64 = grad.iter().zip(&dir).map(|(g, d)| (g * d) as f64).sum();
            assert!(
                (fd - analytic).abs() <= 0.03 * analytic.abs().max(fd.abs()) + 1e-6,
                "trial {trial}: finite difference {fd} vs analytic {analytic}"
            );
        }
        // And single coordinates of the output layer, where the gradient is largest.
        for &i in &[flat.len() - 1, flat.len() - 3, flat.len() - 10] {
            let h = 1e-3f32;
            let mut p = flat.clone();
            p[i] += h;
            let lp = r.loss(&p, &target, &mut s, None);
            p[i] -= 2.0 * h;
            let lm = r.loss(&p, &target, &mut s, None);
            let fd = (lp - lm) / (2.0 * h as f64);
            let g = grad[i] as f64;
            assert!(
                (fd - g).abs() <= 0.03 * g.abs().max(fd.abs()) + 1e-6,
                "param {i}: {fd} vs {g}"
            );
        }
    }

    #[test]
    fn highlight_view_looks_at_the_mirror_direction_only() {
        let theta = 45f64.to_radians();
        let whole = SphereRenderer::new(32, theta, 21);
        let zoom = SphereRenderer::highlight(32, theta, 21, 0.1);
        let max_sin_th = |r: &SphereRenderer| r.inputs.iter().map(|x| x[0]).fold(0.0f32, f32::max);
        let min_sin_th = |r: &SphereRenderer| r.inputs.iter().map(|x| x[0]).fold(1.0f32, f32::min);
        // Every pixel of the zoom is lit, within 10 degrees of the half vector, and one of them
        // sits on it; the whole sphere spans half vectors to the horizon.
        assert_eq!(zoom.pixels.len(), 32 * 32);
        assert!(
            max_sin_th(&zoom) < 10f32.to_radians().sin(),
            "{}",
            max_sin_th(&zoom)
        );
        assert!(min_sin_th(&zoom) < 0.5f32.to_radians().sin());
        assert!(max_sin_th(&whole) > 0.9);
    }

    #[test]
    fn loss_is_zero_against_its_own_image() {
        let r = SphereRenderer::new(16, 45f64.to_radians(), 21);
        let mut s = r.scratch();
        let flat = material(2);
        let target = r.render_toned(&flat, &mut s);
        let mut grad = vec![1.0; flat.len()];
        assert_eq!(r.loss(&flat, &target, &mut s, Some(&mut grad)), 0.0);
        assert!(grad.iter().all(|&g| g == 0.0));
    }
}
