//! ROUKF on small FEM models: Young's modulus and boundary springs identified from synthetic tracked points,
//! parallel = sequential, non-negative springs, tracked points and synthetic noise.

use augsim_filter::observation::{add_noise, tracked_positions};
use augsim_filter::{
    Execution, FemModel, FemModelError, FemParameter, LoadPattern, Model, ObservationNoise, ParameterSpec, Profile,
    Roukf, RoukfConfig, SigmaPointSet, TrackedPoint, Transform,
};
use fem::{Law, Material, Problem, SolverOptions};
use mesh::select::nodes_in_box;
use mesh::{Mesh, MeshLocator, Point};
use nalgebra::DVector;

const LENGTH: f64 = 0.1;
const SIDE: f64 = 0.02;
const TRUE_YOUNG: f64 = 5000.0;
const PERIOD: usize = 8;
/// N/m per unit of the spring parameters' filter values.
const SPRING_SCALE: f64 = 10.0;

fn beam() -> Mesh {
    mesh::box_tet([0.0; 3], [LENGTH, SIDE, SIDE], [5, 2, 2]).unwrap()
}

fn face(mesh: &Mesh, x: f64) -> Vec<usize> {
    nodes_in_box(&mesh.nodes, [x - 1e-9, -1.0, -1.0], [x + 1e-9, 1.0, 1.0])
}

fn top(mesh: &Mesh) -> Vec<usize> {
    nodes_in_box(&mesh.nodes, [-1.0, -1.0, SIDE - 1e-9], [1.0, 1.0, SIDE + 1e-9])
}

/// Cantilever beam fixed at x = 0, a downward force on its free end with a raised-cosine amplitude, observed at
/// the nodes of its top face and at one interior point.
fn young_model() -> FemModel {
    let mesh = beam();
    let mut problem = Problem::new(mesh, Material::new(Law::Svk, TRUE_YOUNG, 0.45));
    problem.fix(&face(&problem.mesh, 0.0));
    let end = face(&problem.mesh, LENGTH);
    let share = 2e-3 / end.len() as f64;
    let load = LoadPattern {
        profile: Profile::RaisedCosine { period: PERIOD },
        forces: end.iter().map(|&k| (k, [0.0, 0.0, -share])).collect(),
        displacements: vec![],
    };
    let mut observed: Vec<TrackedPoint> = top(&problem.mesh).into_iter().map(TrackedPoint::at_node).collect();
    observed.push(TrackedPoint::locate(&MeshLocator::new(&problem.mesh).unwrap(), [0.071, 0.013, 0.004]).unwrap());
    FemModel::new(problem, vec![FemParameter::Young], vec![load], observed, SolverOptions::default()).unwrap()
}

fn clean_observations(model: &FemModel, theta: &[f64], steps: usize) -> Vec<DVector<f64>> {
    let mut out = Vec::new();
    model.simulate(theta, steps, |_, s| out.push(model.observe(s))).unwrap();
    out
}

