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
    /// materials can sit on a plateau for 10-15 epochs before the network finds the specular
    /// peak (alumina-oxide does), which a bare patience would take for convergence.
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
    /// diffuse reflectance). Simple materials reach it within tens of epochs; glossy measured
    /// ones sit at 1e-3 to 1e-2 and train until the patience and decays end. 0 turns it off.
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
        // 17 % of the CPU time as system time); inside it, it is a work-stealing join.
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
mod tests {
    use super::*;
    use crate::merl::{self, cell_coordinates, CELLS, SCALE};
    use crate::phong_fit::PhongParams;

    /// The plateau rule as `TrainConfig` documents it: `patience` epochs without a relative
    /// improvement of `min_improvement` decay the rate, `lr_decays` times, then stop; nothing
    /// before `min_epochs`; the target loss stops at once after `min_epochs`.
    #[test]
    fn schedule_decays_on_plateaus_then_stops() {
        use Step::{Continue as C, DecayLearningRate as D, Stop as S};
        let config = TrainConfig {
            patience: 2,
            lr_decays: 1,
            min_epochs: 3,
            min_improvement: 0.1,
            target_loss: 0.5,
            ..TrainConfig::default()
        };
        let mut schedule = Schedule::new(&config);
        // 0.95 is within 10 % of 1.0: not an improvement.
        let losses = [1.0, 0.95, 0.95, 0.95, 0.8, 0.8, 0.8, 0.8];
        let steps: Vec<Step> = losses
            .iter()
            .enumerate()
            .map(|(i, &loss)| {
                schedule.observe(loss, config.min_improvement);
                schedule.next_step(&config, i + 1, 0.8)
            })
            .collect();
        // Epoch 3 is the second without improvement and the first allowed to act; epoch 5
        // improves on 0.95 by more than 10 %; epochs 6-7 are its plateau with no decay left.
        assert_eq!(steps, [C, C, D, C, C, C, S, S]);
        assert_eq!(
            Schedule::new(&config).next_step(&config, 3, 0.5),
            Step::Stop,
            "the target loss stops once min_epochs are done"
        );
        assert_eq!(Schedule::new(&config).next_step(&config, 2, 0.1), C);
    }

    /// A glossy Blinn-Phong material (smooth enough for a short test run).
    fn glossy(a: &RusinkiewiczAngles) -> Option<[f64; 3]> {
        let p = PhongParams {
            kd: [0.5, 0.3, 0.2],
            ks: [0.3, 0.3, 0.3],
            exponent: 8.0,
        };
        Some(p.eval(a.theta_h.cos()))
    }

    /// A quick training run (also the arrays tests', so both train alike).
    /// Mean log-space error of a trained network against `target` on 2,000 fresh uniform
    /// directions (the validation stream, a seed no training run here uses).
    pub(super) fn log_error_on_fresh_directions(target: &TargetFn<'_>, layers: &[Layer; 3]) -> f64 {
        let test = dataset::draw(
            target,
            AngularSampling::Uniform,
            false,
            2000,
            99,
            Stream::ValidationSamples,
        )
        .unwrap();
        Trainer::from_layers(layers, 64, AdamConfig::default()).validation_loss(&test.samples)
    }

    pub(super) fn small_config() -> TrainConfig {
        TrainConfig {
            samples: 4000,
            max_epochs: 25,
            hidden: 12,
            batch: 64,
            patience: 25,
            seed: 3,
            ..TrainConfig::fixed_budget()
        }
    }

    #[test]
    fn the_target_loss_stops_training_once_reached_after_min_epochs() {
        let full = train(&glossy, &small_config(), "a", &mut |_| {})
            .unwrap()
            .report;
        // A target the full run reaches at some epoch k: a run with it stops at max(k, 5).
        let k = 12;
        let target = full.history[..k]
            .iter()
            .map(|h| h.1)
            .fold(f64::INFINITY, f64::min);
        let reached = full.history.iter().position(|h| h.1 <= target).unwrap() + 1;
        let config = TrainConfig {
            target_loss: target,
            min_epochs: 5,
            ..small_config()
        };
        let stopped = train(&glossy, &config, "b", &mut |_| {}).unwrap().report;
        assert_eq!(stopped.epochs_run, reached.max(5), "{:?}", full.history);
        assert!(stopped.stopped_early);
        assert_eq!(&stopped.history[..], &full.history[..stopped.epochs_run]);
        let bad = TrainConfig {
            target_loss: f64::NAN,
            ..small_config()
        };
        assert!(train(&glossy, &bad, "c", &mut |_| {}).is_err());
    }

