//! `augsim assimilate`: identify Young's modulus and/or boundary spring stiffnesses of a static FEM model with the
//! ROUKF from synthetic tracked surface points.
//!
//! A reference run with the true parameters gives the positions of the observed feature points at every time step;
//! Gaussian noise is added and the filter (one FEM solve per sigma point and step, in parallel, each warm-started
//! from its own previous state) estimates the parameters. Writes the filter trace (CSV, JSON), the assessment
//! errors (CSV), a summary (JSON) and PNG plots into the output directory.
//!
//! The estimated deformation at time step k is the mean of the sigma points' states predicted for step k (before
//! the correction with the measurement of step k); its error at the assessment points is compared with runs where
//! the spring region is fully fixed and fully free.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, ensure, Context, Result};
use fem::{Material, Problem, SolverOptions};
use filter::observation::{add_noise, tracked_positions};
use filter::{
    Execution, FemModel, FemParameter, LoadPattern, Model, ObservationNoise, ParameterSpec, Profile, Roukf,
    RoukfConfig, Trace, TrackedPoint, Transform,
};
use indicatif::{ProgressBar, ProgressStyle};
use mesh::{Mesh, NodeSelection, Point};
use nalgebra::DVector;
use plot::{line_plot, PlotSpec, Series};
use serde::Deserialize;

use crate::scenario::{Fixed, MeshSource};

/// An assimilation scenario file.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AssimilationScenario {
    /// Short name, used for the default output directory.
    pub name: String,
    /// Free text.
    #[serde(default)]
    pub description: String,
    /// Filter iterations = time steps (one observation each).
    pub iterations: usize,
    /// The organ mesh.
    pub mesh: MeshSource,
    /// Material; `young` is the true value of the reference run (and the model's value when not estimated).
    pub material: Material,
    /// Nodes with zero displacement.
    #[serde(default)]
    pub fixed: Vec<Fixed>,
    /// Known forces with a time profile.
    #[serde(default)]
    pub force: Vec<ForceSpec>,
    /// Prescribed displacements (the tool) with a time profile.
    #[serde(default)]
    pub tool: Vec<ToolSpec>,
    /// Estimate Young's modulus.
    pub young: Option<YoungSpec>,
    /// Estimate one spring stiffness per node of a region.
    pub springs: Option<SpringsSpec>,
    /// The tracked feature points and their noise.
    pub observations: ObservationSpec,
    /// Points where the estimated deformation is compared with the reference run.
    pub assessment: Option<AssessmentSpec>,
    /// Filter settings.
    #[serde(default)]
    pub filter: FilterSpec,
    /// Newton-Raphson settings of every solve.
    #[serde(default)]
    pub solver: SolverOptions,
    /// Outputs.
    #[serde(default)]
    pub output: OutputSpec,
}

/// A total force shared equally by the selected nodes, times a profile.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ForceSpec {
    /// Which nodes.
    pub select: NodeSelection,
    /// Total force at amplitude 1 (N).
    pub total: Point,
    /// Amplitude over time.
    pub profile: Profile,
}

/// A prescribed displacement of the selected nodes (optionally only the `count` nearest to `near`), times a profile.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ToolSpec {
    /// Candidate nodes.
    pub select: NodeSelection,
    /// Keep the candidates nearest to this point (m).
    pub near: Option<Point>,
    /// How many to keep with `near` (default 1).
    pub count: Option<usize>,
    /// Displacement at amplitude 1 (m).
    pub displacement: Point,
    /// Amplitude over time.
    pub profile: Profile,
}

/// Prior of Young's modulus (filter space).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct YoungSpec {
    /// Filter-space transform.
    #[serde(default)]
    pub transform: Transform,
    /// Prior mean (filter space; Pa for the identity).
    pub prior_mean: f64,
    /// Prior standard deviation (filter space).
    pub prior_std: f64,
}

