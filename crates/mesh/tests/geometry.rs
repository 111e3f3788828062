//! Organ geometry: surface checks, BVH queries, tetrahedral meshing, the liver
//! phantom, immersed grids, grid embedding and surface sampling.

use std::collections::HashMap;
use std::f64::consts::PI;

use augsim_mesh::bvh::SurfaceBvh;
use augsim_mesh::dihedral_angles;
use augsim_mesh::embedding::{interpolate_at, Embedding, Grid, MeshLocator};
use augsim_mesh::immersed::{immersed_surface, ImmersedOptions};
use augsim_mesh::phantom::{liver_phantom, PhantomSpec};
use augsim_mesh::sampling::{interpolate_samples, sample_visible, sample_visible_boundary};
use augsim_mesh::surface::check_closed_manifold;
use augsim_mesh::tetmesh::{
    mesh_surface, mesh_surface_to_count, stuff, stuff_to_count, tet_quality, BoundaryFit, ImplicitDomain, SdfDomain,
    TetMeshOptions,
};
use augsim_mesh::{boundary_nodes, box_hex, box_tet, icosphere, Cells, Mesh, Point};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

const LIVER_OBJ: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/liver-smooth.obj");

fn norm(p: Point) -> f64 {
    (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt()
}

fn sphere_domain(r: f64) -> SdfDomain<impl Fn(Point) -> f64 + Sync> {
    SdfDomain::new(move |p: Point| norm(p) - r, [-r; 3], [r; 3])
}

fn random_points(n: usize, half: f64, seed: u64) -> Vec<Point> {
    let mut rng = StdRng::seed_from_u64(seed);
    (0..n).map(|_| std::array::from_fn(|_| half * (2.0 * rng.random::<f64>() - 1.0))).collect()
}

/// A conforming mesh: no face is shared by more than two elements, and its
/// boundary faces form a closed oriented surface (every directed edge is
/// matched by its reverse) that encloses exactly the mesh volume. Returns the
/// number of boundary edges shared by more than two boundary triangles (two
/// sheets of the boundary touching along an edge where the organ is thinner
/// than the elements).
fn assert_conforming(mesh: &Mesh) -> usize {
    let Cells::Tet4(tets) = &mesh.cells else { panic!("T4 expected") };
    let mut faces: HashMap<[usize; 3], usize> = HashMap::new();
    for t in tets {
        for f in [[t[1], t[2], t[3]], [t[0], t[2], t[3]], [t[0], t[1], t[3]], [t[0], t[1], t[2]]] {
            let mut k = f;
            k.sort_unstable();
            *faces.entry(k).or_default() += 1;
        }
    }
    assert!(faces.values().all(|&c| c <= 2), "a face is shared by more than two tetrahedra");
    let boundary = augsim_mesh::boundary_surface(mesh);
    let mut directed: HashMap<(usize, usize), i64> = HashMap::new();
    let mut undirected: HashMap<(usize, usize), usize> = HashMap::new();
    for t in &boundary.triangles {
        for e in 0..3 {
            let (a, b) = (t[e], t[(e + 1) % 3]);
            *directed.entry((a.min(b), a.max(b))).or_default() += if a < b { 1 } else { -1 };
            *undirected.entry((a.min(b), a.max(b))).or_default() += 1;
        }
    }
    assert!(directed.values().all(|&c| c == 0), "the boundary is not a closed oriented surface");
    let v = mesh.volume();
    let enclosed = boundary.enclosed_volume();
    assert!((enclosed - v).abs() <= 1e-12 * v, "boundary encloses {enclosed} but the mesh has {v}");
    undirected.values().filter(|&&c| c > 2).count()
}

fn boundary_node_set(mesh: &Mesh) -> Vec<bool> {
    let mut on = vec![false; mesh.num_nodes()];
    for k in boundary_nodes(mesh) {
        on[k] = true;
    }
    on
}

#[test]
fn regular_tetrahedron_dihedral_angles() {
    let p = [[1.0, 1.0, 1.0], [1.0, -1.0, -1.0], [-1.0, 1.0, -1.0], [-1.0, -1.0, 1.0]];
    let expected = (1.0f64 / 3.0).acos();
    for a in dihedral_angles(p) {
        assert!((a - expected).abs() < 1e-12, "dihedral {a} vs {expected}");
    }
}

#[test]
fn sphere_sdf_meshing_volume_and_quality() {
    let r = 0.05;
    let exact = 4.0 / 3.0 * PI * r * r * r;
    let dom = sphere_domain(r);
    // Boundary nodes on the sphere: the chord error needs R/h ≥ 6.5 for 1%.
    let opts = TetMeshOptions::with_size(r / 6.5).with_fit(BoundaryFit::OnSurface);
    let mesh = stuff(&dom, &opts).unwrap();
    assert_eq!(assert_conforming(&mesh), 0);
    let q = tet_quality(&mesh, Some(exact)).unwrap();
    println!("sphere on surface: {q}");
    assert_eq!(q.inverted, 0);
    assert!(q.relative_volume_error.unwrap().abs() < 0.01, "{q}");
    // Measured 22°..146° over several sizes; the paper guarantees 10.7°..164.8°.
    assert!(q.min_dihedral_deg > 15.0 && q.max_dihedral_deg < 160.0, "{q}");
    for (k, &on) in boundary_node_set(&mesh).iter().enumerate() {
        if on {
            assert!((norm(mesh.nodes[k]) - r).abs() < 1e-9 * r, "boundary node {k} off the sphere");
        } else {
            assert!(norm(mesh.nodes[k]) < r, "interior node {k} outside the sphere");
        }
    }
    // Volume-preserving fit: within 0.5% already at R/h = 2.5 (~650 elements).
    for h in [r / 2.5, r / 4.0, r / 6.5] {
        let mesh = stuff(&dom, &TetMeshOptions::with_size(h)).unwrap();
        let q = tet_quality(&mesh, Some(exact)).unwrap();
        println!("sphere volume preserving h = {h:.4}: {q}");
        assert_eq!(q.inverted, 0);
        assert!(q.relative_volume_error.unwrap().abs() < 0.005, "{q}");
        assert!(q.min_dihedral_deg > 15.0, "{q}");
        // Each boundary node moves outward by a mean chord depth, at most the
        // largest sagitta R − √(R² − e²/4) of the boundary edges.
        let surface = augsim_mesh::boundary_surface(&mesh);
        let longest = surface
            .triangles
            .iter()
            .flat_map(|t| (0..3).map(move |e| (t[e], t[(e + 1) % 3])))
            .map(|(a, b)| norm(augsim_mesh::sub(mesh.nodes[a], mesh.nodes[b])))
            .fold(0.0, f64::max);
        let sagitta = r - (r * r - 0.25 * longest * longest).sqrt();
        for (k, &on) in boundary_node_set(&mesh).iter().enumerate() {
            if on {
                let off = norm(mesh.nodes[k]) - r;
                assert!(off > -1e-12 && off <= sagitta, "boundary node {k} moved {off}, sagitta {sagitta}");
            }
        }
    }
}

#[test]
fn stuffing_rejects_bad_sizes_and_empty_domains() {
    let dom = sphere_domain(0.05);
    for h in [0.0, -1.0, f64::NAN] {
        assert!(stuff(&dom, &TetMeshOptions::with_size(h)).is_err());
    }
    let empty = SdfDomain::new(|_: Point| 1.0, [0.0; 3], [1.0; 3]);
    let err = stuff(&empty, &TetMeshOptions::with_size(0.2)).unwrap_err().to_string();
    assert!(err.contains("no element at size 200.0 mm"), "{err}");
    // A count beyond the bound is refused before any memory is taken (100 million would take
    // about 60 GB).
    for (count, what) in [(5, "too small"), (100_000_000, "too large (at most 20000000")] {
        let err = stuff_to_count(&dom, count, None, BoundaryFit::default()).unwrap_err().to_string();
        assert!(err.contains(what), "{err}");
    }
    // So are boxes of too many cells: 500 million hexahedra, 6 × 27 million tetrahedra.
    let err = box_hex([0.0; 3], [1.0; 3], [2000, 500, 500]).unwrap_err().to_string();
    assert!(err.contains("makes 500000000 cells, more than 20000000"), "{err}");
    let err = box_tet([0.0; 3], [1.0; 3], [300; 3]).unwrap_err().to_string();
    assert!(err.contains("makes 162000000 cells"), "{err}");
}

#[test]
fn icosphere_surface_meshing() {
    let s = icosphere(0.05, 3);
    let enclosed = s.enclosed_volume();
    for fit in [BoundaryFit::OnSurface, BoundaryFit::VolumePreserving] {
        let (mesh, q) = mesh_surface(&s, &TetMeshOptions::with_size(0.0075).with_fit(fit)).unwrap();
        println!("icosphere {fit:?}: {q}");
        assert_eq!(assert_conforming(&mesh), 0);
        assert_eq!(q.inverted, 0);
        assert_eq!(q.reference_volume, Some(enclosed));
        assert!(q.relative_volume_error.unwrap().abs() < 0.01, "{q}");
        assert!(q.min_dihedral_deg > 10.0, "{q}");
        mesh.validate().unwrap();
    }
    // An inside-out surface is oriented before meshing.
    let mut flipped = s.clone();
    flipped.flip();
    let (_, q) = mesh_surface(&flipped, &TetMeshOptions::with_size(0.01)).unwrap();
    assert!(q.relative_volume_error.unwrap().abs() < 0.01, "{q}");
}

#[test]
fn a_rod_too_thin_to_fill_is_refused_at_once() {
    // A rod 10 cm long along the diagonal of its box: the box holds 7,700 times its volume (0.5 mm
    // across) or 43 times (6 mm across).
    let diagonal = |p: Point| -> Point {
        let (a, b, c) = (1.0 / 3f64.sqrt(), 1.0 / 2f64.sqrt(), 1.0 / 6f64.sqrt());
        [a * p[0] + b * p[1] + c * p[2], a * p[0] - b * p[1] + c * p[2], a * p[0] - 2.0 * c * p[2]]
    };
    let rod = |across: f64| {
        let mut s = augsim_mesh::boundary_surface(&box_tet([0.0; 3], [0.1, across, across], [10, 1, 1]).unwrap());
        s.vertices.iter_mut().for_each(|p| *p = diagonal(*p));
        s
    };
    let e = mesh_surface_to_count(&rod(5e-4), 5000, BoundaryFit::VolumePreserving).unwrap_err().to_string();
    assert!(e.contains("too thin or flat to fill with 5000 tetrahedra"), "{e}");
    assert!(mesh_surface_to_count(&rod(6e-3), 2000, BoundaryFit::VolumePreserving).is_ok());
}

#[test]
fn liver_smooth_obj_meshing() {
    let mut s = augsim_mesh::io::read_surface(LIVER_OBJ).unwrap();
    let report = check_closed_manifold(&s).unwrap();
    assert_eq!(report.edges * 2, report.triangles * 3);
    s.fit_to(0.2).unwrap();
    let (lo, hi) = augsim_mesh::bounds(&s.vertices);
    let extent = (0..3).map(|d| hi[d] - lo[d]).fold(0.0, f64::max);
    assert!((extent - 0.2).abs() < 1e-12);
    // About 5,000 elements with the (default) volume-preserving fit.
    let (mesh, q) = mesh_surface_to_count(&s, 5000, BoundaryFit::VolumePreserving).unwrap();
    let pinched = assert_conforming(&mesh);
    println!("liver-smooth.obj, volume preserving: {q}; {pinched} pinched boundary edges");
    assert!((4500..=5500).contains(&q.elements), "{q}");
    assert_eq!(q.inverted, 0);
    assert!(q.relative_volume_error.unwrap().abs() < 0.01, "{q}");
    assert!(q.min_dihedral_deg > 10.0, "{q}");
    mesh.validate().unwrap();
    // Boundary nodes exactly on the surface: 1% needs a finer lattice.
    let (mesh, q) = mesh_surface(&s, &TetMeshOptions::with_size(0.0095).with_fit(BoundaryFit::OnSurface)).unwrap();
    let pinched = assert_conforming(&mesh);
    println!("liver-smooth.obj, on surface: {q}; {pinched} pinched boundary edges");
    assert_eq!(q.inverted, 0);
    assert!(q.relative_volume_error.unwrap().abs() < 0.01, "{q}");
    assert!(q.min_dihedral_deg > 10.0, "{q}");
    let bvh = SurfaceBvh::new(&s).unwrap();
    for (k, &on) in boundary_node_set(&mesh).iter().enumerate() {
        if on {
            let d = bvh.distance(mesh.nodes[k]);
            assert!(d < 1e-9, "boundary node {k} is {d} m off the surface");
        }
    }
}

#[test]
fn inside_test_and_signed_distance_match_analytic_sphere() {
    let r = 0.05;
    let s = icosphere(r, 4);
    let bvh = SurfaceBvh::new(&s).unwrap();
    // Vertices on the sphere, faces inside it: the Hausdorff distance between
    // the icosphere and the sphere is R minus the distance from the centre.
    let tol = r - bvh.distance([0.0; 3]) + 1e-12;
    assert!(tol > 0.0 && tol < 2e-3 * r, "icosphere deviation {tol}");
    let mut checked = 0;
    let mut worst_winding: f64 = 0.0;
    for (i, p) in random_points(3000, 1.6 * r, 11).into_iter().enumerate() {
        let exact = norm(p) - r;
        let sd = bvh.signed_distance(p);
        assert!((sd - exact).abs() <= tol, "point {i} {p:?}: signed distance {sd} vs {exact}");
        if exact.abs() > 2.0 * tol {
            assert_eq!(bvh.is_inside(p), exact < 0.0, "point {i} {p:?} (distance {exact})");
            checked += 1;
        }
        if i % 10 == 0 {
            worst_winding = worst_winding.max((bvh.winding_number(p) - bvh.winding_number_exact(p)).abs());
        }
    }
    assert!(checked > 2900);
    println!("fast winding number: worst error {worst_winding:.2e}");
    assert!(worst_winding < 0.05);
    let cp = bvh.closest_point([0.2, 0.0, 0.0]);
    assert!((norm(cp.point) - r).abs() < tol && (cp.distance - (0.2 - r)).abs() < tol);
}

#[test]
fn closedness_checks_report_what_and_where() {
    let s = icosphere(1.0, 2);
    let rep = check_closed_manifold(&s).unwrap();
    assert_eq!((rep.triangles, rep.edges, rep.used_vertices), (320, 480, 162));
    assert!((rep.volume - 4.0 / 3.0 * PI).abs() < 0.05 * 4.0 / 3.0 * PI);
    assert!((rep.area - s.area()).abs() < 1e-12 && rep.area > 0.9 * 4.0 * PI);

    let mut open = s.clone();
    open.triangles.remove(17);
    let err = check_closed_manifold(&open).unwrap_err().to_string();
    assert!(err.contains("surface is open: 3 boundary edges"), "{err}");

    // A vertex of a damaged file is named, not the sound triangles its size makes look degenerate.
    let mut far = s.clone();
    far.vertices[16][2] = 1e30;
    let err = check_closed_manifold(&far).unwrap_err().to_string();
    assert!(err.contains("vertex 16 lies at") && err.contains("beyond 1e9"), "{err}");
    // A surface in µm in a scanner's coordinates (over a metre from its origin) is no damaged file.
    let mut microns = s.clone();
    microns.transform([0.0, 0.0, -120.0], 1e4);
    check_closed_manifold(&microns).unwrap();

    let mut flipped = s.clone();
    flipped.triangles[42].swap(0, 1);
    let err = check_closed_manifold(&flipped).unwrap_err().to_string();
    assert!(err.contains("triangle 42") && err.contains("flipped"), "{err}");

    let mut extra = s.clone();
    let t = extra.triangles[5];
    extra.triangles.push([t[0], t[1], t[2]]);
    let err = check_closed_manifold(&extra).unwrap_err().to_string();
    assert!(err.contains("belongs to 3 triangles"), "{err}");

    let mut degenerate = s.clone();
    degenerate.triangles[3][2] = degenerate.triangles[3][0];
    let err = check_closed_manifold(&degenerate).unwrap_err().to_string();
    assert!(err.contains("triangle 3") && err.contains("repeats a vertex"), "{err}");

    let mut bad_index = s.clone();
    bad_index.triangles[0][1] = 10_000;
    let err = check_closed_manifold(&bad_index).unwrap_err().to_string();
    assert!(err.contains("triangle 0 refers to vertex 10000"), "{err}");

    // Two spheres touching at one vertex: non-manifold vertex.
    let mut pinched = s.clone();
    let other = icosphere(1.0, 2);
    let n = pinched.vertices.len();
    let top = (0..n).max_by(|&a, &b| s.vertices[a][2].total_cmp(&s.vertices[b][2])).unwrap();
    let bottom = (0..n).min_by(|&a, &b| other.vertices[a][2].total_cmp(&other.vertices[b][2])).unwrap();
    let shift = s.vertices[top][2] - other.vertices[bottom][2];
    pinched.vertices.extend(other.vertices.iter().map(|p| [p[0], p[1], p[2] + shift]));
    pinched.triangles.extend(other.triangles.iter().map(|t| t.map(|k| if k == bottom { top } else { k + n })));
    let err = check_closed_manifold(&pinched).unwrap_err().to_string();
    assert!(err.contains(&format!("vertex {top} is non-manifold")), "{err}");

    // Orientation and fitting.
    let mut inside_out = s.clone();
    inside_out.flip();
    assert!(check_closed_manifold(&inside_out).unwrap().volume < 0.0);
    assert!(inside_out.orient_outward());
    assert!(!inside_out.orient_outward());
    assert!(inside_out.enclosed_volume() > 0.0);
    let mut moved = s.clone();
    moved.transform([-3.0, 1.0, 2.0], 0.5);
    let (lo0, hi0) = augsim_mesh::bounds(&moved.vertices);
    let extent0 = (0..3).map(|d| hi0[d] - lo0[d]).fold(0.0, f64::max);
    let (centre, scale) = moved.fit_to(0.2).unwrap();
    assert!((scale * extent0 - 0.2).abs() < 1e-12);
    assert!((0..3).all(|d| (centre[d] - 0.5 * (lo0[d] + hi0[d])).abs() < 1e-12));
    let (lo, hi) = augsim_mesh::bounds(&moved.vertices);
    assert!((0..3).all(|d| (lo[d] + hi[d]).abs() < 1e-12), "centred: {lo:?} {hi:?} (was {centre:?})");
    assert!(((0..3).map(|d| hi[d] - lo[d]).fold(0.0, f64::max) - 0.2).abs() < 1e-12);
    assert!(moved.fit_to(0.0).is_err());
}

#[test]
fn self_overlap_is_detected() {
    let a = icosphere(1.0, 2);
    let bvh = SurfaceBvh::new(&a).unwrap();
    assert!(bvh.winding_defects().is_empty());
    bvh.check_winding(0.0).unwrap();
    // Two overlapping closed spheres: the overlap is covered twice.
    let mut two = a.clone();
    let n = two.vertices.len();
    two.vertices.extend(a.vertices.iter().map(|p| [p[0] + 1.0, p[1], p[2]]));
    two.triangles.extend(a.triangles.iter().map(|t| t.map(|k| k + n)));
    check_closed_manifold(&two).unwrap();
    let bvh = SurfaceBvh::new(&two).unwrap();
    let defects = bvh.winding_defects();
    assert!(!defects.is_empty());
    assert!(defects.iter().all(|&(_, w_in, w_out)| (w_in - 2.0).abs() < 0.1 || (w_out - 1.0).abs() < 0.1));
    let err = bvh.check_winding(0.0).unwrap_err().to_string();
    assert!(err.contains("overlaps itself"), "{err}");
    let err = mesh_surface(&two, &TetMeshOptions::with_size(0.2)).unwrap_err().to_string();
    assert!(err.contains("overlaps itself"), "{err}");
}

/// A linear field u(x) = A x + b, three channels.
fn linear(p: Point) -> [f64; 3] {
    [
        0.3 + 2.0 * p[0] - 1.0 * p[1] + 0.5 * p[2],
        -0.1 + 0.7 * p[0] + 3.0 * p[1] - 2.0 * p[2],
        1.2 - 1.5 * p[0] + 0.25 * p[1] + 4.0 * p[2],
    ]
}

fn check_linear_round_trip(mesh: &Mesh, dims: [usize; 3], seed: u64) {
    let (lo, hi) = mesh.bounds();
    let grid = Grid::covering(lo, hi, dims).unwrap();
    let emb = Embedding::new(mesh, grid.clone()).unwrap();
    assert!(emb.num_inside() > grid.num_nodes() / 5, "{} of {} inside", emb.num_inside(), grid.num_nodes());
    let field: Vec<f64> = mesh.nodes.iter().flat_map(|&p| linear(p)).collect();
    let scale = field.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let tensor = emb.map_nodal(&field, 3).unwrap();
    let n = grid.num_nodes();
    let mask = emb.mask();
    let [nx, ny, nz] = dims;
    for i in 0..nx {
        for j in 0..ny {
            for k in 0..nz {
                let g = grid.node_index(i, j, k);
                let u = linear(grid.node(i, j, k));
                for c in 0..3 {
                    let v = tensor[grid.tensor_index(c, i, j, k)];
                    assert_eq!(grid.tensor_index(c, i, j, k), c * n + g);
                    if mask[g] {
                        assert!((v - u[c]).abs() <= 1e-12 * scale, "grid node {g} channel {c}: {v} vs {}", u[c]);
                    } else {
                        assert_eq!(v, 0.0);
                    }
                }
            }
        }
    }
    // Grid -> points: exact in cells whose eight nodes are all inside.
    let mut rng = StdRng::seed_from_u64(seed);
    let mut points = Vec::new();
    while points.len() < 200 {
        let p: Point = std::array::from_fn(|d| lo[d] + rng.random::<f64>() * (hi[d] - lo[d]));
        let base: [usize; 3] =
            std::array::from_fn(|d| (((p[d] - grid.origin[d]) / grid.spacing[d]).floor() as usize).min(dims[d] - 2));
        let all_in = (0..8usize)
            .all(|c| mask[grid.node_index(base[0] + (c & 1), base[1] + (c >> 1 & 1), base[2] + (c >> 2 & 1))]);
        if all_in {
            points.push(p);
        }
    }
    let values = grid.interpolate(&tensor, 3, &points).unwrap();
    for (p, v) in points.iter().zip(values.chunks(3)) {
        let u = linear(*p);
        for c in 0..3 {
            assert!((v[c] - u[c]).abs() <= 1e-12 * scale, "point {p:?}: {} vs {}", v[c], u[c]);
        }
    }
    // Mesh -> located points: exact wherever the point is inside the mesh.
    let locator = MeshLocator::new(mesh).unwrap();
    let locs: Vec<_> = locator.locate_all(&points).into_iter().flatten().collect();
    assert_eq!(locs.len(), points.len(), "points in fully inside grid cells must be in the mesh");
    let at = interpolate_at(&locs, &field, 3).unwrap();
    for (p, v) in points.iter().zip(at.chunks(3)) {
        let u = linear(*p);
        for c in 0..3 {
            assert!((v[c] - u[c]).abs() <= 1e-12 * scale);
        }
    }
    // Outside the grid box: an error; far outside the mesh: no location.
    let outside = [hi[0] + 1.0, hi[1], hi[2]];
    let err = grid.interpolate(&tensor, 3, &[outside]).unwrap_err().to_string();
    assert!(err.contains("point 0") && err.contains("outside the grid"), "{err}");
    assert!(locator.locate(outside).is_none());
    assert!(emb.map_nodal(&field[..field.len() - 3], 3).is_err());
}

#[test]
fn linear_field_mesh_grid_points_round_trip_t4() {
    let mesh = liver_phantom(2000).unwrap();
    check_linear_round_trip(&mesh, [21, 23, 21], 5);
}

#[test]
fn linear_field_mesh_grid_points_round_trip_h8() {
    // A curved (non-affine) hexahedral mesh exercises the Newton inversion.
    let mut mesh = box_hex([0.0; 3], [0.1, 0.08, 0.06], [6, 5, 4]).unwrap();
    for p in &mut mesh.nodes {
        let (x, y, z) = (p[0], p[1], p[2]);
        *p = [x + 0.004 * (40.0 * y).sin(), y + 0.003 * (50.0 * z).sin() + 0.002 * (30.0 * x).cos(), z + 0.1 * x * y];
    }
    mesh.validate().unwrap();
    check_linear_round_trip(&mesh, [13, 11, 9], 6);
    // The immersed grid of the phantom.
    let grid = PhantomSpec::default().immersed(0.012).unwrap();
    check_linear_round_trip(&grid.mesh, [21, 23, 21], 7);
}

#[test]
fn phantom_regions_and_volume() {
    let spec = PhantomSpec::default();
    let mesh = liver_phantom(5000).unwrap();
    let q = tet_quality(&mesh, Some(spec.volume())).unwrap();
    println!("phantom: {q}");
    assert_eq!(assert_conforming(&mesh), 0);
    assert!((4700..=5300).contains(&q.elements), "{q}");
    assert_eq!(q.inverted, 0);
    assert!(q.relative_volume_error.unwrap().abs() < 0.01, "{q}");
    assert!(q.min_dihedral_deg > 10.0);
    let (lo, hi) = mesh.bounds();
    assert!((hi[0] - lo[0] - 0.2).abs() < 0.01, "length {}", hi[0] - lo[0]);
    for name in ["fixed", "hidden", "visible", "push", "markers", "tumour"] {
        assert!(!mesh.region(name).unwrap().is_empty(), "{name}");
    }
    let counts: Vec<String> = mesh.regions.iter().map(|(k, v)| format!("{k} {}", v.len())).collect();
    println!("phantom regions at {} elements: {}", q.elements, counts.join(", "));
    let fixed = mesh.region("fixed").unwrap().len();
    assert!((50..=90).contains(&fixed), "fixed nodes: {fixed}");
    let on_boundary = boundary_node_set(&mesh);
    let markers = mesh.region("markers").unwrap();
    assert_eq!(markers.len(), 10);
    for &m in markers {
        assert!(!on_boundary[m] && spec.signed_distance(mesh.nodes[m]) < -0.005, "marker {m}");
    }
    for name in ["visible", "hidden", "push"] {
        assert!(mesh.region(name).unwrap().iter().all(|&k| on_boundary[k]), "{name} must be on the surface");
    }
    let visible = mesh.region("visible").unwrap();
    let hidden = mesh.region("hidden").unwrap();
    assert!(hidden.iter().all(|k| visible.binary_search(k).is_err()));
    assert!(mesh.region("push").unwrap().iter().all(|k| visible.binary_search(k).is_ok()));
    for &k in mesh.region("tumour").unwrap() {
        assert!(norm(augsim_mesh::sub(mesh.nodes[k], spec.tumour_centre)) <= spec.tumour_radius);
    }
    // Deterministic.
    assert_eq!(liver_phantom(5000).unwrap(), mesh);
    // The coarse liver of the spring scenario: ~300 nodes, ~35 hidden nodes.
    let coarse = liver_phantom(1100).unwrap();
    let hidden = coarse.region("hidden").unwrap().len();
    println!("coarse phantom: {} nodes, {} hidden", coarse.num_nodes(), hidden);
    assert!((250..=350).contains(&coarse.num_nodes()) && (25..=45).contains(&hidden));
}

/// On the immersed grid the surface cuts through cells: its surface nodes are its cut cells'
/// nodes, and most visible nodes lie inside the grid, where its boundary faces give no normal.
/// The grid carries the phantom's own normal at every node, facing the camera on the visible
/// region (a tool push along it loads the organ, and the normal motion there is an input).
#[test]
fn immersed_grid_nodes_have_the_phantoms_normals() {
    let spec = PhantomSpec::default();
    let grid = spec.immersed(0.01).unwrap();
    grid.mesh.validate().unwrap();
    let mut wrong = grid.mesh.clone();
    wrong.node_normals.as_mut().unwrap().pop();
    assert!(wrong.validate().unwrap_err().to_string().contains("node_normals"));
    let surface = grid.mesh.surface_nodes();
    let outer = augsim_mesh::boundary_nodes(&grid.mesh);
    assert!(surface.windows(2).all(|w| w[0] < w[1]));
    assert!(grid.mesh.region("visible").unwrap().iter().all(|k| surface.binary_search(k).is_ok()));
    let inside = surface.iter().filter(|k| outer.binary_search(k).is_err()).count();
    assert!(inside > surface.len() / 4, "{inside} of {} surface nodes inside the grid", surface.len());
    let normals = grid.mesh.surface_normals();
    let faces = augsim_mesh::boundary_surface(&grid.mesh).vertex_normals();
    let visible = grid.mesh.region("visible").unwrap();
    let without_face_normal = visible.iter().filter(|&&k| faces[k] == [0.0; 3]).count();
    println!("{} visible nodes, {without_face_normal} on no boundary face", visible.len());
    assert!(without_face_normal > visible.len() / 4, "{without_face_normal} of {}", visible.len());
    for &k in visible {
        assert!((norm(normals[k]) - 1.0).abs() < 1e-9, "node {k}: {:?}", normals[k]);
        assert!(augsim_mesh::dot(normals[k], spec.view_direction) < 0.0, "node {k} faces away");
    }
}

#[test]
fn immersed_grid_fractions_and_volume() {
    let spec = PhantomSpec::default();
    let volume = spec.volume();
    let grid = spec.immersed(0.01).unwrap();
    let f = grid.mesh.cell_fraction.as_ref().unwrap();
    assert!(f.iter().all(|&x| x > 0.0 && x <= 1.0));
    assert!(f.iter().any(|&x| x < 1.0) && f.contains(&1.0));
    let err = grid.mesh.body_volume() / volume - 1.0;
    println!("immersed phantom: {} cells, {} nodes, volume error {:+.3}%", f.len(), grid.mesh.num_nodes(), 100.0 * err);
    assert!(err.abs() < 0.03);
    // Without the nearly empty cells: fewer cells, each above the threshold, the regions kept,
    // at most a tenth of a cell's volume lost per cell left out.
    let options = ImmersedOptions { min_fraction: 0.1, ..ImmersedOptions::with_spacing(0.01) };
    let trimmed = spec.immersed_with(&options).unwrap();
    let kept = trimmed.mesh.cell_fraction.as_ref().unwrap();
    let dropped = f.len() - kept.len();
    assert!(dropped > 0 && kept.iter().all(|&x| x > 0.1), "{dropped} cells left out");
    let lost = grid.mesh.body_volume() - trimmed.mesh.body_volume();
    assert!(lost > 0.0 && lost <= 0.1 * dropped as f64 * 1e-6 + 1e-12, "{lost} m³ lost with {dropped} cells");
    for name in ["fixed", "visible", "push", "markers"] {
        assert!(!trimmed.mesh.region(name).unwrap().is_empty(), "{name}");
    }
    // Material shares: 1 at nodes whose cells are all full, the mean of the cell fractions elsewhere.
    let share = grid.mesh.node_material_share();
    let mut around = vec![Vec::new(); grid.mesh.num_nodes()];
    for (c, &x) in f.iter().enumerate() {
        grid.mesh.cells.cell(c).iter().for_each(|&k| around[k].push(x));
    }
    for (k, xs) in around.iter().enumerate() {
        let mean = xs.iter().sum::<f64>() / xs.len() as f64;
        assert!((share[k] - mean).abs() < 1e-12 && share[k] > 0.0 && share[k] <= 1.0);
    }
    assert!(share.contains(&1.0) && share.iter().any(|&s| s < 0.1));
    for (c, &x) in f.iter().enumerate() {
        let ijk = grid.cell_index[c];
        let centre: Point = std::array::from_fn(|d| grid.origin[d] + (ijk[d] as f64 + 0.5) * grid.spacing);
        if x == 1.0 {
            assert!(spec.contains(centre), "full cell {c} has its centre outside");
        }
        let first = grid.mesh.nodes[grid.mesh.cells.cell(c)[0]];
        assert!((0..3).all(|d| (first[d] - (centre[d] - 0.5 * grid.spacing)).abs() < 1e-12));
    }
    for name in ["fixed", "hidden", "visible", "push", "markers", "tumour"] {
        assert!(!grid.mesh.region(name).unwrap().is_empty(), "{name}");
    }
    assert_eq!(grid.mesh.region("markers").unwrap().len(), 10);
    // Regions copied from the T4 phantom lie near their source nodes.
    let t4 = liver_phantom(3000).unwrap();
    assert!(t4.node_material_share().iter().all(|&s| s == 1.0), "a body-fitted mesh has full shares");
    let mut copy = grid.clone();
    copy.mesh.regions.clear();
    assert!(copy.transfer_regions(&t4).is_empty());
    let src = t4.region("fixed").unwrap();
    for &k in copy.mesh.region("fixed").unwrap() {
        let p = copy.mesh.nodes[k];
        let near = src.iter().any(|&s| norm(augsim_mesh::sub(t4.nodes[s], p)) <= 3f64.sqrt() * grid.spacing + 1e-12);
        assert!(near, "grid node {k} is far from the fixed region");
    }
    // From a closed surface.
    let s = icosphere(0.05, 3);
    let g = immersed_surface(&s, &ImmersedOptions::with_spacing(0.008)).unwrap();
    let err = g.mesh.body_volume() / s.enclosed_volume() - 1.0;
    println!("immersed icosphere: {} cells, volume error {:+.3}%", g.mesh.cells.len(), 100.0 * err);
    assert!(err.abs() < 0.03);
    assert!(matches!(g.mesh.cells, Cells::Hex8(_)));
}

#[test]
fn visible_surface_sampling() {
    let view = [0.0, 0.0, -1.0];
    // Uniform by area on the upper hemisphere: mean height R/2.
    let r = 1.0;
    let s = icosphere(r, 4);
    let samples = sample_visible(&s, view, 20000, 3).unwrap();
    let mean_z = samples.iter().map(|x| x.point[2]).sum::<f64>() / samples.len() as f64;
    assert!((mean_z - 0.5 * r).abs() < 0.02 * r, "mean height {mean_z}");
    assert!(samples.iter().all(|x| x.point[2] > -0.1 * r));
    // On the phantom's boundary: on visible triangles, reproducible.
    let mesh = liver_phantom(2000).unwrap();
    let a = sample_visible_boundary(&mesh, view, 100, 42).unwrap();
    assert_eq!(a.len(), 100);
    assert_eq!(a, sample_visible_boundary(&mesh, view, 100, 42).unwrap());
    assert_ne!(a, sample_visible_boundary(&mesh, view, 100, 43).unwrap());
    let surface = augsim_mesh::boundary_surface(&mesh);
    for x in &a {
        assert_eq!(surface.triangles[x.triangle], x.nodes);
        let n = augsim_mesh::surface::triangle_area_vector(&surface, x.triangle);
        assert!(augsim_mesh::dot(n, view) < 0.0);
        assert!(x.barycentric.iter().all(|&b| b >= 0.0) && (x.barycentric.iter().sum::<f64>() - 1.0).abs() < 1e-12);
    }
    // Interpolating the coordinates gives back the points.
    let coords: Vec<f64> = mesh.nodes.iter().flat_map(|p| p.iter().copied()).collect();
    let back = interpolate_samples(&a, &coords, 3).unwrap();
    for (x, p) in a.iter().zip(back.chunks(3)) {
        assert!((0..3).all(|d| (x.point[d] - p[d]).abs() < 1e-15));
    }
    assert!(sample_visible(&s, [0.0; 3], 10, 1).is_err());
}

/// A point on the grid box's face, written in single precision, rounds off it by a few millionths
/// of a cell: taken at the face. A thousandth of a cell out is outside.
#[test]
fn a_point_on_the_grid_box_s_face_in_single_precision_is_inside() {
    let g = Grid::new([0.1, -0.2, 0.3], [0.005; 3], [10, 10, 10]).unwrap();
    let face = [0.1 + 9.0 * 0.005, -0.2 + 4.5 * 0.005, 0.3];
    let rounded = face.map(|x| f64::from(x as f32));
    assert!(rounded != face, "single precision moves the point");
    let nudged = [face[0] + 1e-6 * 0.005, face[1], face[2] - 1e-6 * 0.005];
    for p in [rounded, nudged] {
        let corners = g.corners(0, p).unwrap();
        assert!((corners.iter().map(|(_, w)| w).sum::<f64>() - 1.0).abs() < 1e-12);
    }
    let e = g.corners(3, [face[0] + 1e-3 * 0.005, face[1], face[2]]).unwrap_err().to_string();
    assert!(e.contains("point 3") && e.contains("outside the grid box"), "{e}");
}

#[test]
fn grid_layout_and_errors() {
    assert!(Grid::new([0.0; 3], [1.0; 3], [1, 2, 2]).is_err());
    assert!(Grid::new([0.0; 3], [0.0, 1.0, 1.0], [2, 2, 2]).is_err());
    // More nodes than a workstation holds (a dataset's `grid = [1000000000000, 24, 16]`, and one
    // whose count overflows 64 bits) is an error before anything is allocated.
    for dims in [[1_000_000_000_000, 24, 16], [1 << 62, 24, 16], [272, 272, 271]] {
        let e = Grid::covering([0.0; 3], [1.0; 3], dims).unwrap_err().to_string();
        assert!(e.contains("more than 20000000"), "{e}");
    }
    assert!(Grid::covering([0.0; 3], [1.0; 3], [271, 271, 271]).is_ok());
    let g = Grid::covering([0.0; 3], [1.0, 2.0, 3.0], [2, 3, 4]).unwrap();
    assert_eq!(g.node_index(1, 2, 3), 23);
    assert_eq!(g.tensor_index(1, 0, 0, 1), 25);
    assert_eq!(g.node(1, 2, 3), [1.0, 2.0, 3.0]);
    let nodes = g.nodes();
    assert_eq!(nodes[g.node_index(1, 1, 2)], g.node(1, 1, 2));
}

/// A measured point's fault names the first bad point and, for a non-finite value, the axis and the value
/// alone (its other coordinates may have been scaled into another unit than the file's).
#[test]
fn measured_faults_name_the_point_and_the_axis() {
    let good = [[0.1, 0.2, 0.3]];
    assert_eq!(augsim_mesh::measured_fault(&good), None);
    let nan = [[0.1, 0.2, 0.3], [1.0, f64::NAN, 2.0]];
    assert_eq!(augsim_mesh::measured_fault(&nan), Some((1, "has a non-finite coordinate: y = NaN".to_string())));
    let infinite = [[f64::NEG_INFINITY, 0.0, 0.0]];
    assert_eq!(augsim_mesh::measured_fault(&infinite).unwrap().1, "has a non-finite coordinate: x = -inf");
    let far = [[0.0, 0.0, 2e6]];
    assert!(augsim_mesh::measured_fault(&far).unwrap().1.contains("beyond 1e6"));
}

/// A ball of radius 40 mm with a flap 6 mm thick reaching 45 mm beyond it, as a closed surface
/// (the boundary of a fine mesh of it).
fn ball_with_flap() -> augsim_mesh::TriSurface {
    let flap = |p: Point| {
        let q = [(p[0] - 0.0625).abs() - 0.0425, p[1].abs() - 0.02, p[2].abs() - 0.003];
        let outside = norm(q.map(|c| c.max(0.0)));
        outside + q[0].max(q[1]).max(q[2]).min(0.0)
    };
    let domain = SdfDomain::new(move |p: Point| (norm(p) - 0.04).min(flap(p)), [-0.041; 3], [0.106, 0.041, 0.041]);
    let fine = stuff(&domain, &TetMeshOptions::with_size(0.0015).with_fit(BoundaryFit::OnSurface)).unwrap();
    augsim_mesh::boundary_surface(&fine).compacted()
}

/// A part thinner than the elements is left out of the mesh and the coverage says how much; a
/// mesh fine enough keeps it.
#[test]
fn coverage_names_a_thin_part_the_mesh_leaves_out() {
    let surface = ball_with_flap();
    let (coarse, q) = mesh_surface_to_count(&surface, 400, BoundaryFit::VolumePreserving).unwrap();
    let c = q.coverage.unwrap();
    let reach = coarse.nodes.iter().map(|p| p[0]).fold(f64::MIN, f64::max);
    assert!(reach < 0.09, "the flap reaches x = 105 mm, the coarse mesh {reach} m");
    assert!(c.uncovered > 0.05 && c.farthest > 0.02, "{c:?}");
    assert!((c.distance - 0.02 * 0.145).abs() < 1e-3, "2 % of the 145 mm extent: {c:?}");
    let (fine, q) = mesh_surface_to_count(&surface, 20_000, BoundaryFit::VolumePreserving).unwrap();
    let c = q.coverage.unwrap();
    assert!(fine.nodes.iter().map(|p| p[0]).fold(f64::MIN, f64::max) > 0.1);
    assert!(c.uncovered < 0.005 && c.farthest < c.distance, "{c:?}");
}

/// A ball behind a neck thinner than the lattice comes out of stuffing as a body that shares no
/// node with the rest (nothing would hold it): a small one is left out, the larger body kept; one
/// of a third of the volume is a lobe lost, refused, named by its share.
#[test]
fn a_body_cut_off_by_a_thin_neck_is_left_out_or_refused() {
    let neck = |p: Point| (p[1] * p[1] + p[2] * p[2]).sqrt().max((p[0] - 0.045).abs() - 0.02) - 0.0015;
    let stuffed = |radius: f64| {
        let two = move |p: Point| (norm(p) - 0.03).min(norm([p[0] - 0.09, p[1], p[2]]) - radius).min(neck(p));
        let domain = SdfDomain::new(two, [-0.031, -0.031, -0.031], [0.115, 0.031, 0.031]);
        stuff(&domain, &TetMeshOptions::with_size(0.012))
    };
    let error = stuffed(0.024).unwrap_err().to_string();
    assert!(error.contains("the mesh falls apart: a part of 33 % of the volume"), "{error}");
    let mesh = stuffed(0.01).unwrap();
    assert!(mesh.nodes.iter().all(|p| p[0] < 0.05), "the far ball is left out");
    let (lo, hi) = mesh.bounds();
    assert!(hi[0] - lo[0] > 0.05, "the near ball is kept: {lo:?} {hi:?}");
}

/// A bad cell is named by its number in the mesh's file (a Gmsh tag, an .inp number), not by its
/// place among the cells: a hexahedron folded at a corner (its volume still positive) and an
/// inverted tetrahedron.
#[test]
fn validation_names_a_bad_cell_by_its_file_number() {
    let mut hex = box_hex([0.0; 3], [1.0; 3], [1, 1, 1]).unwrap();
    let corner = hex.nodes.iter().position(|&p| p == [1.0; 3]).unwrap();
    hex.nodes[corner] = [0.4; 3];
    assert!(hex.cell_volume(0) > 0.0);
    hex.file_cells = Some(vec![203]);
    let e = hex.validate().unwrap_err().to_string();
    assert!(e.contains("hexahedron 203 has a non-positive corner Jacobian"), "{e}");
    let mut tet = box_tet([0.0; 3], [1.0; 3], [1, 1, 1]).unwrap();
    if let Cells::Tet4(cells) = &mut tet.cells {
        cells[2].swap(0, 1);
    }
    tet.file_cells = Some((0..tet.cells.len()).map(|c| 17 + c).collect());
    let e = tet.validate().unwrap_err().to_string();
    assert!(e.contains("cell 19 is inverted"), "{e}");
}

/// Two boxes of tetrahedra side by side, sharing nothing, and a small tetrahedron hanging on the
/// first by a vertex.
fn two_boxes(second: [f64; 3]) -> Mesh {
    let a = box_tet([0.0; 3], [0.04, 0.02, 0.02], [4, 2, 2]).unwrap();
    let b = box_tet([0.05, 0.0, 0.0], [0.05 + second[0], second[1], second[2]], [4, 2, 2]).unwrap();
    let (Cells::Tet4(ta), Cells::Tet4(tb)) = (&a.cells, &b.cells) else { unreachable!("tetrahedra") };
    let mut nodes = a.nodes.clone();
    nodes.extend(&b.nodes);
    let mut tets = ta.clone();
    tets.extend(tb.iter().map(|t| t.map(|n| n + a.nodes.len())));
    // A small tetrahedron on the corner (0.04, 0.02, 0.02) of the first box.
    let corner = a.nodes.iter().position(|p| *p == [0.04, 0.02, 0.02]).unwrap();
    let k = nodes.len();
    nodes.extend([[0.042, 0.02, 0.02], [0.04, 0.022, 0.02], [0.04, 0.02, 0.022]]);
    tets.push([corner, k, k + 1, k + 2]);
    Mesh::new(nodes, Cells::Tet4(tets)).unwrap()
}

/// A part apart from the main body as large as it (a lobe behind a neck thinner than the
/// lattice) is refused, named by its share; a small one is dropped with the tetrahedron that
/// hangs by a vertex, the main body numbered afresh.
#[test]
fn a_large_part_apart_is_refused_and_small_pieces_are_dropped() {
    let halves = two_boxes([0.04, 0.02, 0.02]);
    let error = augsim_mesh::without_small_pieces(halves).unwrap_err().to_string();
    assert!(error.contains("the mesh falls apart: a part of 50 % of the volume (16.0 mL)"), "{error}");
    let crumb = two_boxes([0.002, 0.002, 0.002]);
    let kept = augsim_mesh::without_small_pieces(crumb).unwrap();
    let main = box_tet([0.0; 3], [0.04, 0.02, 0.02], [4, 2, 2]).unwrap();
    assert_eq!((kept.num_nodes(), kept.cells.len()), (main.num_nodes(), main.cells.len()));
    assert_eq!((kept.file_nodes, kept.file_cells), (None, None));
}

/// Cells left out (the second box, in the middle of the cells and nodes) drop the nodes only they
/// use; the others keep their file's numbers and their regions, renumbered.
#[test]
fn a_mesh_without_some_cells_keeps_its_file_numbers() {
    let mut mesh = two_boxes([0.002, 0.002, 0.002]);
    let first = box_tet([0.0; 3], [0.04, 0.02, 0.02], [4, 2, 2]).unwrap();
    let (nodes, cells) = (first.num_nodes(), first.cells.len());
    let tip = mesh.cells.len() - 1;
    mesh.regions.insert("tip".into(), mesh.cells.cell(tip).to_vec());
    let second: Vec<usize> = (cells..tip).collect();
    let kept = mesh.without_cells(&second).unwrap();
    let dropped_nodes = mesh.num_nodes() - nodes - 3;
    assert_eq!((kept.num_nodes(), kept.cells.len()), (nodes + 3, cells + 1));
    // The tip's cell and nodes come after the dropped ones in the file: their numbers are kept.
    assert_eq!(kept.file_cell(cells), tip);
    let tip_nodes: Vec<usize> = kept.regions["tip"].iter().map(|&n| kept.file_node(n)).collect();
    assert_eq!(tip_nodes, mesh.cells.cell(tip).to_vec());
    assert_eq!(kept.file_node(nodes), nodes + dropped_nodes, "the first node after the dropped ones");
    assert_eq!(kept.cells.cell(cells)[1], nodes, "renumbered in the cells");
    assert_eq!(kept.nodes[nodes], mesh.nodes[nodes + dropped_nodes]);
}
