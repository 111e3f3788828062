//! Points on disk, with a label per point and, where the file names them, their frame and unit:
//!
//! - **CSV**: a header naming the columns `x`, `y` and `z` (any order, any case), or `x_mm`,
//!   `y_mm`, `z_mm` (or `_m`), which name the unit; a `label`, `name` or `id` column gives each
//!   point's label, a `description` or `desc` column its description; other columns are ignored,
//!   but for a `frame` column naming several frames (a tracks file), refused.
//!   Fields may be quoted (RFC 4180). Comment lines starting with `#` may come before the header,
//!   `# CoordinateSystem = LPS` (or `RAS`) among them.
//! - **`.fcsv`**: 3D Slicer's markups fiducial CSV (4.x and 5.x): `# CoordinateSystem = LPS`,
//!   `RAS`, or the older numeric codes `0` (RAS) and `1` (LPS) (no such line: RAS, as Slicer wrote
//!   before it had one); `# columns = id,x,y,z,ow,ox,oy,oz,vis,sel,lock,label,desc,associatedNodeID`
//!   names the columns; always millimetres. Slicer 5 writes two more fields per row that the
//!   header does not name, each point's position status and whether it was made automatically:
//!   points of status 0 (undefined), 1 (preview) or 3 (missing, skipped when placing) are left
//!   out and named in [`LabelledPoints::unplaced`].
//! - **`.mrk.json`**: 3D Slicer's markups JSON: each markup's `coordinateSystem` (`LPS` when
//!   absent, as Slicer reads it), `coordinateUnits` (`mm` when absent, `um` as Slicer's schema allows, or `m`, `cm`; also
//!   coded, `["mm", "UCUM", "millimeter"]`) and `controlPoints` with
//!   their `position`, `label` and `description`; points whose `positionStatus` is `undefined`
//!   (placeholders not yet placed), `preview` or `missing` (skipped when placing: Slicer writes
//!   no position) are left out and named in [`LabelledPoints::unplaced`].
//!   Several markups are read as one list, in file order ([`LabelledPoints::lists`] says so),
//!   those of other frames or units brought to the first's.
//!
//! Every error names the file and the line (CSV) or the control point (JSON).

use std::io::Write as _;
use std::path::Path;

use serde_json::Value;

use super::csv::{csv_field, write_csv, CsvError, Dialect, Header, Table};
use super::frame::Frame;
use super::{extension, write_atomic, Num, WriteError};
use crate::length::LengthUnit;
use crate::{MeshError, Point};

/// Points with a label and a description each (empty when the file gives none), and the frame and
/// unit their file names (`None` when it names none).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct LabelledPoints {
    /// The positions.
    pub points: Vec<Point>,
    /// One label per point ("" for none).
    pub labels: Vec<String>,
    /// One description per point ("" for none).
    pub descriptions: Vec<String>,
    /// The frame the file names.
    pub frame: Option<Frame>,
    /// The unit the file names.
    pub unit: Option<LengthUnit>,
    /// The control points left out because 3D Slicer has not placed them (their position status
    /// undefined, preview or missing), by label (or place in the file when unlabelled).
    pub unplaced: Vec<String>,
    /// The number of points read from each point list, in file order, when the file holds several
    /// (a `.mrk.json` of several markups, read as one list); empty otherwise.
    pub lists: Vec<usize>,
}

impl LabelledPoints {
    /// Points without labels, frame or unit.
    pub fn new(points: Vec<Point>) -> LabelledPoints {
        let n = points.len();
        LabelledPoints {
            points,
            labels: vec![String::new(); n],
            descriptions: vec![String::new(); n],
            ..Default::default()
        }
    }

    /// The label of point `i`, `None` when it has none (or there is no point `i`).
    pub fn label(&self, i: usize) -> Option<&str> {
        self.labels.get(i).map(String::as_str).filter(|l| !l.is_empty())
    }

    /// A warning naming the control points left out as not placed, `None` when there are none.
    pub fn unplaced_warning(&self) -> Option<String> {
        let n = self.unplaced.len();
        (n > 0).then(|| {
            let (count, verb) =
                if n == 1 { ("1 control point".to_string(), "is") } else { (format!("{n} control points"), "are") };
            format!(
                "{count} not placed in 3D Slicer (positionStatus undefined, preview or missing) {verb} left out: {}",
                self.unplaced.join(", ")
            )
        })
    }

