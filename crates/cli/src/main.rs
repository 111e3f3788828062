//! `augsim`: data-driven simulation for augmented surgery.

mod assimilate;
mod bar;
mod bench;
mod experiment_cmd;
mod learn_cmd;
mod mesh_cmd;
mod prepare_cmd;
mod register_cmd;
mod serve_cmd;
mod signals;
mod solve;

use std::path::PathBuf;

use anyhow::Result;
use clap::{CommandFactory, FromArgMatches, Parser, Subcommand};
use mesh::length::Length;

/// Finite elements, Kalman filtering and U-Net learning for soft organs.
#[derive(Parser)]
#[command(name = "augsim", version = experiment::VERSION, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Static solve of a scenario file; writes displacement, reaction forces, strain and stress as VTK.
    Solve {
        /// Static scenario: a TOML file, or the name of a built-in one (e.g. beam).
        scenario: PathBuf,
        /// Output file (.vtu or .vtk); default `out/<name>.vtu`.
        #[arg(short, long, value_parser = extension_of(&app::solve::SOLVE_FILE_EXTENSIONS))]
        output: Option<PathBuf>,
    },
    /// Mesh a closed surface (or the built-in liver phantom) with tetrahedra or an immersed hex grid.
    Mesh {
        /// Organ surface (.obj, .stl, .ply, .vtk, .vtp, .vtu), repaired first unless --no-repair (through voxels
        /// when local repair cannot mend it), or a segmentation's labelmap (.nii, .nii.gz, .nrrd,
        /// .seg.nrrd, .nhdr, .mha, .mhd, a DICOM SEG or RTSTRUCT; in mm, the scanner's frame kept); the liver phantom when omitted.
        surface: Option<PathBuf>,
        /// The labelmap's label: a number (e.g. 5, TotalSegmentator's liver) or a segment name
        /// (3D Slicer's, a DICOM's, a NIfTI label table's); needed when the file holds
        /// several. `1+2` takes labels 1 and 2 together
        /// (a liver and the tumour labelled apart in it).
        #[arg(long, requires = "surface")]
        label: Option<String>,
        /// Centre the surface and scale its largest extent to this length, with its unit (20cm);
        /// overrides --units.
        #[arg(long, requires = "surface")]
        length: Option<Length>,
        /// Length unit of the surface's coordinates: mm, cm, m, um, or auto (told from the organ's size,
        /// 2 to 60 cm across; a labelmap's is the one its header names, else mm); the surface is
        /// scaled to metres about the origin, keeping its (e.g. CT scanner's) frame.
        #[arg(long, default_value = "auto", value_parser = mesh::length::parse_unit_or_auto)]
        units: mesh::length::UnitOrAuto,
        /// Mesh the surface as it is, without repairing holes, duplicated vertices or flipped
        /// triangles (it must then be a closed 2-manifold).
        #[arg(long, requires = "surface")]
        no_repair: bool,
        /// Target number of tetrahedra.
        #[arg(long, default_value_t = 5000)]
        tets: usize,
        /// Build an immersed-boundary H8 grid with this cell size, with its unit (5mm), instead.
        #[arg(long, value_name = "CELL")]
        immersed: Option<Length>,
        /// Output file (.vtu, .vtk or .msh, in m; .stl or .obj: the mesh's boundary surface in mm,
        /// naming the input's frame, as 3D Slicer reads it).
        #[arg(short, long, default_value = "out/mesh.vtu", value_parser = extension_of(&app::meshing::MESH_FILE_EXTENSIONS))]
        output: PathBuf,
    },
    /// ROUKF identification of Young's modulus and/or boundary springs from tracked surface points (synthetic,
    /// or CSV track files); writes traces (CSV, JSON), the estimated deformation (.pvd), assessment errors and
    /// PNG plots.
    Assimilate(app::assimilation::AssimilationChoice),
    /// Generate a FEM dataset (random loads → grid input/target pairs); resumable, splittable; optionally
    /// with draws chosen where a reduced-order model is least sure (--chosen-by).
    Generate(app::generation::GenerateArgs),
    /// Merge dataset parts written with `generate --shard i/n`.
    Merge {
        /// Output directory.
        out: PathBuf,
        /// Part directories.
        #[arg(required = true)]
        parts: Vec<PathBuf>,
    },
    /// Train a U-Net (from scratch or fine-tuning a pre-trained model; resumable), or fit a
    /// reduced-order model (--method rom), on a dataset.
    Train(app::training::TrainArgs),
    /// Evaluate a model on the samples held out from it (the test split recorded in the model, or a
    /// dataset it never saw): mean/std/max Euclidean error, worst sample as VTK.
    Eval {
        /// The model: its directory (a U-Net's or a reduced-order model's) or its model.json.
        model: PathBuf,
        /// Dataset directory.
        dataset: PathBuf,
        /// Output directory (errors.csv, summary.json, worst.vtu), refused when it holds an earlier
        /// run's results; default a fresh numbered folder under `out/eval` (`001`, `002`, …).
        #[arg(short, long)]
        out: Option<PathBuf>,
        /// Project the model's predictions on the basis of this reduced-order model (its directory)
        /// of the same grid, whose basis spans the dataset's deformations.
        #[arg(long)]
        project: Option<PathBuf>,
        /// Input corruption.
        #[command(flatten)]
        corruption: app::training::CorruptionArgs,
        /// Where the network runs.
        #[command(flatten)]
        device: app::training::DeviceArgs,
    },
    /// Predict the displacement for a constraint tensor or a point cloud and time the network.
    Predict {
        /// The model: its directory (a U-Net's or a reduced-order model's) or its model.json.
        model: PathBuf,
        /// Input: a grid tensor (.npy [3, nx, ny, nz]) or a point cloud (.csv or .npy [N, 6]: x, y, z
        /// and the force (N) or displacement (m) at each point, as the model was trained; in mm where
        /// a CSV header names them so: x_mm, y_mm, z_mm, and ux_mm, uy_mm, uz_mm).
        input: PathBuf,
        /// Output tensor (.npy [3, nx, ny, nz], m); a model that predicts its standard deviation
        /// (a reduced-order model) writes it beside, as NAME_sigma.npy ([nx, ny, nz], m), and on
        /// --mesh as the point field sigma.
        #[arg(short, long, default_value = "out/prediction.npy", value_parser = extension_of(&["npy"]))]
        output: PathBuf,
        /// Also interpolate the displacement to this volume mesh's nodes (same frame as the
        /// training mesh) and write it beside the output as .vtu.
        #[arg(long)]
        mesh: Option<PathBuf>,
        /// Timed runs after warm-up.
        #[arg(long, default_value_t = 50, value_parser = app::values::count)]
        runs: usize,
        /// Where the network runs.
        #[command(flatten)]
        device: app::training::DeviceArgs,
    },
    /// A patient's organ from its segmented surface to a registration set-up: repaired surface,
    /// mesh, regions (what the camera sees, where the organ is held), scenario files, FEM
    /// dataset, trained model, its test error and a report; resumable. Register and serve it with
    /// `--patient DIR`.
    Prepare(app::prepare::PrepareArgs),
    /// Register the organ to an intraoperative point cloud (no correspondences): deformed organ,
    /// registered targets and, given the truth, the target registration error.
    Register(register_cmd::RegisterArgs),
    /// Registration on a stream for navigation systems: an OpenIGTLink server that registers each
    /// point cloud it receives and answers with the registered targets, organ and status.
    Serve(app::serving::ServeArgs),
    /// A self-contained HTML 3D viewer (opens in a browser, no network): a dataset sample on the organ (rest,
    /// FEM reference, the model's prediction, coloured by its error, markers) or a file: a mesh's
    /// displacements, a surface, a sequence (.pvd).
    View(app::sample_view::ViewArgs),
    /// Run a published experiment end to end (generate, train, identify, register, evaluate) and write
    /// result.json, PNG figures and the report (report.md, report.html) beside the published figures.
    Experiment(experiment_cmd::ExperimentArgs),
    /// Benchmarks of the static solver (median times, split by phase), of the U-Net's prediction and
    /// of registration frames (every method, beside the co-rotational FEM).
    Bench {
        /// Repetitions per case.
        #[arg(short, long, default_value_t = 20, value_parser = app::values::count)]
        runs: usize,
        /// The tables to run: solves, prediction, registration (default: all of them).
        #[arg(value_parser = |name: &str| name.parse::<experiment::bench::Table>())]
        tables: Vec<experiment::bench::Table>,
    },
}

