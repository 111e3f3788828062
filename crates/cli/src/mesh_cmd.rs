//! `augsim mesh`: a closed surface, a segmentation's labelmap (or the built-in liver phantom) to
//! a T4 mesh or an immersed-boundary H8 grid, with a quality report. A surface is repaired first
//! (as segmentations give them: holes, duplicated vertices, flipped triangles; through voxels
//! when local repair cannot mend it) and brought from its length unit to metres; a labelmap's
//! label is extracted as a closed surface in millimetres, in the file's scanner frame.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{anyhow, bail, Context, Result};
use mesh::io::Field;
use mesh::isosurface::ExtractOptions;
use mesh::labelmap::{is_labelmap, read_labelmap_surface};
use mesh::phantom::PhantomSpec;
use mesh::rebuild::{repair_or_rebuild, RebuildOptions};
use mesh::repair::{detect_unit, largest_extent, metres_per, LengthUnit, RepairOptions};
use mesh::tetmesh::{tet_quality, BoundaryFit};
use mesh::{Mesh, TriSurface};

/// The length unit of a surface's coordinates.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Units {
    /// Told from the organ's size (2 to 60 cm across).
    Auto,
    /// Millimetres.
    Mm,
    /// Metres.
    M,
}

/// What to mesh and how.
pub struct MeshArgs {
    /// Organ surface (.obj, .stl, .vtk, .vtu) or labelmap (.nii, .nii.gz, .nrrd, .seg.nrrd); the
    /// phantom when `None`.
    pub surface: Option<PathBuf>,
    /// The labelmap's label: a number or a segment name (needed when it holds several).
    pub label: Option<String>,
    /// Scale the surface so that its largest extent is this length (m), centred at the origin;
    /// overrides `units`.
    pub length: Option<f64>,
    /// The unit of the surface's coordinates; the surface is scaled to metres about the origin
    /// (its frame is kept).
    pub units: Units,
    /// Repair the surface first (otherwise it must be a closed 2-manifold as it is).
    pub repair: bool,
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
            let surface = prepare_surface(path, args)?;
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
    write_mesh_file(&args.output, &mesh)?;
    println!("wrote      {}", args.output.display());
    Ok(())
}

/// Reads a surface, repairs it unless told not to, and brings it to metres: fitted to `length`
/// when given, otherwise scaled from its unit (given or detected) about the origin. A labelmap's
/// label is extracted instead, in millimetres.
fn prepare_surface(path: &Path, args: &MeshArgs) -> Result<TriSurface> {
    if is_labelmap(path) {
        return labelmap_surface(path, args);
    }
    if args.label.is_some() {
        bail!("--label chooses a label of a labelmap (.nii, .nii.gz, .nrrd, .seg.nrrd), not of {}", path.display());
    }
    let mut surface = mesh::io::read_surface(path)?;
    let extent = largest_extent(&surface);
    let unit = match (args.length, args.units) {
        (Some(_), _) => None,
        (None, Units::Auto) => {
            let unit =
                detect_unit(&surface).map_err(|e| anyhow!("{}: {e} (--units mm or m, or --length)", path.display()))?;
            let shown = if extent >= 1.0 { format!("{extent:.1}") } else { format!("{extent:.4}") };
            Some((unit, format!("detected: largest extent {shown}")))
        }
        (None, Units::Mm) => Some((LengthUnit::Millimetre, "given".to_string())),
        (None, Units::M) => Some((LengthUnit::Metre, "given".to_string())),
    };
    if args.repair {
        let (repaired, route) = repair_or_rebuild(&surface, &RepairOptions::default(), &RebuildOptions::default())
            .with_context(|| format!("repairing {} (see --no-repair)", path.display()))?;
        for line in route.lines(unit.as_ref().map(|(u, _)| 1e3 * metres_per(*u))) {
            println!("repair     {line}");
        }
        for line in route.warnings() {
            println!("warning    {line}");
        }
        surface = repaired;
    }
    if let Some(l) = args.length {
        surface.fit_to(l)?;
    }
    if let Some((unit, how)) = unit {
        println!("units      {} ({how})", unit.symbol());
        let scale = metres_per(unit);
        if scale != 1.0 {
            surface.transform([0.0; 3], scale);
        }
    }
    Ok(surface)
}

/// The closed surface of a labelmap's label, in metres (from the file's millimetres, in its
/// scanner frame), or fitted to `length`.
fn labelmap_surface(path: &Path, args: &MeshArgs) -> Result<TriSurface> {
    if args.units == Units::M {
        bail!("{} is a labelmap, whose unit is the millimetre: leave out --units m", path.display());
    }
    let organ = read_labelmap_surface(path, args.label.as_deref(), &ExtractOptions::default())?;
    for line in organ.lines() {
        println!("labelmap   {line}");
    }
    let mut surface = organ.surface;
    match args.length {
        Some(l) => {
            surface.fit_to(l)?;
        }
        None => {
            println!("units      mm (the labelmap's); frame {} kept", organ.frame.name());
            surface.transform([0.0; 3], 1e-3);
        }
    }
    Ok(surface)
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

/// Writes the mesh with its regions (point data `region_<name>`, or Gmsh physical groups) and,
/// for an immersed grid, its cells' volume fractions; to .stl or .obj, its boundary surface.
fn write_mesh_file(path: &Path, mesh: &Mesh) -> Result<()> {
    let extension = path.extension().map(|e| e.to_string_lossy().to_ascii_lowercase()).unwrap_or_default();
    if extension == "stl" || extension == "obj" {
        let surface = mesh::boundary_surface(mesh).compacted();
        return mesh::io::write_surface(path, &surface).with_context(|| format!("writing {}", path.display()));
    }
    let is_msh = extension == "msh";
    let fields: Vec<Field> = match &mesh.cell_fraction {
        Some(f) if !is_msh => vec![Field::cell("volume_fraction", 1, f.clone())],
        _ => Vec::new(),
    };
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    mesh::io::write_mesh(path, mesh, &fields).with_context(|| format!("writing {}", path.display()))
}
