//! Mesh and surface file I/O: real SOFA meshes, broken files, round trips.

use std::collections::{BTreeSet, HashMap};
use std::fs;
use std::io::Write;
use std::path::{Path, PathBuf};

use base64::engine::general_purpose::STANDARD as BASE64;
use base64::Engine as _;

use augsim_mesh::io::{
    read_gmsh, read_mesh, read_mesh_with_fields, read_obj, read_stl, read_surface, read_surface_noted, read_vertices,
    read_vtk, read_vtk_with_fields, read_vtu_with_fields, write_mesh, write_msh, write_obj, write_stl, write_surface,
    write_vtk_legacy, write_vtk_legacy_with, write_vtu, write_vtu_with, Encoding, Field, FieldLocation,
};
use augsim_mesh::{box_hex, box_tet, Cells, Mesh, MeshError, NodeSelection, TriSurface};

fn data(name: &str) -> PathBuf {
    Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data")).join(name)
}

/// The error message of a failed read (panics if the read succeeded).
fn message<T: std::fmt::Debug>(result: Result<T, MeshError>) -> String {
    result.expect_err("reading should fail").to_string()
}

/// Writes `text` to `name` in `dir` and returns the path.
fn put(dir: &Path, name: &str, text: impl AsRef<[u8]>) -> PathBuf {
    let path = dir.join(name);
    fs::write(&path, text).unwrap();
    path
}

/// Every cell positively oriented and the mesh valid.
fn assert_oriented(mesh: &Mesh) {
    mesh.validate().unwrap();
    for i in 0..mesh.cells.len() {
        assert!(mesh.cell_volume(i) > 0.0, "cell {i} has volume {}", mesh.cell_volume(i));
    }
}

/// The node sets of the cells, independent of node order within a cell.
fn cell_sets(mesh: &Mesh) -> BTreeSet<Vec<usize>> {
    (0..mesh.cells.len())
        .map(|i| {
            let mut c = mesh.cells.cell(i).to_vec();
            c.sort_unstable();
            c
        })
        .collect()
}

