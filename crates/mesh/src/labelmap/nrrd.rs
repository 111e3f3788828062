//! NRRD (`.nrrd`, `.seg.nrrd` as 3D Slicer saves segmentations, `.nhdr` with its data file beside
//! it): the header's fields and key-value pairs, its space, directions, origin and unit, Slicer's
//! layered segments, and the writers of labelmaps and displacement fields.

use std::collections::BTreeMap;
use std::path::Path;

use super::{
    check_affine, gunzip_if_needed, gzip, in_millimetres, label, label_bytes, labels, read_data_file, Frame, Labelmap,
};
use crate::io::Scalar;
use crate::length::LengthUnit;
use crate::MeshError;

/// The unit a NRRD `space units` entry names (a [`LengthUnit`] symbol, "µm" or "micron"; an empty
/// one is mm).
fn nrrd_unit(unit: &str) -> Result<LengthUnit, String> {
    match unit.trim_matches('"').trim() {
        "" => Ok(LengthUnit::Millimetre),
        "micron" => Ok(LengthUnit::Micrometre),
        other => other.parse().map_err(|_| format!("space unit {other:?} is not supported (mm, m, cm, um)")),
    }
}

/// The one unit a NRRD `space units` field names for the three axes.
fn nrrd_space_unit(text: &str) -> Result<LengthUnit, String> {
    let units: Vec<LengthUnit> = text.split_whitespace().map(nrrd_unit).collect::<Result<_, _>>()?;
    match units[..] {
        [a, b, c] if a == b && b == c => Ok(a),
        _ => Err(format!("'space units' must name one unit for the three axes, got {text}")),
    }
}

/// The header of a NRRD file, its fields by lower-case name and its key-value pairs.
struct NrrdHeader {
    fields: BTreeMap<String, String>,
    pairs: BTreeMap<String, String>,
}

/// Splits a NRRD file into its header and its data (after the blank line; a detached header may
/// end with the file instead).
fn nrrd_header(bytes: &[u8]) -> Result<(NrrdHeader, &[u8]), String> {
    if !bytes.starts_with(b"NRRD000") {
        return Err("not a NRRD file (it does not start with NRRD000x)".into());
    }
    let mut header = NrrdHeader { fields: BTreeMap::new(), pairs: BTreeMap::new() };
    let mut at = 0;
    let (mut first, mut ended) = (true, false);
    while at < bytes.len() {
        let end = bytes[at..].iter().position(|&b| b == b'\n').unwrap_or(bytes.len() - at);
        let line = String::from_utf8_lossy(&bytes[at..at + end]).trim_end_matches('\r').to_string();
        at = (at + end + 1).min(bytes.len());
        if first {
            first = false;
            continue;
        }
        if line.is_empty() {
            ended = true;
            break;
        }
        if line.starts_with('#') {
            continue;
        }
        if let Some((key, value)) = line.split_once(":=") {
            header.pairs.insert(key.trim().to_string(), value.trim().to_string());
        } else if let Some((key, value)) = line.split_once(": ") {
            header.fields.insert(key.trim().to_ascii_lowercase(), value.trim().to_string());
        } else {
            return Err(format!("header line {line:?} is neither 'field: value' nor 'key:=value'"));
        }
    }
    if !ended && header.data_file().is_none() {
        return Err("the header does not end (no blank line before the data)".into());
    }
    Ok((header, &bytes[at..]))
}

impl NrrdHeader {
    fn field(&self, name: &str) -> Result<&str, String> {
        self.fields.get(name).map(String::as_str).ok_or_else(|| format!("the header has no '{name}' field"))
    }

    /// A skip field, under either of its spellings (`byte skip` or `byteskip`): 0 when absent.
    fn skip(&self, name: &str, alias: &str) -> Result<i64, String> {
        let text = self.either(name, alias);
        text.map_or(Ok(0), |s| s.parse::<i64>().map_err(|_| format!("{name}: {s:?} is not a whole number")))
    }

    /// A field the format spells two ways (`data file` or `datafile`), under either.
    fn either(&self, name: &str, alias: &str) -> Option<&str> {
        self.fields.get(name).or_else(|| self.fields.get(alias)).map(String::as_str)
    }

