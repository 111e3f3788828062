//! `augsim mesh` and `augsim prepare` on segmentations as tools write them: a NIfTI labelmap
//! (label chosen by number, the organ kept at its place in the scanner's frame), a 3D Slicer
//! segmentation (label chosen by name), a label that is not there, and a broken surface export
//! (overlapping pieces glued at a vertex, holes) that only the volumetric route gets through.

use std::path::Path;
use std::process::Command;

use mesh::labelmap::{write_nifti, Frame, Labelmap};
use mesh::{norm, sub, Point};

/// Runs `augsim` with `args`, returns (success, stdout + stderr).
fn augsim(args: &[&str]) -> (bool, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_augsim")).args(args).output().unwrap();
    (out.status.success(), format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr)))
}

/// The organ's centre in the scanner's RAS frame (mm).
const CENTRE: Point = [-60.0, 20.0, -100.0];
/// Its semi-axes (mm).
const AXES: Point = [45.0, 30.0, 20.0];

/// An ellipsoid (label 5) and a ball beside it (label 1) in voxels of 1.25 × 1.25 × 3 mm.
fn labelmap() -> Labelmap {
    let dims = [90, 56, 18];
    let affine = [[1.25, 0.0, 0.0, -117.5], [0.0, 1.25, 0.0, -15.0], [0.0, 0.0, 3.0, -126.0]];
    let mut labels = Vec::new();
    for k in 0..dims[2] {
        for j in 0..dims[1] {
            for i in 0..dims[0] {
                let p: Point = std::array::from_fn(|r| affine[r][r] * [i, j, k][r] as f64 + affine[r][3]);
                let e: f64 = (0..3).map(|d| ((p[d] - CENTRE[d]) / AXES[d]).powi(2)).sum();
                labels.push(if e <= 1.0 {
                    5
                } else if norm(sub(p, [-5.0, 20.0, -100.0])) < 6.0 {
                    1
                } else {
                    0
                });
            }
        }
    }
    Labelmap::single(dims, labels, affine, Frame::Ras)
}

#[test]
fn a_nifti_labelmap_is_meshed_in_the_scanner_frame() {
    let dir = tempfile::tempdir().unwrap();
    let seg = dir.path().join("seg.nii.gz");
    write_nifti(&seg, &labelmap()).unwrap();
    let out = dir.path().join("organ.vtu");
    let (ok, text) =
        augsim(&["mesh", seg.to_str().unwrap(), "--label", "5", "--tets", "2000", "-o", out.to_str().unwrap()]);
    assert!(ok, "{text}");
    assert!(text.contains("labelmap   label 5: "), "{text}");
    assert!(text.contains("units      mm (the labelmap's)") && text.contains("frame      RAS kept"), "{text}");
    let organ = mesh::io::read_mesh(&out).unwrap();
    let (lo, hi) = organ.bounds();
    for d in 0..3 {
        let middle = 0.5e3 * (lo[d] + hi[d]);
        assert!((middle - CENTRE[d]).abs() < 1.0, "axis {d}: centre {middle} mm, {CENTRE:?} expected");
        assert!((0.5e3 * (hi[d] - lo[d]) - AXES[d]).abs() < 1.5, "axis {d}: {lo:?} {hi:?}");
    }
    let exact = 4.0 / 3.0 * std::f64::consts::PI * AXES.iter().product::<f64>() * 1e-9;
    assert!((organ.volume() / exact - 1.0).abs() < 0.04, "{} vs {exact}", organ.volume());

    let (ok, text) = augsim(&["mesh", seg.to_str().unwrap(), "--label", "3", "-o", out.to_str().unwrap()]);
    assert!(!ok && text.contains("label 3 is not in the labelmap; labels present: 1 ("), "{text}");
    let (ok, text) = augsim(&["mesh", seg.to_str().unwrap(), "-o", out.to_str().unwrap()]);
    assert!(!ok && text.contains("holds several labels: choose one with --label"), "{text}");
}

#[test]
fn a_slicer_segmentation_is_chosen_by_name() {
    let seg = Path::new(env!("CARGO_MANIFEST_DIR")).join("../mesh/tests/data/liver_labels.seg.nrrd");
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("organ.vtu");
    let (ok, text) =
        augsim(&["mesh", seg.to_str().unwrap(), "--label", "liver", "--tets", "1500", "-o", out.to_str().unwrap()]);
    assert!(ok, "{text}");
    assert!(text.contains("labelmap   label 5 ('liver'): ") && text.contains("frame      LPS kept"), "{text}");
}

#[test]
fn a_broken_export_goes_through_the_volumetric_route() {
    let dir = tempfile::tempdir().unwrap();
    let obj = Path::new(env!("CARGO_MANIFEST_DIR")).join("../mesh/tests/data/broken_export.obj");
    let out = dir.path().join("organ.vtu");
    let (ok, text) = augsim(&["mesh", obj.to_str().unwrap(), "--tets", "2000", "-o", out.to_str().unwrap()]);
    assert!(ok, "{text}");
    assert!(text.contains("repair     route: volumetric (local repair cannot mend it: non-manifold vertex"), "{text}");
    assert!(text.contains("repair     distance to the input surface: mean "), "{text}");
    assert!(text.contains("repair     enclosed volume: ") && text.contains(" mL ("), "{text}");
    let (ok, text) = augsim(&["mesh", obj.to_str().unwrap(), "--label", "5", "-o", out.to_str().unwrap()]);
    assert!(!ok && text.contains("--label 5 chooses a label of a labelmap"), "{text}");
    // A length with no unit is not taken for metres.
    let (ok, text) = augsim(&["mesh", obj.to_str().unwrap(), "--length", "200", "-o", out.to_str().unwrap()]);
    assert!(!ok && text.contains("'200' has no unit: give it, e.g. 200mm or 200m"), "{text}");
    // The phantom has no surface to choose a label of, scale or leave unrepaired.
    for option in [&["--label", "5"][..], &["--length", "10cm"], &["--no-repair"]] {
        let (ok, text) = augsim(&[&["mesh"][..], option, &["-o", out.to_str().unwrap()]].concat());
        assert!(!ok && text.contains("<SURFACE>"), "{option:?}: {text}");
    }
}
