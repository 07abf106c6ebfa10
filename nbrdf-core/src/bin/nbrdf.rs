//! The `nbrdf` command-line tool.
//!
//! One variant of [`Command`] per subcommand, each with its own argument struct and `run_*`
//! function returning the crate's `Result`; `main` alone turns errors into `error: ...` on stderr
//! and exit status 1. New commands (train, fit-phong, compare, ...) slot in the same way.

use clap::{Args, Parser, Subcommand, ValueEnum};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use nbrdf_core::analytic::{catalogue, AnalyticBrdf, ModelKind};
use nbrdf_core::coords::{from_rusinkiewicz, network_input, RusinkiewiczAngles};
use nbrdf_core::lobe_fit::{LobeFitConfig, LobeQuadrature};
use nbrdf_core::merl::{self, MerlTable, PhiFold};
use nbrdf_core::metrics;
use nbrdf_core::network::{SamplingParams, SAMPLING_MODEL_BLINN_PHONG};
use nbrdf_core::phong_fit::{self, FitConfig};
use nbrdf_core::train::adam::AdamConfig;
use nbrdf_core::train::dataset::AngularSampling;
use nbrdf_core::train::dataset::TargetFn;
use nbrdf_core::train::{self, EpochStats, TrainConfig};
use nbrdf_core::{Nbrdf, NbrdfError, Result};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

#[path = "nbrdf/latent_cli.rs"]
mod latent_cli;

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
    /// Train a neural BRDF on a MERL-format table and write it as NAME.nbrdf.json.
    Train(TrainArgs),
    /// Fit the Blinn-Phong sampling lobe (exponent, specular weight) to a table or a network.
    FitPhong(FitPhongArgs),
    /// Compare two materials (tables or networks): sphere images and log-space BRDF error.
    Compare(CompareArgs),
    /// The NBRDF autoencoder: train, encode, decode.
    #[command(subcommand)]
    Ae(latent_cli::AeCommand),
    /// Interpolate two networks in the autoencoder's latent space and in weight space.
    Interpolate(latent_cli::InterpolateArgs),
    /// The predictor of Blinn-Phong sampling parameters from autoencoder codes.
    #[command(subcommand)]
    Predictor(latent_cli::PredictorCommand),
    /// Predict a network's Blinn-Phong sampling parameters from its code (source "predicted").
    PredictPhong(latent_cli::PredictPhongArgs),
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

