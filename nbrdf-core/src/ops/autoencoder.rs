//! `nbrdf ae train|encode|decode|eval` and `nbrdf interpolate`: the autoencoder over networks.

use super::{limits, read_nbrdf_dir, with_threads};
use crate::analytic::{AnalyticBrdf, ModelKind};
use crate::coords::from_rusinkiewicz;
use crate::error::{NbrdfError, Result};
use crate::latent::autoencoder::{AeConfig, AeEpoch, AutoEncoder, Split};
use crate::latent::family::{self, Family, Relearn, RelearnObserver};
use crate::latent::pca::{CellValues, Pca};
use crate::latent::predictor::lobe_label;
use crate::latent::sphere::{LIGHT_THETA_DEG, SIZE};
use crate::merl;
use crate::metrics::{image_errors, render_sphere, ImageErrors};
use crate::network::Nbrdf;
use rayon::prelude::*;
use serde::Serialize;
use std::collections::BTreeMap;
use std::fmt;
use std::path::{Path, PathBuf};
use std::time::Instant;

fn invalid(message: String) -> NbrdfError {
    NbrdfError::InvalidArgument(message)
}

/// What `ae train` trains.
#[derive(Clone, Debug, PartialEq)]
pub struct AeTrainRequest {
    /// Directory of `NAME.nbrdf.json` networks, all of one hidden width.
    pub nbrdfs: PathBuf,
    /// More networks; only those of training (not validation) materials are used.
    pub extra_nbrdfs: Option<PathBuf>,
    pub output: PathBuf,
    /// The settings; `config.seed` is the first seed.
    pub config: AeConfig,
    /// Autoencoders trained (seeds `seed`, `seed + 1`, ...); with more than one, the one whose
    /// refined codes reconstruct the validation materials best is kept.
    pub seeds: u64,
    /// Refinement iterations of that choice.
    pub select_refine: usize,
    pub threads: Option<usize>,
}

/// What `ae train` reports while it runs.
pub trait AeTrainObserver {
    /// A seed's training starts; `several` when more than one seed is trained.
    fn seed_started(&mut self, seed: u64, max_epochs: usize, several: bool);
    /// After every epoch (on the worker pool).
    fn epoch(&mut self, epoch: &AeEpoch);
    /// A seed's training ended.
    fn seed_finished(&mut self);
    /// With several seeds: a seed's refined validation image loss.
    fn seed_scored(&mut self, seed: u64, loss: f64);
}

/// One candidate of the choice between seeds.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct SeedCandidate {
    pub seed: u64,
    pub refined_validation_loss: f64,
}

/// What `ae train` wrote.
#[derive(Clone, Debug, PartialEq)]
pub struct AeTrainReport {
    pub output: PathBuf,
    pub train_materials: usize,
    pub permutations: usize,
    pub test_materials: usize,
    pub seconds: f64,
    pub epochs: usize,
    pub best_epoch: Option<usize>,
    /// Of the last epoch.
    pub validation_image_loss: f64,
}

impl fmt::Display for AeTrainReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "trained the autoencoder on {} materials x {} permutations ({} test) in {:.1} s, {} epochs, best epoch {}, validation image loss {:.4e}\nwrote {}",
            self.train_materials,
            self.permutations,
            self.test_materials,
            self.seconds,
            self.epochs,
            self.best_epoch
                .map_or_else(|| "null".to_string(), |e| e.to_string()),
            self.validation_image_loss,
            self.output.display()
        )
    }
}

/// Named flat networks.
type FlatNetworks = Vec<(String, Vec<f32>)>;

/// The flat networks the autoencoder trains on (with the extra networks of training
/// materials), their hidden width, the fixed split and the family of the networks trained on
/// (`None` unless they share one initialisation of `nbrdf train`, [`Family::common`]).
fn training_materials(
    nets: &[(String, Nbrdf)],
    extra: Option<&Path>,
) -> Result<(FlatNetworks, usize, Split, Option<Family>)> {
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
    let mut used: Vec<Nbrdf> = Vec::new();
    if let Some(dir) = extra {
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
                used.push(net);
            }
        }
    }
    let family = Family::common(nets.iter().map(|(_, n)| n).chain(&used));
    Ok((materials, hidden, split, family))
}

