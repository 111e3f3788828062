//! An organ's volume mesh, as `augsim mesh` makes it: from a closed surface (repaired first, as
//! segmentations give them: holes, duplicated vertices, flipped triangles; through voxels when
//! local repair cannot mend it; brought from its length unit to metres), from a label of a
//! segmentation's labelmap (extracted as a closed surface in millimetres, in the file's scanner
//! frame), or the built-in liver phantom; T4 or an immersed-boundary H8 grid.

use std::path::{Path, PathBuf};

use anyhow::{anyhow, bail, Context, Result};
use mesh::io::{Field, Frame};
use mesh::isosurface::{ExtractOptions, ExtractReport};
use mesh::labelmap::{is_labelmap, read_labelmap_surface, unreadable_segmentation, LABELMAP_FORMATS};
use mesh::length::ORGAN_EXTENT_M;
use mesh::length::{mm, organ_units, Length, LengthUnit, UnitOrAuto};
use mesh::phantom::PhantomSpec;
use mesh::rebuild::{repair_or_rebuild, RebuildOptions};
use mesh::repair::{detect_unit, largest_extent, scattered_pieces, RepairOptions};
use mesh::tetmesh::{mesh_surface_to_count, BoundaryFit, Coverage};
use mesh::{Mesh, TetQuality, TriSurface};

/// What to mesh and how.
#[derive(Clone, Debug)]
pub struct MeshOptions {
    /// Organ surface (.obj, .stl, .ply, .vtk, .vtp, .vtu) or labelmap (.nii, .nii.gz, .nrrd, .seg.nrrd, .dcm); the
    /// phantom when `None`.
    pub surface: Option<PathBuf>,
    /// The labelmap's label: a number or a segment name (needed when it holds several).
    pub label: Option<String>,
    /// Scale the surface so that its largest extent is this length, centred at the origin;
    /// overrides `units`.
    pub length: Option<Length>,
    /// The unit of the surface's coordinates (`None`: told from the organ's size); the surface is
    /// scaled to metres about the origin (its frame is kept).
    pub units: UnitOrAuto,
    /// Repair the surface first (otherwise it must be a closed 2-manifold as it is).
    pub repair: bool,
    /// Target number of tetrahedra.
    pub tets: usize,
    /// Make an immersed hex grid with this cell size instead of tetrahedra.
    pub immersed: Option<Length>,
}

/// A volume mesh and how it was made.
#[derive(Debug)]
pub struct Meshed {
    /// The mesh, in metres.
    pub mesh: Mesh,
    /// The volume of the domain it meshes (the phantom's or the surface's), when known.
    pub reference_volume: Option<f64>,
    /// The frame its input names (a labelmap's, a surface's `SPACE=` header), which the mesh is
    /// in; `None` when it names none or the mesh was fitted to a length.
    pub frame: Option<Frame>,
    /// What was done on the way, each a topic (`labelmap`, `repair`, `warning`, `units`) and a
    /// line, in order.
    pub notes: Vec<(&'static str, String)>,
    /// The quality of a surface's tetrahedral mesh, as meshing measured it (with how much of the
    /// surface it covers); `None` for the phantom and immersed grids.
    pub quality: Option<TetQuality>,
    /// The wall time of the meshing, reading included.
    pub elapsed: std::time::Duration,
}

/// Parts of the surface left out of its mesh beyond this share of its area are warned about.
pub const MOST_UNCOVERED: f64 = 0.01;

/// A warning when the mesh leaves out more than [`MOST_UNCOVERED`] of its surface's area.
pub fn coverage_warning(coverage: &Coverage) -> Option<String> {
    (coverage.uncovered > MOST_UNCOVERED).then(|| {
        format!(
            "{:.1} % of the surface lies more than {:.1} mm from the mesh (up to {:.1} mm): its tetrahedra are too \
             coarse to follow the surface there, or leave out parts thinner than themselves; mesh finer (--tets)",
            100.0 * coverage.uncovered,
            mm(coverage.distance),
            mm(coverage.farthest)
        )
    })
}

/// The warnings on a T4 mesh: pieces joined only by edges or vertices, and parts of its surface
/// left out ([`coverage_warning`], when its quality knows its coverage).
pub fn tet_mesh_warnings(quality: &TetQuality) -> Vec<String> {
    let mut warnings = Vec::new();
    if quality.pieces > 1 {
        warnings.push(format!(
            "the mesh is in {} pieces joined only by edges or vertices (a part thinner than its tetrahedra): the \
             FEM solves fail where a piece has no held node of its own; mesh it finer (--tets)",
            quality.pieces
        ));
    }
    warnings.extend(quality.coverage.as_ref().and_then(coverage_warning));
    warnings
}

/// How an organ's surface is brought from its file's coordinates to metres.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ToMetres {
    /// Scaled from its unit about the origin (in the frame its file names).
    FromUnit(LengthUnit),
    /// Centred at the origin and scaled so that its largest extent is this length (in no frame).
    FittedTo(Length),
}