#[derive(Clone, Copy, ValueEnum)]
enum SamplingArg {
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

#[derive(Clone, Copy, Default, ValueEnum)]
enum PhiFoldArg {
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

#[derive(Args)]
struct TrainArgs {
    /// The MERL-format table to learn.
    #[arg(value_name = "TABLE.binary")]
    table: PathBuf,
    /// Where to write the network; defaults to TABLE's name with .nbrdf.json in the current
    /// directory.
    #[arg(short, long, value_name = "NAME.nbrdf.json")]
    output: Option<PathBuf>,
    /// How training directions are drawn.
    #[arg(long, value_enum, default_value_t = SamplingArg::Adaptive)]
    sampling: SamplingArg,
    /// How the table folds phi_d: reciprocal for MERL tables, mirror for non-reciprocal ones
    /// tabulated with `tabulate_rgl --phi-fold mirror`.
    #[arg(long, value_enum, default_value_t = PhiFoldArg::Reciprocal)]
    phi_fold: PhiFoldArg,
    /// Training samples (invalid cells and directions below the horizon are not counted);
    /// 10% more are drawn for validation.
    #[arg(long, default_value_t = TrainConfig::default().samples)]
    samples: usize,
    /// Maximum number of epochs.
    #[arg(long, default_value_t = TrainConfig::default().max_epochs)]
    epochs: usize,
    /// Width of the two hidden layers.
    #[arg(long, default_value_t = TrainConfig::default().hidden)]
    hidden: usize,
    /// Adam learning rate.
    #[arg(long, default_value_t = AdamConfig::default().learning_rate)]
    lr: f32,
    /// Mini-batch size.
    #[arg(long, default_value_t = TrainConfig::default().batch)]
    batch: usize,
    /// Stop after this many epochs without a 0.1% improvement of the validation loss (the best
    /// weights are kept).
    #[arg(long, default_value_t = TrainConfig::default().patience)]
    patience: usize,
    /// Never stop early before this many epochs (stiff materials can plateau for a while first).
    #[arg(long, default_value_t = TrainConfig::default().min_epochs)]
    min_epochs: usize,
    /// Relative validation improvement that resets the patience.
    #[arg(long, default_value_t = TrainConfig::default().min_improvement)]
    min_improvement: f64,
    /// When the patience runs out, multiply the learning rate by --lr-decay-factor and go on,
    /// up to this many times, before stopping (0: the paper's constant rate).
    #[arg(long, default_value_t = TrainConfig::default().lr_decays)]
    lr_decays: usize,
    /// Factor of each learning-rate drop, in (0, 1).
    #[arg(long, default_value_t = TrainConfig::default().lr_decay_factor)]
    lr_decay_factor: f32,
    /// Random seed; a seed gives the same network whatever the thread count.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Worker threads (default: one per core).
    #[arg(long)]
    threads: Option<usize>,
    /// Name stored in the network file (default: TABLE's file name without extension).
    #[arg(long)]
    name: Option<String>,
    /// No progress bar (it is also hidden when stderr is not a terminal).
    #[arg(short, long)]
    quiet: bool,
}

#[derive(Clone, Copy, PartialEq, Eq, ValueEnum)]
enum LobeArg {
    Variance,
    Model,
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
    /// 7-parameter fit (DESIGN.md section 6), which can be a poor sampler for weak sharp spikes.
    #[arg(long, value_enum, default_value_t = LobeArg::Variance)]
    lobe: LobeArg,
    /// How the table folds phi_d: reciprocal for MERL tables, mirror for non-reciprocal ones
    /// tabulated with `tabulate_rgl --phi-fold mirror`.
    #[arg(long, value_enum, default_value_t = PhiFoldArg::Reciprocal)]
    phi_fold: PhiFoldArg,
    /// Directions sampled (adaptively) for the fit.
    #[arg(long, default_value_t = FitConfig::default().samples)]
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
    /// Width and height of the sphere images, pixels.
    #[arg(long, default_value_t = 128)]
    resolution: usize,
    /// Directions sampled for the log-space error (each of adaptive and uniform sampling).
    #[arg(long, default_value_t = 100_000)]
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
                ExitCode::from(1)
            } else {
                ExitCode::SUCCESS
            };
        }
    };
    match run(cli.command) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::from(1)
        }
    }
}

fn run(command: Command) -> Result<()> {
    match command {
        Command::ListMaterials(args) => run_list_materials(&args),
        Command::Synth(args) => run_synth(&args),
        Command::Tabulate(args) => run_tabulate(&args),
        Command::Info(args) => run_info(&args),
        Command::Train(args) => run_train(&args),
        Command::FitPhong(args) => run_fit_phong(&args),
        Command::Compare(args) => run_compare(&args),
        Command::Ae(command) => latent_cli::run_ae(command),
        Command::Interpolate(args) => latent_cli::run_interpolate(&args),
        Command::Predictor(command) => latent_cli::run_predictor(command),
        Command::PredictPhong(args) => latent_cli::run_predict_phong(&args),
    }
}

