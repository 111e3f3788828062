//! The model-discrepancy allowance (`Roukf::with_discrepancy`): on a linear model observed through a cyclic load,
//! a deliberate model error that a change of the parameter can partly imitate biases the plain filter far outside
//! its σ, and the systematic allowance covers it; with an exact model it adds nothing, the misfit χ²/ν finds the
//! true noise level, and without the option nothing changes.

mod common;

use std::convert::Infallible;

use augsim_filter::{
    Discrepancy, Execution, Model, ObservationNoise, ParameterSpec, Roukf, RoukfConfig, SigmaPointSet, Transform,
};
use common::Rng;
use nalgebra::DVector;

const TRUTH: f64 = 5.0;
const NOMINAL_STD: f64 = 0.01;
const FRAMES: usize = 200;

/// `h_k(θ) = s_k r(θ) φ` with a raised-cosine load `s_k` of period 100 frames (as the ROUKF Young's-modulus
/// scenario's force) and the response `r`: θ itself, or 1/θ (a displacement, θ the stiffness).
struct Cyclic {
    pattern: DVector<f64>,
    response: fn(f64) -> f64,
}

fn load(k: usize) -> f64 {
    0.5 * (1.0 - (2.0 * std::f64::consts::PI * k as f64 / 100.0).cos())
}

impl Model for Cyclic {
    type State = DVector<f64>;
    type Error = Infallible;
    fn step(&self, state: &mut DVector<f64>, theta: &[f64], step: usize) -> Result<(), Infallible> {
        *state = &self.pattern * (load(step) * (self.response)(theta[0]));
        Ok(())
    }
    fn observe(&self, state: &DVector<f64>) -> DVector<f64> {
        state.clone()
    }
}

/// The sensitivity pattern φ (q = 40), a unit pattern ψ orthogonal to it, and the noisy data
/// `z_k = s_k (θ* φ + β φ + γ ψ) + noise`: a model error `s_k (β φ + γ ψ)` that grows with the load, of which
/// the part `β φ` is indistinguishable from a change of θ by β.
struct Data {
    pattern: DVector<f64>,
    frames: Vec<DVector<f64>>,
}

fn data(beta: f64, gamma: f64, noise_std: f64, seed: u64) -> Data {
    let q = 40;
    let mut rng = Rng::new(seed);
    let pattern = DVector::from_fn(q, |_, _| 0.05 + 0.02 * rng.normal());
    let mut other = DVector::from_fn(q, |_, _| rng.normal());
    other -= &pattern * (other.dot(&pattern) / pattern.norm_squared());
    other /= other.norm();
    let frames = (1..=FRAMES)
        .map(|k| {
            let clean = (&pattern * (TRUTH + beta) + &other * gamma) * load(k);
            clean + DVector::from_fn(q, |_, _| noise_std * rng.normal())
        })
        .collect();
    Data { pattern, frames }
}

fn filter(data: &Data, forgetting: f64) -> Roukf<Cyclic> {
    let config = RoukfConfig {
        parameters: vec![ParameterSpec::new("theta", Transform::Identity, 1.0, 2.0)],
        observation_std: ObservationNoise::Uniform(NOMINAL_STD),
        execution: Execution::Sequential,
        forgetting,
        sigma_points: SigmaPointSet::Simplex,
        gate: None,
    };
    let model = Cyclic { pattern: data.pattern.clone(), response: |theta| theta };
    Roukf::new(model, DVector::zeros(data.pattern.len()), config).unwrap()
}

fn run(mut roukf: Roukf<Cyclic>, data: &Data) -> Roukf<Cyclic> {
    for z in &data.frames {
        roukf.step(z).unwrap();
    }
    roukf
}

/// Final (estimate, σ) in physical space.
fn estimate(roukf: &Roukf<Cyclic>) -> (f64, f64) {
    (roukf.mean_physical()[0], roukf.std_physical()[0])
}

/// A model error with a part along the sensitivity twice as large (in norm) as the part the residuals can show.
fn biased() -> Data {
    let beta = 0.5;
    let norm = data(0.0, 0.0, 0.0, 1).pattern.norm();
    data(beta, beta * norm / 2.0, NOMINAL_STD, 1)
}

