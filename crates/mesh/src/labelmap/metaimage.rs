//! ITK's MetaImage (`.mha`, one file; `.mhd`, a header naming its data file), as ITK-SNAP, 3D
//! Slicer and challenge data sets (SLIVER07's livers) save labelmaps.
//!
//! The header is `Key = Value` lines, `ElementDataFile` last: `LOCAL` (the data follow that
//! line) or one file name, relative to the header's folder. Read: `NDims` 3, `DimSize`,
//! `ElementSpacing` (else `ElementSize`), `Offset` (or `Position`, `Origin`), `TransformMatrix`
//! (or `Rotation`, `Orientation`: the direction of axis i in values 3i..3i+3, as ITK reads it),
//! `ElementType` (`MET_CHAR` … `MET_ULONG_LONG`, `MET_FLOAT`, `MET_DOUBLE`), the byte order
//! (`BinaryDataByteOrderMSB` or `ElementByteOrderMSB`), `CompressedData` (zlib) and `HeaderSize`
//! (bytes before the data in their file; −1: the data end the file). The world is ITK's, LPS, in
//! millimetres.

use std::collections::BTreeMap;
use std::io::Read;
use std::path::Path;

use super::{check_affine, labels, Frame, Labelmap};
use crate::io::Scalar;

/// Parses a MetaImage; a data file it names is read from `folder`.
pub(super) fn parse_metaimage(bytes: &[u8], folder: &Path) -> Result<Labelmap, String> {
    let (fields, attached) = header(bytes)?;
    let get = |keys: &[&str]| keys.iter().find_map(|k| fields.get(&k.to_ascii_lowercase()).map(String::as_str));
    let numbers = |keys: &[&str], count: usize| -> Result<Option<Vec<f64>>, String> {
        let Some(text) = get(keys) else { return Ok(None) };
        let values: Vec<f64> = text
            .split_whitespace()
            .map(str::parse)
            .collect::<Result<_, _>>()
            .map_err(|_| format!("{} = {text}: expected {count} numbers", keys[0]))?;
        if values.len() != count || values.iter().any(|v| !v.is_finite()) {
            return Err(format!("{} = {text}: expected {count} numbers", keys[0]));
        }
        Ok(Some(values))
    };
    if let Some(object) = get(&["ObjectType"]).filter(|o| !o.eq_ignore_ascii_case("Image")) {
        return Err(format!("ObjectType = {object}: not an image"));
    }
    let dims_text = get(&["NDims"]).ok_or("the header has no NDims")?;
    if dims_text != "3" {
        return Err(format!("NDims = {dims_text}: expected a 3D volume"));
    }
    let channels = get(&["ElementNumberOfChannels"]).unwrap_or("1");
    if channels != "1" {
        return Err(format!("ElementNumberOfChannels = {channels}: a labelmap has one value per voxel"));
    }
    let size = numbers(&["DimSize"], 3)?.ok_or("the header has no DimSize")?;
    if size.iter().any(|&n| n < 1.0 || n.fract() != 0.0 || n > 1e9) {
        return Err(format!("DimSize {size:?} is not a number of voxels along each axis"));
    }
    let dims = [size[0] as usize, size[1] as usize, size[2] as usize];
    let spacing = numbers(&["ElementSpacing"], 3)?.or(numbers(&["ElementSize"], 3)?).unwrap_or(vec![1.0; 3]);
    let origin = numbers(&["Offset", "Position", "Origin"], 3)?.unwrap_or(vec![0.0; 3]);
    let direction = numbers(&["TransformMatrix", "Rotation", "Orientation"], 9)?
        .unwrap_or(vec![1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]);
    let affine: [[f64; 4]; 3] = std::array::from_fn(|r| {
        std::array::from_fn(|c| if c < 3 { direction[3 * c + r] * spacing[c] } else { origin[r] })
    });
    check_affine(&affine)?;
    let scalar = element_type(get(&["ElementType"]).ok_or("the header has no ElementType")?)?;
    let msb = get(&["BinaryDataByteOrderMSB", "ElementByteOrderMSB"]).unwrap_or("False");
    let compressed = get(&["CompressedData"]).unwrap_or("False");
    let data_file = get(&["ElementDataFile"]).ok_or("the header has no ElementDataFile (the last field)")?;
    let detached;
    let data = if data_file.eq_ignore_ascii_case("LOCAL") {
        attached
    } else {
        detached = super::read_data_file(folder, data_file, "save one .mha")?;
        &detached[..]
    };
    let count = dims.iter().product::<usize>();
    let inflated;
    let data = if is_true(compressed) {
        let mut out = Vec::with_capacity(count * scalar.size());
        flate2::read::ZlibDecoder::new(data)
            .read_to_end(&mut out)
            .map_err(|e| format!("the compressed data cannot be inflated (zlib): {e}"))?;
        inflated = out;
        &inflated[..]
    } else {
        data
    };
    let data = match get(&["HeaderSize"]).map(str::parse::<i64>) {
        None | Some(Ok(0)) => data,
        Some(Ok(-1)) => &data[data.len().saturating_sub(count * scalar.size())..],
        Some(Ok(skip)) if skip > 0 && (skip as usize) <= data.len() => &data[skip as usize..],
        Some(_) => return Err(format!("bad HeaderSize {}", get(&["HeaderSize"]).unwrap_or_default())),
    };
    let labels = labels(scalar, data, count, dims[2], !is_true(msb))?;
    Ok(Labelmap::single(dims, labels, affine, Frame::Lps))
}

