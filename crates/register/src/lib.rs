//! Registration for augmented reality: an intraoperative point cloud (positions
//! only, no correspondences, partial and noisy, rigidly aligned with the
//! preoperative model, or roughly so with the rigid ICP pre-alignment of
//! [`rigid`]) in; the deformed organ and its hidden targets out.
//!
//! The organ is a volumetric mesh with its smooth surface embedded in it. Each
//! iteration matches every cloud point to the closest point of the current
//! deformed surface, turns the matches into displacement observations of mesh
//! nodes, and asks a [`Deformer`] (the finite-element model pulled by springs,
//! or a trained U-Net) for the volumetric displacement that explains them.
//!
//! A soft cube fixed at its base and pressed on top, registered to a cloud of its deformed top
//! face as a camera above it sees it (positions only, no correspondences), through
//! [`Registration`], which `augsim register`, `augsim serve` and Python build (in
//! `augsim_app::registration`, from the user's choices):
//!
//! ```
//! use augsim_register::{FemDeformer, Organ, Registration, RegistrationOptions};
//! use fem::{Law, Material, Problem, SolverOptions, StaticSolver};
//! use mesh::select::nodes_in_box;
//!
//! let cube = mesh::box_tet([0.0; 3], [0.05; 3], [4, 4, 4])?;
//! let mut problem = Problem::new(cube.clone(), Material::new(Law::Corotational, 5000.0, 0.45));
//! problem.fix(&nodes_in_box(&cube.nodes, [-1.0, -1.0, -1e-6], [1.0, 1.0, 1e-6]));
//! // The truth: the top face pressed down.
//! let mut truth = problem.clone();
//! truth.add_traction(&nodes_in_box(&cube.nodes, [-1.0, -1.0, 0.05 - 1e-6], [1.0, 1.0, 1.0]), [0.0, 0.0, -300.0]);
//! let u_true = StaticSolver::new(truth)?.solve(&SolverOptions::default())?.u;
//! let organ = Organ::new(cube, None)?;
//! let rest = organ.surface().vertices.clone();
//! let deformed = organ.deformed_surface(&u_true).vertices;
//! let cloud: Vec<_> = deformed.into_iter().zip(&rest).filter(|(_, r)| r[2] > 0.05 - 1e-6).map(|(p, _)| p).collect();
//!
//! let stiffness = FemDeformer::default_stiffness(&problem);
//! let deformer = FemDeformer::new(problem, stiffness, SolverOptions::default())?;
//! let options = RegistrationOptions { view: Some([0.0, 0.0, -1.0]), ..RegistrationOptions::default() };
//! // The cube's centre, a hidden target.
//! let centre = organ.mesh().nodes.iter().position(|p| p.iter().all(|&x| (x - 0.025).abs() < 1e-9)).unwrap();
//! let target = organ.mesh().nodes[centre];
//! let mut registration =
//!     Registration::new(organ, Box::new(deformer), "co-rotational FEM", vec![target], vec![], options)?;
//! let tracked = registration.register(&cloud)?;
//! // Its error against the truth's motion there.
//! let truth: Vec<f64> = (0..3).map(|d| target[d] + u_true[3 * centre + d]).collect();
//! let error = (0..3).map(|d| (tracked.targets[0][d] - truth[d]).powi(2)).sum::<f64>().sqrt();
//! let motion = (0..3).map(|d| u_true[3 * centre + d].powi(2)).sum::<f64>().sqrt();
//! // Without registration the error would be the whole motion (1.1 mm).
//! assert!(error < 0.25 * motion, "error {error:.2e} m against a motion of {motion:.2e} m");
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

pub mod cloud;
mod error;

pub use error::{RegisterError, Result};
mod checks;
mod deformers;
pub mod frame;
pub mod organ;
pub mod outliers;
pub mod plausibility;
pub mod registration;
pub mod rigid;
pub mod shape;
pub mod structure;
pub mod warp;

pub use checks::check_cloud;
pub use deformers::{FemDeformer, HybridDeformer, NetworkDeformer};
pub use frame::{
    observe, register_frame, Deformer, FrameResult, Observations, PointMatch, RegistrationOptions, TwoWay, IMPLAUSIBLE,
    MAX_POINTS, WARM_START_ITERATION,
};
pub use organ::{Organ, Stencil};
pub use registration::{
    target_errors, within_two_std, FrameOutcome, FrameSummary, GivenBack, Registration, Summary, Tracked,
};
pub use rigid::{in_cloud_frame, rigid_align, IcpMetric, RigidOptions, RigidResult, RigidTransform};
pub use shape::{model_shape_space, ShapeDeformer, ShapeOptions, ShapeSpace};
pub use structure::Structure;
pub use warp::WarpField;
