//! Scenarios 1 and 4: U-Net datasets generated from the shipped scenarios, trained with a
//! train / validation / test split by generation index (the checkpoint chosen on validation),
//! and evaluated on the test samples only.

use std::path::{Path, PathBuf};

use anyhow::Result;
use app::training::{train_unet, UNetRun, UNetStart};
use learn::{Compute, Corruption, CurveRow, Dataset, EvalReport, Model, Samples, SplitPolicy, TrainConfig, UNetConfig};
use mesh::length::{from_mm, mm};
use scenario::DatasetScenario;

use crate::{fmt, reference, write_scenario, ExperimentResult, Headline, Name, Progress, Row, Size, Tenths};

/// A generated dataset and the scenario it came from.
pub(crate) struct Generated {
    pub scenario: DatasetScenario,
    /// The directory the scenario's relative paths start from.
    pub scenario_dir: PathBuf,
    pub dataset: Dataset,
}

impl Generated {
    /// The draws left out for want of a solution, for a note beside the sample count: empty where
    /// every draw solved, otherwise " (n of m draws without a solution, left out)".
    pub fn failed_note(&self) -> String {
        let manifest = self.dataset.manifest();
        match manifest.failed.len() {
            0 => String::new(),
            n => format!(" ({n} of {} draws without a solution, left out)", manifest.num_samples + n),
        }
    }

    /// What the data are, from the scenario itself: its description, material and, for a
    /// displacement input on a sparse sub-domain, the range of observed nodes.
    pub fn note(&self) -> String {
        let (s, m) = (&self.scenario, &self.scenario.material);
        let sparse = match &s.dataset.input {
            learn::data::generate::Input::Displacement { sparse: Some([lo, hi]), .. } => {
                format!("; {lo}–{hi} observed nodes per sample")
            }
            _ => String::new(),
        };
        let order = if m.order == 2 { " quadratic (T10)" } else { "" };
        format!(
            "Data: {}.toml, {} ({}, E = {} Pa, ν = {}, {}{order} elements){sparse}.",
            s.name,
            s.description,
            m.law.display_name(),
            m.young,
            m.poisson,
            m.resolved_formulation().display_name()
        )
    }
}

/// Generates (or resumes) `samples` samples of a shipped scenario into `dir/data-<samples>`.
pub(crate) fn dataset(dir: &Path, name: &str, samples: usize, progress: Progress) -> Result<Generated> {
    let (path, _) = write_scenario(dir, name)?;
    let (mut scenario, scenario_dir) = DatasetScenario::load(&path)?;
    scenario.dataset.samples = samples;
    // One dataset per size: a quick run and a paper run keep their own samples. A complete one of
    // this scenario is reused as it is, one made otherwise refused (the generator checks).
    let data = dir.join(format!("data-{samples}"));
    let generator = scenario.generator(&scenario_dir)?;
    let tenths = Tenths::new(progress, scenario.name.clone(), "samples");
    let manifest = generator.run(&data, &scenario.name, None, &tenths)?;
    progress.line(&format!("{}: {} samples, {} failed", scenario.name, manifest.num_samples, manifest.failed.len()));
    Ok(Generated { dataset: Dataset::open(&data)?, scenario, scenario_dir })
}

/// How a network is trained.
#[derive(Clone)]
pub(crate) struct Recipe {
    pub iterations: usize,
    pub channels: usize,
    pub learning_rate: f64,
    pub final_learning_rate: f64,
    pub validate_every: usize,
    /// Validation and test samples (the last ones by generation index).
    pub validation: usize,
    pub test: usize,
    /// Corruption of training and validation inputs.
    pub corruption: Corruption,
    /// Train on the first this many training samples only (the split stays that of the whole set).
    pub train_samples: Option<usize>,
    /// Fine-tune this pre-trained model (its `model.json`) instead of starting from scratch.
    pub fine_tune: Option<PathBuf>,
    /// A shipped network (its directory, [`app::case::shipped`]) evaluated instead of a
    /// training when its record is this recipe's run on this split: hours of training not run again.
    pub shipped: Option<PathBuf>,
}

