//! Scenarios 5 and 6: ROUKF identification of Young's modulus and of boundary springs, run on
//! the shipped scenarios with synthetic observations.

use std::path::Path;

use anyhow::{bail, Context, Result};
use app::assimilation::{Experiment, ObservationFiles, Report, Setup};
use filter::Discrepancy;
use mesh::length::{mm, LengthUnit};
use scenario::assimilation::ReferenceSpec;
use scenario::{AssimilationScenario, MeshSource};

use crate::{fmt, reference, write_scenario, ExperimentResult, Headline, Name, Progress, Row, Size, Tenths};

/// Tetrahedra of the reference phantoms that make the observations (the published liver size for the Young's-modulus experiment;
/// about 2.6 times the model's for the springs experiment).
const YOUNG_REFERENCE_TETS: usize = 11_000;
const SPRINGS_REFERENCE: Phantom = Phantom::linear(3_000);
/// The ROUKF Young's modulus experiment again with the filter's model at the published liver size, observed on a finer phantom.
const YOUNG_PUBLISHED_MODEL_TETS: usize = 11_000;
const YOUNG_PUBLISHED_REFERENCE_TETS: usize = 20_000;
/// The ROUKF Young's modulus experiment again observed on quadratic tetrahedra (T10, F-bar at the scenario's ν) built
/// from a phantom of this size: another mesh and another element, about 7.5 % off a converged solution under a small
/// load (`augsim experiment fem-convergence`), where linear tetrahedra are 24–41 % off.
const YOUNG_QUADRATIC_REFERENCE: Phantom = Phantom { tets: 3_000, order: 2 };
/// The ROUKF Young's modulus experiment again with the filter's model on quadratic tetrahedra built from a coarse
/// phantom (about as many unknowns as the scenario's linear model), observed on [`YOUNG_QUADRATIC_REFERENCE`].
const YOUNG_QUADRATIC_MODEL: Phantom = Phantom { tets: 1_150, order: 2 };

/// A phantom of the identification experiments: its tetrahedra, and its element order (1, or 2 for T10).
#[derive(Clone, Copy)]
struct Phantom {
    tets: usize,
    order: u8,
}

impl Phantom {
    const fn linear(tets: usize) -> Phantom {
        Phantom { tets, order: 1 }
    }
}

/// The reference run behind a filter's observations: its phantom, and the directory of its tracks (shared by
/// every filter run that observes the same phantom).
struct Reference<'a> {
    phantom: Phantom,
    tracks: &'a Path,
}

