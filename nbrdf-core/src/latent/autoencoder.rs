//! The NBRDF autoencoder (DESIGN.md section 7): flattened networks (675 values at width 21)
//! `-> 32 -> 675`, trained with the image loss of [`super::sphere`].
//!
//! Architecture: encoder `675 -> 96 (tanh) -> 32`, decoder `32 -> 96 (tanh) -> 675`, linear code
//! and output. The decoder has `32*96 + 96 + 96*675 + 675 = 68,571` parameters, about 102
//! NBRDFs (the paper's decoder: ~70k, ~105 NBRDFs). Inputs are standardised per dimension over
//! the (augmented) training set; the decoder's output is de-standardised into network weights.
//!
//! Training: Adam, mini-batches over the training materials times the 6 permutations of the
//! RGB outputs (augmentation) plus fresh weight-space mixtures of two training examples every
//! epoch ([`AeConfig::mixup`]), image loss on the 64 x 64 sphere at 45 degrees. The first
//! `warmup_epochs` minimise the squared error of the standardised weights instead (a warm start
//! that puts the decoded networks near real ones, where the image loss through `exp` is well
//! behaved; the image loss alone from a random decoder gives exploding or dead pixels). Global
//! gradient-norm clipping guards the image phase. Early stopping on the image loss of a
//! validation subset of the training split (identity permutation), keeping the best epoch.
//! Deterministic per seed: per-sample gradients are computed in parallel and summed in sample
//! order.

use super::mlp::Mlp;
use super::sphere::SphereRenderer;
use crate::error::{NbrdfError, Result};
use crate::network::{self, Nbrdf, OUTPUTS};
use crate::train::adam::{Adam, AdamConfig};
use crate::train::rng::{SplitMix64, Stream};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

pub const FORMAT_NAME: &str = "nbrdf-autoencoder";
pub const FORMAT_VERSION: u32 = 1;
pub const CODE_SIZE: usize = 32;
pub const PERMUTATIONS: [[usize; 3]; 6] = [
    [0, 1, 2],
    [0, 2, 1],
    [1, 0, 2],
    [1, 2, 0],
    [2, 0, 1],
    [2, 1, 0],
];