impl Recipe {
    /// 8 channels, Adam at 1e-3 falling to 1e-5 along a half cosine, validated every twentieth of
    /// the run but no more often than every 50 steps, clean inputs, from scratch on every training
    /// sample; `validation` and `test` samples held out.
    pub fn new(iterations: usize, validation: usize, test: usize) -> Recipe {
        Recipe {
            iterations,
            channels: 8,
            learning_rate: 1e-3,
            final_learning_rate: 1e-5,
            validate_every: (iterations / 20).max(50),
            validation,
            test,
            corruption: Corruption::default(),
            train_samples: None,
            fine_tune: None,
            shipped: None,
        }
    }

    /// The training run: batches of 4, the recipe's steps, learning rates and corruption, checkpoints
    /// at every validation.
    pub fn train_config(&self) -> TrainConfig {
        TrainConfig {
            iterations: self.iterations,
            batch_size: 4,
            learning_rate: self.learning_rate,
            final_learning_rate: Some(self.final_learning_rate),
            seed: SEED,
            validate_every: self.validate_every,
            checkpoint_every: self.validate_every,
            train_corruption: self.corruption.clone(),
            val_corruption: self.corruption.clone(),
        }
    }

    /// The split of the recipe's data: its validation and test counts, its training samples.
    pub fn split_policy(&self) -> SplitPolicy {
        SplitPolicy {
            validation_samples: Some(self.validation),
            test_samples: Some(self.test),
            train_samples: self.train_samples,
            ..SplitPolicy::default()
        }
    }
}

/// The model directory of a recipe (relative to the experiment's directory): `model-<steps>-steps`, then
/// `-<n>-samples` when it trains on part of the training split and `-fine-tuned` when it starts from a
/// pre-trained model.
pub(crate) fn model_dir(recipe: &Recipe) -> String {
    let mut name = format!("model-{}-steps", recipe.iterations);
    if let Some(n) = recipe.train_samples {
        name += &format!("-{n}-samples");
    }
    if recipe.fine_tune.is_some() {
        name += "-fine-tuned";
    }
    name
}

/// A trained network, its validation and held-out test samples and its learning curve.
pub(crate) struct Trained {
    pub model: Model,
    /// The training samples and the split they come from (recorded in the model).
    pub train: Samples,
    pub record: learn::Split,
    pub validation: Samples,
    pub test: Samples,
    pub split: [usize; 3],
    pub curve: Vec<CurveRow>,
    pub step_seconds: f64,
    /// The shipped network evaluated in place of a training ([`Recipe::shipped`]).
    pub shipped: Option<PathBuf>,
}

impl Trained {
    /// The step whose weights were kept for their validation error (`None` without validation).
    pub fn best_validation_step(&self) -> Option<usize> {
        match &self.model {
            Model::UNet(m) => m.training.as_ref().and_then(|t| t.best_val_mean_error.and(t.best_iteration)),
            Model::Reduced(_) => None,
        }
    }

    /// The learning curve's PNG (from the experiment's directory), unless the network was shipped.
    pub fn curve_figure(&self, recipe: &Recipe) -> Option<String> {
        self.shipped.is_none().then(|| format!("{}/{}", model_dir(recipe), app::curve::CURVE_PNG))
    }

