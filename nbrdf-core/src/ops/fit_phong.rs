//! `nbrdf fit-phong`: the Blinn-Phong sampling lobe of a table or a network. The fits and
//! searches are [`crate::fit`]'s; this is the command: which of them to run, which lobes and
//! default strategy to store, the file written and the report.

use super::with_threads;
use crate::error::{NbrdfError, Result};
use crate::fit::anisotropic::{fit_anisotropic_lobe, AnisotropicLobeFit, AnisotropicLobeFitConfig};
use crate::fit::lobes::{LobeAnalysis, LobeChoice, LobeFitConfig, LobeQuadrature, TwoLobeFit};
use crate::fit::phong::FitConfig;
use crate::fit::target::material_target;
use crate::merl::PhiFold;
use crate::metrics::Material;
use crate::network::{SamplingParams, SamplingVariances, SecondLobe, SAMPLING_MODEL_BLINN_PHONG};
use crate::sampling::tabulated::{TableConfig, TabulatedSampler, COSINE_WEIGHT_CANDIDATES};
use crate::sampling::{SamplingKind, SamplingStrategy};
use crate::train::dataset::TargetFn;
use glam::DVec3;
use serde::Serialize;
use std::fmt;
use std::path::PathBuf;
use std::sync::Arc;

/// The settings of a fit.
#[derive(Clone, Debug, PartialEq)]
pub struct FitPhongRequest {
    /// A MERL-format table, or a network (`.json`), which gets the chosen lobe.
    pub input: PathBuf,
    /// For a network: where to write it (default: in place). An error for a table.
    pub output: Option<PathBuf>,
    pub lobe: LobeChoice,
    /// One lobe, two lobes, or whichever samples with the lower variance.
    pub lobes: LobeCount,
    pub phi_fold: PhiFold,
    /// Samples and seed of the model fit.
    pub fit: FitConfig,
    pub threads: Option<usize>,
}

/// How many Blinn-Phong lobes the stored sampling mixture has.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum LobeCount {
    /// Two lobes where they sample with a relative variance lower by more than
    /// [`TWO_LOBE_MIN_GAIN`] than one lobe (the simpler strategy otherwise).
    #[default]
    Auto,
    One,
    Two,
}

/// `Auto` stores two lobes only when their relative variance is below this fraction of the
/// one-lobe's: a marginal gain is not worth the file's second lobe.
pub const TWO_LOBE_MIN_GAIN: f64 = 0.98;

/// The two-lobe mixture the search found (stored or not).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct TwoLobeReport {
    /// `[n1, n2]`, sharp lobe first.
    pub exponents: [f64; 2],
    pub weights: [f64; 2],
}

/// Mean relative variance `R - 1` of BSDF sampling with each candidate lobe.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct RelativeVariances {
    pub variance_lobe: f64,
    pub model_lobe: f64,
    pub cosine: f64,
    /// The two-lobe mixture's, when it was searched (`--lobes auto|2` with `--lobe variance`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub two_lobe: Option<f64>,
    /// The anisotropic lobe's, for anisotropic networks (with `--lobe variance`, not
    /// `--lobes 2`); `variance_lobe` and `cosine` are then on its quadrature over all view
    /// azimuths.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub anisotropic: Option<f64>,
    /// The tabulated sampler's (built from the material as the plugin builds it at load time),
    /// with the lowest-variance cosine weight of [`COSINE_WEIGHT_CANDIDATES`].
    pub tabulated: f64,
}

/// The tabulated sampler of a material given by Rusinkiewicz angles: its `f_r` (mean over
/// RGB, negative channels as 0) by direction, as [`TabulatedSampler::from_brdf`] tabulates a
/// renderer's.
fn table_from_target(target: &TargetFn<'_>, config: &TableConfig) -> Result<TabulatedSampler> {
    let f = |v: DVec3, l: DVec3| {
        let a = crate::coords::to_rusinkiewicz(v, l);
        target(&a).map_or(0.0, |rgb| rgb.iter().map(|c| c.max(0.0)).sum::<f64>() / 3.0)
    };
    TabulatedSampler::build(&f, config)
}

/// The tabulated sampler's variance with the cosine weight that gives the lowest.
#[derive(Clone, Copy, Debug, PartialEq)]
struct TableChoice {
    cosine_weight: f64,
    relative_variance: f64,
}

