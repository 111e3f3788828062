//! NIfTI-1 and NIfTI-2 single files (`.nii`, `.nii.gz`), as TotalSegmentator and nibabel write
//! them: the header's dimensions, data type, scaling, unit and the sform or qform affine as 3D
//! Slicer (ITK) reads them, the label table of a header extension, and the writer.

use std::path::Path;

use super::{check_affine, gzip, in_millimetres, label_bytes, labels, Frame, Labelmap, SCALED_LABEL_TOLERANCE};
use crate::io::Scalar;
use crate::length::LengthUnit;
use crate::MeshError;

/// The fields of a NIfTI-1 or NIfTI-2 header that size, read and place the voxels (NIfTI-2 holds
/// the same fields, wider, at other offsets).
struct NiftiHeader {
    version: u8,
    little: bool,
    dim: [i64; 8],
    datatype: i16,
    pixdim: [f64; 8],
    vox_offset: f64,
    scl_slope: f64,
    scl_inter: f64,
    xyzt_units: u8,
    qform_code: i32,
    sform_code: i32,
    quatern: [f64; 3],
    qoffset: [f64; 3],
    srow: [[f64; 4]; 3],
}

impl NiftiHeader {
    /// The header of a single-file NIfTI-1 (`n+1`, 348 bytes) or NIfTI-2 (`n+2`, 540 bytes), in
    /// either byte order, which its size field tells.
    fn parse(bytes: &[u8]) -> Result<NiftiHeader, String> {
        if bytes.len() < 352 {
            return Err(format!("too short for a NIfTI file ({} bytes)", bytes.len()));
        }
        let size = |little: bool| int32_at(bytes, 0, little);
        let (version, little) = match (size(true), size(false)) {
            (348, _) => (1, true),
            (_, 348) => (1, false),
            (540, _) => (2, true),
            (_, 540) => (2, false),
            _ => return Err("not a NIfTI file (its header size is neither 348, NIfTI-1, nor 540, NIfTI-2)".into()),
        };
        let header_size = if version == 1 { 352 } else { 544 };
        if bytes.len() < header_size {
            return Err(format!("too short for a NIfTI-{version} file ({} bytes)", bytes.len()));
        }
        let at = |o: usize, n: usize| -> Vec<u8> {
            let mut b = bytes[o..o + n].to_vec();
            if !little {
                b.reverse();
            }
            b
        };
        let i16_at = |o: usize| i16::from_le_bytes(at(o, 2).try_into().unwrap());
        let i32_at = |o: usize| i32::from_le_bytes(at(o, 4).try_into().unwrap());
        let i64_at = |o: usize| i64::from_le_bytes(at(o, 8).try_into().unwrap());
        let f32_at = |o: usize| f32::from_le_bytes(at(o, 4).try_into().unwrap()) as f64;
        let f64_at = |o: usize| f64::from_le_bytes(at(o, 8).try_into().unwrap());
        if version == 1 {
            if &bytes[344..348] != b"n+1\0" {
                return Err(
                    "not a single-file NIfTI-1 (magic is not \"n+1\"; a .hdr/.img pair is not supported)".into()
                );
            }
            return Ok(NiftiHeader {
                version,
                little,
                dim: std::array::from_fn(|d| i16_at(40 + 2 * d) as i64),
                datatype: i16_at(70),
                pixdim: std::array::from_fn(|d| f32_at(76 + 4 * d)),
                vox_offset: f32_at(108),
                scl_slope: f32_at(112),
                scl_inter: f32_at(116),
                xyzt_units: bytes[123],
                qform_code: i16_at(252) as i32,
                sform_code: i16_at(254) as i32,
                quatern: std::array::from_fn(|k| f32_at(256 + 4 * k)),
                qoffset: std::array::from_fn(|k| f32_at(268 + 4 * k)),
                srow: std::array::from_fn(|r| std::array::from_fn(|c| f32_at(280 + 16 * r + 4 * c))),
            });
        }
        if &bytes[4..12] != b"n+2\0\r\n\x1a\n" {
            return Err("not a single-file NIfTI-2 (magic is not \"n+2\"; a .hdr/.img pair is not supported)".into());
        }
        Ok(NiftiHeader {
            version,
            little,
            dim: std::array::from_fn(|d| i64_at(16 + 8 * d)),
            datatype: i16_at(12),
            pixdim: std::array::from_fn(|d| f64_at(104 + 8 * d)),
            vox_offset: i64_at(168) as f64,
            scl_slope: f64_at(176),
            scl_inter: f64_at(184),
            xyzt_units: i32_at(500) as u8,
            qform_code: i32_at(344),
            sform_code: i32_at(348),
            quatern: std::array::from_fn(|k| f64_at(352 + 8 * k)),
            qoffset: std::array::from_fn(|k| f64_at(376 + 8 * k)),
            srow: std::array::from_fn(|r| std::array::from_fn(|c| f64_at(400 + 32 * r + 8 * c))),
        })
    }
}

