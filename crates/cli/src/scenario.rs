//! Scenario files (TOML): mesh source, material, boundary conditions, loads,
//! solver settings and outputs. Unknown keys are errors that name the key.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use fem::scenario::fixed_problem;
pub use fem::scenario::{build_mesh, Fixed, MeshSource};
use fem::{Material, Problem, SolverOptions};
use mesh::{Mesh, NodeSelection, Point};
use serde::Deserialize;

/// A static solve scenario.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scenario {
    /// Short name, used for output file names.
    pub name: String,
    /// Free text shown by `solve`.
    #[serde(default)]
    pub description: String,
    /// Where the mesh comes from.
    pub mesh: MeshSource,
    /// The material.
    pub material: Material,
    /// Nodes with zero displacement.
    #[serde(default)]
    pub fixed: Vec<Fixed>,
    /// Nodes with a prescribed displacement.
    #[serde(default)]
    pub prescribed: Vec<Prescribed>,
    /// Zero-length springs to the rest position.
    #[serde(default)]
    pub springs: Vec<Springs>,
    /// Total forces spread over selected nodes as a uniform traction ([`fem::force_shares`]).
    #[serde(default)]
    pub force: Vec<Force>,
    /// Surface tractions on boundary faces whose nodes are all selected.
    #[serde(default)]
    pub traction: Vec<Traction>,
    /// Gravity acceleration (m/s²).
    pub gravity: Option<Point>,
    /// Newton-Raphson settings.
    #[serde(default)]
    pub solver: SolverOptions,
    /// Outputs.
    #[serde(default)]
    pub output: Output,
}

/// Prescribed displacement.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Prescribed {
    /// Which nodes.
    pub select: NodeSelection,
    /// Displacement (m).
    pub displacement: Point,
}

/// Springs.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Springs {
    /// Which nodes.
    pub select: NodeSelection,
    /// Stiffness per node (N/m).
    pub stiffness: f64,
}

/// A total force.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Force {
    /// Which nodes share it.
    pub select: NodeSelection,
    /// Total force (N).
    pub total: Point,
}

/// A traction.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Traction {
    /// Nodes of the loaded faces.
    pub select: NodeSelection,
    /// Force per reference area (Pa).
    pub traction: Point,
}

/// Output settings.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Output {
    /// Result file (.vtu or .vtk); default `out/<name>.vtu`.
    pub path: Option<PathBuf>,
}

impl Scenario {
    /// Reads and parses a scenario file.
    pub fn load(path: &Path) -> Result<(Self, PathBuf)> {
        let text = std::fs::read_to_string(path).with_context(|| format!("cannot read scenario {}", path.display()))?;
        let scenario: Scenario =
            toml::from_str(&text).with_context(|| format!("invalid scenario {}", path.display()))?;
        let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
        Ok((scenario, dir))
    }

    /// Builds the boundary-value problem on `mesh`.
    pub fn build_problem(&self, mesh: Mesh) -> Result<Problem> {
        let mut p = fixed_problem(mesh, self.material, &self.fixed)?;
        let pick =
            |s: &NodeSelection, what: &str, p: &Problem| s.select(&p.mesh).with_context(|| format!("{what} selection"));
        for f in &self.prescribed {
            let nodes = pick(&f.select, "prescribed", &p)?;
            p.prescribe(&nodes, f.displacement);
        }
        for s in &self.springs {
            let nodes = pick(&s.select, "springs", &p)?;
            p.add_springs(&nodes, s.stiffness);
        }
        for f in &self.force {
            let nodes = pick(&f.select, "force", &p)?;
            p.add_force(&nodes, f.total);
        }
        for t in &self.traction {
            let nodes = pick(&t.select, "traction", &p)?;
            if p.add_traction(&nodes, t.traction) == 0.0 {
                bail!("traction selection {:?} covers no boundary face", t.select);
            }
        }
        if let Some(g) = self.gravity {
            p.add_gravity(g)?;
        }
        Ok(p)
    }

    /// The output path.
    pub fn output_path(&self) -> PathBuf {
        self.output.path.clone().unwrap_or_else(|| PathBuf::from(format!("out/{}.vtu", self.name)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unknown_keys_are_named() {
        let text = "name = \"x\"\n[mesh.box]\nmin = [0.0, 0.0, 0.0]\nmax = [1.0, 1.0, 1.0]\ncells = [1, 1, 1]\nelement = \"hex\"\n[material]\nlaw = \"svk\"\nyoung = 1.0\npoisson = 0.3\nstiffnes = 3\n";
        let err = toml::from_str::<Scenario>(text).unwrap_err().to_string();
        assert!(err.contains("stiffnes"), "{err}");
    }
}
