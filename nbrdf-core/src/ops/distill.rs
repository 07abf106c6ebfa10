//! Distillation: a network learnt from reflectance that a caller sampled at the trainer's own
//! directions ([`crate::train::arrays`], or spectra at wavelengths of its choice:
//! [`crate::train::spectral`]); `python -m nbrdf_mitsuba.distill` evaluates a Mitsuba 3 BSDF
//! there and calls this through the C ABI of `nbrdf-ffi/train`.

use super::with_threads;
use crate::error::{NbrdfError, Result};
use crate::network::Nbrdf;
use crate::source::RglFold;
use crate::train::arrays::{self, SampledArrays};
use crate::train::spectral::{self, SampledSpectra};
use crate::train::{self, EpochStats, TrainConfig, TrainReport};
use glam::Vec3;

/// The trainer's `(view, light)` pairs for `config` (training, then validation) and how many are
/// for validation, after checking the settings' ranges. Pairs that `fold` leaves out are replaced
/// by the next candidates ([`arrays::sample_directions_for`]), so that a reciprocal-mean
/// distillation trains on `config.samples` pairs, as `nbrdf train --rgl-fold reciprocal-mean` does.
pub fn sample_directions(
    config: &TrainConfig,
    fold: RglFold,
) -> Result<(Vec<(Vec3, Vec3)>, usize)> {
    super::limits::check_train(config)?;
    arrays::sample_directions_for(config, fold)
}

/// The numbers of training and validation pairs of `config`, after checking its settings: those
/// of [`sample_directions`] with either fold, since left-out pairs are replaced.
pub fn sample_counts(config: &TrainConfig) -> Result<(usize, usize)> {
    super::limits::check_train(config)?;
    config.validate()?;
    Ok((config.samples, config.validation_samples()))
}

/// The values to distil: RGB (an RGB network) or spectra (a spectral network, format version 3).
#[derive(Clone, Copy, Debug)]
pub enum DistillArrays<'a> {
    Rgb(SampledArrays<'a>),
    Spectral(SampledSpectra<'a>),
}

impl DistillArrays<'_> {
    fn pairs_and_validation(&self) -> (usize, usize) {
        match self {
            DistillArrays::Rgb(a) => (a.view.len(), a.validation),
            DistillArrays::Spectral(a) => (a.view.len(), a.validation),
        }
    }
}

/// What to distil.
#[derive(Clone, Debug)]
pub struct DistillRequest<'a> {
    pub arrays: DistillArrays<'a>,
    pub fold: RglFold,
    /// Stored in the network.
    pub name: String,
    /// What the values came from, for the provenance (a file, a BSDF description).
    pub source: String,
    /// More provenance from the caller (the renderer, its version, the BSDF's parameters),
    /// stored under `"distilled_from"`.
    pub source_details: Option<serde_json::Value>,
    /// `samples` and `validation_fraction` are not read: the arrays are the samples.
    pub config: TrainConfig,
    pub threads: Option<usize>,
}

/// Trains the network of `request`, with the trainer's provenance plus `"source_kind":
/// "distilled"`, the fold and the caller's details.
pub fn distill(
    request: &DistillRequest<'_>,
    on_epoch: &mut (dyn FnMut(&EpochStats) + Send),
) -> Result<(Nbrdf, TrainReport)> {
    let (n, validation) = request.arrays.pairs_and_validation();
    let config = TrainConfig {
        samples: n.saturating_sub(validation).max(1),
        ..request.config.clone()
    };
    super::limits::check_train(&config)?;
    if request.name.is_empty() {
        return Err(NbrdfError::InvalidArgument(
            "the network name is empty".into(),
        ));
    }
    let (fold, name) = (request.fold, &request.name);
    let outcome = with_threads(request.threads, || match &request.arrays {
        DistillArrays::Rgb(a) => arrays::train_arrays(a, fold, &config, name, on_epoch),
        DistillArrays::Spectral(a) => {
            spectral::train_spectral_arrays(a, fold, &config, name, on_epoch)
        }
    })?
    .map_err(super::about_data(&request.source))?;
    let mut network = outcome.network;
    network.provenance = train::provenance(&config, &outcome.report, &request.source);
    if let Some(p) = network.provenance.as_object_mut() {
        p.insert("source_kind".into(), "distilled".into());
        p.insert("reciprocity".into(), request.fold.as_str().into());
        if let DistillArrays::Spectral(a) = &request.arrays {
            p.insert(
                "spectral_target".into(),
                spectral::provenance_entry(a.wavelengths),
            );
        }
        if let Some(details) = &request.source_details {
            p.insert("distilled_from".into(), details.clone());
        }
    }
    network.validate()?;
    Ok((network, outcome.report))
}
