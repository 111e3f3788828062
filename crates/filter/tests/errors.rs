//! Failures surface as clean errors (naming the sigma point and iteration) and leave the filter unchanged.

use std::sync::atomic::{AtomicUsize, Ordering};

use augsim_filter::{
    Execution, FilterError, Model, ObservationNoise, ParameterSpec, Roukf, RoukfConfig, SigmaPointSet, Transform,
};
use nalgebra::DVector;

#[derive(Debug)]
struct Diverged(f64);

impl std::fmt::Display for Diverged {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Newton diverged for stiffness {}", self.0)
    }
}

impl std::error::Error for Diverged {}

/// x = θ; fails at time step `fail_step` for every parameter value above `threshold`;
/// observes `scale * x` plus a NaN when `nan_above` is exceeded; admits values from `lowest` up.
struct Flaky {
    fail_step: AtomicUsize,
    threshold: f64,
    nan_above: f64,
    scale: f64,
    lowest: f64,
}

impl Flaky {
    fn new(fail_step: usize, threshold: f64) -> Self {
        let fail_step = AtomicUsize::new(fail_step);
        Flaky { fail_step, threshold, nan_above: f64::INFINITY, scale: 1.0, lowest: f64::NEG_INFINITY }
    }
}

impl Model for Flaky {
    type State = f64;
    type Error = Diverged;
    fn step(&self, x: &mut f64, theta: &[f64], step: usize) -> Result<(), Diverged> {
        if step == self.fail_step.load(Ordering::SeqCst) && theta[0] > self.threshold {
            return Err(Diverged(theta[0]));
        }
        *x = theta[0];
        Ok(())
    }
    fn observe(&self, x: &f64) -> DVector<f64> {
        let v = if *x > self.nan_above { f64::NAN } else { self.scale * *x };
        DVector::from_element(1, v)
    }
    fn admissible(&self, theta: &[f64]) -> Result<(), Diverged> {
        match theta[0] >= self.lowest {
            true => Ok(()),
            false => Err(Diverged(theta[0])),
        }
    }
}

fn config(execution: Execution) -> RoukfConfig {
    RoukfConfig {
        parameters: vec![ParameterSpec::new("k", Transform::Identity, 1.0, 0.5)],
        observation_std: ObservationNoise::Uniform(0.1),
        execution,
        forgetting: 1.0,
        sigma_points: SigmaPointSet::Simplex,
        gate: None,
    }
}

fn z(v: f64) -> DVector<f64> {
    DVector::from_element(1, v)
}

#[test]
fn model_error_names_sigma_point_and_iteration_and_leaves_filter_unchanged() {
    for execution in [Execution::Parallel, Execution::Sequential] {
        // With p = 1 the sigma points are θ̂ ∓ σ: only sigma point 1 (above the mean) fails.
        let mut roukf = Roukf::new(Flaky::new(3, 1.0), 0.0, config(execution)).unwrap();
        roukf.step(&z(1.0)).unwrap();
        roukf.step(&z(1.0)).unwrap();
        let before = (roukf.mean().clone(), roukf.covariance(), roukf.sigma_states().to_vec(), roukf.trace().clone());
        let err = roukf.step(&z(1.0)).unwrap_err();
        match &err {
            FilterError::Model { sigma_point, iteration, error } => {
                assert_eq!((*sigma_point, *iteration), (1, 3));
                assert!(error.to_string().contains("Newton diverged"));
            }
            other => panic!("unexpected error {other:?}"),
        }
        let msg = err.to_string();
        assert!(
            msg.contains("sigma point 1") && msg.contains("iteration 3") && msg.contains("Newton diverged"),
            "{msg}"
        );
        assert_eq!(roukf.iteration(), 2);
        let after = (roukf.mean().clone(), roukf.covariance(), roukf.sigma_states().to_vec(), roukf.trace().clone());
        assert_eq!(before, after);
        // Once the model recovers, the same iteration goes through.
        roukf.model().fail_step.store(usize::MAX, Ordering::SeqCst);
        assert_eq!(roukf.step(&z(1.0)).unwrap().iteration, 3);
    }
}

