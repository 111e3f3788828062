//! Assimilation scenarios (`kind = "assimilation"`, `augsim assimilate`): model, loads, unknowns, observations, assessment, filter and outputs.
//! Unknown keys are errors that name the key.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use fem::{Attachment, Law, Material, Problem, SolverOptions};
use filter::{Discrepancy, Execution, LoadPattern, Profile, SigmaPointSet, Transform};
use mesh::select::k_nearest;
use mesh::{Mesh, NodeSelection, Point};
use serde::Deserialize;

use crate::problem::PatchForce;
use crate::{fixed_problem, Fixed, Kind, MeshSource, Result, ScenarioError, ScenarioText};

/// An assimilation scenario file.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AssimilationScenario {
    /// Short name, used for the default output directory.
    pub name: String,
    /// Free text.
    #[serde(default)]
    pub description: String,
    /// Filter iterations = time steps (one observation each); needed for synthetic observations; with observation
    /// files, at most this many frames are used (default: all).
    pub iterations: Option<usize>,
    /// The organ mesh.
    pub mesh: MeshSource,
    /// Material; `young` is the true value of the reference run (and the model's value when not estimated).
    pub material: Material,
    /// Nodes with zero displacement.
    #[serde(default)]
    pub fixed: Vec<Fixed>,
    /// Elastic foundations over the part of the organ inside a ball: unlike fixed nodes, the same on every mesh,
    /// so that the model and the reference solve the same problem.
    #[serde(default)]
    pub attachment: Vec<Attachment>,
    /// Known forces with a time profile.
    #[serde(default)]
    pub force: Vec<ForceSpec>,
    /// Known forces spread as a uniform traction over the boundary inside a ball, with a time profile: unlike a
    /// force on selected nodes, the same on every mesh.
    #[serde(default)]
    pub patch_force: Vec<PatchForceSpec>,
    /// Prescribed displacements (the tool) with a time profile.
    #[serde(default)]
    pub tool: Vec<ToolSpec>,
    /// Estimate Young's modulus.
    pub young: Option<YoungSpec>,
    /// Estimate one spring stiffness per node of a region.
    pub springs: Option<SpringsSpec>,
    /// The tracked feature points and their noise.
    pub observations: ObservationSpec,
    /// Points where the estimated deformation is compared with the reference run (synthetic observations only;
    /// with track files, assessment points come from their own track file).
    pub assessment: Option<AssessmentSpec>,
    /// Where synthetic observations come from when not from the filter's own model: a reference run on another
    /// mesh (and optionally another law), so that the filter never observes its own discretisation (no inverse
    /// crime). Without it the reference run uses the model itself. Ignored when the observations come from files.
    pub reference: Option<ReferenceSpec>,
    /// Filter settings.
    #[serde(default)]
    pub filter: FilterSpec,
    /// Static solver settings of every solve.
    #[serde(default)]
    pub solver: SolverOptions,
    /// Outputs.
    #[serde(default)]
    pub output: OutputSpec,
}

/// A total force spread over the selected nodes as a uniform traction ([`fem::force_shares`]), times a profile.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ForceSpec {
    /// Which nodes.
    pub select: NodeSelection,
    /// Total force at amplitude 1 (N).
    pub total: Point,
    /// Amplitude over time.
    pub profile: Profile,
}

/// A total force spread as a uniform traction over the boundary inside a ball ([`fem::Problem::patch_force_shares`]),
/// times a profile.
#[derive(Debug, Clone, Deserialize)]
pub struct PatchForceSpec {
    /// Where, and the total force at amplitude 1.
    #[serde(flatten)]
    pub force: PatchForce,
    /// Amplitude over time.
    pub profile: Profile,
}

/// A prescribed displacement of the selected nodes (optionally only the `count` nearest to `near`), times a profile.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ToolSpec {
    /// Candidate nodes.
    pub select: NodeSelection,
    /// Keep the candidates nearest to this point (m).
    pub near: Option<Point>,
    /// How many to keep with `near` (default 1).
    pub count: Option<usize>,
    /// Displacement at amplitude 1 (m).
    pub displacement: Point,
    /// Amplitude over time.
    pub profile: Profile,
}