/// A box mesh with slightly perturbed, non-round coordinates (still valid).
fn wobbly(mut mesh: Mesh) -> Mesh {
    let mut state = 12345u64;
    for p in &mut mesh.nodes {
        for c in p.iter_mut() {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            *c += ((state >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 1e-3 + 1.0 / 3.0;
        }
    }
    mesh.validate().unwrap();
    mesh
}

fn tet_box() -> Mesh {
    wobbly(box_tet([-0.1, 0.02, 0.3], [0.17, 0.5, 0.9], [3, 2, 4]).unwrap())
}

fn hex_box() -> Mesh {
    wobbly(box_hex([-0.1, 0.02, 0.3], [0.17, 0.5, 0.9], [3, 2, 4]).unwrap())
}

fn fields_for(mesh: &Mesh) -> Vec<Field> {
    let disp: Vec<[f64; 3]> = mesh.nodes.iter().map(|p| [p[0] * 0.1, -p[1] / 7.0, p[2] * p[0]]).collect();
    vec![
        Field::point_vectors("displacement", &disp),
        Field::point("temperature", 1, mesh.nodes.iter().map(|p| p[0] * 1e-200).collect()),
        Field::cell("stress", 6, (0..mesh.cells.len() * 6).map(|i| i as f64 * 0.1 - 3.0).collect()),
        Field::cell("fraction", 1, (0..mesh.cells.len()).map(|i| 1.0 / (i as f64 + 1.0)).collect()),
    ]
}

#[test]
fn sofa_gmsh_meshes_load_with_the_counts_of_their_headers() {
    // (file, nodes declared in $NOD/$Nodes, volume elements in $ELM/$Elements, kind); every
    // declared node is used by a volume element in these files.
    let cases = [
        ("liver.msh", 181, 596, "T4"),
        ("liver2.msh", 507, 1493, "T4"),
        ("cylinder.msh", 510, 2430, "T4"),
        ("cube_low_res.msh", 26, 44, "T4"),
        ("msh4_cube.msh", 14, 24, "T4"),
        ("SimpleBeamHexa.msh", 16, 3, "H8"),
    ];
    for (file, nodes, cells, kind) in cases {
        let mesh = read_mesh(data(file)).unwrap();
        assert_eq!((mesh.num_nodes(), mesh.cells.len(), mesh.cells.kind_name()), (nodes, cells, kind), "{file}");
        assert_oriented(&mesh);
    }
}

#[test]
fn analytic_volumes_after_orientation_fix() {
    // Three unit cubes side by side, given mirrored (negative volume) in the file.
    let beam = read_gmsh(data("SimpleBeamHexa.msh")).unwrap();
    assert!((beam.volume() - 3.0).abs() < 1e-12, "{}", beam.volume());
    assert!(beam.odd_cells.is_empty(), "all mirrored alike: the file's convention, no cell odd");
    let unit = read_gmsh(data("msh4_cube.msh")).unwrap();
    assert!((unit.volume() - 1.0).abs() < 1e-12, "{}", unit.volume());
    // A 7 m cube whose coordinates are perturbed by ~5e-7.
    let cube = read_gmsh(data("cube_low_res.msh")).unwrap();
    assert!((cube.volume() - 343.0).abs() < 1e-3, "{}", cube.volume());
}

#[test]
fn gmsh_nodes_keep_file_order_and_match_the_obj_surface() {
    // liver2.msh has sparse node tags (2, 9, 17, ...): the first mesh node is the first in the file.
    let text = fs::read_to_string(data("liver2.msh")).unwrap();
    let first: Vec<f64> = text.lines().nth(2).unwrap().split_whitespace().skip(1).map(|t| t.parse().unwrap()).collect();
    let mesh = read_mesh(data("liver2.msh")).unwrap();
    assert_eq!(mesh.nodes[0].to_vec(), first);
    // Selections by number take Gmsh's tags.
    let tag =
        |line: usize| -> usize { text.lines().nth(line).unwrap().split_whitespace().next().unwrap().parse().unwrap() };
    assert_eq!((tag(2), tag(3)), (2, 9));
    assert_eq!(NodeSelection::List(vec![9, 2]).select(&mesh).unwrap(), [0, 1]);
    assert!(message(NodeSelection::List(vec![1]).select(&mesh)).contains("no such node"));
    // liver.obj holds the 181 nodes of liver.msh in the same order.
    let liver = read_mesh(data("liver.msh")).unwrap();
    let surface = read_surface(data("liver.obj")).unwrap();
    assert_eq!(surface.vertices, liver.nodes);
}

#[test]
fn inverted_tetrahedra_are_flipped() {
    let mesh = tet_box();
    let mut text = format!("$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n{}\n", mesh.num_nodes());
    for (i, p) in mesh.nodes.iter().enumerate() {
        text += &format!("{} {:?} {:?} {:?}\n", 10 * i + 7, p[0], p[1], p[2]);
    }
    text += &format!("$EndNodes\n$Elements\n{}\n", mesh.cells.len() + 1);
    text += "1 15 2 0 1 7\n"; // a point element, ignored
    for e in 0..mesh.cells.len() {
        let mut c = mesh.cells.cell(e).to_vec();
        if e % 2 == 0 {
            c.swap(0, 1);
        }
        let tags: Vec<String> = c.iter().map(|i| (10 * i + 7).to_string()).collect();
        text += &format!("{} 4 2 0 1 {}\n", e + 2, tags.join(" "));
    }
    text += "$EndElements\n";
    let dir = tempfile::tempdir().unwrap();
    let read = read_mesh(put(dir.path(), "flipped.msh", text)).unwrap();
    assert_oriented(&read);
    assert_eq!(read.nodes, mesh.nodes);
    assert_eq!(cell_sets(&read), cell_sets(&mesh));
    assert!((read.volume() - mesh.volume()).abs() < 1e-12 * mesh.volume());
    // Half of them the other way round: the fewer orientation's cells are named.
    assert_eq!(read.odd_cells.len(), mesh.cells.len() / 2, "{:?}", read.odd_cells);
}

#[test]
fn surfaces_load_with_their_counts() {
    for (file, vertices, triangles) in [
        ("liver.obj", 181, 274),
        ("liver-smooth.obj", 2194, 4384),
        ("liver2.obj", 1170, 2336),
        ("liver.vtk", 5008, 10000),
    ] {
        let s = read_surface(data(file)).unwrap();
        assert_eq!((s.vertices.len(), s.triangles.len()), (vertices, triangles), "{file}");
        assert!(s.triangles.iter().flatten().all(|&i| i < s.vertices.len()));
    }
}

#[test]
fn the_points_of_a_model_file_are_read_whatever_its_cells() {
    let dir = tempfile::tempdir().unwrap();
    // A cloud saved as a model: vertices only, or VTK vertices.
    let obj = put(dir.path(), "cloud.obj", "# cloud\nv 1 2 3\nv 4 5 6\n");
    assert_eq!(read_vertices(&obj).unwrap(), [[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]);
    assert!(message(read_obj(&obj)).contains("no faces"), "a surface needs faces");
    let vtk = put(
        dir.path(),
        "cloud.vtk",
        "# vtk DataFile Version 3.0\ncloud SPACE=RAS\nASCII\nDATASET POLYDATA\nPOINTS 2 float\n1 2 3 4 5 6\n\
         VERTICES 2 4\n1 0\n1 1\n",
    );
    assert_eq!(read_vertices(&vtk).unwrap(), [[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]);
    // A surface's and a volume mesh's points: an STL's corners once each, a grid's nodes in order.
    let corners = vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    let tetrahedron = TriSurface { vertices: corners, triangles: vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]] };
    let stl = dir.path().join("tetrahedron.stl");
    write_stl(&stl, &tetrahedron).unwrap();
    let mut read = read_vertices(&stl).unwrap();
    read.sort_by(|a, b| a.partial_cmp(b).unwrap());
    assert_eq!(read, [[0.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]], "12 corners, 4 points");
    let mesh = tet_box();
    let vtu = dir.path().join("box.vtu");
    write_vtu(&vtu, &mesh, &[]).unwrap();
    assert_eq!(read_vertices(&vtu).unwrap(), mesh.nodes);
    let legacy = dir.path().join("box.vtk");
    write_vtk_legacy(&legacy, &mesh, &[]).unwrap();
    assert_eq!(read_vertices(&legacy).unwrap(), mesh.nodes);
    assert!(message(read_vertices(dir.path().join("cloud.xyz"))).contains("unknown surface extension"));
    let empty = put(dir.path(), "empty.vtk", "# vtk DataFile Version 3.0\nempty\nASCII\nDATASET POLYDATA\n");
    assert!(message(read_vertices(&empty)).contains("no POINTS"));
}

#[test]
fn binary_vtk_surface_is_closed_and_consistently_oriented() {
    // liver.vtk is a closed, consistently oriented surface: every directed edge appears once and
    // its reverse too. A decoding error in the binary cells would break this.
    let s = read_surface(data("liver.vtk")).unwrap();
    let mut edges = HashMap::new();
    for t in &s.triangles {
        for k in 0..3 {
            *edges.entry((t[k], t[(k + 1) % 3])).or_insert(0) += 1;
        }
    }
    assert!(edges.iter().all(|(&(a, b), &n)| n == 1 && edges.get(&(b, a)) == Some(&1)));
    let (lo, hi) = augsim_mesh::bounds(&s.vertices);
    assert!((0..3).all(|d| hi[d] > lo[d] && lo[d].is_finite() && hi[d].is_finite()));
}

#[test]
fn broken_sofa_vtk_is_rejected_with_the_reason() {
    for result in [
        read_surface(data("liver_for_test_broken.vtk")).map(|_| ()),
        read_vtk(data("liver_for_test_broken.vtk")).map(|_| ()),
    ] {
        let m = message(result);
        assert!(m.contains("liver_for_test_broken.vtk"), "{m}");
        assert!(m.contains("POINTS 508") && m.contains("line 5"), "{m}");
        assert!(m.contains("POLYGONS at line 461"), "{m}");
        assert!(m.contains("corrupt"), "{m}");
    }
}

#[test]
fn missing_file_and_unknown_extension() {
    match read_mesh("/nonexistent/dir/liver.msh") {
        Err(MeshError::Io { path, .. }) => assert!(path.contains("liver.msh")),
        other => panic!("{other:?}"),
    }
    assert!(message(read_surface("/nonexistent/liver.obj")).contains("/nonexistent/liver.obj"));
    assert!(message(read_mesh(data("liver.obj"))).contains("extension"));
    assert!(message(read_surface(data("liver.msh"))).contains("extension"));
}

/// Replaces line `line` (1-based) of `text`.
fn with_line(text: &str, line: usize, new: &str) -> String {
    text.lines().enumerate().map(|(i, l)| if i + 1 == line { new } else { l }).collect::<Vec<_>>().join("\n") + "\n"
}

#[test]
fn corrupted_gmsh_files_give_located_errors() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let liver = fs::read_to_string(data("liver.msh")).unwrap();
    // $NOD on line 1, count on line 2, nodes on lines 3..=183, $ENDNOD 184, $ELM 185, count 186,
    // elements from line 187.
    let half = &liver[..liver.len() / 2];
    let m = message(read_mesh(put(d, "half.msh", half)));
    assert!(m.contains("half.msh") && m.contains("the file ends in the middle of this line: truncated"), "{m}");

    let m = message(read_mesh(put(d, "garbled.msh", with_line(&liver, 10, "8 0.1 2.x5 3"))));
    assert!(m.contains("line 10") && m.contains("2.x5"), "{m}");
    // A node out of reach (its elements' volumes overflowed and were called zero).
    let m = message(read_mesh(put(d, "far.msh", with_line(&liver, 3, "1 -0.979259 1e308 2.61245"))));
    assert!(m.contains("a coordinate beyond 1e9") && m.contains("a damaged file?"), "{m}");

    let m = message(read_mesh(put(d, "range.msh", with_line(&liver, 187, "1 4 1 1 4 128 141 138 9999"))));
    assert!(m.contains("line 187") && m.contains("node 9999"), "{m}");

    let m = message(read_mesh(put(d, "type.msh", with_line(&liver, 188, "2 99 1 1 4 91 143 7 140"))));
    assert!(m.contains("line 188") && m.contains("unknown element type 99"), "{m}");

    let m = message(read_mesh(put(d, "tet10.msh", with_line(&liver, 188, "2 11 1 1 10 1 2 3 4 5 6 7 8 9 10"))));
    assert!(m.contains("mixes tetrahedra") && m.contains("quadratic tetrahedra") && m.contains("line 188"), "{m}");

    let m = message(read_mesh(put(d, "mixed.msh", with_line(&liver, 190, "4 5 1 1 8 1 2 3 4 5 6 7 8"))));
    assert!(m.contains("mixes tetrahedra") && m.contains("line 190"), "{m}");

    let m = message(read_mesh(put(d, "flat.msh", with_line(&liver, 189, "3 4 1 1 4 140 88 91 140"))));
    assert!(m.contains("element 3 (line 189)") && m.contains("zero volume"), "{m}");

    let m = message(read_mesh(put(d, "count.msh", with_line(&liver, 2, "182"))));
    assert!(m.contains("$ENDNOD") && m.contains("181 of the 182 nodes"), "{m}");

    let m = message(read_mesh(put(d, "short.msh", with_line(&liver, 187, "1 4 1 1 4 128 141 138"))));
    assert!(m.contains("line 187") && m.contains("declares 4 nodes but lists 3"), "{m}");

    // Gmsh 4.1: a node block cut short, and a binary file.
    let cube = fs::read_to_string(data("msh4_cube.msh")).unwrap();
    let cut: String = cube.lines().take(120).map(|l| format!("{l}\n")).collect();
    let m = message(read_mesh(put(d, "cut4.msh", cut)));
    assert!(m.contains("file ends") && m.contains("truncated"), "{m}");
    let m = message(read_mesh(put(d, "bin.msh", with_line(&cube, 2, "4.1 1 8"))));
    assert!(m.contains("binary") && m.contains("line 2"), "{m}");
    let m = message(read_mesh(put(d, "v3.msh", with_line(&cube, 2, "3.0 0 8"))));
    assert!(m.contains("version 3.0"), "{m}");
    assert!(message(read_mesh(put(d, "empty.msh", ""))).contains("empty"));
    assert!(message(read_mesh(put(d, "text.msh", "hello\n"))).contains("not a Gmsh mesh"));
}

/// `mesh` as read back from a Gmsh file written by augsim or an Abaqus deck: its nodes and
/// elements numbered from 1.
fn tagged_from_1(mesh: Mesh) -> Mesh {
    Mesh {
        file_nodes: Some((1..=mesh.num_nodes()).collect()),
        file_cells: Some((1..=mesh.cells.len()).collect()),
        ..mesh
    }
}

#[test]
fn gmsh_sections_that_are_not_needed_are_skipped() {
    let dir = tempfile::tempdir().unwrap();
    let mesh = hex_box();
    let path = dir.path().join("a.msh");
    write_msh(&path, &mesh).unwrap();
    let text = fs::read_to_string(&path).unwrap().replace(
        "$EndMeshFormat\n",
        "$EndMeshFormat\n$PhysicalNames\n1\n3 1 \"liver\"\n$EndPhysicalNames\n$Comments\n$Nodes inside a comment\n$EndComments\n",
    );
    assert_eq!(read_mesh(put(dir.path(), "b.msh", &text)).unwrap(), tagged_from_1(mesh));
    let m = message(read_mesh(put(dir.path(), "c.msh", text.replace("$EndComments\n", ""))));
    assert!(m.contains("$Comments") && m.contains("not closed"), "{m}");
}

#[test]
fn corrupted_vtk_files_give_located_errors() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let liver = fs::read(data("liver.vtk")).unwrap();
    let m = message(read_surface(put(d, "cut.vtk", &liver[..100_000])));
    assert!(m.contains("POLYGONS") && m.contains("truncated"), "{m}");

    let mesh = tet_box();
    let ascii = d.join("ascii.vtk");
    write_vtk_legacy_with(&ascii, &mesh, &[], Encoding::Ascii).unwrap();
    let text = fs::read_to_string(&ascii).unwrap();
    // Line 5 is POINTS, so the first point is on line 6.
    let m = message(read_mesh(put(d, "garbled.vtk", with_line(&text, 7, "0.1 0.2 zz"))));
    assert!(m.contains("line 7") && m.contains("'zz', not a number"), "{m}");
    // A point that is not finite, named with its section whatever is read of the file.
    let nan = put(d, "nan.vtk", with_line(&text, 7, "0.1 nan 0.3"));
    let points = mesh.num_nodes();
    for m in [message(read_mesh(&nan)), message(read_surface(&nan)), message(read_vertices(&nan))] {
        let expected = format!("POINTS {points} (line 5): point 1 has a non-finite coordinate: y = NaN");
        assert!(m.contains("nan.vtk") && m.contains(&expected), "{m}");
    }

    let cells_line = 6 + points;
    let m = message(read_mesh(put(d, "range.vtk", with_line(&text, cells_line + 1, "4 0 1 2 100000"))));
    assert!(m.contains("cell 0 refers to point 100000"), "{m}");

    let m = message(read_mesh(put(d, "count.vtk", with_line(&text, 5, &format!("POINTS {} double", points - 1)))));
    assert!(m.contains("more values than the header declares"), "{m}");

    let types_line = cells_line + mesh.cells.len() + 1;
    let m = message(read_mesh(put(d, "wedge.vtk", with_line(&text, types_line + 2, "13"))));
    assert!(m.contains("cell 1 is a wedge"), "{m}");
    let m = message(read_mesh(put(d, "unknown.vtk", with_line(&text, types_line + 2, "99"))));
    assert!(m.contains("unknown VTK cell type 99"), "{m}");
    let m = message(read_mesh(put(d, "nodataset.vtk", with_line(&text, 4, ""))));
    assert!(m.contains("line 4: expected DATASET, found 'POINTS'"), "{m}");
    let m = message(read_mesh(put(d, "notvtk.vtk", "solid x\n")));
    assert!(m.contains("line 1") && m.contains("not a legacy VTK file"), "{m}");
    let m = message(read_mesh(data("liver.vtk")));
    assert!(m.contains("POLYDATA") && m.contains("surface"), "{m}");
}