/// The header's fields by lower-case key, and the bytes after `ElementDataFile`'s line.
fn header(bytes: &[u8]) -> Result<(BTreeMap<String, String>, &[u8]), String> {
    let mut fields = BTreeMap::new();
    let mut at = 0;
    while at < bytes.len() {
        let end = bytes[at..].iter().position(|&b| b == b'\n').unwrap_or(bytes.len() - at);
        let line = std::str::from_utf8(&bytes[at..at + end])
            .map_err(|_| "not a MetaImage header (a line that is not text before ElementDataFile)".to_string())?;
        at = (at + end + 1).min(bytes.len());
        let line = line.trim();
        if line.is_empty() {
            continue;
        }
        let Some((key, value)) = line.split_once('=') else {
            return Err(format!("header line {line:?} is not 'Key = Value'"));
        };
        let key = key.trim().to_ascii_lowercase();
        let last = key == "elementdatafile";
        fields.insert(key, value.trim().to_string());
        if last {
            return Ok((fields, &bytes[at..]));
        }
    }
    Err("the header has no ElementDataFile (the last field)".into())
}

fn is_true(value: &str) -> bool {
    value.eq_ignore_ascii_case("true") || value == "1"
}

/// The scalar of an `ElementType` (MetaIO's `MET_LONG` is 4 bytes, `MET_LONG_LONG` 8).
fn element_type(name: &str) -> Result<Scalar, String> {
    Ok(match name {
        "MET_CHAR" => Scalar::I8,
        "MET_UCHAR" => Scalar::U8,
        "MET_SHORT" => Scalar::I16,
        "MET_USHORT" => Scalar::U16,
        "MET_INT" | "MET_LONG" => Scalar::I32,
        "MET_UINT" | "MET_ULONG" => Scalar::U32,
        "MET_LONG_LONG" => Scalar::I64,
        "MET_ULONG_LONG" => Scalar::U64,
        "MET_FLOAT" => Scalar::F32,
        "MET_DOUBLE" => Scalar::F64,
        other => return Err(format!("ElementType = {other} is not supported")),
    })
}

#[cfg(test)]
mod tests {
    use super::super::{read_labelmap, tests::two_balls};
    use super::*;

