//! `augsim assimilate`: parses the command line, runs a [`app::assimilation::Experiment`] and prints its
//! setup, progress and results.

use std::path::PathBuf;

use anyhow::Result;
use app::assimilation::{Experiment, ObservationFiles, Report};
use clap::Args;
use filter::{Discrepancy, Execution, SigmaPointSet};
use mesh::length::mm;
use scenario::AssimilationScenario;

use crate::bar::Bar;

/// Arguments of `augsim assimilate`.
#[derive(Debug, Args)]
pub struct AssimilateArgs {
    /// Assimilation scenario: a TOML file, or the name of a built-in one (e.g. roukf_young).
    pub scenario: PathBuf,
    /// Number of filter iterations (default: the scenario's; with --observations, all frames).
    #[arg(long)]
    pub iterations: Option<usize>,
    /// Evaluate the sigma points one after the other instead of in parallel.
    #[arg(long)]
    pub sequential: bool,
    /// Output directory; default out/<name>.
    #[arg(short, long)]
    pub output: Option<PathBuf>,
    /// Tracked features instead of synthetic ones: CSV `frame,id,x,y,z` (m; frame 0 = rest, frame k = step k).
    #[arg(long)]
    pub observations: Option<PathBuf>,
    /// Rest positions of the tracked features: CSV `id,x,y,z` (default: their frame-0 rows).
    #[arg(long, requires = "observations")]
    pub features: Option<PathBuf>,
    /// Tracked tool features (CSV `frame,id,x,y,z`): displacement prescribed on the nearest free surface node.
    #[arg(long, requires = "observations")]
    pub controls: Option<PathBuf>,
    /// Tracked assessment points (CSV `frame,id,x,y,z`): the estimated deformation's error is reported there.
    #[arg(long, requires = "observations")]
    pub assessment: Option<PathBuf>,
    /// The scenario's parameter values are the truth behind the tracks (e.g. tracks of a synthetic run on a finer
    /// mesh): report the estimate's error against them.
    #[arg(long, requires = "observations")]
    pub known_truth: bool,
    /// Forgetting factor in (0, 1]: the parameter covariance is divided by it before every step (default: the
    /// scenario's filter.forgetting, else 1 = none).
    #[arg(long)]
    pub forgetting: Option<f64>,
    /// Sigma points: `simplex` (p + 1) or `star` (2p + 1) (default: the scenario's filter.sigma_points, else
    /// simplex).
    #[arg(long, value_name = "SET")]
    pub sigma_points: Option<SigmaPointSet>,
    /// Allowance for model error in the reported σ: `none`, `independent` (the misfit beyond the observation noise
    /// as extra white noise) or `systematic` (a model error that may lie along the parameters' sensitivity)
    /// (default: the scenario's filter.discrepancy, else none).
    #[arg(long, value_name = "KIND")]
    pub discrepancy: Option<Discrepancy>,
    /// Degrees of freedom d ≥ 1 of a systematic discrepancy (default: the scenario's filter.discrepancy_dof, else 1).
    #[arg(long, value_name = "D")]
    pub discrepancy_dof: Option<f64>,
    /// Write the estimated deformation every N steps (default: the scenario's output.every, else 1).
    #[arg(long)]
    pub every: Option<usize>,
}

