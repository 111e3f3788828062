//! `augsim register`: an intraoperative point cloud (or a sequence of them) in,
//! the deformed organ and its targets out, with the TRE when the truth is known.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use experiment::case::{ar_scenario, case_methods, compare, synthetic_case, Network, Registered};
use experiment::picture::side_view;
use experiment::setup::{fem_setup, network_setup, RegistrationSetup};
use mesh::io::{csv_field, write_atomic_bytes, Field};
use mesh::Point;
use register::cloud::{read_frames, read_point_cloud, read_targets, write_csv};
use register::{register_sequence, Organ, RigidOptions, RigidResult, RigidTransform, Summary};
use scenario::registration::{slug, MethodKind, BUILTIN_CASE};
use serde::Serialize;

use crate::solve::ms;
use scenario::{CaseScenario, DatasetScenario};

/// Arguments of `augsim register`.
#[derive(clap::Args)]
pub struct RegisterArgs {
    /// Intraoperative cloud, positions only (m): .csv with a header naming x, y, z; .npy [N, 3];
    /// .ply (ASCII or binary). A directory is a sequence of frames, in file-name order.
    #[arg(required_unless_present = "comparison")]
    cloud: Option<PathBuf>,
    /// FEM registration on this scenario's mesh, material (law, formulation) and fixed nodes.
    #[arg(long, conflicts_with = "model")]
    fem: Option<PathBuf>,
    /// U-Net registration with this model (model.json); the organ comes from --scenario. With
    /// --demo or --case: the network of the comparison (default: models/liver_ar/model.json).
    #[arg(long)]
    model: Option<PathBuf>,
    /// The dataset scenario the model was trained on, for --model (its mesh is the organ, its
    /// observed nodes the network's input); with --demo or --case, default: the shipped
    /// liver_ar_t10.
    #[arg(long)]
    scenario: Option<PathBuf>,
    /// Targets at rest (CSV x,y,z, m); default: the mesh's `markers` and `tumour` regions.
    #[arg(long)]
    targets: Option<PathBuf>,
    /// True deformed positions of the targets (CSV x,y,z, same order, in the cloud's frame), or a
    /// directory of one such file per frame: the TRE is reported.
    #[arg(long)]
    truth: Option<PathBuf>,
    /// Most match-and-deform iterations per frame from rest (default: the library's for --fem, the
    /// built-in case's real-time budget for --model, or the case's and its methods'; given, it holds
    /// for every method of a case).
    #[arg(long)]
    iterations: Option<usize>,
    /// Rigid pre-alignment: trimmed point-to-plane ICP of the cloud to the organ's rest surface
    /// before the deformable iterations (on the first frame of a sequence); targets, organ.vtu and
    /// the TRE are then in the cloud's frame, and summary.json gives the organ → cloud transform.
    #[arg(long)]
    rigid: bool,
    /// Output directory: organ.vtu (organ.pvd for a sequence), targets.csv, summary.json.
    #[arg(short, long, default_value = "out/register")]
    out: PathBuf,
    /// Built-in comparison case (register_case, which describes it): a phantom
    /// truth pushed down (--force) and seen from above, registered by each of the case's methods
    /// (FEM models on another mesh, the shipped U-Net); prints the comparison.
    #[arg(long, group = "comparison")]
    demo: bool,
    /// The comparison of --demo on this case scenario (TOML, as register_case).
    #[arg(long, group = "comparison", value_name = "CASE.toml")]
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

/// One frame's line of summary.json.
#[derive(Serialize)]
struct FrameSummary {
    cloud: String,
    points: usize,
    inliers: usize,
    iterations: usize,
    surface_residual_mm: f64,
    time_ms: f64,
    warnings: Vec<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    tre_mean_mm: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    tre_max_mm: Option<f64>,
}

/// summary.json: the run's figures and each frame's.
#[derive(Serialize)]
struct RunSummary {
    #[serde(flatten)]
    summary: Summary,
    per_frame: Vec<FrameSummary>,
}

/// Runs the registration and writes the outputs.
pub fn run(args: &RegisterArgs) -> Result<()> {
    if args.demo || args.case.is_some() {
        return demo(args);
    }
    let cloud_path = args.cloud.clone().context("a cloud is required")?;
    let setup = if let Some(model) = &args.model {
        network_setup(model, args.scenario.as_deref().context("--model needs --scenario (or --demo)")?)?
    } else if let Some(fem) = &args.fem {
        fem_setup(fem)?
    } else {
        bail!("give --fem SCENARIO or --model MODEL --scenario SCENARIO (or --demo)");
    };
    let options = setup.options_with(args.iterations, args.rigid);
    let RegistrationSetup { organ, mut deformer, method, default_targets, .. } = setup;
    let targets = match &args.targets {
        Some(p) => read_targets(p)?,
        None => default_targets,
    };
    if targets.is_empty() {
        bail!("no targets: give --targets, or a mesh with `markers` or `tumour` regions");
    }
    let frames = read_frames(&cloud_path)?;
    let truths: Option<Vec<Vec<Point>>> = match &args.truth {
        None => None,
        Some(p) => {
            let files = if p.is_dir() { read_frames(p)? } else { vec![p.clone()] };
            if files.len() != frames.len() {
                bail!("{} truth file(s) for {} cloud frame(s)", files.len(), frames.len());
            }
            Some(files.iter().map(|f| read_targets(f)).collect::<Result<Vec<_>, _>>()?)
        }
    };
    println!("method     {method}");
    print_organ(&organ, targets.len());
    std::fs::create_dir_all(&args.out).with_context(|| format!("creating {}", args.out.display()))?;
    let sequence = frames.len() > 1;
    let (mut steps, mut rows) = (Vec::new(), Vec::new());
    let clouds = frames.iter().map(|f| read_point_cloud(f));
    let mut moved_mesh: Option<mesh::Mesh> = None;
    let outcomes =
        register_sequence(&organ, deformer.as_mut(), clouds, &targets, truths.as_deref(), &options, |i, o| {
            if let (Some(rigid), None) = (&o.rigid, &moved_mesh) {
                print_rigid(rigid, None);
                moved_mesh = Some(rigid.organ_to_cloud().move_mesh(organ.mesh()));
            }
            let (r, tre) = (&o.registration, o.tre_mm());
            let row = FrameSummary {
                cloud: frames[i].display().to_string(),
                points: r.points,
                inliers: r.inliers,
                iterations: r.iterations,
                surface_residual_mm: r.surface_residual * 1e3,
                time_ms: ms(r.time),
                warnings: r.warnings.clone(),
                tre_mean_mm: tre.map(|t| t.0),
                tre_max_mm: tre.map(|t| t.1),
            };
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
            let name = if sequence { format!("organ_{i:04}.vtu") } else { "organ.vtu".into() };
            let (m, u) = in_cloud_frame(organ.mesh(), moved_mesh.as_ref(), o.rigid.as_ref(), &r.u);
            mesh::io::write_mesh(args.out.join(&name), &m, &[Field::point("displacement", 3, u)])?;
            steps.push((i as f64, name));
            rows.push(row);
            Ok(())
        })?;
    if sequence {
        mesh::io::write_pvd(args.out.join("organ.pvd"), &steps)?;
    }
    let last = outcomes.last().context("no frame")?;
    write_targets(&args.out.join("targets.csv"), &rest_in_cloud_frame(&targets, last.rigid.as_ref()), &last.targets)?;
    let summary = Summary::new(method, &outcomes)?;
    if let (Some(t), Some(m), Some(r)) = (summary.tre_mean_mm, summary.tre_max_mm, summary.no_deformation_tre_mean_mm) {
        println!("TRE        mean {t:.2} mm, max {m:.2} mm (without deformation: mean {r:.2} mm)");
    }
    let run = RunSummary { summary, per_frame: rows };
    write_atomic_bytes(&args.out.join("summary.json"), serde_json::to_string_pretty(&run)?.as_bytes())?;
    println!(
        "wrote      {} ({}, targets.csv, summary.json)",
        args.out.display(),
        if sequence { "organ.pvd" } else { "organ.vtu" }
    );
    Ok(())
}

/// The organ mesh and a displacement in the cloud's frame: as given without a rigid alignment;
/// with one, the mesh moved by it (`moved`, when already computed) and the displacement rotated.
fn in_cloud_frame<'a>(
    organ: &'a mesh::Mesh,
    moved: Option<&'a mesh::Mesh>,
    rigid: Option<&RigidResult>,
    u: &[f64],
) -> (std::borrow::Cow<'a, mesh::Mesh>, Vec<f64>) {
    match rigid {
        None => (std::borrow::Cow::Borrowed(organ), u.to_vec()),
        Some(r) => {
            let t = r.organ_to_cloud();
            let m = match moved {
                Some(m) => std::borrow::Cow::Borrowed(m),
                None => std::borrow::Cow::Owned(t.move_mesh(organ)),
            };
            (m, t.rotate_field(u))
        }
    }
}

