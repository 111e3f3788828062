//! The outputs of an assimilation run: the summary ([`Report`], `summary.json`), PNG plots of the estimates and
//! the innovation, and the assessment errors (`assessment.csv`, `assessment.png`).

use std::path::Path;

use mesh::io::write_atomic_bytes;
use mesh::length::mm;
use plot::{line_plot, PlotSpec, Series};
use serde::Serialize;

use super::{AssimilationError, Context};
use filter::{Execution, SigmaPointSet, Trace};

/// The reference run that synthesises the observations.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Reference {
    /// It ran on the filter's own model (mesh and law). `false` with a `[reference]` section.
    pub inverse_crime: bool,
    /// Nodes of its mesh.
    pub nodes: usize,
    /// Cells of its mesh.
    pub cells: usize,
    /// Its constitutive law.
    pub law: fem::Law,
    /// Wall-clock time (s).
    pub seconds: f64,
    /// Largest nodal displacement over all steps (m).
    pub max_displacement: f64,
}

/// The results of a run (also written as `summary.json`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Report {
    /// Scenario name.
    pub scenario: String,
    /// Synthetic observations (a reference run with the scenario's true parameters) rather than track files.
    pub synthetic: bool,
    /// Mesh nodes.
    pub nodes: usize,
    /// Filter iterations.
    pub iterations: usize,
    /// Sigma points (parameters + 1 simplex, 2 parameters + 1 star).
    pub sigma_points: usize,
    /// Simplex or star sigma points.
    pub sigma_point_set: SigmaPointSet,
    /// Parallel or sequential sigma points.
    pub execution: Execution,
    /// Wall-clock time of the filter (s).
    pub filter_seconds: f64,
    /// Mean time per iteration (s).
    pub seconds_per_iteration_mean: f64,
    /// Median time per iteration (s).
    pub seconds_per_iteration_median: f64,
    /// Newton iterations per FEM solve.
    pub newton_iterations_per_solve: f64,
    /// Where the filter's time went.
    pub filter_times: FilterTimes,
    /// Wall-clock time since the experiment was prepared (s).
    pub total_seconds: f64,
    /// The reference run behind synthetic observations: its mesh, whether it was the filter's own model, its
    /// time and largest displacement.
    pub reference: Option<Reference>,
    /// Young's modulus, when estimated.
    pub young: Option<YoungReport>,
    /// Boundary springs, when estimated.
    pub springs: Option<SpringsReport>,
    /// Assessment errors of the estimate (and of the comparison runs).
    pub assessment: Vec<AssessmentCase>,
    /// Steps of the estimated deformation written to `deformation.pvd`.
    pub deformation_frames: usize,
    /// The observation noise the filter assumes (m).
    pub observation_std: f64,
    /// The farthest an observed feature moved from its rest position (m).
    pub largest_feature_motion: f64,
    /// The tracked components measured over the run (three a feature seen in a frame).
    pub measured_components: usize,
    /// With a validation gate: the tracked components it left out over the run...
    pub gated_components: usize,
    /// ... and the steps they were left out of...
    pub gated_steps: usize,
    /// ... and the features they belong to, with the steps each was left out of, most often first.
    pub gated_features: Vec<(String, usize)>,
}

/// Where the filter's time went. The FEM solves' times are each solve's own wall-clock time summed over all
/// sigma points and iterations: with parallel sigma points they add up to more than the filter's wall time.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct FilterTimes {
    /// FEM solves in all (s).
    pub solves: f64,
    /// Of which element evaluation and assembly: internal forces and tangents (s).
    pub assembly: f64,
    /// Of which numeric factorisations (s).
    pub factorization: f64,
    /// Of which triangular solves and BFGS updates (s).
    pub triangular_solves: f64,
    /// Numeric factorisations per FEM solve.
    pub factorizations_per_solve: f64,
    /// Writing the estimated deformation (`deformation/step_*.vtu`) (s).
    pub writing: f64,
}

