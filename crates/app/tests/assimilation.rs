//! Assimilation experiments on a small beam: synthetic tracks written by a run and read back give the same
//! estimate, tool tracks as controls, occluded features, and the errors of bad track files.

use std::path::{Path, PathBuf};

use augsim_app::assimilation::tracks::{RestPositions, Tracks};
use augsim_app::assimilation::{Experiment, ObservationFiles, Report};
use filter::SigmaPointSet;
use mesh::length::LengthUnit;
use scenario::AssimilationScenario;

/// The test scenario (see its header).
fn beam() -> String {
    std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/beam_assimilation.toml")).unwrap()
}

/// A tool pressing the middle of the top face, with its own profile.
const TOOL: &str = r#"
[[tool]]
select = { box = { min = [0.039, -1.0, 0.0199], max = [0.061, 1.0, 1.0] } }
displacement = [0.0, 0.0, -5e-4]
profile = { sine = { period = 8 } }
"#;

fn scenario(dir: &Path, name: &str, text: &str) -> (AssimilationScenario, PathBuf) {
    let path = dir.join(name);
    std::fs::write(&path, text).unwrap();
    AssimilationScenario::load(&path).unwrap()
}

fn run(dir: &Path, text: &str, files: Option<&ObservationFiles>, out: &str) -> (Report, Vec<Vec<u64>>) {
    let (sc, base) = scenario(dir, &format!("{out}.toml"), text);
    let sigma = sc.filter.sigma_points;
    let experiment = Experiment::prepare(sc, &base, files).unwrap();
    let setup = experiment.setup().lines(sigma, files);
    assert!(setup[0].starts_with("mesh ") && setup[1].contains(&format!("{sigma} sigma points")), "{setup:?}");
    let source = if files.is_some() { "tracks " } else { "reference " };
    assert!(setup.len() == 3 && setup[2].starts_with(source), "{setup:?}");
    let calls = std::sync::atomic::AtomicUsize::new(0);
    let count = |done: u64, total: u64, note: &str| {
        let call = calls.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
        assert_eq!(done, call as u64);
        assert!(done <= total && !note.is_empty());
    };
    let report = experiment.run(&dir.join(out), &count).unwrap();
    assert_eq!(calls.into_inner(), report.iterations);
    let trace: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join(out).join("trace.json")).unwrap()).unwrap();
    let means = trace["records"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| r["mean"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap().to_bits()).collect())
        .collect();
    (report, means)
}

fn files(tracks: &Path, controls: bool) -> ObservationFiles {
    ObservationFiles {
        observations: tracks.join("observations.csv"),
        features: None,
        controls: controls.then(|| tracks.join("controls.csv")),
        assessment: Some(tracks.join("assessment.csv")),
        known_truth: false,
        units: LengthUnit::Metre,
    }
}

