//! Point-cloud readers and writers: round trips, the formats' variants, and their errors.

use std::fs;
use std::path::{Path, PathBuf};

use augsim_register::cloud::{read_frames, read_point_cloud, read_points_frames};
use mesh::io::points::write_points_csv;
use mesh::io::write_ply_points;
use mesh::Point;

fn sample() -> Vec<Point> {
    vec![
        [0.0, -0.0, 1.0],
        [0.1, 1.0 / 3.0, -123456.789],
        [1e-300, f64::MIN_POSITIVE, 5e-324],
        [-0.0123456789012345, 987654.321, std::f64::consts::PI],
    ]
}

fn write(dir: &Path, name: &str, bytes: impl AsRef<[u8]>) -> PathBuf {
    let path = dir.join(name);
    fs::write(&path, bytes).unwrap();
    path
}

/// The error message of a read that must fail.
fn error(result: augsim_register::Result<Vec<Point>>) -> String {
    match result {
        Ok(points) => panic!("expected an error, read {points:?}"),
        Err(e) => e.to_string(),
    }
}

fn assert_contains(message: &str, parts: &[&str]) {
    for part in parts {
        assert!(message.contains(part), "{message:?} should contain {part:?}");
    }
}

/// A NumPy v1.0 header for `descr` and a 2-D `shape`.
fn npy_header(descr: &str, rows: usize, cols: usize) -> Vec<u8> {
    let mut dict = format!("{{'descr': '{descr}', 'fortran_order': False, 'shape': ({rows}, {cols}), }}");
    while (10 + dict.len() + 1) % 64 != 0 {
        dict.push(' ');
    }
    dict.push('\n');
    let mut out = b"\x93NUMPY\x01\x00".to_vec();
    out.extend_from_slice(&(dict.len() as u16).to_le_bytes());
    out.extend_from_slice(dict.as_bytes());
    out
}

#[test]
fn ply_binary_round_trip_is_exact() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("cloud.ply");
    write_ply_points(&path, &sample()).unwrap();
    let back = read_point_cloud(&path).unwrap();
    assert_eq!(back.len(), sample().len());
    for (a, b) in back.iter().zip(sample()) {
        for k in 0..3 {
            assert_eq!(a[k].to_bits(), b[k].to_bits());
        }
    }
    let bytes = fs::read(&path).unwrap();
    assert!(bytes.starts_with(b"ply\nformat binary_little_endian 1.0\nelement vertex 4\n"));
}

#[test]
fn ascii_ply_with_extra_property_and_faces() {
    let dir = tempfile::tempdir().unwrap();
    let text = "ply\nformat ascii 1.0\ncomment made by hand\nobj_info test\nelement vertex 3\n\
                property float x\nproperty float y\nproperty float z\nproperty uchar red\n\
                element face 1\nproperty list uchar int vertex_indices\nend_header\n\
                0 0 0 255\n1.5 -2 0.25 0\n1e-3 2 3 7\n3 0 1 2\n";
    let path = write(dir.path(), "hand.Ply", text);
    assert_eq!(read_point_cloud(&path).unwrap(), vec![[0.0, 0.0, 0.0], [1.5, -2.0, 0.25], [1e-3, 2.0, 3.0]]);
}

#[test]
fn big_endian_ply_with_float32_and_an_element_before_the_vertices() {
    let dir = tempfile::tempdir().unwrap();
    let mut bytes = b"ply\r\nformat binary_big_endian 1.0\r\n\
        element material 2\r\nproperty list uchar int32 ids\r\nproperty float32 w\r\n\
        element vertex 2\r\nproperty float32 x\r\nproperty int16 intensity\r\nproperty float32 y\r\n\
        property float32 z\r\nend_header\r\n"
        .to_vec();
    // material 0: three ids and a weight; material 1: no ids and a weight.
    bytes.push(3);
    for id in [10i32, -20, 30] {
        bytes.extend_from_slice(&id.to_be_bytes());
    }
    bytes.extend_from_slice(&0.5f32.to_be_bytes());
    bytes.push(0);
    bytes.extend_from_slice(&1.5f32.to_be_bytes());
    for (p, intensity) in [([1.25f32, -2.5, 3.0], 7i16), ([0.125, 1e6, -0.75], -1)] {
        bytes.extend_from_slice(&p[0].to_be_bytes());
        bytes.extend_from_slice(&intensity.to_be_bytes());
        bytes.extend_from_slice(&p[1].to_be_bytes());
        bytes.extend_from_slice(&p[2].to_be_bytes());
    }
    let path = write(dir.path(), "be.ply", &bytes);
    assert_eq!(read_point_cloud(&path).unwrap(), vec![[1.25, -2.5, 3.0], [0.125, 1e6, -0.75]]);

    // One byte short: truncated inside the last vertex.
    let path = write(dir.path(), "short.ply", &bytes[..bytes.len() - 1]);
    assert_contains(&error(read_point_cloud(&path)), &["unexpected end of file", "vertex 1 of 2", "'z'"]);
}

