//! The augmented-reality registration experiment: the augmented-reality network trained from the shipped scenario, then
//! registration of synthetic intraoperative clouds with it and with two FEM models; the TRE
//! at the phantom's internal markers.

use std::path::Path;

use crate::loads::{CaseLoad, LEFT_LOBE_FRONT, RIGHT_LOBE};
use anyhow::{Context, Result};
use app::case::{case_methods, compare, synthetic_case};
use app::models::Network;
use app::sample_view::sample_on_mesh;
use learn::{Compute, Corruption, EvalReport, Model, PointErrors};
use mesh::length::mm;
use mesh::stats::{max, mean};
use scenario::CaseScenario;

use crate::held_out::{marker_motion_mm, rom_polish};
use crate::learning::{dataset, error_histogram, fit_rom, prediction_seconds, train, Generated, Recipe, Trained};
use crate::{fmt, reference, ExperimentResult, Headline, Name, Progress, Row, Size};

use app::case::AR_SCENARIO as LIVER_AR;

/// The case the registration settings were chosen on (with the same patch at 1, 2 and 2.5 N):
/// reported apart.
const DESIGN: CaseLoad = CaseLoad { label: "1.5 N down, left lobe", force: 1.5, direction: DOWN, patch: None, seed: 1 };

const DOWN: [f64; 3] = [0.0, 0.0, -1.0];

/// Held-out cases, fixed before any was registered: an oblique push, another spot of the left
/// lobe, the right lobe, and a harder push of the design spot. The figures beside the published
/// ones are over these only.
const HELD_OUT: [CaseLoad; 4] = [
    CaseLoad { label: "1.75 N oblique, left lobe", force: 1.75, direction: [0.4, 0.0, -1.0], patch: None, seed: 11 },
    CaseLoad { label: "2.5 N down, right lobe", force: 2.5, direction: DOWN, patch: Some(RIGHT_LOBE), seed: 12 },
    CaseLoad {
        label: "1.5 N down, left lobe front",
        force: 1.5,
        direction: DOWN,
        patch: Some(LEFT_LOBE_FRONT),
        seed: 13,
    },
    CaseLoad { label: "3 N down, left lobe", force: 3.0, direction: DOWN, patch: None, seed: 14 },
];

/// Cases beyond pushes, what surgery also does: a lift, a drag and a pull, each on another spot
/// than the held-out suite's (`augsim experiment held-out`). With the design case, they are the
/// cases a network is chosen on; the held-out pushes above stay held out.
const BEYOND_PUSHES: [CaseLoad; 3] = [
    CaseLoad {
        label: "1.5 N up, right lobe",
        force: 1.5,
        direction: [0.0, 0.0, 1.0],
        patch: Some(RIGHT_LOBE),
        seed: 15,
    },
    CaseLoad {
        label: "1.5 N drag along -y, left lobe front",
        force: 1.5,
        direction: [0.0, -1.0, -0.3],
        patch: Some(LEFT_LOBE_FRONT),
        seed: 16,
    },
    CaseLoad { label: "1.2 N oblique pull, left lobe", force: 1.2, direction: [0.5, 0.3, 1.0], patch: None, seed: 17 },
];

/// What a case is for.
#[derive(Clone, Copy, PartialEq)]
enum Role {
    Design,
    HeldOut,
    BeyondPushes,
}

/// One registration method's figures over the cases.
#[derive(Default)]
struct MethodTre {
    method: String,
    /// TRE mean and max (mm) and time per frame (ms), one per held-out case.
    means: Vec<f64>,
    maxima: Vec<f64>,
    times: Vec<f64>,
    /// TRE mean and max (mm) on the design case.
    design: (f64, f64),
    /// TRE mean and max (mm) on each case beyond pushes (NaN where the method failed).
    beyond: Vec<(f64, f64)>,
    /// Held-out cases on which the method failed (not in the figures above), with the error.
    failures: Vec<String>,
}

/// The published figure of a method (text, and its mean TRE in mm where one was published).
fn published(method: &str) -> (&'static str, Option<f64>) {
    match method {
        m if m.starts_with("U-Net") => ("2.92 mm (max 5.3 mm), a few ms", Some(2.92)),
        m if m.contains("co-rotational") => ("3.79 mm, ~25 ms", Some(3.79)),
        m if m.contains("SVK") => ("≈ the U-Net's, 1,550 ms", None),
        _ => ("", None),
    }
}

