//! Legacy VTK `.vtk`: ASCII and big-endian binary `UNSTRUCTURED_GRID` and `POLYDATA`.

use std::io::Write;
use std::path::Path;

use super::scalar::Scalar;
use super::{
    check_for_writing, check_surface, fan, finish_volume, fractions_from_fields, mesh_cells_flat, read_bytes,
    regions_from_fields, restrict_fields, strip, write_atomic, Encoding, Field, FieldLocation, Num, VolumeKind,
    VTK_HEXAHEDRON, VTK_POLYGON, VTK_QUADRATIC_TETRA, VTK_TETRA, VTK_TRIANGLE_STRIP, VTK_VOXEL,
};
use crate::{Mesh, MeshError, Point, TriSurface};

/// Section keywords of the legacy format (used to diagnose a misplaced or corrupt data block).
const KEYWORDS: [&str; 21] = [
    "DATASET",
    "POINTS",
    "CELLS",
    "CELL_TYPES",
    "VERTICES",
    "LINES",
    "POLYGONS",
    "TRIANGLE_STRIPS",
    "POINT_DATA",
    "CELL_DATA",
    "SCALARS",
    "COLOR_SCALARS",
    "LOOKUP_TABLE",
    "VECTORS",
    "NORMALS",
    "TENSORS",
    "TENSORS6",
    "TEXTURE_COORDINATES",
    "FIELD",
    "METADATA",
    "OFFSETS",
];

/// The scalar type of a legacy-format type name.
fn vtk_scalar(name: &str) -> Option<Scalar> {
    Some(match name.to_ascii_lowercase().as_str() {
        "unsigned_char" | "vtktypeuint8" => Scalar::U8,
        "char" | "vtktypeint8" => Scalar::I8,
        "unsigned_short" | "vtktypeuint16" => Scalar::U16,
        "short" | "vtktypeint16" => Scalar::I16,
        "unsigned_int" | "vtktypeuint32" => Scalar::U32,
        "int" | "vtktypeint32" => Scalar::I32,
        "unsigned_long" | "vtktypeuint64" => Scalar::U64,
        // vtkIdType: 64-bit in every VTK built with 64-bit ids (the default since VTK 6), as VTK 9
        // writes the OFFSETS and CONNECTIVITY of some polydata.
        "long" | "vtktypeint64" | "vtkidtype" => Scalar::I64,
        "float" | "vtktypefloat32" => Scalar::F32,
        "double" | "vtktypefloat64" => Scalar::F64,
        _ => return None,
    })
}

/// The last data block read, to explain a corrupt file.
struct Block {
    what: String,
    line: usize,
    start: usize,
    bytes: usize,
}

/// Cells as offsets into a connectivity array.
#[derive(Default)]
struct CellList {
    offsets: Vec<usize>,
    conn: Vec<usize>,
}

impl CellList {
    fn len(&self) -> usize {
        self.offsets.len().saturating_sub(1)
    }

    fn cell(&self, i: usize) -> &[usize] {
        &self.conn[self.offsets[i]..self.offsets[i + 1]]
    }
}

/// Everything read from a legacy file.
struct Parsed {
    dataset: String,
    points: Option<Vec<Point>>,
    /// `CELLS` of an unstructured grid, or the polydata sections by keyword.
    cells: Vec<(String, CellList)>,
    types: Option<Vec<u32>>,
    fields: Vec<Field>,
    /// The string array `SPACE` of the dataset's field data (`LPS` or `RAS`, as VTK writes 3D
    /// Slicer's frame tag), if any.
    space: Option<String>,
}

/// A cursor over the bytes of a legacy file that counts lines (also inside binary blocks, so
/// that line numbers match what a text editor shows).
struct Reader<'a> {
    path: &'a Path,
    data: &'a [u8],
    pos: usize,
    line: usize,
    binary: bool,
    last: Option<Block>,
}

/// A byte string shown safely in a message: printable ASCII as is, other bytes as `\xNN`.
fn show(bytes: &[u8]) -> String {
    let mut s = String::new();
    for &b in bytes.iter().take(24) {
        if b.is_ascii_graphic() {
            s.push(b as char);
        } else {
            s.push_str(&format!("\\x{b:02x}"));
        }
    }
    if bytes.len() > 24 {
        s.push_str("...");
    }
    s
}

/// A non-negative integer stored in a float, as an index (`None` for a fraction, NaN or a value
/// beyond any count).
pub(super) fn to_index(x: f64) -> Option<usize> {
    (x >= 0.0 && x.fract() == 0.0 && x < 9.0e15).then_some(x as usize)
}

impl<'a> Reader<'a> {
    fn error(&self, message: impl std::fmt::Display) -> MeshError {
        MeshError::parse(self.path, format!("line {}: {message}", self.line))
    }

    fn skip_ws(&mut self) {
        while let Some(&b) = self.data.get(self.pos) {
            if !b.is_ascii_whitespace() {
                break;
            }
            if b == b'\n' {
                self.line += 1;
            }
            self.pos += 1;
        }
    }

