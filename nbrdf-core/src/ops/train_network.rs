//! `nbrdf train`: a network learnt from a MERL-format table or an RGL `.bsdf` measurement.

use super::{file_stem, with_threads};
use crate::error::Result;
use crate::merl::PhiFold;
use crate::source::{rgl_target, RglFold, TrainingSource};
use crate::train::{self, Anisotropy, EpochStats, TrainConfig, TrainReport};
use std::fmt;
use std::path::PathBuf;

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
        TrainingSource::Rgl(measurement) => {
            let target = rgl_target(&measurement, request.rgl_fold);
            let outcome = with_threads(request.threads, || {
                train::train(&target, config, &name, on_epoch)
            })?
            .map_err(super::about_data(&request.source.display().to_string()))?;
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
    }
    network.validate()?;
    network.save(&output)?;
    Ok(TrainNetworkReport {
        output,
        report: outcome.report,
    })
}