/// Prior of Young's modulus (filter space).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct YoungSpec {
    /// Filter-space transform.
    #[serde(default)]
    pub transform: Transform,
    /// Prior mean (filter space; Pa for the identity).
    pub prior_mean: f64,
    /// Prior standard deviation (filter space).
    pub prior_std: f64,
}

/// One unknown spring per selected node: stiffness = `scale` · transform(filter value).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SpringsSpec {
    /// The attached nodes (the hidden region Σ).
    pub select: NodeSelection,
    /// Stiffness (N/m) per unit of the transformed value.
    pub scale: f64,
    /// Filter-space transform (default `abs`: non-negative stiffness).
    #[serde(default = "abs")]
    pub transform: Transform,
    /// Prior mean (filter space).
    pub prior_mean: f64,
    /// Prior standard deviation (filter space).
    pub prior_std: f64,
    /// True values (transformed units) of the reference run on parts of Σ; 0 elsewhere.
    #[serde(default)]
    pub truth: Vec<SpringTruth>,
    /// Also run the model with Σ all fixed and all free, and compare the assessment errors.
    #[serde(default)]
    pub compare: bool,
}

fn abs() -> Transform {
    Transform::Abs
}

/// True spring value on the nodes of Σ that a selection picks.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SpringTruth {
    /// Which nodes of Σ.
    pub select: NodeSelection,
    /// Value in transformed units (stiffness / scale).
    pub value: f64,
}

/// The reference run's own model: the scenario's loads, tool, true parameters, observations and assessment applied
/// to another mesh (and law).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReferenceSpec {
    /// The reference mesh (e.g. a finer phantom); its selections (`fixed`, forces, tool, Σ) are made on it.
    pub mesh: MeshSource,
    /// The reference law (default: the scenario's).
    pub law: Option<Law>,
    /// The reference elements' order, 1 or 2 (quadratic tetrahedra; default: the scenario's).
    pub order: Option<u8>,
}

/// Tracked feature points on the visible surface.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ObservationSpec {
    /// Number of synthetic feature points (drawn uniformly by area on the surface facing the camera, away from
    /// constrained nodes); needed unless the observations come from a file.
    pub points: Option<usize>,
    /// Viewing direction of the camera.
    #[serde(default = "view")]
    pub view_direction: Point,
    /// Seed of the point sampling and of the noise.
    #[serde(default)]
    pub seed: u64,
    /// Standard deviation of the measurement noise (m): added to the synthetic observations, and the tracker's
    /// accuracy for observations from a file.
    pub noise_std: f64,
    /// Observation standard deviation assumed by the filter (m); default `noise_std`.
    pub filter_std: Option<f64>,
}

fn view() -> Point {
    [0.0, 0.0, -1.0]
}

/// Assessment points: `count` nodes of a selection, spread out, that are neither constrained nor observed.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AssessmentSpec {
    /// Candidate nodes.
    pub select: NodeSelection,
    /// How many.
    pub count: usize,
}

/// Filter settings.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FilterSpec {
    /// Parallel or sequential sigma points.
    #[serde(default)]
    pub execution: Execution,
    /// Forgetting factor ρ in (0, 1] (see [`filter::RoukfConfig::forgetting`]); 1: none.
    #[serde(default = "one")]
    pub forgetting: f64,
    /// `"simplex"` (p + 1 points, the default) or `"star"` (2p + 1 points) (see [`filter::SigmaPointSet`]).
    #[serde(default)]
    pub sigma_points: SigmaPointSet,
    /// Allowance for model error in the reported σ: `"none"` (the default), `"independent"` (the misfit as extra
    /// white noise) or `"systematic"` (a model error that may lie along the parameters' sensitivity) (see
    /// [`filter::Discrepancy`] and [`filter::Roukf::with_discrepancy`]).
    #[serde(default)]
    pub discrepancy: Discrepancy,
    /// Degrees of freedom d ≥ 1 of a systematic discrepancy (default 1).
    #[serde(default = "one")]
    pub discrepancy_dof: f64,
    /// Validation gate G: a tracked component farther from its prediction than G predicted
    /// standard deviations is left out of that step (see [`filter::RoukfConfig::gate`]); none by
    /// default.
    #[serde(default)]
    pub gate: Option<f64>,
}