/// Scores `table` mixed with each of [`COSINE_WEIGHT_CANDIDATES`] on the lobe search's
/// quadrature; the first of equal variances wins.
fn lowest_variance_cosine_weight(
    quadrature: &LobeQuadrature,
    table: &TabulatedSampler,
) -> Result<TableChoice> {
    let mut scored = Vec::with_capacity(COSINE_WEIGHT_CANDIDATES.len());
    for cosine_weight in COSINE_WEIGHT_CANDIDATES {
        let strategy =
            SamplingStrategy::Tabulated(Arc::new(table.with_cosine_weight(cosine_weight)?));
        scored.push(TableChoice {
            cosine_weight,
            relative_variance: quadrature.strategy_relative_variance(&strategy),
        });
    }
    let best = scored
        .into_iter()
        .filter(|c| c.relative_variance.is_finite())
        .min_by(|a, b| a.relative_variance.total_cmp(&b.relative_variance));
    Ok(best.unwrap_or(TableChoice {
        cosine_weight: COSINE_WEIGHT_CANDIDATES[0],
        relative_variance: f64::INFINITY,
    }))
}

/// What `fit-phong` found (and wrote).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct FitPhongReport {
    /// The stored sampling: model, exponent, specular weight and source.
    pub model: String,
    pub exponent: f32,
    pub specular_weight: f32,
    /// `n_v` of the stored anisotropic lobe (then `exponent` is `n_u`).
    pub exponent_v: Option<f32>,
    /// The stored second lobe, if two lobes were stored.
    pub second_lobe: Option<SecondLobe>,
    pub source: String,
    /// The two-lobe search's result, if it ran.
    pub two_lobe: Option<TwoLobeReport>,
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
    /// The strategy with the lowest relative variance (the plugin's `sampling` name), stored
    /// as the file's `sampling.default`.
    pub default_sampling: SamplingKind,
    /// The tabulated sampler's cosine weight of lowest variance, stored as the file's
    /// `sampling.table_cosine_weight` (isotropic networks).
    pub table_cosine_weight: f64,
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
        if let (Some(nv), Some(variance)) = (self.exponent_v, v.anisotropic) {
            writeln!(
                f,
                "anisotropic lobe (stored): exponents {:.4} along the tangent, {nv:.4} across, \
                 weight {:.4}, relative variance {variance:.4e}",
                self.exponent, self.specular_weight,
            )?;
        }
        if let (Some(two), Some(variance)) = (&self.two_lobe, v.two_lobe) {
            writeln!(
                f,
                "two lobes: exponents {:.4} {:.4}, weights {:.4} {:.4}, relative variance {:.4e} ({})",
                two.exponents[0],
                two.exponents[1],
                two.weights[0],
                two.weights[1],
                variance,
                if self.second_lobe.is_some() { "stored" } else { "not stored: one lobe does as well" },
            )?;
        }
        writeln!(
            f,
            "tabulated sampler: relative variance {:.4e} (cosine weight {})\ndefault sampling (lowest variance): {}",
            v.tabulated, self.table_cosine_weight, self.default_sampling
        )?;
        if let Some(out) = &self.written {
            writeln!(f, "updated the sampling of {out}")?;
        }
        Ok(())
    }
}

/// What the searches of one `fit-phong` run measured.
struct Measured {
    analysis: LobeAnalysis,
    two_lobes: Option<TwoLobeFit>,
    anisotropic: Option<AnisotropicLobeFit>,
    tabulated: TableChoice,
}

/// The lobes to store: the one-lobe choice, or the first of two with the second beside it.
struct StoredLobes {
    exponent: f64,
    specular_weight: f64,
    second_lobe: Option<SecondLobe>,
    /// The one-lobe choice's relative variance (of `request.lobe`).
    one_lobe_variance: f64,
    /// The stored strategy and its relative variance.
    variance: (SamplingKind, f64),
}

/// Fits the model and searches the lowest-variance lobe of the input; a network gets the lobe
/// of `request.lobe` as its "fit" sampling.
pub fn fit_phong(request: &FitPhongRequest) -> Result<FitPhongReport> {
    super::limits::check_fit_samples(request.fit.samples)?;
    let material = Material::read_folded(&request.input, request.phi_fold)?;
    check_request(request, &material)?;
    let measured = measure(request, &material)?;
    let lobes = stored_lobes(request, &measured);
    let default_sampling = default_sampling(&measured, &lobes);
    let sampling = sampling_params(&measured, &lobes, default_sampling);
    let mut written = None;
    if let Material::Network(mut net) = material {
        net.sampling = Some(sampling.clone());
        net.validate()?;
        let out = request.output.as_ref().unwrap_or(&request.input);
        net.save(out)?;
        written = Some(out.display().to_string());
    }
    Ok(report(
        request,
        &measured,
        sampling,
        default_sampling,
        written,
    ))
}