#[test]
fn when_several_sigma_points_fail_the_first_is_reported() {
    for execution in [Execution::Parallel, Execution::Sequential] {
        let mut roukf = Roukf::new(Flaky::new(1, f64::NEG_INFINITY), 0.0, config(execution)).unwrap();
        match roukf.step(&z(1.0)).unwrap_err() {
            FilterError::Model { sigma_point: 0, iteration: 1, .. } => {}
            other => panic!("unexpected error {other:?}"),
        }
    }
}

#[test]
fn nan_observation_from_the_model_names_the_sigma_point() {
    let mut model = Flaky::new(usize::MAX, 0.0);
    model.nan_above = 1.0;
    let mut roukf = Roukf::new(model, 0.0, config(Execution::Parallel)).unwrap();
    let err = roukf.step(&z(1.0)).unwrap_err();
    assert!(matches!(err, FilterError::SigmaPoint { sigma_point: 1, iteration: 1, .. }), "{err:?}");
    assert!(err.to_string().contains("NaN"), "{err}");
}

#[test]
fn overflowing_information_matrix_is_an_error_not_a_panic() {
    // Finite observations whose sensitivity squared overflows: U = I + HLᵀ W⁻¹ HL is infinite.
    let mut model = Flaky::new(usize::MAX, 0.0);
    model.scale = 1e300;
    let mut roukf = Roukf::new(model, 0.0, config(Execution::Sequential)).unwrap();
    let err = roukf.step(&z(1e300)).unwrap_err();
    assert!(matches!(err, FilterError::NonFinite { iteration: 1, .. }), "{err:?}");
    assert_eq!(roukf.iteration(), 0);
}

#[test]
fn bad_measurements_and_configurations_are_rejected() {
    let mut roukf = Roukf::new(Flaky::new(usize::MAX, 0.0), 0.0, config(Execution::Parallel)).unwrap();
    assert!(matches!(roukf.step(&z(f64::NAN)).unwrap_err(), FilterError::NonFinite { .. }));
    let err = roukf.step(&DVector::from_vec(vec![1.0, 2.0])).unwrap_err();
    assert!(matches!(err, FilterError::SigmaPoint { sigma_point: 0, .. }), "{err:?}");
    assert_eq!(roukf.iteration(), 0);

    let mut per = config(Execution::Parallel);
    per.observation_std = ObservationNoise::PerComponent(vec![0.1, 0.1]);
    let mut roukf = Roukf::new(Flaky::new(usize::MAX, 0.0), 0.0, per).unwrap();
    assert!(matches!(roukf.step(&z(1.0)).unwrap_err(), FilterError::DimensionMismatch { .. }));

    let mk = |f: &dyn Fn(&mut RoukfConfig)| {
        let mut c = config(Execution::Parallel);
        f(&mut c);
        Roukf::new(Flaky::new(usize::MAX, 0.0), 0.0, c).err()
    };
    assert!(matches!(mk(&|c| c.parameters.clear()), Some(FilterError::InvalidConfig(_))));
    assert!(matches!(mk(&|c| c.parameters[0].prior_std = 0.0), Some(FilterError::InvalidConfig(_))));
    assert!(matches!(mk(&|c| c.parameters[0].prior_mean = f64::NAN), Some(FilterError::InvalidConfig(_))));
    for scale in [0.0, -1.0, f64::INFINITY] {
        let err = mk(&|c| c.parameters[0].scale = scale).map(|e| e.to_string());
        assert!(err.as_deref().is_some_and(|e| e.contains("scale must be finite and > 0")), "{err:?}");
    }
    assert!(matches!(
        mk(&|c| c.observation_std = ObservationNoise::Uniform(-1.0)),
        Some(FilterError::InvalidConfig(_))
    ));
    assert!(mk(&|_| {}).is_none());
}

#[test]
fn exp_overflow_of_a_sigma_point_is_an_error() {
    let mut c = config(Execution::Parallel);
    c.parameters[0] = ParameterSpec::new("k", Transform::Exp, 800.0, 1.0);
    let mut roukf = Roukf::new(Flaky::new(usize::MAX, 0.0), 0.0, c).unwrap();
    let err = roukf.step(&z(1.0)).unwrap_err();
    assert!(matches!(err, FilterError::SigmaPoint { iteration: 1, .. }), "{err:?}");
}

