//! Dataset scenario files (`augsim generate`, `augsim experiment`): the FEM model and how
//! the samples are drawn, in TOML.

use std::path::{Path, PathBuf};

use fem::scenario::{build_mesh, MeshSource};
use fem::{Material, SolverOptions};
use mesh::Mesh;
use serde::Deserialize;

use crate::generate::{DatasetConfig, Generator};
use crate::{LearnError, Result};

/// A dataset scenario: the organ or beam, its material and solver, and the sampling.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DatasetScenario {
    /// Short name (the default output directory is `out/<name>`).
    pub name: String,
    /// Free text.
    #[serde(default)]
    pub description: String,
    /// The organ or beam.
    pub mesh: MeshSource,
    /// The material.
    pub material: Material,
    /// Newton-Raphson settings.
    #[serde(default)]
    pub solver: SolverOptions,
    /// Sampling of loads and encoding on the grid.
    pub dataset: DatasetConfig,
}

impl DatasetScenario {
    /// Parses scenario text; `origin` names it in errors.
    pub fn parse(text: &str, origin: &Path) -> Result<Self> {
        toml::from_str(text).map_err(|e| LearnError::Manifest { path: origin.to_path_buf(), message: e.to_string() })
    }

    /// Reads a scenario file; returns it with its directory (mesh paths are relative to it).
    pub fn load(path: &Path) -> Result<(Self, PathBuf)> {
        let text = std::fs::read_to_string(path).map_err(|source| LearnError::Io { path: path.into(), source })?;
        let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
        Ok((Self::parse(&text, path)?, dir))
    }

    /// Builds the mesh (paths relative to `dir`).
    pub fn mesh(&self, dir: &Path) -> Result<Mesh> {
        build_mesh(&self.mesh, dir)
            .map_err(|e| LearnError::InvalidInput(format!("scenario {}: building the mesh: {e}", self.name)))
    }

    /// Builds the mesh (paths relative to `dir`) and the sample generator.
    pub fn generator(&self, dir: &Path) -> Result<Generator> {
        Generator::new(self.mesh(dir)?, self.material, self.solver.clone(), self.dataset.clone())
    }
}
