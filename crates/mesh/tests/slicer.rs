//! 3D Slicer's files: markups (`.fcsv`, `.mrk.json`) as Slicer 4.10 to 5.x write them, CSV
//! points with labels and units, the `SPACE=` frame of STL, VTK, OBJ and PLY headers and of VTK
//! XML field data; its models as `.vtp`, `.vtu` and `.ply` (written by VTK's own writers).

use std::fs;
use std::path::{Path, PathBuf};

use augsim_mesh::io::points::{read_points, read_points_csv, write_fcsv, write_points, LabelledPoints};
use augsim_mesh::io::{
    read_surface, read_surface_with_frame, read_vertices, surface_frame, write_surface, write_surface_in_frame, Frame,
};
use augsim_mesh::length::LengthUnit;
use augsim_mesh::MeshError;

fn slicer(name: &str) -> PathBuf {
    Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/slicer")).join(name)
}

/// Writes `text` to `name` in `dir` and returns the path.
fn put(dir: &Path, name: &str, text: impl AsRef<[u8]>) -> PathBuf {
    let path = dir.join(name);
    fs::write(&path, text).unwrap();
    path
}

/// The error message of a failed read (panics if the read succeeded).
fn message<T: std::fmt::Debug>(result: Result<T, MeshError>) -> String {
    result.expect_err("reading should fail").to_string()
}

#[test]
fn fcsv_of_slicer_4_11_gives_points_labels_descriptions_lps_and_millimetres() {
    let p = read_points(slicer("landmarks.fcsv")).unwrap();
    assert_eq!(p.points, [[-61.8216, -142.0372, -118.5], [-12.3051, -198.4416, -80.25], [-104.75, -120.1, -140.0625]]);
    assert_eq!(p.labels, ["hilum", "falciform ligament", "IVC \"upper\""]);
    assert_eq!(p.descriptions, ["", "held, near the umbilical fissure", ""]);
    assert_eq!((p.frame, p.unit), (Some(Frame::Lps), Some(LengthUnit::Millimetre)));
    assert_eq!(p.label(0), Some("hilum"));
    let camera = read_points(slicer("camera.fcsv")).unwrap();
    assert_eq!((camera.points, camera.labels), (vec![[-40.5, -260.0, -60.0]], vec!["laparoscope".to_string()]));
}

#[test]
fn fcsv_of_older_slicer_with_numeric_coordinate_system_is_ras_and_converts_to_lps() {
    let mut ras = read_points(slicer("landmarks_ras_4.10.fcsv")).unwrap();
    assert_eq!(ras.frame, Some(Frame::Ras));
    ras.convert(Some(Frame::Lps), LengthUnit::Millimetre, LengthUnit::Metre);
    let lps = read_points(slicer("landmarks.fcsv")).unwrap();
    assert_eq!((&ras.points, &ras.labels, ras.frame), (&lps.points, &lps.labels, lps.frame));
    // `# CoordinateSystem = 1` is LPS; no such line (before Slicer 4.6): RAS.
    let dir = tempfile::tempdir().unwrap();
    let columns = "# columns = id,x,y,z,ow,ox,oy,oz,vis,sel,lock,label,desc,associatedNodeID\n";
    let row = "0,1,2,3,0,0,0,1,1,1,0,F-1,,\n";
    let one = put(
        dir.path(),
        "one.fcsv",
        format!("# Markups fiducial file version = 4.6\n# CoordinateSystem = 1\n{columns}{row}"),
    );
    assert_eq!(read_points(one).unwrap().frame, Some(Frame::Lps));
    let none = put(dir.path(), "none.fcsv", format!("# Markups fiducial file version = 4.4\n{columns}{row}"));
    assert_eq!(read_points(none).unwrap().frame, Some(Frame::Ras));
}

