//! An organ's closed surface from a labelmap's label, with what a user should know of it: the
//! extraction's repairs, a file that places its voxels nowhere, an organ cut by the image's border.

use std::path::Path;

use super::{in_millimetres, read_labelmap_choosing, Frame};
use crate::isosurface::{mask_surface, ExtractOptions, ExtractReport};
use crate::length::LengthUnit;
use crate::volume::VoxelMask;
use crate::{MeshError, TriSurface};

/// An organ's surface extracted from a labelmap ([`read_labelmap_surface`]).
#[derive(Clone, Debug, PartialEq)]
pub struct LabelSurface {
    /// The closed surface, in millimetres in the labelmap's world frame.
    pub surface: TriSurface,
    /// The world frame.
    pub frame: Frame,
    /// The label chosen, e.g. "label 5 ('liver')".
    pub label: String,
    /// The voxel size along i, j, k (mm).
    pub spacing: [f64; 3],
    /// The label's voxels as the file gives them, all its pieces ([`LabelSurface::extract`] counts
    /// those kept).
    pub label_voxels: usize,
    /// What the extraction did.
    pub extract: ExtractReport,
    /// Whether the file places its voxels in the scanner's frame ([`super::Labelmap::placed`]).
    pub placed: bool,
    /// What a user should know of the organ as read, a line each: a file that places its voxels
    /// nowhere, an organ cut by the image's border.
    pub warnings: Vec<String>,
}

impl LabelSurface {
    /// The scanner's frame the surface is in; `None` when the file places its voxels nowhere.
    pub fn scanner_frame(&self) -> Option<Frame> {
        self.placed.then_some(self.frame)
    }

    /// What was read and extracted, one line each.
    pub fn lines(&self) -> Vec<String> {
        let e = &self.extract;
        let [a, b, c] = self.spacing;
        let frame = match self.placed {
            true => format!("in the scanner's {} frame (mm)", self.frame.name()),
            false => "at its voxel indices times the spacing (mm; no scanner frame)".to_string(),
        };
        let added: Vec<String> = [(e.filled_voxels, "of cavities filled"), (e.closed_voxels, "closing gaps")]
            .into_iter()
            .filter(|&(n, _)| n > 0)
            .map(|(n, what)| format!("{n} {what}"))
            .collect();
        let own = e.voxels - e.filled_voxels - e.closed_voxels;
        // The piece kept, where the label's others were dropped.
        let (all, added) = (self.label_voxels, added.join(", "));
        let voxels = match (e.dropped_pieces.is_empty(), added.is_empty()) {
            (true, true) => format!("{} voxels", e.voxels),
            (true, false) => format!("{} voxels ({own} its own, {added})", e.voxels),
            (false, true) => format!("{own} of its {all} voxels (its largest piece)"),
            (false, false) => format!("{} voxels ({own} of its {all}, its largest piece; {added})", e.voxels),
        };
        let mut lines = vec![format!("{}: {voxels} of {a:.2} × {b:.2} × {c:.2} mm, {frame}", self.label)];
        lines.extend(e.cleaning_lines());
        lines.push(format!(
            "surface: {} triangles (decimated from {}), {}",
            self.surface.triangles.len(),
            e.extracted_triangles,
            e.volume_text(Some(LengthUnit::Millimetre))
        ));
        lines
    }
}