#[test]
fn handwritten_vtk_variants() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // VTK 5.1 OFFSETS/CONNECTIVITY cells, a voxel, a triangle to ignore, SCALARS with a lookup
    // table, VECTORS and METADATA.
    let text = "# vtk DataFile Version 5.1\nvoxel\nASCII\nDATASET UNSTRUCTURED_GRID\n\
        POINTS 8 float\n0 0 0 2 0 0 0 1 0 2 1 0 0 0 1 2 0 1 0 1 1 2 1 1\n\
        CELLS 3 11\nOFFSETS vtktypeint64\n0 3 11\nCONNECTIVITY vtktypeint64\n0 1 2 0 1 2 3 4 5 6 7\n\
        CELL_TYPES 2\n5\n11\n\
        CELL_DATA 2\nSCALARS id int 1\nLOOKUP_TABLE default\n7 9\n\
        METADATA\nINFORMATION 0\n\n\
        POINT_DATA 8\nVECTORS v double\n0 0 0 1 0 0 0 1 0 1 1 0 0 0 1 1 0 1 0 1 1 1 1 1\n";
    let (mesh, fields) = read_mesh_with_fields(put(d, "voxel.vtk", text)).unwrap();
    assert!(matches!(mesh.cells, Cells::Hex8(_)));
    assert_oriented(&mesh);
    assert!((mesh.volume() - 2.0).abs() < 1e-12);
    assert_eq!(fields.len(), 2);
    assert_eq!(
        (fields[0].name.as_str(), fields[0].location, &fields[0].values[..]),
        ("id", FieldLocation::Cell, &[9.0][..])
    );
    assert_eq!((fields[1].name.as_str(), fields[1].components, fields[1].num_tuples()), ("v", 3, 8));
    let surface = read_surface(d.join("voxel.vtk")).unwrap();
    assert_eq!(surface.triangles, vec![[0, 1, 2]]);

    // A tetrahedron flat to the digits printed (its apex 1e-9 off the base's plane): refused.
    let text = "# vtk DataFile Version 3.0\nflat\nASCII\nDATASET UNSTRUCTURED_GRID\n\
        POINTS 4 double\n0 0 0 1 0 0 0 1 0 0.333333333 0.333333333 1e-9\nCELLS 1 5\n4 0 1 2 3\nCELL_TYPES 1\n10\n";
    let e = read_mesh(put(d, "flat.vtk", text)).unwrap_err().to_string();
    assert!(e.contains("zero volume") && e.contains("repeated or coplanar"), "{e}");

    // VTK 9's polydata writer gives some OFFSETS and CONNECTIVITY as vtkIdType (64-bit ids).
    let text = "# vtk DataFile Version 5.1\n3D Slicer output. SPACE=LPS\nASCII\nDATASET POLYDATA\n\
        POINTS 4 float\n0 0 0 1 0 0 0 1 0 1 1 0\n\
        POLYGONS 3 6\nOFFSETS vtkIdType\n0 3 6\nCONNECTIVITY vtkIdType\n0 1 2 2 1 3\n";
    let s = read_surface(put(d, "ids.vtk", text)).unwrap();
    assert_eq!(s.triangles, vec![[0, 1, 2], [2, 1, 3]]);

    // POLYDATA with a triangle strip and a quad polygon.
    let text = "# vtk DataFile Version 3.0\nstrip\nASCII\nDATASET POLYDATA\nPOINTS 5 double\n\
        0 0 0 1 0 0 0 1 0 1 1 0 2 0 0\nTRIANGLE_STRIPS 1 5\n4 0 1 2 3\nPOLYGONS 1 5\n4 1 4 3 2\n";
    let s = read_surface(put(d, "strip.vtk", text)).unwrap();
    assert_eq!(s.triangles, vec![[0, 1, 2], [2, 1, 3], [1, 4, 3], [1, 3, 2]]);
    // All four triangles face +z.
    for t in &s.triangles {
        let [a, b, c] = t.map(|i| s.vertices[i]);
        let n = augsim_mesh::cross(augsim_mesh::sub(b, a), augsim_mesh::sub(c, a));
        assert!(n[2] > 0.0, "{t:?}");
    }
}

#[test]
fn volume_round_trips_are_exact() {
    let dir = tempfile::tempdir().unwrap();
    for mesh in [tet_box(), hex_box(), tet_box().quadratic().unwrap()] {
        let fields = fields_for(&mesh);
        for (name, enc) in [("b.vtu", Encoding::Binary), ("a.vtu", Encoding::Ascii)] {
            let path = dir.path().join(name);
            write_vtu_with(&path, &mesh, &fields, enc).unwrap();
            let (read, read_fields) = read_vtu_with_fields(&path).unwrap();
            assert_eq!(read, mesh, "{name}");
            assert_eq!(read_fields, fields, "{name}");
        }
        for (name, enc) in [("b.vtk", Encoding::Binary), ("a.vtk", Encoding::Ascii)] {
            let path = dir.path().join(name);
            write_vtk_legacy_with(&path, &mesh, &fields, enc).unwrap();
            let (read, read_fields) = read_vtk_with_fields(&path).unwrap();
            assert_eq!(read, mesh, "{name}");
            assert_eq!(read_fields, fields, "{name}");
        }
        let path = dir.path().join("m.msh");
        write_mesh(&path, &mesh, &[]).unwrap();
        assert_eq!(read_mesh(&path).unwrap(), tagged_from_1(mesh.clone()));
        assert!(message(write_mesh(&path, &mesh, &fields)).contains("no fields"));
        // Default writers and dispatch agree with the explicit ones.
        write_vtu(dir.path().join("d.vtu"), &mesh, &fields).unwrap();
        write_vtk_legacy(dir.path().join("d.vtk"), &mesh, &fields).unwrap();
        assert_eq!(read_mesh_with_fields(dir.path().join("d.vtu")).unwrap(), (mesh.clone(), fields.clone()));
        assert_eq!(read_mesh_with_fields(dir.path().join("d.vtk")).unwrap(), (mesh.clone(), fields.clone()));
    }
    // A real mesh through every format.
    let liver = read_mesh(data("liver2.msh")).unwrap();
    for name in ["l.vtu", "l.vtk", "l.msh"] {
        let path = dir.path().join(name);
        write_mesh(&path, &liver, &[]).unwrap();
        // Gmsh's tags are augsim's numbers from 1; VTK numbers nodes from 0.
        let expected = Mesh { file_nodes: None, file_cells: None, ..liver.clone() };
        let expected = if name.ends_with(".msh") { tagged_from_1(expected) } else { expected };
        assert_eq!(read_mesh(&path).unwrap(), expected, "{name}");
    }
    // Writers leave no temporary files behind.
    let mut names: Vec<String> =
        fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name().into_string().unwrap()).collect();
    names.sort();
    assert_eq!(names, ["a.vtk", "a.vtu", "b.vtk", "b.vtu", "d.vtk", "d.vtu", "l.msh", "l.vtk", "l.vtu", "m.msh"]);
}

