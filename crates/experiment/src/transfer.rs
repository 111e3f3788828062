//! The beam transfer experiment: transfer learning on the beam. A U-Net pre-trained on the BC4 boundary conditions
//! is fine-tuned on 100 samples of the target boundary condition, beside networks trained from
//! scratch on the target's whole training split and on the same 100 samples. Every checkpoint is
//! chosen on the target's validation samples and every figure is measured on its test samples; the
//! speed-up of fine-tuning is read off the validation curves of the two 100-sample runs.

use std::path::Path;

use anyhow::{Context, Result};
use learn::{Compute, Corruption, CurveRow, EvalReport};
use mesh::length::{from_mm, mm};
use serde::Serialize;

use crate::learning::{dataset, error_histogram, max_displacement, model_dir, train, Recipe, Trained};
use crate::{fmt, reference, ExperimentResult, Headline, Name, Progress, Row, Size};

/// Training samples of each dataset, as published (the test set is what remains after validation).
const TRAIN: usize = 1209;
/// Validation samples of each dataset, as published.
const VALIDATION: usize = 200;
/// Target training samples of the few-sample strategies, as published.
const FEW: usize = 100;
/// Steps between validations: the resolution of the speed-up.
const VALIDATE_EVERY: usize = 25;
/// Validation errors (mm) at which the two 100-sample runs are compared.
const THRESHOLDS_MM: [f64; 5] = [1.0, 0.8, 0.6, 0.5, 0.4];

/// When the two 100-sample runs first reach a validation error.
#[derive(Serialize)]
struct Crossing {
    threshold_mm: f64,
    /// First validation step of the fine-tuned run at or below the threshold (0: the pre-trained network).
    fine_tuned_step: Option<usize>,
    /// The same for the run from scratch.
    scratch_step: Option<usize>,
}

impl Crossing {
    /// "fine-tuned / scratch steps (ratio)", the ratio bounded where a run never reaches the threshold.
    fn describe(&self, iterations: usize) -> String {
        let step = |s: Option<usize>| s.map_or(format!("not within {iterations}"), |s| s.to_string());
        let ratio = match (self.fine_tuned_step, self.scratch_step) {
            (Some(0), _) => "reached before fine-tuning".to_string(),
            (Some(f), Some(s)) => format!("{:.1}× sooner", s as f64 / f as f64),
            (Some(f), None) => format!("> {:.1}× sooner", iterations as f64 / f as f64),
            (None, Some(s)) => format!("< {:.2}× sooner", s as f64 / iterations as f64),
            (None, None) => "reached by neither".to_string(),
        };
        format!("{} / {} ({ratio})", step(self.fine_tuned_step), step(self.scratch_step))
    }
}

/// Validation ē (m) against step.
fn validation_curve(curve: &[CurveRow]) -> Vec<(usize, f64)> {
    curve.iter().filter_map(|r| r.val.map(|v| (r.iteration, v.mean))).collect()
}

/// The first step of `curve` at which the validation ē is at most `threshold` (m).
fn first_step(curve: &[(usize, f64)], threshold: f64) -> Option<usize> {
    curve.iter().find(|&&(_, e)| e <= threshold).map(|&(step, _)| step)
}

/// ē (σ, max) of a report, in mm.
fn stats_cell(r: &EvalReport) -> String {
    let s = &r.stats;
    format!("ē {} (σ {:.3}, max {:.2})", fmt(mm(s.mean), 3, "mm"), mm(s.std), mm(s.max))
}

