//! The learning curve of a training run drawn as PNG: the training loss, and the validation
//! error ē ± σ when the run validated.

use std::path::Path;

use anyhow::{bail, Context, Result};
use learn::CurveRow;
use mesh::length::mm;
use plot::{line_plot, PlotSpec, Series};

/// File name of the loss plot that `augsim train` writes beside `curve.csv`.
pub const CURVE_PNG: &str = "curve.png";

/// Draws the training loss against the iteration into `path` and, when the curve has
/// validation rows, the validation mean error ē ± σ (mm) into `<stem>_error.png` beside it,
/// both on logarithmic y axes.
pub fn plot_learning_curve(path: &Path, curve: &[CurveRow]) -> Result<()> {
    if curve.is_empty() {
        bail!("empty learning curve");
    }
    let what = || format!("drawing the learning curve {}", path.display());
    let loss = Series {
        name: "training loss".into(),
        points: curve.iter().filter_map(|r| Some((r.iteration as f64, r.train_loss?))).collect(),
        band: None,
    };
    let spec = PlotSpec {
        title: "Training loss (masked MSE, normalised)".into(),
        x_label: "iteration".into(),
        y_label: "loss".into(),
        log_y: true,
    };
    line_plot(path, &spec, &[loss]).with_context(what)?;
    let val: Vec<_> = curve.iter().filter_map(|r| r.val.map(|v| (r.iteration as f64, mm(v.mean), mm(v.std)))).collect();
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
        line_plot(&path.with_file_name(format!("{stem}_error.png")), &spec, &[series]).with_context(what)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use learn::ErrorStats;

    #[test]
    fn draws_loss_and_validation_pngs() {
        let dir = tempfile::tempdir().unwrap();
        let val = ErrorStats { mean: 2e-3, std: 1e-3, max: 5e-3, worst: 0 };
        let curve: Vec<CurveRow> = (1..=4)
            .map(|i| CurveRow {
                iteration: 100 * i,
                train_loss: Some(1.0 / i as f64),
                val: (i % 2 == 0).then_some(val),
            })
            .collect();
        let path = dir.path().join(CURVE_PNG);
        plot_learning_curve(&path, &curve).unwrap();
        for file in [path.clone(), dir.path().join("curve_error.png")] {
            let png = std::fs::read(&file).unwrap();
            assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n", "{}", file.display());
        }
        assert!(plot_learning_curve(&path, &[]).is_err());
    }
}
