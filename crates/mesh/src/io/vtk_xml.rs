//! VTK XML files: unstructured grids (`.vtu`) and poly data (`.vtp`).
//!
//! Written: `.vtu`, with Float64 values and Int64 connectivity, ASCII or base64 (UInt64 headers).
//! Read: either type, one `Piece`, arrays in `ascii`, `binary` (base64) or `appended` (raw or
//! base64) form, UInt32 or UInt64 headers, either byte order, uncompressed or zlib-compressed:
//! what ParaView, VTK, 3D Slicer and meshio write. Every array is checked against its declared
//! size. Poly data's cells are its vertices, lines, polygons and triangle strips, in that order
//! (VTK's). A string array of the field data is read where it names the frame (`SPACE`, as 3D
//! Slicer writes it).

use std::io::Write;
use std::path::Path;

use std::io::Read;
use std::ops::Range;

use base64::engine::general_purpose::STANDARD as BASE64;
use base64::Engine as _;

use super::legacy_vtk::{surface_from_cells, to_index, volume_from_cells};
use super::{
    check_for_writing, check_surface, frame_in_header, mesh_cells_flat, write_atomic, Encoding, Field, FieldLocation,
    Frame, Num, Scalar, VTK_POLYGON, VTK_POLY_LINE, VTK_POLY_VERTEX, VTK_TRIANGLE, VTK_TRIANGLE_STRIP,
};
use crate::{Mesh, MeshError, Point, TriSurface};

/// A scalar type of a `.vtu` data array.
trait VtuScalar: Copy {
    /// The VTK XML type name.
    const NAME: &'static str;
    /// Appends the little-endian bytes.
    fn le_bytes(self, out: &mut Vec<u8>);
    /// Writes the value as text.
    fn text(self, w: &mut dyn Write) -> std::io::Result<()>;
}

impl VtuScalar for f64 {
    const NAME: &'static str = "Float64";
    fn le_bytes(self, out: &mut Vec<u8>) {
        out.extend_from_slice(&self.to_le_bytes());
    }
    fn text(self, w: &mut dyn Write) -> std::io::Result<()> {
        write!(w, "{}", Num(self))
    }
}

impl VtuScalar for i64 {
    const NAME: &'static str = "Int64";
    fn le_bytes(self, out: &mut Vec<u8>) {
        out.extend_from_slice(&self.to_le_bytes());
    }
    fn text(self, w: &mut dyn Write) -> std::io::Result<()> {
        write!(w, "{self}")
    }
}

impl VtuScalar for u8 {
    const NAME: &'static str = "UInt8";
    fn le_bytes(self, out: &mut Vec<u8>) {
        out.push(self);
    }
    fn text(self, w: &mut dyn Write) -> std::io::Result<()> {
        write!(w, "{self}")
    }
}

/// Writes one `<DataArray>` with extra attributes `attrs`: base64 of a UInt64 byte count
/// followed by the data (binary), or text with `per_line` values per line (ASCII).
fn write_array<T: VtuScalar>(
    w: &mut dyn Write,
    attrs: &str,
    values: &[T],
    encoding: Encoding,
    per_line: usize,
) -> std::io::Result<()> {
    match encoding {
        Encoding::Binary => {
            let size = std::mem::size_of_val(values);
            let mut bytes = Vec::with_capacity(8 + size);
            bytes.extend_from_slice(&(size as u64).to_le_bytes());
            for &v in values {
                v.le_bytes(&mut bytes);
            }
            writeln!(w, "<DataArray type=\"{}\"{attrs} format=\"binary\">{}</DataArray>", T::NAME, BASE64.encode(bytes))
        }
        Encoding::Ascii => {
            write!(w, "<DataArray type=\"{}\"{attrs} format=\"ascii\">", T::NAME)?;
            for (i, &v) in values.iter().enumerate() {
                w.write_all(if i % per_line == 0 { b"\n" } else { b" " })?;
                v.text(w)?;
            }
            writeln!(w, "\n</DataArray>")
        }
    }
}

