//! `nbrdf ae train|encode|decode|eval` and `nbrdf interpolate`.

use super::pretrained::{self, Messages, RelearnArgs};
use super::{emit, progress};
use clap::{Args, Subcommand};
use indicatif::ProgressBar;
use nbrdf_core::latent::autoencoder::{AeConfig, AeEpoch};
use nbrdf_core::ops::autoencoder::{
    self as ops_ae, AeEvalRequest, AeTrainObserver, AeTrainRequest, PcaTables as Tables, SplitPart,
};
use nbrdf_core::ops::limits::{MAX_EPOCHS, MAX_HIDDEN};
use nbrdf_core::ops::to_json_pretty;
use nbrdf_core::{NbrdfError, Result};
use std::path::PathBuf;

#[derive(Subcommand)]
pub enum AeCommand {
    /// Train the autoencoder on a directory of NAME.nbrdf.json files (fixed 80/20 split).
    Train(AeTrainArgs),
    /// Print the 32-value code of a network as a JSON array.
    Encode(AeEncodeArgs),
    /// Decode a code (a JSON array file) into a network.
    Decode(AeDecodeArgs),
    /// Reconstruct the test split with the autoencoder and with PCA-32; image errors as JSON.
    Eval(AeEvalArgs),
}

#[derive(Args)]
pub struct AeTrainArgs {
    /// Directory of NAME.nbrdf.json networks (one per material, all of one hidden width).
    #[arg(long, value_name = "DIR")]
    nbrdfs: PathBuf,
    /// Where to write the result.
    #[arg(short, long, value_name = "AE.json")]
    output: PathBuf,
    /// Random seed (training is deterministic per seed).
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Train this many autoencoders (seeds SEED, SEED + 1, ...) and keep the one whose refined
    /// codes reconstruct the validation materials best (held-out training materials, never
    /// the test split). Results vary with the seed; this makes them far less of a draw.
    #[arg(long, default_value_t = 1)]
    seeds: u64,
    /// Refinement iterations of that choice.
    #[arg(long, default_value_t = 30)]
    select_refine: usize,
    /// Epoch limit (early stopping usually ends sooner; at most 1e6).
    #[arg(long, default_value_t = AeConfig::default().max_epochs,
          value_parser = super::count_in::<1, { MAX_EPOCHS }>)]
    epochs: usize,
    /// Epochs of weight-space warm start before the image loss.
    #[arg(long, default_value_t = AeConfig::default().warmup_epochs)]
    warmup: usize,
    /// Early-stopping patience in epochs.
    #[arg(long, default_value_t = AeConfig::default().patience)]
    patience: usize,
    /// Width of the encoder's and decoder's hidden layer (at most 4096).
    #[arg(long, default_value_t = AeConfig::default().hidden,
          value_parser = super::count_in::<1, { MAX_HIDDEN }>)]
    hidden: usize,
    /// Adam learning rate.
    #[arg(long, default_value_t = AeConfig::default().learning_rate)]
    lr: f32,
    /// Learning rate of the image-loss phase.
    #[arg(long, default_value_t = AeConfig::default().image_learning_rate)]
    image_lr: f32,
    /// Gaussian noise on the standardised encoder input (denoising regulariser).
    #[arg(long, default_value_t = AeConfig::default().input_noise)]
    input_noise: f32,
    #[arg(long, default_value_t = AeConfig::default().weight_decay)]
    weight_decay: f32,
    /// More networks of the training split's materials (e.g. trained from another source of
    /// the same materials): extra training examples. Networks of validation and test materials
    /// in it are ignored, so nothing of a held-out material is seen.
    #[arg(long, value_name = "DIR")]
    extra_nbrdfs: Option<PathBuf>,
    /// Half width of a second loss image zoomed on the highlight (0: the sphere alone, the
    /// paper's loss): lets the codes hold the sharpness of lobes finer than the sphere's pixels.
    #[arg(long, default_value_t = AeConfig::default().highlight_zoom)]
    highlight_zoom: f32,
    /// Weight of the auxiliary lobe loss (0: the paper's image loss alone): a linear head on
    /// the code regresses each training material's fitted sampling lobe (ln n, w; from the
    /// networks' "fit" sampling, or fitted here), so that codes hold the lobe's sharpness.
    #[arg(long, default_value_t = AeConfig::default().lobe_weight)]
    lobe_weight: f32,
    /// Extra examples per epoch mixed in weight space from two random training examples
    /// (0: none). The networks share one initialisation, so mixtures are plausible materials
    /// between the two; they fill the decoder's manifold between the training materials.
    #[arg(long, default_value_t = AeConfig::default().mixup)]
    mixup: usize,
    /// Disable the 6 RGB-permutation augmentation.
    #[arg(long)]
    no_augment: bool,
    /// Worker threads (default: one per core).
    #[arg(long)]
    threads: Option<usize>,
    /// No progress bar.
    #[arg(long)]
    quiet: bool,
}

