//! DICOM Segmentation objects (DICOM SEG), as TotalSegmentator (`--output_type dicom`),
//! 3D Slicer, MONAI Label and highdicom write them: a multi-frame image whose frames are planes
//! of one segment each (BINARY: one bit per pixel, FRACTIONAL: a byte or two thresholded at half
//! their maximum; LABELMAP: the segment number per pixel), placed by their per-frame
//! `ImagePositionPatient` and the shared (or per-frame) orientation and spacing, in DICOM's
//! patient frame (LPS, mm), uncompressed or RLE Lossless (as highdicom compresses FRACTIONAL and
//! LABELMAP frames). Empty frames may be left out, as writers do; the volume holds one
//! empty slice beyond the first and the last frame (whether the scan went on there cannot be
//! told). Segments may overlap:
//! a segment that overlaps those of a layer goes to a layer of its own, as 3D Slicer's layered
//! segmentations do, so that every segment is read whole.

use std::collections::{BTreeMap, BTreeSet};

use dicom_dictionary_std::tags;
use dicom_object::{DefaultDicomObject, InMemDicomObject};

use super::{fill_missing_slices, in_layers, items, name_of, number, numbers, slice_step, text, SAME_SLICE_MM};
use crate::labelmap::{Frame, Labelmap};
use crate::length::LengthUnit;

/// The SOP class of a Segmentation (and of a Label Map Segmentation).
pub(super) const SEGMENTATION_CLASSES: [&str; 2] = ["1.2.840.10008.5.1.4.1.1.66.4", "1.2.840.10008.5.1.4.1.1.66.7"];

/// Transfer syntaxes whose pixel data are not compressed, in little endian: implicit and explicit
/// VR, and explicit VR deflated.
const NATIVE_SYNTAXES: [&str; 3] = ["1.2.840.10008.1.2", "1.2.840.10008.1.2.1", "1.2.840.10008.1.2.1.99"];

/// RLE Lossless (PS3.5 Annex G), which highdicom writes for FRACTIONAL and LABELMAP frames.
const RLE_LOSSLESS: &str = "1.2.840.10008.1.2.5";

/// Explicit VR big endian, retired: uncompressed, in the other byte order.
const BIG_ENDIAN: &str = "1.2.840.10008.1.2.2";

/// The `frames` frames of RLE Lossless pixel data (a fragment each, PS3.5 G.2: a header of
/// segment offsets, then a PackBits segment per byte of a pixel, the most significant first),
/// as native little-endian pixels of `bits` (8 or 16) bits.
fn rle_frames(fragments: &[Vec<u8>], frames: usize, frame_pixels: usize, bits: usize) -> Result<Vec<u8>, String> {
    if bits != 8 && bits != 16 {
        return Err(format!("RLE frames of {bits} bit(s) per pixel are not read (8 or 16)"));
    }
    if fragments.len() != frames {
        return Err(format!("its RLE pixel data hold {} fragments for {frames} frames", fragments.len()));
    }
    let width = bits / 8;
    let mut data = vec![0_u8; frames * frame_pixels * width];
    for (f, fragment) in fragments.iter().enumerate() {
        let context = |e: String| format!("RLE frame {}: {e}", f + 1);
        let word = |k: usize| fragment.get(4 * k..4 * k + 4).map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]));
        let segments = word(0).ok_or_else(|| context("no header".into()))? as usize;
        if segments != width {
            return Err(context(format!("{segments} segments for pixels of {width} byte(s)")));
        }
        for s in 0..segments {
            let start = word(1 + s).map(|o| o as usize);
            let end = if s + 1 < segments { word(2 + s).map(|o| o as usize) } else { Some(fragment.len()) };
            let coded = start.zip(end).and_then(|(a, b)| fragment.get(a..b));
            let coded = coded.ok_or_else(|| context(format!("segment {} lies outside the fragment", s + 1)))?;
            let bytes = pack_bits(coded, frame_pixels).map_err(context)?;
            // Segment 0 holds the most significant bytes.
            let byte = width - 1 - s;
            for (p, &b) in bytes.iter().enumerate() {
                data[(f * frame_pixels + p) * width + byte] = b;
            }
        }
    }
    Ok(data)
}

/// The number of images the SEG references (its `ReferencedSeriesSequence`'s instances, the slices
/// of the series segmented), 0 when it names none.
fn referenced_images(object: &InMemDicomObject) -> usize {
    let series = items(object, tags::REFERENCED_SERIES_SEQUENCE);
    let instances = series.iter().flat_map(|s| items(s, tags::REFERENCED_INSTANCE_SEQUENCE));
    instances.filter_map(|i| text(i, tags::REFERENCED_SOP_INSTANCE_UID)).collect::<BTreeSet<_>>().len()
}

