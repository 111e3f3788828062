//! Scenarios 5 and 6: ROUKF identification of Young's modulus and of boundary springs, run on
//! the shipped scenarios with synthetic observations.

use std::path::Path;

use anyhow::{Context, Result};
use filter::assimilation::{AssimilationScenario, Experiment, Report};

use crate::{fmt, write_scenario, ExperimentResult, Name, Progress, Row, Size};

const YOUNG: &str = include_str!("../../../scenarios/roukf_young.toml");
const SPRINGS: &str = include_str!("../../../scenarios/roukf_springs.toml");

/// Runs a shipped assimilation scenario in `dir` (`iterations` overrides the scenario's).
fn assimilate(dir: &Path, file: &str, text: &str, iterations: Option<usize>, progress: Progress) -> Result<Report> {
    let path = write_scenario(dir, file, text)?;
    let (mut scenario, scenario_dir) = AssimilationScenario::load(&path)?;
    if iterations.is_some() {
        scenario.iterations = iterations;
    }
    let experiment = Experiment::prepare(scenario, &scenario_dir, None)?;
    let total = experiment.setup().iterations;
    let mut last = 0;
    let report = experiment.run(&dir.join("run"), |p| {
        if p.iteration >= last + total.div_ceil(10) || p.iteration == total {
            last = p.iteration;
            progress(&format!("{file}: iteration {}/{total} {}", p.iteration, p.message));
        }
    })?;
    Ok(report)
}

fn values(report: &Report) -> Result<serde_json::Map<String, serde_json::Value>> {
    let mut values = serde_json::Map::new();
    values.insert("report".into(), serde_json::to_value(report)?);
    Ok(values)
}

/// Scenario 5 (quick: 200 filter iterations; paper: the scenario's 600).
pub(crate) fn young(size: Size, dir: &Path, progress: Progress) -> Result<ExperimentResult> {
    let iterations = match size {
        Size::Quick => Some(200),
        Size::Paper => None,
    };
    let report = assimilate(dir, "roukf_young.toml", YOUNG, iterations, progress)?;
    let y = report.young.as_ref().context("the Young scenario reported no Young's modulus")?;
    let truth = y.truth.context("synthetic observations carry the true modulus")?;
    let rows = vec![
        Row::new("estimated E (mean ± σ)", format!("{:.0} ± {:.0} Pa", y.mean, y.std), "4,992 ± 15 Pa"),
        Row::new("error against the truth", fmt(100.0 * (y.mean - truth) / truth, 2, "%"), "−0.16 %"),
        Row::new("|error| / σ", format!("{:.1}", (y.mean - truth).abs() / y.std), "0.5"),
        Row::new(
            "within 1 % from iteration",
            y.within_1_percent_from_iteration.map_or("never".into(), |k| k.to_string()),
            "",
        ),
        Row::new(
            "filter time",
            format!("{} for {} iterations", fmt(report.filter_seconds, 1, "s"), report.iterations),
            "500 s for 631 iterations",
        ),
    ];
    Ok(ExperimentResult {
        name: Name::Young,
        title: "Scenario 5: Young's modulus by ROUKF".into(),
        size,
        seconds: 0.0,
        rows,
        figures: vec!["run/young.png".into(), "run/young_zoom.png".into(), "run/innovation.png".into()],
        notes: vec![
            format!(
                "Synthetic observations from the scenario's reference run (true E = {truth:.0} Pa), {} nodes; \
                 prior 1,000 ± 200 Pa; {} sigma points. Published: ~11,000-tet liver.",
                report.nodes, report.sigma_points
            ),
            "The scenario (roukf_young.toml) is written beside the result.".into(),
        ],
        values: values(&report)?,
    })
}

/// Scenario 6 (the scenario's 300 iterations at both sizes: it takes seconds).
pub(crate) fn springs(size: Size, dir: &Path, progress: Progress) -> Result<ExperimentResult> {
    let report = assimilate(dir, "roukf_springs.toml", SPRINGS, None, progress)?;
    let error = |label: &str| {
        report
            .assessment
            .iter()
            .find(|c| c.label == label)
            .map_or("—".to_string(), |c| fmt(1e3 * c.mean_error, 3, "mm"))
    };
    let s = report.springs.as_ref().context("the springs scenario reported no springs")?;
    let mut rows = vec![
        Row::new("assessment error, estimated springs", error("estimated"), "lower than fixed and free"),
        Row::new("assessment error, fixed attachment", error("fixed"), ""),
        Row::new("assessment error, free attachment", error("free"), ""),
    ];
    if let Some(rms) = s.rms_error {
        rows.push(Row::new("spring stiffness RMS error", fmt(rms, 2, "N/m"), ""));
    }
    rows.push(Row::new(
        "filter time",
        format!("{} for {} iterations", fmt(report.filter_seconds, 1, "s"), report.iterations),
        "",
    ));
    Ok(ExperimentResult {
        name: Name::Springs,
        title: "Scenario 6: boundary springs by ROUKF".into(),
        size,
        seconds: 0.0,
        rows,
        figures: vec!["run/springs.png".into(), "run/springs_final.png".into(), "run/assessment.png".into()],
        notes: vec![format!(
            "{} springs on the hidden surface of a {}-node phantom, a tool prescribing displacement on a small \
             visible area, synthetic observations; assessment errors are means over the run at 3 internal markers.",
            s.stiffness.len(),
            report.nodes
        )],
        values: values(&report)?,
    })
}