/// One unknown spring per selected node: stiffness = `scale` · transform(filter value).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SpringsSpec {
    /// The attached nodes (the hidden region Σ).
    pub select: NodeSelection,
    /// Stiffness (N/m) per unit of the transformed value.
    pub scale: f64,
    /// Filter-space transform (default `abs`: non-negative stiffness).
    #[serde(default = "abs")]
    pub transform: Transform,
    /// Prior mean (filter space).
    pub prior_mean: f64,
    /// Prior standard deviation (filter space).
    pub prior_std: f64,
    /// True values (transformed units) of the reference run on parts of Σ; 0 elsewhere.
    #[serde(default)]
    pub truth: Vec<SpringTruth>,
    /// Also run the model with Σ all fixed and all free, and compare the assessment errors.
    #[serde(default)]
    pub compare: bool,
}

fn abs() -> Transform {
    Transform::Abs
}

/// True spring value on the nodes of Σ that a selection picks.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SpringTruth {
    /// Which nodes of Σ.
    pub select: NodeSelection,
    /// Value in transformed units (stiffness / scale).
    pub value: f64,
}

/// Tracked feature points on the visible surface.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ObservationSpec {
    /// Number of feature points (drawn uniformly by area on the surface facing the camera, away from
    /// constrained nodes).
    pub points: usize,
    /// Viewing direction of the camera.
    #[serde(default = "view")]
    pub view_direction: Point,
    /// Seed of the point sampling and of the noise.
    #[serde(default)]
    pub seed: u64,
    /// Standard deviation of the Gaussian noise added to every coordinate of the reference positions (m).
    pub noise_std: f64,
    /// Observation standard deviation assumed by the filter (m); default `noise_std`.
    pub filter_std: Option<f64>,
}

fn view() -> Point {
    [0.0, 0.0, -1.0]
}

/// Assessment points: `count` nodes of a selection, spread out, that are neither constrained nor observed.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AssessmentSpec {
    /// Candidate nodes.
    pub select: NodeSelection,
    /// How many.
    pub count: usize,
}

/// Filter settings.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FilterSpec {
    /// Parallel or sequential sigma points.
    #[serde(default)]
    pub execution: Execution,
}

/// Output settings.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OutputSpec {
    /// Directory of the results; default `out/<name>`.
    pub dir: Option<PathBuf>,
}

/// Command-line overrides of the scenario.
#[derive(Debug, Default)]
pub struct Overrides {
    /// Number of iterations.
    pub iterations: Option<usize>,
    /// Evaluate the sigma points one after the other (default: as the scenario says).
    pub sequential: bool,
    /// Output directory.
    pub output: Option<PathBuf>,
}

/// What the filter estimates, in filter order, and how it maps to the model.
struct Unknowns {
    specs: Vec<ParameterSpec>,
    parameters: Vec<FemParameter>,
    truth: Vec<f64>,
    /// Nodes of Σ (one spring parameter each, after the modulus if estimated) and the stiffness scale.
    springs: Option<(Vec<usize>, f64)>,
}

