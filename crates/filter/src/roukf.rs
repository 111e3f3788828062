//! The reduced-order unscented Kalman filter of Moireau & Chapelle (2011) with the reduced state restricted to the
//! uncertain parameters θ (as in SOFA's Optimus plugin).
//!
//! # Algorithm (one iteration k, p parameters, m unit sigma points I(i) with weights α_i)
//!
//! The sigma points are the p + 1 simplex points (default, α_i = 1/(p+1)) or the 2p + 1 star points (centre and
//! ±√(p+½) along every axis, α_i = 1/(2p+1)), chosen by [`RoukfConfig::sigma_points`] (see [`crate::SigmaPoints`]).
//! Both have `Σ α_i I(i) = 0` and `P_α = Σ α_i I(i) I(i)^T = I_p`, which is all the algorithm below relies on.
//!
//! The covariance is kept in factored form `P = L U^{-1} L^T`, `L = [L_x; L_θ]` (n × p over the full state,
//! p × p over θ), `U` p × p. Initially `L_θ = I_p`, `L_x = 0`, `U = P_θ0^{-1}` (diagonal prior).
//!
//! 1. Sampling: `U = C C^T` (Cholesky); `θ(i) = θ̂ + L_θ C^{-T} I(i)` and, in joint mode, `x(i) = x̂ + L_x C^{-T} I(i)`,
//!    with `C^{-T}` divided by √ρ for a forgetting factor ρ < 1 (the covariance inflated to `P / ρ`).
//! 2. Prediction: every sigma point advances its own copy of the model state with `g(θ(i))` (physical space);
//!    `x(i)⁻`, `Z(i) = H(x(i)⁻)`; means `θ̂⁻ = Σ α_i θ(i)`, `x̂⁻ = Σ α_i x(i)⁻`, `Ẑ = Σ α_i Z(i)`.
//! 3. Correction: `L_θ = Σ α_i (θ(i) - θ̂⁻) I(i)^T`, `L_x = Σ α_i (x(i)⁻ - x̂⁻) I(i)^T`,
//!    `HL = Σ α_i (Z(i) - Ẑ) I(i)^T`, `U = P_α + HL^T W^{-1} HL` with `P_α = Σ α_i I(i) I(i)^T = I_p`,
//!    `θ̂ = θ̂⁻ + L_θ U^{-1} HL^T W^{-1} (z - Ẑ)` and likewise `x̂ = x̂⁻ + L_x U^{-1} HL^T W^{-1} (z - Ẑ)`,
//!    with `W = diag(σ_obs²)`. (The paper writes the mean state minus the measurement with the opposite sign.)
//!
//! Centred sums are used for `L` and `HL` (mathematically identical since `Σ α_i I(i) = 0`, more accurate).
//! For a linear model with Gaussian noise this is exactly the Kalman filter of the augmented state.
//!
//! # Full state of the sigma points
//!
//! * [`Roukf::new`] (parameter-only): each sigma point keeps its own model state from its previous step (warm start)
//!   and only θ is resampled; the model state is not corrected. This is exact when the state is a function of the
//!   current parameters and loads (quasi-static FEM, where the state only serves as the Newton initial guess) and
//!   needs nothing from the model beyond [`Model`]. No mean state is formed; run the model at
//!   [`Roukf::mean_physical`] to display the estimated configuration.
//! * [`Roukf::new_joint`] (paper's algorithm in full, for models with memory): the mean state `x̂` is the weighted
//!   average of the sigma-point states corrected by `L_x`, and at every sampling each sigma point's state vector is
//!   re-set to `x̂ + L_x C^{-T} I(i)` (other warm-start data in the state are kept).
//!
//! # Model discrepancy (optional, [`Roukf::with_discrepancy`])
//!
//! The covariance above accounts for the observation noise only: with `q` components per frame and K frames it
//! shrinks like `1/(K q)`. When the model cannot reproduce the data (a coarser mesh than the one that made the
//! observations, a wrong constitutive law), the estimate is biased by the part of the model error that a change of
//! θ can imitate, and that bias does not shrink. It cannot be seen in the residuals either: the filter moves θ until
//! the part of the model error along the sensitivity `J = ∂H/∂θ` is explained, and what is left in the residuals is
//! only the model error orthogonal to J. [`Discrepancy`] adds to the reported covariance an allowance for that
//! bias, sized by what the residuals do show, under a stated assumption about how much of it can lie along J:
//!
//! * After each correction, the whitened post-correction residual `r̃_k = W^{-1/2}(z_k - Ẑ - HL c)` of frame k
//!   (`c` the correction in sigma-point coordinates, only the available components) is recorded with its
//!   Fisher information `F_k = J̃_k^T J̃_k` and score `J̃_k^T r̃_k`, `J̃_k = W^{-1/2} HL L_θ^{-1}` (the sensitivity in
//!   filter space, through the centred factor `L_θ`), the estimate `θ_k` and the region its sigma points sampled.
//!   The misfit *at the current estimate* θ̂, `χ²(θ̂) = Σ_k |r̃_k - J̃_k (θ̂ - θ_k)|²`, follows to first order over
//!   the frames whose sampled region, three times the sigma points' radius, holds θ̂ (`S` and `ν` over the same
//!   frames): a frame observed while the estimate was far off, where the first order cannot reach θ̂ (the
//!   sensitivity to a modulus falls as its square), does not count as model error. The last frames are kept
//!   (20,000, fewer with many parameters).
//! * With the nominal `W` right and the model right, `χ² ~ χ²(ν)`, `ν = Σ_k q_k - p`. The excess
//!   `e = max(0, χ² - ν - 2√(2ν))` (beyond two standard deviations of a χ²(ν), so that an exact model adds
//!   nothing in about 98 % of runs) is the misfit energy the noise model cannot explain.
//! * The parameter error that a discrepancy of energy `e` can cause depends on how many independent directions
//!   (over all frames) it is spread over, `d` ("degrees of freedom" of the discrepancy): if `d` directions share
//!   it equally and J̃ is one of them, the bias has covariance `(e/d) S^{-1}`, `S = P_0^{-1} + Σ_k F_k` (the
//!   information of the data and the prior). The reported covariance is `P + (e/d) S^{-1}`:
//!   - [`Discrepancy::Independent`], `d = ν`: the misfit is extra white observation noise, independent across
//!     components and frames. This is innovation-based adaptive estimation of the observation variance (Mehra 1972;
//!     the effective σ_obs is `σ_obs √(χ²/ν)`, never below the nominal one) and scales the covariance by the
//!     reduced χ² (the "Birge ratio" of least-squares fitting); it does not cover a bias.
//!   - [`Discrepancy::Systematic`] `{ dof: d }` (default `d = 1`): the misfit is a model error correlated across
//!     the features of a frame and across frames, of at most `d` independent directions, so that all of it may
//!     lie along J. The covariance then does not shrink with the number of observations (`e` and `S` both grow
//!     like K); this is the effective-number-of-observations correction for fully correlated errors, in the
//!     spirit of a Kennedy–O'Hagan model discrepancy or of a Schmidt "consider" covariance for a bias. With an
//!     exact model, `e = 0` and nothing is added. `d = 1` is the worst case and can be very wide with many
//!     parameters: every direction of θ that the data barely determine (small `S`) may take the whole misfit.
//! * With a forgetting factor ρ < 1 every sum is discounted by ρ per frame (ρ² for the variance `2ν` of χ²), so
//!   that misfit and information are measured over the same bounded memory as the filter's covariance.
//!
//! The allowance changes only the reported covariance ([`Roukf::covariance`], [`Roukf::std`], the trace's σ): the
//! estimate, the sigma points and the gain are those of the plain filter, so the option cannot degrade the estimate,
//! and without it the filter is unchanged bit for bit. [`Roukf::misfit`] gives `χ²/ν` and
//! [`Roukf::filter_covariance`] the noise-only covariance; the trace records both.
//!
//! Each iteration works on clones of the sigma-point states and commits only when every step succeeded, so a
//! failed iteration leaves the filter unchanged. Sigma points run in parallel with rayon or sequentially;
//! all reductions are sequential in sigma-point order, so both modes give bit-identical numbers.