    /// The next whitespace-delimited token, or `None` at the end of the file.
    fn token(&mut self) -> Option<&'a [u8]> {
        self.skip_ws();
        let start = self.pos;
        while self.pos < self.data.len() && !self.data[self.pos].is_ascii_whitespace() {
            self.pos += 1;
        }
        (self.pos > start).then(|| &self.data[start..self.pos])
    }

    /// The next token without consuming it, upper-cased.
    fn peek_keyword(&mut self) -> Option<String> {
        let (pos, line) = (self.pos, self.line);
        let token = self.token().map(|t| String::from_utf8_lossy(t).to_ascii_uppercase());
        (self.pos, self.line) = (pos, line);
        token
    }

    /// The rest of the current line (without its newline), consumed with the newline.
    fn read_line(&mut self) -> &'a [u8] {
        let start = self.pos;
        while self.pos < self.data.len() && self.data[self.pos] != b'\n' {
            self.pos += 1;
        }
        let line = &self.data[start..self.pos];
        if self.pos < self.data.len() {
            self.pos += 1;
            self.line += 1;
        }
        line
    }

    /// The arguments of a section header: the rest of its line, split at whitespace. The line
    /// number is the header's.
    fn header_args(&mut self) -> Vec<String> {
        let line = self.read_line();
        String::from_utf8_lossy(line).split_whitespace().map(str::to_string).collect()
    }

    /// `n` strings of a `string` array declared at line `header`: one a line, `%XX` escaped
    /// (ASCII), or each after its length in a 1, 2, 4 or 8-byte big-endian header whose top two
    /// bits say its size (binary), as VTK writes them.
    fn strings(&mut self, n: usize, what: &str, header: usize) -> Result<Vec<String>, MeshError> {
        let mut strings = Vec::with_capacity(n.min(1024));
        for k in 0..n {
            let text = if self.binary {
                let start = self.pos;
                let first = self.data.get(start).copied().unwrap_or(0);
                let size = [8, 4, 2, 1][usize::from(first >> 6)];
                let head = self.data.get(start..start + size);
                let length = head
                    .map(|h| h.iter().fold(0_u64, |a, &b| a << 8 | u64::from(b)) & (u64::MAX >> (64 - 8 * size + 2)));
                let body = length.and_then(|l| self.data.get(start + size..(start + size).checked_add(l as usize)?));
                let Some(body) = body.filter(|_| start < self.data.len()) else {
                    return Err(self.error(format!(
                        "file ends after {k} of the {n} strings of {what} (line {header}) (truncated file?)"
                    )));
                };
                self.line += body.iter().filter(|&&b| b == b'\n').count();
                self.pos = start + size + body.len();
                String::from_utf8_lossy(body).into_owned()
            } else {
                if self.pos >= self.data.len() {
                    return Err(self.error(format!(
                        "file ends after {k} of the {n} strings of {what} (line {header}) (truncated file?)"
                    )));
                }
                percent_decoded(self.read_line())
            };
            strings.push(text);
        }
        Ok(strings)
    }

    /// `n` values of type `scalar` (binary) or `n` numbers (ASCII), declared by the section
    /// `what` at line `header`.
    fn values(&mut self, n: usize, scalar: Scalar, what: &str, header: usize) -> Result<Vec<f64>, MeshError> {
        let start = self.pos;
        let values = if self.binary {
            let bytes = n.checked_mul(scalar.size()).filter(|&b| b <= self.data.len() - self.pos).ok_or_else(|| {
                self.error(format!(
                    "{what} (line {header}) needs {n} × {} bytes of binary data, but only {} bytes remain \
                     (truncated file?)",
                    scalar.size(),
                    self.data.len() - self.pos
                ))
            })?;
            let block = &self.data[self.pos..self.pos + bytes];
            self.line += block.iter().filter(|&&b| b == b'\n').count();
            self.pos += bytes;
            block.chunks_exact(scalar.size()).map(|b| scalar.decode(b, true)).collect()
        } else {
            let mut values = Vec::with_capacity(n.min(self.data.len()));
            for k in 0..n {
                let token = self.token().ok_or_else(|| {
                    self.error(format!(
                        "file ends after {k} of the {n} values of {what} (line {header}) (truncated file?)"
                    ))
                })?;
                let x = std::str::from_utf8(token).ok().and_then(|s| s.parse::<f64>().ok()).ok_or_else(|| {
                    self.error(format!(
                        "value {} of the {n} of {what} (line {header}) is '{}', not a number",
                        k + 1,
                        show(token)
                    ))
                })?;
                values.push(x);
            }
            values
        };
        self.last = Some(Block { what: what.to_string(), line: header, start, bytes: self.pos - start });
        Ok(values)
    }

    /// `n` indices (non-negative integers).
    fn indices(&mut self, n: usize, scalar: Scalar, what: &str, header: usize) -> Result<Vec<usize>, MeshError> {
        let values = self.values(n, scalar, what, header)?;
        values
            .iter()
            .map(|&x| {
                to_index(x).ok_or_else(|| {
                    MeshError::parse(self.path, format!("{what} (line {header}) holds {x}, which is not a valid index"))
                })
            })
            .collect()
    }

    /// `a × b` values, or an error when the declared sizes overflow.
    fn product(&self, a: usize, b: usize, header: usize) -> Result<usize, MeshError> {
        a.checked_mul(b).ok_or_else(|| {
            MeshError::parse(self.path, format!("line {header}: the declared sizes {a} × {b} are too large"))
        })
    }

    /// An error for a token where a section keyword was expected, explaining how the previous
    /// data block went wrong when that can be seen.
    fn unexpected(&self, token: &[u8]) -> MeshError {
        let mut message = format!("line {}: expected a section keyword, found '{}'", self.line, show(token));
        let Some(block) = &self.last else {
            return MeshError::parse(self.path, message);
        };
        message.push_str(&format!(" after the data of {} (line {})", block.what, block.line));
        if !self.binary {
            if std::str::from_utf8(token).is_ok_and(|s| s.parse::<f64>().is_ok()) {
                message.push_str(": the file holds more values than the header declares");
            }
            return MeshError::parse(self.path, message);
        }
        let next = KEYWORDS.iter().filter_map(|k| {
            let pattern = format!("\n{k} ");
            self.data[block.start..]
                .windows(pattern.len())
                .position(|w| w == pattern.as_bytes())
                .map(|p| (block.start + p + 1, *k))
        });
        if let Some((offset, keyword)) = next.min() {
            let line = self.data[..offset].iter().filter(|&&b| b == b'\n').count() + 1;
            message.push_str(&format!(
                ": the data runs for {} bytes up to the next section ({keyword} at line {line}), \
                 but the header declares {} bytes",
                offset - 1 - block.start,
                block.bytes
            ));
            let escapes = self.data[block.start..offset]
                .windows(3)
                .filter(|w| w[0] == b'\\' && w[1..].iter().all(|c| c.is_ascii_hexdigit()))
                .count();
            if escapes >= 16 && escapes * 1000 > offset - block.start {
                message.push_str(&format!(
                    "; the binary data holds {escapes} text escapes such as '\\E3' (bytes rewritten as a \
                     backslash and hex digits): the file is corrupt"
                ));
            } else {
                message.push_str(": the count in the header does not match the data");
            }
        }
        MeshError::parse(self.path, message)
    }

    /// A cell list section: `KEY n size` then either `n` cells as `count i1 .. icount` (legacy)
    /// or `OFFSETS` and `CONNECTIVITY` arrays (format 5).
    fn cell_list(&mut self, keyword: &str, args: &[String], header: usize) -> Result<CellList, MeshError> {
        let [n, size] = self.counts::<2>(keyword, args, header)?;
        if self.peek_keyword().as_deref() == Some("OFFSETS") {
            let mut lists = Vec::new();
            for key in ["OFFSETS", "CONNECTIVITY"] {
                let token = self.token().unwrap_or_default();
                if !token.eq_ignore_ascii_case(key.as_bytes()) {
                    return Err(
                        self.error(format!("expected {key} in {keyword} (line {header}), found '{}'", show(token)))
                    );
                }
                let line = self.line;
                let args = self.header_args();
                let scalar = self.scalar(args.first(), key, line)?;
                let count = if key == "OFFSETS" { n } else { size };
                lists.push(self.indices(count, scalar, &format!("{keyword} {key}"), line)?);
            }
            let conn = lists.pop().unwrap_or_default();
            let offsets = lists.pop().unwrap_or_default();
            let ok = offsets.first().is_none_or(|&o| o == 0)
                && offsets.windows(2).all(|w| w[0] <= w[1])
                && offsets.last().is_none_or(|&o| o == conn.len());
            if !ok {
                return Err(MeshError::parse(
                    self.path,
                    format!("{keyword} (line {header}): OFFSETS must rise from 0 to the connectivity length"),
                ));
            }
            return Ok(CellList { offsets, conn });
        }
        let raw = self.indices(size, Scalar::I32, keyword, header)?;
        let mut list = CellList { offsets: vec![0], conn: Vec::with_capacity(size.saturating_sub(n)) };
        let mut i = 0;
        for c in 0..n {
            let count = raw.get(i).copied().unwrap_or(0);
            if i >= size || i + 1 + count > size {
                return Err(MeshError::parse(
                    self.path,
                    format!("{keyword} (line {header}): cell {c} runs past the declared size {size}"),
                ));
            }
            list.conn.extend_from_slice(&raw[i + 1..i + 1 + count]);
            list.offsets.push(list.conn.len());
            i += 1 + count;
        }
        if i != size {
            return Err(MeshError::parse(
                self.path,
                format!("{keyword} (line {header}): the {n} cells use {i} values, but the size is {size}"),
            ));
        }
        Ok(list)
    }

    /// `N` counts from a header's arguments.
    fn counts<const N: usize>(&self, keyword: &str, args: &[String], header: usize) -> Result<[usize; N], MeshError> {
        let mut out = [0; N];
        for (k, slot) in out.iter_mut().enumerate() {
            let arg = args.get(k).map(String::as_str).unwrap_or("");
            *slot = arg.parse().map_err(|_| {
                MeshError::parse(
                    self.path,
                    format!("line {header}: {keyword} needs {N} counts, found '{}'", args.join(" ")),
                )
            })?;
        }
        Ok(out)
    }

    /// A scalar type name from a header's arguments.
    fn scalar(&self, name: Option<&String>, keyword: &str, header: usize) -> Result<Scalar, MeshError> {
        let name = name.map(String::as_str).unwrap_or("");
        vtk_scalar(name).ok_or_else(|| {
            MeshError::parse(self.path, format!("line {header}: {keyword} has unsupported data type '{name}'"))
        })
    }
    /// The header: the magic line, the title, the format (ASCII or BINARY, taken by the reader)
    /// and the dataset type (UNSTRUCTURED_GRID or POLYDATA), which it returns.
    fn dataset(&mut self) -> Result<String, MeshError> {
        let magic = self.read_line();
        if !magic.to_ascii_lowercase().starts_with(b"# vtk datafile") {
            return Err(MeshError::parse(self.path, format!("line 1: not a legacy VTK file: '{}'", show(magic))));
        }
        if self.pos >= self.data.len() {
            return Err(MeshError::parse(self.path, "file ends after line 1 (truncated file?)"));
        }
        self.read_line();
        let mode = String::from_utf8_lossy(self.read_line()).trim().to_ascii_uppercase();
        self.binary = match mode.as_str() {
            "ASCII" => false,
            "BINARY" => true,
            _ => return Err(MeshError::parse(self.path, format!("line 3: expected ASCII or BINARY, found '{mode}'"))),
        };
        let line = self.line;
        let keyword = self.token().map(|t| String::from_utf8_lossy(t).to_ascii_uppercase());
        let args = self.header_args();
        let dataset = match (keyword.as_deref(), args.first()) {
            (Some("DATASET"), Some(d)) => d.to_ascii_uppercase(),
            _ => {
                let found = keyword.map_or("the end of the file".to_string(), |k| format!("'{k}'"));
                return Err(MeshError::parse(self.path, format!("line {line}: expected DATASET, found {found}")));
            }
        };
        if dataset != "UNSTRUCTURED_GRID" && dataset != "POLYDATA" {
            return Err(MeshError::parse(
                self.path,
                format!("line {line}: DATASET {dataset} is not supported (UNSTRUCTURED_GRID or POLYDATA are)"),
            ));
        }
        Ok(dataset)
    }

    /// An attribute section (`SCALARS`, `VECTORS`, …) of the data section `location` (its
    /// location and tuple count), whose header (`keyword` and `args`) is on line `header`.
    fn attribute(
        &mut self,
        keyword: &str,
        args: &[String],
        header: usize,
        location: Option<(FieldLocation, usize)>,
    ) -> Result<Field, MeshError> {
        let (at, count) =
            location.ok_or_else(|| self.error(format!("{keyword} outside a POINT_DATA or CELL_DATA section")))?;
        let name = args.first().cloned().unwrap_or_default();
        let (components, scalar) = match keyword {
            "SCALARS" => {
                let components = match args.get(2) {
                    Some(_) => self.counts::<1>("SCALARS", &args[2..], header)?[0],
                    None => 1,
                };
                (components, self.scalar(args.get(1), "SCALARS", header)?)
            }
            "COLOR_SCALARS" => {
                let [c] = self.counts::<1>("COLOR_SCALARS", &args[1.min(args.len())..], header)?;
                (c, if self.binary { Scalar::U8 } else { Scalar::F64 })
            }
            "TEXTURE_COORDINATES" => {
                let [c] = self.counts::<1>("TEXTURE_COORDINATES", &args[1.min(args.len())..], header)?;
                (c, self.scalar(args.get(2), keyword, header)?)
            }
            "TENSORS" => (9, self.scalar(args.get(1), keyword, header)?),
            "TENSORS6" => (6, self.scalar(args.get(1), keyword, header)?),
            _ => (3, self.scalar(args.get(1), keyword, header)?),
        };
        if keyword == "SCALARS" && self.peek_keyword().as_deref() == Some("LOOKUP_TABLE") {
            self.token();
            self.header_args();
        }
        let what = format!("{keyword} {name}");
        let mut values = self.values(self.product(count, components, header)?, scalar, &what, header)?;
        if keyword == "COLOR_SCALARS" && self.binary {
            values.iter_mut().for_each(|v| *v /= 255.0);
        }
        Ok(Field { name, location: at, components, values })
    }
}