/// Writes a whole `.vtu` file of cells of one VTK type (`cells`: their connectivity, `k` nodes
/// each, their type).
fn write_grid(
    path: &Path,
    nodes: &[Point],
    (conn, k, cell_type): (&[usize], usize, u8),
    fields: &[Field],
    encoding: Encoding,
    frame: Option<Frame>,
) -> Result<(), MeshError> {
    let cells = conn.len() / k;
    check_for_writing(nodes.len(), cells, conn, fields)?;
    let points: Vec<f64> = nodes.iter().flatten().copied().collect();
    let connectivity: Vec<i64> = conn.iter().map(|&i| i as i64).collect();
    let offsets: Vec<i64> = (1..=cells).map(|c| (c * k) as i64).collect();
    let types = vec![cell_type; cells];
    write_atomic(path, |w| {
        writeln!(
            w,
            "<?xml version=\"1.0\"?>\n\
             <VTKFile type=\"UnstructuredGrid\" version=\"1.0\" byte_order=\"LittleEndian\" header_type=\"UInt64\">\n\
             <UnstructuredGrid>",
        )?;
        if let Some(frame) = frame {
            // As 3D Slicer names a model's frame: a string array `SPACE` of the field data.
            let name: Vec<String> = frame.name().bytes().chain([0]).map(|b| b.to_string()).collect();
            writeln!(
                w,
                "<FieldData>\n<Array type=\"String\" Name=\"SPACE\" NumberOfTuples=\"1\" format=\"ascii\">\n{}\n</Array>\n\
                 </FieldData>",
                name.join(" ")
            )?;
        }
        writeln!(w, "<Piece NumberOfPoints=\"{}\" NumberOfCells=\"{cells}\">", nodes.len())?;
        for (location, tag) in [(FieldLocation::Point, "PointData"), (FieldLocation::Cell, "CellData")] {
            let here: Vec<&Field> = fields.iter().filter(|f| f.location == location).collect();
            if here.is_empty() {
                continue;
            }
            writeln!(w, "<{tag}>")?;
            for f in here {
                let attrs = format!(" Name=\"{}\" NumberOfComponents=\"{}\"", f.name, f.components);
                write_array(w, &attrs, &f.values, encoding, f.components.max(3))?;
            }
            writeln!(w, "</{tag}>")?;
        }
        writeln!(w, "<Points>")?;
        write_array(w, " NumberOfComponents=\"3\"", &points, encoding, 3)?;
        writeln!(w, "</Points>\n<Cells>")?;
        write_array(w, " Name=\"connectivity\"", &connectivity, encoding, k)?;
        write_array(w, " Name=\"offsets\"", &offsets, encoding, 16)?;
        write_array(w, " Name=\"types\"", &types, encoding, 32)?;
        writeln!(w, "</Cells>\n</Piece>\n</UnstructuredGrid>\n</VTKFile>")
    })
    .map_err(MeshError::from)
}

/// Writes a volume mesh with point and cell data as a VTK XML unstructured grid with base64
/// binary arrays (Float64 values, Int64 connectivity), as read by ParaView and meshio.
pub fn write_vtu(path: impl AsRef<Path>, mesh: &Mesh, fields: &[Field]) -> Result<(), MeshError> {
    write_vtu_with(path, mesh, fields, Encoding::Binary)
}

/// Like [`write_vtu`], in the given encoding.
pub fn write_vtu_with(
    path: impl AsRef<Path>,
    mesh: &Mesh,
    fields: &[Field],
    encoding: Encoding,
) -> Result<(), MeshError> {
    let (ty, k, conn) = mesh_cells_flat(mesh);
    write_grid(path.as_ref(), &mesh.nodes, (&conn, k, ty), fields, encoding, None)
}

/// Like [`write_vtu`], naming the mesh's frame as 3D Slicer reads it from a model's field data
/// (a string array `SPACE`).
pub fn write_vtu_in_frame(
    path: impl AsRef<Path>,
    mesh: &Mesh,
    fields: &[Field],
    frame: Frame,
) -> Result<(), MeshError> {
    let (ty, k, conn) = mesh_cells_flat(mesh);
    write_grid(path.as_ref(), &mesh.nodes, (&conn, k, ty), fields, Encoding::Binary, Some(frame))
}

/// Writes a surface as a `.vtu` of triangles.
pub(super) fn write_surface_vtu(path: &Path, surface: &TriSurface) -> Result<(), MeshError> {
    let conn = check_surface(surface)?;
    write_grid(path, &surface.vertices, (&conn, 3, VTK_TRIANGLE), &[], Encoding::Binary, None)
}

/// Message for a binary header that ends early.
const CUT_HEADER: &str = "the binary header is cut short (truncated file?)";
/// Message for binary data that ends before its header says.
const CUT_DATA: &str = "the data is shorter than its header announces (truncated file?)";

/// The scalar type of a VTK XML type name; a `String` array's characters are bytes.
fn scalar(name: &str) -> Option<Scalar> {
    Some(match name {
        "Int8" => Scalar::I8,
        "UInt8" | "String" => Scalar::U8,
        "Int16" => Scalar::I16,
        "UInt16" => Scalar::U16,
        "Int32" => Scalar::I32,
        "UInt32" => Scalar::U32,
        "Int64" => Scalar::I64,
        "UInt64" => Scalar::U64,
        "Float32" => Scalar::F32,
        "Float64" => Scalar::F64,
        _ => return None,
    })
}