    /// The `data file` field of a detached header.
    fn data_file(&self) -> Option<&str> {
        self.either("data file", "datafile")
    }

    /// The data of a detached header: the one file its `data file` names, relative to `folder`
    /// (the header's); `None` for attached data.
    fn detached_data(&self, folder: &Path) -> Result<Option<Vec<u8>>, String> {
        let Some(name) = self.data_file() else { return Ok(None) };
        read_data_file(folder, name, "save the segmentation as one .nrrd").map(Some)
    }
}

/// A NRRD `spacings` field as the axes' vectors, along i, j and k in turn (`nan` for a
/// non-spatial axis, which has none).
fn nrrd_spacings(text: &str) -> Result<Vec<Option<[f64; 3]>>, String> {
    let mut spatial = 0;
    text.split_whitespace()
        .map(|s| match s.parse::<f64>() {
            Ok(x) if x.is_nan() => Ok(None),
            Ok(x) if x > 0.0 && x.is_finite() && spatial < 3 => {
                spatial += 1;
                Ok(Some(std::array::from_fn(|r| if r == spatial - 1 { x } else { 0.0 })))
            }
            _ => Err(format!("spacings: {s:?} is not a voxel size")),
        })
        .collect()
}

/// Parses "(x,y,z)" vectors of a NRRD field, white space allowed inside them ("(1, 0, 0)");
/// "none" gives `None`.
fn nrrd_vectors(text: &str) -> Result<Vec<Option<[f64; 3]>>, String> {
    let mut vectors = Vec::new();
    let mut rest = text.trim_start();
    while !rest.is_empty() {
        if let Some(after) = rest.strip_prefix("none").filter(|a| a.is_empty() || a.starts_with(char::is_whitespace)) {
            vectors.push(None);
            rest = after;
        } else if let Some((inner, after)) = rest.strip_prefix('(').and_then(|r| r.split_once(')')) {
            let values: Vec<f64> = inner
                .split(',')
                .map(|v| v.trim().parse::<f64>())
                .collect::<Result<_, _>>()
                .map_err(|e| format!("\"({inner})\": {e}"))?;
            vectors.push(Some(<[f64; 3]>::try_from(values).map_err(|_| format!("\"({inner})\" is not a 3D vector"))?));
            rest = after;
        } else {
            return Err(format!("bad vector {:?}", rest.split_whitespace().next().unwrap_or(rest)));
        }
        rest = rest.trim_start();
    }
    Ok(vectors)
}

/// The type of a NRRD `type` field.
fn nrrd_scalar(name: &str) -> Result<Scalar, String> {
    Ok(match name {
        "uchar" | "unsigned char" | "uint8" | "uint8_t" => Scalar::U8,
        "signed char" | "int8" | "int8_t" => Scalar::I8,
        "short" | "short int" | "signed short" | "signed short int" | "int16" | "int16_t" => Scalar::I16,
        "ushort" | "unsigned short" | "unsigned short int" | "uint16" | "uint16_t" => Scalar::U16,
        "int" | "signed int" | "int32" | "int32_t" => Scalar::I32,
        "uint" | "unsigned int" | "uint32" | "uint32_t" => Scalar::U32,
        "longlong"
        | "long long"
        | "long long int"
        | "signed long long"
        | "signed long long int"
        | "int64"
        | "int64_t" => Scalar::I64,
        "ulonglong" | "unsigned long long" | "unsigned long long int" | "uint64" | "uint64_t" => Scalar::U64,
        "float" => Scalar::F32,
        "double" => Scalar::F64,
        other => return Err(format!("type '{other}' is not supported")),
    })
}