    #[test]
    fn the_defaults_are_the_adaptive_budget() {
        let (adaptive, fixed) = (TrainConfig::default(), TrainConfig::fixed_budget());
        assert_eq!((fixed.adam.learning_rate, fixed.max_epochs), (5e-4, 100));
        assert_eq!((fixed.lr_decays, fixed.target_loss), (0, 0.0));
        assert!(adaptive.max_epochs > fixed.max_epochs && adaptive.lr_decays > 0);
        assert!(adaptive.target_loss > 0.0);
        assert_eq!(
            (adaptive.samples, adaptive.hidden, adaptive.batch),
            (fixed.samples, fixed.hidden, fixed.batch)
        );
    }

    #[test]
    fn training_lowers_the_loss_and_fits_the_target() {
        let config = small_config();
        let mut epochs = Vec::new();
        let outcome = train(&glossy, &config, "glossy", &mut |e| epochs.push(*e)).unwrap();
        let report = &outcome.report;
        assert_eq!(epochs.len(), report.epochs_run);
        let first = report.history[0].1;
        assert!(
            report.best_validation_loss < 0.05 * first,
            "{:?}",
            report.history
        );
        // Log-space error of the saved network against the target on fresh directions.
        let error = log_error_on_fresh_directions(&glossy, &outcome.network.layers);
        assert!(
            error < 5e-3,
            "log-space error {error}, history {:?}",
            report.history
        );
        assert!(
            (report.best_validation_loss - report.history[report.best_epoch - 1].1).abs() < 1e-12
        );
    }

    /// A closed-form anisotropic test oracle: a diffuse base and an elliptical Gaussian highlight
    /// of the half vector's slopes, `exp(-((h.x / a_x)^2 + (h.y / a_y)^2) / h.z^2)`, stretched
    /// along y (`a_x = 0.15`, `a_y = 0.5`): its value depends on `phi_h`.
    fn anisotropic_oracle(a: &RusinkiewiczAngles) -> Option<[f64; 3]> {
        let (sin_th, cos_th) = a.theta_h.sin_cos();
        let (sin_ph, cos_ph) = a.phi_h.sin_cos();
        let (hx, hy) = (sin_th * cos_ph / 0.15, sin_th * sin_ph / 0.5);
        let peak = 3.0 * (-(hx * hx + hy * hy) / (cos_th * cos_th).max(1e-6)).exp();
        Some([0.2 + peak, 0.1 + peak, 0.05 + peak])
    }

    /// Mean log-space error of `net` against the oracle over all four angles (adaptive in
    /// theta, uniform in phi_h and phi_d), from its own random stream.
    fn error_over_phi_h(net: &Nbrdf) -> f64 {
        let (mut sum, mut kept) = (0.0, 0);
        for k in 0..4000u64 {
            let mut rng = SplitMix64::new(77, Stream::Metrics, k);
            let u = [0; 4].map(|_| rng.next_f64());
            let (view, light, angles) = dataset::directions(AngularSampling::Adaptive, true, u);
            if view.z <= 0.01 || light.z <= 0.01 {
                continue;
            }
            let want = anisotropic_oracle(&angles).unwrap();
            let got = net.eval_at_angles(&angles);
            for c in 0..3 {
                sum += ((want[c] * light.z).ln_1p() - (got[c] * light.z).ln_1p()).abs();
            }
            kept += 3;
        }
        sum / f64::from(kept)
    }