/// Identification without inverse crime: synthetic tracks from the shipped scenario run on the `reference` phantom
/// (in its tracks directory, reused when a completed earlier run with the same scenario, phantom and executable left
/// them there), then the filter on the scenario's own mesh (or the `model` phantom) fed those tracks (`dir/run`)
/// and, with `discrepancy`, again with a systematic model-discrepancy allowance (`dir/run-discrepancy`);
/// `iterations` overrides the scenario's. Returns the reports (plain, then with the allowance), the model's setup
/// and the reference mesh (its cells and element, e.g. "10795 T4").
fn assimilate(
    dir: &Path,
    name: &str,
    reference: &Reference,
    model: Option<Phantom>,
    iterations: Option<usize>,
    discrepancy: bool,
    progress: Progress,
) -> Result<(Vec<Report>, Setup, String)> {
    let (path, text) = write_scenario(dir, name)?;
    let (mut scenario, scenario_dir) = AssimilationScenario::load(&path)?;
    scenario.iterations = iterations.or(scenario.iterations);
    if let Some(model) = model {
        let MeshSource::Phantom { tets } = &mut scenario.mesh else {
            bail!("{name}: another phantom size needs the built-in phantom mesh");
        };
        *tets = model.tets;
        scenario.material.order = model.order;
    }
    let law = scenario.reference.as_ref().and_then(|r| r.law);
    let reference_phantom = reference.phantom;
    let (reference_tets, order) = (reference_phantom.tets, Some(reference_phantom.order));
    let tracks = reference.tracks;
    scenario.reference = Some(ReferenceSpec { mesh: MeshSource::Phantom { tets: reference_tets }, law, order });
    let reference = scenario.reference_scenario().context("the reference section was just set")?;
    let stamp = tracks.join("complete.txt");
    // The reference mesh's own cell count (the mesher reaches about the requested size).
    let cells_file = tracks.join("reference_cells.txt");
    let key = format!(
        "{text}\n# reference phantom {reference_tets} T4, order {}, iterations {:?}, executable {}\n",
        reference_phantom.order,
        reference.iterations,
        executable_stamp()
    );
    if std::fs::read_to_string(&stamp).is_ok_and(|k| k == key) && cells_file.exists() {
        progress.line(&format!(
            "{name}: reference tracks of a {reference_tets}-tet phantom reused from {}",
            tracks.display()
        ));
    } else {
        progress.line(&format!("{name}: reference run on a {reference_tets}-tet phantom"));
        match std::fs::remove_file(&stamp) {
            Err(e) if e.kind() != std::io::ErrorKind::NotFound => {
                return Err(e).with_context(|| format!("cannot remove {}", stamp.display()));
            }
            _ => {}
        }
        let run = Experiment::prepare(reference, &scenario_dir, None)?;
        run.write_tracks(tracks)?;
        mesh::io::write_atomic_bytes(&cells_file, run.setup().cells.to_string().as_bytes())?;
        mesh::io::write_atomic_bytes(&stamp, key.as_bytes())?;
    }
    let reference_cells: usize = std::fs::read_to_string(&cells_file)
        .with_context(|| format!("reading {}", cells_file.display()))?
        .trim()
        .parse()
        .with_context(|| format!("{}: not a cell count", cells_file.display()))?;
    let files = ObservationFiles {
        observations: tracks.join("observations.csv"),
        features: None,
        // The scenario's own [[tool]] moves the model, as it moved the reference: no tool tracks as controls.
        controls: None,
        assessment: Some(tracks.join("assessment.csv")).filter(|p| p.exists()),
        known_truth: true,
        units: LengthUnit::Metre,
    };
    let mut reports = Vec::new();
    let mut setup = None;
    let variants: &[(&str, Discrepancy)] = if discrepancy {
        &[("run", Discrepancy::None), ("run-discrepancy", Discrepancy::Systematic)]
    } else {
        &[("run", Discrepancy::None)]
    };
    for &(run, kind) in variants {
        let mut scenario = scenario.clone();
        scenario.filter.discrepancy = kind;
        let experiment = Experiment::prepare(scenario, &scenario_dir, Some(&files))?;
        let tenths = Tenths::new(progress, format!("{name} ({run})"), "iterations");
        reports.push(experiment.run(&dir.join(run), &tenths)?);
        setup.get_or_insert_with(|| experiment.setup().clone());
    }
    let element = if reference_phantom.order == 2 { "T10" } else { "T4" };
    Ok((reports, setup.context("no filter run")?, format!("{reference_cells} {element}")))
}

/// Size and modification time of the running executable: reference tracks made by another build are not reused.
fn executable_stamp() -> String {
    let meta = std::env::current_exe().and_then(std::fs::metadata);
    match meta.as_ref().map(|m| (m.len(), m.modified())) {
        Ok((len, Ok(t))) => format!("{len} bytes, modified {t:?}"),
        _ => "unknown".into(),
    }
}

/// The raw numbers of a filter run: its report and the run's reference time (ms).
fn values(report: &Report, reference_ms: f64) -> Result<serde_json::Map<String, serde_json::Value>> {
    let mut values = serde_json::Map::new();
    values.insert("report".into(), serde_json::to_value(report)?);
    values.insert("reference_ms".into(), reference_ms.into());
    Ok(values)
}

