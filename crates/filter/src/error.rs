//! Errors of the filter.

use std::path::PathBuf;

use fem::FemError;

/// Boxed error of a model, as carried by [`FilterError::Model`].
pub type BoxedModelError = Box<dyn std::error::Error + Send + Sync + 'static>;

/// Everything that can go wrong while configuring or running the filter, or writing its traces.
#[derive(Debug, thiserror::Error)]
pub enum FilterError {
    /// The configuration is unusable (empty parameter list, non-positive standard deviation, ...).
    #[error("invalid filter configuration: {0}")]
    InvalidConfig(String),
    /// A vector or matrix has the wrong length.
    #[error("dimension mismatch in {what}: expected {expected}, found {found}")]
    DimensionMismatch {
        /// Which quantity.
        what: String,
        /// Expected length.
        expected: usize,
        /// Actual length.
        found: usize,
    },
    /// `Model::step` failed for one sigma point (e.g. Newton did not converge).
    #[error("model step failed for sigma point {sigma_point} at iteration {iteration}: {error}")]
    Model {
        /// Index of the sigma point (0-based, `0..=p`).
        sigma_point: usize,
        /// Filter iteration (1-based) that was being computed.
        iteration: usize,
        /// The model's own error.
        error: BoxedModelError,
    },
    /// The step's estimate lies outside the model's parameter domain ([`crate::Model::admissible`]):
    /// refused, the filter left as it was.
    #[error("the estimate of iteration {iteration} is refused: {error}")]
    Estimate {
        /// Filter iteration (1-based) that was being computed.
        iteration: usize,
        /// The model's reason.
        error: BoxedModelError,
    },
    /// The observation or state vector of one sigma point contains NaN or infinity, or changed length.
    #[error("sigma point {sigma_point} at iteration {iteration}: {what}")]
    SigmaPoint {
        /// Index of the sigma point (0-based).
        sigma_point: usize,
        /// Filter iteration (1-based).
        iteration: usize,
        /// What is wrong.
        what: String,
    },
    /// A NaN or infinity appeared in a filter quantity (observation, innovation, gain, covariance, estimate).
    #[error("non-finite {what} at iteration {iteration}")]
    NonFinite {
        /// Which quantity.
        what: String,
        /// Filter iteration (0 = initialisation).
        iteration: usize,
    },
    /// A matrix that must be symmetric positive definite (the information matrix U) is not.
    #[error("{what} is not positive definite at iteration {iteration}")]
    NotPositiveDefinite {
        /// Which matrix.
        what: String,
        /// Filter iteration (0 = initialisation).
        iteration: usize,
    },
    /// Reading or writing a file failed.
    #[error("I/O error on {path}: {error}")]
    Io {
        /// The file concerned.
        path: PathBuf,
        /// The underlying error.
        error: std::io::Error,
    },
    /// Serialising a trace to JSON failed.
    #[error("JSON serialisation for {path}: {error}")]
    Json {
        /// The file concerned.
        path: PathBuf,
        /// The underlying error.
        error: serde_json::Error,
    },
}

impl From<mesh::io::WriteError> for FilterError {
    fn from(e: mesh::io::WriteError) -> Self {
        FilterError::Io { path: e.path, error: e.error }
    }
}

/// Errors of the finite-element model adapter ([`crate::FemModel`]) and its tracked points.
#[derive(Debug, thiserror::Error)]
pub enum FemModelError {
    /// The solve failed (no convergence, inverted element, invalid parameter value, ...).
    #[error(transparent)]
    Fem(#[from] FemError),
    /// Inconsistent model definition or use.
    #[error("invalid FEM model: {0}")]
    Invalid(String),
}
