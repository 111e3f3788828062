//! `augsim register` with a 3D Slicer user's files: the README's cloud as `.mrk.json` in RAS and
//! mm, its targets as `.fcsv` in LPS and mm, its truth as a CSV whose header names mm; and the
//! same cloud, targets and truth as plain CSV in mm with `--units mm`. Both give the targets and
//! the TRE of the same registration done all in metres and LPS (the examples' frame taken as LPS);
//! the run gives Slicer back its targets and the deformed organ in mm and in its frame, and a
//! displacement field that takes the registered targets back to where they were at rest.

use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::Command;

use mesh::io::points::{read_points, read_points_csv, write_points, write_points_csv, LabelledPoints};
use mesh::io::Frame;
use mesh::length::LengthUnit;

fn augsim(args: &[&str]) -> (bool, String) {
    augsim_in(Path::new("."), args)
}

/// `augsim` run in `dir`: whether it succeeded, and what it printed.
fn augsim_in(dir: &Path, args: &[&str]) -> (bool, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_augsim")).args(args).current_dir(dir).output().expect("augsim runs");
    (out.status.success(), format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr)))
}

fn example(name: &str) -> PathBuf {
    Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../../examples")).join(name)
}

/// The points of an example file (m, LPS) in `frame` (`None`: LPS, unnamed) and in `unit`,
/// named in the file when `named`, with labels when `labels`.
fn points(name: &str, frame: Option<Frame>, unit: LengthUnit, named: bool, labels: bool) -> LabelledPoints {
    let mut p = LabelledPoints::new(read_points_csv(&example(name)).unwrap());
    (p.frame, p.unit) = (Some(Frame::Lps), Some(LengthUnit::Metre));
    p.convert(Some(frame.unwrap_or(Frame::Lps)), unit, LengthUnit::Metre);
    (p.frame, p.unit) = (frame, named.then_some(unit));
    if labels {
        p.labels = (1..=p.points.len()).map(|i| format!("marker {i}")).collect();
    }
    p
}

