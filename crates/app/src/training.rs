//! A model trained on a dataset's split, as `augsim train` trains it (its arguments, with those
//! of the input corruption and the device that `eval` and `predict` share): a U-Net (from
//! scratch or fine-tuned, with its learning curve), or a reduced-order model and its fit in words.

use std::path::{Path, PathBuf};

use anyhow::{bail, ensure, Result};
use learn::rom::{ReducedModel, RomConfig, RomReport};
use learn::{
    Compute, Corruption, Dataset, Initialization, Manifest, Method, Normalization, Progress, Samples, Sparsity, Split,
    SplitPolicy, TrainConfig, TrainOptions, TrainOutcome, UNetConfig,
};
use mesh::length::mm;
use scenario::DatasetScenario;

/// Input corruption, shared by `train` (training and validation inputs) and `eval`.
#[derive(Debug, Clone, clap::Args)]
pub struct CorruptionArgs {
    /// Keep a random visible patch of between MIN and MAX input nodes (e.g. 13,114), MAX at most
    /// the samples' input nodes.
    #[arg(long, value_name = "MIN,MAX", value_parser = node_range)]
    pub sparse: Option<(usize, usize)>,
    /// Additive Gaussian noise on the visible input nodes: standard deviation in the input unit.
    #[arg(long, default_value_t = 0.0, value_parser = crate::values::non_negative)]
    pub noise: f64,
}

/// Parses `MIN,MAX`, two node counts (their order is checked with the other corruption settings).
fn node_range(text: &str) -> Result<(usize, usize), String> {
    let parse = |s: &str| s.trim().parse::<usize>().map_err(|e| format!("'{s}' is not a node count: {e}"));
    let (min, max) = text.split_once(',').ok_or_else(|| format!("expected MIN,MAX (e.g. 13,114), got '{text}'"))?;
    Ok((parse(min)?, parse(max)?))
}

