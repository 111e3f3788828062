//! PNG plots for augsim reports: line charts with several named series, optional shaded bands (e.g. μ ± σ),
//! linear or logarithmic y axis; scatter plots of projected 3D points with equal axis scales; grouped bar charts. Text uses the
//! embedded DejaVu Sans font (no system font lookup), and files are written atomically (temporary sibling, then
//! rename).

pub mod viewer;

use std::ops::Range;
use std::path::{Path, PathBuf};
use std::sync::Once;

use plotters::coord::ranged1d::{AsRangedCoord, ValueFormatter};
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::register_font;

/// Width and height of the PNG, pixels.
const SIZE: (u32, u32) = (1000, 600);

/// Colours of successive series (repeated beyond ten).
const PALETTE: [RGBColor; 10] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(255, 127, 14),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(127, 127, 127),
    RGBColor(188, 189, 34),
    RGBColor(23, 190, 207),
];

/// Errors of plotting.
#[derive(Debug, thiserror::Error)]
pub enum PlotError {
    /// Nothing drawable: no series, or no finite (positive, on a log axis) value.
    #[error("cannot plot {path}: {message}")]
    NoData {
        /// The file that was to be written.
        path: PathBuf,
        /// What is missing.
        message: String,
    },
    /// The drawing backend failed.
    #[error("cannot draw {path}: {message}")]
    Draw {
        /// The file being written.
        path: PathBuf,
        /// The backend's message.
        message: String,
    },
    /// Renaming the finished temporary file onto the target failed.
    #[error("cannot write {path}: {error}")]
    Io {
        /// The target file.
        path: PathBuf,
        /// The underlying error.
        error: std::io::Error,
    },
}

/// Titles and axes of a chart.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct PlotSpec {
    /// Caption above the chart.
    pub title: String,
    /// Label of the x axis.
    pub x_label: String,
    /// Label of the y axis.
    pub y_label: String,
    /// Logarithmic y axis (non-positive values are left out); drawn linear when the values span less than a
    /// decade, where a log axis would carry no tick label.
    pub log_y: bool,
}

/// One line of a chart.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Series {
    /// Legend entry; an empty name leaves the series out of the legend.
    pub name: String,
    /// (x, y) points in order; non-finite points are skipped.
    pub points: Vec<(f64, f64)>,
    /// Optional shaded band (x, low, high) drawn under the line in a light shade of its colour.
    pub band: Option<Vec<(f64, f64, f64)>>,
}

static FONT: Once = Once::new();

/// Registers DejaVu Sans (embedded) as plotters' "sans-serif" font.
fn register_fonts() {
    FONT.call_once(|| {
        // The embedded font is a valid TrueType file; registration cannot fail on it.
        let _ = register_font("sans-serif", FontStyle::Normal, dejavu::sans::regular());
    });
}

/// Draws `series` on one chart into the PNG file `path` (1000 × 600 pixels), written atomically.
pub fn line_plot(path: &Path, spec: &PlotSpec, series: &[Series]) -> Result<(), PlotError> {
    let no_data = |message: &str| PlotError::NoData { path: path.to_path_buf(), message: message.into() };
    let usable = |y: f64| y.is_finite() && (!spec.log_y || y > 0.0);
    let mut xs = Vec::new();
    let mut ys = Vec::new();
    for s in series {
        for &(x, y) in s.points.iter().filter(|(x, y)| x.is_finite() && usable(*y)) {
            xs.push(x);
            ys.push(y);
        }
        for &(x, lo, hi) in s.band.iter().flatten().filter(|(x, _, _)| x.is_finite()) {
            xs.push(x);
            ys.extend([lo, hi].into_iter().filter(|v| usable(*v)));
        }
    }
    let y_range = padded_range(&ys, spec.log_y).ok_or_else(|| {
        no_data(if spec.log_y { "no positive finite value for the log axis" } else { "no finite value" })
    })?;
    let x_range = padded_range(&xs, false).ok_or_else(|| no_data("no finite point"))?;

    write_png(path, SIZE, |root| {
        if spec.log_y && y_range.end >= 10.0 * y_range.start {
            let keys = log_ticks(&y_range);
            draw(root, spec, series, x_range, y_range.clone().log_scale().with_key_points(keys), y_range)
        } else {
            draw(root, spec, series, x_range, y_range.clone(), y_range)
        }
    })
}

/// A straight segment between two points of a chart.
pub type Segment = ((f64, f64), (f64, f64));