/// Reads a labelmap and extracts the closed surface of one label (a number, or a segment name
/// the file carries), in millimetres in the file's world frame. Without a label, the file must
/// hold only one. `unit` is the world's unit where the header names none (read as mm without
/// it); one other than the unit the header names overrides it, with a warning (a header that
/// names metres for millimetres).
pub fn read_labelmap_surface(
    path: impl AsRef<Path>,
    label: Option<&str>,
    unit: Option<LengthUnit>,
    options: &ExtractOptions,
) -> Result<LabelSurface, MeshError> {
    let path = path.as_ref();
    let mut map = read_labelmap_choosing(path, label)?;
    let mut overridden = None;
    match (unit, map.named_unit) {
        (Some(given), Some(named)) if given != named => {
            map.affine = in_millimetres(map.affine, given.millimetres() / named.millimetres());
            map.named_unit = Some(given);
            overridden = Some(format!(
                "its header names its unit, {}; read in {} as given instead (--units): {} than the header makes it",
                named.name(),
                given.name(),
                crate::length::UnitMistake { given, expected: named }.undone_words()
            ));
        }
        (Some(given), None) => {
            map.affine = in_millimetres(map.affine, given.millimetres());
            map.named_unit = Some(given);
        }
        _ => {}
    }
    let present = map.present();
    let label = match (label, &present[..]) {
        (Some(label), _) => label.to_string(),
        (None, [(_, only, _, _)]) => only.to_string(),
        (None, _) => {
            return Err(MeshError::parse(
                path,
                format!("holds several labels: choose one with --label (labels present: {})", map.present_text()),
            ))
        }
    };
    let (whole, label, chosen) = map.select_uncropped(&label).map_err(|e| MeshError::parse(path, e.message()))?;
    let filled = whole.count() as f64 / whole.inside.len().max(1) as f64;
    if filled > FILLED_SHARE {
        return Err(MeshError::parse(
            path,
            format!(
                "{label} fills {:.0} % of the image: a mask of everything (an inverted or all-ones labelmap, the \
                 background's label?), not an organ; labels present: {}",
                100.0 * filled,
                map.present_text()
            ),
        ));
    }
    let borders = touched_borders(&whole, map.placed.then_some(map.frame));
    let label_voxels = whole.count();
    let mask = map.cropped(&whole, &label, chosen).map_err(|e| MeshError::parse(path, e.message()))?;
    let mask = mask.in_scanner_order(map.frame == Frame::Ras);
    let (surface, extract) = mask_surface(&mask, options).map_err(|e| MeshError::parse(path, e.message()))?;
    let mut warnings: Vec<String> =
        map.warnings.iter().filter(|(of, _)| of.is_none_or(|of| of == chosen)).map(|(_, w)| w.clone()).collect();
    warnings.extend(overridden.iter().cloned());
    if !map.placed {
        warnings.push(
            "the file places its voxels nowhere (a NIfTI without qform and sform, a NRRD with spacings but no space \
             directions): the organ lies at its voxel indices times the spacing, not where the CT lies in the scanner's \
             frame"
                .to_string(),
        );
    }
    if !borders.is_empty() {
        warnings.push(format!(
            "the organ reaches the image's border ({}): it is cut there, flat where the image ends",
            borders.join(", ")
        ));
    }
    warnings.extend(extraction_warnings(&extract));
    let span = crate::longest_side(crate::bounds(&surface.vertices));
    if !(ORGAN_SPAN_MM.0..=ORGAN_SPAN_MM.1).contains(&span) {
        let unit = match map.named_unit {
            Some(unit) if overridden.is_some() => format!("in the unit given, {}", unit.name()),
            Some(unit) => {
                // The unit in which the header's numbers would make an organ's size, if any.
                let fits = [LengthUnit::Millimetre, LengthUnit::Centimetre, LengthUnit::Metre, LengthUnit::Micrometre]
                    .into_iter()
                    .find(|&other| {
                        (ORGAN_SPAN_MM.0..=ORGAN_SPAN_MM.1).contains(&(span / unit.millimetres() * other.millimetres()))
                    });
                match fits {
                    Some(other) => format!(
                        "in the unit it names, {}; read in {} they make an organ's size: --units {} says so",
                        unit.name(),
                        other.name(),
                        other.symbol()
                    ),
                    None => format!("in the unit it names, {}", unit.name()),
                }
            }
            None => "it names no unit, so they are read as mm: give the unit (--units) if it is another".into(),
        };
        warnings.push(format!(
            "the organ spans {} mm, no organ's size: its voxels are {} mm as the file's header gives them ({unit}); \
             is that their size?",
            crate::length::number(span),
            map.spacing().map(crate::length::number).join(" × ")
        ));
    }
    let placed = map.placed;
    let spacing = map.spacing();
    Ok(LabelSurface { surface, frame: map.frame, label, spacing, label_voxels, extract, placed, warnings })
}