/// A parser of paths with one of the `allowed` extensions (lower case), refusing others before
/// any work is done.
fn extension_of(allowed: &'static [&'static str]) -> impl Fn(&str) -> Result<PathBuf, String> + Clone {
    move |text: &str| {
        let path = PathBuf::from(text);
        let extension = mesh::io::extension(&path);
        match allowed.contains(&extension.as_str()) {
            true => Ok(path),
            false => Err(format!("expected a file ending in .{}", allowed.join(", ."))),
        }
    }
}

/// The command line, a negative number read as an option's value (`--gate -1`), so that the
/// option's own check says what is wrong with it rather than "unexpected argument '-1'".
fn command_line() -> clap::Command {
    fn negative_numbers_as_values(command: clap::Command) -> clap::Command {
        command
            .mut_args(|a| if a.get_action().takes_values() { a.allow_negative_numbers(true) } else { a })
            .mut_subcommands(negative_numbers_as_values)
    }
    negative_numbers_as_values(Cli::command())
}

fn main() {
    // Output piped into a program that stops reading (e.g. `| head`) ends the process quietly, as
    // for other command-line tools, instead of a panic on the failed write.
    #[cfg(unix)]
    // SAFETY: restoring the default disposition of SIGPIPE before any thread starts.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    let cli = Cli::from_arg_matches(&command_line().get_matches()).unwrap_or_else(|e| e.exit());
    let result: Result<()> = match cli.command {
        Command::Solve { scenario, output } => solve::run(&scenario, output.as_deref()),
        Command::Register(args) => register_cmd::run(&args),
        Command::Prepare(args) => prepare_cmd::run(&args),
        Command::Serve(args) => serve_cmd::run(&args),
        Command::View(args) => app::sample_view::view(&args).map(|lines| bar::print_lines(&lines)),
        Command::Mesh { surface, label, length, units, no_repair, tets, immersed, output } => {
            let repair = !no_repair;
            mesh_cmd::run(&app::meshing::MeshOptions { surface, label, length, units, repair, tets, immersed }, &output)
        }
        Command::Assimilate(args) => assimilate::run(&args),
        Command::Generate(args) => learn_cmd::generate(&args),
        Command::Merge { out, parts } => app::generation::merge(&out, &parts).map(|line| println!("{line}")),
        Command::Train(args) => learn_cmd::train(&args),
        Command::Eval { model, dataset, out, project, corruption, device } => {
            learn_cmd::eval(&model, &dataset, project.as_deref(), &corruption, device, out.as_deref())
        }
        Command::Predict { model, input, output, mesh, runs, device } => {
            learn_cmd::predict(&model, &input, &output, mesh.as_deref(), runs, device)
        }
        Command::Experiment(args) => experiment_cmd::run(&args),
        Command::Bench { runs, tables } => bench::run(runs, &tables),
    };
    if let Err(e) = result {
        eprintln!("error: {e:#}");
        std::process::exit(1);
    }
}
