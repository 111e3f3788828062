//! Evaluation over a sample set, single predictions and prediction timing.

use std::time::Instant;

use burn::module::Module;
use burn::tensor::{Device, Tensor, TensorData};
use serde::{Deserialize, Serialize};

use crate::corrupt::{item_rng, Corruption};
use crate::dataset::{Normalization, Samples};
use crate::grid::CHANNELS;
use crate::metrics::{mean_euclidean_error, EvalReport};
use crate::train::{batch_tensors, STREAM_EVAL_CORRUPTION};
use crate::unet::{TrainedModel, UNet};
use crate::{LearnError, Result};

/// Runs `net` on normalised batches of `samples` (corrupted with generator per sample position
/// derived from `seed`) and returns the per-sample errors (m).
pub(crate) fn evaluate_net(
    net: &UNet,
    norm: &Normalization,
    samples: &Samples,
    corruption: &Corruption,
    seed: u64,
    batch_size: usize,
    device: &Device,
) -> Result<EvalReport> {
    if samples.is_empty() {
        return Err(LearnError::InvalidInput("no samples to evaluate".into()));
    }
    if batch_size == 0 {
        return Err(LearnError::InvalidInput("evaluation batch size must be at least 1".into()));
    }
    let grid = samples.grid;
    let f = grid.field_len();
    let mut errors = Vec::with_capacity(samples.len());
    let positions: Vec<usize> = (0..samples.len()).collect();
    for chunk in positions.chunks(batch_size) {
        let (x, _, _) = batch_tensors(
            samples,
            chunk,
            norm,
            corruption,
            |slot| item_rng(seed, STREAM_EVAL_CORRUPTION, chunk[slot] as u64),
            device,
        )?;
        let pred = to_vec(net.forward(x))?;
        for (slot, &p) in chunk.iter().enumerate() {
            let pred: Vec<f32> =
                pred[slot * f..(slot + 1) * f].iter().map(|v| (f64::from(*v) * norm.target_scale) as f32).collect();
            errors.push(
                mean_euclidean_error(&pred, samples.target(p), samples.mask(p), grid).map_err(|e| {
                    LearnError::InvalidInput(format!("sample {} (index {}): {e}", p, samples.indices[p]))
                })?,
            );
        }
    }
    EvalReport::new(errors, samples.indices.clone())
}

fn to_vec(t: Tensor<5>) -> Result<Vec<f32>> {
    t.into_data()
        .try_into_vec_as::<f32>()
        .map_err(|e| LearnError::InvalidInput(format!("cannot read the network output: {e:?}")))
}

/// Evaluates `model` on `samples`: per-sample mean Euclidean errors (m), mean, std, max and the
/// worst sample. Inputs are corrupted with `corruption`, one reproducible draw per sample from
/// `seed`.
pub fn evaluate(
    model: &TrainedModel,
    samples: &Samples,
    corruption: &Corruption,
    seed: u64,
    batch_size: usize,
) -> Result<EvalReport> {
    corruption.validate()?;
    let device = model_device(model);
    evaluate_net(&model.net, &model.normalization, samples, corruption, seed, batch_size, &device)
}

fn model_device(model: &TrainedModel) -> Device {
    model.net.devices().into_iter().next().unwrap_or_else(crate::inference_device)
}

impl TrainedModel {
    /// Predicts the displacement field (m, `[3, nx, ny, nz]`) for one input field (`[3, nx, ny,
    /// nz]` on the model's grid, in the model's input unit). Values outside the organ are
    /// meaningless; apply the mask.
    pub fn predict(&self, input: &[f32]) -> Result<Vec<f32>> {
        self.predict_batch(input)
    }

    /// Predicts for several inputs concatenated (`[N, 3, nx, ny, nz]`), in one batch.
    pub fn predict_batch(&self, inputs: &[f32]) -> Result<Vec<f32>> {
        let f = self.grid.field_len();
        if inputs.is_empty() || inputs.len() % f != 0 {
            return Err(LearnError::InvalidInput(format!(
                "prediction input has {} values, not a multiple of {f} (3 channels on grid {})",
                inputs.len(),
                self.grid
            )));
        }
        if inputs.iter().any(|v| !v.is_finite()) {
            return Err(LearnError::InvalidInput("prediction input has a non-finite value".into()));
        }
        let n = inputs.len() / f;
        let si = 1.0 / self.normalization.input_scale;
        let x: Vec<f32> = inputs.iter().map(|v| (f64::from(*v) * si) as f32).collect();
        let [nx, ny, nz] = self.grid.dims();
        let x = Tensor::<5>::from_data(TensorData::new(x, [n, CHANNELS, nx, ny, nz]), &model_device(self));
        let out = to_vec(self.net.forward(x))?;
        Ok(out.into_iter().map(|v| (f64::from(v) * self.normalization.target_scale) as f32).collect())
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

/// Times [`TrainedModel::predict`] on `input` (including normalisation and the copy back):
/// `warmup` untimed runs, then `runs` timed ones.
pub fn time_prediction(model: &TrainedModel, input: &[f32], warmup: usize, runs: usize) -> Result<Timing> {
    if runs == 0 {
        return Err(LearnError::InvalidInput("time_prediction needs at least one run".into()));
    }
    for _ in 0..warmup {
        model.predict(input)?;
    }
    let mut d = Vec::with_capacity(runs);
    for _ in 0..runs {
        let t0 = Instant::now();
        std::hint::black_box(model.predict(input)?);
        d.push(t0.elapsed().as_secs_f64());
    }
    Timing::from_durations(d)
}
