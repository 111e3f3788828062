//! Named node regions read from and written to mesh files: `region_<name>` point arrays and label
//! arrays in VTK files, physical groups in Gmsh files.

use std::collections::BTreeMap;
use std::fs;
use std::path::{Path, PathBuf};

use augsim_mesh::io::{
    read_gmsh, read_mesh, read_mesh_with_fields, region_fields, regions_from_fields, write_mesh, write_msh,
    write_vtk_legacy_with, write_vtu, write_vtu_with, Encoding, Field,
};
use augsim_mesh::{boundary_nodes, box_hex, box_tet, Mesh};

fn data(name: &str) -> PathBuf {
    Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data")).join(name)
}

/// Writes `text` to `name` in `dir` and returns the path.
fn put(dir: &Path, name: &str, text: &str) -> PathBuf {
    let path = dir.join(name);
    fs::write(&path, text).unwrap();
    path
}

/// The nodes of `mesh` where `keep` holds, sorted.
fn nodes_where(mesh: &Mesh, keep: impl Fn([f64; 3]) -> bool) -> Vec<usize> {
    (0..mesh.num_nodes()).filter(|&i| keep(mesh.nodes[i])).collect()
}

/// A 3 × 2 × 2 box of tetrahedra (36 nodes) with two overlapping regions: the 12 nodes of the
/// face z = 0 and the 9 of the face x = 0.3.
fn box_with_regions(hex: bool) -> Mesh {
    let (lo, hi, n) = ([0.0, 0.0, 0.0], [0.3, 0.2, 0.1], [3, 2, 2]);
    let mut mesh = if hex { box_hex(lo, hi, n).unwrap() } else { box_tet(lo, hi, n).unwrap() };
    let fixed = nodes_where(&mesh, |p| p[2] == 0.0);
    let push = nodes_where(&mesh, |p| (p[0] - 0.3).abs() < 1e-12);
    assert_eq!((mesh.num_nodes(), fixed.len(), push.len()), (36, 12, 9));
    mesh.regions.insert("fixed".into(), fixed);
    mesh.regions.insert("push".into(), push);
    mesh.validate().unwrap();
    mesh
}

fn names(mesh: &Mesh) -> Vec<&str> {
    mesh.regions.keys().map(String::as_str).collect()
}

#[test]
fn region_fields_are_0_1_point_masks() {
    let mesh = box_with_regions(false);
    let fields = region_fields(&mesh);
    let names: Vec<&str> = fields.iter().map(|f| f.name.as_str()).collect();
    assert_eq!(names, ["region_fixed", "region_push"]);
    for (f, set) in fields.iter().zip(mesh.regions.values()) {
        assert_eq!((f.components, f.values.len()), (1, 36));
        assert_eq!(f.values.iter().filter(|&&v| v == 1.0).count(), set.len());
        assert!(f.values.iter().all(|&v| v == 0.0 || v == 1.0));
        assert!(set.iter().all(|&i| f.values[i] == 1.0));
    }
    assert_eq!(regions_from_fields(&fields), mesh.regions);
}

#[test]
fn vtu_round_trip_keeps_the_regions() {
    let dir = tempfile::tempdir().unwrap();
    for hex in [false, true] {
        let mesh = box_with_regions(hex);
        for encoding in [Encoding::Binary, Encoding::Ascii] {
            let path = dir.path().join(format!("box_{hex}_{encoding:?}.vtu"));
            write_vtu_with(&path, &mesh, &region_fields(&mesh), encoding).unwrap();
            let read = read_mesh(&path).unwrap();
            assert_eq!(names(&read), ["fixed", "push"]);
            assert_eq!(read.regions["fixed"].len(), 12);
            assert_eq!(read, mesh, "hex {hex}, {encoding:?}");
        }
        // Through write_mesh, the region arrays are returned as fields too.
        let path = dir.path().join("box.vtu");
        write_mesh(&path, &mesh, &region_fields(&mesh)).unwrap();
        let (read, fields) = read_mesh_with_fields(&path).unwrap();
        assert_eq!(read.regions, mesh.regions);
        assert_eq!(fields, region_fields(&mesh));
    }
}

