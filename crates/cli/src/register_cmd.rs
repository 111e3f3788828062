//! `augsim register`: an intraoperative point cloud (or a sequence of them) in,
//! the deformed organ and its targets out, with the TRE when the truth is known.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use app::case::{ar_scenario, case_methods, compare, comparison_models, synthetic_case, Network, Registered};
use app::output::{comparison_rows, run_dir, write_case, write_comparison, RunWriter};
use app::points::PointInput;
use app::registration::RegistrationChoice;
use mesh::length::{mm, LengthUnit};
use mesh::Point;
use register::cloud::read_frames;
use register::{Organ, RigidOptions, RigidResult, RigidTransform};
use scenario::registration::{MethodKind, BUILTIN_CASE};

use crate::solve::ms;
use scenario::{CaseScenario, DatasetScenario};

/// Arguments of `augsim register`.
#[derive(clap::Args)]
pub struct RegisterArgs {
    /// Intraoperative cloud, positions only (in --units): .csv with a header naming x, y, z;
    /// 3D Slicer's .fcsv or .mrk.json (their own frame and unit); .npy [N, 3]; .ply (ASCII or
    /// binary). A directory is a sequence of frames, in file-name order (.csv, .npy, .ply).
    #[arg(required_unless_present = "comparison")]
    cloud: Option<PathBuf>,
    #[command(flatten)]
    registration: RegistrationChoice,
    /// True deformed positions of the targets (CSV x,y,z in --units, .fcsv or .mrk.json; same
    /// order), or a directory of one such file per frame: the TRE is reported.
    #[arg(long)]
    truth: Option<PathBuf>,
    /// Output directory: organ.vtu (organ.pvd for a sequence), targets.csv, summary.json; one
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
/// own; a fresh numbered folder is removed again when the run fails before writing into it.
pub fn run(args: &RegisterArgs) -> Result<()> {
    let (out, fresh) = run_dir(args.out.as_deref(), Path::new(RUNS))?;
    let result = if args.demo || args.case.is_some() { demo(args, &out) } else { register(args, &out) };
    if result.is_err() && fresh {
        // Only an empty folder is removed.
        let _ = std::fs::remove_dir(&out);
    }
    result
}

/// Registers the cloud (or sequence) of the command line into `out`.
fn register(args: &RegisterArgs, out: &Path) -> Result<()> {
    let cloud_path = args.cloud.clone().context("a cloud is required")?;
    let spec = args.registration.spec()?;
    let mut registration = spec.build()?;
    let mut input = PointInput::new(spec.targets.frame()?, LengthUnit::Metre, args.registration.units);
    let frames = read_frames(&cloud_path)?;
    let truths: Option<Vec<Vec<Point>>> = match &args.truth {
        None => None,
        Some(p) => {
            let files = if p.is_dir() { read_frames(p)? } else { vec![p.clone()] };
            if files.len() != frames.len() {
                bail!("{} truth file(s) for {} cloud frame(s)", files.len(), frames.len());
            }
            Some(files.iter().map(|f| Ok(input.read(f)?.points)).collect::<Result<Vec<_>>>()?)
        }
    };
    println!("method     {}", registration.method());
    print_organ(registration.organ(), registration.targets().len());
    for w in registration.warnings() {
        eprintln!("warning    {w}");
    }
    let sequence = frames.len() > 1;
    let mut writer = RunWriter::new(out, sequence)?;
    let clouds = frames.iter().map(|f| input.read_cloud(f));
    let mut rigid_printed = false;
    let outcomes = registration.register_sequence(clouds, truths.as_deref(), |i, organ, o| {
        if let (Some(rigid), false) = (&o.rigid, rigid_printed) {
            print_rigid(rigid, None);
            rigid_printed = true;
        }
        let row = writer.frame(i, frames[i].display().to_string(), organ, o).map_err(to_register_error)?;
        println!(
            "frame {i:<4} {} points ({} matched), {} iterations, surface residual {:.2} mm, {:.1} ms{}",
            row.points,
            row.inliers,
            row.iterations,
            row.surface_residual_mm,
            row.time_ms,
            row.tre_mean_mm.map_or(String::new(), |t| format!(
                ", TRE mean {t:.2} mm, max {:.2} mm",
                row.tre_max_mm.unwrap_or(0.0)
            ))
        );
        for w in &row.warnings {
            eprintln!("warning    frame {i}: {w}");
        }
        Ok(())
    })?;
    let summary = writer.finish(registration.method(), registration.targets(), &spec.target_labels()?, &outcomes)?;
    if let Some(sigma) = outcomes.last().and_then(|o| o.target_std.as_ref()) {
        println!(
            "sigma      predicted at the targets: mean {:.2} mm, max {:.2} mm (targets.csv, column sigma_m)",
            mm(mesh::stats::mean(sigma)),
            mm(mesh::stats::max(sigma))
        );
    }
    if let (Some(t), Some(m), Some(r)) = (summary.tre_mean_mm, summary.tre_max_mm, summary.no_deformation_tre_mean_mm) {
        println!("TRE        mean {t:.2} mm, max {m:.2} mm (without deformation: mean {r:.2} mm)");
    }
    println!(
        "wrote      {} ({}, targets.csv, summary.json)",
        out.display(),
        if sequence { "organ.pvd" } else { "organ.vtu" }
    );
    Ok(())
}

/// A writer's error as the registration loop's (its callback returns the loop's error type).
fn to_register_error(e: anyhow::Error) -> register::RegisterError {
    register::RegisterError::Invalid(format!("{e:#}"))
}

/// The rigid alignment's line, with its error against `truth` (the true organ → cloud
/// transform) when known.
fn print_rigid(r: &RigidResult, truth: Option<&RigidTransform>) {
    let t = r.organ_to_cloud();
    println!(
        "rigid      ICP: organ -> cloud rotation {:.2} deg, translation {:.2} mm; {} iterations{}, {} of {} points \
         kept, rms {:.2} mm, {:.1} ms",
        t.angle().to_degrees(),
        mm(t.translation_norm()),
        r.iterations,
        if r.converged { "" } else { " (not converged)" },
        r.kept,
        r.points,
        mm(r.rms),
        ms(r.time)
    );
    if let Some(truth) = truth {
        let (angle, shift) = t.error_to(truth);
        println!(
            "           against the case's true misalignment ({:.2} deg, {:.2} mm): {:.2} deg, {:.2} mm off",
            truth.angle().to_degrees(),
            mm(truth.translation_norm()),
            angle.to_degrees(),
            mm(shift)
        );
    }
}

fn print_organ(organ: &Organ, targets: usize) {
    println!(
        "organ      {} nodes, {} {} cells; surface of {} triangles; {targets} targets",
        organ.mesh().num_nodes(),
        organ.mesh().cells.len(),
        organ.mesh().cells.kind_name(),
        organ.surface().triangles.len(),
    );
}

/// The comparison case of `--demo` (the built-in scenario) or `--case FILE`, with the command
/// line's overrides.
fn comparison_case(args: &RegisterArgs) -> Result<CaseScenario> {
    let mut scenario = match &args.case {
        Some(path) => CaseScenario::load(path)?,
        None => CaseScenario::builtin(),
    };
    if let Some(force) = args.force {
        scenario.truth.force = force;
    }
    if let Some(frames) = args.frames {
        scenario.truth.frames = frames;
    }
    if let Some(deg) = args.misalign_deg {
        scenario.misalignment.rotation_deg = deg;
    }
    if let Some(mm) = args.misalign_mm {
        scenario.misalignment.translation_mm = mm;
    }
    if let Some(iterations) = args.registration.iterations {
        // Given on the command line, it holds for every method.
        scenario.registration.iterations = iterations;
        scenario.models.method.iter_mut().for_each(|m| m.iterations = None);
    }
    if args.registration.rigid && scenario.registration.rigid.is_none() {
        scenario.registration.rigid = Some(RigidOptions::default());
    }
    let origin =
        args.case.as_ref().map_or_else(|| format!("{BUILTIN_CASE} (built-in scenario)"), |p| p.display().to_string());
    scenario.validate().map_err(|m| anyhow::anyhow!("{origin} with the command line's settings: {m}"))?;
    Ok(scenario)
}

/// `--demo` and `--case`: simulates the case, registers it with each method and prints the
/// comparison.
fn demo(args: &RegisterArgs, out: &Path) -> Result<()> {
    let scenario = comparison_case(args)?;
    let (t, c, m) = (&scenario.truth, &scenario.camera, &scenario.misalignment);
    println!("case       {}: {}", scenario.name, scenario.description);
    println!(
        "truth      {:?} phantom (E = {} kPa, nu = {}) of {}, fixed on `{}`, {} N along {:?} on `{}`",
        t.material.law,
        t.material.young * 1e-3,
        t.material.poisson,
        t.mesh_words(),
        t.fixed,
        t.force,
        t.direction,
        t.load
    );
    println!(
        "camera     along {:?}: {} points on the visible surface, {} mm noise, {} % outliers (seed {})",
        c.view,
        c.points,
        mm(c.noise),
        c.outliers * 1e2,
        c.seed
    );
    if m.rotation_deg != 0.0 || m.translation_mm != 0.0 {
        println!(
            "misaligned camera frame: {} deg about {:?}, then {} mm along {:?}",
            m.rotation_deg, m.axis, m.translation_mm, m.direction
        );
    }
    let case = synthetic_case(&scenario)?;
    let dir = out.join("case");
    write_case(&dir, &case)?;
    if case.frames.len() > 1 {
        let forces: Vec<String> = case.frames.iter().map(|f| format!("{:.2}", f.force)).collect();
        println!(
            "frames     {}: forces {} N, each frame warm-started from the previous one",
            forces.len(),
            forces.join(" ")
        );
        println!(
            "case       {} (cloud.csv, truth.csv: the peak frame; clouds/, truths/: every frame; targets_rest.csv)",
            dir.display()
        );
    } else {
        println!("case       {} (cloud.csv, targets_rest.csv, truth.csv)", dir.display());
    }

    let wants_network =
        scenario.models.method.iter().any(|m| matches!(m.kind, MethodKind::Network | MethodKind::Hybrid));
    let (models, missing) =
        if wants_network { comparison_models(args.registration.model.as_deref())? } else { (Vec::new(), Vec::new()) };
    for path in missing {
        println!("model      skipped: {} not found (run from the repository root, or give --model)", path.display());
    }
    let (network_scenario, network_dir) = match &args.registration.scenario {
        Some(path) => DatasetScenario::load(path)?,
        None => (ar_scenario(), PathBuf::new()),
    };
    let networks: Vec<Network> =
        models.iter().map(|model| Network { model, scenario: &network_scenario, dir: &network_dir }).collect();
    let methods = case_methods(&scenario, &networks)?;
    let rows = compare(&case, methods, &scenario.registration);
    if rows.is_empty() {
        bail!("no method to compare");
    }
    let registered: Vec<&Registered> = rows.iter().filter_map(|r| r.result.as_ref().ok()).collect();
    let rigid = registered.first().and_then(|r| r.outcomes[0].rigid.as_ref());
    if let Some(r) = rigid {
        print_rigid(r, Some(&case.pose));
    }
    // The name column fits the longest method name.
    let width = rows.iter().map(|r| r.method.chars().count()).max().unwrap_or(0).max(28);
    println!();
    println!(
        "{:<width$} {:>14} {:>13} {:>14} {:>10} {:>10} {:>10}",
        "method", "TRE mean (mm)", "TRE max (mm)", "residual (mm)", "ms/frame", "p95 (ms)", "iterations"
    );
    for (name, values, error) in comparison_rows(&rows) {
        let [t, m, res, time, p95, it] = values.map(|v| v.map_or("-".to_string(), |v| format!("{v:.2}")));
        if error.is_empty() {
            println!("{name:<width$} {t:>14} {m:>13} {res:>14} {time:>10} {p95:>10} {it:>10}");
        } else {
            println!("{name:<width$} failed: {error}");
        }
    }
    write_comparison(out, &case, &rows)?;
    println!();
    println!(
        "wrote      {} (comparison.csv, summary.json; per method: organ.vtu, targets.csv, registration.png)",
        out.display()
    );
    Ok(())
}