/// A standard normal deviate (Box-Muller).
fn gaussian(rng: &mut SplitMix64) -> f32 {
    let (u1, u2) = (rng.next_f64().max(1e-300), rng.next_f64());
    ((-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()) as f32
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

/// The images of the training loss: the sphere, and optionally the zoom on its highlight.
/// The loss is the sum of the images' losses.
struct LossViews(Vec<SphereRenderer>);

impl LossViews {
    /// The tone-mapped target image of each view.
    fn targets(&self, flat: &[f32]) -> Vec<Vec<f32>> {
        self.0
            .iter()
            .map(|v| v.render_toned(flat, &mut v.scratch()))
            .collect()
    }

    /// Summed loss against `targets`; the summed gradient is written into `grad` if given.
    fn loss(&self, flat: &[f32], targets: &[Vec<f32>], mut grad: Option<&mut [f32]>) -> f64 {
        let mut total = 0.0;
        let mut g_view = vec![0.0f32; flat.len()];
        if let Some(g) = grad.as_deref_mut() {
            g.fill(0.0);
        }
        for (view, target) in self.0.iter().zip(targets) {
            let want_grad = grad.is_some();
            total += view.loss(
                flat,
                target,
                &mut view.scratch(),
                want_grad.then_some(g_view.as_mut_slice()),
            );
            if let Some(g) = grad.as_deref_mut() {
                g.iter_mut().zip(&g_view).for_each(|(a, b)| *a += b);
            }
        }
        total
    }
}

/// The recorded material split.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, Default)]
pub struct Split {
    pub train: Vec<String>,
    pub test: Vec<String>,
    /// The subset of `train` held out of the autoencoder's gradient steps whose image loss
    /// decides early stopping (the predictor trains on all of `train`).
    #[serde(default)]
    pub validation: Vec<String>,
}

impl Split {
    /// The fixed 80/20 split of the project (the same rule as `python/materials.py`, whose
    /// test set the scenes render): in alphabetical order, every fifth material from the third
    /// is a test material. Every tenth training material (from the sixth) is held out for
    /// validation.
    pub fn fixed(names: &[String]) -> Self {
        let mut sorted = names.to_vec();
        sorted.sort();
        sorted.dedup();
        let (mut train, mut test) = (Vec::new(), Vec::new());
        for (i, name) in sorted.into_iter().enumerate() {
            if i % 5 == 2 {
                test.push(name);
            } else {
                train.push(name);
            }
        }
        let mut validation: Vec<String> = train.iter().skip(5).step_by(10).cloned().collect();
        if validation.is_empty() {
            validation.extend(train.first().cloned());
        }
        Split {
            train,
            test,
            validation,
        }
    }
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct AutoEncoder {
    pub format: String,
    pub version: u32,
    /// Hidden width of the NBRDFs it encodes.
    pub nbrdf_hidden: usize,
    pub mean: Vec<f32>,
    pub std: Vec<f32>,
    /// Per-dimension range of the training networks: decoded weights are clamped to it (a
    /// decoded network far outside it can make `exp` overflow to a white sphere).
    #[serde(default)]
    pub min: Vec<f32>,
    #[serde(default)]
    pub max: Vec<f32>,
    pub encoder: Mlp,
    pub decoder: Mlp,
    pub split: Split,
    /// Codes of the training examples (every permutation), recorded after training: further
    /// starting points of [`AutoEncoder::refine_code`]. Empty in files from before.
    #[serde(default)]
    pub anchors: Vec<Vec<f32>>,
    #[serde(default)]
    pub provenance: serde_json::Value,
}

/// Starts screened by a refinement: the encoder's code and the training codes whose spheres
/// are closest to the target's, each given [`SCREEN_ITERATIONS`] iterations.
pub const SCREEN_STARTS: usize = 8;
pub const SCREEN_ITERATIONS: usize = 5;
/// Screened starts that a refinement carries on to its full number of iterations.
pub const REFINE_STARTS: usize = 2;

/// Training settings.
#[derive(Clone, Debug, PartialEq)]
pub struct AeConfig {
    pub seed: u64,
    pub hidden: usize,
    pub max_epochs: usize,
    pub warmup_epochs: usize,
    pub patience: usize,
    pub batch: usize,
    /// Learning rate of the weight-space warm start.
    pub learning_rate: f32,
    /// Learning rate of the image-loss phase.
    pub image_learning_rate: f32,
    pub clip_norm: f32,
    pub augment: bool,
    /// `r0` of the surrogate image gradient (see [`SphereRenderer::loss`]); 0 for the exact one.
    pub surrogate_floor: f32,
    /// Side of the loss's sphere image (64; smaller only for tests).
    pub image_size: usize,
    /// Half width of a second loss image zoomed on the highlight (0: the sphere alone, the
    /// paper's loss). See [`SphereRenderer::highlight`].
    pub highlight_zoom: f32,
    /// Standard deviation of the Gaussian noise added to the standardised encoder input.
    pub input_noise: f32,
    /// L2 penalty gradient `weight_decay * p` added to every parameter's gradient.
    pub weight_decay: f32,
    /// Weight of the auxiliary lobe loss (0: off, the paper's loss alone): a linear head on
    /// the code, trained jointly and then discarded, regresses each training material's fitted
    /// sampling lobe (standardised `ln n` and `w`). The image loss cannot see highlights
    /// sharper than the sphere's pixels, so without it codes need not hold the sharpness that
    /// the Phong predictor must read from them.
    pub lobe_weight: f32,
    /// Extra training examples drawn afresh every epoch: weight-space mixtures
    /// `(1 - t) a + t b` of two random training examples, `t` uniform in [0, 1] (0: none).
    /// The networks share one initialisation, so their hidden units are aligned and mixtures
    /// are plausible materials between the two; they fill the gaps of the decoder's manifold
    /// between the 72 training materials, where held-out materials lie.
    pub mixup: usize,
}

impl Default for AeConfig {
    fn default() -> Self {
        AeConfig {
            seed: 0,
            hidden: 96,
            max_epochs: 600,
            warmup_epochs: 100,
            patience: 40,
            batch: 16,
            learning_rate: 1e-3,
            image_learning_rate: 3e-4,
            clip_norm: 1.0,
            augment: true,
            surrogate_floor: 1e-3,
            input_noise: 0.2,
            weight_decay: 1e-4,
            image_size: super::sphere::SIZE,
            highlight_zoom: 0.0,
            lobe_weight: 0.0,
            // As many mixtures as augmented training examples (80 materials x 6): the one
            // setting measured; it halved the refined test error on the real materials.
            mixup: 480,
        }
    }
}

#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct AeEpoch {
    pub epoch: usize,
    pub phase: &'static str,
    pub train_loss: f64,
    pub validation_image_loss: f64,
    pub seconds: f64,
}

/// The auxiliary lobe loss `weight/2 |head(code) - target|^2` of one example: its value, its
/// gradient in the code (returned) and in the head's parameters (added to `grad_head`).
fn lobe_loss(
    head: &Mlp,
    code: &[f32],
    target: &[f32; 2],
    weight: f32,
    grad_head: &mut [f32],
) -> (f64, Vec<f32>) {
    let acts = head.forward(code);
    let pred = acts.last().cloned().unwrap_or_default();
    let d = [pred[0] - target[0], pred[1] - target[1]];
    let loss = (weight * 0.5 * (d[0] * d[0] + d[1] * d[1])) as f64;
    let g_code = head.backward(&acts, &[weight * d[0], weight * d[1]], grad_head);
    (loss, g_code)
}

/// The flat network of the material `name` in `(name, flat)` pairs (the first, if several).
fn find_network<'a>(materials: &'a [(String, Vec<f32>)], name: &str) -> Result<&'a Vec<f32>> {
    materials
        .iter()
        .find(|(n, _)| n == name)
        .map(|(_, f)| f)
        .ok_or_else(|| NbrdfError::InvalidArgument(format!("no network for '{name}'")))
}

/// The epoch's [`AeConfig::mixup`] examples: (standardised weights, target images). Without
/// `views` (the weight-space warm start, which needs no images) the targets are left empty.
fn mixtures(
    train_flats: &[Vec<f32>],
    config: &AeConfig,
    epoch: usize,
    views: Option<&LossViews>,
    ae: &AutoEncoder,
) -> Vec<(Vec<f32>, Vec<Vec<f32>>)> {
    if train_flats.len() < 2 {
        return Vec::new();
    }
    let mut rng = SplitMix64::new(config.seed, Stream::Latent, (6 << 40) | epoch as u64);
    let picks: Vec<(usize, usize, f32)> = (0..config.mixup)
        .map(|_| {
            let a = rng.below(train_flats.len() as u64) as usize;
            let b = rng.below(train_flats.len() as u64) as usize;
            (a, b, rng.next_f64() as f32)
        })
        .collect();
    picks
        .par_iter()
        .map(|&(a, b, t)| {
            let flat: Vec<f32> = train_flats[a]
                .iter()
                .zip(&train_flats[b])
                .map(|(x, y)| (1.0 - t) * x + t * y)
                .collect();
            let targets = views.map_or_else(Vec::new, |v| v.targets(&flat));
            (ae.standardise(&flat), targets)
        })
        .collect()
}