#[test]
fn systematic_allowance_covers_a_model_error_the_plain_filter_does_not() {
    let data = biased();
    let (plain_mean, plain_std) = estimate(&run(filter(&data, 1.0), &data));
    let plain_ratio = (plain_mean - TRUTH).abs() / plain_std;
    assert!((plain_mean - TRUTH - 0.5).abs() < 0.05, "the plain filter is biased by β: {plain_mean}");
    assert!(plain_ratio > 20.0, "the plain filter's σ {plain_std} should not cover the bias ({plain_ratio:.1} σ)");

    let honest = run(filter(&data, 1.0).with_discrepancy(Discrepancy::Systematic, 1.0).unwrap(), &data);
    let (mean, std) = estimate(&honest);
    assert_eq!(mean, plain_mean, "the allowance must not change the estimate");
    let ratio = (mean - TRUTH).abs() / std;
    println!("plain {plain_mean:.4} ± {plain_std:.4} ({plain_ratio:.1} σ), systematic ± {std:.4} ({ratio:.2} σ)");
    assert!(ratio <= 3.0, "systematic allowance: |error|/σ = {ratio:.2} (σ = {std})");
    assert!(ratio >= 1.0, "the allowance should not be much wider than the error: |error|/σ = {ratio:.2}");
    let noise_std = honest.trace().records.last().unwrap().noise_std_physical.as_ref().unwrap()[0];
    assert_eq!(noise_std, plain_std, "the noise-only σ is the plain filter's");
    assert!(honest.misfit().unwrap() > 1.5, "the model error shows in the misfit: {:?}", honest.misfit());

    // Independent misfit (d = ν) only rescales the noise σ: it does not cover the bias.
    let white = run(filter(&data, 1.0).with_discrepancy(Discrepancy::Independent, 1.0).unwrap(), &data);
    let (_, white_std) = estimate(&white);
    assert!(white_std > plain_std && (plain_mean - TRUTH).abs() / white_std > 10.0, "independent σ {white_std}");

    // More degrees of freedom, a narrower allowance: σ ∝ 1/√d.
    let d4 = run(filter(&data, 1.0).with_discrepancy(Discrepancy::Systematic, 4.0).unwrap(), &data);
    let (_, d4_std) = estimate(&d4);
    let expected = (plain_std.powi(2) + (std.powi(2) - plain_std.powi(2)) / 4.0).sqrt();
    assert!((d4_std - expected).abs() < 1e-9 * expected, "d = 4: {d4_std} vs {expected}");
}

#[test]
fn allowance_with_forgetting_still_covers_the_model_error() {
    let data = biased();
    let roukf = run(filter(&data, 0.98).with_discrepancy(Discrepancy::Systematic, 1.0).unwrap(), &data);
    let (mean, std) = estimate(&roukf);
    let ratio = (mean - TRUTH).abs() / std;
    println!("forgetting 0.98: {mean:.4} ± {std:.4} ({ratio:.2} σ)");
    assert!(ratio <= 3.0, "forgetting 0.98 + systematic: |error|/σ = {ratio:.2} (σ = {std})");
    let (plain_mean, plain_std) = estimate(&run(filter(&data, 0.98), &data));
    assert_eq!(mean, plain_mean);
    assert!((plain_mean - TRUTH).abs() / plain_std > 10.0, "forgetting alone does not cover it");
}

#[test]
fn exact_model_adds_nothing_and_the_misfit_finds_the_noise() {
    // Exact model and nominal noise: no excess beyond the χ² test, σ unchanged.
    let exact = data(0.0, 0.0, NOMINAL_STD, 3);
    let plain = run(filter(&exact, 1.0), &exact);
    let honest = run(filter(&exact, 1.0).with_discrepancy(Discrepancy::Systematic, 1.0).unwrap(), &exact);
    assert_eq!(estimate(&honest), estimate(&plain), "no model error: nothing added");
    let misfit = honest.misfit().unwrap();
    assert!((misfit - 1.0).abs() < 0.05, "χ²/ν = {misfit} with the nominal noise");
    let (mean, std) = estimate(&honest);
    assert!((mean - TRUTH).abs() / std < 3.0);

    // Exact model, true noise 2.5 × the nominal: the effective noise √(χ²/ν) σ_obs converges to the true one, and
    // the independent allowance scales σ by about that much.
    let noisy = data(0.0, 0.0, 2.5 * NOMINAL_STD, 4);
    let plain = run(filter(&noisy, 1.0), &noisy);
    let adaptive = run(filter(&noisy, 1.0).with_discrepancy(Discrepancy::Independent, 1.0).unwrap(), &noisy);
    let scale = adaptive.misfit().unwrap().sqrt();
    assert!((scale - 2.5).abs() < 0.1, "effective noise {scale} × nominal, true 2.5");
    let ratio = estimate(&adaptive).1 / estimate(&plain).1;
    assert!((ratio - 2.5).abs() < 0.15, "σ scaled by {ratio}");
    let mut steps = adaptive.trace().records.iter().skip(1).map(|r| r.misfit.unwrap().sqrt());
    assert!(steps.nth(99).is_some_and(|s| (s - 2.5).abs() < 0.2), "already near the truth after 100 frames");
}