/// Registers `cloud` with `targets` and `truth` on the built-in liver's FEM into `out`: the
/// registered targets (m) and the mean TRE (mm).
fn register(cloud: &Path, targets: &Path, truth: &Path, out: &Path, extra: &[&str]) -> (Vec<[f64; 3]>, f64) {
    let path = |p: &Path| p.to_str().unwrap().to_string();
    let args = [
        vec!["register".to_string(), path(cloud), "--fem".into(), "liver".into()],
        vec!["--targets".into(), path(targets), "--truth".into(), path(truth), "--out".into(), path(out)],
        extra.iter().map(|s| s.to_string()).collect(),
    ]
    .concat();
    let (ok, text) = augsim(&args.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(ok, "{text}");
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    (read_points_csv(&out.join("targets.csv")).unwrap(), summary["tre_mean_mm"].as_f64().unwrap())
}

#[test]
fn slicer_files_and_millimetres_register_as_metres_do() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let mm = LengthUnit::Millimetre;
    let slicer = [d.join("cloud.mrk.json"), d.join("targets.fcsv"), d.join("truth_mm.csv")];
    write_points(&slicer[0], &points("cloud.csv", Some(Frame::Ras), mm, true, false)).unwrap();
    write_points(&slicer[1], &points("targets.csv", Some(Frame::Lps), mm, true, true)).unwrap();
    write_points(&slicer[2], &points("truth.csv", None, mm, true, false)).unwrap();
    assert!(std::fs::read_to_string(&slicer[2]).unwrap().starts_with("x_mm,y_mm,z_mm\n"));
    // The same points in metres and LPS (mm to m is not exact in binary: the registration is
    // given the very values the conversion gives), and in mm, the file naming no unit.
    let metres = ["cloud", "targets", "truth"].map(|n| d.join(format!("{n}_m.csv")));
    let plain_mm = ["cloud", "targets", "truth"].map(|n| d.join(format!("{n}_plain_mm.csv")));
    for k in 0..3 {
        let mut p = read_points(&slicer[k]).unwrap();
        p.convert(Some(Frame::Lps), mm, mm);
        write_points_csv(&plain_mm[k], &p.points).unwrap();
        p.convert(Some(Frame::Lps), LengthUnit::Metre, mm);
        write_points_csv(&metres[k], &p.points).unwrap();
    }
    let (targets, tre) = register(&metres[0], &metres[1], &metres[2], &d.join("m"), &[]);
    let from_slicer = register(&slicer[0], &slicer[1], &slicer[2], &d.join("slicer"), &[]);
    let in_mm = register(&plain_mm[0], &plain_mm[1], &plain_mm[2], &d.join("mm"), &["--units", "mm"]);
    for (name, (other, other_tre)) in [("slicer", from_slicer), ("--units mm", in_mm)] {
        assert_eq!(other.len(), targets.len(), "{name}");
        for (a, b) in other.iter().zip(&targets) {
            assert!((0..3).all(|k| (a[k] - b[k]).abs() < 1e-9), "{name}: {a:?} against {b:?} (m)");
        }
        assert!((other_tre - tre).abs() < 1e-6, "{name}: TRE {other_tre} against {tre} mm");
    }
    // What goes back to Slicer: the registered targets as markups in mm, in the frame the
    // targets named (LPS), with their labels; the deformed surface in mm, naming the same frame.
    let markups = read_points(d.join("slicer/targets.mrk.json")).unwrap();
    assert_eq!((markups.frame, markups.unit), (Some(Frame::Lps), Some(mm)));
    assert_eq!(markups.labels, (1..=targets.len()).map(|i| format!("marker {i}")).collect::<Vec<_>>());
    for (a, b) in markups.points.iter().zip(&targets) {
        assert!((0..3).all(|k| (a[k] - 1e3 * b[k]).abs() < 1e-6), "{a:?} mm against {b:?} m");
    }
    let (surface, frame) = mesh::io::read_surface_with_frame(d.join("slicer/organ_deformed.vtk")).unwrap();
    assert_eq!(frame, Some(Frame::Lps));
    assert_eq!(mesh::io::surface_frame(d.join("slicer/organ.vtu")).unwrap(), Some(Frame::Lps), "the mesh names it too");
    let extent = |k: usize| {
        let values = surface.vertices.iter().map(|v| v[k]);
        values.clone().fold(f64::MIN, f64::max) - values.fold(f64::MAX, f64::min)
    };
    assert!((100.0..400.0).contains(&extent(0)), "the deformed surface spans {} in x: not mm", extent(0));
    // The displacement field, as Slicer applies it to the CT: at each registered target, where
    // that target lay at rest (LPS, mm), to within the grid's interpolation.
    let warp = displacement_field(&d.join("slicer/displacement.nrrd"));
    let rest = read_points(&slicer[1]).unwrap().points;
    let (mut worst, mut moved) = (0.0f64, 0.0f64);
    for (y, x) in markups.points.iter().zip(&rest) {
        let back = warp(*y);
        worst = worst.max((0..3).map(|k| (y[k] + back[k] - x[k]).powi(2)).sum::<f64>().sqrt());
        moved = moved.max((0..3).map(|k| (y[k] - x[k]).powi(2)).sum::<f64>().sqrt());
    }
    println!("displacement.nrrd: the targets back to rest within {worst:.3} mm (they moved up to {moved:.2} mm)");
    assert!(worst < 0.1 * moved, "{worst} mm off, for motions up to {moved} mm");
    // And near the examples' own metres (a last-bit change of the cloud moves the FEM's targets
    // by up to a few tenths of a millimetre).
    let (_, examples_tre) =
        register(&example("cloud.csv"), &example("targets.csv"), &example("truth.csv"), &d.join("examples"), &[]);
    assert!((examples_tre - tre).abs() < 0.05, "TRE {tre} against {examples_tre} mm");

    // The cloud in the other frame (x and y negated): registered, written to look at, and the
    // run fails, so that no script takes its files for a registration; the files for 3D Slicer
    // say so in their names, which Slicer gives the nodes it loads.
    let mirrored: Vec<[f64; 3]> = read_points_csv(&metres[0]).unwrap().iter().map(|p| [-p[0], -p[1], p[2]]).collect();
    write_points_csv(&d.join("mirrored.csv"), &mirrored).unwrap();
    let out = d.join("mirrored");
    let args = ["register", "mirrored.csv", "--fem", "liver", "--targets", "targets_m.csv", "--out", "mirrored"];
    let (ok, text) = augsim_in(d, &args);
    assert!(!ok && text.contains("with x and y negated the cloud lies on the organ"), "{text}");
    assert!(text.contains("error: the registration is not plausible") && text.contains("kept to look at"), "{text}");
    assert!(out.join("summary.json").is_file() && out.join("targets_implausible.mrk.json").is_file());
    assert!(out.join("displacement_implausible.nrrd").is_file() || text.contains("no displacement"), "{text}");
    assert!(text.contains("for 3D Slicer: targets_implausible.mrk.json, organ_deformed_implausible.vtk"), "{text}");
    let slicer_files = std::fs::read_dir(&out).unwrap().map(|e| e.unwrap().file_name().into_string().unwrap());
    let named = |f: &String| f.contains("_implausible.") || !f.ends_with(".mrk.json") && !f.ends_with("deformed.vtk");
    assert!(slicer_files.collect::<Vec<_>>().iter().all(named));
}

