//! On linear-Gaussian models the ROUKF must coincide with the closed-form Kalman filter.

mod common;

use std::convert::Infallible;

use augsim_filter::{
    Execution, Model, ObservationNoise, ParameterSpec, Roukf, RoukfConfig, SigmaPointSet, Transform, VectorState,
};
use common::Rng;
use nalgebra::{DMatrix, DVector};

fn rel_diff(a: &DMatrix<f64>, b: &DMatrix<f64>) -> f64 {
    (a - b).amax() / b.amax().max(1e-300)
}

/// Static parameters observed linearly: y_k = H_k θ + noise. The state holds the last H_k θ.
struct StaticLinear {
    h: Vec<DMatrix<f64>>,
}

impl Model for StaticLinear {
    type State = DVector<f64>;
    type Error = Infallible;
    fn step(&self, state: &mut DVector<f64>, theta: &[f64], step: usize) -> Result<(), Infallible> {
        *state = &self.h[step - 1] * DVector::from_column_slice(theta);
        Ok(())
    }
    fn observe(&self, state: &DVector<f64>) -> DVector<f64> {
        state.clone()
    }
}

/// Runs the ROUKF with the sigma points `set` on `StaticLinear` against the closed-form Kalman filter whose
/// covariance is divided by `forgetting` before every update and which uses only the components that `available(k)`
/// marks at step k.
fn static_parameters_against_kalman(
    set: SigmaPointSet,
    forgetting: f64,
    available: impl Fn(usize) -> Vec<bool>,
) -> Roukf<StaticLinear> {
    let (p, q, steps) = (3, 2, 60);
    let mut rng = Rng::new(11);
    let h: Vec<DMatrix<f64>> = (0..steps).map(|_| DMatrix::from_fn(q, p, |_, _| rng.normal())).collect();
    let truth = DVector::from_vec(vec![1.5, -0.7, 3.0]);
    let obs_std = vec![0.1, 0.25];
    let prior_mean = [0.0, 0.5, 1.0];
    let prior_std = [2.0, 1.0, 0.5];
    let config = RoukfConfig {
        parameters: (0..p)
            .map(|j| ParameterSpec::new(format!("t{j}"), Transform::Identity, prior_mean[j], prior_std[j]))
            .collect(),
        observation_std: ObservationNoise::PerComponent(obs_std.clone()),
        execution: Execution::Parallel,
        forgetting,
        sigma_points: set,
        gate: None,
    };
    let mut roukf = Roukf::new(StaticLinear { h: h.clone() }, DVector::zeros(q), config).unwrap();
    assert_eq!(roukf.sigma_points().count(), set.count(p));

    let mut mu = DVector::from_column_slice(&prior_mean);
    let mut cov = DMatrix::from_diagonal(&DVector::from_iterator(p, prior_std.iter().map(|s| s * s)));
    for (k, hk) in h.iter().enumerate() {
        let noise = DVector::from_iterator(q, obs_std.iter().map(|s| s * rng.normal()));
        let mut z = hk * &truth + noise;
        let mask = available(k);
        let rows: Vec<usize> = (0..q).filter(|&i| mask[i]).collect();
        cov /= forgetting;
        if !rows.is_empty() {
            // Closed-form Kalman filter (Joseph form) on the measured components.
            let hk = hk.select_rows(&rows);
            let r =
                DMatrix::from_diagonal(&DVector::from_iterator(rows.len(), rows.iter().map(|&i| obs_std[i].powi(2))));
            let s = &hk * &cov * hk.transpose() + &r;
            let gain = &cov * hk.transpose() * s.try_inverse().unwrap();
            mu = &mu + &gain * (z.select_rows(&rows) - &hk * &mu);
            let ikh = DMatrix::identity(p, p) - &gain * &hk;
            cov = &ikh * &cov * ikh.transpose() + &gain * &r * gain.transpose();
        }
        // What the filter must ignore: a NaN where nothing was measured.
        for i in (0..q).filter(|&i| !mask[i]) {
            z[i] = f64::NAN;
        }

        let rec = roukf.step_partial(&z, &mask).unwrap().clone();
        assert_eq!(rec.iteration, k + 1);
        // A frame with nothing measured has no innovation (not a zero one).
        assert_eq!(rec.innovation_norm.is_some(), !rows.is_empty(), "step {k}");
        let got_mu = DMatrix::from_column_slice(p, 1, &rec.mean);
        let exp_mu = DMatrix::from_column_slice(p, 1, mu.as_slice());
        assert!(rel_diff(&got_mu, &exp_mu) < 1e-10, "mean at {k}: {got_mu} vs {exp_mu}");
        assert!(rel_diff(&roukf.covariance(), &cov) < 1e-10, "covariance at {k}");
        for j in 0..p {
            assert!((rec.std[j] - cov[(j, j)].sqrt()).abs() < 1e-10 * cov[(j, j)].sqrt());
        }
    }
    // The data are informative: the estimate is close to the truth.
    assert!((roukf.mean() - &truth).amax() < 0.1);
    roukf
}

