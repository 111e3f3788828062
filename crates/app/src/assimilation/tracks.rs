//! Tracked features in CSV files (one header line, comma-separated, blank lines ignored), in the unit that
//! the header names (`x_mm,y_mm,z_mm` or `x_m,y_m,z_m`), else in the unit given (`--units`, metres by default):
//!
//! * tracks (observations, controls, assessment points): header `frame,id,x,y,z`, one row per feature and frame.
//!   Frame 0 is the rest configuration; frames 1, 2, … are the filter's time steps. A feature without a row in a
//!   frame is occluded there.
//! * rest positions (features): header `id,x,y,z`, one row per feature; when given, they replace the frame-0 rows.
//!
//! Every error names the file and, where there is one, the line.

use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};

use mesh::io::csv::{CsvError, Dialect, Row, Table};
use mesh::length::LengthUnit;
use mesh::Point;
use nalgebra::DVector;

use super::AssimilationError;

/// Header of a track file.
pub const TRACK_HEADER: &str = "frame,id,x,y,z";
/// Header of a rest-position file.
pub const REST_HEADER: &str = "id,x,y,z";

/// The rows of a track file, grouped by feature.
#[derive(Debug, Clone, PartialEq)]
pub struct Tracks {
    /// The file read.
    pub path: PathBuf,
    /// Feature ids in order of first appearance.
    pub ids: Vec<String>,
    /// Line of each feature's first row.
    lines: Vec<usize>,
    /// Position of each feature per frame.
    positions: Vec<BTreeMap<usize, Point>>,
}

/// Three or more tracked features spanning less than this share of the organ's size at rest are
/// refused ([`Tracks::check_motion`]): 0.25 mm on a 25 cm liver, closer than any camera tracks.
pub const TINY_SPREAD: f64 = 1e-3;

/// How many times more or less than at rest the tracked features of a frame may span
/// ([`Tracks::check_motion`]).
pub const UNIT_SPREAD: f64 = 10.0;

/// What `now` and `rest` span (their boxes' diagonals), for three points or more, when `now` spans
/// [`UNIT_SPREAD`] times more or less than `rest`, else `None`: tissue stretches, but not tenfold; points in
/// another unit than their rest positions do (metres read as millimetres shrink them a thousand times, and
/// leave each within the organ's size of its rest position near an origin the organ holds).
pub(crate) fn spread_in_another_unit(rest: &[Point], now: &[Point]) -> Option<(f64, f64)> {
    if rest.len() < 3 {
        return None;
    }
    let diagonal = |points: &[Point]| mesh::box_diagonal(mesh::bounds(points));
    let (now, at_rest) = (diagonal(now), diagonal(rest));
    (at_rest > 0.0 && !(1.0 / UNIT_SPREAD..=UNIT_SPREAD).contains(&(now / at_rest))).then_some((now, at_rest))
}

impl Tracks {
    /// Reads a track file (header `frame,id,x,y,z`) into metres, from the unit its header names or else from
    /// `unit`.
    pub fn read(path: &Path, unit: LengthUnit) -> Result<Self, AssimilationError> {
        let mut tracks = Tracks { path: path.to_path_buf(), ids: Vec::new(), lines: Vec::new(), positions: Vec::new() };
        let mut index: HashMap<String, usize> = HashMap::new();
        let mut first_line: HashMap<(usize, usize), usize> = HashMap::new();
        let (rows, unit) = rows(path, TRACK_HEADER, unit)?;
        for row in rows {
            let (line, fields) = (row.line, &row.fields);
            let bad = |message: String| AssimilationError::file(path, Some(line), message);
            let frame: usize =
                fields[0].parse().map_err(|_| bad(format!("frame `{}` is not a whole number ≥ 0", fields[0])))?;
            let id = fields[1].as_str();
            let point = unit.point_to_metres(coordinates(&row, path)?);
            let j = *index.entry(id.to_string()).or_insert_with(|| {
                tracks.ids.push(id.to_string());
                tracks.lines.push(line);
                tracks.positions.push(BTreeMap::new());
                tracks.ids.len() - 1
            });
            if let Some(earlier) = first_line.insert((j, frame), line) {
                return Err(bad(format!("feature `{id}` at frame {frame} is already given on line {earlier}")));
            }
            tracks.positions[j].insert(frame, point);
        }
        Ok(tracks)
    }

