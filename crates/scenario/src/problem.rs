//! Static scenarios (`kind = "static"`, `augsim solve`): mesh source, material, boundary
//! conditions, loads, solver settings and outputs.

use std::path::{Path, PathBuf};

use fem::{Attachment, Material, Problem, SolverOptions};
use mesh::{Ball, Mesh, NodeSelection, Point, SpaceBall};
use serde::Deserialize;

use crate::{build_mesh, fixed_problem, Fixed, Kind, MeshSource, Result, ScenarioError, ScenarioText};

/// A static boundary-value problem.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StaticScenario {
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
    /// Elastic foundations over the part of the organ inside a ball.
    #[serde(default)]
    pub attachment: Vec<Attachment>,
    /// Total forces spread as a uniform traction over the boundary inside a ball.
    #[serde(default)]
    pub patch_force: Vec<PatchForce>,
    /// Gravity acceleration (m/s²).
    pub gravity: Option<Point>,
    /// Static solver settings.
    #[serde(default)]
    pub solver: SolverOptions,
    /// Outputs.
    #[serde(default)]
    pub output: Output,
}

/// Prescribed displacement.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Prescribed {
    /// Which nodes.
    pub select: NodeSelection,
    /// Displacement (m).
    pub displacement: Point,
}

/// Springs.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Springs {
    /// Which nodes.
    pub select: NodeSelection,
    /// Stiffness per node (N/m).
    pub stiffness: f64,
}

/// A total force.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Force {
    /// Which nodes share it.
    pub select: NodeSelection,
    /// Total force (N).
    pub total: Point,
}

/// A traction.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Traction {
    /// Nodes of the loaded faces.
    pub select: NodeSelection,
    /// Force per reference area (Pa).
    pub traction: Point,
}

/// A total force spread as a uniform traction over the boundary inside a ball
/// ([`Problem::add_patch_force`]); the same on every mesh.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PatchForce {
    /// Where.
    #[serde(flatten)]
    pub region: SpaceBall,
    /// Only the faces whose outward normal points against this direction (those a camera looking
    /// along it sees); default: all, or for the phantom's `push` its visible side and for
    /// `hidden` the side away from the camera.
    #[serde(default)]
    pub facing: Option<Point>,
    /// Total force (N).
    pub total: Point,
}

impl PatchForce {
    /// The ball and the side of the boundary it loads: `facing`, else for the phantom's `push`
    /// the side its camera sees and for `hidden` the side away from it, else every side.
    /// An error when the total is not finite, or the ball is not given exactly once.
    pub fn place(&self) -> std::result::Result<(Ball, Option<Point>), String> {
        if !self.total.iter().all(|t| t.is_finite()) {
            return Err(format!("total {:?} must be finite", self.total));
        }
        let view = mesh::PhantomSpec::default().view_direction;
        let facing = self.facing.or(match self.region.phantom.as_deref() {
            Some("push") => Some(view),
            Some("hidden") => Some(view.map(|v| -v)),
            _ => None,
        });
        Ok((self.region.resolve()?, facing))
    }
}

/// Output settings.
#[derive(Clone, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Output {
    /// Result file (.vtu or .vtk); default `out/<name>.vtu`.
    pub path: Option<PathBuf>,
}

impl StaticScenario {
    /// The scenario `name` of the mesh of `source` and `material` alone: no fixed nodes, loads or
    /// springs, the default solver and output.
    pub fn new(name: impl Into<String>, source: MeshSource, material: Material) -> StaticScenario {
        StaticScenario {
            name: name.into(),
            description: String::new(),
            mesh: source,
            material,
            fixed: Vec::new(),
            prescribed: Vec::new(),
            springs: Vec::new(),
            force: Vec::new(),
            traction: Vec::new(),
            attachment: Vec::new(),
            patch_force: Vec::new(),
            gravity: None,
            solver: SolverOptions::default(),
            output: Output::default(),
        }
    }

    /// The built-in static scenario `name` (e.g. `liver_corotational`); panics when there is none.
    pub fn builtin(name: &str) -> StaticScenario {
        crate::builtin_with(name, Self::from_text)
    }

    /// Reads and parses a scenario file (or a built-in scenario); returns it with the directory
    /// that its relative paths start from.
    pub fn load(path: &Path) -> Result<(Self, PathBuf)> {
        crate::load_with(path, Self::from_text)
    }

    /// Parses scenario text.
    pub fn from_text(source: &ScenarioText) -> Result<Self> {
        source.parse_as(Kind::Static)
    }

