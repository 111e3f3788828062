//! `prepare` on a CT-derived liver (SOFA's liver-smooth, scaled to 20 cm, in mm, in a scanner's
//! frame), damaged as segmentations are (holes, written as STL), its points saved as 3D Slicer
//! saves them (the frame named in each file, landmarks in RAS, the rest in LPS): repaired,
//! meshed, its regions selected, a small dataset drawn, a reduced-order model trained and
//! evaluated, and the registration set-up it writes registering a cloud of the organ at rest;
//! resumed without redoing a step; refused with other inputs; a unit mistake named.

use std::path::{Path, PathBuf};

use augsim_app::prepare::{prepare, CameraAt, PrepareOptions, PrepareProgress, STEPS};
use augsim_app::registration::RegistrationSpec;
use augsim_app::setup::{PatientMethod, STATE_FILE};
use mesh::io::points::{read_points, write_points, LabelledPoints};
use mesh::io::Frame;
use mesh::length::LengthUnit;
use mesh::Point;

/// Scanner frame: the organ's corner sits here (mm).
const ORIGIN: Point = [-120.0, 85.0, -310.0];

/// Prints the lines `prepare` tells as it goes, and keeps them.
#[derive(Default)]
struct Told(std::sync::Mutex<Vec<String>>);

impl learn::Progress for Told {
    fn advance(&self, _: u64, _: u64, _: &str) {}
    fn line(&self, text: &str) {
        println!("{text}");
        self.0.lock().unwrap().push(text.to_string());
    }
}

impl PrepareProgress for Told {
    fn step(&self, _: usize, _: &str) {}
}

impl Told {
    /// The lines told of the validation's solves as they ended.
    fn solves(&self) -> usize {
        self.0
            .lock()
            .unwrap()
            .iter()
            .filter(|l| l.starts_with("validation: the ") && l.contains(" push on a truth of "))
            .count()
    }
}

fn write_csv(path: &Path, points: &[Point]) {
    mesh::io::points::write_points_csv(path, points).unwrap();
}

