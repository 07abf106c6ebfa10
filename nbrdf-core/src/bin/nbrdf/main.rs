//! The `nbrdf` command-line tool (feature `cli`).
//!
//! One variant of [`Command`] per subcommand, each with its own argument struct and `run_*`
//! function: it turns the arguments into the settings of one library function of
//! [`nbrdf_core::ops`], calls it and prints its report. `main` alone turns errors into
//! `error: ...` on stderr and an exit status: 2 for usage errors (clap's convention: bad or
//! missing arguments, options out of their range, [`NbrdfError::Usage`]), 1 for failures (I/O,
//! file formats, data).

use clap::{Args, Parser, Subcommand, ValueEnum};
use nbrdf_core::analytic::ModelKind;
use nbrdf_core::fit::lobes::LobeChoice;
use nbrdf_core::fit::phong::FitConfig;
use nbrdf_core::merl::PhiFold;
use nbrdf_core::ops::{self, catalogue, compare, fit_phong, limits, table};
use nbrdf_core::{NbrdfError, Result};
use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;

mod ae_cmd;
mod predictor_cmd;
mod pretrained;
mod progress;
#[cfg(test)]
mod tests;
mod train_cmd;

#[derive(Parser)]
#[command(
    name = "nbrdf",
    version,
    about = "Neural BRDFs: synthesise, train, fit and compare measured materials"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// List the 100 MERL material names of the embedded SGD and ABC fits.
    ListMaterials(ListMaterialsArgs),
    /// Tabulate an analytic fit of a MERL material into a MERL-format table (.binary).
    Synth(SynthArgs),
    /// Tabulate a neural BRDF on the MERL grid into a MERL-format table (.binary).
    Tabulate(TabulateArgs),
    /// Validate a MERL-format table and print per-channel reflectance statistics.
    Info(InfoArgs),
    /// Train a neural BRDF on a MERL-format table or an RGL measurement, write NAME.nbrdf.json.
    Train(train_cmd::TrainArgs),
    /// Fit the Blinn-Phong sampling lobe (exponent, specular weight) to a table or a network.
    FitPhong(FitPhongArgs),
    /// Compare two materials (tables or networks): sphere images and log-space BRDF error.
    Compare(CompareArgs),
    /// The NBRDF autoencoder: train, encode, decode.
    #[command(subcommand)]
    Ae(ae_cmd::AeCommand),
    /// Interpolate two networks in the autoencoder's latent space and in weight space.
    Interpolate(ae_cmd::InterpolateArgs),
    /// The predictor of Blinn-Phong sampling parameters from autoencoder codes.
    #[command(subcommand)]
    Predictor(predictor_cmd::PredictorCommand),
    /// Predict a network's Blinn-Phong sampling parameters from its code (source "predicted").
    PredictPhong(predictor_cmd::PredictPhongArgs),
}

#[derive(Args)]
struct ListMaterialsArgs {
    /// Print a JSON array of {"name", "alias"} objects instead of one name per line.
    #[arg(long)]
    json: bool,
}

#[derive(Clone, Copy, ValueEnum)]
enum ModelArg {
    /// Shifted gamma distribution fits (Bagher et al. 2012).
    Sgd,
    /// ABC fits (Löw et al. 2012).
    Abc,
}

impl From<ModelArg> for ModelKind {
    fn from(m: ModelArg) -> Self {
        match m {
            ModelArg::Sgd => ModelKind::Sgd,
            ModelArg::Abc => ModelKind::Abc,
        }
    }
}

#[derive(Args)]
struct SynthArgs {
    /// Which published analytic model to tabulate.
    #[arg(long, value_enum)]
    model: ModelArg,
    /// MERL material name or alias (see `nbrdf list-materials`).
    #[arg(long)]
    material: String,
    /// Where to write the table; defaults to MATERIAL.binary in the current directory.
    #[arg(short, long, value_name = "OUT.binary")]
    output: Option<PathBuf>,
}

#[derive(Args)]
struct TabulateArgs {
    /// The neural BRDF to tabulate (e.g. one of the authors' networks after import).
    #[arg(value_name = "NBRDF.json")]
    network: PathBuf,
    /// Where to write the table; defaults to NAME.binary in the current directory.
    #[arg(short, long, value_name = "OUT.binary")]
    output: Option<PathBuf>,
    /// Worker threads (default: one per core).
    #[arg(long)]
    threads: Option<usize>,
}

#[derive(Args)]
struct InfoArgs {
    /// The MERL-format table to inspect.
    #[arg(value_name = "FILE.binary")]
    file: PathBuf,
}