/// Parses a NIfTI-1 or NIfTI-2 single file (header, then the voxels at `vox_offset`).
pub(super) fn parse_nifti(bytes: &[u8]) -> Result<Labelmap, String> {
    let header = NiftiHeader::parse(bytes)?;
    let (dim, little) = (header.dim, header.little);
    if !(3..=7).contains(&dim[0]) || (4..=dim[0] as usize).any(|d| dim[d] != 1) {
        let dims = &dim[1..=dim[0].clamp(1, 7) as usize];
        let why = match dims {
            // Sizes no image has: the byte order (which the header's size tells) is worth naming.
            _ if dims.iter().any(|&d| !(1..=100_000).contains(&d)) => {
                format!(" (read {}-endian, as the header size says)", if little { "little" } else { "big" })
            }
            [_, _, _, more @ ..] => format!(
                ": {} volumes (one-hot channels of a network's output, or a time series), where a labelmap is one \
                 volume of labels; save one volume (the channels' argmax, or the channel of the organ)",
                more.iter().product::<i64>()
            ),
            _ => String::new(),
        };
        return Err(format!("expected a 3D volume, got dimensions {dims:?}{why}"));
    }
    if dim[1..4].iter().any(|&n| n < 1 || n > u32::MAX as i64) {
        return Err(format!("bad dimensions {:?}", &dim[1..4]));
    }
    let dims = [dim[1] as usize, dim[2] as usize, dim[3] as usize];
    let scalar = match header.datatype {
        2 => Scalar::U8,
        4 => Scalar::I16,
        8 => Scalar::I32,
        16 => Scalar::F32,
        64 => Scalar::F64,
        256 => Scalar::I8,
        512 => Scalar::U16,
        768 => Scalar::U32,
        1024 => Scalar::I64,
        1280 => Scalar::U64,
        other => {
            return Err(format!("data type {other} is not supported (u8, i8, i16, u16, i32, u32, i64, u64, f32, f64)"))
        }
    };
    let offset = header.vox_offset;
    let smallest = if header.version == 1 { 348.0 } else { 540.0 };
    if !(offset >= smallest) || offset as usize > bytes.len() {
        return Err(format!("bad voxel offset {offset}"));
    }
    let count = dims.iter().try_fold(1usize, |n, &d| n.checked_mul(d)).ok_or("the image's size overflows")?;
    let mut labels = labels(scalar, &bytes[offset as usize..], count, dims[2], little)?;
    // As nifti1_io reads them: a zero or non-finite slope means no scaling, a non-finite intercept 0.
    let (slope, intercept) = (header.scl_slope, header.scl_inter);
    let intercept = if intercept.is_finite() { intercept } else { 0.0 };
    if slope.is_finite() && slope != 0.0 && (slope != 1.0 || intercept != 0.0) {
        for l in labels.iter_mut() {
            let v = *l as f64 * slope + intercept;
            // NIfTI-1 stores slope and intercept in 32 bits: 0.1 is 0.100000001490116, and 40 times
            // it a label to within that precision.
            if (v - v.round()).abs() > SCALED_LABEL_TOLERANCE * (1.0 + v.abs()) {
                return Err(format!("scaled value {v} is not a label (scl_slope {slope}, scl_inter {intercept})"));
            }
            if v.abs() > i32::MAX as f64 {
                return Err(format!("scaled value {v} is beyond 32 bits"));
            }
            *l = v.round() as i32;
        }
    }
    let (qform_code, sform_code) = (header.qform_code, header.sform_code);
    let named_unit = nifti_unit(header.xyzt_units)?;
    let mm_per_unit = named_unit.unwrap_or(LengthUnit::Millimetre).millimetres();
    let (affine, both) = nifti_affine(&header, dims)?;
    let affine = in_millimetres(affine, mm_per_unit);
    let warnings = both
        .map(|(used, apart)| (used, apart * mm_per_unit))
        .filter(|&(_, apart)| apart > FORMS_APART_MM)
        .map(|(used, apart)| {
            let others = match used {
                "sform" => "and nibabel read it; tools that take the qform place it elsewhere",
                _ => "reads it; tools that take the sform whatever its code (nibabel, FSL) place it elsewhere",
            };
            let warning = format!(
                "its sform (code {sform_code}) and qform (code {qform_code}) place the image up to {apart:.1} mm \
                 apart: read by the {used}, as 3D Slicer (ITK) {others}"
            );
            (None, warning)
        })
        .into_iter()
        .chain(negative_spacing_warning(&header).map(|w| (None, w)))
        .collect();
    let placed = qform_code > 0 || sform_code > 0;
    let segments = nifti_label_names(bytes, &header).into_iter().map(|(name, label)| (name, 0, label)).collect();
    Ok(Labelmap { placed, warnings, named_unit, segments, ..Labelmap::single(dims, labels, affine, Frame::Ras) })
}