use std::fmt;
use std::str::FromStr;
use std::time::Instant;

use nalgebra::{Cholesky, DMatrix, DVector};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::{FilterError, IterationTrace, Model, SigmaPointSet, SigmaPoints, Trace, Transform, VectorState};

/// One uncertain parameter: its name, its map to the physical value the model receives (`scale · transform(v)`)
/// and its Gaussian prior **in filter space** (e.g. for [`Transform::Exp`], the mean and standard deviation of the
/// logarithm).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ParameterSpec {
    /// Name used in traces.
    pub name: String,
    /// Map from filter space to physical space.
    #[serde(default)]
    pub transform: Transform,
    /// Prior mean μ0 (filter space).
    pub prior_mean: f64,
    /// Prior standard deviation σ0 > 0 (filter space).
    pub prior_std: f64,
    /// Physical value per unit of the transformed one (> 0, default 1): e.g. a spring stiffness in N/m whose filter
    /// value counts typical stiffnesses. Traces report the physical value, `scale · transform(v)`.
    #[serde(default = "unit_scale")]
    pub scale: f64,
}

fn unit_scale() -> f64 {
    1.0
}

impl ParameterSpec {
    /// A parameter with the given name, transform and filter-space prior, and scale 1.
    pub fn new(name: impl Into<String>, transform: Transform, prior_mean: f64, prior_std: f64) -> Self {
        ParameterSpec { name: name.into(), transform, prior_mean, prior_std, scale: 1.0 }
    }

    /// The same parameter with physical value `scale · transform(v)`.
    pub fn scaled(self, scale: f64) -> Self {
        ParameterSpec { scale, ..self }
    }

    /// The physical value of the filter-space value `v`: `scale · transform(v)`.
    pub fn to_physical(&self, v: f64) -> f64 {
        self.scale * self.transform.to_physical(v)
    }

    /// The derivative d(physical)/d(filter) at `v`.
    pub fn derivative(&self, v: f64) -> f64 {
        self.scale * self.transform.derivative(v)
    }
}

/// Standard deviation of the observation noise, `W = diag(σ_obs²)`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum ObservationNoise {
    /// The same σ_obs for every observed component.
    Uniform(f64),
    /// One σ_obs per observed component (length = observation length).
    PerComponent(Vec<f64>),
}

/// How the sigma points are evaluated.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Execution {
    /// All sigma points at once on the rayon thread pool.
    #[default]
    Parallel,
    /// One after the other on the calling thread (same numbers as `Parallel`).
    Sequential,
}

/// Configuration of a [`Roukf`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RoukfConfig {
    /// The reduced state, in order.
    pub parameters: Vec<ParameterSpec>,
    /// Observation noise.
    pub observation_std: ObservationNoise,
    /// Parallel or sequential sigma-point evaluation.
    #[serde(default)]
    pub execution: Execution,
    /// Forgetting factor ρ in (0, 1]: the covariance is divided by ρ before every prediction (process noise
    /// `(1/ρ − 1) P`, old measurements weigh ρ per step less), so that σ does not shrink below what the model error
    /// allows; 1 (the default) is the plain filter.
    #[serde(default = "no_forgetting")]
    pub forgetting: f64,
    /// Simplex (p + 1, the default) or star (2p + 1) sigma points.
    #[serde(default)]
    pub sigma_points: SigmaPointSet,
    /// Validation gate G: a measured component whose innovation exceeds G predicted standard
    /// deviations, `|z_i − ẑ_i| > G √(σ_obs,i² + Σ_j (HL)_ij²)`, is not measured at this step (a
    /// tracking failure, not the organ); `None` (the default): every component counts. The
    /// innovations of honest steps reach a few predicted standard deviations without model error,
    /// and tens with it: calibrate G on the scenario's own runs.
    #[serde(default)]
    pub gate: Option<f64>,
}