#[test]
fn write_mesh_writes_the_regions_in_every_format() {
    let dir = tempfile::tempdir().unwrap();
    let mesh = box_with_regions(false);
    let disp: Vec<[f64; 3]> = mesh.nodes.iter().map(|p| [p[0], 0.0, -p[2]]).collect();
    let displacement = Field::point_vectors("displacement", &disp);
    for name in ["m.vtu", "m.vtk"] {
        let path = dir.path().join(name);
        // Without the region fields: write_mesh adds them after the given ones.
        write_mesh(&path, &mesh, std::slice::from_ref(&displacement)).unwrap();
        let (read, fields) = read_mesh_with_fields(&path).unwrap();
        assert_eq!(read, mesh, "{name}");
        let names: Vec<&str> = fields.iter().map(|f| f.name.as_str()).collect();
        assert_eq!(names, ["displacement", "region_fixed", "region_push"], "{name}");
        // With them: not twice.
        let mut given = region_fields(&mesh);
        given.insert(0, displacement.clone());
        write_mesh(&path, &mesh, &given).unwrap();
        assert_eq!(read_mesh_with_fields(&path).unwrap(), (mesh.clone(), given), "{name}");
    }
    // A Gmsh file takes the mesh's own region fields (it holds the regions), and no other field.
    let path = dir.path().join("m.msh");
    write_mesh(&path, &mesh, &region_fields(&mesh)).unwrap();
    assert_eq!(read_mesh(&path).unwrap(), tagged_from_1(&mesh));
    let m = write_mesh(&path, &mesh, &[displacement]).unwrap_err().to_string();
    assert!(m.contains("carries no fields"), "{m}");
    let mut other = region_fields(&mesh);
    other[0].values[0] = 0.0;
    assert!(write_mesh(&path, &mesh, &other).is_err(), "a mask that is not the region's is a field");
}

#[test]
fn legacy_vtk_round_trip_keeps_the_regions() {
    let dir = tempfile::tempdir().unwrap();
    let mesh = box_with_regions(false);
    for encoding in [Encoding::Binary, Encoding::Ascii] {
        let path = dir.path().join(format!("box_{encoding:?}.vtk"));
        write_vtk_legacy_with(&path, &mesh, &region_fields(&mesh), encoding).unwrap();
        let read = read_mesh(&path).unwrap();
        assert_eq!(read.regions["push"], nodes_where(&mesh, |p| (p[0] - 0.3).abs() < 1e-12));
        assert_eq!(read, mesh, "{encoding:?}");
    }
}

#[test]
fn vtk_names_that_vtk_cannot_hold_are_written_with_underscores() {
    let dir = tempfile::tempdir().unwrap();
    let mut mesh = box_with_regions(false);
    let lobe = vec![0, 5, 35];
    mesh.regions.insert("left lobe".into(), lobe.clone());
    assert_eq!(region_fields(&mesh)[0].name, "region_fixed");
    assert_eq!(region_fields(&mesh)[1].name, "region_left_lobe");
    let path = dir.path().join("lobe.vtu");
    write_mesh(&path, &mesh, &region_fields(&mesh)).unwrap();
    let read = read_mesh(&path).unwrap();
    assert_eq!(names(&read), ["fixed", "left_lobe", "push"]);
    assert_eq!(read.regions["left_lobe"], lobe);
}