#[test]
fn young_modulus_is_identified_within_one_percent_from_noiseless_data() {
    let model = young_model();
    let data = clean_observations(&model, &[TRUE_YOUNG], 3 * PERIOD);
    // The observed tip really moves: millimetres at the peak of the load.
    let rest =
        tracked_positions(&model.problem().mesh.nodes, model.observed_points(), &vec![0.0; model.problem().num_dofs()]);
    let peak = (&data[PERIOD / 2 - 1] - &rest).amax();
    assert!(peak > 1e-3 && peak < 1e-2, "peak displacement {peak}");

    // Log-space prior around 3,000 Pa (a factor 5/3 off): within 1 % after a few observations.
    let config = |transform, mean, std| RoukfConfig {
        parameters: vec![ParameterSpec::new("young", transform, mean, std)],
        observation_std: ObservationNoise::Uniform(1e-5),
        execution: Execution::Parallel,
        forgetting: 1.0,
        sigma_points: SigmaPointSet::Simplex,
        gate: None,
    };
    let initial = model.initial_state();
    let mut roukf = Roukf::new(model, initial, config(Transform::Exp, 3000f64.ln(), 0.5)).unwrap();
    for z in &data[..4] {
        roukf.step(z).unwrap();
    }
    let last = roukf.trace().records.last().unwrap();
    let err = (last.mean_physical[0] - TRUE_YOUNG).abs() / TRUE_YOUNG;
    assert!(err < 0.01, "estimate {} after {} iterations", last.mean_physical[0], last.iteration);
    assert!(last.std_physical[0] < 200.0, "σ {}", last.std_physical[0]);
    // Each sigma point solved its own equilibrium with its own modulus: their states differ.
    let states = roukf.sigma_states();
    assert_eq!(states.len(), 2);
    assert!(states[0].u != states[1].u);
    assert!(states.iter().all(|s| s.newton_iterations > 0));

    // The published prior (1,000 ± 200 Pa, 20σ from the truth) approaches the truth from below, monotonically,
    // slowed by the confidence gained where the soft sigma points are most sensitive.
    let model = young_model();
    let initial = model.initial_state();
    let mut roukf = Roukf::new(model, initial, config(Transform::Identity, 1000.0, 200.0)).unwrap();
    for z in &data {
        roukf.step(z).unwrap();
    }
    let means: Vec<f64> = roukf.trace().records.iter().map(|r| r.mean_physical[0]).collect();
    assert!(means.windows(2).all(|w| w[1] >= w[0] - 1e-6 * TRUE_YOUNG), "{means:?}");
    assert!(means[means.len() - 1] > 3000.0 && means[means.len() - 1] < TRUE_YOUNG, "{means:?}");
}

/// The beam held at x = 0 by its fixed face and at its free end by two groups of springs (lower and upper end
/// nodes), loaded on its top face.
fn spring_model() -> (FemModel, Vec<Vec<usize>>) {
    let mesh = beam();
    let mut problem = Problem::new(mesh, Material::new(Law::Svk, TRUE_YOUNG, 0.45));
    problem.fix(&face(&problem.mesh, 0.0));
    let end = face(&problem.mesh, LENGTH);
    let groups: Vec<Vec<usize>> = vec![
        end.iter().copied().filter(|&k| problem.mesh.nodes[k][2] < 0.5 * SIDE).collect(),
        end.iter().copied().filter(|&k| problem.mesh.nodes[k][2] >= 0.5 * SIDE).collect(),
    ];
    let loaded = top(&problem.mesh);
    let share = 2e-3 / loaded.len() as f64;
    let loads = vec![
        LoadPattern {
            profile: Profile::RaisedCosine { period: PERIOD },
            forces: loaded.iter().map(|&k| (k, [0.0, 0.0, -share])).collect(),
            displacements: vec![],
        },
        LoadPattern {
            profile: Profile::Sine { period: PERIOD, phase: 0.0 },
            forces: loaded.iter().map(|&k| (k, [share, 0.5 * share, 0.0])).collect(),
            displacements: vec![],
        },
    ];
    let observed = top(&problem.mesh).into_iter().map(TrackedPoint::at_node).collect();
    let parameters = groups.iter().map(|g| FemParameter::Springs { nodes: g.clone() }).collect();
    (FemModel::new(problem, parameters, loads, observed, SolverOptions::default()).unwrap(), groups)
}

/// The filter of the two spring groups, whose values count `SPRING_SCALE` N/m.
fn spring_config(execution: Execution) -> RoukfConfig {
    RoukfConfig {
        parameters: vec![
            ParameterSpec::new("k_low", Transform::Abs, 0.005, 0.01).scaled(SPRING_SCALE),
            ParameterSpec::new("k_high", Transform::Abs, 0.005, 0.01).scaled(SPRING_SCALE),
        ],
        observation_std: ObservationNoise::Uniform(2e-5),
        execution,
        forgetting: 1.0,
        sigma_points: SigmaPointSet::Simplex,
        gate: None,
    }
}