/// The figure of each registration method on the held-out cases.
const HELD_OUT_TRE: &str = "held-out cases: TRE mean (max), time per frame";

/// Quick: 400 samples, 1,500 steps; paper: the shipped network's recipe (2,000 samples, 48,000 steps).
pub(crate) fn liver_ar(size: Size, dir: &Path, progress: Progress) -> Result<ExperimentResult> {
    let (samples, iterations) = match size {
        Size::Quick => (400, 1500),
        Size::Paper => (2000, 48000),
    };
    let data = dataset(dir, LIVER_AR, samples, progress)?;
    let recipe = Recipe {
        corruption: Corruption { noise_std: 5e-4, ..Corruption::default() },
        ..Recipe::new(iterations, samples / 10, samples / 5)
    };
    let t = train(&data.dataset, dir, &recipe, progress)?;
    // The reduced-order model on the same split, trained on inputs as noisy as the U-Net's.
    progress.line("fitting the reduced-order model");
    let config = learn::rom::RomConfig { noise_copies: 2, corruption: recipe.corruption.clone(), ..Default::default() };
    let (fitted, _, rom_seconds) = fit_rom(&data, &t, &config, false)?;
    let rom = Model::Reduced(fitted);
    let test = TestFigures::new(&data, &t, &rom, rom_seconds)?;
    error_histogram(
        &dir.join("errors.png"),
        "Augmented-reality registration: test-sample errors",
        &[("U-Net", &test.report), ("reduced-order model", &test.rom_report)],
    )?;
    write_test_viewer(dir, &data, &t)?;

    // The shipped comparison case (its camera, truth, registration settings and methods, and the
    // reduced-order model polished by the co-rotational FEM) under each load.
    let mut builtin = CaseScenario::builtin();
    builtin.models.method.push(rom_polish(&builtin)?);
    let networks = [&t.model, &rom].map(|model| Network { model, scenario: &data.scenario, dir: &data.scenario_dir });
    let cases = register_cases(&builtin, &networks, progress)?;
    let per_method = &cases.per_method;
    let mut rows = test.rows(iterations);
    rows.push(Row::new(HELD_OUT_TRE, fmt(mean(&cases.no_motion), 2, "mm"), "").of("registration", "no deformation"));
    rows.extend(method_rows(per_method, test.reference_ms));
    let headlines = per_method
        .iter()
        .filter_map(|m| {
            let value = published(&m.method).1?;
            let figure = format!("registration TRE, {} ({} held-out cases)", m.method, HELD_OUT.len());
            // A method that failed on a case has no mean over the cases (not the mean of the others).
            let tre = if m.failures.is_empty() { mean(&m.means) } else { f64::NAN };
            Some(Headline::lower_is_better(figure, tre, value, 2, "mm"))
        })
        .collect();
    rows.extend(cases.rows);
    tre_chart(dir, per_method, cases.marker_count)?;
    let mut values = test.values()?;
    for m in per_method {
        values.insert(m.method.clone(), m.values());
    }
    let [train_n, validation_n, test_n] = t.split;
    Ok(ExperimentResult {
        headlines,
        name: Name::LiverAr,
        size,
        seconds: 0.0,
        build: String::new(),
        rows,
        figures: ["tre.png".into()]
            .into_iter()
            .chain(t.curve_figure(&recipe))
            .chain(["errors.png".into(), "viewer.html".into()])
            .collect(),
        page_figures: Vec::new(),
        notes: vec![
            format!(
                "Network: {} samples of the {LIVER_AR} scenario{} ({train_n} training, {validation_n} validation, \
                 {test_n} test), {iterations} steps, {} channels, {} mm training noise; {}.",
                data.dataset.manifest().num_samples,
                data.failed_note(),
                recipe.channels,
                mm(recipe.corruption.noise_std),
                t.timing(test.reference_ms)
            ),
            format!(
                "Reduced-order model (`augsim train --method rom`): fitted on the network's training and validation \
                 samples, with {} copies of each whose inputs carry the same noise, and tested on its test samples.",
                config.noise_copies
            ),
            cases_note(&builtin),
            reference::note(Some(test.reference_ms)),
        ],
        values,
    })
}

/// The network's and the reduced-order model's figures on the test samples: errors over the grid
/// and at the markers, and the time of one prediction.
struct TestFigures {
    report: EvalReport,
    tre: PointErrors,
    unet_ms: f64,
    rom_report: EvalReport,
    rom_tre: PointErrors,
    rom_ms: f64,
    /// The time the reduced-order model's fit took (s).
    rom_seconds: f64,
    /// The run's reference time (ms), measured beside the predictions.
    reference_ms: f64,
}

