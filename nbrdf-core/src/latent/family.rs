//! Which networks an autoencoder can encode as they are, and re-learning the others.
//!
//! The autoencoder reads a network's weights. It was trained on networks that `nbrdf train`
//! learnt from one common initialisation ([`crate::network::paper_init`] with one seed), which
//! is what aligns their hidden units; a network trained from another initialisation (the
//! authors' Keras files, another seed) computes the same kind of function with its units in
//! another order and scale, and its code is meaningless (an autoencoder fed the authors' 100
//! networks as given reconstructs at tone-mapped MAE 0.13, docs/results/latent.md). Such a
//! network is re-learnt first: tabulated on the MERL grid and trained from the common
//! initialisation, as the networks of the autoencoder's training set were. That needs the
//! autoencoder to record its networks' family (`provenance.networks`, [`Family::record`]); one
//! trained on networks of mixed or unknown origin records none, and nothing is re-learnt for it.

use super::autoencoder::{AutoEncoder, FORMAT_NAME};
use crate::error::Result;
use crate::network::Nbrdf;
use crate::train::{self, EpochStats, TrainConfig, TrainReport};
use std::borrow::Cow;
use std::time::Instant;

/// The networks an autoencoder encodes: width and seed of their common initialisation.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Family {
    pub hidden: usize,
    pub seed: u64,
}

/// Prefix of [`train::TRAINER_VERSION`], the same for every version of the trainer.
const TRAINER_PREFIX: &str = "nbrdf-core ";

/// `provenance.networks.initialisation` of an autoencoder whose training networks form a family.
const COMMON: &str = "common: nbrdf train from one seed";

impl Family {
    /// The family an autoencoder records for its training networks (`provenance.networks`,
    /// written by `nbrdf ae train` when they share one initialisation of `nbrdf train`); `None`
    /// when it records none (an autoencoder of networks of mixed or unknown origin: re-learning
    /// a network would not bring it closer to those).
    pub fn of(ae: &AutoEncoder) -> Option<Family> {
        Family::recorded(ae.nbrdf_hidden, &ae.provenance)
    }

    fn recorded(hidden: usize, provenance: &serde_json::Value) -> Option<Family> {
        let networks = &provenance["networks"];
        if networks["initialisation"].as_str() != Some(COMMON) {
            return None;
        }
        Some(Family {
            hidden,
            seed: networks["seed"].as_u64()?,
        })
    }