/// A line of a `string` array in an ASCII legacy file, its `%XX` escapes (VTK's for spaces and
/// other bytes outside printable ASCII) decoded.
fn percent_decoded(line: &[u8]) -> String {
    let line = line.strip_suffix(b"\r").unwrap_or(line);
    let mut bytes = Vec::with_capacity(line.len());
    let mut i = 0;
    while i < line.len() {
        let hex = line.get(i + 1..i + 3).and_then(|h| u8::from_str_radix(std::str::from_utf8(h).ok()?, 16).ok());
        match (line[i], hex) {
            (b'%', Some(byte)) => {
                bytes.push(byte);
                i += 3;
            }
            (b, _) => {
                bytes.push(b);
                i += 1;
            }
        }
    }
    String::from_utf8_lossy(&bytes).into_owned()
}

/// Parses a whole legacy VTK file; its points must be finite and within
/// [`MAX_COORDINATE`](crate::MAX_COORDINATE).
fn parse(path: &Path) -> Result<Parsed, MeshError> {
    let data = read_bytes(path)?;
    let mut r = Reader { path, data: &data, pos: 0, line: 1, binary: false, last: None };
    let dataset = r.dataset()?;
    let mut parsed = Parsed { dataset, points: None, cells: Vec::new(), types: None, fields: Vec::new(), space: None };
    let mut location: Option<(FieldLocation, usize)> = None;
    let mut points_line = 0;
    while let Some(token) = r.token() {
        let header = r.line;
        let keyword = String::from_utf8_lossy(token).to_ascii_uppercase();
        let args = r.header_args();
        let grid = parsed.dataset == "UNSTRUCTURED_GRID";
        match keyword.as_str() {
            "POINTS" => {
                let [n] = r.counts::<1>("POINTS", &args, header)?;
                let scalar = r.scalar(args.get(1), "POINTS", header)?;
                if parsed.points.is_some() {
                    return Err(r.error("a second POINTS section"));
                }
                let xyz = r.values(r.product(3, n, header)?, scalar, &format!("POINTS {n}"), header)?;
                parsed.points = Some(xyz.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect());
                points_line = header;
            }
            "CELLS" if grid => {
                let list = r.cell_list("CELLS", &args, header)?;
                parsed.cells.push((keyword, list));
            }
            "CELL_TYPES" if grid => {
                let [n] = r.counts::<1>("CELL_TYPES", &args, header)?;
                let types = r.indices(n, Scalar::I32, &format!("CELL_TYPES {n}"), header)?;
                parsed.types = Some(types.iter().map(|&t| t.min(u32::MAX as usize) as u32).collect());
            }
            "VERTICES" | "LINES" | "POLYGONS" | "TRIANGLE_STRIPS" if !grid => {
                let list = r.cell_list(&keyword, &args, header)?;
                parsed.cells.push((keyword, list));
            }
            "POINT_DATA" | "CELL_DATA" => {
                let [n] = r.counts::<1>(&keyword, &args, header)?;
                let at = if keyword == "POINT_DATA" { FieldLocation::Point } else { FieldLocation::Cell };
                location = Some((at, n));
            }
            "SCALARS" | "COLOR_SCALARS" | "VECTORS" | "NORMALS" | "TENSORS" | "TENSORS6" | "TEXTURE_COORDINATES" => {
                parsed.fields.push(r.attribute(&keyword, &args, header, location)?);
            }
            "LOOKUP_TABLE" => {
                let [size] = r.counts::<1>("LOOKUP_TABLE", &args[1.min(args.len())..], header)?;
                let scalar = if r.binary { Scalar::U8 } else { Scalar::F64 };
                r.values(r.product(4, size, header)?, scalar, "LOOKUP_TABLE", header)?;
            }
            "FIELD" => {
                let [arrays] = r.counts::<1>("FIELD", &args[1.min(args.len())..], header)?;
                for _ in 0..arrays {
                    let name = r.token().map(|t| String::from_utf8_lossy(t).into_owned());
                    let line = r.line;
                    let args = r.header_args();
                    let name = name.ok_or_else(|| r.error(format!("file ends in FIELD (line {header})")))?;
                    let [components, tuples] = r.counts::<2>(&format!("FIELD array {name}"), &args, line)?;
                    if args.get(2).is_some_and(|t| t.eq_ignore_ascii_case("string")) {
                        let strings =
                            r.strings(r.product(components, tuples, line)?, &format!("FIELD array {name}"), line)?;
                        if location.is_none() && name.eq_ignore_ascii_case("SPACE") {
                            parsed.space = strings.into_iter().next();
                        }
                        continue;
                    }
                    let scalar = r.scalar(args.get(2), &format!("FIELD array {name}"), line)?;
                    let values =
                        r.values(r.product(components, tuples, line)?, scalar, &format!("FIELD array {name}"), line)?;
                    if let Some((at, count)) = location {
                        if tuples != count {
                            return Err(MeshError::parse(
                                path,
                                format!("line {line}: FIELD array {name} has {tuples} tuples, but the data section holds {count}"),
                            ));
                        }
                        parsed.fields.push(Field { name, location: at, components, values });
                    }
                }
            }
            "METADATA" => while r.pos < data.len() && !String::from_utf8_lossy(r.read_line()).trim().is_empty() {},
            _ => {
                r.line = header;
                return Err(r.unexpected(token));
            }
        }
    }
    // Checked once the file is read, so that a corrupt binary block is told by the section it runs into.
    let points = parsed.points.as_deref().unwrap_or_default();
    if let Some((i, fault)) = crate::coordinate_fault(points.iter().enumerate(), crate::MAX_COORDINATE) {
        return Err(MeshError::parse(path, format!("POINTS {} (line {points_line}): point {i} {fault}", points.len())));
    }
    Ok(parsed)
}

