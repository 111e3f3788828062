//! Segmentations as labelmaps: NIfTI-1 and NIfTI-2 (`.nii`, `.nii.gz`, as TotalSegmentator writes them) and
//! NRRD (`.nrrd`, `.seg.nrrd`, as 3D Slicer saves segmentations; `.nhdr`, a header whose data
//! lie in a file beside it), MetaImage (`.mha`, `.mhd`, as ITK-SNAP and SLIVER07 give them) and
//! DICOM SEG and RT Structure Sets (`.dcm` or no extension, as TotalSegmentator, 3D Slicer,
//! highdicom and treatment planning systems export them).
//!
//! A labelmap is a 3D grid of integer labels (0 is the background) with the affine map from voxel
//! indices (i, j, k) to world coordinates in millimetres, read from the header: spacing (voxels
//! may be anisotropic), orientation and origin, in the unit the header names (NIfTI's
//! `xyzt_units`, NRRD's `space units`: m, mm or µm; mm when it names none), converted to mm. The
//! world frame is the scanner's, as the file states it ([`Frame`]): NIfTI's is always RAS (x
//! towards the patient's right, y anterior, z superior); NRRD's is its `space` field, LPS for
//! DICOM-derived data and most of Slicer's files; MetaImage's is ITK's, LPS. Points given with
//! the organ (camera, landmarks, targets) must be in this frame.
//!
//! [`Labelmap::select`] picks one label, by number or by a segment name the file carries (Slicer's
//! `Segment{i}_Name`, a DICOM's, a NIfTI extension's label table as TotalSegmentator writes it), as
//! a [`VoxelMask`]; [`crate::isosurface::mask_surface`] turns the mask into
//! a closed surface. [`write_displacement_nrrd`] writes a displacement-field transform as a NRRD
//! image that 3D Slicer and ITK load.
//!
//! Supported: NIfTI-1 and NIfTI-2 single files (`n+1`, `n+2`), either byte order, gzipped or not, data types u8,
//! i8, i16, u16, i32, u32, i64, u64, f32, f64, the sform or qform affine as 3D Slicer chooses; NRRD with
//! attached data or detached in one file (`data file`, relative to the header's folder), `raw`,
//! `gzip` or `ascii` encoding, the same types, `space` LPS or RAS (or their long
//! names), `space directions`, `space origin` and `space units`, and Slicer's layered
//! segmentations (a first `list` axis of layers); DICOM SEG of BINARY, FRACTIONAL or LABELMAP
//! frames, uncompressed or RLE Lossless, its segments by number and label; DICOM RT Structure
//! Sets, their structures by number and name (see the `dicom` module).

mod dicom;
mod metaimage;
mod nifti;
mod nrrd;
mod surface;

use std::collections::{BTreeMap, HashSet};
use std::io::Read;
use std::path::Path;

use crate::io::Scalar;

use crate::length::LengthUnit;
use crate::volume::{determinant, VoxelMask};
use crate::MeshError;

pub use crate::io::Frame;
pub use nifti::write_nifti;
pub use nrrd::{nrrd_segment_name, write_displacement_nrrd, write_nrrd};
pub use surface::{read_labelmap_surface, LabelSurface};

/// A labelmap read from a file.
#[derive(Clone, Debug, PartialEq)]
pub struct Labelmap {
    /// Voxels along i, j, k.
    pub dims: [usize; 3],
    /// Layers of a layered segmentation (1 for an ordinary labelmap).
    pub layers: usize,
    /// The labels, layer fastest, then i, then j, then k.
    pub labels: Vec<i32>,
    /// Voxel index (i, j, k) to world (mm): `x = A[..3] · (i, j, k) + A[3]`, row by row.
    pub affine: [[f64; 4]; 3],
    /// The frame of the world coordinates.
    pub frame: Frame,
    /// Named segments the file carries: (name, layer, label).
    pub segments: Vec<(String, usize, i32)>,
    /// Whether the file places its voxels in the scanner's frame (a NIfTI without qform and sform
    /// codes does not: its world is the voxel grid scaled by the spacing).
    pub placed: bool,
    /// What a user should know of the file as read, for every label (`None`) or for one (its
    /// layer and label): a slice the series lacks, a segment cut at the end of the frames.
    pub warnings: Vec<(Option<(usize, i32)>, String)>,
    /// The unit the header names for the world, if it names one (a NIfTI's `xyzt_units` other
    /// than 0, a NRRD's `space units`; DICOM's is the millimetre); read as mm when it names none.
    pub named_unit: Option<LengthUnit>,
}

/// The labelmaps read, for messages.
pub const LABELMAP_FORMATS: &str =
    ".nii, .nii.gz, .nrrd, .seg.nrrd, .nhdr, .mha, .mhd or a DICOM SEG or RTSTRUCT (.dcm or no extension)";

/// True when `path` names a labelmap by its extension ([`LABELMAP_FORMATS`]), or is a DICOM file
/// by its content (PACS and scanners write them without an extension).
pub fn is_labelmap(path: &Path) -> bool {
    let name = path.file_name().map(|n| n.to_string_lossy().to_ascii_lowercase()).unwrap_or_default();
    [".nii", ".nii.gz", ".nrrd", ".nhdr", ".mha", ".mhd", ".dcm"].iter().any(|e| name.ends_with(e))
        || dicom::is_dicom_file(path)
}

/// Why an organ's segmentation given as `path` cannot be read, saying what to give instead: a
/// folder or a DICOM file (a series, a DICOM SEG), an image format not read, or an extension that
/// is neither a labelmap's nor a surface's. `None` for a labelmap or surface extension.
pub fn unreadable_segmentation(path: &Path) -> Option<String> {
    let name = path.file_name().map(|n| n.to_string_lossy().to_ascii_lowercase()).unwrap_or_default();
    let extension = name.rsplit_once('.').map_or("", |(_, e)| e);
    let save_as = format!(
        "save the segmentation as a labelmap ({LABELMAP_FORMATS}) or a surface (.stl, .obj, .ply, .vtk, .vtp, .vtu)"
    );
    if path.is_dir() {
        let dicom = std::fs::read_dir(path)
            .map_or(0, |entries| entries.flatten().filter(|e| dicom::is_dicom_file(&e.path())).count());
        return Some(match dicom {
            0 => format!(
                "a folder, not a file (a DICOM series is not read): segment it (3D Slicer, TotalSegmentator) and \
                 {save_as}"
            ),
            n => format!(
                "a folder, not a file: give its DICOM SEG or RTSTRUCT, if one of its {n} DICOM files is (a DICOM \
                 image series is not read), or {save_as}"
            ),
        });
    }
    if is_labelmap(path) || crate::io::SURFACE_EXTENSIONS.contains(&extension) {
        return None;
    }
    Some(match extension {
        "dicom" | "ima" | "" => format!("neither a DICOM file by its content nor named by an extension: {save_as}"),
        "mrb" => "a 3D Slicer scene bundle (a zip): unzip it; its Data folder holds the segmentation (.seg.nrrd) and \
                  the markups (.mrk.json) to give"
            .to_string(),
        "mrml" => "a 3D Slicer scene, which names its files: give the segmentation it holds (.seg.nrrd, in its \
                   folder)"
            .to_string(),
        "mgz" | "mgh" | "hdr" | "img" | "nia" => {
            format!("this image format is not read: {save_as} (3D Slicer or ITK-SNAP: Save as)")
        }
        _ if !path.exists() => format!("no such file, and not a labelmap nor a surface by its extension: {save_as}"),
        _ => format!("not a labelmap nor a surface by its extension: {save_as}"),
    })
}

/// Reads a NIfTI, NRRD or MetaImage labelmap, chosen by the file's extension; an image's grey
/// values (a CT given for its segmentation) are refused.
pub fn read_labelmap(path: impl AsRef<Path>) -> Result<Labelmap, MeshError> {
    read_labelmap_choosing(path.as_ref(), None)
}

/// [`read_labelmap`]; of an RT Structure Set, only the structure `label` names when it names
/// one, on a grid of its own (see the `dicom` module).
fn read_labelmap_choosing(path: &Path, label: Option<&str>) -> Result<Labelmap, MeshError> {
    let bytes = std::fs::read(path).map_err(|error| MeshError::Io { path: path.display().to_string(), error })?;
    if bytes.starts_with(crate::io::LFS_POINTER) {
        return Err(crate::io::lfs_error(path));
    }
    let name = path.file_name().map(|n| n.to_string_lossy().to_ascii_lowercase()).unwrap_or_default();
    let folder = path.parent().unwrap_or(Path::new(""));
    let mut map = if name.ends_with(".nrrd") || name.ends_with(".nhdr") {
        nrrd::parse_nrrd(&bytes, folder).map_err(|m| MeshError::parse(path, m))?
    } else if name.ends_with(".mha") || name.ends_with(".mhd") {
        metaimage::parse_metaimage(&bytes, folder).map_err(|m| MeshError::parse(path, m))?
    } else if name.ends_with(".nii") || name.ends_with(".nii.gz") {
        nifti::parse_nifti(&gunzip_if_needed(bytes).map_err(|m| MeshError::parse(path, m))?)
            .map_err(|m| MeshError::parse(path, m))?
    } else if name.ends_with(".dcm") || dicom::is_dicom(&bytes) {
        dicom::parse_dicom(&bytes, label).map_err(|m| MeshError::parse(path, m))?
    } else {
        return Err(MeshError::parse(path, format!("not a labelmap: expected {LABELMAP_FORMATS}")));
    };
    if map.labels.iter().all(|&l| l == 0) {
        return Err(MeshError::parse(path, "the labelmap is empty: every voxel is 0 (background)"));
    }
    refuse_image(&map.labels).map_err(|m| MeshError::parse(path, m))?;
    map.warnings.extend(shear_warning(&map.affine).map(|w| (None, w)));
    Ok(map)
}

/// The angle (degrees) by which a voxel grid's axes may stray from perpendicular before it is
/// called sheared (a float32 header's rounding is far below it).
const SHEAR_DEG: f64 = 0.05;

/// A warning for a voxel-to-world affine whose axes are not perpendicular (a sheared grid, which
/// 3D Slicer, through ITK, does not show as the file gives it), naming the largest stray.
fn shear_warning(affine: &[[f64; 4]; 3]) -> Option<String> {
    let axis = |c: usize| -> crate::Point { std::array::from_fn(|r| affine[r][c]) };
    let stray = [(0, 1), (0, 2), (1, 2)]
        .into_iter()
        .map(|(a, b)| {
            let cos = crate::dot(axis(a), axis(b)) / (crate::norm(axis(a)) * crate::norm(axis(b)));
            90.0 - cos.abs().clamp(0.0, 1.0).acos().to_degrees()
        })
        .fold(0.0, f64::max);
    (stray > SHEAR_DEG).then(|| {
        format!(
            "the file's voxel axes are {stray:.1}° from perpendicular (a sheared grid): the organ is read as the \
             file places it, while 3D Slicer (ITK) shows the image without the shear, so that the two disagree"
        )
    })
}