#[test]
fn unused_nodes_are_dropped_and_point_fields_follow() {
    let dir = tempfile::tempdir().unwrap();
    let mesh = tet_box();
    // Put an isolated node first: the reader drops it and shifts everything else, keeping where
    // each node lies in the file.
    let mut nodes = vec![[9.0, 9.0, 9.0]];
    nodes.extend_from_slice(&mesh.nodes);
    let Cells::Tet4(tets) = &mesh.cells else { unreachable!() };
    let padded = Mesh::new(nodes, Cells::Tet4(tets.iter().map(|t| t.map(|i| i + 1)).collect())).unwrap();
    let values: Vec<f64> = (0..padded.num_nodes()).map(|i| i as f64).collect();
    let path = dir.path().join("p.vtu");
    write_vtu(&path, &padded, &[Field::point("index", 1, values)]).unwrap();
    let (read, fields) = read_mesh_with_fields(&path).unwrap();
    assert_eq!(read, Mesh { file_nodes: Some((1..padded.num_nodes()).collect()), ..mesh });
    assert_eq!(fields[0].values, (1..padded.num_nodes()).map(|i| i as f64).collect::<Vec<_>>());
}

#[test]
fn field_and_write_errors() {
    let dir = tempfile::tempdir().unwrap();
    let mesh = tet_box();
    let short = Field::point("u", 3, vec![0.0; 3 * mesh.num_nodes() - 1]);
    let m = message(write_vtu(dir.path().join("x.vtu"), &mesh, &[short]));
    assert!(m.contains("field 'u'") && m.contains(&format!("need {}", 3 * mesh.num_nodes())), "{m}");
    let spaced = Field::cell("von mises", 1, vec![0.0; mesh.cells.len()]);
    assert!(message(write_vtk_legacy(dir.path().join("x.vtk"), &mesh, &[spaced])).contains("whitespace"));
    let twice = [Field::cell("a", 1, vec![0.0; mesh.cells.len()]), Field::cell("a", 1, vec![1.0; mesh.cells.len()])];
    assert!(message(write_vtu(dir.path().join("x.vtu"), &mesh, &twice)).contains("two fields"));
    assert!(fs::read_dir(dir.path()).unwrap().next().is_none(), "nothing written on error");
    // Missing directories are created; a parent that is a regular file is an I/O error naming the target.
    fs::write(dir.path().join("plain"), b"").unwrap();
    match write_vtu(dir.path().join("plain/x.vtu"), &mesh, &[]) {
        Err(MeshError::Io { path, .. }) => assert!(path.ends_with("x.vtu")),
        other => panic!("{other:?}"),
    }
    let bad = TriSurface { vertices: vec![[0.0; 3]; 2], triangles: vec![[0, 1, 2]] };
    assert!(message(write_surface(dir.path().join("s.obj"), &bad)).contains("node 2"));
}

#[test]
fn surface_round_trips() {
    let dir = tempfile::tempdir().unwrap();
    let liver = read_surface(data("liver-smooth.obj")).unwrap();
    for name in ["s.obj", "s.vtk", "s.vtu"] {
        let path = dir.path().join(name);
        write_surface(&path, &liver).unwrap();
        assert_eq!(read_surface(&path).unwrap(), liver, "{name}");
    }
    // STL is single precision and indexed by merging: same triangles, coordinates to f32.
    let path = dir.path().join("s.stl");
    write_stl(&path, &liver).unwrap();
    let stl = read_stl(&path).unwrap();
    assert_eq!(stl.triangles.len(), liver.triangles.len());
    let used: BTreeSet<usize> = liver.triangles.iter().flatten().copied().collect();
    assert_eq!(stl.vertices.len(), used.len());
    for (a, b) in stl.triangles.iter().zip(&liver.triangles) {
        for k in 0..3 {
            let (p, q) = (stl.vertices[a[k]], liver.vertices[b[k]]);
            assert!((0..3).all(|d| (p[d] - q[d]).abs() <= 1e-6 * q[d].abs().max(1.0)), "{p:?} {q:?}");
        }
    }
    // A binary STL whose header starts with "solid" is still read as binary.
    let mut bytes = fs::read(&path).unwrap();
    bytes[..12].copy_from_slice(b"solid liver ");
    assert_eq!(read_stl(put(dir.path(), "solid.stl", &bytes)).unwrap(), stl);
    let m = message(read_stl(put(dir.path(), "cut.stl", &bytes[..bytes.len() - 20])));
    assert!(m.contains(&format!("declares {} triangles", liver.triangles.len())), "{m}");
    // The OBJ writer's output reads back through the generic reader too.
    write_obj(dir.path().join("o.obj"), &liver).unwrap();
    assert_eq!(read_obj(dir.path().join("o.obj")).unwrap(), liver);
}

/// A binary STL whose header's count its size belies (0, as some exporters write, one too low, or
/// bytes after its last record) is read for the records it holds, with a warning saying so; one
/// holding fewer than its count is refused as cut short, and one of count 0 whose size is no whole
/// number of records as no binary STL.
#[test]
fn binary_stl_counts_that_its_size_belies() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let path = d.join("s.stl");
    write_stl(&path, &read_surface(data("liver-smooth.obj")).unwrap()).unwrap();
    let (bytes, stl) = (fs::read(&path).unwrap(), read_stl(&path).unwrap());
    let n = stl.triangles.len();
    let counted = |count: usize, tail: &[u8]| {
        let mut b = [&bytes[..], tail].concat();
        b[80..84].copy_from_slice(&(count as u32).to_le_bytes());
        b
    };
    let read = |name: &str, b: Vec<u8>| read_surface_noted(put(d, name, b)).unwrap();
    let (zero, _, warnings) = read("zero.stl", counted(0, &[]));
    assert_eq!(zero, stl);
    assert_eq!(
        warnings,
        [format!(
            "its header declares 0 triangles (84 bytes), but its size holds {n}: read {n}, as VTK (3D Slicer) does"
        )]
    );
    let (low, _, warnings) = read("low.stl", counted(n - 100, &[]));
    assert!(low == stl && warnings[0].contains(&format!("declares {} triangles", n - 100)), "{warnings:?}");
    let (trailing, _, warnings) = read("trailing.stl", counted(n, &[7; 72]));
    assert_eq!(
        (trailing, warnings),
        (stl.clone(), vec![format!("72 bytes after its {n} triangles, which its header declares, ignored")])
    );
    assert!(read_surface_noted(&path).unwrap().2.is_empty());
    let m = message(read_stl(put(d, "high.stl", counted(n + 1, &[]))));
    assert!(m.contains(&format!("a binary STL cut short: its header declares {} triangles", n + 1)), "{m}");
    assert!(m.contains(&format!("{n} whole triangles")) && !m.contains("truncated"), "{m}");
    let m = message(read_stl(put(d, "odd.stl", counted(0, &[1; 20]))));
    assert!(m.contains("not a binary STL") && m.contains("no whole number of 50-byte triangles"), "{m}");
}

