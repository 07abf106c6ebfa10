//! The pretrained autoencoder and Phong predictor built into the command (`nbrdf-core/data/
//! models/`, made by `python -m nbrdf_tools.pretrained`: the authors' 100 MERL networks re-learnt
//! from the common initialisation), and the messages of re-learning the networks they cannot
//! encode as given (the decision is the library's: `latent::family`).
//!
//! Embedded here, in the command alone: the library (and the C ABI built on it) carries no models.

use clap::Args;
use nbrdf_core::latent::autoencoder::AutoEncoder;
use nbrdf_core::latent::family::{Family, Relearn, RelearnObserver};
use nbrdf_core::latent::predictor::PhongPredictor;
use nbrdf_core::ops::autoencoder::Encoding;
use nbrdf_core::ops::limits::MAX_EPOCHS;
use nbrdf_core::train::TrainReport;
use nbrdf_core::{NbrdfError, Result};
use std::path::Path;

pub const AUTOENCODER: &str = include_str!("../../../data/models/autoencoder.json");
pub const PREDICTOR: &str = include_str!("../../../data/models/predictor.json");

/// `--ae PATH`, or the built-in autoencoder.
pub fn autoencoder(path: Option<&Path>) -> Result<AutoEncoder> {
    match path {
        Some(p) => AutoEncoder::load(p),
        None => AutoEncoder::from_json(AUTOENCODER, "the built-in autoencoder"),
    }
}

/// The autoencoder and predictor of `--ae` and `--predictor`, each built in when not given. A
/// predictor reads the codes of the autoencoder it was trained with, so `--ae` alone (the
/// built-in predictor with another autoencoder's codes) is refused.
pub fn models(
    ae: Option<&Path>,
    predictor: Option<&Path>,
) -> Result<(AutoEncoder, PhongPredictor)> {
    let predictor = match (ae, predictor) {
        (_, Some(p)) => PhongPredictor::load(p)?,
        (Some(a), None) => {
            return Err(NbrdfError::Usage(format!(
                "--ae {} needs --predictor: the built-in predictor reads the built-in \
                 autoencoder's codes (give the one `nbrdf predictor train --ae {}` made)",
                a.display(),
                a.display()
            )))
        }
        (None, None) => PhongPredictor::from_json(PREDICTOR, "the built-in predictor")?,
    };
    Ok((autoencoder(ae)?, predictor))
}

/// The options of the commands that encode a network the user gives.
#[derive(Args, Clone, Copy, Debug, Default)]
pub struct RelearnArgs {
    /// Encode a network as it is even when it is not of the autoencoder's networks (trained by
    /// `nbrdf train` from their initialisation): its code is then not to be trusted. By
    /// default such a network (the authors' Keras files, another --seed) is re-learnt first.
    #[arg(long)]
    no_relearn: bool,
    /// Epoch limit of that re-learn (default: `nbrdf train`'s; fewer are faster but give a
    /// network further from those the autoencoder was trained on).
    #[arg(long, value_name = "N", conflicts_with = "no_relearn",
          value_parser = super::count_in::<1, { MAX_EPOCHS }>)]
    relearn_epochs: Option<usize>,
}

impl RelearnArgs {
    pub fn relearn(&self) -> Relearn {
        if self.no_relearn {
            Relearn::Off
        } else {
            Relearn::Auto {
                max_epochs: self.relearn_epochs,
            }
        }
    }
}

/// Says on stderr what happens to a foreign network.
pub struct Messages;

impl RelearnObserver for Messages {
    fn foreign(&mut self, net: &str, reason: &str, family: Family, relearning: bool) {
        if relearning {
            eprintln!(
                "nbrdf: '{net}' is not of the autoencoder's networks ({reason}): re-learning it \
                 from their common initialisation (tabulate + train, seed {}; --no-relearn \
                 skips this)",
                family.seed
            );
        } else {
            eprintln!(
                "nbrdf: warning: encoding '{net}' as it is (--no-relearn), although it is not of \
                 the autoencoder's networks ({reason}): its code is not to be trusted"
            );
        }
    }

    fn relearnt(&mut self, net: &str, seconds: f64, report: &TrainReport) {
        eprintln!(
            "nbrdf: re-learnt '{net}' in {seconds:.1} s ({} epochs, validation loss {:.3e})",
            report.epochs_run, report.best_validation_loss
        );
    }
}

/// The encoding settings of `args`, reporting on stderr.
pub fn encoding<'a>(args: &RelearnArgs, messages: &'a mut Messages) -> Encoding<'a> {
    Encoding {
        relearn: args.relearn(),
        observer: messages,
    }
}