    /// Seconds per training step (with their multiple of the run's reference time), or that the
    /// model was trained by an earlier run of the experiment or shipped (read back, not timed: the
    /// experiment's time then leaves training out).
    pub fn timing(&self, reference_ms: f64) -> String {
        if let Some(path) = &self.shipped {
            let [train, validation] = match &self.model {
                Model::UNet(network) => network.training.as_ref().map_or([0; 2], |t| [t.train_samples, t.val_samples]),
                Model::Reduced(_) => [0; 2],
            };
            format!(
                "the network is the shipped {}, this recipe's run on these draws as they solved when it was trained \
                 ({train} training and {validation} validation samples, none of them among the test samples here), \
                 evaluated, not trained again",
                path.display()
            )
        } else if self.step_seconds > 0.0 {
            format!("{} per training step", reference::seconds(self.step_seconds, 3, Some(reference_ms)))
        } else {
            "trained by an earlier run, so not timed here".into()
        }
    }
}

/// Trains (or resumes training) a U-Net on `dataset` into `dir/`[`model_dir`].
pub(crate) fn train(dataset: &Dataset, dir: &Path, recipe: &Recipe, progress: Progress) -> Result<Trained> {
    let all = dataset.load_all()?;
    let policy = recipe.split_policy();
    let (split, [train, validation, test]) = policy.apply(&all)?;
    if let Some((path, model)) = shipped_run(recipe, &split, &test)? {
        progress.line(&format!(
            "evaluating the shipped {}: this recipe's run on these draws, none of the test samples seen",
            path.display()
        ));
        return Ok(Trained {
            split: [train.len(), validation.len(), test.len()],
            model,
            train,
            record: split,
            validation,
            test,
            curve: Vec::new(),
            step_seconds: 0.0,
            shipped: Some(path),
        });
    }
    let start = match &recipe.fine_tune {
        Some(model) => UNetStart::FineTune { model: model.clone(), freeze_encoder: false },
        None => UNetStart::Scratch(UNetConfig { base_channels: recipe.channels, ..UNetConfig::default() }),
    };
    let how = if recipe.fine_tune.is_some() { "fine-tuning" } else { "from scratch" };
    progress.line(&format!("training {} steps {how} on {} samples", recipe.iterations, train.len()));
    let run = UNetRun { out: dir.join(model_dir(recipe)), resume: true, compute: Compute::Cpu };
    let outcome = train_unet(dataset, &split, [&train, &validation], start, &recipe.train_config(), run, progress)?;
    Ok(Trained {
        split: [train.len(), validation.len(), test.len()],
        model: Model::UNet(std::sync::Arc::new(outcome.model)),
        train,
        record: split,
        validation,
        test,
        curve: outcome.curve,
        step_seconds: outcome.mean_step_seconds,
        shipped: None,
    })
}

/// The training seed of every recipe.
const SEED: u64 = 0;

/// The recipe's shipped network, when it is there and its record
/// is this recipe's run on the draws of `split`: from scratch, the same seed, steps, channels and
/// input corruption, on the same data source, and none of the `test` samples among those it was
/// trained or selected on (a draw that failed when it was trained and solves now is one it never saw).
fn shipped_run(recipe: &Recipe, split: &learn::Split, test: &Samples) -> Result<Option<(PathBuf, Model)>> {
    let Some(path) = recipe.shipped.as_ref().filter(|p| Model::json_path(p).is_file()) else {
        return Ok(None);
    };
    let Model::UNet(network) = Model::load(path)? else { return Ok(None) };
    let same = recipe.fine_tune.is_none()
        && recipe.train_samples.is_none()
        && network.config.base_channels == recipe.channels
        && network.training.as_ref().is_some_and(|t| {
            t.iterations == recipe.iterations
                && t.seed == SEED
                && t.fine_tuned_from.is_none()
                && t.corruption == recipe.corruption
                && t.split.source == split.source
                && t.split.check_unseen(test).is_ok()
        });
    Ok(same.then(|| (path.clone(), Model::UNet(network))))
}