/// The frame a NRRD header's `space` names, which its `space directions` need.
fn nrrd_frame(header: &NrrdHeader) -> Result<Frame, String> {
    let space = header.field("space").map_err(|e| {
        format!(
            "{e}: its 'space directions' place the voxels in a frame it does not name; add the one the image was \
             saved in, 'space: left-posterior-superior' (DICOM's, ITK's) or 'space: right-anterior-superior'"
        )
    })?;
    match space.to_ascii_lowercase().as_str() {
        "left-posterior-superior" | "lps" => Ok(Frame::Lps),
        "right-anterior-superior" | "ras" => Ok(Frame::Ras),
        other => Err(format!("space '{other}' is not supported (left-posterior-superior or right-anterior-superior)")),
    }
}

/// Parses a NRRD file, its data attached or in the file a detached header names (relative to
/// `folder`).
pub(super) fn parse_nrrd(bytes: &[u8], folder: &Path) -> Result<Labelmap, String> {
    let (header, attached) = nrrd_header(bytes)?;
    let detached = header.detached_data(folder)?;
    let data = detached.as_deref().unwrap_or(attached);
    let scalar = nrrd_scalar(header.field("type")?)?;
    let sizes: Vec<usize> = header
        .field("sizes")?
        .split_whitespace()
        .map(|s| s.parse::<usize>().map_err(|_| format!("sizes: {s:?} is not a number of voxels")))
        .collect::<Result<_, _>>()?;
    let dimension = header.field("dimension")?;
    if dimension.parse::<usize>().ok() != Some(sizes.len()) {
        return Err(format!("dimension: {dimension}, but 'sizes' gives {} axes", sizes.len()));
    }
    // A header without a space gives its voxel sizes alone (`spacings`): placed nowhere.
    let placed = header.fields.contains_key("space directions") || !header.fields.contains_key("spacings");
    let directions = match placed {
        true => nrrd_vectors(header.field("space directions")?)?,
        false => nrrd_spacings(header.field("spacings")?)?,
    };
    let axes: Vec<[f64; 3]> = directions.iter().flatten().copied().collect();
    if axes.len() != 3 || directions.len() != sizes.len() {
        let field = if placed { "space directions" } else { "spacings" };
        return Err(format!(
            "'{field}' must give one vector per spatial axis (3, and 'none' per other axis of \
             'sizes', which has {}), got '{}'",
            sizes.len(),
            header.field(field)?
        ));
    }
    // Layers of segments come first, as 3D Slicer writes them; a last axis of one voxel is no axis.
    let (layers, dims) = match (sizes.as_slice(), directions.iter().position(Option::is_none)) {
        (&[a, b, c], _) => (1, [a, b, c]),
        (&[l, a, b, c], Some(0)) => (l, [a, b, c]),
        (&[a, b, c, 1], Some(3)) => (1, [a, b, c]),
        (&[_, _, _, _], Some(k)) => {
            return Err(format!(
                "the non-spatial axis ('none' in 'space directions') is axis {k} of 'sizes' {sizes:?}: it must come \
                 first, as 3D Slicer writes layers of segments"
            ))
        }
        _ => return Err(format!("expected a 3D volume (or layers of one), got sizes {sizes:?}")),
    };
    // The bytes of the voxels must be countable (a corrupt header may overflow them).
    let bytes = sizes.iter().try_fold(scalar.size(), |n, &s| n.checked_mul(s));
    if layers == 0 || dims.contains(&0) || bytes.is_none_or(|n| n > isize::MAX as usize) {
        return Err(format!("bad sizes {sizes:?}"));
    }
    let count = layers * dims.iter().product::<usize>();
    let frame = if placed { nrrd_frame(&header)? } else { Frame::Ras };
    let origin = match header.fields.get("space origin") {
        Some(text) => nrrd_vectors(text)?.first().copied().flatten().ok_or("bad 'space origin'")?,
        None => [0.0; 3],
    };
    let affine: [[f64; 4]; 3] =
        std::array::from_fn(|r| std::array::from_fn(|c| if c < 3 { axes[c][r] } else { origin[r] }));
    check_affine(&affine)?;
    let named_unit = header.fields.get("space units").map(|text| nrrd_space_unit(text)).transpose()?;
    let affine = in_millimetres(affine, named_unit.unwrap_or(LengthUnit::Millimetre).millimetres());
    let segments = slicer_segments(&header.pairs, layers)?;
    let encoding = header.field("encoding")?;
    let data = after_lines(data, header.skip("line skip", "lineskip")?)?;
    if matches!(encoding, "ascii" | "text" | "txt") {
        let labels = ascii_labels(data, count)?;
        return Ok(Labelmap {
            dims,
            layers,
            labels,
            affine,
            frame,
            segments,
            placed,
            warnings: Vec::new(),
            named_unit,
        });
    }
    // As teem, the reference reader, does: binary data of more than one byte need their byte order.
    let little = match header.fields.get("endian").map(String::as_str) {
        Some("little") => true,
        Some("big") => false,
        Some(other) => return Err(format!("endian '{other}' is neither little nor big")),
        None if scalar.size() == 1 => true,
        None => {
            return Err(format!(
                "the header has no 'endian' field, which {}-byte voxels need: add 'endian: little' (or big) \
                 to the header",
                scalar.size()
            ))
        }
    };
    let raw = match encoding {
        "raw" => data.to_vec(),
        "gzip" | "gz" => gunzip_if_needed(data.to_vec())?,
        other => return Err(format!("encoding '{other}' is not supported (raw, gzip or ascii)")),
    };
    let expected = count * scalar.size();
    let raw = match header.skip("byte skip", "byteskip")? {
        0 => &raw[..],
        -1 => &raw[raw.len().saturating_sub(expected)..],
        s if s > 0 && (s as usize) < raw.len() => &raw[s as usize..],
        s => return Err(format!("bad byte skip {s}")),
    };
    // Bytes beyond the voxels would be read as the first voxels by some readers and ignored by
    // others (a detached header over a NIfTI's data, its header left in): refused, as pynrrd does,
    // but for a line end after raw data.
    let line_end = if encoding == "raw" { 2 } else { 0 };
    if raw.len() > expected + line_end {
        return Err(format!(
            "the data hold {} bytes, {expected} expected ({count} voxels of {} byte(s)): {} more, which no 'byte skip' \
             leaves out (a header before the voxels? 'byte skip: -1' takes the last {expected} bytes)",
            raw.len(),
            scalar.size(),
            raw.len() - expected
        ));
    }
    let labels = labels(scalar, raw, count, dims[2], little)?;
    Ok(Labelmap { dims, layers, labels, affine, frame, segments, placed, warnings: Vec::new(), named_unit })
}

