//! What several of these tests build: the built-in case pushed by a chosen force, and the models'
//! phantom and co-rotational FEM.

use std::path::Path;

use augsim_app::case::{synthetic_case, SyntheticCase};
use register::{FemDeformer, Organ};
use scenario::registration::{CameraSpec, Misalignment};
use scenario::{CaseScenario, StaticScenario};

/// The built-in case ([`CaseScenario::builtin`]) with its `push` patch pressed down by `force` N,
/// seen by `camera`, without misalignment.
#[allow(dead_code)]
pub fn phantom_push(force: f64, camera: &CameraSpec) -> SyntheticCase {
    let mut scenario = CaseScenario::builtin();
    scenario.truth.force = force;
    scenario.camera = camera.clone();
    scenario.misalignment = Misalignment::default();
    synthetic_case(&scenario).unwrap()
}

/// The phantom the built-in case's models deform (`models.tets` tetrahedra: another mesh than the
/// truth's).
#[allow(dead_code)]
pub fn model_mesh() -> mesh::Mesh {
    mesh::phantom::liver_phantom(CaseScenario::builtin().models.tets).unwrap()
}

/// The co-rotational registration model on [`model_mesh`], fixed between the lobes: the built-in
/// static scenario `liver_corotational`.
#[allow(dead_code)]
pub fn corotational_model() -> (Organ, FemDeformer) {
    let (organ, deformer, _) =
        augsim_app::models::fem_model(&StaticScenario::builtin("liver_corotational"), Path::new("")).unwrap();
    (organ, deformer)
}
