//! Reduced-order unscented Kalman filter (ROUKF, Moireau & Chapelle 2011) for identifying the uncertain parameters
//! of a large simulation (e.g. liver stiffness or boundary springs of a FEM model) from sparse observations.
//!
//! * [`Model`]: what the filter drives (one state per sigma point, `step` with physical parameters, `observe`);
//!   [`VectorState`] adds vector access for joint state–parameter filtering.
//! * [`Roukf`]: the filter ([`Roukf::new`] parameter-only, [`Roukf::new_joint`] joint), configured by
//!   [`RoukfConfig`] with one [`ParameterSpec`] (prior, [`Transform`]) per parameter; optionally an allowance for
//!   model error in the reported σ ([`Discrepancy`], [`Roukf::with_discrepancy`]).
//! * [`SigmaPoints`]: the p + 1 simplex or 2p + 1 star sigma points ([`SigmaPointSet`]).
//! * [`Trace`]: per-iteration μ, σ (filter and physical space) and innovation norm, written as CSV or JSON.
//! * [`fem_model::FemModel`]: a static finite-element problem as a [`Model`] (Young's modulus and boundary springs
//!   as parameters, time-profiled loads, one solver per sigma point); [`observation`]: points tracked through
//!   barycentric weights and synthetic noisy measurements.
//!
//! A spring of unknown stiffness k, pulled by a known force that changes at each step and observed
//! through its noisy extension; the filter works on log k (positivity) from a prior half the truth:
//!
//! ```
//! use augsim_filter::{Execution, Model, ObservationNoise, ParameterSpec, Roukf, RoukfConfig, SigmaPointSet, Transform};
//! use nalgebra::DVector;
//!
//! /// Extension u = F_k / k of a spring under the force of step k.
//! struct Spring;
//! impl Model for Spring {
//!     type State = f64;
//!     type Error = std::convert::Infallible;
//!     fn step(&self, u: &mut f64, theta: &[f64], step: usize) -> Result<(), Self::Error> {
//!         *u = force(step) / theta[0];
//!         Ok(())
//!     }
//!     fn observe(&self, u: &f64) -> DVector<f64> {
//!         DVector::from_element(1, *u)
//!     }
//! }
//! fn force(step: usize) -> f64 {
//!     1.0 + 0.5 * (step as f64).sin()
//! }
//!
//! let (k_true, noise) = (200.0, 1e-4);
//! let config = RoukfConfig {
//!     parameters: vec![ParameterSpec::new("k", Transform::Exp, 100.0f64.ln(), 1.0)],
//!     observation_std: ObservationNoise::Uniform(noise),
//!     execution: Execution::Parallel,
//!     forgetting: 1.0,
//!     sigma_points: SigmaPointSet::Simplex,
//!     gate: None,
//! };
//! let mut filter = Roukf::new(Spring, 0.0, config)?;
//! for step in 1..=60 {
//!     let wobble = noise * ((7 * step) as f64).cos(); // a deterministic stand-in for measurement noise
//!     filter.step(&DVector::from_element(1, force(step) / k_true + wobble))?;
//! }
//! let k = filter.mean_physical()[0];
//! assert!((k - k_true).abs() < 0.05 * k_true, "estimated k = {k}");
//! # Ok::<(), augsim_filter::FilterError>(())
//! ```

mod error;
pub mod fem_model;
mod model;
pub mod observation;
mod roukf;
mod sigma;
mod trace;
mod transform;

pub use error::{BoxedModelError, FemModelError, FilterError};
pub use fem_model::{ControlPath, FemModel, FemParameter, FemState, LoadPattern, Profile};
pub use model::{Model, VectorState};
pub use observation::TrackedPoint;
pub use roukf::{Discrepancy, Execution, ObservationNoise, ParameterSpec, Roukf, RoukfConfig};
pub use sigma::{SigmaPointSet, SigmaPoints};
pub use trace::{IterationTrace, Trace};
pub use transform::Transform;
