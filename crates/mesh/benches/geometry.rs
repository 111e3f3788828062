//! Geometry benchmark: meshing the liver phantom and the SOFA liver, the
//! immersed grid, and the embedding of a 21×23×21 grid. Prints the median
//! wall time over repeated runs. Run with
//! `cargo bench -p augsim-mesh --bench geometry`.

use std::time::Instant;

use augsim_mesh::embedding::{Embedding, Grid};
use augsim_mesh::phantom::PhantomSpec;
use augsim_mesh::sampling::sample_visible_boundary;
use augsim_mesh::stats::median;
use augsim_mesh::tetmesh::{mesh_surface_to_count, stuff, surface_domain, tet_quality, BoundaryFit, TetMeshOptions};
use augsim_mesh::{liver_phantom, Mesh, MeshError};

const LIVER_OBJ: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/liver-smooth.obj");

/// Runs `f` `runs` times; returns the median time in milliseconds and the last result.
fn time<T>(runs: usize, mut f: impl FnMut() -> T) -> (f64, T) {
    let mut times = Vec::with_capacity(runs);
    let mut last = None;
    for _ in 0..runs {
        let t = Instant::now();
        let out = f();
        times.push(t.elapsed().as_secs_f64() * 1e3);
        last = Some(out);
    }
    (median(&mut times), last.expect("at least one run"))
}

fn main() -> Result<(), MeshError> {
    let threads = rayon::current_num_threads();
    println!("geometry benchmark ({threads} threads), median of repeated runs");
    let spec = PhantomSpec::default();
    let volume = spec.volume();

    for target in [5000, 11000] {
        let (ms, mesh) = time(7, || liver_phantom(target));
        let mesh = mesh?;
        let q = tet_quality(&mesh, Some(volume))?;
        println!("liver phantom, target {target:>5}: {ms:8.2} ms (with element-count search and regions) | {q}");
    }
    // One meshing at a fixed size (no count search, no regions).
    for size in [0.0137, 0.0105] {
        let (ms, mesh) = time(9, || stuff(&spec, &TetMeshOptions::with_size(size)));
        let mesh: Mesh = mesh?;
        println!("phantom stuffing at size {size} m: {ms:8.2} ms | {} tetrahedra", mesh.cells.len());
    }

    let mut surface = augsim_mesh::io::read_surface(LIVER_OBJ)?;
    surface.fit_to(0.2)?;
    let (ms, dom) = time(5, || surface_domain(&surface));
    let (bvh, enclosed) = dom?;
    println!("liver-smooth.obj checks + BVH + overlap test: {ms:8.2} ms ({} triangles)", bvh.num_triangles());
    for target in [5000, 11000] {
        let (ms, out) = time(3, || mesh_surface_to_count(&surface, target, BoundaryFit::VolumePreserving));
        let (_, q) = out?;
        println!("liver-smooth.obj, target {target:>5}: {ms:8.2} ms (with count search) | {q}");
    }
    for (size, fit) in [(0.0142, BoundaryFit::VolumePreserving), (0.0142, BoundaryFit::OnSurface)] {
        let (ms, mesh) = time(5, || stuff(&bvh, &TetMeshOptions::with_size(size).with_fit(fit)));
        let q = tet_quality(&mesh?, Some(enclosed))?;
        println!("liver-smooth.obj stuffing at size {size} m, {fit:?}: {ms:8.2} ms | {q}");
    }

    let mesh = liver_phantom(5000)?;
    let (lo, hi) = mesh.bounds();
    let grid = Grid::covering(lo, hi, [21, 23, 21])?;
    let (ms, emb) = time(21, || Embedding::new(&mesh, grid.clone()));
    let emb = emb?;
    println!(
        "embedding 21×23×21 in the {}-tet phantom: {ms:8.3} ms | {} of {} grid nodes inside",
        mesh.cells.len(),
        emb.num_inside(),
        grid.num_nodes()
    );
    let field: Vec<f64> = mesh.nodes.iter().flat_map(|p| p.iter().copied()).collect();
    let (ms, _) = time(51, || emb.map_nodal(&field, 3));
    println!("map a 3-channel nodal field to the grid: {ms:8.3} ms");

    for spacing in [0.01, 0.0075] {
        let (ms, grid) = time(7, || spec.immersed(spacing));
        let grid = grid?;
        println!(
            "immersed phantom grid, spacing {spacing} m: {ms:8.2} ms | {} cells, {} nodes, volume error {:+.3}%",
            grid.mesh.cells.len(),
            grid.mesh.num_nodes(),
            100.0 * (grid.mesh.body_volume() / volume - 1.0)
        );
    }
    let (ms, samples) = time(21, || sample_visible_boundary(&mesh, spec.view_direction, 100, 1));
    println!("100 visible surface samples: {ms:8.3} ms ({} points)", samples?.len());
    Ok(())
}
