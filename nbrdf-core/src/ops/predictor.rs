//! `nbrdf predictor train|eval` and `nbrdf predict-phong`: sampling lobes predicted from
//! autoencoder codes.

use super::autoencoder::Encoding;
use super::{read_nbrdf_dir, with_threads};
use crate::error::{NbrdfError, Result};
use crate::fit::lobes::{LobeFitConfig, LobeQuadrature};
use crate::fit::target::network_target;
use crate::latent::autoencoder::{permute_outputs, AutoEncoder, PERMUTATIONS};
use crate::latent::predictor::{
    highlight_profile, lobe_label, Example, PhongPredictor, PredictorConfig, VarianceGrid,
};
use crate::network::{Nbrdf, SamplingParams, SAMPLING_MODEL_BLINN_PHONG};
use rayon::prelude::*;
use serde::Serialize;
use std::fmt;
use std::path::{Path, PathBuf};
use std::time::Instant;

fn invalid(message: String) -> NbrdfError {
    NbrdfError::InvalidArgument(message)
}

/// The predictor's training loss.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum PredictorLoss {
    /// The relative variance of sampling with the predicted lobe over that of the label, with
    /// a small pull towards the label.
    #[default]
    Variance,
    /// Squared error of `(ln n, w)` against the labels.
    Labels,
}

/// What `predictor train` trains.
#[derive(Clone, Debug, PartialEq)]
pub struct PredictorTrainRequest {
    pub nbrdfs: PathBuf,
    /// More labelled networks; those of non-training materials are ignored.
    pub extra_nbrdfs: Option<PathBuf>,
    pub output: PathBuf,
    pub config: PredictorConfig,
    pub loss: PredictorLoss,
    /// Refit the labels even of networks with "fit" sampling ([`lobe_label`]).
    pub refit: bool,
    /// K-fold cross-validation over the training split first (0: off; 1 is an error).
    pub cross_validate: usize,
    /// Predict from the code alone, without the highlight profile.
    pub code_only: bool,
    /// Predict from codes refined by this many iterations.
    pub refine: usize,
    pub threads: Option<usize>,
}

/// The sampling RMSE ratio of one material's predicted lobe, held out.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct MaterialRatio {
    pub name: String,
    pub rmse_ratio: f64,
    pub exponent: f32,
    pub specular_weight: f32,
}

/// K-fold cross-validation over the training split.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct CrossValidation {
    pub folds: usize,
    pub geometric_mean: f64,
    pub median: f64,
    pub mean: f64,
    pub max: f64,
    /// Name and ratio of the worst material.
    pub worst: String,
    pub within_1_25: usize,
    pub materials: usize,
    pub materials_ratio: Vec<MaterialRatio>,
}

impl fmt::Display for CrossValidation {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "{}-fold cross-validation over the training split: sampling RMSE ratio predicted/fitted (lobe-search quadrature) geometric mean {:.3}, median {:.3}, mean {:.3}, max {:.3} ({}), within 1.25x for {} of {} materials",
            self.folds,
            self.geometric_mean,
            self.median,
            self.mean,
            self.max,
            self.worst,
            self.within_1_25,
            self.materials,
        )
    }
}

/// What `predictor train` wrote.
#[derive(Clone, Debug, PartialEq)]
pub struct PredictorTrainReport {
    pub output: PathBuf,
    pub cross_validation: Option<CrossValidation>,
    pub materials: usize,
    pub examples: usize,
    pub label_seconds: f64,
    pub train_seconds: f64,
}

impl fmt::Display for PredictorTrainReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if let Some(cv) = &self.cross_validation {
            write!(f, "{cv}")?;
        }
        writeln!(
            f,
            "labels for {} materials in {:.1} s; trained the predictor on {} codes in {:.2} s\nwrote {}",
            self.materials,
            self.label_seconds,
            self.examples,
            self.train_seconds,
            self.output.display()
        )
    }
}

/// A label as recorded in the predictor's provenance.
#[derive(Serialize)]
struct Label<'a> {
    name: &'a str,
    exponent: f64,
    specular_weight: f64,
}

/// The lobe-search quadrature of a network (it evaluates the network once).
fn network_quadrature(net: &Nbrdf) -> Result<LobeQuadrature> {
    LobeQuadrature::new(&network_target(net), &LobeFitConfig::default())
}