#[test]
fn abs_transform_keeps_springs_non_negative_and_finds_them() {
    let truth = [0.2, 0.02];
    let (model, groups) = spring_model();
    let data = clean_observations(&model, &truth, 5 * PERIOD);
    let initial = model.initial_state();
    let mut roukf = Roukf::new(model, initial, spring_config(Execution::Parallel)).unwrap();
    let mut problem = roukf.model().problem().clone();
    for (k, z) in data.iter().enumerate() {
        // Sigma points fall on both sides of the filter-space mean (which starts at 0), yet every solve accepts
        // its stiffnesses: the model refuses negative ones (see below).
        roukf.step(z).unwrap();
        roukf.model().configure(&mut problem, &roukf.mean_physical(), k + 1).unwrap();
        assert!(problem.springs.iter().all(|s| *s >= 0.0));
    }
    let est = roukf.mean_physical();
    assert!(est.iter().all(|v| *v >= 0.0));
    // Both stiffnesses (N/m) are found: the dominant one within 10 %, each within 3σ; the filter's own values
    // count SPRING_SCALE N/m.
    let filter_values = roukf.mean();
    for j in 0..2 {
        assert!((SPRING_SCALE * filter_values[j].abs() - est[j]).abs() <= 1e-12 * est[j], "{est:?}");
    }
    let std = roukf.std_physical();
    assert!((est[0] - truth[0]).abs() < 0.1 * truth[0], "{est:?}");
    for j in 0..2 {
        assert!((est[j] - truth[j]).abs() < 3.0 * std[j], "{est:?} ± {std:?}");
    }
    // The estimate is applied to the right nodes.
    for (g, value) in groups.iter().zip(&est) {
        assert!(g.iter().all(|&k| (problem.springs[k] - value).abs() <= 1e-12));
    }

    // Without the transform, the same prior spreads sigma points to negative stiffnesses, outside the FEM
    // model's domain: refused before they are solved.
    let (model, _) = spring_model();
    let initial = model.initial_state();
    let mut config = spring_config(Execution::Sequential);
    config.parameters.iter_mut().for_each(|p| p.transform = Transform::Identity);
    let mut roukf = Roukf::new(model, initial, config).unwrap();
    let err = roukf.step(&data[0]).unwrap_err();
    let err = err.to_string();
    assert!(err.contains("sigma point") && err.contains("leaves a node's stiffness negative"), "{err}");
}

fn bits(v: &[f64]) -> Vec<u64> {
    v.iter().map(|x| x.to_bits()).collect()
}

#[test]
fn parallel_and_sequential_fem_filters_are_bit_identical() {
    let truth = [0.15, 0.04];
    let run = |execution| {
        let (model, _) = spring_model();
        let data = add_noise(&clean_observations(&model, &truth, 12), 2e-5, 7).unwrap();
        let initial = model.initial_state();
        let mut roukf = Roukf::new(model, initial, spring_config(execution)).unwrap();
        for z in &data {
            roukf.step(z).unwrap();
        }
        let states: Vec<Vec<f64>> = roukf.sigma_states().iter().map(|s| s.u.clone()).collect();
        (roukf.trace().clone(), states)
    };
    let (par, par_states) = run(Execution::Parallel);
    let (seq, seq_states) = run(Execution::Sequential);
    assert_eq!(par.records.len(), 13);
    for (a, b) in par.records.iter().zip(&seq.records) {
        assert_eq!(bits(&a.mean), bits(&b.mean), "iteration {}", a.iteration);
        assert_eq!(bits(&a.std), bits(&b.std));
        assert_eq!(a.innovation_norm.map(f64::to_bits), b.innovation_norm.map(f64::to_bits));
    }
    for (a, b) in par_states.iter().zip(&seq_states) {
        assert_eq!(bits(a), bits(b));
    }
    // The filter did something: the estimate left the prior.
    assert!(par.records.last().unwrap().mean.iter().any(|m| m.abs() > 1e-4));
}