/// The beam transfer experiment (quick: 2,009 samples per dataset, 8 channels; paper: the published 5,241, 16 channels; 1,500
/// steps per run at both sizes, 1,209 training and 200 validation samples per dataset).
pub(crate) fn beam_transfer(size: Size, dir: &Path, progress: Progress) -> Result<ExperimentResult> {
    let (samples, channels, iterations) = match size {
        Size::Quick => (2009, 8, 1500),
        Size::Paper => (5241, 16, 1500),
    };
    let recipe = Recipe {
        channels,
        validate_every: VALIDATE_EVERY,
        ..Recipe::new(iterations, VALIDATION, samples - TRAIN - VALIDATION)
    };
    let runs = Runs::train(dir, samples, &recipe, progress)?;
    let Runs { pre, full, scratch, tuned, .. } = &runs;

    // The target runs share their validation and test samples (the 100-sample runs use part of the training split).
    let clean = Corruption::default();
    let test = &full.test;
    let bc4_test = learn::evaluate(&pre.model, &pre.test, &clean, 0, Compute::Cpu)?;
    let full_test = learn::evaluate(&full.model, test, &clean, 0, Compute::Cpu)?;
    let scratch_test = learn::evaluate(&scratch.model, test, &clean, 0, Compute::Cpu)?;
    let tuned_test = learn::evaluate(&tuned.model, test, &clean, 0, Compute::Cpu)?;
    let pre_test = learn::evaluate(&pre.model, test, &clean, 0, Compute::Cpu)?;
    // Step 0 of fine-tuning: the pre-trained network on the target's validation samples.
    let pre_validation = learn::evaluate(&pre.model, &full.validation, &clean, 0, Compute::Cpu)?.stats.mean;

    let tuned_curve: Vec<(usize, f64)> =
        std::iter::once((0, pre_validation)).chain(validation_curve(&tuned.curve)).collect();
    let scratch_curve = validation_curve(&scratch.curve);
    let crossings: Vec<Crossing> = THRESHOLDS_MM
        .iter()
        .map(|&threshold_mm| Crossing {
            threshold_mm,
            fine_tuned_step: first_step(&tuned_curve, from_mm(threshold_mm)),
            scratch_step: first_step(&scratch_curve, from_mm(threshold_mm)),
        })
        .collect();

    let few_n = scratch.split[0];
    let [full_label, scratch_label, tuned_label] = runs.labels();
    plot_strategies(
        dir,
        [
            (full_label.as_str(), &validation_curve(&full.curve)),
            (scratch_label.as_str(), &scratch_curve),
            (tuned_label.as_str(), &tuned_curve),
        ],
        full.split[1],
        &[
            (full_label.as_str(), &full_test),
            (scratch_label.as_str(), &scratch_test),
            (tuned_label.as_str(), &tuned_test),
            ("pre-trained on BC4, not fine-tuned", &pre_test),
        ],
    )?;

    let mut rows = vec![
        Row::new(format!("{full_label} (target test split)"), stats_cell(&full_test), "ē 0.71 mm (1,209 samples)"),
        Row::new(format!("{scratch_label} (target test split)"), stats_cell(&scratch_test), "ē 3.49 mm (100 samples)"),
        Row::new(format!("{tuned_label} (target test split)"), stats_cell(&tuned_test), "ē 0.80 mm (BC4, 100 samples)"),
        Row::new("pre-trained on BC4, not fine-tuned (target test split)", stats_cell(&pre_test), ""),
        Row::new("pre-trained on BC4 (BC4's own test split)", stats_cell(&bc4_test), ""),
    ];
    for c in &crossings {
        rows.push(
            Row::new(
                format!("first validation step: fine-tuned / scratch, {few_n} samples"),
                c.describe(iterations),
                "fine-tuning about 20× sooner",
            )
            .of("validation ē ≤", format!("{:.1} mm", c.threshold_mm)),
        );
    }
    rows.push(Row::new("largest displacement in the target test set", fmt(mm(max_displacement(test)), 1, "mm"), ""));
    let reference_ms = reference::measure()?;
    let notes = runs.notes(samples, iterations, &recipe, pre_validation, reference_ms);

    let headlines = vec![
        Headline::lower_is_better(
            format!("beam transfer: test ē, pre-trained on BC4 and fine-tuned on {few_n} samples"),
            mm(tuned_test.stats.mean),
            0.80,
            2,
            "mm",
        ),
        Headline::lower_is_better(
            format!("beam transfer: test ē, from scratch on {few_n} samples"),
            mm(scratch_test.stats.mean),
            3.49,
            2,
            "mm",
        ),
    ];
    let mut values = serde_json::Map::new();
    for (key, r) in [
        ("scratch_full", &full_test),
        ("scratch_few", &scratch_test),
        ("fine_tuned_few", &tuned_test),
        ("pre_trained", &pre_test),
        ("pre_trained_bc4_test", &bc4_test),
    ] {
        values.insert(key.into(), serde_json::to_value(r.stats)?);
    }
    values.insert("pre_trained_validation_m".into(), pre_validation.into());
    values.insert("crossings".into(), serde_json::to_value(&crossings)?);
    Ok(ExperimentResult {
        headlines,
        name: Name::BeamTransfer,
        size,
        seconds: 0.0,
        build: String::new(),
        rows,
        figures: vec!["curves.png".into(), "errors.png".into()],
        page_figures: Vec::new(),
        notes,
        values,
    })
}

