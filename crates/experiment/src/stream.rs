//! Live registration over OpenIGTLink: the registration case's press and release (the truth on
//! a finer mesh and with another law than the models) streamed frame after frame to the server
//! of `augsim serve`, run in this process and reached over TCP by an OpenIGTLink client, in
//! millimetres as 3D Slicer sends them. Each cloud is sent once the previous one is answered
//! (the rate the server sustains); latency from sending to the status, the server's own time,
//! frames per second and the TRE of every frame.

use std::net::TcpListener;
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{anyhow, Context, Result};
use fem::material::kpa;
use live::client::Client;
use live::Outputs;
use mesh::length::{mm, LengthUnit};
use mesh::stats::{max, mean, median, percentile};
use scenario::CaseScenario;
use serde::Serialize;

use crate::held_out::marker_motion_mm;
use crate::loads::LEFT_LOBE_FRONT;
use crate::{fmt, reference, ExperimentResult, Name, Progress, Row, Size};
use app::case::{shipped, skipped_line, synthetic_case, SyntheticCase, AR_SCENARIO, SHIPPED_MODEL, SHIPPED_ROM};
use app::registration::{MethodSpec, RegistrationSpec, TargetsSpec};
use app::serving::serve_setup;

/// The static scenario of the FEM streamed: the registration case's co-rotational model (3k T4).
const FEM_SCENARIO: &str = "liver_corotational";

/// Frames of the press and release.
const FRAMES: usize = 40;

/// Points of each cloud (before the camera's outliers).
const POINTS: usize = 3000;

/// One method's stream.
#[derive(Clone, Debug, Serialize)]
pub struct Stream {
    /// The method.
    pub method: String,
    /// Send-to-status latency of each frame (ms).
    pub latency_ms: Vec<f64>,
    /// The server's time of each frame (ms: registration and encoding).
    pub server_ms: Vec<f64>,
    /// Match-and-deform iterations of each frame.
    pub iterations: Vec<usize>,
    /// Mean TRE of each frame (mm).
    pub tre_mm: Vec<f64>,
    /// Largest TRE of each frame (mm).
    pub tre_max_mm: Vec<f64>,
    /// Frames answered per second once the first (from rest, with the server's start-up) was.
    pub frames_per_second: f64,
    /// Frames whose status flagged the result as not plausible (each cloud is the organ's).
    pub flagged: usize,
    /// The warnings of the first frame flagged.
    pub first_warnings: Vec<String>,
}

/// A press and release held out from the choice of the stream's settings (`warm_iterations`,
/// the registration tolerance: chosen on the built-in case's own press and release): the built-in
/// case's truth, camera and models pressing obliquely by up to 2 N on the front of the left lobe,
/// seen with another seed, in `FRAMES` frames of `POINTS` points.
pub fn press_and_release() -> CaseScenario {
    let mut scenario = CaseScenario::builtin();
    scenario.truth.frames = FRAMES;
    scenario.truth.force = 2.0;
    scenario.truth.direction = [0.3, 0.2, -1.0];
    scenario.truth.patch = Some(LEFT_LOBE_FRONT);
    scenario.camera.points = POINTS;
    scenario.camera.seed = 31;
    scenario
}

/// Streams `case` to a server of `deformed_by` (a new registration per client, with the case's
/// targets, set up as `augsim serve` sets one up) and measures it.
pub fn stream_case(method: &str, case: &SyntheticCase, deformed_by: MethodSpec) -> Result<Stream> {
    let listener = TcpListener::bind("127.0.0.1:0").context("listening on a local port")?;
    let port = listener.local_addr()?.port();
    let spec = RegistrationSpec {
        given_units: LengthUnit::Millimetre,
        ..RegistrationSpec::new(deformed_by, TargetsSpec::Points(case.targets.clone()))
    };
    let unit = spec.given_units;
    let setup = serve_setup(spec, Some(Outputs { targets: true, status: true, ..Outputs::NONE }), None)?;
    let stop = Arc::new(AtomicBool::new(false));
    let server = {
        let stop = stop.clone();
        std::thread::spawn(move || live::serve(listener, setup.registrations, setup.options, &stop))
    };
    let measured = measure(method, case, port, unit);
    stop.store(true, Ordering::SeqCst);
    let served = server.join().map_err(|_| anyhow!("the server panicked"))?;
    served?;
    measured
}