/// The option combinations `fit-phong` refuses.
fn check_request(request: &FitPhongRequest, material: &Material) -> Result<()> {
    if request.output.is_some() && matches!(material, Material::Table(_)) {
        return Err(NbrdfError::Usage(
            "-o/--output applies to networks; for a table the fit is printed".into(),
        ));
    }
    if request.lobes == LobeCount::Two && request.lobe == LobeChoice::Model {
        return Err(NbrdfError::InvalidArgument(
            "--lobes 2 searches the lowest-variance lobes; it does not combine with --lobe model"
                .into(),
        ));
    }
    Ok(())
}

/// Runs the model fit and the lobe searches the request asks for, and scores the tabulated
/// sampler.
fn measure(request: &FitPhongRequest, material: &Material) -> Result<Measured> {
    // Anisotropic networks get the anisotropic lobe unless two (isotropic) lobes are asked for.
    let search_anisotropic = matches!(material, Material::Network(net) if net.anisotropic)
        && request.lobe == LobeChoice::LowestVariance
        && request.lobes != LobeCount::Two;
    let search_two = request.lobes != LobeCount::One
        && request.lobe == LobeChoice::LowestVariance
        && !search_anisotropic;
    let lobe_config = LobeFitConfig::default();
    with_threads(request.threads, || -> Result<_> {
        let target = material_target(material);
        let anisotropic: Option<AnisotropicLobeFit> = if search_anisotropic {
            Some(fit_anisotropic_lobe(
                &*target,
                &AnisotropicLobeFitConfig::default(),
            )?)
        } else {
            None
        };
        let table = table_from_target(&*target, &TableConfig::default())?;
        let tabulated =
            lowest_variance_cosine_weight(&LobeQuadrature::new(&*target, &lobe_config)?, &table)?;
        let (analysis, two_lobes) = if search_two {
            let (analysis, two) =
                LobeAnalysis::with_two_lobes(&*target, &request.fit, &lobe_config)?;
            (analysis, Some(two))
        } else {
            (
                LobeAnalysis::new(&*target, &request.fit, &lobe_config)?,
                None,
            )
        };
        Ok(Measured {
            analysis,
            two_lobes,
            anisotropic,
            tabulated,
        })
    })?
    .map_err(super::about_data(&request.input.display().to_string()))
}

/// The lobe of `request.lobe`, replaced by two lobes where `request.lobes` asks for them or
/// (`Auto`) they gain enough.
fn stored_lobes(request: &FitPhongRequest, measured: &Measured) -> StoredLobes {
    let analysis = &measured.analysis;
    let (exponent, specular_weight) = analysis.lobe(request.lobe);
    let one_lobe_variance = match request.lobe {
        LobeChoice::LowestVariance => analysis.lowest_variance.relative_variance,
        LobeChoice::Model => analysis.model_relative_variance,
    };
    let stored_two = measured.two_lobes.filter(|two| match request.lobes {
        LobeCount::Two => true,
        LobeCount::One => false,
        LobeCount::Auto => two.relative_variance < TWO_LOBE_MIN_GAIN * one_lobe_variance,
    });
    match stored_two {
        Some(TwoLobeFit {
            exponents,
            weights,
            relative_variance,
            ..
        }) => StoredLobes {
            exponent: exponents[0],
            specular_weight: weights[0],
            second_lobe: Some(SecondLobe {
                exponent: exponents[1] as f32,
                specular_weight: weights[1] as f32,
            }),
            one_lobe_variance,
            variance: (SamplingKind::TwoLobe, relative_variance),
        },
        None => StoredLobes {
            exponent,
            specular_weight,
            second_lobe: None,
            one_lobe_variance,
            variance: (SamplingKind::Phong, one_lobe_variance),
        },
    }
}

/// The strategy of lowest relative variance: cosine, the stored lobes or the table. The table
/// is built over the half vector's azimuth relative to the view's (an isotropic material's); an
/// anisotropic network samples with its anisotropic lobe, the stored lobe the plugin picks when
/// the file names no default.
fn default_sampling(measured: &Measured, lobes: &StoredLobes) -> SamplingKind {
    if measured.anisotropic.is_some() {
        return SamplingKind::AnisotropicPhong;
    }
    [
        (
            SamplingKind::Cosine,
            measured.analysis.lowest_variance.cosine_relative_variance,
        ),
        lobes.variance,
        (
            SamplingKind::Tabulated,
            measured.tabulated.relative_variance,
        ),
    ]
    .into_iter()
    .filter(|(_, v)| v.is_finite())
    .min_by(|a, b| a.1.total_cmp(&b.1))
    .map_or(SamplingKind::Cosine, |(kind, _)| kind)
}