/// `length` bytes decoded from PackBits: a byte n of 0 to 127 is followed by n + 1 literal
/// bytes, one of −127 to −1 by a byte repeated 1 − n times; −128 is nothing.
fn pack_bits(coded: &[u8], length: usize) -> Result<Vec<u8>, String> {
    let mut out = Vec::with_capacity(length);
    let mut i = 0;
    while i < coded.len() && out.len() < length {
        let n = coded[i] as i8;
        i += 1;
        match n {
            0.. => {
                let literal = coded.get(i..i + n as usize + 1).ok_or("a literal run goes past the segment's end")?;
                out.extend_from_slice(literal);
                i += literal.len();
            }
            -128 => {}
            _ => {
                let byte = *coded.get(i).ok_or("a repeat run goes past the segment's end")?;
                out.extend(std::iter::repeat_n(byte, (1 - isize::from(n)) as usize));
                i += 1;
            }
        }
    }
    if out.len() < length {
        return Err(format!("its segment decodes to {} bytes, {length} expected", out.len()));
    }
    out.truncate(length);
    Ok(out)
}

/// A compressed transfer syntax by name, with its UID.
fn syntax_name(uid: &str) -> String {
    let name = match uid {
        "1.2.840.10008.1.2.5" => "RLE Lossless",
        "1.2.840.10008.1.2.4.50" | "1.2.840.10008.1.2.4.51" => "JPEG",
        "1.2.840.10008.1.2.4.57" | "1.2.840.10008.1.2.4.70" => "JPEG Lossless",
        "1.2.840.10008.1.2.4.80" | "1.2.840.10008.1.2.4.81" => "JPEG-LS",
        "1.2.840.10008.1.2.4.90" | "1.2.840.10008.1.2.4.91" => "JPEG 2000",
        "1.2.840.10008.1.2.4.201" | "1.2.840.10008.1.2.4.202" | "1.2.840.10008.1.2.4.203" => "HTJ2K",
        _ => return format!("transfer syntax {uid}"),
    };
    format!("{name}, transfer syntax {uid}")
}

/// Reads a DICOM SEG (`object`, of one of the [`SEGMENTATION_CLASSES`]).
pub(super) fn read(object: &DefaultDicomObject) -> Result<Labelmap, String> {
    let syntax = object.meta().transfer_syntax().trim_end_matches('\0').to_string();
    if syntax == BIG_ENDIAN {
        return Err("it is written big endian (a retired transfer syntax), which is not read: save it again little \
                    endian (`gdcmconv --raw IN.dcm OUT.dcm`, or pydicom)"
            .into());
    }
    if !NATIVE_SYNTAXES.contains(&syntax.as_str()) && syntax != RLE_LOSSLESS {
        return Err(format!(
            "its pixel data are compressed ({}), which is not read: decompress it first (`gdcmconv --raw IN.dcm \
             OUT.dcm`, DCMTK's `dcmdrle` or `dcmdjpeg`, pydicom's `decompress()`), or export the segmentation \
             uncompressed or as a labelmap",
            syntax_name(&syntax)
        ));
    }
    let rows = number(object, tags::ROWS)? as usize;
    let columns = number(object, tags::COLUMNS)? as usize;
    if rows == 0 || columns == 0 {
        return Err(format!("its frames have {rows} rows of {columns} columns: no pixel"));
    }
    let frames = text(object, tags::NUMBER_OF_FRAMES)
        .map_or(Ok(1), |t| t.trim().parse::<usize>().map_err(|e| format!("NumberOfFrames {t:?}: {e}")))?;
    let kind = text(object, tags::SEGMENTATION_TYPE).unwrap_or_default();
    let bits = number(object, tags::BITS_ALLOCATED)? as usize;
    let planes = planes(object, frames, &kind)?;
    let pixels = object.element(tags::PIXEL_DATA).map_err(|_| "it holds no pixel data".to_string())?;
    let frame_pixels = rows * columns;
    let data = match (pixels.fragments(), syntax == RLE_LOSSLESS) {
        (Some(fragments), true) => std::borrow::Cow::Owned(rle_frames(fragments, frames, frame_pixels, bits)?),
        (None, false) => pixels.to_bytes().map_err(|e| format!("pixel data: {e}"))?,
        _ => return Err(format!("its pixel data do not match its transfer syntax ({})", syntax_name(&syntax))),
    };
    let value = pixel_reader(&kind, bits, &data, frames * frame_pixels, object)?;
    let grid = Grid::new(&planes, object)?;
    let dims = [columns, rows, grid.slices];
    if dims.iter().product::<usize>() > u32::MAX as usize {
        return Err(format!("its volume of {dims:?} voxels is too large to read"));
    }
    // Each segment's voxels (indices into the grid), in one pass over the frames.
    let mut voxels: BTreeMap<u32, Vec<u32>> = BTreeMap::new();
    let mut slices = BTreeSet::new();
    for (f, plane) in planes.iter().enumerate() {
        let k = grid.slice_of(plane.position);
        slices.insert(k);
        for p in 0..frame_pixels {
            let v = value(f * frame_pixels + p);
            if v != 0 {
                voxels.entry(plane.segment.unwrap_or(v)).or_default().push((p + frame_pixels * k) as u32);
            }
        }
    }
    let mut warnings = Vec::new();
    let missing = fill_missing_slices(&mut voxels, &slices, frame_pixels);
    if !missing.is_empty() {
        let at: Vec<String> = missing.iter().map(|&k| format!("{:.1}", grid.height(k))).collect();
        warnings.push((
            None,
            format!(
                "no frame lies {} mm from the first along the slices' normal, between frames {} mm apart: the \
                 series lacks {}; each segment is filled there with what its slices on both sides share",
                at.join(", "),
                crate::length::number(grid.step),
                if missing.len() == 1 { "that slice" } else { "those slices" }
            ),
        ));
    }
    let mut names = segment_names(object)?;
    for &number in voxels.keys() {
        if let std::collections::btree_map::Entry::Vacant(entry) = names.entry(number) {
            entry.insert(format!("segment {number}"));
            warnings.push((None, format!("frames show segment {number}, which the file does not describe")));
        }
    }
    // Writers leave empty frames out: where the file references more images than its frames' slices,
    // the series goes on beyond them, and a segment ending with its frames is not cut by its end.
    let series_ends = referenced_images(object) <= slices.len();
    let (count, labels, segments) =
        in_layers(&names, &voxels, (dims.iter().product(), frame_pixels), series_ends, &mut warnings);
    if voxels.is_empty() {
        return Err("the labelmap is empty: no segment has a pixel in any frame".into());
    }
    Ok(Labelmap {
        dims,
        layers: count,
        labels,
        affine: grid.affine,
        frame: Frame::Lps,
        segments,
        placed: true,
        warnings,
        named_unit: Some(LengthUnit::Millimetre),
    })
}

