//! `augsim mesh`: a closed surface (or the built-in liver phantom) to a T4
//! mesh or an immersed-boundary H8 grid, with a quality report.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Context, Result};
use mesh::io::Field;
use mesh::phantom::PhantomSpec;
use mesh::tetmesh::{tet_quality, BoundaryFit};
use mesh::Mesh;

/// What to mesh and how.
pub struct MeshArgs {
    /// Closed surface (.obj, .stl, .vtk, .vtu); the phantom when `None`.
    pub surface: Option<PathBuf>,
    /// Scale the surface so that its largest extent is this length (m), centred at the origin.
    pub length: Option<f64>,
    /// Target number of tetrahedra.
    pub tets: usize,
    /// Make an immersed hex grid with this cell size (m) instead of tetrahedra.
    pub immersed: Option<f64>,
    /// Output file (.vtu, .vtk or .msh).
    pub output: PathBuf,
}

/// Runs the command.
pub fn run(args: &MeshArgs) -> Result<()> {
    let start = Instant::now();
    let (mesh, reference) = match (&args.surface, args.immersed) {
        (None, None) => {
            let spec = PhantomSpec::default();
            (spec.mesh(args.tets)?, Some(spec.volume()))
        }
        (None, Some(h)) => {
            let spec = PhantomSpec::default();
            (spec.immersed(h)?.mesh, Some(spec.volume()))
        }
        (Some(path), immersed) => {
            let mut surface = mesh::io::read_surface(path)?;
            if let Some(l) = args.length {
                surface.fit_to(l)?;
            }
            match immersed {
                None => {
                    let (m, _) = mesh::tetmesh::mesh_surface_to_count(&surface, args.tets, BoundaryFit::default())
                        .with_context(|| format!("meshing {}", path.display()))?;
                    (m, Some(surface.enclosed_volume().abs()))
                }
                Some(h) => {
                    let opts = mesh::immersed::ImmersedOptions::with_spacing(h);
                    (mesh::immersed::immersed_surface(&surface, &opts)?.mesh, Some(surface.enclosed_volume().abs()))
                }
            }
        }
    };
    let elapsed = start.elapsed();
    report(&mesh, reference)?;
    println!("time       {:.1} ms", elapsed.as_secs_f64() * 1e3);
    write_with_regions(&args.output, &mesh)?;
    println!("wrote      {}", args.output.display());
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
            print_volume(q.volume, q.reference_volume);
        }
        mesh::Cells::Tet10(_) => print_volume(mesh.volume(), reference),
        mesh::Cells::Hex8(_) => {
            let fraction = mesh.cell_fraction.as_deref().unwrap_or(&[]);
            let organ: f64 =
                (0..mesh.cells.len()).map(|c| mesh.cell_volume(c) * fraction.get(c).copied().unwrap_or(1.0)).sum();
            let partial = fraction.iter().filter(|&&f| f < 1.0).count();
            println!("cells      {} fully inside, {} cut by the surface", mesh.cells.len() - partial, partial);
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

/// Writes the mesh; for VTK formats the regions become 0/1 point fields
/// `region_<name>` and immersed cell fractions a cell field.
pub fn write_with_regions(path: &Path, mesh: &Mesh) -> Result<()> {
    let is_msh = path.extension().is_some_and(|e| e.eq_ignore_ascii_case("msh"));
    let mut fields = Vec::new();
    if !is_msh {
        for (name, nodes) in &mesh.regions {
            let mut v = vec![0.0; mesh.num_nodes()];
            nodes.iter().for_each(|&n| v[n] = 1.0);
            fields.push(Field::point(format!("region_{name}"), 1, v));
        }
        if let Some(f) = &mesh.cell_fraction {
            fields.push(Field::cell("volume_fraction", 1, f.clone()));
        }
    }
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    mesh::io::write_mesh(path, mesh, &fields).with_context(|| format!("writing {}", path.display()))
}
