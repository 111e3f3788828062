//! `augsim register`: the built-in demo end to end, then the same cloud as a
//! two-frame sequence, and clear errors for bad input.

use std::path::Path;
use std::process::Command;

fn augsim(args: &[&str]) -> (bool, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_augsim")).args(args).output().expect("augsim runs");
    (out.status.success(), format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr)))
}

/// The shipped network for the built-in phantom.
const MODEL: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../../models/liver_ar/model.json");

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

#[test]
fn demo_registers_the_phantom_and_reports_the_tre() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("demo");
    let (ok, text) = augsim(&["register", "--demo", "--out", out.to_str().unwrap(), "--model", MODEL]);
    assert!(ok, "{text}");
    let rows = json(&out.join("summary.json"));
    let rows = rows.as_array().unwrap();
    let methods: Vec<&str> = rows.iter().map(|r| r["method"].as_str().unwrap()).collect();
    assert_eq!(methods, ["FEM co-rotational (3k T4)", "FEM SVK (3k T4)", "U-Net"], "{text}");
    // The figures README.md states for the demo (mean / max TRE, mm), within 5 %.
    for (s, stated) in rows.iter().zip([(2.89, 9.35), (3.36, 10.94), (1.49, 6.89)]) {
        let (tre, max) = (s["tre_mean_mm"].as_f64().unwrap(), s["tre_max_mm"].as_f64().unwrap());
        let near = |value: f64, stated: f64| (value - stated).abs() <= 0.05 * stated;
        assert!(near(tre, stated.0) && near(max, stated.1), "TRE {tre} / {max} mm, README: {stated:?}\n{text}");
        assert!((s["no_deformation_tre_mean_mm"].as_f64().unwrap() - 18.13).abs() < 0.05, "{s}");
        assert!(s["surface_residual_mm"].as_f64().unwrap() < 3.0, "{s}");
    }
    let table = std::fs::read_to_string(out.join("comparison.csv")).unwrap();
    assert!(table
        .starts_with("method,tre_mean_mm,tre_max_mm,surface_residual_mm,time_median_ms,time_p95_ms,iterations,error\nno deformation,"));
    assert_eq!(table.lines().count(), 5, "{table}");
    // Every method registered: the error column is empty on every line.
    assert!(table.lines().skip(1).all(|l| l.split(',').count() == 8 && l.ends_with(',')), "{table}");
    let dir_of = |m: &str| out.join(m);
    for m in ["fem_co_rotational_3k_t4", "fem_svk_3k_t4", "u_net"] {
        for f in ["organ.vtu", "targets.csv", "registration.png", "registration.html"] {
            assert!(dir_of(m).join(f).exists(), "{m}/{f}");
        }
    }
    let targets = std::fs::read_to_string(dir_of("u_net").join("targets.csv")).unwrap();
    assert_eq!(targets.lines().count(), 11, "header and 10 markers:\n{targets}");

    // The case's cloud twice as a sequence, on the liver scenario's model; truth per frame.
    let (seq, truth) = (dir.path().join("seq"), dir.path().join("truth"));
    for d in [&seq, &truth] {
        std::fs::create_dir_all(d).unwrap();
    }
    for f in ["a.csv", "b.csv"] {
        std::fs::copy(out.join("case/cloud.csv"), seq.join(f)).unwrap();
        std::fs::copy(out.join("case/truth.csv"), truth.join(f)).unwrap();
    }
    let scenario = Path::new("liver"); // the built-in scenario, by name
    let targets = out.join("case/targets_rest.csv");
    let seq_out = dir.path().join("seq_out");
    let common = ["--fem", scenario.to_str().unwrap(), "--targets", targets.to_str().unwrap()];
    let (ok, text) = augsim(
        &[
            &["register", seq.to_str().unwrap()],
            &common[..],
            &["--truth", truth.to_str().unwrap(), "--out", seq_out.to_str().unwrap()],
        ]
        .concat(),
    );
    assert!(ok, "{text}");
    assert!(seq_out.join("organ.pvd").exists() && seq_out.join("organ_0001.vtu").exists());
    // The last frame's pictures: its 3D page shows its figures, the cloud and the truth.
    assert!(seq_out.join("registration.png").exists());
    let page = std::fs::read_to_string(seq_out.join("registration.html")).unwrap();
    assert!(page.contains("frame 1 ") && page.contains("TRE mean") && page.contains("targets, true"));
    let summary = json(&seq_out.join("summary.json"));
    assert_eq!((summary["frames"].as_u64(), summary["per_frame"].as_array().unwrap().len()), (Some(2), 2));
    // A second run into the same folder is refused: two runs' files are never mixed.
    let (ok, text) = augsim(
        &[
            &["register", seq.to_str().unwrap()],
            &common[..],
            &["--truth", truth.to_str().unwrap(), "--out", seq_out.to_str().unwrap()],
        ]
        .concat(),
    );
    assert!(!ok && text.contains("holds the results of an earlier run"), "{text}");

    // Errors: a truth file for a two-frame sequence, an empty cloud, a target outside the organ.
    let (ok, text) = augsim(
        &[
            &["register", seq.to_str().unwrap()],
            &common[..],
            &["--truth", out.join("case/truth.csv").to_str().unwrap()],
        ]
        .concat(),
    );
    assert!(!ok && text.contains("1 truth file(s) for 2 cloud frame(s)"), "{text}");
    let empty = dir.path().join("empty.csv");
    std::fs::write(&empty, "x,y,z\n").unwrap();
    let (ok, text) = augsim(&[&["register", empty.to_str().unwrap()], &common[..]].concat());
    assert!(!ok && text.contains("no points"), "{text}");
    let far = dir.path().join("far.csv");
    std::fs::write(&far, "x,y,z\n1,1,1\n").unwrap();
    let (ok, text) = augsim(&[
        "register",
        empty.to_str().unwrap(),
        "--fem",
        scenario.to_str().unwrap(),
        "--targets",
        far.to_str().unwrap(),
    ]);
    assert!(!ok && text.contains("target 1") && text.contains("outside"), "{text}");

    // The frame: targets naming RAS, the cloud given in LPS (--frame LPS) comes back in LPS.
    let points = |path: &Path| -> Vec<Vec<f64>> {
        let text = std::fs::read_to_string(path).unwrap();
        let rows = text.lines().filter(|l| !l.starts_with('#')).skip(1);
        rows.map(|l| l.split(',').map(|v| v.parse().unwrap()).collect()).collect()
    };
    let write = |path: &Path, header: &str, rows: &[Vec<f64>], sign: f64| {
        let flip = |r: &Vec<f64>| format!("{},{},{}", sign * r[0], sign * r[1], r[2]);
        std::fs::write(path, format!("{header}x,y,z\n{}\n", rows.iter().map(flip).collect::<Vec<_>>().join("\n")))
            .unwrap();
    };
    let ras_targets = dir.path().join("targets_ras.csv");
    write(&ras_targets, "# CoordinateSystem = RAS\n", &points(&targets), 1.0);
    let lps_cloud = dir.path().join("cloud_lps.csv");
    write(&lps_cloud, "", &points(&out.join("case/cloud.csv")), -1.0);
    let run = |cloud: &Path, frame: &[&str], name: &str| {
        let run_out = dir.path().join(name);
        let (ok, text) = augsim(
            &[
                &["register", cloud.to_str().unwrap(), "--fem", "liver", "--targets", ras_targets.to_str().unwrap()],
                frame,
                &["--out", run_out.to_str().unwrap()],
            ]
            .concat(),
        );
        assert!(ok, "{text}");
        run_out
    };
    let (ras, lps) = (run(&out.join("case/cloud.csv"), &[], "ras"), run(&lps_cloud, &["--frame", "LPS"], "lps"));
    for (dir, frame) in [(&ras, "RAS"), (&lps, "LPS")] {
        let csv = std::fs::read_to_string(dir.join("targets.csv")).unwrap();
        assert!(csv.starts_with(&format!("# CoordinateSystem = {frame}\n")), "{csv}");
        assert_eq!(json(&dir.join("summary.json"))["frame"], frame);
        let markups = std::fs::read_to_string(dir.join("targets.mrk.json")).unwrap();
        assert!(markups.contains(&format!("\"coordinateSystem\": \"{frame}\"")), "{markups}");
    }
    for (a, b) in points(&ras.join("targets.csv")).iter().zip(points(&lps.join("targets.csv"))) {
        let back = [-b[3], -b[4], b[5]];
        assert!((0..3).all(|d| (a[3 + d] - back[d]).abs() < 1e-9), "{a:?} against {b:?} in LPS");
    }
}

