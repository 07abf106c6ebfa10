//! Which one-lobe candidate a material is sampled with: the lowest-variance search's or the
//! model fit's ([`LobeChoice`]), and both measured on one quadrature ([`LobeAnalysis`]).

use super::{fit_lobe, LobeFit, LobeFitConfig, LobeQuadrature, TwoLobeFit};
use crate::error::Result;
use crate::fit::phong::{self, FitConfig, PhongFit, PhongParams};
use crate::train::dataset::TargetFn;

/// Which Blinn-Phong lobe `(n, w)` a material is sampled with.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum LobeChoice {
    /// The candidate of lowest variance of BSDF sampling ([`LobeQuadrature::fit`]): what
    /// `nbrdf fit-phong` stores by default.
    #[default]
    LowestVariance,
    /// `n` and `w = mean(ks) / (mean(kd) + mean(ks))` of the 7-parameter model fit
    /// ([`crate::fit::phong`], docs/design.md section 6): the shape of the BRDF in log space,
    /// which can be a poor sampler for weak sharp spikes but needs no quadrature.
    Model,
}

impl LobeChoice {
    /// The name `nbrdf fit-phong --lobe` takes and its JSON reports.
    pub fn as_str(self) -> &'static str {
        match self {
            LobeChoice::LowestVariance => "variance",
            LobeChoice::Model => "model",
        }
    }
}

/// The lobe `(n, w)` of the model fit: its exponent and `mean(ks) / (mean(kd) + mean(ks))`.
pub fn model_lobe(params: &PhongParams) -> (f64, f64) {
    (params.exponent, params.specular_weight())
}

/// Both candidate lobes of a material, and how well each samples it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LobeAnalysis {
    /// The 7-parameter model fit.
    pub model: PhongFit,
    /// The lowest-variance search.
    pub lowest_variance: LobeFit,
    /// Mean `R - 1` of sampling with the model fit's lobe.
    pub model_relative_variance: f64,
}

impl LobeAnalysis {
    /// Fits the model and searches the lowest-variance lobe of `target`.
    pub fn new(
        target: &TargetFn<'_>,
        fit_config: &FitConfig,
        lobe_config: &LobeFitConfig,
    ) -> Result<Self> {
        let model = phong::fit(target, fit_config)?;
        let quadrature = LobeQuadrature::new(target, lobe_config)?;
        let lowest_variance = quadrature.fit(lobe_config)?;
        let model_relative_variance =
            quadrature.relative_variance(model.params.exponent, model.params.specular_weight());
        Ok(LobeAnalysis {
            model,
            lowest_variance,
            model_relative_variance,
        })
    }

    /// [`LobeAnalysis::new`] plus the two-lobe search ([`LobeQuadrature::fit_two_lobes`]) on
    /// the same quadrature, which is built once.
    pub fn with_two_lobes(
        target: &TargetFn<'_>,
        fit_config: &FitConfig,
        lobe_config: &LobeFitConfig,
    ) -> Result<(Self, TwoLobeFit)> {
        let model = phong::fit(target, fit_config)?;
        let quadrature = LobeQuadrature::new(target, lobe_config)?;
        let two_lobes = quadrature.fit_two_lobes(lobe_config)?;
        let model_relative_variance =
            quadrature.relative_variance(model.params.exponent, model.params.specular_weight());
        let analysis = LobeAnalysis {
            model,
            lowest_variance: two_lobes.one_lobe,
            model_relative_variance,
        };
        Ok((analysis, two_lobes))
    }

    /// The lobe `(n, w)` of `choice` (as [`choose_lobe`] would compute it).
    pub fn lobe(&self, choice: LobeChoice) -> (f64, f64) {
        match choice {
            LobeChoice::LowestVariance => self.lowest_variance.lobe(),
            LobeChoice::Model => model_lobe(&self.model.params),
        }
    }
}

/// The lobe `(n, w)` of `choice` for `target`, computing only that candidate: the
/// lowest-variance search with `lobe_config`, or the model fit with `fit_config`.
pub fn choose_lobe(
    target: &TargetFn<'_>,
    choice: LobeChoice,
    fit_config: &FitConfig,
    lobe_config: &LobeFitConfig,
) -> Result<(f64, f64)> {
    match choice {
        LobeChoice::LowestVariance => Ok(fit_lobe(target, lobe_config)?.lobe()),
        LobeChoice::Model => Ok(model_lobe(&phong::fit(target, fit_config)?.params)),
    }
}
