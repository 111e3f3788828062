//! Point clouds on disk: CSV with a header naming `x`, `y`, `z`; NumPy `.npy` arrays of shape
//! `[N, 3]`; PLY (ASCII or binary, either byte order); the points of a surface or mesh file
//! (`.obj`, `.stl`, `.vtk`, `.vtu`: a cloud saved as a model, as 3D Slicer saves one), whatever its
//! cells. Coordinates are in metres.
//!
//! Every reader rejects an empty cloud and non-finite coordinates, and every error names the
//! file (and, for text, the line).

use std::fs;
use std::io::Write;
use std::path::{Path, PathBuf};

use mesh::io::Scalar;
use mesh::Point;

use crate::{RegisterError, Result};

/// The file extensions (lower case) that [`read_point_cloud`] understands.
pub const CLOUD_EXTENSIONS: [&str; 7] = ["csv", "npy", "ply", "obj", "stl", "vtk", "vtu"];

/// The lower-case extension of `path`, if any.
fn extension(path: &Path) -> Option<String> {
    path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase)
}

/// The cloud formats as a user reads them: ".csv, .npy, … or .vtu".
fn cloud_formats() -> String {
    let [first @ .., last] = CLOUD_EXTENSIONS.map(|e| format!(".{e}"));
    format!("{} or {last}", first.join(", "))
}

/// Whether `path` is a cloud of positions alone, naming no unit: any of the
/// [`CLOUD_EXTENSIONS`] but CSV (whose header may name a unit and carry labels).
pub fn holds_positions_only(path: &Path) -> bool {
    extension(path).is_some_and(|e| e != "csv" && CLOUD_EXTENSIONS.contains(&e.as_str()))
}

fn is_cloud_file(path: &Path) -> bool {
    extension(path).is_some_and(|e| CLOUD_EXTENSIONS.contains(&e.as_str()))
}

/// Reads a point cloud, choosing the format from the extension (any of [`CLOUD_EXTENSIONS`], any
/// case).
pub fn read_point_cloud(path: &Path) -> Result<Vec<Point>> {
    let points = match extension(path).as_deref() {
        Some("csv") => mesh::io::points::read_points_csv(path)?,
        Some("npy") => read_npy_cloud(path)?,
        Some("ply") => read_ply(path)?,
        Some("obj" | "stl" | "vtk" | "vtu") => mesh::io::read_vertices(path)?,
        _ => {
            return Err(RegisterError::format(
                path,
                format!("unsupported point-cloud format: expected a {} file", cloud_formats()),
            ))
        }
    };
    check_points(path, points)
}

/// Reads target (or ground-truth) positions from a CSV file whose header names `x`, `y`, `z`.
pub fn read_targets(path: &Path) -> Result<Vec<Point>> {
    check_points(path, mesh::io::points::read_points_csv(path)?)
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
        return Err(RegisterError::format(path, format!("directory holds no point cloud ({} file)", cloud_formats())));
    }
    frames.sort_by(|a, b| a.file_name().cmp(&b.file_name()));
    Ok(frames)
}

/// Writes `points` as a binary little-endian PLY with float64 `x`, `y`, `z`, atomically.
pub fn write_ply_binary(path: &Path, points: &[Point]) -> Result<()> {
    mesh::io::write_atomic(path, |w| {
        write!(
            w,
            "ply\nformat binary_little_endian 1.0\nelement vertex {}\n\
             property double x\nproperty double y\nproperty double z\nend_header\n",
            points.len()
        )?;
        for p in points {
            for v in p {
                w.write_all(&v.to_le_bytes())?;
            }
        }
        Ok(())
    })?;
    Ok(())
}

/// Writes points as CSV with the header `x,y,z` ([`mesh::io::points::write_points_csv`]).
pub fn write_csv(path: &Path, points: &[Point]) -> Result<()> {
    Ok(mesh::io::points::write_points_csv(path, points)?)
}

/// Rejects an empty cloud and non-finite coordinates ([`crate::checks::check_cloud`]), naming the file.
fn check_points(path: &Path, points: Vec<Point>) -> Result<Vec<Point>> {
    crate::checks::check_cloud(&points).map_err(|e| RegisterError::format(path, e.to_string()))?;
    Ok(points)
}

// ---------------------------------------------------------------------------------------------
// CSV

// ---------------------------------------------------------------------------------------------
// NPY

fn read_npy_cloud(path: &Path) -> Result<Vec<Point>> {
    let array = learn::data::npy::read_npy(path)?;
    if array.shape.len() != 2 || array.shape[1] != 3 {
        return Err(RegisterError::format(path, format!("expected an array of shape [N, 3], found {:?}", array.shape)));
    }
    if matches!(array.data, learn::data::npy::NpyData::U8(_)) {
        return Err(RegisterError::format(path, "expected float32 or float64 values, found uint8"));
    }
    Ok(array.into_f64().chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect())
}