fn no_forgetting() -> f64 {
    1.0
}

/// Allowance for model error in the reported covariance (see the module documentation, "Model discrepancy").
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Discrepancy {
    /// None: the covariance reflects the observation noise only (the plain filter).
    #[default]
    None,
    /// The misfit beyond the nominal noise is extra white observation noise (`d = ν`): adaptive observation
    /// variance, the covariance scaled by the reduced χ².
    Independent,
    /// The misfit is a model error correlated over components and frames, with `d` independent directions over the
    /// whole run (`d = 1`: all of it may lie along the parameters' sensitivity).
    Systematic,
}

impl Discrepancy {
    /// The name used in scenario files and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Discrepancy::None => "none",
            Discrepancy::Independent => "independent",
            Discrepancy::Systematic => "systematic",
        }
    }
}

impl fmt::Display for Discrepancy {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Discrepancy {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "none" => Ok(Discrepancy::None),
            "independent" => Ok(Discrepancy::Independent),
            "systematic" => Ok(Discrepancy::Systematic),
            other => Err(format!("unknown discrepancy `{other}`: expected `none`, `independent` or `systematic`")),
        }
    }
}

/// One frame's misfit as a quadratic in θ (filter space), `χ²_k(θ) = |r̃_k - J̃_k (θ - θ_k)|²`, with the region
/// its sigma points sampled, within which that first-order form holds.
#[derive(Clone)]
struct FrameMisfit {
    /// The forgetting factor's discount, ρ per later frame.
    weight: f64,
    /// `|r̃_k|²`.
    residual: f64,
    /// `J̃_k^T r̃_k`.
    score: DVector<f64>,
    /// `F_k = J̃_k^T J̃_k`.
    information: DMatrix<f64>,
    /// The estimate after the frame, `θ_k`.
    theta: DVector<f64>,
    /// The sigma points' mean and the inverse of their centred factor `L_θ`: θ lies in the sampled region where
    /// `|L_θ^{-1} (θ - mean)|` is at most the unit sigma points' radius.
    centre: DVector<f64>,
    inverse_factor: DMatrix<f64>,
    /// Available components `q_k`.
    components: f64,
}

impl FrameMisfit {
    fn chi_squared(&self, theta: &DVector<f64>) -> f64 {
        let d = theta - &self.theta;
        self.residual - 2.0 * d.dot(&self.score) + d.dot(&(&self.information * &d))
    }
}

/// The frames' misfits (each discounted by the forgetting factor ρ per frame), from which the misfit `χ²(θ)` and
/// the information `S` at any θ follow over the frames whose sampled region holds θ (see the module
/// documentation); the last [`misfit_frames`] frames are kept.
#[derive(Clone)]
struct Misfit {
    /// Degrees of freedom d of a systematic discrepancy; `None` for an independent one (d = ν).
    systematic_dof: Option<f64>,
    /// Prior information `P_0^{-1}` (filter space).
    prior_information: DMatrix<f64>,
    /// The unit sigma points' radius (the largest `|I(i)|`).
    radius: f64,
    frames: std::collections::VecDeque<FrameMisfit>,
}

/// How far beyond its sigma points, in their radii, a frame's first-order misfit is taken to hold (a linear
/// extrapolation three standard deviations out).
const REACH: f64 = 3.0;

/// The last frames a misfit is measured over with `p` parameters: 20,000 (over 13 minutes of a stream at 25 Hz),
/// fewer with many parameters, so that they hold at most 4 million numbers.
fn misfit_frames(p: usize) -> usize {
    (4_000_000 / (2 * p * p + 3 * p + 3)).clamp(1, 20_000)
}

impl Misfit {
    fn new(systematic_dof: Option<f64>, prior_information: DMatrix<f64>, radius: f64) -> Self {
        Misfit { systematic_dof, prior_information, radius, frames: Default::default() }
    }

    /// Adds one frame (`None`: left out), the earlier frames discounted by `rho`; the oldest is dropped beyond
    /// the frames kept.
    fn add(&mut self, rho: f64, frame: Option<FrameMisfit>) {
        self.frames.iter_mut().for_each(|f| f.weight *= rho);
        let p = self.prior_information.nrows();
        while self.frames.len() >= misfit_frames(p) {
            self.frames.pop_front();
        }
        self.frames.extend(frame);
    }

    /// The frames whose sampled region, [`REACH`] times their sigma points' radius, holds `theta`: where their
    /// first-order misfit is near what they measured.
    fn holding<'a>(&'a self, theta: &'a DVector<f64>) -> impl Iterator<Item = &'a FrameMisfit> + 'a {
        let reach = REACH * self.radius;
        self.frames.iter().filter(move |f| (&f.inverse_factor * (theta - &f.centre)).norm() <= reach)
    }

    /// The sums over the frames holding `theta`, in one pass ([`HeldSums`]).
    fn sums(&self, theta: &DVector<f64>) -> HeldSums {
        let mut sums =
            HeldSums { chi_squared: 0.0, components: 0.0, squared: 0.0, information: self.prior_information.clone() };
        for f in self.holding(theta) {
            sums.chi_squared += f.weight * f.chi_squared(theta).max(0.0);
            sums.components += f.weight * f.components;
            sums.squared += f.weight.powi(2) * f.components;
            sums.information.zip_apply(&f.information, |s, i| *s += f.weight * i);
        }
        sums
    }

    /// `components` less the parameters, at least 1.
    fn less_parameters(&self, components: f64) -> f64 {
        (components - self.prior_information.nrows() as f64).max(1.0)
    }

    /// The reduced χ² at `theta`, `χ²(θ)/ν`; `None` while no frame's sampled region holds θ.
    fn reduced_chi_squared(&self, theta: &DVector<f64>) -> Option<f64> {
        let sums = self.sums(theta);
        (sums.components > 0.0).then(|| sums.chi_squared / self.less_parameters(sums.components))
    }

    /// The covariance `(e/d) S^{-1}` added to the filter's at `theta` (`None` when S is singular).
    fn allowance(&self, theta: &DVector<f64>) -> Option<DMatrix<f64>> {
        let sums = self.sums(theta);
        let nu = self.less_parameters(sums.components);
        // The variance of χ² over 2: ν, with the frames discounted by ρ² rather than ρ.
        let nu_variance = self.less_parameters(sums.squared);
        let excess = (sums.chi_squared - nu - 2.0 * (2.0 * nu_variance).sqrt()).max(0.0);
        let d = self.systematic_dof.unwrap_or(nu);
        Cholesky::new(sums.information).map(|c| c.inverse() * (excess / d))
    }
}