/// The settings' ranges (docs/hardening.md).
fn check_train_request(request: &AeTrainRequest) -> Result<()> {
    let c = &request.config;
    limits::check_range("--hidden", c.hidden, 1, limits::MAX_HIDDEN)?;
    limits::check_range("--epochs", c.max_epochs, 1, limits::MAX_EPOCHS)?;
    limits::check_range("--warmup", c.warmup_epochs, 0, limits::MAX_EPOCHS)?;
    limits::check_range("--batch", c.batch, 1, limits::MAX_BATCH)?;
    limits::check_range("--mixup", c.mixup, 0, limits::MAX_ITERATIONS)?;
    limits::check_range("--image-size", c.image_size, 1, limits::MAX_RESOLUTION)?;
    limits::check_range(
        "--select-refine",
        request.select_refine,
        0,
        limits::MAX_ITERATIONS,
    )?;
    let seeds = usize::try_from(request.seeds).unwrap_or(usize::MAX);
    limits::check_range("--seeds", seeds, 1, limits::MAX_ITERATIONS)
}

/// The sampling lobe of each training material, for the lobe term of the loss (none when its
/// weight is 0).
fn training_lobes(
    request: &AeTrainRequest,
    nets: &[(String, Nbrdf)],
    split: &Split,
) -> Result<Vec<(String, f64, f64)>> {
    if request.config.lobe_weight > 0.0 {
        with_threads(request.threads, || {
            nets.par_iter()
                .filter(|(name, _)| split.train.contains(name))
                .map(|(name, net)| lobe_label(net, false).map(|(n, w)| (name.clone(), n, w)))
                .collect::<Result<_>>()
        })?
    } else {
        Ok(Vec::new())
    }
}

/// What the autoencoder trains on.
struct TrainingSet {
    materials: FlatNetworks,
    lobes: Vec<(String, f64, f64)>,
    hidden: usize,
    split: Split,
}

/// Trains one autoencoder per seed of `request.seeds` and keeps the one whose refined
/// validation loss is lowest (the only one, with one seed), with its history and every seed's
/// score.
fn train_best_seed(
    request: &AeTrainRequest,
    set: &TrainingSet,
    observer: &mut (dyn AeTrainObserver + Send),
) -> Result<(AutoEncoder, Vec<AeEpoch>, Vec<SeedCandidate>)> {
    let several = request.seeds > 1;
    let mut best: Option<(f64, AutoEncoder, Vec<AeEpoch>)> = None;
    let mut candidates = Vec::new();
    let first = request.config.seed;
    for seed in first..first.saturating_add(request.seeds.max(1)) {
        let config = AeConfig {
            seed,
            ..request.config.clone()
        };
        observer.seed_started(seed, config.max_epochs, several);
        let (ae, history) = with_threads(request.threads, || {
            AutoEncoder::train(
                &set.materials,
                &set.lobes,
                set.hidden,
                set.split.clone(),
                &config,
                |e| observer.epoch(e),
            )
        })??;
        observer.seed_finished();
        if !several {
            best = Some((f64::NAN, ae, history));
            break;
        }
        let loss = with_threads(request.threads, || {
            ae.refined_validation_loss(&set.materials, request.select_refine)
        })??;
        observer.seed_scored(seed, loss);
        candidates.push(SeedCandidate {
            seed,
            refined_validation_loss: loss,
        });
        if best.as_ref().map_or(true, |(b, _, _)| loss < *b) {
            best = Some((loss, ae, history));
        }
    }
    let Some((_, ae, history)) = best else {
        return Err(invalid("no autoencoder trained".into()));
    };
    Ok((ae, history, candidates))
}

