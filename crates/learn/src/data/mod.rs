//! Datasets: what a network learns from, and how inputs reach its grid.
//!
//! - [`dataset`]: sharded datasets with a JSON manifest, resumable writer, reader, merge.
//! - [`generate`]: FEM-generated samples (random loads → grid input and target), parallel, resumable.
//! - [`chosen`]: σ-chosen draws, where a reduced-order model is least sure (active learning).
//! - [`grid`]: the regular grid, its placement in space, and the mapping between mesh nodes and grid nodes.
//! - [`split`]: train / validation / test splits, the policy that sizes them, and the held-out guard.
//! - [`corrupt`]: sparse visible inputs and Gaussian noise.
//! - [`points`]: point clouds (`.csv`, `.npy`) and grid tensors as prediction input.
//! - [`response`]: the linear-elastic response at rest between grid fields, a physics prior.

pub mod chosen;
pub mod corrupt;
pub mod dataset;
pub mod generate;
pub mod grid;
pub mod points;
pub mod response;
pub mod split;
