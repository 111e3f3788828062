//! Error type of the registration crate.

use std::path::PathBuf;

/// Everything that can go wrong in `augsim-register`; each variant names the file involved, if any.
#[derive(Debug, thiserror::Error)]
pub enum RegisterError {
    /// An operating-system I/O error on a file.
    #[error("{path}: {error}")]
    Io {
        /// The file or directory.
        path: PathBuf,
        /// The underlying error.
        error: std::io::Error,
    },
    /// A file whose content cannot be used (malformed, empty, wrong shape).
    #[error("{path}: {message}")]
    Format {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// An argument or data that do not fit (count mismatch, points outside the model…).
    #[error("{0}")]
    Invalid(String),
    /// A finite-element failure.
    #[error(transparent)]
    Fem(#[from] fem::FemError),
    /// A mesh failure.
    #[error(transparent)]
    Mesh(#[from] mesh::MeshError),
    /// A network failure.
    #[error(transparent)]
    Learn(#[from] learn::LearnError),
}

impl From<mesh::io::WriteError> for RegisterError {
    fn from(e: mesh::io::WriteError) -> Self {
        RegisterError::Io { path: e.path, error: e.error }
    }
}

impl RegisterError {
    /// An I/O error on `path`.
    pub fn io(path: impl Into<PathBuf>, error: std::io::Error) -> Self {
        RegisterError::Io { path: path.into(), error }
    }

    /// A format error in `path`.
    pub fn format(path: impl Into<PathBuf>, message: impl Into<String>) -> Self {
        RegisterError::Format { path: path.into(), message: message.into() }
    }
}

/// Result with [`RegisterError`].
pub type Result<T> = std::result::Result<T, RegisterError>;