/// Every command that reads lengths parses `--units` the same way: m, cm, mm or um (auto where an
/// organ's surface gives the scale), and refuses another unit before doing anything.
#[test]
fn units_are_parsed_the_same_by_every_command() {
    for command in
        [&["register", "cloud.csv", "--fem", "beam", "--units", "in"][..], &["serve", "--fem", "beam", "--units", "in"]]
    {
        let (ok, text) = augsim(command);
        assert!(!ok && text.contains("invalid value 'in' for '--units"), "{command:?}: {text}");
        assert!(text.contains("must be m, cm, mm or um, got 'in'"), "{command:?}: {text}");
    }
    for command in [
        &["mesh", "organ.stl"][..],
        &["prepare", "organ.stl", "--camera", "0,0,1", "--attach", "a.csv", "--targets", "t.csv", "--out", "o"],
    ] {
        let command = [command, &["--units", "in"]].concat();
        let (ok, text) = augsim(&command);
        assert!(!ok && text.contains("must be m, cm, mm, um or auto, got 'in'"), "{command:?}: {text}");
    }
    // A stream of no frame is refused as the flag given, before anything runs.
    let (ok, text) = augsim(&["register", "--demo", "--frames", "0"]);
    assert!(!ok && text.contains("invalid value '0' for '--frames <FRAMES>'") && text.contains("1..=1000"), "{text}");
    // A comparison makes its own cloud, truth, targets and methods: a registration's arguments
    // beside it are refused, not ignored.
    for extra in
        [&["cloud.csv"][..], &["--units", "mm"], &["--frame", "RAS"], &["--fem", "liver"], &["--structure", "s.stl"]]
    {
        for comparison in [&["--demo"][..], &["--case", "case.toml"]] {
            let (ok, text) = augsim(&[&["register"][..], comparison, extra].concat());
            assert!(!ok && text.contains("cannot be used with"), "{comparison:?} {extra:?}: {text}");
        }
    }
    // Without a way of deforming the organ, register and serve say what to give.
    for command in [&["register", "cloud.csv"][..], &["serve", "--port", "0"]] {
        let (ok, text) = augsim(command);
        assert!(!ok && text.contains("give --patient DIR, --fem SCENARIO, or --model MODEL"), "{command:?}: {text}");
    }
}

