//! PLY (Stanford polygon) files: ASCII or binary of either byte order, with any elements and
//! properties, as 3D Slicer, VTK, MeshLab and Open3D write them. Read: the `vertex` element's
//! `x`, `y`, `z` and, for a surface, the `face` element's vertex lists (`vertex_indices` or
//! `vertex_index`); every other element and property is read past. Written: points alone, as
//! binary little-endian doubles.

use std::io::Write as _;
use std::path::Path;

use super::legacy_vtk::{surface_from_cells, to_index};
use super::{read_bytes, write_atomic, Scalar, VTK_POLYGON};
use crate::{MeshError, Point, TriSurface};

/// Reads the points of a PLY file (its `vertex` element), whatever else it holds.
pub(super) fn read_ply_vertices(path: &Path) -> Result<Vec<Point>, MeshError> {
    Ok(read(path, false)?.0)
}

/// Reads a PLY surface: its vertices and its faces, polygons split into triangle fans.
pub(super) fn read_ply_surface(path: &Path) -> Result<TriSurface, MeshError> {
    let (points, faces) = read(path, true)?;
    surface_from_cells(path, points, faces.iter().map(|f| (VTK_POLYGON.into(), f.as_slice())))
}

/// Writes points as a binary little-endian PLY of float64 `x`, `y`, `z` (no faces), atomically.
pub fn write_ply_points(path: impl AsRef<Path>, points: &[Point]) -> Result<(), MeshError> {
    write_atomic(path.as_ref(), |w| {
        write!(
            w,
            "ply\nformat binary_little_endian 1.0\nelement vertex {}\n\
             property double x\nproperty double y\nproperty double z\nend_header\n",
            points.len()
        )?;
        for v in points.iter().flatten() {
            w.write_all(&v.to_le_bytes())?;
        }
        Ok(())
    })?;
    Ok(())
}

/// The vertices and (with `faces`) the faces of a PLY file.
fn read(path: &Path, faces: bool) -> Result<(Vec<Point>, Vec<Vec<usize>>), MeshError> {
    let bytes = read_bytes(path)?;
    parse(&bytes, faces).map_err(|message| MeshError::parse(path, format!("PLY: {message}")))
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Format {
    Ascii,
    BinaryLittleEndian,
    BinaryBigEndian,
}

/// The scalar type of a PLY type name.
fn scalar(name: &str) -> Option<Scalar> {
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
struct Header {
    format: Format,
    elements: Vec<Element>,
    /// Number of header lines, `end_header` included.
    lines: usize,
    /// Byte offset of the data.
    data_start: usize,
}

/// Parses the PLY header at the start of `bytes`.
fn parse_header(bytes: &[u8]) -> Result<Header, String> {
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
                    "ascii" => Format::Ascii,
                    "binary_little_endian" => Format::BinaryLittleEndian,
                    "binary_big_endian" => Format::BinaryBigEndian,
                    _ => return Err(bad("unknown format (expected ascii, binary_little_endian or binary_big_endian)")),
                });
            }
            ["element", name, count] => {
                let count = count.parse().map_err(|_| bad("bad element count"))?;
                elements.push(Element { name: name.to_string(), count, properties: Vec::new() });
            }
            ["property", "list", count, item, name] => {
                let count = scalar(count)
                    .filter(|t| t.is_integer())
                    .ok_or_else(|| bad("list count type must be an integer type"))?;
                let item = scalar(item).ok_or_else(|| bad("unknown property type"))?;
                let element = elements.last_mut().ok_or_else(|| bad("property before any element"))?;
                element.properties.push(Property::List { name: name.to_string(), count, item });
            }
            ["property", ty, name] => {
                let ty = scalar(ty).ok_or_else(|| bad("unknown property type"))?;
                let element = elements.last_mut().ok_or_else(|| bad("property before any element"))?;
                element.properties.push(Property::Scalar { name: name.to_string(), ty });
            }
            ["end_header"] => break,
            _ => return Err(bad("unrecognised header line")),
        }
    }
    let format = format.ok_or("header has no 'format' line")?;
    Ok(Header { format, elements, lines: line_no, data_start: pos })
}

/// The data section of a PLY file, read value by value.
enum Data<'a> {
    Ascii { lines: std::iter::Enumerate<std::str::Lines<'a>>, words: std::str::SplitWhitespace<'a>, line: usize },
    Binary { bytes: &'a [u8], pos: usize, big_endian: bool },
}

