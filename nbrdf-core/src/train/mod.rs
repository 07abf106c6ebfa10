//! Training an NBRDF on a reflectance target (docs/design.md section 5).
//!
//! Recipe: samples drawn once ([`dataset`]), Adam on mini-batches of a shuffled order each
//! epoch, early stopping on a held-out validation set with the best weights kept.
//!
//! Reproducibility: everything random is addressed by the seed ([`rng`]), and a batch's gradient
//! is the sum, in chunk order, of per-chunk gradients of fixed [`LANES`]-sample chunks
//! ([`mlp_grad`]). Threads only decide who computes which chunk, so the weights are bitwise the
//! same for any thread count (on one machine: the AVX2+FMA and portable kernel copies round
//! differently).

pub mod adam;
pub mod arrays;
pub mod dataset;
pub(crate) mod gemm;
pub mod lr_schedule;
pub mod mlp_grad;
pub mod spectral;
/// Kept under `train` for existing callers: the RNG and fast math are crate-wide modules now.
pub use crate::{fastmath, rng};

use crate::coords::RusinkiewiczAngles;
use crate::error::{NbrdfError, Result};
use crate::merl::MerlTable;
use crate::network::{paper_init_with_outputs, Layer, Nbrdf, Spectral};
use crate::rng::{SplitMix64, Stream};
use adam::{Adam, AdamConfig};
use dataset::{AngularSampling, DataSet, Sample, TargetFn};
pub use lr_schedule::LrSchedule;
use mlp_grad::{ChunkScratch, Kernel, Layout, TrainingSample, Weights, LANES};
use rayon::prelude::*;
use std::time::Instant;

/// Names this trainer in the provenance of the networks it writes.
pub const TRAINER_VERSION: &str = concat!("nbrdf-core ", env!("CARGO_PKG_VERSION"), " trainer 1");

/// Everything that decides a training run.
///
/// The defaults are the paper's recipe. Alternatives measured on SGD tables (a larger constant
/// step, exponential decay, halving on plateaus, fewer samples with more epochs) did not pay
/// off (docs/experiments.md); what does save time is early stopping, which diffuse materials
/// reach first.
#[derive(Clone, Debug, PartialEq)]
pub struct TrainConfig {
    pub sampling: AngularSampling,
    /// Train an anisotropic network (file format version 2): the input carries `phi_h` and the
    /// samples cover all four Rusinkiewicz angles. Give it about [`ANISOTROPIC_SAMPLE_FACTOR`]
    /// times the samples ([`TrainConfig::for_anisotropy`]).
    pub anisotropic: bool,
    /// Training samples kept (after dropping invalid ones).
    pub samples: usize,
    /// Validation samples, as a fraction of `samples`, drawn from their own random stream.
    pub validation_fraction: f64,
    pub max_epochs: usize,
    pub hidden: usize,
    pub batch: usize,
    pub adam: AdamConfig,
    /// Stop after this many epochs without a relative validation improvement of
    /// `min_improvement` over the best so far, but not before `min_epochs` epochs: stiff
    /// materials can sit on a plateau before the network finds the specular peak, which a bare
    /// patience would take for convergence (docs/design.md section 5).
    pub patience: usize,
    pub min_improvement: f64,
    pub min_epochs: usize,
    /// Learning-rate drops before stopping: when the patience runs out, the rate is multiplied by
    /// `lr_decay_factor` and training goes on, up to this many times (0: stop at once, the
    /// paper's constant rate). Long runs on stiff measured materials gain from it.
    pub lr_decays: usize,
    pub lr_decay_factor: f32,
    /// How the rate moves within the run of `max_epochs` (the drops above multiply on top).
    pub lr_schedule: LrSchedule,
    /// Stop (after `min_epochs`) once the validation loss is at most this: the mean absolute
    /// error of `ln(1 + f cos)` below which a fit is far from visible (2e-4: 0.1 % of a bright
    /// diffuse reflectance). Simple materials reach it; glossy measured ones stay above it and
    /// train until the patience and decays end (docs/design.md section 5). 0 turns it off.
    pub target_loss: f64,
    pub seed: u64,
}

