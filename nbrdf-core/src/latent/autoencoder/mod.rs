//! The NBRDF autoencoder (docs/design.md section 7): flattened networks `-> 32 -> ` flattened
//! networks, encoder `675 -> 96 (tanh) -> 32`, decoder `32 -> 96 (tanh) -> 675` (width 21),
//! linear code and output, inputs standardised per dimension over the augmented training set.
//!
//! Training: Adam on mini-batches of the training materials times the 6 RGB permutations plus
//! weight-space mixtures ([`AeConfig::mixup`]). The first `warmup_epochs` minimise the squared
//! error of the standardised weights, a warm start near real networks, where the image loss of
//! [`super::sphere`] through `exp` is well behaved (from a random decoder it gives exploding or
//! dead pixels); then the image loss with gradient-norm clipping and early stopping on a
//! validation subset. Deterministic per seed (per-sample gradients summed in sample order).
//!
//! Here: the model, its file and its use; `data`: examples, augmentation, target images, the
//! initial autoencoder; `phases`: warm start, image phase, mixup, early stopping; `refine`: code
//! refinement and the refined validation loss.

mod data;
mod phases;
mod refine;
#[cfg(test)]
mod tests;

use super::mlp::Mlp;
use super::sphere::SphereRenderer;
use crate::error::{NbrdfError, Result};
use crate::network::{self, Nbrdf, OUTPUTS};
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
            // As many mixtures as augmented training examples (80 materials x 6), the setting
            // docs/results/latent.md measured.
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
        super::require_isotropic(net)?;
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
        let views = data::LossViews::new(config, hidden_nbrdf);
        let data =
            data::TrainingData::prepare(materials, lobes, hidden_nbrdf, &split, config, &views)?;
        let mut ae = data.initial_autoencoder(hidden_nbrdf, split, config);
        let (history, best_epoch) = phases::run(&mut ae, &data, &views, config, &mut progress);
        ae.anchors = data.flats.par_iter().map(|f| ae.encode_flat(f)).collect();
        ae.provenance = provenance(&ae, config, data.dims(), history.len(), best_epoch);
        if let Some(p) = ae.provenance.as_object_mut() {
            p.insert("seconds".into(), start.elapsed().as_secs_f64().into());
        }
        Ok((ae, history))
    }
}

/// The settings and outcome of a training run, for the autoencoder file.
fn provenance(
    ae: &AutoEncoder,
    config: &AeConfig,
    dims: usize,
    epochs: usize,
    best_epoch: Option<usize>,
) -> serde_json::Value {
    serde_json::json!({
        "architecture": format!("{dims}-{h}-{CODE_SIZE}-{h}-{dims}, tanh hidden, linear code and output", h = config.hidden),
        "decoder_parameters": ae.decoder.parameter_count(),
        "encoder_parameters": ae.encoder.parameter_count(),
        "seed": config.seed,
        "epochs": epochs,
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
        "threads": rayon::current_num_threads(),
    })
}

/// The default NBRDF width the CLI expects.
pub const NBRDF_HIDDEN: usize = network::DEFAULT_HIDDEN;
