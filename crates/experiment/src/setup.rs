//! A registration method from its files, as `augsim register`, `augsim serve` and the Python
//! package build it: the FEM of a static scenario, or a trained U-Net with the dataset scenario
//! it was trained on.

use std::path::Path;

use anyhow::Result;
use mesh::Point;
use register::{Deformer, FemDeformer, Organ, RegistrationOptions};
use scenario::{CaseScenario, DatasetScenario, StaticScenario};

use crate::case::{network_model, network_options, organ_of, Network};

/// The organ, what deforms it, the method's name, the default targets and registration settings.
pub struct RegistrationSetup {
    /// The organ (its mesh and surface, in m).
    pub organ: Organ,
    /// What deforms it.
    pub deformer: Box<dyn Deformer + Send>,
    /// The method in words (e.g. `FEM, Corotational (Standard elements)`).
    pub method: String,
    /// The rest positions of the mesh's `markers` and `tumour` nodes (empty without such regions).
    pub default_targets: Vec<Point>,
    /// The registration settings that suit the method: the library's for a FEM; for a network,
    /// the real-time iteration budgets of the built-in registration case's network method.
    pub options: RegistrationOptions,
}

impl RegistrationSetup {
    /// Its registration settings with a caller's choices: most iterations from rest, when given, and
    /// a rigid pre-alignment of the first cloud.
    pub fn options_with(&self, iterations: Option<usize>, rigid: bool) -> RegistrationOptions {
        RegistrationOptions {
            iterations: iterations.unwrap_or(self.options.iterations),
            rigid: rigid.then(register::RigidOptions::default),
            ..self.options.clone()
        }
    }
}

/// FEM registration on the static scenario at `path` (a file or a built-in name): its mesh,
/// material, fixed nodes and solver, pulled by springs of the default stiffness.
pub fn fem_setup(path: &Path) -> Result<RegistrationSetup> {
    let (scenario, dir) = StaticScenario::load(path)?;
    let problem = scenario.build_problem(&dir)?;
    let organ = organ_of(&scenario.mesh, problem.mesh.clone())?;
    let default_targets = region_targets(&problem.mesh);
    let method = format!("FEM, {:?} ({:?} elements)", problem.material.law, problem.material.resolved_formulation());
    let stiffness = FemDeformer::default_stiffness(&problem);
    let deformer = Box::new(FemDeformer::new(problem, stiffness, scenario.solver.clone())?);
    Ok(RegistrationSetup { organ, deformer, method, default_targets, options: RegistrationOptions::default() })
}

/// U-Net registration with the model at `model_path` (model.json) trained on the dataset
/// scenario at `scenario_path` (a file or a built-in name), whose mesh is the organ.
pub fn network_setup(model_path: &Path, scenario_path: &Path) -> Result<RegistrationSetup> {
    let (scenario, dir) = DatasetScenario::load(scenario_path)?;
    let model = learn::TrainedModel::load(model_path)?;
    let (organ, deformer) = network_model(&Network { model: &model, scenario: &scenario, dir: &dir })?;
    let default_targets = region_targets(organ.mesh());
    Ok(RegistrationSetup {
        organ,
        deformer: Box::new(deformer),
        method: format!("U-Net {}", model_path.display()),
        default_targets,
        options: network_options(&CaseScenario::builtin())?,
    })
}

/// Rest positions of the nodes of the `markers` and `tumour` regions, when the mesh has them.
fn region_targets(m: &mesh::Mesh) -> Vec<Point> {
    ["markers", "tumour"].iter().filter_map(|r| m.region(r).ok()).flatten().map(|&n| m.nodes[n]).collect()
}