/// A reduced-order model fitted with `config` on the training and validation samples of the
/// network `t` (its split), with the linear-elastic response at rest of the data's scenario as its
/// physics prior when `prior` is set; its fit report and time (s).
pub(crate) fn fit_rom(
    data: &Generated,
    t: &Trained,
    config: &learn::rom::RomConfig,
    prior: bool,
) -> Result<(std::sync::Arc<learn::rom::ReducedModel>, learn::rom::RomReport, f64)> {
    let start = std::time::Instant::now();
    let prior = prior.then_some((&data.scenario, data.scenario_dir.as_path()));
    let samples = [&t.train, &t.validation];
    let (model, report) = app::training::fit_rom_to(data.dataset.manifest(), t.record.clone(), samples, config, prior)?;
    Ok((std::sync::Arc::new(model), report, start.elapsed().as_secs_f64()))
}

/// Median time (s) of one prediction of `model` on `input` on the CPU (3 runs of warm-up, then 20).
pub(crate) fn prediction_seconds(model: &Model, input: &[f32]) -> Result<f64> {
    let predictor = model.predictor(Compute::Cpu)?;
    Ok(learn::time_prediction(|x| predictor.predict(x), input, 3, 20)?.median)
}

/// Histogram of the per-sample errors (mm) as a PNG.
pub(crate) fn error_histogram(path: &Path, title: &str, reports: &[(&str, &EvalReport)]) -> Result<()> {
    let max = reports.iter().map(|(_, r)| mm(r.stats.max)).fold(0.0, f64::max);
    let bins = 30;
    let width = (max / bins as f64).max(f64::MIN_POSITIVE);
    let series: Vec<plot::Series> = reports
        .iter()
        .map(|(name, r)| {
            let mut counts = vec![0usize; bins];
            for e in &r.errors {
                counts[((mm(*e) / width) as usize).min(bins - 1)] += 1;
            }
            let n = r.errors.len().max(1) as f64;
            let points = counts
                .iter()
                .enumerate()
                .flat_map(|(b, &c)| {
                    let y = 100.0 * c as f64 / n;
                    [(b as f64 * width, y), ((b + 1) as f64 * width, y)]
                })
                .collect();
            plot::Series { name: name.to_string(), points, band: None }
        })
        .collect();
    let spec = plot::PlotSpec {
        title: title.into(),
        x_label: "mean nodal error e of a test sample (mm)".into(),
        y_label: "% of test samples".into(),
        log_y: false,
    };
    plot::line_plot(path, &spec, &series)?;
    Ok(())
}

/// The reference displacement's magnitude (m) at every node inside the organ, sample after sample
/// (targets are `[3, nx, ny, nz]` per sample: a node's components are a channel apart).
fn displacement_magnitudes(samples: &Samples) -> impl Iterator<Item = f64> + '_ {
    let n = samples.grid.nodes();
    (0..samples.len()).flat_map(move |i| {
        let (u, mask) = (samples.target(i), samples.mask(i));
        (0..n).filter(move |&k| mask[k] != 0).map(move |k| {
            let [x, y, z] = [u[k], u[n + k], u[2 * n + k]].map(f64::from);
            (x * x + y * y + z * z).sqrt()
        })
    })
}

/// Largest reference displacement over `samples` (m).
pub(crate) fn max_displacement(samples: &Samples) -> f64 {
    displacement_magnitudes(samples).fold(0.0, f64::max)
}

/// Mean reference displacement over the organ's nodes of `samples` (m).
fn mean_displacement(samples: &Samples) -> f64 {
    let (sum, count) = displacement_magnitudes(samples).fold((0.0, 0usize), |(s, c), u| (s + u, c + 1));
    sum / count.max(1) as f64
}

/// The split, the draws and the training's time of `t` on `data`, for an experiment's notes.
fn split_note(t: &Trained, data: &Generated, reference_ms: f64) -> String {
    let [train, validation, test] = t.split;
    let timing = t.timing(reference_ms);
    let failed = data.failed_note();
    // A shipped network's checkpoint was chosen on its own validation samples (its timing says).
    let selection = match (&t.shipped, t.best_validation_step()) {
        (Some(_), _) => String::new(),
        (None, Some(step)) => format!(" (checkpoint selection, best at step {step})"),
        (None, None) => " (checkpoint selection)".into(),
    };
    format!(
        "{} samples generated{failed}: {train} training, {validation} validation{selection}, {test} test (every \
         figure above); {timing}.",
        data.dataset.manifest().num_samples,
    )
}

