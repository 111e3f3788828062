//! Evaluation over a sample set, single predictions and prediction timing.

use std::time::Instant;

use serde::{Deserialize, Serialize};

use crate::corrupt::{item_rng, Corruption, STREAM_EVAL_CORRUPTION};
use crate::dataset::{Normalization, Samples};
use crate::grid::GridShape;
use crate::grid::CHANNELS;
use crate::inference::InferenceNet;
use crate::metrics::{mean_euclidean_error, ErrorStats, EvalReport};
use crate::unet::TrainedModel;
use crate::{LearnError, Result};
use mesh::embedding::Grid;
use mesh::Point;

/// Runs `net` on the normalised inputs of `samples` (each corrupted with its own generator,
/// derived from `seed` and the sample position) and returns the per-sample errors (m);
/// `visit(position, prediction)` sees each prediction (m).
pub(crate) fn evaluate_net(
    net: &InferenceNet,
    norm: &Normalization,
    samples: &Samples,
    corruption: &Corruption,
    seed: u64,
    mut visit: impl FnMut(usize, &[f32]) -> Result<()>,
) -> Result<EvalReport> {
    if samples.is_empty() {
        return Err(LearnError::InvalidInput("no samples to evaluate".into()));
    }
    let grid = samples.grid;
    let (si, st) = (1.0 / norm.input_scale, norm.target_scale);
    let mut errors = Vec::with_capacity(samples.len());
    for p in 0..samples.len() {
        let input = evaluation_input(samples, p, corruption, seed)?;
        let x: Vec<f32> = input.iter().map(|v| (f64::from(*v) * si) as f32).collect();
        let pred: Vec<f32> = net.forward(&x, grid)?.iter().map(|v| (f64::from(*v) * st) as f32).collect();
        visit(p, &pred)?;
        errors.push(
            mean_euclidean_error(&pred, samples.target(p), samples.mask(p), grid)
                .map_err(|e| LearnError::InvalidInput(format!("sample {} (index {}): {e}", p, samples.indices[p])))?,
        );
    }
    EvalReport::new(errors, samples.indices.clone())
}

/// The input evaluation gives the sample at `position`: corrupted with `corruption`, with that
/// sample's own reproducible draw from `seed`.
pub fn evaluation_input(samples: &Samples, position: usize, corruption: &Corruption, seed: u64) -> Result<Vec<f32>> {
    let mut input = samples.input(position).to_vec();
    if !corruption.is_identity() {
        corruption.apply(&mut input, samples.grid, &mut item_rng(seed, STREAM_EVAL_CORRUPTION, position as u64))?;
    }
    Ok(input)
}

/// Evaluates `model` on `samples`: per-sample mean Euclidean errors (m), mean, std, max and the
/// worst sample. Inputs are corrupted with `corruption`, one reproducible draw per sample from
/// `seed`.
pub fn evaluate(model: &TrainedModel, samples: &Samples, corruption: &Corruption, seed: u64) -> Result<EvalReport> {
    corruption.validate()?;
    check_grid(model, samples)?;
    evaluate_net(&model.net.to_inference()?, &model.normalization, samples, corruption, seed, |_, _| Ok(()))
}

fn check_grid(model: &TrainedModel, samples: &Samples) -> Result<()> {
    if samples.grid != model.grid {
        return Err(LearnError::InvalidInput(format!(
            "samples are on grid {}, the model on grid {}",
            samples.grid, model.grid
        )));
    }
    Ok(())
}

/// Errors at given points (e.g. internal markers: target registration errors), over all
/// samples and points (m).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PointErrors {
    /// `|u_pred(x) − u_ref(x)|` over all (sample, point) pairs, both fields interpolated
    /// trilinearly on the grid.
    pub errors: ErrorStats,
    /// `|u_ref(x)|`: the error of assuming the organ did not move, for comparison.
    pub no_motion: ErrorStats,
    /// Mean error of each point over the samples.
    pub per_point_mean: Vec<f64>,
}

