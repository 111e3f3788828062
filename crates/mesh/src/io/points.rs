//! Points as CSV: a header naming the columns `x`, `y` and `z` (any order, any case, other
//! columns ignored), one point per line; what clouds, targets and landmarks are written in.

use std::io::Write as _;
use std::path::Path;

use super::{write_atomic, WriteError};
use crate::{MeshError, Point};

/// Reads the points of a CSV file. Every error names the file and, for its content, the line:
/// no header, a header without `x`, `y` or `z`, a line with another number of fields, a value
/// that is not a finite number.
pub fn read_points_csv(path: &Path) -> Result<Vec<Point>, MeshError> {
    let text =
        std::fs::read_to_string(path).map_err(|error| MeshError::Io { path: path.display().to_string(), error })?;
    let text = text.strip_prefix('\u{feff}').unwrap_or(&text);
    let err = |line: usize, message: String| MeshError::Parse {
        path: path.display().to_string(),
        message: format!("line {line}: {message}"),
    };
    let mut lines = text.lines().enumerate().map(|(i, l)| (i + 1, l.trim()));
    let (header_no, header) = lines.by_ref().find(|(_, l)| !l.is_empty()).ok_or_else(|| MeshError::Parse {
        path: path.display().to_string(),
        message: "no points (empty file, expected a header naming x, y, z)".into(),
    })?;
    let names: Vec<String> = header.split(',').map(|s| s.trim().to_ascii_lowercase()).collect();
    let mut columns = [0usize; 3];
    for (axis, name) in ["x", "y", "z"].iter().enumerate() {
        let mut found = names.iter().enumerate().filter(|(_, n)| n == name).map(|(i, _)| i);
        columns[axis] = found.next().ok_or_else(|| {
            err(header_no, format!("header {header:?} has no '{name}' column (expected the columns x, y, z)"))
        })?;
        if found.next().is_some() {
            return Err(err(header_no, format!("header {header:?} has more than one '{name}' column")));
        }
    }
    let mut points = Vec::new();
    for (line, text) in lines.filter(|(_, l)| !l.is_empty()) {
        let fields: Vec<&str> = text.split(',').map(str::trim).collect();
        if fields.len() != names.len() {
            return Err(err(line, format!("{} fields, the header has {} columns", fields.len(), names.len())));
        }
        let mut p = [0.0; 3];
        for (axis, &column) in columns.iter().enumerate() {
            let name = ["x", "y", "z"][axis];
            let field = fields[column];
            let v: f64 = field.parse().map_err(|_| err(line, format!("{name} = {field:?} is not a number")))?;
            if !v.is_finite() {
                return Err(err(line, format!("{name} = {field:?} is not finite")));
            }
            p[axis] = v;
        }
        points.push(p);
    }
    Ok(points)
}

/// Writes `points` as CSV with the header `x,y,z`, atomically; the values read back exactly.
pub fn write_points_csv(path: &Path, points: &[Point]) -> Result<(), WriteError> {
    write_atomic(path, |w| {
        writeln!(w, "x,y,z")?;
        for p in points {
            writeln!(w, "{},{},{}", Num(p[0]), Num(p[1]), Num(p[2]))?;
        }
        Ok(())
    })
}

/// Shortest round-tripping text of a value: plain notation for ordinary magnitudes, scientific
/// otherwise (both forms of Rust's formatting round-trip exactly).
struct Num(f64);

impl std::fmt::Display for Num {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let a = self.0.abs();
        if a == 0.0 || (1e-4..1e15).contains(&a) {
            write!(f, "{}", self.0)
        } else {
            write!(f, "{:e}", self.0)
        }
    }
}