/// The published U-Net's mean error on scenario 1 (mm), the figure both of ours are set beside.
const PUBLISHED_MEAN_MM: f64 = 0.0694;

/// The published U-Net's standard deviation and largest error on scenario 1 (mm).
const PUBLISHED_STD_MM: f64 = 0.0781;
const PUBLISHED_MAX_MM: f64 = 0.68;

/// The headlines of the liver forces experiment: the U-Net's test error (`s`), the reduced-order
/// model's (`r`), and the time of one prediction (`prediction`, s; with its multiple of the run's
/// reference time).
fn liver_forces_headlines(
    s: &learn::ErrorStats,
    r: &learn::ErrorStats,
    prediction: f64,
    reference_ms: f64,
) -> Vec<Headline> {
    vec![
        Headline::lower_is_better("liver, forces → displacement: test ē", mm(s.mean), PUBLISHED_MEAN_MM, 3, "mm"),
        // The publication has no reduced-order model: its U-Net's figure is the one to reach.
        Headline {
            published: format!("{} (the published U-Net)", fmt(PUBLISHED_MEAN_MM, 3, "mm")),
            ..Headline::lower_is_better(
                "liver, forces → displacement: test ē, reduced-order model with the linear-elastic prior",
                mm(r.mean),
                PUBLISHED_MEAN_MM,
                3,
                "mm",
            )
        },
        Headline {
            ours: reference::ms(prediction * 1e3, 2, Some(reference_ms)),
            ..Headline::lower_is_better(
                "liver, forces → displacement: prediction of one sample (ours: 2 CPU cores; published: GPU)",
                prediction * 1e3,
                3.47,
                2,
                "ms",
            )
        },
    ]
}