// ---------------------------------------------------------------------------------------------
// PLY

#[derive(Clone, Copy, Debug, PartialEq)]
enum PlyFormat {
    Ascii,
    BinaryLittleEndian,
    BinaryBigEndian,
}

/// The scalar type of a PLY type name.
fn ply_scalar(name: &str) -> Option<Scalar> {
    Some(match name {
        "char" | "int8" => Scalar::I8,
        "uchar" | "uint8" => Scalar::U8,
        "short" | "int16" => Scalar::I16,
        "ushort" | "uint16" => Scalar::U16,
        "int" | "int32" => Scalar::I32,
        "uint" | "uint32" => Scalar::U32,
        "float" | "float32" => Scalar::F32,
        "double" | "float64" => Scalar::F64,
        _ => return None,
    })
}

#[derive(Debug)]
enum Property {
    Scalar { name: String, ty: Scalar },
    List { name: String, count: Scalar, item: Scalar },
}

impl Property {
    fn name(&self) -> &str {
        match self {
            Property::Scalar { name, .. } | Property::List { name, .. } => name,
        }
    }
}

#[derive(Debug)]
struct Element {
    name: String,
    count: usize,
    properties: Vec<Property>,
}

#[derive(Debug)]
struct PlyHeader {
    format: PlyFormat,
    elements: Vec<Element>,
    /// Number of header lines, `end_header` included.
    lines: usize,
    /// Byte offset of the data.
    data_start: usize,
}

/// Parses the PLY header at the start of `bytes`.
fn parse_ply_header(bytes: &[u8]) -> std::result::Result<PlyHeader, String> {
    let mut pos = 0;
    let mut line_no = 0;
    let mut format = None;
    let mut elements: Vec<Element> = Vec::new();
    loop {
        let Some(len) = bytes[pos..].iter().position(|&b| b == b'\n') else {
            return Err(if line_no == 0 {
                "not a PLY file (no 'ply' line)".into()
            } else {
                "truncated header: no 'end_header' line".into()
            });
        };
        let line = String::from_utf8_lossy(&bytes[pos..pos + len]);
        pos += len + 1;
        line_no += 1;
        let words: Vec<&str> = line.split_whitespace().collect();
        let bad = |what: &str| format!("header line {line_no}: {what}: {:?}", line.trim());
        if line_no == 1 {
            if words != ["ply"] {
                return Err("not a PLY file (the first line is not 'ply')".into());
            }
            continue;
        }
        match words.as_slice() {
            [] | ["comment", ..] | ["obj_info", ..] => {}
            ["format", name, _version] => {
                format = Some(match *name {
                    "ascii" => PlyFormat::Ascii,
                    "binary_little_endian" => PlyFormat::BinaryLittleEndian,
                    "binary_big_endian" => PlyFormat::BinaryBigEndian,
                    _ => return Err(bad("unknown format (expected ascii, binary_little_endian or binary_big_endian)")),
                });
            }
            ["element", name, count] => {
                let count = count.parse().map_err(|_| bad("bad element count"))?;
                elements.push(Element { name: name.to_string(), count, properties: Vec::new() });
            }
            ["property", "list", count, item, name] => {
                let count = ply_scalar(count)
                    .filter(|t| t.is_integer())
                    .ok_or_else(|| bad("list count type must be an integer type"))?;
                let item = ply_scalar(item).ok_or_else(|| bad("unknown property type"))?;
                let element = elements.last_mut().ok_or_else(|| bad("property before any element"))?;
                element.properties.push(Property::List { name: name.to_string(), count, item });
            }
            ["property", ty, name] => {
                let ty = ply_scalar(ty).ok_or_else(|| bad("unknown property type"))?;
                let element = elements.last_mut().ok_or_else(|| bad("property before any element"))?;
                element.properties.push(Property::Scalar { name: name.to_string(), ty });
            }
            ["end_header"] => break,
            _ => return Err(bad("unrecognised header line")),
        }
    }
    let format = format.ok_or("header has no 'format' line")?;
    Ok(PlyHeader { format, elements, lines: line_no, data_start: pos })
}

/// The data section of a PLY file, read value by value.
enum PlyData<'a> {
    Ascii { lines: std::iter::Enumerate<std::str::Lines<'a>>, words: std::str::SplitWhitespace<'a>, line: usize },
    Binary { bytes: &'a [u8], pos: usize, big_endian: bool },
}