/// The figures of one filter run of the Young's modulus experiment (`reference_mesh`: the
/// reference's mesh in words; `reference_ms`: the run's reference time), as rows of that run.
fn filter_run_rows(run: &str, report: &Report, reference_mesh: &str, reference_ms: f64) -> Result<Vec<Row>> {
    let y = report.young.as_ref().context("the Young scenario reported no Young's modulus")?;
    let truth = y.truth.context("the reference run's modulus is the truth")?;
    let mut figures = vec![
        Row::new("model / reference", format!("{} nodes / {reference_mesh}", report.nodes), ""),
        Row::new("estimated E (mean ± σ)", format!("{:.0} ± {:.0} Pa", y.mean, y.std), "4,992 ± 15 Pa"),
        Row::new(
            "error against the truth",
            fmt(100.0 * (y.mean - truth) / truth, 2, "%"),
            "−0.16 % (from 4,992 ± 15 Pa)",
        ),
        Row::new("|error| / σ", format!("{:.1}", (y.mean - truth).abs() / y.std), "0.5 (from 4,992 ± 15 Pa)"),
    ];
    if let (Some(noise), Some(misfit)) = (y.noise_std, y.misfit) {
        figures.push(Row::new("noise-only σ, misfit χ²/ν", format!("{noise:.0} Pa, {misfit:.3}"), ""));
    }
    figures.extend([
        Row::new(
            "within 1 % from iteration",
            y.within_1_percent_from_iteration.map_or("never".into(), |k| k.to_string()),
            "",
        ),
        filter_time_row(report, reference_ms, "500 s for 631 iterations"),
    ]);
    Ok(figures.into_iter().map(|row| row.of("filter run", run)).collect())
}

/// The row of a filter run's time, with its multiple of the run's reference time.
fn filter_time_row(report: &Report, reference_ms: f64, published: &str) -> Row {
    let time = reference::seconds(report.filter_seconds, 1, Some(reference_ms));
    Row::new("filter time", format!("{time} for {} iterations", report.iterations), published)
}

/// The headlines of the Young's modulus experiment: the error and the time of the scenario's run
/// (`reference_mesh`: its reference's mesh in words; `reference_ms`: the run's reference time).
fn young_headlines(report: &Report, reference_mesh: &str, reference_ms: f64) -> Result<Vec<Headline>> {
    let y = report.young.as_ref().context("the Young scenario reported no Young's modulus")?;
    let truth = y.truth.context("the reference run's modulus is the truth")?;
    Ok(vec![
        Headline::lower_is_better(
            format!(
                "ROUKF Young's modulus: error of the estimate ({}-node model, {reference_mesh} reference)",
                report.nodes
            ),
            100.0 * (y.mean - truth).abs() / truth,
            0.16,
            2,
            "%",
        ),
        Headline {
            ours: reference::seconds(report.filter_seconds, 1, Some(reference_ms)),
            ..Headline::lower_is_better(
                format!("ROUKF Young's modulus: filter time ({} iterations; published 631)", report.iterations),
                report.filter_seconds,
                500.0,
                1,
                "s",
            )
        },
    ])
}

