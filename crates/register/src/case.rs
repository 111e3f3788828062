//! A synthetic intraoperative case on the built-in phantom: the ground truth
//! comes from a finer mesh and another law than the registration model (no
//! inverse crime), the cloud from a camera looking at its deformed surface.

use fem::{Law, Material, Problem, SolverOptions, StaticSolver};
use mesh::{Mesh, Point};

use learn::TrainedModel;

use crate::deformers::{FemDeformer, NetworkDeformer};
use crate::organ::Organ;
use crate::register::{Deformer, RegistrationOptions};
use crate::sequence::{register_sequence, FrameOutcome, Summary};
use crate::simulate::{simulate_cloud, CameraModel};
use crate::Result;

/// Tetrahedra of the ground-truth phantom.
pub const TRUTH_TETS: usize = 9000;

/// What the operating room gives (the cloud) and what it hides (the truth).
#[derive(Clone, Debug)]
pub struct SyntheticCase {
    /// The intraoperative cloud.
    pub cloud: Vec<Point>,
    /// Internal targets at rest (the phantom's `markers`).
    pub targets: Vec<Point>,
    /// Their true deformed positions.
    pub truth: Vec<Point>,
}

/// The Neo-Hookean phantom (E = 5 kPa, ν = 0.48, F-bar) of about [`TRUTH_TETS`] tetrahedra,
/// fixed between the lobes, its `push` patch pressed down by `force` N; the camera model's
/// view of the deformed surface, reproducible from `seed`.
pub fn phantom_push(force: f64, camera: &CameraModel, seed: u64) -> Result<SyntheticCase> {
    let m = mesh::phantom::liver_phantom(TRUTH_TETS)?;
    let mut p = Problem::new(m, Material::new(Law::NeoHookean, 5000.0, 0.48));
    let fixed = p.mesh.region("fixed")?.to_vec();
    let push = p.mesh.region("push")?.to_vec();
    p.fix(&fixed);
    p.add_force(&push, [0.0, 0.0, -force]);
    let u = StaticSolver::new(p.clone())?.solve(&SolverOptions::default())?.u;
    let markers = p.mesh.region("markers")?.to_vec();
    let targets: Vec<Point> = markers.iter().map(|&n| p.mesh.nodes[n]).collect();
    let truth = markers.iter().map(|&n| std::array::from_fn(|d| p.mesh.nodes[n][d] + u[3 * n + d])).collect();
    let organ = Organ::new(p.mesh, None)?;
    let cloud = simulate_cloud(&organ.deformed_surface(&u), camera, seed)?;
    Ok(SyntheticCase { cloud, targets, truth })
}

/// Tetrahedra of the registration models (the FEM models and the network's training mesh).
pub const MODEL_TETS: usize = 3000;

/// The phantom of about [`MODEL_TETS`] tetrahedra that the registration models deform
/// (another mesh than the truth's).
pub fn model_mesh() -> Result<Mesh> {
    Ok(mesh::phantom::liver_phantom(MODEL_TETS)?)
}

/// A FEM registration model for [`phantom_push`] on `mesh` (a phantom, e.g. [`model_mesh`])
/// with `material`, fixed between the lobes, with the default data stiffness.
pub fn fem_model(mesh: Mesh, material: Material) -> Result<(Organ, FemDeformer)> {
    let mut problem = Problem::new(mesh.clone(), material);
    problem.fix(mesh.region("fixed")?);
    let stiffness = FemDeformer::default_stiffness(&problem);
    Ok((Organ::new(mesh, None)?, FemDeformer::new(problem, stiffness, SolverOptions::default())?))
}

/// The co-rotational registration law (E = 5 kPa, ν = 0.48): another law than the truth's.
fn corotational_material() -> Material {
    Material::new(Law::Corotational, 5000.0, 0.48)
}

/// The co-rotational registration model on [`model_mesh`].
pub fn corotational_model() -> Result<(Organ, FemDeformer)> {
    fem_model(model_mesh()?, corotational_material())
}

/// The U-Net registration model on `mesh` (the phantom the network was trained on, e.g.
/// [`model_mesh`]): `model`, trained with the normal displacement of the `visible` region as
/// input (`scenarios/liver_ar.toml`).
pub fn network_model(mesh: Mesh, model: &TrainedModel) -> Result<(Organ, NetworkDeformer)> {
    let visible = mesh.region("visible")?.to_vec();
    let organ = Organ::new(mesh, None)?;
    let deformer = NetworkDeformer::new(model, &organ, &visible, true)?;
    Ok((organ, deformer))
}

/// The methods compared on [`phantom_push`], all on [`model_mesh`]: the co-rotational FEM, the
/// SVK FEM (E = 5 kPa, ν = 0.49, the law of the network's training data) and, when given, the
/// U-Net `network`.
pub fn methods(network: Option<&TrainedModel>) -> Result<Vec<Method>> {
    let mesh = model_mesh()?;
    let fem = |name: &str, material: Material| -> Result<Method> {
        let (organ, deformer) = fem_model(mesh.clone(), material)?;
        Ok(Method { name: name.into(), organ, deformer: Box::new(deformer) })
    };
    let mut out = vec![
        fem("FEM co-rotational (3k T4)", corotational_material())?,
        fem("FEM SVK (3k T4)", Material::new(Law::Svk, 5000.0, 0.49))?,
    ];
    if let Some(model) = network {
        let (organ, deformer) = network_model(mesh, model)?;
        out.push(Method { name: "U-Net".into(), organ, deformer: Box::new(deformer) });
    }
    Ok(out)
}

/// A registration method of a comparison.
pub struct Method {
    /// Name in the table.
    pub name: String,
    /// The organ it deforms.
    pub organ: Organ,
    /// How it deforms.
    pub deformer: Box<dyn Deformer>,
}

/// One method's result in a comparison.
pub struct Compared {
    /// Its figures.
    pub summary: Summary,
    /// Its registration of the case.
    pub outcome: FrameOutcome,
    /// The organ it deformed.
    pub organ: Organ,
}

/// Registers the case's cloud with each method (one frame, from rest), in order.
pub fn compare(case: &SyntheticCase, methods: Vec<Method>, options: &RegistrationOptions) -> Result<Vec<Compared>> {
    let mut rows = Vec::new();
    for mut m in methods {
        let truth = [case.truth.clone()];
        let frames = [Ok(case.cloud.clone())];
        let mut outcomes =
            register_sequence(&m.organ, m.deformer.as_mut(), frames, &case.targets, Some(&truth), options, |_, _| {
                Ok(())
            })?;
        let summary = Summary::new(m.name, &outcomes)?;
        rows.push(Compared { summary, outcome: outcomes.remove(0), organ: m.organ });
    }
    Ok(rows)
}
