//! `augsim register`: an intraoperative point cloud (or a sequence of them) in,
//! the deformed organ and its targets out, with the TRE when the truth is known.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use app::comparison::{run_comparison, LearnedModels};
use app::output::{in_run_dir, register_files, REGISTER_RUNS};
use app::registration::RegistrationChoice;
use mesh::length::Length;
use scenario::registration::CaseOverrides;
use scenario::CaseScenario;

use crate::bar::{print_line, Bar};

/// Arguments of `augsim register`.
#[derive(clap::Args)]
pub struct RegisterArgs {
    /// Intraoperative cloud, positions only (in --units): .csv with a header naming x, y, z;
    /// 3D Slicer's .fcsv or .mrk.json (their own frame and unit); .npy [N, 3]; the points of a
    /// model file, .ply (ASCII or binary), .vtk, .vtp, .vtu, .stl or .obj (in the frame its SPACE=
    /// tag or field names, as Slicer writes it). A directory is a sequence of frames, in file-name
    /// order.
    #[arg(required_unless_present = "comparison")]
    cloud: Option<PathBuf>,
    #[command(flatten)]
    registration: RegistrationChoice,
    /// True deformed positions of the targets (CSV x,y,z in --units, .fcsv or .mrk.json; by
    /// label where both files label every point, else in the same order), or a directory of one
    /// such file per frame: the TRE is reported.
    #[arg(long)]
    truth: Option<PathBuf>,
    /// Output directory: organ.vtu (organ.pvd for a sequence), targets.csv (a sequence's last
    /// frame), summary.json (every frame's TRE); one
    /// that holds anything (an earlier run's results, other files) is refused (runs are never
    /// mixed, a user's files never replaced). Default: a fresh
    /// numbered folder under out/register (out/register/001, 002, …).
    #[arg(short, long)]
    out: Option<PathBuf>,
    /// Built-in comparison case (register_case, which describes it): a phantom
    /// truth pushed down (--force) and seen from above, registered by each of the case's methods
    /// (FEM models on another mesh, the shipped U-Net and reduced-order model, or --model on
    /// --scenario, default liver_ar_t10); prints the comparison. --iterations and --rigid then
    /// hold for every method of the case.
    #[arg(long, group = "comparison", conflicts_with_all = NOT_IN_A_COMPARISON)]
    demo: bool,
    /// The comparison of --demo on this case scenario (TOML, as register_case).
    #[arg(long, group = "comparison", value_name = "CASE.toml", conflicts_with_all = NOT_IN_A_COMPARISON)]
    case: Option<PathBuf>,
    /// The force (N) pushing the case's truth (default: the case's).
    #[arg(long, requires = "comparison")]
    force: Option<f64>,
    /// The case as a press and release of this many frames (the force rising to the case's and
    /// falling back), registered as a stream: each frame warm-started from the previous one.
    #[arg(long, requires = "comparison", value_parser = clap::builder::RangedU64ValueParser::<usize>::new()
        .range(1..=scenario::registration::MAX_FRAMES as u64))]
    frames: Option<usize>,
    /// Misaligns the case's camera frame: rotation (degrees) about the case's axis...
    #[arg(long, requires = "comparison")]
    misalign_deg: Option<f64>,
    /// ... and translation along its direction, with its unit (10mm; try with and without --rigid).
    #[arg(long, requires = "comparison", allow_hyphen_values = true, value_name = "LENGTH")]
    misalign_shift: Option<Length>,
}

/// The registration's arguments a comparison has no use for (its case makes the cloud, the truth,
/// the targets and the methods, in metres and in its own frame): refused beside it, not ignored.
const NOT_IN_A_COMPARISON: [&str; 9] =
    ["cloud", "truth", "patient", "fem", "shape_model", "targets", "units", "frame", "structures"];

/// Runs the registration (or the comparison) into a folder of the run's own.
pub fn run(args: &RegisterArgs) -> Result<()> {
    in_run_dir(args.out.as_deref(), Path::new(REGISTER_RUNS), |out| {
        if args.demo || args.case.is_some() {
            demo(args, out)
        } else {
            register(args, out)
        }
    })
}

/// Registers the cloud (or sequence) of the command line into `out`.
fn register(args: &RegisterArgs, out: &Path) -> Result<()> {
    let cloud = args.cloud.as_deref().context("a cloud is required")?;
    let spec = args.registration.spec()?;
    register_files(&spec, cloud, args.truth.as_deref(), out, &mut print_line)
}

/// The comparison case of `--demo` (the built-in scenario) or `--case FILE`, with the command
/// line's overrides.
fn comparison_case(args: &RegisterArgs) -> Result<CaseScenario> {
    let overrides = CaseOverrides {
        force: args.force,
        frames: args.frames,
        misalign_deg: args.misalign_deg,
        misalign_shift: args.misalign_shift,
        iterations: args.registration.iterations,
        rigid: args.registration.rigid,
    };
    Ok(CaseScenario::with_overrides(args.case.as_deref(), &overrides)?)
}

/// `--demo` and `--case`: simulates the case, registers it with each method and prints the
/// comparison.
fn demo(args: &RegisterArgs, out: &Path) -> Result<()> {
    let scenario = comparison_case(args)?;
    let learned =
        LearnedModels { model: args.registration.model.as_deref(), scenario: args.registration.scenario.as_deref() };
    Bar::during("methods", |bar| run_comparison(&scenario, learned, out, bar))?;
    Ok(())
}
