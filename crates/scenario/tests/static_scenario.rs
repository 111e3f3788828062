//! Scenarios build the problems they describe: static problems, and a registration case's frames.

use std::path::Path;

use augsim_scenario::StaticScenario;

/// `[[attachment]]` and `[[patch_force]]` on the phantom's balls: point springs holding the
/// attachment, nodal forces summing to the total; a region given twice or not at all, and a
/// region the phantom has no ball for, are clear errors.
#[test]
fn geometric_attachments_and_patch_forces_build_and_bad_ones_are_named() {
    let text = |region: &str| {
        format!(
            "kind = \"static\"\nname = \"g\"\n[mesh.phantom]\ntets = 800\n[material]\nlaw = \"linear\"\n\
             young = 5000.0\npoisson = 0.45\n[[attachment]]\n{region}\nstiffness = 5.0e8\n[[patch_force]]\n\
             phantom = \"push\"\ntotal = [0.0, 0.0, -0.3]\n"
        )
    };
    let build = |region: &str| {
        let s = StaticScenario::parse(&text(region), Path::new("g.toml"))?;
        s.build_problem(Path::new("."))
    };
    let p = build("phantom = \"fixed\"").unwrap();
    assert!(p.point_springs.len() > 100 && p.dirichlet.is_empty());
    let fz: f64 = p.f_ext.iter().skip(2).step_by(3).sum();
    assert!((fz + 0.3).abs() < 1e-12, "{fz}");
    // Only the visible side of the push patch is loaded.
    let loaded = (0..p.mesh.num_nodes()).filter(|&n| p.f_ext[3 * n + 2] != 0.0);
    assert!(loaded.clone().all(|n| p.mesh.nodes[n][2] > 0.0), "the push patch is on top");
    assert!(build("ball = { centre = [-0.015, 0.0, -0.03], radius = 0.03 }").is_ok());
    let e = |region: &str| build(region).unwrap_err().to_string();
    assert!(e("").contains("give either"), "{}", e(""));
    let both = "phantom = \"fixed\"\nball = { centre = [0.0, 0.0, 0.0], radius = 0.01 }";
    assert!(e(both).contains("give either"), "{}", e(both));
    assert!(e("phantom = \"liver\"").contains("no ball behind region 'liver'"), "{}", e("phantom = \"liver\""));
    let far = "ball = { centre = [1.0, 1.0, 1.0], radius = 0.01 }";
    assert!(e(far).contains("attachment 1") && e(far).contains("no part of the mesh"), "{}", e(far));
}

/// Selections on any mesh from a scenario file: the attached nodes near landmarks of a CSV file
/// next to the scenario (its relative path starts at the scenario's directory, wherever the
/// program runs), the load on what a camera above sees.
#[test]
fn landmark_and_camera_selections_in_a_scenario_file() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::create_dir(dir.path().join("patient")).unwrap();
    std::fs::write(dir.path().join("patient/ligaments.csv"), "x,y,z\n0.0,0.0,0.0\n0.1,0.0,0.0\n").unwrap();
    let text = r#"
kind = "static"
name = "landmarks"

[mesh.box]
min = [0.0, 0.0, 0.0]
max = [0.1, 0.1, 0.1]
cells = [4, 4, 4]
element = "tet"

[material]
law = "corotational"
young = 5000.0
poisson = 0.45

[[fixed]]
select = { near = { file = "ligaments.csv", distance = 0.026, surface = true } }

[[traction]]
select = { facing = { view = [0.0, 0.0, -1.0] } }
traction = [0.0, 0.0, -10.0]
"#;
    let path = dir.path().join("patient/scenario.toml");
    std::fs::write(&path, text).unwrap();
    let (scenario, base) = StaticScenario::load(&path).unwrap();
    let problem = scenario.build_problem(&base).unwrap();
    // Around each of the two bottom corners: the corner and its 3 neighbours on the boundary.
    assert_eq!(problem.dirichlet.len(), 2 * 4, "{:?}", problem.dirichlet);
}

/// The static scenario `docs/usage.md` shows describes the built-in `beam`'s problem: the same
/// fixed nodes and the same loads on its free end.
#[test]
fn the_usage_page_s_example_scenario_is_the_built_in_beam() {
    let page = std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("../../docs/usage.md")).unwrap();
    let start = page.find("```toml\nkind = \"static\"").expect("the page's static example") + "```toml\n".len();
    let text = &page[start..start + page[start..].find("```").unwrap()];
    let example = StaticScenario::parse(text, Path::new("usage.toml")).unwrap().build_problem(Path::new(".")).unwrap();
    let beam = StaticScenario::builtin("beam").build_problem(Path::new(".")).unwrap();
    assert_eq!(example.mesh.nodes, beam.mesh.nodes);
    assert_eq!(example.dirichlet, beam.dirichlet);
    assert!(example.f_ext.iter().any(|&f| f != 0.0), "the example loads the beam");
    assert_eq!(example.f_ext, beam.f_ext);
}