#[test]
fn binary_ply_with_integer_coordinates() {
    let dir = tempfile::tempdir().unwrap();
    let mut bytes = b"ply\nformat binary_little_endian 1.0\nelement vertex 1\n\
        property uchar x\nproperty int y\nproperty ushort z\nend_header\n"
        .to_vec();
    bytes.push(200);
    bytes.extend_from_slice(&(-70000i32).to_le_bytes());
    bytes.extend_from_slice(&60000u16.to_le_bytes());
    let path = write(dir.path(), "int.ply", &bytes);
    assert_eq!(read_point_cloud(&path).unwrap(), vec![[200.0, -70000.0, 60000.0]]);
}

#[test]
fn npy_f32_and_f64() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("f32.npy");
    mesh::io::npy::write_f32(&path, &[2, 3], &[1.0, 2.0, 3.0, -0.5, 0.25, 1e-3]).unwrap();
    assert_eq!(read_point_cloud(&path).unwrap(), vec![[1.0, 2.0, 3.0], [-0.5, 0.25, f64::from(1e-3f32)]]);

    let mut bytes = npy_header("<f8", 2, 3);
    for v in [0.1, 0.2, 0.3, -1e-300, 5.0, 6.0f64] {
        bytes.extend_from_slice(&v.to_le_bytes());
    }
    let path = write(dir.path(), "f64.NPY", &bytes);
    assert_eq!(read_point_cloud(&path).unwrap(), vec![[0.1, 0.2, 0.3], [-1e-300, 5.0, 6.0]]);
}

#[test]
fn npy_of_wrong_shape_or_with_nan_is_rejected() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("six.npy");
    mesh::io::npy::write_f32(&path, &[2, 6], &[0.0; 12]).unwrap();
    assert_contains(&error(read_point_cloud(&path)), &["[N, 3]", "[2, 6]"]);

    let path = dir.path().join("nan.npy");
    mesh::io::npy::write_f32(&path, &[2, 3], &[0.0, 0.0, 0.0, 1.0, f32::NAN, 2.0]).unwrap();
    assert_contains(&error(read_point_cloud(&path)), &["point 1", "non-finite"]);

    // One point out of reach (a damaged file), which would make every distance to the cloud inf.
    let path = dir.path().join("far.npy");
    mesh::io::npy::write_f64(&path, &[2, 3], &[0.1, 0.0, 0.0, 1e30, 0.0, 0.0]).unwrap();
    assert_contains(&error(read_point_cloud(&path)), &["point 1", "a damaged file?"]);

    let path = dir.path().join("empty.npy");
    mesh::io::npy::write_f32(&path, &[0, 3], &[]).unwrap();
    assert_contains(&error(read_point_cloud(&path)), &["no points"]);
}

