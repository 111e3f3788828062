//! Point clouds on disk: CSV with a header naming `x`, `y`, `z` (read with its labels and unit as
//! points, [`mesh::io::points::read_points`]); NumPy `.npy` arrays of shape `[N, 3]`; the points
//! of a PLY, surface or mesh file (`.ply`, `.obj`, `.stl`, `.vtk`, `.vtp`, `.vtu`: a cloud saved
//! as a model, as 3D Slicer saves one), whatever its cells ([`mesh::io::read_vertices`]).
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

fn is_cloud_file(path: &Path) -> bool {
    CLOUD_EXTENSIONS.contains(&extension(path).as_str())
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

/// The clouds of a sequence: a file is a single frame; a directory gives its files of the
/// [`CLOUD_EXTENSIONS`] sorted by file name (an error if there are none).
pub fn read_frames(path: &Path) -> Result<Vec<PathBuf>> {
    let meta = fs::metadata(path).map_err(|e| RegisterError::io(path, e))?;
    if !meta.is_dir() {
        return Ok(vec![path.to_path_buf()]);
    }
    let mut frames = Vec::new();
    for entry in fs::read_dir(path).map_err(|e| RegisterError::io(path, e))? {
        let entry = entry.map_err(|e| RegisterError::io(path, e))?;
        let file = entry.path();
        if file.is_file() && is_cloud_file(&file) {
            frames.push(file);
        }
    }
    if frames.is_empty() {
        return Err(RegisterError::format(
            path,
            format!("directory holds no point cloud ({} file)", cloud_formats(true)),
        ));
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