/// VTK cell types: `Some(true)` for 3D, `Some(false)` for lower dimensions, with their names.
fn vtk_cell_type(ty: u32) -> Option<(bool, &'static str)> {
    Some(match ty {
        0 => (false, "empty cell"),
        1 => (false, "vertex"),
        2 => (false, "poly-vertex"),
        3 => (false, "line"),
        4 => (false, "poly-line"),
        5 => (false, "triangle"),
        6 => (false, "triangle strip"),
        7 => (false, "polygon"),
        8 => (false, "pixel"),
        9 => (false, "quad"),
        10 => (true, "tetrahedron"),
        11 => (true, "voxel"),
        12 => (true, "hexahedron"),
        13 => (true, "wedge"),
        14 => (true, "pyramid"),
        15 => (true, "pentagonal prism"),
        16 => (true, "hexagonal prism"),
        21 | 35 | 68 | 75 => (false, "higher-order line"),
        22 | 34 | 69 | 76 => (false, "higher-order triangle"),
        23 | 28 | 30 | 70 | 77 => (false, "higher-order quad"),
        36 => (false, "quadratic polygon"),
        24 | 71 | 78 => (true, "higher-order tetrahedron"),
        25 | 29 | 33 | 72 | 79 => (true, "higher-order hexahedron"),
        26 | 31 | 32 | 73 | 80 => (true, "higher-order wedge"),
        27 | 37 | 74 | 81 => (true, "higher-order pyramid"),
        41 => (true, "convex point set"),
        42 => (true, "polyhedron"),
        _ => return None,
    })
}

