//! The latent-space subcommands: `ae train|encode|decode`, `interpolate`, `predict-phong`,
//! `predictor train`, `pca`.

use super::emit;
use clap::{Args, Subcommand};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use nbrdf_core::latent::autoencoder::{AeConfig, AeEpoch, AutoEncoder, Split};
use nbrdf_core::latent::predictor::{PredictorConfig, VarianceGrid};
use nbrdf_core::lobe_fit::LobeQuadrature;
use nbrdf_core::ops::with_threads;
use nbrdf_core::{Nbrdf, NbrdfError, Result};
use std::path::{Path, PathBuf};
use std::time::Instant;

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

#[derive(Subcommand)]
pub enum PredictorCommand {
    /// Train the Phong-parameter predictor on the codes of the training split.
    Train(PredictorTrainArgs),
    /// Fitted vs predicted lobes of the test split, scored by the relative variance of BSDF
    /// sampling (the quantity `fit-phong` minimises), as JSON.
    Eval(PredictorEvalArgs),
}

pub fn run_predictor(command: PredictorCommand) -> Result<()> {
    match command {
        PredictorCommand::Train(a) => run_predictor_train(&a),
        PredictorCommand::Eval(a) => run_predictor_eval(&a),
    }
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
pub struct PredictorEvalArgs {
    /// The trained autoencoder (from `nbrdf ae train`).
    #[arg(long, value_name = "AE.json")]
    ae: PathBuf,
    /// The trained Phong-parameter predictor (from `nbrdf predictor train`).
    #[arg(long, value_name = "P.json")]
    predictor: PathBuf,
    /// The networks (the test split is read from the autoencoder).
    #[arg(long, value_name = "DIR")]
    nbrdfs: PathBuf,
    /// Worker threads (default: one per core).
    #[arg(long)]
    threads: Option<usize>,
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
    /// Epoch limit (early stopping usually ends sooner).
    #[arg(long, default_value_t = AeConfig::default().max_epochs)]
    epochs: usize,
    /// Epochs of weight-space warm start before the image loss.
    #[arg(long, default_value_t = AeConfig::default().warmup_epochs)]
    warmup: usize,
    /// Early-stopping patience in epochs.
    #[arg(long, default_value_t = AeConfig::default().patience)]
    patience: usize,
    /// Width of the encoder's and decoder's hidden layer.
    #[arg(long, default_value_t = AeConfig::default().hidden)]
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
    /// The trained autoencoder (from `nbrdf ae train`).
    #[arg(long, value_name = "AE.json")]
    ae: PathBuf,
    /// The neural BRDF to read.
    #[arg(value_name = "NBRDF.json")]
    input: PathBuf,
    /// Print the encoding time to stderr.
    #[arg(long)]
    timing: bool,
    /// Refine the encoder's code by this many Levenberg-Marquardt iterations on the image
    /// loss against the network's own sphere image (analysis by synthesis; ~10 ms each).
    #[arg(long, default_value_t = 0)]
    refine: usize,
}

#[derive(Args)]
pub struct AeDecodeArgs {
    /// The trained autoencoder (from `nbrdf ae train`).
    #[arg(long, value_name = "AE.json")]
    ae: PathBuf,
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
    /// The trained autoencoder (from `nbrdf ae train`).
    #[arg(long, value_name = "AE.json")]
    ae: PathBuf,
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
}

pub fn run_ae(command: AeCommand) -> Result<()> {
    match command {
        AeCommand::Train(a) => run_ae_train(&a),
        AeCommand::Encode(a) => run_ae_encode(&a),
        AeCommand::Decode(a) => run_ae_decode(&a),
        AeCommand::Eval(a) => run_ae_eval(&a),
    }
}

fn invalid(msg: String) -> NbrdfError {
    NbrdfError::InvalidArgument(msg)
}

/// The `NAME.nbrdf.json` networks of a directory, sorted by name.
pub fn read_nbrdf_dir(dir: &Path) -> Result<Vec<(String, Nbrdf)>> {
    let entries = std::fs::read_dir(dir).map_err(|e| invalid(format!("{}: {e}", dir.display())))?;
    let mut out = Vec::new();
    for entry in entries {
        let path = entry
            .map_err(|e| invalid(format!("{}: {e}", dir.display())))?
            .path();
        let Some(file) = path.file_name().and_then(|f| f.to_str()) else {
            continue;
        };
        if let Some(name) = file.strip_suffix(".nbrdf.json") {
            out.push((name.to_string(), Nbrdf::load(&path)?));
        }
    }
    if out.is_empty() {
        return Err(invalid(format!("no *.nbrdf.json in {}", dir.display())));
    }
    out.sort_by(|a, b| a.0.cmp(&b.0));
    Ok(out)
}

fn run_ae_train(args: &AeTrainArgs) -> Result<()> {
    let nets = read_nbrdf_dir(&args.nbrdfs)?;
    let hidden = nets[0].1.hidden_width();
    if nets.iter().any(|(_, n)| n.hidden_width() != hidden) {
        return Err(invalid("the networks differ in hidden width".into()));
    }
    let names: Vec<String> = nets.iter().map(|(n, _)| n.clone()).collect();
    let split = Split::fixed(&names);
    let mut materials: Vec<(String, Vec<f32>)> = nets
        .iter()
        .map(|(n, net)| (n.clone(), net.to_flat()))
        .collect();
    if let Some(dir) = &args.extra_nbrdfs {
        for (name, net) in read_nbrdf_dir(dir)? {
            if net.hidden_width() != hidden {
                return Err(invalid(format!(
                    "{}: '{name}' has hidden width {}, the networks {hidden}",
                    dir.display(),
                    net.hidden_width()
                )));
            }
            if split.train.contains(&name) && !split.validation.contains(&name) {
                materials.push((name, net.to_flat()));
            }
        }
    }
    let config = AeConfig {
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
    };
    let lobes: Vec<(String, f64, f64)> = if config.lobe_weight > 0.0 {
        use rayon::prelude::*;
        with_threads(args.threads, || {
            nets.par_iter()
                .filter(|(name, _)| split.train.contains(name))
                .map(|(name, net)| phong_label(net, false).map(|(n, w)| (name.clone(), n, w)))
                .collect::<Result<_>>()
        })??
    } else {
        Vec::new()
    };
    let target = || {
        if args.quiet {
            ProgressDrawTarget::hidden()
        } else {
            ProgressDrawTarget::stderr()
        }
    };
    let style =
        ProgressStyle::with_template("{prefix}epoch {pos:>3}/{len} [{bar:24}] {msg}  ETA {eta}")
            .map_err(|e| invalid(format!("progress bar template: {e}")))?
            .progress_chars("=> ");
    let start = Instant::now();
    let mut best: Option<(f64, AutoEncoder, Vec<AeEpoch>)> = None;
    let mut candidates = Vec::new();
    for seed in args.seed..args.seed.saturating_add(args.seeds.max(1)) {
        let config = AeConfig {
            seed,
            ..config.clone()
        };
        let bar = ProgressBar::with_draw_target(Some(config.max_epochs as u64), target())
            .with_style(style.clone());
        if args.seeds > 1 {
            bar.set_prefix(format!("seed {seed} "));
        }
        let (ae, history) = with_threads(args.threads, || {
            AutoEncoder::train(&materials, &lobes, hidden, split.clone(), &config, |e| {
                bar.set_position(e.epoch as u64 + 1);
                if !args.quiet && bar.is_hidden() {
                    eprintln!(
                        "epoch {:>3} {} loss {:.4e} validation image loss {:.4e} ({:.1} s)",
                        e.epoch, e.phase, e.train_loss, e.validation_image_loss, e.seconds
                    );
                }
                bar.set_message(format!(
                    "{} loss {:.3e}, validation image loss {:.3e}",
                    e.phase, e.train_loss, e.validation_image_loss
                ));
            })
        })??;
        bar.finish_and_clear();
        if args.seeds <= 1 {
            best = Some((f64::NAN, ae, history));
            break;
        }
        let loss = with_threads(args.threads, || {
            ae.refined_validation_loss(&materials, args.select_refine)
        })??;
        if !args.quiet {
            eprintln!("seed {seed}: refined validation image loss {loss:.4e}");
        }
        candidates.push(serde_json::json!({"seed": seed, "refined_validation_loss": loss}));
        if best.as_ref().map_or(true, |(b, _, _)| loss < *b) {
            best = Some((loss, ae, history));
        }
    }
    let Some((_, mut ae, history)) = best else {
        return Err(invalid("no autoencoder trained".into()));
    };
    let seconds = start.elapsed().as_secs_f64();
    if let Some(obj) = ae.provenance.as_object_mut() {
        if args.seeds > 1 {
            obj.insert(
                "selection".into(),
                serde_json::json!({
                    "criterion": format!("mean image loss of the validation materials' codes refined by {} iterations", args.select_refine),
                    "candidates": candidates,
                }),
            );
        }
        obj.insert(
            "history".into(),
            serde_json::to_value(&history).unwrap_or_default(),
        );
        obj.insert("nbrdfs".into(), args.nbrdfs.display().to_string().into());
        if let Some(dir) = &args.extra_nbrdfs {
            obj.insert("extra_nbrdfs".into(), dir.display().to_string().into());
        }
    }
    ae.save(&args.output)?;
    let last = history.last();
    emit(&format!(
        "trained the autoencoder on {} materials x {} permutations ({} test) in {:.1} s, {} epochs, best epoch {}, validation image loss {:.4e}\nwrote {}\n",
        ae.split.train.len(),
        if config.augment { 6 } else { 1 },
        ae.split.test.len(),
        seconds,
        history.len(),
        ae.provenance["best_epoch"],
        last.map_or(f64::NAN, |e| e.validation_image_loss),
        args.output.display()
    ))
}

fn run_ae_encode(args: &AeEncodeArgs) -> Result<()> {
    let ae = AutoEncoder::load(&args.ae)?;
    let net = Nbrdf::load(&args.input)?;
    let t0 = Instant::now();
    let code = ae.encode_refined(&net, args.refine)?;
    let ms = t0.elapsed().as_secs_f64() * 1e3;
    if args.timing {
        eprintln!("encoded in {ms:.3} ms");
    }
    let text = serde_json::to_string(&code).map_err(|e| invalid(e.to_string()))?;
    emit(&format!("{text}\n"))
}

pub fn read_code(path: &Path) -> Result<Vec<f32>> {
    let text =
        std::fs::read_to_string(path).map_err(|e| invalid(format!("{}: {e}", path.display())))?;
    serde_json::from_str(&text).map_err(|e| invalid(format!("{}: {e}", path.display())))
}

fn stem_name(path: &Path) -> String {
    let file = path
        .file_name()
        .and_then(|f| f.to_str())
        .unwrap_or("decoded");
    file.strip_suffix(".nbrdf.json")
        .or_else(|| file.strip_suffix(".json"))
        .unwrap_or(file)
        .to_string()
}

fn run_ae_decode(args: &AeDecodeArgs) -> Result<()> {
    let ae = AutoEncoder::load(&args.ae)?;
    let code = read_code(&args.code)?;
    let name = args.name.clone().unwrap_or_else(|| stem_name(&args.output));
    let net = ae.decode(&code, &name)?;
    net.save(&args.output)?;
    emit(&format!("wrote {}\n", args.output.display()))
}

pub fn run_interpolate(args: &InterpolateArgs) -> Result<()> {
    if args.steps < 2 {
        return Err(invalid("--steps must be at least 2".into()));
    }
    let ae = AutoEncoder::load(&args.ae)?;
    let (a, b) = (Nbrdf::load(&args.a)?, Nbrdf::load(&args.b)?);
    let (za, zb) = (
        ae.encode_refined(&a, args.refine)?,
        ae.encode_refined(&b, args.refine)?,
    );
    let (wa, wb) = (a.to_flat(), b.to_flat());
    if wa.len() != wb.len() {
        return Err(invalid("the networks differ in size".into()));
    }
    std::fs::create_dir_all(&args.output)
        .map_err(|e| invalid(format!("{}: {e}", args.output.display())))?;
    let lerp = |x: &[f32], y: &[f32], t: f32| -> Vec<f32> {
        x.iter().zip(y).map(|(x, y)| x + t * (y - x)).collect()
    };
    for i in 0..args.steps {
        let t = i as f32 / (args.steps - 1) as f32;
        let name = format!("latent_{i:02}");
        let mut net = ae.decode(&lerp(&za, &zb, t), &name)?;
        net.provenance =
            serde_json::json!({"interpolation": "latent", "t": t, "a": a.name, "b": b.name});
        net.save(args.output.join(format!("{name}.nbrdf.json")))?;
        let name = format!("weights_{i:02}");
        let mut net = Nbrdf::from_flat(&name, a.hidden_width(), &lerp(&wa, &wb, t))?;
        net.provenance =
            serde_json::json!({"interpolation": "weights", "t": t, "a": a.name, "b": b.name});
        net.save(args.output.join(format!("{name}.nbrdf.json")))?;
    }
    emit(&format!(
        "wrote {} latent_NN and weights_NN networks to {}\n",
        args.steps,
        args.output.display()
    ))
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
    /// The trained autoencoder (from `nbrdf ae train`).
    #[arg(long, value_name = "AE.json")]
    ae: PathBuf,
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

fn errors_json(e: &nbrdf_core::metrics::ImageErrors) -> serde_json::Value {
    serde_json::json!({"mae": e.mae, "rmse": e.rmse, "ssim": e.ssim, "psnr": e.psnr})
}

/// `nbrdf ae eval`: AE and PCA reconstructions of the test split in image space (64 x 64 sphere,
/// light at 45 degrees; MAE and RMSE on linear pixels, SSIM tone-mapped), as JSON.
pub fn run_ae_eval(args: &AeEvalArgs) -> Result<()> {
    use nbrdf_core::analytic::{AnalyticBrdf, ModelKind};
    use nbrdf_core::coords::{from_rusinkiewicz, network_input};
    use nbrdf_core::latent::pca::{CellValues, Pca};
    use nbrdf_core::latent::sphere::{LIGHT_THETA_DEG, SIZE};
    use nbrdf_core::merl;
    use nbrdf_core::metrics::{image_errors, render_sphere};
    let ae = AutoEncoder::load(&args.ae)?;
    let nets = read_nbrdf_dir(&args.nbrdfs)?;
    let get = |name: &String| -> Result<&Nbrdf> {
        nets.iter()
            .find(|(n, _)| n == name)
            .map(|(_, net)| net)
            .ok_or_else(|| invalid(format!("no network for '{name}'")))
    };
    let theta = LIGHT_THETA_DEG.to_radians();
    with_threads(args.threads, || -> Result<()> {
        let t0 = Instant::now();
        let mut rows = Vec::new();
        let evaluated = match args.split {
            SplitArg::Test => &ae.split.test,
            SplitArg::Train => &ae.split.train,
            SplitArg::Validation => &ae.split.validation,
        };
        for name in evaluated {
            let net = get(name)?;
            let t = Instant::now();
            let code = ae.encode(net)?;
            let encode_ms = t.elapsed().as_secs_f64() * 1e3;
            let rec = ae.decode(&code, name)?;
            let reference = render_sphere(net, SIZE, theta);
            let e = image_errors(&reference, &render_sphere(&rec, SIZE, theta));
            let mut row =
                serde_json::json!({"name": name, "ae": errors_json(&e), "encode_ms": encode_ms});
            if args.refine > 0 {
                let t = Instant::now();
                let refined = ae.refine_code(&net.to_flat(), &code, args.refine);
                row["refine_ms"] = (t.elapsed().as_secs_f64() * 1e3).into();
                let rec = ae.decode(&refined, name)?;
                row["ae_refined"] =
                    errors_json(&image_errors(&reference, &render_sphere(&rec, SIZE, theta)));
            }
            rows.push(row);
        }
        let ae_seconds = t0.elapsed().as_secs_f64();
        // PCA: cell values of each material.
        let t0 = Instant::now();
        let cell_fn = |name: &String| -> Result<Box<CellValues<'_>>> {
            match args.pca_tables {
                PcaTables::Sgd => {
                    let brdf = AnalyticBrdf::from_catalogue(ModelKind::Sgd, name)?;
                    Ok(Box::new(move |cell: usize| {
                        let (h, d, p) = merl::cell_coordinates(cell);
                        let (l, v) = from_rusinkiewicz(&merl::cell_centre_angles(h, d, p));
                        brdf.eval_f64(l, v)
                    }))
                }
                PcaTables::Nbrdf => {
                    let net = get(name)?;
                    Ok(Box::new(move |cell: usize| {
                        let (h, d, p) = merl::cell_coordinates(cell);
                        let (l, v) = from_rusinkiewicz(&merl::cell_centre_angles(h, d, p));
                        net.eval_input(network_input(l.as_vec3(), v.as_vec3()))
                            .map(f64::from)
                    }))
                }
            }
        };
        let train: Vec<Box<CellValues<'_>>> =
            ae.split.train.iter().map(cell_fn).collect::<Result<_>>()?;
        let refs: Vec<&CellValues<'_>> = train.iter().map(|b| b.as_ref()).collect();
        let pca = Pca::fit(&refs, args.components, SIZE, theta);
        let fit_seconds = t0.elapsed().as_secs_f64();
        for (row, name) in rows.iter_mut().zip(evaluated) {
            let f = cell_fn(name)?;
            let truth = pca.values(f.as_ref());
            let rec = pca.reconstruct(f.as_ref());
            let e = image_errors(&pca.render(&truth), &pca.render(&rec));
            row["pca"] = errors_json(&e);
        }
        let summary = |key: &str, metric: &str| -> serde_json::Value {
            let v: Vec<f64> = rows
                .iter()
                .filter_map(|r| r[key][metric].as_f64())
                .collect();
            let n = v.len().max(1) as f64;
            let mean = v.iter().sum::<f64>() / n;
            let sd = (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n).sqrt();
            let mut sorted = v.clone();
            sorted.sort_by(f64::total_cmp);
            let median = sorted.get(sorted.len() / 2).copied().unwrap_or(f64::NAN);
            serde_json::json!({"mean": mean, "std": sd, "median": median})
        };
        let mut table = serde_json::Map::new();
        let keys: &[&str] = if args.refine > 0 {
            &["ae", "ae_refined", "pca"]
        } else {
            &["ae", "pca"]
        };
        for &key in keys {
            let mut m = serde_json::Map::new();
            for metric in ["mae", "rmse", "ssim"] {
                m.insert(metric.into(), summary(key, metric));
            }
            table.insert(key.into(), m.into());
        }
        let out = serde_json::json!({
            "split": match args.split { SplitArg::Test => "test", SplitArg::Train => "train", SplitArg::Validation => "validation" },
            "materials": rows,
            "summary": table,
            "pca": {"tables": match args.pca_tables { PcaTables::Sgd => "sgd", PcaTables::Nbrdf => "nbrdf" },
                    "components": pca.components(), "cells": pca.cells.len(), "fit_seconds": fit_seconds},
            "ae_eval_seconds": ae_seconds,
            "image": {"size": SIZE, "light_theta_deg": LIGHT_THETA_DEG},
        });
        let text = serde_json::to_string_pretty(&out).map_err(|e| invalid(e.to_string()))?;
        emit(&format!("{text}\n"))
    })?
}

#[derive(Args)]
pub struct PredictorTrainArgs {
    /// The trained autoencoder (from `nbrdf ae train`).
    #[arg(long, value_name = "AE.json")]
    ae: PathBuf,
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
    /// Predict from the 32-value code alone (DESIGN.md section 7), without the network's
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
pub struct PredictPhongArgs {
    /// The trained autoencoder (from `nbrdf ae train`).
    #[arg(long, value_name = "AE.json")]
    ae: PathBuf,
    /// The trained Phong-parameter predictor (from `nbrdf predictor train`).
    #[arg(long, value_name = "P.json")]
    predictor: PathBuf,
    /// The neural BRDF to read.
    #[arg(value_name = "NBRDF.json")]
    input: PathBuf,
    /// Where to write the network with the predicted sampling (default: in place).
    #[arg(short, long)]
    output: Option<PathBuf>,
    /// Print the encode + predict time to stderr.
    #[arg(long)]
    timing: bool,
}

/// The fitted Blinn-Phong `(n, w)` of a network: its own "fit" sampling, or a fresh fit.
fn phong_label(net: &Nbrdf, refit: bool) -> Result<(f64, f64)> {
    use nbrdf_core::coords::{from_rusinkiewicz, network_input, RusinkiewiczAngles};
    use nbrdf_core::phong_fit::{self, FitConfig};
    if let Some(s) = &net.sampling {
        if s.source == "fit" && !refit {
            return Ok((s.exponent as f64, s.specular_weight as f64));
        }
    }
    let target = |a: &RusinkiewiczAngles| {
        let (l, v) = from_rusinkiewicz(a);
        Some(
            net.eval_input(network_input(l.as_vec3(), v.as_vec3()))
                .map(f64::from),
        )
    };
    let fit = phong_fit::fit(&target, &FitConfig::default())?;
    Ok((fit.params.exponent, fit.params.specular_weight()))
}

/// What [`cross_validate`] needs of the training split: per material (`names`, `labels`,
/// `quadratures`), and the examples with the index of their material.
struct CrossValidationData<'a> {
    names: &'a [&'a str],
    labels: &'a [(f64, f64)],
    quadratures: &'a [LobeQuadrature],
    examples: &'a [nbrdf_core::latent::predictor::Example],
    example_material: &'a [usize],
    grids: Option<&'a [&'a VarianceGrid]>,
}

