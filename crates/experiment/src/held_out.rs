//! Registration on held-out cases, made as a new user would: the phantom on a finer mesh (quadratic
//! tetrahedra), another law and another stiffness than every model (Neo-Hookean, E = 4.5 kPa,
//! ν = 0.49), pressed, lifted, dragged and pulled on both lobes, each seen once by the camera
//! (3,000 points). No setting of the registration or the networks was chosen on them. Each method
//! registers each case from rest, then again as a stream (the tool's force rising and falling over
//! [`STREAM_FRAMES`] frames, each warm-started from the last, as a navigation system streams them);
//! TRE at the phantom's markers, and the time of a frame (correspondence search included).

use std::path::Path;

use anyhow::{Context, Result};
use fem::material::kpa;
use fem::{Formulation, Law, Material};
use mesh::length::mm;
use mesh::stats::{max, mean, median};
use register::{NetworkDeformer, Organ};
use scenario::registration::{CaseMethod, MethodKind};
use scenario::CaseScenario;
use serde::Serialize;

use crate::loads::{CaseLoad, LEFT_LOBE_FRONT, RIGHT_LOBE};
use crate::{fmt, reference, ExperimentResult, Headline, Name, Progress, Row, Size};
use app::case::{
    ar_scenario, case_methods, compare, method_options, network_from_truth, shipped_models, synthetic_case, CaseFrame,
    Registered, SyntheticCase, SHIPPED_MODEL, SHIPPED_ROM,
};
use app::models::{network_model, Network, NETWORK_AFTER_FIT, POLISH_ITERATIONS};

/// The cases, fixed before any method was run on them.
pub(crate) const CASES: [CaseLoad; 7] = [
    CaseLoad { label: "press, left lobe, 2 N", force: 2.0, direction: [0.0, 0.0, -1.0], patch: None, seed: 21 },
    CaseLoad {
        label: "press, right lobe, 2.5 N",
        force: 2.5,
        direction: [0.0, 0.0, -1.0],
        patch: Some(RIGHT_LOBE),
        seed: 22,
    },
    CaseLoad { label: "lift, left lobe, 1.5 N", force: 1.5, direction: [0.0, 0.0, 1.0], patch: None, seed: 23 },
    CaseLoad {
        label: "drag along x, left lobe, 1.5 N",
        force: 1.5,
        direction: [1.0, 0.0, -0.3],
        patch: None,
        seed: 24,
    },
    CaseLoad {
        label: "drag along y, right lobe, 1.5 N",
        force: 1.5,
        direction: [0.0, 1.0, -0.2],
        patch: Some(RIGHT_LOBE),
        seed: 25,
    },
    CaseLoad {
        label: "press, front of the left lobe, 1.5 N",
        force: 1.5,
        direction: [0.0, 0.0, -1.0],
        patch: Some(LEFT_LOBE_FRONT),
        seed: 26,
    },
    CaseLoad {
        label: "oblique pull, left lobe, 1.5 N",
        force: 1.5,
        direction: [-0.5, 0.0, 1.0],
        patch: None,
        seed: 27,
    },
];

/// Points of each cloud (before the camera's outliers).
pub(crate) const POINTS: usize = 3000;

/// Frames of each case registered as a stream: the tool's force rises to the case's and falls
/// back (odd: the middle frame is the case's force), each frame seen anew and warm-started from
/// the last, as a navigation system streams them.
const STREAM_FRAMES: usize = 21;

/// The figure of each method registering the cases from rest.
const FROM_REST: &str = "from rest: TRE mean over the cases (largest), time per frame (median over the cases)";
/// The table of the cases registered from rest: a line per case, a column per method.
const CASE_FROM_REST: &str = "case, from rest: TRE mean / max, time per frame";

/// One method on one case.
#[derive(Clone, Debug, Default, Serialize)]
struct Outcome {
    /// TRE mean and largest (mm); `None` when the method failed.
    tre_mean_mm: Option<f64>,
    tre_max_mm: Option<f64>,
    /// Time of the frame in each run (ms).
    times_ms: Vec<f64>,
    /// The mean predicted σ at the targets (mm) and the share of the targets within 2σ, for a
    /// method that predicts σ.
    std_mean_mm: Option<f64>,
    within_two_std: Option<f64>,
    /// The warnings of its frames, when any (each cloud is the organ's: a warning says that the
    /// result is off, or is a false alarm).
    warnings: Vec<String>,
    /// Why it failed.
    error: Option<String>,
}

