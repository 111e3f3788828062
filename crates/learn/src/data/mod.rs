//! Datasets: what a network learns from, and how inputs reach its grid.
//!
//! - [`dataset`]: sharded datasets with a JSON manifest, resumable writer, reader, merge.
//! - [`generate`]: FEM-generated samples (random loads → grid input and target), parallel, resumable.
//! - [`chosen`]: the record of σ-chosen draws, where a reduced-order model was least sure
//!   (active learning, [`crate::choosing`]).
//! - [`grid`]: the regular grid, its placement in space, and the mapping between mesh nodes and grid nodes.
//! - [`split`]: train / validation / test splits, the policy that sizes them, and the held-out guard.
//! - [`corrupt`]: sparse visible inputs and Gaussian noise.
//! - [`response`]: the linear-elastic response at rest between grid fields, a physics prior.

pub mod chosen;
pub mod corrupt;
pub mod dataset;
pub mod generate;
pub mod grid;
pub mod response;
pub mod split;
