//! Training: Adam ([`Adam`]) on the masked MSE, seeded, with validation, best-weights selection,
//! resumable checkpoints, learning curves and transfer learning. On the CPU ([`Compute::Cpu`])
//! gradients come from the hand-written backward pass of [`backprop`](crate::net::backprop); on a
//! GPU or [`Compute::CpuBurn`] (the `cpu-burn` feature) from burn's autodiff, equal up to
//! summation order. The parameters, the optimiser and the checkpoints are the same either way, so
//! a checkpoint written on one device resumes on the other.
//!
//! Reproducibility: weights are initialised from the seed; batch composition and training-time
//! corruption come from counter-based generators (seed, iteration, batch slot), so the whole
//! random state of a run is `(seed, iteration)`. A checkpoint stores the model, the Adam state,
//! the best weights so far, the learning curve and that state, written atomically every
//! `checkpoint_every` iterations; a run resumed from it produces the same result as an
//! uninterrupted one. Resuming a finished run with more iterations extends it.
//!
//! Files written in `out_dir`: `model.json` + `model.safetensors` (best weights, on completion),
//! `checkpoint.bin` and `curve.csv` (iteration, train loss, validation mean error), and
//! [`WRITER_LOCK`](crate::data::dataset::WRITER_LOCK) while it runs (a second run into the same
//! folder is refused); the application draws the curve from [`TrainOutcome::curve`].
//! `checkpoint.bin` is the magic `AUGSIMCK`, then two
//! sections, each its length (`u64`, little-endian) and its bytes: the JSON state, and a
//! safetensors file of the model (`model.` + parameter path), Adam's moments (`adam.moment_1.`,
//! `adam.moment_2.`) and the best weights so far (`best.`).

use std::path::{Path, PathBuf};
use std::time::Instant;

#[cfg(feature = "cpu-burn")]
use burn::tensor::Device;
use mesh::io::write_atomic_bytes;
use rand::Rng;
use safetensors::SafeTensors;
use serde::{Deserialize, Serialize};

use crate::data::corrupt::{item_rng, splitmix64, Corruption, STREAM_SHUFFLE, STREAM_TRAIN_CORRUPTION};
use crate::data::dataset::{lock_for_writing, Normalization, Samples, WriterLock};
use crate::data::grid::{GridPlacement, GridShape};
use crate::data::split::{IndexSet, Split};
use crate::fsutil::read;
use crate::net::backprop::loss_and_gradients;
#[cfg(feature = "cpu-burn")]
use crate::net::burn_unet::BurnUNet;
use crate::net::predict::Predictor;
use crate::net::unet::{
    read_tensor, write_safetensors, Gradients, Schedule, TrainedModel, TrainingInfo, UNet, UNetConfig,
};
use crate::progress::Progress;
use crate::training::adam::{Adam, Moments};
use crate::training::curve::{write_curve_csv, CurveRow};
use crate::training::evaluation::evaluate_net;
use crate::FieldUnit;
use crate::{Compute, LearnError, Result};

/// Training hyper-parameters.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TrainConfig {
    /// Number of optimizer steps.
    pub iterations: usize,
    /// Samples per step (at most the training samples: a smaller training set is a step's whole
    /// batch).
    pub batch_size: usize,
    /// Adam learning rate (at the first iteration).
    pub learning_rate: f64,
    /// When set, the rate falls from `learning_rate` to this value along a half cosine over
    /// the `iterations` (the schedule then depends on `iterations`, so such a run cannot be
    /// extended by resuming it with more).
    pub final_learning_rate: Option<f64>,
    /// Seed of weights, shuffling and corruption.
    pub seed: u64,
    /// Validate every this many iterations (and after the last one).
    pub validate_every: usize,
    /// Write a checkpoint every this many iterations (and after the last one).
    pub checkpoint_every: usize,
    /// Corruption of training inputs.
    pub train_corruption: Corruption,
    /// Corruption of validation inputs (same draw at every validation).
    pub val_corruption: Corruption,
}