/// The damaged surface (STL, mm), the camera (mm), the landmarks and targets files (mm): plain CSV
/// and a point, or, `slicer`, as 3D Slicer saves them: the surface naming its frame (LPS) in its
/// header, the landmarks as `.mrk.json` in RAS, the targets as `.fcsv` in LPS, the camera as
/// `.fcsv`, with labels.
fn patient_files(dir: &Path, slicer: bool) -> (PathBuf, CameraAt, PathBuf, PathBuf) {
    let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("../mesh/tests/data/liver-smooth.obj");
    let mut surface = mesh::io::read_surface(&data).unwrap();
    let (lo, hi) = mesh::bounds(&surface.vertices);
    let scale = 200.0 / (0..3).map(|d| hi[d] - lo[d]).fold(0.0, f64::max);
    surface.vertices.iter_mut().for_each(|p| *p = std::array::from_fn(|d| (p[d] - lo[d]) * scale + ORIGIN[d]));
    let (lo, hi) = mesh::bounds(&surface.vertices);
    let centre: Point = std::array::from_fn(|d| 0.5 * (lo[d] + hi[d]));
    // Held at the back (lowest z), where four extreme vertices of the bottom layer lie.
    let back: Vec<Point> = surface.vertices.iter().copied().filter(|p| p[2] < lo[2] + 0.08 * (hi[2] - lo[2])).collect();
    let extreme = |key: fn(&Point) -> f64, most: bool| {
        *back.iter().max_by(|a, b| if most { key(a).total_cmp(&key(b)) } else { key(b).total_cmp(&key(a)) }).unwrap()
    };
    let landmarks =
        [extreme(|p| p[0], false), extreme(|p| p[0], true), extreme(|p| p[1], false), extreme(|p| p[1], true)];
    // Two holes: two triangles removed (the STL reader merges the file's repeated vertices).
    surface.triangles.drain(100..102);
    let stl = dir.join("liver.stl");
    if slicer {
        mesh::io::write_surface_in_frame(&stl, &surface, Frame::Lps).unwrap();
    } else {
        mesh::io::write_surface(&stl, &surface).unwrap();
    }
    // Targets halfway between two surface vertices of the same column: inside.
    let vertices = &surface.vertices;
    let targets: Vec<Point> = (0..vertices.len())
        .step_by(97)
        .filter_map(|i| {
            let p = vertices[i];
            let other = vertices
                .iter()
                .filter(|q| (q[0] - p[0]).abs() < 4.0 && (q[1] - p[1]).abs() < 4.0 && (q[2] - p[2]).abs() > 40.0)
                .min_by(|a, b| (a[2] - p[2]).abs().total_cmp(&(b[2] - p[2]).abs()))?;
            Some(std::array::from_fn(|d| 0.5 * (p[d] + other[d])))
        })
        .take(3)
        .collect();
    assert!(!targets.is_empty());
    let camera = [centre[0], centre[1], hi[2] + 250.0];
    if !slicer {
        write_csv(&dir.join("landmarks.csv"), &landmarks);
        write_csv(&dir.join("targets.csv"), &targets);
        return (stl, camera.into(), dir.join("landmarks.csv"), dir.join("targets.csv"));
    }
    let labelled = |points: &[Point], frame: Frame, name: &str| {
        let mut p = LabelledPoints::new(points.to_vec());
        p.labels = (1..=points.len()).map(|i| format!("{name} {i}")).collect();
        (p.frame, p.unit) = (Some(Frame::Lps), Some(LengthUnit::Millimetre));
        p.convert(Some(frame), LengthUnit::Millimetre, LengthUnit::Millimetre);
        p
    };
    let files = [("landmarks.mrk.json", Frame::Ras), ("targets.fcsv", Frame::Lps), ("camera.fcsv", Frame::Lps)];
    let [attach, target_file, camera_file] = files.map(|(name, _)| dir.join(name));
    write_points(&attach, &labelled(&landmarks, files[0].1, "ligament")).unwrap();
    write_points(&target_file, &labelled(&targets, files[1].1, "target")).unwrap();
    write_points(&camera_file, &labelled(&[camera], files[2].1, "laparoscope")).unwrap();
    (stl, CameraAt::File(camera_file), attach, target_file)
}

