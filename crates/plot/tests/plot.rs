//! Line plots: PNG files are written (valid signature and size), atomically, and bad input is refused.

use augsim_plot::{line_plot, PlotError, PlotSpec, Series};

const PNG_SIGNATURE: [u8; 8] = [0x89, b'P', b'N', b'G', 0x0d, 0x0a, 0x1a, 0x0a];

fn png_size(bytes: &[u8]) -> (u32, u32) {
    assert_eq!(&bytes[..8], &PNG_SIGNATURE);
    assert_eq!(&bytes[12..16], b"IHDR");
    let be = |i: usize| u32::from_be_bytes([bytes[i], bytes[i + 1], bytes[i + 2], bytes[i + 3]]);
    (be(16), be(20))
}

fn estimate_series() -> Vec<Series> {
    let mu: Vec<(f64, f64)> = (0..200).map(|k| (k as f64, 5000.0 - 4000.0 * (-(k as f64) / 30.0).exp())).collect();
    let band = mu.iter().map(|&(x, y)| (x, y - 200.0 / (1.0 + x), y + 200.0 / (1.0 + x))).collect();
    vec![
        Series { name: "μ ± σ".into(), points: mu, band: Some(band) },
        Series { name: "truth".into(), points: vec![(0.0, 5000.0), (199.0, 5000.0)], band: None },
        Series { name: String::new(), points: vec![(0.0, 1000.0), (f64::NAN, 2.0), (199.0, 1000.0)], band: None },
    ]
}

#[test]
fn linear_and_log_plots_are_written_as_png() {
    let dir = tempfile::tempdir().unwrap();
    let spec = PlotSpec {
        title: "Young's modulus".into(),
        x_label: "iteration".into(),
        y_label: "E (Pa)".into(),
        log_y: false,
    };
    let path = dir.path().join("young.png");
    line_plot(&path, &spec, &estimate_series()).unwrap();
    let bytes = std::fs::read(&path).unwrap();
    assert_eq!(png_size(&bytes), (1000, 600));
    // Overwriting an existing plot works and leaves no temporary file behind. A log axis over four decades,
    // with a zero left out; a narrow positive range on a log axis is drawn too.
    let log = PlotSpec { log_y: true, ..spec };
    let decay: Vec<(f64, f64)> = (0..100).map(|k| (k as f64, 10f64.powf(-(k as f64) / 25.0))).collect();
    let series = [
        Series { name: "innovation".into(), points: decay, band: None },
        Series { name: "with a zero".into(), points: vec![(0.0, 0.0), (10.0, 0.3)], band: None },
    ];
    line_plot(&path, &log, &series).unwrap();
    line_plot(&dir.path().join("narrow.png"), &log, &estimate_series()).unwrap();
    std::fs::remove_file(dir.path().join("narrow.png")).unwrap();
    assert_eq!(png_size(&std::fs::read(&path).unwrap()), (1000, 600));
    let names: Vec<String> =
        std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    assert_eq!(names, ["young.png"]);
    // The two charts differ (the axis really changed).
    assert_ne!(bytes, std::fs::read(&path).unwrap());
}

#[test]
fn unusable_input_is_refused_with_the_path() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("empty.png");
    let spec = PlotSpec::default();
    let err = line_plot(&path, &spec, &[]).unwrap_err();
    assert!(matches!(err, PlotError::NoData { .. }) && err.to_string().contains("empty.png"), "{err}");
    let only_negative = [Series { name: "e".into(), points: vec![(0.0, -1.0), (1.0, 0.0)], band: None }];
    let log = PlotSpec { log_y: true, ..PlotSpec::default() };
    assert!(line_plot(&path, &log, &only_negative).unwrap_err().to_string().contains("log axis"));
    assert!(!path.exists());
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0, "nothing is left behind");
    // A directory that does not exist yet is made, as every writer of augsim makes it; a path
    // under a file is refused, naming it.
    let missing = dir.path().join("no_such_dir").join("p.png");
    line_plot(&missing, &spec, &estimate_series()).unwrap();
    assert!(missing.exists());
    let under_a_file = missing.join("q.png");
    let err = line_plot(&under_a_file, &spec, &estimate_series()).unwrap_err();
    assert!(err.to_string().contains("p.png"), "{err}");
}