impl Default for TrainConfig {
    fn default() -> Self {
        TrainConfig {
            iterations: 1000,
            batch_size: 4,
            learning_rate: 1e-3,
            final_learning_rate: None,
            seed: 0,
            validate_every: 100,
            checkpoint_every: 100,
            train_corruption: Corruption::none(),
            val_corruption: Corruption::none(),
        }
    }
}

impl TrainConfig {
    /// Checks the values.
    pub fn validate(&self) -> Result<()> {
        let bad = |m: &str| Err(LearnError::InvalidInput(format!("training config: {m}")));
        if self.iterations == 0 || self.batch_size == 0 {
            return bad("iterations and batch_size (`augsim train --iterations`, `--batch`) must be at least 1");
        }
        if self.validate_every == 0 || self.checkpoint_every == 0 {
            return bad("validate_every and checkpoint_every (`augsim train --validate-every`) must be at least 1");
        }
        if !(self.learning_rate > 0.0 && self.learning_rate.is_finite()) {
            return bad("learning_rate (`augsim train --lr`) must be finite and > 0");
        }
        if self.final_learning_rate.is_some_and(|r| !(r > 0.0 && r <= self.learning_rate)) {
            return bad("final_learning_rate (`--final-lr`) must be > 0 and at most learning_rate (`--lr`)");
        }
        self.train_corruption.validate()?;
        self.val_corruption.validate()
    }

    /// Samples per step on a training set of `samples`: [`TrainConfig::batch_size`], at most
    /// the whole set.
    pub fn batch_for(&self, samples: usize) -> usize {
        self.batch_size.min(samples)
    }

    /// The learning rate of (0-based) iteration `it`.
    pub fn learning_rate_at(&self, it: usize) -> f64 {
        match self.final_learning_rate {
            None => self.learning_rate,
            Some(last) => {
                let t = it as f64 / (self.iterations.max(2) - 1) as f64;
                last + 0.5 * (self.learning_rate - last) * (1.0 + (std::f64::consts::PI * t.min(1.0)).cos())
            }
        }
    }
}

/// Where the network starts from.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum Initialization {
    /// A new network with seeded random weights.
    Scratch {
        /// Network configuration.
        unet: UNetConfig,
        /// Input/target scales (e.g. [`Normalization::from_statistics`] of the manifest).
        normalization: Normalization,
        /// Unit of the inputs (forces or displacements).
        input_unit: FieldUnit,
    },
    /// Transfer learning from a saved model (its configuration, weights, normalisation and units).
    FineTune {
        /// The model JSON file.
        model: PathBuf,
        /// Keep the contracting path (encoder levels, down-sampling, bottleneck) fixed.
        freeze_encoder: bool,
    },
}

/// Run options that do not change the result.
#[derive(Clone, Debug)]
pub struct TrainOptions {
    /// Output directory.
    pub out_dir: PathBuf,
    /// Continue from `out_dir/checkpoint.bin` if it exists (it must be from the same setup).
    pub resume: bool,
    /// Stop after this iteration as if interrupted (checkpoint written, no model file); a later
    /// run with `resume` continues. For time-sliced training and tests.
    pub stop_after: Option<usize>,
    /// Where the training grid lies in space (e.g. from
    /// [`Manifest::placement`](crate::Manifest::placement)), recorded in the model for
    /// point-cloud prediction.
    pub placement: Option<GridPlacement>,
    /// The samples of the training data's source held out for testing, recorded in the model
    /// beside the training and validation samples (e.g. [`Split::test`]).
    pub test: IndexSet,
    /// Where the network is trained and validated (the same result up to rounding).
    pub compute: Compute,
}

impl TrainOptions {
    /// Options writing to `out_dir`, resuming if possible, without placement or recorded test
    /// samples, on the CPU.
    pub fn new(out_dir: impl Into<PathBuf>) -> Self {
        TrainOptions {
            out_dir: out_dir.into(),
            resume: true,
            stop_after: None,
            placement: None,
            test: IndexSet::default(),
            compute: Compute::Cpu,
        }
    }
}