/// Swaps the RGB outputs of a flat network: output channel `k` becomes input channel `p[k]`.
pub fn permute_outputs(flat: &[f32], hidden: usize, p: [usize; 3]) -> Vec<f32> {
    let mut out = flat.to_vec();
    let w3 = flat.len() - hidden * OUTPUTS - OUTPUTS;
    let b3 = flat.len() - OUTPUTS;
    for i in 0..hidden {
        for k in 0..OUTPUTS {
            out[w3 + i * OUTPUTS + k] = flat[w3 + i * OUTPUTS + p[k]];
        }
    }
    for k in 0..OUTPUTS {
        out[b3 + k] = flat[b3 + p[k]];
    }
    out
}

impl AutoEncoder {
    pub fn code_size(&self) -> usize {
        self.encoder.outputs()
    }

    pub fn load(path: impl AsRef<std::path::Path>) -> Result<Self> {
        let path = path.as_ref();
        Self::checked(super::read_json(path)?, &path.display().to_string())
    }

    /// An autoencoder from the text of an AE.json file (e.g. one embedded in a program);
    /// errors name `origin`.
    pub fn from_json(text: &str, origin: &str) -> Result<Self> {
        Self::checked(super::parse_json(text, origin)?, origin)
    }

    fn checked(ae: AutoEncoder, origin: &str) -> Result<Self> {
        if ae.format != FORMAT_NAME || ae.mean.len() != ae.encoder.inputs() {
            return Err(NbrdfError::InvalidArgument(format!(
                "{origin}: not an NBRDF autoencoder"
            )));
        }
        Ok(ae)
    }

    pub fn save(&self, path: impl AsRef<std::path::Path>) -> Result<()> {
        super::write_json(self, path.as_ref())
    }

    fn standardise(&self, flat: &[f32]) -> Vec<f32> {
        flat.iter()
            .zip(self.mean.iter().zip(&self.std))
            .map(|(x, (m, s))| (x - m) / s)
            .collect()
    }

    /// Standardised weights back to network weights, unclamped (the training's decoded
    /// networks, whose gradient must not vanish at the training range's bounds).
    fn destandardise(&self, standardised: &[f32]) -> Vec<f32> {
        standardised
            .iter()
            .zip(self.mean.iter().zip(&self.std))
            .map(|(y, (m, s))| y * s + m)
            .collect()
    }

    fn check(&self, net: &Nbrdf) -> Result<()> {
        if net.hidden_width() != self.nbrdf_hidden {
            return Err(NbrdfError::InvalidArgument(format!(
                "network '{}' has hidden width {}, the autoencoder takes {}",
                net.name,
                net.hidden_width(),
                self.nbrdf_hidden
            )));
        }
        Ok(())
    }

    pub fn encode_flat(&self, flat: &[f32]) -> Vec<f32> {
        self.encoder.eval(&self.standardise(flat))
    }

    pub fn encode(&self, net: &Nbrdf) -> Result<Vec<f32>> {
        self.check(net)?;
        Ok(self.encode_flat(&net.to_flat()))
    }

    pub fn decode_flat(&self, code: &[f32]) -> Vec<f32> {
        self.destandardise_clamped(&self.decoder.eval(code))
    }

    /// Decoder output to network weights: de-standardised, clamped to the training range.
    fn destandardise_clamped(&self, out: &[f32]) -> Vec<f32> {
        out.iter()
            .zip(self.mean.iter().zip(&self.std))
            .enumerate()
            .map(|(j, (y, (m, s)))| {
                let w = y * s + m;
                match (self.min.get(j), self.max.get(j)) {
                    (Some(&lo), Some(&hi)) => w.clamp(lo, hi),
                    _ => w,
                }
            })
            .collect()
    }

    /// The loss's sphere (64 x 64, light at 45 degrees) for this autoencoder's networks.
    fn sphere(&self) -> SphereRenderer {
        SphereRenderer::new(
            super::sphere::SIZE,
            super::sphere::LIGHT_THETA_DEG.to_radians(),
            self.nbrdf_hidden,
        )
    }

    /// Refines a code by analysis by synthesis: Levenberg-Marquardt on the tone-mapped pixel
    /// residuals of the decoded network's sphere against the input network's own (the image
    /// loss is their mean square), from the encoder's code and from the [`SCREEN_STARTS`]` - 1`
    /// recorded training codes ([`AutoEncoder::anchors`]) whose spheres are closest to the
    /// target: each start gets [`SCREEN_ITERATIONS`] iterations, the [`REFINE_STARTS`] best go
    /// on for the rest, the best result wins. 0 iterations return the encoder's code. This closes the
    /// gap between what the encoder predicts for an unseen material and the best the decoder
    /// can express.
    /// With 32 unknowns the Jacobian costs 32 extra renders (forward differences) and the
    /// damped normal equations are a 32 x 32 solve, so each iteration is a few milliseconds and
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
        scratch: &mut super::sphere::Scratch,
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
        let residual = |z: &[f32], scratch: &mut super::sphere::Scratch| {
            self.residual(renderer, target, z, scratch)
        };
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