impl Default for FilterSpec {
    fn default() -> Self {
        FilterSpec {
            execution: Execution::default(),
            forgetting: 1.0,
            sigma_points: SigmaPointSet::default(),
            discrepancy: Discrepancy::None,
            discrepancy_dof: 1.0,
            gate: None,
        }
    }
}

fn one() -> f64 {
    1.0
}

/// Output settings.
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OutputSpec {
    /// Directory of the results; default `out/<name>`.
    pub dir: Option<PathBuf>,
    /// Write the estimated deformation of every `every`-th time step (default 1: every step).
    pub every: Option<usize>,
}

impl AssimilationScenario {
    /// Reads and parses a scenario file (or a built-in scenario); returns it with the directory that its relative
    /// paths start from.
    pub fn load(path: &Path) -> Result<(Self, PathBuf)> {
        crate::load_with(path, Self::from_text)
    }

    /// Parses scenario text.
    pub fn from_text(source: &ScenarioText) -> Result<Self> {
        source.parse_as(Kind::Assimilation)
    }

    /// The scenario of the reference run behind its synthetic observations when it has a `[reference]` section:
    /// the same scenario on the reference mesh and law, without the section.
    pub fn reference_scenario(&self) -> Option<AssimilationScenario> {
        let reference = self.reference.as_ref()?;
        let mut scenario = self.clone();
        scenario.mesh = reference.mesh.clone();
        scenario.material.law = reference.law.unwrap_or(self.material.law);
        scenario.material.order = reference.order.unwrap_or(self.material.order);
        scenario.reference = None;
        Some(scenario)
    }

    /// The base problem on `mesh` (material, fixed and tool nodes constrained at rest), the
    /// time-profiled loads (forces and tool displacements), and the tool nodes.
    pub fn build_problem(&self, mesh: Mesh) -> Result<(Problem, Vec<LoadPattern>, Vec<usize>)> {
        let fail = |m: String| ScenarioError::build(&self.name, m);
        let mut problem =
            fixed_problem(mesh, &self.mesh, self.material, &self.fixed).map_err(|e| fail(e.to_string()))?;
        let select = |s: &NodeSelection, what: &str, p: &Problem| {
            crate::source::select_nodes(s, &p.mesh, &self.mesh, what).map_err(fail)
        };
        problem.attach_all(&self.attachment).map_err(|e| fail(e.to_string()))?;
        let pattern = |shares: Vec<(usize, f64)>, total: Point, profile: Profile| {
            let forces = shares.into_iter().map(|(k, s)| (k, total.map(|c| c * s))).collect();
            LoadPattern { profile, forces, displacements: vec![] }
        };
        let mut loads = Vec::new();
        for f in &self.force {
            let nodes = select(&f.select, "force", &problem)?;
            loads.push(pattern(fem::force_shares(&problem.mesh, &nodes), f.total, f.profile));
        }
        for (k, f) in self.patch_force.iter().enumerate() {
            let fail = |e: String| fail(format!("patch force {}: {e}", k + 1));
            let (ball, facing) = f.force.place().map_err(fail)?;
            let (shares, _) = problem.patch_force_shares(&ball, facing).map_err(|e| fail(e.to_string()))?;
            loads.push(pattern(shares, f.force.total, f.profile));
        }
        // The nodes [[fixed]] holds: no tool may move them (tools may share nodes: their displacements add up).
        let held: BTreeSet<usize> = problem.dirichlet.keys().copied().collect();
        let mut tool_nodes = Vec::new();
        for (i, t) in self.tool.iter().enumerate() {
            let mut nodes = select(&t.select, "tool", &problem)?;
            match (t.near, t.count) {
                (Some(_), Some(0)) => return Err(fail("tool: count must be at least 1".into())),
                (Some(p), count) => nodes = k_nearest(&problem.mesh.nodes, nodes, p, count.unwrap_or(1)),
                (None, Some(_)) => {
                    return Err(fail("tool: `count` needs `near`, the point the nodes are nearest to".into()))
                }
                (None, None) => {}
            }
            if let Some(&k) = nodes.iter().find(|k| held.contains(k)) {
                return Err(fail(self.tool_clash(i, k, &problem)));
            }
            for &k in &nodes {
                problem.dirichlet.entry(k).or_insert([0.0; 3]);
            }
            loads.push(LoadPattern {
                profile: t.profile,
                forces: vec![],
                displacements: nodes.iter().map(|&k| (k, t.displacement)).collect(),
            });
            tool_nodes.extend(nodes);
        }
        tool_nodes.sort_unstable();
        tool_nodes.dedup();
        Ok((problem, loads, tool_nodes))
    }