impl CorruptionArgs {
    /// The corruption asked for.
    pub fn corruption(&self) -> Corruption {
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
    #[arg(long, default_value_t = SplitPolicy::default().test_fraction)]
    pub test_fraction: f64,
    /// Number of test samples; overrides --test-fraction.
    #[arg(long)]
    pub test_samples: Option<usize>,
    /// Fraction of the dataset's uniform draws used for validation (checkpoint selection): those
    /// before the test set.
    #[arg(long, default_value_t = SplitPolicy::default().validation_fraction)]
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
    #[arg(long, default_value_t = UNET_DEFAULTS.iterations)]
    pub iterations: usize,
    /// Samples per step (at most the training samples).
    #[arg(long, default_value_t = UNET_DEFAULTS.batch)]
    pub batch: usize,
    /// Adam learning rate.
    #[arg(long, default_value_t = UNET_DEFAULTS.lr)]
    pub lr: f64,
    /// Let the learning rate fall to this value along a half cosine over the iterations.
    #[arg(long)]
    pub final_lr: Option<f64>,
    /// Channels of the first U-Net level [default: 16; with --init, the pre-trained network's].
    #[arg(long)]
    pub channels: Option<usize>,
    /// Down-sampling steps of the U-Net [default: 3; with --init, the pre-trained network's].
    #[arg(long)]
    pub depth: Option<usize>,
    /// Fine-tune this pre-trained U-Net (its directory or model.json; trained on inputs of the
    /// dataset's kind) instead of starting from scratch.
    #[arg(long)]
    pub init: Option<PathBuf>,
    /// With --init: keep the encoder fixed.
    #[arg(long, requires = "init")]
    pub freeze_encoder: bool,
    /// Validate (and keep the best model) every K steps.
    #[arg(long, default_value_t = UNET_DEFAULTS.validate_every)]
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

/// The U-Net's training settings of `augsim train` by default.
struct UNetDefaults {
    iterations: usize,
    batch: usize,
    lr: f64,
    validate_every: usize,
}

const UNET_DEFAULTS: UNetDefaults = UNetDefaults { iterations: 2000, batch: 4, lr: 1e-3, validate_every: 100 };

impl TrainArgs {
    /// The options given that the chosen method does not use, by flag: a U-Net's training
    /// settings for a reduced-order model, a reduced-order model's for a U-Net.
    fn unused_options(&self) -> Vec<&'static str> {
        let (d, rom) = (&UNET_DEFAULTS, RomConfig::default());
        let given = match self.method {
            Method::Rom => vec![
                ("--iterations", self.iterations != d.iterations),
                ("--batch", self.batch != d.batch),
                ("--lr", self.lr != d.lr),
                ("--final-lr", self.final_lr.is_some()),
                ("--channels", self.channels.is_some()),
                ("--depth", self.depth.is_some()),
                ("--init", self.init.is_some()),
                ("--validate-every", self.validate_every != d.validate_every),
                ("--restart", self.restart),
                ("--device", self.device.compute != learn::Compute::Cpu),
            ],
            Method::UNet => vec![
                ("--modes", self.modes != rom.max_modes),
                ("--noise-copies", self.noise_copies != rom.noise_copies),
                ("--inducing", self.inducing != rom.max_inducing),
                ("--prior", self.prior.is_some()),
            ],
        };
        given.into_iter().filter(|(_, given)| *given).map(|(flag, _)| flag).collect()
    }
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
    /// The device, checked, and which it is in a line.
    pub fn described(self) -> Result<(Compute, String)> {
        Ok((self.compute, format!("device     {}", self.compute.describe()?)))
    }

    /// [`described`](Self::described) for the model at `model` (its directory or model.json): a
    /// reduced-order model runs on the CPU, whatever the device.
    pub fn described_for(self, model: &Path) -> Result<(Compute, String)> {
        match learn::Model::kind(&learn::Model::json_path(model))? {
            Method::Rom => Ok((self.compute, "device     cpu (a reduced-order model: no network to run)".into())),
            Method::UNet => self.described(),
        }
    }
}

/// Refuses a folder a model of `method` cannot be trained into: one that holds a dataset, or a
/// model of the other kind; for a reduced-order model, whose fit is made anew, any model (a U-Net's
/// run resumes from its checkpoint).
pub fn check_model_folder(out: &Path, method: Method) -> Result<()> {
    if out.join(learn::data::dataset::MANIFEST_FILE).exists() {
        bail!(
            "{} holds a dataset ({}): a model written there would mix their files; give another --out",
            out.display(),
            learn::data::dataset::MANIFEST_FILE
        );
    }
    let other = match method {
        Method::Rom => [learn::WEIGHTS_FILE, learn::training::train::CHECKPOINT_FILE, learn::MODEL_FILE]
            .into_iter()
            .find(|f| out.join(f).exists()),
        Method::UNet => Some(learn::rom::BASIS_FILE).filter(|f| out.join(f).exists()),
    };
    if let Some(file) = other {
        let (held, this) = match method {
            Method::Rom if file == learn::MODEL_FILE => ("a model", "a new fit"),
            Method::Rom => ("a U-Net", "a reduced-order model"),
            Method::UNet => ("a reduced-order model", "a U-Net"),
        };
        bail!(
            "{} holds {held} ({file}): {this} written there would replace or mix with its files; give another --out",
            out.display()
        );
    }
    Ok(())
}

/// Trains what `augsim train` asks for on its dataset's split: a U-Net (resumed from its
/// checkpoint unless `restart`) or a reduced-order model. Tells `progress` the split and the
/// device in lines, and the training's advance; returns the outcome in lines.
pub fn train(args: &TrainArgs, progress: &dyn Progress) -> Result<Vec<String>> {
    let unused = args.unused_options();
    if !unused.is_empty() {
        let (this, other) = match args.method {
            Method::Rom => ("a reduced-order model (--method rom)", "a U-Net's"),
            Method::UNet => ("a U-Net (--method unet, the default)", "a reduced-order model's (--method rom)"),
        };
        let (are, them) = if unused.len() == 1 { ("is", "it") } else { ("are", "them") };
        bail!("{} {are} {other}: {this} does not use {them}", unused.join(", "));
    }
    check_model_folder(&args.out, args.method)?;
    let torch = learn::training::train::TORCH_CHECKPOINT_FILE;
    if args.out.join(torch).exists() {
        bail!(
            "{} holds a training in PyTorch ({torch}): `augsim train` would replace its model; give another --out, \
             or resume it with `python -m augsim.train`",
            args.out.display()
        );
    }
    // A U-Net's settings are checked before its dataset is read.
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
    if args.method == Method::UNet {
        config.validate()?;
    }
    if let Some(init) = &args.init {
        check_init_shape(args, init)?;
    }
    let dataset = Dataset::open_with_samples(&args.dataset)?;
    let manifest = dataset.manifest();
    if !manifest.complete {
        progress.line(&format!(
            "warning    the dataset is unfinished ({} draws held: its generation or merge was stopped, or runs now): \
             the model learns from these alone; the same `augsim generate` (or `augsim merge`) finishes it",
            manifest.num_samples
        ));
    }
    args.corruption.corruption().check_scale(manifest.statistics.inputs.rms_norm, manifest.units.input)?;
    let all = dataset.load_all()?;
    let (split, [train, validation, test]) = args.split.policy().apply(&all)?;
    args.corruption.corruption().check_sparsity(&train)?;
    progress.line(&format!(
        "split      {} training, {} validation, {} test samples (held out, recorded in the model); grid {}",
        train.len(),
        validation.len(),
        test.len(),
        manifest.grid
    ));
    if args.method == Method::Rom {
        return train_rom(args, &dataset, split, [train, validation]);
    }
    if validation.is_empty() {
        progress.line(
            "warning    no validation sample: nothing selects a checkpoint, and the last iteration's weights are kept \
             (give --validation-samples, or more data)",
        );
    }
    let (compute, device) = args.device.described()?;
    progress.line(&device);
    let net = UNetConfig::default();
    let start = match &args.init {
        Some(model) => UNetStart::FineTune { model: model.clone(), freeze_encoder: args.freeze_encoder },
        None => UNetStart::Scratch(UNetConfig {
            base_channels: args.channels.unwrap_or(net.base_channels),
            depth: args.depth.unwrap_or(net.depth),
            ..net
        }),
    };
    if config.batch_for(train.len()) < args.batch {
        progress.line(&format!(
            "batch      {} samples per step: the whole training set (--batch {} is more than it holds)",
            train.len(),
            args.batch
        ));
    }
    let run = UNetRun { out: args.out.clone(), resume: !args.restart, compute };
    let outcome = train_unet(&dataset, &split, [&train, &validation], start, &config, run, progress)?;
    let pace = match outcome.mean_step_seconds {
        0.0 => "already trained: no step run now".to_string(),
        seconds => format!("{seconds:.3} s per step"),
    };
    let mut lines = vec![format!("steps      {} ({pace})", outcome.iterations_done)];
    match outcome.model.training.as_ref().map(|t| (t.best_iteration, t.best_val_mean_error)) {
        Some((Some(it), Some(e))) => {
            let kept = if it == 0 { " (the pre-trained network, kept: no step improved on it)" } else { "" };
            lines.push(format!("best       validation mean e = {:.4} mm at iteration {it}{kept}", mm(e)));
        }
        _ => lines.push("kept       the last iteration's weights (no validation sample chose them)".into()),
    }
    lines.push(format!("wrote      {}", outcome.model_path.display()));
    Ok(lines)
}

/// Refuses `--channels` or `--depth` given with `--init` that differ from the pre-trained network
/// (`init`, a model's directory or `model.json`): a fine-tuned network keeps its architecture.
fn check_init_shape(args: &TrainArgs, init: &Path) -> Result<()> {
    let json = learn::Model::json_path(init);
    if args.channels.is_none() && args.depth.is_none() || learn::Model::kind(&json)? != Method::UNet {
        return Ok(()); // a reduced-order model as --init is refused with the other checks of the start
    }
    let pre = learn::TrainedModel::load(&json)?.config;
    let asked = [("--channels", args.channels, pre.base_channels), ("--depth", args.depth, pre.depth)];
    let differing: Vec<String> = asked
        .into_iter()
        .filter_map(|(flag, given, own)| given.filter(|&g| g != own).map(|g| format!("{flag} {g}")))
        .collect();
    if !differing.is_empty() {
        bail!(
            "{}: a network fine-tuned from --init keeps the pre-trained one's architecture ({} channels, depth {})",
            differing.join(", "),
            pre.base_channels,
            pre.depth
        );
    }
    Ok(())
}

/// `train` for a reduced-order model: fitted on the training samples, chosen on the validation
/// ones; its fit in lines.
fn train_rom(args: &TrainArgs, dataset: &Dataset, split: Split, samples: [Samples; 2]) -> Result<Vec<String>> {
    let config = RomConfig {
        max_modes: args.modes,
        max_inducing: args.inducing,
        noise_copies: args.noise_copies,
        corruption: args.corruption.corruption(),
        seed: args.seed,
        ..RomConfig::default()
    };
    let (model, report) = fit_rom(dataset, split, samples, &config, args.prior.as_deref(), &args.out)?;
    let mut lines = rom_lines(&model, &report);
    lines.push(format!("wrote      {}", args.out.join(learn::MODEL_FILE).display()));
    Ok(lines)
}

/// Where a U-Net's training starts.
pub enum UNetStart {
    /// A new network of this shape, its normalisation fitted on the training samples.
    Scratch(UNetConfig),
    /// A saved model, fine-tuned.
    FineTune {
        /// The model's directory or file.
        model: PathBuf,
        /// Whether its encoder is frozen (only the decoder learns).
        freeze_encoder: bool,
    },
}

/// Where a U-Net's training writes and runs.
pub struct UNetRun {
    /// The model's directory.
    pub out: PathBuf,
    /// Continue from the checkpoint in `out` where there is one.
    pub resume: bool,
    /// The device.
    pub compute: Compute,
}

/// Trains a U-Net from `start` with `config` on `train` (its checkpoints chosen on `validation`),
/// samples of `dataset` split by `split`: the model records the split's test samples and the
/// dataset's grid placement, and a new network takes the dataset's input unit; a pre-trained
/// network of another grid (shape or spacing) is told to `progress` in a warning. Plots the
/// learning curve beside the model ([`CURVE_PNG`](crate::curve::CURVE_PNG)).
pub fn train_unet(
    dataset: &Dataset,
    split: &Split,
    [train, validation]: [&Samples; 2],
    start: UNetStart,
    config: &TrainConfig,
    run: UNetRun,
    progress: &dyn Progress,
) -> Result<TrainOutcome> {
    let manifest = dataset.manifest();
    let init = match start {
        UNetStart::Scratch(unet) => Initialization::Scratch {
            unet,
            normalization: Normalization::from_samples(train),
            input_unit: manifest.units.input,
        },
        UNetStart::FineTune { model, freeze_encoder } => {
            let model = learn::Model::json_path(&model);
            let pre = learn::Model::load(&model)?;
            ensure!(
                pre.method() == Method::UNet,
                "{} is a reduced-order model: a U-Net's training starts from a U-Net",
                model.display()
            );
            ensure!(
                pre.input_unit() == manifest.units.input,
                "{} was trained on inputs in {}, the dataset's are in {}: fine-tuning needs inputs of the same kind",
                model.display(),
                pre.input_unit(),
                manifest.units.input
            );
            let (theirs, ours) =
                (grid_in_words(pre.grid(), pre.placement()), grid_in_words(manifest.grid, manifest.placement()));
            if theirs != ours {
                progress.line(&format!(
                    "warning    {} was trained on grid {theirs}, the dataset is on grid {ours}: the network carries \
                     over, with its normalisation, what it learned of another grid",
                    model.display()
                ));
            }
            Initialization::FineTune { model, freeze_encoder }
        }
    };
    let options = TrainOptions {
        out_dir: run.out,
        resume: run.resume,
        stop_after: None,
        placement: manifest.placement(),
        test: split.test.clone(),
        compute: run.compute,
    };
    let outcome = learn::train(train, validation, &init, config, &options, progress)?;
    if !outcome.completed {
        bail!(
            "interrupted at step {} of {}: its checkpoint is written in {}; the same command resumes from it",
            outcome.iterations_done,
            config.iterations,
            options.out_dir.display()
        );
    }
    crate::curve::plot_learning_curve(&options.out_dir.join(crate::curve::CURVE_PNG), &outcome.curve)?;
    Ok(outcome)
}

/// A grid in words: its shape and, when placed, its spacing (`21x6x6, spacing 200.000 × 200.000 ×
/// 200.000 mm`).
fn grid_in_words(grid: learn::GridShape, placement: Option<learn::GridPlacement>) -> String {
    match placement {
        Some(p) => {
            format!("{grid}, spacing {:.3} × {:.3} × {:.3} mm", mm(p.spacing[0]), mm(p.spacing[1]), mm(p.spacing[2]))
        }
        None => grid.to_string(),
    }
}

/// Fits a reduced-order model with `config` on `train` (chosen on `validation`) of `dataset`
/// split by `split`, with the linear-elastic response at rest of the dataset scenario `prior`
/// (a file or built-in name) as its physics prior when given; saves it into `out`, held against
/// another training there meanwhile ([`learn::take_model_folder`]). Returns the model and its fit.
pub fn fit_rom(
    dataset: &Dataset,
    split: Split,
    [train, validation]: [Samples; 2],
    config: &RomConfig,
    prior: Option<&Path>,
    out: &Path,
) -> Result<(ReducedModel, RomReport)> {
    let prior = prior.map(DatasetScenario::load).transpose()?;
    let prior = prior.as_ref().map(|(scenario, dir)| (scenario, dir.as_path()));
    let _held = learn::take_model_folder(out)?;
    let (model, report) = fit_rom_to(dataset.manifest(), split, [&train, &validation], config, prior)?;
    model.save(out)?;
    Ok((model, report))
}

/// A reduced-order model fitted with `config` on `train` (chosen on `validation`) of the data
/// `manifest` describes, split by `split`, with the linear-elastic response at rest of `prior` (a
/// dataset scenario and the directory its paths start from) as its physics prior when given.
pub fn fit_rom_to(
    manifest: &Manifest,
    split: Split,
    [train, validation]: [&Samples; 2],
    config: &RomConfig,
    prior: Option<(&DatasetScenario, &Path)>,
) -> Result<(ReducedModel, RomReport)> {
    let mut response = prior.map(|(scenario, dir)| scenario.rest_response(dir, manifest)).transpose()?;
    let context = learn::rom::Context::of_dataset(manifest, split);
    Ok(learn::rom::fit(train, validation, config, context, response.as_mut())?)
}

/// A reduced-order model's fit in words: its basis, prior, regression, validation and time.
pub fn rom_lines(model: &ReducedModel, report: &RomReport) -> Vec<String> {
    let info = &model.info;
    let mut lines = vec![format!(
        "basis      {} modes ({:.6} of the training targets' variance); input: {} {}",
        info.modes,
        report.energy,
        info.input_components,
        if info.prior.is_some() { "modal coefficients of the prior" } else { "principal components" }
    )];
    if let Some(prior) = &info.prior {
        lines.push(format!("prior      {prior}"));
    }
    lines.push(format!(
        "regression {} kernel, length scale {:.4e} {}, noise {:.0e}, features scaled by their spread^-{}; {} \
         inducing points ({}); chosen on validation",
        info.kernel.name(),
        info.length_scale,
        if info.prior.is_some() { &model.target_unit } else { &model.input_unit },
        info.noise,
        info.feature_exponent,
        info.inducing,
        if info.exact { "exact Gaussian process" } else { "Nyström" }
    ));
    lines.push(format!(
        "validation mean e = {:.4} mm (max {:.4} mm); the basis alone {:.4} mm; uncertainty scaled by {:.3} for \
         {:.1} % within 2σ",
        mm(report.val_mean_error),
        mm(report.val_max_error),
        mm(report.val_projection_error),
        info.calibration,
        report.val_coverage * 100.0
    ));
    lines.push(format!("time       {:.1} s", info.seconds));
    lines
}

#[cfg(test)]
mod tests {
    use clap::Args;

    /// The defaults `--channels` and `--depth` say in their help are the network's own.
    #[test]
    fn the_help_names_the_network_s_default_shape() {
        let command = super::TrainArgs::augment_args(clap::Command::new("train"));
        let help = |id: &str| {
            let arg = command.get_arguments().find(|a| a.get_id() == id).unwrap();
            arg.get_help().unwrap().to_string()
        };
        let default = learn::UNetConfig::default();
        assert!(help("channels").contains(&format!("[default: {};", default.base_channels)), "{}", help("channels"));
        assert!(help("depth").contains(&format!("[default: {};", default.depth)), "{}", help("depth"));
    }
}