    pub fn decode(&self, code: &[f32], name: &str) -> Result<Nbrdf> {
        if code.len() != self.code_size() {
            return Err(NbrdfError::InvalidArgument(format!(
                "a code has {} values, got {}",
                self.code_size(),
                code.len()
            )));
        }
        let mut net = Nbrdf::from_flat(name, self.nbrdf_hidden, &self.decode_flat(code))?;
        net.provenance = serde_json::json!({"decoded_by": FORMAT_NAME});
        Ok(net)
    }

    /// Trains on the named flat networks (all of one hidden width); `split` says which are
    /// used. A name may appear more than once (versions of a material from different sources:
    /// all are training examples; validation uses the first). `lobes` holds the fitted sampling
    /// lobes `(name, n, w)` of the training materials, used only when `config.lobe_weight > 0`.
    /// `progress` is called after every epoch.
    pub fn train(
        materials: &[(String, Vec<f32>)],
        lobes: &[(String, f64, f64)],
        hidden_nbrdf: usize,
        split: Split,
        config: &AeConfig,
        mut progress: impl FnMut(&AeEpoch),
    ) -> Result<(AutoEncoder, Vec<AeEpoch>)> {
        let start = std::time::Instant::now();
        let find = |name: &String| find_network(materials, name);
        let perms: &[[usize; 3]] = if config.augment {
            &PERMUTATIONS
        } else {
            &PERMUTATIONS[..1]
        };
        let theta = super::sphere::LIGHT_THETA_DEG.to_radians();
        let mut views = vec![SphereRenderer::new(config.image_size, theta, hidden_nbrdf)];
        if config.highlight_zoom > 0.0 {
            views.push(SphereRenderer::highlight(
                config.image_size,
                theta,
                hidden_nbrdf,
                config.highlight_zoom,
            ));
        }
        views
            .iter_mut()
            .for_each(|v| v.surrogate_floor = config.surrogate_floor);
        let views = LossViews(views);
        // Training samples: (flat weights, target tone-mapped image, lobe label).
        let mut train_flats = Vec::new();
        let mut train_lobes: Vec<[f32; 2]> = Vec::new();
        let use_lobes = config.lobe_weight > 0.0;
        let fitted: Vec<&String> = if split.validation.len() < split.train.len() {
            split
                .train
                .iter()
                .filter(|n| !split.validation.contains(n))
                .collect()
        } else {
            // Too few materials to hold any out (tests): validate on the training set.
            split.train.iter().collect()
        };
        for name in fitted {
            // Every network of the material (`materials` may hold several versions of one).
            find(name)?;
            // The lobe is fitted to the mean over RGB, so it labels every permutation.
            let lobe = match lobes.iter().find(|(n, _, _)| n == name) {
                Some(&(_, n, w)) if n.is_finite() && w.is_finite() => {
                    [n.max(1e-3).ln() as f32, w as f32]
                }
                _ if use_lobes => {
                    return Err(NbrdfError::InvalidArgument(format!(
                        "the lobe loss needs the fitted sampling lobe of '{name}'"
                    )))
                }
                _ => [0.0; 2],
            };
            for (_, flat) in materials.iter().filter(|(n, _)| n == name) {
                for &p in perms {
                    train_flats.push(permute_outputs(flat, hidden_nbrdf, p));
                    train_lobes.push(lobe);
                }
            }
        }
        if train_flats.is_empty() {
            return Err(NbrdfError::InvalidArgument("no training materials".into()));
        }
        let dims = train_flats[0].len();
        let (mean, std) = super::column_mean_std(&train_flats, 1e-4);
        let targets: Vec<Vec<Vec<f32>>> =
            train_flats.par_iter().map(|f| views.targets(f)).collect();
        let validation: Vec<(Vec<f32>, Vec<Vec<f32>>)> = split
            .validation
            .iter()
            .map(|name| {
                let f = find(name)?.clone();
                let t = views.targets(&f);
                Ok((f, t))
            })
            .collect::<Result<_>>()?;

        let mut ae = AutoEncoder {
            format: FORMAT_NAME.into(),
            version: FORMAT_VERSION,
            nbrdf_hidden: hidden_nbrdf,
            min: (0..dims)
                .map(|d| {
                    train_flats
                        .iter()
                        .map(|f| f[d])
                        .fold(f32::INFINITY, f32::min)
                })
                .collect(),
            max: (0..dims)
                .map(|d| {
                    train_flats
                        .iter()
                        .map(|f| f[d])
                        .fold(f32::NEG_INFINITY, f32::max)
                })
                .collect(),
            mean,
            std,
            encoder: Mlp::new(&[dims, config.hidden, CODE_SIZE], config.seed, 0),
            decoder: Mlp::new(&[CODE_SIZE, config.hidden, dims], config.seed, 1 << 32),
            split,
            anchors: Vec::new(),
            provenance: serde_json::Value::Null,
        };
        let standardised: Vec<Vec<f32>> = train_flats.iter().map(|f| ae.standardise(f)).collect();
        // The lobe head's targets: ln n and w standardised over the training examples.
        let lobe_targets: Vec<[f32; 2]> = {
            let (m, s) = super::column_mean_std(&train_lobes, 1e-3);
            train_lobes
                .iter()
                .map(|l| [(l[0] - m[0]) / s[0], (l[1] - m[1]) / s[1]])
                .collect()
        };
        let mut lobe_head = Mlp::new(&[CODE_SIZE, 2], config.seed, 5 << 32);
        let n_enc = ae.encoder.parameter_count();
        let n_dec = n_enc + ae.decoder.parameter_count();
        let mut params: Vec<f32> = ae.encoder.to_flat();
        params.extend(ae.decoder.to_flat());
        if use_lobes {
            params.extend(lobe_head.to_flat());
        }
        let n_all = params.len();
        let mut adam = Adam::new(
            AdamConfig {
                learning_rate: config.learning_rate,
                ..AdamConfig::default()
            },
            n_all,
        );
        let mut order: Vec<usize> = (0..train_flats.len()).collect();
        let mut history = Vec::new();
        let mut best: Option<(f64, Vec<f32>, usize)> = None;
        for epoch in 0..config.max_epochs {
            let t0 = std::time::Instant::now();
            let image_phase = epoch >= config.warmup_epochs;
            if epoch == config.warmup_epochs && epoch > 0 {
                // The weight-space moments are the wrong scale for the image loss: start afresh.
                adam = Adam::new(adam.config, n_all);
            }
            let lr = if image_phase {
                config.image_learning_rate
            } else {
                config.learning_rate
            };
            SplitMix64::new(config.seed, Stream::Latent, 2 << 32 | epoch as u64)
                .shuffle(&mut order);
            let mixed = mixtures(
                &train_flats,
                config,
                epoch,
                image_phase.then_some(&views),
                &ae,
            );
            let mut epoch_order = order.clone();
            if !mixed.is_empty() {
                epoch_order.extend(train_flats.len()..train_flats.len() + mixed.len());
                SplitMix64::new(config.seed, Stream::Latent, 7 << 40 | epoch as u64)
                    .shuffle(&mut epoch_order);
            }
            let mut epoch_loss = 0.0;
            for batch in epoch_order.chunks(config.batch.max(1)) {
                let results: Vec<(f64, Vec<f32>)> = batch
                    .par_iter()
                    .map(|&i| {
                        let mut grad = vec![0.0f32; n_all];
                        let (x, target) = match i.checked_sub(train_flats.len()) {
                            Some(m) => (&mixed[m].0, &mixed[m].1),
                            None => (&standardised[i], &targets[i]),
                        };
                        // Denoising: the encoder sees the input with Gaussian noise (a
                        // regulariser; 72 materials x 6 permutations for ~130k parameters).
                        let noisy: Vec<f32> = if config.input_noise > 0.0 {
                            let mut rng = SplitMix64::new(
                                config.seed,
                                Stream::Latent,
                                (4 << 40) | ((epoch as u64) << 20) | i as u64,
                            );
                            x.iter()
                                .map(|v| v + config.input_noise * gaussian(&mut rng))
                                .collect()
                        } else {
                            x.clone()
                        };
                        let acts_e = ae.encoder.forward(&noisy);
                        let code = acts_e.last().cloned().unwrap_or_default();
                        let acts_d = ae.decoder.forward(&code);
                        let out = acts_d.last().cloned().unwrap_or_default();
                        let (loss, g_out) = if image_phase {
                            let flat = ae.destandardise(&out);
                            let mut g = vec![0.0f32; dims];
                            let loss = views.loss(&flat, target, Some(&mut g));
                            let g: Vec<f32> = g.iter().zip(&ae.std).map(|(g, s)| g * s).collect();
                            (loss, g)
                        } else {
                            let inv = 1.0 / dims as f32;
                            let loss = out
                                .iter()
                                .zip(x)
                                .map(|(y, x)| ((y - x) * (y - x)) as f64)
                                .sum::<f64>()
                                * inv as f64;
                            let g = out
                                .iter()
                                .zip(x)
                                .map(|(y, x)| 2.0 * (y - x) * inv)
                                .collect();
                            (loss, g)
                        };
                        let (ge, rest) = grad.split_at_mut(n_enc);
                        let (gd, gh) = rest.split_at_mut(n_dec - n_enc);
                        let mut g_code = ae.decoder.backward(&acts_d, &g_out, gd);
                        let mut loss = loss;
                        if use_lobes && i < train_flats.len() {
                            let (l, g) = lobe_loss(
                                &lobe_head,
                                &code,
                                &lobe_targets[i],
                                config.lobe_weight,
                                gh,
                            );
                            loss += l;
                            g_code.iter_mut().zip(&g).for_each(|(a, b)| *a += b);
                        }
                        ae.encoder.backward(&acts_e, &g_code, ge);
                        (loss, grad)
                    })
                    .collect();
                let scale = 1.0 / batch.len() as f32;
                let mut grad = vec![0.0f32; n_all];
                for (loss, g) in &results {
                    epoch_loss += loss;
                    for (a, b) in grad.iter_mut().zip(g) {
                        *a += b * scale;
                    }
                }
                if config.weight_decay > 0.0 {
                    for (g, p) in grad.iter_mut().zip(&params) {
                        *g += config.weight_decay * p;
                    }
                }
                let norm = grad.iter().map(|g| (g * g) as f64).sum::<f64>().sqrt() as f32;
                if !norm.is_finite() {
                    continue;
                }
                if norm > config.clip_norm {
                    let s = config.clip_norm / norm;
                    grad.iter_mut().for_each(|g| *g *= s);
                }
                adam.step(&mut params, &grad, lr);
                ae.encoder.set_flat(&params[..n_enc]);
                ae.decoder.set_flat(&params[n_enc..n_dec]);
                if use_lobes {
                    lobe_head.set_flat(&params[n_dec..]);
                }
            }
            let validation_image_loss = ae.image_loss(&views, &validation);
            let stats = AeEpoch {
                epoch,
                phase: if image_phase { "image" } else { "weights" },
                train_loss: epoch_loss / epoch_order.len() as f64,
                validation_image_loss,
                seconds: t0.elapsed().as_secs_f64(),
            };
            progress(&stats);
            history.push(stats);
            if image_phase || config.warmup_epochs >= config.max_epochs {
                let better = best
                    .as_ref()
                    .map_or(true, |(b, _, _)| validation_image_loss < *b);
                if better {
                    best = Some((validation_image_loss, params.clone(), epoch));
                } else if best
                    .as_ref()
                    .is_some_and(|(_, _, e)| epoch - e >= config.patience)
                {
                    break;
                }
            }
        }
        let best_epoch = best.as_ref().map(|b| b.2);
        if let Some((_, p, _)) = best {
            ae.encoder.set_flat(&p[..n_enc]);
            ae.decoder.set_flat(&p[n_enc..n_dec]);
        }
        ae.anchors = train_flats.par_iter().map(|f| ae.encode_flat(f)).collect();
        ae.provenance = serde_json::json!({
            "architecture": format!("{dims}-{h}-{CODE_SIZE}-{h}-{dims}, tanh hidden, linear code and output", h = config.hidden),
            "decoder_parameters": ae.decoder.parameter_count(),
            "encoder_parameters": ae.encoder.parameter_count(),
            "seed": config.seed,
            "epochs": history.len(),
            "best_epoch": best_epoch,
            "warmup_epochs": config.warmup_epochs,
            "batch": config.batch,
            "learning_rate": config.learning_rate,
            "image_learning_rate": config.image_learning_rate,
            "surrogate_floor": config.surrogate_floor,
            "input_noise": config.input_noise,
            "weight_decay": config.weight_decay,
            "augmentation": if config.augment { "6 RGB permutations" } else { "none" },
            "loss": format!("pixel MSE of max(x,1e-12)^(1/2.2), {s}x{s} sphere, light at 45 degrees", s = config.image_size),
            "highlight_zoom": config.highlight_zoom,
            "lobe_weight": config.lobe_weight,
            "mixup": config.mixup,
            "seconds": start.elapsed().as_secs_f64(),
            "threads": rayon::current_num_threads(),
        });
        Ok((ae, history))
    }