    /// A labelmap written as ITK writes it, rotated and in LPS: a `.mha` with zlib-compressed data
    /// and a `.mhd` naming a big-endian `.raw` file beside it read back as the labelmap; a header
    /// without its data file or of four dimensions is refused by name.
    #[test]
    fn metaimages_read_back_their_labelmap() {
        let dir = tempfile::tempdir().unwrap();
        let (mut map, _) = two_balls(Frame::Lps);
        map.segments.clear();
        // Turned by 30° about z, then 20° about x: a direction matrix that is not its transpose.
        let (c, s) = (30f64.to_radians().cos(), 30f64.to_radians().sin());
        let (c2, s2) = (20f64.to_radians().cos(), 20f64.to_radians().sin());
        let turn = [[c, -s, 0.0], [c2 * s, c2 * c, -s2], [s2 * s, s2 * c, c2]];
        map.affine = std::array::from_fn(|r| {
            std::array::from_fn(|k| {
                if k < 3 {
                    (0..3).map(|m| turn[r][m] * map.affine[m][k]).sum()
                } else {
                    map.affine[r][3]
                }
            })
        });
        let spacing = map.spacing();
        let direction: Vec<String> = (0..3)
            .flat_map(|c| (0..3).map(move |r| (c, r)))
            .map(|(c, r)| (map.affine[r][c] / spacing[c]).to_string())
            .collect();
        let header = |extra: &str| {
            format!(
                "ObjectType = Image\nNDims = 3\nBinaryData = True\nTransformMatrix = {}\nOffset = {} {} {}\n\
                 AnatomicalOrientation = RAI\nElementSpacing = {} {} {}\nDimSize = {} {} {}\nElementType = MET_SHORT\n{extra}",
                direction.join(" "),
                map.affine[0][3],
                map.affine[1][3],
                map.affine[2][3],
                spacing[0],
                spacing[1],
                spacing[2],
                map.dims[0],
                map.dims[1],
                map.dims[2]
            )
        };
        let little: Vec<u8> = map.labels.iter().flat_map(|&l| (l as i16).to_le_bytes()).collect();
        let mut zlib = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::default());
        std::io::Write::write_all(&mut zlib, &little).unwrap();
        let mha = dir.path().join("seg.mha");
        let text = header("BinaryDataByteOrderMSB = False\nCompressedData = True\nElementDataFile = LOCAL\n");
        std::fs::write(&mha, [text.as_bytes(), &zlib.finish().unwrap()].concat()).unwrap();
        let big: Vec<u8> = map.labels.iter().flat_map(|&l| (l as i16).to_be_bytes()).collect();
        std::fs::write(dir.path().join("seg.raw"), big).unwrap();
        let mhd = dir.path().join("seg.mhd");
        std::fs::write(&mhd, header("ElementByteOrderMSB = True\nElementDataFile = seg.raw\n")).unwrap();
        for path in [&mha, &mhd] {
            let read = read_labelmap(path).unwrap();
            assert_eq!((read.dims, read.frame, &read.labels), (map.dims, Frame::Lps, &map.labels), "{path:?}");
            let worst = read.affine.iter().flatten().zip(map.affine.iter().flatten()).map(|(a, b)| (a - b).abs());
            assert!(worst.fold(0.0, f64::max) < 1e-9, "{:?} vs {:?}", read.affine, map.affine);
        }
        std::fs::write(&mhd, header("ElementDataFile = gone.raw\n")).unwrap();
        let e = read_labelmap(&mhd).unwrap_err().to_string();
        assert!(e.contains("its data file") && e.contains("gone.raw cannot be read"), "{e}");
        std::fs::write(&mhd, header("ElementDataFile = LOCAL\n").replace("NDims = 3", "NDims = 4")).unwrap();
        assert!(read_labelmap(&mhd).unwrap_err().to_string().contains("NDims = 4: expected a 3D volume"));
        std::fs::write(&mhd, header("")).unwrap();
        assert!(read_labelmap(&mhd).unwrap_err().to_string().contains("no ElementDataFile"));
    }
}