/// `folds`-fold cross-validation by material name over the training split (the test split stays
/// unseen, so settings can be chosen here): each fold's materials are predicted by an ensemble
/// trained on the others, from their unpermuted code; the score is the sampling RMSE ratio
/// `sqrt(R_pred - 1) / sqrt(R_fit - 1)` of the lobe-search quadrature, as `predictor eval`.
fn cross_validate(
    data: &CrossValidationData<'_>,
    config: &PredictorConfig,
    folds: usize,
) -> Result<serde_json::Value> {
    use nbrdf_core::latent::predictor::PhongPredictor;
    let mut unique: Vec<&str> = data.names.to_vec();
    unique.sort_unstable();
    unique.dedup();
    // Every network of one material name (extra networks included) falls in the same fold.
    let material_fold: Vec<usize> = data
        .names
        .iter()
        .map(|n| unique.iter().position(|u| u == n).unwrap_or(0) % folds)
        .collect();
    let mut rows = Vec::new();
    for fold in 0..folds {
        let keep: Vec<usize> = (0..data.examples.len())
            .filter(|&i| material_fold[data.example_material[i]] != fold)
            .collect();
        let examples: Vec<_> = keep.iter().map(|&i| data.examples[i].clone()).collect();
        let grids: Option<Vec<&VarianceGrid>> =
            data.grids.map(|g| keep.iter().map(|&i| g[i]).collect());
        let pred = PhongPredictor::train_ensemble(&examples, grids.as_deref(), config)?;
        // The first example of a material is its identity permutation.
        let mut seen = Vec::new();
        for (i, &m) in data.example_material.iter().enumerate() {
            if material_fold[m] != fold || seen.contains(&m) {
                continue;
            }
            seen.push(m);
            let (n, w) = pred.predict(&data.examples[i].0);
            let q = &data.quadratures[m];
            let (n_fit, w_fit) = data.labels[m];
            let ratio = rmse_ratio(
                q.relative_variance(n as f64, w as f64),
                q.relative_variance(n_fit, w_fit),
            );
            rows.push((data.names[m].to_string(), ratio, n, w));
        }
    }
    let mut ratios: Vec<f64> = rows.iter().map(|r| r.1).collect();
    ratios.sort_by(f64::total_cmp);
    let worst = rows
        .iter()
        .max_by(|a, b| a.1.total_cmp(&b.1))
        .map(|r| format!("{} {:.2}", r.0, r.1))
        .unwrap_or_default();
    Ok(serde_json::json!({
        "folds": folds,
        "geometric_mean": (ratios.iter().map(|r| r.ln()).sum::<f64>() / ratios.len().max(1) as f64).exp(),
        "median": ratios.get(ratios.len() / 2).copied().unwrap_or(f64::NAN),
        "mean": ratios.iter().sum::<f64>() / ratios.len().max(1) as f64,
        "max": ratios.last().copied().unwrap_or(f64::NAN),
        "worst": worst,
        "within_1_25": ratios.iter().filter(|&&r| r <= 1.25).count(),
        "materials": ratios.len(),
        "materials_ratio": rows.iter().map(|r| serde_json::json!({"name": r.0, "rmse_ratio": r.1, "exponent": r.2, "specular_weight": r.3})).collect::<Vec<_>>(),
    }))
}

