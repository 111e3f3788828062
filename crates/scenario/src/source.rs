//! What every scenario kind shares: where the mesh comes from, fixed nodes, and the constrained base problem.

use std::path::{Path, PathBuf};

use mesh::immersed::ImmersedOptions;
use mesh::length::ORGAN_EXTENT_M;
use mesh::length::{organ_units, LengthUnit};
use mesh::{Mesh, MeshError, NodeSelection, Point};
use serde::Deserialize;

use fem::{FemError, Material, Problem};

/// The mesh of a scenario.
#[derive(Debug, Clone, Deserialize)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub enum MeshSource {
    /// A structured box.
    Box {
        /// Lower corner (m).
        min: Point,
        /// Upper corner (m).
        max: Point,
        /// Cells along x, y, z.
        cells: [usize; 3],
        /// "hex" (H8) or "tet" (6 T4 per cell).
        element: ElementKind,
    },
    /// The built-in liver phantom meshed with about `tets` tetrahedra.
    Phantom {
        /// Target number of tetrahedra.
        tets: usize,
    },
    /// The built-in liver phantom as an immersed-boundary H8 grid.
    PhantomGrid {
        /// Cell size (m).
        spacing: f64,
        /// Cells with at most this volume fraction are left out (default 0: every cell with
        /// material); nearly empty cut cells are the first to be crushed under large loads.
        #[serde(default)]
        min_fraction: f64,
    },
    /// A closed surface (.obj, .stl, .ply, .vtk, .vtp, .vtu) meshed with tetrahedra; the path is
    /// relative to the scenario file.
    Surface {
        /// Path of the surface.
        path: PathBuf,
        /// Scale so that the largest extent is this length (m), centred at the origin.
        length: f64,
        /// Target number of tetrahedra.
        tets: usize,
    },
    /// A volume mesh file (.msh, .vtk, .vtu, .inp); the path is relative to the scenario file.
    File {
        /// Path of the file.
        path: PathBuf,
        /// The unit of the file's coordinates (m, cm, mm or um; default: m, as a scenario's).
        #[serde(default)]
        unit: Option<LengthUnit>,
        /// Multiply coordinates by this factor (after the unit), e.g. to enlarge a model.
        #[serde(default = "one")]
        scale: f64,
        /// Move the bounding-box centre to the origin before scaling.
        #[serde(default)]
        centre: bool,
    },
}

fn one() -> f64 {
    1.0
}

impl MeshSource {
    /// The file its mesh is read or meshed from (relative to the scenario's folder), if any.
    pub fn file(&self) -> Option<&Path> {
        match self {
            MeshSource::File { path, .. } | MeshSource::Surface { path, .. } => Some(path),
            _ => None,
        }
    }

    /// The frame (RAS or LPS) its mesh file names ([`mesh::io::surface_frame`]: a `.vtu`'s field
    /// data, a `.vtk`'s title), `dir` the scenario's folder; none for a generated mesh or one
    /// moved to the origin.
    pub fn frame(&self, dir: &Path) -> Result<Option<mesh::io::Frame>, MeshError> {
        match self {
            MeshSource::File { path, centre: false, scale, .. } if *scale > 0.0 => {
                mesh::io::surface_frame(dir.join(path))
            }
            _ => Ok(None),
        }
    }
}

/// Element kind of a generated box.
#[derive(Debug, Clone, Copy, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum ElementKind {
    /// Trilinear hexahedra.
    Hex,
    /// Linear tetrahedra.
    Tet,
}

/// Fixed nodes.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Fixed {
    /// Which nodes.
    pub select: NodeSelection,
}

/// Builds a mesh from its source (file paths relative to `dir`).
pub fn build_mesh(source: &MeshSource, dir: &Path) -> Result<Mesh, MeshError> {
    Ok(match source {
        MeshSource::Box { min, max, cells, element: ElementKind::Hex } => mesh::box_hex(*min, *max, *cells)?,
        MeshSource::Box { min, max, cells, element: ElementKind::Tet } => mesh::box_tet(*min, *max, *cells)?,
        MeshSource::Phantom { tets } => mesh::phantom::liver_phantom(*tets)?,
        MeshSource::PhantomGrid { spacing, min_fraction } => {
            let options = ImmersedOptions { min_fraction: *min_fraction, ..ImmersedOptions::with_spacing(*spacing) };
            mesh::phantom::PhantomSpec::default().immersed_with(&options)?.mesh
        }
        MeshSource::Surface { path, length, tets } => {
            let mut surface = mesh::io::read_surface(dir.join(path))?;
            surface.fit_to(*length)?;
            mesh::tetmesh::mesh_surface_to_count(&surface, *tets, mesh::tetmesh::BoundaryFit::default())?.0
        }
        MeshSource::File { path, unit, scale, centre } => {
            if !(scale.is_finite() && *scale > 0.0) {
                return Err(MeshError::Invalid(format!("[mesh.file] scale must be finite and > 0, got {scale}")));
            }
            let mut m = mesh::io::read_mesh(dir.join(path))?;
            let (lo, hi) = m.bounds();
            let c = if *centre { std::array::from_fn(|d| 0.5 * (lo[d] + hi[d])) } else { [0.0; 3] };
            m.transform(c, unit.unwrap_or(LengthUnit::Metre).metres() * scale);
            m
        }
    })
}

