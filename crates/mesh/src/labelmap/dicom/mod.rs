//! DICOM objects read as labelmaps: Segmentations (DICOM SEG, [`seg`]) and RT Structure Sets
//! (RTSTRUCT, [`rt_struct`]), told apart by their SOP class, and what both readers share.

mod rt_struct;
mod seg;

use std::collections::{BTreeMap, BTreeSet, HashSet};

use dicom_dictionary_std::tags;
use dicom_object::file::ReadPreamble;
use dicom_object::mem::InMemElement;
use dicom_object::meta::FileMetaTableBuilder;
use dicom_object::{DefaultDicomObject, InMemDicomObject, OpenFileOptions};

use super::Labelmap;

/// Positions along the slice normal closer than this (mm) are one slice.
const SAME_SLICE_MM: f64 = 1e-3;

/// Whether the file at `path` is a DICOM file by its content (`DICM` after the 128-byte
/// preamble, or a file without it: [`headless_start`]), whatever its name: PACS and scanners
/// write files without an extension.
pub(super) fn is_dicom_file(path: &std::path::Path) -> bool {
    let mut start = Vec::with_capacity(140);
    std::fs::File::open(path)
        .and_then(|f| std::io::Read::read_to_end(&mut std::io::Read::take(f, 140), &mut start))
        .is_ok()
        && is_dicom(&start)
}

/// Whether `bytes` (a file's start) are DICOM: `DICM` after the preamble, or a file without it
/// ([`headless_start`]).
pub(super) fn is_dicom(bytes: &[u8]) -> bool {
    has_dicom_magic(bytes) || headless_start(bytes).is_some()
}

/// Whether `bytes` (a file's start) hold `DICM` after the 128-byte preamble.
pub(super) fn has_dicom_magic(bytes: &[u8]) -> bool {
    bytes.get(128..132) == Some(b"DICM")
}

/// Where a DICOM file without `DICM` begins in `bytes` (as some archives and toolkits write it:
/// at 0, or after a preamble of zeros), and its first element's group: 0002 for the file meta, or
/// 0008 (the identifying module every data set begins with) for a data set without file meta,
/// little endian; and whether a VR of two capitals follows that first tag (explicit VRs).
fn headless_start(bytes: &[u8]) -> Option<(usize, u8, bool)> {
    [0, 128].into_iter().find_map(|at| {
        let zeros = bytes.get(..at)?.iter().all(|&b| b == 0);
        let head = bytes.get(at..at + 8)?;
        (zeros && matches!(head[..2], [0x02 | 0x08, 0x00]) && head[3] == 0x00)
            .then(|| (at, head[0], head[4..6].iter().all(u8::is_ascii_uppercase)))
    })
}

/// A DICOM file without `DICM` ([`headless_start`]) read as its file would be: its file meta
/// after the missing `DICM`, or its data set in the transfer syntax it is written in (explicit or
/// implicit VR little endian).
fn read_headless(bytes: &[u8]) -> Option<Result<DefaultDicomObject, String>> {
    let (at, group, explicit) = headless_start(bytes)?;
    if group == 0x02 {
        let with_magic = [&[0; 128][..], b"DICM", &bytes[at..]].concat();
        let read = OpenFileOptions::new().read_preamble(ReadPreamble::Always).from_reader(&with_magic[..]);
        return Some(read.map_err(|e| format!("a DICOM file without `DICM` that cannot be read: damaged? ({e})")));
    }
    let syntax = match explicit {
        true => dicom_transfer_syntax_registry::entries::EXPLICIT_VR_LITTLE_ENDIAN.erased(),
        false => dicom_transfer_syntax_registry::entries::IMPLICIT_VR_LITTLE_ENDIAN.erased(),
    };
    let read = || -> Result<DefaultDicomObject, String> {
        let object = InMemDicomObject::read_dataset_with_ts(&bytes[at..], &syntax).map_err(|e| e.to_string())?;
        object.with_meta(FileMetaTableBuilder::new().transfer_syntax(syntax.uid())).map_err(|e| e.to_string())
    };
    Some(read().map_err(|e| {
        format!("a DICOM data set without file meta (no preamble and `DICM`) that cannot be read: damaged? ({e})")
    }))
}