/// The defaults adapt the training time to the material: up to 300 epochs at twice the paper's
/// learning rate, with two learning-rate drops when the validation loss stalls, and a stop as
/// soon as it is below [`TrainConfig::target_loss`]. Measured on the four RGL measurements
/// (docs/results/rgl-training.md): each beats the authors' network, where the paper's fixed
/// budget ([`TrainConfig::fixed_budget`]) beat it on one of four.
impl Default for TrainConfig {
    fn default() -> Self {
        TrainConfig {
            adam: AdamConfig {
                learning_rate: 1e-3,
                ..AdamConfig::default()
            },
            max_epochs: 300,
            patience: 20,
            lr_decays: 2,
            target_loss: 2e-4,
            ..TrainConfig::fixed_budget()
        }
    }
}

impl TrainConfig {
    /// The trainer's defaults before version 0.2: the paper's learning rate (5e-4), at most 100
    /// epochs, patience 10 after epoch 30, no learning-rate drops, no target loss. The networks
    /// the built-in autoencoder was trained on were made this way, so re-learning a network for
    /// it uses these settings.
    pub fn fixed_budget() -> TrainConfig {
        TrainConfig {
            sampling: AngularSampling::Adaptive,
            anisotropic: false,
            samples: 800_000,
            validation_fraction: 0.1,
            max_epochs: 100,
            hidden: crate::network::DEFAULT_HIDDEN,
            batch: 512,
            adam: AdamConfig::default(),
            patience: 10,
            min_improvement: 1e-3,
            min_epochs: 30,
            lr_decays: 0,
            lr_decay_factor: 0.2,
            lr_schedule: LrSchedule::Constant,
            target_loss: 0.0,
            seed: 0,
        }
    }
}

/// How many times the isotropic sample count an anisotropic network is trained on by default:
/// the paper's 5x, for the fourth dimension `phi_h`.
pub const ANISOTROPIC_SAMPLE_FACTOR: usize = 5;

/// Whether a network is anisotropic: decided by the training source, or forced.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Anisotropy {
    /// Anisotropic exactly when the source is (RGL measurements say so; MERL tables are not).
    #[default]
    Auto,
    On,
    Off,
}

impl Anisotropy {
    /// The decision for a source that is (or is not) isotropic.
    pub fn resolve(self, source_isotropic: bool) -> bool {
        match self {
            Anisotropy::Auto => !source_isotropic,
            Anisotropy::On => true,
            Anisotropy::Off => false,
        }
    }

    pub fn as_str(self) -> &'static str {
        match self {
            Anisotropy::Auto => "auto",
            Anisotropy::On => "on",
            Anisotropy::Off => "off",
        }
    }
}

impl TrainConfig {
    /// This configuration for an isotropic or anisotropic network; with `scale_samples`, an
    /// anisotropic one gets [`ANISOTROPIC_SAMPLE_FACTOR`] times the samples (when the count is
    /// a default rather than the user's).
    pub fn for_anisotropy(self, anisotropic: bool, scale_samples: bool) -> TrainConfig {
        let samples = if anisotropic && scale_samples {
            self.samples.saturating_mul(ANISOTROPIC_SAMPLE_FACTOR)
        } else {
            self.samples
        };
        TrainConfig {
            anisotropic,
            samples,
            ..self
        }
    }

