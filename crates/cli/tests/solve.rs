//! `augsim solve` on the shipped large-deformation scenarios, and the diagnosis
//! of Saint-Venant-Kirchhoff's compressive limit point.

use std::path::Path;
use std::process::Command;

/// Runs `augsim solve`, returns (success, stdout + stderr).
fn solve(scenario: &Path, out: &Path) -> (bool, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_augsim"))
        .args(["solve", scenario.to_str().unwrap(), "-o", out.to_str().unwrap()])
        .output()
        .unwrap();
    (out.status.success(), format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr)))
}

fn max_displacement(text: &str) -> f64 {
    let line = text.lines().find(|l| l.starts_with("max |u|")).unwrap_or_else(|| panic!("no max |u| in:\n{text}"));
    line.split_whitespace().nth(2).unwrap().parse().unwrap()
}

#[test]
fn neo_hookean_phantom_reaches_paper_scale_deformation() {
    let dir = tempfile::tempdir().unwrap();
    for (scenario, at_least) in [("liver_large", 0.08), ("liver_tool", 0.04)] {
        let out = dir.path().join("out.vtu");
        let (ok, text) = solve(Path::new(scenario), &out);
        assert!(ok, "{scenario} failed:\n{text}");
        assert!(text.contains("F-bar elements"), "{scenario} must use F-bar at nu >= 0.45:\n{text}");
        let u = max_displacement(&text);
        assert!(u >= at_least, "{scenario}: max |u| = {u} m < {at_least} m");
        assert!(out.exists());
    }
}

#[test]
fn svk_past_its_limit_point_is_diagnosed() {
    let dir = tempfile::tempdir().unwrap();
    let scenario = dir.path().join("svk.toml");
    std::fs::write(
        &scenario,
        r#"kind = "static"
name = "svk_push"
[mesh.phantom]
tets = 2000
[material]
law = "svk"
young = 5000.0
poisson = 0.48
formulation = "standard"
[[fixed]]
select = { region = "fixed" }
[[force]]
select = { region = "push" }
total = [0.0, 0.0, -1.0]
"#,
    )
    .unwrap();
    let (ok, text) = solve(&scenario, &dir.path().join("out.vtu"));
    assert!(!ok, "SVK must not converge under this load:\n{text}");
    assert!(text.contains("passed its compressive limit point beyond load factor 0."), "{text}");
    assert!(text.contains("element ") && text.contains("neo_hookean"), "{text}");
    // A load that defeats the first step: told where the failing iterate crushed the beam, not at
    // the rest state (a stretch of 1).
    std::fs::write(
        &scenario,
        r#"kind = "static"
name = "svk_crush"
[mesh.box]
min = [0.0, 0.0, 0.0]
max = [4.0, 1.0, 1.0]
cells = [8, 2, 2]
element = "hex"
[material]
law = "svk"
young = 300.0
poisson = 0.4
[[fixed]]
select = { box = { min = [-0.001, -0.001, -0.001], max = [0.001, 1.001, 1.001] } }
[[traction]]
select = { box = { min = [3.999, -0.001, -0.001], max = [4.001, 1.001, 1.001] } }
traction = [0.0, 0.0, -1e5]
"#,
    )
    .unwrap();
    let (ok, text) = solve(&scenario, &dir.path().join("out.vtu"));
    let stretch: f64 = text.split("principal stretch of ").nth(1).and_then(|t| t[..5].parse().ok()).expect(&text);
    assert!(!ok && stretch < 0.577, "{text}");
}

/// A missing scenario file is named, with the system's reason said once (not repeated by the
/// error chain).
#[test]
fn a_missing_scenario_file_is_reported_once() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("missing.toml");
    let (ok, text) = solve(&missing, &dir.path().join("out.vtu"));
    assert!(!ok, "{text}");
    let line = text.lines().find(|l| l.starts_with("error:")).unwrap_or_else(|| panic!("no error line:\n{text}"));
    assert!(line.contains("missing.toml"), "{line}");
    assert_eq!(line.matches("os error").count(), 1, "the reason said once: {line}");
}

/// An output that cannot be written fails before the solve, saying which part of its path is a
/// file, rather than after it.
#[test]
fn an_output_that_cannot_be_written_fails_before_the_solve() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("afile");
    std::fs::write(&file, b"x").unwrap();
    let (ok, text) = solve(Path::new("beam"), &file.join("out.vtu"));
    assert!(!ok, "{text}");
    assert!(text.contains(&format!("{} is a file, not a directory", file.display())), "{text}");
    assert!(!text.contains("max |u|") && !text.contains("iterations"), "solved first:\n{text}");
}