/// A set of points drawn as dots of one colour (the `index`-th palette colour).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct PointSet {
    /// Legend entry; an empty name leaves the set out of the legend.
    pub name: String,
    /// (x, y) positions; non-finite ones are skipped.
    pub points: Vec<(f64, f64)>,
    /// Dot radius, pixels.
    pub radius: u32,
    /// Palette colour index.
    pub color: usize,
}

/// Draws point sets (later ones on top) into the PNG file `path` with equal scales on both axes
/// (a projection of a 3D scene keeps its shape), written atomically; `links` are grey segments
/// (e.g. from an estimate to the truth).
pub fn scatter_plot(path: &Path, spec: &PlotSpec, sets: &[PointSet], links: &[Segment]) -> Result<(), PlotError> {
    let finite = |p: &&(f64, f64)| p.0.is_finite() && p.1.is_finite();
    let all: Vec<(f64, f64)> = sets.iter().flat_map(|s| s.points.iter().filter(finite).copied()).collect();
    let (Some(x), Some(y)) = (
        padded_range(&all.iter().map(|p| p.0).collect::<Vec<_>>(), false),
        padded_range(&all.iter().map(|p| p.1).collect::<Vec<_>>(), false),
    ) else {
        return Err(PlotError::NoData { path: path.to_path_buf(), message: "no finite point".into() });
    };
    let (x, y, size) = equal_scales(x, y, &spec.title);
    write_png(path, size, |root| {
        let err = |e: &dyn std::fmt::Display| e.to_string();
        let mut chart = new_chart(root, &spec.title, Frame::SCATTER, x, y)?;
        chart
            .configure_mesh()
            .x_desc(&spec.x_label)
            .y_desc(&spec.y_label)
            .light_line_style(RGBColor(245, 245, 245))
            .label_style(("sans-serif", 14))
            .axis_desc_style(("sans-serif", 16))
            .draw()
            .map_err(|e| err(&e))?;
        let grey = RGBColor(90, 90, 90);
        chart
            .draw_series(links.iter().map(|&(a, b)| PathElement::new(vec![a, b], grey.stroke_width(1))))
            .map_err(|e| err(&e))?;
        for s in sets {
            let color = PALETTE[s.color % PALETTE.len()];
            let r = s.radius;
            let drawn = chart
                .draw_series(s.points.iter().filter(finite).map(|&p| Circle::new(p, r, color.filled())))
                .map_err(|e| err(&e))?;
            if !s.name.is_empty() {
                drawn.label(&s.name).legend(move |(x, y)| Circle::new((x + 10, y), r.max(4), color.filled()));
            }
        }
        if sets.iter().any(|s| !s.name.is_empty()) {
            draw_legend(&mut chart, SeriesLabelPosition::LowerRight)?;
        }
        Ok(())
    })
}

/// The data ranges (`x`, `y` widened about their centres) and picture size of a scatter plot captioned `title`:
/// the height follows the data's aspect within 300..=1400 pixels, and a unit spans as many pixels on both axes.
fn equal_scales(x: Range<f64>, y: Range<f64>, title: &str) -> (Range<f64>, Range<f64>, (u32, u32)) {
    let (across, down) = Frame::SCATTER.surround(title);
    // Pixels from the first to the last pixel of the plotting area, where a range's ends are drawn.
    let w = SIZE.0 - across - 1;
    let aspect = (y.end - y.start) / (x.end - x.start);
    let height = (f64::from(w) * aspect + f64::from(down + 1)).round().clamp(300.0, 1400.0) as u32;
    let h = height - down - 1;
    let per_pixel = ((x.end - x.start) / f64::from(w)).max((y.end - y.start) / f64::from(h));
    let widen = |r: Range<f64>, pixels: u32| {
        let (centre, half) = (0.5 * (r.start + r.end), 0.5 * per_pixel * f64::from(pixels));
        centre - half..centre + half
    };
    (widen(x, w), widen(y, h), (SIZE.0, height))
}

/// One series of a grouped bar chart: a value (or none) per category, in the `index`-th palette colour.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct BarSeries {
    /// Legend entry.
    pub name: String,
    /// One value per category; `None` or a non-finite value leaves a gap.
    pub values: Vec<Option<f64>>,
}