/// The names a NIfTI's header extensions give its labels: the first extension holding a label
/// table (`<Label Key="5" ...>liver</Label>`, the text as it is or in CDATA), as TotalSegmentator
/// writes its multi-label files (a Caret/Workbench `CaretExtension`).
/// Empty when the file has no such table; an extension cut short ends the search.
fn nifti_label_names(bytes: &[u8], header: &NiftiHeader) -> Vec<(String, i32)> {
    let start = if header.version == 1 { 348 } else { 540 };
    // The extender's first byte says whether extensions follow it.
    if bytes.get(start).is_none_or(|&flag| flag == 0) {
        return Vec::new();
    }
    let end = (header.vox_offset as usize).min(bytes.len());
    let mut at = start + 4;
    while at + 8 <= end {
        let size = int32_at(bytes, at, header.little);
        if size < 8 || at + size as usize > end {
            break;
        }
        let text = String::from_utf8_lossy(&bytes[at + 8..at + size as usize]);
        if text.contains("<LabelTable") {
            return label_table(&text);
        }
        at += size as usize;
    }
    Vec::new()
}

/// The 32-bit integer at `offset` of `bytes`, in the byte order `little` says.
fn int32_at(bytes: &[u8], offset: usize, little: bool) -> i32 {
    let b: [u8; 4] = bytes[offset..offset + 4].try_into().unwrap();
    match little {
        true => i32::from_le_bytes(b),
        false => i32::from_be_bytes(b),
    }
}

/// The `(name, key)` of every `<Label Key="...">name</Label>` of an XML label table.
fn label_table(xml: &str) -> Vec<(String, i32)> {
    let mut names = Vec::new();
    for element in xml.split("<Label").skip(1).filter(|e| e.starts_with(char::is_whitespace)) {
        // The start tag ends at the first '>' outside a quoted value.
        let mut quote = None;
        let Some(end) = element.char_indices().find_map(|(i, c)| {
            match (quote, c) {
                (None, '"' | '\'') => quote = Some(c),
                (Some(q), _) if c == q => quote = None,
                (None, '>') => return Some(i),
                _ => {}
            }
            None
        }) else {
            continue;
        };
        let (attributes, rest) = (&element[..end], &element[end + 1..]);
        let (Some(key), Some((text, _))) = (attribute(attributes, "Key"), rest.split_once("</Label>")) else {
            continue;
        };
        let Ok(key) = key.trim().parse::<i32>() else { continue };
        let text = text.trim();
        let text = text.strip_prefix("<![CDATA[").and_then(|t| t.strip_suffix("]]>")).map_or_else(
            || {
                [("&lt;", "<"), ("&gt;", ">"), ("&quot;", "\""), ("&apos;", "'"), ("&amp;", "&")]
                    .iter()
                    .fold(text.to_string(), |t, (entity, c)| t.replace(entity, c))
            },
            str::to_string,
        );
        if key != 0 && !text.trim().is_empty() {
            names.push((text.trim().to_string(), key));
        }
    }
    names
}

/// The value of attribute `name` among an XML start tag's `attributes` (`name="v"` or
/// `name = 'v'`), the name whole (not the end of another's).
fn attribute<'a>(attributes: &'a str, name: &str) -> Option<&'a str> {
    let mut from = 0;
    while let Some(found) = attributes[from..].find(name).map(|i| from + i) {
        from = found + name.len();
        let whole = attributes[..found].ends_with(char::is_whitespace);
        let rest = attributes[from..].trim_start();
        if let (true, Some(value)) = (whole, rest.strip_prefix('=').map(str::trim_start)) {
            let quote = value.chars().next().filter(|&c| c == '"' || c == '\'')?;
            return value[1..].split(quote).next();
        }
    }
    None
}