/// The sampling a network file gets: the anisotropic lobe where it was searched (with no
/// stored default), else the stored lobes with the default and the table's cosine weight.
fn sampling_params(
    measured: &Measured,
    lobes: &StoredLobes,
    default_sampling: SamplingKind,
) -> SamplingParams {
    match measured.anisotropic {
        Some(a) => SamplingParams {
            model: SAMPLING_MODEL_BLINN_PHONG.to_string(),
            exponent: a.exponent_u as f32,
            specular_weight: a.specular_weight as f32,
            source: "fit".to_string(),
            second_lobe: None,
            exponent_v: Some(a.exponent_v as f32),
            relative_variance: Some(SamplingVariances {
                one_lobe: a.isotropic_relative_variance,
                two_lobe: None,
                anisotropic: Some(a.relative_variance),
                cosine: a.cosine_relative_variance,
                tabulated: None,
            }),
            default: None,
            table_cosine_weight: None,
        },
        None => SamplingParams {
            model: SAMPLING_MODEL_BLINN_PHONG.to_string(),
            exponent: lobes.exponent as f32,
            specular_weight: lobes.specular_weight as f32,
            source: "fit".to_string(),
            second_lobe: lobes.second_lobe,
            exponent_v: None,
            relative_variance: Some(SamplingVariances {
                one_lobe: lobes.one_lobe_variance,
                two_lobe: measured.two_lobes.map(|two| two.relative_variance),
                anisotropic: None,
                cosine: measured.analysis.lowest_variance.cosine_relative_variance,
                tabulated: Some(measured.tabulated.relative_variance),
            }),
            default: Some(default_sampling),
            table_cosine_weight: Some(measured.tabulated.cosine_weight as f32),
        },
    }
}

/// What `fit-phong` prints: the stored sampling, the model fit and every candidate's variance.
fn report(
    request: &FitPhongRequest,
    measured: &Measured,
    sampling: SamplingParams,
    default_sampling: SamplingKind,
    written: Option<String>,
) -> FitPhongReport {
    let Measured {
        analysis,
        two_lobes,
        anisotropic,
        tabulated,
    } = measured;
    let p = &analysis.model.params;
    FitPhongReport {
        model: sampling.model,
        exponent: sampling.exponent,
        specular_weight: sampling.specular_weight,
        exponent_v: sampling.exponent_v,
        second_lobe: sampling.second_lobe,
        source: sampling.source,
        two_lobe: two_lobes.map(|two| TwoLobeReport {
            exponents: two.exponents,
            weights: two.weights,
        }),
        lobe: request.lobe.as_str(),
        kd: p.kd,
        ks: p.ks,
        model_exponent: p.exponent,
        model_specular_weight: p.specular_weight(),
        loss: analysis.model.loss,
        relative_variance: RelativeVariances {
            variance_lobe: anisotropic.map_or(analysis.lowest_variance.relative_variance, |a| {
                a.isotropic_relative_variance
            }),
            model_lobe: analysis.model_relative_variance,
            cosine: anisotropic.map_or(analysis.lowest_variance.cosine_relative_variance, |a| {
                a.cosine_relative_variance
            }),
            two_lobe: two_lobes.map(|two| two.relative_variance),
            anisotropic: anisotropic.map(|a| a.relative_variance),
            tabulated: tabulated.relative_variance,
        },
        table_cosine_weight: tabulated.cosine_weight,
        written,
        default_sampling,
        choice: request.lobe,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::lobes::tests::blinn_phong;
    use crate::train::dataset::TargetFn;

    /// A sharp lobe wastes the cosine share (the smallest weight wins); for a Lambertian
    /// material cosine sampling is exact, so the largest weight wins; the choice's variance is
    /// its candidate's.
    #[test]
    fn the_table_keeps_the_cosine_weight_of_lowest_variance() {
        let config = LobeFitConfig::default();
        let glossy = blinn_phong(0.05, 0.9, 400.0);
        let lambertian = blinn_phong(0.8, 0.0, 1.0);
        let cases: [(&TargetFn<'_>, f64); 2] = [
            (&glossy, COSINE_WEIGHT_CANDIDATES[2]),
            (&lambertian, COSINE_WEIGHT_CANDIDATES[0]),
        ];
        for (target, want) in cases {
            let quadrature = LobeQuadrature::new(target, &config).unwrap();
            let table = table_from_target(target, &TableConfig::default()).unwrap();
            let choice = lowest_variance_cosine_weight(&quadrature, &table).unwrap();
            assert_eq!(choice.cosine_weight, want, "{choice:?}");
            let strategy =
                SamplingStrategy::Tabulated(Arc::new(table.with_cosine_weight(want).unwrap()));
            assert_eq!(
                choice.relative_variance,
                quadrature.strategy_relative_variance(&strategy)
            );
        }
    }
}