/// Draws a grouped bar chart (one group per category, one bar per series) into the PNG file
/// `path`, written atomically: bars from 0, or with `spec.log_y` (positive values spanning a
/// decade or more) from the decade below the smallest on a logarithmic axis. The chart is 1000
/// pixels wide, wider when its categories need it (130 pixels each). Every series needs one value
/// per category.
pub fn bar_chart(path: &Path, spec: &PlotSpec, categories: &[String], series: &[BarSeries]) -> Result<(), PlotError> {
    let no_data = |message: String| PlotError::NoData { path: path.to_path_buf(), message };
    if let Some(s) = series.iter().find(|s| s.values.len() != categories.len()) {
        return Err(no_data(format!(
            "series '{}' has {} values for {} categories",
            s.name,
            s.values.len(),
            categories.len()
        )));
    }
    let values: Vec<f64> =
        series.iter().flat_map(|s| s.values.iter().flatten().copied()).filter(|v| v.is_finite()).collect();
    let top = values.iter().fold(0.0f64, |m, &v| m.max(v));
    let bottom = values.iter().fold(0.0f64, |m, &v| m.min(v));
    if values.is_empty() || top == bottom {
        return Err(no_data("no finite non-zero value".into()));
    }
    let smallest = values.iter().copied().filter(|v| *v > 0.0).fold(f64::INFINITY, f64::min);
    let size = (SIZE.0.max(130 * categories.len() as u32), SIZE.1);
    write_png(path, size, |root| {
        if spec.log_y && bottom >= 0.0 && top >= 10.0 * smallest {
            let floor = decade_below(smallest);
            let y = floor..top * 1.5;
            let keys = log_ticks(&y);
            draw_bars(root, spec, categories, series, y.clone().log_scale().with_key_points(keys), y, floor)
        } else {
            let pad = 0.08 * (top - bottom);
            let y = (bottom - if bottom < 0.0 { pad } else { 0.0 })..(top + pad);
            draw_bars(root, spec, categories, series, y.clone(), y, 0.0)
        }
    })
}

/// The largest power of ten strictly below `v` (positive).
fn decade_below(v: f64) -> f64 {
    let decade = 10f64.powf(v.log10().floor());
    if decade < v {
        decade
    } else {
        decade / 10.0
    }
}

/// [`bar_chart`]'s drawing on the y coordinate `y_coord` over `y_range`, bars from `base`.
fn draw_bars<Y>(
    root: &DrawingArea<BitMapBackend, Shift>,
    spec: &PlotSpec,
    categories: &[String],
    series: &[BarSeries],
    y_coord: Y,
    y_range: Range<f64>,
    base: f64,
) -> Result<(), String>
where
    Y: AsRangedCoord<Value = f64>,
    Y::CoordDescType: ValueFormatter<f64>,
{
    let err = |e: &dyn std::fmt::Display| e.to_string();
    let n = categories.len() as f64;
    let mut chart = new_chart(root, &spec.title, Frame::LARGE, 0.0..n, y_coord)?;
    let y_span = (y_range.end - y_range.start).abs().max(y_range.end.abs());
    let label = |v: &f64| {
        let k = v.floor();
        if (v - k - 0.5).abs() < 1e-6 && k >= 0.0 && (k as usize) < categories.len() {
            categories[k as usize].clone()
        } else {
            String::new()
        }
    };
    chart
        .configure_mesh()
        .disable_x_mesh()
        .x_labels(2 * categories.len() + 1)
        .x_desc(&spec.x_label)
        .y_desc(&spec.y_label)
        .light_line_style(RGBColor(242, 242, 242))
        .label_style(("sans-serif", 15))
        .axis_desc_style(("sans-serif", 17))
        .x_label_formatter(&label)
        .y_label_formatter(&|v| tick_label(*v, y_span))
        .draw()
        .map_err(|e| err(&e))?;
    let width = 0.8 / series.len().max(1) as f64;
    for (i, s) in series.iter().enumerate() {
        let color = PALETTE[i % PALETTE.len()];
        let bars = s.values.iter().enumerate().filter_map(|(c, v)| {
            // On a log axis a value that is not positive has no bar.
            let v = v.filter(|v| v.is_finite() && (base == 0.0 || *v > 0.0))?;
            let x0 = c as f64 + 0.1 + i as f64 * width;
            Some(Rectangle::new([(x0, base), (x0 + 0.92 * width, v)], color.filled()))
        });
        let drawn = chart.draw_series(bars).map_err(|e| err(&e))?;
        if !s.name.is_empty() {
            drawn.label(&s.name).legend(move |(x, y)| Rectangle::new([(x, y - 6), (x + 16, y + 6)], color.filled()));
        }
    }
    if series.iter().any(|s| !s.name.is_empty()) {
        draw_legend(&mut chart, SeriesLabelPosition::UpperLeft)?;
    }
    Ok(())
}

