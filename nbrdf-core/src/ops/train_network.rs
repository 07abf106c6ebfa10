//! `nbrdf train`: a network learnt from a MERL-format table or an RGL `.bsdf` measurement; a
//! spectral measurement (`*_spec.bsdf`) gives a spectral network (file format version 3) by
//! default, learnt from its spectra at the file's own wavelengths ([`crate::train::spectral`]).

use super::{file_stem, with_threads};
use crate::error::{NbrdfError, Result};
use crate::merl::PhiFold;
use crate::rgl::RglMeasurement;
use crate::source::{rgl_target, RglFold, TrainingSource};
use crate::train::arrays::sample_directions_for;
use crate::train::spectral::{self, SpectralSource};
use crate::train::{self, Anisotropy, EpochStats, TrainConfig, TrainOutcome, TrainReport};
use glam::Vec3;
use std::fmt;
use std::path::PathBuf;

/// Which network `nbrdf train` makes: RGB values or spectral coefficients.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum NetworkKind {
    /// Spectral for a spectral measurement, RGB otherwise.
    #[default]
    Auto,
    /// An RGB network (of a spectral measurement: its linear sRGB projection under D65).
    Rgb,
    /// A spectral network (file format version 3); only from a spectral measurement.
    Spectral,
}

impl NetworkKind {
    pub fn as_str(self) -> &'static str {
        match self {
            NetworkKind::Auto => "auto",
            NetworkKind::Rgb => "rgb",
            NetworkKind::Spectral => "spectral",
        }
    }

    /// Whether a source with (or without) spectra makes a spectral network; an error for a
    /// spectral network asked of an RGB source.
    pub fn resolve(self, source_is_spectral: bool, source: &str) -> Result<bool> {
        match (self, source_is_spectral) {
            (NetworkKind::Spectral, false) => Err(NbrdfError::InvalidArgument(format!(
                "{source}: a spectral network needs a spectral source (an RGL *_spec.bsdf file \
                 with a \"wavelengths\" field); this one is RGB, so its network is RGB \
                 (leave out --output-kind spectral)"
            ))),
            (NetworkKind::Auto, spectral) => Ok(spectral),
            (kind, _) => Ok(kind == NetworkKind::Spectral),
        }
    }
}

/// What to train.
#[derive(Clone, Debug, PartialEq)]
pub struct TrainRequest {
    /// A MERL-format table or an RGL `.bsdf` measurement, told apart by content.
    pub source: PathBuf,
    /// How a table folds phi_d (tables only).
    pub phi_fold: PhiFold,
    /// How an RGL measurement's non-reciprocity enters the target (measurements only).
    pub rgl_fold: RglFold,
    /// Default: `NAME.nbrdf.json` in the current directory.
    pub output: Option<PathBuf>,
    /// Stored in the network; default: the table's file name without extensions.
    pub name: Option<String>,
    /// `config.anisotropic` is replaced by this decision, made with the source.
    pub config: TrainConfig,
    /// Isotropic or anisotropic network: from the source ([`Anisotropy::Auto`]) or forced.
    pub anisotropy: Anisotropy,
    /// RGB or spectral network: from the source ([`NetworkKind::Auto`]) or forced.
    pub network_kind: NetworkKind,
    /// Whether `config.samples` is a default, multiplied by
    /// [`train::ANISOTROPIC_SAMPLE_FACTOR`] for an anisotropic network (false: the user's count,
    /// used as given).
    pub scale_samples: bool,
    pub threads: Option<usize>,
}

/// The network written and how training went.
#[derive(Clone, Debug, PartialEq)]
pub struct TrainNetworkReport {
    pub output: PathBuf,
    pub report: TrainReport,
}

impl fmt::Display for TrainNetworkReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let r = &self.report;
        writeln!(
            f,
            "wrote {}: {} epochs ({}), best validation loss {:.4e} at epoch {}, {:.1} s",
            self.output.display(),
            r.epochs_run,
            if r.stopped_early {
                "stopped early"
            } else {
                "epoch limit"
            },
            r.best_validation_loss,
            r.best_epoch,
            r.seconds,
        )
    }
}

