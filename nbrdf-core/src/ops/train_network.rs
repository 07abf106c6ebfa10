//! `nbrdf train`: a network learnt from a MERL-format table.

use super::{file_stem, with_threads};
use crate::error::Result;
use crate::merl::{MerlTable, PhiFold};
use crate::train::{self, EpochStats, TrainConfig, TrainReport};
use std::fmt;
use std::path::PathBuf;

/// What to train.
#[derive(Clone, Debug, PartialEq)]
pub struct TrainRequest {
    pub table: PathBuf,
    pub phi_fold: PhiFold,
    /// Default: `NAME.nbrdf.json` in the current directory.
    pub output: Option<PathBuf>,
    /// Stored in the network; default: the table's file name without extensions.
    pub name: Option<String>,
    pub config: TrainConfig,
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

/// Trains a network on the table, calling `on_epoch` after every epoch, and writes it with its
/// provenance (the settings, the source table and its `phi_d` fold).
pub fn train_network(
    request: &TrainRequest,
    on_epoch: &mut (dyn FnMut(&EpochStats) + Send),
) -> Result<TrainNetworkReport> {
    let table = MerlTable::read(&request.table)?.with_phi_fold(request.phi_fold);
    let name = request
        .name
        .clone()
        .unwrap_or_else(|| file_stem(&request.table));
    let output = request
        .output
        .clone()
        .unwrap_or_else(|| PathBuf::from(format!("{name}.nbrdf.json")));
    let config = &request.config;
    let target = train::table_target(&table);
    let outcome = with_threads(request.threads, || {
        train::train(&target, config, &name, on_epoch)
    })??;
    let mut network = outcome.network;
    network.provenance = train::provenance(
        config,
        &outcome.report,
        &request.table.display().to_string(),
    );
    if let Some(p) = network.provenance.as_object_mut() {
        p.insert("phi_fold".into(), table.phi_fold().as_str().into());
    }
    network.validate()?;
    network.save(&output)?;
    Ok(TrainNetworkReport {
        output,
        report: outcome.report,
    })
}
