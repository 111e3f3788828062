//! Learning-curve plot (PNG) with plotters and the embedded DejaVu Sans font.

use std::path::Path;
use std::sync::Once;

use plotters::prelude::*;
use plotters::style::register_font;

use crate::train::CurveRow;
use crate::{LearnError, Result};

static FONT: Once = Once::new();

/// Registers DejaVu Sans (embedded) as plotters' "sans-serif" font.
fn register_fonts() {
    FONT.call_once(|| {
        // The embedded font is a valid TrueType file; registration cannot fail on it.
        let _ = register_font("sans-serif", FontStyle::Normal, dejavu::sans::regular());
    });
}

fn plot_error(path: &Path, e: impl std::fmt::Display) -> LearnError {
    LearnError::model(path, format!("cannot draw the learning curve: {e}"))
}

/// Positive range `[min, max]` of the values, widened for a log axis.
fn log_range(values: impl Iterator<Item = f64>) -> Option<std::ops::Range<f64>> {
    let (lo, hi) = values
        .filter(|v| *v > 0.0 && v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| (lo.min(v), hi.max(v)));
    (lo <= hi).then(|| lo / 1.5..hi * 1.5)
}

/// Draws the training loss and, when present, the validation mean error (mm) against the
/// iteration, on log scales, into a PNG written atomically.
pub fn plot_learning_curve(path: &Path, curve: &[CurveRow]) -> Result<()> {
    if curve.is_empty() {
        return Err(LearnError::InvalidInput("empty learning curve".into()));
    }
    register_fonts();
    let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    let tmp = path.with_file_name(format!(".{name}.tmp-{}.png", std::process::id()));
    let result = draw(&tmp, curve).map_err(|e| plot_error(path, e));
    if let Err(e) = result {
        let _ = std::fs::remove_file(&tmp);
        return Err(e);
    }
    std::fs::rename(&tmp, path).map_err(|e| LearnError::io(path, e))
}

fn draw(path: &Path, curve: &[CurveRow]) -> std::result::Result<(), Box<dyn std::error::Error>> {
    let root = BitMapBackend::new(path, (1200, 500)).into_drawing_area();
    root.fill(&WHITE)?;
    let panels = root.split_evenly((1, 2));
    let x_max = curve.iter().map(|r| r.iteration).max().unwrap_or(1).max(1) as f64;
    let loss: Vec<(f64, f64)> =
        curve.iter().map(|r| (r.iteration as f64, r.train_loss)).filter(|p| p.1 > 0.0).collect();
    let val: Vec<(f64, f64)> =
        curve.iter().filter_map(|r| r.val.map(|e| (r.iteration as f64, e.mean * 1e3))).filter(|p| p.1 > 0.0).collect();
    let series =
        [("training loss (normalised)", "loss", &loss, BLUE), ("validation mean error", "error (mm)", &val, RED)];
    for (panel, (title, y_label, points, color)) in panels.iter().zip(series) {
        let Some(y_range) = log_range(points.iter().map(|p| p.1)) else {
            panel.titled(&format!("{title}: no data"), ("sans-serif", 20))?;
            continue;
        };
        let mut chart = ChartBuilder::on(panel)
            .caption(title, ("sans-serif", 22))
            .margin(15)
            .x_label_area_size(45)
            .y_label_area_size(80)
            .build_cartesian_2d(0.0..x_max, y_range.log_scale())?;
        chart
            .configure_mesh()
            .x_desc("iteration")
            .y_desc(y_label)
            .x_labels(8)
            .y_labels(6)
            .x_label_formatter(&|v| format!("{v:.0}"))
            .y_label_formatter(&|v| format!("{v:.1e}"))
            .label_style(("sans-serif", 14))
            .draw()?;
        chart.draw_series(LineSeries::new(points.iter().copied(), color.stroke_width(2)))?;
        chart.draw_series(points.iter().map(|&p| Circle::new(p, 3, color.filled())))?;
    }
    root.present()?;
    Ok(())
}