/// Title size and label-area sizes (pixels) of a chart.
#[derive(Clone, Copy)]
struct Frame {
    title: u32,
    x_labels: u32,
    y_labels: u32,
}

/// Blank border around every chart, pixels.
const MARGIN: u32 = 20;

impl Frame {
    /// Line and bar charts.
    const LARGE: Frame = Frame { title: 24, x_labels: 50, y_labels: 90 };
    /// Scatter plots.
    const SCATTER: Frame = Frame { title: 22, x_labels: 45, y_labels: 70 };

    /// Pixels of a chart captioned `title` outside its plotting area, across and down: the margins, the label
    /// areas and the caption (its text and up to 5 pixels above and below, as plotters lays it out).
    fn surround(self, title: &str) -> (u32, u32) {
        register_fonts();
        let text = ("sans-serif", self.title).into_font().box_size(title).map_or(self.title, |(_, h)| h);
        (2 * MARGIN + self.y_labels, 2 * MARGIN + self.x_labels + text + 2 * (text / 2).min(5))
    }
}

/// A chart on a PNG bitmap with x and y coordinates of types `X`, `Y`.
type Chart<'b, X, Y> = ChartContext<'b, BitMapBackend<'b>, Cartesian2d<X, Y>>;

/// Fills `root` white and sets up a chart titled `title` over the coordinates `x`, `y`.
fn new_chart<'b, X: AsRangedCoord, Y: AsRangedCoord>(
    root: &DrawingArea<BitMapBackend<'b>, Shift>,
    title: &str,
    frame: Frame,
    x: X,
    y: Y,
) -> Result<Chart<'b, X::CoordDescType, Y::CoordDescType>, String> {
    root.fill(&WHITE).map_err(|e| e.to_string())?;
    ChartBuilder::on(root)
        .caption(title, ("sans-serif", frame.title))
        .margin(MARGIN)
        .x_label_area_size(frame.x_labels)
        .y_label_area_size(frame.y_labels)
        .build_cartesian_2d(x, y)
        .map_err(|e| e.to_string())
}

/// Renders `draw` on a `size` bitmap into a temporary sibling of `path`, then persists (renames) it onto `path`
/// (nothing is left behind on failure). This crate does not depend on `mesh`, whose `mesh::io::write_atomic` the
/// other crates use, so it calls `tempfile`'s persist itself: the same temporary sibling and rename, with a `.png`
/// suffix because the encoder picks the format from the name.
fn write_png(
    path: &Path,
    size: (u32, u32),
    draw: impl FnOnce(&DrawingArea<BitMapBackend, Shift>) -> Result<(), String>,
) -> Result<(), PlotError> {
    register_fonts();
    let io = |error: std::io::Error| PlotError::Io { path: path.to_path_buf(), error };
    let tmp = sibling_tempfile(path, ".tmp.png").map_err(io)?;
    let drawn = {
        let root = BitMapBackend::new(tmp.path(), size).into_drawing_area();
        draw(&root).and_then(|()| root.present().map_err(|e| e.to_string()))
    };
    drawn.map_err(|message| PlotError::Draw { path: path.to_path_buf(), message })?;
    tmp.persist(path).map_err(|e| io(e.error))?;
    Ok(())
}

/// A temporary file beside `path` (same directory, made if need be, so that persisting it over `path` is a rename), named
/// `.<name>.XXXXXX<suffix>`, with ordinary permissions (0o666 less the umask) rather than a temporary file's
/// owner-only ones. The plot crate's writers fill it and persist it: a reader sees the old file or the new one.
pub(crate) fn sibling_tempfile(path: &Path, suffix: &str) -> std::io::Result<tempfile::NamedTempFile> {
    let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    let dir = path.parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(Path::new("."));
    if let Some(file) = dir.ancestors().find(|a| a.is_file()) {
        let message = format!("{} is a file, not a directory", file.display());
        return Err(std::io::Error::new(std::io::ErrorKind::NotADirectory, message));
    }
    std::fs::create_dir_all(dir)?;
    let prefix = format!(".{name}.");
    let mut builder = tempfile::Builder::new();
    builder.prefix(&prefix).suffix(suffix);
    #[cfg(unix)]
    builder.permissions(std::os::unix::fs::PermissionsExt::from_mode(0o666));
    builder.tempfile_in(dir)
}