#[derive(Clone, Copy, Default, ValueEnum)]
pub(crate) enum PhiFoldArg {
    /// MERL's convention: phi_d + pi is the same cell (swapping light and view, reciprocity).
    #[default]
    Reciprocal,
    /// 2 pi - phi_d is the same cell (mirror symmetry): tables of non-reciprocal measurements
    /// written by `python -m nbrdf_mitsuba.tabulate_rgl --phi-fold mirror`.
    Mirror,
}

impl From<PhiFoldArg> for PhiFold {
    fn from(f: PhiFoldArg) -> Self {
        match f {
            PhiFoldArg::Reciprocal => PhiFold::Reciprocal,
            PhiFoldArg::Mirror => PhiFold::Mirror,
        }
    }
}

#[derive(Clone, Copy, PartialEq, Eq, ValueEnum)]
enum LobeArg {
    Variance,
    Model,
}

impl From<LobeArg> for LobeChoice {
    fn from(l: LobeArg) -> Self {
        match l {
            LobeArg::Variance => LobeChoice::LowestVariance,
            LobeArg::Model => LobeChoice::Model,
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
enum LobesArg {
    Auto,
    #[value(name = "1")]
    One,
    #[value(name = "2")]
    Two,
}

impl From<LobesArg> for fit_phong::LobeCount {
    fn from(l: LobesArg) -> Self {
        match l {
            LobesArg::Auto => fit_phong::LobeCount::Auto,
            LobesArg::One => fit_phong::LobeCount::One,
            LobesArg::Two => fit_phong::LobeCount::Two,
        }
    }
}

#[derive(Args)]
struct FitPhongArgs {
    /// A MERL-format table (.binary) or a network (.nbrdf.json, updated with the fit).
    #[arg(value_name = "TABLE.binary|NAME.nbrdf.json")]
    input: PathBuf,
    /// For a network: write the updated network here instead of in place.
    #[arg(short, long, value_name = "OUT.nbrdf.json")]
    output: Option<PathBuf>,
    /// Print the fit as JSON.
    #[arg(long)]
    json: bool,
    /// Which lobe is stored for sampling: `variance` (default) searches (n, w) for the lowest
    /// variance of BSDF sampling; `model` takes n and w = mean(ks) / (mean(kd) + mean(ks)) of the
    /// 7-parameter fit (docs/design.md section 6), which can be a poor sampler for weak sharp spikes.
    #[arg(long, value_enum, default_value_t = LobeArg::Variance)]
    lobe: LobeArg,
    /// How many Blinn-Phong lobes the sampling mixture has: `auto` (default) searches one and
    /// two lobes on the same quadrature and stores two where they lower the relative variance
    /// (by more than 2 %); `1` or `2` force the count (`2` needs `--lobe variance`).
    #[arg(long, value_enum, default_value_t = LobesArg::Auto)]
    lobes: LobesArg,
    /// How the table folds phi_d: reciprocal for MERL tables, mirror for non-reciprocal ones
    /// tabulated with `tabulate_rgl --phi-fold mirror`.
    #[arg(long, value_enum, default_value_t = PhiFoldArg::Reciprocal)]
    phi_fold: PhiFoldArg,
    /// Directions sampled (adaptively) for the fit, at most 1e8.
    #[arg(long, default_value_t = FitConfig::default().samples,
          value_parser = count_in::<1, { limits::MAX_SAMPLES }>)]
    samples: usize,
    /// Random seed of the sampled directions.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Worker threads (default: one per core).
    #[arg(long)]
    threads: Option<usize>,
}

#[derive(Args)]
struct CompareArgs {
    /// The reference: a MERL-format table (.binary) or a network (.nbrdf.json).
    #[arg(value_name = "A")]
    reference: PathBuf,
    /// The material compared against A, table or network.
    #[arg(value_name = "B")]
    test: PathBuf,
    /// How tables fold phi_d: reciprocal for MERL tables, mirror for non-reciprocal ones
    /// tabulated with `tabulate_rgl --phi-fold mirror`.
    #[arg(long, value_enum, default_value_t = PhiFoldArg::Reciprocal)]
    phi_fold: PhiFoldArg,
    /// Width and height of the sphere images, pixels (at most 4096).
    #[arg(long, default_value_t = 128, value_parser = count_in::<1, { limits::MAX_RESOLUTION }>)]
    resolution: usize,
    /// Directions sampled for the log-space error (each of adaptive and uniform sampling), at
    /// most 1e8.
    #[arg(long, default_value_t = 100_000, value_parser = count_in::<1, { limits::MAX_SAMPLES }>)]
    samples: usize,
    /// Print the comparison as JSON.
    #[arg(long)]
    json: bool,
    /// Worker threads (default: one per core).
    #[arg(long)]
    threads: Option<usize>,
}

fn main() -> ExitCode {
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) => {
            // --help and --version come through here too and are not failures.
            let _ = e.print();
            return if e.use_stderr() {
                ExitCode::from(EXIT_USAGE)
            } else {
                ExitCode::SUCCESS
            };
        }
    };
    match run(cli.command) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::from(exit_status(&e))
        }
    }
}

