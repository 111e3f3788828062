//! Wavefront OBJ and STL surfaces.

use std::collections::HashMap;
use std::io::Write;
use std::path::Path;

use super::text::LineReader;
use super::{check_surface, fan, read_bytes, write_atomic, Num};
use crate::{cross, sub, MeshError, Point, TriSurface};

/// Reads a Wavefront OBJ surface: `v` vertices (all kept, in order) and `f` faces (1-based or
/// negative relative indices, `v/vt/vn` forms accepted), polygons split into triangle fans.
/// Normals, texture coordinates, groups and materials are ignored.
pub fn read_obj(path: impl AsRef<Path>) -> Result<TriSurface, MeshError> {
    let path = path.as_ref();
    let surface = parse_obj(path)?;
    if surface.triangles.is_empty() {
        return Err(MeshError::parse(path, "no faces ('f' lines)"));
    }
    Ok(surface)
}

/// The vertices (`v` lines) of a Wavefront OBJ file, with or without faces (a point cloud).
pub(super) fn read_obj_vertices(path: &Path) -> Result<Vec<Point>, MeshError> {
    Ok(parse_obj(path)?.vertices)
}

/// The vertices and the faces (fanned into triangles) of a Wavefront OBJ file, checked.
fn parse_obj(path: &Path) -> Result<TriSurface, MeshError> {
    let bytes = read_bytes(path)?;
    let text = String::from_utf8_lossy(&bytes);
    let mut lines = LineReader::new(path, &text);
    let mut surface = TriSurface::default();
    let mut polygon = Vec::new();
    while let Some(mut line) = lines.next_line() {
        match line.next_token() {
            Some("v") => {
                let p = line.point("vertex coordinate")?;
                surface.vertices.push(p);
            }
            Some("f") => {
                polygon.clear();
                let n = surface.vertices.len() as i64;
                while let Some(token) = line.next_token() {
                    let index: i64 = token
                        .split('/')
                        .next()
                        .and_then(|s| s.parse().ok())
                        .ok_or_else(|| line.error(format!("face vertex '{token}' is not an index")))?;
                    let i = if index < 0 { n + index } else { index - 1 };
                    if index == 0 || i < 0 || i >= n {
                        return Err(
                            line.error(format!("face refers to vertex {index}, but {n} vertices are defined so far"))
                        );
                    }
                    polygon.push(i as usize);
                }
                if polygon.len() < 3 {
                    return Err(line.error(format!("a face needs at least 3 vertices, found {}", polygon.len())));
                }
                fan(&polygon, &mut surface.triangles);
            }
            _ => {}
        }
    }
    Ok(surface)
}

/// Writes a surface as Wavefront OBJ (vertices written exactly, 1-based faces).
pub fn write_obj(path: impl AsRef<Path>, surface: &TriSurface) -> Result<(), MeshError> {
    write_obj_titled(path.as_ref(), surface, "augsim")
}

/// [`write_obj`] with `title` in its first comment line, where 3D Slicer looks for `SPACE=`.
pub(super) fn write_obj_titled(path: &Path, surface: &TriSurface, title: &str) -> Result<(), MeshError> {
    check_surface(surface)?;
    write_atomic(path, |w| {
        writeln!(w, "# {title}")?;
        writeln!(w, "# {} vertices, {} triangles", surface.vertices.len(), surface.triangles.len())?;
        for p in &surface.vertices {
            writeln!(w, "v {} {} {}", Num(p[0]), Num(p[1]), Num(p[2]))?;
        }
        for t in &surface.triangles {
            writeln!(w, "f {} {} {}", t[0] + 1, t[1] + 1, t[2] + 1)?;
        }
        Ok(())
    })
    .map_err(MeshError::from)
}

/// Merges vertices with exactly equal coordinates (0.0 and −0.0 are the same).
#[derive(Default)]
struct Merger {
    index: HashMap<[u64; 3], usize>,
    vertices: Vec<Point>,
}

impl Merger {
    fn add(&mut self, p: Point) -> usize {
        let p = p.map(|c| c + 0.0);
        let next = self.vertices.len();
        let i = *self.index.entry(p.map(f64::to_bits)).or_insert(next);
        if i == next {
            self.vertices.push(p);
        }
        i
    }
}

/// Reads an STL surface, binary or ASCII. Vertices with exactly equal coordinates are merged so
/// that the surface is indexed; facet normals are ignored (orientation is the vertex order), and
/// may be non-finite (`facet normal -nan -nan -nan`, as MeshLab writes for a degenerate facet).
/// A binary STL whose header's triangle count its size belies is read for the records it holds
/// (the warning saying so is dropped here: [`crate::io::read_surface_noted`] gives it).
pub fn read_stl(path: impl AsRef<Path>) -> Result<TriSurface, MeshError> {
    read_stl_noting(path.as_ref()).map(|(surface, _)| surface)
}