/// The volume mesh of a parsed unstructured grid, with its fields restricted to the kept nodes
/// and cells and its regions taken from them ([`regions_from_fields`]). Shared with the `.vtu`
/// reader.
pub(super) fn volume_from_cells(
    path: &Path,
    points: &[Point],
    cells: &[Vec<usize>],
    types: &[u32],
    fields: Vec<Field>,
) -> Result<(Mesh, Vec<Field>), MeshError> {
    if cells.len() != types.len() {
        return Err(MeshError::parse(path, format!("{} cells but {} cell types", cells.len(), types.len())));
    }
    let mut kind: Option<(VolumeKind, usize)> = None;
    let mut conn = Vec::new();
    let mut kept_cells = Vec::new();
    for (c, (cell, &ty)) in cells.iter().zip(types).enumerate() {
        let (solid, name) = vtk_cell_type(ty)
            .ok_or_else(|| MeshError::parse(path, format!("cell {c} has unknown VTK cell type {ty}")))?;
        if !solid {
            continue;
        }
        let (this, order): (VolumeKind, &[usize]) = match ty as u8 {
            VTK_TETRA => (VolumeKind::Tet, &[0, 1, 2, 3]),
            VTK_HEXAHEDRON => (VolumeKind::Hex, &[0, 1, 2, 3, 4, 5, 6, 7]),
            VTK_VOXEL => (VolumeKind::Hex, &[0, 1, 3, 2, 4, 5, 7, 6]),
            VTK_QUADRATIC_TETRA => (VolumeKind::Tet10, &[0, 1, 2, 3, 4, 5, 6, 7, 8, 9]),
            _ => {
                return Err(MeshError::parse(
                    path,
                    format!(
                    "cell {c} is a {name} (VTK type {ty}): only tetrahedra (10, 24) and hexahedra (11, 12) are supported"
                ),
                ))
            }
        };
        if cell.len() != order.len() {
            return Err(MeshError::parse(
                path,
                format!("cell {c} ({name}) has {} nodes, expected {}", cell.len(), order.len()),
            ));
        }
        if let Some(&bad) = cell.iter().find(|&&i| i >= points.len()) {
            return Err(MeshError::parse(
                path,
                format!("cell {c} refers to point {bad}, but there are {} points", points.len()),
            ));
        }
        match kind {
            None => kind = Some((this, c)),
            Some((k, first)) if k != this => {
                return Err(MeshError::parse(
                    path,
                    format!(
                        "cell {c}: the file mixes {} (first: cell {first}) and {}; a mesh holds one kind of cell",
                        k.plural(),
                        this.plural()
                    ),
                ))
            }
            Some(_) => {}
        }
        conn.extend(order.iter().map(|&j| cell[j]));
        kept_cells.push(c);
    }
    let Some((kind, _)) = kind else {
        return Err(MeshError::parse(path, "no tetrahedra or hexahedra: not a volume mesh"));
    };
    for f in &fields {
        let (count, what) = match f.location {
            FieldLocation::Point => (points.len(), "points"),
            FieldLocation::Cell => (cells.len(), "cells"),
        };
        if f.components == 0 || Some(f.values.len()) != count.checked_mul(f.components) {
            return Err(MeshError::parse(
                path,
                format!(
                    "array '{}' has {} values, which is not {} per one of {count} {what}",
                    f.name,
                    f.values.len(),
                    f.components
                ),
            ));
        }
    }
    let describe = |i: usize| format!("cell {}", kept_cells[i]);
    let (mut mesh, kept_nodes) = finish_volume(path, points, kind, conn, &describe, None, &kept_cells)?;
    let fields = restrict_fields(fields, &kept_nodes, &kept_cells);
    mesh.regions = regions_from_fields(&fields);
    mesh.cell_fraction = fractions_from_fields(&fields).map_err(|m| MeshError::parse(path, m))?;
    Ok((mesh, fields))
}