    /// A warning that the file's several point lists were read as one, `None` when it held one.
    pub fn merged_lists_warning(&self) -> Option<String> {
        (self.lists.len() > 1).then(|| {
            let counts: Vec<String> = self.lists.iter().map(usize::to_string).collect();
            format!(
                "its {} point lists ({} points) are read as one list of {}, in that order: save the one meant \
                 alone if the others are not part of it",
                self.lists.len(),
                counts.join(", "),
                self.points.len()
            )
        })
    }

    /// What a user should know of the points as read, a line each: control points left out as not
    /// placed, several point lists read as one.
    pub fn warnings(&self) -> Vec<String> {
        self.unplaced_warning().into_iter().chain(self.merged_lists_warning()).collect()
    }

    /// Brings the points into `frame` (x and y negated when their own frame is the other one;
    /// points of no named frame are taken as being in `frame` already; `None` leaves them as they
    /// are) and into `unit`, from their own unit or, when the file named none, from `assumed`.
    pub fn convert(&mut self, frame: Option<Frame>, unit: LengthUnit, assumed: LengthUnit) {
        if let Some(to) = frame {
            if let Some(from) = self.frame {
                from.convert_all(to, &mut self.points);
            }
            self.frame = Some(to);
        }
        let scale = self.unit.unwrap_or(assumed).metres() / unit.metres();
        if scale != 1.0 {
            self.points.iter_mut().for_each(|p| *p = p.map(|x| x * scale));
        }
        self.unit = Some(unit);
    }
}

/// Reads points, choosing the format by extension: `.fcsv`, `.mrk.json` (or any `.json`), and CSV
/// for any other (see the [module](self) documentation). A point beyond
/// [`MAX_MEASURED_COORDINATE`](crate::MAX_MEASURED_COORDINATE) is an error (a damaged file), and
/// so is a file whose every point 3D Slicer has not placed (nothing would be left of it).
pub fn read_points(path: impl AsRef<Path>) -> Result<LabelledPoints, MeshError> {
    let path = path.as_ref();
    let text = std::fs::read_to_string(path).map_err(|error| match error.kind() {
        std::io::ErrorKind::InvalidData => {
            MeshError::parse(path, "not text: points come as CSV (x, y, z), Slicer's .fcsv or .mrk.json")
        }
        _ => MeshError::Io { path: path.display().to_string(), error },
    })?;
    if text.as_bytes().starts_with(super::LFS_POINTER) {
        return Err(super::lfs_error(path));
    }
    let text = text.strip_prefix('\u{feff}').unwrap_or(&text);
    let points = match extension(path).as_str() {
        "fcsv" => read_table(path, text, true),
        "json" => read_markups_json(path, text),
        _ => read_table(path, text, false),
    }?;
    if points.points.is_empty() && !points.unplaced.is_empty() {
        let warning = points.unplaced_warning().unwrap_or_default();
        return Err(MeshError::parse(path, format!("none of its points is placed: {warning}")));
    }
    match crate::measured_fault(&points.points) {
        Some((i, fault)) => Err(MeshError::parse(path, format!("point {i} {fault}"))),
        None => Ok(points),
    }
}

/// Reads the points of a points file ([`read_points`]; CSV for any extension but `.fcsv` and
/// `.json`): in metres when the file names their unit (`.fcsv`, `.mrk.json`, a CSV header
/// `x_mm`), as written otherwise; labels, descriptions and frame are dropped. Every error names
/// the file and, for its content, the line: no header, a header without `x`, `y` or `z`, a line
/// with another number of fields, a value that is not a finite number.
pub fn read_points_csv(path: &Path) -> Result<Vec<Point>, MeshError> {
    let mut points = read_points(path)?;
    points.convert(None, LengthUnit::Metre, LengthUnit::Metre);
    Ok(points.points)
}

/// The unit that the coordinate columns of a header name (`x_mm, y_mm, z_mm` or `x_m, …`), `None`
/// for plain `x, y, z`; an error for a header without them or naming different units.
pub fn coordinate_unit(names: &[String]) -> Result<Option<LengthUnit>, String> {
    Columns::find(names).map(|c| c.unit)
}

/// The unit a column's name ends with: `_mm` (e.g. `x_mm`) or `_m`; `None` for none.
pub fn column_unit(name: &str) -> Option<LengthUnit> {
    let (_, suffix) = name.rsplit_once('_')?;
    suffix.parse().ok()
}

