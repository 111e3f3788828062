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

mod error;
pub mod fem_model;
mod model;
pub mod observation;
mod roukf;
mod sigma;
mod trace;
mod transform;

pub use error::{BoxedModelError, FilterError};
pub use fem_model::{ControlPath, FemModel, FemModelError, FemParameter, FemState, LoadPattern, Profile};
pub use model::{Model, VectorState};
pub use observation::TrackedPoint;
pub use roukf::{Discrepancy, Execution, ObservationNoise, ParameterSpec, Roukf, RoukfConfig};
pub use sigma::{SigmaPointSet, SigmaPoints};
pub use trace::{IterationTrace, Trace};
pub use transform::Transform;