/// The segments the object describes: segment number to label.
fn segment_names(object: &InMemDicomObject) -> Result<BTreeMap<u32, String>, String> {
    let segments: BTreeMap<u32, String> = items(object, tags::SEGMENT_SEQUENCE)
        .iter()
        .map(|item| {
            let number = number(item, tags::SEGMENT_NUMBER)?;
            Ok((number, text(item, tags::SEGMENT_LABEL).unwrap_or_else(|| format!("segment {number}"))))
        })
        .collect::<Result<_, String>>()?;
    if segments.is_empty() {
        return Err("it describes no segment (its SegmentSequence is empty)".into());
    }
    Ok(segments)
}

/// One frame's plane: where its first pixel lies (mm, LPS), its orientation (the row's and the
/// column's direction) and pixel spacing, and the segment it shows (`None`: a label map's
/// frame, whose pixels hold segment numbers).
struct Plane {
    position: [f64; 3],
    orientation: [f64; 6],
    spacing: [f64; 2],
    segment: Option<u32>,
}

/// A functional group attribute of frame `item`, else of the shared groups.
fn group_value(
    item: &InMemDicomObject,
    shared: Option<&InMemDicomObject>,
    sequence: dicom_object::Tag,
    tag: dicom_object::Tag,
) -> Result<Vec<f64>, String> {
    [Some(item), shared]
        .into_iter()
        .flatten()
        .find_map(|group| items(group, sequence).first().filter(|g| g.get(tag).is_some()))
        .map_or_else(|| Err(format!("no frame nor the shared groups give its {}", name_of(tag))), |g| numbers(g, tag))
}

/// The planes of the `frames` frames, from the per-frame and shared functional groups.
fn planes(object: &InMemDicomObject, frames: usize, kind: &str) -> Result<Vec<Plane>, String> {
    let shared = items(object, tags::SHARED_FUNCTIONAL_GROUPS_SEQUENCE).first();
    let per_frame = items(object, tags::PER_FRAME_FUNCTIONAL_GROUPS_SEQUENCE);
    let placed = |group: &InMemDicomObject| {
        items(group, tags::PLANE_POSITION_SEQUENCE)
            .first()
            .is_some_and(|p| p.get(tags::IMAGE_POSITION_PATIENT).is_some())
    };
    if !shared.is_some_and(placed) && !per_frame.iter().any(placed) {
        return Err("no frame is placed in the patient (no ImagePositionPatient): a segmentation of a 2D image (a \
                    radiograph, a slide), not of a CT or MR volume"
            .into());
    }
    if per_frame.len() != frames {
        return Err(format!("it has {frames} frames but {} per-frame functional groups", per_frame.len()));
    }
    per_frame
        .iter()
        .enumerate()
        .map(|(f, item)| {
            let context = |e: String| format!("frame {}: {e}", f + 1);
            let position = group_value(item, shared, tags::PLANE_POSITION_SEQUENCE, tags::IMAGE_POSITION_PATIENT)
                .map_err(context)?;
            let orientation =
                group_value(item, shared, tags::PLANE_ORIENTATION_SEQUENCE, tags::IMAGE_ORIENTATION_PATIENT)
                    .map_err(context)?;
            let spacing =
                group_value(item, shared, tags::PIXEL_MEASURES_SEQUENCE, tags::PIXEL_SPACING).map_err(context)?;
            let segment = match kind {
                "LABELMAP" => None,
                _ => Some(
                    [Some(item), shared]
                        .into_iter()
                        .flatten()
                        .find_map(|g| items(g, tags::SEGMENT_IDENTIFICATION_SEQUENCE).first())
                        .ok_or_else(|| context("it names no segment (SegmentIdentificationSequence)".into()))
                        .and_then(|g| number(g, tags::REFERENCED_SEGMENT_NUMBER).map_err(context))?,
                ),
            };
            let position: [f64; 3] = position.try_into().map_err(|v: Vec<f64>| {
                context(format!("ImagePositionPatient holds {} numbers, 3 expected", v.len()))
            })?;
            let orientation: [f64; 6] = orientation.try_into().map_err(|v: Vec<f64>| {
                context(format!("ImageOrientationPatient holds {} numbers, 6 expected", v.len()))
            })?;
            let spacing: [f64; 2] = spacing
                .try_into()
                .map_err(|v: Vec<f64>| context(format!("PixelSpacing holds {} numbers, 2 expected", v.len())))?;
            Ok(Plane { position, orientation, spacing, segment })
        })
        .collect()
}

