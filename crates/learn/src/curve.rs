//! The learning curve: its rows, written as CSV and drawn as PNG (training loss,
//! validation error).

use std::path::Path;

use mesh::io::write_atomic_bytes;
use plot::{line_plot, PlotSpec, Series};

use serde::{Deserialize, Serialize};

use crate::metrics::ErrorStats;
use crate::{LearnError, Result};

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

/// Draws the training loss against the iteration into `path` and, when the curve has
/// validation rows, the validation mean error ē ± σ (mm) into `<stem>_error.png` beside it,
/// both on logarithmic y axes.
pub fn plot_learning_curve(path: &Path, curve: &[CurveRow]) -> Result<()> {
    if curve.is_empty() {
        return Err(LearnError::InvalidInput("empty learning curve".into()));
    }
    let fail = |e: plot::PlotError| LearnError::model(path, format!("cannot draw the learning curve: {e}"));
    let loss = Series {
        name: "training loss".into(),
        points: curve.iter().map(|r| (r.iteration as f64, r.train_loss)).collect(),
        band: None,
    };
    let spec = PlotSpec {
        title: "Training loss (masked MSE, normalised)".into(),
        x_label: "iteration".into(),
        y_label: "loss".into(),
        log_y: true,
    };
    line_plot(path, &spec, &[loss]).map_err(fail)?;
    let val: Vec<_> =
        curve.iter().filter_map(|r| r.val.map(|v| (r.iteration as f64, v.mean * 1e3, v.std * 1e3))).collect();
    if !val.is_empty() {
        let series = Series {
            name: "validation mean error".into(),
            points: val.iter().map(|&(x, m, _)| (x, m)).collect(),
            band: Some(val.iter().map(|&(x, m, s)| (x, (m - s).max(m * 0.1), m + s)).collect()),
        };
        let spec = PlotSpec {
            title: "Validation error (mean ± std)".into(),
            x_label: "iteration".into(),
            y_label: "e (mm)".into(),
            log_y: true,
        };
        let stem = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
        line_plot(&path.with_file_name(format!("{stem}_error.png")), &spec, &[series]).map_err(fail)?;
    }
    Ok(())
}