/// The liver forces experiment (quick: 300 samples, 600 steps of an 8-channel network; paper: the
/// published 2,000 samples, 100,000 steps (the published count) of a 16-channel network, about
/// 2.5 hours on 2 cores).
pub(crate) fn liver_forces(size: Size, dir: &Path, progress: Progress) -> Result<ExperimentResult> {
    let (samples, iterations, channels) = match size {
        Size::Quick => (300, 600, 8),
        Size::Paper => (2000, 100_000, 16),
    };
    let data = dataset(dir, "liver_forces_large", samples, progress)?;
    let recipe = Recipe {
        channels,
        shipped: (size == Size::Paper).then(|| app::case::shipped(app::case::SHIPPED_FORCES_MODEL)).flatten(),
        ..Recipe::new(iterations, samples / 10, samples / 5)
    };
    let t = train(&data.dataset, dir, &recipe, progress)?;
    let report = learn::evaluate(&t.model, &t.test, &Corruption::default(), 0, Compute::Cpu)?;
    let input = t.test.get(0).input;
    let reference_ms = reference::measure()?;
    let prediction = prediction_seconds(&t.model, &input)?;
    // The reduced-order model on the same split, and the U-Net's predictions projected on its basis.
    progress.line("fitting the reduced-order model with the linear-elastic prior");
    let (fitted, rom_fit, rom_seconds) = fit_rom(&data, &t, &learn::rom::RomConfig::default(), true)?;
    let rom = Model::Reduced(fitted.clone());
    let rom_report = learn::evaluate(&rom, &t.test, &Corruption::default(), 0, Compute::Cpu)?;
    let rom_prediction = prediction_seconds(&rom, &input)?;
    let projected = learn::Projected::new(t.model.clone(), &rom)?;
    let projected_report = learn::evaluate(&projected, &t.test, &Corruption::default(), 0, Compute::Cpu)?;
    error_histogram(
        &dir.join("errors.png"),
        "Liver forces: test-sample errors",
        &[("U-Net", &report), ("reduced-order model", &rom_report)],
    )?;
    let s = &report.stats;
    let r = &rom_report.stats;
    let mean = mean_displacement(&t.test);
    let rows = vec![
        Row::new("mean error ē", fmt(mm(s.mean), 3, "mm"), fmt(PUBLISHED_MEAN_MM, 4, "mm")),
        Row::new("σ(e)", fmt(mm(s.std), 3, "mm"), fmt(PUBLISHED_STD_MM, 4, "mm")),
        Row::new("max e", fmt(mm(s.max), 3, "mm"), fmt(PUBLISHED_MAX_MM, 2, "mm")),
        Row::new("max displacement in the test set", fmt(mm(max_displacement(&t.test)), 1, "mm"), "80 mm"),
        Row::new(
            "relative error: ē / mean displacement of the test set",
            format!("{:.1} % (mean displacement {})", 100.0 * s.mean / mean, fmt(mm(mean), 2, "mm")),
            "",
        ),
        Row::new(
            "prediction (one sample)",
            format!("{} (CPU, median of 20)", reference::ms(prediction * 1e3, 2, Some(reference_ms))),
            "3.47 ms (GTX 1080 Ti)",
        ),
        Row::new(
            "training",
            format!("{iterations} steps, {} channels", recipe.channels),
            "100,000 steps, 128 channels",
        ),
        Row::new(
            "reduced-order model with the linear-elastic prior: ē (σ, max)",
            format!("{} ({}, {})", fmt(mm(r.mean), 3, "mm"), fmt(mm(r.std), 3, "mm"), fmt(mm(r.max), 3, "mm")),
            format!(
                "{} ({PUBLISHED_STD_MM}, {PUBLISHED_MAX_MM} mm), the published U-Net",
                fmt(PUBLISHED_MEAN_MM, 4, "mm")
            ),
        ),
        Row::new(
            "reduced-order model: prediction (one sample); fit",
            format!(
                "{} (CPU, median of 20); {} ({} modes, {} features)",
                reference::ms(rom_prediction * 1e3, 2, Some(reference_ms)),
                reference::seconds(rom_seconds, 0, Some(reference_ms)),
                fitted.info.modes,
                fitted.info.input_components
            ),
            "",
        ),
        Row::new(
            "U-Net projected on the reduced-order model's basis: ē (max)",
            format!(
                "{} ({})",
                fmt(mm(projected_report.stats.mean), 3, "mm"),
                fmt(mm(projected_report.stats.max), 3, "mm")
            ),
            "",
        ),
    ];
    let headlines = liver_forces_headlines(s, r, prediction, reference_ms);
    let mut values = serde_json::Map::new();
    values.insert("test".into(), serde_json::to_value(report.stats)?);
    values.insert("prediction_seconds".into(), prediction.into());
    values.insert("rom_test".into(), serde_json::to_value(rom_report.stats)?);
    values.insert("rom_validation_mean".into(), rom_fit.val_mean_error.into());
    values.insert("rom_prediction_seconds".into(), rom_prediction.into());
    values.insert("rom_fit_seconds".into(), rom_seconds.into());
    values.insert("reference_ms".into(), reference_ms.into());
    values.insert("projected_unet_test".into(), serde_json::to_value(projected_report.stats)?);
    Ok(ExperimentResult {
        headlines,
        name: Name::LiverForces,
        size,
        seconds: 0.0,
        build: String::new(),
        rows,
        figures: t.curve_figure(&recipe).into_iter().chain(["errors.png".into()]).collect(),
        page_figures: Vec::new(),
        notes: vec![
            split_note(&t, &data, reference_ms),
            format!(
                "{} Neo-Hookean because SVK passes its compressive limit point under these loads; the largest \
                 displacement of our test set is in the table.",
                data.note()
            ),
            "The reduced-order model (`augsim train --method rom --prior`) is fitted on the training and validation \
             samples above and tested on the test samples: a POD basis, the linear-elastic response at rest of \
             the scenario's FEM as a prior, and a Gaussian process on what the prior leaves. The U-Net's projection \
             on that basis keeps only what the training targets span."
                .into(),
            reference::note(Some(reference_ms)),
        ],
        values,
    })
}