/// Trains the autoencoder (of the best of `request.seeds` seeds) and writes it with its
/// history and, with several seeds, the choice in its provenance.
pub fn train_autoencoder(
    request: &AeTrainRequest,
    observer: &mut (dyn AeTrainObserver + Send),
) -> Result<AeTrainReport> {
    check_train_request(request)?;
    let nets = read_nbrdf_dir(&request.nbrdfs)?;
    let (materials, hidden, split, family) =
        training_materials(&nets, request.extra_nbrdfs.as_deref())?;
    let lobes = training_lobes(request, &nets, &split)?;
    let set = TrainingSet {
        materials,
        lobes,
        hidden,
        split,
    };
    let start = Instant::now();
    let (mut ae, history, candidates) = train_best_seed(request, &set, observer)?;
    let seconds = start.elapsed().as_secs_f64();
    if let Some(obj) = ae.provenance.as_object_mut() {
        if request.seeds > 1 {
            obj.insert(
                "selection".into(),
                serde_json::json!({
                    "criterion": format!("mean image loss of the validation materials' codes refined by {} iterations", request.select_refine),
                    "candidates": candidates,
                }),
            );
        }
        obj.insert(
            "history".into(),
            serde_json::to_value(&history).unwrap_or_default(),
        );
        obj.insert("nbrdfs".into(), request.nbrdfs.display().to_string().into());
        // What the commands that encode read back to decide which networks to re-learn.
        obj.insert("networks".into(), Family::record(family));
        if let Some(dir) = &request.extra_nbrdfs {
            obj.insert("extra_nbrdfs".into(), dir.display().to_string().into());
        }
    }
    ae.save(&request.output)?;
    Ok(AeTrainReport {
        output: request.output.clone(),
        train_materials: ae.split.train.len(),
        permutations: if request.config.augment { 6 } else { 1 },
        test_materials: ae.split.test.len(),
        seconds,
        epochs: history.len(),
        best_epoch: ae.provenance["best_epoch"].as_u64().map(|e| e as usize),
        validation_image_loss: history.last().map_or(f64::NAN, |e| e.validation_image_loss),
    })
}

/// A network's code and how long encoding took.
#[derive(Clone, Debug, PartialEq)]
pub struct Encoded {
    pub code: Vec<f32>,
    /// Encoding time (a re-learn before it not included).
    pub milliseconds: f64,
}

/// How the commands that encode networks treat those foreign to the autoencoder's family
/// ([`family::encodable`]), and who hears about it.
pub struct Encoding<'a> {
    pub relearn: Relearn,
    pub observer: &'a mut dyn RelearnObserver,
}

impl Encoding<'_> {
    /// `net` as `ae` can encode it.
    pub fn prepare<'n>(
        &mut self,
        ae: &AutoEncoder,
        net: &'n Nbrdf,
    ) -> Result<std::borrow::Cow<'n, Nbrdf>> {
        if let Relearn::Auto {
            max_epochs: Some(epochs),
        } = self.relearn
        {
            limits::check_range("--relearn-epochs", epochs, 1, limits::MAX_EPOCHS)?;
        }
        family::encodable(Family::of(ae), net, self.relearn, &mut *self.observer)
    }
}

/// The code of the network at `input` (re-learnt first if foreign, see [`Encoding`]), refined
/// by `refine` iterations.
pub fn encode(
    ae: &AutoEncoder,
    input: &Path,
    refine: usize,
    encoding: &mut Encoding<'_>,
) -> Result<Encoded> {
    limits::check_range("--refine", refine, 0, limits::MAX_ITERATIONS)?;
    let net = Nbrdf::load(input)?;
    net.require_no_base("encoding it")?;
    let net = encoding.prepare(ae, &net)?;
    let t0 = Instant::now();
    let code = ae.encode_refined(&net, refine)?;
    Ok(Encoded {
        code,
        milliseconds: t0.elapsed().as_secs_f64() * 1e3,
    })
}

/// A code: a JSON array of numbers.
pub fn read_code(path: &Path) -> Result<Vec<f32>> {
    crate::error::regular_file_size(path, 64 << 20, "a code (a JSON array of numbers)")?;
    let text =
        std::fs::read_to_string(path).map_err(|e| invalid(format!("{}: {e}", path.display())))?;
    serde_json::from_str(&text).map_err(|e| invalid(format!("{}: {e}", path.display())))
}

/// The default name of a decoded network: the output's file name without `.nbrdf.json`.
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

