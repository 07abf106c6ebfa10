//! `nbrdf train`.

use super::{count_in, emit, progress, PhiFoldArg};
use clap::{Args, ValueEnum};
use nbrdf_core::ops::limits::{MAX_BATCH, MAX_EPOCHS, MAX_HIDDEN, MAX_SAMPLES};
use nbrdf_core::ops::train_network::{train_network, NetworkKind, TrainRequest};
use nbrdf_core::source::RglFold;
use nbrdf_core::train::adam::AdamConfig;
use nbrdf_core::train::dataset::AngularSampling;
use nbrdf_core::train::{Anisotropy, EpochStats, LrSchedule, TrainConfig};
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
pub enum AnisotropyArg {
    /// Anisotropic exactly when the source is (an anisotropic RGL measurement); MERL tables and
    /// isotropic measurements give the paper's isotropic network.
    Auto,
    /// Always an anisotropic network (input with phi_h, file format version 2).
    On,
    /// Always an isotropic network (phi_h = 0, format version 1).
    Off,
}

impl From<AnisotropyArg> for Anisotropy {
    fn from(a: AnisotropyArg) -> Self {
        match a {
            AnisotropyArg::Auto => Anisotropy::Auto,
            AnisotropyArg::On => Anisotropy::On,
            AnisotropyArg::Off => Anisotropy::Off,
        }
    }
}

#[derive(Clone, Copy, ValueEnum)]
pub enum OutputKindArg {
    /// Spectral for a spectral measurement (*_spec.bsdf), RGB otherwise.
    Auto,
    /// An RGB network; of a spectral measurement, its linear sRGB projection under D65.
    Rgb,
    /// A spectral network (format version 3: 16 B-spline coefficients over 360-830 nm); only
    /// from a spectral measurement.
    Spectral,
}

impl From<OutputKindArg> for NetworkKind {
    fn from(k: OutputKindArg) -> Self {
        match k {
            OutputKindArg::Auto => NetworkKind::Auto,
            OutputKindArg::Rgb => NetworkKind::Rgb,
            OutputKindArg::Spectral => NetworkKind::Spectral,
        }
    }
}

#[derive(Clone, Copy, ValueEnum)]
pub enum LrScheduleArg {
    /// The learning rate as given throughout (with drops on plateaus, --lr-decays).
    Constant,
    /// A one-epoch warm-up, then a half cosine down to 1 % of the rate at --epochs.
    Cosine,
}