/// Slicer 5 writes two fields per row more than its header names (the position status and
/// whether the point was made automatically); a point skipped when placing (status 3, missing)
/// is written at the origin and left out.
#[test]
fn fcsv_of_slicer_5_reads_its_unnamed_status_fields_and_leaves_out_missing_points() {
    let five = read_points(slicer("landmarks_5.6.fcsv")).unwrap();
    let four = read_points(slicer("landmarks.fcsv")).unwrap();
    assert_eq!((&five.points, &five.labels, &five.descriptions), (&four.points, &four.labels, &four.descriptions));
    assert_eq!((five.frame, five.unit), (Some(Frame::Lps), Some(LengthUnit::Millimetre)));
    assert_eq!(five.unplaced, ["F-4"]);
    let dir = tempfile::tempdir().unwrap();
    let columns =
        "# CoordinateSystem = LPS\n# columns = id,x,y,z,ow,ox,oy,oz,vis,sel,lock,label,desc,associatedNodeID\n";
    let statuses = put(
        dir.path(),
        "statuses.fcsv",
        format!(
            "{columns}a,1,2,3,0,0,0,1,1,1,0,,,,0,0\nb,4,5,6,0,0,0,1,1,1,0,B,,,1,0\nc,7,8,9,0,0,0,1,1,1,0,C,,,2,1\n"
        ),
    );
    let p = read_points(statuses).unwrap();
    assert_eq!((p.points, p.labels), (vec![[7.0, 8.0, 9.0]], vec!["C".to_string()]));
    assert_eq!(p.unplaced, ["line 3", "B"], "an unlabelled point named by its line");
    // A file of which no point is placed is refused, rather than read as no points.
    let unplaced = put(dir.path(), "unplaced.fcsv", format!("{columns}a,1,2,3,0,0,0,1,1,1,0,A,,,0,0\n"));
    let m = message(read_points(unplaced));
    assert!(m.contains("unplaced.fcsv: none of its points is placed: 1 control point not placed"), "{m}");
    let unknown = put(dir.path(), "unknown.fcsv", format!("{columns}a,1,2,3,0,0,0,1,1,1,0,A,,,7,0\n"));
    assert_eq!(
        message(read_points(unknown)),
        format!(
            "{}: line 3: position status \"7\": Slicer's .fcsv rows end with two fields its columns comment does \
             not name, the position status (0 to 3) and whether the point was made automatically; a row two fields \
             longer than its columns reads them there",
            dir.path().join("unknown.fcsv").display()
        )
    );
}

#[test]
fn mrk_json_of_slicer_5_gives_defined_points_with_labels_frame_and_units() {
    let p = read_points(slicer("targets.mrk.json")).unwrap();
    assert_eq!(p.points, [[-70.25, -160.5, -101.0], [-55.0, -150.125, -112.5], [-80.0, -140.75, -95.5]]);
    assert_eq!(p.labels, ["tumour", "portal bifurcation", "hepatic vein"], "the undefined F-3 is left out");
    assert_eq!(p.unplaced, ["F-3"]);
    assert_eq!(
        p.unplaced_warning().unwrap(),
        "1 control point not placed in 3D Slicer (positionStatus undefined, preview or missing) is left out: F-3"
    );
    assert_eq!(p.descriptions, ["segment VIII", "", ""]);
    assert_eq!((p.frame, p.unit), (Some(Frame::Lps), Some(LengthUnit::Millimetre)));
    // The documentation's minimal file: no units (millimetres), several markups brought to the first's frame.
    let dir = tempfile::tempdir().unwrap();
    let two = put(
        dir.path(),
        "two.mrk.json",
        r#"{"markups": [{"type": "Fiducial", "coordinateSystem": "RAS", "controlPoints": [{"label": "a", "position": [1, 2, 3]}]},
                       {"type": "Fiducial", "coordinateSystem": "LPS", "coordinateUnits": "m", "controlPoints": [{"position": [0.001, 0.002, 0.003]},
                         {"position": [0, 0, 0], "positionStatus": "undefined"},
                         {"label": "skipped", "position": "", "positionStatus": "missing"}]}]}"#,
    );
    let p = read_points(two).unwrap();
    assert_eq!((p.frame, p.unit), (Some(Frame::Ras), Some(LengthUnit::Millimetre)));
    assert_eq!(p.points, [[1.0, 2.0, 3.0], [-1.0, -2.0, 3.0]]);
    assert_eq!(p.labels, ["a", ""]);
    assert_eq!(
        p.unplaced,
        ["markups[1].controlPoints[1]", "skipped"],
        "an unlabelled placeholder named by its place; a point skipped when placing, which has no position"
    );
    assert_eq!(p.lists, [1, 1], "two point lists read as one");
    assert!(
        p.warnings()[1].starts_with("its 2 point lists (1, 1 points) are read as one list of 2"),
        "{:?}",
        p.warnings()
    );
    // A position status 3D Slicer does not write is refused, naming the point.
    let odd = put(
        dir.path(),
        "odd.mrk.json",
        r#"{"markups": [{"controlPoints": [{"label": "p", "position": [1, 2, 3], "positionStatus": "weird"}]}]}"#,
    );
    let m = message(read_points(odd));
    assert!(
        m.ends_with(
            "markups[0].controlPoints[0] (p): positionStatus \"weird\" is none of 3D Slicer's (defined, \
         undefined, preview, missing)"
        ),
        "{m}"
    );
    // A curve is a shape, not a point list.
    let curve = put(
        dir.path(),
        "curve.mrk.json",
        r#"{"markups": [{"type": "Curve", "controlPoints": [{"position": [1, 2, 3]}, {"position": [4, 5, 6]}]}]}"#,
    );
    let m = message(read_points(curve));
    assert!(
        m.ends_with(
            "markups[0] is a Curve, not a point list: save the points as a point list (type Fiducial in the file)"
        ),
        "{m}"
    );
    // Microns, which Slicer's schema allows beside millimetres.
    let um = put(
        dir.path(),
        "um.mrk.json",
        r#"{"markups": [{"coordinateUnits": "um", "controlPoints": [{"position": [1500, -20, 3]}]}]}"#,
    );
    let p = read_points(um).unwrap();
    assert_eq!(p.unplaced_warning(), None);
    assert_eq!((p.unit, &p.points), (Some(LengthUnit::Micrometre), &vec![[1500.0, -20.0, 3.0]]));
    let metres = read_points_csv(&dir.path().join("um.mrk.json")).unwrap()[0];
    assert!(metres.iter().zip([1.5e-3, -2e-5, 3e-6]).all(|(a, b)| (a - b).abs() < 1e-15), "{metres:?}");
    // The unit coded as the schema also allows it: [code, scheme, meaning].
    let coded = put(
        dir.path(),
        "coded.mrk.json",
        r#"{"markups": [{"coordinateUnits": ["m", "UCUM", "meter"], "controlPoints": [{"position": [0.1, 0.2, 0.3]}]}]}"#,
    );
    let p = read_points(coded).unwrap();
    assert_eq!((p.unit, p.points), (Some(LengthUnit::Metre), vec![[0.1, 0.2, 0.3]]));
}