/// The triangles of surface cells (triangles, strips, polygons, quads, pixels given by VTK cell
/// type) over `points`; lower- and higher-dimensional cells are skipped, unless there are only
/// volume cells: then the boundary of the volume they fill.
pub(super) fn surface_from_cells<'c>(
    path: &Path,
    points: Vec<Point>,
    cells: impl Iterator<Item = (u32, &'c [usize])>,
) -> Result<TriSurface, MeshError> {
    let mut triangles = Vec::new();
    let (mut solids, mut solid_types) = (Vec::new(), Vec::new());
    for (c, (ty, cell)) in cells.enumerate() {
        if let Some(&bad) = cell.iter().find(|&&i| i >= points.len()) {
            return Err(MeshError::parse(
                path,
                format!("cell {c} refers to point {bad}, but there are {} points", points.len()),
            ));
        }
        let (need, what) = match ty {
            5 => (3, "triangle"),
            6 => (3, "triangle strip"),
            7 => (3, "polygon"),
            8 | 9 => (4, "quad"),
            _ => {
                if vtk_cell_type(ty).is_some_and(|(solid, _)| solid) {
                    solids.push(cell.to_vec());
                    solid_types.push(ty);
                }
                continue;
            }
        };
        if cell.len() < need || (ty != 6 && ty != 7 && cell.len() != need) {
            return Err(MeshError::parse(path, format!("cell {c} ({what}) has {} vertices", cell.len())));
        }
        match ty {
            6 => strip(cell, &mut triangles),
            8 => fan(&[cell[0], cell[1], cell[3], cell[2]], &mut triangles),
            _ => fan(cell, &mut triangles),
        }
    }
    if triangles.is_empty() && !solids.is_empty() {
        // A volume mesh (an organ meshed before): its boundary.
        let (mesh, _) = volume_from_cells(path, &points, &solids, &solid_types, Vec::new())?;
        return Ok(crate::boundary_surface(&mesh).compacted());
    }
    if triangles.is_empty() {
        return Err(MeshError::parse(path, "no triangles, polygons, triangle strips nor volume cells"));
    }
    Ok(TriSurface { vertices: points, triangles })
}

