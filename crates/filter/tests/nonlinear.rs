//! Nonlinear models: convergence of the estimate, monotone σ, parallel = sequential bit for bit, trace output.

mod common;

use std::convert::Infallible;

use augsim_filter::{
    Execution, Model, ObservationNoise, ParameterSpec, Roukf, RoukfConfig, SigmaPointSet, Trace, Transform, VectorState,
};
use common::Rng;
use nalgebra::DVector;

const DT: f64 = 0.1;

fn forcing(step: usize) -> f64 {
    1.0 + 0.8 * (0.3 * step as f64).sin()
}

/// Scalar exponential decay with forcing: x_{k+1} = x_k exp(-θ dt) + f_k dt, observing x.
struct Decay;

impl Model for Decay {
    type State = f64;
    type Error = Infallible;
    fn step(&self, x: &mut f64, theta: &[f64], step: usize) -> Result<(), Infallible> {
        *x = *x * (-theta[0] * DT).exp() + forcing(step) * DT;
        Ok(())
    }
    fn observe(&self, x: &f64) -> DVector<f64> {
        DVector::from_element(1, *x)
    }
}

impl VectorState for Decay {
    fn state_vector(&self, x: &f64) -> DVector<f64> {
        DVector::from_element(1, *x)
    }
    fn set_state_vector(&self, x: &mut f64, v: &DVector<f64>) {
        *x = v[0];
    }
}

fn decay_measurements(theta: f64, steps: usize, obs_std: f64, seed: u64) -> Vec<DVector<f64>> {
    let mut rng = Rng::new(seed);
    let mut x = 0.0;
    (1..=steps)
        .map(|k| {
            Decay.step(&mut x, &[theta], k).unwrap();
            DVector::from_element(1, x + obs_std * rng.normal())
        })
        .collect()
}

fn rate_config(execution: Execution) -> RoukfConfig {
    RoukfConfig {
        // Kept positive: the filter estimates ln θ, prior θ ≈ 0.5 (a factor 4 from the truth 2).
        parameters: vec![ParameterSpec::new("rate", Transform::Exp, 0.5f64.ln(), 1.0)],
        observation_std: ObservationNoise::Uniform(0.01),
        execution,
        forgetting: 1.0,
        sigma_points: SigmaPointSet::Simplex,
        gate: None,
    }
}

fn check_convergence(trace: &Trace, truth: f64) {
    let first = &trace.records[0];
    let last = trace.records.last().unwrap();
    for pair in trace.records.windows(2) {
        // Without model noise the parameter covariance can only shrink.
        assert!(pair[1].std[0] <= pair[0].std[0] * (1.0 + 1e-12), "σ grew at iteration {}", pair[1].iteration);
    }
    assert!(last.std[0] < first.std[0] / 10.0, "σ {} vs prior {}", last.std[0], first.std[0]);
    let err = (last.mean_physical[0] - truth).abs();
    assert!(err < 0.01 * truth, "estimate {} vs truth {truth}", last.mean_physical[0]);
    assert!(err < 5.0 * last.std_physical[0] + 1e-9, "error {err} vs σ {}", last.std_physical[0]);
}

#[test]
fn scalar_decay_rate_converges_joint() {
    let truth = 2.0;
    let data = decay_measurements(truth, 200, 0.01, 5);
    let mut roukf = Roukf::new_joint(Decay, 0.0, rate_config(Execution::Parallel)).unwrap();
    for z in &data {
        roukf.step(z).unwrap();
    }
    check_convergence(roukf.trace(), truth);
    assert_eq!(roukf.trace().records.len(), 201);
    assert!((roukf.mean_physical()[0] - roukf.mean()[0].exp()).abs() < 1e-15);
    // The corrected mean state follows the noise-free truth within a few observation σ.
    let mut x = 0.0;
    for k in 1..=200 {
        Decay.step(&mut x, &[truth], k).unwrap();
    }
    assert!((roukf.mean_state().unwrap()[0] - x).abs() < 0.03);
}