/// A case's press and release reaches its force at frame ⌈n / 2⌉ for any number of frames n, and
/// keeps the sine profile sin(π k / (n + 1)) for odd n.
#[test]
fn a_press_and_release_reaches_the_case_s_force_for_any_number_of_frames() {
    let mut truth = augsim_scenario::CaseScenario::builtin().truth;
    for n in 2..=8 {
        truth.frames = n;
        let forces = truth.frame_forces();
        assert_eq!(forces.len(), n);
        assert!((forces[n.div_ceil(2) - 1] - truth.force).abs() < 1e-12, "{n} frames: {forces:?}");
        assert!(forces.iter().all(|&f| f > 0.0 && f <= truth.force + 1e-12), "{n} frames: {forces:?}");
        if n % 2 == 1 {
            for (k, f) in (1..).zip(&forces) {
                let sine = truth.force * (std::f64::consts::PI * k as f64 / (n + 1) as f64).sin();
                assert!((f - sine).abs() < 1e-12, "{n} frames, frame {k}: {f} against {sine}");
            }
        }
    }
}

/// A file as some editors save it (a byte-order mark first) reads as without; a load or a mesh scale
/// that no solve can use is named by its section and key, before any solve.
#[test]
fn a_byte_order_mark_is_read_and_unusable_numbers_are_named() {
    let text = "kind = \"static\"\nname = \"b\"\n[mesh.box]\nmin = [0.0, 0.0, 0.0]\nmax = [0.1, 0.02, 0.02]\n\
                cells = [4, 1, 1]\nelement = \"hex\"\n[material]\nlaw = \"linear\"\nyoung = 5000.0\npoisson = 0.3\n\
                [[fixed]]\nselect = { box = { min = [-1.0, -1.0, -1.0], max = [1e-9, 1.0, 1.0] } }\n";
    let parse = |text: &str| StaticScenario::parse(text, Path::new("b.toml"));
    let with_bom = parse(&format!("\u{feff}{text}")).unwrap();
    assert_eq!(with_bom.name, "b");
    let load = "[[prescribed]]\nselect = { box = { min = [0.099, -1.0, -1.0], max = [1.0, 1.0, 1.0] } }\n\
                displacement = [0.0, 0.0, nan]\n";
    let err = parse(&format!("{text}{load}")).unwrap().build_problem(Path::new(".")).unwrap_err().to_string();
    assert!(err.contains("prescribed 1: displacement = [0.0, 0.0, NaN] must be finite"), "{err}");
    // A node both fixed and prescribed a displacement: refused, whichever comes first in the file.
    let clash = "[[prescribed]]\nselect = { box = { min = [-1.0, -1.0, -1.0], max = [1.0, 1.0, 1.0] } }\n\
                 displacement = [0.0, 0.0, 0.005]\n";
    let err = parse(&format!("{text}{clash}")).unwrap().build_problem(Path::new(".")).unwrap_err().to_string();
    assert!(err.contains("prescribed 1: node 0 is already held at (0, 0, 0) mm (by [[fixed]]"), "{err}");
    assert!(err.ends_with("not at (0, 0, 5) mm: give each node one displacement"), "{err}");
    let force = "[[force]]\nselect = { box = { min = [0.099, -1.0, -1.0], max = [1.0, 1.0, 1.0] } }\n\
                 total = [inf, 0.0, 0.0]\n";
    let err = parse(&format!("{text}{force}")).unwrap().build_problem(Path::new(".")).unwrap_err().to_string();
    assert!(err.contains("force 1: total = [inf, 0.0, 0.0] must be finite"), "{err}");
    // Gravity and springs are named too, as their keys give them.
    let gravity = text.replace("name = \"b\"\n", "name = \"b\"\ngravity = [0.0, 0.0, nan]\n");
    let err = parse(&gravity).unwrap().build_problem(Path::new(".")).unwrap_err().to_string();
    assert!(err.contains("gravity = [0.0, 0.0, NaN] must be finite"), "{err}");
    let springs = "[[springs]]\nselect = { box = { min = [0.099, -1.0, -1.0], max = [1.0, 1.0, 1.0] } }\n\
                   stiffness = -10.0\n";
    let err = parse(&format!("{text}{springs}")).unwrap().build_problem(Path::new(".")).unwrap_err().to_string();
    assert!(err.contains("springs 1: stiffness = -10 N/m must be at least 0"), "{err}");
    // Two meshes: one is kept.
    let err = parse(&format!("{text}[mesh.phantom]\ntets = 500\n")).unwrap_err().to_string();
    assert!(err.contains("is given more than one of them here: keep one"), "{err}");
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("m.vtu");
    mesh::io::write_vtu(&file, &mesh::box_tet([0.0; 3], [1.0; 3], [1, 1, 1]).unwrap(), &[]).unwrap();
    let scaled = format!(
        "kind = \"static\"\nname = \"s\"\n[mesh.file]\npath = \"{}\"\nscale = -1.0\n[material]\nlaw = \"linear\"\n\
         young = 5000.0\npoisson = 0.3\n",
        file.display()
    );
    let err = parse(&scaled).unwrap().build_problem(Path::new(".")).unwrap_err().to_string();
    assert!(err.contains("[mesh.file] scale must be finite and > 0, got -1"), "{err}");
    // A file's unit brings it to metres, as the factor would; a unit augsim does not know is named.
    let in_unit = |key: &str| scaled.replace("scale = -1.0", key);
    let mesh = |key: &str| parse(&in_unit(key)).unwrap().build_problem(Path::new(".")).unwrap().mesh;
    let (millimetres, factor) = (mesh("unit = \"mm\""), mesh("scale = 0.001"));
    assert_eq!(millimetres.nodes, factor.nodes);
    assert_eq!(mesh::longest_side(millimetres.bounds()), 0.001);
    assert_eq!(mesh("unit = \"cm\"\nscale = 2.0").nodes, mesh("scale = 0.02").nodes);
    let err = parse(&in_unit("unit = \"ft\"")).unwrap_err().to_string();
    assert!(err.contains("ft") && err.contains("mm"), "{err}");
}

