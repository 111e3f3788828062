//! The labelmaps shipped in `tests/data` (a TotalSegmentator-style NIfTI and a 3D Slicer
//! `.seg.nrrd` of the liver phantom, synthetic): what their generator writes, and the liver
//! extracted whole, at its place in the scanner's frame (RAS for NIfTI, LPS for the NRRD).
//!
//! To write them anew: `AUGSIM_WRITE_TEST_DATA=1 cargo test --release -p augsim-mesh --test labelmap`.

use std::path::{Path, PathBuf};

use augsim_mesh::isosurface::ExtractOptions;
use augsim_mesh::labelmap::{read_labelmap, read_labelmap_surface, write_nifti, write_nrrd, Frame, Labelmap};
use augsim_mesh::length::LengthUnit;
use augsim_mesh::phantom::PhantomSpec;
use augsim_mesh::surface::check_closed_manifold;
use augsim_mesh::{norm, sub, Point};

fn data(name: &str) -> PathBuf {
    Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data")).join(name)
}

/// Where the phantom's origin lies in the scanner's RAS frame (mm): the patient's right, as a
/// liver is.
const PLACE: Point = [-80.0, 30.0, -140.0];

/// The liver phantom (label 5) and a kidney-sized ball below it (label 2) in voxels of
/// 1.5 × 1.5 × 4 mm, the i axis running to the patient's left (as CT scanners write it), in RAS.
fn phantom_labelmap() -> Labelmap {
    let phantom = PhantomSpec::default();
    let (lo, hi) = augsim_mesh::tetmesh::ImplicitDomain::bounds(&phantom);
    let spacing = [1.5, 1.5, 4.0];
    let kidney: Point = [PLACE[0] - 20.0, PLACE[1] + 10.0, PLACE[2] + 1e3 * lo[2] - 28.0];
    // Rounded to quarter millimetres, exact in NIfTI's 32-bit floats.
    let start: Point =
        [PLACE[0] + 1e3 * hi[0] + 6.0, PLACE[1] + 1e3 * lo[1] - 6.0, kidney[2] - 36.0].map(|x| (4.0 * x).round() / 4.0);
    let dims: [usize; 3] = std::array::from_fn(|d| {
        let top = if d == 2 { PLACE[2] + 1e3 * hi[2] + 12.0 } else { PLACE[d] + 1e3 * hi[d] + 6.0 };
        let bottom = if d == 0 { PLACE[0] + 1e3 * lo[0] - 6.0 } else { start[d] };
        ((top - bottom) / spacing[d]).ceil() as usize
    });
    let affine =
        [[-spacing[0], 0.0, 0.0, start[0]], [0.0, spacing[1], 0.0, start[1]], [0.0, 0.0, spacing[2], start[2]]];
    let mut labels = Vec::with_capacity(dims.iter().product());
    for k in 0..dims[2] {
        for j in 0..dims[1] {
            for i in 0..dims[0] {
                let p: Point = std::array::from_fn(|r| affine[r][r] * [i, j, k][r] as f64 + affine[r][3]);
                let local = std::array::from_fn(|d| 1e-3 * (p[d] - PLACE[d]));
                labels.push(if phantom.signed_distance(local) < 0.0 {
                    5
                } else if norm(sub(p, kidney)) < 28.0 {
                    2
                } else {
                    0
                });
            }
        }
    }
    let segments = vec![("liver".into(), 0, 5), ("kidney".into(), 0, 2)];
    Labelmap { segments, ..Labelmap::single(dims, labels, affine, Frame::Ras) }
}

/// The same voxels in LPS, as 3D Slicer's DICOM-derived files hold them.
fn in_lps(map: &Labelmap) -> Labelmap {
    let mut lps = Labelmap { frame: Frame::Lps, ..map.clone() };
    (0..2).for_each(|r| lps.affine[r].iter_mut().for_each(|x| *x = -*x));
    lps
}

#[test]
fn shipped_labelmaps_are_what_their_generator_writes() {
    let map = phantom_labelmap();
    if std::env::var_os("AUGSIM_WRITE_TEST_DATA").is_some() {
        write_nifti(data("liver_labels.nii.gz"), &Labelmap { segments: Vec::new(), ..map.clone() }).unwrap();
        write_nrrd(data("liver_labels.seg.nrrd"), &in_lps(&map)).unwrap();
    }
    let nifti = read_labelmap(data("liver_labels.nii.gz")).unwrap();
    let written = Labelmap { segments: Vec::new(), named_unit: Some(LengthUnit::Millimetre), ..map.clone() };
    assert!(nifti == written, "the NIfTI differs from its generator");
    let nrrd = read_labelmap(data("liver_labels.seg.nrrd")).unwrap();
    assert!(nrrd == in_lps(&map), "the NRRD differs from its generator");
    assert_eq!(nifti.dims, [153, 113, 46]);
}

