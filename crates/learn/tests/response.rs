//! The linear-elastic response at rest between grid fields, and the reduced-order model built on it
//! as a physics prior.

use augsim_learn::data::generate::{DatasetConfig, Generator, Input, Load};
use augsim_learn::rom::{fit, Context, RomConfig};
use augsim_learn::{Dataset, SplitPolicy};
use fem::{Law, Material, SolverOptions};
use mesh::NodeSelection;

/// A box of T4 (0.2 × 0.1 × 0.1 m) fixed at x = 0 and loaded by point forces anywhere, on a grid
/// of `dims`, in `material`.
fn box_generator(material: Material, dims: [usize; 3], samples: usize) -> Generator {
    let mesh = mesh::box_tet([0.0; 3], [0.2, 0.1, 0.1], [4, 2, 2]).unwrap();
    let config = DatasetConfig {
        samples,
        seed: 5,
        shard_size: samples,
        grid: Some(dims),
        fixed: vec![NodeSelection::Box { min: [-1e-6; 3], max: [1e-6, 1.0, 1.0] }],
        attachment: vec![],
        load: Load::PointForces {
            nodes: NodeSelection::Box { min: [0.1, -1.0, -1.0], max: [1.0; 3] },
            count: 2,
            magnitude: [0.5, 2.0],
        },
        gravity: None,
        input: Input::Force,
    };
    Generator::new(mesh, material, SolverOptions::default(), config).unwrap()
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// With the mesh's nodes on grid nodes, spreading forces to the grid and pulling them back is
/// exact: the response of a linear-elastic dataset's input is its target.
#[test]
fn the_response_of_a_linear_datasets_input_is_its_target() {
    let g = box_generator(Material::new(Law::Linear, 5000.0, 0.45), [9, 5, 5], 3);
    let dir = tempfile::tempdir().unwrap();
    g.run(dir.path(), "box", None, &augsim_learn::Silent).unwrap();
    let samples = Dataset::open(dir.path()).unwrap().load_all().unwrap();
    let mut response = g.rest_response().unwrap();
    for i in 0..samples.len() {
        let input: Vec<f64> = samples.input(i).iter().map(|&v| f64::from(v)).collect();
        let u = response.apply(&input).unwrap();
        let target = samples.target(i);
        let largest = target.iter().map(|v| f64::from(v.abs())).fold(0.0, f64::max);
        let error = u.iter().zip(target).map(|(a, b)| (a - f64::from(*b)).abs()).fold(0.0, f64::max);
        assert!(largest > 1e-4 && error < 1e-5 * largest, "sample {i}: error {error:e} of {largest:e}");
    }
}

/// The adjoint is the response's transpose (a dot-product test), on quadratic tetrahedra whose
/// nodes do not lie on the grid.
#[test]
fn the_adjoint_is_the_transpose() {
    let g = box_generator(Material::new(Law::NeoHookean, 5000.0, 0.45).with_order(2), [7, 4, 4], 1);
    let mut response = g.rest_response().unwrap();
    let len = 3 * g.grid().nodes();
    let field = |seed: usize| -> Vec<f64> {
        (0..len).map(|i| (((i * 7919 + seed * 104_729) % 1000) as f64 - 500.0) / 500.0).collect()
    };
    let (x, b) = (field(1), field(2));
    let (ax, atb) = (response.apply(&x).unwrap(), response.adjoint(&b).unwrap());
    let (left, right) = (dot(&b, &ax), dot(&atb, &x));
    assert!(left.abs() > 0.0 && (left - right).abs() < 1e-10 * left.abs(), "bᵀ(Ax) = {left:e}, (Aᵀb)ᵀx = {right:e}");
    assert!(response.apply(&x[1..]).is_err(), "a field of the wrong length is refused");
}

/// On a linear-elastic dataset the prior is the answer: the model's validation error is that of the
/// basis alone, far below the same model's without the prior.
#[test]
fn with_the_prior_a_linear_dataset_is_learned_to_its_basis() {
    let g = box_generator(Material::new(Law::Linear, 5000.0, 0.45), [9, 5, 5], 60);
    let dir = tempfile::tempdir().unwrap();
    g.run(dir.path(), "box", None, &augsim_learn::Silent).unwrap();
    let all = Dataset::open(dir.path()).unwrap().load_all().unwrap();
    let policy = SplitPolicy { validation_samples: Some(10), test_samples: Some(10), ..SplitPolicy::default() };
    let (split, [train, validation, _]) = policy.apply(&all).unwrap();
    let context = || Context {
        placement: None,
        input_unit: augsim_learn::FieldUnit::Newton,
        target_unit: augsim_learn::FieldUnit::Metre,
        split: split.clone(),
    };
    let (plain, plain_report) = fit(&train, &validation, &RomConfig::default(), context(), None).unwrap();
    let mut response = g.rest_response().unwrap();
    let (model, report) = fit(&train, &validation, &RomConfig::default(), context(), Some(&mut response)).unwrap();
    assert!(plain.info.prior.is_none() && model.info.prior.is_some());
    let size = validation.targets.iter().map(|v| f64::from(v.abs())).sum::<f64>() / validation.targets.len() as f64;
    assert!(
        report.val_mean_error < 1.01 * report.val_projection_error + 1e-6 * size
            && report.val_mean_error < 0.1 * plain_report.val_mean_error,
        "with the prior {:e} m (the basis alone {:e} m), without {:e} m, mean |u| component {size:e} m",
        report.val_mean_error,
        report.val_projection_error,
        plain_report.val_mean_error
    );
    // Saved and loaded, it predicts the same.
    let out = tempfile::tempdir().unwrap();
    model.save(out.path()).unwrap();
    assert!(out.path().join("prior.npy").exists() && !out.path().join("input_components.npy").exists());
    let loaded = augsim_learn::rom::ReducedModel::load(&out.path().join("model.json")).unwrap();
    let (a, b) = (model.predict(validation.input(0)).unwrap(), loaded.predict(validation.input(0)).unwrap());
    let largest = a.iter().zip(&b).map(|(x, y)| (x - y).abs()).fold(0f32, f32::max);
    assert!(largest < 1e-6 * size as f32 * 100.0, "loaded and fitted models differ by {largest:e}");
}