/// Whether 3D Slicer (ITK) places a NIfTI's voxels by its sform ([`nifti_affine`]): when its code
/// says scanner coordinates (1), or when there is no qform.
fn placed_by_sform(header: &NiftiHeader) -> bool {
    header.sform_code > 0 && (header.qform_code == 0 || header.sform_code == 1)
}

/// The warning of a NIfTI placed by its spacings (its qform, or no form) of which one is negative:
/// the readers part ways there.
fn negative_spacing_warning(header: &NiftiHeader) -> Option<String> {
    let by_sform = placed_by_sform(header);
    let negative: Vec<String> =
        (1..4).filter(|&d| header.pixdim[d] < 0.0).map(|d| format!("pixdim[{d}] = {}", header.pixdim[d])).collect();
    (!by_sform && !negative.is_empty()).then(|| {
        format!(
            "{} negative: read as 3D Slicer (ITK) reads it, its size with the axis reversed, where FSL (nifti1_io) \
             takes 1 and nibabel its size without reversing it; check where the organ lies, and save the image again \
             with positive spacings",
            negative.join(", ") + if negative.len() > 1 { " are" } else { " is" }
        )
    })
}

/// The unit a NIfTI spatial unit code names (the low three bits of `xyzt_units`): metre, mm,
/// micron; none for an unknown unit (0), which is read as mm, as 3D Slicer and ITK read it.
fn nifti_unit(xyzt_units: u8) -> Result<Option<LengthUnit>, String> {
    match xyzt_units & 0x07 {
        0 => Ok(None),
        1 => Ok(Some(LengthUnit::Metre)),
        2 => Ok(Some(LengthUnit::Millimetre)),
        3 => Ok(Some(LengthUnit::Micrometre)),
        other => Err(format!("spatial unit code {other} in xyzt_units is not a length (1: m, 2: mm, 3: µm)")),
    }
}

/// The voxel-to-world affine of a NIfTI header (of a `dims` image), as 3D Slicer reads it through
/// ITK: the sform when its code says scanner coordinates (1) or there is no qform, otherwise the
/// qform (quaternion, offsets, spacing and qfac), otherwise the spacing alone; and when both are
/// set, which one is read and how far apart (in the file's unit) the two place the image's corners
/// (nibabel and FSL take the sform whatever its code).
fn nifti_affine(header: &NiftiHeader, dims: [usize; 3]) -> Result<([[f64; 4]; 3], Option<FormRead>), String> {
    let (qform_code, sform_code, pixdim) = (header.qform_code, header.sform_code, &header.pixdim);
    let sform = || header.srow;
    let qform = || qform_affine(header);
    let (affine, other) = if placed_by_sform(header) {
        (sform(), (qform_code > 0).then(|| ("sform", qform())))
    } else if qform_code > 0 {
        (qform(), (sform_code > 0).then(|| ("qform", sform())))
    } else {
        (std::array::from_fn(|r| std::array::from_fn(|c| if c == r { pixdim[r + 1] } else { 0.0 })), None)
    };
    check_affine(&affine)?;
    let apart = |other: &[[f64; 4]; 3]| {
        let corners = (0..8)
            .map(|k| std::array::from_fn::<f64, 3, _>(|d| if k >> d & 1 == 1 { dims[d] as f64 - 1.0 } else { 0.0 }));
        let place = |a: &[[f64; 4]; 3], v: [f64; 3]| -> [f64; 3] {
            std::array::from_fn(|r| (0..3).map(|c| a[r][c] * v[c]).sum::<f64>() + a[r][3])
        };
        corners.map(|v| crate::distance(place(&affine, v), place(other, v))).fold(0.0, f64::max)
    };
    Ok((affine, other.map(|(used, other)| (used, apart(&other)))))
}

