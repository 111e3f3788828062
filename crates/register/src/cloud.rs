//! Point clouds on disk: CSV with a header naming `x`, `y`, `z` (read with its labels and unit as
//! points, [`mesh::io::points::read_points`]); NumPy `.npy` arrays of shape `[N, 3]`; the points
//! of a PLY, surface or mesh file (`.ply`, `.obj`, `.stl`, `.vtk`, `.vtp`, `.vtu`: a cloud saved
//! as a model, as 3D Slicer saves one), whatever its cells ([`mesh::io::read_vertices`]); a
//! sequence of them in a directory ([`read_frames`]), 3D Slicer's markups among them.
//!
//! Every reader rejects an empty cloud and non-finite coordinates, and every error names the
//! file (and, for text, the line).

use std::fs;
use std::path::{Path, PathBuf};

use mesh::io::extension;
use mesh::Point;

use crate::{RegisterError, Result};

/// The file extensions (lower case) of a point cloud: CSV and those [`read_point_cloud`] reads.
pub const CLOUD_EXTENSIONS: [&str; 8] = ["csv", "npy", "ply", "obj", "stl", "vtk", "vtp", "vtu"];

/// The cloud formats as a user reads them (".csv, .npy, … or .vtu"), CSV among them or not.
fn cloud_formats(csv: bool) -> String {
    let dotted: Vec<String> =
        CLOUD_EXTENSIONS.iter().filter(|&&e| csv || e != "csv").map(|e| format!(".{e}")).collect();
    let (last, first) = dotted.split_last().expect("cloud extensions are given");
    format!("{} or {last}", first.join(", "))
}

/// Whether `path` is a cloud of positions alone, naming no unit: any of the
/// [`CLOUD_EXTENSIONS`] but CSV (whose header may name a unit and carry labels).
pub fn holds_positions_only(path: &Path) -> bool {
    let e = extension(path);
    e != "csv" && CLOUD_EXTENSIONS.contains(&e.as_str())
}

/// Whether `path` is 3D Slicer's markups: `.fcsv` or `.mrk.json` (any case).
fn is_markups_file(path: &Path) -> bool {
    let name = path.file_name().map(|n| n.to_string_lossy().to_ascii_lowercase()).unwrap_or_default();
    name.ends_with(".fcsv") || name.ends_with(".mrk.json")
}

/// Whether `path` is a cloud: one of the [`CLOUD_EXTENSIONS`], or 3D Slicer's markups.
fn is_cloud_file(path: &Path) -> bool {
    CLOUD_EXTENSIONS.contains(&extension(path).as_str()) || is_markups_file(path)
}

/// Whether `path` is a points file: CSV, or 3D Slicer's markups.
fn is_points_file(path: &Path) -> bool {
    extension(path) == "csv" || is_markups_file(path)
}

/// Reads a cloud of positions alone ([`holds_positions_only`]), choosing the format from the
/// extension (any case).
pub fn read_point_cloud(path: &Path) -> Result<Vec<Point>> {
    if !holds_positions_only(path) {
        let expected = format!("unsupported point-cloud format: expected a {} file", cloud_formats(false));
        return Err(RegisterError::format(path, expected));
    }
    let points = if extension(path) == "npy" { read_npy_cloud(path)? } else { mesh::io::read_vertices(path)? };
    check_points(path, points)
}

/// The clouds of a sequence: a file is a single frame; a directory gives its clouds (files of the
/// [`CLOUD_EXTENSIONS`], 3D Slicer's `.fcsv` and `.mrk.json`) sorted by file name (an error if
/// there are none, naming the files it holds).
pub fn read_frames(path: &Path) -> Result<Vec<PathBuf>> {
    let formats = format!("point cloud ({}, .fcsv or .mrk.json file)", cloud_formats(true));
    sequence_files(path, is_cloud_file, &formats)
}

/// The points files of a sequence (one per frame: the truth of each): a file is a single frame;
/// a directory gives its CSV, `.fcsv` and `.mrk.json` files sorted by file name (an error if
/// there are none, naming the files it holds).
pub fn read_points_frames(path: &Path) -> Result<Vec<PathBuf>> {
    sequence_files(path, is_points_file, "points file (.csv, .fcsv or .mrk.json)")
}

/// The files of a sequence in `path` that `keep` accepts, `what` naming them in the error.
fn sequence_files(path: &Path, keep: fn(&Path) -> bool, what: &str) -> Result<Vec<PathBuf>> {
    let meta = fs::metadata(path).map_err(|e| RegisterError::io(path, e))?;
    if !meta.is_dir() {
        return Ok(vec![path.to_path_buf()]);
    }
    let (mut frames, mut others) = (Vec::new(), Vec::new());
    for entry in fs::read_dir(path).map_err(|e| RegisterError::io(path, e))? {
        let entry = entry.map_err(|e| RegisterError::io(path, e))?;
        let file = entry.path();
        match (file.is_file(), keep(&file)) {
            (true, true) => frames.push(file),
            (true, false) => others.push(entry.file_name().to_string_lossy().into_owned()),
            _ => {}
        }
    }
    if frames.is_empty() {
        others.sort();
        let held = match others.len() {
            0 => "it holds no file".to_string(),
            n => format!(
                "its {n} file(s) ({}{}) are none",
                others[..n.min(3)].join(", "),
                if n > 3 { ", …" } else { "" }
            ),
        };
        return Err(RegisterError::format(path, format!("directory holds no {what}: {held}")));
    }
    frames.sort_by(|a, b| a.file_name().cmp(&b.file_name()));
    Ok(frames)
}

/// Rejects an empty cloud and non-finite coordinates ([`crate::check_cloud`]), naming the file.
pub fn check_points(path: &Path, points: Vec<Point>) -> Result<Vec<Point>> {
    crate::checks::check_cloud(&points).map_err(|e| RegisterError::format(path, e.to_string()))?;
    Ok(points)
}

/// Reads an `.npy` array of shape `[N, 3]` (float32 or float64) as points.
fn read_npy_cloud(path: &Path) -> Result<Vec<Point>> {
    Ok(mesh::io::npy::read_npy(path)?.into_rows(path, "x, y, z")?)
}