/// The reader of pixel `n` (frames one after the other, rows of `columns` in each): 1 inside a
/// BINARY segment's frame, or a FRACTIONAL frame's value at half its maximum or above, or a
/// LABELMAP's segment number.
fn pixel_reader<'a>(
    kind: &str,
    bits: usize,
    data: &'a [u8],
    count: usize,
    object: &InMemDicomObject,
) -> Result<Box<dyn Fn(usize) -> u32 + 'a>, String> {
    let needed = (count * bits).div_ceil(8);
    if data.len() < needed {
        return Err(format!(
            "its pixel data hold {} bytes, {needed} expected ({count} pixels of {bits} bit(s))",
            data.len()
        ));
    }
    let word = move |n: usize| -> u32 {
        match bits {
            8 => u32::from(data[n]),
            _ => u32::from(u16::from_le_bytes([data[2 * n], data[2 * n + 1]])),
        }
    };
    Ok(match (kind, bits) {
        ("BINARY", 1) => Box::new(move |n| u32::from(data[n / 8] >> (n % 8) & 1)),
        ("FRACTIONAL", 8 | 16) => {
            let most = number(object, tags::MAXIMUM_FRACTIONAL_VALUE)?;
            Box::new(move |n| {
                let value = word(n);
                u32::from(value > 0 && 2 * value >= most)
            })
        }
        ("LABELMAP", 8 | 16) => Box::new(word),
        (kind, bits) => {
            return Err(format!(
                "segmentation type {kind:?} with {bits} bit(s) per pixel is not read (BINARY of 1 bit, FRACTIONAL \
                 or LABELMAP of 8 or 16)"
            ))
        }
    })
}

/// The voxel grid the frames lie on: the affine map of the labelmap and the slices it spans.
struct Grid {
    affine: [[f64; 4]; 3],
    /// The origin's position along the normal, the slice spacing, the normal (mm).
    first: f64,
    step: f64,
    normal: [f64; 3],
    slices: usize,
}

impl Grid {
    /// The grid of `planes`: one orientation and pixel spacing for all, slices a whole number of
    /// steps apart along their normal (`SpacingBetweenSlices` when given, else the smallest gap).
    fn new(planes: &[Plane], object: &InMemDicomObject) -> Result<Grid, String> {
        let first = planes.first().ok_or("it has no frame")?;
        for plane in planes {
            let apart = (0..6).map(|i| (plane.orientation[i] - first.orientation[i]).abs()).fold(0.0, f64::max);
            if apart > 1e-4 || (0..2).any(|i| (plane.spacing[i] - first.spacing[i]).abs() > 1e-4) {
                return Err("its frames have different orientations or pixel spacings: not one volume".into());
            }
        }
        let o = first.orientation;
        let (row, column) = ([o[0], o[1], o[2]], [o[3], o[4], o[5]]);
        let normal = crate::cross(row, column);
        let length = crate::norm(normal);
        if !(length > 0.5) {
            return Err(format!("ImageOrientationPatient {o:?} is not two orthogonal unit vectors"));
        }
        let normal = normal.map(|c| c / length);
        let along = |p: [f64; 3]| crate::dot(p, normal);
        let mut heights: Vec<f64> = planes.iter().map(|p| along(p.position)).collect();
        heights.sort_by(f64::total_cmp);
        heights.dedup_by(|a, b| (*a - *b).abs() < SAME_SLICE_MM);
        let between = items(object, tags::SHARED_FUNCTIONAL_GROUPS_SEQUENCE)
            .first()
            .and_then(|g| items(g, tags::PIXEL_MEASURES_SEQUENCE).first())
            .and_then(|m| m.get(tags::SPACING_BETWEEN_SLICES))
            .and_then(|e| e.to_float64().ok())
            .filter(|s| *s > 0.0);
        let step = slice_step(&heights, between, "frames")?.unwrap_or(1.0);
        let (lowest, highest) = (heights[0], heights[heights.len() - 1]);
        // One empty slice beyond each end: frames are written where segments are (writers leave
        // the empty ones out), so the ends are not where the image ends.
        let (lowest, highest) = (lowest - step, highest + step);
        let slices = ((highest - lowest) / step).round() as usize + 1;
        // The origin: the first frame's position moved along the normal to the lowest slice.
        let shift = lowest - along(first.position);
        let origin: [f64; 3] = std::array::from_fn(|d| first.position[d] + shift * normal[d]);
        // Check that every frame's first pixel lies on the grid's column of the origin.
        for plane in planes {
            let offset = crate::sub(plane.position, origin);
            let sideways = crate::norm(crate::sub(offset, normal.map(|c| c * crate::dot(offset, normal))));
            if sideways > 0.01 * first.spacing[0].min(first.spacing[1]) {
                return Err("its frames are shifted within their planes: not one volume".into());
            }
        }
        let [row_spacing, column_spacing] = first.spacing;
        let affine =
            std::array::from_fn(|r| [row[r] * column_spacing, column[r] * row_spacing, normal[r] * step, origin[r]]);
        Ok(Grid { affine, first: lowest, step, normal, slices })
    }

