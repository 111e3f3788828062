//! `augsim register`: an intraoperative point cloud (or a sequence of them) in,
//! the deformed organ and its targets out, with the TRE when the truth is known.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use mesh::io::Field;
use mesh::Point;
use register::case::{phantom_push, target_errors};
use register::cloud::{read_frames, read_point_cloud, read_targets, write_csv};
use register::organ::displaced;
use register::{register_frame, CameraModel, Deformer, FemDeformer, NetworkDeformer, Organ, RegistrationOptions};
use serde::Serialize;

use crate::learn_cmd::write_atomic;
use crate::learn_cmd::DatasetScenario;
use crate::scenario::{build_mesh, MeshSource, Scenario};
use crate::solve::ms;

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
    /// U-Net registration with this model (model.json); the organ comes from --scenario.
    #[arg(long, requires = "scenario")]
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
    /// above (1,500 points, 1 mm noise, 5 % outliers), registered with a co-rotational FEM on
    /// another mesh of 3,000; the case's files are written to --out first.
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

#[derive(Serialize)]
struct Summary {
    method: String,
    targets: usize,
    #[serde(skip_serializing_if = "Option::is_none")]
    tre_mean_mm: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    tre_max_mm: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    no_deformation_tre_mean_mm: Option<f64>,
    surface_residual_mm: f64,
    time_ms: f64,
    frames: Vec<FrameSummary>,
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
    let (cloud_path, targets_path, truth_path) = if args.demo {
        write_demo_case(&args.out, args.force)?
    } else {
        let cloud = args.cloud.clone().context("a cloud is required")?;
        (cloud, args.targets.clone(), args.truth.clone())
    };
    let setup = if args.demo {
        demo_setup()?
    } else if let Some(model) = &args.model {
        network_setup(model, args.scenario.as_deref().context("--model needs --scenario")?)?
    } else if let Some(fem) = &args.fem {
        fem_setup(fem)?
    } else {
        bail!("give --fem SCENARIO or --model MODEL --scenario SCENARIO (or --demo)");
    };
    let Setup { organ, mut deformer, method, default_targets } = setup;
    let targets = match &targets_path {
        Some(p) => read_targets(p)?,
        None => default_targets,
    };
    if targets.is_empty() {
        bail!("no targets: give --targets, or a mesh with `markers` or `tumour` regions");
    }
    let stencils = organ.locate(&targets, "target")?;
    let frames = read_frames(&cloud_path)?;
    let truths: Option<Vec<Vec<Point>>> = match &truth_path {
        None => None,
        Some(p) => {
            let files = if p.is_dir() { read_frames(p)? } else { vec![p.clone()] };
            if files.len() != frames.len() {
                bail!("{} truth file(s) for {} cloud frame(s)", files.len(), frames.len());
            }
            let t = files.iter().map(|f| read_targets(f)).collect::<Result<Vec<_>, _>>()?;
            if let Some((i, bad)) = t.iter().enumerate().find(|(_, t)| t.len() != targets.len()) {
                bail!("truth of frame {i} has {} points for {} targets", bad.len(), targets.len());
            }
            Some(t)
        }
    };
    let options = RegistrationOptions { iterations: args.iterations, ..Default::default() };
    println!("method     {method}");
    println!(
        "organ      {} nodes, {} {} cells; surface of {} triangles; {} targets",
        organ.mesh().num_nodes(),
        organ.mesh().cells.len(),
        organ.mesh().cells.kind_name(),
        organ.surface().triangles.len(),
        targets.len()
    );
    std::fs::create_dir_all(&args.out).with_context(|| format!("creating {}", args.out.display()))?;
    let sequence = frames.len() > 1;
    let mut u: Option<Vec<f64>> = None;
    let (mut rows, mut steps, mut all_errors, mut rigid_errors) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let mut registered = Vec::new();
    for (i, file) in frames.iter().enumerate() {
        let cloud = read_point_cloud(file)?;
        let frame = register_frame(&organ, deformer.as_mut(), &cloud, u.as_deref(), &options)
            .with_context(|| format!("registering {}", file.display()))?;
        registered = displaced(&targets, &stencils, &frame.u);
        let errors = truths.as_ref().map(|t| target_errors(&registered, &t[i]));
        if let Some(t) = &truths {
            rigid_errors.extend(target_errors(&targets, &t[i]));
        }
        let name = if sequence { format!("organ_{i:04}.vtu") } else { "organ.vtu".into() };
        let fields = [Field::point("displacement", 3, frame.u.clone())];
        mesh::io::write_mesh(args.out.join(&name), organ.mesh(), &fields)?;
        steps.push((i as f64, name));
        let row = FrameSummary {
            cloud: file.display().to_string(),
            points: cloud.len(),
            inliers: frame.inliers,
            iterations: frame.iterations,
            surface_residual_mm: frame.surface_residual * 1e3,
            time_ms: ms(frame.time),
            tre_mean_mm: errors.as_ref().map(|e| mean(e) * 1e3),
            tre_max_mm: errors.as_ref().map(|e| max(e) * 1e3),
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
        all_errors.extend(errors.unwrap_or_default());
        rows.push(row);
        u = Some(frame.u);
    }
    if sequence {
        mesh::io::write_pvd(args.out.join("organ.pvd"), &steps)?;
    }
    write_targets(&args.out.join("targets.csv"), &targets, &registered)?;
    let summary = Summary {
        method,
        targets: targets.len(),
        tre_mean_mm: (!all_errors.is_empty()).then(|| mean(&all_errors) * 1e3),
        tre_max_mm: (!all_errors.is_empty()).then(|| max(&all_errors) * 1e3),
        no_deformation_tre_mean_mm: (!rigid_errors.is_empty()).then(|| mean(&rigid_errors) * 1e3),
        surface_residual_mm: rows.iter().map(|r| r.surface_residual_mm).sum::<f64>() / rows.len() as f64,
        time_ms: rows.iter().map(|r| r.time_ms).sum::<f64>() / rows.len() as f64,
        frames: rows,
    };
    if let (Some(t), Some(m), Some(r)) = (summary.tre_mean_mm, summary.tre_max_mm, summary.no_deformation_tre_mean_mm) {
        println!("TRE        mean {t:.2} mm, max {m:.2} mm (without deformation: mean {r:.2} mm)");
    }
    write_atomic(&args.out.join("summary.json"), serde_json::to_string_pretty(&summary)?.as_bytes())?;
    println!(
        "wrote      {} ({}, targets.csv, summary.json)",
        args.out.display(),
        if sequence { "organ.pvd" } else { "organ.vtu" }
    );
    Ok(())
}

fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len() as f64
}