/// The beam sparse input experiment (quick: 1,200 samples, 800 steps; paper: the published 12,600 = 10,080 + 2,520, 6,000 steps).
pub(crate) fn beam_sparse(size: Size, dir: &Path, progress: Progress) -> Result<ExperimentResult> {
    let (samples, iterations) = match size {
        Size::Quick => (1200, 800),
        Size::Paper => (12600, 6000),
    };
    let data = dataset(dir, "beam_sparse", samples, progress)?;
    let recipe = Recipe::new(iterations, samples / 25, samples / 5);
    let t = train(&data.dataset, dir, &recipe, progress)?;
    let reference_ms = reference::measure()?;
    let noise = |std: f64| Corruption { noise_std: std, ..Corruption::default() };
    let clean = learn::evaluate(&t.model, &t.test, &noise(0.0), 0, Compute::Cpu)?;
    let noisy_mm = learn::evaluate(&t.model, &t.test, &noise(from_mm(1.0)), 0, Compute::Cpu)?;
    let noisy_cm = learn::evaluate(&t.model, &t.test, &noise(from_mm(10.0)), 0, Compute::Cpu)?;
    error_histogram(
        &dir.join("errors.png"),
        "Beam sparse input: test-sample errors by input noise",
        &[("no noise", &clean), ("σ = 1 mm", &noisy_mm), ("σ = 1 cm", &noisy_cm)],
    )?;
    let pair = |r: &EvalReport| format!("{} (max {})", fmt(mm(r.stats.mean), 2, "mm"), fmt(mm(r.stats.max), 1, "mm"));
    let headlines = vec![Headline::lower_is_better(
        "beam, sparse input: test ē without noise",
        mm(clean.stats.mean),
        3.03,
        2,
        "mm",
    )];
    let rows = vec![
        Row::new("ē, no noise", pair(&clean), "3.03 mm (max 57.1 mm), 10,080 training samples"),
        Row::new("ē, noise σ = 1 mm", pair(&noisy_mm), "nearly unchanged"),
        Row::new("ē, noise σ = 1 cm", pair(&noisy_cm), "about 10 mm"),
        // The scale of the motion the errors are of: the published test set's is not given.
        Row::new("max displacement in the test set", fmt(mm(max_displacement(&t.test)), 1, "mm"), ""),
    ];
    let mut values = serde_json::Map::new();
    for (key, r) in [("clean", &clean), ("noise_1mm", &noisy_mm), ("noise_1cm", &noisy_cm)] {
        values.insert(key.into(), serde_json::to_value(r.stats)?);
    }
    Ok(ExperimentResult {
        headlines,
        name: Name::BeamSparse,
        size,
        seconds: 0.0,
        build: String::new(),
        rows,
        figures: t.curve_figure(&recipe).into_iter().chain(["errors.png".into()]).collect(),
        page_figures: Vec::new(),
        notes: vec![
            split_note(&t, &data, reference_ms),
            format!("{} Noise is added to the visible inputs at evaluation only.", data.note()),
            reference::note(Some(reference_ms)),
        ],
        values,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use learn::{GridShape, Initialization, Sample, TrainOptions};

    /// A node's displacement components are a channel apart, and nodes outside the organ do not count.
    #[test]
    fn displacement_magnitudes_read_each_node_across_the_channels() {
        let mut samples = Samples::new(GridShape::new(1, 1, 3));
        // Nodes: (3, 0, 4) → 5, (0, 1, 0) → 1, and a node outside the organ moved by 100.
        let target = vec![3.0, 0.0, 100.0, 0.0, 1.0, 0.0, 4.0, 0.0, 0.0];
        samples.push(&Sample { index: 0, input: vec![0.0; 9], target, mask: vec![1, 1, 0] }).unwrap();
        assert_eq!(displacement_magnitudes(&samples).collect::<Vec<_>>(), vec![5.0, 1.0]);
        assert_eq!(max_displacement(&samples), 5.0);
        assert_eq!(mean_displacement(&samples), 3.0);
    }

    /// A shipped network stands in for a training only when its record is the recipe's run on the
    /// same draws and it never saw the test samples: a test sample it was selected on, other draws,
    /// another width, step count or input noise train anew.
    #[test]
    fn a_shipped_network_stands_in_only_for_its_own_recipe_and_unseen_test_samples() {
        let grid = GridShape::new(4, 4, 4);
        let mut all = Samples::new(grid);
        for index in 0..8u64 {
            let input = (0..grid.field_len()).map(|k| ((k as u64 * 7 + index) % 5) as f32).collect();
            let target = (0..grid.field_len()).map(|k| 1e-3 * ((k as u64 + index) % 3) as f32).collect();
            all.push(&Sample { index, input, target, mask: vec![1; grid.nodes()] }).unwrap();
        }
        all.source = Some("toy/seed 0/0".into());
        let recipe = Recipe { channels: 2, ..Recipe::new(2, 2, 2) };
        let (split, [train, validation, test]) = recipe.split_policy().apply(&all).unwrap();
        let dir = tempfile::tempdir().unwrap();
        let init = Initialization::Scratch {
            unet: UNetConfig { base_channels: recipe.channels, depth: 1, ..UNetConfig::default() },
            normalization: learn::Normalization::from_samples(&train),
            input_unit: learn::FieldUnit::Newton,
        };
        let options = TrainOptions { test: split.test.clone(), ..TrainOptions::new(dir.path().to_path_buf()) };
        learn::train(&train, &validation, &init, &recipe.train_config(), &options, &learn::Silent).unwrap();

        let shipped = Recipe { shipped: Some(dir.path().to_path_buf()), ..recipe.clone() };
        let (path, model) = shipped_run(&shipped, &split, &test).unwrap().expect("the shipped network's own run");
        assert_eq!(path, dir.path());
        assert!(matches!(model, Model::UNet(_)));
        // Another validation count, the same test samples: still none it saw.
        let split_of = |all: &Samples, validation, test| {
            let (split, [_, _, test]) = Recipe::new(2, validation, test).split_policy().apply(all).unwrap();
            (split, test)
        };
        let (fewer, fewer_test) = split_of(&all, 1, 2);
        assert_ne!(fewer, split);
        assert!(shipped_run(&shipped, &fewer, &fewer_test).unwrap().is_some());
        let seen = split_of(&all, 2, 3);
        let other_draws = split_of(&Samples { source: Some("toy/seed 1/0".into()), ..all.clone() }, 2, 2);
        let noisy = Corruption { noise_std: 1e-3, ..Corruption::default() };
        for (what, recipe, (split, test)) in [
            ("a test sample it was selected on", shipped.clone(), &seen),
            ("other draws", shipped.clone(), &other_draws),
            ("another width", Recipe { channels: 4, ..shipped.clone() }, &(split.clone(), test.clone())),
            ("more steps", Recipe { iterations: 3, ..shipped.clone() }, &(split.clone(), test.clone())),
            ("noisy inputs", Recipe { corruption: noisy, ..shipped.clone() }, &(split.clone(), test.clone())),
            (
                "no shipped network",
                Recipe { shipped: Some(dir.path().join("absent")), ..shipped.clone() },
                &(split.clone(), test.clone()),
            ),
        ] {
            assert!(shipped_run(&recipe, split, test).unwrap().is_none(), "{what}");
        }
    }
}