/// The four training runs: pre-training on BC4, and on the target from scratch on its training
/// split, from scratch on [`FEW`] samples, and fine-tuned from the pre-trained network on them.
struct Runs {
    pre: Trained,
    full: Trained,
    scratch: Trained,
    tuned: Trained,
    /// The draws of either dataset left out for want of a solution, for the notes (empty: none).
    failed: String,
}

impl Runs {
    /// Generates the BC4 and the target datasets of `samples` samples each in `dir` and trains
    /// the four runs there.
    fn train(dir: &Path, samples: usize, recipe: &Recipe, progress: Progress) -> Result<Runs> {
        let (bc4_dir, target_dir) = (dir.join("bc4"), dir.join("target"));
        let bc4 = dataset(&bc4_dir, "beam_bc4", samples, progress)?;
        let target = dataset(&target_dir, "beam_target", samples, progress)?;

        progress.line("BC4: pre-training");
        let pre = train(&bc4.dataset, &bc4_dir, recipe, progress)?;
        let pre_path = bc4_dir.join(model_dir(recipe)).join(learn::training::train::MODEL_FILE);
        // The path is part of the fine-tuning run's identity: the same however `dir` was spelled.
        let pre_path = std::fs::canonicalize(&pre_path)
            .with_context(|| format!("finding the pre-trained {}", pre_path.display()))?;
        progress.line(&format!(
            "target: from scratch on the training split, from scratch on {FEW} samples, fine-tuned on them"
        ));
        let full = train(&target.dataset, &target_dir, recipe, progress)?;
        let few = Recipe { train_samples: Some(FEW), ..recipe.clone() };
        let scratch = train(&target.dataset, &target_dir, &few, progress)?;
        let tuned = train(&target.dataset, &target_dir, &Recipe { fine_tune: Some(pre_path), ..few }, progress)?;
        let failed = [("BC4", &bc4), ("target", &target)]
            .iter()
            .map(|(name, data)| (name, data.failed_note()))
            .filter(|(_, note)| !note.is_empty())
            .map(|(name, note)| format!("; {name}{note}"))
            .collect();
        Ok(Runs { pre, full, scratch, tuned, failed })
    }

    /// The names of the target strategies: from scratch on the training split, from scratch on
    /// the few samples, fine-tuned on them.
    fn labels(&self) -> [String; 3] {
        let (train_n, few_n) = (self.full.split[0], self.scratch.split[0]);
        [
            format!("scratch, {train_n} samples"),
            format!("scratch, {few_n} samples"),
            format!("pre-trained on BC4, fine-tuned on the {few_n}"),
        ]
    }