#[test]
fn ascii_stl_and_obj_details() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // Two facets sharing an edge (one written as a quad loop is split into a fan), -0 == 0.
    let text = "solid square\n facet normal 0 0 1\n  outer loop\n   vertex 0 0 0\n   vertex 1 0 0\n   vertex 1 1 0\n  endloop\n endfacet\n\
        facet normal 0 0 1\n  outer loop\n   vertex -0 0 0\n   vertex 1 1 0\n   vertex 0 1 0\n  endloop\n endfacet\nendsolid square\n";
    let s = read_stl(put(d, "sq.stl", text)).unwrap();
    assert_eq!(s.vertices.len(), 4);
    assert_eq!(s.triangles, vec![[0, 1, 2], [0, 2, 3]]);
    let cut: String = text.lines().take(10).map(|l| format!("{l}\n")).collect();
    let m = message(read_stl(put(d, "cut.stl", cut)));
    assert!(m.contains("file ends") && m.contains("vertex"), "{m}");
    // Every facet closed but no `endsolid`, as some exporters end: read.
    let unended = text.replace("endsolid square\n", "");
    assert_eq!(read_stl(put(d, "unended.stl", unended)).unwrap(), s);
    let m = message(read_stl(put(
        d,
        "bad.stl",
        text.replace("vertex 1 1 0\n   vertex 0 1 0", "vertex 1 1\n   vertex 0 1 0"),
    )));
    assert!(m.contains("line 12") && m.contains("missing vertex coordinate"), "{m}");
    // A degenerate facet's normal as MeshLab writes it: ignored; a missing one is still an error.
    let nan_normal = text.replacen("facet normal 0 0 1", "facet normal -nan -nan -nan", 1);
    assert_eq!(read_stl(put(d, "nan.stl", nan_normal)).unwrap(), s);
    let m = message(read_stl(put(d, "nonormal.stl", text.replacen("facet normal 0 0 1", "facet normal 0 0", 1))));
    assert!(m.contains("line 2") && m.contains("missing normal component"), "{m}");
    // NUL padding after an ASCII STL (some exporters fill a block) is not read as a binary header.
    let padded = [text.as_bytes(), &[0u8; 37]].concat();
    std::fs::write(d.join("padded.stl"), &padded).unwrap();
    assert_eq!(read_stl(d.join("padded.stl")).unwrap(), s);
    // So is a NUL byte on a line of its own, which makes the file's size no binary STL's.
    let nul = text.replace("endsolid", "\0\nendsolid");
    assert_eq!(read_stl(put(d, "nul.stl", &nul)).unwrap(), s);
    // Text after the solid is a text error, not a binary header's count.
    let m = message(read_stl(put(d, "garbage.stl", format!("{text}garbage\0\u{1}\n"))));
    assert!(m.contains("line 17: expected 'solid', found 'garbage"), "{m}");
    // A binary STL of no triangles is named as empty.
    let empty = [&[b' '; 80][..], &0u32.to_le_bytes()].concat();
    std::fs::write(d.join("empty.stl"), &empty).unwrap();
    let m = message(read_stl(d.join("empty.stl")));
    assert!(m.contains("a binary STL of no triangles"), "{m}");

    // OBJ: quads as fans, negative indices, v/vt/vn forms, comments and other statements.
    let text = "# a square\no sq\nv 0 0 0\nv 1 0 0\nv 1 1 0\nvt 0 0\nvn 0 0 1\nv 0 1 0\ns off\nf 1/1/1 2//1 -2 -1\n";
    let s = read_obj(put(d, "sq.obj", text)).unwrap();
    assert_eq!(s.triangles, vec![[0, 1, 2], [0, 2, 3]]);
    let m = message(read_obj(put(d, "range.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n")));
    assert!(m.contains("line 4") && m.contains("vertex 4"), "{m}");
    let m = message(read_obj(put(d, "garbled.obj", "v 0 0 0\nv 1 x 0\n")));
    assert!(m.contains("line 2") && m.contains("'x'"), "{m}");
    assert!(message(read_obj(put(d, "none.obj", "v 0 0 0\n"))).contains("no faces"));
}

/// Round trips through Python's meshio, the reference reader of the field. Needs
/// `pip install meshio`; run with `cargo test -p augsim-mesh --test io -- --ignored`.
#[test]
#[ignore = "needs Python with meshio (pip install meshio); run with -- --ignored"]
fn meshio_round_trips() {
    let has_meshio =
        std::process::Command::new("python3").args(["-c", "import meshio"]).output().is_ok_and(|o| o.status.success());
    assert!(has_meshio, "this test was asked for but python3 cannot import meshio: pip install meshio");
    let dir = tempfile::tempdir().unwrap();
    for (mesh, cell_name) in
        [(tet_box(), "tetra"), (hex_box(), "hexahedron"), (tet_box().quadratic().unwrap(), "tetra10")]
    {
        let fields = fields_for(&mesh);
        for (name, enc) in [("m.vtu", Encoding::Binary), ("a.vtu", Encoding::Ascii), ("m.vtk", Encoding::Binary)] {
            let path = dir.path().join(name);
            if name.ends_with(".vtu") {
                write_vtu_with(&path, &mesh, &fields, enc).unwrap();
            } else {
                write_vtk_legacy_with(&path, &mesh, &fields, enc).unwrap();
            }
            let script = "import meshio, sys\nm = meshio.read(sys.argv[1])\n\
                 print(len(m.points), m.cells[0].type, len(m.cells[0].data), repr(float(m.points.sum())), \
                 repr(float(m.point_data['displacement'].sum())), repr(float(m.cell_data['stress'][0].sum())))";
            let out =
                std::process::Command::new("python3").args(["-c", script, path.to_str().unwrap()]).output().unwrap();
            assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
            let out = String::from_utf8(out.stdout).unwrap();
            let words: Vec<&str> = out.split_whitespace().collect();
            assert_eq!(
                words[..3],
                [mesh.num_nodes().to_string().as_str(), cell_name, mesh.cells.len().to_string().as_str()]
            );
            let sum = |v: &[f64]| v.iter().sum::<f64>();
            let points: Vec<f64> = mesh.nodes.iter().flatten().copied().collect();
            for (word, expected) in
                words[3..].iter().zip([sum(&points), sum(&fields[0].values), sum(&fields[2].values)])
            {
                let got: f64 = word.parse().unwrap();
                assert!((got - expected).abs() <= 1e-9 * expected.abs().max(1.0), "{name}: {got} vs {expected}");
            }
        }
        // What meshio writes (zlib-compressed and raw .vtu, VTK 5.1 legacy, Gmsh 2.2 and 4.1)
        // reads back as the same mesh and point data.
        let source = dir.path().join("m.vtu");
        write_vtu(&source, &mesh, &fields).unwrap();
        let script = "import meshio, sys\nm = meshio.read(sys.argv[1])\nd = sys.argv[2]\n\
            m.write(d + '/z.vtu')\nm.write(d + '/r.vtu', compression=None)\nm.write(d + '/l.vtk')\n\
            g = meshio.Mesh(m.points, m.cells)\ng.write(d + '/g41.msh', file_format='gmsh', binary=False)\n\
            g.write(d + '/g22.msh', file_format='gmsh22', binary=False)";
        let out = std::process::Command::new("python3")
            .args(["-c", script, source.to_str().unwrap(), dir.path().to_str().unwrap()])
            .output()
            .unwrap();
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        for name in ["z.vtu", "r.vtu", "l.vtk"] {
            let (read, read_fields) = read_mesh_with_fields(dir.path().join(name)).unwrap();
            assert_eq!(read, mesh, "{name}");
            let displacement = read_fields.iter().find(|f| f.name == "displacement").unwrap();
            assert_eq!(displacement, &fields[0], "{name}");
        }
        for name in ["g41.msh", "g22.msh"] {
            assert_eq!(read_mesh(dir.path().join(name)).unwrap(), mesh, "{name}");
        }
    }
}

#[test]
fn corrupted_vtu_files_give_located_errors() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let mesh = tet_box();
    let fields = fields_for(&mesh);
    write_vtu(d.join("m.vtu"), &mesh, &fields).unwrap();
    write_vtu_with(d.join("a.vtu"), &mesh, &fields, Encoding::Ascii).unwrap();
    let b = fs::read_to_string(d.join("m.vtu")).unwrap();
    let a = fs::read_to_string(d.join("a.vtu")).unwrap();
    let n = mesh.num_nodes();
    let binary = "format=\"binary\">";
    let cases = [
        ("cut.vtu", b[..b.len() / 2].to_string(), "truncated"),
        ("end.vtu", b[..b.len() - 30].to_string(), "truncated"),
        ("b64.vtu", b.replacen(binary, "format=\"binary\">A!", 1), "line 6: DataArray 'displacement': invalid base64"),
        (
            "count.vtu",
            b.replacen(binary, "format=\"binary\">AAAAAAAA", 1),
            "line 6: DataArray 'displacement': the data is shorter than its header",
        ),
        ("points.vtu", b.replace(&format!("NumberOfPoints=\"{n}\""), "NumberOfPoints=\"7\""), "7 × 3 components"),
        ("ascii.vtu", a.replacen("\n0.", "\n0.x", 1), "'0.x"),
        (
            "conn.vtu",
            a.replacen("\"connectivity\" format=\"ascii\">\n0 ", "\"connectivity\" format=\"ascii\">\n", 1),
            "past the",
        ),
        ("lzma.vtu", b.replace("\"UInt64\"", "\"UInt64\" compressor=\"vtkLZMADataCompressor\""), "not supported"),
        ("poly.vtu", b.replace("type=\"UnstructuredGrid\"", "type=\"PolyData\""), "PolyData holds a surface"),
        ("image.vtu", b.replace("type=\"UnstructuredGrid\"", "type=\"ImageData\""), "not UnstructuredGrid or PolyData"),
        ("tags.vtu", b.replace("</Points>", "</Cells>"), "</Cells> closes <Points>"),
        ("empty.vtu", String::new(), "no <VTKFile>"),
    ];
    for (name, text, expected) in cases {
        let m = message(read_mesh(put(d, name, text)));
        assert!(m.contains(name) && m.contains(expected), "{name}: {m}");
    }
}

