//! Dataset scenarios built into augsim generate what they promise.

use std::path::Path;

use augsim_scenario::DatasetScenario;
use learn::Dataset;

#[test]
fn the_grid_ar_scenario_presses_the_immersed_phantom_by_centimetres() {
    let (mut scenario, dir) = DatasetScenario::load(Path::new("liver_ar_grid")).unwrap();
    scenario.dataset.samples = 2;
    let g = scenario.generator(&dir).unwrap();
    let tmp = tempfile::tempdir().unwrap();
    let manifest = g.run(tmp.path(), "liver_ar_grid", None, &learn::Silent).unwrap();
    assert!(manifest.failed.is_empty(), "{:?}", manifest.failed);
    let data = Dataset::open(tmp.path()).unwrap().load_all().unwrap();
    let n = data.grid.nodes();
    for i in 0..data.len() {
        let u = data.target(i);
        let largest = (0..n).map(|k| (0..3).map(|c| u[c * n + k].powi(2)).sum::<f32>().sqrt()).fold(0.0, f32::max);
        assert!((0.01..0.1).contains(&largest), "sample {i}: largest displacement {largest} m");
    }
}

/// A dataset regenerated from the built-in `liver_ar_t10` scenario has the source identity recorded in the
/// shipped network's split, so that `eval` finds its test samples and refuses its training ones
/// (options added to the generator since must not change the manifest of a scenario without them).
#[test]
fn a_regenerated_liver_ar_t10_dataset_is_the_shipped_networks_own() {
    let (mut scenario, dir) = DatasetScenario::load(Path::new("liver_ar_t10")).unwrap();
    scenario.dataset.samples = 1;
    let tmp = tempfile::tempdir().unwrap();
    scenario.generator(&dir).unwrap().run(tmp.path(), &scenario.name, None, &learn::Silent).unwrap();
    let model = std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("../../models/liver_ar/model.json"))
        .unwrap();
    let model: serde_json::Value = serde_json::from_str(&model).unwrap();
    assert_eq!(Dataset::open(tmp.path()).unwrap().manifest().source_id(), model["training"]["split"]["source"]);
    // The scenario's mesh is the one its samples are solved on (what `augsim view` shows them on):
    // the quadratic mesh of the generator, node for node.
    let mesh = scenario.mesh(&dir).unwrap();
    let solved = scenario.generator(&dir).unwrap().mesh().clone();
    assert_eq!((mesh.cells.kind_name(), &mesh.nodes), (solved.cells.kind_name(), &solved.nodes));
}

/// The large loads of `liver_forces_large` on stabilised T10 F-bar: each of the first ten draws
/// finds a solution (on T10 F-bar with J constant per element, four of them stalled on a tangent
/// that had lost positive definiteness), and moves the organ by centimetres.
#[test]
fn stabilised_t10_fbar_solves_the_large_load_draws() {
    let (mut scenario, dir) = DatasetScenario::load(Path::new("liver_forces_large")).unwrap();
    scenario.material.formulation = fem::Formulation::Fbar;
    scenario.dataset.samples = 10;
    let tmp = tempfile::tempdir().unwrap();
    let manifest = scenario.generator(&dir).unwrap().run(tmp.path(), "fbar", None, &learn::Silent).unwrap();
    assert!(manifest.failed.is_empty(), "{:?}", manifest.failed);
    let data = Dataset::open(tmp.path()).unwrap().load_all().unwrap();
    let n = data.grid.nodes();
    let largest = (0..data.len())
        .flat_map(|i| {
            let u = data.target(i);
            (0..n).map(move |k| (0..3).map(|c| u[c * n + k].powi(2)).sum::<f32>().sqrt())
        })
        .fold(0.0, f32::max);
    assert!(largest > 0.03, "largest displacement {largest} m");
}

/// A dataset held by an attachment (an elastic foundation over the phantom's `fixed` ball, about as
/// stiff as the one of `fem-convergence`) instead of the fixed nodes inside that ball: the same
/// draws solve and move the organ about as far (measured: 0.75–0.9 times; on this coarse mesh the
/// foundation acts on the whole of every cell its ball cuts, more than the nodes inside it); an
/// attachment given neither a ball nor a phantom region is named in the error.
#[test]
fn a_dataset_held_by_an_attachment_solves_the_draws_of_one_held_by_fixed_nodes() {
    // The same patch centres for both (by default they avoid the held part, which differs).
    let original = augsim_scenario::builtin("liver_forces")
        .unwrap()
        .replace("radius = 0.02", "radius = 0.02\ncentres = { region = \"visible\" }");
    let text = original
        .replace("fixed = [{ region = \"fixed\" }]", "attachment = [{ phantom = \"fixed\", stiffness = 5.0e8 }]");
    assert_ne!(text, original);
    let tmp = tempfile::tempdir().unwrap();
    let largest = |text: &str, name: &str| {
        let path = tmp.path().join(format!("{name}.toml"));
        std::fs::write(&path, text).unwrap();
        let (mut scenario, dir) = DatasetScenario::load(&path).unwrap();
        scenario.dataset.samples = 3;
        let out = tmp.path().join(name);
        let manifest = scenario.generator(&dir).unwrap().run(&out, name, None, &learn::Silent).unwrap();
        assert!(manifest.failed.is_empty(), "{name}: {:?}", manifest.failed);
        let data = Dataset::open(&out).unwrap().load_all().unwrap();
        let n = data.grid.nodes();
        (0..data.len())
            .map(|i| {
                let u = data.target(i);
                (0..n).map(|k| (0..3).map(|c| u[c * n + k].powi(2)).sum::<f32>().sqrt()).fold(0.0, f32::max)
            })
            .collect::<Vec<f32>>()
    };
    let (held, fixed) = (largest(&text, "held"), largest(&original, "fixed"));
    for (h, f) in held.iter().zip(&fixed) {
        assert!(*h > 0.6 * f && *h < 1.5 * f, "largest displacement {h} m held by the attachment, {f} m fixed");
    }
    let bad = text.replace("{ phantom = \"fixed\", stiffness", "{ stiffness");
    let path = tmp.path().join("bad.toml");
    std::fs::write(&path, bad).unwrap();
    let (scenario, dir) = DatasetScenario::load(&path).unwrap();
    let err = scenario.generator(&dir).err().expect("an attachment without a region").to_string();
    assert!(err.contains("attachment 1"), "{err}");
}

/// A dataset whose first draws fail for one reason stops after them with that reason and what to
/// change, instead of solving every draw: here the phantom is held at a single node, about which
/// it can turn.
#[test]
fn a_generation_whose_first_draws_fail_stops_and_says_what_to_change() {
    let (mut scenario, dir) = DatasetScenario::load(Path::new("liver_forces")).unwrap();
    scenario.dataset.samples = 2000;
    scenario.dataset.fixed = vec![mesh::NodeSelection::List(vec![0])];
    let tmp = tempfile::tempdir().unwrap();
    let error = scenario.generator(&dir).unwrap().run(tmp.path(), "held_at_a_point", None, &learn::Silent).unwrap_err();
    let message = error.to_string();
    assert!(message.contains("of the first") && message.contains("held at a single point"), "{message}");
    assert!(message.contains("Change the attachments or the mesh"), "{message}");
    let manifest: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(tmp.path().join("manifest.json")).unwrap()).unwrap();
    let failed = manifest["failed"].as_array().unwrap().len();
    assert!((16..2000).contains(&failed), "{failed} draws failed before the stop");
}