/// A `<DataArray>` (or, in `<FieldData>`, an `<Array>`) of the file.
struct ArrayDecl {
    /// The enclosing element (`Points`, `Cells`, `Polys`, `PointData`, `CellData`, `FieldData`, ...).
    parent: String,
    name: String,
    ty: String,
    components: usize,
    format: String,
    offset: Option<usize>,
    /// Byte range of the element's text.
    content: Range<usize>,
    /// Byte offset of the tag, for line numbers.
    at: usize,
}

/// The sections of poly data's cells in VTK's order: element, count attribute, VTK cell type.
const POLY_SECTIONS: [(&str, &str, u8); 4] = [
    ("Verts", "NumberOfVerts", VTK_POLY_VERTEX),
    ("Lines", "NumberOfLines", VTK_POLY_LINE),
    ("Polys", "NumberOfPolys", VTK_POLYGON),
    ("Strips", "NumberOfStrips", VTK_TRIANGLE_STRIP),
];

/// The structure of a VTK XML file: its settings, sizes, arrays and appended data.
struct XmlFile<'a> {
    path: &'a Path,
    data: &'a [u8],
    /// Poly data (`.vtp`), not an unstructured grid.
    poly: bool,
    header64: bool,
    big_endian: bool,
    zlib: bool,
    points: usize,
    /// The number of cells of an unstructured grid, or of each of the [`POLY_SECTIONS`].
    cell_counts: Vec<usize>,
    arrays: Vec<ArrayDecl>,
    /// Appended data: (raw, byte range after the `_` marker).
    appended: Option<(bool, Range<usize>)>,
}

/// Line number (from 1) of byte offset `at`.
fn line_at(data: &[u8], at: usize) -> usize {
    data[..at.min(data.len())].iter().filter(|&&b| b == b'\n').count() + 1
}

/// Position of `needle` in `data` at or after `from`.
fn find(data: &[u8], from: usize, needle: &[u8]) -> Option<usize> {
    data.get(from..)?.windows(needle.len()).position(|w| w == needle).map(|p| p + from)
}

/// Replaces the five predefined XML entities.
fn unescape(s: &str) -> String {
    s.replace("&quot;", "\"").replace("&apos;", "'").replace("&lt;", "<").replace("&gt;", ">").replace("&amp;", "&")
}

/// Base64 characters needed for `n` bytes.
fn b64_len(n: usize) -> usize {
    n.div_ceil(3).saturating_mul(4)
}

/// An opening tag: name, attributes, whether it closes itself, and the offset after `>`.
type Tag = (String, Vec<(String, String)>, bool, usize);

/// Parses the opening tag that starts at `lt` (the `<`).
fn parse_tag(data: &[u8], lt: usize) -> Result<Tag, String> {
    let end = find(data, lt, b">").ok_or("a tag is not closed by '>' (truncated file?)")?;
    let inner = String::from_utf8_lossy(&data[lt + 1..end]);
    let (inner, self_closing) = match inner.strip_suffix('/') {
        Some(s) => (s.to_string(), true),
        None => (inner.to_string(), false),
    };
    let name_end = inner.find(|c: char| c.is_whitespace()).unwrap_or(inner.len());
    let name = inner[..name_end].to_string();
    let mut attrs = Vec::new();
    let mut rest = inner[name_end..].trim_start();
    while !rest.is_empty() {
        let eq = rest.find('=').ok_or_else(|| format!("malformed attribute in <{name}>"))?;
        let key = rest[..eq].trim().to_string();
        let after = rest[eq + 1..].trim_start();
        let quote = after.chars().next().filter(|c| *c == '"' || *c == '\'');
        let quote = quote.ok_or_else(|| format!("attribute {key} of <{name}> is not quoted"))?;
        let close = after[1..].find(quote).ok_or_else(|| format!("attribute {key} of <{name}> is not closed"))?;
        attrs.push((key, unescape(&after[1..1 + close])));
        rest = after[close + 2..].trim_start();
    }
    Ok((name, attrs, self_closing, end + 1))
}

/// The offset of the next opening tag `<name` (followed by whitespace, `/` or `>`) at or after
/// `from`.
pub(super) fn find_tag(data: &[u8], from: usize, name: &str) -> Option<usize> {
    let open = format!("<{name}");
    let mut at = from;
    loop {
        let lt = find(data, at, open.as_bytes())?;
        match data.get(lt + open.len()) {
            Some(b) if b.is_ascii_whitespace() || *b == b'/' || *b == b'>' => return Some(lt),
            _ => at = lt + 1,
        }
    }
}