fn run_compare(args: &CompareArgs) -> Result<()> {
    let fold = args.phi_fold.into();
    let reference = metrics::Material::read_folded(&args.reference, fold)?;
    let test = metrics::Material::read_folded(&args.test, fold)?;
    let c = with_threads(args.threads, || {
        metrics::compare(&reference, &test, args.resolution, args.samples)
    })??;
    if args.json {
        let value = serde_json::json!({
            "reference": args.reference.display().to_string(),
            "test": args.test.display().to_string(),
            "comparison": c,
        });
        let text = serde_json::to_string_pretty(&value)
            .map_err(|e| NbrdfError::InvalidArgument(format!("cannot format JSON: {e}")))?;
        return emit(&format!("{text}\n"));
    }
    let mut out = format!(
        "{} vs {} (reference first), {}x{} spheres:\n  {:>9}{:>12}{:>12}{:>9}{:>8}\n",
        args.reference.display(),
        args.test.display(),
        c.resolution,
        c.resolution,
        "theta_l",
        "MAE",
        "RMSE",
        "PSNR",
        "SSIM"
    );
    let row = |label: String, e: &metrics::ImageErrors| {
        format!(
            "  {label:>9}{:>12.4e}{:>12.4e}{:>9.2}{:>8.4}\n",
            e.mae, e.rmse, e.psnr_peak_reference, e.ssim
        )
    };
    for (deg, e) in &c.per_light {
        out += &row(format!("{deg:.0} deg"), e);
    }
    out += &row("mean".to_string(), &c.mean);
    out += &format!(
        "log-space BRDF error |ln(1+fA cos) - ln(1+fB cos)|: adaptive {:.4e}, uniform {:.4e}\n",
        c.log_error_adaptive, c.log_error_uniform
    );
    emit(&out)
}

/// Runs `f` on a pool of `threads` workers, or on the global pool (one per core).
fn with_threads<T: Send>(threads: Option<usize>, f: impl FnOnce() -> T + Send) -> Result<T> {
    match threads {
        None => Ok(f()),
        Some(0) => Err(NbrdfError::InvalidArgument(
            "--threads must be at least 1".into(),
        )),
        Some(n) => {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(n)
                .build()
                .map_err(|e| {
                    NbrdfError::InvalidArgument(format!("cannot start {n} threads: {e}"))
                })?;
            Ok(pool.install(f))
        }
    }
}

/// The file name without its extensions: `gold.binary` and `gold.nbrdf.json` give `gold`.
fn file_stem(path: &Path) -> String {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let stem = name.split('.').next().unwrap_or_default();
    if stem.is_empty() {
        "nbrdf".to_string()
    } else {
        stem.to_string()
    }
}

fn run_train(args: &TrainArgs) -> Result<()> {
    let table = MerlTable::read(&args.table)?.with_phi_fold(args.phi_fold.into());
    let name = args.name.clone().unwrap_or_else(|| file_stem(&args.table));
    let output = args
        .output
        .clone()
        .unwrap_or_else(|| PathBuf::from(format!("{name}.nbrdf.json")));
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
    let bar = epoch_bar(config.max_epochs, args.quiet)?;
    let target = train::table_target(&table);
    let outcome = with_threads(args.threads, || {
        train::train(&target, &config, &name, &mut |e: &EpochStats| {
            bar.set_position(e.epoch as u64);
            bar.set_message(format!(
                "train {:.3e}  val {:.3e}  best {:.3e} @ {}",
                e.train_loss, e.validation_loss, e.best_validation_loss, e.best_epoch
            ));
        })
    })??;
    bar.finish_and_clear();
    let report = &outcome.report;
    let mut network = outcome.network;
    network.provenance = train::provenance(&config, report, &args.table.display().to_string());
    if let Some(p) = network.provenance.as_object_mut() {
        p.insert("phi_fold".into(), table.phi_fold().as_str().into());
    }
    network.validate()?;
    network.save(&output)?;
    emit(&format!(
        "wrote {}: {} epochs ({}), best validation loss {:.4e} at epoch {}, {:.1} s\n",
        output.display(),
        report.epochs_run,
        if report.stopped_early {
            "stopped early"
        } else {
            "epoch limit"
        },
        report.best_validation_loss,
        report.best_epoch,
        report.seconds,
    ))
}