    /// The height of slice `k` along the normal from the first frame's (mm).
    fn height(&self, k: usize) -> f64 {
        (k as f64 - 1.0) * self.step
    }

    /// The slice a frame at `position` lies in.
    fn slice_of(&self, position: [f64; 3]) -> usize {
        ((crate::dot(position, self.normal) - self.first) / self.step).round() as usize
    }
}

#[cfg(test)]
mod tests {
    use dicom_core::value::DataSetSequence;
    use dicom_core::{DataElement, PrimitiveValue, VR};
    use dicom_object::mem::InMemElement;
    use dicom_object::meta::FileMetaTableBuilder;

    use super::*;
    use crate::labelmap::dicom::parse_dicom;
    use dicom_object::OpenFileOptions;
    use dicom_transfer_syntax_registry::entries;

    /// An element of `vr` holding `text` (several values separated by `\`).
    fn text_element(tag: dicom_object::Tag, vr: VR, text: &str) -> InMemElement {
        DataElement::new(tag, vr, PrimitiveValue::from(text))
    }

    /// A sequence of one item holding `elements`.
    fn sequence(tag: dicom_object::Tag, elements: Vec<InMemElement>) -> InMemElement {
        DataElement::new(tag, VR::SQ, DataSetSequence::from(vec![InMemDicomObject::from_element_iter(elements)]))
    }

    /// A DICOM SEG file of 4 × 4 pixel frames, 1 mm apart in plane, each frame (its segment, its
    /// height z in mm; NaN: not placed, as a radiograph's or a slide's) in a plane of normal +z;
    /// `pixels` bit-packed (BINARY) or a byte each.
    fn seg_file(class: &str, kind: &str, frames: &[(u32, f64)], bits: u16, pixels: Vec<u8>) -> Vec<u8> {
        seg_file_of_series(class, kind, frames, bits, pixels, 0)
    }