/// A folder that holds the run's input (its targets, the sequence's frames), as any folder of
/// files, is not written into: the run's targets.csv would replace the targets read, its organ
/// files be read as frames next.
#[test]
fn an_output_folder_holding_an_input_is_refused() {
    let (dir, examples, seq) = sequence_folder();
    std::fs::copy(examples.join("cloud.csv"), seq.join("f1.csv")).unwrap();
    let targets = dir.path().join("targets.csv");
    std::fs::copy(examples.join("targets.csv"), &targets).unwrap();
    let before = std::fs::read(&targets).unwrap();
    let (cloud, targets) = (seq.join("f1.csv"), targets.to_str().unwrap().to_string());
    for (input, out, held) in
        [(cloud.as_path(), dir.path(), "(seq, targets.csv)"), (seq.as_path(), seq.as_path(), "(f1.csv)")]
    {
        let args = ["register", input.to_str().unwrap(), "--fem", "liver_corotational", "--units", "mm"];
        let (ok, text) = augsim(&[&args[..], &["--targets", &targets, "--out", out.to_str().unwrap()]].concat());
        assert!(!ok && text.contains(&format!("of its own {held}: the run's files could replace them")), "{text}");
        assert!(!text.contains("frame 0"), "registered first:\n{text}");
    }
    // A file given for the folder is named so before anything is read.
    let args = ["register", cloud.to_str().unwrap(), "--fem", "liver_corotational", "--units", "mm", "--out", &targets];
    let (ok, text) = augsim(&args);
    assert!(!ok && text.contains("targets.csv is a file, not a folder: give another --out"), "{text}");
    assert!(!text.contains("method "), "{text}");
    assert_eq!(std::fs::read(dir.path().join("targets.csv")).unwrap(), before);
    assert_eq!(std::fs::read_dir(&seq).unwrap().count(), 1, "written into the sequence's folder");
}

/// A sequence with a bad frame late in it is refused before any frame is registered: no half run
/// is left to block the next one.
#[test]
fn a_bad_frame_late_in_a_sequence_writes_nothing() {
    let (dir, examples, seq) = sequence_folder();
    let cloud = std::fs::read_to_string(examples.join("cloud.csv")).unwrap();
    std::fs::write(seq.join("a.csv"), &cloud).unwrap();
    let mut lines: Vec<&str> = cloud.lines().collect();
    lines[11] = "nan,0,0";
    std::fs::write(seq.join("b.csv"), lines.join("\n")).unwrap();
    let (out, targets) = (dir.path().join("run"), examples.join("targets.csv"));
    let (ok, text) = augsim(&[
        "register",
        seq.to_str().unwrap(),
        "--fem",
        "liver_corotational",
        "--units",
        "mm",
        "--targets",
        targets.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(!ok && text.contains("b.csv") && text.contains("line 12"), "{text}");
    assert!(!text.contains("frame 0"), "registered first:\n{text}");
    assert!(!out.exists(), "the run's folder is left behind");
}

/// A temporary folder with an empty `seq` folder in it for a sequence's frames, and the examples'.
fn sequence_folder() -> (tempfile::TempDir, std::path::PathBuf, std::path::PathBuf) {
    let dir = tempfile::tempdir().unwrap();
    let seq = dir.path().join("seq");
    std::fs::create_dir(&seq).unwrap();
    (dir, Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples"), seq)
}
