//! Learning for augsim: dataset format, 3D U-Net (burn), training with Adam, transfer learning,
//! input corruption, evaluation and timed prediction.
//!
//! # Grid tensor layout
//!
//! Every field on the regular grid is stored as `[channel, x, y, z]` in C order, `z` fastest:
//! the value of channel `c` at grid node `(i, j, k)` of an `nx × ny × nz` grid is at
//! `((c * nx + i) * ny + j) * nz + k` (see [`GridShape::field_index`]). A batch or a dataset
//! shard prepends the sample axis: `[sample, channel, x, y, z]`. Masks are `[x, y, z]`
//! (`[sample, x, y, z]` in a shard), 1 inside the organ and 0 outside.
//!
//! A sample is an input field `C` (3 channels: nodal forces in N or imposed surface
//! displacements in m, zero where nothing is applied), a target displacement `U` (3 channels,
//! m) and a mask. Units are SI throughout.
//!
//! # Modules
//! - [`npy`]: minimal NumPy `.npy` reader/writer (v1.0 header, `<f4`, `<f8`, `|u1`, `|b1`).
//! - [`dataset`]: sharded datasets with a JSON manifest, resumable writer, reader, merge.
//! - [`generate`]: FEM-generated samples (random loads → grid input and target), parallel, resumable.
//! - [`unet`]: the 3D U-Net, its configuration and the saved-model bundle (JSON + safetensors).
//! - [`corrupt`]: sparse visible inputs and Gaussian noise.
//! - [`metrics`]: masked MSE loss and mean Euclidean errors.
//! - [`train`](mod@train): the training loop (Adam, checkpoints, resume, fine-tuning, learning curves).
//! - [`inference`]: the trained network repacked for fast CPU inference.
//! - [`evaluation`]: errors of a model over a sample set and at points.
//! - [`predict`]: single predictions and their timing.
//! - [`compute`]: where the network runs (CPU engines, or a GPU through burn with the `gpu` feature).
//! - [`points`]: point clouds (`.csv`, `.npy`) and grid tensors as prediction input.
//! - [`split`]: train / validation / test splits, the policy that sizes them, and the held-out guard.

#![warn(missing_docs)]

pub mod backprop;
pub mod compute;
pub mod corrupt;
pub mod curve;
pub mod dataset;
mod error;
pub mod evaluation;
mod fsutil;
pub mod generate;
mod grid;
pub mod inference;
mod lanes;
pub mod metrics;
pub mod npy;
pub mod points;
pub mod predict;
pub mod sample_view;
pub mod scenario;
pub mod split;
pub mod train;
pub mod unet;
mod winograd;

pub use compute::Compute;
pub use corrupt::{Corruption, Sparsity};
pub use curve::CurveRow;
pub use dataset::{
    merge_datasets, Dataset, DatasetPart, DatasetSpec, DatasetWriter, FailedSample, Manifest, Normalization, Sample,
    Samples, ShardInfo, Statistics,
};
pub use error::LearnError;
pub use evaluation::{evaluate, evaluate_at_points, evaluation_input, write_grid_sample, PointErrors};
pub use grid::{encode_points, GridMesh, GridPlacement, GridShape, GridToMesh, CHANNELS, LAYOUT};
pub use inference::InferenceNet;
pub use metrics::{ErrorStats, EvalReport};
pub use points::{PointCloud, PredictInput};
pub use predict::{time_prediction, Predictor, Timing};
pub use split::{IndexSet, Split, SplitPolicy};
pub use train::{train, Initialization, TrainConfig, TrainOptions, TrainOutcome};
pub use unet::{TrainedModel, TrainingInfo, UNet, UNetConfig};

/// Result type of this crate.
pub type Result<T> = std::result::Result<T, LearnError>;

/// The device used for inference: burn's pure-Rust `flex` CPU backend.
pub fn inference_device() -> burn::tensor::Device {
    burn::tensor::Device::flex()
}

/// The device used for training: the `flex` CPU backend with autodiff enabled.
pub fn training_device() -> burn::tensor::Device {
    burn::tensor::Device::flex().autodiff()
}