/// Runs the scenario file `path`.
pub fn run(path: &Path, overrides: Overrides) -> Result<()> {
    let start = Instant::now();
    let text = std::fs::read_to_string(path).with_context(|| format!("cannot read scenario {}", path.display()))?;
    let mut sc: AssimilationScenario =
        toml::from_str(&text).with_context(|| format!("invalid scenario {}", path.display()))?;
    if let Some(n) = overrides.iterations {
        sc.iterations = n;
    }
    if overrides.sequential {
        sc.filter.execution = Execution::Sequential;
    }
    ensure!(sc.iterations > 0, "{}: iterations must be at least 1", path.display());
    ensure!(
        sc.young.is_some() || sc.springs.is_some(),
        "{}: nothing to estimate: add [young] or [springs]",
        path.display()
    );
    let obs = &sc.observations;
    let filter_std = obs.filter_std.unwrap_or(obs.noise_std);
    ensure!(
        filter_std.is_finite() && filter_std > 0.0,
        "{}: the filter needs an observation std > 0: set observations.noise_std or observations.filter_std",
        path.display()
    );
    let compare = sc.springs.as_ref().is_some_and(|s| s.compare);
    ensure!(!compare || sc.assessment.is_some(), "{}: springs.compare needs [assessment] points", path.display());
    let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
    let out_dir = overrides.output.or(sc.output.dir.clone()).unwrap_or_else(|| PathBuf::from("out").join(&sc.name));
    std::fs::create_dir_all(&out_dir).with_context(|| format!("cannot create {}", out_dir.display()))?;

    let mesh = crate::scenario::build_mesh(&sc.mesh, &dir).context("building the mesh")?;
    println!(
        "scenario     {}{}",
        sc.name,
        if sc.description.is_empty() { String::new() } else { format!(": {}", sc.description) }
    );
    println!("mesh         {} nodes, {} {} cells", mesh.num_nodes(), mesh.cells.len(), mesh.cells.kind_name());

    let setup = || format!("setting up {}", path.display());
    let (problem, loads, tool_nodes) = build_problem(&sc, mesh).with_context(setup)?;
    let unknowns = unknowns(&sc, &problem.mesh).with_context(setup)?;
    let observed = feature_points(&problem, &sc.observations).with_context(setup)?;
    let observed_nodes: Vec<usize> = observed.iter().flat_map(|t| t.nodes).collect();
    let assessment = match &sc.assessment {
        Some(a) => assessment_points(&problem, a, &observed_nodes).with_context(setup)?,
        None => Vec::new(),
    };
    println!(
        "setup        {} fixed/tool nodes ({} tool), {} feature points, {} assessment points, {} parameter(s), {} sigma points",
        problem.dirichlet.len(),
        tool_nodes.len(),
        observed.len(),
        assessment.len(),
        unknowns.specs.len(),
        unknowns.specs.len() + 1
    );

    // Reference run with the true parameters.
    let rest = problem.mesh.nodes.clone();
    let comparison_base = problem.clone();
    let model =
        FemModel::new(problem, unknowns.parameters.clone(), loads.clone(), observed.clone(), sc.solver.clone())?;
    let t0 = Instant::now();
    let mut clean = Vec::with_capacity(sc.iterations);
    let mut truth_assess = Vec::with_capacity(sc.iterations);
    let mut max_disp: f64 = 0.0;
    model
        .simulate(&unknowns.truth, sc.iterations, |_, s| {
            clean.push(model.observe(s));
            truth_assess.push(tracked_positions(&rest, &assessment, &s.u));
            max_disp = max_disp.max(fem::post::max_displacement(&s.u));
        })
        .context("reference simulation with the true parameters")?;
    println!(
        "reference    {} steps in {:.2} s, max |u| = {:.2} mm",
        sc.iterations,
        t0.elapsed().as_secs_f64(),
        1e3 * max_disp
    );
    let measurements = add_noise(&clean, obs.noise_std, obs.seed)?;

    // Comparison runs: Σ fully fixed and fully free.
    let mut comparisons: Vec<(&str, Vec<f64>)> = Vec::new();
    if let (true, Some((nodes, _))) = (compare, &unknowns.springs) {
        let young: Vec<FemParameter> = sc.young.iter().map(|_| FemParameter::Young).collect();
        let theta = &unknowns.truth[..young.len()];
        let mut fixed = comparison_base.clone();
        fixed.fix(nodes);
        for (label, p) in [("fixed", fixed), ("free", comparison_base)] {
            let m = FemModel::new(p, young.clone(), loads.clone(), observed.clone(), sc.solver.clone())?;
            let mut errors = Vec::with_capacity(sc.iterations);
            m.simulate(theta, sc.iterations, |k, s| {
                errors.push(mean_error(&tracked_positions(&rest, &assessment, &s.u), &truth_assess[k - 1]));
            })
            .with_context(|| format!("comparison run with Σ {label}"))?;
            comparisons.push((label, errors));
        }
    }

    // The filter.
    let config = RoukfConfig {
        parameters: unknowns.specs.clone(),
        observation_std: ObservationNoise::Uniform(filter_std),
        execution: sc.filter.execution,
    };
    let initial = model.initial_state();
    let mut roukf = Roukf::new(model, initial, config)?;
    let bar = ProgressBar::new(sc.iterations as u64);
    bar.set_style(ProgressStyle::with_template("{bar:30} {pos}/{len} [{elapsed_precise} < {eta_precise}] {msg}")?);
    let mut estimated_errors = Vec::with_capacity(sc.iterations);
    let mut newton = 0usize;
    let t_filter = Instant::now();
    for (k, z) in measurements.iter().enumerate() {
        let rec = roukf.step(z).with_context(|| format!("filter iteration {}", k + 1))?;
        let innovation = rec.innovation_norm.unwrap_or(0.0);
        let states = roukf.sigma_states();
        newton += states.iter().map(|s| s.newton_iterations).sum::<usize>();
        if !assessment.is_empty() {
            let mut mean = DVector::zeros(3 * assessment.len());
            for s in states {
                mean += tracked_positions(&rest, &assessment, &s.u);
            }
            mean /= states.len() as f64;
            estimated_errors.push(mean_error(&mean, &truth_assess[k]));
        }
        bar.set_message(progress_message(&roukf, &unknowns, innovation));
        bar.inc(1);
    }
    bar.finish_and_clear();
    let filter_seconds = t_filter.elapsed().as_secs_f64();

    // Outputs.
    let trace = roukf.trace();
    trace.write_csv(&out_dir.join("trace.csv"))?;
    trace.write_json(&out_dir.join("trace.json"))?;
    let times: Vec<f64> = trace.records.iter().filter_map(|r| r.wall_seconds).collect();
    let per_iteration_mean = times.iter().sum::<f64>() / times.len() as f64;
    let per_iteration_median = median(&times);
    println!(
        "filter       {} iterations in {:.2} s: {:.2} ms per iteration (median {:.2} ms), {:.2} Newton iterations per solve, {:?}",
        sc.iterations,
        filter_seconds,
        1e3 * per_iteration_mean,
        1e3 * per_iteration_median,
        newton as f64 / (sc.iterations * (unknowns.specs.len() + 1)) as f64,
        sc.filter.execution
    );
    let mut summary = serde_json::json!({
        "scenario": sc.name,
        "nodes": rest.len(),
        "iterations": sc.iterations,
        "sigma_points": unknowns.specs.len() + 1,
        "execution": format!("{:?}", sc.filter.execution),
        "filter_seconds": filter_seconds,
        "seconds_per_iteration_mean": per_iteration_mean,
        "seconds_per_iteration_median": per_iteration_median,
        "total_seconds": start.elapsed().as_secs_f64(),
        "max_displacement": max_disp,
    });
    let offset = usize::from(sc.young.is_some());
    if sc.young.is_some() {
        summary["young"] = report_young(trace, unknowns.truth[0], &out_dir)?;
    }
    if let Some((nodes, scale)) = &unknowns.springs {
        summary["springs"] = report_springs(trace, nodes, *scale, &unknowns.truth[offset..], offset, &out_dir)?;
    }
    let innovation: Vec<(f64, f64)> =
        trace.records.iter().filter_map(|r| r.innovation_norm.map(|v| (r.iteration as f64, v))).collect();
    line_plot(
        &out_dir.join("innovation.png"),
        &PlotSpec {
            title: "Innovation norm ‖z − Σ α_i H(x_i)‖".into(),
            x_label: "iteration".into(),
            y_label: "innovation norm (m)".into(),
            log_y: true,
        },
        &[Series { name: String::new(), points: innovation, band: None }],
    )?;
    if !assessment.is_empty() {
        let mut cases: Vec<(&str, Vec<f64>)> = vec![("estimated", estimated_errors)];
        cases.extend(comparisons);
        summary["assessment_mean_error"] = report_assessment(&cases, assessment.len(), &out_dir)?;
    }
    let summary_path = out_dir.join("summary.json");
    write_atomic(&summary_path, serde_json::to_string_pretty(&summary)?.as_bytes())?;
    println!("wall time    {:.2} s in all", start.elapsed().as_secs_f64());
    println!("wrote        {}/{{trace.csv, trace.json, summary.json, *.png}}", out_dir.display());
    Ok(())
}