/// The progress bar of `nbrdf train`: epochs, losses and an ETA against the epoch limit.
fn epoch_bar(max_epochs: usize, quiet: bool) -> Result<ProgressBar> {
    // indicatif's stderr target draws nothing when stderr is not a terminal.
    let target = if quiet {
        ProgressDrawTarget::hidden()
    } else {
        ProgressDrawTarget::stderr()
    };
    let style = ProgressStyle::with_template("epoch {pos:>3}/{len} [{bar:24}] {msg}  ETA {eta}")
        .map_err(|e| NbrdfError::InvalidArgument(format!("progress bar template: {e}")))?
        .progress_chars("=> ");
    let bar = ProgressBar::with_draw_target(Some(max_epochs as u64), target).with_style(style);
    bar.set_message("drawing samples");
    Ok(bar)
}

/// What `fit-phong` reads.
enum FitSource {
    Table(MerlTable),
    Network(Box<Nbrdf>),
}

impl FitSource {
    /// A network when the file name ends in `.json`, a MERL table otherwise.
    fn read(path: &Path, fold: PhiFold) -> Result<Self> {
        let is_json = path
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("json"));
        if is_json {
            Ok(FitSource::Network(Box::new(Nbrdf::load(path)?)))
        } else {
            Ok(FitSource::Table(MerlTable::read(path)?.with_phi_fold(fold)))
        }
    }

    /// `f_r` by Rusinkiewicz angles, what both fits read.
    fn target(&self) -> Box<TargetFn<'_>> {
        match self {
            FitSource::Table(table) => Box::new(train::table_target(table)),
            FitSource::Network(net) => Box::new(move |a: &RusinkiewiczAngles| {
                let (v, l) = from_rusinkiewicz(a);
                Some(
                    net.eval_input(network_input(v.as_vec3(), l.as_vec3()))
                        .map(f64::from),
                )
            }),
        }
    }
}

fn run_fit_phong(args: &FitPhongArgs) -> Result<()> {
    let source = FitSource::read(&args.input, args.phi_fold.into())?;
    if args.output.is_some() && matches!(source, FitSource::Table(_)) {
        return Err(NbrdfError::InvalidArgument(
            "-o/--output applies to networks; for a table the fit is printed".into(),
        ));
    }
    let config = FitConfig {
        samples: args.samples,
        seed: args.seed,
        ..FitConfig::default()
    };
    let lobe_config = LobeFitConfig::default();
    let (fit, lobe, model_variance) = with_threads(args.threads, || -> Result<_> {
        let target = source.target();
        let fit = phong_fit::fit(&*target, &config)?;
        let quadrature = LobeQuadrature::new(&*target, &lobe_config)?;
        let lobe = quadrature.fit(&lobe_config)?;
        let model_variance =
            quadrature.relative_variance(fit.params.exponent, fit.params.specular_weight());
        Ok((fit, lobe, model_variance))
    })??;
    let p = &fit.params;
    let (exponent, specular_weight) = match args.lobe {
        LobeArg::Variance => (lobe.exponent, lobe.specular_weight),
        LobeArg::Model => (p.exponent, p.specular_weight()),
    };
    let sampling = SamplingParams {
        model: SAMPLING_MODEL_BLINN_PHONG.to_string(),
        exponent: exponent as f32,
        specular_weight: specular_weight as f32,
        source: "fit".to_string(),
    };
    let mut written = None;
    if let FitSource::Network(mut net) = source {
        net.sampling = Some(sampling.clone());
        net.validate()?;
        let out = args.output.clone().unwrap_or_else(|| args.input.clone());
        net.save(&out)?;
        written = Some(out);
    }
    if args.json {
        let value = serde_json::json!({
            "model": sampling.model,
            "exponent": sampling.exponent,
            "specular_weight": sampling.specular_weight,
            "source": sampling.source,
            "lobe": match args.lobe { LobeArg::Variance => "variance", LobeArg::Model => "model" },
            "kd": p.kd,
            "ks": p.ks,
            "model_exponent": p.exponent,
            "model_specular_weight": p.specular_weight(),
            "loss": fit.loss,
            "relative_variance": {
                "variance_lobe": lobe.relative_variance,
                "model_lobe": model_variance,
                "cosine": lobe.cosine_relative_variance,
            },
            "written": written.as_ref().map(|w| w.display().to_string()),
        });
        let text = serde_json::to_string_pretty(&value)
            .map_err(|e| NbrdfError::InvalidArgument(format!("cannot format JSON: {e}")))?;
        return emit(&format!("{text}\n"));
    }
    let mut text = format!(
        "sampling lobe ({}): exponent {:.4}, specular weight {:.4}\n\
         model fit: exponent {:.4}, specular weight {:.4}, log loss {:.4e}\n  kd {:.4e} {:.4e} {:.4e}\n  ks {:.4e} {:.4e} {:.4e}\n\
         relative variance of BSDF sampling: variance lobe {:.4e}, model lobe {:.4e}, cosine {:.4e}\n",
        match args.lobe { LobeArg::Variance => "lowest variance", LobeArg::Model => "model fit" },
        sampling.exponent, sampling.specular_weight, p.exponent, p.specular_weight(), fit.loss,
        p.kd[0], p.kd[1], p.kd[2], p.ks[0], p.ks[1], p.ks[2],
        lobe.relative_variance, model_variance, lobe.cosine_relative_variance,
    );
    if let Some(out) = written {
        text += &format!("updated the sampling of {}\n", out.display());
    }
    emit(&text)
}