/// The warnings of a registration's frames: each frame's, in order (empty when none was flagged).
fn frame_warnings(r: &Registered) -> Vec<String> {
    r.outcomes.iter().flat_map(|o| o.registration.warnings.iter().cloned()).collect()
}

/// The words for the frames a method flagged (`flagged` of `frames`), none when it flagged none.
fn flagged(flagged: usize, frames: usize) -> String {
    match flagged {
        0 => String::new(),
        n => format!("; {n} of {frames} frames flagged"),
    }
}

/// The words for a method that failed on `failed` cases (none when it failed on none).
fn failures(failed: usize) -> String {
    match failed {
        0 => String::new(),
        n => format!("; failed on {n} of {} cases (not in these figures)", CASES.len()),
    }
}

/// The words for the predicted σ of a method over its cases (each case's mean σ in mm and share of
/// targets within 2σ): none for a method that predicts no σ.
fn coverage(cases: impl Iterator<Item = (Option<f64>, Option<f64>)>) -> String {
    let (std, within): (Vec<f64>, Vec<f64>) = cases.filter_map(|(s, w)| s.zip(w)).unzip();
    match std.is_empty() {
        true => String::new(),
        false => {
            format!("; σ {} mean, {:.0} % of the targets within 2σ", fmt(mean(&std), 2, "mm"), 100.0 * mean(&within))
        }
    }
}

/// One method on one case registered as a stream.
#[derive(Clone, Debug, Default, Serialize)]
struct StreamOutcome {
    /// TRE mean and largest at the peak frame (mm); `None` when the method failed.
    peak_tre_mean_mm: Option<f64>,
    peak_tre_max_mm: Option<f64>,
    /// TRE mean over all targets and frames (mm).
    tre_mean_mm: Option<f64>,
    /// Median time of a frame over the stream (ms).
    time_median_ms: f64,
    /// The mean predicted σ at the targets over the frames (mm) and the share within 2σ.
    std_mean_mm: Option<f64>,
    within_two_std: Option<f64>,
    /// The frames flagged by a warning (as from rest), and the first warning.
    flagged: usize,
    first_warning: Option<String>,
    /// Why it failed.
    error: Option<String>,
}

impl StreamOutcome {
    /// Its cell in a case's line, its time also over the run's reference (ms).
    fn cell(&self, reference_ms: f64) -> String {
        match (self.peak_tre_mean_mm, self.peak_tre_max_mm, self.tre_mean_mm, &self.error) {
            (Some(m), Some(x), Some(all), None) => format!(
                "{} / {}, {} over the frames, {}",
                fmt(m, 2, "mm"),
                fmt(x, 1, "mm"),
                fmt(all, 2, "mm"),
                reference::ms(self.time_median_ms, 0, Some(reference_ms))
            ),
            (.., e) => format!("failed ({})", e.as_deref().unwrap_or("no TRE")),
        }
    }
}

/// The methods of `scenario` (with `network`) on its case as a press and release of
/// [`STREAM_FRAMES`] frames, each frame warm-started from the last.
fn register_stream(scenario: &CaseScenario, networks: &[Network]) -> Result<Vec<StreamOutcome>> {
    let mut streamed = scenario.clone();
    streamed.truth.frames = STREAM_FRAMES;
    let stream = synthetic_case(&streamed)?;
    let compared = compare(&stream, &case_methods(&streamed, networks)?);
    Ok(compared
        .iter()
        .map(|c| match &c.result {
            Ok(r) => {
                let peak = r.peak(&stream).tre_mm();
                StreamOutcome {
                    peak_tre_mean_mm: peak.map(|p| p.0),
                    peak_tre_max_mm: peak.map(|p| p.1),
                    tre_mean_mm: r.summary.tre_mean_mm,
                    time_median_ms: r.summary.time_median_ms,
                    std_mean_mm: r.summary.target_std_mean_mm,
                    within_two_std: r.summary.within_two_std,
                    flagged: r.outcomes.iter().filter(|o| !o.registration.warnings.is_empty()).count(),
                    first_warning: frame_warnings(r).into_iter().next(),
                    error: None,
                }
            }
            Err(e) => StreamOutcome { error: Some(format!("{e}")), ..StreamOutcome::default() },
        })
        .collect())
}