/// The data file a detached header (`.nhdr`, `.mhd`) names, read from `folder` (the header's);
/// data in several files (`what` says how to save them as one) and a Git LFS pointer are refused.
fn read_data_file(folder: &Path, name: &str, what: &str) -> Result<Vec<u8>, String> {
    if several_files(name) {
        return Err(format!("data file {name}: data in several files are not read; {what}"));
    }
    let path = folder.join(name);
    let bytes = std::fs::read(&path).map_err(|e| format!("its data file {} cannot be read: {e}", path.display()))?;
    if bytes.starts_with(crate::io::LFS_POINTER) {
        return Err(format!("its data file {}: {}", path.display(), crate::io::LFS_MESSAGE));
    }
    Ok(bytes)
}

/// Whether a detached header's data file names several files: `LIST`, or a `printf` pattern with
/// its range (`slice%03d.raw 1 46 1`), as NRRD and MetaImage write them.
fn several_files(name: &str) -> bool {
    let words: Vec<&str> = name.split_whitespace().collect();
    name.starts_with("LIST") || (words.len() >= 4 && words[0].contains('%'))
}

/// More distinct values than any labelmap holds: an image's grey values.
const MAX_LABELS: usize = 1000;

/// Refuses an image given for a labelmap: values below −1 (a CT's Hounsfield units; −1 is a
/// common "ignore" label) or more than [`MAX_LABELS`] distinct values.
fn refuse_image(labels: &[i32]) -> Result<(), String> {
    let mut distinct = HashSet::new();
    let mut previous = None;
    for &l in labels {
        if previous != Some(l) && distinct.insert(l) && distinct.len() > MAX_LABELS {
            break;
        }
        previous = Some(l);
    }
    let (lo, hi) = labels.iter().fold((i32::MAX, i32::MIN), |(lo, hi), &l| (lo.min(l), hi.max(l)));
    if lo >= -1 && distinct.len() <= MAX_LABELS {
        return Ok(());
    }
    let count = if distinct.len() > MAX_LABELS { format!("over {MAX_LABELS}") } else { distinct.len().to_string() };
    Err(format!(
        "holds {count} distinct values, from {lo} to {hi}: an image (CT or MR grey values), not a labelmap; give \
         the segmentation, one label per voxel (e.g. TotalSegmentator's liver.nii.gz or 3D Slicer's .seg.nrrd)"
    ))
}

/// The bytes, decompressed when they start with gzip's magic number.
fn gunzip_if_needed(bytes: Vec<u8>) -> Result<Vec<u8>, String> {
    if bytes.starts_with(&[0x1f, 0x8b]) {
        let mut out = Vec::new();
        flate2::read::MultiGzDecoder::new(&bytes[..])
            .read_to_end(&mut out)
            .map_err(|e| format!("cannot decompress (gzip): {e}"))?;
        Ok(out)
    } else {
        Ok(bytes)
    }
}

/// The voxels of `data` as labels, `count` values of type `ty` in the given byte order (a
/// non-integral or non-finite float is an error: a labelmap holds labels, not intensities; so is
/// one beyond 32 bits). Data short of them, or holding a whole slice more (`count` over the grid's
/// last size `nz`: sizes smaller than the data's), are an error; a few bytes more are padding.
fn labels(ty: Scalar, data: &[u8], count: usize, nz: usize, little: bool) -> Result<Vec<i32>, String> {
    let size = ty.size();
    let expected = count * size;
    if data.len() < expected || data.len() - expected >= (count / nz.max(1)).max(1) * size {
        return Err(format!(
            "the data hold {} bytes, {expected} expected ({count} voxels of {size} byte(s)): do the sizes in the \
             header match the image?",
            data.len()
        ));
    }
    (0..count).map(|i| label(i, ty.decode(&data[i * size..(i + 1) * size], !little))).collect()
}

/// Voxel `i`'s value `x` as a label (a labelmap holds whole numbers; a float a rounding away from
/// one, as exports in floating point leave them, within [`SCALED_LABEL_TOLERANCE`], is that
/// number).
fn label(i: usize, x: f64) -> Result<i32, String> {
    let whole = x.round();
    if (x - whole).abs() <= SCALED_LABEL_TOLERANCE * whole.abs().max(1.0)
        && (f64::from(i32::MIN)..=f64::from(i32::MAX)).contains(&whole)
    {
        Ok(whole as i32)
    } else {
        Err(format!(
            "voxel {i} holds {x}, not a label (a labelmap holds whole numbers; threshold a probability map, e.g. at \
             0.5)"
        ))
    }
}

/// How far (relative) a voxel scaled by a NIfTI's slope and intercept may lie from a whole number
/// and still be a label: several times the precision of the 32-bit numbers NIfTI-1 stores them in.
const SCALED_LABEL_TOLERANCE: f64 = 1e-6;

/// A voxel-to-world affine whose world unit is `mm_per_unit` millimetres, in millimetres.
fn in_millimetres(affine: [[f64; 4]; 3], mm_per_unit: f64) -> [[f64; 4]; 3] {
    affine.map(|row| row.map(|x| x * mm_per_unit))
}

/// Refuses an affine with non-finite entries or without volume (a zero spacing).
fn check_affine(affine: &[[f64; 4]; 3]) -> Result<(), String> {
    if affine.iter().flatten().any(|x| !x.is_finite()) {
        return Err(format!("the voxel-to-world map has a non-finite entry: {affine:?}"));
    }
    if determinant(affine).abs() < 1e-12 {
        return Err(format!("the voxel-to-world map is singular (a zero spacing?): {affine:?}"));
    }
    Ok(())
}

/// The labels a message lists at most.
const SHOWN_LABELS: usize = 20;

impl Labelmap {
    /// A labelmap of one layer: `labels` (i fastest, then j, then k) on a grid of `dims` voxels
    /// placed in `frame` by `affine`, naming no segment.
    pub fn single(dims: [usize; 3], labels: Vec<i32>, affine: [[f64; 4]; 3], frame: Frame) -> Labelmap {
        let (segments, warnings) = (Vec::new(), Vec::new());
        Labelmap { dims, layers: 1, labels, affine, frame, segments, placed: true, warnings, named_unit: None }
    }

    /// The size of a voxel along i, j and k (mm).
    pub fn spacing(&self) -> [f64; 3] {
        std::array::from_fn(|c| (0..3).map(|r| self.affine[r][c].powi(2)).sum::<f64>().sqrt())
    }

    /// The labels present (other than 0), each with its voxel count and its name if it has one.
    pub fn present(&self) -> Vec<(usize, i32, usize, Option<String>)> {
        let mut counts: BTreeMap<(usize, i32), usize> = BTreeMap::new();
        for (n, &l) in self.labels.iter().enumerate() {
            if l != 0 {
                *counts.entry((n % self.layers, l)).or_default() += 1;
            }
        }
        counts
            .into_iter()
            .map(|((layer, label), count)| {
                let names = self.names_of(layer, label);
                (layer, label, count, (!names.is_empty()).then(|| names.join(" / ")))
            })
            .collect()
    }

    /// A list of the labels present for messages, e.g. "1 (liver, 5120 voxels), 2 (842 voxels)";
    /// past twenty, how many more.
    pub fn present_text(&self) -> String {
        let present = self.present();
        let mut items: Vec<String> = present
            .iter()
            .take(SHOWN_LABELS)
            .cloned()
            .map(|(layer, label, count, name)| {
                let layer = if self.layers > 1 { format!("layer {layer}, ") } else { String::new() };
                match name {
                    Some(n) => format!("{label} ('{n}', {layer}{count} voxels)"),
                    None => format!("{label} ({layer}{count} voxels)"),
                }
            })
            .collect();
        if present.len() > SHOWN_LABELS {
            items.push(format!("and {} more", present.len() - SHOWN_LABELS));
        }
        items.join(", ")
    }

    /// The voxels of one label, chosen by number ("5") or by segment name ("liver", any case),
    /// as a mask in the labelmap's world frame, its grid cut to the label's box with one voxel
    /// around. Returns the mask and a description of
    /// the choice ("label 5 ('liver')"). An absent label or name is an error that lists those
    /// present; a number matching segments of several layers must be chosen by name, and a name
    /// that several segments carry is refused. `1+2` selects segments 1 and 2 together.
    pub fn select(&self, choice: &str) -> Result<(VoxelMask, String), MeshError> {
        let (whole, description, chosen) = self.select_uncropped(choice)?;
        Ok((self.cropped(&whole, &description, chosen)?, description))
    }

    /// `whole`, a selection of `description` on this labelmap's grid, cut to its box with one
    /// voxel around; an error when it has no voxel.
    fn cropped(&self, whole: &VoxelMask, description: &str, chosen: (usize, i32)) -> Result<VoxelMask, MeshError> {
        whole.cropped(1).ok_or_else(|| {
            let why: Vec<&str> =
                self.warnings.iter().filter(|(of, _)| *of == Some(chosen)).map(|(_, w)| w.as_str()).collect();
            let why = if why.is_empty() { String::new() } else { format!(" ({})", why.join("; ")) };
            MeshError::Invalid(format!("{description} has no voxel{why}; labels present: {}", self.present_text()))
        })
    }

    /// [`Labelmap::select`] on the labelmap's whole grid; `a+b` (not a segment's own name) is the
    /// union of segments `a` and `b` (a liver labelled 1 and its tumour 2, as LiTS and MSD label
    /// them), chosen for the first's warnings.
    fn select_uncropped(&self, choice: &str) -> Result<(VoxelMask, String, (usize, i32)), MeshError> {
        let named = self.segments.iter().any(|s| s.0.eq_ignore_ascii_case(choice.trim()));
        if let (false, Some((first, rest))) = (named, choice.split_once('+')) {
            let (mut union, first, chosen) = self.select_single(first)?;
            let (other, rest, _) = self.select_uncropped(rest)?;
            union.inside.iter_mut().zip(&other.inside).for_each(|(a, &b)| *a |= b);
            return Ok((union, format!("{first} + {rest}"), chosen));
        }
        self.select_single(choice)
    }

    /// The names of the segments the file puts at `label` of `layer` (several where it gives them
    /// no label value apart).
    fn names_of(&self, layer: usize, label: i32) -> Vec<&str> {
        self.segments.iter().filter(|s| s.1 == layer && s.2 == label).map(|s| s.0.as_str()).collect()
    }

    /// The segments' names that hold `choice` or a word of it, or that it holds, or that it or a
    /// word of it misspells ([`misspells`]; any case), as ", names like it: 'liver' (5),
    /// 'liver_tumor' (100)"; empty when none does.
    fn names_like(&self, choice: &str) -> String {
        let words = |s: &str| -> Vec<String> {
            s.to_lowercase().split(|c: char| !c.is_alphanumeric()).filter(|w| w.len() > 2).map(str::to_string).collect()
        };
        let wanted = words(choice);
        let choice = choice.to_lowercase();
        let like: Vec<String> = self
            .segments
            .iter()
            .filter(|(name, _, _)| {
                let name = name.to_lowercase();
                name.contains(&choice)
                    || choice.contains(&name)
                    || misspells(&choice, &name)
                    || words(&name).iter().any(|w| wanted.iter().any(|c| c == w || misspells(c, w)))
            })
            .map(|(name, _, label)| format!("'{name}' ({label})"))
            .take(SHOWN_LABELS)
            .collect();
        match like.is_empty() {
            true => String::new(),
            false => format!(", names like it: {}", like.join(", ")),
        }
    }