/// Quasi-static nonlinear spring: the state solves θ x + x³ = f_k by Newton, warm-started from the previous x
/// (the situation of a static FEM model, where the state only serves as the initial guess).
struct QuasiStatic;

#[derive(Debug)]
struct NoConvergence;

impl std::fmt::Display for NoConvergence {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Newton did not converge")
    }
}

impl std::error::Error for NoConvergence {}

impl Model for QuasiStatic {
    type State = f64;
    type Error = NoConvergence;
    fn step(&self, x: &mut f64, theta: &[f64], step: usize) -> Result<(), NoConvergence> {
        let f = forcing(step);
        for _ in 0..50 {
            let r = theta[0] * *x + x.powi(3) - f;
            if r.abs() < 1e-14 {
                return Ok(());
            }
            *x -= r / (theta[0] + 3.0 * *x * *x);
        }
        Err(NoConvergence)
    }
    fn observe(&self, x: &f64) -> DVector<f64> {
        DVector::from_element(1, *x)
    }
}

#[test]
fn quasi_static_stiffness_converges_parameter_only() {
    let truth = 2.0;
    let obs_std = 0.005;
    let mut rng = Rng::new(6);
    let mut x_true = 0.0;
    let mut roukf = Roukf::new(QuasiStatic, 0.0, rate_config(Execution::Sequential)).unwrap();
    assert!(roukf.mean_state().is_none());
    for k in 1..=150 {
        QuasiStatic.step(&mut x_true, &[truth], k).unwrap();
        roukf.step(&DVector::from_element(1, x_true + obs_std * rng.normal())).unwrap();
    }
    check_convergence(roukf.trace(), truth);
    // Each sigma point carries its own solution: x(i) solves the equilibrium of its own last parameter value.
    assert_eq!(roukf.sigma_states().len(), 2);
    assert!(roukf.sigma_states()[0] != roukf.sigma_states()[1]);
}

/// Three-parameter nonlinear model with two observed components (for parallel vs sequential comparisons).
struct Cascade;

impl Model for Cascade {
    type State = [f64; 2];
    type Error = Infallible;
    fn step(&self, x: &mut [f64; 2], theta: &[f64], step: usize) -> Result<(), Infallible> {
        let x1 = x[0] * (-theta[0] * DT).exp() + theta[1] * forcing(step) * DT;
        let x2 = x[1] * (-theta[2] * DT).exp() + x[0] * x[0] * DT;
        *x = [x1, x2];
        Ok(())
    }
    fn observe(&self, x: &[f64; 2]) -> DVector<f64> {
        DVector::from_column_slice(x)
    }
}

impl VectorState for Cascade {
    fn state_vector(&self, x: &[f64; 2]) -> DVector<f64> {
        DVector::from_column_slice(x)
    }
    fn set_state_vector(&self, x: &mut [f64; 2], v: &DVector<f64>) {
        *x = [v[0], v[1]];
    }
}

fn cascade_run(execution: Execution, joint: bool) -> (Trace, Vec<[f64; 2]>) {
    let truth = [1.5, 2.0, 0.7];
    let mut rng = Rng::new(99);
    let mut x = [0.0, 0.0];
    let config = RoukfConfig {
        parameters: vec![
            ParameterSpec::new("a", Transform::Exp, 0.0, 0.5),
            ParameterSpec::new("b", Transform::Identity, 1.0, 1.0),
            ParameterSpec::new("c", Transform::Abs, 0.2, 0.5),
        ],
        observation_std: ObservationNoise::PerComponent(vec![0.01, 0.02]),
        execution,
        forgetting: 1.0,
        sigma_points: SigmaPointSet::Simplex,
        gate: None,
    };
    let mut roukf = if joint {
        Roukf::new_joint(Cascade, [0.0, 0.0], config).unwrap()
    } else {
        Roukf::new(Cascade, [0.0, 0.0], config).unwrap()
    };
    for k in 1..=60 {
        Cascade.step(&mut x, &truth, k).unwrap();
        let z = DVector::from_vec(vec![x[0] + 0.01 * rng.normal(), x[1] + 0.02 * rng.normal()]);
        roukf.step(&z).unwrap();
    }
    (roukf.trace().clone(), roukf.sigma_states().to_vec())
}