/// Prints and plots the Young's modulus estimate (`young.png`, and `young_zoom.png` without the first tenth of the
/// iterations); returns its summary.
fn report_young(trace: &Trace, truth: f64, out_dir: &Path) -> Result<serde_json::Value> {
    let last = trace.records.last().context("the trace is empty")?;
    let within = converged_at(trace.records.iter().map(|r| r.mean_physical[0]), truth, 0.01);
    println!(
        "young        μ = {:.1} ± {:.1} Pa (truth {truth:.0} Pa, error {:+.2} %), within 1 % {}",
        last.mean_physical[0],
        last.std_physical[0],
        100.0 * (last.mean_physical[0] - truth) / truth,
        within.map_or("never (so far)".to_string(), |k| format!("from iteration {k} on"))
    );
    let n = last.iteration;
    for (file, from) in [("young.png", 0), ("young_zoom.png", n / 10)] {
        let records = || trace.records.iter().filter(|r| r.iteration >= from);
        let mu = records().map(|r| (r.iteration as f64, r.mean_physical[0])).collect();
        let band = records()
            .map(|r| {
                (r.iteration as f64, r.mean_physical[0] - r.std_physical[0], r.mean_physical[0] + r.std_physical[0])
            })
            .collect();
        line_plot(
            &out_dir.join(file),
            &PlotSpec {
                title: format!("Young's modulus: ROUKF estimate μ ± σ (iterations {from}–{n})"),
                x_label: "iteration".into(),
                y_label: "Young's modulus (Pa)".into(),
                log_y: false,
            },
            &[
                Series { name: "estimate μ ± σ".into(), points: mu, band: Some(band) },
                Series {
                    name: format!("truth {truth:.0} Pa"),
                    points: vec![(from as f64, truth), (n as f64, truth)],
                    band: None,
                },
            ],
        )?;
    }
    Ok(serde_json::json!({
        "mean": last.mean_physical[0], "std": last.std_physical[0], "truth": truth,
        "within_1_percent_from_iteration": within,
    }))
}