/// Sampling RMSE of a lobe over the fitted lobe's, from their relative variances `R - 1`: the
/// RMSE of an estimator scales with the square root of its variance.
fn rmse_ratio(relative_variance: f64, fitted_relative_variance: f64) -> f64 {
    (relative_variance.max(1e-12) / fitted_relative_variance.max(1e-12)).sqrt()
}

/// Trains the predictor on the codes of the training split's networks (every RGB
/// permutation), labelled by [`lobe_label`], and writes it.
pub fn train_predictor(
    ae: &AutoEncoder,
    request: &PredictorTrainRequest,
) -> Result<PredictorTrainReport> {
    use super::limits::{check_range, MAX_ITERATIONS};
    check_range("--refine", request.refine, 0, MAX_ITERATIONS)?;
    check_range("--cross-validate", request.cross_validate, 0, 1000)?;
    if request.cross_validate == 1 {
        return Err(invalid(
            "--cross-validate needs at least 2 folds (0 turns it off)".into(),
        ));
    }
    let mut nets = read_nbrdf_dir(&request.nbrdfs)?;
    if let Some(dir) = &request.extra_nbrdfs {
        // Only training materials: `train` below keeps those.
        nets.extend(read_nbrdf_dir(dir)?);
    }
    with_threads(request.threads, || train_on_split(request, ae, &nets))?
}

/// The labels of the training materials and, where the loss or cross-validation needs them,
/// their lobe-search quadratures and variance grids.
struct SplitLabels {
    labels: Vec<(f64, f64)>,
    quadratures: Vec<LobeQuadrature>,
    grids: Vec<VarianceGrid>,
}

fn split_labels(
    request: &PredictorTrainRequest,
    train: &[&(String, Nbrdf)],
) -> Result<SplitLabels> {
    let labels: Vec<(f64, f64)> = train
        .par_iter()
        .map(|(_, net)| lobe_label(net, request.refit))
        .collect::<Result<_>>()?;
    let variance_loss = request.loss == PredictorLoss::Variance;
    let quadratures: Vec<LobeQuadrature> = if variance_loss || request.cross_validate > 1 {
        train
            .iter()
            .map(|(_, net)| network_quadrature(net))
            .collect::<Result<_>>()?
    } else {
        Vec::new()
    };
    let grids: Vec<VarianceGrid> = if variance_loss {
        quadratures
            .iter()
            .map(|q| VarianceGrid::new(|n, w| q.relative_variance(n, w)))
            .collect()
    } else {
        Vec::new()
    };
    Ok(SplitLabels {
        labels,
        quadratures,
        grids,
    })
}

/// The training examples, each RGB permutation of each material: its (refined) code with the
/// material's highlight profile, and its label; with the index of their material and, for the
/// variance loss, its grid.
fn training_examples<'g>(
    request: &PredictorTrainRequest,
    ae: &AutoEncoder,
    train: &[&(String, Nbrdf)],
    split: &'g SplitLabels,
) -> (Vec<Example>, Vec<usize>, Vec<&'g VarianceGrid>) {
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
        .map(|(_, flat)| ae.refine_code(flat, &ae.encode_flat(flat), request.refine))
        .collect();
    // The profile is a mean over RGB: one per material serves its 6 permutations.
    let profiles: Vec<Vec<f32>> = train
        .iter()
        .map(|(_, net)| {
            if !request.code_only {
                highlight_profile(net)
            } else {
                Vec::new()
            }
        })
        .collect();
    let mut examples = Vec::new();
    let mut example_grids = Vec::new();
    for ((m, _), mut code) in inputs.iter().zip(codes) {
        let (n, w) = split.labels[*m];
        code.extend_from_slice(&profiles[*m]);
        examples.push((code, n, w));
        example_grids.extend(split.grids.get(*m));
    }
    let example_material = inputs.iter().map(|(m, _)| *m).collect();
    (examples, example_material, example_grids)
}

