//! Errors of scenario files.

use std::path::{Path, PathBuf};

/// What is wrong with a scenario, naming the file.
#[derive(Debug, thiserror::Error)]
pub enum ScenarioError {
    /// The file cannot be read.
    #[error("cannot read scenario {}: {error}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// Why.
        error: std::io::Error,
    },
    /// A bare name that is neither a readable file nor a built-in scenario's name.
    #[error(
        "cannot read scenario {}: {error}; nor is it a built-in scenario's name ({})",
        path.display(),
        crate::BUILTIN.map(|(name, _)| name).join(", ")
    )]
    Unknown {
        /// The name given.
        path: PathBuf,
        /// Why it could not be read as a file.
        error: std::io::Error,
    },
    /// A file name (`liver.toml`) that is not there, though a built-in scenario has its stem's
    /// name: a file is never replaced by a built-in.
    #[error("cannot read scenario {}: {error} (the built-in scenario of that name is `{name}`, without .toml)", path.display())]
    MissingFile {
        /// The file given.
        path: PathBuf,
        /// Why it could not be read.
        error: std::io::Error,
        /// The built-in scenario's name.
        name: String,
    },
    /// The text is not a valid scenario of its kind, or its values are unusable.
    #[error("invalid scenario {origin}: {message}")]
    Invalid {
        /// The file (or built-in) at fault.
        origin: String,
        /// What is wrong: the line and key where known.
        message: String,
    },
    /// The scenario is valid but what it describes cannot be built (e.g. a mesh file that cannot
    /// be read, a selection that picks no node).
    #[error("scenario {name}: {message}")]
    Build {
        /// The scenario's name.
        name: String,
        /// What failed.
        message: String,
    },
}

impl ScenarioError {
    /// An invalid scenario from `origin`.
    pub fn invalid(origin: &Path, message: impl Into<String>) -> Self {
        ScenarioError::Invalid { origin: origin.display().to_string(), message: message.into() }
    }

    /// A failure to build what the scenario `name` describes.
    pub fn build(name: &str, message: impl std::fmt::Display) -> Self {
        ScenarioError::Build { name: name.to_string(), message: message.to_string() }
    }
}

/// Result type of this crate.
pub type Result<T> = std::result::Result<T, ScenarioError>;