/// A tumour given as 3D Slicer exports a segment (an STL in LPS and mm) comes back moved with
/// the organ: about the registered target it was drawn around, and where the displacement field
/// the run writes takes it back to rest. The same ball given as a label of a NIfTI labelmap
/// comes back about the same target; a label of two balls comes back in two pieces; a structure
/// partly outside the organ, and a hollow one, are warned about in summary.json.
#[test]
fn a_structure_moves_with_the_organ_as_the_displacement_field_says() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let mm = LengthUnit::Millimetre;
    let centre = points("targets.csv", Some(Frame::Lps), mm, true, false).points[0];
    let mut ball = mesh::generate::icosphere(6.0, 2);
    ball.transform(centre.map(|x| -x), 1.0);
    let tumour = d.join("tumour.stl");
    mesh::io::write_surface_in_frame(&tumour, &ball, Frame::Lps).unwrap();
    let tumour = tumour.to_str().unwrap();
    // The ball in 1 mm voxels, label 5.
    let dims = [20, 20, 20];
    let affine: [[f64; 4]; 3] = std::array::from_fn(|r| {
        std::array::from_fn(|c| {
            if c == r {
                1.0
            } else if c == 3 {
                centre[r] - 9.5
            } else {
                0.0
            }
        })
    });
    let mut labels = Vec::new();
    for k in 0..20 {
        for j in 0..20 {
            for i in 0..20 {
                let p = [i, j, k].map(|n| n as f64 - 9.5);
                let within = |c: f64, r: f64| p.iter().map(|x| (x - c).powi(2)).sum::<f64>() <= r * r;
                labels.push(match () {
                    _ if within(0.0, 6.0) => 5,
                    _ if within(-6.0, 2.5) || within(6.0, 2.5) => 7,
                    _ if within(0.0, 8.5) && !within(0.0, 6.5) => 9,
                    _ => 0,
                });
            }
        }
    }
    let map = mesh::labelmap::Labelmap::single(dims, labels, affine, Frame::Ras);
    mesh::labelmap::write_nifti(d.join("seg.nii.gz"), &map).unwrap();
    let labelled = format!("{}:5", d.join("seg.nii.gz").display());
    // Named on the command line (a second labelmap's label 7 would collide with `label_7`).
    let two_pieces = format!("nodules={}:7", d.join("seg.nii.gz").display());
    let hollow = format!("cyst={}:9", d.join("seg.nii.gz").display());
    ball.transform([70.0, 0.0, 0.0], 1.0);
    let far = d.join("far.stl");
    mesh::io::write_surface_in_frame(&far, &ball, Frame::Lps).unwrap();
    let far = far.to_str().unwrap();
    let (registered, _) = register(
        &example("cloud.csv"),
        &example("targets.csv"),
        &example("truth.csv"),
        &d.join("run"),
        &[
            "--units",
            "mm",
            "--structure",
            tumour,
            "--structure",
            &labelled,
            "--structure",
            &two_pieces,
            "--structure",
            &hollow,
            "--structure",
            far,
        ],
    );
    let said = "`far`: 39 of its 162 vertices lie outside the organ";
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("run/summary.json")).unwrap()).unwrap();
    let warnings = summary["warnings"].as_array().unwrap();
    assert!(warnings.iter().any(|w| w.as_str().unwrap().starts_with(said)), "{warnings:?}");
    let hollow = "`cyst` is hollow: ";
    assert!(warnings.iter().any(|w| w.as_str().unwrap().starts_with(hollow)), "{warnings:?}");
    let pieces = mesh::io::read_surface(d.join("run/nodules_deformed.vtk")).unwrap();
    assert_eq!(surface_pieces(&pieces), 2);
    let moved = mesh::io::read_surface(d.join("run/tumour_deformed.vtk")).unwrap();
    let rest = mesh::io::read_surface(tumour).unwrap();
    assert_eq!(moved.triangles, rest.triangles);
    let n = moved.vertices.len() as f64;
    let middle: Vec<f64> = (0..3).map(|k| moved.vertices.iter().map(|v| v[k]).sum::<f64>() / n).collect();
    let off = (0..3).map(|k| (middle[k] - 1e3 * registered[0][k]).powi(2)).sum::<f64>().sqrt(); // targets.csv read in m
    let warp = displacement_field(&d.join("run/displacement.nrrd"));
    let (mut worst, mut motion) = (0.0f64, 0.0f64);
    for (y, x) in moved.vertices.iter().zip(&rest.vertices) {
        let back = warp(*y);
        worst = worst.max((0..3).map(|k| (y[k] + back[k] - x[k]).powi(2)).sum::<f64>().sqrt());
        motion = motion.max((0..3).map(|k| (y[k] - x[k]).powi(2)).sum::<f64>().sqrt());
    }
    println!(
        "tumour: centre {off:.2} mm from its target; back to rest within {worst:.3} mm of motions up to {motion:.1} mm"
    );
    assert!(motion > 5.0 && worst < 0.05 * motion, "{worst} mm back from rest, motions up to {motion} mm");
    assert!(off < 1.0, "the tumour's centre is {off} mm from its registered target");
    let label = mesh::io::read_surface(d.join("run/label_5_deformed.vtk")).unwrap();
    let n = label.vertices.len() as f64;
    let off = (0..3)
        .map(|k| (label.vertices.iter().map(|v| v[k]).sum::<f64>() / n - 1e3 * registered[0][k]).powi(2))
        .sum::<f64>()
        .sqrt();
    assert!(off < 1.0, "the labelmap's ball is {off} mm from its registered target");
}