#[derive(Args)]
pub struct AeEncodeArgs {
    /// The autoencoder (from `nbrdf ae train`; default: the built-in one).
    #[arg(long, value_name = "AE.json")]
    ae: Option<PathBuf>,
    /// The neural BRDF to read.
    #[arg(value_name = "NBRDF.json")]
    input: PathBuf,
    /// Print the encoding time to stderr.
    #[arg(long)]
    timing: bool,
    /// Refine the encoder's code by this many Levenberg-Marquardt iterations on the image
    /// loss against the network's own sphere image (analysis by synthesis).
    #[arg(long, default_value_t = 0)]
    refine: usize,
    #[command(flatten)]
    relearn: RelearnArgs,
}

#[derive(Args)]
pub struct AeDecodeArgs {
    /// The autoencoder (from `nbrdf ae train`; default: the built-in one).
    #[arg(long, value_name = "AE.json")]
    ae: Option<PathBuf>,
    /// The latent code: a JSON array of 32 numbers (from `nbrdf ae encode`).
    #[arg(value_name = "CODE.json")]
    code: PathBuf,
    /// Where to write the result.
    #[arg(short, long, value_name = "NBRDF.json")]
    output: PathBuf,
    /// Name of the decoded material (default: the output file's stem).
    #[arg(long)]
    name: Option<String>,
}

#[derive(Args)]
pub struct InterpolateArgs {
    /// The autoencoder (from `nbrdf ae train`; default: the built-in one).
    #[arg(long, value_name = "AE.json")]
    ae: Option<PathBuf>,
    /// The first material (a neural BRDF).
    #[arg(value_name = "A.json")]
    a: PathBuf,
    /// The second material (a neural BRDF).
    #[arg(value_name = "B.json")]
    b: PathBuf,
    /// Number of networks per path, endpoints included.
    #[arg(long, default_value_t = 7)]
    steps: usize,
    /// Refine the endpoint codes by this many iterations (`ae encode --refine`), so that the
    /// latent path starts and ends at faithful reconstructions of A and B.
    #[arg(long, default_value_t = 0)]
    refine: usize,
    /// Where to write the result.
    #[arg(short, long, value_name = "DIR")]
    output: PathBuf,
    #[command(flatten)]
    relearn: RelearnArgs,
}

#[derive(Clone, Copy, clap::ValueEnum)]
pub enum PcaTables {
    /// The SGD fits of the MERL materials tabulated at cell centres (`nbrdf synth --model sgd`).
    Sgd,
    /// The input networks themselves tabulated at cell centres (like for like with the AE).
    Nbrdf,
}

#[derive(Clone, Copy, PartialEq, clap::ValueEnum)]
pub enum SplitArg {
    Test,
    Train,
    /// The training materials held out of the autoencoder's updates (early stopping): unseen
    /// by its weights, so they can choose between autoencoders without touching the test split.
    Validation,
}

#[derive(Args)]
pub struct AeEvalArgs {
    /// The autoencoder (from `nbrdf ae train`; default: the built-in one).
    #[arg(long, value_name = "AE.json")]
    ae: Option<PathBuf>,
    /// The networks the autoencoder was trained on.
    #[arg(long, value_name = "DIR")]
    nbrdfs: PathBuf,
    /// Which tables the PCA-32 baseline decomposes.
    #[arg(long, value_enum, default_value = "sgd")]
    pca_tables: PcaTables,
    /// Principal components kept.
    #[arg(long, default_value_t = 32)]
    components: usize,
    /// Which materials to reconstruct: the test split (the comparison) or the training split
    /// (how well the autoencoder fits what it saw; PCA then reconstructs its own training set).
    #[arg(long, value_enum, default_value = "test")]
    split: SplitArg,
    /// Also report the autoencoder with codes refined by this many iterations
    /// (`ae encode --refine`), as "ae_refined".
    #[arg(long, default_value_t = 0)]
    refine: usize,
    /// Worker threads (default: one per core).
    #[arg(long)]
    threads: Option<usize>,
}

impl From<PcaTables> for Tables {
    fn from(t: PcaTables) -> Self {
        match t {
            PcaTables::Sgd => Tables::Sgd,
            PcaTables::Nbrdf => Tables::Nbrdf,
        }
    }
}

impl From<SplitArg> for SplitPart {
    fn from(s: SplitArg) -> Self {
        match s {
            SplitArg::Test => SplitPart::Test,
            SplitArg::Train => SplitPart::Train,
            SplitArg::Validation => SplitPart::Validation,
        }
    }
}

pub fn run_ae(command: AeCommand) -> Result<()> {
    match command {
        AeCommand::Train(a) => run_ae_train(&a),
        AeCommand::Encode(a) => run_ae_encode(&a),
        AeCommand::Decode(a) => run_ae_decode(&a),
        AeCommand::Eval(a) => run_ae_eval(&a),
    }
}