/// Prints and plots the spring estimates (`springs.png` over the iterations, `springs_final.png` per node against
/// the truth), in N/m; `truth` in transformed units, parameters from index `offset` on; returns their summary.
fn report_springs(
    trace: &Trace,
    nodes: &[usize],
    scale: f64,
    truth: &[f64],
    offset: usize,
    out_dir: &Path,
) -> Result<serde_json::Value> {
    let last = trace.records.last().context("the trace is empty")?;
    let est: Vec<f64> = (0..nodes.len()).map(|j| scale * last.mean_physical[offset + j]).collect();
    let sd: Vec<f64> = (0..nodes.len()).map(|j| scale * last.std_physical[offset + j]).collect();
    let truth: Vec<f64> = truth.iter().map(|t| scale * t).collect();
    let rms = (est.iter().zip(&truth).map(|(a, b)| (a - b).powi(2)).sum::<f64>() / est.len() as f64).sqrt();
    println!(
        "springs      {} stiffnesses: RMS error {:.1} N/m (true values 0..{:.1} N/m), mean σ {:.1} N/m",
        nodes.len(),
        rms,
        truth.iter().copied().fold(0.0, f64::max),
        sd.iter().sum::<f64>() / sd.len() as f64
    );
    let series: Vec<Series> = (0..nodes.len())
        .map(|j| Series {
            name: String::new(),
            points: trace.records.iter().map(|r| (r.iteration as f64, scale * r.mean_physical[offset + j])).collect(),
            band: None,
        })
        .collect();
    line_plot(
        &out_dir.join("springs.png"),
        &PlotSpec {
            title: format!("{} boundary springs: ROUKF estimates μ", nodes.len()),
            x_label: "iteration".into(),
            y_label: "stiffness (N/m)".into(),
            log_y: false,
        },
        &series,
    )?;
    let at = |v: &[f64]| -> Vec<(f64, f64)> { v.iter().enumerate().map(|(j, v)| (j as f64, *v)).collect() };
    line_plot(
        &out_dir.join("springs_final.png"),
        &PlotSpec {
            title: format!("Spring stiffness per node of Σ after {} iterations", last.iteration),
            x_label: "spring (node of Σ, by index)".into(),
            y_label: "stiffness (N/m)".into(),
            log_y: false,
        },
        &[
            Series {
                name: "estimate μ ± σ".into(),
                points: at(&est),
                band: Some(est.iter().zip(&sd).enumerate().map(|(j, (v, s))| (j as f64, v - s, v + s)).collect()),
            },
            Series { name: "truth".into(), points: at(&truth), band: None },
        ],
    )?;
    Ok(serde_json::json!({ "nodes": nodes, "stiffness": est, "std": sd, "truth": truth, "rms_error": rms }))
}