/// The columns of a table: where x, y, z, the label and the description are, and the unit.
struct Columns {
    xyz: [usize; 3],
    label: Option<usize>,
    description: Option<usize>,
    unit: Option<LengthUnit>,
}

impl Columns {
    /// Finds the columns in the (lower-case) header names.
    fn find(names: &[String]) -> Result<Columns, String> {
        let mut xyz = [0usize; 3];
        let mut unit = None;
        for (axis, name) in ["x", "y", "z"].into_iter().enumerate() {
            let mut found = names.iter().enumerate().filter_map(|(i, n)| {
                let u = match n.strip_prefix(name)? {
                    "" => None,
                    suffix => Some(column_unit(suffix).filter(|_| suffix.starts_with('_'))?),
                };
                Some((i, u))
            });
            let (column, u) = found.next().ok_or_else(|| {
                // A spreadsheet saved with semicolons (a locale whose decimal mark is a comma), or
                // tabs.
                let semicolons = match (names.iter().any(|n| n.contains(';')), names.iter().any(|n| n.contains('\t'))) {
                    (true, _) => "; its fields are separated by semicolons: save it with commas (and decimal points)",
                    (_, true) => "; its fields are separated by tabs: save it with commas",
                    _ => "",
                };
                format!(
                    "the header has no '{name}' column (expected the columns x, y, z, or x_mm, y_mm, z_mm){semicolons}"
                )
            })?;
            if found.next().is_some() {
                return Err(format!("the header has more than one '{name}' column"));
            }
            if axis > 0 && u != unit {
                return Err("the x, y and z columns name different units".into());
            }
            (xyz[axis], unit) = (column, u);
        }
        let position = |candidates: &[&str]| candidates.iter().find_map(|c| names.iter().position(|n| n == c));
        Ok(Columns {
            xyz,
            label: position(&["label", "name", "id"]),
            description: position(&["description", "desc"]),
            unit,
        })
    }
}

/// Reads CSV text, or Slicer's `.fcsv` when `fcsv` (columns named by the `# columns =` comment,
/// RAS when no `# CoordinateSystem` line, millimetres); a CSV file with a `# columns =` comment
/// is read as `.fcsv` names its columns.
fn read_table(path: &Path, text: &str, fcsv: bool) -> Result<LabelledPoints, MeshError> {
    let table_error = |e: CsvError| MeshError::parse(path, e.to_string());
    let by_comment = Dialect { header: Header::Comment("columns"), ..Dialect::CSV };
    let mut table = Table::parse(text, if fcsv { &by_comment } else { &Dialect::CSV }).map_err(table_error)?;
    if !fcsv && table.settings.iter().any(|s| s.key == "columns") {
        table = Table::parse(text, &by_comment).map_err(table_error)?;
    }
    let mut frame = None;
    for setting in table.settings.iter().filter(|s| s.key == "coordinatesystem") {
        frame = Some(coordinate_system(&setting.value).map_err(|m| table_error(CsvError::at(setting.line, m)))?);
    }
    let header_line = table
        .header_line
        .ok_or_else(|| MeshError::parse(path, "no points (empty file, expected a header naming x, y, z)"))?;
    let header = table.names.join(",");
    let columns = Columns::find(&table.names)
        .map_err(|m| table_error(CsvError::at(header_line, format!("{m} in {header:?}"))))?;
    // Slicer 5's two unnamed fields: the position status and whether the point was made
    // automatically.
    let unnamed = fcsv && table.column(FCSV_STATUS).is_none();
    if unnamed && table.rows.iter().any(|r| r.fields.len() == table.names.len() + 2) {
        table.names.extend([FCSV_STATUS.to_string(), "autocreated".to_string()]);
    }
    table.check_widths().map_err(table_error)?;
    // A tracks file (frame, id, x, y, z) holds several frames' points: read as one set, they would mix.
    if let Some(c) = table.column("frame").filter(|_| !fcsv) {
        let mut frames: Vec<&str> = table.rows.iter().map(|r| r.fields[c].as_str()).collect();
        // Numbers in their order (0, 2, 10), other names in the text's.
        frames.sort_by(|a, b| match (a.parse::<f64>(), b.parse::<f64>()) {
            (Ok(x), Ok(y)) => x.total_cmp(&y),
            _ => a.cmp(b),
        });
        frames.dedup();
        if frames.len() > 1 {
            return Err(MeshError::parse(
                path,
                format!(
                    "its `frame` column names {} frames ({} to {}): points of one frame are expected (a tracks file \
                     is read by `augsim assimilate --observations`; a sequence of clouds is a folder of files)",
                    frames.len(),
                    frames[0],
                    frames[frames.len() - 1]
                ),
            ));
        }
    }
    let status = table.column(FCSV_STATUS).filter(|_| fcsv);
    let mut out = LabelledPoints {
        frame: if fcsv { frame.or(Some(Frame::Ras)) } else { frame },
        unit: if fcsv { Some(LengthUnit::Millimetre) } else { columns.unit },
        ..Default::default()
    };
    for row in &table.rows {
        let field = |c: Option<usize>| c.map_or_else(String::new, |c| row.fields[c].clone());
        if let Some(code) = status.map(|c| row.fields[c].as_str()).filter(|&c| c != "2" && !c.is_empty()) {
            let label = field(columns.label);
            match code {
                "0" | "1" | "3" => {
                    out.unplaced.push(if label.is_empty() { format!("line {}", row.line) } else { label });
                    continue;
                }
                other => {
                    let message = format!(
                        "position status {other:?}: Slicer's .fcsv rows end with two fields its columns comment does \
                         not name, the position status (0 to 3) and whether the point was made automatically; a row \
                         two fields longer than its columns reads them there"
                    );
                    return Err(table_error(CsvError::at(row.line, message)));
                }
            }
        }
        out.points.push(row.point(columns.xyz).map_err(table_error)?);
        out.labels.push(field(columns.label));
        out.descriptions.push(field(columns.description));
    }
    Ok(out)
}