/// Decodes the code at `code` into a network named `name` (default: `output`'s stem) and
/// writes it to `output`.
pub fn decode(ae: &AutoEncoder, code: &Path, output: &Path, name: Option<&str>) -> Result<()> {
    let code = read_code(code)?;
    let name = name.map_or_else(|| stem_name(output), str::to_string);
    ae.decode(&code, &name)?.save(output)
}

/// Writes `steps` networks along the latent path (`latent_NN`) and the weight-space path
/// (`weights_NN`) from `a` to `b` into `output`; the endpoint codes are refined by `refine`
/// iterations. Foreign endpoints are re-learnt first ([`Encoding`]), and both paths start
/// from those: weights are only comparable between networks of one initialisation.
pub fn interpolate(
    ae: &AutoEncoder,
    (a, b): (&Path, &Path),
    steps: usize,
    refine: usize,
    output: &Path,
    encoding: &mut Encoding<'_>,
) -> Result<()> {
    limits::check_range("--steps", steps, 2, 1000)?;
    limits::check_range("--refine", refine, 0, limits::MAX_ITERATIONS)?;
    let (a, b) = (Nbrdf::load(a)?, Nbrdf::load(b)?);
    a.require_no_base("interpolating it")?;
    b.require_no_base("interpolating it")?;
    // Both checked before either is relearnt (minutes), not only when its turn comes.
    crate::latent::require_isotropic(&a)?;
    crate::latent::require_isotropic(&b)?;
    let (a, b) = (encoding.prepare(ae, &a)?, encoding.prepare(ae, &b)?);
    let (za, zb) = (
        ae.encode_refined(&a, refine)?,
        ae.encode_refined(&b, refine)?,
    );
    let (wa, wb) = (a.to_flat(), b.to_flat());
    if wa.len() != wb.len() {
        return Err(invalid("the networks differ in size".into()));
    }
    std::fs::create_dir_all(output).map_err(|e| invalid(format!("{}: {e}", output.display())))?;
    let lerp = |x: &[f32], y: &[f32], t: f32| -> Vec<f32> {
        x.iter().zip(y).map(|(x, y)| x + t * (y - x)).collect()
    };
    for i in 0..steps {
        let t = i as f32 / (steps - 1) as f32;
        let name = format!("latent_{i:02}");
        let mut net = ae.decode(&lerp(&za, &zb, t), &name)?;
        net.provenance =
            serde_json::json!({"interpolation": "latent", "t": t, "a": a.name, "b": b.name});
        net.save(output.join(format!("{name}.nbrdf.json")))?;
        let name = format!("weights_{i:02}");
        let mut net = Nbrdf::from_flat(&name, a.hidden_width(), &lerp(&wa, &wb, t))?;
        net.provenance =
            serde_json::json!({"interpolation": "weights", "t": t, "a": a.name, "b": b.name});
        net.save(output.join(format!("{name}.nbrdf.json")))?;
    }
    Ok(())
}

/// The autoencoder's image errors on one material decoded from its code, the encoding time
/// (ms), and with `refine > 0` the refinement time (ms) and errors of the refined code.
type AeErrors = (ImageErrors, f64, Option<(f64, ImageErrors)>);

/// [`AeErrors`] of one material.
fn ae_errors(ae: &AutoEncoder, net: &Nbrdf, name: &str, refine: usize) -> Result<AeErrors> {
    let theta = LIGHT_THETA_DEG.to_radians();
    let t = Instant::now();
    let code = ae.encode(net)?;
    let encode_ms = t.elapsed().as_secs_f64() * 1e3;
    let rec = ae.decode(&code, name)?;
    let reference = render_sphere(net, SIZE, theta);
    let errors = image_errors(&reference, &render_sphere(&rec, SIZE, theta));
    let refined = if refine > 0 {
        let t = Instant::now();
        let refined = ae.refine_code(&net.to_flat(), &code, refine);
        let refine_ms = t.elapsed().as_secs_f64() * 1e3;
        let rec = ae.decode(&refined, name)?;
        let e = image_errors(&reference, &render_sphere(&rec, SIZE, theta));
        Some((refine_ms, e))
    } else {
        None
    };
    Ok((errors, encode_ms, refined))
}

