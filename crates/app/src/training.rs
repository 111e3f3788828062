//! A model trained on a dataset's split, as `augsim train` trains it: a U-Net (from scratch or
//! fine-tuned, with its learning curve), or a reduced-order model and its fit in words.

use std::path::{Path, PathBuf};

use anyhow::Result;
use learn::rom::{ReducedModel, RomConfig, RomReport};
use learn::{
    Compute, Dataset, Initialization, Normalization, Progress, Samples, Split, TrainConfig, TrainOptions, TrainOutcome,
    UNetConfig,
};
use mesh::length::mm;
use scenario::DatasetScenario;

/// Where a U-Net's training starts.
pub enum UNetStart {
    /// A new network of this shape, its normalisation fitted on the training samples.
    Scratch(UNetConfig),
    /// The model saved at `model`, fine-tuned; its encoder frozen when `freeze_encoder`.
    FineTune { model: PathBuf, freeze_encoder: bool },
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
/// dataset's grid placement, and a new network takes the dataset's input unit. Plots the learning
/// curve beside the model ([`CURVE_PNG`](crate::curve::CURVE_PNG)).
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
            input_unit: manifest.units.input.clone(),
        },
        UNetStart::FineTune { model, freeze_encoder } => Initialization::FineTune { model, freeze_encoder },
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
    crate::curve::plot_learning_curve(&options.out_dir.join(crate::curve::CURVE_PNG), &outcome.curve)?;
    Ok(outcome)
}

/// Fits a reduced-order model with `config` on `train` (chosen on `validation`) of `dataset`
/// split by `split`, with the linear-elastic response at rest of the dataset scenario `prior`
/// (a file or built-in name) as its physics prior when given; saves it into `out`. Returns the
/// model and its fit.
pub fn fit_rom(
    dataset: &Dataset,
    split: Split,
    [train, validation]: [Samples; 2],
    config: &RomConfig,
    prior: Option<&Path>,
    out: &Path,
) -> Result<(ReducedModel, RomReport)> {
    let manifest = dataset.manifest();
    let mut prior = match prior {
        Some(path) => {
            let (scenario, dir) = DatasetScenario::load(path)?;
            Some(scenario.rest_response(&dir, manifest)?)
        }
        None => None,
    };
    let context = learn::rom::Context::of_dataset(manifest, split);
    let (model, report) = learn::rom::fit(&train, &validation, config, context, prior.as_mut())?;
    model.save(out)?;
    Ok((model, report))
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