/// [`read_stl`], with what a user should know of the file as read. A file starting with `solid`
/// is text unless it is a binary STL whose size its header's count gives exactly (binary headers
/// may start with `solid` too); one whose text does not parse is binary unless it reads as text.
/// A binary STL whose size after the 84-byte header is a whole number of 50-byte records is read
/// for the records its size holds, as VTK (3D Slicer) reads it, with a warning where its header's
/// count says otherwise (exporters write 0); where part of a record trails, for its header's count
/// (a warning: the bytes after them ignored), and not at all where that count is 0 (another file,
/// or one cut short). One holding fewer records than its count is cut short, an error.
pub(super) fn read_stl_noting(path: &Path) -> Result<(TriSurface, Vec<String>), MeshError> {
    let bytes = read_bytes(path)?;
    let declared = bytes.get(80..84).map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize);
    let exact = declared.is_some_and(|n| 84 + 50 * n as u128 == bytes.len() as u128);
    let ascii_start = bytes.trim_ascii_start().get(..5).is_some_and(|s| s.eq_ignore_ascii_case(b"solid"));
    if ascii_start && !exact {
        // Some exporters pad an ASCII STL with NUL bytes (to a block size, or a line of its own).
        let text: Vec<u8> = bytes.iter().map(|&b| if b == 0 { b' ' } else { b }).collect();
        let ascii = read_stl_ascii(path, &String::from_utf8_lossy(&text));
        if ascii.is_ok() || looks_like_text(&bytes) {
            return ascii.map(|surface| (surface, Vec::new()));
        }
    }
    let Some(declared) = declared else {
        return Err(MeshError::parse(
            path,
            format!(
                "{} bytes: too short for a binary STL, and not an ASCII STL (which starts with 'solid')",
                bytes.len()
            ),
        ));
    };
    let (records, left) = ((bytes.len() - 84) / 50, (bytes.len() - 84) % 50);
    let declares = format!("its header declares {declared} triangles ({} bytes)", 84 + 50 * declared as u128);
    let (n, warning) = match (declared.cmp(&records), left) {
        (std::cmp::Ordering::Equal, 0) => (declared, None),
        (std::cmp::Ordering::Greater, _) => {
            return Err(MeshError::parse(
                path,
                format!(
                    "a binary STL cut short: {declares}, but the file has {} bytes, {records} whole triangles",
                    bytes.len()
                ),
            ))
        }
        (_, 0) => (
            records,
            Some(format!("{declares}, but its size holds {records}: read {records}, as VTK (3D Slicer) does")),
        ),
        _ if declared == 0 => {
            return Err(MeshError::parse(
                path,
                format!(
                    "not a binary STL: {declares}, and its {} bytes after the header are no whole number of \
                     50-byte triangles (cut short, or another file)",
                    bytes.len() - 84
                ),
            ))
        }
        _ => {
            let after = bytes.len() - 84 - 50 * declared;
            (
                declared,
                Some(format!("{after} bytes after its {declared} triangles, which its header declares, ignored")),
            )
        }
    };
    if n == 0 {
        return Err(MeshError::parse(path, "a binary STL of no triangles: the surface is empty"));
    }
    let mut merger = Merger::default();
    let mut triangles = Vec::with_capacity(n);
    for (t, record) in bytes[84..84 + 50 * n].chunks_exact(50).enumerate() {
        let f = |k: usize| {
            let b = &record[12 + 4 * k..16 + 4 * k];
            f32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64
        };
        let corners: [Point; 3] = std::array::from_fn(|v| [f(3 * v), f(3 * v + 1), f(3 * v + 2)]);
        if corners.iter().flatten().any(|c| !c.is_finite()) {
            return Err(MeshError::parse(path, format!("triangle {t} has a non-finite coordinate")));
        }
        triangles.push(corners.map(|p| merger.add(p)));
    }
    Ok((TriSurface { vertices: merger.vertices, triangles }, warning.into_iter().collect()))
}

/// Whether `bytes` are text, as an ASCII STL's are: under 1 % of them control characters (NUL,
/// tab and line ends aside) or bytes beyond ASCII, where a binary STL's floats hold far more.
fn looks_like_text(bytes: &[u8]) -> bool {
    let binary = bytes.iter().filter(|&&b| !(b == 0 || b.is_ascii_graphic() || b.is_ascii_whitespace())).count();
    100 * binary < bytes.len()
}

