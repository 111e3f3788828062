//! `augsim assimilate` on a small beam: a synthetic run writes its tracks, the tracks fed back with
//! `--observations` give the same estimate, and a bad track file stops the run with its file and line.

use std::path::Path;
use std::process::Command;

/// Runs `augsim assimilate` with `args`; returns (success, stdout + stderr).
fn assimilate(args: &[&str]) -> (bool, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_augsim")).arg("assimilate").args(args).output().unwrap();
    (out.status.success(), format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr)))
}

fn young(summary: &Path) -> f64 {
    let json: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(summary).unwrap()).unwrap();
    json["young"]["mean"].as_f64().unwrap()
}

#[test]
fn synthetic_tracks_fed_back_and_bad_files() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // The filter crate's test beam: 8 steps, Young's modulus from 10 tracked points, deformation every 4 steps.
    let scenario = Path::new(env!("CARGO_MANIFEST_DIR")).join("../app/tests/data/beam_assimilation.toml");
    let s = scenario.to_str().unwrap();
    let synthetic = d.join("synthetic");
    let (ok, text) = assimilate(&[s, "-o", synthetic.to_str().unwrap()]);
    assert!(ok, "{text}");
    assert!(text.contains("reference    8 steps") && text.contains("young        μ ="), "{text}");
    assert!(text.contains("on the filter's own model (an inverse crime"), "{text}");
    assert!(synthetic.join("deformation.pvd").exists() && synthetic.join("deformation/step_00008.vtu").exists());
    // A second run into the same folder is refused: two runs' files are never mixed.
    // (`--out`, as every command writing a folder names it, the error's advice.)
    let (ok, again) = assimilate(&[s, "--out", synthetic.to_str().unwrap()]);
    assert!(!ok && again.contains("holds the results of an earlier run (summary.json): give another --out"), "{again}");

    let tracks = synthetic.join("tracks/observations.csv");
    let read = d.join("read");
    let (ok, text) = assimilate(&[s, "--observations", tracks.to_str().unwrap(), "-o", read.to_str().unwrap()]);
    assert!(ok, "{text}");
    assert!(text.contains("tracks       8 frames") && text.contains("0 occluded"), "{text}");
    assert_eq!(young(&synthetic.join("summary.json")).to_bits(), young(&read.join("summary.json")).to_bits());
    // The same file (in m) read as mm: its features crowd within a fraction of a millimetre.
    let (ok, text) = assimilate(&[s, "--observations", tracks.to_str().unwrap(), "--units", "mm", "-o", "/dev/null/x"]);
    assert!(!ok && text.contains("features span") && text.contains("in metres read as millimetres"), "{text}");

    let bad = d.join("bad.csv");
    std::fs::write(&bad, "frame,id,x,y,z\n0,f0,0.05,0.01,0.02\n1,f0,0.05,oops,0.02\n").unwrap();
    let (ok, text) = assimilate(&[s, "--observations", bad.to_str().unwrap(), "-o", d.join("bad").to_str().unwrap()]);
    assert!(!ok);
    assert!(text.contains(&format!("error: {}:3: y = \"oops\" is not a number", bad.display())), "{text}");
    // A prior whose mean gives no modulus is refused before the filter starts, naming its key.
    let text = std::fs::read_to_string(&scenario).unwrap();
    for (mean, said) in [
        ("transform = \"exp\"\nprior_mean = 800.0", "of inf Pa (under transform = \"exp\" it is ln E)"),
        ("transform = \"identity\"\nprior_mean = -1000.0", "of -1000 Pa:"),
    ] {
        let bad_prior = d.join("bad_prior.toml");
        std::fs::write(&bad_prior, text.replace("transform = \"exp\"\nprior_mean = 8.0", mean)).unwrap();
        let (ok, out) = assimilate(&[bad_prior.to_str().unwrap(), "-o", d.join("prior").to_str().unwrap()]);
        assert!(!ok && out.contains("[young] prior_mean = ") && out.contains(said), "{out}");
        assert!(!out.contains("filter iteration"), "{out}");
    }
    // A prior σ as wide as its mean, on the modulus itself: the sigma points reach past zero.
    let wide = d.join("wide.toml");
    std::fs::write(&wide, text.replace("transform = \"exp\"\nprior_mean = 8.0\nprior_std = 0.5", WIDE)).unwrap();
    let (ok, out) = assimilate(&[wide.to_str().unwrap(), "-o", d.join("wide").to_str().unwrap()]);
    assert!(!ok && out.contains("sigma point") && out.contains("a prior_std not well below prior_mean"), "{out}");
    // A tracking noise given in mm is named, before the reference run it would spoil.
    let noisy = d.join("noisy.toml");
    std::fs::write(&noisy, text.replace("noise_std = 1e-5", "noise_std = 0.2")).unwrap();
    let (ok, out) = assimilate(&[noisy.to_str().unwrap(), "-o", d.join("noisy").to_str().unwrap()]);
    assert!(!ok && out.contains("observations.noise_std = 0.2 m is 192 % of the organ's size (104 mm)"), "{out}");
    // A folder of the user's files is no place for a run's (it writes tracks/, trace.csv, …).
    std::fs::create_dir_all(d.join("mine/tracks")).unwrap();
    std::fs::write(d.join("mine/tracks/observations.csv"), "my own tracks").unwrap();
    let (ok, out) = assimilate(&[s, "-o", d.join("mine").to_str().unwrap()]);
    assert!(!ok && out.contains("holds 1 file(s) or folder(s) of its own (tracks)"), "{out}");
    assert_eq!(std::fs::read_to_string(d.join("mine/tracks/observations.csv")).unwrap(), "my own tracks");
    let (ok, out) = assimilate(&[s, "--every", "0", "-o", d.join("every").to_str().unwrap()]);
    assert!(!ok && out.contains("--every must be at least 1"), "{out}");
    // Track options need --observations.
    let (ok, text) = assimilate(&[s, "--controls", bad.to_str().unwrap()]);
    assert!(!ok && text.contains("--observations"), "{text}");
}