fn train_on_split(
    request: &PredictorTrainRequest,
    ae: &AutoEncoder,
    nets: &[(String, Nbrdf)],
) -> Result<PredictorTrainReport> {
    let t0 = Instant::now();
    let train: Vec<&(String, Nbrdf)> = nets
        .iter()
        .filter(|(n, _)| ae.split.train.contains(n))
        .collect();
    let split = split_labels(request, &train)?;
    let label_seconds = t0.elapsed().as_secs_f64();
    let t1 = Instant::now();
    let (examples, example_material, example_grids) =
        training_examples(request, ae, &train, &split);
    let grids_arg = (!example_grids.is_empty()).then_some(example_grids.as_slice());
    let config = &request.config;
    let cross_validation = if request.cross_validate > 1 {
        let names: Vec<&str> = train.iter().map(|(n, _)| n.as_str()).collect();
        Some(cross_validate(
            &CrossValidationData {
                names: &names,
                labels: &split.labels,
                quadratures: &split.quadratures,
                examples: &examples,
                example_material: &example_material,
                grids: grids_arg,
            },
            config,
            request.cross_validate,
        )?)
    } else {
        None
    };
    let mut pred = PhongPredictor::train_ensemble(&examples, grids_arg, config)?;
    pred.refine_steps = request.refine;
    pred.highlight_profile = !request.code_only;
    let train_seconds = t1.elapsed().as_secs_f64();
    if let Some(o) = pred.provenance.as_object_mut() {
        let recorded: Vec<Label<'_>> = train
            .iter()
            .zip(&split.labels)
            .map(|((name, _), &(exponent, specular_weight))| Label {
                name,
                exponent,
                specular_weight,
            })
            .collect();
        o.insert(
            "labels".into(),
            serde_json::to_value(&recorded).unwrap_or_default(),
        );
        o.insert("label_seconds".into(), label_seconds.into());
        o.insert("train_seconds".into(), train_seconds.into());
        o.insert("highlight_profile".into(), (!request.code_only).into());
        if let Some(cv) = &cross_validation {
            o.insert(
                "cross_validation".into(),
                serde_json::to_value(cv).unwrap_or_default(),
            );
        }
    }
    pred.save(&request.output)?;
    Ok(PredictorTrainReport {
        output: request.output.clone(),
        cross_validation,
        materials: train.len(),
        examples: examples.len(),
        label_seconds,
        train_seconds,
    })
}

/// What [`cross_validate`] needs of the training split: per material (`names`, `labels`,
/// `quadratures`), and the examples with the index of their material.
struct CrossValidationData<'a> {
    names: &'a [&'a str],
    labels: &'a [(f64, f64)],
    quadratures: &'a [LobeQuadrature],
    examples: &'a [Example],
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
) -> Result<CrossValidation> {
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
            rows.push(MaterialRatio {
                name: data.names[m].to_string(),
                rmse_ratio: ratio,
                exponent: n,
                specular_weight: w,
            });
        }
    }
    let mut ratios: Vec<f64> = rows.iter().map(|r| r.rmse_ratio).collect();
    ratios.sort_by(f64::total_cmp);
    let worst = rows
        .iter()
        .max_by(|a, b| a.rmse_ratio.total_cmp(&b.rmse_ratio))
        .map(|r| format!("{} {:.2}", r.name, r.rmse_ratio))
        .unwrap_or_default();
    let count = ratios.len().max(1) as f64;
    Ok(CrossValidation {
        folds,
        geometric_mean: (ratios.iter().map(|r| r.ln()).sum::<f64>() / count).exp(),
        median: ratios.get(ratios.len() / 2).copied().unwrap_or(f64::NAN),
        mean: ratios.iter().sum::<f64>() / count,
        max: ratios.last().copied().unwrap_or(f64::NAN),
        worst,
        within_1_25: ratios.iter().filter(|&&r| r <= 1.25).count(),
        materials: ratios.len(),
        materials_ratio: rows,
    })
}

/// A lobe and its relative variance of BSDF sampling.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct ScoredLobe<T> {
    pub exponent: T,
    pub specular_weight: T,
    pub relative_variance: f64,
}

/// The fitted and the predicted lobe of a test material.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct PredictionScore {
    pub name: String,
    pub fitted: ScoredLobe<f64>,
    pub predicted: ScoredLobe<f32>,
    pub cosine_relative_variance: f64,
    pub rmse_ratio: f64,
}

/// Summary of the RMSE ratios.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct RatioSummary {
    pub median: f64,
    pub max: f64,
    pub within_1_25: usize,
    pub materials: usize,
}

