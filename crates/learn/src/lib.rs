//! Learning for augsim: dataset format, 3D U-Net, training with Adam, transfer learning,
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
//! - [`data`]: datasets — the `.npy` format, sharded datasets, FEM generation, the grid and its
//!   placement, splits, input corruption.
//! - [`net`]: the network — the 3D U-Net, its saved-model bundle, and the engines that run it
//!   (the repacked CPU inference engine, the hand-written backward pass, and with the `cpu-burn`
//!   or `gpu` cargo feature burn on the CPU or a GPU).
//! - [`rom`]: the reduced-order model (POD basis and Gaussian-process regression), the second
//!   learned model beside the U-Net.
//! - [`training`]: training (Adam, checkpoints, resume, fine-tuning), metrics, evaluation and the
//!   learning curve.
//! - [`model`]: a saved model of either kind, loaded and predicting.
//! - [`points`]: point clouds (`.csv`, `.npy`) and grid tensors as a model's prediction input.
//! - [`choosing`]: draws chosen where a reduced-order model is least sure (active learning).
//! - [`Progress`]: how generation and training (and the application's long runs) report how far
//!   they have come, for the caller to draw.

pub mod choosing;
pub mod data;
mod error;
mod fsutil;
pub mod model;
pub mod net;
pub mod points;
mod progress;
pub mod rom;
pub mod training;

pub use data::chosen::{ChoiceRecipe, ChosenDraws, ChosenRound, CANDIDATE_BASE};
pub use data::corrupt::{nonzero_nodes, Corruption, Sparsity};
pub use data::dataset::{
    json_differences, merge_datasets, Dataset, DatasetPart, DatasetSpec, DatasetWriter, FailedSample, FieldUnit,
    Manifest, Normalization, Sample, Samples, ShardInfo, Statistics, WriterLock, MANIFEST_FILE,
};
pub use data::grid::{encode_points, GridMesh, GridPlacement, GridShape, GridToMesh, CHANNELS, LAYOUT};
pub use data::split::{IndexSet, Split, SplitPolicy};
pub use error::LearnError;
pub use model::{LearnedModel, Method, Model, ModelPredictor, Projected, MODEL_FILE, WEIGHTS_FILE};
pub use net::compute::Compute;
pub use net::inference::InferenceNet;
pub use net::predict::{time_prediction, Predictor, Timing};
pub use net::unet::{digest, Gradients, Schedule, TrainedModel, TrainingInfo, UNet, UNetConfig};
pub use points::{NetworkInput, PointCloud, PredictInput};
pub use progress::{Progress, Silent};
pub use training::curve::CurveRow;
pub use training::evaluation::{
    evaluate, evaluate_at_points, evaluation_input, uncertainty_coverage, write_grid_sample, PointErrors,
};
pub use training::metrics::{ErrorStats, EvalReport};
pub use training::train::{take_model_folder, train, Initialization, TrainConfig, TrainOptions, TrainOutcome};

/// Result type of this crate.
pub type Result<T> = std::result::Result<T, LearnError>;
