//! Error type of the learning crate.

use std::path::PathBuf;

/// Everything that can go wrong in `augsim-learn`; each variant names the file involved, if any.
#[derive(Debug, thiserror::Error)]
pub enum LearnError {
    /// An operating-system I/O error on a file.
    #[error("{path}: {error}")]
    Io {
        /// The file or directory.
        path: PathBuf,
        /// The underlying error.
        error: std::io::Error,
    },
    /// A malformed manifest, or one that disagrees with the files on disk.
    #[error("{path}: {message}")]
    Manifest {
        /// The manifest (or the shard file it disagrees with).
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// An input file (a point cloud) that cannot be used.
    #[error("{}{}: {message}", path.display(), line.map(|l| format!(":{l}")).unwrap_or_default())]
    Input {
        /// The file.
        path: PathBuf,
        /// The line (1-based), where known.
        line: Option<usize>,
        /// What is wrong.
        message: String,
    },
    /// A model bundle, checkpoint or weights file that cannot be used.
    #[error("{path}: {message}")]
    Model {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// An argument that does not fit (wrong length, empty set, bad configuration value).
    #[error("invalid input: {0}")]
    InvalidInput(String),
    /// A mesh that cannot be used (refined, embedded, sampled), or a file of the formats `mesh::io`
    /// reads that cannot be read or written (a malformed or truncated `.npy` file).
    #[error(transparent)]
    Mesh(#[from] mesh::MeshError),
    /// A finite-element problem that cannot be set up.
    #[error(transparent)]
    Fem(#[from] fem::FemError),
}

impl From<mesh::io::WriteError> for LearnError {
    fn from(e: mesh::io::WriteError) -> Self {
        LearnError::Io { path: e.path, error: e.error }
    }
}

impl LearnError {
    /// Wraps an I/O error with the path it concerns.
    pub(crate) fn io(path: impl Into<PathBuf>, error: std::io::Error) -> Self {
        LearnError::Io { path: path.into(), error }
    }

    /// A manifest error for `path`.
    pub(crate) fn manifest(path: impl Into<PathBuf>, message: impl Into<String>) -> Self {
        LearnError::Manifest { path: path.into(), message: message.into() }
    }

    /// A model/checkpoint error for `path`.
    pub(crate) fn model(path: impl Into<PathBuf>, message: impl Into<String>) -> Self {
        LearnError::Model { path: path.into(), message: message.into() }
    }
}