fn run_list_materials(args: &ListMaterialsArgs) -> Result<()> {
    let names = catalogue::material_names();
    if args.json {
        let entries: Vec<serde_json::Value> = names
            .iter()
            .map(|&name| serde_json::json!({ "name": name, "alias": catalogue::alias(name) }))
            .collect();
        let text = serde_json::to_string_pretty(&entries)
            .map_err(|e| NbrdfError::InvalidArgument(format!("cannot format JSON: {e}")))?;
        emit(&format!("{text}\n"))
    } else {
        emit(&names.iter().map(|n| format!("{n}\n")).collect::<String>())
    }
}

fn run_synth(args: &SynthArgs) -> Result<()> {
    let model = ModelKind::from(args.model);
    let brdf = AnalyticBrdf::from_catalogue(model, &args.material)?;
    // from_catalogue succeeded, so the name resolves; the canonical one makes the file name.
    let name = catalogue::canonical_name(&args.material).unwrap_or(&args.material);
    let output = args
        .output
        .clone()
        .unwrap_or_else(|| PathBuf::from(format!("{name}.binary")));
    let start = Instant::now();
    let table = brdf.tabulate();
    table.write(&output)?;
    let seconds = start.elapsed().as_secs_f64();
    let invalid = table.stats().invalid_cells;
    emit(&format!(
        "wrote {} ({} fit of {name}, {} bytes{}) in {seconds:.2} s\n",
        output.display(),
        model.name().to_uppercase(),
        merl::FILE_SIZE,
        if invalid > 0 {
            format!(", {invalid} cells not finite and marked invalid")
        } else {
            String::new()
        },
    ))
}

fn run_tabulate(args: &TabulateArgs) -> Result<()> {
    let net = Nbrdf::load(&args.network)?;
    let output = args
        .output
        .clone()
        .unwrap_or_else(|| PathBuf::from(format!("{}.binary", net.name)));
    let start = Instant::now();
    let table = with_threads(args.threads, || net.tabulate())?;
    table.write(&output)?;
    emit(&format!(
        "wrote {} (network {}, {} cells below the horizon marked invalid) in {:.2} s\n",
        output.display(),
        net.name,
        table.stats().invalid_cells,
        start.elapsed().as_secs_f64()
    ))
}