/// The MERL cell values of a material that the PCA baseline decomposes: its SGD fit's or its
/// network's (`net` is asked only then).
fn pca_cell_values<'a>(
    tables: PcaTables,
    name: &str,
    net: impl FnOnce() -> Result<&'a Nbrdf>,
) -> Result<Box<CellValues<'a>>> {
    match tables {
        PcaTables::Sgd => {
            let brdf = AnalyticBrdf::from_catalogue(ModelKind::Sgd, name)?;
            Ok(Box::new(move |cell: usize| {
                let (h, d, p) = merl::cell_coordinates(cell);
                let (v, l) = from_rusinkiewicz(&merl::cell_centre_angles(h, d, p));
                brdf.eval_f64(v, l)
            }))
        }
        PcaTables::Nbrdf => {
            let net = net()?;
            Ok(Box::new(move |cell: usize| {
                let (h, d, p) = merl::cell_coordinates(cell);
                net.eval_at_angles(&merl::cell_centre_angles(h, d, p))
            }))
        }
    }
}

/// Which tables the PCA baseline of `ae eval` decomposes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PcaTables {
    /// The SGD fits of the MERL materials at cell centres.
    Sgd,
    /// The networks themselves at cell centres.
    Nbrdf,
}

impl PcaTables {
    pub fn as_str(self) -> &'static str {
        match self {
            PcaTables::Sgd => "sgd",
            PcaTables::Nbrdf => "nbrdf",
        }
    }
}

/// Which materials of the autoencoder's split.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SplitPart {
    Test,
    Train,
    Validation,
}

impl SplitPart {
    pub fn as_str(self) -> &'static str {
        match self {
            SplitPart::Test => "test",
            SplitPart::Train => "train",
            SplitPart::Validation => "validation",
        }
    }

    fn of(self, split: &Split) -> &[String] {
        match self {
            SplitPart::Test => &split.test,
            SplitPart::Train => &split.train,
            SplitPart::Validation => &split.validation,
        }
    }
}

/// What `ae eval` evaluates.
#[derive(Clone, Debug, PartialEq)]
pub struct AeEvalRequest {
    pub nbrdfs: PathBuf,
    pub pca_tables: PcaTables,
    pub components: usize,
    pub split: SplitPart,
    /// Also the autoencoder with codes refined by this many iterations (0: not).
    pub refine: usize,
    pub threads: Option<usize>,
}

/// The errors of one material's reconstructions.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct MaterialErrors {
    pub name: String,
    pub ae: ImageErrors,
    pub encode_ms: f64,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub refine_ms: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ae_refined: Option<ImageErrors>,
    pub pca: ImageErrors,
}

/// Mean, standard deviation and median of a metric over the materials.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Summary {
    pub mean: f64,
    pub std: f64,
    pub median: f64,
}

impl Summary {
    /// Over the finite values (a JSON report has no others).
    fn of(values: impl Iterator<Item = f64>) -> Self {
        let v: Vec<f64> = values.filter(|x| x.is_finite()).collect();
        let n = v.len().max(1) as f64;
        let mean = v.iter().sum::<f64>() / n;
        let std = (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n).sqrt();
        let mut sorted = v.clone();
        sorted.sort_by(f64::total_cmp);
        let median = sorted.get(sorted.len() / 2).copied().unwrap_or(f64::NAN);
        Summary { mean, std, median }
    }
}

/// The PCA baseline's settings and fit time.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct PcaInfo {
    pub tables: &'static str,
    pub components: usize,
    pub cells: usize,
    pub fit_seconds: f64,
}

/// The evaluation image.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct ImageInfo {
    pub size: usize,
    pub light_theta_deg: f64,
}

/// What `ae eval` prints.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct AeEvalReport {
    pub split: &'static str,
    pub materials: Vec<MaterialErrors>,
    /// Per method (`ae`, `ae_refined`, `pca`) and metric (`mae`, `rmse`, `ssim`).
    pub summary: BTreeMap<&'static str, BTreeMap<&'static str, Summary>>,
    pub pca: PcaInfo,
    pub ae_eval_seconds: f64,
    pub image: ImageInfo,
}