impl Outcome {
    /// The median time of a frame over the runs (ms).
    fn time_ms(&self) -> f64 {
        median(&mut self.times_ms.clone())
    }
}

/// The truth of the held-out cases: the built-in case's, on about 5,000 T10 of Neo-Hookean tissue
/// (E = 4.5 kPa, ν = 0.49), its camera seeing [`POINTS`] points; its methods: the co-rotational FEM,
/// and the shipped network.
pub(crate) fn base_case() -> Result<CaseScenario> {
    let mut scenario = CaseScenario::builtin();
    scenario.truth.tets = 5000;
    scenario.truth.material =
        Material { order: 2, formulation: Formulation::Standard, ..Material::new(Law::NeoHookean, 4500.0, 0.49) };
    scenario.camera.points = POINTS;
    let polish = rom_polish(&scenario)?;
    let corotational = corotational(&scenario).cloned().context("the built-in case has no co-rotational FEM method")?;
    let network = scenario.models.method.iter().find(|m| m.kind == MethodKind::Network).cloned();
    scenario.models.method = std::iter::once(corotational).chain(network).chain([polish]).collect();
    Ok(scenario)
}

/// The hybrid of `scenario`'s reduced-order model and co-rotational FEM: the shape fit's
/// iterations from rest, then [`POLISH_ITERATIONS`] of the FEM.
pub(crate) fn rom_polish(scenario: &CaseScenario) -> Result<CaseMethod> {
    let corotational = corotational(scenario).context("the case has no co-rotational FEM method")?;
    Ok(CaseMethod {
        name: "ROM, then FEM polish".into(),
        kind: MethodKind::Hybrid,
        network_iterations: Some(register::shape::SHAPE_ITERATIONS),
        ..corotational.clone()
    })
}

/// The loop's settings of `scenario`'s network method (a network's defaults when it has none).
fn network_budget(scenario: &CaseScenario) -> register::RegistrationOptions {
    match scenario.models.method.iter().find(|m| m.kind == MethodKind::Network) {
        Some(spec) => method_options(scenario, spec),
        None => NetworkDeformer::loop_options(&scenario.registration),
    }
}

/// The co-rotational FEM method of `scenario`.
fn corotational(scenario: &CaseScenario) -> Option<&CaseMethod> {
    scenario
        .models
        .method
        .iter()
        .find(|m| m.kind == MethodKind::Fem && m.material.is_some_and(|m| m.law == Law::Corotational))
}

/// The mean motion (mm) of `case`'s markers from rest to `frame`'s truth: the TRE of not
/// deforming.
pub(crate) fn marker_motion_mm(case: &SyntheticCase, frame: &CaseFrame) -> f64 {
    mm(mean(&register::target_errors(&case.targets, &frame.truth)))
}