    /// [`seg_file`], referencing `referenced` images of the series segmented.
    fn seg_file_of_series(
        class: &str,
        kind: &str,
        frames: &[(u32, f64)],
        bits: u16,
        pixels: Vec<u8>,
        referenced: usize,
    ) -> Vec<u8> {
        let per_frame = frames
            .iter()
            .map(|&(segment, z)| {
                let position = sequence(
                    tags::PLANE_POSITION_SEQUENCE,
                    vec![text_element(tags::IMAGE_POSITION_PATIENT, VR::DS, &format!("10\\20\\{z}"))],
                );
                let identification = sequence(
                    tags::SEGMENT_IDENTIFICATION_SEQUENCE,
                    vec![DataElement::new(
                        tags::REFERENCED_SEGMENT_NUMBER,
                        VR::US,
                        PrimitiveValue::from(segment as u16),
                    )],
                );
                InMemDicomObject::from_element_iter(
                    z.is_finite().then_some(position).into_iter().chain([identification]),
                )
            })
            .collect::<Vec<_>>();
        let segment = |number: u16, label: &str| {
            InMemDicomObject::from_element_iter([
                DataElement::new(tags::SEGMENT_NUMBER, VR::US, PrimitiveValue::from(number)),
                text_element(tags::SEGMENT_LABEL, VR::LO, label),
            ])
        };
        let mut object = InMemDicomObject::from_element_iter([
            text_element(tags::SOP_CLASS_UID, VR::UI, class),
            text_element(tags::SOP_INSTANCE_UID, VR::UI, "2.25.1"),
            text_element(tags::MODALITY, VR::CS, if class == SEGMENTATION_CLASSES[0] { "SEG" } else { "CT" }),
            text_element(tags::SEGMENTATION_TYPE, VR::CS, kind),
            DataElement::new(tags::ROWS, VR::US, PrimitiveValue::from(4_u16)),
            DataElement::new(tags::COLUMNS, VR::US, PrimitiveValue::from(4_u16)),
            DataElement::new(tags::BITS_ALLOCATED, VR::US, PrimitiveValue::from(bits)),
            text_element(tags::NUMBER_OF_FRAMES, VR::IS, &frames.len().to_string()),
            DataElement::new(
                tags::SEGMENT_SEQUENCE,
                VR::SQ,
                DataSetSequence::from(vec![segment(1, "liver"), segment(2, "tumour")]),
            ),
            sequence(
                tags::SHARED_FUNCTIONAL_GROUPS_SEQUENCE,
                vec![
                    sequence(
                        tags::PLANE_ORIENTATION_SEQUENCE,
                        vec![text_element(tags::IMAGE_ORIENTATION_PATIENT, VR::DS, "1\\0\\0\\0\\1\\0")],
                    ),
                    sequence(tags::PIXEL_MEASURES_SEQUENCE, vec![text_element(tags::PIXEL_SPACING, VR::DS, "1\\1")]),
                ],
            ),
            DataElement::new(tags::PER_FRAME_FUNCTIONAL_GROUPS_SEQUENCE, VR::SQ, DataSetSequence::from(per_frame)),
            DataElement::new(tags::PIXEL_DATA, if bits == 1 { VR::OB } else { VR::OW }, PrimitiveValue::from(pixels)),
        ]);
        if referenced > 0 {
            let image = |i: usize| {
                InMemDicomObject::from_element_iter([text_element(
                    tags::REFERENCED_SOP_INSTANCE_UID,
                    VR::UI,
                    &format!("2.25.{}", 100 + i),
                )])
            };
            let instances = DataSetSequence::from((0..referenced).map(image).collect::<Vec<_>>());
            let series = InMemDicomObject::from_element_iter([DataElement::new(
                tags::REFERENCED_INSTANCE_SEQUENCE,
                VR::SQ,
                instances,
            )]);
            object.put(DataElement::new(tags::REFERENCED_SERIES_SEQUENCE, VR::SQ, DataSetSequence::from(vec![series])));
        }
        let file = object.with_meta(FileMetaTableBuilder::new().transfer_syntax("1.2.840.10008.1.2.1")).unwrap();
        let mut bytes = Vec::new();
        file.write_all(&mut bytes).unwrap();
        bytes
    }

    const SEG: &str = SEGMENTATION_CLASSES[0];

    /// A whole 4 × 4 frame of segment 1 at z = 0 and z = 2 (two slices of 2 mm), and one pixel
    /// (row 1, column 2) of segment 2 inside it at z = 2, in frames of 16 bits each.
    fn liver_and_tumour() -> Vec<u8> {
        let tumour_pixel = 4 + 2;
        seg_file(SEG, "BINARY", &[(1, 0.0), (1, 2.0), (2, 2.0)], 1, vec![0xff, 0xff, 0xff, 0xff, 1 << tumour_pixel, 0])
    }

    /// A SEG stored as its data set alone (no preamble, `DICM` or file meta), in explicit or
    /// implicit VR, or after a preamble of zeros, or with its file meta but no `DICM`, reads as
    /// its Part 10 file does; a damaged one says what it is.
    #[test]
    fn a_data_set_without_file_meta_reads_as_its_file() {
        let file = liver_and_tumour();
        let whole = parse_dicom(&file, None).unwrap();
        let object = OpenFileOptions::new().from_reader(&file[..]).unwrap();
        for syntax in [entries::EXPLICIT_VR_LITTLE_ENDIAN.erased(), entries::IMPLICIT_VR_LITTLE_ENDIAN.erased()] {
            let mut raw = Vec::new();
            object.write_dataset_with_ts(&mut raw, &syntax).unwrap();
            assert_eq!(parse_dicom(&raw, None).unwrap(), whole, "{}", syntax.name());
            assert!(crate::labelmap::dicom::is_dicom(&raw), "recognised by its content");
            let zeros = [vec![0; 128], raw.clone()].concat();
            assert_eq!(parse_dicom(&zeros, None).unwrap(), whole, "{} after zeros", syntax.name());
            let e = parse_dicom(&raw[..raw.len() / 2], None).unwrap_err();
            assert!(e.contains("a DICOM data set without file meta") && e.contains("cannot be read"), "{e}");
        }
        assert!(parse_dicom(b"hello, not DICOM at all", None).unwrap_err().starts_with("not a DICOM file"));
        // A file whose preamble is there but not `DICM`.
        let without_magic = [&file[..128], &file[132..]].concat();
        assert_eq!(parse_dicom(&without_magic, None).unwrap(), whole);
    }

