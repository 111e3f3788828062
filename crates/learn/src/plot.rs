//! Learning-curve plots (PNG): the training loss and the validation error.

use std::path::Path;

use plot::{line_plot, PlotSpec, Series};

use crate::train::CurveRow;
use crate::{LearnError, Result};

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