/// What [`train`] returns.
#[derive(Debug)]
pub struct TrainOutcome {
    /// The best model (on the inference device); saved as `model.json` when `completed`.
    pub model: TrainedModel,
    /// The learning curve.
    pub curve: Vec<CurveRow>,
    /// Iterations done (including those of a resumed checkpoint).
    pub iterations_done: usize,
    /// Whether all iterations ran (false after `stop_after`, or when interrupted:
    /// [`fem::interrupt`]).
    pub completed: bool,
    /// Path of the model JSON (written only when `completed`).
    pub model_path: PathBuf,
    /// Mean wall time of one training step in this run (s); 0 when it ran none (resumed after
    /// the last).
    pub mean_step_seconds: f64,
}

/// Names of the files in the output directory.
pub use crate::model::MODEL_FILE;
/// Checkpoint file name.
pub const CHECKPOINT_FILE: &str = "checkpoint.bin";
/// The checkpoint the PyTorch trainer (`python -m augsim.train`) writes in its model folder.
pub const TORCH_CHECKPOINT_FILE: &str = "checkpoint.pt";
/// Learning-curve CSV file name.
pub const CURVE_CSV: &str = "curve.csv";

/// The resolved starting point, beside its network.
struct Start {
    config: UNetConfig,
    normalization: Normalization,
    input_unit: FieldUnit,
    target_unit: FieldUnit,
    fine_tuned_from: Option<String>,
    freeze: bool,
    /// The splits of the model fine-tuned from.
    pretraining: Vec<Split>,
}

fn resolve_start(init: &Initialization, seed: u64) -> Result<(UNet, Start)> {
    match init {
        Initialization::Scratch { unet, normalization, input_unit } => {
            normalization.validate()?;
            let start = Start {
                config: unet.clone(),
                normalization: *normalization,
                input_unit: *input_unit,
                target_unit: FieldUnit::Metre,
                fine_tuned_from: None,
                freeze: false,
                pretraining: Vec::new(),
            };
            Ok((UNet::new(unet, seed)?, start))
        }
        Initialization::FineTune { model, freeze_encoder } => {
            let pre = TrainedModel::load(model)?;
            let net = if *freeze_encoder { pre.net.freeze_encoder() } else { pre.net };
            let start = Start {
                config: pre.config,
                normalization: pre.normalization,
                input_unit: pre.input_unit,
                target_unit: pre.target_unit,
                fine_tuned_from: Some(model.display().to_string()),
                freeze: *freeze_encoder,
                pretraining: pre.training.map(|t| t.splits().cloned().collect()).unwrap_or_default(),
            };
            Ok((net, start))
        }
    }
}

/// The batch positions of one iteration: an endless stream of per-epoch permutations.
struct Shuffler {
    seed: u64,
    n: usize,
    epoch: Option<u64>,
    perm: Vec<usize>,
}

impl Shuffler {
    fn position(&mut self, stream_pos: u64) -> usize {
        let epoch = stream_pos / self.n as u64;
        if self.epoch != Some(epoch) {
            let mut rng = item_rng(self.seed, STREAM_SHUFFLE, epoch);
            self.perm = (0..self.n).collect();
            for i in (1..self.n).rev() {
                let j = rng.random_range(0..=i);
                self.perm.swap(i, j);
            }
            self.epoch = Some(epoch);
        }
        self.perm[(stream_pos % self.n as u64) as usize]
    }
}

/// A normalised batch in the grid layout: inputs and targets `[batch, 3, nx, ny, nz]`, masks
/// `[batch, 1, nx, ny, nz]` as weights.
struct Batch {
    inputs: Vec<f32>,
    targets: Vec<f32>,
    masks: Vec<f32>,
}

/// Builds the normalised batch of the samples at `positions`; `rng_for` gives each slot its
/// own corruption generator.
fn batch(
    samples: &Samples,
    positions: &[usize],
    norm: &Normalization,
    corruption: &Corruption,
    rng_for: impl Fn(usize) -> rand::rngs::StdRng,
) -> Result<Batch> {
    let grid = samples.grid;
    let (f, n) = (grid.field_len(), grid.nodes());
    let b = positions.len();
    let mut out = Batch {
        inputs: Vec::with_capacity(b * f),
        targets: Vec::with_capacity(b * f),
        masks: Vec::with_capacity(b * n),
    };
    let (si, st) = ((1.0 / norm.input_scale) as f32, (1.0 / norm.target_scale) as f32);
    for (slot, &p) in positions.iter().enumerate() {
        let mut input = samples.input(p).to_vec();
        if !corruption.is_identity() {
            corruption.apply(&mut input, grid, &mut rng_for(slot))?;
        }
        out.inputs.extend(input.iter().map(|v| v * si));
        out.targets.extend(samples.target(p).iter().map(|v| v * st));
        out.masks.extend(samples.mask(p).iter().map(|&v| f32::from(v)));
    }
    Ok(out)
}