impl TestFigures {
    /// Evaluates the network of `t` and the reduced-order model `rom` on `t`'s test samples.
    fn new(data: &Generated, t: &Trained, rom: &Model, rom_seconds: f64) -> Result<TestFigures> {
        let manifest = data.dataset.manifest();
        let markers = manifest.markers();
        let placement = manifest.placement().context("the liver_ar dataset records its grid placement")?;
        let grid = placement.grid(t.model.grid())?;
        let (report, tre) =
            learn::evaluate_at_points(&t.model, &t.test, &Corruption::default(), 0, &grid, &markers, Compute::Cpu)?;
        let (rom_report, rom_tre) =
            learn::evaluate_at_points(rom, &t.test, &Corruption::default(), 0, &grid, &markers, Compute::Cpu)?;
        let input = t.test.get(0).input;
        let reference_ms = reference::measure()?;
        let (unet_ms, rom_ms) = (prediction_seconds(&t.model, &input)? * 1e3, prediction_seconds(rom, &input)? * 1e3);
        Ok(TestFigures { report, tre, unet_ms, rom_report, rom_tre, rom_ms, rom_seconds, reference_ms })
    }

    /// The rows of the figures (`iterations`: the network's training steps).
    fn rows(&self, iterations: usize) -> Vec<Row> {
        vec![
            Row::new("network on the test samples: ē (max)", mean_and_max(&self.report), ""),
            Row::new(
                "network on the test samples: TRE at the markers",
                format!(
                    "{} (no motion: {})",
                    fmt(mm(self.tre.errors.mean), 2, "mm"),
                    fmt(mm(self.tre.no_motion.mean), 1, "mm")
                ),
                "",
            ),
            Row::new(
                "network: prediction (one sample); training",
                format!(
                    "{} (CPU, median of 20); {iterations} steps",
                    reference::ms(self.unet_ms, 2, Some(self.reference_ms))
                ),
                "",
            ),
            Row::new("reduced-order model on the test samples: ē (max)", mean_and_max(&self.rom_report), ""),
            Row::new(
                "reduced-order model on the test samples: TRE at the markers",
                fmt(mm(self.rom_tre.errors.mean), 2, "mm"),
                "",
            ),
            Row::new(
                "reduced-order model: prediction (one sample); fit",
                format!(
                    "{} (CPU, median of 20); {}",
                    reference::ms(self.rom_ms, 2, Some(self.reference_ms)),
                    reference::seconds(self.rom_seconds, 0, Some(self.reference_ms))
                ),
                "",
            ),
        ]
    }

    /// The figures as the result's values.
    fn values(&self) -> Result<serde_json::Map<String, serde_json::Value>> {
        let mut values = serde_json::Map::new();
        values.insert("test".into(), serde_json::to_value(self.report.stats)?);
        values.insert("test_marker_tre".into(), serde_json::to_value(self.tre.errors)?);
        values.insert("prediction_ms".into(), self.unet_ms.into());
        values.insert("rom_test".into(), serde_json::to_value(self.rom_report.stats)?);
        values.insert("rom_test_marker_tre".into(), serde_json::to_value(self.rom_tre.errors)?);
        values.insert("rom_prediction_ms".into(), self.rom_ms.into());
        values.insert("rom_fit_seconds".into(), self.rom_seconds.into());
        values.insert("reference_ms".into(), self.reference_ms.into());
        Ok(values)
    }
}

/// A report's mean error (max) in mm.
fn mean_and_max(report: &EvalReport) -> String {
    format!("{} ({})", fmt(mm(report.stats.mean), 2, "mm"), fmt(mm(report.stats.max), 1, "mm"))
}

/// The first test sample of `t` in the 3D viewer (`viewer.html`), on the mesh its samples were
/// solved on (quadratic for a T10 scenario).
fn write_test_viewer(dir: &Path, data: &Generated, t: &Trained) -> Result<()> {
    let organ = data.scenario.generator(&data.scenario_dir)?.mesh().clone();
    let index = t.test.indices.first().copied().context("no test sample")?;
    let sample = sample_on_mesh(&t.model, &data.dataset, index, &organ)?;
    let title = format!("liver_ar, test sample {index}: U-Net prediction vs FEM reference");
    plot::viewer::write_html(&dir.join("viewer.html"), &sample.scene(&organ, &title))?;
    Ok(())
}