    pub(crate) fn validate(&self) -> Result<()> {
        let bad = |what: &str| Err(NbrdfError::InvalidArgument(what.to_string()));
        if self.samples == 0 || self.batch == 0 || self.hidden == 0 || self.max_epochs == 0 {
            return bad("samples, batch, hidden width and epochs must be at least 1");
        }
        if !(self.validation_fraction > 0.0 && self.validation_fraction <= 1.0) {
            return bad("the validation fraction must be in (0, 1]");
        }
        let lr = self.adam.learning_rate;
        if !(lr.is_finite() && lr > 0.0) {
            return bad("the learning rate must be a positive number");
        }
        if !(self.min_improvement.is_finite() && self.min_improvement >= 0.0) {
            return bad("the minimum improvement must be a non-negative number");
        }
        if !(self.lr_decay_factor > 0.0 && self.lr_decay_factor < 1.0) {
            return bad("the learning-rate decay factor must be in (0, 1)");
        }
        if !self.lr_schedule.is_valid() {
            return bad(
                "the learning-rate schedule needs a warm-up >= 0 and a final fraction in (0, 1]",
            );
        }
        if !(self.target_loss.is_finite() && self.target_loss >= 0.0) {
            return bad("the target loss must be a non-negative number");
        }
        Ok(())
    }

    /// Validation samples drawn with `samples` training samples (at least 1).
    pub fn validation_samples(&self) -> usize {
        ((self.samples as f64 * self.validation_fraction).ceil() as usize).max(1)
    }
}

/// Progress after one epoch.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EpochStats {
    /// 1-based.
    pub epoch: usize,
    pub max_epochs: usize,
    pub train_loss: f64,
    pub validation_loss: f64,
    pub best_validation_loss: f64,
    pub best_epoch: usize,
    pub seconds: f64,
}

/// How a run went.
#[derive(Clone, Debug, PartialEq)]
pub struct TrainReport {
    pub epochs_run: usize,
    pub best_epoch: usize,
    pub best_validation_loss: f64,
    pub stopped_early: bool,
    /// Wall-clock seconds, drawing the samples included.
    pub seconds: f64,
    pub train_samples: usize,
    pub validation_samples: usize,
    /// Training candidates dropped while drawing (below the horizon, invalid data).
    pub dropped_below_horizon: u64,
    pub dropped_invalid: u64,
    /// `(train, validation)` loss per epoch.
    pub history: Vec<(f64, f64)>,
}

/// A trained network and its report.
#[derive(Clone, Debug)]
pub struct TrainOutcome {
    pub network: Nbrdf,
    pub report: TrainReport,
}

/// Trains a network named `name` on `target`, calling `on_epoch` after every epoch.
/// Runs on the current rayon thread pool.
pub fn train(
    target: &TargetFn<'_>,
    config: &TrainConfig,
    name: &str,
    on_epoch: &mut dyn FnMut(&EpochStats),
) -> Result<TrainOutcome> {
    let start = Instant::now();
    let (train_set, validation) = draw_sets(target, config)?;
    train_on_sets(&train_set, &validation, config, name, start, on_epoch)
}

/// The optimisation of [`train`] on samples drawn already (`config.samples` and
/// `config.validation_fraction` are not read); `start` is when the run began, for its timings.
pub fn train_on_sets(
    train_set: &DataSet,
    validation: &DataSet,
    config: &TrainConfig,
    name: &str,
    start: Instant,
    on_epoch: &mut dyn FnMut(&EpochStats),
) -> Result<TrainOutcome> {
    let sets = SampleSets {
        train: &train_set.samples,
        validation: &validation.samples,
        dropped_below_horizon: train_set.below_horizon,
        dropped_invalid: train_set.invalid,
    };
    train_on_samples(&sets, config, name, None, start, on_epoch)
}

/// Training and validation samples of any kind ([`TrainingSample`]) and what was dropped while
/// making them (for the report).
#[derive(Clone, Copy, Debug)]
pub struct SampleSets<'a, S> {
    pub train: &'a [S],
    pub validation: &'a [S],
    pub dropped_below_horizon: u64,
    pub dropped_invalid: u64,
}