/// The Young's modulus estimate.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct YoungReport {
    /// Final mean (Pa).
    pub mean: f64,
    /// Final standard deviation (Pa).
    pub std: f64,
    /// The prior's standard deviation (Pa).
    pub prior_std: f64,
    /// The true value (synthetic only).
    pub truth: Option<f64>,
    /// First iteration from which every estimate stays within 1 % of the truth.
    pub within_1_percent_from_iteration: Option<usize>,
    /// Filter wall-clock time (s, the iterations' own times summed) until that iteration.
    pub within_1_percent_after_seconds: Option<f64>,
    /// How much the estimate changed over the last tenth of the iterations (at least five): the steps
    /// and the change (Pa); `None` for a run shorter than that.
    pub drift: Option<(usize, f64)>,
    /// With a model-discrepancy allowance (`[filter] discrepancy`): the final σ of the observation noise alone
    /// (Pa), while `std` includes the allowance.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub noise_std: Option<f64>,
    /// With a model-discrepancy allowance: the final reduced misfit χ²/ν of the frames whose sigma points came near
    /// the final estimate (the last 20,000 at most; 1 when the model and the nominal noise are right).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub misfit: Option<f64>,
}

/// The spring estimates, in N/m.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SpringsReport {
    /// The node of each spring.
    pub nodes: Vec<usize>,
    /// Final stiffness per node.
    pub stiffness: Vec<f64>,
    /// Final standard deviation per node.
    pub std: Vec<f64>,
    /// True stiffness per node (synthetic only).
    pub truth: Option<Vec<f64>>,
    /// RMS error against the truth.
    pub rms_error: Option<f64>,
}

/// Assessment errors of one case over the run.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct AssessmentCase {
    /// `estimated`, `fixed` or `free`.
    pub label: String,
    /// Mean over the steps of the mean distance at the assessment points (m).
    pub mean_error: f64,
    /// Largest per-step mean distance (m).
    pub max_error: f64,
}

impl Report {
    /// Writes the report as pretty JSON, atomically.
    pub fn write_json(&self, path: &Path) -> Result<(), AssimilationError> {
        let text = serde_json::to_vec_pretty(self).context(|| "serialising the summary".into())?;
        Ok(write_atomic_bytes(path, &text)?)
    }
}

/// The fewest last iterations over which an estimate's drift is measured.
const DRIFT_STEPS: usize = 5;

/// The change of the first parameter's estimate (physical) over the last tenth of the iterations, at least
/// [`DRIFT_STEPS`] of them: (steps, change).
fn drift(trace: &Trace) -> Option<(usize, f64)> {
    let n = trace.records.last()?.iteration;
    let steps = (n / 10).max(DRIFT_STEPS);
    let from = trace.records.iter().find(|r| r.iteration + steps == n)?;
    Some((steps, trace.records.last()?.mean_physical[0] - from.mean_physical[0]))
}