/// The name given to Slicer 5's unnamed position status field of `.fcsv` rows.
const FCSV_STATUS: &str = "positionstatus";

/// The frame of an `.fcsv` `CoordinateSystem` value: `LPS`, `RAS`, or Slicer's older codes
/// `0` (RAS) and `1` (LPS).
fn coordinate_system(value: &str) -> Result<Frame, String> {
    match value.trim() {
        "0" => Ok(Frame::Ras),
        "1" => Ok(Frame::Lps),
        "2" => Err("CoordinateSystem = 2 (IJK, voxel indices) is not supported: save the points in LPS or RAS".into()),
        other => other.parse(),
    }
}

/// Reads the control points of Slicer's markups JSON.
fn read_markups_json(path: &Path, text: &str) -> Result<LabelledPoints, MeshError> {
    let root: Value = serde_json::from_str(text).map_err(|e| MeshError::parse(path, format!("not valid JSON: {e}")))?;
    let markups = root
        .get("markups")
        .and_then(Value::as_array)
        .ok_or_else(|| MeshError::parse(path, "no \"markups\" list: not a Slicer markups (.mrk.json) file"))?;
    let mut out: Option<LabelledPoints> = None;
    let mut lists = Vec::with_capacity(markups.len());
    for (m, markup) in markups.iter().enumerate() {
        let mut points = read_markup(markup, m).map_err(|message| MeshError::parse(path, message))?;
        lists.push(points.points.len());
        match &mut out {
            None => out = Some(points),
            Some(all) => {
                points.convert(all.frame, all.unit.unwrap_or(LengthUnit::Millimetre), LengthUnit::Millimetre);
                all.points.append(&mut points.points);
                all.labels.append(&mut points.labels);
                all.descriptions.append(&mut points.descriptions);
                all.unplaced.append(&mut points.unplaced);
            }
        }
    }
    let mut out = out.ok_or_else(|| MeshError::parse(path, "the \"markups\" list is empty"))?;
    if lists.len() > 1 {
        out.lists = lists;
    }
    Ok(out)
}