/// [`train_on_sets`] for samples of any output count: an RGB network (`spectral` `None`, 3
/// targets a sample) or a spectral one, whose basis has as many coefficients as a sample has
/// targets.
pub fn train_on_samples<S: TrainingSample>(
    sets: &SampleSets<'_, S>,
    config: &TrainConfig,
    name: &str,
    spectral: Option<Spectral>,
    start: Instant,
    on_epoch: &mut dyn FnMut(&EpochStats),
) -> Result<TrainOutcome> {
    check_sets(sets, config, spectral.as_ref())?;
    let (train_samples, validation_samples) = (sets.train, sets.validation);
    let mut trainer = Trainer::<S>::new(config.hidden, config.batch, config.adam, config.seed);
    let mut order: Vec<u32> = Vec::new();
    let mut best = (f64::INFINITY, 0usize, trainer.weights.p.clone());
    let mut schedule = Schedule::new(config);
    let mut history = Vec::with_capacity(config.max_epochs);
    for epoch in 1..=config.max_epochs {
        // On a pool thread: from outside the pool each batch's parallel loop would put the
        // caller to sleep and wake it again (two context switches and futex calls per batch,
        // docs/results/training.md); inside it, it is a work-stealing join.
        let (train_loss, validation_loss) = rayon::scope(|_| {
            let train_loss = trainer.scheduled_epoch(
                train_samples,
                &mut order,
                config.seed,
                epoch as u64,
                (config.lr_schedule, config.max_epochs),
            );
            (train_loss, trainer.validation_loss(validation_samples))
        });
        if !(train_loss.is_finite() && validation_loss.is_finite()) {
            // Cannot happen with bounded gradients; fail loudly rather than save garbage.
            return Err(NbrdfError::InvalidArgument(format!(
                "training diverged in epoch {epoch} (loss {train_loss})"
            )));
        }
        history.push((train_loss, validation_loss));
        if validation_loss < best.0 {
            best = (validation_loss, epoch, trainer.weights.p.clone());
        }
        schedule.observe(validation_loss, config.min_improvement);
        on_epoch(&EpochStats {
            epoch,
            max_epochs: config.max_epochs,
            train_loss,
            validation_loss,
            best_validation_loss: best.0,
            best_epoch: best.1,
            seconds: start.elapsed().as_secs_f64(),
        });
        match schedule.next_step(config, epoch, best.0) {
            Step::Continue => {}
            Step::Stop => break,
            Step::DecayLearningRate => {
                trainer.set_learning_rate(trainer.learning_rate() * config.lr_decay_factor)
            }
        }
    }
    let report = TrainReport {
        epochs_run: history.len(),
        best_epoch: best.1,
        best_validation_loss: best.0,
        stopped_early: history.len() < config.max_epochs,
        seconds: start.elapsed().as_secs_f64(),
        train_samples: train_samples.len(),
        validation_samples: validation_samples.len(),
        dropped_below_horizon: sets.dropped_below_horizon,
        dropped_invalid: sets.dropped_invalid,
        history,
    };
    let network = Nbrdf {
        name: name.to_string(),
        layers: trainer.weights.layout.unpad(&best.2),
        anisotropic: config.anisotropic,
        spectral,
        sampling: None,
        base: None,
        provenance: serde_json::Value::Null,
    };
    Ok(TrainOutcome { network, report })
}

/// The settings and sets of [`train_on_samples`] are usable: samples in both sets, with as many
/// targets as the network has outputs.
fn check_sets<S: TrainingSample>(
    sets: &SampleSets<'_, S>,
    config: &TrainConfig,
    spectral: Option<&Spectral>,
) -> Result<()> {
    config.validate()?;
    if sets.train.is_empty() || sets.validation.is_empty() {
        return Err(NbrdfError::InvalidArgument(
            "training needs at least one training and one validation sample".into(),
        ));
    }
    let outputs = spectral.map_or(crate::network::OUTPUTS, Spectral::count);
    if outputs != S::OUTPUTS {
        return Err(NbrdfError::InvalidArgument(format!(
            "samples with {} targets cannot train a network with {outputs} outputs",
            S::OUTPUTS
        )));
    }
    Ok(())
}

