//! `nbrdf train`.

use super::{count_in, emit, progress, PhiFoldArg};
use clap::{Args, ValueEnum};
use nbrdf_core::ops::limits::{MAX_BATCH, MAX_EPOCHS, MAX_HIDDEN, MAX_SAMPLES};
use nbrdf_core::ops::train_network::{train_network, TrainRequest};
use nbrdf_core::source::RglFold;
use nbrdf_core::train::adam::AdamConfig;
use nbrdf_core::train::dataset::AngularSampling;
use nbrdf_core::train::{EpochStats, TrainConfig};
use nbrdf_core::Result;
use std::path::PathBuf;

#[derive(Clone, Copy, ValueEnum)]
pub enum SamplingArg {
    /// theta_h, theta_d, phi_d uniform in the angles: dense near the specular peak (the paper's).
    Adaptive,
    /// Light and view uniform over the hemisphere (the paper's baseline).
    Uniform,
}

impl From<SamplingArg> for AngularSampling {
    fn from(s: SamplingArg) -> Self {
        match s {
            SamplingArg::Adaptive => AngularSampling::Adaptive,
            SamplingArg::Uniform => AngularSampling::Uniform,
        }
    }
}

#[derive(Clone, Copy, ValueEnum)]
pub enum RglFoldArg {
    /// f(view, light) as Mitsuba's `measured` evaluates it (RGL data is not reciprocal).
    AsMeasured,
    /// The mean of f(view, light) and f(light, view): a reciprocal network.
    ReciprocalMean,
}

impl From<RglFoldArg> for RglFold {
    fn from(f: RglFoldArg) -> Self {
        match f {
            RglFoldArg::AsMeasured => RglFold::AsMeasured,
            RglFoldArg::ReciprocalMean => RglFold::ReciprocalMean,
        }
    }
}

#[derive(Args)]
pub struct TrainArgs {
    /// What to learn: a MERL-format table or an RGL .bsdf measurement (told apart by content).
    /// A measurement is learnt as Mitsuba's `measured` plugin evaluates it, at the trainer's
    /// sample directions.
    #[arg(value_name = "TABLE.binary|MEASUREMENT.bsdf")]
    pub table: PathBuf,
    /// Where to write the network; defaults to TABLE's name with .nbrdf.json in the current
    /// directory.
    #[arg(short, long, value_name = "NAME.nbrdf.json")]
    pub output: Option<PathBuf>,
    /// How training directions are drawn.
    #[arg(long, value_enum, default_value_t = SamplingArg::Adaptive)]
    pub sampling: SamplingArg,
    /// How the table folds phi_d: reciprocal for MERL tables, mirror for non-reciprocal ones
    /// tabulated with `tabulate_rgl --phi-fold mirror`.
    #[arg(long, value_enum, default_value_t = PhiFoldArg::Reciprocal)]
    pub phi_fold: PhiFoldArg,
    /// How an RGL measurement's non-reciprocity enters the target (measurements only).
    #[arg(long, value_enum, default_value_t = RglFoldArg::AsMeasured)]
    pub rgl_fold: RglFoldArg,
    /// Training samples (invalid cells and directions below the horizon are not counted);
    /// 10% more are drawn for validation. At most 1e8.
    #[arg(long, default_value_t = TrainConfig::default().samples,
          value_parser = count_in::<1, MAX_SAMPLES>)]
    pub samples: usize,
    /// Maximum number of epochs (at most 1e6).
    #[arg(long, default_value_t = TrainConfig::default().max_epochs,
          value_parser = count_in::<1, MAX_EPOCHS>)]
    pub epochs: usize,
    /// Width of the two hidden layers (at most 4096; the traced Mitsuba backend is slow beyond a
    /// few hundred).
    #[arg(long, default_value_t = TrainConfig::default().hidden,
          value_parser = count_in::<1, MAX_HIDDEN>)]
    pub hidden: usize,
    /// Adam learning rate.
    #[arg(long, default_value_t = AdamConfig::default().learning_rate)]
    pub lr: f32,
    /// Mini-batch size (at most 2^20; with the width, within the 8 GiB memory estimate).
    #[arg(long, default_value_t = TrainConfig::default().batch,
          value_parser = count_in::<1, MAX_BATCH>)]
    pub batch: usize,
    /// Stop after this many epochs without a 0.1% improvement of the validation loss (the best
    /// weights are kept).
    #[arg(long, default_value_t = TrainConfig::default().patience)]
    pub patience: usize,
    /// Never stop early before this many epochs (stiff materials can plateau for a while first).
    #[arg(long, default_value_t = TrainConfig::default().min_epochs)]
    pub min_epochs: usize,
    /// Relative validation improvement that resets the patience.
    #[arg(long, default_value_t = TrainConfig::default().min_improvement)]
    pub min_improvement: f64,
    /// When the patience runs out, multiply the learning rate by --lr-decay-factor and go on,
    /// up to this many times, before stopping (0: the paper's constant rate).
    #[arg(long, default_value_t = TrainConfig::default().lr_decays)]
    pub lr_decays: usize,
    /// Factor of each learning-rate drop, in (0, 1).
    #[arg(long, default_value_t = TrainConfig::default().lr_decay_factor)]
    pub lr_decay_factor: f32,
    /// Random seed; a seed gives the same network whatever the thread count.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Worker threads (default: one per core).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Name stored in the network file (default: TABLE's file name without extension).
    #[arg(long)]
    pub name: Option<String>,
    /// No progress bar (it is also hidden when stderr is not a terminal).
    #[arg(short, long)]
    pub quiet: bool,
}

pub fn run_train(args: &TrainArgs) -> Result<()> {
    let config = TrainConfig {
        sampling: args.sampling.into(),
        samples: args.samples,
        max_epochs: args.epochs,
        hidden: args.hidden,
        batch: args.batch,
        adam: AdamConfig {
            learning_rate: args.lr,
            ..AdamConfig::default()
        },
        patience: args.patience,
        min_epochs: args.min_epochs,
        min_improvement: args.min_improvement,
        lr_decays: args.lr_decays,
        lr_decay_factor: args.lr_decay_factor,
        seed: args.seed,
        ..TrainConfig::default()
    };
    let bar = progress::epoch_bar(config.max_epochs, args.quiet)?;
    bar.set_message("drawing samples");
    let request = TrainRequest {
        source: args.table.clone(),
        phi_fold: args.phi_fold.into(),
        rgl_fold: args.rgl_fold.into(),
        output: args.output.clone(),
        name: args.name.clone(),
        config,
        threads: args.threads,
    };
    let report = train_network(&request, &mut |e: &EpochStats| {
        bar.set_position(e.epoch as u64);
        bar.set_message(format!(
            "train {:.3e}  val {:.3e}  best {:.3e} @ {}",
            e.train_loss, e.validation_loss, e.best_validation_loss, e.best_epoch
        ));
    });
    bar.finish_and_clear();
    emit(&report?.to_string())
}