    /// Mean image loss of reconstructing `(flat, target image)` pairs.
    fn image_loss(&self, views: &LossViews, set: &[(Vec<f32>, Vec<Vec<f32>>)]) -> f64 {
        if set.is_empty() {
            return f64::NAN;
        }
        set.par_iter()
            .map(|(f, t)| {
                let rec = self.decode_flat(&self.encode_flat(f));
                views.loss(&rec, t, None)
            })
            .collect::<Vec<_>>()
            .iter()
            .sum::<f64>()
            / set.len() as f64
    }
}

/// The default NBRDF width the CLI expects.
pub const NBRDF_HIDDEN: usize = network::DEFAULT_HIDDEN;

#[cfg(test)]
mod tests {
    use super::*;

    fn material(seed: u64, bias: [f32; 3]) -> Vec<f32> {
        let mut net = Nbrdf::random("m", 21, seed);
        for l in &mut net.layers {
            l.weights.iter_mut().for_each(|v| *v *= 10.0);
        }
        net.layers[2].bias = bias.to_vec();
        net.to_flat()
    }

    /// Two visible materials, both trained on and validated on.
    fn two_materials() -> (Vec<(String, Vec<f32>)>, Split) {
        let mats = vec![
            ("a".to_string(), material(1, [0.5, 0.2, -0.3])),
            ("b".to_string(), material(2, [-0.4, 0.1, 0.6])),
        ];
        let split = Split {
            train: vec!["a".into(), "b".into()],
            test: vec![],
            validation: vec!["a".into(), "b".into()],
        };
        (mats, split)
    }