    /// One segment, by number or name ([`Labelmap::select`]), on the labelmap's whole grid.
    fn select_single(&self, choice: &str) -> Result<(VoxelMask, String, (usize, i32)), MeshError> {
        let choice = choice.trim();
        let present = self.present();
        let (layer, label) = if let Some(label) = label_number(choice) {
            let layers: Vec<usize> = present.iter().filter(|p| p.1 == label).map(|p| p.0).collect();
            match layers[..] {
                [layer] if label != 0 => (layer, label),
                [_, _, ..] => {
                    return Err(MeshError::Invalid(format!(
                        "label {label} is in {} layers: choose the segment by name; labels present: {}",
                        layers.len(),
                        self.present_text()
                    )))
                }
                _ if label == 0 => {
                    return Err(MeshError::Invalid(format!(
                        "label 0 is the background, not a segment; labels present: {}",
                        self.present_text()
                    )))
                }
                // A segment the file names, which holds no voxel: said so as when named.
                _ => match self.segments.iter().find(|s| s.2 == label) {
                    Some(s) => (s.1, s.2),
                    None => {
                        return Err(MeshError::Invalid(format!(
                            "label {choice} is not in the labelmap; labels present: {}",
                            self.present_text()
                        )))
                    }
                },
            }
        } else {
            let named: Vec<&(String, usize, i32)> =
                self.segments.iter().filter(|s| s.0.eq_ignore_ascii_case(choice)).collect();
            match named[..] {
                [s] if self.names_of(s.1, s.2).len() > 1 => {
                    let sharing: Vec<String> = self.names_of(s.1, s.2).iter().map(|n| format!("'{n}'")).collect();
                    return Err(MeshError::Invalid(format!(
                        "segments {} all take label {} of layer {} (no Segment{{i}}_LabelValue sets them apart): \
                         the file does not say which voxels are '{choice}'; save the segmentation again from 3D \
                         Slicer, or choose by number (labels present: {})",
                        sharing.join(", "),
                        s.2,
                        s.1,
                        self.present_text()
                    )));
                }
                [s] => (s.1, s.2),
                [_, _, ..] => {
                    return Err(MeshError::Invalid(format!(
                        "{} segments are named '{choice}': rename them apart, or choose by number (labels present: {})",
                        named.len(),
                        self.present_text()
                    )))
                }
                [] if self.segments.is_empty() => {
                    let liver = match choice.eq_ignore_ascii_case("liver") {
                        true => " (TotalSegmentator's `total` task numbers the liver 5)",
                        false => "",
                    };
                    return Err(MeshError::Invalid(format!(
                        "the file names no segment (a NIfTI without a label table or a plain NRRD holds numbers \
                         only): choose '{choice}' \
                         by its number{liver}; labels present: {}",
                        self.present_text()
                    )));
                }
                [] => {
                    return Err(MeshError::Invalid(format!(
                        "no segment is named '{choice}'{}; labels present: {}",
                        self.names_like(choice),
                        self.present_text()
                    )))
                }
            }
        };
        let inside: Vec<bool> = self.labels.iter().skip(layer).step_by(self.layers).map(|&l| l == label).collect();
        let mut description = match self.names_of(layer, label)[..] {
            [n] => format!("label {label} ('{n}')"),
            _ => format!("label {label}"),
        };
        // A number is a label's value: a segment named by another number is said to be elsewhere.
        if label_number(choice).is_some() {
            if let Some(s) = self.segments.iter().find(|s| s.0.trim() == choice && (s.1, s.2) != (layer, label)) {
                description += &format!(" (the segment named '{choice}' is label {0}: choose {0} for it)", s.2);
            }
        }
        Ok((VoxelMask { dims: self.dims, inside, affine: self.affine }, description, (layer, label)))
    }
}

/// The label a choice names by number: an integer, or a whole number written as a float stores
/// it (`5.0`, as a float labelmap's values print); `None` for a name.
fn label_number(choice: &str) -> Option<i32> {
    choice.parse::<i32>().ok().or_else(|| {
        let x = choice.parse::<f64>().ok().filter(|x| x.fract() == 0.0 && x.abs() <= i32::MAX as f64)?;
        choice.contains('.').then_some(x as i32)
    })
}

/// Whether `typed` misspells `name`: a letter left out, added or changed per four letters, one at
/// the least (`livr` for `liver`, `kidny` for `kidney`), as an edit distance counts them.
fn misspells(typed: &str, name: &str) -> bool {
    let (a, b): (Vec<char>, Vec<char>) = (typed.chars().collect(), name.chars().collect());
    let allowed = (a.len().min(b.len()) / 4).max(1);
    if a.len().abs_diff(b.len()) > allowed {
        return false;
    }
    // The edit distance, row by row.
    let mut row: Vec<usize> = (0..=b.len()).collect();
    for (i, ca) in a.iter().enumerate() {
        let mut previous = row[0];
        row[0] = i + 1;
        for (j, cb) in b.iter().enumerate() {
            let replaced = previous + usize::from(ca != cb);
            previous = row[j + 1];
            row[j + 1] = replaced.min(row[j] + 1).min(previous + 1);
        }
    }
    row[b.len()] <= allowed
}

/// `bytes` gzipped (`path` names the file in an error).
fn gzip(path: &Path, bytes: &[u8]) -> Result<Vec<u8>, MeshError> {
    let io_error = |error| MeshError::Io { path: path.display().to_string(), error };
    let mut encoder = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::default());
    std::io::Write::write_all(&mut encoder, bytes).map_err(io_error)?;
    encoder.finish().map_err(io_error)
}