/// The client's side of [`stream_case`], sending and reading points in `unit`, the server's.
fn measure(method: &str, case: &SyntheticCase, port: u16, unit: LengthUnit) -> Result<Stream> {
    let mut client = Client::connect(("127.0.0.1", port), Duration::from_secs(120)).map_err(|e| anyhow!(e))?;
    let mut s = Stream {
        method: method.into(),
        latency_ms: Vec::new(),
        server_ms: Vec::new(),
        iterations: Vec::new(),
        tre_mm: Vec::new(),
        tre_max_mm: Vec::new(),
        frames_per_second: 0.0,
        flagged: 0,
        first_warnings: Vec::new(),
    };
    let mut began = Instant::now();
    for (k, frame) in case.frames.iter().enumerate() {
        let cloud: Vec<[f32; 3]> = frame.cloud.iter().map(|p| unit.point_from_metres(*p).map(|x| x as f32)).collect();
        let sent = Instant::now();
        client.send_cloud(cloud).map_err(|e| anyhow!(e))?;
        let live::client::Frame { targets, status } = client.until_status().map_err(|e| anyhow!(e))?;
        s.latency_ms.push(mesh::stats::ms(sent.elapsed()));
        if let Some(e) = status.get("error") {
            return Err(anyhow!("{method}, frame {k}: the server answered {e}"));
        }
        let targets = targets.ok_or_else(|| anyhow!("{method}, frame {k}: no targets"))?;
        let registered: Vec<mesh::Point> = targets.iter().map(|p| unit.point_to_metres(p.map(f64::from))).collect();
        let errors: Vec<f64> = register::target_errors(&registered, &frame.truth).into_iter().map(mm).collect();
        s.tre_mm.push(mean(&errors));
        s.tre_max_mm.push(max(&errors));
        s.server_ms.push(status["ms"].as_f64().unwrap_or(f64::NAN));
        s.iterations.push(status["iterations"].as_u64().unwrap_or(0) as usize);
        if status["plausible"].as_bool() == Some(false) {
            s.flagged += 1;
            if s.first_warnings.is_empty() {
                let warnings = status["warnings"].as_array().into_iter().flatten();
                s.first_warnings = warnings.filter_map(|w| w.as_str().map(str::to_string)).collect();
            }
        }
        if k == 0 {
            began = Instant::now();
        }
    }
    s.frames_per_second = (case.frames.len() - 1) as f64 / began.elapsed().as_secs_f64();
    Ok(s)
}

/// The TRE of a registration over the stream (and of no registration: the motion of the markers).
const STREAM_TRE: &str = "TRE mean over frames (largest frame mean; largest)";

/// The methods streamed: the co-rotational FEM (3k T4) and the shipped learned models that are
/// there, `network` (the U-Net) and `rom` (the reduced-order model): each alone, the U-Net after the
/// ROM's shape fit when both are, the ROM then the FEM's polish (the hybrid) when the ROM is.
fn methods(network: Option<&Path>, rom: Option<&Path>) -> Vec<(&'static str, MethodSpec)> {
    let mut methods = vec![("FEM co-rotational (3k T4), warm-started", MethodSpec::fem(FEM_SCENARIO))];
    if let Some(network) = network {
        methods.push(("U-Net (models/liver_ar)", MethodSpec::learned(network, AR_SCENARIO)));
    }
    if let Some(rom) = rom {
        methods.push(("ROM (models/liver_ar_rom)", MethodSpec::learned(rom, AR_SCENARIO)));
    }
    if let (Some(network), Some(rom)) = (network, rom) {
        let after_fit = MethodSpec::learned_after_shape_fit(network, AR_SCENARIO, rom);
        methods.push(("U-Net after the ROM's shape fit", after_fit));
    }
    if let Some(rom) = rom {
        methods.push(("ROM, then FEM polish", MethodSpec::hybrid(rom, AR_SCENARIO, FEM_SCENARIO)));
    }
    methods
}