#[test]
fn tracks_written_by_a_synthetic_run_give_the_same_estimate() {
    let dir = tempfile::tempdir().unwrap();
    let beam = beam();
    let (synthetic, expected) = run(dir.path(), &beam, None, "synthetic");
    assert!(synthetic.synthetic);
    let young = synthetic.young.as_ref().unwrap();
    assert!((young.mean - 5000.0).abs() < 0.01 * 5000.0, "{young:?}");
    let lines = synthetic.lines();
    assert!(lines[0].starts_with(&format!("filter       {} iterations", synthetic.iterations)), "{lines:?}");
    assert!(lines.iter().any(|l| l.starts_with("young        μ = ") && l.contains("(truth 5000 Pa")), "{lines:?}");
    assert!(lines.last().unwrap().starts_with("wall time"), "{lines:?}");
    // The estimated deformation of steps 4 and 8 as a ParaView series.
    assert_eq!(synthetic.deformation_frames, 2);
    let pvd = std::fs::read_to_string(dir.path().join("synthetic/deformation.pvd")).unwrap();
    assert!(pvd.contains("deformation/step_00008.vtu"), "{pvd}");
    // At step 4 the load peaks (the end moves by millimetres); at step 8 it is back to zero.
    let max_u = |step: &str| {
        let (_, fields) = mesh::io::read_vtu_with_fields(dir.path().join("synthetic/deformation").join(step)).unwrap();
        let u = fields.iter().find(|f| f.name == "displacement").unwrap();
        u.values.iter().fold(0.0f64, |m, v| m.max(v.abs()))
    };
    assert!(max_u("step_00004.vtu") > 1e-3 && max_u("step_00008.vtu") < 1e-9);

    let tracks = dir.path().join("synthetic/tracks");
    let (read, got) = run(dir.path(), &beam, Some(&files(&tracks, false)), "read");
    assert!(!read.synthetic);
    assert_eq!(got, expected, "the filter means of every iteration, bit for bit");
    assert_eq!(read.young.as_ref().unwrap().std.to_bits(), young.std.to_bits());
    // The assessment tracks give the same errors (up to the rounding of nodes located as points).
    let (a, b) = (&synthetic.assessment[0], &read.assessment[0]);
    assert!((a.mean_error - b.mean_error).abs() < 1e-12 && a.mean_error > 0.0, "{a:?} vs {b:?}");

    // Rest positions from a features file instead of frame 0, with the frame-0 rows gone: the same again.
    let text = std::fs::read_to_string(tracks.join("observations.csv")).unwrap();
    let mut features = String::from("id,x,y,z\n");
    let mut moving = String::from("frame,id,x,y,z\n");
    for line in text.lines().skip(1) {
        match line.strip_prefix("0,") {
            Some(rest) => features.push_str(&format!("{rest}\n")),
            None => moving.push_str(&format!("{line}\n")),
        }
    }
    std::fs::write(dir.path().join("features.csv"), features).unwrap();
    std::fs::write(dir.path().join("moving.csv"), &moving).unwrap();
    let split = ObservationFiles {
        observations: dir.path().join("moving.csv"),
        features: Some(dir.path().join("features.csv")),
        controls: None,
        assessment: None,
        known_truth: false,
        units: LengthUnit::Metre,
    };
    assert_eq!(run(dir.path(), &beam, Some(&split), "split").1, expected);

    // An occluded feature (f1 at frame 3) is skipped for that frame: the run goes on and lands nearby.
    let occluded: String = moving.lines().filter(|l| !l.starts_with("3,f1,")).map(|l| format!("{l}\n")).collect();
    std::fs::write(dir.path().join("moving.csv"), occluded).unwrap();
    let (sc, base) = scenario(dir.path(), "occluded.toml", &beam);
    let experiment = Experiment::prepare(sc, &base, Some(&split)).unwrap();
    assert_eq!(experiment.setup().occluded, 1);
    let report = experiment.run(&dir.path().join("occluded"), &learn::Silent).unwrap();
    let (e, e0) = (report.young.unwrap().mean, young.mean);
    assert!(e != e0 && (e - e0).abs() < 1e-3 * e0, "{e} vs {e0}");
    assert_eq!((report.gated_components, report.gated_steps), (0, 0));

    // A tracking failure instead (f1 at frame 3 off by 5 cm on each axis): with a validation gate it
    // is left out as the occluded feature was, to the same estimate.
    let jumped: String = moving
        .lines()
        .map(|l| match l.strip_prefix("3,f1,") {
            Some(rest) => {
                let moved: Vec<String> =
                    rest.split(',').map(|v| (v.parse::<f64>().unwrap() + 0.05).to_string()).collect();
                format!("3,f1,{}\n", moved.join(","))
            }
            None => format!("{l}\n"),
        })
        .collect();
    std::fs::write(dir.path().join("moving.csv"), jumped).unwrap();
    let (sc, base) = scenario(dir.path(), "gated.toml", &format!("{beam}\n[filter]\ngate = 30.0\n"));
    let gated = Experiment::prepare(sc, &base, Some(&split)).unwrap().run(&dir.path().join("gated"), &learn::Silent);
    let gated = gated.unwrap();
    assert_eq!((gated.gated_components, gated.gated_steps), (3, 1));
    let gate_line = gated.lines().into_iter().find(|l| l.starts_with("gate ")).unwrap();
    assert!(gate_line.starts_with("gate         3 tracked components left out of 1 steps"), "{gate_line}");
    assert_eq!(gated.gated_features, [("f1".to_string(), 1)], "the feature that jumped");
    assert!(gate_line.ends_with("most often: `f1` 1"), "{gate_line}");
    let g = gated.young.unwrap().mean;
    assert!((g - e).abs() < 1e-9 * e, "{g} vs the occluded run's {e}");
}