/// The square roots of a covariance's diagonal (a rounding below 0 taken as 0).
fn standard_deviations(covariance: &DMatrix<f64>) -> Vec<f64> {
    covariance.diagonal().iter().map(|v| v.max(0.0).sqrt()).collect()
}

/// Sums over the frames whose sampled region holds an estimate θ ([`Misfit::sums`]).
struct HeldSums {
    /// `χ²(θ) = Σ_k |r̃_k - J̃_k (θ - θ_k)|²` (first order, each frame's never negative).
    chi_squared: f64,
    /// `Σ q_k`, and `Σ q_k` discounted by ρ² rather than ρ (for the variance of χ²).
    components: f64,
    squared: f64,
    /// `S = P_0^{-1} + Σ_k F_k`.
    information: DMatrix<f64>,
}

/// Mean state and its factor for joint state–parameter filtering.
struct Joint<M: Model> {
    x: DVector<f64>,
    l_x: DMatrix<f64>,
    get: fn(&M, &M::State) -> DVector<f64>,
    set: fn(&M, &mut M::State, &DVector<f64>),
}

/// What one sigma point returns from the prediction: observation and (joint mode) state vector.
type SigmaOutput = (DVector<f64>, Option<DVector<f64>>);
/// The sigma points' parameters (reduced space) and their model states.
type Sampled<S> = (Vec<DVector<f64>>, Vec<S>);

/// Reduced-order unscented Kalman filter over the parameters of a [`Model`] (see the module documentation).
pub struct Roukf<M: Model> {
    model: M,
    config: RoukfConfig,
    sigma: SigmaPoints,
    theta: DVector<f64>,
    l_theta: DMatrix<f64>,
    u: DMatrix<f64>,
    u_chol: DMatrix<f64>,
    states: Vec<M::State>,
    joint: Option<Joint<M>>,
    iteration: usize,
    misfit: Option<Misfit>,
    trace: Trace,
}

impl<M: Model> Roukf<M> {
    /// Parameter-only filter: every sigma point starts from a clone of `initial_state` (passed through
    /// [`Model::assign_sigma_point`]) and then keeps its own state.
    pub fn new(model: M, initial_state: M::State, config: RoukfConfig) -> Result<Self, FilterError> {
        Self::build(model, initial_state, config, None)
    }

    /// Adds an allowance for model error to the reported covariance from now on (see the module documentation,
    /// "Model discrepancy"); `dof` is the number d ≥ 1 of independent directions of a
    /// [`Discrepancy::Systematic`] one (ignored otherwise). [`Discrepancy::None`] keeps the plain filter. Call it
    /// before the first [`Roukf::step`]: the frames before are not counted.
    pub fn with_discrepancy(mut self, kind: Discrepancy, dof: f64) -> Result<Self, FilterError> {
        if kind == Discrepancy::Systematic && !(dof.is_finite() && dof >= 1.0) {
            return Err(FilterError::InvalidConfig(format!(
                "the discrepancy's degrees of freedom must be finite and ≥ 1, got {dof}"
            )));
        }
        let radius = self.sigma.points().column_iter().map(|c| c.norm()).fold(0.0, f64::max);
        let misfit = |dof| Some(Misfit::new(dof, prior_information(&self.config.parameters), radius));
        self.misfit = match kind {
            Discrepancy::None => None,
            Discrepancy::Independent => misfit(None),
            Discrepancy::Systematic => misfit(Some(dof)),
        };
        Ok(self)
    }

