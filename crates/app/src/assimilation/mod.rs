//! Assimilation experiments: identify Young's modulus and/or boundary spring stiffnesses of a static FEM model with
//! the ROUKF from tracked surface features, as a scenario file describes them.
//!
//! The scenario file ([`scenario::AssimilationScenario`]) describes the model, the time-profiled forces and tool,
//! the unknowns with their priors, the observations, assessment points, filter and output settings.
//! * [`Experiment::prepare`]: builds the model and the measurements, either synthetic (a reference run with the
//!   true parameters, on the scenario's `[reference]` mesh and law where it has one and else on the filter's own
//!   model, observed at feature points drawn on the visible surface, plus Gaussian noise) or read from
//!   track files ([`ObservationFiles`], formats in [`tracks`]): observed features, tool features whose
//!   displacement is prescribed on the nearest free surface node, and assessment points.
//! * [`Experiment::run`]: the filter (one FEM solve per sigma point and step, in parallel), then the outputs in a
//!   directory: `trace.csv`, `trace.json`, `summary.json`, PNG plots, the estimated deformation as
//!   `deformation.pvd` + `deformation/step_*.vtu`, `assessment.csv` with assessment points, and for synthetic
//!   data the observed tracks in `tracks/` (readable back with [`ObservationFiles`]).
//!
//! The estimated deformation at time step k is the weighted mean of the sigma points' states predicted for step k
//! (before the correction with the measurement of step k); its error at the assessment points is compared, on
//! request, with runs where the spring region is fully fixed and fully free. `summary.json` also says where the
//! filter's time went ([`FilterTimes`]: the FEM solves' assembly, factorisations and triangular solves, and the
//! writing of the deformation).

mod choice;
mod lines;
mod online;
mod report;
mod run;
pub mod tracks;

use std::path::Path;

pub use choice::{AssimilationChoice, PreparedAssimilation};
pub use online::{Estimate, OnlineFilter};
pub use report::{AssessmentCase, FilterTimes, Reference, Report, SpringsReport, YoungReport};
pub use run::{Experiment, ObservationFiles, Setup};

/// Errors of an assimilation experiment.
#[derive(Debug, thiserror::Error)]
pub enum AssimilationError {
    /// A file that cannot be read, understood or written.
    #[error("{location}: {message}")]
    File {
        /// The file, with `:line` where known.
        location: String,
        /// What is wrong.
        message: String,
    },
    /// An unusable scenario or combination of inputs.
    #[error("{0}")]
    Setup(String),
    /// A step of the experiment failed.
    #[error("{what}")]
    Failed {
        /// What was being done.
        what: String,
        /// Why it failed.
        #[source]
        source: filter::BoxedModelError,
    },
}

impl From<mesh::io::WriteError> for AssimilationError {
    fn from(e: mesh::io::WriteError) -> Self {
        AssimilationError::file(&e.path, None, format!("cannot write: {}", e.error))
    }
}

impl AssimilationError {
    /// An error in `path` (at `line`, 1-based, when given).
    pub fn file(path: &Path, line: Option<usize>, message: String) -> Self {
        let location = match line {
            Some(l) => format!("{}:{l}", path.display()),
            None => path.display().to_string(),
        };
        AssimilationError::File { location, message }
    }
}

/// Wraps the error of a failed step with what was being done.
trait Context<T> {
    fn context(self, what: impl FnOnce() -> String) -> Result<T, AssimilationError>;
}

impl<T, E: std::error::Error + Send + Sync + 'static> Context<T> for Result<T, E> {
    fn context(self, what: impl FnOnce() -> String) -> Result<T, AssimilationError> {
        self.map_err(|e| AssimilationError::Failed { what: what(), source: Box::new(e) })
    }
}
