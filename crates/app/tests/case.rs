//! The comparison case as a TOML scenario: the built-in one is the documented case, a scenario
//! builds the case exactly as the code it replaced, and bad files are clear errors.

use std::path::Path;

use augsim_app::case::{case_methods, synthetic_case};
use augsim_app::simulate::simulate_cloud;
use fem::{Formulation, Law, Material, Problem, SolverOptions, StaticSolver};
use mesh::Point;
use register::{Organ, RegistrationOptions, RigidTransform};
use scenario::registration::{CameraSpec, MethodKind};
use scenario::CaseScenario;

/// The built-in case's text.
fn builtin_text() -> &'static str {
    scenario::builtin("register_case").unwrap()
}

#[test]
fn the_builtin_case_is_the_documented_one() {
    let s = CaseScenario::builtin();
    assert_eq!(
        s,
        CaseScenario::parse(builtin_text(), Path::new("register_case.toml")).unwrap(),
        "the file is the built-in text"
    );
    assert_eq!((s.truth.tets, s.models.tets), (9000, 3000));
    assert_eq!(
        s.truth.material,
        Material::new(Law::NeoHookean, 5000.0, 0.48).with_order(2).with_formulation(Formulation::Standard)
    );
    assert_eq!((s.truth.force, s.truth.direction), (1.5, [0.0, 0.0, -1.0]));
    assert_eq!((s.truth.fixed.as_str(), s.truth.load.as_str(), s.truth.targets.as_str()), ("fixed", "push", "markers"));
    assert_eq!(s.truth.patch, None);
    let c = &s.camera;
    assert_eq!((c.view, c.points, c.noise, c.outliers, c.seed), ([0.0, 0.0, -1.0], 1500, 1e-3, 0.05, 1));
    assert_eq!(s.misalignment.transform().unwrap(), RigidTransform::identity());
    assert_eq!(s.registration, RegistrationOptions::default());
    let methods: Vec<(&str, MethodKind, Option<Material>)> =
        s.models.method.iter().map(|m| (m.name.as_str(), m.kind, m.material)).collect();
    assert_eq!(
        methods,
        [
            ("FEM co-rotational (3k T4)", MethodKind::Fem, Some(Material::new(Law::Corotational, 5000.0, 0.48))),
            ("FEM SVK (3k T4)", MethodKind::Fem, Some(Material::new(Law::Svk, 5000.0, 0.49))),
            ("U-Net", MethodKind::Network, None),
        ]
    );
    let caps: Vec<Option<usize>> = s.models.method.iter().map(|m| m.iterations).collect();
    assert_eq!(caps, [None, None, None], "each method's kind's budget");
}

/// The case built by hand from its definition: the phantom, its law and loads, the camera.
fn hard_coded(tets: usize, force: f64, camera: &CameraSpec) -> (Vec<Point>, Vec<Point>, Vec<Point>) {
    let m = mesh::phantom::liver_phantom(tets).unwrap();
    let mut p = Problem::new(m, Material::new(Law::NeoHookean, 5000.0, 0.48));
    let fixed = p.mesh.region("fixed").unwrap().to_vec();
    let push = p.mesh.region("push").unwrap().to_vec();
    p.fix(&fixed);
    p.add_force(&push, [0.0, 0.0, -force]);
    let u = StaticSolver::new(p.clone()).unwrap().solve(&SolverOptions::default()).unwrap().u;
    let markers = p.mesh.region("markers").unwrap().to_vec();
    let targets: Vec<Point> = markers.iter().map(|&n| p.mesh.nodes[n]).collect();
    let truth = markers.iter().map(|&n| std::array::from_fn(|d| p.mesh.nodes[n][d] + u[3 * n + d])).collect();
    let organ = Organ::new(p.mesh, None).unwrap();
    let cloud = simulate_cloud(&organ.deformed_surface(&u), camera).unwrap();
    (cloud, targets, truth)
}

#[test]
fn a_scenario_builds_the_case_exactly_as_its_definition_says() {
    let s = CaseScenario::load(Path::new("register_case_test")).unwrap();
    let case = synthetic_case(&s).unwrap();
    let (cloud, targets, truth) = hard_coded(s.truth.tets, s.truth.force, &s.camera);
    assert_eq!(case.frames.len(), 1);
    let frame = case.frames[0].clone();
    assert_eq!((frame.cloud, case.targets, frame.truth), (cloud, targets, truth), "bit for bit");
    assert_eq!(case.pose, RigidTransform::identity());
    // A misalignment moves cloud and truth, not the rest targets.
    let mut moved = s.clone();
    moved.misalignment.rotation_deg = 5.0;
    moved.misalignment.translation = "10 mm".parse().unwrap();
    let off = synthetic_case(&moved).unwrap();
    let plain = synthetic_case(&s).unwrap();
    assert_eq!(off.targets, plain.targets);
    let pose = off.pose;
    assert!((pose.angle().to_degrees() - 5.0).abs() < 1e-9 && (pose.translation_norm() - 0.01).abs() < 1e-12);
    let (off, plain) = (off.peak(), plain.peak());
    for (a, b) in off.truth.iter().zip(&plain.truth).chain(off.cloud.iter().zip(&plain.cloud)) {
        let p = pose.apply(*b);
        assert!((0..3).all(|d| (a[d] - p[d]).abs() < 1e-15), "{a:?} {p:?}");
    }
    let methods = case_methods(&s, &[]).unwrap();
    assert_eq!(methods.iter().map(|m| m.name.as_str()).collect::<Vec<_>>(), ["FEM co-rotational", "FEM SVK"]);
}