/// An estimate finite in the filter's space but not in physical units (its exponential
/// overflowing) is refused, and the filter left as it was.
#[test]
fn an_estimate_overflowing_its_transform_is_an_error() {
    let mut c = config(Execution::Parallel);
    c.parameters[0] = ParameterSpec::new("k", Transform::Exp, 700.0, 1.0);
    c.observation_std = ObservationNoise::Uniform(1e300);
    let mut roukf = Roukf::new(Flaky::new(usize::MAX, 0.0), 0.0, c).unwrap();
    let err = roukf.step(&z(1e308)).unwrap_err();
    assert!(matches!(err, FilterError::NonFinite { iteration: 1, .. }), "{err:?}");
    assert!(err.to_string().contains("parameter estimate"), "{err}");
    assert_eq!(roukf.iteration(), 0);
}

/// An estimate outside the model's domain (a negative stiffness from a measurement in the wrong
/// unit) is refused, the filter left as it was: the next, sound measurement goes through.
#[test]
fn an_estimate_outside_the_model_s_domain_is_refused_and_the_filter_goes_on() {
    let mut model = Flaky::new(usize::MAX, 0.0);
    model.lowest = 0.0;
    let mut roukf = Roukf::new(model, 0.0, config(Execution::Parallel)).unwrap();
    let err = roukf.step(&z(-50.0)).unwrap_err();
    assert!(matches!(err, FilterError::Estimate { iteration: 1, .. }), "{err:?}");
    assert!(err.to_string().starts_with("the estimate of iteration 1 is refused"), "{err}");
    assert_eq!((roukf.iteration(), roukf.mean()[0]), (0, 1.0));
    assert_eq!(roukf.step(&z(1.2)).unwrap().iteration, 1);
    assert!(roukf.mean()[0] > 1.0);
}

/// A sigma point outside the model's domain (a prior σ as wide as its mean, on a positive
/// parameter) is an error naming it, before the model steps it.
#[test]
fn a_sigma_point_outside_the_model_s_domain_is_an_error() {
    let mut model = Flaky::new(usize::MAX, 0.0);
    model.lowest = 0.0;
    let mut c = config(Execution::Parallel);
    c.parameters[0] = ParameterSpec::new("k", Transform::Identity, 1.0, 5.0);
    let mut roukf = Roukf::new(model, 0.0, c).unwrap();
    let err = roukf.step(&z(1.0)).unwrap_err();
    assert!(matches!(err, FilterError::SigmaPoint { iteration: 1, .. }), "{err:?}");
    assert!(err.to_string().contains("its parameters lie outside the model's domain"), "{err}");
}

#[test]
fn config_deserialises_and_rejects_unknown_fields() {
    let text = r#"{"parameters": [{"name": "E", "transform": "exp", "prior_mean": 6.9, "prior_std": 0.2},
                                  {"name": "k", "prior_mean": 0.0, "prior_std": 0.01}],
                   "observation_std": 0.001}"#;
    let c: RoukfConfig = serde_json::from_str(text).unwrap();
    assert_eq!(c.parameters[0].transform, Transform::Exp);
    assert_eq!(c.parameters[1].transform, Transform::Identity);
    assert_eq!(c.observation_std, ObservationNoise::Uniform(0.001));
    assert_eq!(c.execution, Execution::Parallel);
    let per: RoukfConfig = serde_json::from_str(
        r#"{"parameters": [{"name": "k", "transform": "abs", "prior_mean": 0.0, "prior_std": 0.01}],
            "observation_std": [0.1, 0.2], "execution": "sequential"}"#,
    )
    .unwrap();
    assert_eq!(per.observation_std, ObservationNoise::PerComponent(vec![0.1, 0.2]));
    assert_eq!(per.execution, Execution::Sequential);
    let bad = r#"{"parameters": [{"name": "k", "prior_mean": 0.0, "prior_std": 0.01, "sigma": 1}],
                  "observation_std": 0.1}"#;
    assert!(serde_json::from_str::<RoukfConfig>(bad).is_err());
}