    #[test]
    fn overlapping_segments_are_read_whole_in_layers_of_their_own() {
        let map = parse_dicom(&liver_and_tumour(), None).unwrap();
        assert_eq!((map.dims, map.layers), ([4, 4, 4], 2), "two slices and an empty one beyond each");
        assert_eq!(map.segments, [("liver".to_string(), 0, 1), ("tumour".to_string(), 1, 2)]);
        // i along x by 1 mm, j along y by 1 mm, k along z by 2 mm, from the first pixel.
        assert_eq!(map.affine, [[1.0, 0.0, 0.0, 10.0], [0.0, 1.0, 0.0, 20.0], [0.0, 0.0, 2.0, -2.0]]);
        assert_eq!(map.select("liver").unwrap().0.count(), 32, "the liver keeps the voxel the tumour takes");
        let (tumour, _) = map.select("tumour").unwrap();
        assert_eq!(tumour.count(), 1);
        let at = tumour.inside.iter().position(|&b| b).unwrap();
        let [nx, ny, _] = tumour.dims;
        let ijk = [at % nx, (at / nx) % ny, at / (nx * ny)].map(|c| c as f64);
        let world: [f64; 3] =
            std::array::from_fn(|r| (0..3).map(|c| tumour.affine[r][c] * ijk[c]).sum::<f64>() + tumour.affine[r][3]);
        assert_eq!(world, [12.0, 21.0, 2.0], "column 2, row 1 of the slice at z = 2");
    }

    /// Warnings of `map` for the segment `number` and for all.
    fn warnings(map: &Labelmap, number: i32) -> Vec<&str> {
        map.warnings.iter().filter(|(of, _)| of.is_none_or(|(_, l)| l == number)).map(|(_, w)| w.as_str()).collect()
    }

    /// A slice that no frame lies on between the frames of a segment is one the series lacks:
    /// filled with what the slices on both sides share, and said.
    #[test]
    fn a_slice_missing_from_the_series_is_filled_and_named() {
        // Frames 2 mm apart at z = 0, 2 and 6: none at 4. The frame at 6 holds the first row only.
        let pixels = vec![0xff, 0xff, 0xff, 0xff, 0x0f, 0x00];
        let map = parse_dicom(&seg_file(SEG, "BINARY", &[(1, 0.0), (1, 2.0), (1, 6.0)], 1, pixels), None).unwrap();
        let (liver, _) = map.select("liver").unwrap();
        assert_eq!(liver.count(), 16 + 16 + 4 + 4, "the slice at z = 4 takes the row both sides share");
        let said = warnings(&map, 1);
        assert!(
            said.iter().any(|w| w.starts_with("no frame lies 4.0 mm from the first along the slices' normal")),
            "{said:?}"
        );
    }

    /// A segment whose end slices are as large as its largest goes on beyond the frames; one that
    /// tapers does not.
    #[test]
    fn a_segment_cut_at_the_end_of_the_frames_is_said_to_be() {
        let map = parse_dicom(&liver_and_tumour(), None).unwrap();
        assert!(warnings(&map, 1)
            .iter()
            .any(|w| w.starts_with("its first slice holds 16 pixels, 100 % of its largest")));
        // Three slices of 1, 16 and 1 pixels: a tapering organ.
        let pixels = vec![0x01, 0x00, 0xff, 0xff, 0x01, 0x00];
        let map = parse_dicom(&seg_file(SEG, "BINARY", &[(1, 0.0), (1, 2.0), (1, 4.0)], 1, pixels), None).unwrap();
        assert!(map.warnings.is_empty(), "{:?}", map.warnings);
    }

    /// A segment whose end slices are as large as its largest but whose frames lie on fewer slices
    /// than the series it references (writers leave empty frames out) is not said to be cut; one
    /// whose frames lie on every referenced image is.
    #[test]
    fn a_segment_ending_inside_the_series_referenced_is_not_said_to_be_cut() {
        let frames = [(1, 0.0), (1, 2.0), (2, 2.0)];
        let pixels = vec![0xff, 0xff, 0xff, 0xff, 1 << 6, 0];
        let map = parse_dicom(&seg_file_of_series(SEG, "BINARY", &frames, 1, pixels.clone(), 81), None).unwrap();
        assert!(map.warnings.is_empty(), "{:?}", map.warnings);
        let map = parse_dicom(&seg_file_of_series(SEG, "BINARY", &frames, 1, pixels, 2), None).unwrap();
        assert!(warnings(&map, 1).iter().any(|w| w.contains("seems to go on beyond the slices")), "{:?}", map.warnings);
    }

    /// A described segment no frame shows is named and empty; frames of a segment the file does not
    /// describe are read as `segment N`, and said.
    #[test]
    fn empty_and_undescribed_segments_are_told_apart() {
        let map =
            parse_dicom(&seg_file(SEG, "BINARY", &[(1, 0.0), (3, 0.0)], 1, vec![0xff, 0xff, 0x01, 0]), None).unwrap();
        let tumour = map.select("tumour").unwrap_err().to_string();
        assert!(tumour.contains("label 2 ('tumour') has no voxel"), "{tumour}");
        assert_eq!(map.select("segment 3").unwrap().0.count(), 1);
        assert!(warnings(&map, 3).contains(&"frames show segment 3, which the file does not describe"));
    }

