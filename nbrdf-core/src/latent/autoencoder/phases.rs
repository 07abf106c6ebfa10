//! The training phases of the autoencoder. Every epoch runs mini-batches of the examples and
//! the epoch's mixtures ([`mixtures`]) through the same step ([`example_gradient`],
//! [`Optimiser::step`]); what differs is the loss of an example: the squared error of the
//! standardised weights during the weight-space warm start ([`weight_space_loss`]), the
//! image loss afterwards ([`image_loss`]), plus the auxiliary lobe loss ([`lobe_loss`]).
//! Early stopping ([`EarlyStopping`]) watches the validation image loss of the image phase.

use super::data::{LossViews, TrainingData};
use super::{AeConfig, AeEpoch, AutoEncoder, CODE_SIZE};
use crate::latent::mlp::Mlp;
use crate::train::adam::{Adam, AdamConfig};
use crate::train::rng::{SplitMix64, Stream};
use rayon::prelude::*;

/// A standard normal deviate (Box-Muller).
fn gaussian(rng: &mut SplitMix64) -> f32 {
    let (u1, u2) = (rng.next_f64().max(1e-300), rng.next_f64());
    ((-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()) as f32
}

/// The auxiliary lobe loss `weight/2 |head(code) - target|^2` of one example: its value, its
/// gradient in the code (returned) and in the head's parameters (added to `grad_head`).
pub(super) fn lobe_loss(
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

/// The epoch's [`AeConfig::mixup`] examples: (standardised weights, target images). Without
/// `views` (the weight-space warm start, which needs no images) the targets are left empty.
pub(super) fn mixtures(
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

/// The weight-space warm start's loss of an example: the mean squared error of the decoder's
/// output `out` against the standardised input `x`, and its gradient in `out`.
fn weight_space_loss(out: &[f32], x: &[f32]) -> (f64, Vec<f32>) {
    let inv = 1.0 / out.len() as f32;
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
}

/// The image phase's loss of an example: the loss views' image loss of the network decoded
/// from `out` against `target`, and its gradient in `out` (standardised).
fn image_loss(
    ae: &AutoEncoder,
    views: &LossViews,
    out: &[f32],
    target: &[Vec<f32>],
) -> (f64, Vec<f32>) {
    let flat = ae.destandardise(out);
    let mut g = vec![0.0f32; out.len()];
    let loss = views.loss(&flat, target, Some(&mut g));
    let g = g.iter().zip(&ae.std).map(|(g, s)| g * s).collect();
    (loss, g)
}

/// Denoising: the encoder sees the input with Gaussian noise (a regulariser; 72 materials x 6
/// permutations for ~130k parameters), drawn per epoch and example.
fn noisy_input(x: &[f32], config: &AeConfig, epoch: usize, example: usize) -> Vec<f32> {
    if config.input_noise > 0.0 {
        let mut rng = SplitMix64::new(
            config.seed,
            Stream::Latent,
            (4 << 40) | ((epoch as u64) << 20) | example as u64,
        );
        x.iter()
            .map(|v| v + config.input_noise * gaussian(&mut rng))
            .collect()
    } else {
        x.to_vec()
    }
}

/// What one run trains: encoder, decoder and (with the lobe loss) the lobe head, as one
/// parameter vector for Adam.
struct Optimiser {
    lobe_head: Mlp,
    params: Vec<f32>,
    adam: Adam,
    /// Ends of the encoder's and the decoder's parameters in `params`.
    n_enc: usize,
    n_dec: usize,
    use_lobes: bool,
}

impl Optimiser {
    fn new(ae: &AutoEncoder, config: &AeConfig) -> Self {
        let lobe_head = Mlp::new(&[CODE_SIZE, 2], config.seed, 5 << 32);
        let use_lobes = config.lobe_weight > 0.0;
        let n_enc = ae.encoder.parameter_count();
        let n_dec = n_enc + ae.decoder.parameter_count();
        let mut params: Vec<f32> = ae.encoder.to_flat();
        params.extend(ae.decoder.to_flat());
        if use_lobes {
            params.extend(lobe_head.to_flat());
        }
        let adam = Adam::new(
            AdamConfig {
                learning_rate: config.learning_rate,
                ..AdamConfig::default()
            },
            params.len(),
        );
        Optimiser {
            lobe_head,
            params,
            adam,
            n_enc,
            n_dec,
            use_lobes,
        }
    }

    /// Forgets Adam's moments (the weight-space ones are the wrong scale for the image loss).
    fn restart(&mut self) {
        self.adam = Adam::new(self.adam.config, self.params.len());
    }

    /// One Adam step with the mean of the examples' gradients, weight decay and global-norm
    /// clipping; skipped when the gradient is not finite.
    fn step(
        &mut self,
        ae: &mut AutoEncoder,
        gradients: &[(f64, Vec<f32>)],
        config: &AeConfig,
        lr: f32,
    ) {
        let scale = 1.0 / gradients.len() as f32;
        let mut grad = vec![0.0f32; self.params.len()];
        for (_, g) in gradients {
            for (a, b) in grad.iter_mut().zip(g) {
                *a += b * scale;
            }
        }
        if config.weight_decay > 0.0 {
            for (g, p) in grad.iter_mut().zip(&self.params) {
                *g += config.weight_decay * p;
            }
        }
        let norm = grad.iter().map(|g| (g * g) as f64).sum::<f64>().sqrt() as f32;
        if !norm.is_finite() {
            return;
        }
        if norm > config.clip_norm {
            let s = config.clip_norm / norm;
            grad.iter_mut().for_each(|g| *g *= s);
        }
        self.adam.step(&mut self.params, &grad, lr);
        self.load_into(ae, &self.params);
        if self.use_lobes {
            self.lobe_head.set_flat(&self.params[self.n_dec..]);
        }
    }

    /// Sets the encoder's and decoder's weights from a parameter vector.
    fn load_into(&self, ae: &mut AutoEncoder, params: &[f32]) {
        ae.encoder.set_flat(&params[..self.n_enc]);
        ae.decoder.set_flat(&params[self.n_enc..self.n_dec]);
    }
}

/// Per-example inputs of an epoch: the training examples, then the epoch's mixtures.
struct EpochExamples<'a> {
    standardised: &'a [Vec<f32>],
    targets: &'a [Vec<Vec<f32>>],
    lobe_targets: &'a [[f32; 2]],
    mixed: Vec<(Vec<f32>, Vec<Vec<f32>>)>,
}

/// The loss of example `i` of an epoch and its gradient in all parameters of `opt`.
fn example_gradient(
    ae: &AutoEncoder,
    opt: &Optimiser,
    views: &LossViews,
    examples: &EpochExamples<'_>,
    config: &AeConfig,
    (epoch, image_phase): (usize, bool),
    i: usize,
) -> (f64, Vec<f32>) {
    let mut grad = vec![0.0f32; opt.params.len()];
    let trained = examples.standardised.len();
    let (x, target) = match i.checked_sub(trained) {
        Some(m) => (&examples.mixed[m].0, &examples.mixed[m].1),
        None => (&examples.standardised[i], &examples.targets[i]),
    };
    let noisy = noisy_input(x, config, epoch, i);
    let acts_e = ae.encoder.forward(&noisy);
    let code = acts_e.last().cloned().unwrap_or_default();
    let acts_d = ae.decoder.forward(&code);
    let out = acts_d.last().cloned().unwrap_or_default();
    let (mut loss, g_out) = if image_phase {
        image_loss(ae, views, &out, target)
    } else {
        weight_space_loss(&out, x)
    };
    let (ge, rest) = grad.split_at_mut(opt.n_enc);
    let (gd, gh) = rest.split_at_mut(opt.n_dec - opt.n_enc);
    let mut g_code = ae.decoder.backward(&acts_d, &g_out, gd);
    if opt.use_lobes && i < trained {
        let (l, g) = lobe_loss(
            &opt.lobe_head,
            &code,
            &examples.lobe_targets[i],
            config.lobe_weight,
            gh,
        );
        loss += l;
        g_code.iter_mut().zip(&g).for_each(|(a, b)| *a += b);
    }
    ae.encoder.backward(&acts_e, &g_code, ge);
    (loss, grad)
}

/// Keeps the parameters of the epoch with the lowest validation image loss and says when
/// `patience` epochs have passed without a better one.
#[derive(Default)]
struct EarlyStopping {
    best: Option<(f64, Vec<f32>, usize)>,
}

impl EarlyStopping {
    /// Records an epoch; true when training should stop.
    fn update(&mut self, loss: f64, params: &[f32], epoch: usize, patience: usize) -> bool {
        let better = self.best.as_ref().map_or(true, |(b, _, _)| loss < *b);
        if better {
            self.best = Some((loss, params.to_vec(), epoch));
            false
        } else {
            self.best
                .as_ref()
                .is_some_and(|(_, _, e)| epoch - e >= patience)
        }
    }
}

/// Trains `ae` on `data`: the weight-space warm start for `config.warmup_epochs`, then the
/// image phase until early stopping or `config.max_epochs`; the best epoch's weights are kept.
/// Returns the epochs' statistics and the best epoch.
pub(super) fn run(
    ae: &mut AutoEncoder,
    data: &TrainingData,
    views: &LossViews,
    config: &AeConfig,
    progress: &mut dyn FnMut(&AeEpoch),
) -> (Vec<AeEpoch>, Option<usize>) {
    let standardised: Vec<Vec<f32>> = data.flats.iter().map(|f| ae.standardise(f)).collect();
    let lobe_targets = data.lobe_targets();
    let mut opt = Optimiser::new(ae, config);
    let mut order: Vec<usize> = (0..data.flats.len()).collect();
    let mut history = Vec::new();
    let mut stopping = EarlyStopping::default();
    for epoch in 0..config.max_epochs {
        let t0 = std::time::Instant::now();
        let image_phase = epoch >= config.warmup_epochs;
        if epoch == config.warmup_epochs && epoch > 0 {
            opt.restart();
        }
        let lr = if image_phase {
            config.image_learning_rate
        } else {
            config.learning_rate
        };
        SplitMix64::new(config.seed, Stream::Latent, 2 << 32 | epoch as u64).shuffle(&mut order);
        let examples = EpochExamples {
            standardised: &standardised,
            targets: &data.targets,
            lobe_targets: &lobe_targets,
            mixed: mixtures(&data.flats, config, epoch, image_phase.then_some(views), ae),
        };
        let mut epoch_order = order.clone();
        if !examples.mixed.is_empty() {
            epoch_order.extend(data.flats.len()..data.flats.len() + examples.mixed.len());
            SplitMix64::new(config.seed, Stream::Latent, 7 << 40 | epoch as u64)
                .shuffle(&mut epoch_order);
        }
        let mut epoch_loss = 0.0;
        for batch in epoch_order.chunks(config.batch.max(1)) {
            let gradients: Vec<(f64, Vec<f32>)> = batch
                .par_iter()
                .map(|&i| {
                    example_gradient(ae, &opt, views, &examples, config, (epoch, image_phase), i)
                })
                .collect();
            // Summed in example order, one by one: the reported loss is reproducible.
            for (loss, _) in &gradients {
                epoch_loss += loss;
            }
            opt.step(ae, &gradients, config, lr);
        }
        let validation_image_loss = ae.image_loss(views, &data.validation);
        let stats = AeEpoch {
            epoch,
            phase: if image_phase { "image" } else { "weights" },
            train_loss: epoch_loss / epoch_order.len() as f64,
            validation_image_loss,
            seconds: t0.elapsed().as_secs_f64(),
        };
        progress(&stats);
        history.push(stats);
        if (image_phase || config.warmup_epochs >= config.max_epochs)
            && stopping.update(validation_image_loss, &opt.params, epoch, config.patience)
        {
            break;
        }
    }
    let best_epoch = stopping.best.as_ref().map(|b| b.2);
    if let Some((_, p, _)) = &stopping.best {
        opt.load_into(ae, p);
    }
    (history, best_epoch)
}

impl AutoEncoder {
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