    /// Tracks of every feature in frames 0, 1, … (`frames[f]` stacks x, y, z per feature), as [`write_tracks`]
    /// would write them to `path`: messages name that file and the lines the rows would have there.
    pub fn from_frames(path: PathBuf, ids: &[String], frames: &[DVector<f64>]) -> Self {
        let n = ids.len();
        let mut positions = vec![BTreeMap::new(); n];
        // The rows in the order [`write_tracks`] writes them (after the header line), occluded points left out.
        let mut lines = vec![0; n];
        let mut line = 1;
        for (f, z) in frames.iter().enumerate() {
            for (j, track) in positions.iter_mut().enumerate() {
                let p = [z[3 * j], z[3 * j + 1], z[3 * j + 2]];
                if p.iter().all(|v| v.is_finite()) {
                    line += 1;
                    if track.is_empty() {
                        lines[j] = line;
                    }
                    track.insert(f, p);
                }
            }
        }
        Tracks { path, ids: ids.to_vec(), lines, positions }
    }

    /// The largest frame number in the file.
    pub fn last_frame(&self) -> usize {
        self.positions.iter().filter_map(|p| p.keys().next_back()).copied().max().unwrap_or(0)
    }

    /// Line of feature `j`'s first row.
    pub fn line(&self, j: usize) -> usize {
        self.lines[j]
    }

    /// Position of feature `j` in `frame`, or `None` when it is occluded there.
    pub fn position(&self, j: usize, frame: usize) -> Option<Point> {
        self.positions.get(j)?.get(&frame).copied()
    }

    /// Rest position of every feature: from `rest` when given (every id must be there), else its frame-0 row.
    pub fn rest_positions(&self, rest: Option<&RestPositions>) -> Result<Vec<Point>, AssimilationError> {
        self.ids
            .iter()
            .enumerate()
            .map(|(j, id)| {
                let line = Some(self.lines[j]);
                match rest {
                    Some(r) => r.get(id).ok_or_else(|| {
                        AssimilationError::file(
                            &self.path,
                            line,
                            format!("unknown id `{id}`: {} gives no rest position for it", r.path.display()),
                        )
                    }),
                    None => self.position(j, 0).ok_or_else(|| {
                        AssimilationError::file(
                            &self.path,
                            line,
                            format!(
                                "feature `{id}` has no frame-0 row (its rest position) and no features file gives it"
                            ),
                        )
                    }),
                }
            })
            .collect()
    }

    /// Refuses a feature that moves farther from its rest position (`rest[j]`, given by the file `rest_file` when
    /// there is one) than `size` (the organ's) in frames 1..=`frames`: no tissue does, but a file in another unit
    /// than its rest positions does. Refuses as well three or more features whose rest positions span less than
    /// [`TINY_SPREAD`] of the organ's size: a file in metres read as millimetres.
    pub fn check_motion(
        &self,
        rest: &[Point],
        size: f64,
        frames: usize,
        rest_file: Option<&RestPositions>,
    ) -> Result<(), AssimilationError> {
        let spread = mesh::box_diagonal(mesh::bounds(rest));
        if rest.len() >= 3 && spread < TINY_SPREAD * size {
            return Err(AssimilationError::file(
                &self.path,
                None,
                format!(
                    "its {} features span {:.3} mm at rest, {:.2} % of the organ's size ({:.1} mm): no camera \
                     tracks points so close; is the file in metres read as millimetres? A header x_mm, y_mm, z_mm \
                     or x_m, y_m, z_m names the unit (or give --units)",
                    rest.len(),
                    mesh::length::mm(spread),
                    100.0 * spread / size,
                    mesh::length::mm(size)
                ),
            ));
        }
        self.check_spread(rest, frames, rest_file)?;
        for (j, id) in self.ids.iter().enumerate() {
            for (&frame, p) in self.positions[j].range(1..frames + 1) {
                let distance = mesh::norm(mesh::sub(*p, rest[j]));
                if distance > size {
                    let cause = match rest_file {
                        Some(r) => format!(
                            "is this file in another unit than the rest positions in {}? A header x_mm, y_mm, z_mm or \
                             x_m, y_m, z_m names the unit",
                            r.path.display()
                        ),
                        None => "no tissue moves that far: a tracking error, or two features under one id?".into(),
                    };
                    let (distance, size) = (mesh::length::mm(distance), mesh::length::mm(size));
                    return Err(AssimilationError::file(
                        &self.path,
                        Some(self.lines[j]),
                        format!(
                            "feature `{id}` lies {distance:.1} mm from its rest position at frame {frame}, farther \
                             than the organ's size ({size:.1} mm, its mesh's box diagonal): {cause}"
                        ),
                    ));
                }
            }
        }
        Ok(())
    }

