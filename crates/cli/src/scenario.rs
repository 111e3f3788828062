//! Scenario files (TOML): mesh source, material, boundary conditions, loads,
//! solver settings and outputs. Unknown keys are errors that name the key.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
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
    /// Total forces shared equally by selected nodes.
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

/// The mesh of a scenario.
#[derive(Debug, Deserialize)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub enum MeshSource {
    /// A structured box.
    Box {
        /// Lower corner (m).
        min: Point,
        /// Upper corner (m).
        max: Point,
        /// Cells along x, y, z.
        cells: [usize; 3],
        /// "hex" (H8) or "tet" (6 T4 per cell).
        element: ElementKind,
    },
    /// The built-in liver phantom meshed with about `tets` tetrahedra.
    Phantom {
        /// Target number of tetrahedra.
        tets: usize,
    },
    /// The built-in liver phantom as an immersed-boundary H8 grid.
    PhantomGrid {
        /// Cell size (m).
        spacing: f64,
    },
    /// A closed surface (.obj, .stl, .vtk) meshed with tetrahedra; the path is
    /// relative to the scenario file.
    Surface {
        /// Path of the surface.
        path: PathBuf,
        /// Scale so that the largest extent is this length (m), centred at the origin.
        length: f64,
        /// Target number of tetrahedra.
        tets: usize,
    },
    /// A volume mesh file (.msh, .vtk, .vtu); the path is relative to the scenario file.
    File {
        /// Path of the file.
        path: PathBuf,
        /// Multiply coordinates by this factor (e.g. 0.001 for mm).
        #[serde(default = "one")]
        scale: f64,
        /// Move the bounding-box centre to the origin before scaling.
        #[serde(default)]
        centre: bool,
    },
}

fn one() -> f64 {
    1.0
}

/// Element kind of a generated box.
#[derive(Debug, Clone, Copy, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum ElementKind {
    /// Trilinear hexahedra.
    Hex,
    /// Linear tetrahedra.
    Tet,
}

/// Fixed nodes.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Fixed {
    /// Which nodes.
    pub select: NodeSelection,
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
        self.material.validate().map_err(anyhow::Error::msg).context("material")?;
        let mut p = Problem::new(mesh, self.material);
        let pick =
            |s: &NodeSelection, what: &str, p: &Problem| s.select(&p.mesh).with_context(|| format!("{what} selection"));
        for f in &self.fixed {
            let nodes = pick(&f.select, "fixed", &p)?;
            p.fix(&nodes);
        }
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

/// Builds a mesh from its source (file paths relative to `dir`).
pub fn build_mesh(source: &MeshSource, dir: &Path) -> Result<Mesh> {
    Ok(match source {
        MeshSource::Box { min, max, cells, element: ElementKind::Hex } => mesh::box_hex(*min, *max, *cells)?,
        MeshSource::Box { min, max, cells, element: ElementKind::Tet } => mesh::box_tet(*min, *max, *cells)?,
        MeshSource::Phantom { tets } => mesh::phantom::liver_phantom(*tets)?,
        MeshSource::PhantomGrid { spacing } => mesh::phantom::PhantomSpec::default().immersed(*spacing)?.mesh,
        MeshSource::Surface { path, length, tets } => {
            let mut surface = mesh::io::read_surface(dir.join(path))?;
            surface.fit_to(*length)?;
            mesh::tetmesh::mesh_surface_to_count(&surface, *tets, mesh::tetmesh::BoundaryFit::default())?.0
        }
        MeshSource::File { path, scale, centre } => {
            let mut m = mesh::io::read_mesh(dir.join(path))?;
            let (lo, hi) = m.bounds();
            let c = if *centre { std::array::from_fn(|d| 0.5 * (lo[d] + hi[d])) } else { [0.0; 3] };
            m.transform(c, *scale);
            m
        }
    })
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