#[test]
fn painted_arrays_become_regions_and_empty_masks_make_none() {
    let dir = tempfile::tempdir().unwrap();
    let mesh = box_tet([0.0; 3], [1.0; 3], [1, 1, 1]).unwrap();
    assert_eq!(mesh.num_nodes(), 8);
    let fields = vec![
        // All zeros: no region.
        Field::point("region_x", 1, vec![0.0; 8]),
        // Interpolated (float) mask: over 0.5 is in.
        Field::point("region_soft", 1, vec![0.2, 0.7, 1.0, 0.5, 0.0, 0.51, 0.49, 0.0]),
        // A 0/255 mask as some tools paint it.
        Field::point("region_bytes", 1, vec![255.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 255.0]),
        // A label per node: each non-zero label is a region.
        Field::point("regions", 1, vec![0.0, 1.0, 2.0, 2.0, 0.0, 7.0, 1.0, 0.0]),
        // Not regions: a vector array, any other name and a cell array.
        Field::point("region_vector", 3, vec![1.0; 24]),
        Field::point("painted", 1, vec![1.0; 8]),
        Field::cell("region_cells", 1, vec![1.0; mesh.cells.len()]),
    ];
    let expected: BTreeMap<String, Vec<usize>> = [
        ("bytes", vec![0, 7]),
        ("label_1", vec![1, 6]),
        ("label_2", vec![2, 3]),
        ("label_7", vec![5]),
        ("soft", vec![1, 2, 5]),
    ]
    .into_iter()
    .map(|(k, v)| (k.to_string(), v))
    .collect();
    assert_eq!(regions_from_fields(&fields), expected);
    for name in ["painted.vtu", "painted.vtk"] {
        let path = dir.path().join(name);
        write_mesh(&path, &mesh, &fields).unwrap();
        let (read, read_fields) = read_mesh_with_fields(&path).unwrap();
        assert_eq!(read.regions, expected, "{name}");
        assert!(!read.regions.contains_key("x"), "an all-zero mask makes no region");
        assert_eq!(read_fields, fields, "{name}: the arrays are still returned as fields");
    }

    // A painted integer label array named `region` in a legacy file, as a painting tool writes it.
    let text = "# vtk DataFile Version 3.0\npainted\nASCII\nDATASET UNSTRUCTURED_GRID\n\
        POINTS 5 float\n0 0 0 1 0 0 0 1 0 0 0 1 1 1 1\n\
        CELLS 2 10\n4 0 1 2 3\n4 1 2 3 4\nCELL_TYPES 2\n10\n10\n\
        POINT_DATA 5\nSCALARS region int 1\nLOOKUP_TABLE default\n3 0 3 -1 0\n\
        SCALARS region_tip unsigned_char 1\nLOOKUP_TABLE default\n0 0 0 0 1\n";
    let read = read_mesh(put(dir.path(), "labels.vtk", text)).unwrap();
    let got: Vec<(&str, &[usize])> = read.regions.iter().map(|(k, v)| (k.as_str(), v.as_slice())).collect();
    assert_eq!(got, [("label_-1", &[3][..]), ("label_3", &[0, 2][..]), ("tip", &[4][..])]);
}

#[test]
fn region_nodes_follow_the_renumbering_of_dropped_nodes() {
    // Node 0 is used by no cell: the reader drops it, and the region keeps the others, renumbered.
    let text = "# vtk DataFile Version 3.0\nloose node\nASCII\nDATASET UNSTRUCTURED_GRID\n\
        POINTS 5 double\n9 9 9 0 0 0 1 0 0 0 1 0 0 0 1\n\
        CELLS 1 5\n4 1 2 3 4\nCELL_TYPES 1\n10\n\
        POINT_DATA 5\nSCALARS region_a double 1\nLOOKUP_TABLE default\n1 0 1 0 1\n";
    let dir = tempfile::tempdir().unwrap();
    let read = read_mesh(put(dir.path(), "loose.vtk", text)).unwrap();
    assert_eq!(read.num_nodes(), 4);
    assert_eq!(read.regions["a"], [1, 3]);
}

#[test]
fn gmsh_round_trip_keeps_the_regions() {
    let dir = tempfile::tempdir().unwrap();
    for hex in [false, true] {
        let mut mesh = box_with_regions(hex);
        mesh.regions.insert("left lobe".into(), vec![3, 4, 5]);
        mesh.regions.insert("empty".into(), Vec::new());
        let path = dir.path().join(format!("box_{hex}.msh"));
        write_msh(&path, &mesh).unwrap();
        let text = fs::read_to_string(&path).unwrap();
        assert!(
            text.starts_with(
                "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$PhysicalNames\n3\n0 1 \"fixed\"\n0 2 \"left lobe\"\n\
                 0 3 \"push\"\n$EndPhysicalNames\n$Nodes\n36\n"
            ),
            "{text}"
        );
        // The cells keep their numbers; then one point element per region node (12 + 3 + 9).
        let cells = mesh.cells.len();
        assert!(text.contains(&format!("$Elements\n{}\n", cells + 24)), "{text}");
        let fixed0 = mesh.regions["fixed"][0];
        assert!(text.contains(&format!("\n{} 15 2 1 1 {}\n", cells + 1, fixed0 + 1)), "{text}");
        let push_last = *mesh.regions["push"].last().unwrap();
        assert!(text.ends_with(&format!("\n{} 15 2 3 3 {}\n$EndElements\n", cells + 24, push_last + 1)), "{text}");

        let read = read_gmsh(&path).unwrap();
        assert_eq!(names(&read), ["fixed", "left lobe", "push"], "an empty region is not written");
        mesh.regions.remove("empty");
        assert_eq!(read, tagged_from_1(&mesh), "hex {hex}");
        // The same regions reach a .vtu through region_fields.
        let vtu = dir.path().join("from_msh.vtu");
        write_vtu(&vtu, &read, &region_fields(&read)).unwrap();
        let again = read_mesh(&vtu).unwrap();
        assert_eq!(again.regions["left_lobe"], [3, 4, 5]);
        assert_eq!(again.regions["fixed"], mesh.regions["fixed"]);
    }
}

