//! Learning commands: `generate`, `merge`, `train`, `eval`, `predict`.

use std::path::{Path, PathBuf};

use anyhow::Result;
use app::evaluation::{evaluate_held_out, write_evaluation};
use app::generation::GenerateArgs;
use app::prediction::predict_file;
use app::training::{fit_rom, rom_lines, train_unet, UNetRun, UNetStart};

use learn::rom::RomConfig;
use learn::LearnedModel;
use learn::{Compute, Corruption, Dataset, Method, Model, Sparsity, SplitPolicy, TrainConfig, UNetConfig};
use mesh::length::mm;

use crate::bar::Bar;

/// `augsim generate`.
pub fn generate(args: &GenerateArgs) -> Result<()> {
    let bar = Bar::new("samples", "");
    let lines = app::generation::generate(args, &bar);
    bar.finish();
    lines?.iter().for_each(|l| println!("{l}"));
    Ok(())
}

/// `augsim merge`.
pub fn merge(out: &Path, parts: &[PathBuf]) -> Result<()> {
    let manifest = learn::merge_datasets(parts, out, None)?;
    println!(
        "merged {} parts: {} samples, {} failed → {}",
        parts.len(),
        manifest.num_samples,
        manifest.failed.len(),
        out.display()
    );
    Ok(())
}

/// Input corruption, shared by `train` (training and validation inputs) and `eval`.
#[derive(Debug, Clone, clap::Args)]
pub struct CorruptionArgs {
    /// Keep a random visible patch of between MIN and MAX input nodes (e.g. 13,114).
    #[arg(long, value_name = "MIN,MAX", value_parser = node_range)]
    pub sparse: Option<(usize, usize)>,
    /// Additive Gaussian noise on the visible input nodes: standard deviation in the input unit.
    #[arg(long, default_value_t = 0.0)]
    pub noise: f64,
}

/// Parses `MIN,MAX`, two node counts (their order is checked with the other corruption settings).
fn node_range(text: &str) -> Result<(usize, usize), String> {
    let parse = |s: &str| s.trim().parse::<usize>().map_err(|e| format!("'{s}' is not a node count: {e}"));
    let (min, max) = text.split_once(',').ok_or_else(|| format!("expected MIN,MAX (e.g. 13,114), got '{text}'"))?;
    Ok((parse(min)?, parse(max)?))
}

impl CorruptionArgs {
    fn corruption(&self) -> Corruption {
        Corruption {
            sparsity: self.sparse.map(|(min_nodes, max_nodes)| Sparsity::Patch { min_nodes, max_nodes }),
            noise_std: self.noise,
        }
    }
}

/// How `train` splits the dataset (by generation index: the last uniform samples are the test set,
/// the ones before them the validation set, the rest and every σ-chosen draw the training set); see
/// [`SplitPolicy`].
#[derive(Debug, Clone, clap::Args)]
pub struct SplitArgs {
    /// Fraction of the dataset's uniform draws held out as the test set (its last ones).
    #[arg(long, default_value_t = 0.2)]
    pub test_fraction: f64,
    /// Number of test samples; overrides --test-fraction.
    #[arg(long)]
    pub test_samples: Option<usize>,
    /// Fraction of the dataset's uniform draws used for validation (checkpoint selection): those
    /// before the test set.
    #[arg(long, default_value_t = 0.1)]
    pub validation_fraction: f64,
    /// Number of validation samples; overrides --validation-fraction.
    #[arg(long)]
    pub validation_samples: Option<usize>,
    /// Use only the first N training samples (e.g. 100 for transfer learning).
    #[arg(long)]
    pub train_samples: Option<usize>,
}

impl SplitArgs {
    fn policy(&self) -> SplitPolicy {
        SplitPolicy {
            test_fraction: self.test_fraction,
            test_samples: self.test_samples,
            validation_fraction: self.validation_fraction,
            validation_samples: self.validation_samples,
            train_samples: self.train_samples,
        }
    }
}