/// An output named as the file a command reads (through another spelling of its path) is refused
/// before any work, the input left as it was: the surface `mesh` meshes, the mesh a scenario reads.
#[test]
fn mesh_and_solve_refuse_to_write_over_their_input() {
    let dir = tempfile::tempdir().unwrap();
    let run = |args: &[&str]| {
        let out = Command::new(env!("CARGO_BIN_EXE_augsim")).args(args).output().unwrap();
        (
            out.status.success(),
            format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr)),
        )
    };
    let surface = dir.path().join("organ.stl");
    std::fs::copy(concat!(env!("CARGO_MANIFEST_DIR"), "/../../examples/organ.stl"), &surface).unwrap();
    let before = std::fs::read(&surface).unwrap();
    let again = dir.path().join("sub/../organ.stl");
    let (ok, text) = run(&["mesh", surface.to_str().unwrap(), "--tets", "300", "-o", again.to_str().unwrap()]);
    assert!(!ok && text.contains("would be written over the surface it meshes"), "{text}");
    assert!(!text.contains("mesh       "), "meshed first:\n{text}");
    assert_eq!(std::fs::read(&surface).unwrap(), before);

    let volume = dir.path().join("organ.vtu");
    let (ok, text) = run(&["mesh", "--tets", "300", "-o", volume.to_str().unwrap()]);
    assert!(ok, "{text}");
    let scenario = dir.path().join("s.toml");
    std::fs::write(
        &scenario,
        "kind = \"static\"\nname = \"own\"\n[mesh.file]\npath = \"organ.vtu\"\n[material]\nlaw = \"linear\"\n\
         young = 5000.0\npoisson = 0.45\n[[fixed]]\nselect = { box = { min = [-1, -1, -1], max = [1, 1, 0] } }\n",
    )
    .unwrap();
    let before = std::fs::read(&volume).unwrap();
    let (ok, text) = solve(&scenario, &dir.path().join("./organ.vtu"));
    assert!(!ok && text.contains("which the solve reads"), "{text}");
    assert!(!text.contains("max |u|"), "solved first:\n{text}");
    assert_eq!(std::fs::read(&volume).unwrap(), before);
}

/// Without repair a surface must be a closed 2-manifold as it is: one that crosses itself (two
/// overlapping cubes) is refused, not meshed with its overlap counted twice.
#[test]
fn a_surface_crossing_itself_is_refused_without_repair() {
    let dir = tempfile::tempdir().unwrap();
    let cube = |o: f64| -> Vec<[[f64; 3]; 3]> {
        let p =
            |i: usize| [o + 100.0 * (i & 1) as f64, o + 100.0 * (i >> 1 & 1) as f64, o + 100.0 * (i >> 2 & 1) as f64];
        let quads = [[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]];
        quads.iter().flat_map(|q| [[p(q[0]), p(q[1]), p(q[2])], [p(q[0]), p(q[2]), p(q[3])]]).collect()
    };
    let mut text = String::from("solid two\n");
    for t in cube(0.0).into_iter().chain(cube(50.0)) {
        text.push_str("facet normal 0 0 0\nouter loop\n");
        t.iter().for_each(|v| text.push_str(&format!("vertex {} {} {}\n", v[0], v[1], v[2])));
        text.push_str("endloop\nendfacet\n");
    }
    let stl = dir.path().join("two.stl");
    std::fs::write(&stl, text + "endsolid two\n").unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_augsim"))
        .args(["mesh", stl.to_str().unwrap(), "--no-repair", "--tets", "300", "-o"])
        .arg(dir.path().join("two.vtu"))
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && text.contains("the surface crosses itself"), "{text}");
}

/// A Young's modulus far below soft tissues' (one written in kPa) is doubted aloud, whether the
/// solve then fails or not.
#[test]
fn a_modulus_in_kilopascals_is_doubted() {
    let dir = tempfile::tempdir().unwrap();
    let scenario = dir.path().join("kpa.toml");
    let text = |young: f64| {
        format!(
            "kind = \"static\"\nname = \"kpa\"\n[mesh.phantom]\ntets = 500\n[material]\nlaw = \"neo_hookean\"\n\
             young = {young:?}\npoisson = 0.45\n[[fixed]]\nselect = {{ region = \"fixed\" }}\n[[force]]\n\
             select = {{ region = \"push\" }}\ntotal = [0.0, 0.0, -0.001]\n"
        )
    };
    std::fs::write(&scenario, text(5.0)).unwrap();
    let (_, said) = solve(&scenario, &dir.path().join("out.vtu"));
    assert!(said.contains("E = 5 Pa, where soft tissues are 0.1 to 100 kPa: is it in kPa?"), "{said}");
    std::fs::write(&scenario, text(5000.0)).unwrap();
    let (ok, said) = solve(&scenario, &dir.path().join("out.vtu"));
    assert!(ok && !said.contains("kPa?"), "{said}");
}

/// A solve's file is shown by `view`: its displacement field named (its reaction force is not one),
/// one HTML file written, never over another file.
#[test]
fn a_solved_file_is_viewed() {
    let dir = tempfile::tempdir().unwrap();
    let (vtu, html) = (dir.path().join("beam.vtu"), dir.path().join("beam.html"));
    let (ok, text) = solve(Path::new("beam"), &vtu);
    assert!(ok, "{text}");
    let out = Command::new(env!("CARGO_BIN_EXE_augsim"))
        .args(["view", "--file", vtu.to_str().unwrap(), "-o", html.to_str().unwrap()])
        .output()
        .unwrap();
    let said = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{said}{}", String::from_utf8_lossy(&out.stderr));
    assert!(said.contains("displacement fields: displacement\n") && said.contains("wrote"), "{said}");
    assert!(std::fs::read_to_string(&html).unwrap().contains("<html"), "an HTML page");
    // The page only: asked to write over the mesh it shows, it refuses and leaves the mesh as it was.
    let before = std::fs::read(&vtu).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_augsim"))
        .args(["view", "--file", vtu.to_str().unwrap(), "-o", vtu.to_str().unwrap()])
        .output()
        .unwrap();
    let said = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && said.contains("the viewer writes an HTML page"), "{said}");
    assert_eq!(std::fs::read(&vtu).unwrap(), before);
}