#[test]
fn tool_tracks_as_controls_reproduce_the_tool() {
    let dir = tempfile::tempdir().unwrap();
    let beam = beam();
    let with_tool = format!("{beam}{TOOL}");
    let (synthetic, _) = run(dir.path(), &with_tool, None, "synthetic");
    let tracks = dir.path().join("synthetic/tracks");
    let controls = Tracks::read(&tracks.join("controls.csv"), LengthUnit::Metre).unwrap();
    assert_eq!(controls.ids.len(), 6, "the tool's nodes");
    // The same beam without the scenario's tool, driven by the tracked tool instead.
    let (sc, base) = scenario(dir.path(), "controlled.toml", &beam);
    let experiment = Experiment::prepare(sc, &base, Some(&files(&tracks, true))).unwrap();
    assert_eq!(experiment.setup().control_nodes, 6);
    let read = experiment.run(&dir.path().join("controlled"), &learn::Silent).unwrap();
    let (a, b) = (synthetic.young.unwrap(), read.young.unwrap());
    assert!((a.mean - b.mean).abs() < 1e-9 * a.mean && (a.std - b.std).abs() < 1e-9 * a.std, "{a:?} vs {b:?}");
    // The scenario's tool kept beside the tracked one would move the beam twice: refused.
    let (sc, base) = scenario(dir.path(), "both.toml", &with_tool);
    let Err(error) = Experiment::prepare(sc, &base, Some(&files(&tracks, true))) else {
        panic!("the scenario's tool and tracked controls together are refused")
    };
    assert!(error.to_string().contains("remove [[tool]] from the scenario"), "{error}");
    // Without the controls the beam moves differently and the estimate is off.
    let (sc, base) = scenario(dir.path(), "uncontrolled.toml", &beam);
    let report = Experiment::prepare(sc, &base, Some(&files(&tracks, false)))
        .unwrap()
        .run(&dir.path().join("uncontrolled"), &learn::Silent)
        .unwrap();
    assert!((report.young.unwrap().mean - a.mean).abs() > 1e-3 * a.mean);
}

/// The beam scenario as `augsim assimilate --observations` reads it: every frame of the track
/// files, not the scenario's own number of iterations.
fn tracked(dir: &Path) -> (AssimilationScenario, PathBuf) {
    let (mut sc, base) = scenario(dir, "beam.toml", &beam());
    sc.iterations = None;
    (sc, base)
}

/// The experiment of [`tracked`] on the track file `file` of `dir`, or its error message.
fn prepare_tracks(dir: &Path, file: &str) -> Result<Experiment, String> {
    let (sc, base) = tracked(dir);
    let files = ObservationFiles { observations: dir.join(file), ..Default::default() };
    Experiment::prepare(sc, &base, Some(&files)).map_err(|e| e.to_string())
}

/// Writes `text` to a file in `dir` and reads it as tracks; returns the error message.
fn track_error(dir: &Path, text: &str) -> String {
    let path = dir.join("bad.csv");
    std::fs::write(&path, text).unwrap();
    Tracks::read(&path, LengthUnit::Metre).unwrap_err().to_string()
}