/// Options of `augsim train`.
#[derive(Debug, clap::Args)]
pub struct TrainArgs {
    /// Dataset directory (from `augsim generate`).
    pub dataset: PathBuf,
    /// Output directory: the model directory (model.json and its arrays for `rom`; model.json,
    /// model.safetensors, checkpoint.bin, curve.csv, curve.png for `unet`).
    #[arg(short, long)]
    pub out: PathBuf,
    /// `unet` (the published 3D U-Net, trained by Adam) or `rom` (a reduced-order model: POD
    /// basis and Gaussian-process regression, fitted in seconds).
    #[arg(long, default_value = "unet")]
    pub method: Method,
    /// ROM: most POD modes (the number used is chosen on validation).
    #[arg(long, default_value_t = RomConfig::default().max_modes)]
    pub modes: usize,
    /// ROM: corrupted copies of each training sample (with --noise / --sparse) in the regression's
    /// training set.
    #[arg(long, default_value_t = 0)]
    pub noise_copies: usize,
    /// ROM: most inducing points (above this many training samples the regression is a Nyström
    /// approximation).
    #[arg(long, default_value_t = RomConfig::default().max_inducing)]
    pub inducing: usize,
    /// ROM, force inputs: the linear-elastic response at rest of the dataset's scenario (its file
    /// or built-in name) as a physics prior; the regression learns what it leaves.
    #[arg(long)]
    pub prior: Option<PathBuf>,
    /// Optimiser steps.
    #[arg(long, default_value_t = 2000)]
    pub iterations: usize,
    /// Samples per step.
    #[arg(long, default_value_t = 4)]
    pub batch: usize,
    /// Adam learning rate.
    #[arg(long, default_value_t = 1e-3)]
    pub lr: f64,
    /// Let the learning rate fall to this value along a half cosine over the iterations.
    #[arg(long)]
    pub final_lr: Option<f64>,
    /// Channels of the first U-Net level.
    #[arg(long, default_value_t = 16)]
    pub channels: usize,
    /// Down-sampling steps of the U-Net.
    #[arg(long, default_value_t = 3)]
    pub depth: usize,
    /// Fine-tune this pre-trained model (model.json) instead of starting from scratch.
    #[arg(long)]
    pub init: Option<PathBuf>,
    /// With --init: keep the encoder fixed.
    #[arg(long)]
    pub freeze_encoder: bool,
    /// Validate (and keep the best model) every K steps.
    #[arg(long, default_value_t = 100)]
    pub validate_every: usize,
    /// Seed of weights, batches and corruption.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Start afresh instead of resuming from out/checkpoint.bin.
    #[arg(long)]
    pub restart: bool,
    /// Train / validation / test split.
    #[command(flatten)]
    pub split: SplitArgs,
    /// Input corruption.
    #[command(flatten)]
    pub corruption: CorruptionArgs,
    /// Where the network trains.
    #[command(flatten)]
    pub device: DeviceArgs,
}

/// `--device`: where the network runs.
#[derive(Debug, Clone, Copy, clap::Args)]
pub struct DeviceArgs {
    /// `cpu` (the repacked CPU engines, fastest on a CPU), `gpu` (burn on a GPU through wgpu: Vulkan,
    /// Metal or DX12; needs a build with `--features gpu`) or `cpu-burn` (burn's own kernels on the CPU: the GPU's code
    /// path, slower; needs a build with `--features cpu-burn`).
    #[arg(long = "device", default_value = "cpu")]
    pub compute: Compute,
}

impl DeviceArgs {
    /// Checks the device and prints which it is.
    fn announce(self) -> Result<Compute> {
        println!("device     {}", self.compute.describe()?);
        Ok(self.compute)
    }
}