#[test]
fn a_damaged_segmentation_to_a_registration_set_up() {
    let dir = tempfile::tempdir().unwrap();
    let (surface, camera, attach, targets) = patient_files(dir.path(), true);
    let mut options = PrepareOptions::new(surface, camera, attach, targets.clone());
    options.samples = 30;
    options.tets = 800;
    let out = dir.path().join("patient");
    let told = Told::default();
    let state = prepare(&options, &out, &told).unwrap();
    assert_eq!(state.steps.iter().map(|s| s.name.as_str()).collect::<Vec<_>>(), STEPS);
    let organ = &state.steps[0].lines;
    assert!(organ.iter().any(|l| l.starts_with("units: mm")), "{organ:?}");
    assert!(organ.iter().any(|l| l.starts_with("frame: LPS (named by")), "{organ:?}");
    // The points written in m and LPS, labels kept: the landmarks given in RAS are where the LPS ones are.
    assert_eq!(mesh::io::surface_frame(out.join("surface.stl")).unwrap(), Some(Frame::Lps));
    // The surface in mm (for 3D Slicer), the organ's mesh in m.
    let (surface, organ_mesh) =
        (mesh::io::read_surface(out.join("surface.stl")).unwrap(), mesh::io::read_mesh(out.join("organ.vtu")).unwrap());
    let extent = |p: (Point, Point)| (0..3).map(|d| p.1[d] - p.0[d]).fold(0.0, f64::max);
    let (in_mm, in_m) = (extent(mesh::bounds(&surface.vertices)), extent(organ_mesh.bounds()));
    assert!((in_mm / (1e3 * in_m) - 1.0).abs() < 0.02, "surface {in_mm} mm across, organ {in_m} m");
    let written = read_points(out.join("targets.csv")).unwrap();
    assert_eq!((written.frame, written.unit), (Some(Frame::Lps), Some(LengthUnit::Metre)));
    assert_eq!(written.labels, ["target 1", "target 2", "target 3"][..written.points.len()]);
    let mut given = read_points(&targets).unwrap();
    given.convert(Some(Frame::Lps), LengthUnit::Metre, LengthUnit::Metre);
    assert_eq!(written.points, given.points);
    let mut held = read_points(dir.path().join("landmarks.mrk.json")).unwrap();
    held.convert(Some(Frame::Lps), LengthUnit::Metre, LengthUnit::Metre);
    assert_eq!((read_points(out.join("attach.csv")).unwrap().points, held.frame), (held.points, Some(Frame::Lps)));
    let mut seen_from = read_points(dir.path().join("camera.fcsv")).unwrap();
    seen_from.convert(Some(Frame::Lps), LengthUnit::Metre, LengthUnit::Metre);
    let written = read_points(out.join("camera.csv")).unwrap();
    assert_eq!(
        (written.points, written.frame, written.unit),
        (seen_from.points, Some(Frame::Lps), Some(LengthUnit::Metre))
    );
    assert!(organ.iter().any(|l| l.starts_with("repair: filled 2 holes (3, 3 edges)")), "the holes: {organ:?}");
    // The draws' motion, read from the shards, against the statistics the generator kept as it
    // wrote them: the mean of the displacements' lengths is at most their root mean square.
    let dataset = &state.steps[2].lines;
    let motion = dataset.iter().find(|l| l.starts_with("dataset: the draws move the organ by")).unwrap();
    let [mean, p90, largest] = [" by ", " most ", "largest by "]
        .map(|before| -> f64 { motion.split(before).nth(1).unwrap().split(" mm").next().unwrap().parse().unwrap() });
    let dataset_dir = out.join("dataset");
    let generated = learn::Dataset::open(&dataset_dir).unwrap();
    let rms = generated.manifest().statistics.targets.rms_norm * 1e3;
    // The viewer finds the organ of the dataset in the scenario written beside it.
    let (viewed, from) = augsim_app::sample_view::organ_mesh(None, None, &dataset_dir, generated.manifest()).unwrap();
    assert_eq!(from, out.join("dataset.toml"));
    assert_eq!(viewed.num_nodes(), mesh::io::read_mesh(out.join("organ.vtu")).unwrap().num_nodes());
    assert!(0.0 < mean && mean <= rms + 0.05 && mean <= largest && p90 <= largest, "{motion}; RMS {rms:.2} mm");
    let validation = &state.steps[5].lines;
    assert!(validation.iter().any(|l| l.starts_with("validation: FEM TRE")), "{validation:?}");
    // The truth the cases are registered against is the mesh the last convergence check accepted
    // (the coarser of its two when converged, the finer otherwise).
    let check = validation.iter().rfind(|l| l.starts_with("validation: the truth's convergence under")).unwrap();
    let counts: Vec<&str> = check.split(" T10").map(|part| part.rsplit(' ').next().unwrap()).take(2).collect();
    let used = if check.ends_with("converged (at most 10 %)") { counts[0] } else { counts[1] };
    assert!(validation.iter().any(|l| l.contains(&format!("on a truth of {used} T10"))), "{validation:?}");
    // Its four pushes are kept, solved or not, for a validation run again; so are the frames of
    // each solved push's stream, a quarter of its force more each.
    let kept: Vec<String> = std::fs::read_dir(out.join(augsim_app::prepare::TRUTH_DIR))
        .unwrap()
        .map(|f| f.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    let has = |stem: String| kept.iter().any(|f| f == &format!("{stem}.npy") || f == &format!("{stem}.failed"));
    for (push, force) in [1.5, 2.5, 2.0, 3.0].into_iter().enumerate() {
        assert!(has(format!("truth-{used}-{push}-{force}N")), "push {push}: {kept:?}");
        if kept.contains(&format!("truth-{used}-{push}-{force}N.npy")) {
            assert!(has(format!("truth-{used}-{push}-{}N", force / 4.0)), "push {push}'s first frame: {kept:?}");
        }
    }
    // Each solve was told as it ended, one line for each solution kept.
    assert_eq!(told.solves(), kept.len(), "{kept:?}");
    // The set-up names the method that registered the validation's pushes the best, from rest and
    // as streams: of those no worse than the FEM (within 5 %) both ways, the lowest mean ratio of
    // its TRE to the FEM's.
    let chosen = validation.iter().find(|l| l.contains("registers with the")).expect("the chosen method");
    let line = |what: &str| validation.iter().find(|l| l.starts_with(&format!("validation: {what} TRE "))).unwrap();
    let tre = |what: &str| -> f64 {
        line(what).split(" TRE ").nth(1).and_then(|r| r.split_whitespace().next()).unwrap().parse().unwrap()
    };
    let streamed = |what: &str| format!("{what} as streams of 4 frames");
    assert!(validation.iter().all(|l| !l.contains("failed on")), "{validation:?}");
    let (fem_rest, fem_stream) = (tre("FEM"), tre(&streamed("FEM")));
    let (best, _) = [("learned", "learned model"), ("fem", "FEM"), ("hybrid", "learned model, then FEM (hybrid)")]
        .map(|(name, words)| {
            let ratios = [tre(words) / fem_rest, tre(&streamed(words)) / fem_stream];
            (name, (ratios.iter().any(|&r| r > 1.05), ratios[0] + ratios[1]))
        })
        .into_iter()
        .fold(("", (true, f64::INFINITY)), |best, method| if method.1 < best.1 { method } else { best });
    // The ROM predicts σ, from rest and on a stream, and the validation says how well it held; the
    // FEM predicts none.
    assert!(line("learned model").contains("of the targets within 2σ"), "{validation:?}");
    assert!(line(&streamed("learned model")).contains("of the targets within 2σ"), "{validation:?}");
    assert!(!line("FEM").contains("σ") && !line(&streamed("FEM")).contains("σ"), "{validation:?}");
    let named = format!("method = \"{best}\"");
    assert!(chosen.contains(&format!("({named})")), "{validation:?}");
    let set_up = std::fs::read_to_string(out.join("registration.toml")).unwrap();
    assert!(set_up.contains(&named), "{set_up}");
    for file in ["organ.vtu", "dataset.toml", "static.toml", "registration.toml", "report.md", "regions.png"] {
        assert!(out.join(file).exists(), "{file}");
    }
    // The chosen method's registration of the strongest push, pictured and shown by the report.
    let pictured = validation.iter().find(|l| l.contains("on the strongest push, pictured")).unwrap();
    let words = [("learned", "learned model"), ("fem", "FEM"), ("hybrid", "learned model, then FEM (hybrid)")];
    let (_, best_words) = words.iter().find(|(name, _)| *name == best).unwrap();
    assert!(pictured.starts_with(&format!("validation: the {best_words} on")), "{pictured}");
    let page = std::fs::read_to_string(out.join("validation.html")).unwrap();
    assert!(page.contains("targets, true") && page.contains("TRE at the "), "the page's scene");
    let report = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(out.join("validation.png").exists() && report.contains("](validation.png)"));
    // The validation's table: a row per method, kind and push solved, and one over all of them,
    // whose TRE is the line's; the report shows those.
    let text = std::fs::read_to_string(out.join(augsim_app::prepare::TABLE)).unwrap();
    let table = mesh::io::csv::Table::parse(&text, &mesh::io::csv::Dialect::CSV).unwrap();
    table.check_widths().unwrap();
    let solved = [1.5, 2.5, 2.0, 3.0]
        .iter()
        .enumerate()
        .filter(|(push, force)| kept.contains(&format!("truth-{used}-{push}-{force}N.npy")))
        .count();
    let at = |name: &str| table.column(name).unwrap();
    let rest_rows = table.rows.iter().filter(|r| r.fields[at("registered")] == "rest").count();
    let all_rows: Vec<_> = table.rows.iter().filter(|r| r.fields[at("push_n")] == "all").collect();
    assert_eq!((all_rows.len(), rest_rows), (6, 3 * (solved + 1)), "{text}");
    for (name, words) in [("learned", "learned model"), ("fem", "FEM"), ("hybrid", "learned model, then FEM (hybrid)")]
    {
        let row = all_rows.iter().find(|r| r.fields[at("method")] == name && r.fields[at("registered")] == "rest");
        let tre_mm: f64 = row.unwrap().fields[at("tre_mm")].parse().unwrap();
        assert!((tre_mm - tre(words)).abs() <= 0.005 + 1e-9, "{name}: {tre_mm} against the line's {}", tre(words));
        let shown = format!("| {words} | {:.2} mm", tre_mm);
        assert!(report.contains(&shown), "{shown} not in the report:\n{report}");
    }
    // The regions travel with the mesh file: what ParaView shows is what the scenarios select.
    let mesh = mesh::io::read_mesh(out.join("organ.vtu")).unwrap();
    assert!(mesh.region("visible").unwrap().len() > 20 && mesh.region("attached").unwrap().len() > 5);
    // Held by default over 12 % of its surface: the distance the organ step reports is the one
    // both scenarios hold the organ at, and it selects the region the mesh file carries.
    let line = organ.iter().find(|l| l.starts_with("regions:")).unwrap();
    assert!(line.ends_with("landmarks, 12 % of its surface"), "{line}");
    let reported: f64 = line.split(" held within ").nth(1).unwrap().split(" mm").next().unwrap().parse().unwrap();
    let distance_in = |file: &str| -> f64 {
        let text = std::fs::read_to_string(out.join(file)).unwrap();
        text.split("distance = ").nth(1).unwrap().split(',').next().unwrap().parse().unwrap()
    };
    let distance = distance_in("dataset.toml");
    assert_eq!(distance_in("static.toml"), distance);
    assert!((distance * 1e3 - reported).abs() <= 0.05, "{distance} m against the report's {reported} mm");
    let landmarks = read_points(out.join("attach.csv")).unwrap().points;
    let near = mesh::Near { points: landmarks.clone(), file: None, distance, surface: true }.nodes(&mesh).unwrap();
    assert_eq!(near.as_slice(), mesh.region("attached").unwrap());
    assert_eq!(distance, mesh::distance_holding_share(&mesh, &landmarks, augsim_app::prepare::HELD_SHARE).unwrap());

    // The set-up registers: a cloud of the organ's surface at rest leaves the targets where they are.
    for method in [PatientMethod::Learned, PatientMethod::Fem, PatientMethod::Hybrid] {
        let mut registration = RegistrationSpec::patient(&out, Some(method), None, false).unwrap().build().unwrap();
        assert_eq!(registration.method().contains("then FEM"), method == PatientMethod::Hybrid, "{method:?}");
        if method == PatientMethod::Hybrid {
            // The ROM's shape fit, then the FEM's polish; on a stream's next frames the fit alone.
            let iterations = register::shape::SHAPE_ITERATIONS + augsim_app::models::POLISH_ITERATIONS;
            assert_eq!(registration.options().iterations, iterations);
            assert_eq!(registration.options().warm_iterations, register::shape::SHAPE_WARM_ITERATIONS);
        }
        let cloud: Vec<Point> = registration.organ().surface().vertices.iter().step_by(2).copied().collect();
        let rest = registration.targets().to_vec();
        let tracked = registration.register(&cloud).unwrap();
        let moved = mesh::stats::max(&mesh::distances(&tracked.targets, &rest));
        assert!(moved < 2e-3, "{}: targets moved {:.2} mm for a cloud at rest", registration.method(), moved * 1e3);
        // The σ of the methods that give one, calibrated by the validation: the factor its line
        // reports, at least 1, kept in the set-up and applied to what the method gives.
        if method == PatientMethod::Fem {
            continue;
        }
        let words = if method == PatientMethod::Learned { "learned model" } else { "learned model, then FEM (hybrid)" };
        let calibrated = validation.iter().find(|l| l.starts_with(&format!("validation: σ of the {words} calibrated")));
        let factor: f64 = calibrated.unwrap().split('×').nth(1).unwrap().split(',').next().unwrap().parse().unwrap();
        let kept: f64 =
            set_up.split(&format!("{} = ", method.name())).nth(1).unwrap().lines().next().unwrap().parse().unwrap();
        assert!(factor >= 1.0 && (kept - factor).abs() < 0.005, "{factor} reported, {kept} kept");
        let spec = RegistrationSpec::patient(&out, Some(method), None, false).unwrap();
        let mut own = RegistrationSpec { sigma_factor: 1.0, ..spec }.build().unwrap();
        let std = |tracked: &register::Tracked| tracked.target_std.clone().unwrap();
        let (given, scaled) = (std(&own.register(&cloud).unwrap()), std(&tracked));
        assert!(given.iter().zip(&scaled).all(|(g, s)| (s - kept * g).abs() <= 1e-9 * s), "{given:?} → {scaled:?}");
    }

    // Run again: every step kept; other inputs refused.
    let again = prepare(&options, &out, &Told::default()).unwrap();
    let computed = |s: &augsim_app::prepare::PrepareState| s.steps[..STEPS.len() - 1].to_vec();
    assert_eq!(computed(&again), computed(&state), "kept, not computed again");
    assert_eq!(again.steps.last().unwrap().name, "report", "written anew");
    options.samples = 40;
    let refused = prepare(&options, &out, &Told::default()).unwrap_err().to_string();
    assert!(refused.contains("other inputs") && refused.contains("samples 30 there, 40 now"), "{refused}");
    // An input file changed under the same name is another input too.
    options.samples = 30;
    let targets = std::fs::read(&options.targets).unwrap();
    std::fs::write(&options.targets, [targets.as_slice(), b"\n"].concat()).unwrap();
    let refused = prepare(&options, &out, &Told::default()).unwrap_err().to_string();
    let changed = format!("{} changed since", std::path::absolute(&options.targets).unwrap().display());
    assert!(refused.contains("other inputs") && refused.contains(&changed), "{refused}");
    std::fs::write(&options.targets, targets).unwrap();
    assert!(prepare(&options, &out, &Told::default()).is_ok());
    // A folder that holds an input is not written into.
    let holder = options.targets.parent().unwrap().to_path_buf();
    let refused = prepare(&options, &holder, &Told::default()).unwrap_err().to_string();
    assert!(refused.contains("which the run reads") && refused.contains("give another --out"), "{refused}");
    std::fs::remove_file(out.join(STATE_FILE)).unwrap();
}

#[test]
fn targets_in_another_unit_are_named() {
    let dir = tempfile::tempdir().unwrap();
    let (surface, camera, attach, targets) = patient_files(dir.path(), false);
    // The targets written in m while the rest is in mm.
    let in_metres: Vec<Point> =
        mesh::io::points::read_points_csv(&targets).unwrap().iter().map(|p| p.map(|x| x * 1e-3)).collect();
    write_csv(&targets, &in_metres);
    let mut options = PrepareOptions::new(surface, camera, attach, targets);
    options.samples = 30;
    options.tets = 800;
    let error = format!("{:#}", prepare(&options, &dir.path().join("patient"), &Told::default()).unwrap_err());
    assert!(
        error.contains("outside the organ") && error.contains("were they given in m where mm were expected"),
        "{error}"
    );
}

#[test]
fn landmarks_in_another_unit_are_named() {
    let dir = tempfile::tempdir().unwrap();
    let (surface, camera, attach, targets) = patient_files(dir.path(), false);
    // The landmarks written in m while the rest is in mm.
    let in_metres: Vec<Point> =
        mesh::io::points::read_points_csv(&attach).unwrap().iter().map(|p| p.map(|x| x * 1e-3)).collect();
    write_csv(&attach, &in_metres);
    let mut options = PrepareOptions::new(surface, camera, attach, targets);
    options.samples = 30;
    options.tets = 800;
    let error = format!("{:#}", prepare(&options, &dir.path().join("patient"), &Told::default()).unwrap_err());
    assert!(
        error.contains("the landmarks of") && error.contains("were they given in m where mm were expected?"),
        "{error}"
    );
}

#[test]
fn a_damaged_points_file_is_named_once_with_its_point() {
    let dir = tempfile::tempdir().unwrap();
    let (surface, camera, attach, targets) = patient_files(dir.path(), false);
    let mut far = mesh::io::points::read_points_csv(&targets).unwrap();
    far[1][0] = 1e300;
    write_csv(&targets, &far);
    let options = PrepareOptions::new(surface, camera, attach, targets.clone());
    let error = format!("{:#}", prepare(&options, &dir.path().join("patient"), &Told::default()).unwrap_err());
    let name = targets.display().to_string();
    assert_eq!(error.matches(&name).count(), 1, "{error}");
    assert!(error.contains("point 1 lies at [1e300") && error.contains("beyond 1e6"), "{error}");
}

/// Targets a registration would refuse (none but a header, a label twice), a camera inside the
/// organ and a folder of other files are refused as the preparation starts, not after its dataset
/// and model are made.
#[test]
fn inputs_a_set_up_could_not_use_are_refused_first() {
    let dir = tempfile::tempdir().unwrap();
    let (surface, camera, attach, targets) = patient_files(dir.path(), false);
    let options = |targets: &Path, camera: CameraAt| {
        let mut options = PrepareOptions::new(surface.clone(), camera, attach.clone(), targets.to_path_buf());
        (options.samples, options.tets) = (30, 800);
        options
    };
    let refused = |options: &PrepareOptions, out: &str| {
        format!("{:#}", prepare(options, &dir.path().join(out), &Told::default()).unwrap_err())
    };
    let header = dir.path().join("header.csv");
    std::fs::write(&header, "x_mm,y_mm,z_mm\n").unwrap();
    let error = refused(&options(&header, camera.clone()), "a");
    assert!(error.ends_with("header.csv holds no targets"), "{error}");
    let twice = dir.path().join("twice.csv");
    let text = std::fs::read_to_string(&targets).unwrap().replacen('\n', ",label\n", 1);
    let labelled: Vec<String> =
        text.lines().enumerate().map(|(i, l)| if i == 0 { l.into() } else { format!("{l},tumour") }).collect();
    std::fs::write(&twice, labelled.join("\n")).unwrap();
    let error = refused(&options(&twice, camera.clone()), "b");
    assert!(error.contains("twice.csv: the label `tumour` names two targets (points 1 and 2)"), "{error}");
    let inside = mesh::io::points::read_points_csv(&targets).unwrap()[0];
    let error = refused(&options(&targets, inside.into()), "c");
    assert!(error.contains("lies inside the organ: give where the laparoscope looks from"), "{error}");
    let notes = dir.path().join("notes");
    std::fs::create_dir_all(&notes).unwrap();
    std::fs::write(notes.join("report.md"), "mine").unwrap();
    let error = refused(&options(&targets, camera.clone()), "notes");
    assert!(error.contains("holds 1 file(s) or folder(s) of its own (report.md)"), "{error}");
    assert_eq!(std::fs::read_to_string(notes.join("report.md")).unwrap(), "mine");
}