#[test]
fn tracked_points_interpolate_linear_fields_exactly() {
    let mesh = beam();
    let locator = MeshLocator::new(&mesh).unwrap();
    let p: Point = [0.0437, 0.0071, 0.0155];
    let t = TrackedPoint::locate(&locator, p).unwrap();
    assert!(t.weights.iter().all(|w| *w >= 0.0));
    assert!((t.weights.iter().sum::<f64>() - 1.0).abs() < 1e-12);
    // A linear displacement field u(x) = A x + b is reproduced exactly at the point.
    let a = [[0.1, -0.2, 0.05], [0.0, 0.3, -0.1], [0.2, 0.1, 0.0]];
    let b = [1e-3, -2e-3, 5e-4];
    let field = |x: Point| -> Point { std::array::from_fn(|i| (0..3).map(|j| a[i][j] * x[j]).sum::<f64>() + b[i]) };
    let u: Vec<f64> = mesh.nodes.iter().flat_map(|&x| field(x)).collect();
    let got = t.position(&mesh.nodes, &u);
    let want = field(p);
    for d in 0..3 {
        assert!((got[d] - (p[d] + want[d])).abs() < 1e-14, "{got:?} vs {want:?}");
    }
    // Points on the boundary are found; points outside and hexahedral meshes are rejected with a message.
    let corner = TrackedPoint::locate(&locator, [LENGTH, SIDE, SIDE]).unwrap();
    assert!((tracked_positions(&mesh.nodes, &[corner], &vec![0.0; u.len()])[0] - LENGTH).abs() < 1e-15);
    let outside = TrackedPoint::locate(&locator, [0.05, 0.01, 0.03]).unwrap_err();
    assert!(outside.to_string().contains("outside"), "{outside}");
    let hex = mesh::box_hex([0.0; 3], [1.0; 3], [1, 1, 1]).unwrap();
    let err = TrackedPoint::locate(&MeshLocator::new(&hex).unwrap(), [0.5; 3]).unwrap_err();
    assert!(err.to_string().contains("tetrahedral"), "{err}");
    assert!(TrackedPoint::at_node(54).validate(54).is_err());
}

#[test]
fn profiles_and_noise() {
    let rc = Profile::RaisedCosine { period: 10 };
    assert!(rc.amplitude(0).abs() < 1e-15 && rc.amplitude(10).abs() < 1e-15);
    assert!((rc.amplitude(5) - 1.0).abs() < 1e-15);
    assert!((rc.amplitude(25) - 1.0).abs() < 1e-15);
    assert!((rc.amplitude(2) - 0.5 * (1.0 - (0.4 * std::f64::consts::PI).cos())).abs() < 1e-15);
    let sine = Profile::Sine { period: 8, phase: std::f64::consts::FRAC_PI_2 };
    assert!((sine.amplitude(0) - 1.0).abs() < 1e-15 && (sine.amplitude(4) + 1.0).abs() < 1e-12);

    let clean: Vec<DVector<f64>> = (0..200).map(|i| DVector::from_element(50, i as f64)).collect();
    assert_eq!(add_noise(&clean, 0.0, 1).unwrap(), clean);
    let noisy = add_noise(&clean, 0.5, 3).unwrap();
    assert_eq!(noisy, add_noise(&clean, 0.5, 3).unwrap(), "same seed, same noise");
    assert_ne!(noisy, add_noise(&clean, 0.5, 4).unwrap());
    let e: Vec<f64> = noisy.iter().zip(&clean).flat_map(|(a, b)| (a - b).iter().copied().collect::<Vec<_>>()).collect();
    let n = e.len() as f64;
    let mean = e.iter().sum::<f64>() / n;
    let std = (e.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n).sqrt();
    assert!(mean.abs() < 0.02 && (std - 0.5).abs() < 0.02, "mean {mean}, std {std}");
    assert!(add_noise(&clean, -1.0, 0).is_err() && add_noise(&clean, f64::NAN, 0).is_err());
}