/// Sampling RMSE of a lobe over the fitted lobe's, from their relative variances `R - 1`: the
/// RMSE of an estimator scales with the square root of its variance.
fn rmse_ratio(relative_variance: f64, fitted_relative_variance: f64) -> f64 {
    (relative_variance.max(1e-12) / fitted_relative_variance.max(1e-12)).sqrt()
}

/// The lobe-search quadrature of a network (it evaluates the network once).
fn network_quadrature(net: &Nbrdf) -> Result<LobeQuadrature> {
    use nbrdf_core::coords::{from_rusinkiewicz, network_input, RusinkiewiczAngles};
    use nbrdf_core::lobe_fit::LobeFitConfig;
    let target = |a: &RusinkiewiczAngles| {
        let (l, v) = from_rusinkiewicz(a);
        Some(
            net.eval_input(network_input(l.as_vec3(), v.as_vec3()))
                .map(f64::from),
        )
    };
    LobeQuadrature::new(&target, &LobeFitConfig::default())
}

pub fn run_predictor_eval(args: &PredictorEvalArgs) -> Result<()> {
    use nbrdf_core::latent::predictor::PhongPredictor;
    let ae = AutoEncoder::load(&args.ae)?;
    let pred = PhongPredictor::load(&args.predictor)?;
    let nets = read_nbrdf_dir(&args.nbrdfs)?;
    with_threads(args.threads, || -> Result<()> {
        let mut rows = Vec::new();
        let mut ratios = Vec::new();
        for name in &ae.split.test {
            let Some((_, net)) = nets.iter().find(|(n, _)| n == name) else {
                return Err(invalid(format!("no network for '{name}'")));
            };
            let (n_fit, w_fit) = phong_label(net, false)?;
            let code = ae.encode_refined(net, pred.refine_steps)?;
            let (n_pred, w_pred) = pred.predict(&pred.inputs(&code, net));
            let q = network_quadrature(net)?;
            let (v_fit, v_pred, v_cos) = (
                q.relative_variance(n_fit, w_fit),
                q.relative_variance(n_pred as f64, w_pred as f64),
                q.relative_variance(0.0, 0.0),
            );
            let ratio = rmse_ratio(v_pred, v_fit);
            ratios.push(ratio);
            rows.push(serde_json::json!({
                "name": name,
                "fitted": {"exponent": n_fit, "specular_weight": w_fit, "relative_variance": v_fit},
                "predicted": {"exponent": n_pred, "specular_weight": w_pred, "relative_variance": v_pred},
                "cosine_relative_variance": v_cos,
                "rmse_ratio": ratio,
            }));
        }
        let mut sorted = ratios.clone();
        sorted.sort_by(f64::total_cmp);
        let out = serde_json::json!({
            "test": rows,
            "rmse_ratio": {
                "median": sorted.get(sorted.len() / 2).copied().unwrap_or(f64::NAN),
                "max": sorted.last().copied().unwrap_or(f64::NAN),
                "within_1_25": ratios.iter().filter(|&&r| r <= 1.25).count(),
                "materials": ratios.len(),
            },
        });
        let text = serde_json::to_string_pretty(&out).map_err(|e| invalid(e.to_string()))?;
        emit(&format!("{text}\n"))
    })?
}