#[test]
fn ply_errors() {
    let dir = tempfile::tempdir().unwrap();

    // Truncated binary PLY written by the writer.
    let path = dir.path().join("cut.ply");
    write_ply_points(&path, &[[1.0, 2.0, 3.0], [4.0, 5.0, 6.0], [7.0, 8.0, 9.0]]).unwrap();
    let bytes = fs::read(&path).unwrap();
    fs::write(&path, &bytes[..bytes.len() - 12]).unwrap();
    assert_contains(&error(read_point_cloud(&path)), &["cut.ply", "unexpected end of file", "vertex 2 of 3"]);

    // Header without end_header.
    let path = write(dir.path(), "nohead.ply", "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n");
    assert_contains(&error(read_point_cloud(&path)), &["end_header"]);

    // No z property.
    let path = write(
        dir.path(),
        "noz.ply",
        "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nend_header\n1 2\n",
    );
    assert_contains(&error(read_point_cloud(&path)), &["no 'z' property"]);

    // Unknown format.
    let path = write(dir.path(), "fmt.ply", "ply\nformat binary_middle_endian 1.0\nend_header\n");
    assert_contains(&error(read_point_cloud(&path)), &["unknown format", "binary_middle_endian"]);

    // More vertices in the data than in the header, and fewer.
    let head =
        "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\nend_header\n";
    let path = write(dir.path(), "more.ply", format!("{head}1 2 3\n4 5 6\n7 8 9\n"));
    assert_contains(&error(read_point_cloud(&path)), &["more data than the header declares"]);
    let path = write(dir.path(), "fewer.ply", format!("{head}1 2 3\n"));
    assert_contains(&error(read_point_cloud(&path)), &["unexpected end of file", "vertex 1 of 2"]);
    let path = write(dir.path(), "word.ply", format!("{head}1 2 3\n4 five 6\n"));
    assert_contains(&error(read_point_cloud(&path)), &["line 9", "\"five\" is not a number"]);

    // NaN and empty.
    let path = write(dir.path(), "nan.ply", format!("{head}1 2 3\n4 nan 6\n"));
    assert_contains(&error(read_point_cloud(&path)), &["line 9", "vertex 1", "non-finite"]);
    let path = dir.path().join("empty.ply");
    write_ply_points(&path, &[]).unwrap();
    assert_contains(&error(read_point_cloud(&path)), &["no points"]);

    // Not a PLY file at all.
    let path = write(dir.path(), "text.ply", "hello\nworld\n");
    assert_contains(&error(read_point_cloud(&path)), &["not a PLY file"]);
}

#[test]
fn unsupported_extension_lists_the_supported_ones() {
    let dir = tempfile::tempdir().unwrap();
    let path = write(dir.path(), "cloud.xyz", "1 2 3\n");
    assert_contains(
        &error(read_point_cloud(&path)),
        &["cloud.xyz", "a .npy, .ply, .obj, .stl, .vtk, .vtp or .vtu file"],
    );
    let path = write(dir.path(), "noext", "1 2 3\n");
    assert_contains(&error(read_point_cloud(&path)), &[".npy", ".ply"]);
    // A CSV names its unit and labels: it is read as points, not as positions alone.
    let path = write(dir.path(), "cloud.csv", "x,y,z\n1,2,3\n");
    assert_contains(&error(read_point_cloud(&path)), &["cloud.csv", "unsupported point-cloud format"]);
}

#[test]
fn frames_of_a_directory_and_of_a_file() {
    let dir = tempfile::tempdir().unwrap();
    let b = dir.path().join("b.ply");
    write_ply_points(&b, &[[1.0, 2.0, 3.0]]).unwrap();
    let a = dir.path().join("a.csv");
    write_points_csv(&a, &[[4.0, 5.0, 6.0]]).unwrap();
    write(dir.path(), "notes.txt", "not a cloud");
    let c = write(dir.path(), "c.obj", "v 7 8 9\n");
    fs::create_dir(dir.path().join("sub.csv")).unwrap();
    let d = write(dir.path(), "d.mrk.json", "{}");
    write(dir.path(), "summary.json", "{}");
    assert_eq!(read_frames(dir.path()).unwrap(), vec![a.clone(), b, c.clone(), d.clone()]);
    assert_eq!(read_points_frames(dir.path()).unwrap(), vec![a.clone(), d], "a truth's points files");
    assert_eq!(read_point_cloud(&c).unwrap(), [[7.0, 8.0, 9.0]], "a model file's points");
    assert_eq!(read_frames(&a).unwrap(), vec![a]);

    let empty = tempfile::tempdir().unwrap();
    write(empty.path(), "readme.md", "nothing here");
    let message = read_frames(empty.path()).unwrap_err().to_string();
    assert_contains(&message, &["no point cloud", ".fcsv or .mrk.json file): its 1 file(s) (readme.md) are none"]);

    assert!(read_frames(&dir.path().join("missing")).is_err());
}