#[test]
fn inconsistent_models_are_rejected() {
    let mesh = beam();
    let mut problem = Problem::new(mesh, Material::new(Law::Svk, TRUE_YOUNG, 0.45));
    problem.fix(&face(&problem.mesh, 0.0));
    let obs = vec![TrackedPoint::at_node(53)];
    let opts = SolverOptions::default();
    let new = |params, loads, obs| FemModel::new(problem.clone(), params, loads, obs, opts.clone()).map(|_| ());
    let msg = |r: Result<(), FemModelError>| r.unwrap_err().to_string();
    let free_node = 53;
    let tool = |profile| LoadPattern { profile, forces: vec![], displacements: vec![(free_node, [0.0, 0.0, 1e-3])] };
    assert!(msg(new(vec![], vec![tool(Profile::RaisedCosine { period: 4 })], obs.clone())).contains("not constrained"));
    assert!(msg(new(vec![], vec![tool(Profile::RaisedCosine { period: 0 })], obs.clone())).contains("period"));
    let springs = |nodes: Vec<usize>| vec![FemParameter::Springs { nodes }];
    assert!(msg(new(springs(vec![99]), vec![], obs.clone())).contains("node 99"));
    assert!(msg(new(vec![FemParameter::Young], vec![], vec![])).contains("no observed point"));

    let model = FemModel::new(problem.clone(), vec![FemParameter::Young], vec![], obs, opts.clone()).unwrap();
    let mut p = problem.clone();
    assert!(model.configure(&mut p, &[1.0, 2.0], 1).unwrap_err().to_string().contains("2 parameter values"));
    // A non-physical modulus reaches the solver's validation as an error, not a panic.
    let mut state = model.initial_state();
    let err = model.step(&mut state, &[-5.0], 1).unwrap_err();
    assert!(err.to_string().contains("Young"), "{err}");
    // One solver per sigma point of either set (2p + 1 = 3 star points here): a state tied to a slot beyond them is
    // refused.
    model.assign_sigma_point(&mut state, 2);
    model.step(&mut state, &[TRUE_YOUNG], 1).unwrap();
    model.assign_sigma_point(&mut state, 3);
    assert!(model.step(&mut state, &[TRUE_YOUNG], 2).unwrap_err().to_string().contains("slot 3"));
}

/// Identifies E on the beam from noisy data with the given sigma-point set; returns the filter.
fn young_filter(set: SigmaPointSet, data: &[DVector<f64>]) -> Roukf<FemModel> {
    let model = young_model();
    let initial = model.initial_state();
    let config = RoukfConfig {
        parameters: vec![ParameterSpec::new("young", Transform::Exp, 3000f64.ln(), 0.5)],
        observation_std: ObservationNoise::Uniform(2e-5),
        execution: Execution::Parallel,
        forgetting: 1.0,
        sigma_points: set,
        gate: None,
    };
    let mut roukf = Roukf::new(model, initial, config).unwrap();
    for z in data {
        roukf.step(z).unwrap();
    }
    roukf
}

#[test]
fn star_and_simplex_sigma_points_converge_to_the_same_young_modulus() {
    let model = young_model();
    // Two and a half load cycles: the last step is at the peak of the load.
    let data = add_noise(&clean_observations(&model, &[TRUE_YOUNG], 2 * PERIOD + PERIOD / 2), 2e-5, 11).unwrap();
    let simplex = young_filter(SigmaPointSet::Simplex, &data);
    let star = young_filter(SigmaPointSet::Star, &data);
    assert_eq!(simplex.sigma_states().len(), 2);
    assert_eq!(star.sigma_states().len(), 3);
    // The star set's centre point solves with the mean modulus, the other two on either side of it.
    let star_states = star.sigma_states();
    assert!(star_states[1].u != star_states[0].u && star_states[2].u != star_states[0].u);
    let (a, b) = (simplex.mean_physical()[0], star.mean_physical()[0]);
    let (sa, sb) = (simplex.std_physical()[0], star.std_physical()[0]);
    for (e, s) in [(a, sa), (b, sb)] {
        assert!((e - TRUE_YOUNG).abs() < 0.01 * TRUE_YOUNG, "estimate {e} ± {s}");
        assert!((e - TRUE_YOUNG).abs() < 4.0 * s, "estimate {e} ± {s}");
    }
    // Same data: the two estimates agree well inside their σ (they differ by what the sigma points' spreads, ±1 and
    // ±√1.5 standard deviations, sample of the nonlinearity on the way from the prior).
    assert!((a - b).abs() < 0.25 * sa.min(sb), "simplex {a} ± {sa}, star {b} ± {sb}");
    assert!((sa / sb - 1.0).abs() < 0.05, "σ simplex {sa}, star {sb}");
}