fn bits(v: &[f64]) -> Vec<u64> {
    v.iter().map(|x| x.to_bits()).collect()
}

#[test]
fn parallel_and_sequential_runs_are_bit_identical() {
    for joint in [false, true] {
        let (par, par_states) = cascade_run(Execution::Parallel, joint);
        let (seq, seq_states) = cascade_run(Execution::Sequential, joint);
        assert_eq!(par.records.len(), seq.records.len());
        for (a, b) in par.records.iter().zip(&seq.records) {
            assert_eq!(a.iteration, b.iteration);
            assert_eq!(bits(&a.mean), bits(&b.mean), "joint={joint} iteration {}", a.iteration);
            assert_eq!(bits(&a.std), bits(&b.std));
            assert_eq!(bits(&a.mean_physical), bits(&b.mean_physical));
            assert_eq!(bits(&a.std_physical), bits(&b.std_physical));
            assert_eq!(a.innovation_norm.map(f64::to_bits), b.innovation_norm.map(f64::to_bits));
        }
        let flat = |s: &[[f64; 2]]| bits(&s.iter().flatten().copied().collect::<Vec<_>>());
        assert_eq!(flat(&par_states), flat(&seq_states));
        // The estimate moved from the prior towards the truth (guards against a trivially constant filter).
        let last = par.records.last().unwrap();
        assert!((last.mean_physical[1] - 2.0).abs() < 0.5, "b = {}", last.mean_physical[1]);
    }
}

#[test]
fn traces_are_written_as_csv_and_json() {
    let (trace, _) = cascade_run(Execution::Parallel, true);
    let dir = tempfile::tempdir().unwrap();
    let csv_path = dir.path().join("trace.csv");
    let json_path = dir.path().join("trace.json");
    trace.write_csv(&csv_path).unwrap();
    trace.write_json(&json_path).unwrap();
    // Overwriting works too (rename onto an existing file).
    trace.write_json(&json_path).unwrap();

    let back: Trace = serde_json::from_str(&std::fs::read_to_string(&json_path).unwrap()).unwrap();
    assert_eq!(back, trace);

    let csv = std::fs::read_to_string(&csv_path).unwrap();
    let lines: Vec<&str> = csv.lines().collect();
    assert_eq!(lines.len(), trace.records.len() + 1);
    let header: Vec<&str> = lines[0].split(',').collect();
    assert_eq!(header.len(), 3 + 4 * 3);
    assert_eq!(&header[..4], &["iteration", "innovation_norm", "wall_seconds", "mu_a"]);
    assert_eq!(header[14], "sigma_phys_c");
    let prior: Vec<&str> = lines[1].split(',').collect();
    assert_eq!(&prior[..3], &["0", "", ""]);
    let last: Vec<&str> = lines.last().unwrap().split(',').collect();
    let rec = trace.records.last().unwrap();
    assert_eq!(last[0].parse::<usize>().unwrap(), rec.iteration);
    assert_eq!(last[1].parse::<f64>().unwrap(), rec.innovation_norm.unwrap());
    assert_eq!(last[3].parse::<f64>().unwrap(), rec.mean[0]);
    assert_eq!(last[14].parse::<f64>().unwrap(), rec.std_physical[2]);

    // Only the two files remain: no temporary left behind.
    let mut names: Vec<String> =
        std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    names.sort();
    assert_eq!(names, ["trace.csv", "trace.json"]);

    // A parent that is a regular file cannot hold the output: a clear error naming the path.
    let blocked = dir.path().join("trace.csv").join("t.csv");
    let err = trace.write_csv(&blocked).unwrap_err();
    assert!(err.to_string().contains("trace.csv/t.csv"), "{err}");
}