/// Runs the experiment: the co-rotational FEM (3k T4), the shipped learned models that are there,
/// the U-Net after the ROM's shape fit and the hybrid where they can be made.
pub fn run(size: Size, dir: &Path, progress: Progress) -> Result<ExperimentResult> {
    let scenario = press_and_release();
    progress
        .line(&format!("simulating the press and release ({FRAMES} frames, truth of {})", scenario.truth.mesh_words()));
    let case = synthetic_case(&scenario)?;
    let options = scenario.registration.clone();
    let (network, rom) = (shipped(SHIPPED_MODEL), shipped(SHIPPED_ROM));
    let mut streams = Vec::new();
    for (method, spec) in methods(network.as_deref(), rom.as_deref()) {
        progress.line(&format!("streaming to the {method}"));
        streams.push(stream_case(method, &case, spec)?);
    }
    let rest: Vec<f64> = case.frames.iter().map(|f| marker_motion_mm(&case, f)).collect();
    let reference_ms = Some(reference::measure()?);
    let ms = |v: f64| reference::ms(v, 1, reference_ms);
    let mut rows = vec![Row::new(STREAM_TRE, format!("{:.2} mm ({:.2} mm)", mean(&rest), max(&rest)), "")
        .of("registration", "no deformation")];
    for s in &streams {
        let mut latency = s.latency_ms.clone();
        let mut server = s.server_ms.clone();
        let figures = [
            Row::new(
                STREAM_TRE,
                format!("{:.2} mm ({:.2} mm; {:.2} mm)", mean(&s.tre_mm), max(&s.tre_mm), max(&s.tre_max_mm)),
                "",
            ),
            Row::new(
                "latency median / p95",
                format!("{} / {}", ms(median(&mut latency)), ms(percentile(&s.latency_ms, 95.0))),
                "",
            ),
            Row::new(
                "server time median / p95",
                format!("{} / {}", ms(median(&mut server)), ms(percentile(&s.server_ms, 95.0))),
                "",
            ),
            Row::new(
                "first frame: latency; server time",
                format!("{}; {}", ms(s.latency_ms[0]), ms(s.server_ms[0])),
                "",
            ),
            Row::new("sustained rate after the first frame", format!("{:.1} frames/s", s.frames_per_second), ""),
            Row::new("frames flagged as not plausible", format!("{} of {}", s.flagged, s.tre_mm.len()), ""),
        ];
        rows.extend(figures.map(|row| row.of("registration", &s.method)));
    }
    for (name, found) in [(SHIPPED_MODEL, &network), (SHIPPED_ROM, &rom)] {
        if found.is_none() {
            rows.push(Row::new("learned model", skipped_line(name), ""));
        }
    }
    let (figure, latency_figure) = ("stream.png", "stream_latency.png");
    plot_stream(&dir.join(figure), &dir.join(latency_figure), &rest, &streams)?;
    let notes = vec![
        format!(
            "Case: the built-in registration case's truth ({} phantom, E = {} kPa, ν = {}, {}) \
             pressed obliquely along {:?} on the front of the left lobe by a force rising to {} N and falling back \
             over {FRAMES} frames (sine), each frame seen anew by the camera ({POINTS} points, {} noise, {:.0} % \
             outliers); the models are another mesh (3k T4) and law. The stream's settings were chosen on the \
             built-in case's own press and release, not on this one.",
            scenario.truth.material.law.display_name(),
            kpa(scenario.truth.material.young),
            scenario.truth.material.poisson,
            scenario.truth.mesh_words(),
            scenario.truth.direction,
            scenario.truth.force,
            fmt(mm(scenario.camera.noise), 1, "mm"),
            100.0 * scenario.camera.outliers
        ),
        format!(
            "Server in this process, client over TCP on this machine (OpenIGTLink POLYDATA in mm; answers: POINT \
             targets and STRING status). Each cloud is sent when the previous one is answered. A frame warm-started \
             from the previous one runs at most {} iterations for the FEM, {} for the U-Net, {} for a reduced-order \
             model's shape fit (the hybrid's too) and {} for the U-Net after it; the learned models match both ways \
             on those frames. The first frame, from rest, runs up to {} iterations for the FEM and {} for \
             the U-Net (its real-time budget), {} for a reduced-order model's shape fit, {} more \
             for the U-Net after it and {} of the FEM after it for the hybrid (\"ROM, then FEM polish\", which \
             registers the next frames by the shape fit alone); its latency also holds the building of the client's \
             registration (its organ and model, made as the client connects), which its server time does not.",
            options.warm_iterations,
            register::NetworkDeformer::WARM_ITERATIONS,
            register::shape::SHAPE_WARM_ITERATIONS,
            app::models::NETWORK_AFTER_FIT_WARM_ITERATIONS,
            options.iterations,
            register::NetworkDeformer::ITERATIONS,
            register::shape::SHAPE_ITERATIONS,
            app::models::NETWORK_AFTER_FIT,
            app::models::POLISH_ITERATIONS,
        ),
        format!(
            "Timings: one run on this machine; the figures are only as quiet as the machine was. {}",
            reference::note(reference_ms)
        ),
    ];
    let mut values = serde_json::Map::new();
    values.insert("streams".into(), serde_json::to_value(&streams)?);
    values.insert("no_deformation_tre_mm".into(), serde_json::to_value(&rest)?);
    values.insert("reference_ms".into(), serde_json::to_value(reference_ms)?);
    Ok(ExperimentResult {
        name: Name::Stream,
        size,
        seconds: 0.0,
        build: String::new(),
        headlines: Vec::new(),
        rows,
        figures: vec![figure.into(), latency_figure.into()],
        page_figures: vec![figure.into()],
        notes,
        values,
    })
}