/// The registration of every case by every method.
struct CaseFigures {
    /// Each method's figures.
    per_method: Vec<MethodTre>,
    /// The markers' mean motion (mm) in each held-out case: the TRE of not deforming.
    no_motion: Vec<f64>,
    /// The number of markers.
    marker_count: usize,
    /// A row per case and method.
    rows: Vec<Row>,
}

/// Registers the design case, the held-out cases and the cases beyond pushes (the shipped case
/// `builtin` under each load) with its methods and the `networks`.
fn register_cases(builtin: &CaseScenario, networks: &[Network<'_>; 2], progress: Progress) -> Result<CaseFigures> {
    let mut figures = CaseFigures { per_method: Vec::new(), no_motion: Vec::new(), marker_count: 0, rows: Vec::new() };
    let cases = std::iter::once((Role::Design, &DESIGN))
        .chain(HELD_OUT.iter().map(|c| (Role::HeldOut, c)))
        .chain(BEYOND_PUSHES.iter().map(|c| (Role::BeyondPushes, c)));
    let methods = case_methods(builtin, networks)?;
    for (role, variant) in cases {
        progress.line(&format!("registering the case {}", variant.label));
        let case = synthetic_case(&variant.apply(builtin))?;
        figures.marker_count = case.targets.len();
        // Each method set up anew: it registers from rest, with no state from the last case.
        let rows = compare(&case, &methods);
        if figures.per_method.is_empty() {
            figures.per_method =
                rows.iter().map(|r| MethodTre { method: r.method.clone(), ..MethodTre::default() }).collect();
        }
        let motion = marker_motion_mm(&case, case.peak());
        let kind = match role {
            Role::Design => "design case",
            Role::HeldOut => "held-out case",
            Role::BeyondPushes => "case beyond pushes",
        };
        let label = format!("{kind} {} (markers move {} on average)", variant.label, fmt(motion, 1, "mm"));
        let cell = |method: &str, ours: String| Row::new(method, ours, "").of("case: TRE mean / max", &label);
        for (entry, r) in figures.per_method.iter_mut().zip(&rows) {
            let s = match &r.result {
                Ok(registered) => &registered.summary,
                Err(e) => {
                    figures.rows.push(cell(&r.method, "failed".into()));
                    match role {
                        Role::Design => entry.design = (f64::NAN, f64::NAN),
                        Role::HeldOut => entry.failures.push(format!("{}: {e}", variant.label)),
                        Role::BeyondPushes => entry.beyond.push((f64::NAN, f64::NAN)),
                    }
                    continue;
                }
            };
            let (tre_mean, tre_max) = (s.tre_mean_mm.unwrap_or(f64::NAN), s.tre_max_mm.unwrap_or(f64::NAN));
            figures.rows.push(cell(&r.method, format!("{} / {}", fmt(tre_mean, 2, "mm"), fmt(tre_max, 1, "mm"))));
            match role {
                Role::Design => entry.design = (tre_mean, tre_max),
                Role::HeldOut => {
                    entry.means.push(tre_mean);
                    entry.maxima.push(tre_max);
                    entry.times.push(s.time_ms);
                }
                Role::BeyondPushes => entry.beyond.push((tre_mean, tre_max)),
            }
        }
        if role == Role::HeldOut {
            figures.no_motion.push(motion);
        }
    }
    Ok(figures)
}

/// Each method's rows: on the held-out cases (with the time per frame and its multiple of
/// `reference_ms`), on the cases beyond pushes, and on those a network is chosen on.
fn method_rows(per_method: &[MethodTre], reference_ms: f64) -> Vec<Row> {
    let mut rows = Vec::new();
    for m in per_method {
        rows.push(
            Row::new(
                HELD_OUT_TRE,
                format!(
                    "{} ({}), {}{}",
                    fmt(mean(&m.means), 2, "mm"),
                    fmt(max(&m.maxima), 1, "mm"),
                    reference::ms(mean(&m.times), 0, Some(reference_ms)),
                    match m.failures.len() {
                        0 => String::new(),
                        n => format!("; failed on {n} of {} cases", HELD_OUT.len()),
                    }
                ),
                published(&m.method).0,
            )
            .of("registration", &m.method),
        );
    }
    for m in per_method {
        let beyond: Vec<f64> = m.beyond.iter().map(|b| b.0).collect();
        let choice: Vec<f64> = std::iter::once(m.design.0).chain(beyond.iter().copied()).collect();
        let failed = choice.iter().filter(|t| t.is_nan()).count();
        let choice = match failed {
            0 => fmt(mean(&choice), 2, "mm"),
            n => format!("failed on {n} of {} cases", choice.len()),
        };
        rows.extend([
            Row::new(
                "cases beyond pushes: TRE mean (max)",
                format!(
                    "{} (max {})",
                    fmt(mean(&beyond), 2, "mm"),
                    fmt(max(&m.beyond.iter().map(|b| b.1).collect::<Vec<_>>()), 1, "mm"),
                ),
                "",
            )
            .of("registration", &m.method),
            Row::new("cases a network is chosen on (design and beyond pushes): TRE mean", choice, "")
                .of("registration", &m.method),
        ]);
    }
    rows
}

/// `tre.png`: each method's TRE on the held-out cases (mean and largest) beside the published mean.
fn tre_chart(dir: &Path, per_method: &[MethodTre], marker_count: usize) -> Result<()> {
    let categories: Vec<String> = per_method.iter().map(|m| m.method.clone()).collect();
    let bars = |name: &str, f: &dyn Fn(&MethodTre) -> Option<f64>| plot::BarSeries {
        name: name.into(),
        values: per_method.iter().map(f).collect(),
    };
    plot::bar_chart(
        &dir.join("tre.png"),
        &plot::PlotSpec {
            title: format!(
                "TRE at {marker_count} markers over the {} held-out cases: mean, and the largest",
                HELD_OUT.len()
            ),
            x_label: String::new(),
            y_label: "mm".into(),
            log_y: false,
        },
        &categories,
        &[
            bars("TRE mean", &|m| Some(mean(&m.means))),
            bars("TRE max", &|m| Some(max(&m.maxima))),
            bars("published TRE mean", &|m| published(&m.method).1),
        ],
    )?;
    Ok(())
}

impl MethodTre {
    /// The method's figures as the result's values.
    fn values(&self) -> serde_json::Value {
        serde_json::json!({
            "held_out_cases": HELD_OUT.iter().map(|v| v.label).collect::<Vec<_>>(),
            "tre_mean_mm": self.means,
            "tre_max_mm": self.maxima,
            "time_ms": self.times,
            "design_case": DESIGN.label,
            "design_tre_mean_mm": self.design.0,
            "design_tre_max_mm": self.design.1,
            "beyond_pushes_cases": BEYOND_PUSHES.iter().map(|v| v.label).collect::<Vec<_>>(),
            "beyond_pushes_tre_mean_mm": self.beyond.iter().map(|b| b.0).collect::<Vec<_>>(),
            "beyond_pushes_tre_max_mm": self.beyond.iter().map(|b| b.1).collect::<Vec<_>>(),
            "failures": self.failures,
        })
    }
}

/// The one registration rule compared on held-out cases, said wherever those cases are said to have
/// played no part in the settings.
pub(crate) const RULE_COMPARED_ON_HELD_OUT: &str = "one rule was compared on held-out cases: the FEM's \
    recovery from a solve that finds no equilibrium (its springs softened rather than the solver's arc length, \
    `docs/method.md` § 6.2), on the 2.5 N right-lobe press of `augsim experiment liver-ar` and on the cases of \
    `augsim experiment held-out`";

/// The note on the registration cases.
fn cases_note(builtin: &CaseScenario) -> String {
    format!(
        "Registration cases: register_case's truth ({} phantom of {}, \
         another mesh and law than the models) under the loads listed; its camera along {:?} sees \
         {} points with {} noise and {:.0} % outliers. The registration figures beside the published ones \
         are over the {} held-out cases only (a failed method is counted apart); the design case, with \
         the same spot pushed by 1, 2 and 2.5 N, is where the registration settings were chosen. The \
         {} cases beyond pushes (a lift, a drag, a pull) cover what surgery also does; a network is chosen \
         on its mean over them and the design case, never on the held-out cases here or on `augsim \
         experiment held-out`; {RULE_COMPARED_ON_HELD_OUT}. Published: ex vivo human liver.",
        builtin.truth.material.law.display_name(),
        builtin.truth.mesh_words(),
        builtin.camera.view,
        builtin.camera.points,
        fmt(mm(builtin.camera.noise), 1, "mm"),
        100.0 * builtin.camera.outliers,
        HELD_OUT.len(),
        BEYOND_PUSHES.len()
    )
}