impl From<LrScheduleArg> for LrSchedule {
    fn from(s: LrScheduleArg) -> Self {
        match s {
            LrScheduleArg::Constant => LrSchedule::Constant,
            LrScheduleArg::Cosine => LrSchedule::COSINE,
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
    /// sample directions; a spectral one (*_spec.bsdf) at its own wavelengths (a spectral
    /// network; --output-kind rgb learns its linear sRGB projection under D65 instead).
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
    /// 10% more are drawn for validation. At most 1e8 [default: 800000; 5x that, 4000000, for
    /// an anisotropic network].
    #[arg(long, value_parser = count_in::<1, MAX_SAMPLES>)]
    pub samples: Option<usize>,
    /// Isotropic network (the paper's, phi_h = 0) or anisotropic one (input with the half
    /// vector's azimuth phi_h, format version 2): auto follows the source (anisotropic RGL
    /// measurements give anisotropic networks; MERL tables are isotropic).
    #[arg(long, value_enum, default_value_t = AnisotropyArg::Auto)]
    pub anisotropy: AnisotropyArg,
    /// RGB or spectral network: auto makes a spectral one (format version 3) of a spectral
    /// measurement, an RGB one otherwise; spectral of an RGB source is an error.
    #[arg(long, value_enum, default_value_t = OutputKindArg::Auto)]
    pub output_kind: OutputKindArg,
    /// Maximum number of epochs (at most 1e6) [default: 300; 100 with --fixed-budget].
    #[arg(long, value_parser = count_in::<1, MAX_EPOCHS>)]
    pub epochs: Option<usize>,
    /// Width of the two hidden layers (at most 4096; the traced Mitsuba backend is slow beyond a
    /// few hundred).
    #[arg(long, default_value_t = TrainConfig::default().hidden,
          value_parser = count_in::<1, MAX_HIDDEN>)]
    pub hidden: usize,
    /// Adam learning rate [default: 1e-3; the paper's 5e-4 with --fixed-budget].
    #[arg(long)]
    pub lr: Option<f32>,
    /// Mini-batch size (at most 2^20; with the width, within the 8 GiB memory estimate).
    #[arg(long, default_value_t = TrainConfig::default().batch,
          value_parser = count_in::<1, MAX_BATCH>)]
    pub batch: usize,
    /// Epochs without a --min-improvement of the validation loss before the learning rate drops
    /// or, after --lr-decays drops, training stops (the best weights are kept) [default: 20; 10
    /// with --fixed-budget].
    #[arg(long)]
    pub patience: Option<usize>,
    /// Never stop early before this many epochs (stiff materials can plateau for a while first)
    /// [default: 30].
    #[arg(long)]
    pub min_epochs: Option<usize>,
    /// Relative validation improvement that resets the patience [default: 0.001].
    #[arg(long)]
    pub min_improvement: Option<f64>,
    /// When the patience runs out, multiply the learning rate by --lr-decay-factor and go on,
    /// up to this many times, before stopping [default: 2; 0, the paper's constant rate, with
    /// --fixed-budget].
    #[arg(long)]
    pub lr_decays: Option<usize>,
    /// Factor of each learning-rate drop, in (0, 1) [default: 0.2].
    #[arg(long)]
    pub lr_decay_factor: Option<f32>,
    /// How the learning rate moves within the run [default: the defaults' schedule; constant
    /// with --fixed-budget].
    #[arg(long, value_enum)]
    pub lr_schedule: Option<LrScheduleArg>,
    /// Stop (after --min-epochs) once the validation loss, the mean |ln(1 + f cos)| error, is at
    /// most this: simple materials get there in tens of epochs [default: 2e-4; 0 (off) with
    /// --fixed-budget].
    #[arg(long)]
    pub target_loss: Option<f64>,
    /// Start from the paper's fixed budget, the defaults before 0.2 (learning rate 5e-4, at most
    /// 100 epochs, patience 10, no learning-rate drops, no target loss) instead of the adaptive
    /// one; options given explicitly still apply.
    #[arg(long)]
    pub fixed_budget: bool,
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

/// The defaults (adaptive or fixed budget) with the options given on the command line.
pub fn train_config(args: &TrainArgs) -> TrainConfig {
    let base = if args.fixed_budget {
        TrainConfig::fixed_budget()
    } else {
        TrainConfig::default()
    };
    TrainConfig {
        sampling: args.sampling.into(),
        samples: args.samples.unwrap_or(base.samples),
        max_epochs: args.epochs.unwrap_or(base.max_epochs),
        hidden: args.hidden,
        batch: args.batch,
        adam: AdamConfig {
            learning_rate: args.lr.unwrap_or(base.adam.learning_rate),
            ..base.adam
        },
        patience: args.patience.unwrap_or(base.patience),
        min_epochs: args.min_epochs.unwrap_or(base.min_epochs),
        min_improvement: args.min_improvement.unwrap_or(base.min_improvement),
        lr_decays: args.lr_decays.unwrap_or(base.lr_decays),
        lr_decay_factor: args.lr_decay_factor.unwrap_or(base.lr_decay_factor),
        lr_schedule: args.lr_schedule.map_or(base.lr_schedule, Into::into),
        target_loss: args.target_loss.unwrap_or(base.target_loss),
        seed: args.seed,
        ..base
    }
}

pub fn run_train(args: &TrainArgs) -> Result<()> {
    let config = train_config(args);
    let bar = progress::epoch_bar(config.max_epochs, args.quiet)?;
    bar.set_message("drawing samples");
    let request = TrainRequest {
        source: args.table.clone(),
        phi_fold: args.phi_fold.into(),
        rgl_fold: args.rgl_fold.into(),
        output: args.output.clone(),
        name: args.name.clone(),
        config,
        anisotropy: args.anisotropy.into(),
        network_kind: args.output_kind.into(),
        scale_samples: args.samples.is_none(),
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