/// The points of markup `m` of a markups JSON file, or what is wrong (naming the point).
fn read_markup(markup: &Value, m: usize) -> Result<LabelledPoints, String> {
    let at = format!("markups[{m}]");
    let text_of = |key: &str| -> Result<Option<&str>, String> {
        match markup.get(key) {
            None | Some(Value::Null) => Ok(None),
            Some(Value::String(s)) => Ok(Some(s.as_str())),
            Some(other) => Err(format!("{at}.{key} is {other}, not a string")),
        }
    };
    // Slicer's point list; its other markups (a curve, a plane, a line, an angle, a box) are shapes.
    if let Some(kind) = text_of("type")?.filter(|&kind| kind != "Fiducial") {
        return Err(format!(
            "{at} is a {kind}, not a point list: save the points as a point list (type Fiducial in the file)"
        ));
    }
    let frame = text_of("coordinateSystem")?.map_or(Ok(Frame::Lps), str::parse).map_err(|e| format!("{at}: {e}"))?;
    // A unit code alone ("mm"), or coded as the schema also allows: [code, scheme, meaning].
    let unit = match markup.get("coordinateUnits") {
        Some(Value::Array(coded)) => coded.first().and_then(Value::as_str).map(Some).ok_or_else(|| {
            format!("{at}.coordinateUnits is {}, not [code, scheme, meaning]", Value::Array(coded.clone()))
        })?,
        _ => text_of("coordinateUnits")?,
    };
    let unit = unit.map_or(Ok(LengthUnit::Millimetre), str::parse).map_err(|e| format!("{at}: coordinateUnits {e}"))?;
    let mut out = LabelledPoints { frame: Some(frame), unit: Some(unit), ..Default::default() };
    let points = match markup.get("controlPoints") {
        None | Some(Value::Null) => return Ok(out),
        Some(Value::Array(points)) => points,
        Some(_) => return Err(format!("{at}.controlPoints is not a list")),
    };
    for (i, point) in points.iter().enumerate() {
        let text = |key: &str| point.get(key).and_then(Value::as_str).unwrap_or_default().to_string();
        let label = text("label");
        let name = if label.is_empty() {
            format!("{at}.controlPoints[{i}]")
        } else {
            format!("{at}.controlPoints[{i}] ({label})")
        };
        match text("positionStatus").as_str() {
            "" | "defined" => {}
            "undefined" | "preview" | "missing" => {
                out.unplaced.push(if label.is_empty() { name } else { label });
                continue;
            }
            other => {
                return Err(format!(
                    "{name}: positionStatus \"{other}\" is none of 3D Slicer's (defined, undefined, preview, missing)"
                ))
            }
        }
        let position = point.get("position").ok_or_else(|| format!("{name}: no position"))?;
        let values: Vec<f64> = position
            .as_array()
            .map(|a| a.iter().filter_map(Value::as_f64).collect())
            .filter(|v: &Vec<f64>| v.len() == 3 && position.as_array().is_some_and(|a| a.len() == 3))
            .ok_or_else(|| format!("{name}: position {position} is not 3 numbers"))?;
        if values.iter().any(|v| !v.is_finite()) {
            return Err(format!("{name}: position {position} is not finite"));
        }
        out.points.push([values[0], values[1], values[2]]);
        out.labels.push(label);
        out.descriptions.push(text("description"));
    }
    Ok(out)
}

/// Writes points with their labels, choosing the format by extension: `.fcsv`
/// ([`write_fcsv`]), `.mrk.json` ([`write_markups_json`]), else CSV: a `label` column when a
/// point has a label, `x`, `y`, `z` with the unit's suffix when the unit is known (`x_mm`), a
/// `description` column when a point has one, and a first line `# CoordinateSystem = …` when the
/// frame is known. Reading the file back with [`read_points`] gives the same points (Slicer's
/// files in millimetres), but for line breaks in labels and descriptions, which CSV and `.fcsv`
/// (a line per point) hold as spaces.
pub fn write_points(path: impl AsRef<Path>, points: &LabelledPoints) -> Result<(), MeshError> {
    let path = path.as_ref();
    let name = path.file_name().map(|n| n.to_string_lossy().to_ascii_lowercase()).unwrap_or_default();
    if name.ends_with(".fcsv") {
        write_fcsv(path, points)
    } else if name.ends_with(".json") {
        write_markups_json(path, points)
    } else {
        write_labelled_csv(path, points)
    }
}

/// Checks that a point list can be written: labels and descriptions per point, finite positions.
fn check_points(points: &LabelledPoints) -> Result<(), MeshError> {
    let n = points.points.len();
    let describe = |k: usize| if k == n || k == 0 { String::new() } else { format!(" ({k} for {n} points)") };
    if points.labels.len() != n && !points.labels.is_empty() {
        return Err(MeshError::Invalid(format!("one label per point, or none{}", describe(points.labels.len()))));
    }
    if points.descriptions.len() != n && !points.descriptions.is_empty() {
        let k = points.descriptions.len();
        return Err(MeshError::Invalid(format!("one description per point, or none{}", describe(k))));
    }
    if let Some(i) = points.points.iter().position(|p| p.iter().any(|v| !v.is_finite())) {
        return Err(MeshError::Invalid(format!("point {i} is not finite: {:?}", points.points[i])));
    }
    Ok(())
}