/// Plots the Young's modulus estimate (`young.png`, and `young_zoom.png` without the first tenth of the
/// iterations) and summarises it.
pub(super) fn young(trace: &Trace, truth: Option<f64>, out_dir: &Path) -> Result<YoungReport, AssimilationError> {
    let last = last(trace)?;
    let within = truth.and_then(|t| converged_at(trace.records.iter().map(|r| r.mean_physical[0]), t, 0.01));
    let n = last.iteration;
    for (file, from) in [("young.png", 0), ("young_zoom.png", n / 10)] {
        let records = || trace.records.iter().filter(|r| r.iteration >= from);
        let mu = records().map(|r| (r.iteration as f64, r.mean_physical[0])).collect();
        let band = records()
            .map(|r| {
                (r.iteration as f64, r.mean_physical[0] - r.std_physical[0], r.mean_physical[0] + r.std_physical[0])
            })
            .collect();
        let mut series = vec![Series { name: "estimate μ ± σ".into(), points: mu, band: Some(band) }];
        if let Some(t) = truth {
            series.push(Series {
                name: format!("truth {t:.0} Pa"),
                points: vec![(from as f64, t), (n as f64, t)],
                band: None,
            });
        }
        plot(
            &out_dir.join(file),
            format!("Young's modulus: ROUKF estimate μ ± σ (iterations {from}–{n})"),
            "iteration",
            "Young's modulus (Pa)",
            &series,
        )?;
    }
    let seconds =
        within.map(|k| trace.records.iter().filter(|r| r.iteration <= k).filter_map(|r| r.wall_seconds).sum::<f64>());
    Ok(YoungReport {
        mean: last.mean_physical[0],
        std: last.std_physical[0],
        prior_std: trace.records.first().map_or(f64::NAN, |r| r.std_physical[0]),
        truth,
        within_1_percent_from_iteration: within,
        within_1_percent_after_seconds: seconds,
        drift: drift(trace),
        noise_std: last.noise_std_physical.as_ref().map(|s| s[0]),
        misfit: last.misfit,
    })
}

/// Plots the spring estimates (`springs.png` over the iterations, `springs_final.png` per node, with the truth when
/// known), in N/m; parameters from index `offset` on.
pub(super) fn springs(
    trace: &Trace,
    nodes: &[usize],
    truth: Option<&[f64]>,
    offset: usize,
    out_dir: &Path,
) -> Result<SpringsReport, AssimilationError> {
    let last = last(trace)?;
    let est = last.mean_physical[offset..offset + nodes.len()].to_vec();
    let sd = last.std_physical[offset..offset + nodes.len()].to_vec();
    let truth: Option<Vec<f64>> = truth.map(<[f64]>::to_vec);
    let rms = truth
        .as_ref()
        .map(|truth| (est.iter().zip(truth).map(|(a, b)| (a - b).powi(2)).sum::<f64>() / est.len() as f64).sqrt());
    let series: Vec<Series> = (0..nodes.len())
        .map(|j| Series {
            name: String::new(),
            points: trace.records.iter().map(|r| (r.iteration as f64, r.mean_physical[offset + j])).collect(),
            band: None,
        })
        .collect();
    plot(
        &out_dir.join("springs.png"),
        format!("{} boundary springs: ROUKF estimates μ", nodes.len()),
        "iteration",
        "stiffness (N/m)",
        &series,
    )?;
    let at = |v: &[f64]| -> Vec<(f64, f64)> { v.iter().enumerate().map(|(j, v)| (j as f64, *v)).collect() };
    let mut series = vec![Series {
        name: "estimate μ ± σ".into(),
        points: at(&est),
        band: Some(est.iter().zip(&sd).enumerate().map(|(j, (v, s))| (j as f64, v - s, v + s)).collect()),
    }];
    if let Some(t) = &truth {
        series.push(Series { name: "truth".into(), points: at(t), band: None });
    }
    plot(
        &out_dir.join("springs_final.png"),
        format!("Spring stiffness per node of Σ after {} iterations", last.iteration),
        "spring (node of Σ, by index)",
        "stiffness (N/m)",
        &series,
    )?;
    Ok(SpringsReport { nodes: nodes.to_vec(), stiffness: est, std: sd, truth, rms_error: rms })
}

/// Plots the innovation norm (`innovation.png`).
pub(super) fn innovation(trace: &Trace, out_dir: &Path) -> Result<(), AssimilationError> {
    let points: Vec<(f64, f64)> =
        trace.records.iter().filter_map(|r| r.innovation_norm.map(|v| (r.iteration as f64, v))).collect();
    let path = out_dir.join("innovation.png");
    let spec = PlotSpec {
        title: "Innovation norm ‖z − Σ α_i H(x_i)‖".into(),
        x_label: "iteration".into(),
        y_label: "innovation norm (m)".into(),
        log_y: true,
    };
    line_plot(&path, &spec, &[Series { name: String::new(), points, band: None }])
        .context(|| format!("plotting {}", path.display()))
}

