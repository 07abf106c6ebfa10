//! `nbrdf fit-phong`: the Blinn-Phong sampling lobe of a table or a network.

use super::with_threads;
use crate::error::{NbrdfError, Result};
use crate::lobe_fit::{LobeAnalysis, LobeChoice, LobeFitConfig};
use crate::merl::PhiFold;
use crate::metrics::Material;
use crate::network::{SamplingParams, SAMPLING_MODEL_BLINN_PHONG};
use crate::phong_fit::FitConfig;
use crate::target::material_target;
use serde::Serialize;
use std::fmt;
use std::path::PathBuf;

/// The settings of a fit.
#[derive(Clone, Debug, PartialEq)]
pub struct FitPhongRequest {
    /// A MERL-format table, or a network (`.json`), which gets the chosen lobe.
    pub input: PathBuf,
    /// For a network: where to write it (default: in place). An error for a table.
    pub output: Option<PathBuf>,
    pub lobe: LobeChoice,
    pub phi_fold: PhiFold,
    /// Samples and seed of the model fit.
    pub fit: FitConfig,
    pub threads: Option<usize>,
}

/// Mean relative variance `R - 1` of BSDF sampling with each candidate lobe.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct RelativeVariances {
    pub variance_lobe: f64,
    pub model_lobe: f64,
    pub cosine: f64,
}

/// What `fit-phong` found (and wrote).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct FitPhongReport {
    /// The stored sampling: model, exponent, specular weight and source.
    pub model: String,
    pub exponent: f32,
    pub specular_weight: f32,
    pub source: String,
    /// [`LobeChoice::as_str`] of the stored lobe.
    pub lobe: &'static str,
    pub kd: [f64; 3],
    pub ks: [f64; 3],
    pub model_exponent: f64,
    pub model_specular_weight: f64,
    /// Log loss of the model fit.
    pub loss: f64,
    pub relative_variance: RelativeVariances,
    /// The network file written, if the input was a network.
    pub written: Option<String>,
    #[serde(skip)]
    pub choice: LobeChoice,
}

impl fmt::Display for FitPhongReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let v = &self.relative_variance;
        write!(
            f,
            "sampling lobe ({}): exponent {:.4}, specular weight {:.4}\n\
             model fit: exponent {:.4}, specular weight {:.4}, log loss {:.4e}\n  kd {:.4e} {:.4e} {:.4e}\n  ks {:.4e} {:.4e} {:.4e}\n\
             relative variance of BSDF sampling: variance lobe {:.4e}, model lobe {:.4e}, cosine {:.4e}\n",
            match self.choice {
                LobeChoice::LowestVariance => "lowest variance",
                LobeChoice::Model => "model fit",
            },
            self.exponent, self.specular_weight, self.model_exponent, self.model_specular_weight,
            self.loss, self.kd[0], self.kd[1], self.kd[2], self.ks[0], self.ks[1], self.ks[2],
            v.variance_lobe, v.model_lobe, v.cosine,
        )?;
        if let Some(out) = &self.written {
            writeln!(f, "updated the sampling of {out}")?;
        }
        Ok(())
    }
}

/// Fits the model and searches the lowest-variance lobe of the input; a network gets the lobe
/// of `request.lobe` as its "fit" sampling.
pub fn fit_phong(request: &FitPhongRequest) -> Result<FitPhongReport> {
    let material = Material::read_folded(&request.input, request.phi_fold)?;
    if request.output.is_some() && matches!(material, Material::Table(_)) {
        return Err(NbrdfError::InvalidArgument(
            "-o/--output applies to networks; for a table the fit is printed".into(),
        ));
    }
    let lobe_config = LobeFitConfig::default();
    let analysis = with_threads(request.threads, || {
        LobeAnalysis::new(&*material_target(&material), &request.fit, &lobe_config)
    })??;
    let (exponent, specular_weight) = analysis.lobe(request.lobe);
    let sampling = SamplingParams {
        model: SAMPLING_MODEL_BLINN_PHONG.to_string(),
        exponent: exponent as f32,
        specular_weight: specular_weight as f32,
        source: "fit".to_string(),
    };
    let mut written = None;
    if let Material::Network(mut net) = material {
        net.sampling = Some(sampling.clone());
        net.validate()?;
        let out = request.output.as_ref().unwrap_or(&request.input);
        net.save(out)?;
        written = Some(out.display().to_string());
    }
    let p = &analysis.model.params;
    Ok(FitPhongReport {
        model: sampling.model,
        exponent: sampling.exponent,
        specular_weight: sampling.specular_weight,
        source: sampling.source,
        lobe: request.lobe.as_str(),
        kd: p.kd,
        ks: p.ks,
        model_exponent: p.exponent,
        model_specular_weight: p.specular_weight(),
        loss: analysis.model.loss,
        relative_variance: RelativeVariances {
            variance_lobe: analysis.lowest_variance.relative_variance,
            model_lobe: analysis.model_relative_variance,
            cosine: analysis.lowest_variance.cosine_relative_variance,
        },
        written,
        choice: request.lobe,
    })
}