/// The label and the description of point `i` ("" when there are none).
fn texts(points: &LabelledPoints, i: usize) -> (&str, &str) {
    let label = points.labels.get(i).map_or("", String::as_str);
    (label, points.descriptions.get(i).map_or("", String::as_str))
}

/// [`texts`] on one line each, their line breaks as spaces, for a CSV row of the point.
fn one_line_texts(points: &LabelledPoints, i: usize) -> (String, String) {
    let one_line = |text: &str| text.replace("\r\n", " ").replace(['\r', '\n'], " ");
    let (label, description) = texts(points, i);
    (one_line(label), one_line(description))
}

fn write_labelled_csv(path: &Path, points: &LabelledPoints) -> Result<(), MeshError> {
    check_points(points)?;
    let labelled = points.labels.iter().any(|l| !l.is_empty());
    let described = points.descriptions.iter().any(|d| !d.is_empty());
    let suffix = points.unit.map_or(String::new(), |u| format!("_{}", u.symbol()));
    let comments: Vec<String> = points.frame.iter().map(|frame| format!("CoordinateSystem = {frame}")).collect();
    let xyz: Vec<String> = ["x", "y", "z"].iter().map(|a| format!("{a}{suffix}")).collect();
    let mut header: Vec<&str> = xyz.iter().map(String::as_str).collect();
    if labelled {
        header.insert(0, "label");
    }
    if described {
        header.push("description");
    }
    let rows = points.points.iter().enumerate().map(|(i, p)| {
        let (label, description) = one_line_texts(points, i);
        let mut row: Vec<String> = p.iter().map(|&v| Num(v).to_string()).collect();
        if labelled {
            row.insert(0, label);
        }
        if described {
            row.push(description);
        }
        row
    });
    write_csv(path, &comments, &header, rows)?;
    Ok(())
}

/// Writes points as Slicer's markups fiducial CSV (`.fcsv`, version 4.11, which Slicer 4.11 and
/// later read), atomically: in millimetres (converted from the points' unit; none named:
/// millimetres), in the points' frame, which must be named; line breaks in labels and
/// descriptions are written as spaces.
pub fn write_fcsv(path: impl AsRef<Path>, points: &LabelledPoints) -> Result<(), MeshError> {
    let path = path.as_ref();
    check_points(points)?;
    let frame = points.frame.ok_or_else(|| {
        MeshError::Invalid(format!(
            "{}: an .fcsv file names its frame: give the points one (LPS or RAS)",
            path.display()
        ))
    })?;
    let scale = millimetres_per_unit(points);
    write_atomic(path, |w| {
        writeln!(w, "# Markups fiducial file version = 4.11")?;
        writeln!(w, "# CoordinateSystem = {frame}")?;
        writeln!(w, "# columns = id,x,y,z,ow,ox,oy,oz,vis,sel,lock,label,desc,associatedNodeID")?;
        for (i, p) in points.points.iter().enumerate() {
            let [x, y, z] = p.map(|v| Num(v * scale));
            let (label, description) = one_line_texts(points, i);
            writeln!(w, "{},{x},{y},{z},0,0,0,1,1,1,0,{},{},", i + 1, csv_field(&label), csv_field(&description))?;
        }
        Ok(())
    })?;
    Ok(())
}