    /// The notes: the data, the runs, the speed-up (`pre_validation`: the pre-trained network's
    /// validation ē on the target, m; times with their multiple of `reference_ms`, the run's
    /// reference time) and the beam.
    fn notes(
        &self,
        samples: usize,
        iterations: usize,
        recipe: &Recipe,
        pre_validation: f64,
        reference_ms: f64,
    ) -> Vec<String> {
        let [train_n, validation_n, test_n] = self.full.split;
        let few_n = self.scratch.split[0];
        let [full_label, scratch_label, _] = self.labels();
        let best = |t: &Trained| t.best_validation_step().map_or("—".to_string(), |step| step.to_string());
        let timed: Vec<f64> = [&self.pre, &self.full, &self.scratch, &self.tuned]
            .iter()
            .map(|t| t.step_seconds)
            .filter(|&s| s > 0.0)
            .collect();
        let step_time = if timed.is_empty() {
            String::new()
        } else {
            let step = timed.iter().sum::<f64>() / timed.len() as f64;
            format!("; {} per training step", reference::seconds(step, 3, Some(reference_ms)))
        };
        vec![
            format!(
                "BC4 and target: {samples} draws each{}, split by generation index into {train_n} training, \
                 {validation_n} validation (checkpoint selection only) and {test_n} test samples; the {few_n}-sample \
                 runs use the first {few_n} target training samples. Every figure above is on the target's {test_n} test samples (BC4's own \
                 row: BC4's), which played no part in training or selection.",
                self.failed
            ),
            format!(
                "Each run: {iterations} steps, {} channels, Adam from {:e} falling to {:e} along a half cosine, validated \
                 every {VALIDATE_EVERY} steps; best validation at step {} (pre-training), {} ({full_label}), {} \
                 ({scratch_label}), {} (fine-tuned){step_time}.",
                recipe.channels,
                recipe.learning_rate,
                recipe.final_learning_rate,
                best(&self.pre),
                best(&self.full),
                best(&self.scratch),
                best(&self.tuned)
            ),
            format!(
                "Speed-up: the first validation step at which each {few_n}-sample run's validation ē (the curves of \
                 curves.png, {validation_n} target validation samples, every {VALIDATE_EVERY} steps, so each step is known \
                 to within {VALIDATE_EVERY}) falls to the threshold; step 0 of fine-tuning is the pre-trained network \
                 ({} on the validation samples). The ratio is the scratch run's step over the fine-tuned run's; each run \
                 has one seed and noisy curves, so the steps are indicative.",
                fmt(mm(pre_validation), 3, "mm")
            ),
            "Beam 4 × 1 × 1 m (20×5×5 H8), SVK, Y = 300 Pa, ν = 0.4, a downward force of 0–0.3 N on a patch of radius 0.5 m on the \
             top face; input: the top-face displacement. BC4: each sample fixes one of four adjacent 1 m cuboids of the \
             bottom face; target: the cuboid x ∈ [1.5, 2.5] m. Not run: 16,128 samples from scratch (published 0.45 mm), \
             fine-tuning on 1,209 (0.52 mm), BC1 and BC8 pre-training."
                .into(),
            reference::note(Some(reference_ms)),
        ]
    }
}

/// `curves.png`: the validation curve of each target strategy (`validation_n` samples);
/// `errors.png`: the histogram of the test errors of each strategy and of the pre-trained network.
fn plot_strategies(
    dir: &Path,
    curves: [(&str, &[(usize, f64)]); 3],
    validation_n: usize,
    reports: &[(&str, &EvalReport)],
) -> Result<()> {
    let mm_points = |curve: &[(usize, f64)]| curve.iter().map(|&(step, e)| (step as f64, mm(e))).collect();
    // In the order of the histogram, so that each strategy has the same colour in both figures.
    let series =
        curves.map(|(name, curve)| plot::Series { name: name.to_string(), points: mm_points(curve), band: None });
    let spec = plot::PlotSpec {
        title: "Beam transfer: validation error on the target against training step".into(),
        x_label: "training step (0: the pre-trained network before fine-tuning)".into(),
        y_label: format!("validation ē over {validation_n} samples (mm)"),
        log_y: false,
    };
    plot::line_plot(&dir.join("curves.png"), &spec, &series)?;
    error_histogram(&dir.join("errors.png"), "Beam transfer: target test-sample errors by strategy", reports)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crossings_read_the_first_step_and_bound_the_ratio_when_a_run_falls_short() {
        let curve = [(0, 2e-3), (25, 0.9e-3), (50, 1.1e-3), (75, 0.5e-3)];
        assert_eq!(first_step(&curve, 1e-3), Some(25));
        assert_eq!(first_step(&curve, 0.5e-3), Some(75));
        assert_eq!(first_step(&curve, 0.4e-3), None);
        let c = |fine_tuned_step, scratch_step| Crossing { threshold_mm: 1.0, fine_tuned_step, scratch_step };
        assert_eq!(c(Some(25), Some(500)).describe(1500), "25 / 500 (20.0× sooner)");
        assert_eq!(c(Some(0), Some(500)).describe(1500), "0 / 500 (reached before fine-tuning)");
        assert_eq!(c(Some(300), None).describe(1500), "300 / not within 1500 (> 5.0× sooner)");
        assert_eq!(c(None, Some(750)).describe(1500), "not within 1500 / 750 (< 0.50× sooner)");
        assert_eq!(c(None, None).describe(1500), "not within 1500 / not within 1500 (reached by neither)");
    }
}
