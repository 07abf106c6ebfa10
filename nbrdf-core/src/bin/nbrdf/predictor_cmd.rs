//! `nbrdf predictor train|eval` and `nbrdf predict-phong`.

use super::emit;
use super::pretrained::{self, Messages, RelearnArgs};
use clap::{Args, Subcommand};
use nbrdf_core::latent::predictor::PredictorConfig;
use nbrdf_core::ops::predictor::{self as ops_pred, PredictorLoss as Loss, PredictorTrainRequest};
use nbrdf_core::ops::to_json_pretty;
use nbrdf_core::Result;
use std::path::PathBuf;

#[derive(Subcommand)]
pub enum PredictorCommand {
    /// Train the Phong-parameter predictor on the codes of the training split.
    Train(PredictorTrainArgs),
    /// Fitted vs predicted lobes of the test split, scored by the relative variance of BSDF
    /// sampling (the quantity `fit-phong` minimises), as JSON.
    Eval(PredictorEvalArgs),
}

#[derive(Clone, Copy, PartialEq, clap::ValueEnum)]
pub enum PredictorLoss {
    /// The relative variance of sampling with the predicted lobe over that of the fitted one
    /// (the objective `fit-phong` minimises), with a small pull towards the labels.
    Variance,
    /// Squared error of (ln n, w) against the fitted labels.
    Labels,
}

#[derive(Args)]
pub struct PredictorTrainArgs {
    /// The autoencoder (from `nbrdf ae train`; default: the built-in one).
    #[arg(long, value_name = "AE.json")]
    ae: Option<PathBuf>,
    /// The networks of the training split (with or without fitted sampling parameters).
    #[arg(long, value_name = "DIR")]
    nbrdfs: PathBuf,
    /// Where to write the result.
    #[arg(short, long, value_name = "P.json")]
    output: PathBuf,
    /// Width of the hidden layer (0: a linear map from the code).
    #[arg(long, default_value_t = PredictorConfig::default().hidden)]
    hidden: usize,
    /// Full-batch Adam iterations.
    #[arg(long, default_value_t = PredictorConfig::default().iterations)]
    iterations: usize,
    /// L2 penalty on the weights (a regulariser: 80 labelled materials).
    #[arg(long, default_value_t = PredictorConfig::default().weight_decay)]
    weight_decay: f32,
    /// Random seed (training is deterministic per seed).
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Refit the Blinn-Phong labels even where a file has "source": "fit" sampling.
    #[arg(long)]
    refit: bool,
    /// Training loss.
    #[arg(long, value_enum, default_value = "variance")]
    loss: PredictorLoss,
    /// More labelled networks of the training split's materials (e.g. from another source of
    /// the same materials); networks of test materials in it are ignored.
    #[arg(long, value_name = "DIR")]
    extra_nbrdfs: Option<PathBuf>,
    /// Networks in the ensemble (seeds SEED, SEED + 1, ...; the prediction is their mean).
    #[arg(long, default_value_t = PredictorConfig::default().members)]
    members: usize,
    /// Before training, report K-fold cross-validation over the training split's materials
    /// (held-out sampling RMSE ratio, as `predictor eval`): a way to choose settings without
    /// looking at the test split. 0: off.
    #[arg(long, default_value_t = 0, value_name = "K")]
    cross_validate: usize,
    /// Predict from the 32-value code alone (docs/design.md section 7), without the network's
    /// highlight profile (27 evaluations along theta_h). The code cannot hold peaks sharper
    /// than the autoencoder's 64 x 64 sphere resolves (README); the settings the code alone
    /// did best with were `--hidden 0 --weight-decay 0.01`.
    #[arg(long)]
    code_only: bool,
    /// Predict from codes refined by this many iterations (`ae encode --refine`).
    /// Recorded in P.json; `predict-phong` and `predictor eval` refine the same way. Off by
    /// default: refined codes fit the image better but predicted worse lobes (README).
    #[arg(long, default_value_t = 0)]
    refine: usize,
    /// Worker threads (default: one per core).
    #[arg(long)]
    threads: Option<usize>,
}