/// Writes points as Slicer's markups JSON (`.mrk.json`, one point list), atomically: each
/// point's label and description; the points' frame as `coordinateSystem` when named (Slicer
/// takes LPS when it is not); in millimetres, the unit Slicer's markups schema knows (converted
/// from the points' unit, then named as `coordinateUnits`; none named: millimetres).
pub fn write_markups_json(path: impl AsRef<Path>, points: &LabelledPoints) -> Result<(), MeshError> {
    let path = path.as_ref();
    check_points(points)?;
    let scale = millimetres_per_unit(points);
    // Slicer's orientation of a point is the identity in RAS, written in the file's frame.
    let orientation = match points.frame {
        Some(Frame::Ras) => [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
        _ => [-1.0, -0.0, -0.0, -0.0, -1.0, -0.0, 0.0, 0.0, 1.0],
    };
    let control: Vec<Value> = points
        .points
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let (label, description) = texts(points, i);
            let p = p.map(|v| v * scale);
            serde_json::json!({
                "id": (i + 1).to_string(),
                "label": label,
                "description": description,
                "associatedNodeID": "",
                "position": p,
                "orientation": orientation,
                "selected": true,
                "locked": false,
                "visibility": true,
                "positionStatus": "defined",
            })
        })
        .collect();
    let mut markup = serde_json::json!({ "type": "Fiducial" });
    if let Some(frame) = points.frame {
        markup["coordinateSystem"] = frame.name().into();
    }
    if points.unit.is_some() {
        markup["coordinateUnits"] = LengthUnit::Millimetre.symbol().into();
    }
    markup["locked"] = false.into();
    markup["labelFormat"] = "%N-%d".into();
    markup["controlPoints"] = control.into();
    markup["measurements"] = Value::Array(Vec::new());
    let root = serde_json::json!({
        "@schema": "https://raw.githubusercontent.com/slicer/slicer/master/Modules/Loadable/Markups/Resources/Schema/markups-schema-v1.0.3.json#",
        "markups": [markup],
    });
    write_atomic(path, |w| {
        serde_json::to_writer_pretty(&mut *w, &root)?;
        writeln!(w)
    })?;
    Ok(())
}

/// The factor that brings `points` to millimetres, the unit 3D Slicer's files hold (1 when they
/// name no unit: taken as millimetres).
fn millimetres_per_unit(points: &LabelledPoints) -> f64 {
    points.unit.map_or(1.0, LengthUnit::millimetres)
}

/// Writes `points` as CSV with the header `x,y,z`, atomically; the values read back exactly.
pub fn write_points_csv(path: &Path, points: &[Point]) -> Result<(), WriteError> {
    write_csv(path, &[], &["x", "y", "z"], points.iter().map(|p| p.map(|v| Num(v).to_string())))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn conversion_takes_the_named_unit_and_frame_or_the_assumed_ones() {
        let mut p = LabelledPoints::new(vec![[1.0, 2.0, 3.0]]);
        p.frame = Some(Frame::Ras);
        p.unit = Some(LengthUnit::Millimetre);
        p.convert(Some(Frame::Lps), LengthUnit::Metre, LengthUnit::Metre);
        assert_eq!(p.points, [[-1e-3, -2e-3, 3e-3]]);
        assert_eq!((p.frame, p.unit), (Some(Frame::Lps), Some(LengthUnit::Metre)));
        let mut q = LabelledPoints::new(vec![[1.0, 2.0, 3.0]]);
        q.convert(Some(Frame::Lps), LengthUnit::Metre, LengthUnit::Millimetre);
        assert_eq!(q.points, [[1e-3, 2e-3, 3e-3]], "no named frame: taken as the target frame");
        q.convert(None, LengthUnit::Metre, LengthUnit::Millimetre);
        assert_eq!(q.points, [[1e-3, 2e-3, 3e-3]], "a named unit wins over the assumed one");
    }

    /// A CSV saved with semicolons and decimal commas (a spreadsheet in such a locale), or with tabs,
    /// is refused, saying so.
    #[test]
    fn semicolons_are_named() {
        let e = read_table(Path::new("p.csv"), "x_mm;y_mm;z_mm\n1,5;2;3\n", false).unwrap_err().to_string();
        assert!(e.contains("no 'y' column") && e.contains("separated by semicolons: save it with commas"), "{e}");
        let e = read_table(Path::new("p.csv"), "x_mm\ty_mm\tz_mm\n1\t2\t3\n", false).unwrap_err().to_string();
        assert!(e.contains("no 'y' column") && e.contains("separated by tabs: save it with commas"), "{e}");
    }

    /// A tracks file's points of several frames are refused as one set; one frame's are read.
    #[test]
    fn points_of_several_frames_are_refused() {
        let tracks = "frame,id,x,y,z\n0,a,1,2,3\n0,b,4,5,6\n10,a,1,2,4\n2,a,1,2,5\n";
        let e = read_table(Path::new("t.csv"), tracks, false).unwrap_err().to_string();
        assert!(e.contains("its `frame` column names 3 frames (0 to 10): points of one frame are expected"), "{e}");
        let one = read_table(Path::new("t.csv"), "frame,id,x,y,z\n3,a,1,2,3\n3,b,4,5,6\n", false).unwrap();
        assert_eq!(one.points.len(), 2);
    }
}