    fn build(
        model: M,
        initial_state: M::State,
        config: RoukfConfig,
        joint: Option<Joint<M>>,
    ) -> Result<Self, FilterError> {
        let p = config.parameters.len();
        let sigma = config.sigma_points.build(p)?;
        for spec in &config.parameters {
            if !(spec.prior_mean.is_finite() && spec.prior_std.is_finite() && spec.prior_std > 0.0) {
                return Err(FilterError::InvalidConfig(format!(
                    "parameter '{}': prior mean must be finite and prior std finite and > 0 (got {}, {})",
                    spec.name, spec.prior_mean, spec.prior_std
                )));
            }
            if !(spec.scale.is_finite() && spec.scale > 0.0) {
                return Err(FilterError::InvalidConfig(format!(
                    "parameter '{}': scale must be finite and > 0 (got {})",
                    spec.name, spec.scale
                )));
            }
        }
        if !(config.forgetting > 0.0 && config.forgetting <= 1.0) {
            return Err(FilterError::InvalidConfig(format!(
                "the forgetting factor must lie in (0, 1], got {}",
                config.forgetting
            )));
        }
        if let Some(gate) = config.gate.filter(|g| !(g.is_finite() && *g > 0.0)) {
            return Err(FilterError::InvalidConfig(format!("the validation gate must be finite and > 0, got {gate}")));
        }
        let stds: &[f64] = match &config.observation_std {
            ObservationNoise::Uniform(s) => std::slice::from_ref(s),
            ObservationNoise::PerComponent(v) => v,
        };
        if let Some((j, s)) = stds.iter().enumerate().find(|(_, s)| !(s.is_finite() && **s > 0.0)) {
            return Err(FilterError::InvalidConfig(format!("observation std #{j} must be finite and > 0 (got {s})")));
        }
        let theta = DVector::from_iterator(p, config.parameters.iter().map(|s| s.prior_mean));
        let u = prior_information(&config.parameters);
        let u_chol =
            DMatrix::from_diagonal(&DVector::from_iterator(p, config.parameters.iter().map(|s| 1.0 / s.prior_std)));
        let trace = Trace {
            parameter_names: config.parameters.iter().map(|s| s.name.clone()).collect(),
            transforms: config.parameters.iter().map(|s| s.transform).collect(),
            scales: config.parameters.iter().map(|s| s.scale).collect(),
            records: Vec::new(),
        };
        let mut states = vec![initial_state; sigma.count()];
        for (i, state) in states.iter_mut().enumerate() {
            model.assign_sigma_point(state, i);
        }
        let mut filter = Roukf {
            model,
            config,
            sigma,
            theta,
            l_theta: DMatrix::identity(p, p),
            u,
            u_chol,
            states,
            joint,
            iteration: 0,
            misfit: None,
            trace,
        };
        let record = filter.record(None, None);
        filter.trace.records.push(record);
        Ok(filter)
    }

    /// Runs one iteration with the measurement `z` at time step `iteration() + 1`: sampling, prediction of every
    /// sigma point (model step + observation), correction. Returns the new trace record.
    pub fn step(&mut self, z: &DVector<f64>) -> Result<&IterationTrace, FilterError> {
        self.step_partial(z, &vec![true; z.len()])
    }

    /// Like [`Roukf::step`] with only the components of `z` marked in `available` measured (e.g. tracked features
    /// occluded in this frame): the others get zero weight in the correction and their values in `z` are ignored
    /// (they may be NaN). With no component available the iteration only predicts, and its record has no
    /// innovation norm; otherwise the norm is over the available components. With a validation gate
    /// ([`RoukfConfig::gate`]), the available components beyond it count as not available.
    pub fn step_partial(&mut self, z: &DVector<f64>, available: &[bool]) -> Result<&IterationTrace, FilterError> {
        let start = Instant::now();
        let k = self.iteration + 1;
        let p = self.sigma.dim();
        let m = self.sigma.count();
        let q = z.len();
        let mut inv_std = self.measurement_weights(z, available, k)?;
        let (thetas, mut states) = self.sample(k)?;
        let (observations, state_vectors) = self.predict(&mut states, &thetas, k, q)?;
        let mut theta_matrix = DMatrix::zeros(p, m);
        for (i, t) in thetas.iter().enumerate() {
            theta_matrix.set_column(i, t);
        }
        let (theta_mean, l_theta) = self.mean_and_factor(&theta_matrix);
        let (z_mean, hl) = self.mean_and_factor(&observations);
        let gated = self.gate(z, &z_mean, &hl, &mut inv_std);
        let available: Vec<bool> = inv_std.iter().map(|&w| w > 0.0).collect();

        // Correction.
        let mut g = hl;
        for (mut row, w) in g.row_iter_mut().zip(inv_std.iter()) {
            row *= *w;
        }
        // U = P_α + HL^T W^{-1} HL with P_α = I_p for both sigma-point sets.
        let u = DMatrix::identity(p, p) + g.transpose() * &g;
        let innovation = DVector::from_iterator(
            q,
            z.iter().zip(&z_mean).zip(&available).map(|((v, mean), &a)| if a { v - mean } else { 0.0 }),
        );
        let weighted = innovation.component_mul(&inv_std);
        let nonfinite = |what: &str| FilterError::NonFinite { what: what.into(), iteration: k };
        if u.iter().any(|v| !v.is_finite()) {
            return Err(nonfinite("information matrix U"));
        }
        let chol = Cholesky::new(u.clone())
            .ok_or_else(|| FilterError::NotPositiveDefinite { what: "U".into(), iteration: k })?;
        let correction = chol.solve(&(g.transpose() * &weighted));
        let theta = &theta_mean + &l_theta * &correction;
        // Finite in the filter's space is not enough: an exponential transform may overflow.
        let physical: Vec<f64> = theta.iter().zip(&self.config.parameters).map(|(v, s)| s.to_physical(*v)).collect();
        if theta.iter().chain(&physical).any(|v| !v.is_finite()) {
            return Err(nonfinite("parameter estimate"));
        }
        self.model.admissible(&physical).map_err(|e| FilterError::Estimate { iteration: k, error: Box::new(e) })?;
        let joint_update = match &self.joint {
            Some(_) => {
                let (x_mean, l_x) = self.mean_and_factor(&state_vectors);
                let x = &x_mean + &l_x * &correction;
                if x.iter().any(|v| !v.is_finite()) {
                    return Err(nonfinite("state estimate"));
                }
                Some((x, l_x))
            }
            None => None,
        };
        let u_chol = chol.l();
        let covariance = covariance_from(&l_theta, &u_chol).ok_or_else(|| nonfinite("parameter covariance"))?;
        if covariance.iter().any(|v| !v.is_finite()) {
            return Err(nonfinite("parameter covariance"));
        }

        // The frame's misfit statistics: whitened post-correction residual and sensitivity J̃ = G L_θ^{-1} (a singular
        // L_θ, which the sampling never produces, would leave the frame out).
        let frame_misfit = self.misfit.as_ref().and_then(|_| {
            let jt = l_theta.transpose().lu().solve(&g.transpose())?;
            let inverse_factor = l_theta.clone().try_inverse()?;
            let residual = &weighted - &g * &correction;
            let frame = FrameMisfit {
                weight: 1.0,
                residual: residual.norm_squared(),
                score: &jt * residual,
                information: &jt * jt.transpose(),
                theta: theta.clone(),
                centre: theta_mean.clone(),
                inverse_factor,
                components: available.iter().filter(|&&a| a).count() as f64,
            };
            Some(frame)
        });

        // Commit.
        self.theta = theta;
        self.l_theta = l_theta;
        self.u = u;
        self.u_chol = u_chol;
        self.states = states;
        if let (Some(joint), Some((x, l_x))) = (&mut self.joint, joint_update) {
            joint.x = x;
            joint.l_x = l_x;
        }
        self.iteration = k;
        if let Some(misfit) = &mut self.misfit {
            misfit.add(self.config.forgetting, frame_misfit);
        }
        let measured = available.contains(&true).then(|| innovation.norm());
        let mut record = self.record(measured, Some(start.elapsed().as_secs_f64()));
        (record.gated, record.gated_components) = (gated.len(), gated);
        self.trace.records.push(record);
        Ok(self.trace.records.last().expect("a record was just pushed"))
    }

