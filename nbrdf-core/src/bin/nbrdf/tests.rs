//! The command-line definition parses what the documentation promises; user errors are errors.

use super::train_cmd::SamplingArg;
use super::*;
use clap::CommandFactory;
use nbrdf_core::ops::train_network::NetworkKind;
use nbrdf_core::train::Anisotropy;

#[test]
fn cli_definition_is_consistent() {
    Cli::command().debug_assert();
}

#[test]
fn every_command_and_option_has_help() {
    let cli = Cli::command();
    for sub in cli.get_subcommands() {
        assert!(sub.get_about().is_some(), "{}", sub.get_name());
        for arg in sub.get_arguments() {
            let builtin = matches!(arg.get_id().as_str(), "help" | "version");
            assert!(
                builtin || arg.get_help().is_some(),
                "{} {}",
                sub.get_name(),
                arg.get_id()
            );
        }
    }
}

#[test]
fn arguments_parse() {
    let cli = Cli::try_parse_from([
        "nbrdf",
        "synth",
        "--model",
        "abc",
        "--material",
        "x",
        "-o",
        "y.binary",
    ]);
    let Ok(Cli {
        command: Command::Synth(args),
    }) = cli
    else {
        panic!("synth must parse")
    };
    assert!(matches!(args.model, ModelArg::Abc));
    assert_eq!(args.output, Some(PathBuf::from("y.binary")));
    assert!(Cli::try_parse_from(["nbrdf", "synth", "--model", "ggx", "--material", "x"]).is_err());
    assert!(Cli::try_parse_from(["nbrdf", "info"]).is_err());
}

#[test]
fn train_and_fit_phong_arguments_parse() {
    let Ok(Cli {
        command: Command::Train(args),
    }) = Cli::try_parse_from([
        "nbrdf",
        "train",
        "t.binary",
        "-o",
        "n.nbrdf.json",
        "--sampling",
        "uniform",
        "--samples",
        "1000",
        "--epochs",
        "3",
        "--threads",
        "2",
        "--seed",
        "9",
        "--quiet",
    ])
    else {
        panic!("train must parse")
    };
    assert!(matches!(args.sampling, SamplingArg::Uniform));
    assert_eq!(
        (args.samples, args.epochs, args.threads, args.seed),
        (Some(1000), Some(3), Some(2), 9)
    );
    assert_eq!((args.hidden, args.batch), (21, 512));
    assert!(matches!(args.phi_fold, PhiFoldArg::Reciprocal));
    let Ok(Cli {
        command: Command::Train(args),
    }) = Cli::try_parse_from(["nbrdf", "train", "t.binary", "--phi-fold", "mirror"])
    else {
        panic!("train --phi-fold must parse")
    };
    assert_eq!(PhiFold::from(args.phi_fold), PhiFold::Mirror);
    assert!(Cli::try_parse_from(["nbrdf", "train", "t.binary", "--phi-fold", "odd"]).is_err());
    assert!(matches!(args.anisotropy, train_cmd::AnisotropyArg::Auto));
    assert_eq!(args.samples, None);
    for (flag, want) in [("on", Anisotropy::On), ("off", Anisotropy::Off)] {
        let Ok(Cli {
            command: Command::Train(a),
        }) = Cli::try_parse_from(["nbrdf", "train", "t.bsdf", "--anisotropy", flag])
        else {
            panic!("train --anisotropy {flag} must parse")
        };
        assert_eq!(Anisotropy::from(a.anisotropy), want);
    }
    assert!(Cli::try_parse_from(["nbrdf", "train", "t", "--anisotropy", "maybe"]).is_err());
    assert_eq!(
        NetworkKind::from(args.output_kind),
        NetworkKind::Auto,
        "a spectral source makes a spectral network unless told otherwise"
    );
    for (flag, want) in [
        ("rgb", NetworkKind::Rgb),
        ("spectral", NetworkKind::Spectral),
    ] {
        let Ok(Cli {
            command: Command::Train(a),
        }) = Cli::try_parse_from(["nbrdf", "train", "t.bsdf", "--output-kind", flag])
        else {
            panic!("train --output-kind {flag} must parse")
        };
        assert_eq!(NetworkKind::from(a.output_kind), want);
    }
    assert!(Cli::try_parse_from(["nbrdf", "train", "t", "--output-kind", "xyz"]).is_err());
    let config = train_cmd::train_config(&args);
    assert_eq!(
        (
            config.adam.learning_rate,
            config.max_epochs,
            config.lr_decays
        ),
        (1e-3, 300, 2)
    );
    assert_eq!(config.target_loss, 2e-4);
    let Ok(Cli {
        command: Command::Train(fixed),
    }) = Cli::try_parse_from([
        "nbrdf",
        "train",
        "t.binary",
        "--fixed-budget",
        "--epochs",
        "50",
    ])
    else {
        panic!("train --fixed-budget must parse")
    };
    let config = train_cmd::train_config(&fixed);
    assert_eq!(
        (
            config.adam.learning_rate,
            config.max_epochs,
            config.patience
        ),
        (5e-4, 50, 10)
    );
    assert_eq!((config.lr_decays, config.target_loss), (0, 0.0));
    assert!(Cli::try_parse_from(["nbrdf", "train", "t.binary", "--sampling", "random"]).is_err());
    assert!(Cli::try_parse_from(["nbrdf", "train", "t.binary", "--samples", "-5"]).is_err());
    let Ok(Cli {
        command: Command::FitPhong(args),
    }) = Cli::try_parse_from(["nbrdf", "fit-phong", "n.nbrdf.json", "--json"])
    else {
        panic!("fit-phong must parse")
    };
    assert!(args.json && args.output.is_none());
    assert!(args.lobe == LobeArg::Variance);
    let Ok(Cli {
        command: Command::FitPhong(args),
    }) = Cli::try_parse_from(["nbrdf", "fit-phong", "n.nbrdf.json", "--lobe", "model"])
    else {
        panic!("fit-phong --lobe model must parse")
    };
    assert!(args.lobe == LobeArg::Model);
    assert!(Cli::try_parse_from(["nbrdf", "fit-phong", "n.nbrdf.json", "--lobe", "x"]).is_err());
}