/// The mean of the vertices.
fn centre(points: &[Point]) -> Point {
    std::array::from_fn(|d| points.iter().map(|p| p[d]).sum::<f64>() / points.len() as f64)
}

#[test]
fn the_shipped_liver_comes_back_whole_at_its_place() {
    let phantom = PhantomSpec::default();
    let exact = phantom.volume() * 1e9;
    let options = ExtractOptions::default();
    let ras = read_labelmap_surface(data("liver_labels.nii.gz"), Some("5"), None, &options).unwrap();
    let report = check_closed_manifold(&ras.surface).unwrap();
    let error = report.volume / exact - 1.0;
    println!(
        "{:#?}\nvolume {:.1} mL, the phantom's {:.1} mL ({:+.2} %)",
        ras.lines(),
        report.volume * 1e-3,
        exact * 1e-3,
        100.0 * error
    );
    assert!(error.abs() < 0.03, "{error}");
    assert_eq!(ras.frame, Frame::Ras);
    // The extent within a voxel of the phantom's, at its place.
    let (lo, hi) = augsim_mesh::bounds(&ras.surface.vertices);
    let (plo, phi) = augsim_mesh::tetmesh::ImplicitDomain::bounds(&phantom);
    let margin = 0.25 * phantom.blend + 1e-3;
    for d in 0..3 {
        let (want_lo, want_hi) = (PLACE[d] + 1e3 * (plo[d] + margin), PLACE[d] + 1e3 * (phi[d] - margin));
        let voxel = [1.5, 1.5, 4.0][d];
        assert!((lo[d] - want_lo).abs() < voxel && (hi[d] - want_hi).abs() < voxel, "axis {d}: {lo:?} {hi:?}");
    }
    let lps = read_labelmap_surface(data("liver_labels.seg.nrrd"), Some("Liver"), None, &options).unwrap();
    assert_eq!((lps.frame, lps.label.as_str()), (Frame::Lps, "label 5 ('liver')"));
    let (a, b) = (centre(&ras.surface.vertices), centre(&lps.surface.vertices));
    assert!(norm(sub(b, [-a[0], -a[1], a[2]])) < 1e-6, "{a:?} vs {b:?}");
}

/// The world positions (mm, rounded to µm) of the voxels of `map` in `choice`.
fn voxel_positions(map: &Labelmap, choice: &str) -> std::collections::BTreeSet<[i64; 3]> {
    let (mask, _) = map.select(choice).unwrap();
    let [nx, ny, _] = mask.dims;
    let a = mask.affine;
    let at = |n: usize| {
        let ijk = [(n % nx) as f64, ((n / nx) % ny) as f64, (n / (nx * ny)) as f64];
        std::array::from_fn(|r| ((0..3).map(|c| a[r][c] * ijk[c]).sum::<f64>() + a[r][3]) * 1e3)
            .map(|x| x.round() as i64)
    };
    mask.inside.iter().enumerate().filter(|(_, &inside)| inside).map(|(n, _)| at(n)).collect()
}

/// The phantom's labelmap as a DICOM SEG written by highdicom (`make_dicom.py`: a writer
/// that is not augsim's; its frames stacked along −z of their normal, the empty ones left out)
/// holds the same voxels, at the same places in LPS, as the `.seg.nrrd` it was made from.
#[test]
fn a_dicom_seg_holds_the_voxels_of_the_labelmap_it_was_made_from() {
    let seg = read_labelmap(data("liver_labels_seg.dcm")).unwrap();
    let nrrd = read_labelmap(data("liver_labels.seg.nrrd")).unwrap();
    assert_eq!(seg.frame, Frame::Lps);
    assert!(seg.placed);
    let names: Vec<(&str, i32)> = seg.segments.iter().map(|(name, _, label)| (name.as_str(), *label)).collect();
    assert_eq!(names, [("liver", 1), ("kidney", 2)]);
    assert_eq!(seg.spacing(), [1.5, 1.5, 4.0]);
    for (in_seg, in_nrrd) in [("liver", "liver"), ("2", "kidney")] {
        let (a, b) = (voxel_positions(&seg, in_seg), voxel_positions(&nrrd, in_nrrd));
        assert!(!a.is_empty() && a == b, "{in_seg}: {} voxels, {} in the NRRD", a.len(), b.len());
    }
    let options = ExtractOptions::default();
    let from_seg = read_labelmap_surface(data("liver_labels_seg.dcm"), Some("liver"), None, &options).unwrap();
    let from_nrrd = read_labelmap_surface(data("liver_labels.seg.nrrd"), Some("liver"), None, &options).unwrap();
    assert_eq!(from_seg.frame, Frame::Lps);
    assert!(from_seg.warnings.is_empty(), "frames left out are not the image's border: {:?}", from_seg.warnings);
    // The same voxels on a grid whose k runs the other way: the same surface to within the
    // extraction's dependence on the grid's axes (a fraction of a voxel).
    let volume = |s: &augsim_mesh::TriSurface| check_closed_manifold(s).unwrap().volume;
    let (a, b) = (volume(&from_seg.surface), volume(&from_nrrd.surface));
    assert!((a / b - 1.0).abs() < 0.005, "{a} vs {b} mm³");
    let (a, b) = (centre(&from_seg.surface.vertices), centre(&from_nrrd.surface.vertices));
    assert!(norm(sub(a, b)) < 1.0, "{a:?} vs {b:?}");
}