/// Trains a network on the source, calling `on_epoch` after every epoch, and writes it with its
/// provenance (the settings, the source file, its kind and fold).
pub fn train_network(
    request: &TrainRequest,
    on_epoch: &mut (dyn FnMut(&EpochStats) + Send),
) -> Result<TrainNetworkReport> {
    super::limits::check_train(&request.config)?;
    let source = TrainingSource::open(&request.source)?;
    let name = request
        .name
        .clone()
        .unwrap_or_else(|| file_stem(&request.source));
    let output = request
        .output
        .clone()
        .unwrap_or_else(|| PathBuf::from(format!("{name}.nbrdf.json")));
    let anisotropic = request.anisotropy.resolve(source.is_isotropic());
    let config = &request
        .config
        .clone()
        .for_anisotropy(anisotropic, request.scale_samples);
    let kind = source.kind();
    let source_name = request.source.display().to_string();
    let spectra = match &source {
        TrainingSource::Rgl(m) => m.spectra().map(|s| s.wavelengths().to_vec()),
        TrainingSource::Table { .. } => None,
    };
    let spectral_network = request
        .network_kind
        .resolve(spectra.is_some(), &source_name)?;
    let (outcome, fold_key, fold) = match source {
        TrainingSource::Table { table, .. } => {
            let table = table.with_phi_fold(request.phi_fold);
            let target = train::table_target(&table);
            let outcome = with_threads(request.threads, || {
                train::train(&target, config, &name, on_epoch)
            })?
            .map_err(super::about_data(&request.source.display().to_string()))?;
            (outcome, "phi_fold", table.phi_fold().as_str())
        }
        TrainingSource::Rgl(measurement) if spectral_network => {
            let outcome = with_threads(request.threads, || {
                train_rgl_spectra(&measurement, request.rgl_fold, config, &name, on_epoch)
            })?
            .map_err(super::about_data(&source_name))?;
            (outcome, "rgl_fold", request.rgl_fold.as_str())
        }
        TrainingSource::Rgl(measurement) => {
            let target = rgl_target(&measurement, request.rgl_fold);
            let outcome = with_threads(request.threads, || {
                train::train(&target, config, &name, on_epoch)
            })?
            .map_err(super::about_data(&source_name))?;
            (outcome, "rgl_fold", request.rgl_fold.as_str())
        }
    };
    let mut network = outcome.network;
    network.provenance = train::provenance(
        config,
        &outcome.report,
        &request.source.display().to_string(),
    );
    if let Some(p) = network.provenance.as_object_mut() {
        p.insert("source_kind".into(), kind.into());
        p.insert(fold_key.into(), fold.into());
        p.insert("anisotropy".into(), request.anisotropy.as_str().into());
        p.insert("network_kind".into(), request.network_kind.as_str().into());
        if let (true, Some(wavelengths)) = (spectral_network, &spectra) {
            p.insert(
                "spectral_target".into(),
                spectral::provenance_entry(wavelengths),
            );
        }
    }
    network.validate()?;
    network.save(&output)?;
    Ok(TrainNetworkReport {
        output,
        report: outcome.report,
    })
}

/// A spectral measurement evaluated at the trainer's own directions (those of
/// [`sample_directions_for`]: training pairs, then validation pairs) and the file's wavelengths, as
/// Mitsuba's `measured` evaluates it in a spectral variant.
struct RglSpectra<'a> {
    measurement: &'a RglMeasurement,
    wavelengths: &'a [f32],
    pairs: Vec<(Vec3, Vec3)>,
}

impl SpectralSource for RglSpectra<'_> {
    fn pairs(&self) -> usize {
        self.pairs.len()
    }

    fn wavelengths(&self) -> &[f32] {
        self.wavelengths
    }

    fn directions(&self, i: usize) -> (Vec3, Vec3) {
        self.pairs[i]
    }

    fn values(&self, i: usize, a: &mut [f32], b: Option<&mut [f32]>) -> Result<()> {
        let (view, light) = self.pairs[i];
        let m = self.measurement;
        m.eval_spectrum_cos_f32(view, light, self.wavelengths, a)?;
        match b {
            Some(b) => m.eval_spectrum_cos_f32(light, view, self.wavelengths, b),
            None => Ok(()),
        }
    }

    fn has_swapped(&self) -> bool {
        true
    }
}

/// A spectral network of a spectral measurement, on `config.samples` pairs: as in the RGB path,
/// pairs the reciprocal mean leaves out at grazing angles are replaced by the next candidates.
fn train_rgl_spectra(
    measurement: &RglMeasurement,
    fold: RglFold,
    config: &TrainConfig,
    name: &str,
    on_epoch: &mut dyn FnMut(&EpochStats),
) -> Result<TrainOutcome> {
    let wavelengths = measurement
        .spectra()
        .map(|s| s.wavelengths())
        .ok_or_else(|| NbrdfError::InvalidArgument("the measurement has no spectra".into()))?;
    let (pairs, validation) = sample_directions_for(config, fold)?;
    let source = RglSpectra {
        measurement,
        wavelengths,
        pairs,
    };
    spectral::train_spectral(&source, validation, fold, config, name, on_epoch)
}