    /// Refuses a frame (1..=`frames`) whose features span another unit's ([`spread_in_another_unit`]) than their
    /// rest positions `rest`.
    fn check_spread(
        &self,
        rest: &[Point],
        frames: usize,
        rest_file: Option<&RestPositions>,
    ) -> Result<(), AssimilationError> {
        for frame in 1..frames + 1 {
            let seen: Vec<usize> = (0..self.ids.len()).filter(|&j| self.positions[j].contains_key(&frame)).collect();
            let at_rest: Vec<Point> = seen.iter().map(|&j| rest[j]).collect();
            let now: Vec<Point> = seen.iter().map(|&j| self.positions[j][&frame]).collect();
            if let Some((now, at_rest)) = spread_in_another_unit(&at_rest, &now) {
                let ratio = now / at_rest;
                let against = match rest_file {
                    Some(r) => format!("the rest positions in {}", r.path.display()),
                    None => "its frame 0".into(),
                };
                return Err(AssimilationError::file(
                    &self.path,
                    None,
                    format!(
                        "its {} features at frame {frame} span {:.3} mm, {ratio:.3e} times what they span at rest \
                         ({:.1} mm): is the file in another unit than {against}? A header x_mm, y_mm, z_mm or x_m, \
                         y_m, z_m names the unit (or give --units)",
                        seen.len(),
                        mesh::length::mm(now),
                        mesh::length::mm(at_rest)
                    ),
                ));
            }
        }
        Ok(())
    }

    /// The stacked positions (x, y, z per feature) in `frame` and, per component, whether it was measured;
    /// occluded components hold NaN.
    pub fn frame(&self, frame: usize) -> (DVector<f64>, Vec<bool>) {
        let mut z = DVector::from_element(3 * self.ids.len(), f64::NAN);
        let mut available = vec![false; z.len()];
        for j in 0..self.ids.len() {
            if let Some(p) = self.position(j, frame) {
                for d in 0..3 {
                    z[3 * j + d] = p[d];
                    available[3 * j + d] = true;
                }
            }
        }
        (z, available)
    }
}

/// Rest positions of features, read from a file with header `id,x,y,z`.
#[derive(Debug, Clone, PartialEq)]
pub struct RestPositions {
    /// The file read.
    pub path: PathBuf,
    positions: HashMap<String, Point>,
    lines: HashMap<String, usize>,
}

impl RestPositions {
    /// Reads a rest-position file (header `id,x,y,z`) into metres, from the unit its header names or else from
    /// `unit`; an id given twice is an error.
    pub fn read(path: &Path, unit: LengthUnit) -> Result<Self, AssimilationError> {
        let mut positions = HashMap::new();
        let mut lines: HashMap<String, usize> = HashMap::new();
        let (rows, unit) = rows(path, REST_HEADER, unit)?;
        for row in rows {
            let point = unit.point_to_metres(coordinates(&row, path)?);
            let id = &row.fields[0];
            if let Some(earlier) = lines.insert(id.clone(), row.line) {
                return Err(AssimilationError::file(
                    path,
                    Some(row.line),
                    format!("feature `{id}` is already given on line {earlier}"),
                ));
            }
            positions.insert(id.clone(), point);
        }
        Ok(RestPositions { path: path.to_path_buf(), positions, lines })
    }

    /// The rest position of feature `id`.
    pub fn get(&self, id: &str) -> Option<Point> {
        self.positions.get(id).copied()
    }

    /// The line that gives feature `id`'s rest position.
    pub fn line(&self, id: &str) -> Option<usize> {
        self.lines.get(id).copied()
    }
}

/// Writes a track file atomically: `frames[f]` holds the stacked positions of the features `ids` at frame f
/// (frame 0 = rest); non-finite components mark an occluded feature, whose row is left out. Numbers are written
/// in the shortest form that reads back to the same value.
pub fn write_tracks(path: &Path, ids: &[String], frames: &[DVector<f64>]) -> Result<(), AssimilationError> {
    if let Some((f, z)) = frames.iter().enumerate().find(|(_, z)| z.len() != 3 * ids.len()) {
        return Err(AssimilationError::Setup(format!("frame {f} holds {} values for {} features", z.len(), ids.len())));
    }
    if let Some(id) = ids.iter().find(|id| id.is_empty() || id.contains([',', '\n', '\r']) || id.trim() != *id) {
        return Err(AssimilationError::Setup(format!("feature id `{id}` cannot be written to a CSV field")));
    }
    let rows = frames.iter().enumerate().flat_map(|(f, z)| {
        ids.iter().enumerate().filter_map(move |(j, id)| {
            let p = [z[3 * j], z[3 * j + 1], z[3 * j + 2]];
            p.iter()
                .all(|v| v.is_finite())
                .then(|| vec![f.to_string(), id.clone(), p[0].to_string(), p[1].to_string(), p[2].to_string()])
        })
    });
    let header: Vec<&str> = TRACK_HEADER.split(',').collect();
    mesh::io::csv::write_csv(path, &[], &header, rows)?;
    Ok(())
}