    /// The weight `1/σ_obs` of each component of measurement `z` at iteration `k`, 0 for those not
    /// `available`; checks the mask's length and the available components' finiteness.
    fn measurement_weights(&self, z: &DVector<f64>, available: &[bool], k: usize) -> Result<DVector<f64>, FilterError> {
        let q = z.len();
        if available.len() != q {
            return Err(FilterError::DimensionMismatch {
                what: "availability mask vs. measurement".into(),
                expected: q,
                found: available.len(),
            });
        }
        let mut inv_std = self.inverse_observation_std(q)?;
        if z.iter().zip(available).any(|(v, &a)| a && !v.is_finite()) {
            return Err(FilterError::NonFinite { what: "measurement z".into(), iteration: k });
        }
        for (w, &a) in inv_std.iter_mut().zip(available) {
            if !a {
                *w = 0.0;
            }
        }
        Ok(inv_std)
    }

    /// The validation gate ([`RoukfConfig::gate`]): sets the weight of each measured component of `z`
    /// farther from its prediction `z_mean` (sigma-point spread `hl`) than the gate allows to 0;
    /// returns their indices.
    fn gate(
        &self,
        z: &DVector<f64>,
        z_mean: &DVector<f64>,
        hl: &DMatrix<f64>,
        inv_std: &mut DVector<f64>,
    ) -> Vec<usize> {
        let Some(gate) = self.config.gate else { return Vec::new() };
        let mut gated = Vec::new();
        for (i, w) in inv_std.iter_mut().enumerate().filter(|(_, w)| **w > 0.0) {
            let predicted = (1.0 / (*w * *w) + hl.row(i).norm_squared()).sqrt();
            if (z[i] - z_mean[i]).abs() > gate * predicted {
                *w = 0.0;
                gated.push(i);
            }
        }
        gated
    }

    /// Sampling at iteration `k`: the sigma points' parameters (reduced space), and a copy of the
    /// model states with the joint state, if any, set to each sigma point's.
    fn sample(&self, k: usize) -> Result<Sampled<M::State>, FilterError> {
        let m = self.sigma.count();
        let offsets = self
            .sigma
            .offsets(&self.u_chol)
            .ok_or_else(|| FilterError::NotPositiveDefinite { what: "U".into(), iteration: k })?
            / self.config.forgetting.sqrt();
        let thetas: Vec<DVector<f64>> = (0..m).map(|i| &self.theta + &self.l_theta * offsets.column(i)).collect();
        let mut states = self.states.clone();
        if let Some(joint) = &self.joint {
            for (i, state) in states.iter_mut().enumerate() {
                let x = &joint.x + &joint.l_x * offsets.column(i);
                (joint.set)(&self.model, state, &x);
            }
        }
        Ok((thetas, states))
    }

    /// Prediction at iteration `k`: steps every sigma point's state with its physical parameters
    /// (from `thetas`) and observes it. Returns the observations (a column of length `q` per sigma
    /// point) and, with a joint state, the state vectors (a column per sigma point; else empty).
    fn predict(
        &self,
        states: &mut [M::State],
        thetas: &[DVector<f64>],
        k: usize,
        q: usize,
    ) -> Result<(DMatrix<f64>, DMatrix<f64>), FilterError> {
        let m = thetas.len();
        let mut physical: Vec<Vec<f64>> = Vec::with_capacity(m);
        for (i, t) in thetas.iter().enumerate() {
            let phys: Vec<f64> = t.iter().zip(&self.config.parameters).map(|(v, s)| s.to_physical(*v)).collect();
            if phys.iter().any(|v| !v.is_finite()) {
                return Err(FilterError::SigmaPoint {
                    sigma_point: i,
                    iteration: k,
                    what: format!("non-finite physical parameters {phys:?}"),
                });
            }
            // Spread by the estimate's σ about it, a sigma point may leave the domain the estimate is in.
            self.model.admissible(&phys).map_err(|e| FilterError::SigmaPoint {
                sigma_point: i,
                iteration: k,
                what: format!("its parameters lie outside the model's domain: {e}"),
            })?;
            physical.push(phys);
        }
        let model = &self.model;
        let get = self.joint.as_ref().map(|j| j.get);
        let run = |(i, state): (usize, &mut M::State)| -> Result<SigmaOutput, M::Error> {
            model.step(state, &physical[i], k)?;
            Ok((model.observe(state), get.map(|g| g(model, state))))
        };
        let results: Vec<Result<SigmaOutput, M::Error>> = match self.config.execution {
            Execution::Parallel => states.par_iter_mut().enumerate().map(run).collect(),
            Execution::Sequential => states.iter_mut().enumerate().map(run).collect(),
        };
        let mut observations = DMatrix::zeros(q, m);
        let n = self.joint.as_ref().map_or(0, |j| j.x.len());
        let mut state_vectors = DMatrix::zeros(n, m);
        for (i, result) in results.into_iter().enumerate() {
            let (zi, xi) =
                result.map_err(|e| FilterError::Model { sigma_point: i, iteration: k, error: Box::new(e) })?;
            let bad = |what: String| FilterError::SigmaPoint { sigma_point: i, iteration: k, what };
            if zi.len() != q {
                return Err(bad(format!("observation has length {}, the measurement has {q}", zi.len())));
            }
            if zi.iter().any(|v| !v.is_finite()) {
                return Err(bad("observation contains NaN or infinity".into()));
            }
            observations.set_column(i, &zi);
            if let Some(xi) = xi {
                if xi.len() != n {
                    return Err(bad(format!("state vector has length {}, expected {n}", xi.len())));
                }
                if xi.iter().any(|v| !v.is_finite()) {
                    return Err(bad("state vector contains NaN or infinity".into()));
                }
                state_vectors.set_column(i, &xi);
            }
        }
        Ok((observations, state_vectors))
    }