/// A selection by position that picks nothing on a mesh spanning metres (an organ in millimetres
/// or centimetres: scenarios are in metres) asks for the unit in which it is an organ's size,
/// naming `[mesh.file] unit` for a mesh read from a file only; on a mesh of an organ's size it
/// does not, nor where a region or a landmarks file is at fault.
#[test]
fn an_empty_selection_on_a_mesh_of_metres_asks_for_its_unit() {
    let dir = tempfile::tempdir().unwrap();
    let with = |mesh: &str, force: &str| {
        let text = format!(
            "kind = \"static\"\nname = \"mm\"\n{mesh}[material]\nlaw = \"linear\"\nyoung = 5000.0\npoisson = 0.3\n\
             [[fixed]]\nselect = {{ box = {{ min = [-1.0, -1.0, -1.0], max = [1e4, 1e4, 1e-9] }} }}\n[[force]]\n\
             select = {force}\ntotal = [0.0, 0.2, 0.0]\n"
        );
        let scenario = StaticScenario::parse(&text, &dir.path().join("mm.toml")).unwrap();
        scenario.build_problem(dir.path()).unwrap_err().to_string()
    };
    let cube = |max: f64| {
        format!(
            "[mesh.box]\nmin = [0.0, 0.0, 0.0]\nmax = [{max}, {max}, {max}]\ncells = [2, 2, 2]\nelement = \"tet\"\n"
        )
    };
    let ball = "{ ball = { centre = [0.0, -0.09, 0.0], radius = 0.03 } }";
    let error = |max: f64| with(&cube(max), ball);
    let millimetres = error(200.0);
    assert!(millimetres.contains("force selection: ") && millimetres.contains("picks no node"), "{millimetres}");
    assert!(
        millimetres.contains("the mesh spans 200 m: is it in millimetres? scenarios are in metres)"),
        "{millimetres}"
    );
    // 8 m across is an organ in centimetres (8 mm is none); 50 m one in either; 5 km in neither.
    assert!(error(8.0).contains("is it in centimetres? scenarios are in metres"), "{}", error(8.0));
    assert!(error(50.0).contains("is it in millimetres or centimetres?"), "{}", error(50.0));
    assert!(error(5000.0).contains("where organs span 2 to 60 cm: is its unit right?"), "{}", error(5000.0));
    assert!(!error(0.2).contains("millimetres"), "{}", error(0.2));
    // A box has no unit key; a mesh file has.
    assert!(!error(200.0).contains("[mesh.file]"), "{}", error(200.0));
    let mesh = mesh::box_tet([0.0; 3], [200.0; 3], [2, 2, 2]).unwrap();
    mesh::io::write_mesh(dir.path().join("cube.vtu"), &mesh, &[]).unwrap();
    let file = with("[mesh.file]\npath = \"cube.vtu\"\n", ball);
    assert!(file.contains("scenarios are in metres: [mesh.file] unit = \"mm\""), "{file}");
    for unrelated in ["{ region = \"liver\" }", "{ near = { file = \"missing.csv\", distance = 0.01 } }"] {
        let e = with(&cube(200.0), unrelated);
        assert!(e.contains("force selection: ") && !e.contains("the mesh spans"), "{e}");
    }
    // Landmarks in mm under a bare header, about a 20 cm organ: their file's header is named.
    std::fs::write(dir.path().join("mm.csv"), "x,y,z\n100,100,200\n").unwrap();
    let e = with(&cube(0.2), "{ near = { file = \"mm.csv\", distance = 0.01 } }");
    assert!(e.contains("within 0.01 m of the landmarks of ") && e.contains("mm.csv picks no node"), "{e}");
    assert!(e.contains("are these in millimetres?; a landmarks file's header x_mm, y_mm, z_mm names its unit"), "{e}");
}
