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

pub mod cloud;
mod error;

pub use error::{RegisterError, Result};
mod deformers;
pub mod organ;
pub mod outliers;
pub mod register;
pub mod rigid;
pub mod sequence;

pub use deformers::{FemDeformer, NetworkDeformer};
pub use organ::{Organ, Stencil};
pub use register::{
    check_cloud, observe, register_frame, Deformer, FrameResult, Observations, PointMatch, RegistrationOptions,
};
pub use rigid::{rigid_align, IcpMetric, RigidOptions, RigidResult, RigidTransform};
pub use sequence::{register_sequence, target_errors, FrameOutcome, Summary};