/// Plots each frame's TRE (`tre_path`, with the markers' own motion: no deformation) and each
/// frame's latency from sending the cloud to its answer (`latency_path`, on a log axis), a method
/// in the same colour in both.
fn plot_stream(tre_path: &Path, latency_path: &Path, rest: &[f64], streams: &[Stream]) -> Result<()> {
    let frames = |v: &[f64]| -> Vec<(f64, f64)> { v.iter().enumerate().map(|(k, &y)| (k as f64 + 1.0, y)).collect() };
    let mut tre = vec![plot::Series { name: "no deformation".into(), points: frames(rest), band: None }];
    // The first colour is no deformation's in both charts.
    let mut latency = vec![plot::Series::default()];
    for s in streams {
        tre.push(plot::Series { name: s.method.clone(), points: frames(&s.tre_mm), band: None });
        latency.push(plot::Series { name: s.method.clone(), points: frames(&s.latency_ms), band: None });
    }
    let title = "Press and release streamed over OpenIGTLink";
    let spec = |what: &str, y_label: &str, log_y| plot::PlotSpec {
        title: format!("{title}: {what}"),
        x_label: "frame".into(),
        y_label: y_label.into(),
        log_y,
    };
    plot::line_plot(tre_path, &spec("TRE", "TRE, mean over the markers (mm)", false), &tre)?;
    plot::line_plot(latency_path, &spec("latency", "from sending a cloud to its answer (ms)", true), &latency)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use register::RegistrationOptions;
    use scenario::registration::MethodKind;
    use scenario::{MeshSource, StaticScenario};

    /// The streams are set up as `augsim serve` sets them up, in each method's default settings,
    /// which are the registration case's; the FEM is the case's co-rotational model.
    #[test]
    fn the_streamed_methods_are_the_registration_cases() {
        let case = press_and_release();
        assert_eq!(case.registration, RegistrationOptions::default());
        let (fem, _) = StaticScenario::load(Path::new(FEM_SCENARIO)).unwrap();
        let model = case.models.method.iter().find(|m| m.kind == MethodKind::Fem).unwrap();
        assert_eq!(Some(fem.material), model.material);
        assert!(matches!(fem.mesh, MeshSource::Phantom { tets } if tets == case.models.tets));
    }
}