    #[test]
    fn lobe_loss_gradients_match_finite_differences() {
        let head = Mlp::new(&[CODE_SIZE, 2], 3, 5 << 32);
        let code: Vec<f32> = (0..CODE_SIZE).map(|k| (k as f32 * 0.37).sin()).collect();
        let target = [0.8f32, -1.3];
        let mut g_head = vec![0.0f32; head.parameter_count()];
        let (loss, g_code) = lobe_loss(&head, &code, &target, 0.7, &mut g_head);
        let eps = 1e-2f32;
        let f = |h: &Mlp, c: &[f32]| {
            lobe_loss(h, c, &target, 0.7, &mut vec![0.0; h.parameter_count()]).0
        };
        assert!((f(&head, &code) - loss).abs() < 1e-12);
        for k in [0, 7, 31] {
            let (mut up, mut down) = (code.clone(), code.clone());
            up[k] += eps;
            down[k] -= eps;
            let fd = (f(&head, &up) - f(&head, &down)) / (2.0 * eps as f64);
            assert!(
                (fd - g_code[k] as f64).abs() < 1e-3 * (1.0 + fd.abs()),
                "code {k}: {fd} vs {}",
                g_code[k]
            );
        }
        let flat = head.to_flat();
        for k in [0, 5, 40, 64, 65] {
            let (mut up, mut down) = (head.clone(), head.clone());
            let mut p = flat.clone();
            p[k] += eps;
            up.set_flat(&p);
            p[k] -= 2.0 * eps;
            down.set_flat(&p);
            let fd = (f(&up, &code) - f(&down, &code)) / (2.0 * eps as f64);
            assert!(
                (fd - g_head[k] as f64).abs() < 1e-3 * (1.0 + fd.abs()),
                "param {k}: {fd} vs {}",
                g_head[k]
            );
        }
    }