/// Reads a legacy VTK `UNSTRUCTURED_GRID` (ASCII or binary) as a volume mesh of tetrahedra or
/// hexahedra (voxels become hexahedra).
pub fn read_vtk(path: impl AsRef<Path>) -> Result<Mesh, MeshError> {
    Ok(read_vtk_with_fields(path)?.0)
}

/// Like [`read_vtk`], also returning the point and cell data (scalars, vectors, normals,
/// tensors, texture coordinates, field arrays) restricted to the kept nodes and cells.
pub fn read_vtk_with_fields(path: impl AsRef<Path>) -> Result<(Mesh, Vec<Field>), MeshError> {
    let path = path.as_ref();
    let parsed = parse(path)?;
    if parsed.dataset != "UNSTRUCTURED_GRID" {
        let dataset = format!("DATASET {}", parsed.dataset);
        return Err(MeshError::NotVolume { path: path.display().to_string(), dataset });
    }
    let points = parsed.points.ok_or_else(|| MeshError::parse(path, "no POINTS section"))?;
    let (_, list) = parsed.cells.into_iter().next().ok_or_else(|| MeshError::parse(path, "no CELLS section"))?;
    let types = parsed.types.ok_or_else(|| MeshError::parse(path, "no CELL_TYPES section"))?;
    let cells: Vec<Vec<usize>> = (0..list.len()).map(|i| list.cell(i).to_vec()).collect();
    volume_from_cells(path, &points, &cells, &types, parsed.fields)
}

/// The `POINTS` of a legacy VTK file of any dataset, whatever its cells (a point cloud).
pub(super) fn read_vtk_points(path: &Path) -> Result<Vec<Point>, MeshError> {
    parse(path)?.points.ok_or_else(|| MeshError::parse(path, "no POINTS section"))
}

/// Reads the triangles of a legacy VTK file as a surface: `POLYDATA` polygons and triangle
/// strips, or the triangles, quads and polygons of an `UNSTRUCTURED_GRID` (all points kept), or
/// the boundary of its volume cells when it has no others.
pub fn read_vtk_surface(path: impl AsRef<Path>) -> Result<TriSurface, MeshError> {
    Ok(read_vtk_surface_and_space(path.as_ref())?.0)
}

/// [`read_vtk_surface`], with the string array `SPACE` of the file's field data, if any.
pub(super) fn read_vtk_surface_and_space(path: &Path) -> Result<(TriSurface, Option<String>), MeshError> {
    let parsed = parse(path)?;
    let space = parsed.space.clone();
    Ok((surface_of(path, parsed)?, space))
}

/// The triangles of a parsed legacy file (see [`read_vtk_surface`]).
fn surface_of(path: &Path, parsed: Parsed) -> Result<TriSurface, MeshError> {
    let points = parsed.points.ok_or_else(|| MeshError::parse(path, "no POINTS section"))?;
    if parsed.dataset == "POLYDATA" {
        let cells = parsed.cells.iter().flat_map(|(key, list)| {
            let ty = match key.as_str() {
                "POLYGONS" => VTK_POLYGON.into(),
                "TRIANGLE_STRIPS" => VTK_TRIANGLE_STRIP.into(),
                _ => 0,
            };
            (0..list.len()).map(move |i| (ty, list.cell(i)))
        });
        surface_from_cells(path, points, cells)
    } else {
        let (_, list) = parsed.cells.first().ok_or_else(|| MeshError::parse(path, "no CELLS section"))?;
        let types = parsed.types.ok_or_else(|| MeshError::parse(path, "no CELL_TYPES section"))?;
        if types.len() != list.len() {
            return Err(MeshError::parse(path, format!("{} cells but {} cell types", list.len(), types.len())));
        }
        surface_from_cells(path, points, types.iter().enumerate().map(|(i, &t)| (t, list.cell(i))))
    }
}

/// Writes `values` as big-endian doubles (binary) or text, `per_line` per line.
fn write_reals(
    w: &mut impl Write,
    values: impl Iterator<Item = f64>,
    encoding: Encoding,
    per_line: usize,
) -> std::io::Result<()> {
    match encoding {
        Encoding::Binary => {
            for x in values {
                w.write_all(&x.to_be_bytes())?;
            }
        }
        Encoding::Ascii => {
            for (i, x) in values.enumerate() {
                let sep = if i == 0 {
                    ""
                } else if i % per_line == 0 {
                    "\n"
                } else {
                    " "
                };
                write!(w, "{sep}{}", Num(x))?;
            }
        }
    }
    writeln!(w)
}

/// Writes cells as `k i1 .. ik` 32-bit integers (big-endian binary or text).
fn write_cells(w: &mut impl Write, conn: &[usize], k: usize, encoding: Encoding) -> std::io::Result<()> {
    for cell in conn.chunks_exact(k) {
        match encoding {
            Encoding::Binary => {
                w.write_all(&(k as i32).to_be_bytes())?;
                for &i in cell {
                    w.write_all(&(i as i32).to_be_bytes())?;
                }
            }
            Encoding::Ascii => {
                write!(w, "{k}")?;
                for &i in cell {
                    write!(w, " {i}")?;
                }
                writeln!(w)?;
            }
        }
    }
    if encoding == Encoding::Binary {
        writeln!(w)?;
    }
    Ok(())
}