/// The progress of `ae train`: a bar per seed, epoch lines where no bar can be drawn, and the
/// score of each seed.
struct Progress {
    quiet: bool,
    bar: Option<ProgressBar>,
    error: Option<NbrdfError>,
}

impl AeTrainObserver for Progress {
    fn seed_started(&mut self, seed: u64, max_epochs: usize, several: bool) {
        match progress::epoch_bar(max_epochs, self.quiet) {
            Ok(bar) => {
                if several {
                    bar.set_prefix(format!("seed {seed} "));
                }
                self.bar = Some(bar);
            }
            Err(e) => self.error = Some(e),
        }
    }

    fn epoch(&mut self, e: &AeEpoch) {
        let Some(bar) = &self.bar else { return };
        bar.set_position(e.epoch as u64 + 1);
        if !self.quiet && bar.is_hidden() {
            eprintln!(
                "epoch {:>3} {} loss {:.4e} validation image loss {:.4e} ({:.1} s)",
                e.epoch, e.phase, e.train_loss, e.validation_image_loss, e.seconds
            );
        }
        bar.set_message(format!(
            "{} loss {:.3e}, validation image loss {:.3e}",
            e.phase, e.train_loss, e.validation_image_loss
        ));
    }

    fn seed_finished(&mut self) {
        if let Some(bar) = self.bar.take() {
            bar.finish_and_clear();
        }
    }

    fn seed_scored(&mut self, seed: u64, loss: f64) {
        if !self.quiet {
            eprintln!("seed {seed}: refined validation image loss {loss:.4e}");
        }
    }
}

fn run_ae_train(args: &AeTrainArgs) -> Result<()> {
    let request = AeTrainRequest {
        nbrdfs: args.nbrdfs.clone(),
        extra_nbrdfs: args.extra_nbrdfs.clone(),
        output: args.output.clone(),
        config: AeConfig {
            seed: args.seed,
            hidden: args.hidden,
            max_epochs: args.epochs,
            warmup_epochs: args.warmup,
            patience: args.patience,
            learning_rate: args.lr,
            image_learning_rate: args.image_lr,
            input_noise: args.input_noise,
            weight_decay: args.weight_decay,
            augment: !args.no_augment,
            highlight_zoom: args.highlight_zoom,
            lobe_weight: args.lobe_weight,
            mixup: args.mixup,
            ..AeConfig::default()
        },
        seeds: args.seeds,
        select_refine: args.select_refine,
        threads: args.threads,
    };
    // The bar's template is checked before any work, as it always was.
    progress::epoch_bar(0, true)?;
    let mut observer = Progress {
        quiet: args.quiet,
        bar: None,
        error: None,
    };
    let report = ops_ae::train_autoencoder(&request, &mut observer);
    if let Some(e) = observer.error {
        return Err(e);
    }
    emit(&report?.to_string())
}

fn run_ae_encode(args: &AeEncodeArgs) -> Result<()> {
    let ae = pretrained::autoencoder(args.ae.as_deref())?;
    let encoded = ops_ae::encode(
        &ae,
        &args.input,
        args.refine,
        &mut pretrained::encoding(&args.relearn, &mut Messages),
    )?;
    if args.timing {
        eprintln!("encoded in {:.3} ms", encoded.milliseconds);
    }
    let text = serde_json::to_string(&encoded.code)
        .map_err(|e| NbrdfError::InvalidArgument(e.to_string()))?;
    emit(&format!("{text}\n"))
}

fn run_ae_decode(args: &AeDecodeArgs) -> Result<()> {
    let ae = pretrained::autoencoder(args.ae.as_deref())?;
    ops_ae::decode(&ae, &args.code, &args.output, args.name.as_deref())?;
    emit(&format!("wrote {}\n", args.output.display()))
}

pub fn run_interpolate(args: &InterpolateArgs) -> Result<()> {
    let ae = pretrained::autoencoder(args.ae.as_deref())?;
    ops_ae::interpolate(
        &ae,
        (&args.a, &args.b),
        args.steps,
        args.refine,
        &args.output,
        &mut pretrained::encoding(&args.relearn, &mut Messages),
    )?;
    emit(&format!(
        "wrote {} latent_NN and weights_NN networks to {}\n",
        args.steps,
        args.output.display()
    ))
}

/// `nbrdf ae eval`: AE and PCA reconstructions of the test split in image space, as JSON.
fn run_ae_eval(args: &AeEvalArgs) -> Result<()> {
    let ae = pretrained::autoencoder(args.ae.as_deref())?;
    let report = ops_ae::evaluate_autoencoder(
        &ae,
        &AeEvalRequest {
            nbrdfs: args.nbrdfs.clone(),
            pca_tables: args.pca_tables.into(),
            components: args.components,
            split: args.split.into(),
            refine: args.refine,
            threads: args.threads,
        },
    )?;
    emit(&to_json_pretty(&report)?)
}