/// The attributes of the opening tag that starts at `lt`, and the offset after its `>`.
pub(super) fn tag_attributes(data: &[u8], lt: usize) -> Result<(Vec<(String, String)>, usize), String> {
    parse_tag(data, lt).map(|(_, attrs, _, end)| (attrs, end)).map_err(|m| format!("line {}: {m}", line_at(data, lt)))
}

/// An opening tag's name and attributes.
struct OpenTag<'t> {
    name: &'t str,
    attrs: &'t [(String, String)],
}

impl OpenTag<'_> {
    /// The value of attribute `key`, if any.
    fn attr(&self, key: &str) -> Option<&str> {
        self.attrs.iter().find(|(k, _)| k == key).map(|(_, v)| v.as_str())
    }

    /// Attribute `key` as a count.
    fn count(&self, key: &str) -> Result<usize, String> {
        let v = self.attr(key).ok_or_else(|| format!("<{}> has no {key}", self.name))?;
        v.trim().parse().map_err(|_| format!("{key}=\"{v}\" is not a count"))
    }

    /// The declaration of a `<DataArray>` in `parent`, whose tag starts at `lt` and ends at `end`.
    fn array(
        &self,
        data: &[u8],
        parent: String,
        self_closing: bool,
        lt: usize,
        end: usize,
    ) -> Result<ArrayDecl, String> {
        let content = if self_closing {
            end..end
        } else {
            let close = find(data, end, b"<").ok_or("<DataArray> is not closed (truncated file?)")?;
            end..close
        };
        Ok(ArrayDecl {
            parent,
            name: self.attr("Name").unwrap_or("").to_string(),
            ty: self.attr("type").unwrap_or("").to_string(),
            components: match self.attr("NumberOfComponents") {
                Some(_) => self.count("NumberOfComponents")?,
                None => 1,
            },
            format: self.attr("format").unwrap_or("ascii").to_string(),
            offset: match self.attr("offset") {
                Some(_) => Some(self.count("offset")?),
                None => None,
            },
            content,
            at: lt,
        })
    }

    /// The encoding (raw or not: base64) and the byte range of the `<AppendedData>` whose tag ends
    /// at `end`.
    fn appended(&self, data: &[u8], end: usize) -> Result<(bool, Range<usize>), String> {
        let raw = match self.attr("encoding") {
            Some("raw") => true,
            Some("base64") => false,
            other => return Err(format!("AppendedData encoding {other:?} is not raw or base64")),
        };
        let start = find(data, end, b"_").ok_or("AppendedData has no '_' marker (truncated file?)")?;
        let stop = data
            .windows(b"</AppendedData>".len())
            .rposition(|w| w == b"</AppendedData>")
            .filter(|&p| p > start)
            .ok_or("AppendedData is not closed (truncated file?)")?;
        Ok((raw, start + 1..stop))
    }
}

impl XmlFile<'_> {
    /// Takes the dataset type, the byte order, the header type and the compressor from the
    /// `<VTKFile>` tag.
    fn set_format(&mut self, tag: &OpenTag) -> Result<(), String> {
        self.poly = match tag.attr("type") {
            Some("UnstructuredGrid") => false,
            Some("PolyData") => true,
            other => return Err(format!("type {:?} is not UnstructuredGrid or PolyData", other.unwrap_or(""))),
        };
        self.big_endian = tag.attr("byte_order") == Some("BigEndian");
        self.header64 = match tag.attr("header_type") {
            None | Some("UInt32") => false,
            Some("UInt64") => true,
            Some(other) => return Err(format!("unsupported header_type {other}")),
        };
        self.zlib = match tag.attr("compressor") {
            None | Some("") => false,
            Some("vtkZLibDataCompressor") => true,
            Some(other) => return Err(format!("compressor {other} is not supported (zlib or none are)")),
        };
        Ok(())
    }
}