/// What computes the gradients.
enum GradientEngine {
    /// The hand-written backward pass.
    Backprop,
    /// burn's autodiff on this (autodiff) device.
    #[cfg(feature = "cpu-burn")]
    Autodiff(Device),
}

impl GradientEngine {
    /// The engine of `compute`: an error when it is not built in or not found.
    fn new(compute: Compute) -> Result<GradientEngine> {
        compute.ensure_available()?;
        #[cfg(feature = "cpu-burn")]
        if compute.uses_burn() {
            return Ok(GradientEngine::Autodiff(compute.training_device()?));
        }
        Ok(GradientEngine::Backprop)
    }

    /// The masked MSE loss of `net` on a batch of `batch` samples and its gradients.
    fn loss_and_gradients(&self, net: &UNet, b: &Batch, batch: usize, grid: GridShape) -> Result<(f64, Gradients)> {
        match self {
            GradientEngine::Backprop => loss_and_gradients(net, &b.inputs, &b.targets, &b.masks, batch, grid),
            #[cfg(feature = "cpu-burn")]
            GradientEngine::Autodiff(device) => {
                BurnUNet::new(net, device)?.loss_and_gradients(&b.inputs, &b.targets, &b.masks, batch, grid, device)
            }
        }
    }
}

/// Checkpoint metadata (the JSON section of `checkpoint.bin`).
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct CheckpointState {
    format: String,
    version: u32,
    /// Identifies the setup; a resume with a different one is refused.
    fingerprint: serde_json::Value,
    /// Iterations done.
    iteration: usize,
    /// The random state: generators are counter-based on (seed, iteration).
    seed: u64,
    /// Training loss accumulated since the last curve row.
    loss_sum: f64,
    loss_count: usize,
    /// Iteration of the best weights so far (stored in the checkpoint when set).
    best_iteration: Option<usize>,
    best_val: Option<f64>,
    curve: Vec<CurveRow>,
    /// Adam's step count of each parameter (0: no state yet, no moments stored).
    adam_steps: Vec<usize>,
}

const CHECKPOINT_MAGIC: &[u8; 8] = b"AUGSIMCK";
const CHECKPOINT_FORMAT: &str = "augsim-checkpoint";
const CHECKPOINT_VERSION: u32 = 2;

fn write_checkpoint(path: &Path, state: &CheckpointState, net: &UNet, adam: &Adam, best: Option<&UNet>) -> Result<()> {
    let json = serde_json::to_vec(state)
        .map_err(|e| LearnError::model(path, format!("cannot serialize checkpoint state: {e}")))?;
    let names: Vec<String> = net.parameter_names().collect();
    let moments = names.iter().enumerate().zip(&adam.moments).filter_map(|((p, name), m)| {
        m.as_ref().map(|m| {
            let shape = net.parameter_shape(p);
            [
                (format!("adam.moment_1.{name}"), shape.clone(), &m.moment_1[..]),
                (format!("adam.moment_2.{name}"), shape, &m.moment_2[..]),
            ]
        })
    });
    let tensors =
        net.tensors("model.").chain(moments.flatten()).chain(best.into_iter().flat_map(|b| b.tensors("best.")));
    let tensors = write_safetensors(tensors, None)?;
    let mut out = Vec::with_capacity(8 + 16 + json.len() + tensors.len());
    out.extend_from_slice(CHECKPOINT_MAGIC);
    for section in [&json[..], &tensors[..]] {
        out.extend_from_slice(&(section.len() as u64).to_le_bytes());
        out.extend_from_slice(section);
    }
    Ok(write_atomic_bytes(path, &out)?)
}