/// Runs the experiment; quick: the median of 3 runs per frame time, paper: of 10.
pub(crate) fn run(size: Size, _dir: &Path, progress: Progress) -> Result<ExperimentResult> {
    let runs = match size {
        Size::Quick => 3,
        Size::Paper => 10,
    };
    let reference_ms = reference::measure()?;
    let base = base_case()?;
    let (models, skipped) = shipped_models()?;
    let network_scenario = ar_scenario();
    let networks = Network::each(&models, &network_scenario, Path::new(""));
    // The U-Net the truth's surface motion is fed to (the diagnostic row).
    let oracle = networks.iter().find(|n| n.model.method() == learn::Method::UNet).map(network_model).transpose()?;
    let methods: Vec<String> = case_methods(&base, &networks)?.into_iter().map(|m| m.name).collect();
    let mut cases = Cases::new(methods.len(), reference_ms);
    for case in &CASES {
        cases.register(case, &base, &networks, &methods, oracle.as_ref(), runs, progress)?;
    }
    let mut summary =
        vec![Row::new(FROM_REST, fmt(mean(&cases.motion), 2, "mm"), "").of("registration", "no deformation")];
    let means = from_rest_rows(&methods, &cases.outcomes, reference_ms, &mut summary);
    let stream_means = stream_rows(&methods, &cases.streams, reference_ms, &mut summary);
    if !cases.from_truth.is_empty() {
        let (tre, largest): (Vec<f64>, Vec<f64>) = cases.from_truth.iter().copied().unzip();
        summary.push(
            Row::new(FROM_REST, format!("{} ({})", fmt(mean(&tre), 2, "mm"), fmt(max(&largest), 1, "mm")), "").of(
                "registration",
                "U-Net fed the truth's motion of its input nodes, no cloud (the network's error alone, not a method)",
            ),
        );
    }
    summary.extend(std::mem::take(&mut cases.rows));
    let headlines = headlines(&methods, &means, &stream_means);
    summary.extend(skipped.into_iter().map(|line| Row::new("learned model", line, "")));
    let notes = notes(&base, runs, reference_ms)?;
    let mut values = serde_json::Map::new();
    values.insert("reference_ms".into(), reference_ms.into());
    values.insert("cases".into(), serde_json::to_value(CASES.iter().map(|c| c.label).collect::<Vec<_>>())?);
    values.insert("no_deformation_tre_mm".into(), serde_json::to_value(&cases.motion)?);
    values.insert("network_from_truth_tre_mm".into(), serde_json::to_value(&cases.from_truth)?);
    for ((method, outcomes), stream) in methods.iter().zip(&cases.outcomes).zip(&cases.streams) {
        values.insert(method.clone(), serde_json::to_value(outcomes)?);
        values.insert(format!("{method}, stream"), serde_json::to_value(stream)?);
    }
    Ok(ExperimentResult {
        name: Name::HeldOut,
        size,
        seconds: 0.0,
        build: String::new(),
        headlines,
        rows: summary,
        figures: Vec::new(),
        page_figures: Vec::new(),
        notes,
        values,
    })
}

/// What the cases gave, as they are registered.
struct Cases {
    /// Per method, its outcome from rest on each case.
    outcomes: Vec<Vec<Outcome>>,
    /// Per method, its outcome on each case as a stream.
    streams: Vec<Vec<StreamOutcome>>,
    /// The markers' mean motion in each case (mm): the TRE of not deforming.
    motion: Vec<f64>,
    /// The network fed the truth's surface motion: TRE mean and max (mm) per case.
    from_truth: Vec<(f64, f64)>,
    /// The tables of the cases: from rest, and as streams (a line per case, a column per method).
    rows: Vec<Row>,
    /// The run's reference time (ms), which each time is also given over.
    reference_ms: f64,
}

impl Cases {
    /// No case yet, for `methods` methods, with the run's reference time (ms).
    fn new(methods: usize, reference_ms: f64) -> Cases {
        Cases {
            outcomes: vec![Vec::new(); methods],
            streams: vec![Vec::new(); methods],
            motion: Vec::new(),
            from_truth: Vec::new(),
            rows: Vec::new(),
            reference_ms,
        }
    }

