//! `augsim mesh`: a closed surface, a segmentation's labelmap (or the built-in liver phantom) to
//! a T4 mesh or an immersed-boundary H8 grid (see `app::meshing`), with a quality report.

use std::path::Path;
use std::time::Instant;

use anyhow::{bail, Result};
use app::meshing::{immersed_fill, mesh_organ, write_mesh_file, MeshOptions};
use mesh::tetmesh::tet_quality;
use mesh::Mesh;

/// Runs the command: meshes, prints the report and writes `output`.
pub fn run(options: &MeshOptions, output: &Path) -> Result<()> {
    let start = Instant::now();
    let meshed = mesh_organ(options)?;
    let elapsed = start.elapsed();
    for (topic, line) in &meshed.notes {
        println!("{topic:<10} {line}");
    }
    report(&meshed.mesh, meshed.reference_volume)?;
    println!("time       {:.1} ms", elapsed.as_secs_f64() * 1e3);
    write_mesh_file(output, &meshed.mesh)?;
    println!("wrote      {}", output.display());
    Ok(())
}

fn report(mesh: &Mesh, reference: Option<f64>) -> Result<()> {
    let (lo, hi) = mesh.bounds();
    println!("mesh       {} nodes, {} {} cells", mesh.num_nodes(), mesh.cells.len(), mesh.cells.kind_name());
    println!("extent     {:.4} × {:.4} × {:.4} m", hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]);
    match &mesh.cells {
        mesh::Cells::Tet4(_) => {
            let q = tet_quality(mesh, reference)?;
            if q.inverted > 0 {
                bail!("{} inverted tetrahedra", q.inverted);
            }
            println!("dihedral   min {:.1}°, max {:.1}°", q.min_dihedral_deg, q.max_dihedral_deg);
            if q.pieces > 1 {
                println!("warning    {} pieces joined only by edges or vertices: mesh finer (--tets)", q.pieces);
            }
            print_volume(q.volume, q.reference_volume);
        }
        mesh::Cells::Tet10(_) => print_volume(mesh.volume(), reference),
        mesh::Cells::Hex8(_) => {
            let (organ, cut) = immersed_fill(mesh);
            println!("cells      {} fully inside, {cut} cut by the surface", mesh.cells.len() - cut);
            print_volume(organ, reference);
        }
    }
    for (name, nodes) in &mesh.regions {
        println!("region     {name}: {} nodes", nodes.len());
    }
    Ok(())
}

fn print_volume(volume: f64, reference: Option<f64>) {
    match reference {
        Some(r) => println!("volume     {volume:.4e} m³ (domain {r:.4e} m³, {:+.2} %)", 100.0 * (volume - r) / r),
        None => println!("volume     {volume:.4e} m³"),
    }
}