fn max(v: &[f64]) -> f64 {
    v.iter().copied().fold(0.0, f64::max)
}

/// targets.csv: rest and registered position of each target.
fn write_targets(path: &Path, rest: &[Point], registered: &[Point]) -> Result<()> {
    let mut text = String::from("x0,y0,z0,x,y,z\n");
    for (a, b) in rest.iter().zip(registered) {
        text.push_str(&format!("{},{},{},{},{},{}\n", a[0], a[1], a[2], b[0], b[1], b[2]));
    }
    write_atomic(path, text.as_bytes())
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
    let inputs = match &scenario.dataset.input {
        learn::generate::Input::Displacement { nodes, .. } => nodes.select(&mesh)?,
        learn::generate::Input::Force => {
            bail!("{}: the model must take displacements as input, not forces", scenario_path.display())
        }
    };
    let default_targets = region_targets(&mesh);
    let organ = organ_of(&scenario.mesh, mesh)?;
    let model = learn::TrainedModel::load(model_path, &learn::inference_device())?;
    let deformer = Box::new(NetworkDeformer::new(&model, &organ, &inputs)?);
    Ok(Setup { organ, deformer, method: format!("U-Net {}", model_path.display()), default_targets })
}

/// The demo's registration model ([`register::case::corotational_model`]).
fn demo_setup() -> Result<Setup> {
    let (organ, deformer) = register::case::corotational_model()?;
    let method = format!("FEM, Corotational, phantom of {} T4 (demo)", organ.mesh().cells.len());
    Ok(Setup { organ, deformer: Box::new(deformer), method, default_targets: vec![] })
}

/// Simulates the demo case and writes cloud.csv, targets.csv (rest) and truth.csv into `out/case`.
fn write_demo_case(out: &Path, force: f64) -> Result<(PathBuf, Option<PathBuf>, Option<PathBuf>)> {
    let camera = CameraModel { view: [0.0, 0.0, -1.0], points: 1500, noise: 1e-3, outliers: 0.05 };
    println!(
        "demo       truth: Neo-Hookean phantom of about {} T4 pushed down by {force} N; camera along {:?},",
        register::case::TRUTH_TETS,
        camera.view
    );
    println!(
        "           {} points on the visible surface, {} mm noise, {} % outliers",
        camera.points,
        camera.noise * 1e3,
        camera.outliers * 1e2
    );
    let case = phantom_push(force, &camera, 1)?;
    let dir = out.join("case");
    let (cloud, targets, truth) = (dir.join("cloud.csv"), dir.join("targets_rest.csv"), dir.join("truth.csv"));
    write_csv(&cloud, &case.cloud)?;
    write_csv(&targets, &case.targets)?;
    write_csv(&truth, &case.truth)?;
    println!("case       {}", dir.display());
    Ok((cloud, Some(targets), Some(truth)))
}