    /// `1/σ_obs` for an observation of length `q`.
    fn inverse_observation_std(&self, q: usize) -> Result<DVector<f64>, FilterError> {
        match &self.config.observation_std {
            ObservationNoise::Uniform(s) => Ok(DVector::from_element(q, 1.0 / s)),
            ObservationNoise::PerComponent(v) if v.len() == q => {
                Ok(DVector::from_iterator(q, v.iter().map(|s| 1.0 / s)))
            }
            ObservationNoise::PerComponent(v) => Err(FilterError::DimensionMismatch {
                what: "measurement vs. per-component observation std".into(),
                expected: v.len(),
                found: q,
            }),
        }
    }

    /// Weighted mean of the columns of `a` and the centred factor `Σ α_i (a_i - ā) I(i)^T`.
    fn mean_and_factor(&self, a: &DMatrix<f64>) -> (DVector<f64>, DMatrix<f64>) {
        let w = self.sigma.weights();
        let mut mean = DVector::zeros(a.nrows());
        for (col, wi) in a.column_iter().zip(w) {
            mean.axpy(*wi, &col, 1.0);
        }
        let mut centred = a.clone();
        for (i, mut col) in centred.column_iter_mut().enumerate() {
            col -= &mean;
            col *= w[i];
        }
        let factor = centred * self.sigma.points().transpose();
        (mean, factor)
    }

    /// Trace record of the current estimate.
    fn record(&self, innovation_norm: Option<f64>, wall_seconds: Option<f64>) -> IterationTrace {
        let covariance = self.covariance();
        IterationTrace {
            iteration: self.iteration,
            mean: self.theta.iter().copied().collect(),
            std: standard_deviations(&covariance),
            mean_physical: self.mean_physical(),
            std_physical: self.physical(&covariance),
            innovation_norm,
            wall_seconds,
            noise_std_physical: self.misfit.as_ref().map(|_| self.physical(&self.filter_covariance())),
            misfit: self.misfit(),
            gated: 0,
            gated_components: Vec::new(),
        }
    }

    /// Number of completed iterations (0 before the first [`Roukf::step`]).
    pub fn iteration(&self) -> usize {
        self.iteration
    }

    /// Current parameter mean θ̂ in filter space.
    pub fn mean(&self) -> &DVector<f64> {
        &self.theta
    }

    /// Current parameter estimate in physical space (`scale · transform(θ̂)`).
    pub fn mean_physical(&self) -> Vec<f64> {
        self.theta.iter().zip(&self.config.parameters).map(|(v, s)| s.to_physical(*v)).collect()
    }

    /// Reported parameter covariance in filter space (p × p): the filter's [`Roukf::filter_covariance`], plus the
    /// allowance for model error when [`Roukf::with_discrepancy`] asked for one.
    pub fn covariance(&self) -> DMatrix<f64> {
        let p = self.filter_covariance();
        match self.misfit.as_ref().and_then(|m| m.allowance(&self.theta)) {
            Some(allowance) => p + allowance,
            None => p,
        }
    }

    /// The filter's own parameter covariance `L_θ U^{-1} L_θ^T` in filter space (p × p): the observation noise only.
    pub fn filter_covariance(&self) -> DMatrix<f64> {
        covariance_from(&self.l_theta, &self.u_chol)
            .unwrap_or_else(|| DMatrix::from_element(self.sigma.dim(), self.sigma.dim(), f64::NAN))
    }

    /// With a discrepancy allowance ([`Roukf::with_discrepancy`]) and at least one frame: the reduced misfit
    /// `χ²(θ̂)/ν` at the current estimate of the frames whose sigma points came near it (the last 20,000 at most;
    /// about 1 when the model and the nominal noise are right; its square root times σ_obs is the effective
    /// observation noise).
    pub fn misfit(&self) -> Option<f64> {
        self.misfit.as_ref().and_then(|m| m.reduced_chi_squared(&self.theta))
    }

    /// Standard deviations in filter space (of [`Roukf::covariance`]).
    pub fn std(&self) -> Vec<f64> {
        standard_deviations(&self.covariance())
    }

    /// Standard deviations in physical space, first order: `|g'(θ̂)| σ` for g = `scale · transform`.
    pub fn std_physical(&self) -> Vec<f64> {
        self.physical(&self.covariance())
    }

    /// First-order physical standard deviations `|g'(θ̂)| √P_jj` of a filter-space covariance.
    fn physical(&self, covariance: &DMatrix<f64>) -> Vec<f64> {
        covariance
            .diagonal()
            .iter()
            .zip(self.theta.iter())
            .zip(&self.config.parameters)
            .map(|((c, v), spec)| spec.derivative(*v).abs() * c.max(0.0).sqrt())
            .collect()
    }