/// The phantom's liver as a FRACTIONAL DICOM SEG compressed RLE Lossless by highdicom holds the
/// voxels of the labelmap it was made from.
#[test]
fn an_rle_compressed_dicom_seg_holds_the_same_voxels() {
    let rle = read_labelmap(data("liver_labels_seg_rle.dcm")).unwrap();
    let nrrd = read_labelmap(data("liver_labels.seg.nrrd")).unwrap();
    let (a, b) = (voxel_positions(&rle, "liver"), voxel_positions(&nrrd, "liver"));
    assert!(!a.is_empty() && a == b, "{} voxels, {} in the NRRD", a.len(), b.len());
}

/// The centroid of the volume a closed surface encloses.
fn enclosed_centroid(surface: &augsim_mesh::TriSurface) -> Point {
    let (mut volume, mut moment) = (0.0, [0.0; 3]);
    for t in &surface.triangles {
        let [a, b, c] = t.map(|v| surface.vertices[v]);
        let v = augsim_mesh::dot(a, augsim_mesh::cross(b, c)) / 6.0;
        volume += v;
        (0..3).for_each(|d| moment[d] += v * (a[d] + b[d] + c[d]) / 4.0);
    }
    moment.map(|m| m / volume)
}

/// The phantom's labelmap as an RT Structure Set written by rt-utils (`make_dicom.py`: contours
/// through the centres of each CT slice's boundary pixels, as TotalSegmentator writes them) reads
/// as its polygons filled, and so as the same organs at the same places in LPS, smaller by the half
/// pixel the contours lose around each slice (2 % of the liver, 5 % of the ball below it).
#[test]
fn an_rt_structure_set_holds_the_organs_it_was_drawn_from() {
    let rt = read_labelmap(data("liver_labels_rt.dcm")).unwrap();
    assert_eq!(rt.frame, Frame::Lps);
    let names: Vec<(&str, i32)> = rt.segments.iter().map(|(name, _, label)| (name.as_str(), *label)).collect();
    assert_eq!(names, [("liver", 1), ("kidney", 2)]);
    assert_eq!(rt.spacing(), [1.0, 1.0, 4.0]);
    let options = ExtractOptions::default();
    let volume = |s: &augsim_mesh::TriSurface| check_closed_manifold(s).unwrap().volume;
    // The contours' areas (shoelace, by pydicom) times the 4 mm between slices, in mm³.
    for (organ, contours, (low, high)) in [("liver", 1_111_383.0, (0.97, 0.99)), ("kidney", 86_220.0, (0.94, 0.96))] {
        let filled = rt.select(organ).unwrap().0.count() as f64 * 4.0;
        assert!((filled / contours - 1.0).abs() < 0.003, "{organ}: {filled} mm³ filled, {contours} in its contours");
        let from_rt = read_labelmap_surface(data("liver_labels_rt.dcm"), Some(organ), None, &options).unwrap();
        let from_nrrd = read_labelmap_surface(data("liver_labels.seg.nrrd"), Some(organ), None, &options).unwrap();
        assert!(from_rt.warnings.is_empty(), "{:?}", from_rt.warnings);
        let ratio = volume(&from_rt.surface) / volume(&from_nrrd.surface);
        assert!(ratio > low && ratio < high, "{organ}: {ratio} of the labelmap's volume");
        let (p, q) = (enclosed_centroid(&from_rt.surface), enclosed_centroid(&from_nrrd.surface));
        assert!(norm(sub(p, q)) < 0.3, "{organ}: {p:?} vs {q:?}");
    }
}