/// The ROUKF Young's modulus experiment (quick: 200 filter iterations; paper: the scenario's 600).
pub(crate) fn young(size: Size, dir: &Path, progress: Progress) -> Result<ExperimentResult> {
    let iterations = match size {
        Size::Quick => Some(200),
        Size::Paper => None,
    };
    let reference_ms = reference::measure()?;
    let young = "roukf_young";
    let reference = Reference { phantom: Phantom::linear(YOUNG_REFERENCE_TETS), tracks: &dir.join("reference-tracks") };
    let (reports, setup, reference_mesh) = assimilate(dir, young, &reference, None, iterations, true, progress)?;
    let fine_dir = dir.join(format!("model-{YOUNG_PUBLISHED_MODEL_TETS}"));
    let fine_reference = Reference {
        phantom: Phantom::linear(YOUNG_PUBLISHED_REFERENCE_TETS),
        tracks: &fine_dir.join("reference-tracks"),
    };
    let model = Some(Phantom::linear(YOUNG_PUBLISHED_MODEL_TETS));
    let (fines, _, fine_reference_mesh) =
        assimilate(&fine_dir, young, &fine_reference, model, iterations, true, progress)?;
    // One quadratic reference run, observed by the linear model and by the quadratic one.
    let quadratic_dir = dir.join("reference-t10");
    let quadratic_reference =
        Reference { phantom: YOUNG_QUADRATIC_REFERENCE, tracks: &quadratic_dir.join("reference-tracks") };
    let (quadratics, _, quadratic_reference_mesh) =
        assimilate(&quadratic_dir, young, &quadratic_reference, None, iterations, true, progress)?;
    let model = Some(YOUNG_QUADRATIC_MODEL);
    let (quadratic_models, _, _) =
        assimilate(&dir.join("model-t10"), young, &quadratic_reference, model, iterations, true, progress)?;
    let (report, honest) = (&reports[0], &reports[1]);
    let (fine, fine_honest) = (&fines[0], &fines[1]);
    let (quadratic, quadratic_honest) = (&quadratics[0], &quadratics[1]);
    let (quadratic_model, quadratic_model_honest) = (&quadratic_models[0], &quadratic_models[1]);
    let mut rows = Vec::new();
    let runs = [
        ("scenario's model and reference", report, &reference_mesh),
        ("scenario's model and reference, systematic discrepancy", honest, &reference_mesh),
        ("11k model", fine, &fine_reference_mesh),
        ("11k model, systematic discrepancy", fine_honest, &fine_reference_mesh),
        ("T10 reference", quadratic, &quadratic_reference_mesh),
        ("T10 reference, systematic discrepancy", quadratic_honest, &quadratic_reference_mesh),
        ("T10 model and reference", quadratic_model, &quadratic_reference_mesh),
        ("T10 model and reference, systematic discrepancy", quadratic_model_honest, &quadratic_reference_mesh),
    ];
    for (run, report, reference_mesh) in runs {
        rows.extend(filter_run_rows(run, report, reference_mesh, reference_ms)?);
    }
    let headlines = young_headlines(report, &reference_mesh, reference_ms)?;
    Ok(ExperimentResult {
        headlines,
        name: Name::Young,
        size,
        seconds: 0.0,
        build: String::new(),
        rows,
        figures: vec!["run/young.png".into(), "run/young_zoom.png".into(), "run/innovation.png".into()],
        page_figures: Vec::new(),
        notes: vec![
            format!(
                "No inverse crime: the observations ({} noisy surface features) come from a reference run \
                 with E = {:.0} Pa on a phantom of {reference_mesh}; the filter's model is the \
                 scenario's {}-node phantom, on whose surface {} features outside it were located, keeping their offset (at most {:.2} mm). \
                 {} sigma points. Published: ~11,000-tet liver.",
                setup.features,
                report.young.as_ref().and_then(|y| y.truth).unwrap_or(f64::NAN),
                report.nodes,
                setup.projected,
                mm(setup.max_projection),
                report.sigma_points
            ),
            format!(
                "The '11k model' rows: the same scenario with the filter's model a phantom of about \
                 {YOUNG_PUBLISHED_MODEL_TETS} T4 (the published size, {} nodes) observed on one of {fine_reference_mesh}. The \
                 error is the model error of the filter's mesh (the same loads move the coarser phantom more or \
                 less than the finer one); σ only reflects the observation noise, and it shrinks with the \
                 number of observations while that bias stays.",
                fine.nodes
            ),
            format!(
                "The 'T10 reference' rows: the same filter on the scenario's model, observed on quadratic tetrahedra \
                 (T10, F-bar) built from a phantom of {quadratic_reference_mesh}: another mesh and another element, \
                 much closer to a converged solution than linear tetrahedra (by how much: fem-convergence). The \
                 error is then mostly the model error \
                 of the filter's linear tetrahedra, which are stiffer than the converged solid. The 'T10 model and \
                 reference' rows: the filter's model is quadratic too, built from a phantom of about {} T4 ({} nodes, \
                 about as many unknowns as the scenario's linear model).",
                YOUNG_QUADRATIC_MODEL.tets,
                quadratic_model.nodes
            ),
            "The attachment and the push are regions of space (an elastic foundation over the phantom's `fixed` \
             ball, a traction over the visible boundary inside its `push` ball), so the model and every reference \
             solve the same problem and differ only by their discretisation."
                .into(),
            "The 'systematic discrepancy' rows: the same filter runs ([filter] discrepancy = \"systematic\", \
             d = 1, in run-discrepancy/) with an allowance for model error added to σ: the misfit at the estimate \
             beyond the observation noise, over the frames whose sigma points came near it (not the start-up's, \
             taken far off), assumed able to lie wholly along the modulus' sensitivity (σ² += excess χ² × the \
             inverse information). The estimate is the plain filter's. A model error that looks like another \
             modulus (linear tetrahedra stiffer throughout) leaves no misfit beyond the noise, and so no allowance."
                .into(),
            "The scenario (roukf_young.toml) is written beside the result.".into(),
            reference::note(Some(reference_ms)),
        ],
        values: {
            let mut v = values(report, reference_ms)?;
            v.insert("discrepancy_report".into(), serde_json::to_value(honest)?);
            v.insert("published_size_report".into(), serde_json::to_value(fine)?);
            v.insert("published_size_discrepancy_report".into(), serde_json::to_value(fine_honest)?);
            v.insert("quadratic_reference_report".into(), serde_json::to_value(quadratic)?);
            v.insert("quadratic_reference_discrepancy_report".into(), serde_json::to_value(quadratic_honest)?);
            v.insert("quadratic_model_report".into(), serde_json::to_value(quadratic_model)?);
            v.insert("quadratic_model_discrepancy_report".into(), serde_json::to_value(quadratic_model_honest)?);
            v
        },
    })
}