#[derive(Args)]
pub struct PredictorEvalArgs {
    /// The autoencoder (from `nbrdf ae train`; default: the built-in one).
    #[arg(long, value_name = "AE.json")]
    ae: Option<PathBuf>,
    /// The predictor (from `nbrdf predictor train`; default: the built-in one, which reads
    /// the built-in autoencoder's codes: --ae needs --predictor).
    #[arg(long, value_name = "P.json")]
    predictor: Option<PathBuf>,
    /// The networks (the test split is read from the autoencoder).
    #[arg(long, value_name = "DIR")]
    nbrdfs: PathBuf,
    /// Worker threads (default: one per core).
    #[arg(long)]
    threads: Option<usize>,
}

#[derive(Args)]
pub struct PredictPhongArgs {
    /// The autoencoder (from `nbrdf ae train`; default: the built-in one).
    #[arg(long, value_name = "AE.json")]
    ae: Option<PathBuf>,
    /// The predictor (from `nbrdf predictor train`; default: the built-in one, which reads
    /// the built-in autoencoder's codes: --ae needs --predictor).
    #[arg(long, value_name = "P.json")]
    predictor: Option<PathBuf>,
    /// The neural BRDF to read.
    #[arg(value_name = "NBRDF.json")]
    input: PathBuf,
    /// Where to write the network with the predicted sampling (default: in place).
    #[arg(short, long)]
    output: Option<PathBuf>,
    /// Print the encode + predict time to stderr.
    #[arg(long)]
    timing: bool,
    #[command(flatten)]
    relearn: RelearnArgs,
}

impl From<PredictorLoss> for Loss {
    fn from(l: PredictorLoss) -> Self {
        match l {
            PredictorLoss::Variance => Loss::Variance,
            PredictorLoss::Labels => Loss::Labels,
        }
    }
}

pub fn run_predictor(command: PredictorCommand) -> Result<()> {
    match command {
        PredictorCommand::Train(a) => run_predictor_train(&a),
        PredictorCommand::Eval(a) => run_predictor_eval(&a),
    }
}

fn run_predictor_train(args: &PredictorTrainArgs) -> Result<()> {
    let ae = pretrained::autoencoder(args.ae.as_deref())?;
    let report = ops_pred::train_predictor(
        &ae,
        &PredictorTrainRequest {
            nbrdfs: args.nbrdfs.clone(),
            extra_nbrdfs: args.extra_nbrdfs.clone(),
            output: args.output.clone(),
            config: PredictorConfig {
                hidden: args.hidden,
                iterations: args.iterations,
                seed: args.seed,
                members: args.members,
                weight_decay: args.weight_decay,
            },
            loss: args.loss.into(),
            refit: args.refit,
            cross_validate: args.cross_validate,
            code_only: args.code_only,
            refine: args.refine,
            threads: args.threads,
        },
    )?;
    emit(&report.to_string())
}

fn run_predictor_eval(args: &PredictorEvalArgs) -> Result<()> {
    let (ae, predictor) = pretrained::models(args.ae.as_deref(), args.predictor.as_deref())?;
    let report = ops_pred::evaluate_predictor(&ae, &predictor, &args.nbrdfs, args.threads)?;
    emit(&to_json_pretty(&report)?)
}

pub fn run_predict_phong(args: &PredictPhongArgs) -> Result<()> {
    let (ae, predictor) = pretrained::models(args.ae.as_deref(), args.predictor.as_deref())?;
    let report = ops_pred::predict_phong(
        &ae,
        &predictor,
        &args.input,
        args.output.as_deref(),
        &mut pretrained::encoding(&args.relearn, &mut Messages),
    )?;
    if args.timing {
        eprintln!("encoded and predicted in {:.3} ms", report.milliseconds);
    }
    emit(&report.to_string())
}