/// Where an ASCII STL parser is.
#[derive(Clone, Copy, PartialEq, Eq)]
enum State {
    Outside,
    Solid,
    Facet,
    Loop,
    LoopDone,
}

impl State {
    fn expected(self) -> &'static str {
        match self {
            State::Outside => "'solid'",
            State::Solid => "'facet normal' or 'endsolid'",
            State::Facet => "'outer loop'",
            State::Loop => "'vertex' or 'endloop'",
            State::LoopDone => "'endfacet'",
        }
    }
}

/// Parses an ASCII STL (several solids allowed, the last `endsolid` optional; loops of more than
/// 3 vertices become fans).
fn read_stl_ascii(path: &Path, text: &str) -> Result<TriSurface, MeshError> {
    let mut lines = LineReader::new(path, text);
    let mut merger = Merger::default();
    let mut triangles = Vec::new();
    let mut polygon = Vec::new();
    let mut state = State::Outside;
    while let Some(mut line) = lines.next_line() {
        let key = line.next_token().unwrap_or("").to_ascii_lowercase();
        state = match (state, key.as_str()) {
            (State::Outside, "solid") => State::Solid,
            (State::Solid, "facet") => {
                if !line.token("'normal'")?.eq_ignore_ascii_case("normal") {
                    return Err(line.error("expected 'facet normal'"));
                }
                for _ in 0..3 {
                    line.parse::<f64>("normal component")?;
                }
                State::Facet
            }
            (State::Facet, "outer") => {
                if !line.token("'loop'")?.eq_ignore_ascii_case("loop") {
                    return Err(line.error("expected 'outer loop'"));
                }
                polygon.clear();
                State::Loop
            }
            (State::Loop, "vertex") => {
                let p = line.point("vertex coordinate")?;
                line.finish("the vertex coordinates")?;
                polygon.push(merger.add(p));
                State::Loop
            }
            (State::Loop, "endloop") => {
                if polygon.len() < 3 {
                    return Err(line.error(format!("a facet needs 3 vertices, found {}", polygon.len())));
                }
                fan(&polygon, &mut triangles);
                State::LoopDone
            }
            (State::LoopDone, "endfacet") => State::Solid,
            (State::Solid, "endsolid") => State::Outside,
            (state, _) => {
                return Err(line.error(format!("expected {}, found '{}'", state.expected(), line.text.trim())));
            }
        };
    }
    // A file may end after its last facet without `endsolid`; inside a facet it is cut short.
    if state != State::Outside && state != State::Solid {
        return Err(lines.end_of_file(state.expected()));
    }
    if triangles.is_empty() {
        return Err(MeshError::parse(path, "no facets"));
    }
    Ok(TriSurface { vertices: merger.vertices, triangles })
}

/// Writes a surface as binary STL (single precision, unit facet normals from the vertex order).
pub fn write_stl(path: impl AsRef<Path>, surface: &TriSurface) -> Result<(), MeshError> {
    write_stl_titled(path.as_ref(), surface, "augsim binary STL")
}

/// [`write_stl`] with `title` at the start of the 80-byte header (ASCII, at most 80 bytes, not
/// starting with `solid`, which would make the file look like an ASCII STL).
pub(super) fn write_stl_titled(path: &Path, surface: &TriSurface, title: &str) -> Result<(), MeshError> {
    if !title.is_ascii() || title.len() > 80 || title.trim_start().to_ascii_lowercase().starts_with("solid") {
        return Err(MeshError::Invalid(format!(
            "a binary STL header is ASCII, at most 80 bytes, not `solid…`: {title:?}"
        )));
    }
    check_surface(surface)?;
    let count = u32::try_from(surface.triangles.len())
        .map_err(|_| MeshError::Invalid("too many triangles for binary STL".into()))?;
    write_atomic(path, |w| {
        let mut header = [b' '; 80];
        header[..title.len()].copy_from_slice(title.as_bytes());
        w.write_all(&header)?;
        w.write_all(&count.to_le_bytes())?;
        for t in &surface.triangles {
            let [a, b, c] = t.map(|i| surface.vertices[i]);
            let n = cross(sub(b, a), sub(c, a));
            let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
            let n = if len > 0.0 { n.map(|x| x / len) } else { [0.0; 3] };
            for x in n.iter().chain(a.iter()).chain(b.iter()).chain(c.iter()) {
                w.write_all(&(*x as f32).to_le_bytes())?;
            }
            w.write_all(&[0, 0])?;
        }
        Ok(())
    })
    .map_err(MeshError::from)
}
