//! `augsim register`: an intraoperative point cloud (or a sequence of them) in,
//! the deformed organ and its targets out, with the TRE when the truth is known.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use mesh::io::{write_atomic_bytes, Field};
use mesh::Point;
use register::case::{compare, phantom_push};
use register::cloud::{read_frames, read_point_cloud, read_targets, write_csv};
use register::picture::side_view;
use register::{
    register_sequence, CameraModel, Deformer, FemDeformer, NetworkDeformer, Organ, RegistrationOptions, Summary,
};
use serde::Serialize;

use crate::scenario::{build_mesh, MeshSource, Scenario};
use crate::solve::ms;
use learn::scenario::DatasetScenario;

/// Arguments of `augsim register`.
#[derive(clap::Args)]
pub struct RegisterArgs {
    /// Intraoperative cloud, positions only (m): .csv with a header naming x, y, z; .npy [N, 3];
    /// .ply (ASCII or binary). A directory is a sequence of frames, in file-name order.
    #[arg(required_unless_present = "demo")]
    cloud: Option<PathBuf>,
    /// FEM registration on this scenario's mesh, material (law, formulation) and fixed nodes.
    #[arg(long, conflicts_with = "model")]
    fem: Option<PathBuf>,
    /// U-Net registration with this model (model.json); the organ comes from --scenario. With
    /// --demo: the network of the comparison (default: models/liver_ar/model.json).
    #[arg(long)]
    model: Option<PathBuf>,
    /// The dataset scenario the model was trained on, for --model (its mesh is the organ, its
    /// observed nodes the network's input).
    #[arg(long)]
    scenario: Option<PathBuf>,
    /// Targets at rest (CSV x,y,z, m); default: the mesh's `markers` and `tumour` regions.
    #[arg(long)]
    targets: Option<PathBuf>,
    /// True deformed positions of the targets (CSV x,y,z, same order): the TRE is reported.
    #[arg(long)]
    truth: Option<PathBuf>,
    /// Most match-and-deform iterations per frame.
    #[arg(long, default_value_t = RegistrationOptions::default().iterations)]
    iterations: usize,
    /// Output directory: organ.vtu (organ.pvd for a sequence), targets.csv, summary.json.
    #[arg(short, long, default_value = "out/register")]
    out: PathBuf,
    /// Built-in demo: a Neo-Hookean phantom of 9,000 tetrahedra pushed down (--force), seen from
    /// above (1,500 points, 1 mm noise, 5 % outliers), registered with a co-rotational FEM, an
    /// SVK FEM (both on another mesh of 3,000) and the shipped U-Net; prints the comparison.
    #[arg(long)]
    demo: bool,
    /// The force (N) pushing the demo's truth down.
    #[arg(long, default_value_t = 1.5, requires = "demo")]
    force: f64,
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

/// The organ, its deformer and default targets.
struct Setup {
    organ: Organ,
    deformer: Box<dyn Deformer>,
    method: String,
    default_targets: Vec<Point>,
}

/// Runs the registration and writes the outputs.
pub fn run(args: &RegisterArgs) -> Result<()> {
    if args.demo {
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
    let Setup { organ, mut deformer, method, default_targets } = setup;
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
    let options = RegistrationOptions { iterations: args.iterations, ..Default::default() };
    println!("method     {method}");
    print_organ(&organ, targets.len());
    std::fs::create_dir_all(&args.out).with_context(|| format!("creating {}", args.out.display()))?;
    let sequence = frames.len() > 1;
    let (mut steps, mut rows) = (Vec::new(), Vec::new());
    let clouds = frames.iter().map(|f| read_point_cloud(f));
    let outcomes =
        register_sequence(&organ, deformer.as_mut(), clouds, &targets, truths.as_deref(), &options, |i, o| {
            let (r, tre) = (&o.registration, o.tre_mm());
            let row = FrameSummary {
                cloud: frames[i].display().to_string(),
                points: r.points,
                inliers: r.inliers,
                iterations: r.iterations,
                surface_residual_mm: r.surface_residual * 1e3,
                time_ms: ms(r.time),
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
            let name = if sequence { format!("organ_{i:04}.vtu") } else { "organ.vtu".into() };
            mesh::io::write_mesh(args.out.join(&name), organ.mesh(), &[Field::point("displacement", 3, r.u.clone())])?;
            steps.push((i as f64, name));
            rows.push(row);
            Ok(())
        })?;
    if sequence {
        mesh::io::write_pvd(args.out.join("organ.pvd"), &steps)?;
    }
    let last = outcomes.last().context("no frame")?;
    write_targets(&args.out.join("targets.csv"), &targets, &last.targets)?;
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

/// A file name for a method: its lowercase letters and digits, other runs as one `_`.
fn slug(name: &str) -> String {
    let lower = name.to_ascii_lowercase();
    let words: Vec<&str> = lower.split(|c: char| !c.is_ascii_alphanumeric()).filter(|w| !w.is_empty()).collect();
    words.join("_")
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

/// Rest positions of the nodes of the `markers` and `tumour` regions, when the mesh has them.
fn region_targets(m: &mesh::Mesh) -> Vec<Point> {
    ["markers", "tumour"].iter().filter_map(|r| m.region(r).ok()).flatten().map(|&n| m.nodes[n]).collect()
}

/// The organ of a mesh source: its mesh, with the phantom's smooth surface when the mesh is the
/// phantom's immersed grid (the camera sees the organ, not the grid's staircase).
fn organ_of(source: &MeshSource, mesh: mesh::Mesh) -> Result<Organ> {
    let surface = match source {
        MeshSource::PhantomGrid { .. } => Some(mesh::boundary_surface(&mesh::phantom::liver_phantom(5000)?)),
        _ => None,
    };
    Ok(Organ::new(mesh, surface)?)
}

fn fem_setup(path: &Path) -> Result<Setup> {
    let (scenario, dir) = Scenario::load(path)?;
    let mesh = build_mesh(&scenario.mesh, &dir).context("building the mesh")?;
    let problem = scenario.build_problem(mesh.clone())?;
    let organ = organ_of(&scenario.mesh, mesh)?;
    let default_targets = region_targets(&problem.mesh);
    let method = format!("FEM, {:?} ({:?} elements)", problem.material.law, problem.material.resolved_formulation());
    let stiffness = FemDeformer::default_stiffness(&problem);
    let deformer = Box::new(FemDeformer::new(problem, stiffness, scenario.solver.clone())?);
    Ok(Setup { organ, deformer, method, default_targets })
}

fn network_setup(model_path: &Path, scenario_path: &Path) -> Result<Setup> {
    let text = std::fs::read_to_string(scenario_path)
        .with_context(|| format!("cannot read scenario {}", scenario_path.display()))?;
    let scenario: DatasetScenario =
        toml::from_str(&text).with_context(|| format!("invalid dataset scenario {}", scenario_path.display()))?;
    let dir = scenario_path.parent().map(Path::to_path_buf).unwrap_or_default();
    let mesh = build_mesh(&scenario.mesh, &dir).context("building the mesh")?;
    let (inputs, normal) = match &scenario.dataset.input {
        learn::generate::Input::Displacement { nodes, normal, .. } => (nodes.select(&mesh)?, *normal),
        learn::generate::Input::Force => {
            bail!("{}: the model must take displacements as input, not forces", scenario_path.display())
        }
    };
    let default_targets = region_targets(&mesh);
    let organ = organ_of(&scenario.mesh, mesh)?;
    let model = learn::TrainedModel::load(model_path, &learn::inference_device())?;
    let deformer = Box::new(NetworkDeformer::new(&model, &organ, &inputs, normal)?);
    Ok(Setup { organ, deformer, method: format!("U-Net {}", model_path.display()), default_targets })
}

/// The shipped network for the built-in phantom (trained by `scenarios/liver_ar.toml`).
const DEMO_MODEL: &str = "models/liver_ar/model.json";

/// `--demo`: simulates the case, registers it with each method and prints the comparison.
fn demo(args: &RegisterArgs) -> Result<()> {
    let camera = CameraModel { view: [0.0, 0.0, -1.0], points: 1500, noise: 1e-3, outliers: 0.05 };
    println!(
        "demo       truth: Neo-Hookean phantom (nu = 0.48) of about {} T4, its push patch pressed down by {} N;",
        register::case::TRUTH_TETS,
        args.force
    );
    println!(
        "           camera along {:?}: {} points on the visible surface, {} mm noise, {} % outliers",
        camera.view,
        camera.points,
        camera.noise * 1e3,
        camera.outliers * 1e2
    );
    let case = phantom_push(args.force, &camera, 1)?;
    let dir = args.out.join("case");
    write_csv(&dir.join("cloud.csv"), &case.cloud)?;
    write_csv(&dir.join("targets_rest.csv"), &case.targets)?;
    write_csv(&dir.join("truth.csv"), &case.truth)?;
    println!("case       {} (cloud.csv, targets_rest.csv, truth.csv)", dir.display());

    let model_path = args.model.clone().unwrap_or_else(|| PathBuf::from(DEMO_MODEL));
    let network = if model_path.exists() {
        Some(learn::TrainedModel::load(&model_path, &learn::inference_device())?)
    } else {
        println!(
            "U-Net      skipped: {} not found (run from the repository root, or give --model)",
            model_path.display()
        );
        None
    };
    let methods = register::case::methods(network.as_ref())?;
    let options = RegistrationOptions { iterations: args.iterations, ..Default::default() };
    let rows = compare(&case, methods, &options)?;
    let rest = &rows.first().context("no method to compare")?.summary;
    println!();
    println!(
        "{:<28} {:>14} {:>13} {:>14} {:>10} {:>10}",
        "method", "TRE mean (mm)", "TRE max (mm)", "residual (mm)", "ms/frame", "iterations"
    );
    let mut csv = String::from("method,tre_mean_mm,tre_max_mm,surface_residual_mm,time_ms,iterations\n");
    let mut row = |name: &str, values: [Option<f64>; 5]| {
        let [t, m, res, time, it] = values.map(|v| v.map_or("-".to_string(), |v| format!("{v:.2}")));
        println!("{name:<28} {t:>14} {m:>13} {res:>14} {time:>10} {it:>10}");
        let fields = values.map(|v| v.map_or(String::new(), |v| v.to_string()));
        csv.push_str(&format!("{name},{}\n", fields.join(",")));
    };
    row("no deformation", [rest.no_deformation_tre_mean_mm, rest.no_deformation_tre_max_mm, None, None, None]);
    for r in &rows {
        let s = &r.summary;
        let values = [s.tre_mean_mm, s.tre_max_mm, Some(s.surface_residual_mm), Some(s.time_ms), Some(s.iterations)];
        row(&s.method, values);
    }
    for row in &rows {
        let (s, outcome) = (&row.summary, &row.outcome);
        let slug = slug(&s.method);
        let method_dir = args.out.join(slug);
        std::fs::create_dir_all(&method_dir).with_context(|| format!("creating {}", method_dir.display()))?;
        let fields = [Field::point("displacement", 3, outcome.registration.u.clone())];
        mesh::io::write_mesh(method_dir.join("organ.vtu"), row.organ.mesh(), &fields)?;
        write_targets(&method_dir.join("targets.csv"), &case.targets, &outcome.targets)?;
        let title = format!("{}: TRE mean {:.2} mm (side view)", s.method, s.tre_mean_mm.unwrap_or(f64::NAN));
        let u = &outcome.registration.u;
        side_view(
            &method_dir.join("registration.png"),
            &title,
            &row.organ,
            u,
            &case.cloud,
            &outcome.targets,
            Some(&case.truth),
        )?;
    }
    write_atomic_bytes(&args.out.join("comparison.csv"), csv.as_bytes())?;
    let summaries: Vec<&Summary> = rows.iter().map(|r| &r.summary).collect();
    write_atomic_bytes(&args.out.join("summary.json"), serde_json::to_string_pretty(&summaries)?.as_bytes())?;
    println!();
    println!(
        "wrote      {} (comparison.csv, summary.json; per method: organ.vtu, targets.csv, registration.png)",
        args.out.display()
    );
    Ok(())
}