/// Prints, writes (`assessment.csv`) and plots (`assessment.png`) the assessment errors over time of each case;
/// returns the mean error of each case.
fn report_assessment(cases: &[(&str, Vec<f64>)], points: usize, out_dir: &Path) -> Result<serde_json::Value> {
    write_assessment_csv(&out_dir.join("assessment.csv"), cases)?;
    let mut means = serde_json::Map::new();
    let mut series = Vec::new();
    for (label, errors) in cases {
        let mean = errors.iter().sum::<f64>() / errors.len() as f64;
        let max = errors.iter().copied().fold(0.0, f64::max);
        println!("assessment   {label:<10} mean error {:.3} mm (max {:.3} mm)", 1e3 * mean, 1e3 * max);
        means.insert(label.to_string(), serde_json::json!(mean));
        series.push(Series {
            name: format!("{label} ({:.2} mm mean)", 1e3 * mean),
            points: errors.iter().enumerate().map(|(k, e)| ((k + 1) as f64, 1e3 * e)).collect(),
            band: None,
        });
    }
    line_plot(
        &out_dir.join("assessment.png"),
        &PlotSpec {
            title: format!("Mean error at {points} assessment points"),
            x_label: "time step".into(),
            y_label: "error (mm)".into(),
            log_y: false,
        },
        &series,
    )?;
    Ok(serde_json::Value::Object(means))
}

/// The base problem (material, fixed and tool nodes constrained at rest), the time-profiled loads, and the tool
/// nodes.
fn build_problem(sc: &AssimilationScenario, mesh: Mesh) -> Result<(Problem, Vec<LoadPattern>, Vec<usize>)> {
    sc.material.validate().map_err(anyhow::Error::msg).context("material")?;
    let mut problem = Problem::new(mesh, sc.material);
    for f in &sc.fixed {
        let nodes = f.select.select(&problem.mesh).context("fixed selection")?;
        problem.fix(&nodes);
    }
    let mut loads = Vec::new();
    for f in &sc.force {
        let nodes = f.select.select(&problem.mesh).context("force selection")?;
        let share = 1.0 / nodes.len() as f64;
        let forces = nodes.iter().map(|&k| (k, f.total.map(|c| c * share))).collect();
        loads.push(LoadPattern { profile: f.profile, forces, displacements: vec![] });
    }
    let mut tool_nodes = Vec::new();
    for t in &sc.tool {
        let mut nodes = t.select.select(&problem.mesh).context("tool selection")?;
        match (t.near, t.count) {
            (Some(p), count) => {
                let count = count.unwrap_or(1);
                ensure!(count > 0, "tool: count must be at least 1");
                let d2 = |k: usize| dist2(problem.mesh.nodes[k], p);
                nodes.sort_by(|&a, &b| d2(a).total_cmp(&d2(b)).then(a.cmp(&b)));
                nodes.truncate(count);
            }
            (None, Some(_)) => bail!("tool: `count` needs `near`, the point the nodes are nearest to"),
            (None, None) => {}
        }
        for &k in &nodes {
            problem.dirichlet.entry(k).or_insert([0.0; 3]);
        }
        loads.push(LoadPattern {
            profile: t.profile,
            forces: vec![],
            displacements: nodes.iter().map(|&k| (k, t.displacement)).collect(),
        });
        tool_nodes.extend(nodes);
    }
    tool_nodes.sort_unstable();
    tool_nodes.dedup();
    Ok((problem, loads, tool_nodes))
}