/// The sections of a checkpoint file.
struct Checkpoint {
    state: CheckpointState,
    /// The safetensors section.
    tensors: Vec<u8>,
}

fn read_checkpoint(path: &Path) -> Result<Checkpoint> {
    let bytes = read(path)?;
    let bad = |m: &str| LearnError::model(path, format!("corrupt checkpoint: {m}"));
    if bytes.len() < 8 || &bytes[..8] != CHECKPOINT_MAGIC {
        return Err(bad("missing AUGSIMCK magic"));
    }
    let mut at = 8;
    let mut sections = Vec::new();
    for _ in 0..2 {
        let len_bytes: [u8; 8] =
            bytes.get(at..at + 8).and_then(|s| s.try_into().ok()).ok_or_else(|| bad("truncated"))?;
        let len = u64::from_le_bytes(len_bytes) as usize;
        at += 8;
        let section = bytes.get(at..at.saturating_add(len)).ok_or_else(|| bad("truncated"))?;
        sections.push(section.to_vec());
        at += len;
    }
    if at != bytes.len() {
        return Err(bad("trailing bytes"));
    }
    let tensors = sections.pop().unwrap_or_default();
    let json = sections.pop().unwrap_or_default();
    let state: CheckpointState = serde_json::from_slice(&json).map_err(|e| bad(&format!("state JSON: {e}")))?;
    if state.format != CHECKPOINT_FORMAT || state.version != CHECKPOINT_VERSION {
        return Err(bad("unknown checkpoint format or version"));
    }
    Ok(Checkpoint { state, tensors })
}

/// Restores the model, Adam's state and the best weights (if recorded) of a checkpoint into
/// `net` and `adam`; returns the best weights.
fn restore(saved: &Checkpoint, net: &mut UNet, adam: &mut Adam, path: &Path) -> Result<Option<UNet>> {
    let bad = |m: String| LearnError::model(path, format!("corrupt checkpoint: {m}"));
    let tensors = SafeTensors::deserialize(&saved.tensors).map_err(|e| bad(format!("tensors: {e}")))?;
    net.load_tensors(&tensors, "model.", path)?;
    let steps = &saved.state.adam_steps;
    if steps.len() != adam.moments.len() {
        return Err(bad(format!("{} Adam states for {} parameters", steps.len(), adam.moments.len())));
    }
    let names: Vec<String> = net.parameter_names().collect();
    for (p, (name, &time)) in names.iter().zip(steps).enumerate() {
        adam.moments[p] = if time == 0 {
            None
        } else {
            let shape = net.parameter_shape(p);
            let moment = |which: &str| read_tensor(&tensors, &format!("adam.{which}.{name}"), &shape).map_err(&bad);
            Some(Moments { time, moment_1: moment("moment_1")?, moment_2: moment("moment_2")? })
        };
    }
    if saved.state.best_iteration.is_none() {
        return Ok(None);
    }
    let mut best = net.clone();
    best.load_tensors(&tensors, "best.", path)?;
    Ok(Some(best))
}

fn indices_hash(samples: &Samples) -> u64 {
    samples.indices.iter().fold(splitmix64(samples.len() as u64), |h, &i| splitmix64(h ^ i))
}

/// The split of a run: `train`, `val` and `test` must be disjoint, and `val` from the source of
/// `train`.
fn held_out_split(train: &Samples, val: &Samples, test: &IndexSet) -> Result<Split> {
    if !val.is_empty() && val.source != train.source {
        return Err(LearnError::InvalidInput(format!(
            "validation samples (source {:?}) and training samples (source {:?}) come from different data",
            val.source, train.source
        )));
    }
    let split = Split {
        source: train.source.clone(),
        train: IndexSet::from_indices(&train.indices),
        validation: IndexSet::from_indices(&val.indices),
        test: test.clone(),
    };
    let overlap = |set: &IndexSet, indices: &[u64], roles: &str| match set.first_common(indices) {
        Some(i) => Err(LearnError::InvalidInput(format!("sample {i} is both a {roles} sample"))),
        None => Ok(()),
    };
    overlap(&split.train, &val.indices, "training and a validation")?;
    overlap(test, &train.indices, "training and a test")?;
    overlap(test, &val.indices, "validation and a test")?;
    Ok(split)
}