fn run_info(args: &InfoArgs) -> Result<()> {
    let table = MerlTable::read(&args.file)?;
    emit(&info_report(&args.file, &table))
}

/// Writes to stdout. A closed pipe (`nbrdf list-materials | head`) just ends the output; the
/// print macros would panic there.
fn emit(text: &str) -> Result<()> {
    let mut stdout = std::io::stdout().lock();
    match stdout
        .write_all(text.as_bytes())
        .and_then(|()| stdout.flush())
    {
        Err(e) if e.kind() != std::io::ErrorKind::BrokenPipe => Err(NbrdfError::io("<stdout>", e)),
        _ => Ok(()),
    }
}

/// The text `nbrdf info` prints.
fn info_report(path: &Path, table: &MerlTable) -> String {
    let stats = table.stats();
    let mut out = format!(
        "{}: valid MERL table (90 x 90 x 180 cells, {} bytes)\n",
        path.display(),
        merl::FILE_SIZE
    );
    out += &format!(
        "cells: {} valid, {} invalid (not measured) of {}\n",
        stats.valid_cells,
        stats.invalid_cells,
        merl::CELLS
    );
    out += "reflectance over valid cells (1/sr):\n";
    out += &format!(
        "  {:<7}{:>14}{:>14}{:>14}\n",
        "channel", "min", "max", "mean"
    );
    for (c, channel) in ["red", "green", "blue"].iter().enumerate() {
        out += &format!(
            "  {:<7}{:>14.6e}{:>14.6e}{:>14.6e}\n",
            channel, stats.min[c], stats.max[c], stats.mean[c]
        );
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::CommandFactory;

    #[test]
    fn cli_definition_is_consistent() {
        Cli::command().debug_assert();
    }

    #[test]
    fn every_command_and_option_has_help() {
        let cli = Cli::command();
        for sub in cli.get_subcommands() {
            assert!(sub.get_about().is_some(), "{}", sub.get_name());
            for arg in sub.get_arguments() {
                let builtin = matches!(arg.get_id().as_str(), "help" | "version");
                assert!(
                    builtin || arg.get_help().is_some(),
                    "{} {}",
                    sub.get_name(),
                    arg.get_id()
                );
            }
        }
    }

    #[test]
    fn arguments_parse() {
        let cli = Cli::try_parse_from([
            "nbrdf",
            "synth",
            "--model",
            "abc",
            "--material",
            "x",
            "-o",
            "y.binary",
        ]);
        let Ok(Cli {
            command: Command::Synth(args),
        }) = cli
        else {
            panic!("synth must parse")
        };
        assert!(matches!(args.model, ModelArg::Abc));
        assert_eq!(args.output, Some(PathBuf::from("y.binary")));
        assert!(
            Cli::try_parse_from(["nbrdf", "synth", "--model", "ggx", "--material", "x"]).is_err()
        );
        assert!(Cli::try_parse_from(["nbrdf", "info"]).is_err());
    }

    #[test]
    fn train_and_fit_phong_arguments_parse() {
        let Ok(Cli {
            command: Command::Train(args),
        }) = Cli::try_parse_from([
            "nbrdf",
            "train",
            "t.binary",
            "-o",
            "n.nbrdf.json",
            "--sampling",
            "uniform",
            "--samples",
            "1000",
            "--epochs",
            "3",
            "--threads",
            "2",
            "--seed",
            "9",
            "--quiet",
        ])
        else {
            panic!("train must parse")
        };
        assert!(matches!(args.sampling, SamplingArg::Uniform));
        assert_eq!(
            (args.samples, args.epochs, args.threads, args.seed),
            (1000, 3, Some(2), 9)
        );
        assert_eq!((args.hidden, args.batch), (21, 512));
        assert!(matches!(args.phi_fold, PhiFoldArg::Reciprocal));
        let Ok(Cli {
            command: Command::Train(args),
        }) = Cli::try_parse_from(["nbrdf", "train", "t.binary", "--phi-fold", "mirror"])
        else {
            panic!("train --phi-fold must parse")
        };
        assert_eq!(PhiFold::from(args.phi_fold), PhiFold::Mirror);
        assert!(Cli::try_parse_from(["nbrdf", "train", "t.binary", "--phi-fold", "odd"]).is_err());
        assert!((args.lr - 5e-4).abs() < 1e-9);
        assert!(
            Cli::try_parse_from(["nbrdf", "train", "t.binary", "--sampling", "random"]).is_err()
        );
        assert!(Cli::try_parse_from(["nbrdf", "train", "t.binary", "--samples", "-5"]).is_err());
        let Ok(Cli {
            command: Command::FitPhong(args),
        }) = Cli::try_parse_from(["nbrdf", "fit-phong", "n.nbrdf.json", "--json"])
        else {
            panic!("fit-phong must parse")
        };
        assert!(args.json && args.output.is_none());
        assert!(args.lobe == LobeArg::Variance);
        let Ok(Cli {
            command: Command::FitPhong(args),
        }) = Cli::try_parse_from(["nbrdf", "fit-phong", "n.nbrdf.json", "--lobe", "model"])
        else {
            panic!("fit-phong --lobe model must parse")
        };
        assert!(args.lobe == LobeArg::Model);
        assert!(
            Cli::try_parse_from(["nbrdf", "fit-phong", "n.nbrdf.json", "--lobe", "x"]).is_err()
        );
    }

    #[test]
    fn compare_arguments_parse() {
        let Ok(Cli {
            command: Command::Compare(args),
        }) = Cli::try_parse_from([
            "nbrdf",
            "compare",
            "a.binary",
            "b.nbrdf.json",
            "--resolution",
            "32",
            "--json",
        ])
        else {
            panic!("compare must parse")
        };
        assert_eq!(
            (args.resolution, args.samples, args.json),
            (32, 100_000, true)
        );
        assert!(Cli::try_parse_from(["nbrdf", "compare", "a.binary"]).is_err());
    }

    #[test]
    fn default_names_drop_every_extension() {
        assert_eq!(file_stem(Path::new("/x/gold-paint.binary")), "gold-paint");
        assert_eq!(file_stem(Path::new("net.nbrdf.json")), "net");
        assert_eq!(file_stem(Path::new("/")), "nbrdf");
    }

    #[test]
    fn zero_threads_is_an_error() {
        assert!(with_threads(Some(0), || ()).is_err());
        assert_eq!(
            with_threads(Some(1), rayon::current_num_threads).unwrap(),
            1
        );
    }

    #[test]
    fn unknown_material_is_an_error_not_a_panic() {
        let args = SynthArgs {
            model: ModelArg::Sgd,
            material: "unobtainium".into(),
            output: None,
        };
        let err = run_synth(&args).unwrap_err();
        assert!(err.to_string().contains("unknown material 'unobtainium'"));
    }

    #[test]
    fn info_of_a_missing_file_names_it() {
        let args = InfoArgs {
            file: std::env::temp_dir().join("nbrdf-no-such-file.binary"),
        };
        assert!(run_info(&args)
            .unwrap_err()
            .to_string()
            .contains("nbrdf-no-such-file.binary"));
    }

    #[test]
    fn info_report_lists_channels() {
        let mut stored = vec![1500.0; 3 * merl::CELLS];
        stored[0] = -1.0;
        let table = MerlTable::from_stored(stored).unwrap();
        let report = info_report(Path::new("t.binary"), &table);
        assert!(report.contains("1457999 valid, 1 invalid"), "{report}");
        assert!(
            report.contains("red") && report.contains("1.000000e0"),
            "{report}"
        );
    }
}
