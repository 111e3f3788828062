//! The learning curve: its rows (training loss, validation error), written as CSV.

use std::path::Path;

use mesh::io::csv::write_csv;
use serde::{Deserialize, Serialize};

use crate::training::metrics::ErrorStats;
use crate::Result;

/// One row of the learning curve.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct CurveRow {
    /// Iterations done.
    pub iteration: usize,
    /// Mean training loss (normalised units) over the iterations since the previous row; none
    /// before the first step (a pre-trained network validated as it came).
    pub train_loss: Option<f64>,
    /// Validation errors (m): mean, std and max of the per-sample mean Euclidean error, if
    /// there are validation samples.
    pub val: Option<ErrorStats>,
}

/// Writes the learning curve as CSV:
/// `iteration,train_loss,val_mean_error_m,val_std_error_m,val_max_error_m` (validation columns
/// empty without validation samples, the training loss empty at iteration 0).
pub fn write_curve_csv(path: &Path, curve: &[CurveRow]) -> Result<()> {
    let header = ["iteration", "train_loss", "val_mean_error_m", "val_std_error_m", "val_max_error_m"];
    let rows = curve.iter().map(|r| {
        let val = r.val.map_or([String::new(), String::new(), String::new()], |v| {
            [format!("{:e}", v.mean), format!("{:e}", v.std), format!("{:e}", v.max)]
        });
        let [mean, std, max] = val;
        [r.iteration.to_string(), r.train_loss.map_or(String::new(), |l| format!("{l:e}")), mean, std, max]
    });
    Ok(write_csv(path, &[], &header, rows)?)
}