/// Rest targets in the cloud's frame (moved by the rigid alignment, if any).
fn rest_in_cloud_frame(targets: &[Point], rigid: Option<&RigidResult>) -> Vec<Point> {
    match rigid {
        None => targets.to_vec(),
        Some(r) => {
            let t = r.organ_to_cloud();
            targets.iter().map(|&p| t.apply(p)).collect()
        }
    }
}

/// The rigid alignment's line, with its error against `truth` (the true organ → cloud
/// transform) when known.
fn print_rigid(r: &RigidResult, truth: Option<&RigidTransform>) {
    let t = r.organ_to_cloud();
    println!(
        "rigid      ICP: organ -> cloud rotation {:.2} deg, translation {:.2} mm; {} iterations{}, {} of {} points \
         kept, rms {:.2} mm, {:.1} ms",
        t.angle().to_degrees(),
        t.translation_norm() * 1e3,
        r.iterations,
        if r.converged { "" } else { " (not converged)" },
        r.kept,
        r.points,
        r.rms * 1e3,
        ms(r.time)
    );
    if let Some(truth) = truth {
        let (angle, shift) = t.error_to(truth);
        println!(
            "           against the case's true misalignment ({:.2} deg, {:.2} mm): {:.2} deg, {:.2} mm off",
            truth.angle().to_degrees(),
            truth.translation_norm() * 1e3,
            angle.to_degrees(),
            shift * 1e3
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

/// targets.csv: rest and registered position of each target.
fn write_targets(path: &Path, rest: &[Point], registered: &[Point]) -> Result<()> {
    let mut text = String::from("x0,y0,z0,x,y,z\n");
    for (a, b) in rest.iter().zip(registered) {
        text.push_str(&format!("{},{},{},{},{},{}\n", a[0], a[1], a[2], b[0], b[1], b[2]));
    }
    Ok(write_atomic_bytes(path, text.as_bytes())?)
}

/// The shipped network for the built-in phantom (trained by the built-in `liver_ar_t10` scenario).
const DEMO_MODEL: &str = "models/liver_ar/model.json";

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
    if let Some(iterations) = args.iterations {
        // Given on the command line, it holds for every method.
        scenario.registration.iterations = iterations;
        scenario.models.method.iter_mut().for_each(|m| m.iterations = None);
    }
    if args.rigid && scenario.registration.rigid.is_none() {
        scenario.registration.rigid = Some(RigidOptions::default());
    }
    let origin =
        args.case.as_ref().map_or_else(|| format!("{BUILTIN_CASE} (built-in scenario)"), |p| p.display().to_string());
    scenario.validate().map_err(|m| anyhow::anyhow!("{origin} with the command line's settings: {m}"))?;
    Ok(scenario)
}

/// `--demo` and `--case`: simulates the case, registers it with each method and prints the
/// comparison.
fn demo(args: &RegisterArgs) -> Result<()> {
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
        c.noise * 1e3,
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
    let dir = args.out.join("case");
    let peak = case.peak();
    write_csv(&dir.join("cloud.csv"), &peak.cloud)?;
    write_csv(&dir.join("targets_rest.csv"), &case.targets)?;
    write_csv(&dir.join("truth.csv"), &peak.truth)?;
    if case.frames.len() > 1 {
        for (k, frame) in case.frames.iter().enumerate() {
            write_csv(&dir.join("clouds").join(format!("cloud_{k:04}.csv")), &frame.cloud)?;
            write_csv(&dir.join("truths").join(format!("truth_{k:04}.csv")), &frame.truth)?;
        }
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
    let model_path = args.model.clone().unwrap_or_else(|| PathBuf::from(DEMO_MODEL));
    let model = if !wants_network {
        None
    } else if model_path.exists() {
        Some(learn::TrainedModel::load(&model_path)?)
    } else {
        println!(
            "U-Net      skipped: {} not found (run from the repository root, or give --model)",
            model_path.display()
        );
        None
    };
    let (network_scenario, network_dir) = match &args.scenario {
        Some(path) => DatasetScenario::load(path)?,
        None => (ar_scenario(), PathBuf::new()),
    };
    let network = model.as_ref().map(|model| Network { model, scenario: &network_scenario, dir: &network_dir });
    let methods = case_methods(&scenario, network.as_ref())?;
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
    let mut csv =
        String::from("method,tre_mean_mm,tre_max_mm,surface_residual_mm,time_median_ms,time_p95_ms,iterations,error\n");
    let mut row = |name: &str, values: [Option<f64>; 6], error: &str| {
        let [t, m, res, time, p95, it] = values.map(|v| v.map_or("-".to_string(), |v| format!("{v:.2}")));
        if error.is_empty() {
            println!("{name:<width$} {t:>14} {m:>13} {res:>14} {time:>10} {p95:>10} {it:>10}");
        } else {
            println!("{name:<width$} failed: {error}");
        }
        let fields = values.map(|v| v.map_or(String::new(), |v| v.to_string()));
        csv.push_str(&format!("{},{},{}\n", csv_field(name), fields.join(","), csv_field(error)));
    };
    if let Some(first) = registered.first() {
        let (rest, baseline) = (&first.summary, if rigid.is_some() { "rigid only (ICP)" } else { "no deformation" });
        row(baseline, [rest.no_deformation_tre_mean_mm, rest.no_deformation_tre_max_mm, None, None, None, None], "");
    }
    for r in &rows {
        match &r.result {
            Ok(reg) => {
                let s = &reg.summary;
                let values = [
                    s.tre_mean_mm,
                    s.tre_max_mm,
                    Some(s.surface_residual_mm),
                    Some(s.time_median_ms),
                    Some(s.time_p95_ms),
                    Some(s.iterations),
                ];
                row(&r.method, values, "");
            }
            Err(e) => row(&r.method, [None; 6], &e.to_string()),
        }
    }
    for reg in &registered {
        let (s, outcome) = (&reg.summary, reg.peak(&case));
        let method_dir = args.out.join(slug(&s.method));
        std::fs::create_dir_all(&method_dir).with_context(|| format!("creating {}", method_dir.display()))?;
        let u = &outcome.registration.u;
        let (m, u_cloud) = in_cloud_frame(reg.organ.mesh(), None, outcome.rigid.as_ref(), u);
        mesh::io::write_mesh(method_dir.join("organ.vtu"), &m, &[Field::point("displacement", 3, u_cloud)])?;
        let rest_targets = rest_in_cloud_frame(&case.targets, outcome.rigid.as_ref());
        write_targets(&method_dir.join("targets.csv"), &rest_targets, &outcome.targets)?;
        // The picture is drawn in the organ's frame: cloud, targets and truth moved back.
        let back = outcome.rigid.as_ref().map_or_else(RigidTransform::identity, |r| r.cloud_to_organ);
        let to_organ = |points: &[Point]| -> Vec<Point> { points.iter().map(|&p| back.apply(p)).collect() };
        let title = format!("{}: TRE mean {:.2} mm (side view)", s.method, s.tre_mean_mm.unwrap_or(f64::NAN));
        side_view(
            &method_dir.join("registration.png"),
            &title,
            &reg.organ,
            u,
            &to_organ(&peak.cloud),
            &to_organ(&outcome.targets),
            Some(&to_organ(&peak.truth)),
        )?;
    }
    write_atomic_bytes(&args.out.join("comparison.csv"), csv.as_bytes())?;
    let summaries: Vec<serde_json::Value> = rows
        .iter()
        .map(|r| match &r.result {
            Ok(reg) => serde_json::to_value(&reg.summary),
            Err(e) => Ok(serde_json::json!({ "method": r.method, "error": e.to_string() })),
        })
        .collect::<Result<_, _>>()?;
    write_atomic_bytes(&args.out.join("summary.json"), serde_json::to_string_pretty(&summaries)?.as_bytes())?;
    println!();
    println!(
        "wrote      {} (comparison.csv, summary.json; per method: organ.vtu, targets.csv, registration.png)",
        args.out.display()
    );
    Ok(())
}