/// Finds the elements of a VTK XML file that matter.
fn scan<'a>(path: &'a Path, data: &'a [u8]) -> Result<XmlFile<'a>, MeshError> {
    let at_error = |at: usize, m: String| MeshError::parse(path, format!("line {}: {m}", line_at(data, at)));
    let mut file = XmlFile {
        path,
        data,
        header64: false,
        big_endian: false,
        poly: false,
        zlib: false,
        points: 0,
        cell_counts: Vec::new(),
        arrays: Vec::new(),
        appended: None,
    };
    let mut stack: Vec<(String, usize)> = Vec::new();
    let mut seen_file = false;
    let mut pieces = 0;
    let mut pos = 0;
    while let Some(lt) = find(data, pos, b"<") {
        let rest = &data[lt..];
        let skip_to = |end: &[u8]| find(data, lt, end).map(|p| p + end.len());
        if rest.starts_with(b"<?") || rest.starts_with(b"<!--") || rest.starts_with(b"<!") {
            let end: &[u8] = if rest.starts_with(b"<?") {
                b"?>"
            } else if rest.starts_with(b"<!--") {
                b"-->"
            } else {
                b">"
            };
            pos = skip_to(end).ok_or_else(|| at_error(lt, "unclosed declaration or comment".into()))?;
            continue;
        }
        if rest.starts_with(b"</") {
            let end = find(data, lt, b">").ok_or_else(|| at_error(lt, "unclosed end tag (truncated file?)".into()))?;
            let name = String::from_utf8_lossy(&data[lt + 2..end]).trim().to_string();
            match stack.pop() {
                Some((open, _)) if open == name => {}
                Some((open, at)) => {
                    return Err(at_error(lt, format!("</{name}> closes <{open}> of line {}", line_at(data, at))))
                }
                None => return Err(at_error(lt, format!("</{name}> closes nothing"))),
            }
            pos = end + 1;
            continue;
        }
        let (name, attrs, self_closing, end) = parse_tag(data, lt).map_err(|m| at_error(lt, m))?;
        let tag = OpenTag { name: &name, attrs: &attrs };
        match name.as_str() {
            "VTKFile" => {
                seen_file = true;
                file.set_format(&tag).map_err(|m| at_error(lt, m))?;
            }
            "Piece" => {
                pieces += 1;
                if pieces > 1 {
                    return Err(at_error(lt, "a second <Piece>: only single-piece files are supported".into()));
                }
                file.points = tag.count("NumberOfPoints").map_err(|m| at_error(lt, m))?;
                file.cell_counts = match file.poly {
                    true => POLY_SECTIONS
                        .iter()
                        .map(|(_, key, _)| if tag.attr(key).is_some() { tag.count(key) } else { Ok(0) })
                        .collect::<Result<_, _>>(),
                    false => tag.count("NumberOfCells").map(|n| vec![n]),
                }
                .map_err(|m| at_error(lt, m))?;
                if file.cell_counts.iter().try_fold(0usize, |sum, &n| sum.checked_add(n)).is_none() {
                    return Err(at_error(lt, "its cell counts add up past any file's size".into()));
                }
            }
            "DataArray" | "Array" => {
                let parent = stack.last().map(|(n, _)| n.clone()).unwrap_or_default();
                file.arrays.push(tag.array(data, parent, self_closing, lt, end).map_err(|m| at_error(lt, m))?);
            }
            "AppendedData" => {
                file.appended = Some(tag.appended(data, end).map_err(|m| at_error(lt, m))?);
                stack.clear();
                break;
            }
            _ => {}
        }
        if !self_closing {
            stack.push((name, lt));
        }
        pos = end;
    }
    if !seen_file {
        return Err(MeshError::parse(path, "not a VTK XML file (no <VTKFile> element)"));
    }
    if let Some((open, at)) = stack.last() {
        return Err(MeshError::parse(
            path,
            format!("file ends inside <{open}> of line {} (truncated file?)", line_at(data, *at)),
        ));
    }
    if pieces == 0 {
        return Err(MeshError::parse(path, "no <Piece> element"));
    }
    Ok(file)
}