/// The ROUKF boundary springs experiment (the scenario's 300 iterations at both sizes: it takes seconds).
pub(crate) fn springs(size: Size, dir: &Path, progress: Progress) -> Result<ExperimentResult> {
    let reference_ms = reference::measure()?;
    let reference = Reference { phantom: SPRINGS_REFERENCE, tracks: &dir.join("reference-tracks") };
    let (reports, setup, reference_mesh) = assimilate(dir, "roukf_springs", &reference, None, None, false, progress)?;
    let report = &reports[0];
    let error = |label: &str| {
        report
            .assessment
            .iter()
            .find(|c| c.label == label)
            .map_or("—".to_string(), |c| fmt(mm(c.mean_error), 3, "mm"))
    };
    let s = report.springs.as_ref().context("the springs scenario reported no springs")?;
    let mut rows = vec![
        Row::new("assessment error, estimated springs", error("estimated"), "lower than fixed and free"),
        Row::new("assessment error, fixed attachment", error("fixed"), ""),
        Row::new("assessment error, free attachment", error("free"), ""),
    ];
    if let (Some(rms), Some(truth)) = (s.rms_error, &s.truth) {
        // The scale of the error: the reference run's stiffnesses.
        let (lo, hi) = truth.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &k| (lo.min(k), hi.max(k)));
        rows.push(Row::new(
            format!("spring stiffness RMS error (true: {lo:.0} to {hi:.0} N/m)"),
            fmt(rms, 2, "N/m"),
            "",
        ));
    }
    rows.push(filter_time_row(report, reference_ms, ""));
    let mean_error = |label: &str| report.assessment.iter().find(|c| c.label == label).map(|c| c.mean_error);
    let holds = match (mean_error("estimated"), mean_error("fixed"), mean_error("free")) {
        (Some(e), Some(fixed), Some(free)) => e < fixed && e < free,
        _ => false,
    };
    let headlines = vec![Headline::finding(
        "ROUKF boundary springs: assessment error of the estimated springs",
        format!("{} (fixed {}, free {})", error("estimated"), error("fixed"), error("free")),
        "lower than fixed and free",
        holds,
    )];
    Ok(ExperimentResult {
        headlines,
        name: Name::Springs,
        size,
        seconds: 0.0,
        build: String::new(),
        rows,
        figures: vec!["run/springs.png".into(), "run/springs_final.png".into(), "run/assessment.png".into()],
        page_figures: Vec::new(),
        notes: vec![
            format!(
                "{} springs on the hidden surface of a {}-node phantom, a tool prescribing displacement on a small \
             visible area (on each mesh its own nodes nearest the tool). No inverse crime: observations and \
             assessment points come from a reference run on a phantom of {reference_mesh} ({} points located \
             on the model's surface, keeping their offset, at most {:.2} mm); assessment errors are means over the run at {} internal \
             markers.",
                s.stiffness.len(),
                report.nodes,
                setup.projected,
                mm(setup.max_projection),
                setup.assessment_points
            ),
            reference::note(Some(reference_ms)),
        ],
        values: values(report, reference_ms)?,
    })
}