/// Reads a DICOM SEG or RTSTRUCT from the bytes of its file; of an RTSTRUCT, only the structure
/// `wanted` (by number or name) when it names one, on a grid of its own extent.
pub(super) fn parse_dicom(bytes: &[u8], wanted: Option<&str>) -> Result<Labelmap, String> {
    let object = match OpenFileOptions::new().read_preamble(ReadPreamble::Auto).from_reader(bytes) {
        Ok(object) => object,
        Err(e) if has_dicom_magic(bytes) => {
            return Err(format!("a DICOM file that cannot be read: cut short or damaged? ({e})"))
        }
        Err(e) => read_headless(bytes).unwrap_or_else(|| Err(format!("not a DICOM file ({e})")))?,
    };
    let class = text(&object, tags::SOP_CLASS_UID).unwrap_or_default();
    if seg::SEGMENTATION_CLASSES.contains(&class.as_str()) {
        seg::read(&object)
    } else if class == rt_struct::RT_STRUCTURE_SET {
        rt_struct::read(&object, wanted)
    } else {
        let modality = text(&object, tags::MODALITY).unwrap_or_else(|| "unknown".into());
        Err(format!(
            "a DICOM {modality} image (SOP class {class}), not a segmentation: segment it (3D Slicer, \
             TotalSegmentator) and give its DICOM SEG, RTSTRUCT or a labelmap"
        ))
    }
}

/// The spacing of slices at `heights` (mm along their normal, sorted, distinct): `given` when
/// known, else the smallest gap; `None` for a single slice without `given`. An error, naming the
/// `parts` that lie there ("frames", "contours"), when one lies off that spacing's grid.
pub(super) fn slice_step(heights: &[f64], given: Option<f64>, parts: &str) -> Result<Option<f64>, String> {
    let smallest = heights.windows(2).map(|w| w[1] - w[0]).fold(f64::INFINITY, f64::min);
    let Some(step) = given.or(smallest.is_finite().then_some(smallest)) else { return Ok(None) };
    for h in heights {
        let steps = (h - heights[0]) / step;
        if (steps - steps.round()).abs() * step > 0.01 * step.max(SAME_SLICE_MM) {
            return Err(format!(
                "its {parts} do not lie on slices {step} mm apart (one lies {:.3} mm along the normal from the \
                 first): not one volume",
                h - heights[0]
            ));
        }
    }
    Ok(Some(step))
}

/// A segment as [`Labelmap::segments`] lists it: name, layer, label.
type Segment = (String, usize, i32);

/// The segments `names`, their `voxels` each in the first layer of `count` voxels it does not
/// overlap (an empty one in the first): the number of layers, the labels (layer fastest) and the
/// segments' (name, layer, label); a warning for each cut at an end of the slices
/// ([`cut_at_an_end`]) where `series_ends`: the slices may end where the series does (not a SEG
/// whose frames lie on fewer slices than the images it references).
pub(super) fn in_layers(
    names: &BTreeMap<u32, String>,
    voxels: &BTreeMap<u32, Vec<u32>>,
    (count, frame_pixels): (usize, usize),
    series_ends: bool,
    warnings: &mut Vec<(Option<(usize, i32)>, String)>,
) -> (usize, Vec<i32>, Vec<Segment>) {
    let mut layers: Vec<Vec<i32>> = vec![vec![0; count]];
    let mut segments = Vec::new();
    for (&number, name) in names {
        let own = voxels.get(&number).map_or(&[][..], Vec::as_slice);
        let layer = match layers.iter().position(|l| own.iter().all(|&n| l[n as usize] == 0)) {
            Some(layer) => layer,
            None => {
                layers.push(vec![0; count]);
                layers.len() - 1
            }
        };
        own.iter().for_each(|&n| layers[layer][n as usize] = number as i32);
        segments.push((name.clone(), layer, number as i32));
        if let Some(cut) = cut_at_an_end(own, frame_pixels).filter(|_| series_ends) {
            warnings.push((Some((layer, number as i32)), cut));
        }
    }
    let count = layers.len();
    let labels = (0..layers[0].len() * count).map(|n| layers[n % count][n / count]).collect();
    (count, labels, segments)
}