/// Range of the values with a 5 % margin (multiplicative on a log axis); a single value v gets v ± |v|/2
/// (± 1/2 when v is 0), or v/2..2v on a log axis.
fn padded_range(values: &[f64], log: bool) -> Option<Range<f64>> {
    let (lo, hi) = values
        .iter()
        .filter(|v| v.is_finite() && (!log || **v > 0.0))
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &v| (lo.min(v), hi.max(v)));
    if lo > hi {
        return None;
    }
    Some(if log {
        let pad = if hi > lo { (hi / lo).powf(0.05) } else { 2.0 };
        lo / pad..hi * pad
    } else {
        let pad = if hi > lo {
            0.05 * (hi - lo)
        } else if lo != 0.0 {
            0.5 * lo.abs()
        } else {
            0.5
        };
        lo - pad..hi + pad
    })
}

fn draw<Y>(
    root: &DrawingArea<BitMapBackend, Shift>,
    spec: &PlotSpec,
    series: &[Series],
    x_range: Range<f64>,
    y_coord: Y,
    y_range: Range<f64>,
) -> Result<(), String>
where
    Y: AsRangedCoord<Value = f64>,
    Y::CoordDescType: ValueFormatter<f64>,
{
    let err = |e: &dyn std::fmt::Display| e.to_string();
    let mut chart = new_chart(root, &spec.title, Frame::LARGE, x_range, y_coord)?;
    let y_span = (y_range.end - y_range.start).abs().max(y_range.end.abs());
    chart
        .configure_mesh()
        .x_desc(&spec.x_label)
        .y_desc(&spec.y_label)
        .light_line_style(RGBColor(242, 242, 242))
        .bold_line_style(RGBColor(205, 205, 205))
        .label_style(("sans-serif", 15))
        .axis_desc_style(("sans-serif", 17))
        .x_label_formatter(&|v| tick_label(*v, 0.0))
        .y_label_formatter(&|v| tick_label(*v, y_span))
        .draw()
        .map_err(|e| err(&e))?;
    let clamp = |y: f64| y.clamp(y_range.start, y_range.end);
    for (i, s) in series.iter().enumerate() {
        let color = PALETTE[i % PALETTE.len()];
        if let Some(band) = &s.band {
            let ok: Vec<&(f64, f64, f64)> =
                band.iter().filter(|b| b.0.is_finite() && b.1.is_finite() && b.2.is_finite()).collect();
            if ok.len() >= 2 {
                let outline: Vec<(f64, f64)> =
                    ok.iter().map(|b| (b.0, clamp(b.2))).chain(ok.iter().rev().map(|b| (b.0, clamp(b.1)))).collect();
                chart
                    .draw_series(std::iter::once(Polygon::new(outline, color.mix(0.2).filled())))
                    .map_err(|e| err(&e))?;
            }
        }
        let points: Vec<(f64, f64)> = s
            .points
            .iter()
            .copied()
            .filter(|(x, y)| x.is_finite() && y.is_finite() && (!spec.log_y || *y > 0.0))
            .collect();
        let line = chart.draw_series(LineSeries::new(points, color.stroke_width(2))).map_err(|e| err(&e))?;
        if !s.name.is_empty() {
            line.label(&s.name)
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 24, y)], color.stroke_width(3)));
        }
    }
    if series.iter().any(|s| !s.name.is_empty()) {
        draw_legend(&mut chart, SeriesLabelPosition::UpperRight)?;
    }
    Ok(())
}

/// Draws the legend of the labelled series at `position`.
fn draw_legend<'a, CT: CoordTranslate>(
    chart: &mut ChartContext<'a, BitMapBackend<'a>, CT>,
    position: SeriesLabelPosition,
) -> Result<(), String> {
    chart
        .configure_series_labels()
        .position(position)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .label_font(("sans-serif", 15))
        .draw()
        .map_err(|e| e.to_string())
}