#[test]
fn static_parameters_linear_observation_match_kalman_filter() {
    static_parameters_against_kalman(SigmaPointSet::Simplex, 1.0, |_| vec![true; 2]);
}

#[test]
fn star_sigma_points_match_kalman_filter() {
    // 2p + 1 = 7 points instead of 4, same closed-form mean and covariance at every step, with and without
    // forgetting and missing components.
    let all = |_: usize| vec![true; 2];
    let mask = |k: usize| vec![k % 5 != 4, k.is_multiple_of(2)];
    let star = static_parameters_against_kalman(SigmaPointSet::Star, 1.0, all);
    assert_eq!(star.sigma_states().len(), 7);
    static_parameters_against_kalman(SigmaPointSet::Star, 0.95, mask);
    // Both sets give the same filter up to rounding.
    let simplex = static_parameters_against_kalman(SigmaPointSet::Simplex, 1.0, all);
    assert!((star.mean() - simplex.mean()).amax() < 1e-12 * simplex.mean().amax());
    assert!(rel_diff(&star.covariance(), &simplex.covariance()) < 1e-10);
}

#[test]
fn forgetting_and_missing_components_match_kalman_filter() {
    // Component 1 missing every third step, both missing every seventh.
    let mask = |k: usize| vec![k % 7 != 6, !k.is_multiple_of(3) && k % 7 != 6];
    let plain = static_parameters_against_kalman(SigmaPointSet::Simplex, 1.0, mask);
    let forgetting = static_parameters_against_kalman(SigmaPointSet::Simplex, 0.9, mask);
    // Forgetting keeps σ from collapsing as 1/√k: after 60 steps it is over twice the plain filter's.
    let (s1, s09) = (plain.std(), forgetting.std());
    assert!(s1.iter().zip(&s09).all(|(a, b)| *b > 2.0 * a), "{s1:?} vs {s09:?}");
    // Invalid factors are configuration errors.
    for rho in [0.0, -0.5, 1.5, f64::NAN] {
        let config = RoukfConfig {
            parameters: vec![ParameterSpec::new("t", Transform::Identity, 0.0, 1.0)],
            observation_std: ObservationNoise::Uniform(1.0),
            execution: Execution::Sequential,
            forgetting: rho,
            sigma_points: SigmaPointSet::Simplex,
            gate: None,
        };
        let err = Roukf::new(StaticLinear { h: vec![] }, DVector::zeros(1), config).err().unwrap().to_string();
        assert!(err.contains("forgetting factor"), "{err}");
    }
}

/// Linear state space with unknown static parameters: x_{k+1} = A x_k + B θ + u_k, y = C x.
struct LinearStateSpace {
    a: DMatrix<f64>,
    b: DMatrix<f64>,
    c: DMatrix<f64>,
    inputs: Vec<DVector<f64>>,
}

impl Model for LinearStateSpace {
    type State = DVector<f64>;
    type Error = Infallible;
    fn step(&self, x: &mut DVector<f64>, theta: &[f64], step: usize) -> Result<(), Infallible> {
        *x = &self.a * &*x + &self.b * DVector::from_column_slice(theta) + &self.inputs[step - 1];
        Ok(())
    }
    fn observe(&self, x: &DVector<f64>) -> DVector<f64> {
        &self.c * x
    }
}