/// What `predictor eval` prints.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct PredictorEvalReport {
    pub test: Vec<PredictionScore>,
    pub rmse_ratio: RatioSummary,
}

/// Fitted vs predicted lobes of the autoencoder's test split, scored by the relative variance
/// of BSDF sampling.
pub fn evaluate_predictor(
    ae: &AutoEncoder,
    pred: &PhongPredictor,
    nbrdfs: &Path,
    threads: Option<usize>,
) -> Result<PredictorEvalReport> {
    let nets = read_nbrdf_dir(nbrdfs)?;
    with_threads(threads, || -> Result<PredictorEvalReport> {
        let mut test = Vec::new();
        for name in &ae.split.test {
            let Some((_, net)) = nets.iter().find(|(n, _)| n == name) else {
                return Err(invalid(format!("no network for '{name}'")));
            };
            let (n_fit, w_fit) = lobe_label(net, false)?;
            let code = ae.encode_refined(net, pred.refine_steps)?;
            let (n_pred, w_pred) = pred.predict(&pred.inputs(&code, net));
            let q = network_quadrature(net)?;
            let (v_fit, v_pred, v_cos) = (
                q.relative_variance(n_fit, w_fit),
                q.relative_variance(n_pred as f64, w_pred as f64),
                q.relative_variance(0.0, 0.0),
            );
            test.push(PredictionScore {
                name: name.clone(),
                fitted: ScoredLobe {
                    exponent: n_fit,
                    specular_weight: w_fit,
                    relative_variance: v_fit,
                },
                predicted: ScoredLobe {
                    exponent: n_pred,
                    specular_weight: w_pred,
                    relative_variance: v_pred,
                },
                cosine_relative_variance: v_cos,
                rmse_ratio: rmse_ratio(v_pred, v_fit),
            });
        }
        let mut sorted: Vec<f64> = test.iter().map(|t| t.rmse_ratio).collect();
        sorted.sort_by(f64::total_cmp);
        Ok(PredictorEvalReport {
            rmse_ratio: RatioSummary {
                median: sorted.get(sorted.len() / 2).copied().unwrap_or(f64::NAN),
                max: sorted.last().copied().unwrap_or(f64::NAN),
                within_1_25: sorted.iter().filter(|&&r| r <= 1.25).count(),
                materials: sorted.len(),
            },
            test,
        })
    })?
}

/// What `predict-phong` wrote.
#[derive(Clone, Debug, PartialEq)]
pub struct PredictReport {
    pub exponent: f32,
    pub specular_weight: f32,
    pub output: PathBuf,
    /// Encoding and prediction time (a re-learn before it not included).
    pub milliseconds: f64,
}

impl fmt::Display for PredictReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "predicted blinn-phong: exponent {:.4}, specular weight {:.4}\nwrote {}",
            self.exponent,
            self.specular_weight,
            self.output.display()
        )
    }
}

/// Predicts the network's lobe from its code and writes it as "predicted" sampling to
/// `output` (default: in place). A network foreign to the autoencoder's family is re-learnt
/// first ([`Encoding`]) and the lobe predicted from that version; the file written is the
/// network read, with the lobe.
pub fn predict_phong(
    ae: &AutoEncoder,
    pred: &PhongPredictor,
    input: &Path,
    output: Option<&Path>,
    encoding: &mut Encoding<'_>,
) -> Result<PredictReport> {
    let mut net = Nbrdf::load(input)?;
    let encodable = encoding.prepare(ae, &net)?;
    let t0 = Instant::now();
    let code = ae.encode_refined(&encodable, pred.refine_steps)?;
    let (n, w) = pred.predict(&pred.inputs(&code, &encodable));
    let milliseconds = t0.elapsed().as_secs_f64() * 1e3;
    net.sampling = Some(SamplingParams {
        model: SAMPLING_MODEL_BLINN_PHONG.to_string(),
        exponent: n,
        specular_weight: w,
        source: "predicted".to_string(),
        second_lobe: None,
        exponent_v: None,
        relative_variance: None,
        default: None,
        table_cosine_weight: None,
    });
    net.validate()?;
    let out = output.unwrap_or(input);
    net.save(out)?;
    Ok(PredictReport {
        exponent: n,
        specular_weight: w,
        output: out.to_path_buf(),
        milliseconds,
    })
}