/// Fails when a fine-tuning run's `split` tests on samples of the same data that the runs behind
/// the pre-trained network (`pretraining`) trained or validated on, or validates on samples they
/// trained on: its figures would not be held out, and its checkpoint would be chosen on samples
/// the network had learned (sharing the pre-training's validation samples only selects again).
fn check_unseen_by_pretraining(split: &Split, pretraining: &[Split]) -> Result<()> {
    let same = |p: &&Split| crate::data::split::same_source(p.source.as_deref(), split.source.as_deref());
    for pre in pretraining.iter().filter(same) {
        let checks = [
            (&pre.train, &split.test, "a test sample of this run", "trained"),
            (&pre.validation, &split.test, "a test sample of this run", "was validated"),
            (&pre.train, &split.validation, "a validation sample of this run", "trained"),
        ];
        for (theirs, ours, what, role) in checks {
            if let Some(i) = theirs.first_common_with(ours) {
                return Err(LearnError::InvalidInput(format!(
                    "sample {i}, {what}, is one the pre-trained network {role} on: its figures would not be held \
                     out; fine-tune with the split of the pre-training (its test and validation sizes) or on other \
                     data (another seed)"
                )));
            }
        }
    }
    Ok(())
}

/// Trains a U-Net on `train`, validating on `val` (may be empty: then the last weights are
/// kept), reporting the iterations done and the loss to `progress`. See the module documentation
/// for files, reproducibility and resume.
pub fn train(
    train: &Samples,
    val: &Samples,
    init: &Initialization,
    config: &TrainConfig,
    options: &TrainOptions,
    progress: &dyn Progress,
) -> Result<TrainOutcome> {
    config.validate()?;
    if train.is_empty() {
        return Err(LearnError::InvalidInput("no training samples".into()));
    }
    if !val.is_empty() && val.grid != train.grid {
        return Err(LearnError::InvalidInput(format!(
            "validation grid {} differs from training grid {}",
            val.grid, train.grid
        )));
    }
    let split = held_out_split(train, val, &options.test)?;
    let engine = GradientEngine::new(options.compute)?;
    let (mut net, start) = resolve_start(init, config.seed)?;
    check_unseen_by_pretraining(&split, &start.pretraining)?;
    // Made once the settings are known to build a network: a refused run leaves no folder.
    let out = &options.out_dir;
    let _lock = take_model_folder(out)?;
    let mut adam = Adam::new(net.values().len());
    let mut state = CheckpointState::new(config, fingerprint(train, val, init, config)?);
    let mut best: Option<UNet> = None;
    let checkpoint_path = out.join(CHECKPOINT_FILE);
    if options.resume && checkpoint_path.exists() {
        best = resume(&checkpoint_path, config, &mut state, &mut net, &mut adam)?;
        progress.line(&format!(
            "resuming {} at step {} of {}",
            checkpoint_path.display(),
            state.iteration,
            config.iterations
        ));
    }

    // A fine-tuned network must earn its place: the pre-trained one, validated before its first
    // step, is kept when no later validation beats it.
    if state.iteration == 0 && start.fine_tuned_from.is_some() && !val.is_empty() {
        state.validate(&net, val, &start.normalization, config, options.compute)?;
        best = Some(net.clone());
    }
    let total = config.iterations as u64;
    progress.advance(state.iteration as u64, total, "");

    let mut shuffler = Shuffler { seed: config.seed, n: train.len(), epoch: None, perm: Vec::new() };
    let batch_size = config.batch_for(train.len());
    let mut step_time = 0.0;
    let mut steps = 0usize;
    let mut completed = true;
    while state.iteration < config.iterations {
        let it = state.iteration;
        let t0 = Instant::now();
        let first = (it * batch_size) as u64;
        let positions: Vec<usize> = (0..batch_size as u64).map(|b| shuffler.position(first + b)).collect();
        let b = batch(train, &positions, &start.normalization, &config.train_corruption, |slot| {
            item_rng(config.seed, STREAM_TRAIN_CORRUPTION, first + slot as u64)
        })?;
        let (loss_value, grads) = engine.loss_and_gradients(&net, &b, positions.len(), train.grid)?;
        if !loss_value.is_finite() {
            return Err(LearnError::InvalidInput(format!(
                "training diverged at iteration {} (loss {loss_value}); lower the learning rate",
                it + 1
            )));
        }
        adam.step(config.learning_rate_at(it), &mut net, &grads)?;
        step_time += t0.elapsed().as_secs_f64();
        steps += 1;
        state.iteration += 1;
        state.loss_sum += loss_value;
        state.loss_count += 1;
        let mut note = format!("loss {loss_value:.3e}");

        let done = state.iteration == config.iterations;
        if state.iteration.is_multiple_of(config.validate_every) || done {
            let snapshot = net.clone();
            if state.validate(&snapshot, val, &start.normalization, config, options.compute)? {
                best = Some(snapshot);
            }
            write_curve_csv(&out.join(CURVE_CSV), &state.curve)?;
            if let Some(e) = state.curve.last().and_then(|row| row.val) {
                note = format!("loss {loss_value:.3e} val {:.4} mm", mesh::length::mm(e.mean));
            }
        }
        progress.advance(state.iteration as u64, total, &note);
        // Asked for, or interrupted (Ctrl-C: `fem::interrupt`): checkpointed, returned unfinished.
        let stop =
            (options.stop_after.is_some_and(|s| state.iteration >= s) || fem::interrupt::check().is_err()) && !done;
        if state.iteration.is_multiple_of(config.checkpoint_every) || done || stop {
            state.adam_steps = adam.moments.iter().map(|m| m.as_ref().map_or(0, |m| m.time)).collect();
            write_checkpoint(&checkpoint_path, &state, &net, &adam, best.as_ref())?;
        }
        if stop {
            completed = false;
            break;
        }
    }

    let model = trained_model(start, best.unwrap_or(net), train, val, config, options, &state, split);
    let model_path = out.join(MODEL_FILE);
    if completed {
        model.save(&model_path)?;
    }
    if !state.curve.is_empty() {
        write_curve_csv(&out.join(CURVE_CSV), &state.curve)?;
    }
    Ok(TrainOutcome {
        model,
        curve: state.curve,
        iterations_done: state.iteration,
        completed,
        model_path,
        mean_step_seconds: if steps > 0 { step_time / steps as f64 } else { 0.0 },
    })
}