#[test]
fn a_press_and_release_rises_to_the_force_and_falls_back_each_frame_seen_anew() {
    let mut s = CaseScenario::load(Path::new("register_case_test")).unwrap();
    s.truth.frames = 5;
    let case = synthetic_case(&s).unwrap();
    let forces: Vec<f64> = case.frames.iter().map(|f| f.force).collect();
    let f = s.truth.force;
    let expected = [0.5 * f, 0.75f64.sqrt() * f, f, 0.75f64.sqrt() * f, 0.5 * f];
    assert!(forces.iter().zip(expected).all(|(a, b)| (a - b).abs() < 1e-12), "{forces:?}");
    assert_eq!(case.peak_index(), 2);
    // The peak frame, warm-started from the frames before it, is the single frame at the force
    // solved from rest (to the solver's tolerance), seen with the seed of its place.
    let (_, _, truth) = hard_coded(s.truth.tets, f, &s.camera);
    let motion = mesh::stats::mean(&register::target_errors(&case.targets, &truth));
    let off = mesh::stats::max(&register::target_errors(&case.peak().truth, &truth));
    assert!(off < 1e-4 * motion, "{off} m off the single frame for a motion of {motion} m");
    // Symmetric loads give the same truth on the way down, and every frame has its own cloud.
    let back = mesh::stats::max(&register::target_errors(&case.frames[1].truth, &case.frames[3].truth));
    assert!(back < 1e-4 * motion, "{back}");
    assert_ne!(case.frames[1].cloud, case.frames[3].cloud);
    let mut single = s.clone();
    single.truth.frames = 1;
    single.camera.seed += 2;
    let alone = synthetic_case(&single).unwrap().frames[0].cloud.clone();
    let apart = mesh::stats::max(&register::target_errors(&case.peak().cloud, &alone));
    assert!(case.peak().cloud.len() == alone.len() && apart < 1e-4 * motion, "{apart}");
}

#[test]
fn bad_case_scenarios_are_clear_errors() {
    let origin = Path::new("bad_case.toml");
    let parse = |text: &str| CaseScenario::parse(text, origin).unwrap_err().to_string();
    let edit = |from: &str, to: &str| {
        assert!(builtin_text().contains(from), "{from}");
        builtin_text().replacen(from, to, 1)
    };
    let e = parse(&edit("points = 1500", "points = 1500\nfocal = 3"));
    assert!(e.contains("bad_case.toml") && e.contains("unknown field `focal`"), "{e}");
    let e = parse(&edit("law = \"neo_hookean\"", "law = \"rubber\""));
    assert!(e.contains("bad_case.toml") && e.contains("rubber"), "{e}");
    let e = parse(&edit("kind = \"network\"\n", "kind = \"spline\"\n"));
    assert!(e.contains("spline"), "{e}");
    let e = parse(&edit("kind = \"network\"\n", "kind = \"network\"\nmodel = \"x.json\"\n"));
    assert!(e.contains("unknown field `model`"), "{e}");
    let e = parse(&edit("kind = \"network\"\n", "kind = \"fem\"\n"));
    assert!(e.contains("U-Net") && e.contains("needs a `material`"), "{e}");
    let e = parse(&edit("[truth]\ntets = 9000\n", "[truth]\n"));
    assert!(e.contains("missing field `tets`"), "{e}");
    let e = parse(&edit("noise = 0.001", "noise = -0.001"));
    assert!(e.contains("camera.noise"), "{e}");
    let e = parse(&edit("name = \"U-Net\"", "name = \"FEM SVK (3k T4)\""));
    assert!(e.contains("not distinct"), "{e}");
    let e = parse(&edit("poisson = 0.49", "poisson = 0.5"));
    assert!(e.contains("FEM SVK") && e.contains("Poisson"), "{e}");
    let e = parse(&edit("iterations = 30", "iterations = 0"));
    assert!(e.contains("registration"), "{e}");
    let e = parse(&edit("kind = \"network\"\n", "kind = \"network\"\niterations = 0\n"));
    assert!(e.contains("U-Net") && e.contains("iterations must be at least 1"), "{e}");
    let e = parse(&edit("capture_decay = 0.93", "capture_decay = 0.93\n\n[registration.rigid]\nkeep = 1.5"));
    assert!(e.contains("keep"), "{e}");
    let e = parse(&edit("capture_decay = 0.93", "capture_decay = 1.5"));
    assert!(e.contains("registration"), "{e}");
    let e = parse(&edit("capture_decay = 0.93", "capture_decay = 0.93\nview = [0.0, 0.0, 0.0]"));
    assert!(e.contains("registration"), "{e}");
    let e = parse(&edit("tets = 3000", "tets = 10"));
    assert!(e.contains("at least 100"), "{e}");
    let e = parse(&edit("translation = 0.0", "translation = nan"));
    assert!(e.contains("the length NaN is not finite"), "{e}");
    let e = parse(&edit("translation = 0.0", "translation = \"10\""));
    assert!(e.contains("'10' has no unit"), "{e}");
    let e = CaseScenario::load(Path::new("no/such/case.toml")).unwrap_err().to_string();
    assert!(e.contains("no/such/case.toml"), "{e}");
    // A rigid table with defaults, and a moved push patch, are accepted.
    let ok = edit("capture_decay = 0.93", "capture_decay = 0.93\n\n[registration.rigid]\nmetric = \"point_to_point\"");
    let s = CaseScenario::parse(&ok, origin).unwrap();
    assert_eq!(s.registration.rigid.unwrap().metric, register::IcpMetric::PointToPoint);
    let ok = edit(
        "targets = \"markers\"",
        "targets = \"markers\"\npatch = { from = [0.05, 0.0, 0.0], direction = [0.0, 0.0, 1.0], radius = 0.02 }",
    );
    assert!(CaseScenario::parse(&ok, origin).unwrap().truth.patch.is_some());
}