impl XmlFile<'_> {
    /// An unsigned integer of the header type at the start of `b`.
    fn header_uint(&self, b: &[u8]) -> Option<usize> {
        let n = if self.header64 { 8 } else { 4 };
        let b = b.get(..n)?;
        let mut w = [0u8; 8];
        if self.big_endian {
            w[8 - n..].copy_from_slice(b);
            Some(u64::from_be_bytes(w) as usize)
        } else {
            w[..n].copy_from_slice(b);
            Some(u64::from_le_bytes(w) as usize)
        }
    }

    /// Decompresses the zlib blocks described by `header` (a VTK compression header).
    fn inflate(&self, header: &[u8], blocks: &[u8]) -> Result<Vec<u8>, String> {
        let h: usize = if self.header64 { 8 } else { 4 };
        let field = |k: usize| self.header_uint(header.get(k * h..).unwrap_or(&[])).ok_or(CUT_HEADER);
        let (count, size, last) = (field(0)?, field(1)?, field(2)?);
        let mut out = Vec::new();
        let mut at = 0usize;
        for b in 0..count {
            let compressed = field(3 + b)?;
            let end = at.checked_add(compressed).filter(|&e| e <= blocks.len()).ok_or(CUT_DATA)?;
            let expected = if b + 1 == count && last != 0 { last } else { size };
            let before = out.len();
            flate2::read::ZlibDecoder::new(&blocks[at..end])
                .take((expected as u64).saturating_add(1))
                .read_to_end(&mut out)
                .map_err(|e| format!("zlib block {b} cannot be inflated: {e}"))?;
            if out.len() - before != expected {
                return Err(format!("zlib block {b} inflates to {} bytes, not {expected}", out.len() - before));
            }
            at = end;
        }
        Ok(out)
    }

    /// Size in bytes of a zlib compression header of `count` blocks.
    fn zlib_header_len(&self, count: usize) -> Result<usize, String> {
        let h: usize = if self.header64 { 8 } else { 4 };
        count.checked_add(3).and_then(|c| c.checked_mul(h)).ok_or_else(|| CUT_HEADER.to_string())
    }

    /// Total compressed size announced by a zlib compression header.
    fn zlib_data_len(&self, header: &[u8]) -> Result<usize, String> {
        let h: usize = if self.header64 { 8 } else { 4 };
        let count = self.header_uint(header).ok_or(CUT_HEADER)?;
        (0..count).try_fold(0usize, |total, b| {
            let size = self.header_uint(header.get((3 + b) * h..).unwrap_or(&[])).ok_or(CUT_HEADER)?;
            total.checked_add(size).ok_or_else(|| CUT_DATA.to_string())
        })
    }

    /// The bytes of a binary block (header then data) stored raw.
    fn raw_block(&self, bytes: &[u8]) -> Result<Vec<u8>, String> {
        let h: usize = if self.header64 { 8 } else { 4 };
        let first = self.header_uint(bytes).ok_or(CUT_HEADER)?;
        if self.zlib {
            let header = bytes.get(..self.zlib_header_len(first)?).ok_or(CUT_HEADER)?;
            return self.inflate(header, &bytes[header.len()..]);
        }
        let data = h.checked_add(first).and_then(|end| bytes.get(h..end));
        Ok(data.ok_or(format!("the header announces {first} bytes, more than the file holds (truncated?)"))?.to_vec())
    }

    /// The bytes of a binary block stored in base64: header and data encoded together or as
    /// two streams (both are written by common tools). With `exact`, `text` must hold exactly
    /// this block.
    fn base64_block(&self, text: &[u8], exact: bool) -> Result<Vec<u8>, String> {
        let h: usize = if self.header64 { 8 } else { 4 };
        let decode = |t: &[u8]| BASE64.decode(t).map_err(|e| format!("invalid base64: {e}"));
        let piece = |from: usize, to: usize| text.get(from..to).ok_or(CUT_DATA);
        let hl = b64_len(h);
        let first = self.header_uint(&decode(piece(0, hl)?)?).ok_or(CUT_HEADER)?;
        let (bytes, needed) = if self.zlib {
            let header_chars = b64_len(self.zlib_header_len(first)?);
            let header = decode(piece(0, header_chars)?)?;
            let needed = header_chars.saturating_add(b64_len(self.zlib_data_len(&header)?));
            (self.inflate(&header, &decode(piece(header_chars, needed)?)?)?, needed)
        } else if text[hl - 1] == b'=' {
            let needed = hl.saturating_add(b64_len(first));
            (decode(piece(hl, needed)?)?, needed)
        } else {
            let needed = b64_len(h.saturating_add(first));
            (decode(piece(0, needed)?)?.get(h..).unwrap_or(&[]).to_vec(), needed)
        };
        if !self.zlib && bytes.len() != first {
            return Err(format!("the header announces {first} bytes, but the data holds {}", bytes.len()));
        }
        if exact && text.len() != needed {
            return Err(format!("{} base64 characters, but the header announces {needed}", text.len()));
        }
        Ok(bytes)
    }

    /// The values of an array as `f64`.
    fn values(&self, a: &ArrayDecl) -> Result<Vec<f64>, MeshError> {
        let fail = |m: String| self.array_error(a, m);
        let ty = scalar(&a.ty).ok_or_else(|| fail(format!("unsupported type '{}'", a.ty)))?;
        let size = ty.size();
        if a.format == "ascii" {
            let text = String::from_utf8_lossy(&self.data[a.content.clone()]);
            return text
                .split_whitespace()
                .map(|t| t.parse::<f64>().map_err(|_| fail(format!("'{t}' is not a number"))))
                .collect();
        }
        let bytes = match (a.format.as_str(), &self.appended, a.offset) {
            ("binary", _, _) => {
                let text: Vec<u8> =
                    self.data[a.content.clone()].iter().copied().filter(|b| !b.is_ascii_whitespace()).collect();
                self.base64_block(&text, true)
            }
            ("appended", Some((raw, range)), Some(offset)) => {
                let region = &self.data[range.clone()];
                let start = offset.min(region.len());
                if *raw {
                    self.raw_block(&region[start..])
                } else {
                    let text: Vec<u8> =
                        region[start..].iter().copied().take_while(|b| !b.is_ascii_whitespace()).collect();
                    self.base64_block(&text, false)
                }
            }
            ("appended", None, _) => Err("format is appended, but the file has no <AppendedData>".into()),
            ("appended", _, None) => Err("format is appended, but there is no offset".into()),
            (other, _, _) => Err(format!("unknown format '{other}'")),
        }
        .map_err(fail)?;
        if bytes.len() % size != 0 {
            return Err(fail(format!("{} bytes is not a whole number of {} values", bytes.len(), a.ty)));
        }
        Ok(bytes.chunks_exact(size).map(|c| ty.decode(c, self.big_endian)).collect())
    }

    /// An error about array `a`, with its line.
    fn array_error(&self, a: &ArrayDecl, message: String) -> MeshError {
        let line = line_at(self.data, a.at);
        match a.name.as_str() {
            "" => MeshError::parse(self.path, format!("line {line}: <{}> DataArray: {message}", a.parent)),
            name => MeshError::parse(self.path, format!("line {line}: DataArray '{name}': {message}")),
        }
    }

    /// The values of an array, checked to hold `count` tuples.
    fn sized(&self, a: &ArrayDecl, count: usize) -> Result<Vec<f64>, MeshError> {
        let values = self.values(a)?;
        if Some(values.len()) != count.checked_mul(a.components) {
            let m = format!("{} values, but {count} × {} components are declared", values.len(), a.components);
            return Err(self.array_error(a, m));
        }
        Ok(values)
    }

    /// The array named `name` in `<section>`, as indices.
    fn cell_array(&self, section: &str, name: &str, count: Option<usize>) -> Result<Vec<usize>, MeshError> {
        let a = self
            .arrays
            .iter()
            .find(|a| a.parent == section && a.name == name)
            .ok_or_else(|| MeshError::parse(self.path, format!("<{section}> has no '{name}' array")))?;
        let values = match count {
            Some(n) => self.sized(a, n)?,
            None => self.values(a)?,
        };
        values.iter().map(|&x| to_index(x).ok_or_else(|| self.array_error(a, format!("{x} is not an index")))).collect()
    }

    /// The `count` cells of `<section>` (its connectivity cut at its offsets), appended to
    /// `cells`.
    fn read_cells(&self, section: &str, count: usize, cells: &mut Vec<Vec<usize>>) -> Result<(), MeshError> {
        if count == 0 {
            return Ok(());
        }
        let connectivity = self.cell_array(section, "connectivity", None)?;
        let mut start = 0;
        for (c, end) in self.cell_array(section, "offsets", Some(count))?.into_iter().enumerate() {
            if end < start || end > connectivity.len() {
                let m = format!(
                    "<{section}> cell {c}: offset {end} is out of order or past the {} connectivity entries",
                    connectivity.len()
                );
                return Err(MeshError::parse(self.path, m));
            }
            cells.push(connectivity[start..end].to_vec());
            start = end;
        }
        Ok(())
    }

    /// The text of the field data's string array `name` (up to its first NUL), if there is one.
    fn field_text(&self, name: &str) -> Result<Option<String>, MeshError> {
        let Some(a) = self.arrays.iter().find(|a| a.parent == "FieldData" && a.name == name) else {
            return Ok(None);
        };
        if a.ty != "String" {
            return Err(self.array_error(a, format!("type {} is not String", a.ty)));
        }
        let bytes: Vec<u8> = self.values(a)?.into_iter().take_while(|&c| c != 0.0).map(|c| c as u8).collect();
        Ok(Some(String::from_utf8_lossy(&bytes).into_owned()))
    }

    /// The `<Points>`, each finite and within [`MAX_COORDINATE`](crate::MAX_COORDINATE).
    fn points(&self) -> Result<Vec<Point>, MeshError> {
        let points_array = self
            .arrays
            .iter()
            .find(|a| a.parent == "Points")
            .ok_or_else(|| MeshError::parse(self.path, "no <Points> DataArray"))?;
        if points_array.components != 3 {
            return Err(MeshError::parse(self.path, "<Points> must have 3 components"));
        }
        let xyz = self.sized(points_array, self.points)?;
        let points: Vec<Point> = xyz.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
        match crate::coordinate_fault(points.iter().enumerate(), crate::MAX_COORDINATE) {
            Some((i, fault)) => Err(self.array_error(points_array, format!("point {i} {fault}"))),
            None => Ok(points),
        }
    }

    /// The cells and their VTK types: an unstructured grid's, or poly data's.
    fn cells(&self) -> Result<(Vec<Vec<usize>>, Vec<u32>), MeshError> {
        let num_cells = self.cell_counts.iter().sum();
        // Not reserved from the declared counts: a count the arrays do not hold is an error below.
        let mut cells = Vec::new();
        let types: Vec<u32> = if self.poly {
            let mut types = Vec::new();
            for ((section, _, ty), &count) in POLY_SECTIONS.iter().zip(&self.cell_counts) {
                self.read_cells(section, count, &mut cells)?;
                types.resize(cells.len(), u32::from(*ty));
            }
            types
        } else {
            self.read_cells("Cells", num_cells, &mut cells)?;
            let types = self.cell_array("Cells", "types", Some(num_cells))?;
            types.iter().map(|&t| t.min(u32::MAX as usize) as u32).collect()
        };
        Ok((cells, types))
    }

    /// The point and cell data arrays.
    fn fields(&self) -> Result<Vec<Field>, MeshError> {
        let num_cells = self.cell_counts.iter().sum();
        let mut fields = Vec::new();
        for (parent, location, count) in
            [("PointData", FieldLocation::Point, self.points), ("CellData", FieldLocation::Cell, num_cells)]
        {
            for a in self.arrays.iter().filter(|a| a.parent == parent) {
                let values = self.sized(a, count)?;
                fields.push(Field { name: a.name.clone(), location, components: a.components, values });
            }
        }
        Ok(fields)
    }

    /// The triangles, quads, polygons and triangle strips as a surface.
    fn surface(&self) -> Result<TriSurface, MeshError> {
        let (cells, types) = self.cells()?;
        surface_from_cells(self.path, self.points()?, types.iter().zip(&cells).map(|(&t, c)| (t, c.as_slice())))
    }

    /// The frame the field data's string array `SPACE` names, as 3D Slicer writes it (`RAS` or
    /// `LPS`); `None` without one.
    fn frame(&self) -> Result<Option<Frame>, MeshError> {
        let Some(space) = self.field_text("SPACE")? else {
            return Ok(None);
        };
        frame_in_header(&format!("SPACE={}", space.trim()))
            .map_err(|m| MeshError::parse(self.path, format!("field data: {m}")))
    }
}