    /// An anisotropic network learns the phi_h dependence that an isotropic one cannot: trained
    /// alike on the oracle, its error over all four angles is well below the isotropic network's.
    #[test]
    fn an_anisotropic_network_learns_what_an_isotropic_one_cannot() {
        let config = TrainConfig {
            samples: 12_000,
            max_epochs: 30,
            hidden: 16,
            adam: AdamConfig {
                learning_rate: 2e-3,
                ..AdamConfig::default()
            },
            ..small_config()
        };
        let aniso = train(
            &anisotropic_oracle,
            &config.clone().for_anisotropy(true, false),
            "a",
            &mut |_| {},
        )
        .unwrap()
        .network;
        let iso = train(&anisotropic_oracle, &config, "i", &mut |_| {})
            .unwrap()
            .network;
        assert!(aniso.anisotropic && !iso.anisotropic);
        let (ea, ei) = (error_over_phi_h(&aniso), error_over_phi_h(&iso));
        assert!(ea < 0.5 * ei, "anisotropic {ea} vs isotropic {ei}");
        // The trained network's sampling lobe is anisotropic the oracle's way: its peak is
        // narrow along x (tangent width 0.15 vs 0.5, i.e. n_u ~ 44, n_v ~ 4), and the lobe
        // samples it better than the best isotropic one.
        let mut lobe_config = crate::anisotropic_lobe_fit::AnisotropicLobeFitConfig::default();
        lobe_config.base.s_bins = 60;
        lobe_config.base.phi_bins = 48;
        lobe_config.base.view_thetas = vec![0.3, 0.8, 1.2];
        lobe_config.refine_levels = 3;
        let target = crate::target::network_target(&aniso);
        let lobe =
            crate::anisotropic_lobe_fit::fit_anisotropic_lobe(&target, &lobe_config).unwrap();
        assert!(lobe.exponent_u > 2.0 * lobe.exponent_v, "{lobe:?}");
        assert!(
            lobe.relative_variance < lobe.isotropic_relative_variance,
            "{lobe:?}"
        );
    }

    #[test]
    fn anisotropy_resolves_from_the_source_and_scales_default_samples() {
        assert!(Anisotropy::Auto.resolve(false) && !Anisotropy::Auto.resolve(true));
        assert!(Anisotropy::On.resolve(true) && !Anisotropy::Off.resolve(false));
        let base = TrainConfig::default();
        let scaled = base.clone().for_anisotropy(true, true);
        assert_eq!(scaled.samples, ANISOTROPIC_SAMPLE_FACTOR * base.samples);
        assert_eq!(
            base.clone().for_anisotropy(true, false).samples,
            base.samples
        );
        assert_eq!(base.clone().for_anisotropy(false, true), base);
    }

    #[test]
    fn learning_rate_decay_continues_past_the_plateau() {
        // Same seed, so both runs are identical up to the first plateau; the decayed run goes on
        // from there and can only keep or improve the best validation loss.
        let plain = TrainConfig {
            patience: 2,
            min_epochs: 1,
            max_epochs: 60,
            min_improvement: 0.05,
            ..small_config()
        };
        let decayed = TrainConfig {
            lr_decays: 2,
            ..plain.clone()
        };
        let a = train(&glossy, &plain, "a", &mut |_| {}).unwrap().report;
        let b = train(&glossy, &decayed, "b", &mut |_| {}).unwrap().report;
        assert!(a.stopped_early, "{:?}", a.history);
        assert!(b.epochs_run > a.epochs_run);
        assert_eq!(&b.history[..a.epochs_run], &a.history[..]);
        assert!(b.best_validation_loss <= a.best_validation_loss);
        let bad = TrainConfig {
            lr_decay_factor: 1.0,
            ..plain
        };
        assert!(train(&glossy, &bad, "c", &mut |_| {}).is_err());
    }

    fn weights_bits(outcome: &TrainOutcome) -> Vec<u32> {
        outcome
            .network
            .layers
            .iter()
            .flat_map(|l| l.weights.iter().chain(&l.bias))
            .map(|w| w.to_bits())
            .collect()
    }