#[test]
fn compare_arguments_parse() {
    let Ok(Cli {
        command: Command::Compare(args),
    }) = Cli::try_parse_from([
        "nbrdf",
        "compare",
        "a.binary",
        "b.nbrdf.json",
        "--resolution",
        "32",
        "--json",
    ])
    else {
        panic!("compare must parse")
    };
    assert_eq!(
        (args.resolution, args.samples, args.json),
        (32, 100_000, true)
    );
    assert!(Cli::try_parse_from(["nbrdf", "compare", "a.binary"]).is_err());
}

#[test]
fn unknown_material_is_an_error_not_a_panic() {
    let args = SynthArgs {
        model: ModelArg::Sgd,
        material: "unobtainium".into(),
        output: None,
    };
    let err = run_synth(&args).unwrap_err();
    assert!(err.to_string().contains("unknown material 'unobtainium'"));
}

#[test]
fn info_of_a_missing_file_names_it() {
    let args = InfoArgs {
        file: std::env::temp_dir().join("nbrdf-no-such-file.binary"),
    };
    assert!(run_info(&args)
        .unwrap_err()
        .to_string()
        .contains("nbrdf-no-such-file.binary"));
}

/// The built-in models are what `python -m nbrdf_tools.pretrained` packages: an autoencoder that
/// records the family of its training networks (`nbrdf train`'s default seed and width), which
/// decides what is re-learnt, and a predictor of its codes.
#[test]
fn builtin_models_record_their_family() {
    use nbrdf_core::latent::family::Family;
    use nbrdf_core::network::{Nbrdf, DEFAULT_HIDDEN};
    let (ae, predictor) = pretrained::models(None, None).unwrap();
    assert_eq!(
        Family::of(&ae),
        Some(Family {
            hidden: DEFAULT_HIDDEN,
            seed: 0
        })
    );
    assert_eq!(predictor.provenance["networks"], ae.provenance["networks"]);
    assert_eq!((ae.split.train.len(), ae.split.test.len()), (80, 20));
    let net = Nbrdf::random("n", DEFAULT_HIDDEN, 1);
    let code = ae.encode(&net).unwrap();
    assert_eq!(predictor.inputs(&code, &net).len(), predictor.mlp.inputs());
    let (n, w) = predictor.predict(&predictor.inputs(&code, &net));
    assert!(n.is_finite() && n >= 0.0 && (0.0..=1.0).contains(&w));
}

#[test]
fn models_are_optional_but_a_predictor_goes_with_its_autoencoder() {
    for command in [
        vec!["nbrdf", "predict-phong", "n.nbrdf.json"],
        vec!["nbrdf", "predict-phong", "n.nbrdf.json", "--no-relearn"],
        vec![
            "nbrdf",
            "predict-phong",
            "n.nbrdf.json",
            "--relearn-epochs",
            "3",
        ],
        vec!["nbrdf", "ae", "encode", "n.nbrdf.json"],
        vec!["nbrdf", "ae", "decode", "code.json", "-o", "d.nbrdf.json"],
        vec!["nbrdf", "ae", "eval", "--nbrdfs", "dir"],
        vec!["nbrdf", "interpolate", "a.json", "b.json", "-o", "dir"],
        vec![
            "nbrdf",
            "predictor",
            "train",
            "--nbrdfs",
            "dir",
            "-o",
            "p.json",
        ],
        vec!["nbrdf", "predictor", "eval", "--nbrdfs", "dir"],
    ] {
        assert!(Cli::try_parse_from(&command).is_ok(), "{command:?}");
    }
    for command in [
        vec![
            "nbrdf",
            "predict-phong",
            "n.json",
            "--no-relearn",
            "--relearn-epochs",
            "3",
        ],
        vec!["nbrdf", "predict-phong", "n.json", "--relearn-epochs", "0"],
    ] {
        assert!(Cli::try_parse_from(&command).is_err(), "{command:?}");
    }
    let refused = pretrained::models(Some(std::path::Path::new("ae.json")), None).unwrap_err();
    assert!(matches!(refused, NbrdfError::Usage(_)), "{refused}");
    assert!(refused.to_string().contains("--predictor"));
}