#[test]
fn bad_track_files_are_named_with_their_line() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let bad = d.join("bad.csv").display().to_string();
    let cases = [
        ("", format!("{bad}: the file is empty")),
        ("\n  \n", format!("{bad}: the file is empty")),
        ("frame,id,x,y,z\n", format!("{bad}: no data rows")),
        ("frame,name,x,y,z\n0,a,0,0,0\n", format!("{bad}:1: the header must be `frame,id,x,y,z`")),
        ("frame,id,x,y,z\n0,a,0,0,0\n1,a,0,abc,0\n", format!("{bad}:3: y = \"abc\" is not a number")),
        ("frame,id,x,y,z\n0,a,0,0,NaN\n", format!("{bad}:2: z = \"NaN\" is not finite")),
        (
            "frame,id,x,y,z\n0,a,0,0,0\n1,a,1e300,0,0\n",
            format!("{bad}:3: the point lies at [1e300, 0.0, 0.0]: a coordinate beyond 1e6, out of reach"),
        ),
        ("frame,id,x,y,z\n\n-1,a,0,0,0\n", format!("{bad}:3: frame `-1` is not a whole number")),
        ("frame,id,x,y,z\n0,a,0,0\n", format!("{bad}:2: 4 fields, the header has 5 columns")),
        ("frame,id,x,y,z\n0, ,0,0,0\n", format!("{bad}:2: empty id")),
        (
            "frame,id,x,y,z\n0,a,0,0,0\n0,a,1,0,0\n",
            format!("{bad}:3: feature `a` at frame 0 is already given on line 2"),
        ),
    ];
    for (text, want) in cases {
        let got = track_error(d, text);
        assert!(got.starts_with(&want), "{text:?}: got `{got}`, want `{want}…`");
    }
    // Header case and spaces, a byte-order mark, CRLF line ends and blank lines are accepted.
    std::fs::write(d.join("ok.csv"), "\u{feff}Frame, ID, x, y, z\r\n0,a,0,0,0\r\n\r\n2,a,0.001,0,0\r\n").unwrap();
    let ok = Tracks::read(&d.join("ok.csv"), LengthUnit::Metre).unwrap();
    assert_eq!((ok.last_frame(), ok.position(0, 1), ok.position(0, 2)), (2, None, Some([0.001, 0.0, 0.0])));
    // Units: the header's, else the one given.
    std::fs::write(d.join("mm.csv"), "frame,id,x_mm,y_mm,z_mm\n0,a,1,2,3\n").unwrap();
    let mm = Tracks::read(&d.join("mm.csv"), LengthUnit::Metre).unwrap();
    assert_eq!(mm.position(0, 0), Some([0.001, 0.002, 0.003]));
    let given = Tracks::read(&d.join("ok.csv"), LengthUnit::Millimetre).unwrap();
    assert_eq!(given.position(0, 2), Some([1e-6, 0.0, 0.0]));
    std::fs::write(d.join("mixed.csv"), "frame,id,x_mm,y,z\n0,a,1,2,3\n").unwrap();
    let err = Tracks::read(&d.join("mixed.csv"), LengthUnit::Metre).unwrap_err().to_string();
    assert!(err.contains("the header must be `frame,id,x,y,z`"), "{err}");

    // Rest positions: unknown ids, repeated ids, a missing frame 0.
    std::fs::write(d.join("features.csv"), "id,x,y,z\na,0.01,0.01,0.01\n").unwrap();
    let features = RestPositions::read(&d.join("features.csv"), LengthUnit::Metre).unwrap();
    std::fs::write(d.join("tracks.csv"), "frame,id,x,y,z\n1,a,0,0,0\n1,b,0,0,0\n").unwrap();
    let tracks = Tracks::read(&d.join("tracks.csv"), LengthUnit::Metre).unwrap();
    let err = tracks.rest_positions(Some(&features)).unwrap_err().to_string();
    assert!(err.contains("tracks.csv:3: unknown id `b`") && err.contains("features.csv"), "{err}");
    let err = tracks.rest_positions(None).unwrap_err().to_string();
    assert!(err.contains("tracks.csv:2: feature `a` has no frame-0 row"), "{err}");
    std::fs::write(d.join("features.csv"), "id,x,y,z\na,0,0,0\na,1,1,1\n").unwrap();
    let err = RestPositions::read(&d.join("features.csv"), LengthUnit::Metre).unwrap_err().to_string();
    assert!(err.contains("features.csv:3: feature `a` is already given on line 2"), "{err}");
    let err = RestPositions::read(&d.join("missing.csv"), LengthUnit::Metre).unwrap_err().to_string();
    assert!(err.contains("missing.csv: cannot read"), "{err}");

    // Through an experiment: a feature outside the organ, named with its line.
    std::fs::write(
        d.join("outside.csv"),
        "frame,id,x,y,z\n0,in,0.05,0.01,0.02\n0,out,0.05,0.01,0.03\n1,in,0.05,0.01,0.02\n",
    )
    .unwrap();
    let (sc, base) = tracked(d);
    let files = ObservationFiles { observations: d.join("outside.csv"), ..Default::default() };
    let err = Experiment::prepare(sc, &base, Some(&files)).err().unwrap().to_string();
    assert!(err.contains("outside.csv:3: feature `out`") && err.contains("outside the mesh"), "{err}");

    // A feature just outside (0.5 mm above the top face, as from a finer surface) is located on the surface
    // and keeps its offset: the model sees it where it was tracked, so a constant offset is no innovation.
    std::fs::write(
        d.join("near.csv"),
        "frame,id,x,y,z\n0,in,0.05,0.01,0.02\n0,near,0.05,0.01,0.0205\n1,in,0.05,0.01,0.02\n1,near,0.05,0.01,0.0205\n",
    )
    .unwrap();
    let (sc, base) = tracked(d);
    let files = ObservationFiles { observations: d.join("near.csv"), ..Default::default() };
    let experiment = Experiment::prepare(sc, &base, Some(&files)).unwrap();
    let setup = experiment.setup().clone();
    assert_eq!((setup.features, setup.projected), (2, 1));
    assert!((setup.max_projection - 5e-4).abs() < 1e-12, "{}", setup.max_projection);
    let near = experiment.observed_points()[1];
    assert!(mesh::distance(near, [0.05, 0.01, 0.0205]) < 1e-12, "observed at rest at {near:?}");

    // The same in mm under a bare header, read as metres: far outside, and the unit named (one feature lies
    // on the surface, not in the mesh).
    let in_mm = "frame,id,x,y,z\n0,in,50,10,20\n0,near,50,10,20.5\n1,in,50,10,20\n1,near,50,10,20.5\n";
    std::fs::write(d.join("near_mm.csv"), in_mm).unwrap();
    let err = prepare_tracks(d, "near_mm.csv").err().unwrap();
    assert!(err.contains("every feature lies in the organ or on its surface; is the file given in mm"), "{err}");

    // A feature 10 mm below the top face (the beam is 20 mm thick): said, by name and depth.
    std::fs::write(
        d.join("deep.csv"),
        "frame,id,x,y,z\n0,in,0.05,0.01,0.02\n0,deep,0.05,0.01,0.01\n1,in,0.05,0.01,0.02\n",
    )
    .unwrap();
    let experiment = prepare_tracks(d, "deep.csv").unwrap();
    let files = ObservationFiles { observations: d.join("deep.csv"), ..Default::default() };
    let lines = experiment.setup().lines(SigmaPointSet::Simplex, Some(&files));
    assert!(
        lines.iter().any(|l| l.starts_with("warning      1 feature(s) lie deeper") && l.contains("(`deep` 10.0 mm)")),
        "{lines:?}"
    );
    assert!(!experiment.setup().deep_features.iter().any(|(id, _)| id == "in"));

    // Frames without a row (a frame column that skips): every feature occluded there, said.
    std::fs::write(
        d.join("gap.csv"),
        "frame,id,x,y,z\n0,in,0.05,0.01,0.02\n1,in,0.05,0.01,0.02\n4,in,0.05,0.01,0.02\n",
    )
    .unwrap();
    let experiment = prepare_tracks(d, "gap.csv").unwrap();
    assert_eq!((experiment.setup().iterations, experiment.setup().blind_frames), (4, 2));
    let files = ObservationFiles { observations: d.join("gap.csv"), ..Default::default() };
    let lines = experiment.setup().lines(SigmaPointSet::Simplex, Some(&files));
    assert!(lines.iter().any(|l| l.starts_with("warning      2 of the 4 frames have no row")), "{lines:?}");

    // More iterations than the file has frames are refused, not cut short.
    let (mut sc, base) = tracked(d);
    sc.iterations = Some(3);
    let files = ObservationFiles { observations: d.join("near.csv"), ..Default::default() };
    let err = Experiment::prepare(sc, &base, Some(&files)).err().unwrap().to_string();
    assert!(err.contains("near.csv: 3 iterations asked for, but the file's last frame is 1"), "{err}");

    // Rest positions in m and frames in mm read as m: the features seem to leave the organ by metres.
    std::fs::write(d.join("rest.csv"), "id,x,y,z\nin,0.05,0.01,0.02\n").unwrap();
    std::fs::write(d.join("frames_mm.csv"), "frame,id,x,y,z\n1,in,50,10,19.5\n").unwrap();
    let in_mm = ObservationFiles {
        observations: d.join("frames_mm.csv"),
        features: Some(d.join("rest.csv")),
        ..Default::default()
    };
    let (sc, base) = tracked(d);
    let err = Experiment::prepare(sc, &base, Some(&in_mm)).err().unwrap().to_string();
    assert!(
        err.contains("frames_mm.csv:2: feature `in` lies 54")
            && err.contains("at frame 1, farther than the organ's size (103.9 mm")
            && err.contains("another unit than the rest positions in")
            && err.contains("rest.csv"),
        "{err}"
    );
    // Rest positions in mm and frames in m read as mm: each feature within the organ's size of its rest
    // position, but the features span a thousand times less.
    std::fs::write(
        d.join("rest_mm.csv"),
        "id,x_mm,y_mm,z_mm\nin,50,10,20\nleft,20,10,20\nright,80,10,20\nfront,50,0,20\n",
    )
    .unwrap();
    std::fs::write(
        d.join("frames_m.csv"),
        "frame,id,x,y,z\n1,in,0.05,0.01,0.0195\n1,left,0.02,0.01,0.02\n1,right,0.08,0.01,0.02\n1,front,0.05,0,0.02\n",
    )
    .unwrap();
    let m_as_mm = ObservationFiles {
        observations: d.join("frames_m.csv"),
        features: Some(d.join("rest_mm.csv")),
        units: LengthUnit::Millimetre,
        ..Default::default()
    };
    let (sc, base) = tracked(d);
    let err = Experiment::prepare(sc, &base, Some(&m_as_mm)).err().unwrap().to_string();
    assert!(
        err.contains("frames_m.csv: its 4 features at frame 1 span 0.061 mm, 1.0")
            && err.contains("e-3 times what they span at rest (60.8 mm): is the file in another unit"),
        "{err}"
    );
    // Millimetres under a plain header read as metres: outside the organ, a thousand times too far.
    std::fs::write(d.join("plain_mm.csv"), "frame,id,x,y,z\n0,in,50,10,19.5\n1,in,50,10,19\n").unwrap();
    let err = prepare_tracks(d, "plain_mm.csv").err().unwrap();
    assert!(
        err.contains("plain_mm.csv:2: feature `in`: tracked point")
            && err.contains("is the file given in mm where m were expected?")
            && !err.contains("invalid FEM model"),
        "{err}"
    );
    // A feature 8 mm off the organ's corner at the origin fits read a thousand times smaller too, as
    // any point near it would: its unit is not blamed.
    std::fs::write(d.join("off.csv"), "frame,id,x,y,z\n0,off,-0.008,0.01,0.01\n1,off,-0.008,0.01,0.01\n").unwrap();
    let err = prepare_tracks(d, "off.csv").err().unwrap();
    assert!(err.contains("off.csv:2: feature `off`") && !err.contains("where m were expected"), "{err}");
    // Zero iterations are refused, not filtered.
    let (mut sc, base) = tracked(d);
    sc.iterations = Some(0);
    let files = ObservationFiles { observations: d.join("near.csv"), ..Default::default() };
    let err = Experiment::prepare(sc, &base, Some(&files)).err().unwrap().to_string();
    assert!(err.contains("iterations must be at least 1"), "{err}");
    // A rest position outside the organ is named at its own line, in the features file.
    std::fs::write(d.join("rest.csv"), "id,x,y,z\nin,0.05,0.01,0.2\n").unwrap();
    let (sc, base) = tracked(d);
    let err = Experiment::prepare(sc, &base, Some(&in_mm)).err().unwrap().to_string();
    assert!(err.contains("rest.csv:2: feature `in`") && err.contains("outside the mesh, 180.00 mm"), "{err}");
}