/// A zlib block header declaring a block of 2^64 − 1 bytes is refused, not overflowed.
#[test]
fn a_zlib_block_of_any_declared_size_is_refused_cleanly() {
    let dir = tempfile::tempdir().unwrap();
    let payload: Vec<u8> = [1.0f64, 2.0, 3.0].iter().flat_map(|x| x.to_le_bytes()).collect();
    let mut e = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::default());
    e.write_all(&payload).unwrap();
    let compressed = e.finish().unwrap();
    // One block of u64::MAX bytes, none in a last partial block, then its compressed size.
    let header: Vec<u8> = [1, u64::MAX, 0, compressed.len() as u64].iter().flat_map(|x| x.to_le_bytes()).collect();
    let vtp = format!(
        "<?xml version=\"1.0\"?>\n<VTKFile type=\"PolyData\" version=\"1.0\" byte_order=\"LittleEndian\" \
         header_type=\"UInt64\" compressor=\"vtkZLibDataCompressor\">\n<PolyData>\n<Piece NumberOfPoints=\"1\">\n\
         <Points>\n<DataArray type=\"Float64\" NumberOfComponents=\"3\" format=\"binary\">\n{}{}\n</DataArray>\n\
         </Points>\n</Piece>\n</PolyData>\n</VTKFile>\n",
        BASE64.encode(&header),
        BASE64.encode(&compressed)
    );
    let m = message(read_vertices(put(dir.path(), "huge.vtp", vtp)));
    assert!(
        m.contains("huge.vtp") && m.contains(&format!("zlib block 0 inflates to 24 bytes, not {}", u64::MAX)),
        "{m}"
    );
}

/// Array layouts of VTK XML files that other tools write.
#[derive(Clone, Copy, Debug)]
struct Layout {
    header64: bool,
    big_endian: bool,
    zlib: bool,
    /// `None`: inline base64; `Some(true)`: appended raw; `Some(false)`: appended base64.
    appended: Option<bool>,
}

/// A `.vtu` of `mesh` and `fields` in `layout`, written independently of the library (Int32
/// cells, zlib blocks of 100 bytes, header and data as separate base64 streams, as VTK does).
fn vtu_in_layout(mesh: &Mesh, fields: &[Field], layout: Layout) -> Vec<u8> {
    let uint = |x: usize| -> Vec<u8> {
        match (layout.header64, layout.big_endian) {
            (true, false) => (x as u64).to_le_bytes().to_vec(),
            (true, true) => (x as u64).to_be_bytes().to_vec(),
            (false, false) => (x as u32).to_le_bytes().to_vec(),
            (false, true) => (x as u32).to_be_bytes().to_vec(),
        }
    };
    let f64s = |v: &[f64]| -> Vec<u8> {
        v.iter().flat_map(|x| if layout.big_endian { x.to_be_bytes() } else { x.to_le_bytes() }).collect()
    };
    let i32s = |v: &[usize]| -> Vec<u8> {
        let e = |x: usize| if layout.big_endian { (x as i32).to_be_bytes() } else { (x as i32).to_le_bytes() };
        v.iter().flat_map(|&x| e(x)).collect()
    };
    let block = |payload: Vec<u8>| -> (Vec<u8>, Vec<u8>) {
        if !layout.zlib {
            return (uint(payload.len()), payload);
        }
        let chunks: Vec<&[u8]> = payload.chunks(100).collect();
        let compressed: Vec<Vec<u8>> = chunks
            .iter()
            .map(|c| {
                let mut e = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::default());
                e.write_all(c).unwrap();
                e.finish().unwrap()
            })
            .collect();
        let mut header = uint(chunks.len());
        header.extend(uint(100));
        header.extend(uint(payload.len() % 100));
        compressed.iter().for_each(|c| header.extend(uint(c.len())));
        (header, compressed.concat())
    };
    let (ty, k) = match &mesh.cells {
        Cells::Tet4(_) => (10u8, 4),
        Cells::Hex8(_) => (12u8, 8),
        Cells::Tet10(_) => (24u8, 10),
    };
    let conn: Vec<usize> = (0..mesh.cells.len()).flat_map(|i| mesh.cells.cell(i).to_vec()).collect();
    let offsets: Vec<usize> = (1..=mesh.cells.len()).map(|c| c * k).collect();
    let mut arrays: Vec<(String, String)> = Vec::new(); // (element, parent)
    let mut appended = Vec::new();
    let mut add = |attrs: String, payload: Vec<u8>, parent: &str| {
        let (header, data) = block(payload);
        let element = match layout.appended {
            None => format!(
                "<DataArray {attrs} format=\"binary\">\n  {}{}\n</DataArray>",
                BASE64.encode(&header),
                BASE64.encode(&data)
            ),
            Some(raw) => {
                let element = format!("<DataArray {attrs} format=\"appended\" offset=\"{}\"/>", appended.len());
                if raw {
                    appended.extend(header);
                    appended.extend(data);
                } else {
                    appended.extend(BASE64.encode(&header).into_bytes());
                    appended.extend(BASE64.encode(&data).into_bytes());
                }
                element
            }
        };
        arrays.push((element, parent.to_string()));
    };
    for f in fields {
        let parent = if f.location == FieldLocation::Point { "PointData" } else { "CellData" };
        let attrs = format!("type=\"Float64\" Name=\"{}\" NumberOfComponents=\"{}\"", f.name, f.components);
        add(attrs, f64s(&f.values), parent);
    }
    let points: Vec<f64> = mesh.nodes.iter().flatten().copied().collect();
    add("type=\"Float64\" NumberOfComponents=\"3\"".into(), f64s(&points), "Points");
    add("type=\"Int32\" Name=\"connectivity\"".into(), i32s(&conn), "Cells");
    add("type=\"Int32\" Name=\"offsets\"".into(), i32s(&offsets), "Cells");
    add("type=\"UInt8\" Name=\"types\"".into(), vec![ty; mesh.cells.len()], "Cells");
    let mut out = format!(
        "<?xml version=\"1.0\"?>\n<!-- written by a test -->\n<VTKFile type=\"UnstructuredGrid\" version=\"1.0\" \
         byte_order=\"{}\" header_type=\"{}\"{}>\n<UnstructuredGrid>\n<Piece NumberOfPoints=\"{}\" NumberOfCells=\"{}\">\n",
        if layout.big_endian { "BigEndian" } else { "LittleEndian" },
        if layout.header64 { "UInt64" } else { "UInt32" },
        if layout.zlib { " compressor=\"vtkZLibDataCompressor\"" } else { "" },
        mesh.num_nodes(),
        mesh.cells.len()
    );
    for parent in ["PointData", "CellData", "Points", "Cells"] {
        out += &format!("<{parent}>\n");
        for (element, _) in arrays.iter().filter(|(_, p)| p == parent) {
            out += &format!("{element}\n");
        }
        out += &format!("</{parent}>\n");
    }
    out += "</Piece>\n</UnstructuredGrid>\n";
    let mut bytes = out.into_bytes();
    if let Some(raw) = layout.appended {
        bytes.extend(format!("<AppendedData encoding=\"{}\">\n   _", if raw { "raw" } else { "base64" }).into_bytes());
        bytes.extend(appended);
        bytes.extend(b"\n</AppendedData>\n");
    }
    bytes.extend(b"</VTKFile>\n");
    bytes
}

#[test]
fn vtu_layouts_of_other_writers_are_read() {
    let dir = tempfile::tempdir().unwrap();
    for mesh in [tet_box(), hex_box()] {
        let fields = fields_for(&mesh);
        for header64 in [false, true] {
            for big_endian in [false, true] {
                for zlib in [false, true] {
                    for appended in [None, Some(true), Some(false)] {
                        let layout = Layout { header64, big_endian, zlib, appended };
                        let path = put(dir.path(), "layout.vtu", vtu_in_layout(&mesh, &fields, layout));
                        let (read, read_fields) =
                            read_vtu_with_fields(&path).unwrap_or_else(|e| panic!("{layout:?}: {e}"));
                        assert_eq!(read, mesh, "{layout:?}");
                        assert_eq!(read_fields, fields, "{layout:?}");
                    }
                }
            }
        }
    }
}