/// Fills, in each segment, the slices between its first and last that no frame or contour of any
/// segment lies on (a slice the series lacks) with the pixels its nearest slices on both sides share;
/// returns those slices.
pub(super) fn fill_missing_slices(
    voxels: &mut BTreeMap<u32, Vec<u32>>,
    present: &BTreeSet<usize>,
    frame_pixels: usize,
) -> Vec<usize> {
    let mut missing = BTreeSet::new();
    for own in voxels.values_mut() {
        let slice = |n: &u32| *n as usize / frame_pixels;
        let (Some(first), Some(last)) = (own.iter().map(slice).min(), own.iter().map(slice).max()) else { continue };
        let gaps: Vec<usize> = (first..=last).filter(|k| !present.contains(k)).collect();
        if gaps.is_empty() {
            continue;
        }
        let mut by_slice: BTreeMap<usize, HashSet<usize>> = BTreeMap::new();
        own.iter().for_each(|&n| {
            by_slice.entry(n as usize / frame_pixels).or_default().insert(n as usize % frame_pixels);
        });
        for &k in &gaps {
            let below = (first..k).rev().find(|s| present.contains(s)).and_then(|s| by_slice.get(&s));
            let above = (k + 1..=last).find(|s| present.contains(s)).and_then(|s| by_slice.get(&s));
            if let (Some(below), Some(above)) = (below, above) {
                own.extend(below.intersection(above).map(|&p| (p + frame_pixels * k) as u32));
            }
            missing.insert(k);
        }
    }
    missing.into_iter().collect()
}

/// The share of its largest slice at or above which a segment's first or last slice says it goes
/// on beyond them: organs taper to their ends.
pub(super) const CUT_SHARE: f64 = 0.5;

/// The share of the slice next to it at or above which an end slice is not tapering: a cut end
/// is as large as its neighbour, a round end (a tumour on coarse slices) smaller.
pub(super) const CUT_NEIGHBOUR_SHARE: f64 = 0.9;

/// A warning when a segment's first or last slice holds [`CUT_SHARE`] of its largest slice's
/// pixels or more and [`CUT_NEIGHBOUR_SHARE`] of its neighbour's: the organ goes on beyond the
/// slices (a scan's end, a segmentation made on part of the series).
pub(super) fn cut_at_an_end(own: &[u32], frame_pixels: usize) -> Option<String> {
    let mut counts: BTreeMap<usize, usize> = BTreeMap::new();
    own.iter().for_each(|&n| *counts.entry(n as usize / frame_pixels).or_default() += 1);
    let largest = *counts.values().max()?;
    let sizes: Vec<usize> = counts.values().copied().collect();
    let (first, last) = (sizes.first()?, sizes.last()?);
    let ends =
        [("first", *first, sizes.get(1)), ("last", *last, sizes.len().checked_sub(2).and_then(|i| sizes.get(i)))];
    let (end, count, _) = ends.into_iter().find(|&(_, count, next)| {
        count as f64 >= CUT_SHARE * largest as f64
            && next.is_some_and(|&n| count as f64 >= CUT_NEIGHBOUR_SHARE * n as f64)
    })?;
    Some(format!(
        "its {end} slice holds {count} pixels, {:.0} % of its largest: the organ seems to go on beyond the slices (cut \
         by the scan's end, or segmented on part of the series)",
        100.0 * count as f64 / largest as f64
    ))
}

/// An attribute's text, trimmed of DICOM's padding; `None` when absent.
pub(super) fn text(object: &InMemDicomObject, tag: dicom_object::Tag) -> Option<String> {
    object.get(tag).and_then(|e| e.to_str().ok()).map(|s| s.trim_matches(|c: char| c == '\0' || c == ' ').to_string())
}

/// An attribute's integer, an error naming it when absent.
pub(super) fn number(object: &InMemDicomObject, tag: dicom_object::Tag) -> Result<u32, String> {
    let element = object.get(tag).ok_or_else(|| format!("it has no {}", name_of(tag)))?;
    element.to_int::<u32>().map_err(|e| format!("{}: {e}", name_of(tag)))
}

/// An attribute's numbers, an error naming it when absent.
pub(super) fn numbers(object: &InMemDicomObject, tag: dicom_object::Tag) -> Result<Vec<f64>, String> {
    let element = object.get(tag).ok_or_else(|| format!("it has no {}", name_of(tag)))?;
    element.to_multi_float64().map_err(|e| format!("{}: {e}", name_of(tag)))
}

/// The name of an attribute the reader needs, for messages.
pub(super) fn name_of(tag: dicom_object::Tag) -> String {
    use dicom_core::DataDictionary as _;
    dicom_dictionary_std::StandardDataDictionary
        .by_tag(tag)
        .map_or_else(|| format!("{tag}"), |entry| entry.alias.to_string())
}

/// The items of a sequence attribute (none when absent).
pub(super) fn items(object: &InMemDicomObject, tag: dicom_object::Tag) -> &[InMemDicomObject] {
    object.get(tag).and_then(InMemElement::items).unwrap_or(&[])
}