#[test]
fn gmsh_without_regions_is_written_as_before() {
    let dir = tempfile::tempdir().unwrap();
    let mesh = box_tet([0.0; 3], [1.0; 3], [1, 1, 1]).unwrap();
    let path = dir.path().join("plain.msh");
    write_msh(&path, &mesh).unwrap();
    let text = fs::read_to_string(&path).unwrap();
    assert!(text.starts_with("$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n8\n"), "{text}");
    assert!(!text.contains("$PhysicalNames") && !text.contains(" 15 2 "), "{text}");
    assert!(text.contains("$Elements\n6\n1 4 2 1 1 "), "{text}");
    let read = read_gmsh(&path).unwrap();
    assert!(read.regions.is_empty(), "the group of all the cells is the mesh, not a region");
    assert_eq!(read, tagged_from_1(&mesh));
}

/// `mesh` as read back from a Gmsh file augsim wrote: nodes and cells tagged from 1.
fn tagged_from_1(mesh: &Mesh) -> Mesh {
    let (nodes, cells) = (mesh.num_nodes(), mesh.cells.len());
    Mesh { file_nodes: Some((1..=nodes).collect()), file_cells: Some((1..=cells).collect()), ..mesh.clone() }
}

#[test]
fn gmsh_region_names_that_cannot_be_written_are_errors() {
    let dir = tempfile::tempdir().unwrap();
    let mut mesh = box_tet([0.0; 3], [1.0; 3], [1, 1, 1]).unwrap();
    mesh.regions.insert("say \"hi\"".into(), vec![0]);
    let path = dir.path().join("bad.msh");
    let m = write_msh(&path, &mesh).unwrap_err().to_string();
    assert!(m.contains("say") && m.contains("double quote"), "{m}");
    assert!(!path.exists());
    mesh.regions.clear();
    mesh.regions.insert("far".into(), vec![8]);
    let m = write_msh(&path, &mesh).unwrap_err().to_string();
    assert!(m.contains("region 'far' refers to node 8"), "{m}");
}

#[test]
fn liver2_physical_group_is_its_surface() {
    // liver2.msh (legacy $ELM) puts 71 lines and 860 triangles in physical region 1 and its 1,493
    // tetrahedra in physical region 2: region 1 is the closed surface (860 = 2 × 432 − 4
    // triangles), region 2 holds every tetrahedron and is the mesh itself.
    let mesh = read_gmsh(data("liver2.msh")).unwrap();
    assert_eq!((mesh.num_nodes(), mesh.cells.len()), (507, 1493));
    assert_eq!(names(&mesh), ["physical_1"]);
    let surface = &mesh.regions["physical_1"];
    assert_eq!(surface.len(), 432);
    assert_eq!(*surface, boundary_nodes(&mesh));
    // The other SOFA meshes put every element in one physical group, or in none.
    for file in ["liver.msh", "cylinder.msh", "cube_low_res.msh", "msh4_cube.msh", "SimpleBeamHexa.msh"] {
        assert!(read_gmsh(data(file)).unwrap().regions.is_empty(), "{file}");
    }
}

/// Five nodes and two tetrahedra: 0-1-2-3 and 1-2-3-4.
const NODES_V2: &str = "$Nodes\n5\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n5 1 1 1\n$EndNodes\n";

#[test]
fn gmsh_2_physical_groups_of_every_dimension_are_regions() {
    let dir = tempfile::tempdir().unwrap();
    let text = format!(
        "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n\
         $PhysicalNames\n4\n2 3 \"left lobe\"\n3 1 \"a\"\n3 2 \"b\"\n2 4 \"vessel\" extra\n$EndPhysicalNames\n\
         {NODES_V2}$Elements\n8\n\
         1 15 2 0 1 5\n\
         2 15 2 8 1 5\n\
         3 1 2 7 1 4 5\n\
         4 2 2 3 1 1 2 3\n\
         5 2 3 4 1 0 1 2 4\n\
         6 4 2 1 1 1 2 3 4\n\
         7 4 2 2 1 2 3 4 5\n\
         8 2 0 2 3 4\n\
         $EndElements\n"
    );
    let mesh = read_gmsh(put(dir.path(), "groups.msh", &text)).unwrap();
    let got: Vec<(&str, &[usize])> = mesh.regions.iter().map(|(k, v)| (k.as_str(), v.as_slice())).collect();
    assert_eq!(
        got,
        [
            ("a", &[0, 1, 2, 3][..]),
            ("b", &[1, 2, 3, 4][..]),
            ("left lobe", &[0, 1, 2][..]),
            ("physical_7", &[3, 4][..]),
            ("physical_8", &[4][..]),
            ("vessel", &[0, 1, 3][..]),
        ]
    );
}