/// The filter's parameters, in order: Young's modulus (if estimated), then one spring per node of Σ.
fn unknowns(sc: &AssimilationScenario, mesh: &Mesh) -> Result<Unknowns> {
    let mut u = Unknowns { specs: Vec::new(), parameters: Vec::new(), truth: Vec::new(), springs: None };
    if let Some(y) = &sc.young {
        u.specs.push(ParameterSpec::new("young", y.transform, y.prior_mean, y.prior_std));
        u.parameters.push(FemParameter::Young);
        u.truth.push(sc.material.young);
    }
    if let Some(s) = &sc.springs {
        ensure!(s.scale.is_finite() && s.scale > 0.0, "springs.scale must be finite and > 0, got {}", s.scale);
        let nodes = s.select.select(mesh).context("springs selection")?;
        let mut truth = vec![0.0; nodes.len()];
        for t in &s.truth {
            ensure!(
                t.value.is_finite() && t.value >= 0.0,
                "spring truth values must be finite and ≥ 0, got {}",
                t.value
            );
            let picked = t.select.select(mesh).context("springs.truth selection")?;
            let mut hit = false;
            for (j, k) in nodes.iter().enumerate() {
                if picked.binary_search(k).is_ok() {
                    truth[j] = t.value;
                    hit = true;
                }
            }
            ensure!(hit, "springs.truth selection {:?} picks no node of the springs region", t.select);
        }
        for (j, &k) in nodes.iter().enumerate() {
            u.specs.push(ParameterSpec::new(format!("k_{k}"), s.transform, s.prior_mean, s.prior_std));
            u.parameters.push(FemParameter::Springs { nodes: vec![k], scale: s.scale });
            u.truth.push(truth[j]);
        }
        u.springs = Some((nodes, s.scale));
    }
    Ok(u)
}

/// Feature points drawn on the surface facing the camera, on triangles without constrained nodes, located in
/// the mesh.
fn feature_points(problem: &Problem, spec: &ObservationSpec) -> Result<Vec<TrackedPoint>> {
    ensure!(spec.points > 0, "observations.points must be at least 1");
    ensure!(spec.noise_std.is_finite() && spec.noise_std >= 0.0, "observations.noise_std must be ≥ 0");
    // Draw generously, then keep the first points away from constrained nodes.
    let samples =
        mesh::sampling::sample_visible_boundary(&problem.mesh, spec.view_direction, 8 * spec.points, spec.seed)?;
    let mut points = Vec::with_capacity(spec.points);
    for s in samples.iter().filter(|s| s.nodes.iter().all(|k| !problem.dirichlet.contains_key(k))) {
        if points.len() == spec.points {
            break;
        }
        points.push(TrackedPoint::locate(&problem.mesh, s.point)?);
    }
    if points.len() < spec.points {
        bail!(
            "only {} feature points found on the visible surface away from constrained nodes, {} asked",
            points.len(),
            spec.points
        );
    }
    Ok(points)
}