    #[test]
    fn training_is_deterministic_for_a_seed_and_any_thread_count() {
        let config = TrainConfig {
            samples: 1500,
            max_epochs: 2,
            batch: 200,
            ..small_config()
        };
        let run = |threads: usize| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            pool.install(|| train(&glossy, &config, "g", &mut |_| {}).unwrap())
        };
        let a = run(1);
        let b = run(2);
        let c = run(2);
        assert_eq!(weights_bits(&a), weights_bits(&b));
        assert_eq!(weights_bits(&b), weights_bits(&c));
        assert_eq!(a.report.history, c.report.history);
        let other = TrainConfig {
            seed: 4,
            ..config.clone()
        };
        let d = train(&glossy, &other, "g", &mut |_| {}).unwrap();
        assert_ne!(weights_bits(&a), weights_bits(&d));
    }

    /// The cosine schedule depends on the batch's place in the run only: any thread count gives
    /// the same weights, and they differ from the constant rate's.
    #[test]
    fn a_cosine_schedule_is_deterministic_for_any_thread_count() {
        let cosine = TrainConfig {
            lr_schedule: LrSchedule::COSINE,
            adam: AdamConfig {
                learning_rate: 2e-3,
                ..AdamConfig::default()
            },
            ..small_config()
        };
        let run = |threads: usize, config: &TrainConfig| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            pool.install(|| train(&glossy, config, "g", &mut |_| {}).unwrap())
        };
        let (a, b) = (run(1, &cosine), run(2, &cosine));
        assert_eq!(weights_bits(&a), weights_bits(&b));
        assert_eq!(a.report.history, b.report.history);
        let constant = TrainConfig {
            lr_schedule: LrSchedule::Constant,
            ..cosine.clone()
        };
        let c = run(2, &constant);
        assert_ne!(weights_bits(&a), weights_bits(&c));
        let bad = TrainConfig {
            lr_schedule: LrSchedule::Cosine {
                warmup_epochs: 1.0,
                final_fraction: 0.0,
            },
            ..small_config()
        };
        assert!(train(&glossy, &bad, "x", &mut |_| {}).is_err());
    }

    #[test]
    fn invalid_cells_never_become_samples() {
        // Reflectance 0.25 everywhere, except: no data at all for theta_d index >= 60, and the
        // red channel alone unmeasured for theta_h index 30..40 (any channel invalidates a cell).
        let mut stored = vec![0.0; 3 * CELLS];
        for cell in 0..CELLS {
            let (h, d, _) = cell_coordinates(cell);
            for c in 0..3 {
                let unmeasured = d >= 60 || (c == 0 && (30..40).contains(&h));
                stored[c * CELLS + cell] = if unmeasured {
                    merl::NOT_MEASURED
                } else {
                    0.25 / SCALE[c]
                };
            }
        }
        let table = MerlTable::from_stored(stored).unwrap();
        let target = table_target(&table);
        let set = dataset::draw(
            &target,
            AngularSampling::Adaptive,
            false,
            20_000,
            1,
            Stream::TrainSamples,
        )
        .unwrap();
        assert!(set.invalid > 1000, "{}", set.invalid);
        for s in &set.samples {
            // Every target is the valid value: an unmeasured neighbour never leaks in.
            let expect = (0.25 * s.cos_light as f64).ln_1p() as f32;
            assert!(
                (s.log_target[0] - expect).abs() <= 1e-6 * expect.max(1.0),
                "{s:?}"
            );
            // And no sample lies where all neighbours are unmeasured.
            let theta_d_index =
                90.0 * (s.x[5] as f64).clamp(-1.0, 1.0).acos() / std::f64::consts::FRAC_PI_2;
            assert!(theta_d_index < 60.5 + 1e-3, "{s:?}");
            let theta_h_index = 90.0
                * ((s.x[2] as f64).clamp(-1.0, 1.0).acos() / std::f64::consts::FRAC_PI_2).sqrt();
            assert!(
                !(30.5 + 1e-3..39.5 - 1e-3).contains(&theta_h_index),
                "{s:?}"
            );
        }
    }

    #[test]
    fn bad_configs_are_errors() {
        for config in [
            TrainConfig {
                samples: 0,
                ..TrainConfig::default()
            },
            TrainConfig {
                batch: 0,
                ..TrainConfig::default()
            },
            TrainConfig {
                adam: AdamConfig {
                    learning_rate: f32::NAN,
                    ..AdamConfig::default()
                },
                ..TrainConfig::default()
            },
            TrainConfig {
                validation_fraction: 0.0,
                ..TrainConfig::default()
            },
        ] {
            assert!(train(&glossy, &config, "x", &mut |_| {}).is_err());
        }
    }
}