/// A mesh larger than this (m) is no organ nor a built-in beam, but an organ in another unit read
/// as metres (organs span 60 cm at most).
const MISREAD_MESH_EXTENT: f64 = 5.0;

/// The nodes `selection` picks on `mesh` (built from `source`), or what went wrong, naming the
/// selection's table (`what`: "fixed", "force"); where a selection by position picks nothing on a
/// mesh of metres, asks for the mesh's unit (scenarios are in metres).
pub fn select_nodes(
    selection: &NodeSelection,
    mesh: &Mesh,
    source: &MeshSource,
    what: &str,
) -> Result<Vec<usize>, String> {
    selection.select(mesh).map_err(|e| {
        let unit_caused = matches!(e, MeshError::Invalid(_)) && by_position(selection);
        let hint = unit_hint(mesh, source).filter(|_| unit_caused).map_or(String::new(), |h| format!(" ({h})"));
        format!("{what} selection: {e}{hint}")
    })
}

/// Whether `selection` picks nodes by their position (which a mesh in another unit misplaces), in
/// part at least.
fn by_position(selection: &NodeSelection) -> bool {
    match selection {
        NodeSelection::Box { .. } | NodeSelection::Ball(_) | NodeSelection::Near(_) | NodeSelection::Facing(_) => true,
        NodeSelection::Union(parts) | NodeSelection::Intersection(parts) => parts.iter().any(by_position),
        _ => false,
    }
}

/// For a mesh over 5 m across (no organ is), what it probably is: an organ in millimetres or
/// centimetres (those in which its size is an organ's) read as metres; a mesh file's `unit` key is
/// named where `source` is a file.
pub fn unit_hint(mesh: &Mesh, source: &MeshSource) -> Option<String> {
    let extent = mesh::longest_side(mesh.bounds());
    if extent <= MISREAD_MESH_EXTENT {
        return None;
    }
    let units = organ_units(extent, &[LengthUnit::Millimetre, LengthUnit::Centimetre]);
    let names: Vec<&str> = units.iter().map(|u| u.name()).collect();
    let from_file = matches!(source, MeshSource::File { .. });
    let key = |keys: &str| if from_file { format!(": [mesh.file] {keys}") } else { String::new() };
    let keys: Vec<String> = units.iter().map(|u| format!("unit = \"{u}\"")).collect();
    Some(match units.is_empty() {
        true => format!(
            "the mesh spans {extent:.0} m, where organs span {} to {} cm: is its unit right? scenarios are in metres{}",
            LengthUnit::Centimetre.from_metres(*ORGAN_EXTENT_M.start()),
            LengthUnit::Centimetre.from_metres(*ORGAN_EXTENT_M.end()),
            key("unit")
        ),
        false => format!(
            "the mesh spans {extent:.0} m: is it in {}? scenarios are in metres{}",
            names.join(" or "),
            key(&keys.join(" or "))
        ),
    })
}

/// Soft tissues' Young's moduli (Pa): a brain's to a stiff liver's.
const TISSUE_YOUNG_PA: std::ops::RangeInclusive<f64> = 100.0..=1e5;

/// A hint for a Young's modulus `young` (Pa) far below soft tissues', as one given in kPa is:
/// said beside a solve that failed.
pub fn young_hint(young: f64) -> Option<String> {
    (young < *TISSUE_YOUNG_PA.start()).then(|| {
        format!(
            "E = {young} Pa, where soft tissues are {} to {} kPa: is it in kPa? scenarios are in pascals",
            TISSUE_YOUNG_PA.start() / 1e3,
            TISSUE_YOUNG_PA.end() / 1e3
        )
    })
}

/// The problem on `mesh` (built from `source`) with `material` (validated) and the `fixed` nodes held at zero
/// displacement; errors name the material or the selection at fault.
pub fn fixed_problem(
    mesh: Mesh,
    source: &MeshSource,
    material: Material,
    fixed: &[Fixed],
) -> Result<Problem, FemError> {
    material.validate().map_err(|m| FemError::Invalid(format!("material: {m}")))?;
    let mut problem = Problem::new(mesh, material);
    for f in fixed {
        let nodes = select_nodes(&f.select, &problem.mesh, source, "fixed").map_err(FemError::Invalid)?;
        problem.fix(&nodes);
    }
    Ok(problem)
}
