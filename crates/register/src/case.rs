//! A synthetic intraoperative case on the built-in phantom: the ground truth
//! comes from a finer mesh and another law than the registration model (no
//! inverse crime), the cloud from a camera looking at its deformed surface.

use fem::{Law, Material, Problem, SolverOptions, StaticSolver};
use mesh::Point;

use crate::deformers::FemDeformer;
use crate::organ::Organ;
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

/// Tetrahedra of the registration model of [`corotational_model`].
pub const MODEL_TETS: usize = 3000;

/// The registration model for [`phantom_push`]: a co-rotational phantom of about
/// [`MODEL_TETS`] tetrahedra (another mesh and another law than the truth's), fixed between
/// the lobes, with the default data stiffness.
pub fn corotational_model() -> Result<(Organ, FemDeformer)> {
    let m = mesh::phantom::liver_phantom(MODEL_TETS)?;
    let mut problem = Problem::new(m.clone(), Material::new(Law::Corotational, 5000.0, 0.48));
    problem.fix(m.region("fixed")?);
    let stiffness = FemDeformer::default_stiffness(&problem);
    Ok((Organ::new(m, None)?, FemDeformer::new(problem, stiffness, SolverOptions::default())?))
}

/// Per-target distances (m) between two lists of positions of the same length.
pub fn target_errors(registered: &[Point], truth: &[Point]) -> Vec<f64> {
    registered.iter().zip(truth).map(|(a, b)| crate::register::distance(*a, *b)).collect()
}