#[test]
fn star_sigma_points_from_the_scenario() {
    let dir = tempfile::tempdir().unwrap();
    let beam = beam();
    let (simplex, _) = run(dir.path(), &beam, None, "simplex");
    assert_eq!((simplex.sigma_points, simplex.sigma_point_set), (2, SigmaPointSet::Simplex));
    let star_text = format!("{beam}[filter]\nsigma_points = \"star\"\n");
    let (sc, base) = scenario(dir.path(), "star.toml", &star_text);
    let experiment = Experiment::prepare(sc, &base, None).unwrap();
    assert_eq!((experiment.setup().parameters, experiment.setup().sigma_points), (1, 3));
    let star = experiment.run(&dir.path().join("star"), &learn::Silent).unwrap();
    assert_eq!((star.sigma_points, star.sigma_point_set), (3, SigmaPointSet::Star));
    let summary = std::fs::read_to_string(dir.path().join("star/summary.json")).unwrap();
    assert!(summary.contains("\"sigma_point_set\": \"star\""), "{summary}");
    // Same observations, both within 1 % of the truth and of each other.
    let (a, b) = (simplex.young.unwrap(), star.young.unwrap());
    for y in [&a, &b] {
        assert!((y.mean - 5000.0).abs() < 0.01 * 5000.0, "{y:?}");
        let k = y.within_1_percent_from_iteration.unwrap();
        assert!(k >= 1 && y.within_1_percent_after_seconds.unwrap() > 0.0, "{y:?}");
    }
    assert!((a.mean - b.mean).abs() < 0.002 * a.mean, "{a:?} vs {b:?}");

    // An unknown set is an error that names the value and the choices.
    let err = AssimilationScenario::load(&{
        let path = dir.path().join("cross.toml");
        std::fs::write(&path, format!("{beam}[filter]\nsigma_points = \"cross\"\n")).unwrap();
        path
    })
    .unwrap_err()
    .to_string();
    assert!(err.contains("cross") && err.contains("simplex") && err.contains("star"), "{err}");
}