/// What [`train_on_sets`] does after an epoch.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Step {
    Continue,
    Stop,
    DecayLearningRate,
}

/// Early stopping and learning-rate decay on a plateau of the validation loss.
#[derive(Clone, Debug, PartialEq)]
struct Schedule {
    /// The validation loss an epoch must beat by `min_improvement` to count as progress.
    reference: f64,
    since_improvement: usize,
    decays_left: usize,
}

impl Schedule {
    fn new(config: &TrainConfig) -> Self {
        Schedule {
            reference: f64::INFINITY,
            since_improvement: 0,
            decays_left: config.lr_decays,
        }
    }

    /// Counts the epochs since the validation loss last improved by a relative `min_improvement`.
    fn observe(&mut self, validation_loss: f64, min_improvement: f64) {
        if validation_loss < self.reference * (1.0 - min_improvement) {
            self.reference = validation_loss;
            self.since_improvement = 0;
        } else {
            self.since_improvement += 1;
        }
    }

    /// After `epoch` (best validation loss `best_loss` so far): stop once past `min_epochs`
    /// when the target loss is reached, or on a plateau with no decays left; decay the learning
    /// rate on a plateau otherwise.
    fn next_step(&mut self, config: &TrainConfig, epoch: usize, best_loss: f64) -> Step {
        if epoch >= config.min_epochs && best_loss <= config.target_loss {
            return Step::Stop;
        }
        if self.since_improvement >= config.patience && epoch >= config.min_epochs {
            if self.decays_left == 0 {
                return Step::Stop;
            }
            self.decays_left -= 1;
            self.since_improvement = 0;
            return Step::DecayLearningRate;
        }
        Step::Continue
    }
}

/// The training target of a MERL table: its trilinear lookup, where at least one neighbour cell
/// with a positive weight is valid in all channels ([`MerlTable::lookup_valid`]); elsewhere the
/// table has no data and no sample is drawn.
pub fn table_target(
    table: &MerlTable,
) -> impl Fn(&RusinkiewiczAngles) -> Option<[f64; 3]> + Sync + '_ {
    move |angles| table.lookup_valid(angles)
}

/// Free-form provenance for the network file.
pub fn provenance(config: &TrainConfig, report: &TrainReport, source: &str) -> serde_json::Value {
    serde_json::json!({
        "trainer": TRAINER_VERSION,
        "source": source,
        "sampling": config.sampling.as_str(),
        "anisotropic": config.anisotropic,
        "samples": report.train_samples,
        "validation_samples": report.validation_samples,
        "dropped_below_horizon": report.dropped_below_horizon,
        "dropped_invalid": report.dropped_invalid,
        "hidden": config.hidden,
        "batch": config.batch,
        // Through its shortest decimal form: 5e-4 as f32 widened to f64 would print 0.000500000024.
        "learning_rate": config.adam.learning_rate.to_string().parse::<f64>().unwrap_or(f64::NAN),
        "max_epochs": config.max_epochs,
        "patience": config.patience,
        "min_epochs": config.min_epochs,
        "min_improvement": config.min_improvement,
        "lr_decays": config.lr_decays,
        "target_loss": config.target_loss,
        "lr_decay_factor": config.lr_decay_factor.to_string().parse::<f64>().unwrap_or(f64::NAN),
        "lr_schedule": config.lr_schedule.describe(),
        "epochs": report.epochs_run,
        "best_epoch": report.best_epoch,
        "best_validation_loss": report.best_validation_loss,
        "loss": "mean |ln(1 + f cos) - ln(1 + f_net cos)| over samples and channels",
        "seconds": (report.seconds * 1000.0).round() / 1000.0,
        "seed": config.seed,
    })
}