/// `augsim train`.
pub fn train(args: &TrainArgs) -> Result<()> {
    let dataset = Dataset::open(&args.dataset)?;
    let all = dataset.load_all()?;
    let (split, [train, validation, test]) = args.split.policy().apply(&all)?;
    println!(
        "split      {} training, {} validation, {} test samples (held out, recorded in the model); grid {}",
        train.len(),
        validation.len(),
        test.len(),
        dataset.manifest().grid
    );
    if args.method == Method::Rom {
        return train_rom(args, &dataset, split, [train, validation]);
    }
    let compute = args.device.announce()?;
    let start = match &args.init {
        Some(model) => UNetStart::FineTune { model: model.clone(), freeze_encoder: args.freeze_encoder },
        None => {
            UNetStart::Scratch(UNetConfig { base_channels: args.channels, depth: args.depth, ..UNetConfig::default() })
        }
    };
    let config = TrainConfig {
        iterations: args.iterations,
        batch_size: args.batch,
        learning_rate: args.lr,
        final_learning_rate: args.final_lr,
        seed: args.seed,
        validate_every: args.validate_every,
        checkpoint_every: args.validate_every,
        train_corruption: args.corruption.corruption(),
        val_corruption: args.corruption.corruption(),
    };
    let run = UNetRun { out: args.out.clone(), resume: !args.restart, compute };
    let bar = Bar::new("steps", "");
    let outcome = train_unet(&dataset, &split, [&train, &validation], start, &config, run, &bar);
    bar.finish();
    let outcome = outcome?;
    println!("steps      {} ({:.3} s per step)", outcome.iterations_done, outcome.mean_step_seconds);
    if let Some((it, Some(e))) = outcome.model.training.as_ref().map(|t| (t.best_iteration, t.best_val_mean_error)) {
        println!("best       validation mean e = {:.4} mm at iteration {it}", mm(e));
    }
    println!("wrote      {}", outcome.model_path.display());
    Ok(())
}

/// `augsim train --method rom`.
fn train_rom(args: &TrainArgs, dataset: &Dataset, split: learn::Split, samples: [learn::Samples; 2]) -> Result<()> {
    let config = RomConfig {
        max_modes: args.modes,
        max_inducing: args.inducing,
        noise_copies: args.noise_copies,
        corruption: args.corruption.corruption(),
        seed: args.seed,
        ..RomConfig::default()
    };
    let (model, report) = fit_rom(dataset, split, samples, &config, args.prior.as_deref(), &args.out)?;
    rom_lines(&model, &report).iter().for_each(|l| println!("{l}"));
    println!("wrote      {}", args.out.join(learn::MODEL_FILE).display());
    Ok(())
}

/// `augsim eval`: errors on the samples held out from the model (its recorded test split of
/// the dataset it was trained on, or every unseen sample of another dataset), per-sample CSV and
/// the worst sample as VTK.
pub fn eval(
    model_path: &Path,
    dataset_dir: &Path,
    project: Option<&Path>,
    corruption: &CorruptionArgs,
    device: DeviceArgs,
    out: &Path,
) -> Result<()> {
    let compute = device.announce()?;
    let model = Model::load(model_path)?;
    let dataset = Dataset::open(dataset_dir)?;
    match project {
        Some(basis) => {
            let projected = learn::Projected::new(model, &Model::load(basis)?)?;
            println!("projected  on the basis of {} ({} modes)", basis.display(), projected.basis.info.modes);
            evaluate_model(&projected, model_path, &dataset, dataset_dir, corruption, compute, out)
        }
        None => evaluate_model(&model, model_path, &dataset, dataset_dir, corruption, compute, out),
    }
}

/// The body of `augsim eval` for a loaded model: evaluates, prints and writes.
fn evaluate_model(
    model: &impl LearnedModel,
    model_path: &Path,
    dataset: &Dataset,
    dataset_dir: &Path,
    corruption: &CorruptionArgs,
    compute: Compute,
    out: &Path,
) -> Result<()> {
    let corruption = corruption.corruption();
    let e = evaluate_held_out(model, dataset, dataset_dir, &corruption, compute)?;
    e.lines().iter().for_each(|l| println!("{l}"));
    let [errors, summary, vtu] = write_evaluation(out, model, model_path, dataset, &e, compute)?;
    println!("wrote      {}, {}, {}", errors.display(), summary.display(), vtu.display());
    Ok(())
}

/// `augsim predict`: a grid tensor (.npy `[3, nx, ny, nz]`) or a point cloud (.csv or .npy
/// `[N, 6]`: x, y, z and the vector in the model's input unit) to a displacement tensor, timed;
/// with `mesh`, the displacement interpolated to that mesh's nodes is written beside the tensor.
pub fn predict(
    model_path: &Path,
    input: &Path,
    output: &Path,
    mesh_path: Option<&Path>,
    runs: usize,
    device: DeviceArgs,
) -> Result<()> {
    let compute = device.announce()?;
    predict_file(model_path, input, output, mesh_path, runs, compute)?.iter().for_each(|l| println!("{l}"));
    Ok(())
}
