//! The command-line definition parses what the documentation promises; user errors are errors.

use super::train_cmd::SamplingArg;
use super::*;
use clap::CommandFactory;

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
        (1000, 3, Some(2), 9)
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
    assert!((args.lr - 5e-4).abs() < 1e-9);
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