#[test]
fn random_corruptions_never_panic() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let mesh = tet_box();
    let fields = fields_for(&mesh);
    let mut sources: Vec<(String, Vec<u8>)> =
        ["liver.msh", "msh4_cube.msh", "cube_low_res.msh", "liver.obj", "liver.vtk"]
            .iter()
            .map(|f| (f.to_string(), fs::read(data(f)).unwrap()))
            .collect();
    let layout = Layout { header64: false, big_endian: false, zlib: true, appended: None };
    sources.push(("zlib.vtu".into(), vtu_in_layout(&mesh, &fields, layout)));
    let layout = Layout { header64: true, big_endian: true, zlib: false, appended: Some(true) };
    sources.push(("raw.vtu".into(), vtu_in_layout(&mesh, &fields, layout)));
    for (name, enc) in [("b.vtu", Encoding::Binary), ("a.vtu", Encoding::Ascii)] {
        write_vtu_with(d.join(name), &mesh, &fields, enc).unwrap();
        sources.push((name.into(), fs::read(d.join(name)).unwrap()));
    }
    for (name, enc) in [("b.vtk", Encoding::Binary), ("a.vtk", Encoding::Ascii)] {
        write_vtk_legacy_with(d.join(name), &mesh, &fields, enc).unwrap();
        sources.push((name.into(), fs::read(d.join(name)).unwrap()));
    }
    let surface = read_surface(data("liver.obj")).unwrap();
    write_stl(d.join("b.stl"), &surface).unwrap();
    sources.push(("b.stl".into(), fs::read(d.join("b.stl")).unwrap()));
    for f in ["tetrahedron_lps_ascii.ply", "tetrahedron_ras.ply", "tetrahedron_lps_ascii.vtp", "tetrahedron_ras.vtp"] {
        sources.push((f.to_string(), fs::read(data(&format!("slicer/{f}"))).unwrap()));
    }
    let ascii_stl = "solid t\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 1 0\nendloop\nendfacet\nendsolid t\n";
    sources.push(("a.stl".into(), ascii_stl.as_bytes().to_vec()));

    let mut state = 7u64;
    let mut next = |n: usize| {
        state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        ((state >> 33) as usize) % n.max(1)
    };
    let alphabet = b"0123456789-.eE \n\t<>/=\"$ABCnaf\\\x00\xff";
    for (name, bytes) in &sources {
        let ext = name.rsplit('.').next().unwrap();
        let path = d.join(format!("fuzz.{ext}"));
        for trial in 0..150 {
            let mut b = bytes.clone();
            match trial % 3 {
                0 => b.truncate(next(b.len())),
                1 => {
                    for _ in 0..1 + next(4) {
                        let i = next(b.len());
                        b[i] = alphabet[next(alphabet.len())];
                    }
                }
                _ => {
                    let i = next(b.len());
                    let j = (i + 1 + next(64)).min(b.len());
                    b.drain(i..j);
                }
            }
            fs::write(&path, &b).unwrap();
            // Either result is fine; a panic fails the test.
            let _ = read_mesh_with_fields(&path);
            let _ = read_surface(&path);
        }
    }
}

/// Every integer of a file's text replaced in turn by counts no file can hold: each read returns
/// (an error, or a mesh where the number was not a count) and never aborts on an allocation sized
/// by the header, as a PLY face's list count and a VTP's `NumberOfPolys` once did.
#[test]
fn counts_beyond_any_file_never_abort() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let mesh = box_tet([0.0; 3], [1.0; 3], [1, 1, 1]).unwrap();
    write_vtu_with(d.join("a.vtu"), &mesh, &fields_for(&mesh), Encoding::Ascii).unwrap();
    write_vtk_legacy_with(d.join("a.vtk"), &mesh, &fields_for(&mesh), Encoding::Ascii).unwrap();
    write_msh(d.join("a.msh"), &mesh).unwrap();
    let msh4 = "$MeshFormat\n4.1 0 8\n$EndMeshFormat\n$PhysicalNames\n1\n3 1 \"liver\"\n$EndPhysicalNames\n\
        $Entities\n0 0 0 1\n1 0 0 0 1 1 1 1 1 0\n$EndEntities\n$Nodes\n1 4 1 4\n3 1 0 4\n1\n2\n3\n4\n\
        0 0 0\n1 0 0\n0 1 0\n0 0 1\n$EndNodes\n$Elements\n1 1 1 1\n3 1 4 1\n1 1 2 3 4\n$EndElements\n";
    assert_eq!(read_mesh(put(d, "a4.msh", msh4)).unwrap().cells.len(), 1);
    let mut raw_nrrd = b"NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 2 2\nspace: left-posterior-superior\n\
        space directions: (1,0,0) (0,1,0) (0,0,1)\nspace origin: (0,0,0)\nencoding: raw\n\n"
        .to_vec();
    raw_nrrd.extend([0, 1, 1, 0, 1, 0, 0, 1]);
    fs::write(d.join("raw.nrrd"), raw_nrrd).unwrap();
    let slicer = |f: &str| data(&format!("slicer/{f}"));
    let sources = [
        slicer("tetrahedron_lps_ascii.ply"),
        slicer("tetrahedron_ras.ply"),
        slicer("tetrahedron_lps_ascii.vtp"),
        slicer("tetrahedron_strips.vtp"),
        slicer("tetrahedron_ras.vtk"),
        slicer("landmarks.fcsv"),
        slicer("targets.mrk.json"),
        d.join("a4.msh"),
        d.join("a.msh"),
        d.join("a.vtu"),
        d.join("a.vtk"),
        d.join("raw.nrrd"),
    ];
    let counts = ["4294967299", "1000000000000", "4611686018427387904", "18446744073709551615", "1e30"];
    for source in &sources {
        let bytes = fs::read(source).unwrap();
        let name = source.file_name().unwrap().to_string_lossy().into_owned();
        let path = d.join(format!("huge_{name}"));
        // The text part: a binary PLY's data follows its header.
        let text_end = bytes.windows(11).position(|w| w == b"end_header\n").map_or(bytes.len(), |i| i + 11);
        let mut start = 0;
        while let Some(first) = bytes[start..text_end].iter().position(u8::is_ascii_digit) {
            let first = start + first;
            let end = bytes[first..].iter().position(|b| !b.is_ascii_digit()).map_or(bytes.len(), |n| first + n);
            // A count is a whole number: the digits of a decimal are left alone.
            let decimal = |b: Option<&u8>| b.is_some_and(|b| b".eE+-".contains(b));
            if decimal(first.checked_sub(1).map(|i| &bytes[i])) || decimal(bytes.get(end)) {
                start = end;
                continue;
            }
            for count in counts {
                fs::write(&path, [&bytes[..first], count.as_bytes(), &bytes[end..]].concat()).unwrap();
                // Either result is fine; a panic or an abort fails the test.
                let _ = match name.rsplit('.').next().unwrap() {
                    "fcsv" | "json" => augsim_mesh::io::points::read_points(&path).map(drop),
                    "nrrd" => augsim_mesh::labelmap::read_labelmap(&path).map(drop),
                    _ => read_mesh_with_fields(&path).map(drop).and(read_surface(&path).map(drop)),
                };
            }
            start = end;
        }
    }
    // The two that aborted, by name.
    let ply = fs::read_to_string(slicer("tetrahedron_lps_ascii.ply")).unwrap();
    let ply = ply.replace("list uchar int", "list uint int").replacen("\n3 0 2 1", "\n4000000000 0 2 1", 1);
    assert!(message(read_surface(put(d, "list.ply", ply))).contains("face"));
    // A binary PLY whose header declares the other byte order: its faces' indices come out
    // impossible, and the message names the likely cause.
    let ply = fs::read(slicer("tetrahedron_ras.ply")).unwrap();
    let swapped = String::from_utf8_lossy(&ply).replacen("binary_little_endian", "binary_big_endian   ", 1);
    let bytes =
        [&swapped.as_bytes()[..swapped.find("end_header").unwrap()], &ply[swapped.find("end_header").unwrap()..]]
            .concat();
    let m = message(read_surface(put(d, "endian.ply", bytes)));
    assert!(m.contains("byte order and element counts"), "{m}");
    let vtp = fs::read_to_string(slicer("tetrahedron_lps_ascii.vtp")).unwrap();
    let vtp = vtp.replacen("NumberOfPolys=\"4\"", "NumberOfPolys=\"1000000000000\"", 1);
    assert!(message(read_surface(put(d, "polys.vtp", vtp))).contains("offsets"));
}

/// A volume mesh given where a surface is read (an organ meshed before) gives its boundary: the
/// closed surface of the volume it fills, from a .vtu and a .vtk alike.
#[test]
fn a_volume_mesh_read_as_a_surface_gives_its_boundary() {
    let dir = tempfile::tempdir().unwrap();
    let mesh = box_tet([0.0, 0.0, 0.0], [0.1, 0.2, 0.3], [2, 3, 4]).unwrap();
    for name in ["organ.vtu", "organ.vtk"] {
        let path = dir.path().join(name);
        write_mesh(&path, &mesh, &[]).unwrap();
        let surface = read_surface(&path).unwrap();
        let closed = augsim_mesh::check_closed_manifold(&surface).unwrap();
        assert!((closed.volume - 0.006).abs() < 1e-12, "{name}: {}", closed.volume);
        // 2 × (2·3 + 3·4 + 2·4) squares of two triangles on the box's faces.
        assert_eq!(surface.triangles.len(), 2 * 2 * (6 + 12 + 8), "{name}");
    }
}