/// `data` after its first `lines` lines (NRRD's `line skip`, before any decompression).
fn after_lines(data: &[u8], lines: i64) -> Result<&[u8], String> {
    let lines = usize::try_from(lines).map_err(|_| format!("bad line skip {lines}"))?;
    let mut rest = data;
    for skipped in 0..lines {
        let end = rest.iter().position(|&b| b == b'\n');
        let end = end.ok_or(format!("line skip {lines}: the data hold {skipped} lines"))?;
        rest = &rest[end + 1..];
    }
    Ok(rest)
}

/// The `count` labels of NRRD's ascii encoding: numbers separated by white space.
fn ascii_labels(data: &[u8], count: usize) -> Result<Vec<i32>, String> {
    let text = std::str::from_utf8(data).map_err(|_| "ascii data that are not text".to_string())?;
    let labels = text
        .split_whitespace()
        .enumerate()
        .map(|(i, word)| {
            let x = word.parse::<f64>().map_err(|_| format!("voxel {i} holds {word:?}, not a number"))?;
            label(i, x)
        })
        .collect::<Result<Vec<i32>, String>>()?;
    if labels.len() != count {
        return Err(format!("the ascii data hold {} values, {count} expected", labels.len()));
    }
    Ok(labels)
}

/// The name 3D Slicer gives the segment of label value `label` in the NRRD file `path`
/// (`Segment{i}_Name` in its header, read alone), when one segment alone has that value (several
/// layers may reuse it); `None` otherwise, or for a file that is not a NRRD.
pub fn nrrd_segment_name(path: &Path, label: i32) -> Option<String> {
    use std::io::Read;
    let mut head = Vec::new();
    std::fs::File::open(path).ok()?.take(HEADER_BYTES).read_to_end(&mut head).ok()?;
    let (header, _) = nrrd_header(&head).ok()?;
    let segments = named_segments(&header.pairs).ok()?;
    let mut named: Vec<String> = segments.into_iter().filter(|s| s.2 == label).map(|s| s.0).collect();
    (named.len() == 1).then(|| named.remove(0))
}