    /// The family of a training set: `Some` when every network was trained by `nbrdf train`
    /// from the same seed at the same width.
    pub fn common<'a>(nets: impl IntoIterator<Item = &'a Nbrdf>) -> Option<Family> {
        let mut family = None;
        for net in nets {
            let p = &net.provenance;
            if !p["trainer"].as_str()?.starts_with(TRAINER_PREFIX) {
                return None;
            }
            let this = Family {
                hidden: net.hidden_width(),
                seed: p["seed"].as_u64()?,
            };
            if *family.get_or_insert(this) != this {
                return None;
            }
        }
        family
    }

    /// What an autoencoder records of its training networks (`provenance.networks`), which
    /// [`Family::of`] reads back: this family, or (`None`) that they share no initialisation.
    pub fn record(family: Option<Family>) -> serde_json::Value {
        match family {
            Some(f) => serde_json::json!({
                "initialisation": COMMON,
                "seed": f.seed,
                "hidden": f.hidden,
                "weights": crate::network::INITIALISATION,
            }),
            None => serde_json::json!({"initialisation": "mixed or unknown"}),
        }
    }

    /// Why `net` is not of this family, read from its provenance; `None` when it is: trained by
    /// `nbrdf train` from this family's seed, or decoded or interpolated by the latent tools.
    /// A network without a recognised provenance is taken as foreign (re-learning it costs
    /// seconds; encoding a misaligned one gives a wrong code without any warning).
    pub fn foreign_reason(&self, net: &Nbrdf) -> Option<String> {
        let hidden = net.hidden_width();
        if hidden != self.hidden {
            return Some(format!(
                "hidden width {hidden}, the autoencoder's networks have {}",
                self.hidden
            ));
        }
        let p = &net.provenance;
        if p["decoded_by"].as_str() == Some(FORMAT_NAME) || p["interpolation"].is_string() {
            return None;
        }
        if let Some(trainer) = p["trainer"].as_str() {
            if !trainer.starts_with(TRAINER_PREFIX) {
                return Some(format!("trained by '{trainer}', not `nbrdf train`"));
            }
            return match p["seed"].as_u64() {
                Some(seed) if seed == self.seed => None,
                Some(seed) => Some(format!(
                    "trained from seed {seed}, not the common initialisation (seed {})",
                    self.seed
                )),
                None => Some("its provenance names no training seed".to_string()),
            };
        }
        if let Some(method) = p["method"].as_str() {
            return Some(format!(
                "{method}: initialised independently of the autoencoder's networks"
            ));
        }
        Some("no provenance of `nbrdf train`".to_string())
    }

    /// The training settings of a re-learn: the fixed budget the family's networks were trained
    /// with ([`TrainConfig::fixed_budget`], `nbrdf train`'s defaults before 0.2; a re-learnt
    /// network should land where the autoencoder's training networks did), from this family's
    /// initialisation.
    pub fn train_config(&self) -> TrainConfig {
        TrainConfig {
            hidden: self.hidden,
            seed: self.seed,
            ..TrainConfig::fixed_budget()
        }
    }

    /// `net` re-learnt in this family: tabulated on the MERL grid ([`Nbrdf::tabulate`], as
    /// `nbrdf tabulate`) and trained from the common initialisation ([`train::train`], as
    /// `nbrdf train`). The result keeps `net`'s name and sampling; its provenance is the
    /// trainer's, with `net`'s own under `relearnt_from`. Runs on the current rayon pool.
    pub fn relearn(
        &self,
        net: &Nbrdf,
        on_epoch: &mut dyn FnMut(&EpochStats),
    ) -> Result<(Nbrdf, TrainReport)> {
        self.relearn_with(net, &self.train_config(), on_epoch)
    }

    /// [`Family::relearn`] with other training settings (their width and seed are this
    /// family's whatever `config` says).
    pub fn relearn_with(
        &self,
        net: &Nbrdf,
        config: &TrainConfig,
        on_epoch: &mut dyn FnMut(&EpochStats),
    ) -> Result<(Nbrdf, TrainReport)> {
        let table = net.tabulate();
        let config = TrainConfig {
            hidden: self.hidden,
            seed: self.seed,
            ..config.clone()
        };
        let target = train::table_target(&table);
        let outcome = train::train(&target, &config, &net.name, on_epoch)?;
        let mut relearnt = outcome.network;
        let mut provenance = train::provenance(
            &config,
            &outcome.report,
            &format!("tabulation of network '{}'", net.name),
        );
        provenance["relearnt_from"] = net.provenance.clone();
        relearnt.provenance = provenance;
        relearnt.sampling = net.sampling.clone();
        relearnt.validate()?;
        Ok((relearnt, outcome.report))
    }
}

/// What happens to a network foreign to the autoencoder's family before it is encoded.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Relearn {
    /// Re-learn it ([`Family::relearn_with`]) with `nbrdf train`'s defaults, or at most
    /// `max_epochs` epochs (faster, and a network further from those the autoencoder saw).
    Auto { max_epochs: Option<usize> },
    /// Encode it as it is (its code is then not to be trusted).
    Off,
}

impl Default for Relearn {
    fn default() -> Self {
        Relearn::Auto { max_epochs: None }
    }
}

/// Told what [`encodable`] does, for the messages of a command.
pub trait RelearnObserver {
    /// `net` is not of `family` for `reason`; `relearning`: it is re-learnt now (else it is
    /// encoded as it is).
    fn foreign(&mut self, net: &str, reason: &str, family: Family, relearning: bool);
    /// `net` was re-learnt in `seconds`.
    fn relearnt(&mut self, net: &str, seconds: f64, report: &TrainReport);
}