    #[test]
    fn a_labelmap_segmentation_holds_segment_numbers() {
        let mut pixels = vec![0u8; 32];
        pixels[5] = 1;
        pixels[16 + 6] = 2;
        let frames = [(0, 0.0), (0, 3.0)];
        let map = parse_dicom(&seg_file(SEGMENTATION_CLASSES[1], "LABELMAP", &frames, 8, pixels), None).unwrap();
        assert_eq!((map.dims, map.layers, map.spacing()), ([4, 4, 4], 1, [1.0, 1.0, 3.0]));
        assert_eq!(map.present().iter().map(|p| (p.1, p.2)).collect::<Vec<_>>(), [(1, 1), (2, 1)]);
    }

    /// PackBits as Apple's technical note gives it, and RLE frames of two segments (16 bits).
    #[test]
    fn rle_segments_decode() {
        let coded = [0xfe, 0xaa, 0x02, 0x80, 0x00, 0x2a, 0xfd, 0xaa, 0x03, 0x80, 0x00, 0x2a, 0x22, 0xf7, 0xaa];
        let mut expected = vec![0xaa, 0xaa, 0xaa, 0x80, 0x00, 0x2a, 0xaa, 0xaa, 0xaa, 0xaa, 0x80, 0x00, 0x2a, 0x22];
        expected.extend([0xaa; 10]);
        assert_eq!(pack_bits(&coded, 24).unwrap(), expected);
        assert!(pack_bits(&coded[..14], 24).unwrap_err().contains("past the segment's end"));
        assert!(pack_bits(&coded, 30).unwrap_err().contains("decodes to 24 bytes, 30 expected"));
        // Two pixels of 16 bits: 0x0102 and 0x0304; the high bytes first, each a literal run.
        let mut fragment = vec![0_u8; 64];
        fragment[..4].copy_from_slice(&2_u32.to_le_bytes());
        fragment[4..8].copy_from_slice(&64_u32.to_le_bytes());
        fragment[8..12].copy_from_slice(&67_u32.to_le_bytes());
        fragment.extend([1, 0x01, 0x03, 1, 0x02, 0x04]);
        assert_eq!(rle_frames(&[fragment.clone()], 1, 2, 16).unwrap(), [0x02, 0x01, 0x04, 0x03]);
        assert!(rle_frames(&[fragment.clone()], 1, 2, 8).unwrap_err().contains("2 segments for pixels of 1 byte"));
        assert!(rle_frames(&[fragment], 2, 2, 16).unwrap_err().contains("1 fragments for 2 frames"));
    }

    #[test]
    fn what_is_not_one_segmented_volume_is_refused_by_name() {
        let error = |bytes: Vec<u8>| parse_dicom(&bytes, None).unwrap_err();
        let ct = error(seg_file("1.2.840.10008.5.1.4.1.1.2", "BINARY", &[(1, 0.0)], 1, vec![0xff, 0xff]));
        assert!(ct.starts_with("a DICOM CT image (SOP class 1.2.840.10008.5.1.4.1.1.2), not a segmentation"), "{ct}");
        // Slices 0, 2 and 3 mm high are slices 1 mm apart, one empty; 0, 2 and 3.5 mm are no grid.
        let off = error(seg_file(SEG, "BINARY", &[(1, 0.0), (1, 2.0), (1, 3.5)], 1, vec![0xff; 6]));
        assert!(off.starts_with("its frames do not lie on slices 1.5 mm apart"), "{off}");
        let short = error(seg_file(SEG, "BINARY", &[(1, 0.0), (1, 2.0)], 1, vec![0xff; 2]));
        assert!(short.contains("pixel data hold 2 bytes, 4 expected"), "{short}");
        let flat = error(seg_file(SEG, "BINARY", &[(1, f64::NAN), (1, f64::NAN)], 1, vec![0xff; 4]));
        assert!(flat.starts_with("no frame is placed in the patient") && flat.contains("2D image"), "{flat}");
        let fractional = error(seg_file(SEG, "FRACTIONAL", &[(1, 0.0)], 8, vec![255; 16]));
        assert!(fractional.contains("MaximumFractionalValue"), "{fractional}");
        assert!(error(vec![0; 200]).starts_with("not a DICOM file"));
        let whole = liver_and_tumour();
        let cut = error(whole[..whole.len() * 7 / 10].to_vec());
        assert!(cut.starts_with("a DICOM file that cannot be read: cut short or damaged?"), "{cut}");
        assert_eq!(syntax_name("1.2.840.10008.1.2.4.90"), "JPEG 2000, transfer syntax 1.2.840.10008.1.2.4.90");
        assert_eq!(syntax_name(BIG_ENDIAN), format!("transfer syntax {BIG_ENDIAN}"), "not a compression");
    }
}