    #[test]
    fn lobe_loss_needs_every_training_lobe_and_is_off_at_weight_zero() {
        let (mats, split) = two_materials();
        let config = AeConfig {
            hidden: 8,
            max_epochs: 6,
            warmup_epochs: 3,
            batch: 2,
            augment: false,
            image_size: 16,
            lobe_weight: 1.0,
            mixup: 0,
            ..AeConfig::default()
        };
        let only_a = [("a".to_string(), 30.0, 0.5)];
        let err = AutoEncoder::train(&mats, &only_a, 21, split.clone(), &config, |_| {})
            .unwrap_err()
            .to_string();
        assert!(err.contains("'b'"), "{err}");
        let both = [("a".to_string(), 30.0, 0.5), ("b".to_string(), 3000.0, 0.9)];
        let (with, _) =
            AutoEncoder::train(&mats, &both, 21, split.clone(), &config, |_| {}).unwrap();
        let off = AeConfig {
            lobe_weight: 0.0,
            ..config
        };
        let (plain, _) = AutoEncoder::train(&mats, &[], 21, split.clone(), &off, |_| {}).unwrap();
        let (labelled_off, _) = AutoEncoder::train(&mats, &both, 21, split, &off, |_| {}).unwrap();
        // Weight 0 is the paper's loss exactly, labels or not; the lobe term changes training.
        assert_eq!(plain.encoder, labelled_off.encoder);
        assert_ne!(plain.encoder, with.encoder);
    }

    #[test]
    fn permutation_swaps_the_rendered_channels() {
        let r = SphereRenderer::new(8, 45f64.to_radians(), 21);
        let f = material(1, [0.5, 0.0, -0.5]);
        let p = [2, 0, 1];
        let (a, b) = (
            r.render(&f, &mut r.scratch()),
            r.render(&permute_outputs(&f, 21, p), &mut r.scratch()),
        );
        for k in 0..3 {
            assert_eq!(&b[k * 64..(k + 1) * 64], &a[p[k] * 64..(p[k] + 1) * 64]);
        }
    }

    #[test]
    fn tiny_autoencoder_overfits_two_materials() {
        let (mats, split) = two_materials();
        let config = AeConfig {
            hidden: 8,
            max_epochs: 250,
            warmup_epochs: 120,
            patience: 1000,
            batch: 2,
            learning_rate: 3e-3,
            augment: false,
            input_noise: 0.0,
            weight_decay: 0.0,
            image_size: 16,
            mixup: 0,
            ..AeConfig::default()
        };
        let (ae, history) = AutoEncoder::train(&mats, &[], 21, split, &config, |_| {}).unwrap();
        let first_image = history.iter().find(|e| e.phase == "image").unwrap();
        let last = history.last().unwrap();
        assert!(
            last.validation_image_loss < 1e-4,
            "final image loss {} (first image epoch {})",
            last.validation_image_loss,
            first_image.validation_image_loss
        );
        // Codes decode to valid networks and are deterministic.
        let code = ae.encode_flat(&mats[0].1);
        assert_eq!(code.len(), CODE_SIZE);
        ae.decode(&code, "a").unwrap();
        let (ae2, _) =
            AutoEncoder::train(&mats, &[], 21, ae.split.clone(), &config, |_| {}).unwrap();
        assert_eq!(ae.decoder, ae2.decoder);
    }

    #[test]
    fn mixup_examples_lie_between_two_training_networks_and_target_their_own_sphere() {
        let (mats, _) = two_materials();
        let (ae, _) = small_autoencoder(2, 1);
        let flats: Vec<Vec<f32>> = mats.iter().map(|m| m.1.clone()).collect();
        let config = AeConfig {
            mixup: 12,
            image_size: 16,
            ..AeConfig::default()
        };
        let theta = super::super::sphere::LIGHT_THETA_DEG.to_radians();
        let views = LossViews(vec![SphereRenderer::new(16, theta, 21)]);
        let mixed = mixtures(&flats, &config, 3, Some(&views), &ae);
        assert_eq!(mixed.len(), 12);
        let (a, b) = (&flats[0], &flats[1]);
        let mut strictly_between = 0;
        for (standardised, targets) in &mixed {
            let flat = ae.destandardise(standardised);
            // Each mixture is a, b, or (1 - t) a + t b with one t for every weight.
            let candidates = [(a, a), (b, b), (a, b), (b, a)];
            let on_segment = candidates.iter().any(|(p, q)| {
                let (k, d) = (0..flat.len())
                    .map(|k| (k, q[k] - p[k]))
                    .max_by(|x, y| x.1.abs().total_cmp(&y.1.abs()))
                    .unwrap();
                let t = if d.abs() < 1e-6 {
                    0.0
                } else {
                    (flat[k] - p[k]) / d
                };
                (-1e-4..=1.0 + 1e-4).contains(&t)
                    && flat
                        .iter()
                        .zip(p.iter().zip(q.iter()))
                        .all(|(f, (p, q))| (f - ((1.0 - t) * p + t * q)).abs() < 1e-3)
            });
            assert!(on_segment, "a mixture off the segment between the networks");
            if flat.iter().zip(a).any(|(f, x)| (f - x).abs() > 1e-3)
                && flat.iter().zip(b).any(|(f, y)| (f - y).abs() > 1e-3)
            {
                strictly_between += 1;
            }
            let want = views.targets(&flat);
            let err = targets[0]
                .iter()
                .zip(&want[0])
                .map(|(x, y)| (x - y).abs())
                .fold(0.0f32, f32::max);
            assert!(err < 1e-3, "target off the mixture's own sphere by {err}");
        }
        assert!(strictly_between > 0, "no mixture strictly between a and b");
        // Deterministic per epoch, fresh between epochs.
        let again = mixtures(&flats, &config, 3, Some(&views), &ae);
        assert_eq!(mixed, again);
        assert_ne!(mixed, mixtures(&flats, &config, 4, Some(&views), &ae));
    }