/// Writes (`assessment.csv`) and plots (`assessment.png`) the assessment errors over time of each case, and
/// summarises them (steps without a measured assessment point are left out).
pub(super) fn assessment(
    cases: &[(&str, Vec<f64>)],
    points: usize,
    out_dir: &Path,
) -> Result<Vec<AssessmentCase>, AssimilationError> {
    let columns: Vec<String> = cases.iter().map(|(label, _)| format!("{label}_mean_error_m")).collect();
    let header: Vec<&str> = std::iter::once("step").chain(columns.iter().map(String::as_str)).collect();
    let steps = cases.iter().map(|c| c.1.len()).min().unwrap_or(0);
    let rows = (0..steps).map(|k| {
        std::iter::once((k + 1).to_string()).chain(cases.iter().map(|(_, e)| e[k].to_string())).collect::<Vec<_>>()
    });
    mesh::io::csv::write_csv(&out_dir.join("assessment.csv"), &[], &header, rows)?;
    let mut summary = Vec::new();
    let mut series = Vec::new();
    for (label, errors) in cases {
        let finite: Vec<f64> = errors.iter().copied().filter(|e| e.is_finite()).collect();
        let mean = finite.iter().sum::<f64>() / finite.len() as f64;
        let max = finite.iter().copied().fold(f64::NAN, f64::max);
        summary.push(AssessmentCase { label: label.to_string(), mean_error: mean, max_error: max });
        series.push(Series {
            name: format!("{label} ({:.2} mm mean)", mm(mean)),
            points: errors.iter().enumerate().map(|(k, &e)| ((k + 1) as f64, mm(e))).collect(),
            band: None,
        });
    }
    plot(
        &out_dir.join("assessment.png"),
        format!("Mean error at {points} assessment points"),
        "time step",
        "error (mm)",
        &series,
    )?;
    Ok(summary)
}

fn plot(path: &Path, title: String, x: &str, y: &str, series: &[Series]) -> Result<(), AssimilationError> {
    let spec = PlotSpec { title, x_label: x.into(), y_label: y.into(), log_y: false };
    line_plot(path, &spec, series).context(|| format!("plotting {}", path.display()))
}

fn last(trace: &Trace) -> Result<&filter::IterationTrace, AssimilationError> {
    trace.records.last().ok_or_else(|| AssimilationError::Setup("the trace is empty".into()))
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

#[cfg(test)]
mod tests {
    use super::*;

    /// A trace of `n` iterations whose estimate is `mean(k)` at iteration k.
    fn trace(n: usize, mean: impl Fn(usize) -> f64) -> Trace {
        let record = |k: usize| filter::IterationTrace {
            iteration: k,
            mean: vec![mean(k)],
            std: vec![1.0],
            mean_physical: vec![mean(k)],
            std_physical: vec![1.0],
            innovation_norm: None,
            wall_seconds: None,
            noise_std_physical: None,
            misfit: None,
            gated: 0,
            gated_components: Vec::new(),
        };
        let names = vec!["young".to_string()];
        Trace { parameter_names: names, transforms: vec![], scales: vec![1.0], records: (0..=n).map(record).collect() }
    }

    /// The drift is the change over the last tenth of the iterations, at least five of them; a run
    /// shorter than that has none.
    #[test]
    fn the_drift_is_over_the_last_tenth_of_the_run() {
        assert_eq!(drift(&trace(200, |k| 10.0 * k as f64)), Some((20, 200.0)));
        assert_eq!(drift(&trace(30, |k| if k < 28 { 0.0 } else { 3.0 })), Some((5, 3.0)));
        assert_eq!(drift(&trace(4, |k| k as f64)), None);
    }
}
