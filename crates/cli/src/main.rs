//! `augsim`: data-driven simulation for augmented surgery.

mod bench;
mod scenario;
mod solve;

use std::path::PathBuf;

use anyhow::Result;
use clap::{Parser, Subcommand};

/// Finite elements, Kalman filtering and U-Net learning for soft organs.
#[derive(Parser)]
#[command(name = "augsim", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Static solve of a scenario file; writes displacement, strain and stress as VTK.
    Solve {
        /// Scenario TOML file (e.g. scenarios/beam.toml).
        scenario: PathBuf,
        /// Output file (.vtu or .vtk); default out/<name>.vtu.
        #[arg(short, long)]
        output: Option<PathBuf>,
    },
    /// Benchmarks of the static solver (median times, split by phase).
    Bench {
        /// Repetitions per case.
        #[arg(short, long, default_value_t = 20)]
        runs: usize,
    },
}

fn main() {
    let cli = Cli::parse();
    let result: Result<()> = match cli.command {
        Command::Solve { scenario, output } => solve::run(&scenario, output.as_deref()),
        Command::Bench { runs } => bench::run(runs),
    };
    if let Err(e) = result {
        eprintln!("error: {e:#}");
        std::process::exit(1);
    }
}