    /// Simulates `case` (the `base` scenario under its load) and registers it with every method
    /// (named `methods`), `runs` times from rest and once as a stream; with an `oracle`, feeds the
    /// truth's surface motion to it too.
    #[allow(clippy::too_many_arguments)]
    fn register(
        &mut self,
        case: &CaseLoad,
        base: &CaseScenario,
        networks: &[Network],
        methods: &[String],
        oracle: Option<&(Organ, NetworkDeformer)>,
        runs: usize,
        progress: Progress,
    ) -> Result<()> {
        progress.line(&format!("simulating the case {}", case.label));
        let scenario = case.apply(base);
        let synthetic = synthetic_case(&scenario)?;
        let moved = marker_motion_mm(&synthetic, synthetic.peak());
        self.motion.push(moved);
        let mut here = vec![Outcome::default(); methods.len()];
        let specs = case_methods(&scenario, networks)?;
        for run in 0..runs {
            progress.line(&format!("registering the case {} ({}/{runs})", case.label, run + 1));
            // Each method set up anew: it registers from rest, with nothing kept from the last run.
            let compared = compare(&synthetic, &specs);
            for (outcome, c) in here.iter_mut().zip(&compared) {
                match &c.result {
                    Ok(r) => {
                        outcome.tre_mean_mm = r.summary.tre_mean_mm;
                        outcome.tre_max_mm = r.summary.tre_max_mm;
                        outcome.times_ms.push(r.summary.time_ms);
                        outcome.std_mean_mm = r.summary.target_std_mean_mm;
                        outcome.within_two_std = r.summary.within_two_std;
                        outcome.warnings = frame_warnings(r);
                    }
                    Err(e) => outcome.error = Some(format!("{e}")),
                }
            }
        }
        // A line per case in the table of cases from rest, a column per method.
        let label = format!("{} (markers move {} on average)", case.label, fmt(moved, 1, "mm"));
        for (method, o) in methods.iter().zip(&here) {
            let cell = match (o.tre_mean_mm, o.tre_max_mm, &o.error) {
                (Some(m), Some(x), None) => {
                    let time = reference::ms(o.time_ms(), 0, Some(self.reference_ms));
                    format!("{} / {}, {time}", fmt(m, 2, "mm"), fmt(x, 1, "mm"))
                }
                (_, _, e) => format!("failed ({})", e.as_deref().unwrap_or("no TRE")),
            };
            self.rows.push(Row::new(method, cell, "").of(CASE_FROM_REST, &label));
        }
        if let Some((organ, deformer)) = oracle {
            let errors = network_from_truth(&synthetic, organ, deformer)?;
            let (m, x) = (mm(mean(&errors)), mm(max(&errors)));
            let cell = format!("{} / {}", fmt(m, 2, "mm"), fmt(x, 1, "mm"));
            self.rows.push(Row::new("U-Net fed the truth's surface motion", cell, "").of(CASE_FROM_REST, &label));
            self.from_truth.push((m, x));
        }
        for (all, o) in self.outcomes.iter_mut().zip(here) {
            all.push(o);
        }
        progress
            .line(&format!("simulating and registering the case {} as a stream ({STREAM_FRAMES} frames)", case.label));
        let here = register_stream(&scenario, networks)?;
        // The table of the cases registered as streams: a line per case, a column per method.
        let case_as_stream = format!(
            "case, as a stream of {STREAM_FRAMES} frames: TRE at the peak mean / max, TRE over the frames, time per \
             frame (median)"
        );
        for (method, o) in methods.iter().zip(&here) {
            self.rows.push(Row::new(method, o.cell(self.reference_ms), "").of(&case_as_stream, case.label));
        }
        for (all, o) in self.streams.iter_mut().zip(here) {
            all.push(o);
        }
        Ok(())
    }
}

/// A summary row per method of its registrations from rest over the cases (times also over
/// `reference_ms`), pushed on `summary`; returns each method's mean TRE (NaN where it failed on a
/// case).
fn from_rest_rows(
    methods: &[String],
    outcomes: &[Vec<Outcome>],
    reference_ms: f64,
    summary: &mut Vec<Row>,
) -> Vec<f64> {
    let mut means = Vec::new();
    for (method, cases) in methods.iter().zip(outcomes) {
        let ok: Vec<&Outcome> = cases.iter().filter(|o| o.error.is_none() && o.tre_mean_mm.is_some()).collect();
        let tre: Vec<f64> = ok.iter().filter_map(|o| o.tre_mean_mm).collect();
        let largest: Vec<f64> = ok.iter().filter_map(|o| o.tre_max_mm).collect();
        let mut times: Vec<f64> = ok.iter().map(|o| o.time_ms()).collect();
        let failed = cases.len() - ok.len();
        let warned = ok.iter().filter(|o| !o.warnings.is_empty()).count();
        means.push(if failed == 0 { mean(&tre) } else { f64::NAN });
        summary.push(
            Row::new(
                FROM_REST,
                format!(
                    "{} ({}), {}{}{}{}",
                    fmt(mean(&tre), 2, "mm"),
                    fmt(max(&largest), 1, "mm"),
                    reference::ms(median(&mut times), 0, Some(reference_ms)),
                    coverage(ok.iter().map(|o| (o.std_mean_mm, o.within_two_std))),
                    flagged(warned, ok.len()),
                    failures(failed)
                ),
                "",
            )
            .of("registration", method),
        );
    }
    means
}