/// The optimisation state: weights, Adam moments and per-chunk working memory, for samples of
/// type `S` (RGB [`Sample`]s by default; the output count is theirs).
pub struct Trainer<S: TrainingSample = Sample> {
    kernel: Kernel,
    pub weights: Weights,
    adam: Adam,
    learning_rate: f32,
    batch: usize,
    scratches: Vec<ChunkScratch>,
    /// One padded gradient per chunk of a batch, reduced in chunk order.
    chunk_grads: Vec<f32>,
    chunk_losses: Vec<f64>,
    grad: Vec<f32>,
    /// The samples of an epoch in its shuffled order ([`TrainingSample::gather`]).
    shuffled: Vec<S>,
}

impl<S: TrainingSample> Trainer<S> {
    /// Starts from [`crate::network::paper_init`] (of `S::OUTPUTS` outputs).
    pub fn new(hidden: usize, batch: usize, adam: AdamConfig, seed: u64) -> Self {
        Self::from_layers(
            &paper_init_with_outputs(hidden, S::OUTPUTS, seed),
            batch,
            adam,
        )
    }

    /// Starts from given weights (shapes `6 -> h -> h -> S::OUTPUTS`, checked by the caller).
    pub fn from_layers(layers: &[Layer; 3], batch: usize, adam: AdamConfig) -> Self {
        debug_assert_eq!(layers[2].outputs, S::OUTPUTS);
        let layout = Layout::with_outputs(layers[0].outputs, S::OUTPUTS);
        let p = layout.pad(layers);
        let chunks = batch.div_ceil(LANES);
        let len = layout.len;
        Trainer {
            kernel: Kernel::detect(),
            adam: Adam::new(adam, len),
            learning_rate: adam.learning_rate,
            batch,
            scratches: (0..chunks).map(|_| ChunkScratch::new(&layout)).collect(),
            chunk_grads: vec![0.0; chunks * len],
            chunk_losses: vec![0.0; chunks],
            grad: vec![0.0; len],
            shuffled: Vec::new(),
            weights: Weights::new(layout, p),
        }
    }

    /// Forces the portable kernel copy (for tests).
    pub fn with_kernel(mut self, kernel: Kernel) -> Self {
        self.kernel = kernel;
        self
    }

    /// Gradient of the mean loss over the samples `indices` (at most one batch) into
    /// [`Trainer::gradient`]; returns the loss sum.
    pub fn compute_gradient(&mut self, samples: &[S], indices: &[u32]) -> f64 {
        let mut batch = std::mem::take(&mut self.shuffled);
        S::gather(samples, indices, &mut batch);
        let loss = self.compute_gradient_of(&batch);
        self.shuffled = batch;
        loss
    }

    /// [`Trainer::compute_gradient`] of the samples `batch` (at most one batch), in order.
    fn compute_gradient_of(&mut self, batch: &[S]) -> f64 {
        assert!(
            batch.len() <= self.batch,
            "more samples than the batch size"
        );
        let chunks = batch.len().div_ceil(LANES);
        let len = self.weights.layout.len;
        let scale = 1.0 / (S::OUTPUTS * batch.len().max(1)) as f32;
        let (kernel, weights) = (self.kernel, &self.weights);
        self.scratches[..chunks]
            .par_iter_mut()
            .zip(self.chunk_grads.par_chunks_mut(len))
            .zip(self.chunk_losses.par_iter_mut())
            .zip(batch.par_chunks(LANES))
            .for_each(|(((scratch, grad), loss), samples)| {
                scratch.load_slice(samples);
                *loss = kernel.gradient(weights, scratch, scale, grad);
            });
        self.grad.copy_from_slice(&self.chunk_grads[..len]);
        for chunk in self.chunk_grads[len..chunks * len].chunks_exact(len) {
            for (g, &c) in self.grad.iter_mut().zip(chunk) {
                *g += c;
            }
        }
        self.chunk_losses[..chunks].iter().sum()
    }

    /// The gradient of the last [`Trainer::compute_gradient`] (padded layout).
    pub fn gradient(&self) -> &[f32] {
        &self.grad
    }

    pub fn learning_rate(&self) -> f32 {
        self.learning_rate
    }