#[test]
fn without_the_option_nothing_changes() {
    let data = biased();
    let plain = run(filter(&data, 0.99), &data);
    let none = run(filter(&data, 0.99).with_discrepancy(Discrepancy::None, 1.0).unwrap(), &data);
    let timeless = |r: &Roukf<Cyclic>| {
        let mut t = r.trace().clone();
        t.records.iter_mut().for_each(|r| r.wall_seconds = None);
        t
    };
    assert_eq!(timeless(&plain), timeless(&none));
    assert!(plain.trace().records.iter().all(|r| r.misfit.is_none() && r.noise_std_physical.is_none()));
    assert!(!plain.trace().to_csv().contains("misfit"));
    let json = serde_json::to_string(plain.trace()).unwrap();
    assert!(!json.contains("misfit") && !json.contains("noise_std_physical"));

    let honest = run(filter(&data, 0.99).with_discrepancy(Discrepancy::Systematic, 1.0).unwrap(), &data);
    let csv = honest.trace().to_csv();
    assert!(csv.starts_with("iteration,innovation_norm,wall_seconds,misfit,mu_theta,sigma_theta,"));
    assert!(csv.lines().next().unwrap().ends_with(",noise_sigma_phys_theta"));
    for (a, b) in plain.trace().records.iter().zip(&honest.trace().records) {
        assert_eq!(a.mean, b.mean);
    }
}

#[test]
fn invalid_degrees_of_freedom_are_refused() {
    let data = biased();
    for dof in [0.5, 0.0, f64::NAN, f64::INFINITY] {
        assert!(filter(&data, 1.0).with_discrepancy(Discrepancy::Systematic, dof).is_err(), "dof {dof}");
    }
    assert!(filter(&data, 1.0).with_discrepancy(Discrepancy::Independent, f64::NAN).is_ok());
    assert_eq!("systematic".parse::<Discrepancy>(), Ok(Discrepancy::Systematic));
    assert!("bias".parse::<Discrepancy>().is_err());
}

/// An exact model reached from a prior far from the truth (1 ± 0.2 for 5, as the Young's modulus
/// scenario's): the frames observed on the way, whose sensitivity at their estimate is not the one at
/// the end, do not count as model error; the misfit is the noise's, and σ is the plain filter's.
#[test]
fn the_frames_taken_far_from_the_estimate_do_not_count_as_model_error() {
    let q = 40;
    let mut rng = Rng::new(7);
    let pattern = DVector::from_fn(q, |_, _| 0.25 + 0.1 * rng.normal());
    let frames: Vec<DVector<f64>> = (1..=FRAMES)
        .map(|k| &pattern * (load(k) / TRUTH) + DVector::from_fn(q, |_, _| NOMINAL_STD * rng.normal()))
        .collect();
    let make = || {
        let config = RoukfConfig {
            parameters: vec![ParameterSpec::new("theta", Transform::Identity, 1.0, 0.2)],
            observation_std: ObservationNoise::Uniform(NOMINAL_STD),
            execution: Execution::Sequential,
            forgetting: 1.0,
            sigma_points: SigmaPointSet::Simplex,
            gate: None,
        };
        let model = Cyclic { pattern: pattern.clone(), response: |theta| 1.0 / theta };
        Roukf::new(model, DVector::zeros(q), config).unwrap()
    };
    let mut plain = make();
    let mut honest = make().with_discrepancy(Discrepancy::Systematic, 1.0).unwrap();
    for z in &frames {
        plain.step(z).unwrap();
        honest.step(z).unwrap();
    }
    let (mean, std) = (honest.mean_physical()[0], honest.std_physical()[0]);
    let misfit = honest.misfit().unwrap();
    println!("{mean:.4} ± {std:.5} (plain ± {:.5}), χ²/ν {misfit:.4}", plain.std_physical()[0]);
    assert!((misfit - 1.0).abs() < 0.03, "χ²/ν = {misfit} with an exact model and the nominal noise");
    assert_eq!(std, plain.std_physical()[0], "an exact model adds nothing to σ");
}