/// The data rows of a file with the columns of `header` (its coordinates may name their unit) and the
/// unit of its coordinates: the one the header names, else `given`.
fn rows(path: &Path, header: &str, given: LengthUnit) -> Result<(Vec<Row>, LengthUnit), AssimilationError> {
    let text =
        std::fs::read_to_string(path).map_err(|e| AssimilationError::file(path, None, format!("cannot read: {e}")))?;
    let table_error = |e: CsvError| AssimilationError::file(path, e.line, e.message);
    let table = Table::parse(&text, &Dialect::CSV).map_err(table_error)?;
    let first = table.header_line.ok_or_else(|| {
        AssimilationError::file(path, None, format!("the file is empty: expected the header `{header}`"))
    })?;
    let found = table.names.join(",");
    let n = table.names.len();
    let unit = mesh::io::points::coordinate_unit(&table.names[n.saturating_sub(3)..]).ok().flatten();
    // The header without the unit its coordinates name.
    let suffix = unit.map(|u| format!("_{}", u.symbol()));
    let plain: Vec<&str> = (table.names.iter().enumerate())
        .map(|(i, c)| match &suffix {
            Some(suffix) if i + 3 >= n => c.strip_suffix(suffix.as_str()).unwrap_or(c),
            _ => c,
        })
        .collect();
    if plain.join(",") != header {
        return Err(AssimilationError::file(
            path,
            Some(first),
            format!("the header must be `{header}` (or name the unit: x_mm, y_mm, z_mm), found `{found}`"),
        ));
    }
    table.check_widths().map_err(table_error)?;
    let id = table.column("id");
    if let Some(row) = table.rows.iter().find(|r| id.is_some_and(|i| r.fields[i].is_empty())) {
        return Err(AssimilationError::file(path, Some(row.line), "empty id".into()));
    }
    if table.rows.is_empty() {
        return Err(AssimilationError::file(path, None, format!("no data rows after the header `{header}`")));
    }
    Ok((table.rows, unit.unwrap_or(given)))
}

/// The point in the last three fields `x, y, z` of a row (finite numbers, none beyond
/// [`mesh::MAX_MEASURED_COORDINATE`]).
fn coordinates(row: &Row, path: &Path) -> Result<Point, AssimilationError> {
    let n = row.fields.len();
    let p = row.point([n - 3, n - 2, n - 1]).map_err(|e| AssimilationError::file(path, e.line, e.message))?;
    match mesh::measured_fault(&[p]) {
        Some((_, fault)) => Err(AssimilationError::file(path, Some(row.line), format!("the point {fault}"))),
        None => Ok(p),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Tracks made from frames in memory are those read back from the file the frames are written to,
    /// line numbers included, with a point occluded (not finite) in the first frame.
    #[test]
    fn tracks_from_frames_are_those_of_their_file() {
        let ids = vec!["a".to_string(), "b".to_string()];
        let frames = vec![
            DVector::from_vec(vec![f64::NAN, 0.0, 0.0, 1.0, 2.0, 3.0]),
            DVector::from_vec(vec![0.1, 0.2, 0.3, 1.1, 2.1, 3.1]),
            DVector::from_vec(vec![0.4, 0.5, 0.6, f64::NAN, 2.2, 3.2]),
        ];
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("tracks.csv");
        write_tracks(&path, &ids, &frames).unwrap();
        let read = Tracks::read(&path, LengthUnit::Metre).unwrap();
        let made = Tracks::from_frames(path, &ids, &frames);
        // Ids come in order of first appearance in the file: `b` (frame 0) before `a` (frame 1).
        assert_eq!(read.ids, ["b", "a"]);
        for (j, id) in made.ids.iter().enumerate() {
            let k = read.ids.iter().position(|r| r == id).unwrap();
            assert_eq!(made.line(j), read.line(k), "{id}");
            for f in 0..frames.len() {
                assert_eq!(made.position(j, f), read.position(k, f), "{id} frame {f}");
            }
        }
    }
}