/// The most bytes read for a NRRD header alone (3D Slicer's of hundreds of segments fit).
const HEADER_BYTES: u64 = 1 << 20;

/// Slicer's segments of a file of `layers` layers: `Segment{i}_Name`, `Segment{i}_LabelValue`
/// (1 where absent), `Segment{i}_Layer` (where absent, as 3D Slicer reads files written before
/// segments shared layers: segment `i` in layer `i` of several, else in the only one).
fn slicer_segments(pairs: &BTreeMap<String, String>, layers: usize) -> Result<Vec<(String, usize, i32)>, String> {
    let mut segments = Vec::new();
    for (i, (name, layer, label)) in named_segments(pairs)?.into_iter().enumerate() {
        let layer = layer.unwrap_or(if layers > 1 { i } else { 0 });
        if layer >= layers {
            return Err(format!("Segment{i}_Layer = {layer} ('{name}'), but the file holds {layers} layer(s)"));
        }
        segments.push((name, layer, label));
    }
    Ok(segments)
}

/// 3D Slicer's segments as its header's pairs name them: `Segment{i}_Name`, `Segment{i}_Layer`
/// where given, `Segment{i}_LabelValue` (1 where absent).
fn named_segments(pairs: &BTreeMap<String, String>) -> Result<Vec<(String, Option<usize>, i32)>, String> {
    let mut segments = Vec::new();
    for i in 0.. {
        let Some(name) = pairs.get(&format!("Segment{i}_Name")) else { break };
        let get = |key: &str| pairs.get(&format!("Segment{i}_{key}"));
        let label =
            get("LabelValue").map_or(Ok(1), |v| v.parse::<i32>()).map_err(|e| format!("Segment{i}_LabelValue: {e}"))?;
        let layer =
            get("Layer").map(|v| v.parse::<usize>()).transpose().map_err(|e| format!("Segment{i}_Layer: {e}"))?;
        segments.push((name.clone(), layer, label));
    }
    Ok(segments)
}

/// Writes a labelmap as a NRRD file with gzipped 16-bit labels (32-bit when they do not fit), its
/// frame as the `space` and its segments as 3D Slicer's `Segment{i}_...` pairs.
pub fn write_nrrd(path: impl AsRef<Path>, map: &Labelmap) -> Result<(), MeshError> {
    let path = path.as_ref();
    let (data, wide) = label_bytes(&map.labels);
    if map.labels.len() != map.layers * map.dims.iter().product::<usize>() {
        return Err(MeshError::Invalid(format!("{}: bad labelmap size", path.display())));
    }
    let vector = |v: [f64; 3]| format!("({},{},{})", v[0], v[1], v[2]);
    let axes: Vec<String> = (0..3).map(|c| vector(std::array::from_fn(|r| map.affine[r][c]))).collect();
    let layered = map.layers > 1;
    let mut text = format!(
        "NRRD0004\n# written by augsim\ntype: {}\ndimension: {}\nspace: {}\nsizes: {}{} {} {}\n\
         space directions: {}{}\nkinds: {}domain domain domain\nendian: little\nencoding: gzip\n\
         space origin: {}\n",
        if wide { "int" } else { "short" },
        if layered { 4 } else { 3 },
        match map.frame {
            Frame::Ras => "right-anterior-superior",
            Frame::Lps => "left-posterior-superior",
        },
        if layered { format!("{} ", map.layers) } else { String::new() },
        map.dims[0],
        map.dims[1],
        map.dims[2],
        if layered { "none " } else { "" },
        axes.join(" "),
        if layered { "list " } else { "" },
        vector(std::array::from_fn(|r| map.affine[r][3])),
    );
    for (i, (name, layer, label)) in map.segments.iter().enumerate() {
        text += &format!("Segment{i}_Name:={name}\nSegment{i}_LabelValue:={label}\nSegment{i}_Layer:={layer}\n");
    }
    text.push('\n');
    let bytes = [text.into_bytes(), gzip(path, &data)?].concat();
    crate::io::write_atomic_bytes(path, &bytes).map_err(MeshError::from)
}