/// The pieces of a surface: its triangles joined through shared corners.
fn surface_pieces(surface: &mesh::TriSurface) -> usize {
    let mut piece: Vec<usize> = (0..surface.vertices.len()).collect();
    fn root(piece: &mut [usize], mut a: usize) -> usize {
        while piece[a] != a {
            a = piece[a];
        }
        a
    }
    for t in &surface.triangles {
        for k in 1..3 {
            let (a, b) = (root(&mut piece, t[0]), root(&mut piece, t[k]));
            piece[a] = b;
        }
    }
    (0..piece.len()).filter(|&v| root(&mut piece, v) == v).count()
}

/// The displacement field of an augsim displacement.nrrd (LPS, mm), interpolated trilinearly as
/// ITK resamples it; the file's header checked to be what Slicer reads as a transform.
fn displacement_field(path: &Path) -> impl Fn([f64; 3]) -> [f64; 3] {
    let bytes = std::fs::read(path).unwrap();
    let split = bytes.windows(2).position(|w| w == b"\n\n").unwrap();
    let header = String::from_utf8(bytes[..split].to_vec()).unwrap();
    let field = |name: &str| {
        header.lines().find_map(|l| l.strip_prefix(&format!("{name}: "))).unwrap_or_else(|| panic!("no {name}"))
    };
    assert_eq!(field("kinds"), "vector domain domain domain");
    assert_eq!(field("space"), "left-posterior-superior");
    assert_eq!((field("type"), field("encoding"), field("endian")), ("float", "gzip", "little"));
    let sizes: Vec<usize> = field("sizes").split(' ').map(|s| s.parse().unwrap()).collect();
    let vector = |text: &str| -> [f64; 3] {
        let v: Vec<f64> = text.trim_matches(['(', ')']).split(',').map(|x| x.parse().unwrap()).collect();
        [v[0], v[1], v[2]]
    };
    let axes: Vec<[f64; 3]> = field("space directions").split(' ').skip(1).map(vector).collect();
    let origin = vector(field("space origin"));
    let mut raw = Vec::new();
    flate2::read::GzDecoder::new(&bytes[split + 2..]).read_to_end(&mut raw).unwrap();
    let values: Vec<f64> = raw.chunks_exact(4).map(|b| f32::from_le_bytes(b.try_into().unwrap()) as f64).collect();
    let dims = [sizes[1], sizes[2], sizes[3]];
    assert_eq!((sizes[0], values.len()), (3, 3 * dims.iter().product::<usize>()));
    // These runs' results are in LPS: the grid's axes are x, y and z, one step each.
    let step = axes[0][0];
    assert!(axes.iter().enumerate().all(|(c, a)| (0..3).all(|r| a[r] == if r == c { step } else { 0.0 })), "{axes:?}");
    // Read back in metres, the grid interpolates as ITK resamples it (`WarpField::at`).
    let m = |x: f64| x * 1e-3;
    let vectors = values.chunks_exact(3).map(|v| [m(v[0]), m(v[1]), m(v[2])]).collect();
    let field = register::WarpField { origin: origin.map(m), spacing: m(step), dims, vectors, inverted: 0 };
    move |p: [f64; 3]| field.at(p.map(m)).expect("inside the grid").map(|x| x * 1e3)
}