/// A name a volume group shares with a surface group (the whole mesh and its boundary, both
/// called `liver`) is split by dimension, the whole mesh's group kept too: `liver` was the surface
/// alone, silently. Lower-dimensional groups of one name still add up (`fixed`: a face and an edge).
#[test]
fn gmsh_a_name_shared_by_a_volume_and_its_surface_is_split_by_dimension() {
    let dir = tempfile::tempdir().unwrap();
    let text = format!(
        "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n\
         $PhysicalNames\n4\n3 1 \"liver\"\n2 2 \"liver\"\n2 3 \"fixed\"\n1 4 \"fixed\"\n$EndPhysicalNames\n\
         {NODES_V2}$Elements\n5\n\
         1 2 2 2 1 1 2 3\n\
         2 2 2 3 1 2 3 5\n\
         3 1 2 4 1 4 5\n\
         4 4 2 1 1 1 2 3 4\n\
         5 4 2 1 1 2 3 4 5\n\
         $EndElements\n"
    );
    let mesh = read_gmsh(put(dir.path(), "shared.msh", &text)).unwrap();
    let got: Vec<(&str, &[usize])> = mesh.regions.iter().map(|(k, v)| (k.as_str(), v.as_slice())).collect();
    assert_eq!(
        got,
        [("fixed", &[1, 2, 3, 4][..]), ("liver_surface", &[0, 1, 2][..]), ("liver_volume", &[0, 1, 2, 3, 4][..])]
    );
}

#[test]
fn gmsh_4_physical_groups_come_from_the_entities() {
    // A point entity in unnamed group 9, a surface entity in group 5 "bottom", volume 1 in group 6
    // "body" and volume 2 in none.
    let text = "$MeshFormat\n4.1 0 8\n$EndMeshFormat\n\
        $PhysicalNames\n2\n2 5 \"bottom\"\n3 6 \"body\"\n$EndPhysicalNames\n\
        $Entities\n1 0 1 2\n\
        1 1 1 1 1 9\n\
        1 0 0 0 1 1 0 1 5 0\n\
        1 0 0 0 1 1 1 1 6 0\n\
        2 0 0 0 1 1 1 0 0\n\
        $EndEntities\n\
        $Nodes\n1 5 1 5\n3 1 0 5\n1\n2\n3\n4\n5\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n1 1 1\n$EndNodes\n\
        $Elements\n4 4 1 4\n0 1 15 1\n4 5\n2 1 2 1\n3 1 2 3\n3 1 4 1\n1 1 2 3 4\n3 2 4 1\n2 2 3 4 5\n$EndElements\n";
    let dir = tempfile::tempdir().unwrap();
    let mesh = read_gmsh(put(dir.path(), "v4.msh", text)).unwrap();
    assert_eq!((mesh.num_nodes(), mesh.cells.len()), (5, 2));
    let got: Vec<(&str, &[usize])> = mesh.regions.iter().map(|(k, v)| (k.as_str(), v.as_slice())).collect();
    assert_eq!(got, [("body", &[0, 1, 2, 3][..]), ("bottom", &[0, 1, 2][..]), ("physical_9", &[4][..])]);

    // $Entities is read, so a broken one is reported with its line.
    let broken = text.replace("1 1 1 1 1 9\n", "1 1 1 1 x 9\n");
    let m = read_gmsh(put(dir.path(), "broken.msh", &broken)).unwrap_err().to_string();
    assert!(m.contains("line 11") && m.contains("number of physical tags, found 'x'"), "{m}");
}

/// A region asked of a mesh is named among those it has, or the mesh said to have none.
#[test]
fn a_missing_region_names_those_there_are() {
    let mut mesh = box_hex([0.0; 3], [1.0; 3], [1, 1, 1]).unwrap();
    let e = mesh.region("bottom").unwrap_err().to_string();
    assert!(e.ends_with("no region named 'bottom': the mesh has no region"), "{e}");
    mesh.regions.insert("top".into(), vec![4, 5, 6, 7]);
    let e = mesh.region("bottom").unwrap_err().to_string();
    assert!(e.ends_with("no region named 'bottom' (regions: top)"), "{e}");
}