/// `count` nodes of the selection, neither constrained nor carrying an observed point, spread out by farthest-point
/// sampling from the candidate nearest their centroid.
fn assessment_points(problem: &Problem, spec: &AssessmentSpec, observed_nodes: &[usize]) -> Result<Vec<TrackedPoint>> {
    let nodes = &problem.mesh.nodes;
    let candidates: Vec<usize> = spec
        .select
        .select(&problem.mesh)
        .context("assessment selection")?
        .into_iter()
        .filter(|k| !problem.dirichlet.contains_key(k) && !observed_nodes.contains(k))
        .collect();
    ensure!(
        candidates.len() >= spec.count && spec.count > 0,
        "assessment: {} points asked, {} candidate nodes are neither constrained nor observed",
        spec.count,
        candidates.len()
    );
    let n = candidates.len() as f64;
    let centroid: Point = std::array::from_fn(|d| candidates.iter().map(|&k| nodes[k][d]).sum::<f64>() / n);
    let first = candidates
        .iter()
        .copied()
        .min_by(|&a, &b| dist2(nodes[a], centroid).total_cmp(&dist2(nodes[b], centroid)))
        .context("no assessment candidate")?;
    let mut chosen = vec![first];
    while chosen.len() < spec.count {
        let next = candidates
            .iter()
            .copied()
            .filter(|k| !chosen.contains(k))
            .max_by(|&a, &b| {
                let d = |k: usize| chosen.iter().map(|&c| dist2(nodes[k], nodes[c])).fold(f64::INFINITY, f64::min);
                d(a).total_cmp(&d(b))
            })
            .context("not enough assessment candidates")?;
        chosen.push(next);
    }
    Ok(chosen.into_iter().map(TrackedPoint::at_node).collect())
}

fn dist2(a: Point, b: Point) -> f64 {
    (0..3).map(|d| (a[d] - b[d]).powi(2)).sum()
}

/// Mean Euclidean distance between two stacked point lists.
fn mean_error(a: &DVector<f64>, b: &DVector<f64>) -> f64 {
    let n = a.len() / 3;
    (0..n).map(|i| (0..3).map(|d| (a[3 * i + d] - b[3 * i + d]).powi(2)).sum::<f64>().sqrt()).sum::<f64>() / n as f64
}

fn median(v: &[f64]) -> f64 {
    let mut s = v.to_vec();
    s.sort_by(|a, b| a.total_cmp(b));
    s.get(s.len() / 2).copied().unwrap_or(f64::NAN)
}

/// First iteration from which every estimate stays within `tol` (relative) of `truth`.
fn converged_at(means: impl Iterator<Item = f64>, truth: f64, tol: f64) -> Option<usize> {
    let mut since = None;
    for (k, m) in means.enumerate() {
        if ((m - truth) / truth).abs() < tol {
            since.get_or_insert(k);
        } else {
            since = None;
        }
    }
    since
}

fn progress_message(roukf: &Roukf<FemModel>, unknowns: &Unknowns, innovation: f64) -> String {
    let mu = roukf.mean_physical();
    let sd = roukf.std_physical();
    match (&unknowns.springs, unknowns.parameters.first()) {
        (_, Some(FemParameter::Young)) => {
            format!("E = {:.1} ± {:.1} Pa, |innovation| = {innovation:.2e} m", mu[0], sd[0])
        }
        (Some((_, scale)), _) => {
            let mean = scale * mu.iter().sum::<f64>() / mu.len() as f64;
            format!("mean k = {mean:.1} N/m, |innovation| = {innovation:.2e} m")
        }
        _ => format!("|innovation| = {innovation:.2e} m"),
    }
}

fn write_assessment_csv(path: &Path, cases: &[(&str, Vec<f64>)]) -> Result<()> {
    let mut s = String::from("step");
    for (label, _) in cases {
        s.push_str(&format!(",{label}_mean_error_m"));
    }
    s.push('\n');
    let steps = cases.iter().map(|c| c.1.len()).min().unwrap_or(0);
    for k in 0..steps {
        s.push_str(&(k + 1).to_string());
        for (_, e) in cases {
            s.push_str(&format!(",{}", e[k]));
        }
        s.push('\n');
    }
    write_atomic(path, s.as_bytes())
}

/// Writes `bytes` to `path` atomically.
fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    use std::io::Write;
    mesh::io::write_file_atomic(path, |f| f.write_all(bytes))
        .with_context(|| format!("cannot write {}", path.display()))
}