impl VectorState for LinearStateSpace {
    fn state_vector(&self, x: &DVector<f64>) -> DVector<f64> {
        x.clone()
    }
    fn set_state_vector(&self, x: &mut DVector<f64>, v: &DVector<f64>) {
        x.copy_from(v);
    }
}

#[test]
fn joint_linear_state_space_matches_augmented_kalman_filter() {
    joint_against_augmented_kalman(SigmaPointSet::Simplex);
    joint_against_augmented_kalman(SigmaPointSet::Star);
}

fn joint_against_augmented_kalman(set: SigmaPointSet) {
    let (n, p, q, steps) = (3, 2, 2, 80);
    let mut rng = Rng::new(23);
    let (c, s) = (0.3f64.cos(), 0.3f64.sin());
    let a = DMatrix::from_row_slice(n, n, &[0.95 * c, -0.95 * s, 0.0, 0.95 * s, 0.95 * c, 0.1, 0.0, 0.0, 0.9]);
    let b = DMatrix::from_row_slice(n, p, &[0.2, 0.0, 0.0, 0.1, 0.3, -0.2]);
    let cm = DMatrix::from_row_slice(q, n, &[1.0, 0.0, 0.5, 0.0, 1.0, -1.0]);
    let inputs: Vec<DVector<f64>> = (0..steps).map(|_| DVector::from_fn(n, |_, _| 0.5 * rng.normal())).collect();
    let truth = DVector::from_vec(vec![2.0, -1.0]);
    let x0 = DVector::from_vec(vec![1.0, 0.0, -0.5]);
    let obs_std = 0.05;
    let prior_mean = [0.5, 0.0];
    let prior_std = [1.0, 2.0];
    let config = RoukfConfig {
        parameters: (0..p)
            .map(|j| ParameterSpec::new(format!("b{j}"), Transform::Identity, prior_mean[j], prior_std[j]))
            .collect(),
        observation_std: ObservationNoise::Uniform(obs_std),
        execution: Execution::Sequential,
        forgetting: 1.0,
        sigma_points: set,
        gate: None,
    };
    let model = LinearStateSpace { a: a.clone(), b: b.clone(), c: cm.clone(), inputs: inputs.clone() };
    let mut roukf = Roukf::new_joint(model, x0.clone(), config).unwrap();

    // Augmented Kalman filter on s = (x, θ), no process noise, x0 known.
    let d = n + p;
    let mut f = DMatrix::zeros(d, d);
    f.view_mut((0, 0), (n, n)).copy_from(&a);
    f.view_mut((0, n), (n, p)).copy_from(&b);
    f.view_mut((n, n), (p, p)).fill_with_identity();
    let mut hm = DMatrix::zeros(q, d);
    hm.view_mut((0, 0), (q, n)).copy_from(&cm);
    let r = DMatrix::identity(q, q) * (obs_std * obs_std);
    let mut s_mean = DVector::zeros(d);
    s_mean.rows_mut(0, n).copy_from(&x0);
    s_mean.rows_mut(n, p).copy_from(&DVector::from_column_slice(&prior_mean));
    let mut cov = DMatrix::zeros(d, d);
    for j in 0..p {
        cov[(n + j, n + j)] = prior_std[j] * prior_std[j];
    }
    let mut x_true = x0.clone();
    for (k, input) in inputs.iter().enumerate() {
        x_true = &a * &x_true + &b * &truth + input;
        let z = &cm * &x_true + DVector::from_fn(q, |_, _| obs_std * rng.normal());

        let mut u = DVector::zeros(d);
        u.rows_mut(0, n).copy_from(input);
        s_mean = &f * &s_mean + u;
        cov = &f * &cov * f.transpose();
        let sm = &hm * &cov * hm.transpose() + &r;
        let gain = &cov * hm.transpose() * sm.try_inverse().unwrap();
        s_mean = &s_mean + &gain * (&z - &hm * &s_mean);
        let ikh = DMatrix::identity(d, d) - &gain * &hm;
        cov = &ikh * &cov * ikh.transpose() + &gain * &r * gain.transpose();

        roukf.step(&z).unwrap();
        let theta = DMatrix::from_column_slice(p, 1, roukf.mean().as_slice());
        let exp_theta = DMatrix::from_column_slice(p, 1, s_mean.rows(n, p).as_slice());
        assert!(rel_diff(&theta, &exp_theta) < 1e-10, "θ at {k} ({set}): {theta} vs {exp_theta}");
        let x = DMatrix::from_column_slice(n, 1, roukf.mean_state().unwrap().as_slice());
        let exp_x = DMatrix::from_column_slice(n, 1, s_mean.rows(0, n).as_slice());
        assert!(rel_diff(&x, &exp_x) < 1e-10, "x at {k} ({set})");
        assert!(rel_diff(&roukf.covariance(), &cov.view((n, n), (p, p)).into_owned()) < 1e-10, "P_θθ at {k} ({set})");
        let u_inv = roukf.u().clone().try_inverse().unwrap();
        let lx = roukf.state_factor().unwrap();
        let pxx = lx * &u_inv * lx.transpose();
        assert!(rel_diff(&pxx, &cov.view((0, 0), (n, n)).into_owned()) < 1e-9, "P_xx at {k} ({set})");
        let pxt = lx * &u_inv * roukf.l_theta().transpose();
        assert!(rel_diff(&pxt, &cov.view((0, n), (n, p)).into_owned()) < 1e-9, "P_xθ at {k} ({set})");
    }
    assert!((roukf.mean() - &truth).amax() < 0.05, "estimate {} vs truth {truth}", roukf.mean());
}