#[test]
fn a_reference_section_observes_another_mesh() {
    let dir = tempfile::tempdir().unwrap();
    let beam = beam();
    let (plain, plain_means) = run(dir.path(), &beam, None, "plain");
    let own = plain.reference.unwrap();
    assert!(own.inverse_crime && own.nodes == plain.nodes, "{own:?}");

    // The model's own mesh as the reference: the tracks go through location on the model, the same bits.
    let same_mesh = "[reference.mesh.box]\nmin = [0.0, 0.0, 0.0]\nmax = [0.1, 0.02, 0.02]\ncells = [5, 2, 2]\n\
                     element = \"tet\"\n";
    let (same, same_means) = run(dir.path(), &format!("{beam}{same_mesh}"), None, "same");
    assert_eq!(same_means, plain_means, "the filter means of every iteration, bit for bit");
    assert!(same.synthetic && !same.reference.unwrap().inverse_crime);

    // A finer reference under Neo-Hookean: another discretisation and law, so another estimate,
    // reported against the scenario's truth; the tracks written are the reference's.
    let finer = "[reference]\nlaw = \"neo_hookean\"\n[reference.mesh.box]\nmin = [0.0, 0.0, 0.0]\n\
                 max = [0.1, 0.02, 0.02]\ncells = [10, 4, 4]\nelement = \"tet\"\n";
    let (other, other_means) = run(dir.path(), &format!("{beam}{finer}"), None, "finer");
    let reference = other.reference.unwrap();
    assert!(!reference.inverse_crime && reference.nodes == 11 * 5 * 5 && reference.cells == 960, "{reference:?}");
    assert_eq!(reference.law, fem::Law::NeoHookean);
    assert_eq!(other.nodes, plain.nodes, "the filter keeps the scenario's mesh");
    let (y, y0) = (other.young.unwrap(), plain.young.unwrap());
    assert_eq!(y.truth, Some(5000.0));
    // The finer beam, less stiff, bends more under the same force than the coarse one:
    // the model must be softer to follow it.
    assert!(other_means != plain_means && y.mean < 0.9 * y0.mean, "{} vs {}", y.mean, y0.mean);
    let tracks = std::fs::read_to_string(dir.path().join("finer/tracks/observations.csv")).unwrap();
    assert_eq!(tracks.lines().count(), 1 + 10 * 9, "10 features over frames 0..=8");
}