/// `net` as an autoencoder of `family` ([`Family::of`]) can encode it: as it is when it is of
/// the family, when `relearn` is off, or when the autoencoder records no family (re-learning
/// would not bring a network closer to networks of mixed origin); else re-learnt.
pub fn encodable<'a>(
    family: Option<Family>,
    net: &'a Nbrdf,
    relearn: Relearn,
    observer: &mut dyn RelearnObserver,
) -> Result<Cow<'a, Nbrdf>> {
    // Before relearning, which would make an isotropic stand-in of it.
    super::require_isotropic(net)?;
    let Some(family) = family else {
        return Ok(Cow::Borrowed(net));
    };
    let Some(reason) = family.foreign_reason(net) else {
        return Ok(Cow::Borrowed(net));
    };
    let Relearn::Auto { max_epochs } = relearn else {
        observer.foreign(&net.name, &reason, family, false);
        return Ok(Cow::Borrowed(net));
    };
    observer.foreign(&net.name, &reason, family, true);
    let mut config = family.train_config();
    if let Some(epochs) = max_epochs {
        config.max_epochs = epochs;
        config.min_epochs = config.min_epochs.min(epochs);
    }
    let start = Instant::now();
    let (relearnt, report) = family.relearn_with(net, &config, &mut |_| {})?;
    observer.relearnt(&net.name, start.elapsed().as_secs_f64(), &report);
    Ok(Cow::Owned(relearnt))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn family() -> Family {
        Family {
            hidden: crate::network::DEFAULT_HIDDEN,
            seed: 0,
        }
    }

    fn with_provenance(p: serde_json::Value) -> Nbrdf {
        let mut net = Nbrdf::random("n", crate::network::DEFAULT_HIDDEN, 3);
        net.provenance = p;
        net
    }

    #[test]
    fn provenance_decides_the_family() {
        let f = family();
        let trained = |seed: u64| {
            with_provenance(serde_json::json!({"trainer": train::TRAINER_VERSION, "seed": seed}))
        };
        assert_eq!(f.foreign_reason(&trained(0)), None);
        assert!(f.foreign_reason(&trained(7)).unwrap().contains("seed 7"));
        let keras = with_provenance(serde_json::json!({"method": "imported from Keras"}));
        assert!(f.foreign_reason(&keras).unwrap().contains("Keras"));
        assert!(f
            .foreign_reason(&with_provenance(serde_json::json!({})))
            .is_some());
        assert!(f
            .foreign_reason(&with_provenance(serde_json::json!({"trainer": "keras"})))
            .is_some());
        let decoded = with_provenance(serde_json::json!({"decoded_by": FORMAT_NAME}));
        assert_eq!(f.foreign_reason(&decoded), None);
        let narrow = Nbrdf::random("n", 8, 0);
        assert!(f
            .foreign_reason(&narrow)
            .unwrap()
            .contains("hidden width 8"));
        let other = Family { seed: 7, ..f };
        assert_eq!(other.foreign_reason(&trained(7)), None);
    }

    #[test]
    fn an_autoencoder_records_the_family_of_its_training_networks() {
        let trained = |seed: u64, hidden: usize| {
            let mut net = Nbrdf::random("n", hidden, 1);
            net.provenance = serde_json::json!({"trainer": train::TRAINER_VERSION, "seed": seed});
            net
        };
        let same = [trained(3, 21), trained(3, 21)];
        let f = Family::common(&same).unwrap();
        assert_eq!(
            f,
            Family {
                hidden: 21,
                seed: 3
            }
        );
        let provenance = serde_json::json!({"networks": Family::record(Some(f))});
        assert_eq!(Family::recorded(21, &provenance), Some(f));
        assert_eq!(Family::common(&[trained(3, 21), trained(4, 21)]), None);
        assert_eq!(Family::common(&[trained(3, 21), trained(3, 8)]), None);
        let keras = with_provenance(serde_json::json!({"method": "imported from Keras"}));
        assert_eq!(Family::common([&same[0], &keras]), None);
        let mixed = serde_json::json!({"networks": Family::record(None)});
        assert_eq!(Family::recorded(21, &mixed), None);
        assert_eq!(Family::recorded(21, &serde_json::Value::Null), None);
    }

    /// Records what [`encodable`] reports.
    #[derive(Default)]
    struct Events(Vec<String>);

    impl RelearnObserver for Events {
        fn foreign(&mut self, net: &str, reason: &str, _: Family, relearning: bool) {
            self.0.push(format!("foreign {net} {relearning}: {reason}"));
        }
        fn relearnt(&mut self, net: &str, _: f64, report: &TrainReport) {
            self.0.push(format!("relearnt {net} {}", report.epochs_run));
        }
    }

    #[test]
    fn anisotropic_networks_are_refused_before_any_relearning() {
        let mut net = Nbrdf::random("brushed", 4, 1);
        net.anisotropic = true;
        let mut events = Events::default();
        for family in [None, Some(Family { hidden: 4, seed: 2 })] {
            let relearn = Relearn::Auto {
                max_epochs: Some(1),
            };
            let err = encodable(family, &net, relearn, &mut events).unwrap_err();
            assert!(err.to_string().contains("anisotropic"), "{err}");
        }
        assert!(events.0.is_empty(), "{:?}", events.0);
    }

    #[test]
    fn only_foreign_networks_are_relearnt_and_each_step_is_reported() {
        let f = Family { hidden: 4, seed: 2 };
        let mut own = Nbrdf::random("own", 4, 1);
        own.provenance = serde_json::json!({"trainer": train::TRAINER_VERSION, "seed": 2});
        let mut keras = Nbrdf::random("keras", 4, 3);
        keras.provenance = serde_json::json!({"method": "imported from Keras"});
        let quick = Relearn::Auto {
            max_epochs: Some(1),
        };
        let mut events = Events::default();
        let same =
            |c: &Cow<'_, Nbrdf>, n: &Nbrdf| matches!(c, Cow::Borrowed(b) if std::ptr::eq(*b, n));

        assert!(same(
            &encodable(Some(f), &own, quick, &mut events).unwrap(),
            &own
        ));
        assert!(same(
            &encodable(None, &keras, quick, &mut events).unwrap(),
            &keras
        ));
        assert!(events.0.is_empty(), "{:?}", events.0);

        let kept = encodable(Some(f), &keras, Relearn::Off, &mut events).unwrap();
        assert!(same(&kept, &keras));
        assert_eq!(events.0.len(), 1);
        assert!(events.0[0].starts_with("foreign keras false: imported from Keras"));

        events.0.clear();
        let relearnt = encodable(Some(f), &keras, quick, &mut events).unwrap();
        assert!(matches!(relearnt, Cow::Owned(_)));
        assert_eq!(f.foreign_reason(&relearnt), None);
        assert_eq!(relearnt.provenance["relearnt_from"], keras.provenance);
        assert_eq!(events.0.len(), 2, "{:?}", events.0);
        assert!(events.0[0].starts_with("foreign keras true"));
        assert_eq!(events.0[1], "relearnt keras 1");
    }

    /// A re-learnt network is a fresh `nbrdf train` run on the tabulation, i.e. the weights of
    /// training from the family's initialisation on that table, whatever the source's width.
    #[test]
    fn relearn_is_train_from_the_common_initialisation_on_the_tabulation() {
        let f = Family { hidden: 4, seed: 2 };
        let mut source = Nbrdf::random("m", 6, 9);
        source.provenance = serde_json::json!({"method": "imported from Keras"});
        let config = TrainConfig {
            samples: 4_000,
            max_epochs: 2,
            ..TrainConfig::default()
        };
        let (relearnt, report) = f.relearn_with(&source, &config, &mut |_| {}).unwrap();
        let direct_config = TrainConfig {
            hidden: 4,
            seed: 2,
            ..config
        };
        let table = source.tabulate();
        let direct = train::train(
            &train::table_target(&table),
            &direct_config,
            "m",
            &mut |_| {},
        )
        .unwrap()
        .network;
        assert_eq!(relearnt.layers, direct.layers);
        assert_eq!(report.epochs_run, 2);
        assert_eq!(
            relearnt.provenance["relearnt_from"]["method"],
            "imported from Keras"
        );
        assert_eq!(relearnt.provenance["seed"], 2);
        assert_eq!(
            f.foreign_reason(&source)
                .map(|r| r.contains("hidden width 6")),
            Some(true)
        );
        assert_eq!(f.foreign_reason(&relearnt), None);
    }
}
