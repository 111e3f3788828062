//! The learning curve: its rows (training loss, validation error), written as CSV.

use std::path::Path;

use mesh::io::write_atomic_bytes;
use serde::{Deserialize, Serialize};

use crate::training::metrics::ErrorStats;
use crate::Result;

/// One row of the learning curve.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct CurveRow {
    /// Iterations done.
    pub iteration: usize,
    /// Mean training loss (normalised units) over the iterations since the previous row.
    pub train_loss: f64,
    /// Validation errors (m): mean, std and max of the per-sample mean Euclidean error, if
    /// there are validation samples.
    pub val: Option<ErrorStats>,
}

/// Writes the learning curve as CSV:
/// `iteration,train_loss,val_mean_error_m,val_std_error_m,val_max_error_m` (validation columns
/// empty without validation samples).
pub fn write_curve_csv(path: &Path, curve: &[CurveRow]) -> Result<()> {
    let mut text = String::from("iteration,train_loss,val_mean_error_m,val_std_error_m,val_max_error_m\n");
    for r in curve {
        let val = r.val.map(|v| format!("{:e},{:e},{:e}", v.mean, v.std, v.max)).unwrap_or_else(|| ",,".into());
        text.push_str(&format!("{},{:e},{val}\n", r.iteration, r.train_loss));
    }
    Ok(write_atomic_bytes(path, text.as_bytes())?)
}