/// [`evaluate`], plus the errors at `points` (positions on `grid`, the model grid placed in
/// space).
pub fn evaluate_at_points(
    model: &TrainedModel,
    samples: &Samples,
    corruption: &Corruption,
    seed: u64,
    grid: &Grid,
    points: &[Point],
) -> Result<(EvalReport, PointErrors)> {
    corruption.validate()?;
    check_grid(model, samples)?;
    if points.is_empty() || grid.dims != samples.grid.dims() {
        return Err(LearnError::InvalidInput(format!(
            "{} evaluation points on a {:?} grid (samples on {})",
            points.len(),
            grid.dims,
            samples.grid
        )));
    }
    let at = |field: &[f32]| -> Result<Vec<f64>> {
        let f: Vec<f64> = field.iter().map(|v| f64::from(*v)).collect();
        grid.interpolate(&f, CHANNELS, points).map_err(|e| LearnError::InvalidInput(e.to_string()))
    };
    let norm3 = |v: &[f64]| (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    let (mut errors, mut no_motion) = (Vec::new(), Vec::new());
    let report =
        evaluate_net(&model.net.to_inference()?, &model.normalization, samples, corruption, seed, |p, pred| {
            let (pred, reference) = (at(pred)?, at(samples.target(p))?);
            for (a, b) in pred.chunks_exact(3).zip(reference.chunks_exact(3)) {
                errors.push(norm3(&[a[0] - b[0], a[1] - b[1], a[2] - b[2]]));
                no_motion.push(norm3(b));
            }
            Ok(())
        })?;
    let per_point_mean = (0..points.len())
        .map(|k| errors.iter().skip(k).step_by(points.len()).sum::<f64>() / samples.len() as f64)
        .collect();
    Ok((
        report,
        PointErrors {
            errors: ErrorStats::from_errors(&errors)?,
            no_motion: ErrorStats::from_errors(&no_motion)?,
            per_point_mean,
        },
    ))
}

/// A trained model ready for repeated predictions: its network repacked once for fast CPU
/// inference ([`InferenceNet`]), with its normalisation and grid.
pub struct Predictor {
    net: InferenceNet,
    normalization: Normalization,
    grid: GridShape,
}

impl Predictor {
    /// Repacks `model` for prediction.
    pub fn new(model: &TrainedModel) -> Result<Predictor> {
        Ok(Predictor { net: model.net.to_inference()?, normalization: model.normalization, grid: model.grid })
    }

    /// Predicts the displacement field (m, `[3, nx, ny, nz]`) for one input field (`[3, nx, ny,
    /// nz]` on the model's grid, in the model's input unit). Values outside the organ are
    /// meaningless; apply the mask.
    pub fn predict(&self, input: &[f32]) -> Result<Vec<f32>> {
        let f = self.grid.field_len();
        if input.len() != f {
            return Err(LearnError::InvalidInput(format!(
                "prediction input has {} values, expected {f} (3 channels on grid {})",
                input.len(),
                self.grid
            )));
        }
        if input.iter().any(|v| !v.is_finite()) {
            return Err(LearnError::InvalidInput("prediction input has a non-finite value".into()));
        }
        let si = 1.0 / self.normalization.input_scale;
        let x: Vec<f32> = input.iter().map(|v| (f64::from(*v) * si) as f32).collect();
        let out = self.net.forward(&x, self.grid)?;
        Ok(out.into_iter().map(|v| (f64::from(v) * self.normalization.target_scale) as f32).collect())
    }
}

impl TrainedModel {
    /// Predicts one displacement field (see [`Predictor::predict`]); for repeated predictions
    /// build a [`Predictor`] once.
    pub fn predict(&self, input: &[f32]) -> Result<Vec<f32>> {
        Predictor::new(self)?.predict(input)
    }
}

/// Wall-clock statistics of repeated predictions (s).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Timing {
    /// Timed runs.
    pub runs: usize,
    /// Median.
    pub median: f64,
    /// Mean.
    pub mean: f64,
    /// Standard deviation.
    pub std: f64,
    /// Fastest run.
    pub min: f64,
    /// Slowest run.
    pub max: f64,
}

impl Timing {
    /// Statistics of a non-empty list of durations (s).
    pub fn from_durations(mut d: Vec<f64>) -> Result<Timing> {
        if d.is_empty() {
            return Err(LearnError::InvalidInput("no timed runs".into()));
        }
        d.sort_by(f64::total_cmp);
        let n = d.len();
        let median = if n % 2 == 1 { d[n / 2] } else { 0.5 * (d[n / 2 - 1] + d[n / 2]) };
        let mean = d.iter().sum::<f64>() / n as f64;
        let std = (d.iter().map(|x| (x - mean) * (x - mean)).sum::<f64>() / n as f64).sqrt();
        Ok(Timing { runs: n, median, mean, std, min: d[0], max: d[n - 1] })
    }
}

/// Times [`Predictor::predict`] on `input` (including normalisation and the copy back):
/// `warmup` untimed runs, then `runs` timed ones.
pub fn time_prediction(predictor: &Predictor, input: &[f32], warmup: usize, runs: usize) -> Result<Timing> {
    if runs == 0 {
        return Err(LearnError::InvalidInput("time_prediction needs at least one run".into()));
    }
    for _ in 0..warmup {
        predictor.predict(input)?;
    }
    let mut d = Vec::with_capacity(runs);
    for _ in 0..runs {
        let t0 = Instant::now();
        std::hint::black_box(predictor.predict(input)?);
        d.push(t0.elapsed().as_secs_f64());
    }
    Timing::from_durations(d)
}