impl Data<'_> {
    /// The next value, read as `ty`; the error says what is wrong, without context.
    fn value(&mut self, ty: Scalar) -> Result<f64, String> {
        match self {
            Data::Ascii { lines, words, line } => {
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
            Data::Binary { bytes, pos, big_endian } => {
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
            Data::Ascii { line, .. } => format!("line {}", header_lines + line + 1),
            Data::Binary { pos, .. } => format!("byte {}", data_start + pos),
        }
    }

    /// Whether anything but whitespace is left.
    fn has_more(&mut self) -> bool {
        match self {
            Data::Ascii { lines, words, .. } => words.next().is_some() || lines.any(|(_, l)| !l.trim().is_empty()),
            Data::Binary { bytes, pos, .. } => *pos < bytes.len(),
        }
    }
}

/// What a property of the vertex or face element gives.
#[derive(Clone, Copy, PartialEq)]
enum Role {
    /// A coordinate of a vertex (0, 1, 2: x, y, z).
    Axis(usize),
    /// The vertex list of a face.
    Face,
    /// Nothing read.
    Skipped,
}

/// The role of each property of `element`, checked: a vertex's coordinates are scalars, a face's
/// vertex list is a list of integers.
fn roles(element: &Element, is_vertex: bool, is_face: bool) -> Result<Vec<Role>, String> {
    let mut roles = vec![Role::Skipped; element.properties.len()];
    if is_vertex {
        for (axis, name) in ["x", "y", "z"].iter().enumerate() {
            let k = element
                .properties
                .iter()
                .position(|p| p.name() == *name)
                .ok_or_else(|| format!("the vertex element has no '{name}' property"))?;
            if matches!(element.properties[k], Property::List { .. }) {
                return Err(format!("the vertex property '{name}' is a list, expected a scalar"));
            }
            roles[k] = Role::Axis(axis);
        }
    }
    if is_face {
        let k = element
            .properties
            .iter()
            .position(|p| matches!(p.name(), "vertex_indices" | "vertex_index"))
            .ok_or("the face element has no 'vertex_indices' property")?;
        match element.properties[k] {
            Property::List { item, .. } if item.is_integer() => roles[k] = Role::Face,
            _ => return Err("the face property 'vertex_indices' is not a list of integers".into()),
        }
    }
    Ok(roles)
}

/// The vertices and (with `want_faces`) the faces of the PLY file `bytes`. Elements are read in
/// order up to the last one needed (an element of no property holds nothing to read); a vertex
/// must be finite and within [`MAX_COORDINATE`](crate::MAX_COORDINATE).
fn parse(bytes: &[u8], want_faces: bool) -> Result<(Vec<Point>, Vec<Vec<usize>>), String> {
    let header = parse_header(bytes)?;
    let position = |name: &str| header.elements.iter().position(|e| e.name == name);
    let vertex_index = position("vertex").ok_or("no 'vertex' element in the header")?;
    let face_index = match want_faces {
        true => Some(position("face").ok_or("no 'face' element: a point cloud, not a surface")?),
        false => None,
    };
    let last = vertex_index.max(face_index.unwrap_or(0));

    let data = &bytes[header.data_start..];
    let mut reader = match header.format {
        Format::Ascii => {
            let text = std::str::from_utf8(data).map_err(|_| "ASCII data is not text")?;
            Data::Ascii { lines: text.lines().enumerate(), words: "".split_whitespace(), line: 0 }
        }
        Format::BinaryLittleEndian | Format::BinaryBigEndian => {
            Data::Binary { bytes: data, pos: 0, big_endian: header.format == Format::BinaryBigEndian }
        }
    };

    // What a face's impossible list length or index most often comes from.
    let cause = match header.format {
        Format::Ascii => "do the header's element counts match the data?",
        _ => "do the header's byte order and element counts match the data?",
    };
    let mut points = Vec::with_capacity(header.elements[vertex_index].count.min(data.len()));
    let mut faces = Vec::new();
    for (e, element) in header.elements.iter().enumerate().take(last + 1) {
        let (is_vertex, is_face) = (e == vertex_index, Some(e) == face_index);
        let roles = roles(element, is_vertex, is_face)?;
        if element.properties.is_empty() {
            continue;
        }
        for item in 0..element.count {
            let mut p = [0.0; 3];
            for (property, &role) in element.properties.iter().zip(&roles) {
                let context = |reader: &Data, message: String| {
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
                        if let Role::Axis(axis) = role {
                            p[axis] = v;
                        }
                    }
                    Property::List { count, item: item_ty, .. } => {
                        let n = reader.value(*count).map_err(|m| context(&reader, m))?;
                        let n = to_index(n).ok_or_else(|| context(&reader, format!("bad list length {n}: {cause}")))?;
                        // Not reserved from `n`: a count the data does not hold fails at its end.
                        let mut list = Vec::new();
                        for _ in 0..n {
                            let v = reader.value(*item_ty).map_err(|m| context(&reader, m))?;
                            if role == Role::Face {
                                let index = to_index(v)
                                    .ok_or_else(|| context(&reader, format!("vertex index {v}: {cause}")))?;
                                list.push(index);
                            }
                        }
                        if role == Role::Face {
                            faces.push(list);
                        }
                    }
                }
            }
            if is_vertex {
                if let Some((_, fault)) = crate::coordinate_fault([(item, &p)], crate::MAX_COORDINATE) {
                    let at = reader.location(header.lines, header.data_start);
                    return Err(format!("{at}: vertex {item} {fault}"));
                }
                points.push(p);
            }
        }
    }
    let beyond =
        faces.iter().enumerate().find_map(|(f, face)| face.iter().find(|&&v| v >= points.len()).map(|&v| (f, v)));
    if let Some((f, v)) = beyond {
        return Err(format!("face {f} refers to vertex {v}, but there are {} vertices: {cause}", points.len()));
    }
    if last + 1 == header.elements.len() && reader.has_more() {
        let element = &header.elements[last];
        return Err(format!(
            "more data than the header declares ({} is the last element, with {} items)",
            element.name, element.count
        ));
    }
    Ok((points, faces))
}