/// A 3D Slicer user's round trip: the organ as an LPS surface (`SPACE=LPS` STL), its landmarks and
/// targets as `.mrk.json` in LPS, the camera as `.fcsv`; `prepare` at a small size; then
/// `register --patient` with a cloud saved in RAS and mm. The targets come back as `.mrk.json` in
/// LPS and mm, where the same registration done all in metres and LPS puts them; the deformed
/// surface, the segmentation's own, comes back in LPS and mm, on the cloud.
#[test]
fn a_slicer_users_files_prepare_register_and_come_back_in_their_frame_and_unit() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (mm, m) = (LengthUnit::Millimetre, LengthUnit::Metre);
    let path = |p: &Path| p.to_str().unwrap().to_string();
    let in_lps_mm = |name: &str, label: &str| {
        let mut p = read_points(example(name)).unwrap();
        p.convert(None, mm, mm);
        p.frame = Some(Frame::Lps);
        p.labels = (1..=p.points.len()).map(|i| format!("{label} {i}")).collect();
        p
    };
    let surface = mesh::io::read_surface(example("organ.stl")).unwrap();
    mesh::io::write_surface_in_frame(d.join("liver.stl"), &surface, Frame::Lps).unwrap();
    write_points(d.join("landmarks.mrk.json"), &in_lps_mm("organ_ligaments.csv", "ligament")).unwrap();
    write_points(d.join("targets.mrk.json"), &in_lps_mm("organ_targets.csv", "tumour")).unwrap();
    let mut camera = LabelledPoints::new(vec![[35.0, -60.0, 120.0]]);
    (camera.frame, camera.unit) = (Some(Frame::Lps), Some(mm));
    write_points(d.join("camera.fcsv"), &camera).unwrap();
    // A tumour about the first target, as Slicer exports a segment: kept in the set-up.
    let tumour_centre = in_lps_mm("organ_targets.csv", "tumour").points[0];
    let mut ball = mesh::generate::icosphere(5.0, 2);
    ball.transform(tumour_centre.map(|x| -x), 1.0);
    mesh::io::write_surface_in_frame(d.join("tumour.stl"), &ball, Frame::Lps).unwrap();
    let prepare = [
        "prepare",
        &path(&d.join("liver.stl")),
        "--camera",
        &path(&d.join("camera.fcsv")),
        "--attach",
        &path(&d.join("landmarks.mrk.json")),
        "--targets",
        &path(&d.join("targets.mrk.json")),
        "--samples",
        "40",
        "--tets",
        "800",
        "--structure",
        &path(&d.join("tumour.stl")),
        "--out",
        &path(&d.join("patient")),
    ];
    let (ok, text) = augsim(&prepare);
    assert!(ok && text.contains("frame: LPS (named by"), "{text}");

    // The cloud in RAS and mm as Slicer saves it; the same cloud in LPS and m, given the very values
    // the conversion gives (so that the two registrations see the same numbers).
    let mut cloud = in_lps_mm("organ_cloud.csv", "p");
    cloud.convert(Some(Frame::Ras), mm, mm);
    write_points(d.join("cloud.mrk.json"), &cloud).unwrap();
    let mut in_metres = read_points(d.join("cloud.mrk.json")).unwrap();
    in_metres.convert(Some(Frame::Lps), m, mm);
    write_points_csv(&d.join("cloud_m.csv"), &in_metres.points).unwrap();
    let mut truth = in_lps_mm("organ_truth.csv", "tumour");
    write_points(d.join("truth.mrk.json"), &truth).unwrap();
    truth.convert(Some(Frame::Lps), m, mm);
    write_points_csv(&d.join("truth_m.csv"), &truth.points).unwrap();
    let run = |cloud: &str, truth: &str, out: &str, extra: &[&str]| -> serde_json::Value {
        let [cloud, patient, truth, out] = [cloud, "patient", truth, out].map(|name| path(&d.join(name)));
        let args = [&["register", &cloud, "--patient", &patient, "--truth", &truth, "--out", &out][..], extra].concat();
        let (ok, text) = augsim(&args);
        assert!(ok, "{text}");
        serde_json::from_str(&std::fs::read_to_string(Path::new(&out).join("summary.json")).unwrap()).unwrap()
    };
    let slicer = run("cloud.mrk.json", "truth.mrk.json", "slicer", &[]);
    let metres = run("cloud_m.csv", "truth_m.csv", "metres", &["--units", "m"]);

    let markups = read_points(d.join("slicer/targets.mrk.json")).unwrap();
    assert_eq!((markups.frame, markups.unit), (Some(Frame::Lps), Some(mm)));
    assert_eq!(markups.labels, in_lps_mm("organ_targets.csv", "tumour").labels, "the targets' labels kept");
    let in_m = read_points(d.join("metres/targets.csv")).unwrap();
    assert_eq!(in_m.unit, Some(m), "--units m: targets.csv in m");
    assert_eq!(markups.points.len(), in_m.points.len());
    for (a, b) in markups.points.iter().zip(&in_m.points) {
        assert!((0..3).all(|k| (a[k] - 1e3 * b[k]).abs() < 0.01), "{a:?} mm against {b:?} m");
    }
    // The set-up's tumour comes back moved with the organ, about its registered target, whatever
    // the unit the registration is given.
    let centre = |run: &str| -> Vec<f64> {
        let moved = mesh::io::read_surface(d.join(run).join("tumour_deformed.vtk")).unwrap();
        (0..3).map(|k| moved.vertices.iter().map(|v| v[k]).sum::<f64>() / moved.vertices.len() as f64).collect()
    };
    let (in_slicer, in_metres) = (centre("slicer"), centre("metres"));
    let gap = |a: &[f64], b: &[f64]| (0..3).map(|k| (a[k] - b[k]).powi(2)).sum::<f64>().sqrt();
    assert!(
        gap(&in_slicer, &markups.points[0]) < 1.0,
        "tumour at {in_slicer:?}, its target at {:?}",
        markups.points[0]
    );
    assert!(gap(&in_slicer, &in_metres) < 0.01, "{in_slicer:?} against {in_metres:?}");
    let tre = |s: &serde_json::Value| s["tre_mean_mm"].as_f64().unwrap();
    assert!((tre(&slicer) - tre(&metres)).abs() < 0.01, "TRE {} against {} mm", tre(&slicer), tre(&metres));
    let csv = std::fs::read_to_string(d.join("slicer/targets.csv")).unwrap();
    let own = "# CoordinateSystem = LPS\nx0_mm,y0_mm,z0_mm,x_mm,y_mm,z_mm";
    assert!(csv.starts_with(own), "the patient's own unit and frame: {csv}");

    // The deformed surface: LPS and mm, and on the cloud (closer to it than the organ at rest).
    let (deformed, frame) = mesh::io::read_surface_with_frame(d.join("slicer/organ_deformed.vtk")).unwrap();
    assert_eq!(frame, Some(Frame::Lps));
    let rest = mesh::io::read_surface(d.join("patient/surface.stl")).unwrap();
    // The organ given back is the segmentation's own surface, not the coarser mesh's boundary.
    assert_eq!(deformed.triangles.len(), rest.triangles.len());
    let cloud_lps = in_lps_mm("organ_cloud.csv", "p").points;
    let median_distance = |surface: &mesh::TriSurface| {
        let bvh = mesh::bvh::SurfaceBvh::new(surface).unwrap();
        let mut d: Vec<f64> = cloud_lps.iter().map(|&p| bvh.distance(p)).collect();
        d.sort_by(f64::total_cmp);
        d[d.len() / 2]
    };
    let (on, off) = (median_distance(&deformed), median_distance(&rest));
    println!("TRE {:.3} mm; the cloud's median distance {on:.2} mm to the result, {off:.2} mm at rest", tre(&slicer));
    assert!(on < 3.0 && on < 0.5 * off, "median distance of the cloud: {on:.2} mm to the result, {off:.2} mm at rest");
}