/// Of a NIfTI with both forms set: the one read ("sform" or "qform") and how far apart (in the
/// file's unit) the two place the image's corners.
type FormRead = (&'static str, f64);

/// How far apart (mm) a NIfTI's sform and qform may place the image's corners before the file is
/// said to be ambiguous: the rounding of the qform's quaternion.
const FORMS_APART_MM: f64 = 0.1;

/// The qform's voxel-to-world affine (quaternion, offsets, spacing and qfac), as ITK makes it.
fn qform_affine(header: &NiftiHeader) -> [[f64; 4]; 3] {
    let [mut b, mut c, mut d] = header.quatern;
    let pixdim = &header.pixdim;
    // As nifti1_io reads it: where b² + c² + d² reaches 1, a = 0 and (b, c, d) is normalised,
    // so that the quaternion is a rotation and leaves the spacing as it is.
    let norm2 = b * b + c * c + d * d;
    let a = if 1.0 - norm2 < 1e-7 {
        let scale = 1.0 / norm2.sqrt();
        (b, c, d) = (b * scale, c * scale, d * scale);
        0.0
    } else {
        (1.0 - norm2).sqrt()
    };
    let rotation = [
        [a * a + b * b - c * c - d * d, 2.0 * (b * c - a * d), 2.0 * (b * d + a * c)],
        [2.0 * (b * c + a * d), a * a + c * c - b * b - d * d, 2.0 * (c * d - a * b)],
        [2.0 * (b * d - a * c), 2.0 * (c * d + a * b), a * a + d * d - b * b - c * c],
    ];
    let qfac = if pixdim[0] < 0.0 { -1.0 } else { 1.0 };
    // As ITK (3D Slicer) reads it: a negative spacing reverses its axis (nifti1_io takes it as 1,
    // nibabel as its size), a zero one is 1.
    let size = |d: usize| if pixdim[d] != 0.0 { pixdim[d] } else { 1.0 };
    let spacing = [size(1), size(2), qfac * size(3)];
    let offset = header.qoffset;
    std::array::from_fn(|r| std::array::from_fn(|c| if c < 3 { rotation[r][c] * spacing[c] } else { offset[r] }))
}

/// Writes a labelmap as a single-file NIfTI-1 (gzipped when the name ends in .gz): 16-bit
/// labels (32-bit when they do not fit), the affine as the sform, code 1 (scanner). Only an
/// RAS labelmap of one layer can be written (NIfTI's world is RAS).
pub fn write_nifti(path: impl AsRef<Path>, map: &Labelmap) -> Result<(), MeshError> {
    let path = path.as_ref();
    let fail = |m: &str| Err(MeshError::Invalid(format!("{}: {m}", path.display())));
    if map.frame != Frame::Ras || map.layers != 1 {
        return fail("NIfTI holds one layer of labels in RAS");
    }
    if map.dims.iter().any(|&n| n == 0 || n > i16::MAX as usize)
        || map.labels.len() != map.dims.iter().product::<usize>()
    {
        return fail("bad dimensions");
    }
    let (data, wide) = label_bytes(&map.labels);
    let mut header = vec![0u8; 352];
    let mut put = |offset: usize, bytes: &[u8]| header[offset..offset + bytes.len()].copy_from_slice(bytes);
    put(0, &348i32.to_le_bytes());
    let dims = [3, map.dims[0] as i16, map.dims[1] as i16, map.dims[2] as i16, 1, 1, 1, 1];
    dims.iter().enumerate().for_each(|(d, n)| put(40 + 2 * d, &n.to_le_bytes()));
    put(70, &(if wide { 8i16 } else { 4i16 }).to_le_bytes());
    put(72, &(if wide { 32i16 } else { 16i16 }).to_le_bytes());
    let spacing = map.spacing();
    let pixdim = [1.0, spacing[0], spacing[1], spacing[2], 1.0, 1.0, 1.0, 1.0];
    pixdim.iter().enumerate().for_each(|(d, x)| put(76 + 4 * d, &(*x as f32).to_le_bytes()));
    put(108, &352f32.to_le_bytes());
    put(112, &1f32.to_le_bytes());
    put(123, &[10]); // xyzt_units: mm and s
    put(254, &1i16.to_le_bytes());
    for r in 0..3 {
        (0..4).for_each(|c| put(280 + 16 * r + 4 * c, &(map.affine[r][c] as f32).to_le_bytes()));
    }
    put(344, b"n+1\0");
    header.extend_from_slice(&data);
    let bytes = match path.to_string_lossy().to_ascii_lowercase().ends_with(".gz") {
        true => gzip(path, &header)?,
        false => header,
    };
    crate::io::write_atomic_bytes(path, &bytes).map_err(MeshError::from)
}