#[test]
fn scatter_plots_keep_the_aspect_of_the_data() {
    use augsim_plot::{scatter_plot, PointSet};
    let dir = tempfile::tempdir().unwrap();
    let spec = PlotSpec { title: "side view".into(), x_label: "x (m)".into(), y_label: "z (m)".into(), log_y: false };
    let ring: Vec<(f64, f64)> = (0..60).map(|k| (k as f64 * 0.1).sin_cos()).map(|(s, c)| (0.2 * c, 0.05 * s)).collect();
    let sets = [
        PointSet { name: "surface".into(), points: ring.clone(), radius: 2, color: 7 },
        PointSet { name: "targets".into(), points: vec![(0.0, 0.0), (f64::NAN, 1.0)], radius: 5, color: 1 },
    ];
    let path = dir.path().join("scatter.png");
    scatter_plot(&path, &spec, &sets, &[((0.0, 0.0), (0.01, 0.01))]).unwrap();
    let (w, h) = png_size(&std::fs::read(&path).unwrap());
    // A 4:1 wide scene gives a wide picture (at the minimum height here).
    assert_eq!(w, 1000);
    assert!(h < w / 2, "{w} x {h}");
    let tall: Vec<(f64, f64)> = ring.iter().map(|&(x, y)| (y, x)).collect();
    let tall_sets = [PointSet { points: tall, ..sets[0].clone() }];
    scatter_plot(&path, &spec, &tall_sets, &[]).unwrap();
    let (_, h2) = png_size(&std::fs::read(&path).unwrap());
    assert!(h2 > w, "a tall scene gives a tall picture: {h2}");
    let e = scatter_plot(&dir.path().join("none.png"), &spec, &[], &[]).unwrap_err();
    assert!(matches!(e, PlotError::NoData { .. }), "{e}");
    assert!(!dir.path().join("none.png").exists());
}

#[test]
fn bar_charts_are_written_and_mismatched_series_refused() {
    use augsim_plot::{bar_chart, BarSeries};
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bars.png");
    let spec = PlotSpec { title: "TRE".into(), x_label: "method".into(), y_label: "mm".into(), log_y: false };
    let categories = vec!["FEM".to_string(), "U-Net".to_string()];
    let series = [
        BarSeries { name: "ours".into(), values: vec![Some(2.2), Some(2.1)] },
        BarSeries { name: "published".into(), values: vec![Some(3.79), None] },
    ];
    bar_chart(&path, &spec, &categories, &series).unwrap();
    assert_eq!(png_size(&std::fs::read(&path).unwrap()), (1000, 600));
    let short = [BarSeries { name: "ours".into(), values: vec![Some(1.0)] }];
    let e = bar_chart(&dir.path().join("bad.png"), &spec, &categories, &short).unwrap_err();
    assert!(e.to_string().contains("bad.png") && e.to_string().contains("1 values for 2 categories"), "{e}");
    let empty = [BarSeries { name: "ours".into(), values: vec![None, Some(f64::NAN)] }];
    assert!(bar_chart(&dir.path().join("empty.png"), &spec, &categories, &empty).is_err());
    assert!(!dir.path().join("bad.png").exists() && !dir.path().join("empty.png").exists());
    // Ten categories of times spanning three decades: a log axis, and a chart wide enough for the
    // labels.
    let categories: Vec<String> = (0..10).map(|k| format!("case {k} label")).collect();
    let times = [BarSeries { name: "ms".into(), values: (0..10).map(|k| Some(2.0 * 2f64.powi(k))).collect() }];
    let log = PlotSpec { log_y: true, ..spec };
    bar_chart(&path, &log, &categories, &times).unwrap();
    assert_eq!(png_size(&std::fs::read(&path).unwrap()), (1300, 600));
}