/// Makes a training's folder `out` and locks it for this run, until the lock drops (a second run
/// there, of `augsim train` or `python -m augsim.train`, is refused); what a killed run left
/// half-written there goes: the run resumes from its last checkpoint.
pub fn take_model_folder(out: &Path) -> Result<WriterLock> {
    mesh::io::create_folder(out)?;
    let lock = lock_for_writing(out, TRAINERS)?;
    mesh::io::remove_stale_temporaries(out);
    Ok(lock)
}

/// Who writes a model's folder, and why a second writer is refused (see [`lock_for_writing`]).
const TRAINERS: &str = "(`augsim train`, `python -m augsim.train`): two trainings would mix their checkpoints, \
                        and one's model would replace the other's";

/// Everything that shapes the trajectory, so that a checkpoint is only resumed into the run it
/// came from. The checkpoint interval is left out, and so is the iteration count under a constant
/// rate: such a finished run can be extended by resuming it with more.
fn fingerprint(
    train: &Samples,
    val: &Samples,
    init: &Initialization,
    config: &TrainConfig,
) -> Result<serde_json::Value> {
    let mut trajectory = serde_json::to_value(config)
        .map_err(|e| LearnError::InvalidInput(format!("cannot serialize the training config: {e}")))?;
    if let Some(map) = trajectory.as_object_mut() {
        if config.final_learning_rate.is_none() {
            map.remove("iterations");
        }
        map.remove("checkpoint_every");
    }
    Ok(serde_json::json!({
        "config": trajectory,
        "init": init,
        "grid": train.grid,
        "train": [train.len(), indices_hash(train)],
        "val": [val.len(), indices_hash(val)],
    }))
}

