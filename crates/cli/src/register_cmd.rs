//! `augsim register`: an intraoperative point cloud (or a sequence of them) in,
//! the deformed organ and its targets out, with the TRE when the truth is known.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use app::comparison::{run_comparison, LearnedModels};
use app::output::{run_dir, tidy_failed_run, RunWriter};
use app::points::PointInput;
use app::printout::{frame_line, organ_line, rigid_lines, run_lines};
use app::registration::RegistrationChoice;
use mesh::length::LengthUnit;
use register::cloud::read_frames;
use scenario::registration::CaseOverrides;
use scenario::CaseScenario;

use crate::bar::{print_lines, Bar};

/// Arguments of `augsim register`.
#[derive(clap::Args)]
pub struct RegisterArgs {
    /// Intraoperative cloud, positions only (in --units): .csv with a header naming x, y, z;
    /// 3D Slicer's .fcsv or .mrk.json (their own frame and unit); .npy [N, 3]; the points of a
    /// model file, .ply (ASCII or binary), .vtk, .vtp, .vtu, .stl or .obj (in the frame its SPACE=
    /// tag or field names, as Slicer writes it). A directory is a sequence of frames, in file-name
    /// order (any of these but .fcsv and .mrk.json).
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
    /// that holds an earlier run's results is refused (runs are never mixed). Default: a fresh
    /// numbered folder under out/register (out/register/001, 002, …).
    #[arg(short, long)]
    out: Option<PathBuf>,
    /// Built-in comparison case (register_case, which describes it): a phantom
    /// truth pushed down (--force) and seen from above, registered by each of the case's methods
    /// (FEM models on another mesh, the shipped U-Net and reduced-order model, or --model on
    /// --scenario, default liver_ar_t10); prints the comparison. --iterations and --rigid then
    /// hold for every method of the case.
    #[arg(long, group = "comparison", conflicts_with = "patient")]
    demo: bool,
    /// The comparison of --demo on this case scenario (TOML, as register_case).
    #[arg(long, group = "comparison", value_name = "CASE.toml", conflicts_with = "patient")]
    case: Option<PathBuf>,
    /// The force (N) pushing the case's truth (default: the case's).
    #[arg(long, requires = "comparison")]
    force: Option<f64>,
    /// The case as a press and release of this many frames (the force rising to the case's and
    /// falling back), registered as a stream: each frame warm-started from the previous one.
    #[arg(long, requires = "comparison")]
    frames: Option<usize>,
    /// Misaligns the case's camera frame: rotation (degrees) about the case's axis...
    #[arg(long, requires = "comparison", allow_negative_numbers = true)]
    misalign_deg: Option<f64>,
    /// ... and translation (mm) along its direction (try with and without --rigid).
    #[arg(long, requires = "comparison", allow_negative_numbers = true)]
    misalign_mm: Option<f64>,
}

/// Where runs go when --out is not given, each in a numbered folder of its own.
const RUNS: &str = "out/register";

/// Runs the registration (or the comparison) and writes the outputs into a folder of the run's
/// own; a folder the run made is removed again when the run fails before writing into it.
pub fn run(args: &RegisterArgs) -> Result<()> {
    let (out, own) = run_dir(args.out.as_deref(), Path::new(RUNS))?;
    let result = if args.demo || args.case.is_some() { demo(args, &out) } else { register(args, &out) };
    tidy_failed_run(&out, own, result)
}

/// Registers the cloud (or sequence) of the command line into `out`.
fn register(args: &RegisterArgs, out: &Path) -> Result<()> {
    let cloud_path = args.cloud.clone().context("a cloud is required")?;
    let spec = args.registration.spec()?;
    let mut registration = spec.build()?;
    let organ_frame = registration.frame();
    let mut input =
        PointInput::new(organ_frame, LengthUnit::Metre, spec.given_units).with_given_frame(spec.given_frame);
    let frames = read_frames(&cloud_path)?;
    let labels = registration.target_labels();
    let truths = args.truth.as_ref().map(|p| input.read_truths(p, frames.len(), labels)).transpose()?;
    println!("method     {}", registration.method());
    println!("{}", organ_line(registration.organ(), registration.targets().len()));
    for w in registration.warnings() {
        eprintln!("warning    {w}");
    }
    let sequence = frames.len() > 1;
    let mut writer = RunWriter::new(out, sequence, spec.given_units, (organ_frame, spec.given_frame))?;
    let mut last_cloud = Vec::new();
    let clouds = frames.iter().map(|f| input.read_cloud(f).inspect(|c| last_cloud.clone_from(c)));
    let mut printed_pose = None;
    let outcomes = registration.register_sequence(clouds, truths.as_deref(), |i, organ, o| {
        if let Some(rigid) = o.rigid.as_ref().filter(|r| printed_pose != Some(r.cloud_to_organ)) {
            print_lines(&rigid_lines(rigid, None));
            printed_pose = Some(rigid.cloud_to_organ);
        }
        let row = writer.frame(i, frames[i].display().to_string(), organ, o).map_err(to_register_error)?;
        println!("{}", frame_line(i, row));
        for w in &row.warnings {
            eprintln!("warning    frame {i}: {w}");
        }
        Ok(())
    })?;
    for w in &input.warnings {
        eprintln!("warning    {w}");
    }
    let last_truth = truths.as_ref().and_then(|t| t.last()).map(Vec::as_slice);
    let finished = writer.finish(&registration, input.frame, &outcomes, (&last_cloud, last_truth))?;
    print_lines(&run_lines(&outcomes, &finished.summary, spec.given_units));
    for note in &finished.notes {
        eprintln!("warning    {note}");
    }
    println!(
        "wrote      {} ({}, targets.csv, summary.json, registration.png and .html; for 3D Slicer: {})",
        out.display(),
        if sequence { "organ.pvd" } else { "organ.vtu" },
        finished.for_slicer.join(", ")
    );
    Ok(())
}

/// A writer's error as the registration loop's (its callback returns the loop's error type).
fn to_register_error(e: anyhow::Error) -> register::RegisterError {
    register::RegisterError::Invalid(format!("{e:#}"))
}

/// The comparison case of `--demo` (the built-in scenario) or `--case FILE`, with the command
/// line's overrides.
fn comparison_case(args: &RegisterArgs) -> Result<CaseScenario> {
    let overrides = CaseOverrides {
        force: args.force,
        frames: args.frames,
        misalign_deg: args.misalign_deg,
        misalign_mm: args.misalign_mm,
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
    println!();
    let peak = if args.frames.is_some_and(|n| n > 1) { ", of the peak frame" } else { "" };
    println!(
        "wrote      {} (comparison.csv, summary.json; per method{peak}: organ.vtu, targets.csv, registration.png and .html)",
        out.display()
    );
    Ok(())
}