    /// Changes the step size of the following steps (Adam's moments are kept).
    pub fn set_learning_rate(&mut self, lr: f32) {
        self.learning_rate = lr;
    }

    /// One Adam step on the samples `indices`; returns the loss sum before the step.
    pub fn step(&mut self, samples: &[S], indices: &[u32]) -> f64 {
        let loss = self.compute_gradient(samples, indices);
        self.apply_gradient();
        loss
    }

    /// One Adam step on the gradient of the last [`Trainer::compute_gradient`].
    fn apply_gradient(&mut self) {
        let lr = self.learning_rate;
        self.adam.step(&mut self.weights.p, &self.grad, lr);
        self.weights.refresh_transposes();
    }

    /// One pass over `samples` in the order of epoch `epoch`; returns the mean training loss.
    pub fn epoch(&mut self, samples: &[S], order: &mut Vec<u32>, seed: u64, epoch: u64) -> f64 {
        self.scheduled_epoch(samples, order, seed, epoch, (LrSchedule::Constant, 1))
    }

    /// [`Trainer::epoch`] (1-based `epoch`) with the rate of each batch scaled by the schedule
    /// of a run of `max_epochs`; the learning rate itself is left as it was.
    pub fn scheduled_epoch(
        &mut self,
        samples: &[S],
        order: &mut Vec<u32>,
        seed: u64,
        epoch: u64,
        (schedule, max_epochs): (LrSchedule, usize),
    ) -> f64 {
        order.clear();
        order.extend(0..samples.len() as u32);
        SplitMix64::new(seed, Stream::Shuffle, epoch).shuffle(order);
        // Batches then read consecutive samples: gathered through the order inside the
        // gradient kernel, each sample was a cache miss the kernel's work could not hide.
        let mut shuffled = std::mem::take(&mut self.shuffled);
        S::gather(samples, order, &mut shuffled);
        let base = self.learning_rate;
        let batches = order.len().div_ceil(self.batch).max(1) as f64;
        let mut sum = 0.0;
        for (b, batch) in shuffled.chunks(self.batch).enumerate() {
            let done = epoch.saturating_sub(1) as f64 + b as f64 / batches;
            self.learning_rate = base * schedule.factor(done, max_epochs);
            sum += self.compute_gradient_of(batch);
            self.apply_gradient();
        }
        self.shuffled = shuffled;
        self.learning_rate = base;
        sum / (S::OUTPUTS * samples.len().max(1)) as f64
    }

    /// Mean loss of the network as evaluated (output clamped at 0) over `samples`.
    pub fn validation_loss(&self, samples: &[S]) -> f64 {
        let (kernel, weights) = (self.kernel, &self.weights);
        let sums: Vec<f64> = samples
            .par_chunks(LANES)
            .map_init(
                || ChunkScratch::new(&weights.layout),
                |scratch, chunk| {
                    scratch.load_slice(chunk);
                    kernel.loss(weights, scratch)
                },
            )
            .collect();
        sums.iter().sum::<f64>() / (S::OUTPUTS * samples.len().max(1)) as f64
    }

    /// The current weights as network layers.
    pub fn layers(&self) -> [Layer; 3] {
        self.weights.layout.unpad(&self.weights.p)
    }
}

/// Data sets drawn for a config, for benchmarks and experiments that drive [`Trainer`] directly.
pub fn draw_sets(target: &TargetFn<'_>, config: &TrainConfig) -> Result<(DataSet, DataSet)> {
    config.validate()?;
    let train = dataset::draw(
        target,
        config.sampling,
        config.anisotropic,
        config.samples,
        config.seed,
        Stream::TrainSamples,
    )?;
    let validation = dataset::draw(
        target,
        config.sampling,
        config.anisotropic,
        config.validation_samples(),
        config.seed,
        Stream::ValidationSamples,
    )?;
    Ok((train, validation))
}

#[cfg(test)]
mod tests;
