//! `augsim`: data-driven simulation for augmented surgery.

mod bench;
mod mesh_cmd;
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
    /// Mesh a closed surface (or the built-in liver phantom) with tetrahedra or an immersed hex grid.
    Mesh {
        /// Closed surface (.obj, .stl, .vtk, .vtu); the liver phantom when omitted.
        surface: Option<PathBuf>,
        /// Centre the surface and scale its largest extent to this length (m).
        #[arg(long)]
        length: Option<f64>,
        /// Target number of tetrahedra.
        #[arg(long, default_value_t = 5000)]
        tets: usize,
        /// Build an immersed-boundary H8 grid with this cell size (m) instead.
        #[arg(long)]
        immersed: Option<f64>,
        /// Output file (.vtu, .vtk or .msh).
        #[arg(short, long, default_value = "out/mesh.vtu")]
        output: PathBuf,
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
        Command::Mesh { surface, length, tets, immersed, output } => {
            mesh_cmd::run(&mesh_cmd::MeshArgs { surface, length, tets, immersed, output })
        }
        Command::Bench { runs } => bench::run(runs),
    };
    if let Err(e) = result {
        eprintln!("error: {e:#}");
        std::process::exit(1);
    }
}
