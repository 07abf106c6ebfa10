//! The `nbrdf` command-line tool.
//!
//! One variant of [`Command`] per subcommand, each with its own argument struct and `run_*`
//! function returning the crate's `Result`; `main` alone turns errors into `error: ...` on stderr
//! and exit status 1. New commands (train, fit-phong, compare, ...) slot in the same way.

use clap::{Args, Parser, Subcommand, ValueEnum};
use nbrdf_core::analytic::{catalogue, AnalyticBrdf, ModelKind};
use nbrdf_core::merl::{self, MerlTable};
use nbrdf_core::{NbrdfError, Result};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

#[derive(Parser)]
#[command(
    name = "nbrdf",
    version,
    about = "Neural BRDFs: synthesise, train, fit and compare measured materials"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// List the 100 MERL material names of the embedded SGD and ABC fits.
    ListMaterials(ListMaterialsArgs),
    /// Tabulate an analytic fit of a MERL material into a MERL-format table (.binary).
    Synth(SynthArgs),
    /// Validate a MERL-format table and print per-channel reflectance statistics.
    Info(InfoArgs),
}

#[derive(Args)]
struct ListMaterialsArgs {
    /// Print a JSON array of {"name", "alias"} objects instead of one name per line.
    #[arg(long)]
    json: bool,
}

#[derive(Clone, Copy, ValueEnum)]
enum ModelArg {
    /// Shifted gamma distribution fits (Bagher et al. 2012).
    Sgd,
    /// ABC fits (Löw et al. 2012).
    Abc,
}

impl From<ModelArg> for ModelKind {
    fn from(m: ModelArg) -> Self {
        match m {
            ModelArg::Sgd => ModelKind::Sgd,
            ModelArg::Abc => ModelKind::Abc,
        }
    }
}

#[derive(Args)]
struct SynthArgs {
    /// Which published analytic model to tabulate.
    #[arg(long, value_enum)]
    model: ModelArg,
    /// MERL material name or alias (see `nbrdf list-materials`).
    #[arg(long)]
    material: String,
    /// Where to write the table; defaults to MATERIAL.binary in the current directory.
    #[arg(short, long, value_name = "OUT.binary")]
    output: Option<PathBuf>,
}

#[derive(Args)]
struct InfoArgs {
    /// The MERL-format table to inspect.
    #[arg(value_name = "FILE.binary")]
    file: PathBuf,
}

fn main() -> ExitCode {
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) => {
            // --help and --version come through here too and are not failures.
            let _ = e.print();
            return if e.use_stderr() {
                ExitCode::from(1)
            } else {
                ExitCode::SUCCESS
            };
        }
    };
    match run(cli.command) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::from(1)
        }
    }
}

fn run(command: Command) -> Result<()> {
    match command {
        Command::ListMaterials(args) => run_list_materials(&args),
        Command::Synth(args) => run_synth(&args),
        Command::Info(args) => run_info(&args),
    }
}

fn run_list_materials(args: &ListMaterialsArgs) -> Result<()> {
    let names = catalogue::material_names();
    if args.json {
        let entries: Vec<serde_json::Value> = names
            .iter()
            .map(|&name| serde_json::json!({ "name": name, "alias": catalogue::alias(name) }))
            .collect();
        let text = serde_json::to_string_pretty(&entries)
            .map_err(|e| NbrdfError::InvalidArgument(format!("cannot format JSON: {e}")))?;
        emit(&format!("{text}\n"))
    } else {
        emit(&names.iter().map(|n| format!("{n}\n")).collect::<String>())
    }
}

fn run_synth(args: &SynthArgs) -> Result<()> {
    let model = ModelKind::from(args.model);
    let brdf = AnalyticBrdf::from_catalogue(model, &args.material)?;
    // from_catalogue succeeded, so the name resolves; the canonical one makes the file name.
    let name = catalogue::canonical_name(&args.material).unwrap_or(&args.material);
    let output = args
        .output
        .clone()
        .unwrap_or_else(|| PathBuf::from(format!("{name}.binary")));
    let start = Instant::now();
    let table = brdf.tabulate();
    table.write(&output)?;
    let seconds = start.elapsed().as_secs_f64();
    let invalid = table.stats().invalid_cells;
    emit(&format!(
        "wrote {} ({} fit of {name}, {} bytes{}) in {seconds:.2} s\n",
        output.display(),
        model.name().to_uppercase(),
        merl::FILE_SIZE,
        if invalid > 0 {
            format!(", {invalid} cells not finite and marked invalid")
        } else {
            String::new()
        },
    ))
}

fn run_info(args: &InfoArgs) -> Result<()> {
    let table = MerlTable::read(&args.file)?;
    emit(&info_report(&args.file, &table))
}

/// Writes to stdout. A closed pipe (`nbrdf list-materials | head`) just ends the output; the
/// print macros would panic there.
fn emit(text: &str) -> Result<()> {
    let mut stdout = std::io::stdout().lock();
    match stdout
        .write_all(text.as_bytes())
        .and_then(|()| stdout.flush())
    {
        Err(e) if e.kind() != std::io::ErrorKind::BrokenPipe => Err(NbrdfError::io("<stdout>", e)),
        _ => Ok(()),
    }
}

/// The text `nbrdf info` prints.
fn info_report(path: &Path, table: &MerlTable) -> String {
    let stats = table.stats();
    let mut out = format!(
        "{}: valid MERL table (90 x 90 x 180 cells, {} bytes)\n",
        path.display(),
        merl::FILE_SIZE
    );
    out += &format!(
        "cells: {} valid, {} invalid (not measured) of {}\n",
        stats.valid_cells,
        stats.invalid_cells,
        merl::CELLS
    );
    out += "reflectance over valid cells (1/sr):\n";
    out += &format!(
        "  {:<7}{:>14}{:>14}{:>14}\n",
        "channel", "min", "max", "mean"
    );
    for (c, channel) in ["red", "green", "blue"].iter().enumerate() {
        out += &format!(
            "  {:<7}{:>14.6e}{:>14.6e}{:>14.6e}\n",
            channel, stats.min[c], stats.max[c], stats.mean[c]
        );
    }
    out
}

#[cfg(test)]
mod tests {
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
        assert!(
            Cli::try_parse_from(["nbrdf", "synth", "--model", "ggx", "--material", "x"]).is_err()
        );
        assert!(Cli::try_parse_from(["nbrdf", "info"]).is_err());
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

    #[test]
    fn info_report_lists_channels() {
        let mut stored = vec![1500.0; 3 * merl::CELLS];
        stored[0] = -1.0;
        let table = MerlTable::from_stored(stored).unwrap();
        let report = info_report(Path::new("t.binary"), &table);
        assert!(report.contains("1457999 valid, 1 invalid"), "{report}");
        assert!(
            report.contains("red") && report.contains("1.000000e0"),
            "{report}"
        );
    }
}