/// Two hexahedra side by side along x (nodes numbered 101…112, some in an included file), a skin
/// of S4 shells on x = 0, sets of every form, and an include.
const HEX_DECK: &str = "\
** two bricks
*HEADING
A deck as Abaqus or cgx writes it, 2 C3D8R
*Node, nset=Nall
101, 0.
102, 1., 0., 0.
103, 2., 0., 0.
104, 0., 1., 0.
105, 1., 1., 0.
106, 2., 1., 0.
*INCLUDE, INPUT=top.inp
*Element, type=C3D8R, elset=Eall
1, 101, 102, 105, 104, 107, 108, 111, 110
2, 102, 103, 106, 105, 108, 109, 112, 111
*ELEMENT, TYPE=S4, ELSET=Skin
10, 101, 104, 110,
107
*ELSET, ELSET=Right
2
*NSET, NSET=fix, GENERATE
101, 107, 3
*NSET, NSET=Both
FIX, 112
*NSET, NSET=RightNodes, ELSET=RIGHT
*MATERIAL, NAME=TISSUE
*ELASTIC
3000., 0.45
*STEP
*STATIC
*BOUNDARY
Fix, 1, 3
*END STEP
";

#[test]
fn abaqus_and_calculix_decks_give_the_mesh_its_numbers_and_sets() {
    let dir = tempfile::tempdir().unwrap();
    put(
        dir.path(),
        "top.inp",
        "*NODE, NSET=NALL\n107, 0, 0, 1\n108, 1, 0, 1\n109, 2., 0, 1\n110, 0, 1, 1\n111, 1, 1, 1\n112, 2, 1, 1\n",
    );
    let mesh = read_mesh(put(dir.path(), "bricks.inp", HEX_DECK)).unwrap();
    let Cells::Hex8(hexes) = &mesh.cells else { panic!("{:?}", mesh.cells.kind()) };
    assert_eq!(hexes, &[[0, 1, 4, 3, 6, 7, 10, 9], [1, 2, 5, 4, 7, 8, 11, 10]]);
    // Missing coordinates are 0 (node 101 gives only x).
    assert_eq!(mesh.nodes[0], [0.0; 3]);
    assert_oriented(&mesh);
    assert_eq!(mesh.file_nodes, Some((101..=112).collect()));
    assert_eq!(mesh.file_cells, Some(vec![1, 2]));
    let region = |name: &str| mesh.regions.get(name).cloned().unwrap_or_default();
    assert_eq!(region("fix"), [0, 3, 6]);
    assert_eq!(region("Both"), [0, 3, 6, 11]);
    assert_eq!(region("Skin"), [0, 3, 6, 9]);
    assert_eq!(region("Right"), [1, 2, 4, 5, 7, 8, 10, 11]);
    assert_eq!(region("RightNodes"), region("Right"));
    // Every node is in Nall; Eall holds every solid, so it is the mesh, not a region.
    assert_eq!(region("Nall").len(), 12);
    assert!(!mesh.regions.contains_key("Eall"));
    // `list` takes the deck's numbers.
    assert_eq!(NodeSelection::List(vec![112, 101]).select(&mesh).unwrap(), [0, 11]);
    assert!(message(NodeSelection::List(vec![0]).select(&mesh)).contains("101 to 112"));
}

#[test]
fn quadratic_tetrahedra_read_from_a_deck_as_from_vtk() {
    // C3D10 numbers its mid-edge nodes as VTK does; continuation lines are read.
    let dir = tempfile::tempdir().unwrap();
    let mesh = tet_box().quadratic().unwrap();
    let mut deck = String::from("*NODE\n");
    for (i, p) in mesh.nodes.iter().enumerate() {
        deck += &format!("{}, {:e}, {:e}, {:e}\n", i + 1, p[0], p[1], p[2]);
    }
    deck += "*ELEMENT, TYPE=C3D10M\n";
    let Cells::Tet10(tets) = &mesh.cells else { unreachable!() };
    for (c, t) in tets.iter().enumerate() {
        let n: Vec<String> = t.iter().map(|i| (i + 1).to_string()).collect();
        deck += &format!("{}, {},\n{}\n", c + 1, n[..6].join(", "), n[6..].join(", "));
    }
    let read = read_mesh(put(dir.path(), "t10.inp", deck)).unwrap();
    assert_eq!(read, tagged_from_1(mesh));
}

#[test]
fn broken_decks_are_refused_with_their_line() {
    let dir = tempfile::tempdir().unwrap();
    let nodes = "*NODE\n1,0,0,0\n2,1,0,0\n3,0,1,0\n4,0,0,1\n5,1,1,1\n";
    let tet = "*ELEMENT, TYPE=C3D4\n1, 1, 2, 3, 4\n";
    // Each deck, and what its error must say.
    let cases: [(&str, String, &[&str]); 14] = [
        ("c20", format!("{nodes}*ELEMENT, TYPE=C3D20R\n1, 1, 2, 3, 4\n"), &["line 7", "C3D20R", "C3D10"]),
        (
            "mixed",
            format!("{nodes}{tet}*ELEMENT, TYPE=C3D8\n2, 1, 2, 3, 4, 5, 5, 5, 5\n"),
            &["mixes tetrahedra (first at", "line 10"],
        ),
        (
            "ghost",
            format!("{nodes}*ELEMENT, TYPE=C3D4\n1, 1, 2, 3, 9\n"),
            &["element 1 names node 9, which no *NODE defines", "line 8"],
        ),
        (
            "short",
            format!("{nodes}*ELEMENT, TYPE=C3D4\n1, 1, 2, 3,\n"),
            &["element 1 lists too few nodes", "the file ends"],
        ),
        ("twice", format!("{nodes}3, 1, 1, 1\n{tet}"), &["line 7", "node 3 is defined twice"]),
        ("noset", format!("{nodes}{tet}*NSET, NSET=A\nB\n"), &["line 10", "set A names B, which is not a node set"]),
        ("badset", format!("{nodes}{tet}*NSET, NSET=A\n1, 77\n"), &["line 10", "node set A names node 77"]),
        ("include", format!("{nodes}*INCLUDE, INPUT=elements.inp\n"), &["line 7", "*INCLUDE", "elements.inp"]),
        ("self", "*INCLUDE, INPUT=self.inp\n".into(), &["nested more than"]),
        ("parts", "*PART, NAME=A\n*END PART\n*PART, NAME=B\n".into(), &["line 3", "second *PART"]),
        (
            "moved",
            format!("*PART, NAME=A\n{nodes}*END PART\n*ASSEMBLY\n*INSTANCE, NAME=A-1, PART=A\n10., 0., 0.\n"),
            &["line 11", "translation or rotation"],
        ),
        ("shells", format!("{nodes}*ELEMENT, TYPE=S3\n1, 1, 2, 3\n"), &["no solid elements"]),
        ("cyl", "*NODE, SYSTEM=C\n1, 1, 0, 0\n".into(), &["rectangular"]),
        ("nan", "*NODE\n1, 0, x, 0\n".into(), &["line 2", "expected a coordinate, found 'x'"]),
    ];
    for (name, text, said) in cases {
        let m = message(read_mesh(put(dir.path(), &format!("{name}.inp"), text)));
        assert!(said.iter().all(|s| m.contains(s)), "{name}: {m}");
    }
}

/// A node moved through its neighbours inverts the cells around it; turned round, they would
/// overlap those neighbours. Such a mesh is refused, naming an inverted cell by the file's number
/// (cells given inside out all together, or every other one, are turned: see above). A tangled
/// hexahedral mesh fails on its corner Jacobians.
#[test]
fn a_tangled_mesh_is_refused() {
    for mesh in [tet_box(), tet_box().quadratic().unwrap()] {
        let mut tangled = mesh.clone();
        let interior = (0..mesh.num_nodes())
            .find(|&i| !augsim_mesh::boundary_nodes(&mesh).contains(&i))
            .expect("the box has interior nodes");
        tangled.nodes[interior][0] += 0.15; // 1.7 cell widths
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("tangled.vtu");
        write_vtu(&path, &tangled, &[]).unwrap();
        let e = message(read_mesh(&path));
        assert!(e.contains("is inverted") && e.contains("folds over") && e.contains("tangled"), "{e}");
        // Unmoved, the same file reads.
        write_vtu(&path, &mesh, &[]).unwrap();
        assert_eq!(read_mesh(&path).unwrap().cells.len(), mesh.cells.len());
    }
}