/// The 1-2-5 values of each decade inside `range` (positive): labelled ticks on a log axis
/// (plotters' own labels only the decade of the upper bound when the range spans a few decades).
fn log_ticks(range: &Range<f64>) -> Vec<f64> {
    let first = range.start.log10().floor() as i32;
    let last = range.end.log10().ceil() as i32;
    let all: Vec<f64> =
        (first..=last).flat_map(|e| [1.0, 2.0, 5.0].map(|m| m * 10f64.powi(e))).filter(|v| range.contains(v)).collect();
    // Several decades: the decades only, so that labels do not crowd.
    if last - first > 4 {
        all.into_iter().filter(|v| (v.log10() - v.log10().round()).abs() < 1e-9).collect()
    } else {
        all
    }
}

/// Tick text: plain decimals for moderate magnitudes, scientific notation with a trimmed mantissa otherwise
/// (`span` is the axis extent, so that 0 on an axis of tiny values reads "0").
fn tick_label(v: f64, span: f64) -> String {
    let a = v.abs();
    if a == 0.0 || a < 1e-9 * span {
        "0".into()
    } else if (0.1..1e5).contains(&a) {
        let s = format!("{v:.3}");
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        let s = format!("{v:.2e}");
        match s.split_once('e') {
            Some((mantissa, exponent)) => {
                let mantissa = if mantissa.contains('.') {
                    mantissa.trim_end_matches('0').trim_end_matches('.')
                } else {
                    mantissa
                };
                format!("{mantissa}e{exponent}")
            }
            None => s,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scatter_plots_draw_a_unit_as_long_on_both_axes() {
        register_fonts();
        // Tall and wide data sets reach the height limits; a square one does not.
        for (x, y) in [(0.0..1.0, -2.0..2.0), (0.0..5.0, 1.0..1.5), (-1.0..1.0, -1.0..1.0)] {
            let (xr, yr, (w, h)) = equal_scales(x.clone(), y.clone(), "side view");
            assert!(xr.start <= x.start && x.end <= xr.end && yr.start <= y.start && y.end <= yr.end);
            let mut buffer = vec![0; (3 * w * h) as usize];
            let root = BitMapBackend::with_buffer(&mut buffer, (w, h)).into_drawing_area();
            let chart = new_chart(&root, "side view", Frame::SCATTER, xr.clone(), yr.clone()).unwrap();
            let (left, bottom) = chart.backend_coord(&(xr.start, yr.start));
            let (right, top) = chart.backend_coord(&(xr.end, yr.end));
            let per_x = (xr.end - xr.start) / f64::from(right - left);
            let per_y = (yr.end - yr.start) / f64::from(bottom - top);
            assert!((per_x / per_y - 1.0).abs() < 0.01, "{x:?} {y:?}: {per_x} vs {per_y} units per pixel, {w} x {h}");
        }
    }

    /// A path through a file is told as such, not as the system's "File exists".
    #[test]
    fn a_file_where_a_folder_should_be_is_named() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("cloud.csv");
        std::fs::write(&file, "x").unwrap();
        let e = sibling_tempfile(&file.join("sub/view.html"), ".tmp").unwrap_err().to_string();
        assert_eq!(e, format!("{} is a file, not a directory", file.display()));
    }

    #[test]
    fn log_bars_start_a_decade_below_the_smallest_value() {
        assert_eq!(decade_below(10.0), 1.0);
        assert_eq!(decade_below(2.0), 1.0);
        assert_eq!(decade_below(1000.0), 100.0);
        assert!((decade_below(0.05) / 0.01 - 1.0).abs() < 1e-12);
    }

    #[test]
    fn a_single_value_gets_a_range_around_it() {
        assert_eq!(padded_range(&[0.0], false), Some(-0.5..0.5));
        assert_eq!(padded_range(&[-4.0, -4.0], false), Some(-6.0..-2.0));
        assert_eq!(padded_range(&[3.0], true), Some(1.5..6.0));
        assert_eq!(padded_range(&[0.0, 10.0], false), Some(-0.5..10.5));
        assert_eq!(padded_range(&[f64::NAN], false), None);
    }

    #[test]
    fn a_log_axis_is_labelled_at_1_2_5_in_each_decade_or_at_decades_over_many() {
        assert_eq!(log_ticks(&(1.3..45.0)), [2.0, 5.0, 10.0, 20.0]);
        let wide = log_ticks(&(2e-4..3e3));
        assert_eq!(wide.len(), 7, "{wide:?}");
        assert!(wide.iter().zip([1e-3, 1e-2, 0.1, 1.0, 10.0, 100.0, 1000.0]).all(|(a, b)| (a / b - 1.0).abs() < 1e-12));
    }
}