    /// Factor `L_θ` (p × p) of the parameter covariance.
    pub fn l_theta(&self) -> &DMatrix<f64> {
        &self.l_theta
    }

    /// Information factor `U` (p × p).
    pub fn u(&self) -> &DMatrix<f64> {
        &self.u
    }

    /// The sigma points in use.
    pub fn sigma_points(&self) -> &SigmaPoints {
        &self.sigma
    }

    /// Model states of the sigma points (in the order of [`Roukf::sigma_points`]) after the last prediction (before any joint-mode re-sampling).
    pub fn sigma_states(&self) -> &[M::State] {
        &self.states
    }

    /// Joint mode: the corrected mean state vector x̂ (None in parameter-only mode).
    pub fn mean_state(&self) -> Option<&DVector<f64>> {
        self.joint.as_ref().map(|j| &j.x)
    }

    /// Joint mode: the state factor `L_x` (n × p) (None in parameter-only mode).
    pub fn state_factor(&self) -> Option<&DMatrix<f64>> {
        self.joint.as_ref().map(|j| &j.l_x)
    }

    /// History of the estimates, starting with the prior.
    pub fn trace(&self) -> &Trace {
        &self.trace
    }

    /// The model.
    pub fn model(&self) -> &M {
        &self.model
    }

    /// The configuration.
    pub fn config(&self) -> &RoukfConfig {
        &self.config
    }
}

impl<M: VectorState> Roukf<M> {
    /// Joint state–parameter filter (the paper's algorithm in full): the mean state starts at
    /// `state_vector(initial_state)` with no uncertainty of its own (`L_x = 0`) and is corrected at every iteration.
    pub fn new_joint(model: M, initial_state: M::State, config: RoukfConfig) -> Result<Self, FilterError> {
        let x = model.state_vector(&initial_state);
        if x.iter().any(|v| !v.is_finite()) {
            return Err(FilterError::NonFinite { what: "initial state vector".into(), iteration: 0 });
        }
        let p = config.parameters.len();
        let joint = Joint {
            l_x: DMatrix::zeros(x.len(), p),
            x,
            get: <M as VectorState>::state_vector,
            set: <M as VectorState>::set_state_vector,
        };
        Self::build(model, initial_state, config, Some(joint))
    }
}

/// The prior information `P_0^{-1} = diag(1/σ0²)` of the parameters (filter space).
fn prior_information(parameters: &[ParameterSpec]) -> DMatrix<f64> {
    DMatrix::from_diagonal(&DVector::from_iterator(
        parameters.len(),
        parameters.iter().map(|s| 1.0 / (s.prior_std * s.prior_std)),
    ))
}

/// `L U^{-1} L^T` from the lower Cholesky factor C of U, as `Y^T Y` with `C Y = L^T`.
fn covariance_from(l: &DMatrix<f64>, c_lower: &DMatrix<f64>) -> Option<DMatrix<f64>> {
    let y = c_lower.solve_lower_triangular(&l.transpose())?;
    Some(y.transpose() * y)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A frame of whitened residual energy 10 over 4 components, no sensitivity, sampled about `centre`
    /// with a unit factor.
    fn frame(centre: f64) -> Option<FrameMisfit> {
        Some(FrameMisfit {
            weight: 1.0,
            residual: 10.0,
            score: DVector::zeros(1),
            information: DMatrix::zeros(1, 1),
            theta: DVector::zeros(1),
            centre: DVector::from_element(1, centre),
            inverse_factor: DMatrix::identity(1, 1),
            components: 4.0,
        })
    }

    /// The allowance's excess is `χ² − ν − 2√(2ν)` with `ν = Σq − p`, as the module documentation states, over
    /// the frames whose sampled region holds the estimate.
    #[test]
    fn the_excess_is_beyond_two_standard_deviations_of_chi_squared() {
        let mut misfit = Misfit::new(Some(1.0), DMatrix::identity(1, 1), 1.0);
        for _ in 0..10 {
            misfit.add(1.0, frame(0.5));
        }
        // Sampled about 5 with a unit factor: θ = 0 lies beyond their reach, so these do not count.
        for _ in 0..5 {
            misfit.add(1.0, frame(5.0));
        }
        let theta = DVector::zeros(1);
        let HeldSums { chi_squared, components, .. } = misfit.sums(&theta);
        assert!((chi_squared - 100.0).abs() < 1e-9 && components == 40.0, "χ² = {chi_squared}, Σq = {components}");
        let allowance = misfit.allowance(&theta).unwrap()[(0, 0)];
        let expected = 100.0 - 39.0 - 2.0 * (2.0 * 39.0f64).sqrt();
        assert!((allowance - expected).abs() < 1e-9, "allowance {allowance}, expected {expected}");
        assert_eq!(misfit.reduced_chi_squared(&DVector::from_element(1, 20.0)), None, "no frame holds θ = 20");
        // Forgetting (ρ = 0.9): χ² and ν discounted by ρ per frame, the variance's sum by ρ².
        let mut forgetting = Misfit::new(Some(1.0), DMatrix::identity(1, 1), 1.0);
        let (mut chi_squared, mut components, mut squared) = (0.0, 0.0, 0.0);
        for _ in 0..10 {
            forgetting.add(0.9, frame(0.0));
            chi_squared = 0.9 * chi_squared + 10.0;
            components = 0.9 * components + 4.0;
            squared = 0.81 * squared + 4.0;
        }
        let expected = chi_squared - (components - 1.0) - 2.0 * (2.0 * (squared - 1.0f64)).sqrt();
        let allowance = forgetting.allowance(&theta).unwrap()[(0, 0)];
        assert!((allowance - expected).abs() < 1e-9, "allowance {allowance}, expected {expected}");
    }
}
