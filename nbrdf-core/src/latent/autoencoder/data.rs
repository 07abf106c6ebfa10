//! The training data of the autoencoder: the examples (each training material's networks
//! under the RGB permutations, with their lobe labels), their target images, the validation
//! set, and the untrained autoencoder standardised over the examples.

use super::permute_outputs;
use super::{AeConfig, AutoEncoder, Split, CODE_SIZE, FORMAT_NAME, FORMAT_VERSION, PERMUTATIONS};
use crate::error::{NbrdfError, Result};
use crate::latent::mlp::Mlp;
use crate::latent::sphere::{SphereRenderer, LIGHT_THETA_DEG};
use rayon::prelude::*;

/// The images of the training loss: the sphere, and optionally the zoom on its highlight.
/// The loss is the sum of the images' losses.
pub(super) struct LossViews(pub(super) Vec<SphereRenderer>);

impl LossViews {
    /// The tone-mapped target image of each view.
    pub(super) fn targets(&self, flat: &[f32]) -> Vec<Vec<f32>> {
        self.0
            .iter()
            .map(|v| v.render_toned(flat, &mut v.scratch()))
            .collect()
    }

    /// Summed loss against `targets`; the summed gradient is written into `grad` if given.
    pub(super) fn loss(
        &self,
        flat: &[f32],
        targets: &[Vec<f32>],
        mut grad: Option<&mut [f32]>,
    ) -> f64 {
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

impl LossViews {
    /// The sphere of the loss, and the zoom on its highlight if `config.highlight_zoom > 0`.
    pub(super) fn new(config: &AeConfig, hidden_nbrdf: usize) -> Self {
        let theta = LIGHT_THETA_DEG.to_radians();
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
        LossViews(views)
    }
}

/// The flat network of the material `name` in `(name, flat)` pairs (the first, if several).
pub(super) fn find_network<'a>(
    materials: &'a [(String, Vec<f32>)],
    name: &str,
) -> Result<&'a Vec<f32>> {
    materials
        .iter()
        .find(|(n, _)| n == name)
        .map(|(_, f)| f)
        .ok_or_else(|| NbrdfError::InvalidArgument(format!("no network for '{name}'")))
}

/// The examples of one training run.
pub(super) struct TrainingData {
    /// Flat networks: every network of each fitted training material under each permutation.
    pub flats: Vec<Vec<f32>>,
    /// The lobe label `[ln n, w]` of each example (zeros without the lobe loss).
    pub lobes: Vec<[f32; 2]>,
    /// The tone-mapped target images of each example, one per loss view.
    pub targets: Vec<Vec<Vec<f32>>>,
    /// `(flat, target images)` of each validation material (identity permutation).
    pub validation: Vec<(Vec<f32>, Vec<Vec<f32>>)>,
}

impl TrainingData {
    /// The examples of `split`'s training materials less its validation ones (all of them if
    /// that would leave none). `lobes` holds `(name, n, w)`; the lobe loss
    /// (`config.lobe_weight > 0`) needs one for every fitted material.
    pub(super) fn prepare(
        materials: &[(String, Vec<f32>)],
        lobes: &[(String, f64, f64)],
        hidden_nbrdf: usize,
        split: &Split,
        config: &AeConfig,
        views: &LossViews,
    ) -> Result<Self> {
        let find = |name: &String| find_network(materials, name);
        let perms: &[[usize; 3]] = if config.augment {
            &PERMUTATIONS
        } else {
            &PERMUTATIONS[..1]
        };
        let mut flats = Vec::new();
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
                    flats.push(permute_outputs(flat, hidden_nbrdf, p));
                    train_lobes.push(lobe);
                }
            }
        }
        if flats.is_empty() {
            return Err(NbrdfError::InvalidArgument("no training materials".into()));
        }
        let targets = flats.par_iter().map(|f| views.targets(f)).collect();
        let validation = split
            .validation
            .iter()
            .map(|name| {
                let f = find(name)?.clone();
                let t = views.targets(&f);
                Ok((f, t))
            })
            .collect::<Result<_>>()?;
        Ok(TrainingData {
            flats,
            lobes: train_lobes,
            targets,
            validation,
        })
    }

    /// Values of a flat network.
    pub(super) fn dims(&self) -> usize {
        self.flats[0].len()
    }

    /// The untrained autoencoder: standardisation and clamp range over the examples, encoder and
    /// decoder initialised from `config.seed`.
    pub(super) fn initial_autoencoder(
        &self,
        hidden_nbrdf: usize,
        split: Split,
        config: &AeConfig,
    ) -> AutoEncoder {
        let dims = self.dims();
        let (mean, std) = crate::latent::column_mean_std(&self.flats, 1e-4);
        let column = |d: usize| self.flats.iter().map(move |f| f[d]);
        AutoEncoder {
            format: FORMAT_NAME.into(),
            version: FORMAT_VERSION,
            nbrdf_hidden: hidden_nbrdf,
            min: (0..dims)
                .map(|d| column(d).fold(f32::INFINITY, f32::min))
                .collect(),
            max: (0..dims)
                .map(|d| column(d).fold(f32::NEG_INFINITY, f32::max))
                .collect(),
            mean,
            std,
            encoder: Mlp::new(&[dims, config.hidden, CODE_SIZE], config.seed, 0),
            decoder: Mlp::new(&[CODE_SIZE, config.hidden, dims], config.seed, 1 << 32),
            split,
            anchors: Vec::new(),
            provenance: serde_json::Value::Null,
        }
    }

    /// The lobe head's targets: `ln n` and `w` standardised over the examples.
    pub(super) fn lobe_targets(&self) -> Vec<[f32; 2]> {
        let (m, s) = crate::latent::column_mean_std(&self.lobes, 1e-3);
        self.lobes
            .iter()
            .map(|l| [(l[0] - m[0]) / s[0], (l[1] - m[1]) / s[1]])
            .collect()
    }
}
