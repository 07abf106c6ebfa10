//! The training run: settings ([`TexturedTrainConfig`]), the split into training and validation
//! samples, epochs of shuffled mini-batches with the homogeneous trainer's Adam and learning-rate
//! schedule, and the best weights on the validation samples kept ([`TexturedModel`]).

use super::joint::{JointTrainer, JointWeights};
use super::samples::{Rows, TexturedSamples};
use crate::error::{NbrdfError, Result};
use crate::network::{glorot_uniform, Layer, Spectral, INPUTS};
use crate::rng::{SplitMix64, Stream};
use crate::spectral_basis::SpectralBasis;
use crate::textured::{Decoder, MAX_DECODER_LAYERS, MAX_DECODER_WIDTH, MAX_LATENT_CHANNELS};
use crate::train::adam::AdamConfig;
use crate::train::{EpochStats, LrSchedule, TrainReport};
use std::time::Instant;

/// Everything that decides a training run.
#[derive(Clone, Debug, PartialEq)]
pub struct TexturedTrainConfig {
    /// `C`, the latent channels of the code.
    pub channels: usize,
    /// Hidden widths of the encoder (`P -> ... -> C`) and of the decoder (`6 + C -> ... -> 3`, or
    /// the spectral basis' count for spectral samples).
    pub encoder_hidden: Vec<usize>,
    pub decoder_hidden: Vec<usize>,
    /// Feed the half vector's azimuth to the decoder ([`crate::network::Nbrdf::anisotropic`]).
    pub anisotropic: bool,
    pub epochs: usize,
    pub batch: usize,
    pub adam: AdamConfig,
    pub lr_schedule: LrSchedule,
    /// Samples held out to pick the best epoch, as a fraction of the valid samples.
    pub validation_fraction: f64,
    pub seed: u64,
}

impl Default for TexturedTrainConfig {
    fn default() -> Self {
        TexturedTrainConfig {
            channels: 8,
            encoder_hidden: vec![32, 32],
            decoder_hidden: vec![32, 32],
            anisotropic: false,
            epochs: 40,
            batch: 512,
            adam: AdamConfig {
                learning_rate: 2e-3,
                ..AdamConfig::default()
            },
            lr_schedule: LrSchedule::COSINE,
            validation_fraction: 0.1,
            seed: 0,
        }
    }
}

impl TexturedTrainConfig {
    fn validate(&self) -> Result<()> {
        let bad = |what: String| Err(NbrdfError::InvalidArgument(what));
        if !(1..=MAX_LATENT_CHANNELS).contains(&self.channels) {
            return bad(format!(
                "latent channels {} must be in [1, {MAX_LATENT_CHANNELS}]",
                self.channels
            ));
        }
        if self.decoder_hidden.len() + 1 > MAX_DECODER_LAYERS {
            return bad(format!(
                "{} decoder hidden layers: a decoder has at most {MAX_DECODER_LAYERS} layers",
                self.decoder_hidden.len()
            ));
        }
        let widths = self.encoder_hidden.iter().chain(&self.decoder_hidden);
        if widths
            .clone()
            .any(|&w| !(1..=MAX_DECODER_WIDTH).contains(&w))
        {
            return bad(format!("hidden widths must be in [1, {MAX_DECODER_WIDTH}]"));
        }
        if self.epochs == 0 || self.batch == 0 {
            return bad("epochs and batch must be at least 1".into());
        }
        if !(self.validation_fraction > 0.0 && self.validation_fraction < 1.0) {
            return bad("the validation fraction must be in (0, 1)".into());
        }
        let lr = self.adam.learning_rate;
        if !(lr.is_finite() && lr > 0.0 && self.lr_schedule.is_valid()) {
            return bad("the learning rate must be positive and its schedule valid".into());
        }
        Ok(())
    }

    /// The initial layers of an encoder of `parameters` inputs and of a decoder of `outputs`
    /// outputs: Glorot uniform from the seed's [`Stream::Init`] stream, encoder first.
    pub(crate) fn initial_layers(
        &self,
        parameters: usize,
        outputs: usize,
    ) -> (Vec<Layer>, Vec<Layer>) {
        let mut rng = SplitMix64::new(self.seed, Stream::Init, 0);
        let encoder_widths: Vec<usize> = std::iter::once(parameters)
            .chain(self.encoder_hidden.iter().copied())
            .chain([self.channels])
            .collect();
        let decoder_widths: Vec<usize> = std::iter::once(INPUTS + self.channels)
            .chain(self.decoder_hidden.iter().copied())
            .chain([outputs])
            .collect();
        let encoder = glorot_uniform(&encoder_widths, &mut rng);
        let decoder = glorot_uniform(&decoder_widths, &mut rng);
        (encoder, decoder)
    }
}