    /// Parses the text of a scenario; `origin` names it in errors and relative paths start
    /// from its directory.
    pub fn parse(text: &str, origin: &Path) -> Result<Self> {
        Self::from_text(&ScenarioText::new(text, origin))
    }

    /// The boundary-value problem: the mesh built from its source (file paths relative to
    /// `dir`), the material, constraints and loads.
    pub fn build_problem(&self, dir: &Path) -> Result<Problem> {
        let mesh = build_mesh(&self.mesh, dir)
            .map_err(|e| ScenarioError::build(&self.name, format!("building the mesh: {e}")))?;
        self.build_problem_on(mesh)
    }

    /// The boundary-value problem on `mesh` (the scenario's, as [`StaticScenario::build_problem`]
    /// builds it, or a part of it): the material, constraints and loads.
    pub fn build_problem_on(&self, mesh: Mesh) -> Result<Problem> {
        let fail = |m: String| ScenarioError::build(&self.name, m);
        let mut p = fixed_problem(mesh, &self.mesh, self.material, &self.fixed).map_err(|e| fail(e.to_string()))?;
        let pick = |s: &NodeSelection, what: &str, p: &Problem| {
            crate::source::select_nodes(s, &p.mesh, &self.mesh, what).map_err(fail)
        };
        // Each value where the file gives it: [[prescribed]] 2's displacement, not the assembled load.
        let finite = |what: &str, k: usize, key: &str, values: &[f64]| match values.iter().all(|v| v.is_finite()) {
            true => Ok(()),
            false => Err(fail(format!("{what} {}: {key} = {values:?} must be finite", k + 1))),
        };
        for (k, f) in self.prescribed.iter().enumerate() {
            finite("prescribed", k, "displacement", &f.displacement)?;
            let nodes = pick(&f.select, "prescribed", &p)?;
            let clash =
                nodes.iter().find_map(|n| p.dirichlet.get(n).filter(|&&d| d != f.displacement).map(|d| (*n, *d)));
            if let Some((n, held)) = clash {
                return Err(fail(format!(
                    "prescribed {}: node {} is already held at {} (by [[fixed]] or an earlier [[prescribed]]), not at \
                     {}: give each node one displacement",
                    k + 1,
                    p.mesh.file_node(n),
                    mesh::length::point_in_mm(held),
                    mesh::length::point_in_mm(f.displacement)
                )));
            }
            p.prescribe(&nodes, f.displacement);
        }
        for (k, s) in self.springs.iter().enumerate() {
            finite("springs", k, "stiffness", &[s.stiffness])?;
            if s.stiffness < 0.0 {
                return Err(fail(format!("springs {}: stiffness = {} N/m must be at least 0", k + 1, s.stiffness)));
            }
            let nodes = pick(&s.select, "springs", &p)?;
            p.add_springs(&nodes, s.stiffness);
        }
        for (k, f) in self.force.iter().enumerate() {
            finite("force", k, "total", &f.total)?;
            let nodes = pick(&f.select, "force", &p)?;
            p.add_force(&nodes, f.total);
        }
        for (k, t) in self.traction.iter().enumerate() {
            finite("traction", k, "traction", &t.traction)?;
            let nodes = pick(&t.select, "traction", &p)?;
            if p.add_traction(&nodes, t.traction) == 0.0 {
                return Err(fail(format!(
                    "traction {}: its selection ({} nodes) covers no whole boundary face of the mesh",
                    k + 1,
                    nodes.len()
                )));
            }
        }
        p.attach_all(&self.attachment).map_err(|e| fail(e.to_string()))?;
        for (k, f) in self.patch_force.iter().enumerate() {
            let (ball, facing) = f.place().map_err(|e| fail(format!("patch force {}: {e}", k + 1)))?;
            p.add_patch_force(&ball, facing, f.total).map_err(|e| fail(format!("patch force {}: {e}", k + 1)))?;
        }
        if let Some(g) = self.gravity {
            if !g.iter().all(|v| v.is_finite()) {
                return Err(fail(format!("gravity = {g:?} must be finite")));
            }
            p.add_gravity(g).map_err(|e| fail(format!("gravity: {e}")))?;
        }
        Ok(p)
    }

    /// The output path: `output.path`, else `out/<name>.vtu`.
    pub fn output_path(&self) -> PathBuf {
        self.output.path.clone().unwrap_or_else(|| PathBuf::from(format!("out/{}.vtu", self.name)))
    }
}