/// Reads and scans a `.vtu` or `.vtp` file, then takes from it what `take` reads.
fn with_file<T>(path: &Path, take: impl FnOnce(&XmlFile) -> Result<T, MeshError>) -> Result<T, MeshError> {
    let data = super::read_bytes(path)?;
    take(&scan(path, &data)?)
}

/// Reads a `.vtu` unstructured grid as a volume mesh of tetrahedra or hexahedra.
pub fn read_vtu(path: impl AsRef<Path>) -> Result<Mesh, MeshError> {
    Ok(read_vtu_with_fields(path)?.0)
}

/// Like [`read_vtu`], also returning the point and cell data arrays restricted to the kept
/// nodes and cells.
pub fn read_vtu_with_fields(path: impl AsRef<Path>) -> Result<(Mesh, Vec<Field>), MeshError> {
    let path = path.as_ref();
    with_file(path, |file| {
        if file.poly {
            return Err(MeshError::NotVolume { path: path.display().to_string(), dataset: "PolyData".into() });
        }
        let (cells, types) = file.cells()?;
        volume_from_cells(path, &file.points()?, &cells, &types, file.fields()?)
    })
}

/// The `<Points>` of a `.vtu` or `.vtp` file, whatever its cells (a point cloud).
pub(super) fn read_xml_points(path: &Path) -> Result<Vec<Point>, MeshError> {
    with_file(path, |file| file.points())
}

/// Reads the triangles, quads, polygons and triangle strips of a `.vtu` or `.vtp` file as a
/// surface.
pub(super) fn read_xml_surface(path: &Path) -> Result<TriSurface, MeshError> {
    with_file(path, |file| file.surface())
}

/// [`read_xml_surface`] and the frame the file's field data names ([`XmlFile::frame`]), from one
/// read of the file.
pub(super) fn read_xml_surface_with_frame(path: &Path) -> Result<(TriSurface, Option<Frame>), MeshError> {
    with_file(path, |file| Ok((file.surface()?, file.frame()?)))
}

/// The frame a `.vtu` or `.vtp` file names in its field data ([`XmlFile::frame`]).
pub(super) fn xml_frame(path: &Path) -> Result<Option<Frame>, MeshError> {
    with_file(path, |file| file.frame())
}