/// Writes a displacement field as 3D Slicer and ITK read a displacement-field transform: NRRD,
/// `kinds: vector domain domain domain`, 32-bit floats, gzip, `space: left-posterior-superior`,
/// and the key 3D Slicer writes to say which way it maps, `displacement field type:=resampling`
/// (a position in the fixed image plus its vector is where to sample the moving one).
/// `affine` maps grid indices to LPS positions (mm) as [`Labelmap::affine`]; `vectors` (mm, LPS)
/// are x fastest, then y, then z, as many as grid points.
pub fn write_displacement_nrrd(
    path: impl AsRef<Path>,
    dims: [usize; 3],
    affine: [[f64; 4]; 3],
    vectors: &[[f64; 3]],
) -> Result<(), MeshError> {
    let path = path.as_ref();
    if vectors.len() != dims.iter().product::<usize>() {
        return Err(MeshError::Invalid(format!(
            "{}: {} vectors for a grid of {dims:?}",
            path.display(),
            vectors.len()
        )));
    }
    // Adding 0 writes −0 as 0.
    let vector = |v: [f64; 3]| format!("({},{},{})", v[0] + 0.0, v[1] + 0.0, v[2] + 0.0);
    let axes: Vec<String> = (0..3).map(|c| vector(std::array::from_fn(|r| affine[r][c]))).collect();
    let text = format!(
        "NRRD0004\n# displacement field, written by augsim\ntype: float\ndimension: 4\n\
         space: left-posterior-superior\nsizes: 3 {} {} {}\nspace directions: none {}\n\
         kinds: vector domain domain domain\nendian: little\nencoding: gzip\nspace origin: {}\n\
         displacement field type:=resampling\n\n",
        dims[0],
        dims[1],
        dims[2],
        axes.join(" "),
        vector(std::array::from_fn(|r| affine[r][3])),
    );
    let data: Vec<u8> = vectors.iter().flatten().flat_map(|&x| (x as f32).to_le_bytes()).collect();
    let bytes = [text.into_bytes(), gzip(path, &data)?].concat();
    crate::io::write_atomic_bytes(path, &bytes).map_err(MeshError::from)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::labelmap::read_labelmap;

    /// `line skip` lines before the data are passed over, before decompressing (as pynrrd's
    /// test file has them: text, then the gzip stream); bytes left beyond the voxels (a detached
    /// header over a NIfTI's data, its 352-byte header left in) are refused, not read as voxels.
    #[test]
    fn skipped_lines_are_passed_over_and_data_left_over_refused() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("skip.nrrd");
        let voxels: Vec<u8> = (0..8).map(|i| u8::from(i == 3)).collect();
        let header = |extra: &str| {
            format!(
                "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 2 2\nspace: left-posterior-superior\n\
                 space directions: (1,0,0) (0,1,0) (0,0,1)\nencoding: gzip\n{extra}\n"
            )
        };
        let gzipped = super::super::gzip(&path, &voxels).unwrap();
        let text = [header("line skip: 2\n").as_bytes(), b"a line\nanother\n", &gzipped].concat();
        std::fs::write(&path, text).unwrap();
        assert_eq!(read_labelmap(&path).unwrap().labels, voxels.iter().map(|&v| i32::from(v)).collect::<Vec<_>>());
        let stray = super::super::gzip(&path, &[&[9u8; 352][..], &voxels].concat()).unwrap();
        std::fs::write(&path, [header("").as_bytes(), &stray].concat()).unwrap();
        let e = read_labelmap(&path).unwrap_err().to_string();
        assert!(e.contains("the data hold 360 bytes, 8 expected") && e.contains("byte skip: -1"), "{e}");
        std::fs::write(&path, [header("byteskip: -1\n").as_bytes(), &stray].concat()).unwrap();
        assert_eq!(read_labelmap(&path).unwrap().labels[3], 1);
    }

    /// NRRD's `space units` take every symbol of a length unit (both micro signs), "micron", and
    /// an empty entry as mm; other units, or several for the three axes, are refused.
    #[test]
    fn nrrd_space_units_are_read_as_length_units() {
        let unit = |text: &str| nrrd_space_unit(text);
        assert_eq!(unit("\"mm\" \"mm\" \"mm\""), Ok(LengthUnit::Millimetre));
        assert_eq!(unit("\"\" \"\" \"\""), Ok(LengthUnit::Millimetre));
        for micro in ["um", "\u{b5}m", "\u{3bc}m", "micron"] {
            assert_eq!(unit(&[micro; 3].join(" ")), Ok(LengthUnit::Micrometre), "{micro}");
        }
        assert_eq!(unit("cm cm cm"), Ok(LengthUnit::Centimetre));
        assert!(unit("in in in").unwrap_err().contains("space unit \"in\" is not supported"));
        assert!(unit("mm m mm").unwrap_err().contains("one unit for the three axes"));
    }

    /// NRRD vectors may hold white space, as some writers put it after the commas.
    #[test]
    fn nrrd_vectors_may_hold_white_space() {
        let spaced = nrrd_vectors(" none ( 1, 0,0 ) (0, 1.5, 0)(0 ,0, 2) ").unwrap();
        assert_eq!(spaced, [None, Some([1.0, 0.0, 0.0]), Some([0.0, 1.5, 0.0]), Some([0.0, 0.0, 2.0])]);
        assert!(nrrd_vectors("(1, 0, 0) (0, 1)").unwrap_err().contains("\"(0, 1)\" is not a 3D vector"));
        assert!(nrrd_vectors("(1, 0, 0) (0, 1, 0").unwrap_err().contains("bad vector \"(0,\""));
        assert!(nrrd_vectors("nonesuch").unwrap_err().contains("bad vector \"nonesuch\""));
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("spaced.nrrd");
        let header = "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 2 2\nspace: left-posterior-superior\n\
                      space directions: (1, 0, 0) (0, 1, 0) (0, 0, 2)\nspace origin: (1, 2, 3)\nencoding: raw\n\n";
        std::fs::write(&path, [header.as_bytes(), &[0, 0, 0, 1, 0, 0, 0, 0]].concat()).unwrap();
        let map = read_labelmap(&path).unwrap();
        assert_eq!(map.affine, [[1.0, 0.0, 0.0, 1.0], [0.0, 1.0, 0.0, 2.0], [0.0, 0.0, 2.0, 3.0]]);
        assert!(map.placed);
        // Directions in a space it does not name: refused, saying which line to add.
        let unnamed = header.replace("space: left-posterior-superior\n", "space dimension: 3\n");
        std::fs::write(&path, [unnamed.as_bytes(), &[0, 0, 0, 1, 0, 0, 0, 0]].concat()).unwrap();
        let e = read_labelmap(&path).unwrap_err().to_string();
        assert!(e.contains("no 'space' field") && e.contains("add the one the image was saved in"), "{e}");
        // Voxel sizes alone (`spacings`, no space), as ITK reads them: at the indices times the
        // spacing, placed nowhere; a size that is not one is refused.
        let header = "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 2 2\nspacings: 0.8 0.9 2.5\nencoding: raw\n\n";
        std::fs::write(&path, [header.as_bytes(), &[0, 0, 0, 1, 0, 0, 0, 0]].concat()).unwrap();
        let map = read_labelmap(&path).unwrap();
        assert_eq!(map.affine, [[0.8, 0.0, 0.0, 0.0], [0.0, 0.9, 0.0, 0.0], [0.0, 0.0, 2.5, 0.0]]);
        assert!(!map.placed);
        std::fs::write(&path, [header.replace("0.9", "-1").as_bytes(), &[0; 8]].concat()).unwrap();
        assert!(read_labelmap(&path).unwrap_err().to_string().contains("spacings: \"-1\" is not a voxel size"));
    }
}