#[test]
fn discrepancy_from_the_scenario_file() {
    let dir = tempfile::tempdir().unwrap();
    let beam = std::fs::read_to_string(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/beam_assimilation.toml"),
    )
    .unwrap();
    let run = |name: &str, text: &str| {
        let path = dir.path().join(format!("{name}.toml"));
        std::fs::write(&path, text).unwrap();
        let (sc, base) = AssimilationScenario::load(&path).unwrap();
        Experiment::prepare(sc, &base, None).unwrap().run(&dir.path().join(name), &learn::Silent)
    };
    let plain = run("plain", &beam).unwrap().young.unwrap();
    let honest = run("honest", &format!("{beam}[filter]\ndiscrepancy = \"systematic\"\n")).unwrap().young.unwrap();
    assert_eq!(honest.mean, plain.mean, "the allowance does not change the estimate");
    assert_eq!(honest.noise_std, Some(plain.std));
    assert!(honest.std >= plain.std && honest.misfit.is_some_and(|m| m > 0.5 && m < 2.0), "{honest:?}");
    assert!(plain.noise_std.is_none() && plain.misfit.is_none());
    let summary = std::fs::read_to_string(dir.path().join("honest/summary.json")).unwrap();
    assert!(summary.contains("\"misfit\"") && summary.contains("\"noise_std\""), "{summary}");
    let plain_summary = std::fs::read_to_string(dir.path().join("plain/summary.json")).unwrap();
    assert!(!plain_summary.contains("misfit"), "{plain_summary}");
    let csv = std::fs::read_to_string(dir.path().join("honest/trace.csv")).unwrap();
    assert!(csv.lines().next().unwrap().contains(",misfit,"), "{csv}");

    let bad = run("bad", &format!("{beam}[filter]\ndiscrepancy = \"systematic\"\ndiscrepancy_dof = 0.5\n"));
    let message = anyhow_like(bad.unwrap_err());
    assert!(message.contains("degrees of freedom") && message.contains("0.5"), "{message}");
    let path = dir.path().join("unknown.toml");
    std::fs::write(&path, format!("{beam}[filter]\ndiscrepancy = \"bias\"\n")).unwrap();
    let err = AssimilationScenario::load(&path).unwrap_err().to_string();
    assert!(err.contains("bias") && err.contains("systematic"), "{err}");
}

/// The error with its chain of sources, one per line.
fn anyhow_like(e: impl std::error::Error) -> String {
    let mut text = e.to_string();
    let mut source = e.source();
    while let Some(s) = source {
        text.push_str(&format!("\n{s}"));
        source = s.source();
    }
    text
}