/// Writes a whole legacy file: `UNSTRUCTURED_GRID` when `grid_type` is given, else `POLYDATA`
/// with `k`-gon polygons.
/// `title` is the header line (line 2): one line, at most 256 characters.
#[allow(clippy::too_many_arguments)]
fn write_legacy(
    path: &Path,
    title: &str,
    nodes: &[Point],
    conn: &[usize],
    k: usize,
    grid_type: Option<u8>,
    fields: &[Field],
    encoding: Encoding,
) -> Result<(), MeshError> {
    let cells = conn.len() / k;
    check_for_writing(nodes.len(), cells, conn, fields)?;
    if nodes.len() > i32::MAX as usize || conn.len() + cells > i32::MAX as usize {
        return Err(MeshError::Invalid("too large for the 32-bit indices of legacy VTK; write .vtu".into()));
    }
    let mode = if encoding == Encoding::Binary { "BINARY" } else { "ASCII" };
    let dataset = if grid_type.is_some() { "UNSTRUCTURED_GRID" } else { "POLYDATA" };
    write_atomic(path, |w| {
        write!(w, "# vtk DataFile Version 3.0\n{title}\n{mode}\nDATASET {dataset}\nPOINTS {} double\n", nodes.len())?;
        write_reals(w, nodes.iter().flatten().copied(), encoding, 3)?;
        match grid_type {
            Some(ty) => {
                writeln!(w, "CELLS {cells} {}", cells * (k + 1))?;
                write_cells(w, conn, k, encoding)?;
                writeln!(w, "CELL_TYPES {cells}")?;
                match encoding {
                    Encoding::Binary => {
                        for _ in 0..cells {
                            w.write_all(&(ty as i32).to_be_bytes())?;
                        }
                        writeln!(w)?;
                    }
                    Encoding::Ascii => {
                        for _ in 0..cells {
                            writeln!(w, "{ty}")?;
                        }
                    }
                }
            }
            None => {
                writeln!(w, "POLYGONS {cells} {}", cells * (k + 1))?;
                write_cells(w, conn, k, encoding)?;
            }
        }
        for (location, keyword, count) in
            [(FieldLocation::Point, "POINT_DATA", nodes.len()), (FieldLocation::Cell, "CELL_DATA", cells)]
        {
            let here: Vec<&Field> = fields.iter().filter(|f| f.location == location).collect();
            if here.is_empty() {
                continue;
            }
            writeln!(w, "{keyword} {count}\nFIELD FieldData {}", here.len())?;
            for f in here {
                writeln!(w, "{} {} {count} double", f.name, f.components)?;
                write_reals(w, f.values.iter().copied(), encoding, f.components.max(3))?;
            }
        }
        Ok(())
    })
    .map_err(MeshError::from)
}

/// Writes a volume mesh with point and cell data as a binary legacy VTK `UNSTRUCTURED_GRID`.
pub fn write_vtk_legacy(path: impl AsRef<Path>, mesh: &Mesh, fields: &[Field]) -> Result<(), MeshError> {
    write_vtk_legacy_with(path, mesh, fields, Encoding::Binary)
}

/// Writes a volume mesh with point and cell data as a legacy VTK `UNSTRUCTURED_GRID` in the
/// given encoding (fields as `FIELD` arrays of doubles).
pub fn write_vtk_legacy_with(
    path: impl AsRef<Path>,
    mesh: &Mesh,
    fields: &[Field],
    encoding: Encoding,
) -> Result<(), MeshError> {
    write_vtk_legacy_titled(path.as_ref(), mesh, fields, encoding, "augsim")
}

/// [`write_vtk_legacy_with`] with `title` as the header line (one line of at most 256
/// characters; `augsim SPACE=LPS` names the frame as 3D Slicer reads it).
pub(super) fn write_vtk_legacy_titled(
    path: &Path,
    mesh: &Mesh,
    fields: &[Field],
    encoding: Encoding,
    title: &str,
) -> Result<(), MeshError> {
    check_title(title)?;
    let (ty, k, conn) = mesh_cells_flat(mesh);
    write_legacy(path, title, &mesh.nodes, &conn, k, Some(ty), fields, encoding)
}

/// A legacy VTK title is one line of at most 256 characters.
fn check_title(title: &str) -> Result<(), MeshError> {
    if title.contains(['\n', '\r']) || title.len() > 256 {
        return Err(MeshError::Invalid(format!("a legacy VTK title is one line of at most 256 characters: {title:?}")));
    }
    Ok(())
}

/// Writes a surface as a binary legacy VTK `POLYDATA` of triangles.
pub(super) fn write_surface_vtk(path: &Path, surface: &TriSurface) -> Result<(), MeshError> {
    write_surface_vtk_titled(path, surface, "augsim")
}

/// [`write_surface_vtk`] with `title` as the header line (one line of at most 256 characters).
pub(super) fn write_surface_vtk_titled(path: &Path, surface: &TriSurface, title: &str) -> Result<(), MeshError> {
    check_title(title)?;
    let conn = check_surface(surface)?;
    write_legacy(path, title, &surface.vertices, &conn, 3, None, &[], Encoding::Binary)
}
