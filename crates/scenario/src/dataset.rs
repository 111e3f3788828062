//! Dataset scenarios (`kind = "dataset"`, `augsim generate`, `augsim experiment`): the FEM model
//! and how the samples are drawn.

use std::path::{Path, PathBuf};

use fem::{Material, SolverOptions};
use learn::data::generate::{DatasetConfig, Generator};
use mesh::Mesh;
use serde::Deserialize;

use crate::{build_mesh, Kind, MeshSource, Result, ScenarioError, ScenarioText};

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
    /// Parses scenario text.
    pub fn from_text(source: &ScenarioText) -> Result<Self> {
        source.parse_as(Kind::Dataset)
    }

    /// Reads a scenario file (or a built-in scenario); returns it with its directory (mesh paths
    /// are relative to it).
    pub fn load(path: &Path) -> Result<(Self, PathBuf)> {
        crate::load_with(path, Self::from_text)
    }

    /// The built-in dataset scenario `name` (e.g. `liver_ar`); panics when there is none.
    pub fn builtin(name: &str) -> DatasetScenario {
        crate::builtin_with(name, Self::from_text)
    }

    /// Builds the mesh the samples are solved on (paths relative to `dir`): quadratic
    /// tetrahedra made from the given mesh when the material's order is 2.
    pub fn mesh(&self, dir: &Path) -> Result<Mesh> {
        let mesh = build_mesh(&self.mesh, dir)
            .map_err(|e| ScenarioError::build(&self.name, format!("building the mesh: {e}")))?;
        match self.material.order {
            2 => mesh.quadratic().map_err(|e| ScenarioError::build(&self.name, format!("quadratic elements: {e}"))),
            _ => Ok(mesh),
        }
    }

    /// Builds the mesh (paths relative to `dir`) and the sample generator.
    pub fn generator(&self, dir: &Path) -> Result<Generator> {
        Generator::new(self.mesh(dir)?, self.material, self.solver.clone(), self.dataset.clone())
            .map_err(|e| ScenarioError::build(&self.name, e))
    }
}