    /// A small autoencoder of the two-material fixture after `epochs` epochs, `warmup` of
    /// them in weight space.
    fn small_autoencoder(epochs: usize, warmup: usize) -> (AutoEncoder, Vec<(String, Vec<f32>)>) {
        let (mats, split) = two_materials();
        let config = AeConfig {
            hidden: 8,
            max_epochs: epochs,
            warmup_epochs: warmup,
            batch: 2,
            augment: false,
            input_noise: 0.0,
            image_size: 16,
            mixup: 0,
            ..AeConfig::default()
        };
        let (ae, _) = AutoEncoder::train(&mats, &[], 21, split, &config, |_| {}).unwrap();
        (ae, mats)
    }

    /// The image loss of a code's decoded network against the sphere of `flat`.
    fn code_loss(ae: &AutoEncoder, flat: &[f32], code: &[f32]) -> f64 {
        let r = SphereRenderer::standard();
        let mut s = r.scratch();
        let target = r.render_toned(flat, &mut s);
        r.loss(&ae.decode_flat(code), &target, &mut s, None)
    }

    #[test]
    fn refining_a_code_lowers_the_image_loss_and_zero_steps_keep_it() {
        // A barely trained autoencoder: its codes are poor, so refinement has work to do.
        let (ae, mats) = small_autoencoder(4, 3);
        let flat = &mats[1].1;
        let code = ae.encode_flat(flat);
        let loss = |c: &[f32]| code_loss(&ae, flat, c);
        assert_eq!(ae.refine_code(flat, &code, 0), code);
        let refined = ae.refine_code(flat, &code, 10);
        let (before, after) = (loss(&code), loss(&refined));
        assert!(
            after < 0.7 * before,
            "refined loss {after} vs encoder's {before}"
        );
    }

    #[test]
    fn refined_validation_loss_is_the_mean_loss_of_the_validation_materials() {
        let (ae, mats) = small_autoencoder(4, 3);
        assert!(!ae.split.validation.is_empty());
        let flat_of = |name: &String| find_network(&mats, name).unwrap();
        let encoder_only: f64 = ae
            .split
            .validation
            .iter()
            .map(|n| code_loss(&ae, flat_of(n), &ae.encode_flat(flat_of(n))))
            .sum::<f64>()
            / ae.split.validation.len() as f64;
        let at_zero = ae.refined_validation_loss(&mats, 0).unwrap();
        assert!((at_zero - encoder_only).abs() <= 1e-9 * encoder_only.max(1e-30));
        let refined = ae.refined_validation_loss(&mats, 10).unwrap();
        assert!(refined < 0.7 * at_zero, "{refined} vs {at_zero}");
        let missing: Vec<(String, Vec<f32>)> = Vec::new();
        assert!(ae.refined_validation_loss(&missing, 1).is_err());
    }

    #[test]
    fn refinement_also_starts_from_the_closest_training_codes() {
        let (ae, mats) = small_autoencoder(40, 30);
        // One anchor per training example, each the encoder's code of that example.
        assert_eq!(ae.anchors.len(), 2);
        assert_eq!(ae.anchors[1], ae.encode_flat(&mats[1].1));
        let flat = &mats[1].1;
        let loss = |c: &[f32]| code_loss(&ae, flat, c);
        // A start far off the manifold: alone it stays poor, the anchors rescue it.
        let far: Vec<f32> = ae.anchors[1].iter().map(|v| v + 40.0).collect();
        let mut alone = ae.clone();
        alone.anchors.clear();
        let (single, multi) = (
            loss(&alone.refine_code(flat, &far, 3)),
            loss(&ae.refine_code(flat, &far, 3)),
        );
        let at_anchor = loss(&ae.anchors[1]);
        assert!(multi <= at_anchor, "{multi} vs the anchor's {at_anchor}");
        assert!(
            multi < 0.5 * single,
            "multi-start {multi} vs single start {single}"
        );
    }

    #[test]
    fn fixed_split_is_80_20_and_stable() {
        let names: Vec<String> = (0..100).map(|i| format!("m{i:03}")).collect();
        let s = Split::fixed(&names);
        assert_eq!(
            (s.train.len(), s.test.len(), s.validation.len()),
            (80, 20, 8)
        );
        assert!(s.validation.iter().all(|v| s.train.contains(v)));
        let mut rev = names.clone();
        rev.reverse();
        assert_eq!(Split::fixed(&rev), s);
        // python/materials.py's rule: sorted(names)[2::5].
        let expected: Vec<String> = names.iter().skip(2).step_by(5).cloned().collect();
        assert_eq!(s.test, expected);
        assert!(s.test.iter().all(|t| !s.train.contains(t)));
    }
}