/// An organ's surface meshed with tetrahedra ([`mesh_organ_surface`]).
#[derive(Debug)]
pub struct OrganMesh {
    /// The surface meshed, in metres (repaired when it was).
    pub surface: TriSurface,
    /// The mesh, in metres.
    pub mesh: Mesh,
    /// Its quality, with how much of the surface it covers.
    pub quality: TetQuality,
}

/// Meshes with about `tets` tetrahedra the organ's surface read from `path` (in the file's
/// coordinates), brought to metres as `to_metres` says. A surface file's is repaired first when
/// `repair` asks (local repair, through voxels when it cannot mend it); a labelmap's label never
/// is: its extraction makes it closed, manifold and within the overlap a mesh allows
/// ([`mesh::isosurface`]), where repair would find nothing to mend, or voxelise it a second time.
/// What was done is added to `notes` as it is done (each a topic, `repair` or `warning`, and a
/// line, the repair's lengths in the file's unit when known), so that they hold it when an error
/// follows.
pub fn mesh_organ_surface(
    path: &Path,
    surface: TriSurface,
    to_metres: ToMetres,
    tets: usize,
    repair: bool,
    notes: &mut Vec<(&'static str, String)>,
) -> Result<OrganMesh> {
    let surface = organ_surface_in_metres(path, surface, to_metres, repair, notes)?;
    let (mesh, quality) =
        mesh_surface_to_count(&surface, tets, BoundaryFit::default()).with_context(|| match &notes[..] {
            [] => format!("meshing {}", path.display()),
            done => format!("meshing {} ({})", path.display(), note_lines(done).join("; ")),
        })?;
    Ok(OrganMesh { surface, mesh, quality })
}

/// The organ's surface read from `path` in metres, repaired first as [`mesh_organ_surface`]
/// says.
fn organ_surface_in_metres(
    path: &Path,
    mut surface: TriSurface,
    to_metres: ToMetres,
    repair: bool,
    notes: &mut Vec<(&'static str, String)>,
) -> Result<TriSurface> {
    if repair && !is_labelmap(path) {
        let (repaired, route) = repair_or_rebuild(&surface, &RepairOptions::default(), &RebuildOptions::default())
            .with_context(|| format!("repairing {}", path.display()))?;
        let unit = match to_metres {
            ToMetres::FromUnit(unit) => Some(unit),
            ToMetres::FittedTo(_) => None,
        };
        notes.extend(route.lines(unit).into_iter().map(|l| ("repair", l)));
        notes.extend(route.warnings().into_iter().map(|l| ("warning", l)));
        surface = repaired;
    } else if let Some((a, b)) =
        (!is_labelmap(path)).then(|| mesh::repair::self_intersections(&surface).first().copied()).flatten()
    {
        bail!(
            "{}: the surface crosses itself (triangles {a} and {b}, among others): it must be a closed 2-manifold to \
             be meshed without repair; leave out --no-repair",
            path.display()
        );
    }
    match to_metres {
        ToMetres::FromUnit(unit) => surface.transform([0.0; 3], unit.metres()),
        ToMetres::FittedTo(length) => {
            surface.fit_to(length.in_metres())?;
        }
    }
    Ok(surface)
}

/// Refuses, before any meshing, an `output` that names the surface `options` mesh.
pub fn check_mesh_output(options: &MeshOptions, output: &Path) -> Result<()> {
    if let Some((_, surface)) = options.surface.as_deref().and_then(|s| mesh::io::overwritten(&[output], &[s])) {
        bail!(
            "{} would be written over the surface it meshes, {}: give another -o",
            output.display(),
            surface.display()
        );
    }
    Ok(())
}

/// Meshes the organ of `options`.
pub fn mesh_organ(options: &MeshOptions) -> Result<Meshed> {
    let start = std::time::Instant::now();
    let mut notes = Vec::new();
    let mut quality = None;
    let (mesh, reference_volume, frame) = match (&options.surface, options.immersed.map(Length::in_metres)) {
        (None, None) => {
            let spec = PhantomSpec::default();
            (spec.mesh(options.tets)?, Some(spec.volume()), None)
        }
        (None, Some(h)) => {
            let spec = PhantomSpec::default();
            (spec.immersed(h)?.mesh, Some(spec.volume()), None)
        }
        (Some(path), None) => {
            let (surface, to_metres, frame) = read_organ(path, options, &mut notes)?;
            let organ = mesh_organ_surface(path, surface, to_metres, options.tets, options.repair, &mut notes)?;
            let reference_volume = organ.quality.reference_volume;
            quality = Some(organ.quality);
            (organ.mesh, reference_volume, frame)
        }
        (Some(path), Some(h)) => {
            let (surface, to_metres, frame) = read_organ(path, options, &mut notes)?;
            let surface = organ_surface_in_metres(path, surface, to_metres, options.repair, &mut notes)?;
            let opts = mesh::immersed::ImmersedOptions::with_spacing(h);
            let volume = Some(surface.enclosed_volume().abs());
            (mesh::immersed::immersed_surface(&surface, &opts)?.mesh, volume, frame)
        }
    };
    Ok(Meshed { mesh, reference_volume, frame, notes, quality, elapsed: start.elapsed() })
}

/// Notes of what was read (topic, line) as lines `topic: line`.
pub fn note_lines(notes: &[(&'static str, String)]) -> Vec<String> {
    notes.iter().map(|(topic, line)| format!("{topic}: {line}")).collect()
}

/// An organ's segmentation as given: a labelmap's label extracted (in mm, in its scanner frame),
/// or a surface file read (in its unit, in the frame its header names).
#[derive(Debug)]
pub struct OrganInput {
    /// The surface, in its unit.
    pub surface: TriSurface,
    /// The frame the file names, if any.
    pub frame: Option<Frame>,
    /// Whether it is a labelmap's label (a clean surface, in mm).
    pub labelmap: bool,
    /// Its unit when known, and how: a labelmap's millimetre, the one given, or the one its
    /// file's header names ([`OrganInput::unit`]).
    unit: Option<(LengthUnit, &'static str)>,
    /// What was read, each a topic (`labelmap`, `warning`, `units`) and a line, in order.
    pub notes: Vec<(&'static str, String)>,
    /// What the extraction of a labelmap's label did (none for a surface file).
    pub extract: Option<ExtractReport>,
}

impl OrganInput {
    /// Reads `path` ([`LABELMAP_FORMATS`], or a surface: [`mesh::io::SURFACE_EXTENSIONS`]),
    /// choosing a labelmap's `label`, in `units` when given; a folder, a DICOM file or an image
    /// format not read is refused saying what to save instead.
    pub fn read(path: &Path, label: Option<&str>, units: UnitOrAuto) -> Result<OrganInput> {
        OrganInput::read_with(path, label, units, &ExtractOptions::default())
    }

    /// [`OrganInput::read`], a labelmap's label extracted with `extract` (a structure's:
    /// [`ExtractOptions::structure`], every piece kept).
    pub fn read_with(
        path: &Path,
        label: Option<&str>,
        units: UnitOrAuto,
        extract: &ExtractOptions,
    ) -> Result<OrganInput> {
        if let Some(why) = unreadable_segmentation(path) {
            bail!("{}: {why}", path.display());
        }
        if is_labelmap(path) {
            let organ = read_labelmap_surface(path, label, units, extract)?;
            let mut notes: Vec<_> = organ.lines().into_iter().map(|l| ("labelmap", l)).collect();
            notes.extend(organ.warnings.iter().map(|w| ("warning", w.clone())));
            let (frame, unit) = (organ.scanner_frame(), Some((LengthUnit::Millimetre, "the labelmap's")));
            let extract = Some(organ.extract);
            return Ok(OrganInput { surface: organ.surface, frame, labelmap: true, unit, notes, extract });
        }
        if let Some(label) = label {
            bail!("--label {label} chooses a label of a labelmap ({LABELMAP_FORMATS}), not of {}", path.display());
        }
        let (surface, frame, warnings) = mesh::io::read_surface_noted(path)?;
        // The unit its header names (Materialise's OBJ comment) where none is given.
        let unit = match units {
            Some(unit) => Some((unit, "given")),
            None => mesh::io::surface_unit(path)?.map(|unit| (unit, "named by the file's header")),
        };
        let notes = warnings.into_iter().map(|w| ("warning", w)).collect();
        Ok(OrganInput { surface, frame, labelmap: false, unit, notes, extract: None })
    }

    /// Its unit: a labelmap's millimetre, the one given, the one its file's header names, or the
    /// one detected from the surface's size; noted.
    pub fn unit(&mut self) -> Result<LengthUnit> {
        let (unit, how) = match self.unit {
            Some((unit, how)) if self.labelmap => (unit, how.to_string()),
            Some((unit, how)) => {
                let extent = unit.to_metres(largest_extent(&self.surface));
                if !ORGAN_EXTENT_M.contains(&extent) {
                    // The units in which the file's numbers would make an organ.
                    let fitting: Vec<String> = organ_units(largest_extent(&self.surface), &LengthUnit::ALL)
                        .into_iter()
                        .map(|u| format!(" (in {}? give --units {u})", u.name()))
                        .collect();
                    self.notes.push((
                        "warning",
                        format!(
                            "in {unit} the organ is {} mm across, where organs are {:.0} to {:.0} mm: is the unit \
                             right?{}",
                            // To the millimetre; a smaller organ to its digits (0.12 mm, not 0).
                            match mm(extent) {
                                across if across >= 1.0 => format!("{across:.0}"),
                                across => mesh::length::number(across),
                            },
                            mm(*ORGAN_EXTENT_M.start()),
                            mm(*ORGAN_EXTENT_M.end()),
                            fitting.concat()
                        ),
                    ));
                }
                (unit, how.to_string())
            }
            None => {
                let unit = detect_unit(&self.surface).map_err(|e| {
                    if scattered_pieces(&self.surface).is_some() {
                        return anyhow!("{e}");
                    }
                    let extent = largest_extent(&self.surface);
                    // The units auto does not tell (their organs' numbers overlap mm's) that would fit.
                    let fitting: Vec<String> = organ_units(extent, &[LengthUnit::Centimetre, LengthUnit::Micrometre])
                        .into_iter()
                        .map(|u| format!(" (in {}? give --units {u})", u.name()))
                        .collect();
                    anyhow!("{e}: give --units (m, cm, mm or um){}", fitting.concat())
                })?;
                let extent = largest_extent(&self.surface);
                let shown = if extent >= 1.0 { format!("{extent:.1}") } else { format!("{extent:.4}") };
                if unit == LengthUnit::Millimetre && !organ_units(extent, &[LengthUnit::Centimetre]).is_empty() {
                    // 20 to 60 mm across in mm, or 20 to 60 cm across (a liver) in cm.
                    self.notes.push((
                        "warning",
                        format!(
                            "the organ, taken as in mm, is {extent:.0} mm across: if its file is in centimetres \
                             ({:.0} mm across), give --units cm",
                            10.0 * extent
                        ),
                    ));
                }
                (unit, format!("detected: largest extent {shown} in the file's unit; give --units otherwise"))
            }
        };
        self.unit = Some((unit, "detected"));
        self.notes.push(("units", format!("{} ({how})", unit.symbol())));
        Ok(unit)
    }
}

/// Reads the organ's segmentation ([`OrganInput`]): its surface in the file's coordinates, how it
/// is brought to metres (fitted to the length given, otherwise scaled from its unit: a labelmap's
/// mm, given or detected) and the frame it is then in (see [`Meshed::frame`]; none when fitted).
fn read_organ(
    path: &Path,
    options: &MeshOptions,
    notes: &mut Vec<(&'static str, String)>,
) -> Result<(TriSurface, ToMetres, Option<Frame>)> {
    if let Some(length) = options.length.filter(|l| !(l.in_metres() > 0.0)) {
        bail!("--length must be positive, got {length}");
    }
    let mut input = OrganInput::read(path, options.label.as_deref(), options.units)?;
    let (to_metres, frame) = match options.length {
        Some(length) => (ToMetres::FittedTo(length), None),
        None => {
            let unit = input.unit().with_context(|| format!("the unit of {} (or give --length)", path.display()))?;
            (ToMetres::FromUnit(unit), input.frame)
        }
    };
    notes.append(&mut input.notes);
    if let Some(frame) = frame {
        notes.push(("frame", format!("{frame} kept")));
    }
    Ok((input.surface, to_metres, frame))
}

/// An immersed grid's organ volume ([`Mesh::body_volume`]: each cell's volume times its volume
/// fraction) and its cells cut by the surface (fraction below 1).
pub fn immersed_fill(mesh: &Mesh) -> (f64, usize) {
    let cut = mesh.cell_fraction.as_deref().map_or(0, |fraction| fraction.iter().filter(|&&f| f < 1.0).count());
    (mesh.body_volume(), cut)
}

/// The files [`write_mesh_file`] writes, by extension: a volume mesh (VTK, Gmsh) or its boundary surface.
pub const MESH_FILE_EXTENSIONS: [&str; 5] = ["vtu", "vtk", "msh", "stl", "obj"];

/// Writes the mesh in metres with its regions (point data `region_<name>`, or Gmsh physical
/// groups) and, for an immersed grid, its cells' volume fractions (not in `.msh`); to .stl or
/// .obj, its boundary surface in millimetres, as 3D Slicer and surface tools read them, naming
/// `frame` in its header when known (a `.vtu` names it in its field data, a `.vtk` in its title,
/// a `.msh` nowhere; the directory created by the writer). Returns what was written, in words.
pub fn write_mesh_file(path: &Path, mesh: &Mesh, frame: Option<Frame>) -> Result<String> {
    let extension = mesh::io::extension(path);
    let context = || format!("writing {}", path.display());
    if extension == "stl" || extension == "obj" {
        write_surface_in_mm(path, &mesh::boundary_surface(mesh).compacted(), frame).with_context(context)?;
        let named = frame.map_or(String::new(), |f| format!(", frame {f} named"));
        return Ok(format!("its boundary surface, in mm{named}"));
    }
    let fields: Vec<Field> = match &mesh.cell_fraction {
        Some(_) if extension == "msh" => bail!(
            "{}: an immersed grid's cell volume fractions have no place in Gmsh's format (read back, every cut \
             cell would solve as full); write .vtu or .vtk",
            path.display()
        ),
        Some(f) => vec![Field::cell(mesh::io::FRACTION_FIELD, 1, f.clone())],
        None => Vec::new(),
    };
    mesh::io::write_mesh_in_frame(path, mesh, &fields, frame).with_context(context)?;
    let named = match (frame, extension.as_str()) {
        // 3D Slicer reads a model's numbers as mm: this one would show 1,000 times too small.
        (Some(f), "vtu" | "vtk") => {
            format!(", frame {f} named; for 3D Slicer, which reads models in mm, write .stl or .obj")
        }
        (Some(f), _) => format!(", in {f}: Gmsh's format names no frame"),
        _ => String::new(),
    };
    Ok(format!("in m{named}"))
}

/// Writes a surface given in metres in millimetres, as 3D Slicer and surface tools read it (.stl,
/// .obj, .vtk), naming `frame` in its header when known.
pub fn write_surface_in_mm(path: &Path, surface: &TriSurface, frame: Option<Frame>) -> Result<()> {
    let vertices = surface.vertices.iter().map(|&v| LengthUnit::Millimetre.point_from_metres(v)).collect();
    let surface = TriSurface { vertices, triangles: surface.triangles.clone() };
    match frame {
        Some(frame) => mesh::io::write_surface_in_frame(path, &surface, frame)?,
        None => mesh::io::write_surface(path, &surface)?,
    }
    Ok(())
}

impl Meshed {
    /// What `augsim mesh` prints: the notes, the [`Meshed::report`] and the time it took.
    pub fn lines(&self) -> Result<Vec<String>> {
        let mut lines: Vec<String> = self.notes.iter().map(|(topic, line)| format!("{topic:<10} {line}")).collect();
        lines.extend(self.report()?);
        lines.push(format!("time       {:.1} ms", mesh::stats::ms(self.elapsed)));
        Ok(lines)
    }

    /// The mesh in words: size, extent, quality (tetrahedra) or fill (immersed cells), volume
    /// against the domain's, regions. Inverted tetrahedra are an error.
    pub fn report(&self) -> Result<Vec<String>> {
        let (mesh, reference) = (&self.mesh, self.reference_volume);
        let (lo, hi) = mesh.bounds();
        let mut lines = vec![
            format!("mesh       {} nodes, {} {} cells", mesh.num_nodes(), mesh.cells.len(), mesh.cells.kind_name()),
            format!("extent     {:.4} × {:.4} × {:.4} m", hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]),
        ];
        let volume = match &mesh.cells {
            mesh::Cells::Tet4(_) => {
                let q = match &self.quality {
                    Some(q) => q.clone(),
                    None => mesh::tetmesh::tet_quality(mesh, reference)?,
                };
                if q.inverted > 0 {
                    bail!("{} inverted tetrahedra", q.inverted);
                }
                lines.push(format!("dihedral   min {:.1}°, max {:.1}°", q.min_dihedral_deg, q.max_dihedral_deg));
                lines.extend(tet_mesh_warnings(&q).into_iter().map(|w| format!("warning    {w}")));
                let pinched = mesh::pinch::pinched_edge_count(mesh);
                if pinched > 0 {
                    lines.push(format!(
                        "warning    {pinched} edge(s) of its surface are shared by four triangles (two tetrahedra meet \
                         there along an edge only): surface tools refuse such a surface (.stl, .obj); mesh with \
                         another --tets"
                    ));
                }
                volume_line(q.volume, q.reference_volume)
            }
            mesh::Cells::Tet10(_) => volume_line(mesh.volume(), reference),
            mesh::Cells::Hex8(_) => {
                let (organ, cut) = immersed_fill(mesh);
                lines.push(format!("cells      {} fully inside, {cut} cut by the surface", mesh.cells.len() - cut));
                volume_line(organ, reference)
            }
        };
        lines.push(volume);
        lines.extend(mesh.regions.iter().map(|(name, nodes)| format!("region     {name}: {} nodes", nodes.len())));
        Ok(lines)
    }
}

/// The volume's line, against the domain's when known.
fn volume_line(volume: f64, reference: Option<f64>) -> String {
    match reference {
        Some(r) => format!("volume     {volume:.4e} m³ (domain {r:.4e} m³, {:+.2} %)", 100.0 * (volume - r) / r),
        None => format!("volume     {volume:.4e} m³"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn phantom(immersed: Option<f64>) -> MeshOptions {
        let immersed = immersed.map(Length::metres);
        MeshOptions { surface: None, label: None, length: None, units: None, repair: true, tets: 800, immersed }
    }

    #[test]
    fn a_mesh_that_leaves_out_part_of_its_surface_is_warned_about() {
        let lost = Coverage { distance: 0.005, uncovered: 0.097, farthest: 0.027 };
        let warning = coverage_warning(&lost).unwrap();
        assert!(warning.starts_with("9.7 % of the surface lies more than 5.0 mm from the mesh (up to 27.0 mm)"));
        assert_eq!(coverage_warning(&Coverage { uncovered: 0.005, ..lost }), None);
    }

    #[test]
    fn an_immersed_phantom_fills_about_its_volume_and_keeps_its_fractions() {
        let meshed = mesh_organ(&phantom(Some(0.02))).unwrap();
        let (organ, cut) = immersed_fill(&meshed.mesh);
        let reference = meshed.reference_volume.unwrap();
        assert!((organ - reference).abs() < 0.1 * reference, "{organ} vs {reference}");
        assert!(cut > 0 && cut < meshed.mesh.cells.len());
        let report = meshed.report().unwrap();
        let fill = format!("cells      {} fully inside, {cut} cut by the surface", meshed.mesh.cells.len() - cut);
        assert_eq!(report[2], fill, "{report:?}");
        assert!(report[3].starts_with("volume     ") && report[3].contains("domain"), "{report:?}");
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("grid/organ.vtu");
        assert_eq!(write_mesh_file(&path, &meshed.mesh, meshed.frame).unwrap(), "in m");
        let (read, fields) = mesh::io::read_mesh_with_fields(&path).unwrap();
        assert!(fields.iter().any(|f| f.name == "volume_fraction"));
        // Read back, the grid keeps its fractions (the FEM weighs each cell by its own).
        assert_eq!(read.cell_fraction, meshed.mesh.cell_fraction);
        assert_eq!(immersed_fill(&read), (organ, cut));
        // Gmsh's format has no place for them: refused, not written without.
        let msh = dir.path().join("grid/organ.msh");
        let e = write_mesh_file(&msh, &meshed.mesh, meshed.frame).unwrap_err().to_string();
        assert!(e.contains("volume fractions have no place in Gmsh's format") && !msh.exists(), "{e}");
    }

    #[test]
    fn a_surface_in_millimetres_or_centimetres_is_meshed_in_metres_and_a_wrong_label_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let sphere = mesh::generate::icosphere(40.0, 2);
        let path = dir.path().join("ball.stl");
        mesh::io::write_surface(&path, &sphere).unwrap();
        let options = MeshOptions { surface: Some(path.clone()), repair: false, ..phantom(None) };
        let meshed = mesh_organ(&options).unwrap();
        let (lo, hi) = meshed.mesh.bounds();
        assert!((hi[0] - lo[0] - 0.08).abs() < 0.01, "{lo:?} {hi:?}");
        let report = meshed.report().unwrap();
        assert!(report[2].starts_with("dihedral   min "), "{report:?}");
        assert!(meshed.notes.iter().any(|(topic, line)| *topic == "units" && line.starts_with("mm (detected")));
        assert!(!meshed.notes.iter().any(|(topic, _)| *topic == "warning"), "{:?}", meshed.notes);
        // A liver in cm is 20 to 60 across, as a small organ in mm: taken as mm, and named.
        let liver_cm = dir.path().join("liver_cm.stl");
        mesh::io::write_surface(&liver_cm, &mesh::generate::icosphere(12.0, 2)).unwrap();
        let notes = mesh_organ(&MeshOptions { surface: Some(liver_cm), tets: 200, ..options.clone() }).unwrap().notes;
        assert!(
            notes.iter().any(|(topic, line)| *topic == "warning"
                && line.contains("is 24 mm across: if its file is in centimetres (240 mm")),
            "{notes:?}"
        );
        // A unit given that makes no organ of it is warned about; a size in cm is named so.
        let in_metres = MeshOptions { units: Some(LengthUnit::Metre), tets: 200, ..options.clone() };
        let warned = mesh_organ(&in_metres).unwrap().notes;
        assert!(warned.contains(&(
            "warning",
            "in m the organ is 80000 mm across, where organs are 20 to 600 mm: is the unit right? (in millimetres? \
             give --units mm)"
                .into()
        )));
        // One in m read as mm: its size said to the digits that show it, not rounded to 0.
        let metres = dir.path().join("ball_m.stl");
        mesh::io::write_surface(&metres, &mesh::generate::icosphere(0.06, 2)).unwrap();
        let mut input = OrganInput::read(&metres, None, Some(LengthUnit::Millimetre)).unwrap();
        input.unit().unwrap();
        let said = input.notes.iter().find(|(topic, _)| *topic == "warning").map(|n| n.1.as_str()).unwrap_or("");
        assert!(said.starts_with("in mm the organ is 0.1"), "{said}");
        let centimetres = dir.path().join("ball_cm.stl");
        mesh::io::write_surface(&centimetres, &mesh::generate::icosphere(4.0, 2)).unwrap();
        let e = mesh_organ(&MeshOptions { surface: Some(centimetres.clone()), ..options.clone() }).unwrap_err();
        assert!(format!("{e:#}").contains("give --units (m, cm, mm or um) (in centimetres? give --units cm)"), "{e:#}");
        let given = MeshOptions { surface: Some(centimetres), units: Some(LengthUnit::Centimetre), ..options.clone() };
        let (lo, hi) = mesh_organ(&given).unwrap().mesh.bounds();
        assert!((hi[0] - lo[0] - 0.08).abs() < 0.01, "a 4 cm ball in cm: {lo:?} {hi:?}");
        let labelled = MeshOptions { label: Some("5".into()), ..options };
        assert!(mesh_organ(&labelled).unwrap_err().to_string().contains("--label 5 chooses a label of a labelmap"));
        let folder = MeshOptions { surface: Some(dir.path().to_path_buf()), ..labelled };
        assert!(mesh_organ(&folder)
            .unwrap_err()
            .to_string()
            .contains("a folder, not a file (a DICOM series is not read)"));
    }

    #[test]
    fn a_mesh_gives_back_its_boundary_surface_in_millimetres_in_the_frame_its_input_names() {
        let dir = tempfile::tempdir().unwrap();
        let mut ball = mesh::generate::icosphere(40.0, 2);
        ball.transform([60.0, -120.0, -30.0], 1.0);
        let path = dir.path().join("ball_lps.stl");
        mesh::io::write_surface_in_frame(&path, &ball, Frame::Lps).unwrap();
        let options = MeshOptions { surface: Some(path), repair: false, ..phantom(None) };
        let meshed = mesh_organ(&options).unwrap();
        assert_eq!(meshed.frame, Some(Frame::Lps));
        let out = dir.path().join("new/out.stl");
        assert_eq!(
            write_mesh_file(&out, &meshed.mesh, meshed.frame).unwrap(),
            "its boundary surface, in mm, frame LPS named"
        );
        let (back, frame) = mesh::io::read_surface_with_frame(&out).unwrap();
        assert_eq!(frame, Some(Frame::Lps));
        let named_obj = dir.path().join("out_lps.obj");
        assert_eq!(
            write_mesh_file(&named_obj, &meshed.mesh, meshed.frame).unwrap(),
            "its boundary surface, in mm, frame LPS named"
        );
        let (obj_back, obj_frame) = mesh::io::read_surface_with_frame(&named_obj).unwrap();
        assert_eq!((obj_back.triangles, obj_frame), (back.triangles.clone(), Some(Frame::Lps)));
        let (lo, hi) = mesh::bounds(&back.vertices);
        for k in 0..3 {
            let centre = [-60.0, 120.0, 30.0][k];
            assert!(
                (hi[k] - lo[k] - 80.0).abs() < 8.0 && ((hi[k] + lo[k]) / 2.0 - centre).abs() < 1.0,
                "{lo:?} {hi:?}"
            );
        }
        // A volume mesh names it in a .vtu's field data and a .vtk's title; a .msh cannot.
        for (name, said) in [
            ("out.vtu", "in m, frame LPS named; for 3D Slicer, which reads models in mm, write .stl or .obj"),
            ("out.vtk", "in m, frame LPS named; for 3D Slicer, which reads models in mm, write .stl or .obj"),
            ("out.msh", "in m, in LPS: Gmsh's format names no frame"),
        ] {
            assert_eq!(write_mesh_file(&dir.path().join(name), &meshed.mesh, meshed.frame).unwrap(), said);
        }
        assert_eq!(mesh::io::surface_frame(dir.path().join("out.vtk")).unwrap(), Some(Frame::Lps));
        let (vtk, _) = mesh::io::read_mesh_with_fields(dir.path().join("out.vtk")).unwrap();
        assert_eq!(vtk.cells.len(), meshed.mesh.cells.len());
        // Fitted to a length, it is no longer where its input was: no frame named.
        let fitted = mesh_organ(&MeshOptions { length: Some(Length::metres(0.1)), ..options }).unwrap();
        assert_eq!(fitted.frame, None);
        let obj = dir.path().join("out.obj");
        assert_eq!(write_mesh_file(&obj, &fitted.mesh, fitted.frame).unwrap(), "its boundary surface, in mm");
        let extent = largest_extent(&mesh::io::read_surface(&obj).unwrap());
        assert!((extent - 100.0).abs() < 1.0, "{extent}");
    }
}