/// A prior on the modulus itself whose σ equals its mean.
const WIDE: &str = "transform = \"identity\"\nprior_mean = 4000.0\nprior_std = 4000.0";

#[test]
fn star_sigma_points_from_the_command_line() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let scenario = Path::new(env!("CARGO_MANIFEST_DIR")).join("../app/tests/data/beam_assimilation.toml");
    let s = scenario.to_str().unwrap();
    let star = d.join("star");
    let (ok, text) = assimilate(&[s, "--sigma-points", "star", "-o", star.to_str().unwrap()]);
    assert!(ok, "{text}");
    assert!(text.contains("1 parameter(s), 3 star sigma points"), "{text}");
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(star.join("summary.json")).unwrap()).unwrap();
    assert_eq!((json["sigma_points"].as_u64(), json["sigma_point_set"].as_str()), (Some(3), Some("star")));
    assert!((young(&star.join("summary.json")) - 5000.0).abs() < 50.0);
    // An unknown set is refused with the choices.
    let (ok, text) = assimilate(&[s, "--sigma-points", "cross", "-o", d.join("cross").to_str().unwrap()]);
    assert!(!ok && text.contains("cross") && text.contains("`simplex` or `star`"), "{text}");
}

#[test]
fn discrepancy_from_the_command_line() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let scenario = Path::new(env!("CARGO_MANIFEST_DIR")).join("../app/tests/data/beam_assimilation.toml");
    let s = scenario.to_str().unwrap();
    let (plain, honest) = (d.join("plain"), d.join("honest"));
    let (ok, text) = assimilate(&[s, "-o", plain.to_str().unwrap()]);
    assert!(ok && !text.contains("discrepancy"), "{text}");
    let (ok, text) =
        assimilate(&[s, "--discrepancy", "systematic", "--discrepancy-dof", "2", "-o", honest.to_str().unwrap()]);
    assert!(ok, "{text}");
    assert!(text.contains("discrepancy  σ = ") && text.contains("misfit χ²/ν = "), "{text}");
    assert_eq!(young(&plain.join("summary.json")).to_bits(), young(&honest.join("summary.json")).to_bits());
    let (ok, text) = assimilate(&[s, "--discrepancy", "bias", "-o", d.join("bias").to_str().unwrap()]);
    assert!(!ok && text.contains("`none`, `independent` or `systematic`"), "{text}");
    let (ok, text) = assimilate(&[
        s,
        "--discrepancy",
        "systematic",
        "--discrepancy-dof",
        "0",
        "-o",
        d.join("dof").to_str().unwrap(),
    ]);
    assert!(!ok && text.contains("'--discrepancy-dof <D>': expected a finite number at least 1, got 0"), "{text}");
}