impl PlyData<'_> {
    /// The next value, read as `ty`; the error says what is wrong, without context.
    fn value(&mut self, ty: Scalar) -> std::result::Result<f64, String> {
        match self {
            PlyData::Ascii { lines, words, line } => {
                let word = loop {
                    if let Some(w) = words.next() {
                        break w;
                    }
                    let (i, next) = lines.next().ok_or("unexpected end of file")?;
                    *line = i;
                    *words = next.split_whitespace();
                };
                word.parse().map_err(|_| format!("{word:?} is not a number"))
            }
            PlyData::Binary { bytes, pos, big_endian } => {
                let size = ty.size();
                let raw = bytes.get(*pos..*pos + size).ok_or("unexpected end of file")?;
                *pos += size;
                Ok(ty.decode(raw, *big_endian))
            }
        }
    }

    /// Where the reader is, for error messages (1-based line of the file, or byte offset).
    fn location(&self, header_lines: usize, data_start: usize) -> String {
        match self {
            PlyData::Ascii { line, .. } => format!("line {}", header_lines + line + 1),
            PlyData::Binary { pos, .. } => format!("byte {}", data_start + pos),
        }
    }

    /// Whether anything but whitespace is left.
    fn has_more(&mut self) -> bool {
        match self {
            PlyData::Ascii { lines, words, .. } => words.next().is_some() || lines.any(|(_, l)| !l.trim().is_empty()),
            PlyData::Binary { bytes, pos, .. } => *pos < bytes.len(),
        }
    }
}

fn read_ply(path: &Path) -> Result<Vec<Point>> {
    let bytes = fs::read(path).map_err(|e| RegisterError::io(path, e))?;
    parse_ply(&bytes).map_err(|message| RegisterError::format(path, format!("PLY: {message}")))
}

fn parse_ply(bytes: &[u8]) -> std::result::Result<Vec<Point>, String> {
    let header = parse_ply_header(bytes)?;
    let vertex_index =
        header.elements.iter().position(|e| e.name == "vertex").ok_or("no 'vertex' element in the header")?;
    let vertex = &header.elements[vertex_index];
    // For each vertex property, the axis it gives, if any.
    let mut axis_of = vec![None; vertex.properties.len()];
    for (axis, name) in ["x", "y", "z"].iter().enumerate() {
        let k = vertex
            .properties
            .iter()
            .position(|p| p.name() == *name)
            .ok_or_else(|| format!("the vertex element has no '{name}' property"))?;
        if matches!(vertex.properties[k], Property::List { .. }) {
            return Err(format!("the vertex property '{name}' is a list, expected a scalar"));
        }
        axis_of[k] = Some(axis);
    }

    let data = &bytes[header.data_start..];
    let mut reader = match header.format {
        PlyFormat::Ascii => {
            let text = std::str::from_utf8(data).map_err(|_| "ASCII data is not text")?;
            PlyData::Ascii { lines: text.lines().enumerate(), words: "".split_whitespace(), line: 0 }
        }
        PlyFormat::BinaryLittleEndian | PlyFormat::BinaryBigEndian => {
            PlyData::Binary { bytes: data, pos: 0, big_endian: header.format == PlyFormat::BinaryBigEndian }
        }
    };

    let mut points = Vec::with_capacity(vertex.count.min(data.len()));
    for (e, element) in header.elements.iter().enumerate().take(vertex_index + 1) {
        let is_vertex = e == vertex_index;
        for item in 0..element.count {
            let mut p = [0.0; 3];
            for (k, property) in element.properties.iter().enumerate() {
                let context = |reader: &PlyData, message: String| {
                    format!(
                        "{}: {} {item} of {}, property '{}': {message}",
                        reader.location(header.lines, header.data_start),
                        element.name,
                        element.count,
                        property.name()
                    )
                };
                match property {
                    Property::Scalar { ty, .. } => {
                        let v = reader.value(*ty).map_err(|m| context(&reader, m))?;
                        if let Some(axis) = axis_of.get(k).copied().flatten().filter(|_| is_vertex) {
                            p[axis] = v;
                        }
                    }
                    Property::List { count, item: item_ty, .. } => {
                        let n = reader.value(*count).map_err(|m| context(&reader, m))?;
                        if n < 0.0 || n.fract() != 0.0 {
                            return Err(context(&reader, format!("bad list length {n}")));
                        }
                        for _ in 0..n as usize {
                            reader.value(*item_ty).map_err(|m| context(&reader, m))?;
                        }
                    }
                }
            }
            if is_vertex {
                points.push(p);
            }
        }
    }
    if vertex_index + 1 == header.elements.len() && reader.has_more() {
        return Err(format!(
            "more data than the header declares (vertex is the last element, with {} items)",
            vertex.count
        ));
    }
    Ok(points)
}