/// Runs `augsim assimilate`.
pub fn run(args: &AssimilateArgs) -> Result<()> {
    let (mut sc, dir): (AssimilationScenario, PathBuf) = AssimilationScenario::load(&args.scenario)?;
    if args.iterations.is_some() {
        sc.iterations = args.iterations;
    }
    if args.sequential {
        sc.filter.execution = Execution::Sequential;
    }
    if let Some(rho) = args.forgetting {
        sc.filter.forgetting = rho;
    }
    if let Some(set) = args.sigma_points {
        sc.filter.sigma_points = set;
    }
    if let Some(kind) = args.discrepancy {
        sc.filter.discrepancy = kind;
    }
    if let Some(d) = args.discrepancy_dof {
        sc.filter.discrepancy_dof = d;
    }
    if args.every.is_some() {
        sc.output.every = args.every;
    }
    let out_dir = args.output.clone().unwrap_or_else(|| sc.output_dir());
    let files = args.observations.as_ref().map(|observations| ObservationFiles {
        observations: observations.clone(),
        features: args.features.clone(),
        controls: args.controls.clone(),
        assessment: args.assessment.clone(),
        known_truth: args.known_truth,
    });
    println!(
        "scenario     {}{}",
        sc.name,
        if sc.description.is_empty() { String::new() } else { format!(": {}", sc.description) }
    );
    let sigma_set = sc.filter.sigma_points;
    let experiment = Experiment::prepare(sc, &dir, files.as_ref())?;
    let s = experiment.setup();
    println!("mesh         {} nodes, {} {} cells", s.nodes, s.cells, s.cell_kind);
    println!(
        "setup        {} constrained nodes ({} tool, {} tracked tool), {} feature points, {} assessment points, \
         {} parameter(s), {} {} sigma points",
        s.constrained_nodes,
        s.tool_nodes,
        s.control_nodes,
        s.features,
        s.assessment_points,
        s.parameters,
        s.sigma_points,
        sigma_set
    );
    match (&s.reference, &files) {
        (Some(r), _) => println!(
            "reference    {} steps in {:.2} s, max |u| = {:.2} mm, on {}",
            s.iterations,
            r.seconds,
            mm(r.max_displacement),
            if r.inverse_crime {
                "the filter's own model (an inverse crime: add a [reference] section with another mesh)".to_string()
            } else {
                format!(
                    "a reference of its own: {} nodes, {} cells, {:?} ({} tracked points moved onto the model's \
                     surface, at most {:.2} mm)",
                    r.nodes,
                    r.cells,
                    r.law,
                    s.projected,
                    mm(s.max_projection)
                )
            }
        ),
        (None, Some(f)) => println!(
            "tracks       {} frames from {}, {} occluded feature observations, {} points outside the mesh moved \
             onto its surface (at most {:.2} mm)",
            s.iterations,
            f.observations.display(),
            s.occluded,
            s.projected,
            mm(s.max_projection)
        ),
        (None, None) => {}
    }

    let bar = Bar::new("iterations", "");
    let report = experiment.run(&out_dir, &bar);
    bar.finish();
    print_report(&report?);
    println!(
        "wrote        {}/{{trace.csv, trace.json, summary.json, deformation.pvd, *.png}}{}",
        out_dir.display(),
        if files.is_none() { ", tracks/*.csv (the synthetic observations)" } else { "" }
    );
    Ok(())
}

fn print_report(r: &Report) {
    println!(
        "filter       {} iterations in {:.2} s: {:.2} ms per iteration (median {:.2} ms), {:.2} Newton iterations \
         per solve, {:?}",
        r.iterations,
        r.filter_seconds,
        1e3 * r.seconds_per_iteration_mean,
        1e3 * r.seconds_per_iteration_median,
        r.newton_iterations_per_solve,
        r.execution
    );
    let t = &r.filter_times;
    println!(
        "time         FEM solves {:.2} s summed over the sigma points (assembly {:.2} s, {:.2} factorisations per \
         solve {:.2} s, triangular solves {:.2} s), writing the deformation {:.2} s",
        t.solves, t.assembly, t.factorizations_per_solve, t.factorization, t.triangular_solves, t.writing
    );
    if let Some(y) = &r.young {
        let truth = match y.truth {
            Some(t) => format!(
                " (truth {t:.0} Pa, error {:+.2} %), within 1 % {}",
                100.0 * (y.mean - t) / t,
                match (y.within_1_percent_from_iteration, y.within_1_percent_after_seconds) {
                    (Some(k), Some(t)) => format!("from iteration {k} on ({t:.2} s of filter time)"),
                    (Some(k), None) => format!("from iteration {k} on"),
                    _ => "never (so far)".to_string(),
                }
            ),
            None => String::new(),
        };
        println!("young        μ = {:.1} ± {:.1} Pa{truth}", y.mean, y.std);
        if let (Some(noise), Some(misfit)) = (y.noise_std, y.misfit) {
            println!(
                "discrepancy  σ = {:.1} Pa from the observation noise alone; misfit χ²/ν = {misfit:.3} (effective \
                 observation noise {:.2} × nominal)",
                noise,
                misfit.sqrt()
            );
        }
    }
    if let Some(s) = &r.springs {
        let n = s.stiffness.len() as f64;
        let truth = match (&s.truth, s.rms_error) {
            (Some(t), Some(rms)) => {
                format!(": RMS error {rms:.1} N/m (true values 0..{:.1} N/m)", t.iter().copied().fold(0.0, f64::max))
            }
            _ => String::new(),
        };
        println!(
            "springs      {} stiffnesses{truth}, mean {:.1} N/m, mean σ {:.1} N/m",
            s.stiffness.len(),
            s.stiffness.iter().sum::<f64>() / n,
            s.std.iter().sum::<f64>() / n
        );
    }
    for c in &r.assessment {
        println!("assessment   {:<10} mean error {:.3} mm (max {:.3} mm)", c.label, mm(c.mean_error), mm(c.max_error));
    }
    println!("wall time    {:.2} s in all", r.total_seconds);
}