#[test]
fn a_component_past_the_validation_gate_counts_as_not_measured() {
    let (p, q, steps, outlier) = (3, 2, 30, 12);
    let mut rng = Rng::new(17);
    let h: Vec<DMatrix<f64>> = (0..steps).map(|_| DMatrix::from_fn(q, p, |_, _| rng.normal())).collect();
    let truth = DVector::from_vec(vec![1.5, -0.7, 3.0]);
    let filter = |gate: Option<f64>| {
        let config = RoukfConfig {
            parameters: (0..p).map(|j| ParameterSpec::new(format!("t{j}"), Transform::Identity, 0.0, 2.0)).collect(),
            observation_std: ObservationNoise::Uniform(0.1),
            execution: Execution::Sequential,
            forgetting: 1.0,
            sigma_points: SigmaPointSet::Simplex,
            gate,
        };
        Roukf::new(StaticLinear { h: h.clone() }, DVector::zeros(q), config).unwrap()
    };
    let (mut gated, mut told, mut plain) = (filter(Some(10.0)), filter(None), filter(None));
    for (k, hk) in h.iter().enumerate() {
        let mut z = hk * &truth + DVector::from_fn(q, |_, _| 0.1 * rng.normal());
        // A tracking failure: component 0 off by 100 σ at one step.
        if k == outlier {
            z[0] += 10.0;
        }
        let record = gated.step(&z).unwrap().clone();
        assert_eq!(record.gated, usize::from(k == outlier), "step {k}");
        // The gated filter is the one told that the component was not measured at that step.
        let told_record = told.step_partial(&z, &[k != outlier, true]).unwrap().clone();
        assert_eq!(told_record.gated, 0);
        for (a, b) in record.mean.iter().zip(&told_record.mean) {
            assert!((a - b).abs() < 1e-12 * b.abs().max(1.0), "step {k}: {:?} vs {:?}", record.mean, told_record.mean);
        }
        plain.step(&z).unwrap();
    }
    // Without the gate the failure pulls the estimate off; with it the estimate holds.
    let off = |f: &Roukf<StaticLinear>| (f.mean() - &truth).amax();
    assert!(off(&gated) < 0.1 && off(&plain) > 2.0 * off(&gated), "{} vs {}", off(&gated), off(&plain));
    // A gate must be a positive number.
    for gate in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        let config = RoukfConfig { gate: Some(gate), ..filter(None).config().clone() };
        let err = Roukf::new(StaticLinear { h: vec![] }, DVector::zeros(q), config).err().unwrap().to_string();
        assert!(err.contains("validation gate"), "{err}");
    }
}