/// A written point's orientation is Slicer's identity (in RAS) in the file's frame: negated x
/// and y in LPS, as it is in RAS.
#[test]
fn mrk_json_orientation_is_the_identity_in_the_files_frame() {
    let dir = tempfile::tempdir().unwrap();
    for (frame, identity) in [(Frame::Lps, [-1.0, -1.0, 1.0]), (Frame::Ras, [1.0, 1.0, 1.0])] {
        let path = dir.path().join(format!("{frame}.mrk.json"));
        let points = LabelledPoints { frame: Some(frame), ..LabelledPoints::new(vec![[1.0, 2.0, 3.0]]) };
        augsim_mesh::io::points::write_markups_json(&path, &points).unwrap();
        let json: serde_json::Value = serde_json::from_str(&fs::read_to_string(&path).unwrap()).unwrap();
        let o: Vec<f64> = json["markups"][0]["controlPoints"][0]["orientation"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        assert_eq!([o[0], o[4], o[8]], identity, "{frame}");
        assert!(o.iter().enumerate().all(|(k, v)| k % 4 == 0 || *v == 0.0), "{frame}: {o:?}");
    }
}

#[test]
fn csv_points_keep_their_labels_and_the_unit_their_header_names() {
    let dir = tempfile::tempdir().unwrap();
    let mm = put(dir.path(), "mm.csv", "id,x_mm,y_mm,z_mm,std\nT1,10,20,30,0.5\n\"T2, deep\",-1,0,1e1,1\n");
    let p = read_points(&mm).unwrap();
    assert_eq!(
        (p.labels.clone(), p.unit, p.frame),
        (vec!["T1".into(), "T2, deep".into()], Some(LengthUnit::Millimetre), None)
    );
    assert_eq!(read_points_csv(&mm).unwrap(), [[0.01, 0.02, 0.03], [-0.001, 0.0, 0.01]], "in metres");
    let m = put(dir.path(), "m.csv", "# CoordinateSystem = RAS\nlabel,X_M,Y_M,Z_M\na,0.1,0.2,0.3\n");
    let p = read_points(&m).unwrap();
    assert_eq!(
        (p.points, p.labels, p.frame, p.unit),
        (vec![[0.1, 0.2, 0.3]], vec!["a".into()], Some(Frame::Ras), Some(LengthUnit::Metre))
    );
    let plain = put(dir.path(), "plain.csv", "z,y,x\n3,2,1\n");
    let p = read_points(&plain).unwrap();
    assert_eq!((p.points, p.labels, p.unit), (vec![[1.0, 2.0, 3.0]], vec![String::new()], None));
}

#[test]
fn labels_descriptions_frame_and_unit_round_trip_through_every_points_format() {
    let dir = tempfile::tempdir().unwrap();
    let mut points = read_points(slicer("targets.mrk.json")).unwrap();
    points.descriptions[1] = "sigma 1.25 mm, \"calibrated\"".into();
    // What is written is the placed points.
    points.unplaced.clear();
    for name in ["out.mrk.json", "out.fcsv", "out.csv"] {
        let path = dir.path().join(name);
        write_points(&path, &points).unwrap();
        assert_eq!(read_points(&path).unwrap(), points, "{name}");
    }
    // Metres are written as such in CSV, and as millimetres in Slicer's files (its markups schema
    // knows mm and um only).
    points.convert(Some(Frame::Ras), LengthUnit::Metre, LengthUnit::Metre);
    let csv = dir.path().join("m.csv");
    write_points(&csv, &points).unwrap();
    assert_eq!(read_points(&csv).unwrap(), points);
    for name in ["m.mrk.json", "m.fcsv"] {
        let path = dir.path().join(name);
        write_points(&path, &points).unwrap();
        let mut back = read_points(&path).unwrap();
        assert_eq!((back.unit, back.frame), (Some(LengthUnit::Millimetre), Some(Frame::Ras)), "{name}");
        assert!(name.ends_with(".fcsv") || fs::read_to_string(&path).unwrap().contains(r#""coordinateUnits": "mm""#));
        back.convert(None, LengthUnit::Metre, LengthUnit::Metre);
        assert_eq!(back.labels, points.labels);
        for (a, b) in back.points.iter().zip(&points.points) {
            assert!((0..3).all(|d| (a[d] - b[d]).abs() < 1e-15), "{name}: {a:?} {b:?}");
        }
    }
    // Points of no frame cannot go to .fcsv, which names one; bare points go to CSV as x,y,z.
    let bare = LabelledPoints::new(vec![[1.0, 2.0, 3.0]]);
    assert!(write_fcsv(dir.path().join("bare.fcsv"), &bare).unwrap_err().to_string().contains("names its frame"));
    write_points(dir.path().join("bare.csv"), &bare).unwrap();
    assert_eq!(fs::read_to_string(dir.path().join("bare.csv")).unwrap(), "x,y,z\n1,2,3\n");
    let bad = LabelledPoints { labels: vec!["a".into(), "b".into()], ..bare };
    assert!(write_points(dir.path().join("bad.mrk.json"), &bad)
        .unwrap_err()
        .to_string()
        .contains("one label per point"));
}

/// A label starting with `#` is written quoted, so that its row is not read as a comment; a
/// line break in a label or a description is a space in CSV and `.fcsv` (a line per point), and
/// kept in `.mrk.json`.
#[test]
fn hash_labels_and_line_breaks_survive_every_points_format() {
    let dir = tempfile::tempdir().unwrap();
    let mut points = LabelledPoints::new(vec![[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]);
    points.frame = Some(Frame::Lps);
    points.unit = Some(LengthUnit::Millimetre);
    points.labels = vec!["#1".into(), " # 2".into()];
    points.descriptions = vec!["two\nlines".into(), "three\r\nlines".into()];
    let json = dir.path().join("p.mrk.json");
    write_points(&json, &points).unwrap();
    assert_eq!(read_points(&json).unwrap(), points);
    let one_line = LabelledPoints { descriptions: vec!["two lines".into(), "three lines".into()], ..points.clone() };
    for name in ["p.csv", "p.fcsv"] {
        let path = dir.path().join(name);
        write_points(&path, &points).unwrap();
        assert_eq!(read_points(&path).unwrap(), one_line, "{name}");
    }
    // A quoted "#" in a file written by hand is data too.
    let quoted = put(dir.path(), "quoted.csv", "# CoordinateSystem = RAS\nlabel,x,y,z\n\"#7\",1,2,3\n# a note\n");
    assert_eq!(read_points(&quoted).unwrap().labels, ["#7"]);
}

#[test]
fn stl_and_vtk_headers_name_the_frame_as_slicer_writes_it() {
    let (surface, frame) = read_surface_with_frame(slicer("tetrahedron_lps.stl")).unwrap();
    assert_eq!((surface.triangles.len(), frame), (4, Some(Frame::Lps)));
    let (vtk, frame) = read_surface_with_frame(slicer("tetrahedron_ras.vtk")).unwrap();
    assert_eq!((vtk.vertices.len(), frame), (4, Some(Frame::Ras)));
    let dir = tempfile::tempdir().unwrap();
    for (name, frame) in [("out.vtk", Frame::Lps), ("out.stl", Frame::Ras), ("out.obj", Frame::Ras)] {
        let path = dir.path().join(name);
        write_surface_in_frame(&path, &surface, frame).unwrap();
        let (back, read) = read_surface_with_frame(&path).unwrap();
        assert_eq!((back.triangles.len(), read), (4, Some(frame)), "{name}");
    }
    let written = fs::read(dir.path().join("out.stl")).unwrap();
    assert!(written.starts_with(b"augsim binary STL SPACE=RAS"));
    let vtk_header = fs::read(dir.path().join("out.vtk")).unwrap();
    assert!(vtk_header.starts_with(b"# vtk DataFile Version 3.0\naugsim SPACE=LPS\n"));
    assert!(fs::read(dir.path().join("out.obj")).unwrap().starts_with(b"# augsim SPACE=RAS\n"));
    // No tag: no frame; a frame cannot be put in a .vtu.
    let plain = dir.path().join("plain.stl");
    write_surface(&plain, &surface).unwrap();
    assert_eq!(surface_frame(&plain).unwrap(), None);
    let vtu = dir.path().join("plain.vtu");
    write_surface(&vtu, &surface).unwrap();
    assert_eq!(surface_frame(&vtu).unwrap(), None, "a .vtu without a SPACE field");
    // Slicer's OBJ and PLY writers put the tag in a comment.
    let obj = put(dir.path(), "slicer.obj", "# wavefront obj file\n# 3D Slicer output. SPACE=LPS\nv 1 2 3\n");
    assert_eq!(surface_frame(obj).unwrap(), Some(Frame::Lps));
    let ply = "ply\nformat ascii 1.0\ncomment VTK generated PLY File\ncomment SPACE=RAS\nelement vertex 1\n\
               property float x\nproperty float y\nproperty float z\nend_header\n1 2 3\n";
    assert_eq!(surface_frame(put(dir.path(), "slicer.ply", ply)).unwrap(), Some(Frame::Ras));
    let after = ply.replace("comment SPACE=RAS\n", "") + "comment SPACE=LPS\n";
    assert_eq!(surface_frame(put(dir.path(), "body.ply", after)).unwrap(), None, "only the header's comments");
    let plain_obj = put(dir.path(), "plain.obj", "v 1 2 3 # SPACE=LPS\n");
    assert_eq!(surface_frame(plain_obj).unwrap(), None, "only comment lines");
    let indented = put(dir.path(), "indented.stl", "\n  solid liver SPACE=RAS\nendsolid liver SPACE=RAS\n");
    assert_eq!(surface_frame(indented).unwrap(), Some(Frame::Ras));
    let vtu = dir.path().join("out.vtu");
    assert!(write_surface_in_frame(&vtu, &surface, Frame::Lps).unwrap_err().to_string().contains(".vtk, .stl or .obj"));
    assert_eq!(read_surface(slicer("tetrahedron_lps.stl")).unwrap(), surface, "the plain reader reads the same");
}

/// A legacy VTK file may name its frame in a string array `SPACE` of its field data, as VTK saves
/// a Slicer model read from a `.vtp`: one string a line (ASCII) or after its length (binary).
#[test]
fn a_legacy_vtk_file_names_its_frame_in_a_string_field() {
    let dir = tempfile::tempdir().unwrap();
    let points = TETRAHEDRON.iter().flatten().map(|c| format!("{c}")).collect::<Vec<_>>().join(" ");
    let polygons: String = TETRAHEDRON_TRIANGLES.iter().map(|t| format!("3 {} {} {}\n", t[0], t[1], t[2])).collect();
    let ascii = format!(
        "# vtk DataFile Version 4.2\nvtk output\nASCII\nDATASET POLYDATA\nFIELD FieldData 2\nSPACE 1 1 string\nLPS\n\
         note 1 1 string\na%20segment\nPOINTS 4 float\n{points}\nPOLYGONS 4 16\n{polygons}"
    );
    let (surface, frame) = read_surface_with_frame(put(dir.path(), "ascii.vtk", &ascii)).unwrap();
    assert_eq!((oriented_set(&surface.triangles), frame), (oriented_set(&TETRAHEDRON_TRIANGLES), Some(Frame::Lps)));
    let mut binary = b"# vtk DataFile Version 4.2\nvtk output\nBINARY\nDATASET POLYDATA\nFIELD FieldData 1\n\
                       SPACE 1 1 string\n"
        .to_vec();
    binary.extend([0xc0 | 3, b'R', b'A', b'S']);
    binary.extend(b"\nPOINTS 4 float\n");
    TETRAHEDRON.iter().flatten().for_each(|&c| binary.extend((c as f32).to_be_bytes()));
    binary.extend(b"\nPOLYGONS 4 16\n");
    TETRAHEDRON_TRIANGLES
        .iter()
        .for_each(|t| [3, t[0], t[1], t[2]].iter().for_each(|&i| binary.extend((i as i32).to_be_bytes())));
    let path = dir.path().join("binary.vtk");
    fs::write(&path, &binary).unwrap();
    let (surface, frame) = read_surface_with_frame(&path).unwrap();
    assert_eq!((surface.vertices, frame), (TETRAHEDRON.to_vec(), Some(Frame::Ras)));
    // A frame the field names that is not one is refused; no field, no frame.
    let wrong = put(dir.path(), "wrong.vtk", ascii.replace("\nLPS\n", "\nXYZ\n"));
    assert!(read_surface_with_frame(wrong).unwrap_err().to_string().contains("SPACE=XYZ"));
    let none = ascii.replace("FIELD FieldData 2\nSPACE 1 1 string\nLPS\n", "FIELD FieldData 1\n");
    assert_eq!(read_surface_with_frame(put(dir.path(), "none.vtk", &none)).unwrap().1, None);
}

/// The tetrahedron `write_vtk_files.py` writes.
const TETRAHEDRON: [[f64; 3]; 4] = [[0.0, 0.0, 0.0], [10.0, 0.0, 0.0], [0.0, 20.0, 0.0], [0.0, 0.0, 30.0]];
const TETRAHEDRON_TRIANGLES: [[usize; 3]; 4] = [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]];

/// Triangles each turned to start at its smallest index, then sorted: equal for the same
/// oriented triangles in any order.
fn oriented_set(triangles: &[[usize; 3]]) -> Vec<[usize; 3]> {
    let mut set: Vec<[usize; 3]> = triangles
        .iter()
        .map(|t| {
            let k = (0..3).min_by_key(|&k| t[k]).unwrap();
            [t[k], t[(k + 1) % 3], t[(k + 2) % 3]]
        })
        .collect();
    set.sort();
    set
}

#[test]
fn vtp_vtu_and_ply_models_as_slicer_writes_them_give_the_surface_and_its_frame() {
    for (file, frame) in [
        ("tetrahedron_ras.vtp", Some(Frame::Ras)),
        ("tetrahedron_lps_ascii.vtp", Some(Frame::Lps)),
        ("tetrahedron_lps.vtu", Some(Frame::Lps)),
        ("tetrahedron_ras.ply", Some(Frame::Ras)),
        ("tetrahedron_lps_ascii.ply", Some(Frame::Lps)),
        ("tetrahedron_strips.vtp", None),
    ] {
        let (surface, read) = read_surface_with_frame(slicer(file)).unwrap();
        assert_eq!(read, frame, "{file}");
        assert_eq!(surface.vertices, TETRAHEDRON, "{file}");
        assert_eq!(oriented_set(&surface.triangles), oriented_set(&TETRAHEDRON_TRIANGLES), "{file}");
        assert_eq!(read_vertices(slicer(file)).unwrap(), TETRAHEDRON, "{file}: its points");
    }
    // A cloud saved as a model: its points, and no surface.
    let cloud = slicer("cloud_ras.vtp");
    assert_eq!(read_vertices(&cloud).unwrap(), [[1.5, -2.0, 3.0], [4.0, 5.25, -6.0], [-7.0, 8.0, 9.5]]);
    assert_eq!(surface_frame(&cloud).unwrap(), Some(Frame::Ras));
    assert!(message(read_surface(&cloud)).contains("no triangles"));
}

#[test]
fn broken_vtp_and_ply_models_are_refused_naming_the_file_and_what_is_wrong() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let ascii_vtp = fs::read_to_string(slicer("tetrahedron_lps_ascii.vtp")).unwrap();
    let compressed = fs::read(slicer("tetrahedron_ras.vtp")).unwrap();
    let ply = fs::read_to_string(slicer("tetrahedron_lps_ascii.ply")).unwrap();
    let cut = put(d, "cut.vtp", &compressed[..compressed.len() - 200]);
    let cases: Vec<(PathBuf, &str)> = vec![
        // "IJK" in the field data's characters.
        (put(d, "ijk.vtp", ascii_vtp.replace("76 80 83 0", "73 74 75 0")), "field data: header tag SPACE=IJK"),
        (put(d, "number.vtp", ascii_vtp.replace("type=\"String\"", "type=\"Int32\"")), "type Int32 is not String"),
        (put(d, "offset.vtp", ascii_vtp.replace("3 6 9 12", "3 6 13 12")), "<Polys> cell 2: offset 13"),
        (put(d, "index.vtp", ascii_vtp.replace("0 3 2 1 2 3", "0 3 2 1 2 4")), "refers to point 4"),
        (put(d, "image.vtp", ascii_vtp.replace("\"PolyData\" version", "\"ImageData\" version")), "ImageData"),
        (cut.clone(), "truncated"),
        (
            put(
                d,
                "cloud.ply",
                ply.replace("element face 4\n", "").replace("property list uchar int vertex_indices\n", ""),
            ),
            "no 'face' element",
        ),
        (put(d, "face.ply", ply.replace("3 1 2 3", "3 1 2 9")), "face 3 refers to vertex 9, but there are 4"),
        (put(d, "short.ply", ply.replace("3 1 2 3 \n", "")), "face 3 of 4"),
        (
            put(d, "float.ply", ply.replace("uchar int vertex_indices", "uchar float vertex_indices")),
            "not a list of integers",
        ),
        // Integers written as fractions or NaN, and a vertex that is not finite, by their line.
        (
            put(d, "fraction.ply", ply.replace("3 1 2 3", "3 1 2 1.5")),
            "line 20: face 3 of 4, property 'vertex_indices'",
        ),
        (
            put(d, "nan.ply", ply.replace("3 1 2 3", "3 1 2 nan")),
            "line 20: face 3 of 4, property 'vertex_indices': vertex index NaN",
        ),
        (
            put(d, "length.ply", ply.replace("3 1 2 3", "2.5 1 2 3")),
            "line 20: face 3 of 4, property 'vertex_indices': bad list length 2.5",
        ),
        (
            put(d, "vertex.ply", ply.replace("10 0 0", "10 nan 0")),
            "line 14: vertex 1 has a non-finite coordinate: y = NaN",
        ),
        (
            put(d, "vertex.vtp", ascii_vtp.replace("0 0 0 10 0 0", "0 0 0 10 0 inf")),
            "line 15: DataArray 'Points': point 1 has a non-finite coordinate: z = inf",
        ),
    ];
    for (path, expected) in cases {
        let e = message(read_surface_with_frame(&path));
        assert!(e.starts_with(&path.display().to_string()), "{e}");
        assert!(e.contains(expected), "{}: {e}\nexpected: {expected}", path.display());
    }
    assert!(message(read_vertices(&cut)).contains("truncated"), "the points of a cut file");
    assert!(message(read_vertices(d.join("vertex.ply"))).contains("line 14: vertex 1 has a non-finite"));
}

/// An element of no property holds nothing to read, whatever its count.
#[test]
fn ply_elements_without_properties_are_skipped() {
    let dir = tempfile::tempdir().unwrap();
    let ply = fs::read_to_string(slicer("tetrahedron_lps_ascii.ply")).unwrap();
    let empty = ply.replace("element vertex 4\n", "element nothing 18446744073709551615\nelement vertex 4\n");
    let surface = read_surface(put(dir.path(), "empty.ply", empty)).unwrap();
    assert_eq!(surface.vertices, TETRAHEDRON);
}

#[test]
fn malformed_slicer_files_are_refused_naming_the_file_and_the_line_or_point() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let header = "# Markups fiducial file version = 4.11\n# CoordinateSystem = LPS\n\
                  # columns = id,x,y,z,ow,ox,oy,oz,vis,sel,lock,label,desc,associatedNodeID\n";
    let cases: Vec<(PathBuf, &str)> = vec![
        (
            put(d, "bad.fcsv", format!("{header}0,1,2,3,0,0,0,1,1,1,0,F-1,,\n1,1,two,3,0,0,0,1,1,1,0,F-2,,\n")),
            "line 5: y = \"two\" is not a number",
        ),
        (put(d, "short.fcsv", format!("{header}0,1,2,3,0,0,0,1\n")), "line 4: 8 fields, the header has 14 columns"),
        (put(d, "ijk.fcsv", header.replace("LPS", "2")), "line 2: CoordinateSystem = 2 (IJK"),
        (put(d, "xyz.fcsv", header.replace("LPS", "XYZ")), "line 2: unknown coordinate system 'XYZ'"),
        (put(d, "nocolumns.fcsv", "# Markups fiducial file version = 4.11\n0,1,2,3\n"), "no '# columns = …' line"),
        (put(d, "quote.fcsv", format!("{header}0,1,2,3,0,0,0,1,1,1,0,\"F-1,,\n")), "line 4: field 12 opens a quote"),
        (put(d, "units.csv", "x_mm,y_m,z_mm\n1,2,3\n"), "line 1: the x, y and z columns name different units"),
        (put(d, "inf.csv", "x,y,z\n1,inf,3\n"), "line 2: y = \"inf\" is not finite"),
        (put(d, "array.npy", b"\x93NUMPY\x01\x00\xff\xfe"), "not text: points come as CSV (x, y, z)"),
        (put(d, "far.csv", "x,y,z\n1,2,3\n1,1e300,3\n"), "point 1 lies at [1.0, 1e300, 3.0]: a coordinate beyond 1e6"),
        (
            put(d, "far.mrk.json", r#"{"markups": [{"controlPoints": [{"position": [1, 2, 3e7]}]}]}"#),
            "point 0 lies at [1.0, 2.0, 30000000.0]: a coordinate beyond 1e6",
        ),
        (put(d, "syntax.mrk.json", "{\"markups\": [\n{\"type\": \"Fiducial\",,}]}"), "not valid JSON: "),
        (put(d, "other.mrk.json", "{\"nodes\": []}"), "no \"markups\" list"),
        (
            put(d, "frame.mrk.json", r#"{"markups": [{"coordinateSystem": "IJK", "controlPoints": []}]}"#),
            "markups[0]: unknown coordinate system 'IJK'",
        ),
        (
            put(d, "unit.mrk.json", r#"{"markups": [{"coordinateUnits": "in", "controlPoints": []}]}"#),
            "markups[0]: coordinateUnits must be m, cm, mm or um, got 'in'",
        ),
        (
            put(d, "nopos.mrk.json", r#"{"markups": [{"controlPoints": [{"label": "A"}, {"label": "B"}]}]}"#),
            "markups[0].controlPoints[0] (A): no position",
        ),
        (
            put(
                d,
                "pos.mrk.json",
                r#"{"markups": [{"controlPoints": [{"position": [1, 2, 3]}, {"position": [1, "2", 3]}]}]}"#,
            ),
            "markups[0].controlPoints[1]: position [1,\"2\",3] is not 3 numbers",
        ),
        (put(d, "space.stl", "solid SPACE=IJK\nendsolid\n"), "header tag SPACE=IJK: unknown coordinate system"),
    ];
    for (path, expected) in cases {
        let e = if path.extension().unwrap() == "stl" {
            message(surface_frame(&path))
        } else {
            message(read_points(&path))
        };
        assert!(e.starts_with(&path.display().to_string()), "{e}");
        assert!(e.contains(expected), "{}: {e}\nexpected: {expected}", path.display());
    }
    // A JSON syntax error gives its line.
    let e = message(read_points(d.join("syntax.mrk.json")));
    assert!(e.contains("line 2"), "{e}");
}