/// Labels as a writer stores them: little-endian 16-bit integers, or 32-bit where one does not fit
/// in 16 (`true`).
fn label_bytes(labels: &[i32]) -> (Vec<u8>, bool) {
    let wide = labels.iter().any(|&l| i16::try_from(l).is_err());
    let bytes = match wide {
        true => labels.iter().flat_map(|l| l.to_le_bytes()).collect(),
        false => labels.iter().flat_map(|&l| (l as i16).to_le_bytes()).collect(),
    };
    (bytes, wide)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::isosurface::{mask_surface, ExtractOptions};
    use crate::{norm, sub, Point, TriSurface};

    /// A labelmap of two balls (labels 5 and 2) at world positions given in `frame`, with
    /// anisotropic voxels and the x axis flipped.
    pub(super) fn two_balls(frame: Frame) -> (Labelmap, Point) {
        let dims = [52, 44, 16];
        // Spacings exact in f32, as NIfTI stores them.
        let affine = [[-0.75, 0.0, 0.0, 60.0], [0.0, 0.875, 0.0, -100.0], [0.0, 0.0, 2.5, 200.0]];
        let (organ, other): (Point, Point) = ([40.0, -82.0, 220.0], [25.0, -80.0, 215.0]);
        let mut labels = Vec::new();
        for k in 0..dims[2] {
            for j in 0..dims[1] {
                for i in 0..dims[0] {
                    let p: Point = std::array::from_fn(|r| {
                        affine[r][0] * i as f64 + affine[r][1] * j as f64 + affine[r][2] * k as f64 + affine[r][3]
                    });
                    labels.push(if norm(sub(p, organ)) <= 10.0 {
                        5
                    } else if norm(sub(p, other)) <= 3.0 {
                        2
                    } else {
                        0
                    });
                }
            }
        }
        let segments = vec![("liver".to_string(), 0, 5), ("tumour".to_string(), 0, 2)];
        (Labelmap { segments, ..Labelmap::single(dims, labels, affine, frame) }, organ)
    }

    /// Whether two affines agree entry by entry within `tolerance`.
    fn close(a: &[[f64; 4]; 3], b: &[[f64; 4]; 3], tolerance: f64) -> bool {
        a.iter().flatten().zip(b.iter().flatten()).all(|(x, y)| (x - y).abs() < tolerance)
    }

    fn centroid(s: &TriSurface) -> Point {
        std::array::from_fn(|d| s.vertices.iter().map(|p| p[d]).sum::<f64>() / s.vertices.len() as f64)
    }

    #[test]
    fn a_nifti_labelmap_round_trips_and_its_organ_lands_at_its_scanner_position() {
        let dir = tempfile::tempdir().unwrap();
        let (map, centre) = two_balls(Frame::Ras);
        for name in ["seg.nii.gz", "seg.nii"] {
            let path = dir.path().join(name);
            write_nifti(&path, &map).unwrap();
            let back = read_labelmap(&path).unwrap();
            let in_mm = Some(LengthUnit::Millimetre);
            assert!(back == Labelmap { segments: Vec::new(), named_unit: in_mm, ..map.clone() }, "{:?}", back.affine);
            let organ = read_labelmap_surface(&path, Some("5"), None, &ExtractOptions::default()).unwrap();
            assert_eq!(organ.frame, Frame::Ras);
            let c = centroid(&organ.surface);
            assert!(norm(sub(c, centre)) < 0.5, "{c:?} vs {centre:?}");
            let exact = 4.0 / 3.0 * std::f64::consts::PI * 1000.0;
            assert!((organ.extract.volume / exact - 1.0).abs() < 0.05, "{}", organ.extract.volume);
            assert!(organ.lines()[0].starts_with("label 5: "), "{:?}", organ.lines());
        }
        // The same voxels as 64-bit integers, signed (datatype 1024) and unsigned (1280), as
        // SimpleITK writes a NumPy integer mask.
        let plain = std::fs::read(dir.path().join("seg.nii")).unwrap();
        let offset = f32::from_le_bytes(plain[108..112].try_into().unwrap()) as usize;
        assert_eq!(i16::from_le_bytes([plain[70], plain[71]]), 4, "written as 16-bit labels");
        let longs: Vec<u8> = plain[offset..]
            .chunks_exact(2)
            .flat_map(|v| i64::from(i16::from_le_bytes([v[0], v[1]])).to_le_bytes())
            .collect();
        for datatype in [1024i16, 1280] {
            let mut bytes = [&plain[..offset], &longs].concat();
            bytes[70..72].copy_from_slice(&datatype.to_le_bytes());
            bytes[72..74].copy_from_slice(&64i16.to_le_bytes());
            let path = dir.path().join(format!("seg{datatype}.nii"));
            std::fs::write(&path, bytes).unwrap();
            assert!(read_labelmap(&path).unwrap().labels == map.labels, "datatype {datatype}");
        }
    }

    /// The NIfTI-2 header of `map` (its fields at their NIfTI-2 offsets, 64-bit wide), 16-bit
    /// labels after it, in either byte order, as nibabel's `Nifti2Image` writes one.
    fn nifti2(map: &Labelmap, little: bool) -> Vec<u8> {
        let mut bytes = vec![0u8; 544];
        let mut put = |offset: usize, mut b: Vec<u8>| {
            if !little {
                b.reverse();
            }
            bytes[offset..offset + b.len()].copy_from_slice(&b);
        };
        put(0, 540i32.to_le_bytes().to_vec());
        put(12, 4i16.to_le_bytes().to_vec());
        put(14, 16i16.to_le_bytes().to_vec());
        let dims = [3, map.dims[0] as i64, map.dims[1] as i64, map.dims[2] as i64, 1, 1, 1, 1];
        dims.iter().enumerate().for_each(|(d, n)| put(16 + 8 * d, n.to_le_bytes().to_vec()));
        let spacing = map.spacing();
        let pixdim = [1.0, spacing[0], spacing[1], spacing[2], 1.0, 1.0, 1.0, 1.0];
        pixdim.iter().enumerate().for_each(|(d, x)| put(104 + 8 * d, x.to_le_bytes().to_vec()));
        put(168, 544i64.to_le_bytes().to_vec());
        put(176, 1f64.to_le_bytes().to_vec());
        put(348, 1i32.to_le_bytes().to_vec());
        for r in 0..3 {
            (0..4).for_each(|c| put(400 + 32 * r + 8 * c, map.affine[r][c].to_le_bytes().to_vec()));
        }
        put(500, 2i32.to_le_bytes().to_vec()); // xyzt_units: mm
        bytes[4..12].copy_from_slice(b"n+2\0\r\n\x1a\n");
        for &l in &map.labels {
            bytes.extend(if little { (l as i16).to_le_bytes() } else { (l as i16).to_be_bytes() });
        }
        bytes
    }

    /// A NIfTI-1 file with header extensions of codes and texts `extensions` after its header
    /// (the extender's flag set, the voxels moved after them), as nibabel writes them.
    fn with_extensions(plain: &[u8], extensions: &[(i32, &str)]) -> Vec<u8> {
        let mut all = Vec::new();
        for (code, text) in extensions {
            let size = (8 + text.len()).div_ceil(16) * 16;
            let mut extension = [(size as i32).to_le_bytes(), code.to_le_bytes()].concat();
            extension.extend_from_slice(text.as_bytes());
            extension.resize(size, 0);
            all.extend(extension);
        }
        let mut bytes = [&plain[..352], &all, &plain[352..]].concat();
        bytes[348] = 1;
        bytes[108..112].copy_from_slice(&((352 + all.len()) as f32).to_le_bytes());
        bytes
    }

    /// A NIfTI whose extension holds a label table names its labels: TotalSegmentator's
    /// multi-label files (its `CaretExtension`, code 0, the names in CDATA, as its
    /// `add_label_map_to_nifti` writes them) and a table of plain text with XML entities, its
    /// attributes in any order and quotes, each behind an extension of another kind. A
    /// segment is then chosen by name, a name not there is answered with those like it, and an
    /// extension cut short leaves the labels unnamed.
    #[test]
    fn a_nifti_label_table_names_its_labels() {
        let dir = tempfile::tempdir().unwrap();
        let (map, _) = two_balls(Frame::Ras);
        let path = dir.path().join("plain.nii");
        write_nifti(&path, &map).unwrap();
        let plain = std::fs::read(&path).unwrap();
        let total_segmentator = concat!(
            "<?xml version=\"1.0\" encoding=\"UTF-8\"?> <CaretExtension>  ",
            "<Date><![CDATA[2013-07-14T05:45:09]]></Date>   <VolumeInformation Index=\"0\">   <LabelTable>\n",
            "<Label Key=\"5\" Red=\"0.6\" Green=\"0.3\" Blue=\"0.2\" Alpha=\"1\"><![CDATA[liver]]></Label>\n",
            "<Label Key=\"2\" Red=\"1\" Green=\"0\" Blue=\"0\" Alpha=\"1\"><![CDATA[liver_tumor]]></Label>\n\n",
            "  </LabelTable>  <StudyMetaDataLinkSet>  </StudyMetaDataLinkSet>  ",
            "<VolumeType><![CDATA[Label]]></VolumeType>   </VolumeInformation></CaretExtension>\n"
        );
        let entities =
            "<LabelTable><Label Key=\"0\">???</Label><Label ParentKey=\"9\" Name=\"a>b\" Key=\"5\">liver &amp; \
            hilum</Label><Label\nRed=\"1\" Key = '2'>tumour &lt;2 cm&gt;</Label></LabelTable>";
        for (code, text, liver, tumour) in
            [(0, total_segmentator, "liver", "liver_tumor"), (32, entities, "liver & hilum", "tumour <2 cm>")]
        {
            let path = dir.path().join(format!("named{code}.nii"));
            // Behind an extension of another kind (a JSON sidecar's, code 44).
            std::fs::write(&path, with_extensions(&plain, &[(44, "{\"Modality\": \"CT\"}"), (code, text)])).unwrap();
            let named = read_labelmap(&path).unwrap();
            assert_eq!(named.labels, map.labels, "the voxels read past the extension");
            assert_eq!(named.segments, [(liver.to_string(), 0, 5), (tumour.to_string(), 0, 2)]);
            let (mask, description) = named.select(&liver.to_uppercase()).unwrap();
            assert_eq!(
                (mask.count(), description),
                (map.labels.iter().filter(|&&l| l == 5).count(), format!("label 5 ('{liver}')"))
            );
            assert!(named.present_text().contains(&format!("2 ('{tumour}', ")), "{}", named.present_text());
        }
        let path = dir.path().join("named0.nii");
        let e = read_labelmap(&path).unwrap().select("tumour").unwrap_err().to_string();
        assert!(e.contains("no segment is named 'tumour', names like it: 'liver_tumor' (2);"), "{e}");
        let e = read_labelmap(&path).unwrap().select("liver tumour").unwrap_err().to_string();
        assert!(e.contains("names like it: 'liver' (5), 'liver_tumor' (2);"), "{e}");
        let e = read_labelmap(&path).unwrap().select("livr").unwrap_err().to_string();
        assert!(e.contains("no segment is named 'livr', names like it: 'liver' (5), 'liver_tumor' (2);"), "{e}");
        // An extension whose size runs past the voxels' offset: no names, the voxels read.
        let mut cut = with_extensions(&plain, &[(0, total_segmentator)]);
        cut[352..356].copy_from_slice(&100_000i32.to_le_bytes());
        let path = dir.path().join("cut.nii");
        std::fs::write(&path, cut).unwrap();
        let unnamed = read_labelmap(&path).unwrap();
        assert!(unnamed.segments.is_empty() && unnamed.labels == map.labels);
    }

    /// A label of two pieces apart (`5+2`: two balls) is said as its largest piece of all its
    /// voxels; a whole number written as a float (`5.0`) chooses that label.
    #[test]
    fn a_label_in_pieces_is_counted_whole_and_a_float_number_chooses_it() {
        let dir = tempfile::tempdir().unwrap();
        let (map, _) = two_balls(Frame::Ras);
        let path = dir.path().join("seg.nii");
        write_nifti(&path, &map).unwrap();
        let count = |label: i32| map.labels.iter().filter(|&&l| l == label).count();
        let (own, all) = (count(5), count(5) + count(2));
        let organ = read_labelmap_surface(&path, Some("5+2"), None, &ExtractOptions::default()).unwrap();
        assert_eq!(organ.label_voxels, all);
        let line = &organ.lines()[0];
        let said = format!("label 5 + label 2: {own} of its {all} voxels (its largest piece) of ");
        assert!(line.starts_with(&said), "{line}");
        let (mask, description) = map.select("5.0").unwrap();
        assert_eq!((mask.count(), description.as_str()), (own, "label 5 ('liver')"));
        let e = map.select("5.5").unwrap_err().to_string();
        assert!(e.contains("no segment is named '5.5'"), "{e}");
    }

    /// A NIfTI-2 file (either byte order, gzipped or not) reads as the NIfTI-1 of the same
    /// voxels; its 64-bit affine is kept whole (NIfTI-1 rounds it to 32 bits).
    #[test]
    fn a_nifti2_labelmap_reads_as_its_nifti1() {
        let dir = tempfile::tempdir().unwrap();
        let (mut map, _) = two_balls(Frame::Ras);
        map.affine[0][3] += 0.1;
        map.segments.clear();
        map.named_unit = Some(LengthUnit::Millimetre);
        for little in [true, false] {
            let path = dir.path().join("seg.nii");
            std::fs::write(&path, nifti2(&map, little)).unwrap();
            assert!(read_labelmap(&path).unwrap() == map, "little-endian {little}");
            let gz = dir.path().join("seg.nii.gz");
            std::fs::write(&gz, gzip(&gz, &nifti2(&map, little)).unwrap()).unwrap();
            assert!(read_labelmap(&gz).unwrap() == map, "gzipped, little-endian {little}");
        }
        let mut bad = nifti2(&map, true);
        bad[4..8].copy_from_slice(b"ni2\0");
        let path = dir.path().join("pair.nii");
        std::fs::write(&path, bad).unwrap();
        let e = read_labelmap(&path).unwrap_err().to_string();
        assert!(e.contains("not a single-file NIfTI-2"), "{e}");
    }

    #[test]
    fn a_slicer_segmentation_round_trips_and_lps_flips_x_and_y() {
        let dir = tempfile::tempdir().unwrap();
        let (ras, centre) = two_balls(Frame::Ras);
        // The same voxels in LPS: the first two rows of the affine change sign.
        let mut lps = Labelmap { frame: Frame::Lps, ..ras.clone() };
        (0..2).for_each(|r| lps.affine[r].iter_mut().for_each(|x| *x = -*x));
        let path = dir.path().join("seg.seg.nrrd");
        write_nrrd(&path, &lps).unwrap();
        assert!(read_labelmap(&path).unwrap() == lps);
        let organ = read_labelmap_surface(&path, Some("Liver"), None, &ExtractOptions::default()).unwrap();
        assert_eq!((organ.frame, organ.label.as_str()), (Frame::Lps, "label 5 ('liver')"));
        let c = centroid(&organ.surface);
        let expected = [-centre[0], -centre[1], centre[2]];
        assert!(norm(sub(c, expected)) < 0.5, "{c:?} vs {expected:?}");
        let error = |choice: &str| {
            read_labelmap_surface(&path, Some(choice), None, &ExtractOptions::default()).unwrap_err().to_string()
        };
        let absent = error("7");
        assert!(absent.contains("label 7 is not in the labelmap") && absent.contains("5 ('liver',"), "{absent}");
        assert!(error("kidney").contains("no segment is named 'kidney'; labels present: 2 ('tumour',"));
        assert!(error("tumor").contains("no segment is named 'tumor', names like it: 'tumour' (2);"));
        assert!(error("0").contains("label 0 is the background, not a segment"));
        let unchosen = read_labelmap_surface(&path, None, None, &ExtractOptions::default()).unwrap_err().to_string();
        assert!(unchosen.contains("holds several labels: choose one with --label"), "{unchosen}");
    }

    /// The same voxels as a RAS NIfTI, an LPS NRRD and a RAS NIfTI stored with its k axis
    /// reversed give the same surface, vertex for vertex (x and y negated in LPS).
    #[test]
    fn the_same_voxels_give_the_same_surface_whatever_their_frame_and_order() {
        let dir = tempfile::tempdir().unwrap();
        let (ras, _) = two_balls(Frame::Ras);
        let ras = Labelmap { segments: Vec::new(), ..ras };
        let mut lps = Labelmap { frame: Frame::Lps, ..ras.clone() };
        (0..2).for_each(|r| lps.affine[r].iter_mut().for_each(|x| *x = -*x));
        let [nx, ny, nz] = ras.dims;
        let mut reversed = ras.clone();
        reversed.labels =
            (0..nx * ny * nz).map(|n| ras.labels[n % (nx * ny) + nx * ny * (nz - 1 - n / (nx * ny))]).collect();
        (0..3).for_each(|r| {
            reversed.affine[r][3] += (nz - 1) as f64 * ras.affine[r][2];
            reversed.affine[r][2] = -ras.affine[r][2];
        });
        let surface = |name: &str, map: &Labelmap| {
            let path = dir.path().join(name);
            match map.frame {
                Frame::Ras => write_nifti(&path, map).unwrap(),
                Frame::Lps => write_nrrd(&path, map).unwrap(),
            }
            read_labelmap_surface(&path, Some("5"), None, &ExtractOptions::default()).unwrap().surface
        };
        let reference = surface("ras.nii", &ras);
        let negated =
            |s: TriSurface| TriSurface { vertices: s.vertices.iter().map(|p| [-p[0], -p[1], p[2]]).collect(), ..s };
        for other in [negated(surface("lps.nrrd", &lps)), surface("reversed.nii", &reversed)] {
            assert!(other.triangles == reference.triangles, "the triangles differ");
            let apart =
                other.vertices.iter().zip(&reference.vertices).map(|(a, b)| norm(sub(*a, *b))).fold(0.0, f64::max);
            assert!(apart < 1e-9, "{apart} mm apart");
        }
    }

    #[test]
    fn segments_are_taken_together_with_a_plus() {
        let (map, _) = two_balls(Frame::Lps);
        let count = |l: i32| map.labels.iter().filter(|&&x| x == l).count();
        let (union, description) = map.select("5 + tumour").unwrap();
        assert_eq!(union.count(), count(5) + count(2));
        assert_eq!(description, "label 5 ('liver') + label 2 ('tumour')");
        assert!(map.select("5+3").unwrap_err().to_string().contains("label 3 is not in the labelmap"));
        // A segment whose own name holds a plus is that segment.
        let named = Labelmap { segments: vec![("liver+tumour".into(), 0, 5)], ..map.clone() };
        assert_eq!(named.select("liver+tumour").unwrap().0.count(), count(5));
    }

    /// A number chooses a label's value, and says so where a segment is named by that number but
    /// holds another label (3D Slicer names segments imported from a labelmap by their values,
    /// which may change when segments are removed).
    #[test]
    fn a_number_that_names_another_segment_says_where_that_one_is() {
        let (map, _) = two_balls(Frame::Lps);
        let count = |l: i32| map.labels.iter().filter(|&&x| x == l).count();
        let named = Labelmap { segments: vec![("liver".into(), 0, 5), ("5".into(), 0, 2)], ..map.clone() };
        let (mask, description) = named.select("5").unwrap();
        assert_eq!(mask.count(), count(5));
        assert_eq!(description, "label 5 ('liver') (the segment named '5' is label 2: choose 2 for it)");
        assert_eq!(named.select("2").unwrap().1, "label 2 ('5')");
    }

    #[test]
    fn layered_segments_are_chosen_by_name() {
        let (single, _) = two_balls(Frame::Lps);
        // Two layers: the liver in layer 0, an overlapping vessel (also label 5) in layer 1.
        let labels: Vec<i32> = single.labels.iter().flat_map(|&l| [l, if l == 2 { 5 } else { 0 }]).collect();
        let segments = vec![("liver".into(), 0, 5), ("vessel".into(), 1, 5)];
        let map = Labelmap { layers: 2, labels, segments, ..single.clone() };
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("layers.seg.nrrd");
        write_nrrd(&path, &map).unwrap();
        let back = read_labelmap(&path).unwrap();
        assert!(back == map);
        let (vessel, name) = back.select("vessel").unwrap();
        assert_eq!(name, "label 5 ('vessel')");
        assert_eq!(vessel.count(), single.labels.iter().filter(|&&l| l == 2).count());
        assert!(back.select("5").unwrap_err().to_string().contains("in 2 layers: choose the segment by name"));
        // Without `Segment{i}_Layer` (a file from before segments shared layers), segment i is in
        // layer i, as 3D Slicer reads it; a layer the file does not hold is refused.
        let text = std::fs::read(&path).unwrap();
        let cut = text.windows(2).position(|w| w == b"\n\n").unwrap() + 2;
        let header = String::from_utf8(text[..cut].to_vec()).unwrap();
        let unlayered: String = header.lines().filter(|l| !l.contains("_Layer:=")).map(|l| format!("{l}\n")).collect();
        assert_ne!(unlayered, header, "the layers were named");
        let legacy = dir.path().join("legacy.seg.nrrd");
        std::fs::write(&legacy, [unlayered.as_bytes(), &text[cut..]].concat()).unwrap();
        let (vessel, _) = read_labelmap(&legacy).unwrap().select("vessel").unwrap();
        assert_eq!(vessel.count(), single.labels.iter().filter(|&&l| l == 2).count(), "layer 1's segment");
        let beyond = header.replace("Segment1_Layer:=1", "Segment1_Layer:=3");
        assert_ne!(beyond, header);
        std::fs::write(&legacy, [beyond.as_bytes(), &text[cut..]].concat()).unwrap();
        let e = read_labelmap(&legacy).unwrap_err().to_string();
        assert!(e.contains("Segment1_Layer = 3 ('vessel'), but the file holds 2 layer(s)"), "{e}");
    }

    /// Rewrites the NIfTI file at `path` to have no sform, a qform with the offset (1, 2, 3) and
    /// the given header floats (byte offset, value); returns its bytes.
    fn qform_only(path: &Path, floats: &[(usize, f32)]) -> Vec<u8> {
        let mut bytes = std::fs::read(path).unwrap();
        bytes[254..256].copy_from_slice(&0i16.to_le_bytes());
        bytes[252..254].copy_from_slice(&1i16.to_le_bytes());
        for &(o, x) in floats.iter().chain(&[(268, 1.0), (272, 2.0), (276, 3.0)]) {
            bytes[o..o + 4].copy_from_slice(&x.to_le_bytes());
        }
        std::fs::write(path, &bytes).unwrap();
        bytes
    }

    /// A label that fills its whole image (an all-ones mask) is refused as no organ, before it is
    /// meshed.
    #[test]
    fn a_label_filling_its_image_is_no_organ() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("ones.nii");
        let affine = [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]];
        write_nifti(&path, &Labelmap::single([30, 30, 30], vec![1; 27_000], affine, Frame::Ras)).unwrap();
        let e = read_labelmap_surface(&path, Some("1"), None, &ExtractOptions::default()).unwrap_err().to_string();
        assert!(e.contains("label 1 fills 100 % of the image: a mask of everything"), "{e}");
    }

    /// A NIfTI without qform and sform codes places its voxels nowhere: read at its indices times
    /// the spacing, with no scanner frame, and said so; an organ cut by the image's border is
    /// said to be, naming the faces.
    #[test]
    fn a_labelmap_placed_nowhere_or_cut_by_its_border_is_warned_about() {
        let dir = tempfile::tempdir().unwrap();
        let (map, _) = two_balls(Frame::Ras);
        let path = dir.path().join("seg.nii");
        write_nifti(&path, &map).unwrap();
        let placed = read_labelmap_surface(&path, Some("5"), None, &ExtractOptions::default()).unwrap();
        assert_eq!((placed.scanner_frame(), placed.warnings.len()), (Some(Frame::Ras), 0), "{:?}", placed.warnings);
        let mut bytes = std::fs::read(&path).unwrap();
        bytes[252..256].copy_from_slice(&[0; 4]);
        std::fs::write(&path, &bytes).unwrap();
        let nowhere = read_labelmap_surface(&path, Some("5"), None, &ExtractOptions::default()).unwrap();
        assert_eq!(nowhere.scanner_frame(), None);
        assert!(nowhere.lines()[0].contains("no scanner frame"), "{:?}", nowhere.lines());
        assert!(nowhere.warnings[0].contains("without qform and sform"), "{:?}", nowhere.warnings);
        let (lo, _) = crate::bounds(&nowhere.surface.vertices);
        assert!(lo.iter().all(|&x| x > -1.0), "at indices times spacing, from the origin: {lo:?}");
        // The ball reaches past the first slice (k = 0) once the image starts at its middle.
        let [ni, nj, _] = map.dims;
        let cut = Labelmap { dims: [ni, nj, 10], labels: map.labels[ni * nj * 6..].to_vec(), ..map.clone() };
        let path = dir.path().join("cut.nii");
        write_nifti(&path, &cut).unwrap();
        let organ = read_labelmap_surface(&path, Some("5"), None, &ExtractOptions::default()).unwrap();
        assert_eq!(organ.warnings.len(), 1, "{:?}", organ.warnings);
        assert!(organ.warnings[0].contains("image's border (k = 0, inferior)"), "{:?}", organ.warnings);
        // The whole ball in an image cropped to it (as 3D Slicer saves a segmentation) tapers to
        // every face it touches: not cut.
        let (lo, hi) = (0..3).fold(([usize::MAX; 3], [0; 3]), |(mut lo, mut hi), d| {
            for (v, &l) in map.labels.iter().enumerate() {
                let ijk = [v % ni, v / ni % nj, v / (ni * nj)];
                if l == 5 {
                    (lo[d], hi[d]) = (lo[d].min(ijk[d]), hi[d].max(ijk[d]));
                }
            }
            (lo, hi)
        });
        let dims: [usize; 3] = std::array::from_fn(|d| hi[d] - lo[d] + 1);
        let labels = (0..dims.iter().product::<usize>())
            .map(|v| {
                let ijk = [lo[0] + v % dims[0], lo[1] + v / dims[0] % dims[1], lo[2] + v / (dims[0] * dims[1])];
                map.labels[ijk[0] + ni * (ijk[1] + nj * ijk[2])]
            })
            .collect();
        let cropped = Labelmap { dims, labels, ..map.clone() };
        let path = dir.path().join("cropped.nii");
        write_nifti(&path, &cropped).unwrap();
        let organ = read_labelmap_surface(&path, Some("5"), None, &ExtractOptions::default()).unwrap();
        assert!(organ.warnings.is_empty(), "{:?}", organ.warnings);
    }

    #[test]
    fn a_qform_header_gives_its_rotation_and_flip() {
        let dir = tempfile::tempdir().unwrap();
        let (map, _) = two_balls(Frame::Ras);
        let path = dir.path().join("q.nii");
        write_nifti(&path, &map).unwrap();
        // A qform turning half a turn about z, with qfac -1 (k flipped), offset (1,2,3).
        let mut bytes = qform_only(&path, &[(76, -1.0), (256, 0.0), (260, 0.0), (264, 1.0)]);
        let back = read_labelmap(&path).unwrap();
        let expected = [[-0.75, 0.0, 0.0, 1.0], [0.0, -0.875, 0.0, 2.0], [0.0, 0.0, -2.5, 3.0]];
        assert!(close(&back.affine, &expected, 1e-6), "{:?}", back.affine);
        // A quaternion longer than a rotation's is normalised (as nifti1_io does) rather than let
        // scale the voxels.
        bytes[264..268].copy_from_slice(&2f32.to_le_bytes());
        std::fs::write(&path, &bytes).unwrap();
        let back = read_labelmap(&path).unwrap();
        assert!(close(&back.affine, &expected, 1e-6), "{:?}", back.affine);
    }

    /// A structure one slice thick loses most of its volume to the surface's smoothing, and is
    /// said to; a ball does not; an organ one slice thick is refused.
    #[test]
    fn a_thinned_segment_is_warned_about() {
        let dir = tempfile::tempdir().unwrap();
        let (mut map, _) = two_balls(Frame::Ras);
        let [ni, nj, _] = map.dims;
        for j in 5..40 {
            for i in 5..45 {
                map.labels[i + ni * (j + nj * 3)] = 7;
            }
        }
        let path = dir.path().join("plate.nii");
        write_nifti(&path, &map).unwrap();
        let thinned = |label: &str| {
            let read = read_labelmap_surface(&path, Some(label), None, &ExtractOptions::structure()).unwrap();
            read.warnings.iter().any(|w| w.contains("less than its voxels: a structure a voxel or two thick"))
        };
        assert!(thinned("7"), "a plate one slice thick");
        assert!(!thinned("5"), "a ball");
        let e = read_labelmap_surface(&path, Some("7"), None, &ExtractOptions::default()).unwrap_err().to_string();
        assert!(e.contains("it lies on a single slice of the image"), "{e}");
    }

    /// A piece of the organ's label dropped apart from its largest is warned about when it holds
    /// more than specks (a 5 mm ball beside a 10 mm one: 12 %; a 3 mm one, 2.8 %; a voxel is not);
    /// so is an organ of no organ's size, as a header naming microns for millimetre voxels makes
    /// it.
    #[test]
    fn a_dropped_lobe_and_an_organ_of_no_organs_size_are_warned_about() {
        let dir = tempfile::tempdir().unwrap();
        let (map, _) = two_balls(Frame::Ras);
        let path = dir.path().join("lobes.nii");
        let warned = |map: &Labelmap, what: &str| {
            write_nifti(&path, map).unwrap();
            let read = read_labelmap_surface(&path, Some("5"), None, &ExtractOptions::default()).unwrap();
            read.warnings.iter().find(|w| w.contains(what)).cloned()
        };
        let drop = "were dropped: if they are part of it";
        let small =
            Labelmap { labels: map.labels.iter().map(|&l| if l == 2 { 5 } else { l }).collect(), ..map.clone() };
        assert!(warned(&small, drop).expect("a ball of 2.8 %").contains("2.8 % of its voxels"));
        let mut speck = map.clone();
        *speck.labels.last_mut().unwrap() = 5;
        assert_eq!(warned(&speck, drop), None);
        let other = [25.0, -80.0, 215.0];
        let mut lobe = map.clone();
        for (v, label) in lobe.labels.iter_mut().enumerate() {
            let ijk = [v % 52, v / 52 % 44, v / (52 * 44)];
            let p: Point = std::array::from_fn(|r| map.affine[r][r] * ijk[r] as f64 + map.affine[r][3]);
            if norm(sub(p, other)) <= 5.0 {
                *label = 5;
            }
        }
        let w = warned(&lobe, drop).expect("a lobe of 12 %");
        assert!(w.contains("pieces apart from the organ's largest, 1"), "{w}");
        assert_eq!(warned(&map, "no organ's size"), None);
        write_nifti(&path, &map).unwrap();
        let mut bytes = std::fs::read(&path).unwrap();
        bytes[123] = 3 | 8;
        std::fs::write(&path, bytes).unwrap();
        let read = read_labelmap_surface(&path, Some("5"), None, &ExtractOptions::default()).unwrap();
        let w = read.warnings.iter().find(|w| w.contains("no organ's size")).expect("microns");
        assert!(w.contains("spans 0.019") && w.contains("0.00075 × 0.000875 × 0.0025 mm"), "{w}");
        assert!(w.contains("read in millimetres they make an organ's size: --units mm says so"), "{w}");
    }

    /// A sheared voxel grid (its axes not perpendicular) is read as the file places it, and said
    /// to be; a rotated, flipped, anisotropic one is not.
    #[test]
    fn a_sheared_grid_is_named() {
        let dir = tempfile::tempdir().unwrap();
        let (mut map, _) = two_balls(Frame::Ras);
        assert_eq!(shear_warning(&map.affine), None);
        let (c, s) = (0.6_f64.cos(), 0.6_f64.sin());
        let turned = [[-0.75 * c, -0.875 * s, 0.0, 60.0], [-0.75 * s, 0.875 * c, 0.0, -100.0], [0.0, 0.0, 2.5, 200.0]];
        assert_eq!(shear_warning(&turned), None);
        map.affine[0][1] = 0.3 * 0.875;
        let path = dir.path().join("shear.nii");
        write_nifti(&path, &map).unwrap();
        let read = read_labelmap_surface(&path, Some("5"), None, &ExtractOptions::default()).unwrap();
        let w = read.warnings.iter().find(|w| w.contains("from perpendicular")).expect("named");
        assert!(w.contains("16.7° from perpendicular (a sheared grid)"), "{w}");
    }

    /// Where both forms are set, the sform is read when its code is 1 (scanner), the qform when
    /// the sform's is another (as 3D Slicer reads it through ITK); forms that disagree are said to.
    #[test]
    fn the_form_slicer_reads_is_read_and_disagreeing_forms_are_named() {
        let dir = tempfile::tempdir().unwrap();
        let (map, _) = two_balls(Frame::Ras);
        let path = dir.path().join("sq.nii");
        write_nifti(&path, &map).unwrap();
        let sform = read_labelmap(&path).unwrap().affine;
        // The qform: the sform's axes (half a turn about y, k flipped), offset (1, 2, 3).
        let mut bytes = qform_only(&path, &[(76, -1.0), (256, 0.0), (260, 1.0), (264, 0.0)]);
        let qform = read_labelmap(&path).unwrap().affine;
        let axes = |a: &[[f64; 4]; 3]| a.map(|row| [row[0], row[1], row[2], 0.0]);
        assert!(close(&axes(&sform), &axes(&qform), 1e-6), "{sform:?} {qform:?}");
        let mut with_sform = |code: i16, x: f32| {
            bytes[254..256].copy_from_slice(&code.to_le_bytes());
            for (at, offset) in [(292, x), (308, 2.0f32), (324, 3.0)] {
                bytes[at..at + 4].copy_from_slice(&offset.to_le_bytes());
            }
            std::fs::write(&path, &bytes).unwrap();
            read_labelmap(&path).unwrap()
        };
        let aligned = with_sform(2, -49.0);
        assert_eq!(aligned.affine[0][3], 1.0, "code 2: the qform");
        assert!(aligned.warnings[0].1.contains("place the image up to 50.0 mm apart: read by the qform"));
        let scanner = with_sform(1, -49.0);
        assert_eq!(scanner.affine[0][3], -49.0, "code 1: the sform");
        assert!(scanner.warnings[0]
            .1
            .contains("read by the sform, as 3D Slicer (ITK) and nibabel read it; tools that take the qform"));
        assert!(with_sform(2, 1.0).warnings.is_empty(), "the forms agree");
    }

    /// A qform's zero spacing is taken as 1, a negative one as its size with the axis reversed
    /// (as ITK reads them: SimpleITK 2 gives spacing 1.5 and a reversed direction for -1.5),
    /// with a warning.
    #[test]
    fn a_qform_spacing_that_is_not_positive_is_read_as_itk_reads_it() {
        let dir = tempfile::tempdir().unwrap();
        let (map, _) = two_balls(Frame::Ras);
        let path = dir.path().join("q.nii");
        write_nifti(&path, &map).unwrap();
        // The identity quaternion, pixdim (0, -2, 2.5).
        qform_only(&path, &[(80, 0.0), (84, -2.0), (256, 0.0), (260, 0.0), (264, 0.0)]);
        let back = read_labelmap(&path).unwrap();
        let expected = [[1.0, 0.0, 0.0, 1.0], [0.0, -2.0, 0.0, 2.0], [0.0, 0.0, 2.5, 3.0]];
        assert!(close(&back.affine, &expected, 1e-6), "{:?}", back.affine);
        assert_eq!(back.warnings.len(), 1, "{:?}", back.warnings);
        assert!(
            back.warnings[0].1.starts_with("pixdim[2] = -2 is negative: read as 3D Slicer (ITK)"),
            "{:?}",
            back.warnings
        );
    }

    /// A NaN or infinite scl_slope means no scaling, a non-finite scl_inter 0 (as nifti1_io and
    /// nibabel read them).
    #[test]
    fn a_non_finite_nifti_scale_means_no_scaling() {
        let dir = tempfile::tempdir().unwrap();
        let (map, _) = two_balls(Frame::Ras);
        let path = dir.path().join("s.nii");
        write_nifti(&path, &map).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        for (slope, intercept) in [(f32::NAN, 0.0), (f32::INFINITY, f32::NAN), (1.0, f32::NAN), (0.0, 7.0)] {
            let mut bytes = bytes.clone();
            bytes[112..116].copy_from_slice(&slope.to_le_bytes());
            bytes[116..120].copy_from_slice(&intercept.to_le_bytes());
            std::fs::write(&path, &bytes).unwrap();
            let back = read_labelmap(&path).unwrap_or_else(|e| panic!("slope {slope}, intercept {intercept}: {e}"));
            assert!(back.labels == map.labels, "slope {slope}, intercept {intercept}");
        }
    }

    /// A NIfTI of several volumes (a network's one-hot channels) is refused with what to save
    /// instead; one whose fourth axis holds a single volume is that volume.
    #[test]
    fn a_nifti_of_several_volumes_is_refused_saying_what_a_labelmap_is() {
        let dir = tempfile::tempdir().unwrap();
        let (map, _) = two_balls(Frame::Ras);
        let path = dir.path().join("v.nii");
        write_nifti(&path, &map).unwrap();
        let mut bytes = std::fs::read(&path).unwrap();
        bytes[40..42].copy_from_slice(&4i16.to_le_bytes());
        for (volumes, refused) in [(1i16, false), (3, true)] {
            bytes[48..50].copy_from_slice(&volumes.to_le_bytes());
            std::fs::write(&path, &bytes).unwrap();
            match read_labelmap(&path) {
                Ok(back) => assert!(!refused && back.labels == map.labels),
                Err(e) => {
                    let e = e.to_string();
                    assert!(refused && e.contains("3 volumes (one-hot channels") && !e.contains("endian"), "{e}");
                }
            }
        }
    }

    /// Labels stored as ten times their value with a slope of 0.1 (in 32 bits: 0.100000001490116)
    /// read as labels; a slope that leaves a voxel between labels is refused.
    #[test]
    fn a_nifti_scaled_by_a_32_bit_slope_gives_its_labels() {
        let dir = tempfile::tempdir().unwrap();
        let (map, _) = two_balls(Frame::Ras);
        let tenfold = Labelmap { labels: map.labels.iter().map(|l| 10 * l).collect(), ..map.clone() };
        let path = dir.path().join("s.nii");
        write_nifti(&path, &tenfold).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        let scaled = |slope: f32| {
            let mut bytes = bytes.clone();
            bytes[112..116].copy_from_slice(&slope.to_le_bytes());
            std::fs::write(&path, &bytes).unwrap();
            read_labelmap(&path)
        };
        assert_eq!(scaled(0.1).unwrap().labels, map.labels);
        let e = scaled(0.025).unwrap_err().to_string();
        assert!(e.contains("is not a label"), "{e}");
    }

    #[test]
    fn bad_files_are_refused_clearly() {
        let dir = tempfile::tempdir().unwrap();
        let write = |name: &str, bytes: &[u8]| {
            let p = dir.path().join(name);
            std::fs::write(&p, bytes).unwrap();
            read_labelmap(&p).unwrap_err().to_string()
        };
        assert!(write("a.nii", b"short").contains("too short"));
        assert!(write("b.nii", &[0u8; 400]).contains("not a NIfTI file (its header size is neither 348"));
        assert!(write("c.nrrd", b"P3\n").contains("not a NRRD file"));
        let header = "NRRD0004\ntype: short\ndimension: 3\nsizes: 2 2 2\nspace: left-posterior-superior\n\
                      space directions: (1,0,0) (0,1,0) (0,0,1)\nendian: little\nencoding: raw\n\n";
        assert!(write("d.nrrd", header.as_bytes()).contains("the data hold 0 bytes, 16 expected"));
        // Shorts without their byte order would be read in a guessed one: refused, as
        // teem refuses them; bytes need none.
        let data = [0u8; 16];
        let unordered = header.replace("endian: little\n", "");
        assert!(write("d1.nrrd", &[unordered.as_bytes(), &data].concat()).contains("no 'endian' field"));
        let odd = header.replace("endian: little", "endian: middle");
        assert!(write("d2.nrrd", &[odd.as_bytes(), &data].concat()).contains("endian 'middle' is neither"));
        // 64-bit labels (NumPy's default integer, as SimpleITK writes it).
        let longs = header.replace("type: short", "type: int64");
        let voxels: Vec<u8> = (0..8).flat_map(|i| i64::from(i == 6).to_le_bytes()).collect();
        std::fs::write(dir.path().join("d4.nrrd"), [longs.as_bytes(), &voxels].concat()).unwrap();
        assert_eq!(read_labelmap(dir.path().join("d4.nrrd")).unwrap().labels, [0, 0, 0, 0, 0, 0, 1, 0]);
        let bytes = unordered.replace("type: short", "type: uchar");
        std::fs::write(dir.path().join("d3.nrrd"), [bytes.as_bytes(), &[0, 0, 0, 1, 0, 0, 0, 0]].concat()).unwrap();
        assert_eq!(read_labelmap(dir.path().join("d3.nrrd")).unwrap().labels, [0, 0, 0, 1, 0, 0, 0, 0]);
        let zeros = [header.as_bytes(), &[0u8; 16]].concat();
        assert!(write("e.nrrd", &zeros).contains("empty"));
        // Sizes one slice short of the data (2 × 2 shorts more) would crop the organ: refused. A line
        // end after raw data is not.
        let slab = [header.as_bytes(), &[0u8; 24]].concat();
        assert!(write("e1.nrrd", &slab).contains("the data hold 24 bytes, 16 expected"), "{}", write("e1.nrrd", &slab));
        let padded = [header.as_bytes(), &[0u8; 14], &[1u8, 0], &[0u8; 2]].concat();
        std::fs::write(dir.path().join("e2.nrrd"), &padded).unwrap();
        assert_eq!(read_labelmap(dir.path().join("e2.nrrd")).unwrap().labels.iter().filter(|&&l| l == 1).count(), 1);
        let floats = header.replace("short", "float");
        let values: Vec<u8> = (0..8).flat_map(|i| (i as f32 * 0.3).to_le_bytes()).collect();
        let said = write("f.nrrd", &[floats.as_bytes(), &values].concat());
        assert!(said.contains("voxel 1 holds 0.30000001192092896, not a label"), "{said}");
        // A float export's rounding (1.0000002 in 32 bits) is the label it rounds to.
        let near: Vec<u8> = (0..8).flat_map(|i| if i == 6 { 1.000_000_2_f32 } else { 0.0 }.to_le_bytes()).collect();
        std::fs::write(dir.path().join("f1.nrrd"), [floats.as_bytes(), &near].concat()).unwrap();
        assert_eq!(read_labelmap(dir.path().join("f1.nrrd")).unwrap().labels, [0, 0, 0, 0, 0, 0, 1, 0]);
        let scanner = header.replace("left-posterior-superior", "scanner-xyz");
        assert!(write("g.nrrd", scanner.as_bytes()).contains("space 'scanner-xyz' is not supported"));
        // Sizes whose voxels overflow a byte count, and units that are not lengths.
        let huge = header.replace("sizes: 2 2 2", "sizes: 9223372036854775809 2 1");
        assert!(write("h.nrrd", huge.as_bytes()).contains("bad sizes"));
        let seconds = header.replace("encoding", "space units: \"s\" \"s\" \"s\"\nencoding");
        assert!(write("i.nrrd", seconds.as_bytes()).contains("space unit \"s\" is not supported"));
        let mixed = header.replace("encoding", "space units: \"mm\" \"m\" \"mm\"\nencoding");
        assert!(write("j.nrrd", mixed.as_bytes()).contains("one unit for the three axes"));
        // A non-spatial axis last: of one voxel it is no axis; of more it must come first.
        let last = header
            .replace("dimension: 3", "dimension: 4")
            .replace("sizes: 2 2 2", "sizes: 2 2 2 3")
            .replace("(0,0,1)\n", "(0,0,1) none\n");
        let e = write("k.nrrd", &[last.as_bytes(), &[0u8; 48]].concat());
        assert!(e.contains("is axis 3 of 'sizes' [2, 2, 2, 3]: it must come first"), "{e}");
        let one = last.replace("sizes: 2 2 2 3", "sizes: 2 2 2 1");
        let voxels: Vec<u8> = (0..8).flat_map(|i| i16::from(i == 5).to_le_bytes()).collect();
        std::fs::write(dir.path().join("k1.nrrd"), [one.as_bytes(), &voxels].concat()).unwrap();
        let read = read_labelmap(dir.path().join("k1.nrrd")).unwrap();
        assert_eq!((read.dims, read.layers, read.labels[5]), ([2, 2, 2], 1, 1));
        // A dimension that is not the number of sizes, a size that is no count.
        let dimension = header.replace("dimension: 3", "dimension: 99");
        assert!(write("j1.nrrd", dimension.as_bytes()).contains("dimension: 99, but 'sizes' gives 3 axes"));
        let negative = header.replace("sizes: 2 2 2", "sizes: 2 -153 2");
        assert!(write("j2.nrrd", negative.as_bytes()).contains("sizes: \"-153\" is not a number of voxels"));
        // Ascii data: read as numbers, their count checked.
        let ascii = header.replace("encoding: raw", "encoding: ascii");
        let read = |name: &str, data: &str| {
            let p = dir.path().join(name);
            std::fs::write(&p, format!("{ascii}{data}")).unwrap();
            read_labelmap(&p)
        };
        assert_eq!(read("k.nrrd", "0 0 0 1\n0 1 1 0\n").unwrap().labels, [0, 0, 0, 1, 0, 1, 1, 0]);
        assert!(read("l.nrrd", "0 0 1").unwrap_err().to_string().contains("hold 3 values, 8 expected"));
        assert!(read("m.nrrd", "0 0 1 x 0 0 0 0").unwrap_err().to_string().contains("voxel 3 holds \"x\""));
    }

    /// A NRRD header detached from its data (`.nhdr`, as 3D Slicer can save a volume) reads as
    /// the file with both; data in several files, a data file that is not there or a Git LFS
    /// pointer in its place are refused by name.
    #[test]
    fn a_detached_nrrd_header_reads_its_data_file() {
        let dir = tempfile::tempdir().unwrap();
        let (map, _) = two_balls(Frame::Lps);
        let whole = dir.path().join("seg.nrrd");
        write_nrrd(&whole, &map).unwrap();
        let bytes = std::fs::read(&whole).unwrap();
        let split = bytes.windows(2).position(|w| w == b"\n\n").unwrap();
        let header = String::from_utf8(bytes[..split + 1].to_vec()).unwrap();
        std::fs::create_dir(dir.path().join("data")).unwrap();
        std::fs::write(dir.path().join("data/seg.raw.gz"), &bytes[split + 2..]).unwrap();
        // Ending with the file, without the blank line an attached header needs.
        let nhdr = dir.path().join("seg.nhdr");
        std::fs::write(&nhdr, format!("{header}data file: data/seg.raw.gz\n")).unwrap();
        assert!(is_labelmap(&nhdr));
        assert!(read_labelmap(&nhdr).unwrap() == read_labelmap(&whole).unwrap());
        // A file name with spaces is one file.
        std::fs::copy(dir.path().join("data/seg.raw.gz"), dir.path().join("my seg.raw.gz")).unwrap();
        std::fs::write(&nhdr, format!("{header}data file: my seg.raw.gz\n")).unwrap();
        assert!(read_labelmap(&nhdr).unwrap() == read_labelmap(&whole).unwrap());
        std::fs::write(&nhdr, format!("{header}data file: seg.raw.gz\n")).unwrap();
        let e = read_labelmap(&nhdr).unwrap_err().to_string();
        assert!(e.contains("its data file") && e.contains("seg.raw.gz cannot be read"), "{e}");
        let pointer = "version https://git-lfs.github.com/spec/v1\noid sha256:4d7a2146\nsize 12345\n";
        std::fs::write(dir.path().join("seg.raw.gz"), pointer).unwrap();
        let e = read_labelmap(&nhdr).unwrap_err().to_string();
        assert!(e.contains("seg.raw.gz: a Git LFS pointer, not the file itself"), "{e}");
        std::fs::write(&nhdr, format!("{header}data file: slice%03d.raw 1 46 1\n")).unwrap();
        assert!(read_labelmap(&nhdr).unwrap_err().to_string().contains("data in several files are not read"));
        std::fs::write(&nhdr, &header).unwrap();
        assert!(read_labelmap(&nhdr).unwrap_err().to_string().contains("the header does not end"));
    }

    /// What cannot be an organ's segmentation says what to give instead.
    #[test]
    fn a_dicom_folder_or_an_unread_format_says_what_to_give() {
        let dir = tempfile::tempdir().unwrap();
        let said = |name: &str| unreadable_segmentation(&dir.path().join(name)).unwrap_or_default();
        assert!(said("").starts_with("a folder, not a file (a DICOM series is not read)"), "{}", said(""));
        assert!(said("IM0001").starts_with("neither a DICOM file by its content nor named by an extension"));
        assert!(said("liver.mgz").contains("this image format is not read"), "{}", said("liver.mgz"));
        assert!(said("case.mrb").starts_with("a 3D Slicer scene bundle (a zip): unzip it"));
        assert!(said("case.mrml").starts_with("a 3D Slicer scene, which names its files"));
        assert!(said("liver.xyz").starts_with("no such file, and not a labelmap nor a surface"));
        std::fs::write(dir.path().join("liver.xyz"), "1 2 3\n").unwrap();
        assert!(said("liver.xyz").starts_with("not a labelmap nor a surface"));
        for fine in ["liver.STL", "seg.seg.nrrd", "seg.nii.gz", "seg.nhdr", "liver.mhd", "organ.vtu", "seg.dcm"] {
            assert_eq!(said(fine), "", "{fine}");
        }
        // A DICOM file is one by its content, as PACS write them: without an extension.
        std::fs::copy(concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/liver_labels_rt.dcm"), dir.path().join("RS1"))
            .unwrap();
        assert_eq!(said("RS1"), "");
        assert!(read_labelmap(dir.path().join("RS1")).is_ok());
        assert!(said("").starts_with("a folder, not a file: give its DICOM SEG or RTSTRUCT, if one of its 1 DICOM"));
    }

    /// A CT given for a labelmap is named an image, in a message of a line; a labelmap of many
    /// labels lists twenty of them; a label that is not there is said without "invalid mesh".
    #[test]
    fn an_image_is_not_a_labelmap_and_messages_stay_short() {
        let dir = tempfile::tempdir().unwrap();
        let header = |n: usize| {
            format!(
                "NRRD0004\ntype: short\ndimension: 3\nsizes: {n} {n} {n}\nspace: left-posterior-superior\n\
                 space directions: (1,0,0) (0,1,0) (0,0,1)\nendian: little\nencoding: raw\n\n"
            )
        };
        let write = |name: &str, n: usize, value: &dyn Fn(usize) -> i16| {
            let voxels: Vec<u8> = (0..n * n * n).flat_map(|v| value(v).to_le_bytes()).collect();
            let path = dir.path().join(name);
            std::fs::write(&path, [header(n).as_bytes(), &voxels].concat()).unwrap();
            path
        };
        // Hounsfield units: air at −1000, soft tissue about 40.
        let ct = write("ct.nrrd", 12, &|v| if v % 7 == 0 { -1000 } else { 40 + (v % 13) as i16 });
        let e = read_labelmap(&ct).unwrap_err().to_string();
        assert!(e.contains("holds 14 distinct values, from -1000 to 52: an image"), "{e}");
        // Grey values without a sign (an MR, a CT stored with an offset).
        let mr = write("mr.nrrd", 12, &|v| v as i16);
        let e = read_labelmap(&mr).unwrap_err().to_string();
        assert!(e.contains("holds over 1000 distinct values, from 0 to 1727: an image"), "{e}");
        assert!(e.len() < 300, "{e}");
        // Over a hundred labels (a row of voxels each), none chosen: twenty listed.
        let many = write("many.nrrd", 12, &|v| {
            if v % 12 < 10 && v / 144 < 9 {
                (1 + v / 12 % 12 + v / 144 * 12) as i16
            } else {
                0
            }
        });
        let map = read_labelmap(&many).unwrap();
        assert!(map.present().len() > 30, "{}", map.present().len());
        let e = read_labelmap_surface(&many, None, None, &ExtractOptions::default()).unwrap_err().to_string();
        assert!(
            e.contains("choose one with --label") && e.contains(&format!("and {} more", map.present().len() - 20)),
            "{e}"
        );
        let e = read_labelmap_surface(&many, Some("500"), None, &ExtractOptions::default()).unwrap_err().to_string();
        assert!(e.contains("label 500 is not in the labelmap") && !e.contains("invalid mesh"), "{e}");
    }

    /// The unit a header names (NIfTI's `xyzt_units`, NRRD's `space units`) scales the world to
    /// millimetres; a NIfTI file naming none is read in mm.
    #[test]
    fn the_header_s_unit_is_converted_to_millimetres() {
        let dir = tempfile::tempdir().unwrap();
        let (map, _) = two_balls(Frame::Ras);
        let path = dir.path().join("u.nii");
        write_nifti(&path, &map).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        let in_metres = |affine: [[f64; 4]; 3]| affine.map(|row| row.map(|x| ((x * 1e-3) as f32) as f64));
        for (code, scale) in [(0u8, 1.0), (2, 1.0), (1, 1e3), (3, 1e-3)] {
            let mut bytes = bytes.clone();
            // Metres and microns: the header's affine in that unit, so that the world is the same.
            let stored = match code {
                1 => in_metres(map.affine),
                3 => map.affine.map(|row| row.map(|x| x * 1e3)),
                _ => map.affine,
            };
            for (r, row) in stored.iter().enumerate() {
                for (c, x) in row.iter().enumerate() {
                    bytes[280 + 16 * r + 4 * c..][..4].copy_from_slice(&(*x as f32).to_le_bytes());
                }
            }
            bytes[123] = code | 8;
            std::fs::write(&path, &bytes).unwrap();
            let back = read_labelmap(&path).unwrap().affine;
            assert!(close(&back, &map.affine, 1e-3), "unit code {code} (×{scale} mm): {back:?}");
        }
        let mut seconds = bytes;
        seconds[123] = 5;
        std::fs::write(&path, &seconds).unwrap();
        assert!(read_labelmap(&path).unwrap_err().to_string().contains("spatial unit code 5"));
        // NRRD in metres: the same world as in mm.
        let nrrd = dir.path().join("m.nrrd");
        let metres = Labelmap { affine: in_metres(map.affine), ..map.clone() };
        write_nrrd(&nrrd, &metres).unwrap();
        let text = std::fs::read(&nrrd).unwrap();
        let at = text.windows(10).position(|w| w == b"encoding: ").unwrap();
        let with_units = [&text[..at], b"space units: \"m\" \"m\" \"m\"\n", &text[at..]].concat();
        std::fs::write(&nrrd, with_units).unwrap();
        let back = read_labelmap(&nrrd).unwrap().affine;
        assert!(close(&back, &map.affine, 1e-3), "{back:?}");
    }

    /// A labelmap in metres whose header names no unit is read in mm, with a warning that names
    /// the way out; given its unit, it is the organ the same labelmap in mm gives. A unit other
    /// than the one the header names is refused.
    #[test]
    fn a_unit_is_given_where_the_header_names_none() {
        let dir = tempfile::tempdir().unwrap();
        let (map, _) = two_balls(Frame::Ras);
        let (in_mm, in_m) = (dir.path().join("mm.nii"), dir.path().join("m.nii"));
        write_nifti(&in_mm, &map).unwrap();
        let metres = Labelmap { affine: map.affine.map(|row| row.map(|x| x * 1e-3)), ..map.clone() };
        write_nifti(&in_m, &metres).unwrap();
        let mut bytes = std::fs::read(&in_m).unwrap();
        bytes[123] = 0; // xyzt_units: none
        std::fs::write(&in_m, &bytes).unwrap();
        let read = |path: &Path, unit| read_labelmap_surface(path, Some("5"), unit, &ExtractOptions::default());
        let unnamed = read(&in_m, None).unwrap();
        assert!(unnamed.warnings.iter().any(|w| w.contains("names no unit") && w.contains("--units")), "{unnamed:?}");
        let given = read(&in_m, Some(LengthUnit::Metre)).unwrap();
        let reference = read(&in_mm, None).unwrap();
        assert!(given.warnings.is_empty(), "{:?}", given.warnings);
        let (a, b) = (centroid(&given.surface), centroid(&reference.surface));
        assert!(norm(sub(a, b)) < 1e-3, "{a:?} vs {b:?}");
        assert!((given.spacing[0] - reference.spacing[0]).abs() < 1e-6);
        // The header of the mm file names mm: mm agrees with it, without a word.
        assert!(read(&in_mm, Some(LengthUnit::Millimetre)).unwrap().warnings.is_empty());
        // A header that names metres for voxels in mm: the unit given overrides it, and says so.
        let wrong = dir.path().join("wrong.nii");
        let mut bytes = std::fs::read(&in_mm).unwrap();
        bytes[123] = 1; // xyzt_units: metre
        std::fs::write(&wrong, &bytes).unwrap();
        let overridden = read(&wrong, Some(LengthUnit::Millimetre)).unwrap();
        let (a, b) = (centroid(&overridden.surface), centroid(&reference.surface));
        assert!(norm(sub(a, b)) < 1e-6, "{a:?} vs {b:?}");
        let said =
            "its header names its unit, metres; read in millimetres as given instead (--units): 1,000 times smaller";
        assert!(overridden.warnings.iter().any(|w| w.starts_with(said)), "{:?}", overridden.warnings);
    }

    /// A label split into two pieces of similar size is not one organ; a segment name carried
    /// by two segments is ambiguous.
    #[test]
    fn a_label_in_two_similar_pieces_and_a_shared_name_are_refused() {
        let (mut map, _) = two_balls(Frame::Ras);
        // The tumour ball relabelled as a second, smaller liver piece: dropped below 20 %.
        let twice: Vec<i32> = map.labels.iter().map(|&l| if l == 2 { 5 } else { l }).collect();
        let (mask, _) = Labelmap { labels: twice, ..map.clone() }.select("5").unwrap();
        let (_, report) = mask_surface(&mask, &ExtractOptions::default()).unwrap();
        assert_eq!(report.dropped_pieces.len(), 1);
        // Two balls of the same size, both label 5: refused.
        let (dims, centres) = ([40, 20, 20], [[10.0, 10.0, 10.0], [30.0, 10.0, 10.0]]);
        let labels: Vec<i32> = (0..dims[2])
            .flat_map(|k| (0..dims[1]).flat_map(move |j| (0..dims[0]).map(move |i| [i, j, k].map(|x| x as f64))))
            .map(|p| if centres.iter().any(|&c| norm(sub(p, c)) <= 6.0) { 5 } else { 0 })
            .collect();
        let affine = [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]];
        let twins = Labelmap::single(dims, labels, affine, Frame::Ras);
        let (mask, _) = twins.select("5").unwrap();
        let e = mask_surface(&mask, &ExtractOptions::default()).unwrap_err().to_string();
        assert!(e.contains("several pieces of similar size"), "{e}");
        map.segments.push(("Liver".into(), 0, 2));
        let e = map.select("liver").unwrap_err().to_string();
        assert!(e.contains("2 segments are named 'liver'"), "{e}");
    }

    /// Segments a file puts at the same label (a single layer, no `Segment{i}_LabelValue`: each
    /// takes 1) do not say whose voxels are whose: chosen by name, refused; by number, the label
    /// is not given one of their names.
    #[test]
    fn segments_sharing_a_label_are_not_chosen_by_name() {
        let (mut map, _) = two_balls(Frame::Ras);
        map.segments = vec![("liver".into(), 0, 5), ("stomach".into(), 0, 5)];
        let e = map.select("stomach").unwrap_err().to_string();
        assert!(e.contains("segments 'liver', 'stomach' all take label 5 of layer 0"), "{e}");
        let (_, description) = map.select("5").unwrap();
        assert_eq!(description, "label 5");
        assert!(map.present_text().contains("liver / stomach"), "{}", map.present_text());
        // A file that names no segment is told so, and where the liver is in TotalSegmentator's.
        map.segments.clear();
        let e = map.select("Liver").unwrap_err().to_string();
        assert!(e.contains("the file names no segment") && e.contains("numbers the liver 5"), "{e}");
    }
}
