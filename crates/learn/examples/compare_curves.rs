//! Draws the validation error of several training runs against the step on one chart, e.g.
//! training from scratch against fine-tuning (DESIGN scenario 3):
//!
//! `cargo run --release -p augsim-learn --example compare_curves -- out.png "scratch=runs/a/curve.csv" "fine-tuned=runs/b/curve.csv"`
//!
//! Each CSV is a `curve.csv` written by `augsim train` (`iteration,train_loss,val_mean_error_m,...`).

use std::path::Path;

use plot::{line_plot, PlotSpec, Series};

fn read_curve(path: &Path) -> Result<Vec<(f64, f64)>, String> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let mut lines = text.lines();
    let header = lines.next().ok_or_else(|| format!("{}: empty", path.display()))?;
    let column = header
        .split(',')
        .position(|c| c == "val_mean_error_m")
        .ok_or_else(|| format!("{}: no val_mean_error_m column", path.display()))?;
    let mut points = Vec::new();
    for (l, line) in lines.enumerate() {
        let fields: Vec<&str> = line.split(',').collect();
        let parse = |i: usize| fields.get(i).and_then(|f| f.parse::<f64>().ok());
        match (parse(0), parse(column)) {
            (Some(step), Some(e)) => points.push((step, e * 1e3)),
            _ => return Err(format!("{}:{}: expected an iteration and a validation error", path.display(), l + 2)),
        }
    }
    Ok(points)
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.len() < 2 {
        eprintln!("usage: compare_curves OUT.png LABEL=curve.csv [LABEL=curve.csv ...]");
        std::process::exit(2);
    }
    let mut series = Vec::new();
    for arg in &args[1..] {
        let (name, path) = arg.split_once('=').unwrap_or((arg.as_str(), arg.as_str()));
        match read_curve(Path::new(path)) {
            Ok(points) => series.push(Series { name: name.into(), points, band: None }),
            Err(e) => {
                eprintln!("error: {e}");
                std::process::exit(1);
            }
        }
    }
    let spec = PlotSpec {
        title: "Validation mean error against training step".into(),
        x_label: "step".into(),
        y_label: "ē (mm)".into(),
        log_y: true,
    };
    if let Err(e) = line_plot(Path::new(&args[0]), &spec, &series) {
        eprintln!("error: {e}");
        std::process::exit(1);
    }
    println!("wrote {}", args[0]);
}