/// A trained encoder and decoder, and how the run went.
#[derive(Clone, Debug)]
pub struct TexturedModel {
    /// `P -> ... -> C`, ReLU between layers, the last linear.
    pub encoder: Vec<Layer>,
    pub decoder: Decoder,
    pub report: TrainReport,
}

impl TexturedModel {
    /// `P`, the source parameters the encoder reads.
    pub fn parameter_count(&self) -> usize {
        self.encoder[0].inputs
    }

    pub(crate) fn weights(&self) -> JointWeights {
        JointWeights::new(&self.encoder, self.decoder.layers())
    }
}

/// Trains an encoder and a decoder on `samples`, calling `progress` after every epoch: an RGB
/// decoder, or for spectral samples one of the default spectral basis' coefficients
/// ([`super::TargetValues::Spectral`]). Runs on the current rayon thread pool; the result is the
/// same for a seed on any thread count.
pub fn train_textured(
    samples: &TexturedSamples<'_>,
    config: &TexturedTrainConfig,
    progress: &mut dyn FnMut(&EpochStats),
) -> Result<TexturedModel> {
    let start = Instant::now();
    config.validate()?;
    let rows = Rows::from_samples(samples, config.anisotropic)?;
    let (train, validation) = split(&rows, config)?;
    let (encoder, decoder) = config.initial_layers(rows.parameters, rows.outputs);
    let mut trainer = JointTrainer::new(
        JointWeights::new(&encoder, &decoder),
        config.batch,
        config.adam,
    );
    let mut order: Vec<u32> = Vec::new();
    let mut best = (f64::INFINITY, 0, trainer.weights.clone());
    let mut history = Vec::with_capacity(config.epochs);
    let batches = train.len().div_ceil(config.batch) as f64;
    for epoch in 1..=config.epochs {
        let (train_loss, validation_loss) = rayon::scope(|_| {
            order.clear();
            order.extend(0..train.len() as u32);
            SplitMix64::new(config.seed, Stream::Shuffle, epoch as u64).shuffle(&mut order);
            let mut sum = 0.0;
            for (b, indices) in order.chunks(config.batch).enumerate() {
                let done = (epoch - 1) as f64 + b as f64 / batches;
                let lr = config.adam.learning_rate * config.lr_schedule.factor(done, config.epochs);
                sum += trainer.step(&train.subset(indices), lr);
            }
            let train_loss = sum / (rows.outputs * train.len()) as f64;
            (train_loss, trainer.loss(&validation))
        });
        if !(train_loss.is_finite() && validation_loss.is_finite()) {
            return Err(NbrdfError::InvalidArgument(format!(
                "training diverged in epoch {epoch} (loss {train_loss})"
            )));
        }
        history.push((train_loss, validation_loss));
        if validation_loss < best.0 {
            best = (validation_loss, epoch, trainer.weights.clone());
        }
        progress(&EpochStats {
            epoch,
            max_epochs: config.epochs,
            train_loss,
            validation_loss,
            best_validation_loss: best.0,
            best_epoch: best.1,
            seconds: start.elapsed().as_secs_f64(),
        });
    }
    let weights = best.2;
    let spectral = match samples.target {
        super::TargetValues::Spectral { .. } => Some(Spectral::new(SpectralBasis::default())?),
        super::TargetValues::Rgb(_) => None,
    };
    let decoder = Decoder::new(
        weights.decoder.layout.unpad(&weights.decoder.p),
        config.channels,
        config.anisotropic,
        spectral,
    )?;
    Ok(TexturedModel {
        encoder: weights.encoder.layout.unpad(&weights.encoder.p),
        decoder,
        report: TrainReport {
            epochs_run: history.len(),
            best_epoch: best.1,
            best_validation_loss: best.0,
            stopped_early: false,
            seconds: start.elapsed().as_secs_f64(),
            train_samples: train.len(),
            validation_samples: validation.len(),
            dropped_below_horizon: rows.below_horizon,
            dropped_invalid: rows.invalid,
            history,
        },
    })
}

/// The valid rows split at random (the seed's [`Stream::ValidationSamples`] stream) into
/// training and validation rows, each at least one.
fn split(rows: &Rows, config: &TexturedTrainConfig) -> Result<(Rows, Rows)> {
    let n = rows.len();
    if n < 2 {
        return Err(NbrdfError::InvalidArgument(format!(
            "textured training needs at least 2 valid samples (above the horizon, finite targets \
             >= 0), got {n} ({} below the horizon, {} invalid)",
            rows.below_horizon, rows.invalid
        )));
    }
    let held = ((n as f64 * config.validation_fraction).ceil() as usize).clamp(1, n - 1);
    let mut order: Vec<u32> = (0..n as u32).collect();
    SplitMix64::new(config.seed, Stream::ValidationSamples, 0).shuffle(&mut order);
    let (validation, train) = order.split_at(held);
    let mut train = train.to_vec();
    train.sort_unstable();
    Ok((rows.subset(&train), rows.subset(validation)))
}