pub fn run_predictor_train(args: &PredictorTrainArgs) -> Result<()> {
    use nbrdf_core::latent::autoencoder::{permute_outputs, PERMUTATIONS};
    use nbrdf_core::latent::predictor::{highlight_profile, PhongPredictor};
    use rayon::prelude::*;
    if args.cross_validate == 1 {
        return Err(invalid(
            "--cross-validate needs at least 2 folds (0 turns it off)".into(),
        ));
    }
    let ae = AutoEncoder::load(&args.ae)?;
    let mut nets = read_nbrdf_dir(&args.nbrdfs)?;
    if let Some(dir) = &args.extra_nbrdfs {
        // Only training materials: `train` below keeps those.
        nets.extend(read_nbrdf_dir(dir)?);
    }
    with_threads(args.threads, || -> Result<()> {
        let t0 = Instant::now();
        let train: Vec<&(String, Nbrdf)> = nets
            .iter()
            .filter(|(n, _)| ae.split.train.contains(n))
            .collect();
        let labels: Vec<(f64, f64)> = train
            .par_iter()
            .map(|(_, net)| phong_label(net, args.refit))
            .collect::<Result<_>>()?;
        let quadratures: Vec<LobeQuadrature> =
            if args.loss == PredictorLoss::Variance || args.cross_validate > 1 {
                train
                    .iter()
                    .map(|(_, net)| network_quadrature(net))
                    .collect::<Result<_>>()?
            } else {
                Vec::new()
            };
        let grids: Vec<VarianceGrid> = if args.loss == PredictorLoss::Variance {
            quadratures
                .iter()
                .map(|q| VarianceGrid::new(|n, w| q.relative_variance(n, w)))
                .collect()
        } else {
            Vec::new()
        };
        let label_seconds = t0.elapsed().as_secs_f64();
        let t1 = Instant::now();
        // The lobe (and its variance, computed on the mean over RGB) is invariant under RGB
        // permutations, so every augmented code shares it.
        let inputs: Vec<(usize, Vec<f32>)> = train
            .iter()
            .enumerate()
            .flat_map(|(m, (_, net))| {
                PERMUTATIONS
                    .iter()
                    .map(move |&p| (m, permute_outputs(&net.to_flat(), net.hidden_width(), p)))
            })
            .collect();
        let codes: Vec<Vec<f32>> = inputs
            .par_iter()
            .map(|(_, flat)| ae.refine_code(flat, &ae.encode_flat(flat), args.refine))
            .collect();
        let mut examples = Vec::new();
        let mut example_grids = Vec::new();
        // The profile is a mean over RGB: one per material serves its 6 permutations.
        let profiles: Vec<Vec<f32>> = train
            .iter()
            .map(|(_, net)| {
                if !args.code_only {
                    highlight_profile(net)
                } else {
                    Vec::new()
                }
            })
            .collect();
        for ((m, _), mut code) in inputs.iter().zip(codes) {
            let (n, w) = labels[*m];
            code.extend_from_slice(&profiles[*m]);
            examples.push((code, n, w));
            example_grids.extend(grids.get(*m));
        }
        let grids_arg = (!example_grids.is_empty()).then_some(example_grids.as_slice());
        let config = PredictorConfig {
            hidden: args.hidden,
            iterations: args.iterations,
            seed: args.seed,
            members: args.members,
            weight_decay: args.weight_decay,
        };
        let cross_validation = if args.cross_validate > 1 {
            let names: Vec<&str> = train.iter().map(|(n, _)| n.as_str()).collect();
            let example_material: Vec<usize> = inputs.iter().map(|(m, _)| *m).collect();
            let cv = cross_validate(
                &CrossValidationData {
                    names: &names,
                    labels: &labels,
                    quadratures: &quadratures,
                    examples: &examples,
                    example_material: &example_material,
                    grids: grids_arg,
                },
                &config,
                args.cross_validate,
            )?;
            emit(&format!(
                "{}-fold cross-validation over the training split: sampling RMSE ratio predicted/fitted (lobe-search quadrature) geometric mean {:.3}, median {:.3}, mean {:.3}, max {:.3} ({}), within 1.25x for {} of {} materials\n",
                args.cross_validate,
                cv["geometric_mean"].as_f64().unwrap_or(f64::NAN),
                cv["median"].as_f64().unwrap_or(f64::NAN),
                cv["mean"].as_f64().unwrap_or(f64::NAN),
                cv["max"].as_f64().unwrap_or(f64::NAN),
                cv["worst"].as_str().unwrap_or(""),
                cv["within_1_25"],
                cv["materials"],
            ))?;
            Some(cv)
        } else {
            None
        };
        let mut pred = PhongPredictor::train_ensemble(&examples, grids_arg, &config)?;
        pred.refine_steps = args.refine;
        pred.highlight_profile = !args.code_only;
        let train_seconds = t1.elapsed().as_secs_f64();
        if let Some(o) = pred.provenance.as_object_mut() {
            o.insert("labels".into(), serde_json::json!(train.iter().zip(&labels).map(|((name, _), (n, w))| serde_json::json!({"name": name, "exponent": n, "specular_weight": w})).collect::<Vec<_>>()));
            o.insert("label_seconds".into(), label_seconds.into());
            o.insert("train_seconds".into(), train_seconds.into());
            o.insert("highlight_profile".into(), (!args.code_only).into());
            if let Some(cv) = cross_validation {
                o.insert("cross_validation".into(), cv);
            }
        }
        pred.save(&args.output)?;
        emit(&format!(
            "labels for {} materials in {:.1} s; trained the predictor on {} codes in {:.2} s\nwrote {}\n",
            train.len(),
            label_seconds,
            examples.len(),
            train_seconds,
            args.output.display()
        ))
    })?
}

pub fn run_predict_phong(args: &PredictPhongArgs) -> Result<()> {
    use nbrdf_core::latent::predictor::PhongPredictor;
    use nbrdf_core::network::{SamplingParams, SAMPLING_MODEL_BLINN_PHONG};
    let ae = AutoEncoder::load(&args.ae)?;
    let pred = PhongPredictor::load(&args.predictor)?;
    let mut net = Nbrdf::load(&args.input)?;
    let t0 = Instant::now();
    let code = ae.encode_refined(&net, pred.refine_steps)?;
    let (n, w) = pred.predict(&pred.inputs(&code, &net));
    let ms = t0.elapsed().as_secs_f64() * 1e3;
    if args.timing {
        eprintln!("encoded and predicted in {ms:.3} ms");
    }
    net.sampling = Some(SamplingParams {
        model: SAMPLING_MODEL_BLINN_PHONG.to_string(),
        exponent: n,
        specular_weight: w,
        source: "predicted".to_string(),
    });
    net.validate()?;
    let out = args.output.clone().unwrap_or_else(|| args.input.clone());
    net.save(&out)?;
    emit(&format!(
        "predicted blinn-phong: exponent {n:.4}, specular weight {w:.4}\nwrote {}\n",
        out.display()
    ))
}
