//! Loss and error metrics.
//!
//! - Loss (U-Mesh Eq. 1.9): mean over masked grid nodes of the squared displacement error
//!   `‖u_pred − u_true‖²` (summed over the 3 components, averaged over nodes of the batch).
//! - Error of one sample `e`: mean over its masked nodes of `‖u_pred − u_true‖` (m).
//! - Over a set: mean `ē`, population standard deviation `σ(e)`, maximum, and the worst sample.

use mesh::length::mm;
use serde::{Deserialize, Serialize};

use crate::data::grid::{GridShape, CHANNELS};
use crate::{LearnError, Result};

/// Masked MSE of one or more samples given as plain arrays: the mean over masked nodes of the
/// squared error norm (the training loss; burn's engine, with the `cpu-burn` feature, trains on
/// its tensors' own, `net::burn_unet::masked_mse`).
pub fn masked_mse_values(pred: &[f32], target: &[f32], masks: &[u8], grid: GridShape) -> Result<f64> {
    let samples = check_lengths(pred, target, masks, grid)?;
    let n = grid.nodes();
    let (mut total, mut nodes) = (0.0f64, 0usize);
    for s in 0..samples {
        for v in 0..n {
            if masks[s * n + v] != 0 {
                nodes += 1;
                for c in 0..CHANNELS {
                    let i = (s * CHANNELS + c) * n + v;
                    let d = f64::from(pred[i]) - f64::from(target[i]);
                    total += d * d;
                }
            }
        }
    }
    Ok(if nodes == 0 { 0.0 } else { total / nodes as f64 })
}

fn check_lengths(pred: &[f32], target: &[f32], masks: &[u8], grid: GridShape) -> Result<usize> {
    let n = grid.nodes();
    if n == 0 || !masks.len().is_multiple_of(n) {
        return Err(LearnError::InvalidInput(format!("mask length {} is not a multiple of grid {grid}", masks.len())));
    }
    let samples = masks.len() / n;
    if pred.len() != samples * grid.field_len() || target.len() != pred.len() {
        return Err(LearnError::InvalidInput(format!(
            "prediction ({}) and target ({}) lengths do not match {samples} sample(s) on grid {grid}",
            pred.len(),
            target.len()
        )));
    }
    Ok(samples)
}

/// Mean Euclidean error of one sample: mean over masked nodes of `‖pred − target‖`.
pub fn mean_euclidean_error(pred: &[f32], target: &[f32], mask: &[u8], grid: GridShape) -> Result<f64> {
    if check_lengths(pred, target, mask, grid)? != 1 {
        return Err(LearnError::InvalidInput("mean_euclidean_error takes one sample".into()));
    }
    let n = grid.nodes();
    let (mut total, mut nodes) = (0.0f64, 0usize);
    for v in 0..n {
        if mask[v] != 0 {
            nodes += 1;
            let d2: f64 = (0..CHANNELS)
                .map(|c| {
                    let d = f64::from(pred[c * n + v]) - f64::from(target[c * n + v]);
                    d * d
                })
                .sum();
            total += d2.sqrt();
        }
    }
    if nodes == 0 {
        return Err(LearnError::InvalidInput("sample has an empty mask: its error is undefined".into()));
    }
    Ok(total / nodes as f64)
}

/// Summary of per-sample errors.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ErrorStats {
    /// Mean `ē`.
    pub mean: f64,
    /// Population standard deviation `σ(e)`.
    pub std: f64,
    /// Maximum.
    pub max: f64,
    /// Position of the sample with the maximum error.
    pub worst: usize,
}

impl ErrorStats {
    /// Statistics of a non-empty list of errors.
    pub fn from_errors(errors: &[f64]) -> Result<ErrorStats> {
        if errors.is_empty() {
            return Err(LearnError::InvalidInput("no errors to summarize".into()));
        }
        let n = errors.len() as f64;
        let mean = errors.iter().sum::<f64>() / n;
        let var = errors.iter().map(|e| (e - mean) * (e - mean)).sum::<f64>() / n;
        let (worst, max) =
            errors
                .iter()
                .copied()
                .enumerate()
                .fold((0, f64::NEG_INFINITY), |(bi, bm), (i, e)| if e > bm { (i, e) } else { (bi, bm) });
        Ok(ErrorStats { mean, std: var.sqrt(), max, worst })
    }
}

/// Result of evaluating a model on a set of samples (errors in m).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EvalReport {
    /// Error `e` of each sample (m), in sample order.
    pub errors: Vec<f64>,
    /// Generation index of each sample.
    pub indices: Vec<u64>,
    /// Mean, std, max and worst position.
    pub stats: ErrorStats,
}

impl EvalReport {
    /// Builds the report from per-sample errors.
    pub fn new(errors: Vec<f64>, indices: Vec<u64>) -> Result<EvalReport> {
        let stats = ErrorStats::from_errors(&errors)?;
        Ok(EvalReport { errors, indices, stats })
    }

    /// Generation index of the worst sample.
    pub fn worst_index(&self) -> u64 {
        self.indices[self.stats.worst]
    }

    /// `[mean, std, max]` in millimetres.
    pub fn summary_mm(&self) -> [f64; 3] {
        [mm(self.stats.mean), mm(self.stats.std), mm(self.stats.max)]
    }
}

impl std::fmt::Display for EvalReport {
    /// `mean e = … mm, std = … mm, max = … mm (sample index …), N samples`.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let [mean, std, max] = self.summary_mm();
        write!(
            f,
            "mean e = {mean:.4} mm, std = {std:.4} mm, max = {max:.4} mm (sample index {}), {} samples",
            self.worst_index(),
            self.errors.len()
        )
    }
}