/// Exit status of a usage error (clap's own for bad arguments).
const EXIT_USAGE: u8 = 2;
/// Exit status of a failure: I/O, a bad file, data the command cannot work with.
const EXIT_FAILURE: u8 = 1;

fn exit_status(error: &NbrdfError) -> u8 {
    match error {
        NbrdfError::Usage(_) => EXIT_USAGE,
        _ => EXIT_FAILURE,
    }
}

/// A clap value parser for a count in `[MIN, MAX]` (the ranges of [`ops::limits`], which the
/// library checks again for its other callers).
pub(crate) fn count_in<const MIN: usize, const MAX: usize>(
    text: &str,
) -> std::result::Result<usize, String> {
    let value: usize = text
        .parse()
        .map_err(|e| format!("{e} (a whole number in [{MIN}, {MAX}])"))?;
    if (MIN..=MAX).contains(&value) {
        Ok(value)
    } else {
        Err(format!(
            "{value} is out of range: it must be in [{MIN}, {MAX}] (docs/hardening.md)"
        ))
    }
}

fn run(command: Command) -> Result<()> {
    match command {
        Command::ListMaterials(args) => run_list_materials(&args),
        Command::Synth(args) => run_synth(&args),
        Command::Tabulate(args) => run_tabulate(&args),
        Command::Info(args) => run_info(&args),
        Command::Train(args) => train_cmd::run_train(&args),
        Command::FitPhong(args) => run_fit_phong(&args),
        Command::Compare(args) => run_compare(&args),
        Command::Ae(command) => ae_cmd::run_ae(command),
        Command::Interpolate(args) => ae_cmd::run_interpolate(&args),
        Command::Predictor(command) => predictor_cmd::run_predictor(command),
        Command::PredictPhong(args) => predictor_cmd::run_predict_phong(&args),
    }
}

fn run_list_materials(args: &ListMaterialsArgs) -> Result<()> {
    let materials = catalogue::list_materials();
    if args.json {
        emit(&ops::to_json_pretty(&materials)?)
    } else {
        emit(
            &materials
                .iter()
                .map(|m| format!("{}\n", m.name))
                .collect::<String>(),
        )
    }
}

fn run_synth(args: &SynthArgs) -> Result<()> {
    let report = catalogue::synth(args.model.into(), &args.material, args.output.as_deref())?;
    emit(&report.to_string())
}

fn run_tabulate(args: &TabulateArgs) -> Result<()> {
    let report = table::tabulate(&args.network, args.output.as_deref(), args.threads)?;
    emit(&report.to_string())
}

fn run_info(args: &InfoArgs) -> Result<()> {
    emit(&table::info(&args.file)?.to_string())
}

fn run_fit_phong(args: &FitPhongArgs) -> Result<()> {
    let report = fit_phong::fit_phong(&fit_phong::FitPhongRequest {
        input: args.input.clone(),
        output: args.output.clone(),
        lobe: args.lobe.into(),
        lobes: args.lobes.into(),
        phi_fold: args.phi_fold.into(),
        fit: FitConfig {
            samples: args.samples,
            seed: args.seed,
            ..FitConfig::default()
        },
        threads: args.threads,
    })?;
    if args.json {
        emit(&ops::to_json_pretty(&report)?)
    } else {
        emit(&report.to_string())
    }
}

fn run_compare(args: &CompareArgs) -> Result<()> {
    let report = compare::compare(
        &args.reference,
        &args.test,
        args.phi_fold.into(),
        args.resolution,
        args.samples,
        args.threads,
    )?;
    if args.json {
        emit(&ops::to_json_pretty(&report)?)
    } else {
        emit(&report.to_string())
    }
}

/// Writes to stdout. A closed pipe (`nbrdf list-materials | head`) just ends the output; the
/// print macros would panic there.
pub(crate) fn emit(text: &str) -> Result<()> {
    let mut stdout = std::io::stdout().lock();
    match stdout
        .write_all(text.as_bytes())
        .and_then(|()| stdout.flush())
    {
        Err(e) if e.kind() != std::io::ErrorKind::BrokenPipe => Err(NbrdfError::io("<stdout>", e)),
        _ => Ok(()),
    }
}