/// A summary row per method of its registrations as streams over the cases (times also over
/// `reference_ms`), pushed on `summary`; returns each method's mean TRE at the peak (NaN where it
/// failed on a case).
fn stream_rows(
    methods: &[String],
    streams: &[Vec<StreamOutcome>],
    reference_ms: f64,
    summary: &mut Vec<Row>,
) -> Vec<f64> {
    let as_streams = format!(
        "each case as a stream of {STREAM_FRAMES} frames: TRE at the peak mean over the cases (largest); TRE over \
         all frames; time per frame (median over the cases)"
    );
    let mut stream_means = Vec::new();
    for (method, cases) in methods.iter().zip(streams) {
        let ok: Vec<&StreamOutcome> =
            cases.iter().filter(|o| o.error.is_none() && o.peak_tre_mean_mm.is_some()).collect();
        let peak: Vec<f64> = ok.iter().filter_map(|o| o.peak_tre_mean_mm).collect();
        let largest: Vec<f64> = ok.iter().filter_map(|o| o.peak_tre_max_mm).collect();
        let all: Vec<f64> = ok.iter().filter_map(|o| o.tre_mean_mm).collect();
        let mut times: Vec<f64> = ok.iter().map(|o| o.time_median_ms).collect();
        let failed = cases.len() - ok.len();
        let warned = ok.iter().map(|o| o.flagged).sum();
        stream_means.push(if failed == 0 { mean(&peak) } else { f64::NAN });
        summary.push(
            Row::new(
                &as_streams,
                format!(
                    "{} ({}); {}; {}{}{}{}",
                    fmt(mean(&peak), 2, "mm"),
                    fmt(max(&largest), 1, "mm"),
                    fmt(mean(&all), 2, "mm"),
                    reference::ms(median(&mut times), 0, Some(reference_ms)),
                    coverage(ok.iter().map(|o| (o.std_mean_mm, o.within_two_std))),
                    flagged(warned, ok.len() * STREAM_FRAMES),
                    failures(failed)
                ),
                "",
            )
            .of("registration", method),
        );
    }
    stream_means
}

/// Each learned model's TRE against the co-rotational FEM's (the first method), from rest and as
/// streams; the models are the shipped ones, named so beside the networks other experiments train.
fn headlines(methods: &[String], means: &[f64], stream_means: &[f64]) -> Vec<Headline> {
    let mut headlines = Vec::new();
    for learned in ["U-Net", "ROM", "U-Net after the ROM's shape fit"] {
        let (Some(k), Some(&fem), Some(&fem_stream)) =
            (methods.iter().position(|m| m == learned), means.first(), stream_means.first())
        else {
            continue;
        };
        let named = format!("shipped {learned}");
        headlines.push(Headline::aim_lower(
            format!("held-out registration, {} cases: TRE {named} / co-rotational FEM", CASES.len()),
            format!("{} / {}", fmt(means[k], 2, "mm"), fmt(fem, 2, "mm")),
            format!("the {named} as accurate as the FEM"),
            means[k],
            fem,
        ));
        headlines.push(Headline::aim_lower(
            format!(
                "held-out registration as streams of {STREAM_FRAMES} frames, {} cases: TRE at the peak {named} / \
                 co-rotational FEM",
                CASES.len()
            ),
            format!("{} / {}", fmt(stream_means[k], 2, "mm"), fmt(fem_stream, 2, "mm")),
            format!("the {named} as accurate as the FEM"),
            stream_means[k],
            fem_stream,
        ));
    }
    headlines
}