    /// Why tool `i` may not take node `k`, which a `[[fixed]]` holds: the node and both selections.
    fn tool_clash(&self, i: usize, k: usize, problem: &Problem) -> String {
        let holds = |f: &Fixed| {
            crate::source::select_nodes(&f.select, &problem.mesh, &self.mesh, "fixed").is_ok_and(|n| n.contains(&k))
        };
        let by = match self.fixed.iter().position(holds) {
            Some(j) => format!("[[fixed]] {} ({})", j + 1, self.fixed[j].select),
            None => "[[fixed]]".to_string(),
        };
        format!(
            "tool {}: node {} of its selection ({}) is already held at rest by {by}, and a tool cannot move a held \
             node: leave the node out of one of the two selections",
            i + 1,
            problem.mesh.file_node(k),
            self.tool[i].select
        )
    }

    /// The output directory: `output.dir`, else `out/<name>`.
    pub fn output_dir(&self) -> PathBuf {
        self.output.dir.clone().unwrap_or_else(|| PathBuf::from("out").join(&self.name))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The built-in Young's modulus scenario holds the phantom by a foundation over its `fixed` ball and loads it
    /// with a time-profiled patch force: the pattern's nodal forces are a static patch force's, and sum to the total.
    #[test]
    fn geometric_attachments_and_patch_forces_hold_and_load_the_model() {
        let text = crate::builtin("roukf_young").expect("built in");
        let parse = |t: &str| AssimilationScenario::from_text(&ScenarioText::new(t, Path::new("young.toml")));
        let scenario = parse(text).unwrap();
        let mesh = mesh::PhantomSpec::default().mesh(1150).unwrap();
        let (problem, loads, tools) = scenario.build_problem(mesh.clone()).unwrap();
        assert!(problem.dirichlet.is_empty() && tools.is_empty(), "no node is fixed");
        assert!(!problem.point_springs.is_empty(), "the foundation ties the fixed ball");
        assert_eq!(loads.len(), 1);
        let mut total = [0.0; 3];
        let mut pattern = vec![0.0; 3 * mesh.nodes.len()];
        for &(k, f) in &loads[0].forces {
            for d in 0..3 {
                total[d] += f[d];
                pattern[3 * k + d] += f[d];
            }
        }
        assert!((total[2] + 0.3).abs() < 1e-12 && total[0].abs() < 1e-12 && total[1].abs() < 1e-12, "{total:?}");
        let spec = mesh::PhantomSpec::default();
        let mut fixed = Problem::new(mesh, scenario.material);
        fixed.add_patch_force(&spec.region_ball("push").unwrap(), Some(spec.view_direction), [0.0, 0.0, -0.3]).unwrap();
        let gap = pattern.iter().zip(&fixed.f_ext).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
        assert!(gap < 1e-15, "the pattern differs from the static patch force by {gap} N");
        // An unknown key, a missing total and a ball that misses the organ are named.
        let extra = text.replace("total = [0.0, 0.0, -0.3]", "total = [0.0, 0.0, -0.3]\ncentre = 1");
        assert!(
            parse(&extra).is_err_and(|e| e.to_string().contains("unknown field `centre`")),
            "an unknown key passed"
        );
        let bad = text.replace("total = [0.0, 0.0, -0.3]", "totl = [0.0, 0.0, -0.3]");
        assert!(parse(&bad).is_err_and(|e| e.to_string().contains("missing field `total`")), "a misspelt key passed");
        let away = text.replace("phantom = \"push\"", "ball = { centre = [1.0, 1.0, 1.0], radius = 0.01 }");
        let built = parse(&away).and_then(|s| s.build_problem(mesh::PhantomSpec::default().mesh(1150).unwrap()));
        assert!(built.is_err_and(|e| e.to_string().contains("patch force 1")), "a ball off the organ passed");
    }

    /// Tools may share nodes (their displacements add up), but a tool on a node that `[[fixed]]` holds is refused,
    /// naming the node and both selections.
    #[test]
    fn a_tool_on_a_fixed_node_is_refused() {
        let text = crate::builtin("roukf_springs").expect("built in");
        let parse = |t: &str| AssimilationScenario::from_text(&ScenarioText::new(t, Path::new("springs.toml")));
        let mesh = mesh::PhantomSpec::default().mesh(1150).unwrap();
        let (problem, loads, tools) = parse(text).unwrap().build_problem(mesh.clone()).unwrap();
        assert_eq!(tools.len(), 4, "the two tools move the same 4 nodes");
        assert!(tools.iter().all(|k| problem.dirichlet[k] == [0.0; 3]));
        assert_eq!(loads.iter().filter(|l| !l.displacements.is_empty()).count(), 2);
        let clash = text.replacen("[[tool]]", "[[fixed]]\nselect = { region = \"visible\" }\n\n[[tool]]", 1);
        let err = parse(&clash).and_then(|s| s.build_problem(mesh)).unwrap_err().to_string();
        assert!(
            err.contains("tool 1: node ")
                && err.contains("region 'visible'")
                && err.contains("is already held at rest by [[fixed]] 1 (region 'visible')"),
            "{err}"
        );
    }

    /// The reference run takes its own mesh, law and element order, and keeps the rest.
    #[test]
    fn the_reference_scenario_takes_its_mesh_law_and_order() {
        let text = crate::builtin("roukf_young").expect("built in").replace(
            "[reference.mesh.phantom]",
            "[reference]\nlaw = \"neo_hookean\"\norder = 2\n\n[reference.mesh.phantom]",
        );
        let parse = |t: &str| AssimilationScenario::from_text(&ScenarioText::new(t, Path::new("young.toml")));
        let scenario = parse(&text).unwrap();
        let reference = scenario.reference_scenario().unwrap();
        assert!(matches!(reference.mesh, MeshSource::Phantom { tets: 11000 }));
        assert_eq!((reference.material.law, reference.material.order), (Law::NeoHookean, 2));
        assert_eq!((scenario.material.law, scenario.material.order), (Law::Svk, 1));
        assert_eq!(reference.material.young, scenario.material.young);
        assert!(reference.reference.is_none());
        let bad = text.replace("order = 2", "order = 3");
        let built = parse(&bad).and_then(|s| {
            s.reference_scenario()
                .unwrap()
                .build_problem(mesh::box_tet([0.0; 3], [1.0; 3], [1, 1, 1]).unwrap())
                .map(|_| ())
        });
        assert!(built.is_err_and(|e| e.to_string().contains("order must be 1")), "order 3 accepted");
    }
}