/// What the extraction of a label's surface did to its voxels that a user should know: gaps
/// closed, pieces dropped, volume lost to the smoothing.
fn extraction_warnings(extract: &ExtractReport) -> Vec<String> {
    let mut warnings = Vec::new();
    if extract.closed_voxels > 0 {
        warnings.push(format!(
            "the surface of its voxels as given overlapped itself (voxels that touch by an edge or a corner only: a \
             checkerboard, a brush's dithering): it was extracted with gaps of a voxel closed, {:.1} % of its voxels \
             added; smooth the segment if that is not the organ",
            100.0 * extract.closed_voxels as f64 / (extract.voxels - extract.closed_voxels).max(1) as f64
        ));
    }
    if extract.dropped_share() > DROPPED_SHARE {
        warnings.push(format!(
            "pieces apart from the organ's largest, {:.1} % of its voxels, were dropped: if they are part of it (a \
             lobe the segmentation cut off, by a gap as thin as a voxel), join them to it in the segmentation (a \
             closing or a brush stroke across the gap)",
            100.0 * extract.dropped_share()
        ));
    }
    let lost = 1.0 - extract.volume / extract.voxel_volume;
    if lost > THINNED_SHARE {
        warnings.push(format!(
            "its surface holds {:.0} % less than its voxels: a structure a voxel or two thick (a vessel, a thin \
             segment) is thinned by the surface's smoothing; one drawn on a single slice has no thickness to keep",
            100.0 * lost
        ));
    }
    warnings
}

/// The share of the kept piece's voxels that the pieces dropped apart from it may hold before
/// a warning: specks of a segmentation hold well under it; a lobe cut off by a gap of a voxel
/// (4 % of a liver in a tester's case) is over it.
const DROPPED_SHARE: f64 = 0.01;

/// The share of its image a label may fill before it is refused as no organ: an organ's segment
/// cropped to it (3D Slicer's) fills a half to two thirds of its box.
const FILLED_SHARE: f64 = 0.9;

/// The span (mm) of a structure a labelmap may give without a warning: a few millimetres (a small
/// tumour) to a metre; outside, the header's unit or voxel size is likely wrong.
const ORGAN_SPAN_MM: (f64, f64) = (3.0, 1000.0);

/// The share of an organ's largest slice under which a slice at the image's face is its tip, not
/// a cut (a voxel or two, whatever the slice next to it holds).
const TIP_SHARE: f64 = 0.1;

/// The share of its voxels' volume a surface may lose before it is said to be thinned (an organ
/// loses about 1 %, a 14 mm tumour on 5 mm slices 7 %).
const THINNED_SHARE: f64 = 0.2;