/// The notes: the truth, the methods, the streams, the diagnostic row (`runs`: the runs per
/// frame time) and the reference time (`reference_ms`).
fn notes(base: &CaseScenario, runs: usize, reference_ms: f64) -> Result<Vec<String>> {
    let fem = corotational(base).and_then(|m| m.material).context("the held-out cases have no co-rotational FEM")?;
    Ok(vec![
        format!(
            "Truth: the built-in registration case's phantom of {} (quadratic tetrahedra), {}, \
             E = {} kPa, ν = {}: another mesh, element, law and stiffness than every model; fixed between the \
             lobes; one tool force per case as listed. Camera along {:?}: {POINTS} points, {} noise, {:.0} % \
             outliers; no correspondences. No setting was chosen on these cases, but {}.",
            base.truth.mesh_words(),
            base.truth.material.law.display_name(),
            kpa(base.truth.material.young),
            base.truth.material.poisson,
            base.camera.view,
            fmt(mm(base.camera.noise), 1, "mm"),
            100.0 * base.camera.outliers,
            crate::registration::RULE_COMPARED_ON_HELD_OUT
        ),
        format!(
            "Methods: the co-rotational FEM ({} T4, E = {} kPa, ν = {}), the shipped network ({SHIPPED_MODEL}) and \
             the shipped reduced-order model ({SHIPPED_ROM}): \"ROM\" fits the coefficients of its modes to the \
             cloud (its shape space, {} iterations coarse to fine, {} points matched per iteration), \"ROM, membrane \
             loop\" fits a membrane to the matches and predicts from it, as the U-Net does ({} iterations), \
             \"U-Net after the ROM's shape fit\" fits the reduced-order model's shape space, then lets the U-Net \
             predict from the surface that fit found ({NETWORK_AFTER_FIT} iteration of its loop), \
             \"ROM, then FEM polish\" fits the reduced-order model's shape space on the FEM's mesh (its modes \
             interpolated there), then takes {POLISH_ITERATIONS} iterations of the co-rotational FEM from that fit, its \
             data springs stiff at once (a hybrid); each registers each case from rest. Time per frame: the median \
             of {runs} runs \
             with fresh methods, correspondence search included; one machine, only as quiet as it was.",
            base.models.tets,
            kpa(fem.young),
            fem.poisson,
            register::shape::SHAPE_ITERATIONS,
            register::shape::SHAPE_POINTS,
            network_budget(base).iterations
        ),
        format!(
            "Streams: each case again as a press and release of {STREAM_FRAMES} frames, as a navigation system \
             streams them: frame k is pushed by F sin(πk/{}) (F the case's force, at the middle frame), each truth \
             solved from the last and seen anew by the camera (seed + k − 1). Each method registers frame 1 from \
             rest and every next frame warm-started from the last, with its warm budget (the FEM {} iterations, the \
             U-Net and \"ROM, membrane loop\" {}, \"ROM\" {} of its shape fit, all its modes under the model's \
             own prior; the U-Net after the shape fit {}: one of the fit from the last frame's posterior, then the \
             U-Net's loop; the hybrid's are its shape fit's, as \"ROM\"); the U-Net (both rows), \"ROM\" and \
             the hybrid match both ways on those frames: the surface they see over the cloud is matched to the \
             cloud as well. \
             TRE at the peak frame, and over all frames; time: the median over the stream's frames, one run.",
            STREAM_FRAMES + 1,
            corotational(base).and_then(|m| m.warm_iterations).unwrap_or(base.registration.warm_iterations),
            network_budget(base).warm_iterations,
            register::shape::SHAPE_WARM_ITERATIONS,
            app::models::NETWORK_AFTER_FIT_WARM_ITERATIONS,
        ),
        "Diagnostic, not a method: the network fed the truth's own motion of its input nodes (each node takes \
         the motion of the truth's surface point nearest to it), as if the whole visible surface were seen and \
         fitted without error. What it leaves is the network's own error; the rest of the registered U-Net's is \
         the cloud's and the surface fit's."
            .into(),
        reference::note(Some(reference_ms)),
    ])
}