/// AE and PCA reconstructions of a part of the split in image space (64 x 64 sphere, light at
/// 45 degrees; MAE and RMSE on linear pixels, SSIM tone-mapped).
pub fn evaluate_autoencoder(ae: &AutoEncoder, request: &AeEvalRequest) -> Result<AeEvalReport> {
    limits::check_range("--refine", request.refine, 0, limits::MAX_ITERATIONS)?;
    limits::check_range("--components", request.components, 1, 10_000)?;
    let nets = read_nbrdf_dir(&request.nbrdfs)?;
    let get = |name: &String| -> Result<&Nbrdf> {
        nets.iter()
            .find(|(n, _)| n == name)
            .map(|(_, net)| net)
            .ok_or_else(|| invalid(format!("no network for '{name}'")))
    };
    let theta = LIGHT_THETA_DEG.to_radians();
    with_threads(request.threads, || -> Result<AeEvalReport> {
        let t0 = Instant::now();
        let evaluated = request.split.of(&ae.split);
        let mut rows = Vec::new();
        for name in evaluated {
            let (errors, encode_ms, refined) = ae_errors(ae, get(name)?, name, request.refine)?;
            rows.push((name, errors, encode_ms, refined));
        }
        let ae_eval_seconds = t0.elapsed().as_secs_f64();
        // PCA: cell values of each material.
        let t0 = Instant::now();
        let cell_fn = |name: &String| pca_cell_values(request.pca_tables, name, || get(name));
        let train: Vec<Box<CellValues<'_>>> =
            ae.split.train.iter().map(cell_fn).collect::<Result<_>>()?;
        let refs: Vec<&CellValues<'_>> = train.iter().map(|b| b.as_ref()).collect();
        let pca = Pca::fit(&refs, request.components, SIZE, theta);
        let fit_seconds = t0.elapsed().as_secs_f64();
        let mut materials = Vec::new();
        for (name, errors, encode_ms, refined) in rows {
            let f = cell_fn(name)?;
            let truth = pca.values(f.as_ref());
            let rec = pca.reconstruct(f.as_ref());
            materials.push(MaterialErrors {
                name: name.clone(),
                ae: errors,
                encode_ms,
                refine_ms: refined.map(|r| r.0),
                ae_refined: refined.map(|r| r.1),
                pca: image_errors(&pca.render(&truth), &pca.render(&rec)),
            });
        }
        Ok(AeEvalReport {
            split: request.split.as_str(),
            summary: summarise(&materials, request.refine > 0),
            materials,
            pca: PcaInfo {
                tables: request.pca_tables.as_str(),
                components: pca.components(),
                cells: pca.cells.len(),
                fit_seconds,
            },
            ae_eval_seconds,
            image: ImageInfo {
                size: SIZE,
                light_theta_deg: LIGHT_THETA_DEG,
            },
        })
    })?
}

/// Mean, deviation and median of MAE, RMSE and SSIM of each method.
fn summarise(
    materials: &[MaterialErrors],
    refined: bool,
) -> BTreeMap<&'static str, BTreeMap<&'static str, Summary>> {
    type Pick = fn(&MaterialErrors) -> Option<ImageErrors>;
    type Metric = (&'static str, fn(&ImageErrors) -> f64);
    let mut methods: Vec<(&'static str, Pick)> =
        vec![("ae", |m| Some(m.ae)), ("pca", |m| Some(m.pca))];
    if refined {
        methods.push(("ae_refined", |m| m.ae_refined));
    }
    let metrics: [Metric; 3] = [
        ("mae", |e| e.mae),
        ("rmse", |e| e.rmse),
        ("ssim", |e| e.ssim),
    ];
    methods
        .into_iter()
        .map(|(method, pick)| {
            let per_metric = metrics
                .iter()
                .map(|&(metric, value)| {
                    (
                        metric,
                        Summary::of(materials.iter().filter_map(pick).map(|e| value(&e))),
                    )
                })
                .collect();
            (method, per_metric)
        })
        .collect()
}