/// The faces of the image where the mask's organ is cut, as `i = 0, left`, `k = 63, superior`
/// (the side of the patient the face looks to, in `frame`, the scanner's when the file places its
/// voxels there): faces it reaches
/// with a slice that holds [`super::dicom::CUT_SHARE`] of its largest slice's voxels, or that does not
/// taper (as large as [`super::dicom::CUT_NEIGHBOUR_SHARE`] of the slice next to it) and is more than
/// its tip ([`TIP_SHARE`] of the largest), or that is more than its tip in an image that leaves
/// empty slices beyond four of its faces or more (not cropped to the organ, as a CT's grid). An
/// organ whole in an image cropped to it, as 3D Slicer saves a segmentation, tapers to each face
/// it touches; one the field of view cuts does not.
fn touched_borders(mask: &VoxelMask, frame: Option<Frame>) -> Vec<String> {
    let [ni, nj, nk] = mask.dims;
    let mut counts = [vec![0usize; ni], vec![0; nj], vec![0; nk]];
    for k in 0..nk {
        for j in 0..nj {
            for i in 0..ni {
                if mask.inside[i + ni * (j + nj * k)] {
                    [i, j, k].into_iter().zip(counts.iter_mut()).for_each(|(index, c)| c[index] += 1);
                }
            }
        }
    }
    let mut faces = Vec::new();
    // The side of the patient a face of the image looks to (its outward direction's largest
    // part), when the file places its voxels in the scanner's frame.
    let side = |axis: usize, outward: f64| {
        let direction: [f64; 3] = std::array::from_fn(|r| outward * mask.affine[r][axis]);
        let along = (0..3).max_by(|&a, &b| direction[a].abs().total_cmp(&direction[b].abs())).unwrap_or(2);
        let sides = match frame? {
            Frame::Ras => [["left", "right"], ["posterior", "anterior"], ["inferior", "superior"]],
            Frame::Lps => [["right", "left"], ["anterior", "posterior"], ["inferior", "superior"]],
        };
        Some(sides[along][usize::from(direction[along] > 0.0)])
    };
    let face = |name: &str, index: usize, axis: usize, outward: f64| match side(axis, outward) {
        Some(side) => format!("{name} = {index}, {side}"),
        None => format!("{name} = {index}"),
    };
    // An image larger than the organ (empty slices on four faces or more, as a CT's grid is) cuts
    // it wherever the organ reaches a face with more than its tip, tapering or not (a dome cut a
    // slice or two below its top).
    let touched = counts.iter().flat_map(|c| [c.first(), c.last()]).filter(|end| end.is_some_and(|&n| n > 0)).count();
    let uncropped = touched <= 2;
    for (axis, (name, c)) in ["i", "j", "k"].into_iter().zip(&counts).enumerate() {
        let (n, largest) = (c.len(), *c.iter().max().unwrap_or(&0) as f64);
        let cut = |end: usize, next: Option<&usize>| {
            let end = end as f64;
            end > 0.0
                && (end >= super::dicom::CUT_SHARE * largest
                    || (end >= TIP_SHARE * largest
                        && (uncropped
                            || next.is_none_or(|&next| end >= super::dicom::CUT_NEIGHBOUR_SHARE * next as f64))))
        };
        faces.extend(cut(c[0], c.get(1)).then(|| face(name, 0, axis, -1.0)));
        if n > 1 {
            faces.extend(cut(c[n - 1], c.get(n - 2)).then(|| face(name, n - 1, axis, 1.0)));
        }
    }
    faces
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{norm, sub};

    /// A ball whose top a CT's grid cuts a little below its pole (the last slice 36 % of the
    /// largest, tapering from the one below) is cut; the same ball cropped to its extent on every
    /// side, as 3D Slicer saves a segment, tapers to its faces and is not.
    #[test]
    fn a_dome_cut_by_a_larger_image_is_told_from_a_cropped_one() {
        let ball = |dims: [usize; 3], centre: [f64; 3]| {
            let inside = (0..dims[2])
                .flat_map(|k| (0..dims[1]).flat_map(move |j| (0..dims[0]).map(move |i| [i, j, k].map(|x| x as f64))))
                .map(|p| norm(sub(p, centre)) <= 10.0)
                .collect();
            let affine = [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]];
            VoxelMask { dims, inside, affine }
        };
        let cut = touched_borders(&ball([40, 40, 28], [20.0, 20.0, 19.0]), Some(Frame::Ras));
        assert_eq!(cut, ["k = 27, superior"]);
        let cropped = touched_borders(&ball([21, 21, 19], [10.0, 10.0, 10.0]), Some(Frame::Ras));
        assert!(cropped.is_empty(), "{cropped:?}");
    }
}
