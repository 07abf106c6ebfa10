//! The `nbrdf` command-line tool.

use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(name = "nbrdf", version, about = "Neural BRDFs: synthesise, train, fit and compare measured materials")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// List the 100 MERL material names of the embedded SGD and ABC fits.
    ListMaterials,
}

fn main() {
    let cli = Cli::parse();
    match cli.command {
        Command::ListMaterials => {}
    }
}