/// Resumes from the checkpoint at `path` into `state`, `net` and `adam`: it must be of the same
/// setup (`state`'s fingerprint) and not beyond the iterations asked for. Returns the best
/// weights it holds.
fn resume(
    path: &Path,
    config: &TrainConfig,
    state: &mut CheckpointState,
    net: &mut UNet,
    adam: &mut Adam,
) -> Result<Option<UNet>> {
    let saved = read_checkpoint(path)?;
    if saved.state.fingerprint != state.fingerprint {
        let differences = crate::data::dataset::json_differences(&saved.state.fingerprint, &state.fingerprint);
        return Err(LearnError::model(
            path,
            format!(
                "checkpoint is from a different setup ({}); use another output directory, or start afresh without \
                 resuming (`augsim train --restart`)",
                differences.join("; ")
            ),
        ));
    }
    let best = restore(&saved, net, adam, path)?;
    *state = saved.state;
    if state.iteration > config.iterations {
        return Err(LearnError::model(
            path,
            format!(
                "checkpoint is at iteration {}, beyond the {} iterations asked for",
                state.iteration, config.iterations
            ),
        ));
    }
    Ok(best)
}

impl CheckpointState {
    /// The state of a run that has not started.
    fn new(config: &TrainConfig, fingerprint: serde_json::Value) -> CheckpointState {
        CheckpointState {
            format: CHECKPOINT_FORMAT.into(),
            version: CHECKPOINT_VERSION,
            fingerprint,
            iteration: 0,
            seed: config.seed,
            loss_sum: 0.0,
            loss_count: 0,
            best_iteration: None,
            best_val: None,
            curve: Vec::new(),
            adam_steps: Vec::new(),
        }
    }

    /// Validates `net` on `val` (when there are validation samples), adds the learning curve's
    /// row and restarts the loss sums; returns whether `net` is the best so far (always, without
    /// validation samples).
    fn validate(
        &mut self,
        net: &UNet,
        val: &Samples,
        normalization: &Normalization,
        config: &TrainConfig,
        compute: Compute,
    ) -> Result<bool> {
        let val_error = if val.is_empty() {
            None
        } else {
            let predictor = Predictor::from_net(net, compute, *normalization, val.grid)?;
            let report =
                evaluate_net(|x| predictor.predict(x), val, &config.val_corruption, config.seed, |_, _| Ok(()))?;
            Some(report.stats)
        };
        self.curve.push(CurveRow {
            iteration: self.iteration,
            train_loss: (self.loss_count > 0).then(|| self.loss_sum / self.loss_count as f64),
            val: val_error,
        });
        self.loss_sum = 0.0;
        self.loss_count = 0;
        let val_mean = val_error.map(|v| v.mean);
        let improved = match (val_mean, self.best_val) {
            (None, _) => true,
            (Some(e), Some(b)) => e < b,
            (Some(_), None) => true,
        };
        if improved {
            self.best_val = val_mean;
            self.best_iteration = Some(self.iteration);
        }
        Ok(improved)
    }
}

/// The model trained from `start` to `state`, with the weights `net`.
#[allow(clippy::too_many_arguments)]
fn trained_model(
    start: Start,
    net: UNet,
    train: &Samples,
    val: &Samples,
    config: &TrainConfig,
    options: &TrainOptions,
    state: &CheckpointState,
    split: Split,
) -> TrainedModel {
    TrainedModel {
        config: start.config,
        normalization: start.normalization,
        grid: train.grid,
        placement: options.placement,
        input_unit: start.input_unit,
        target_unit: start.target_unit,
        training: Some(TrainingInfo {
            iterations: state.iteration,
            best_iteration: state.best_val.and(state.best_iteration),
            best_val_mean_error: state.best_val,
            train_samples: train.len(),
            val_samples: val.len(),
            seed: config.seed,
            fine_tuned_from: start.fine_tuned_from,
            frozen_encoder: start.freeze,
            corruption: config.train_corruption.clone(),
            split,
            pretraining: start.pretraining,
            schedule: Some(Schedule {
                batch_size: config.batch_for(train.len()),
                learning_rate: config.learning_rate,
                final_learning_rate: config.final_learning_rate,
                validate_every: config.validate_every,
            }),
        }),
        net,
    }
}