/// A sequence given as 3D Slicer's markups, its truth a folder of them too; a truth whose label
/// is a target left out as not placed fails with the warning that explains it.
#[test]
fn a_sequence_and_its_truth_come_as_markups() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let mm = LengthUnit::Millimetre;
    let (clouds, truths) = (d.join("clouds"), d.join("truths"));
    std::fs::create_dir_all(&clouds).unwrap();
    std::fs::create_dir_all(&truths).unwrap();
    for k in 0..2 {
        write_points(clouds.join(format!("{k}.mrk.json")), &points("cloud.csv", Some(Frame::Lps), mm, true, false))
            .unwrap();
        write_points(truths.join(format!("{k}.fcsv")), &points("truth.csv", Some(Frame::Lps), mm, true, true)).unwrap();
    }
    let targets = d.join("targets.mrk.json");
    write_points(&targets, &points("targets.csv", Some(Frame::Lps), mm, true, true)).unwrap();
    let out = d.join("out");
    let (_, tre) = register(&clouds, &targets, &truths, &out, &[]);
    assert!(tre > 0.0 && tre < 10.0, "{tre}");
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    assert_eq!(summary["per_frame"].as_array().unwrap().len(), 2);
    // Marker 2 not placed in the targets: the truth's marker 2 is no target's, and the warning says why.
    let mut markups: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&targets).unwrap()).unwrap();
    let second = &mut markups["markups"][0]["controlPoints"][1];
    assert_eq!(second["label"], "marker 2");
    second["positionStatus"] = "undefined".into();
    std::fs::write(&targets, markups.to_string()).unwrap();
    let path = |p: &Path| p.to_str().unwrap().to_string();
    let args = ["register", &path(&clouds), "--fem", "liver", "--targets", &path(&targets), "--truth", &path(&truths)];
    let (ok, text) = augsim(&[&args[..], &["--out", &path(&d.join("out2"))]].concat());
    assert!(!ok, "{text}");
    assert!(text.contains("after these warnings: ") && text.contains("is left out: marker 2"), "{text}");
    assert!(text.contains("`marker 2` is no target's label"), "{text}");
}
