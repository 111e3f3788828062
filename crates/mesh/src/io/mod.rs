//! Mesh and surface file input and output.
//!
//! Volume meshes ([`Mesh`]) are read from Gmsh `.msh` (legacy `$NOD`/`$ELM`, 2.x ASCII and
//! 4.1 ASCII), legacy VTK `.vtk` (ASCII or big-endian binary `UNSTRUCTURED_GRID`), VTK XML
//! `.vtu` and Abaqus or CalculiX input decks `.inp` ([`read_inp`]). Only tetrahedra (linear or
//! quadratic) or trilinear hexahedra are kept (lower-dimensional cells are ignored); nodes not
//! used by any kept cell are dropped and the rest renumbered in file order, the file's own node
//! numbers kept in [`Mesh::file_nodes`]; every cell is turned positively oriented (mirrored cells
//! are flipped), and a cell of zero volume is an error, as is a cell inverted among cells turned
//! the other way that, flipped, would overlap a neighbour (a tangled mesh).
//!
//! Surfaces ([`TriSurface`]) are read from `.obj`, `.stl` (ASCII or binary, duplicate vertices
//! merged exactly), `.ply` (ASCII or binary), legacy VTK `.vtk` (`POLYDATA` or
//! `UNSTRUCTURED_GRID`), `.vtp` and `.vtu`; polygons are split into triangle fans and triangle
//! strips into triangles. All vertices are kept.
//!
//! The frame a surface file names (`SPACE=LPS` or `SPACE=RAS` where 3D Slicer writes it: in an
//! STL, OBJ, PLY or legacy VTK header, in a `.vtp` or `.vtu` file's field data) is read by
//! [`read_surface_with_frame`] and written by
//! [`write_surface_in_frame`]; points with labels, frame and unit (CSV, Slicer's `.fcsv` and
//! `.mrk.json`) by the [`points`] module. Every CSV file of the project is read and written by
//! the [`csv`] module, every NumPy `.npy` array (datasets, clouds, predictions) by [`npy`].
//!
//! Writers ([`write_vtu`], [`write_vtk_legacy`], [`write_msh`], [`write_surface`]) go through
//! [`write_atomic`] (a temporary file in the target directory, renamed onto the target), so a
//! reader never sees a partial file; the other crates write their files with it too.
//! Numbers are written in their shortest exact decimal form (ASCII) or as IEEE doubles (binary):
//! reading back gives the same values. `cell_fraction` and `node_normals` are not written; pass
//! them as [`Field`]s where needed.
//!
//! # Named regions
//!
//! The named node sets of [`Mesh::regions`] are read from and written to every volume format, so
//! that a region painted in ParaView, 3D Slicer or Gmsh can be used:
//!
//! - `.vtu` and `.vtk`: a one-component point array named `region_<name>` is region `<name>`: the
//!   nodes whose value is non-zero, precisely whose absolute value is over 0.5 (so a 0/1 mask
//!   stored as floats or integers, or a 0/255 mask, works). An array with no such node makes no
//!   region. A one-component point array named `regions` or `region` holds a label per node, as
//!   a painting tool gives it: each non-zero label `k` (the value rounded to an integer) makes
//!   region `label_<k>`. Two arrays giving the same region name add their nodes up. Other
//!   arrays, cell arrays and arrays of several components make no region. The region arrays are
//!   still returned as fields by [`read_vtu_with_fields`] and [`read_vtk_with_fields`].
//!   [`region_fields`] gives the `region_<name>` 0/1 arrays of a mesh's regions; [`write_mesh`]
//!   adds them to the fields it writes (so that reading its file back gives the same non-empty
//!   regions), while [`write_vtu`] and [`write_vtk_legacy`] write only the fields they are given.
//! - `.msh`: the physical groups of the elements of any dimension (points, lines, surfaces,
//!   volumes) are regions: named by `$PhysicalNames` when it names the group, else
//!   `physical_<tag>`, each holding the nodes of the group's elements (groups of the same name add
//!   their nodes up). The physical group of an element is its first tag (2.x; 0 is none), its
//!   physical region (legacy) or that of its entity in `$Entities` (4.1). A volume group that holds
//!   every volume element is the whole mesh, not a region (Gmsh gives one to any volume mesh). A
//!   name shared by a volume group and groups of lower dimension is split by dimension
//!   (`liver_volume`, `liver_surface`, `_curve`, `_point`), so that neither is taken for the other.
//!   [`write_msh`] writes each non-empty region as a named 0-dimensional physical group of point
//!   elements, one per node, which Gmsh opens and which is read back as the same region.
//!
//! - `.inp`: node sets and element sets (the nodes of their elements); see [`read_inp`].
//!
//! Region nodes are mesh nodes: nodes that the reader drops (used by no volume cell) are left out
//! of the regions, and the rest are renumbered with the mesh. A region with no node is not read.

mod abaqus;
pub mod csv;
mod frame;
mod gmsh;
mod legacy_vtk;
pub mod npy;
mod ply;
pub mod points;
mod scalar;
mod surface_io;
mod text;
mod vtk_xml;

use std::borrow::Cow;
use std::collections::BTreeMap;
use std::fmt;
use std::fs::{self, File};
use std::io::{BufWriter, Write as _};
use std::path::{Path, PathBuf};

use crate::{Cells, Mesh, MeshError, Point, TriSurface, HEX_TO_TETS};

pub use abaqus::read_inp;
pub use csv::csv_field;
pub use frame::{
    frame_in_header, read_surface_noted, read_surface_with_frame, surface_frame, surface_unit, write_surface_in_frame,
    Frame, FrameChange, GivenCoordinates,
};
pub use gmsh::{read_gmsh, write_msh};
pub use legacy_vtk::{read_vtk, read_vtk_surface, read_vtk_with_fields, write_vtk_legacy, write_vtk_legacy_with};
pub use ply::write_ply_points;
pub use scalar::Scalar;
pub use surface_io::{read_obj, read_stl, write_obj, write_stl};
pub use vtk_xml::{read_vtu, read_vtu_with_fields, write_vtu, write_vtu_in_frame, write_vtu_with};

/// Prefix of the name of a point field that holds a region (see the [module](self) documentation).
pub const REGION_FIELD_PREFIX: &str = "region_";

/// The regions of a mesh as one-component point fields named `region_<name>`, 1 at the nodes of
/// the region and 0 elsewhere, in name order: what [`write_mesh`] adds to a `.vtu` or `.vtk` file,
/// and what to pass to [`write_vtu`] or [`write_vtk_legacy`] to keep the regions (a `.msh` file
/// carries them itself: see [`write_msh`]). Characters not allowed in a VTK array name
/// (whitespace, control characters, quotes and `<>&`) become `_`; two names that become the same
/// make the writer fail. Node indices out of range are left out.
pub fn region_fields(mesh: &Mesh) -> Vec<Field> {
    mesh.regions
        .iter()
        .map(|(name, set)| {
            let mut values = vec![0.0; mesh.num_nodes()];
            for &i in set {
                if let Some(v) = values.get_mut(i) {
                    *v = 1.0;
                }
            }
            let name: String = name.chars().map(|c| if bad_name_char(c) { '_' } else { c }).collect();
            Field::point(format!("{REGION_FIELD_PREFIX}{name}"), 1, values)
        })
        .collect()
}

/// Whether `c` may not appear in a VTK array name: whitespace, control characters, quotes and `<>&`.
fn bad_name_char(c: char) -> bool {
    c.is_whitespace() || c.is_control() || "\"'<>&".contains(c)
}

/// `fields` and, after them, the [`region_fields`] of `mesh` whose names no point field of
/// `fields` has.
fn with_region_fields<'a>(mesh: &Mesh, fields: &'a [Field]) -> Cow<'a, [Field]> {
    if mesh.regions.is_empty() {
        return Cow::Borrowed(fields);
    }
    let given = |f: &Field| fields.iter().any(|g| g.location == FieldLocation::Point && g.name == f.name);
    let missing: Vec<Field> = region_fields(mesh).into_iter().filter(|f| !given(f)).collect();
    if missing.is_empty() {
        return Cow::Borrowed(fields);
    }
    Cow::Owned(fields.iter().cloned().chain(missing).collect())
}

/// Whether every field is one of the [`region_fields`] of `mesh`.
fn is_region_fields_of(mesh: &Mesh, fields: &[Field]) -> bool {
    let regions = region_fields(mesh);
    fields.iter().all(|f| regions.contains(f))
}

/// The regions held by point fields, as read from `.vtu` and `.vtk` files: `region_<name>` masks
/// and `regions` (or `region`) label arrays (see the [module](self) documentation). Each region's
/// nodes are sorted; regions with no node are left out.
pub fn regions_from_fields(fields: &[Field]) -> BTreeMap<String, Vec<usize>> {
    let mut regions: BTreeMap<String, Vec<usize>> = BTreeMap::new();
    for f in fields.iter().filter(|f| f.location == FieldLocation::Point && f.components == 1) {
        if let Some(name) = f.name.strip_prefix(REGION_FIELD_PREFIX).filter(|n| !n.is_empty()) {
            let set: Vec<usize> = (0..f.values.len()).filter(|&i| f.values[i].abs() > 0.5).collect();
            if !set.is_empty() {
                regions.entry(name.to_string()).or_default().extend(set);
            }
        } else if f.name == "regions" || f.name == "region" {
            for (i, &v) in f.values.iter().enumerate() {
                let label = v.round();
                if label != 0.0 && label.is_finite() {
                    regions.entry(format!("label_{label}")).or_default().push(i);
                }
            }
        }
    }
    for set in regions.values_mut() {
        set.sort_unstable();
        set.dedup();
    }
    regions
}

/// Name of the one-component cell field that holds an immersed grid's cell fractions
/// ([`Mesh::cell_fraction`]), as `augsim mesh --immersed` writes it to `.vtu` and `.vtk`.
pub const FRACTION_FIELD: &str = "volume_fraction";

/// The cell fractions held by a [`FRACTION_FIELD`] cell field of `fields`, if any; an error for
/// a fraction outside [0, 1] (not a share of a cell's volume).
fn fractions_from_fields(fields: &[Field]) -> Result<Option<Vec<f64>>, String> {
    let Some(f) = fields.iter().find(|f| f.location == FieldLocation::Cell && f.name == FRACTION_FIELD) else {
        return Ok(None);
    };
    match f.values.iter().position(|v| !(0.0..=1.0).contains(v)) {
        _ if f.components != 1 => Err(format!("cell array '{FRACTION_FIELD}' has {} components, not 1", f.components)),
        Some(i) => Err(format!(
            "cell array '{FRACTION_FIELD}' holds {} at cell {i}: a cell's share of material is within [0, 1]",
            f.values[i]
        )),
        None => Ok(Some(f.values.clone())),
    }
}

/// Where the values of a [`Field`] live.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FieldLocation {
    /// One tuple per node.
    Point,
    /// One tuple per cell.
    Cell,
}

/// A named array of values attached to the nodes or the cells of a mesh, written as VTK point
/// or cell data. Values are stored tuple after tuple: `values[i * components + c]`.
#[derive(Clone, Debug, PartialEq)]
pub struct Field {
    /// Array name: non-empty, without whitespace, quotes or `<>&`.
    pub name: String,
    /// Nodes or cells.
    pub location: FieldLocation,
    /// Components per tuple (1 for a scalar, 3 for a vector).
    pub components: usize,
    /// `components` values per node or cell.
    pub values: Vec<f64>,
}

impl Field {
    /// A point field with `components` values per node.
    pub fn point(name: impl Into<String>, components: usize, values: Vec<f64>) -> Self {
        Field { name: name.into(), location: FieldLocation::Point, components, values }
    }

    /// A cell field with `components` values per cell.
    pub fn cell(name: impl Into<String>, components: usize, values: Vec<f64>) -> Self {
        Field { name: name.into(), location: FieldLocation::Cell, components, values }
    }

    /// A 3-component point field from one vector per node (e.g. a displacement).
    pub fn point_vectors(name: impl Into<String>, vectors: &[Point]) -> Self {
        Field::point(name, 3, vectors.iter().flatten().copied().collect())
    }

    /// Number of tuples (`values.len() / components`).
    pub fn num_tuples(&self) -> usize {
        self.values.len().checked_div(self.components).unwrap_or(0)
    }

    /// The tuple at index `i` (panics when `i >= num_tuples()`).
    pub fn tuple(&self, i: usize) -> &[f64] {
        &self.values[i * self.components..(i + 1) * self.components]
    }

    /// Checks the name, the component count and the length against a mesh of `num_points` nodes
    /// and `num_cells` cells.
    pub fn check(&self, num_points: usize, num_cells: usize) -> Result<(), MeshError> {
        if self.name.is_empty() || self.name.chars().any(bad_name_char) {
            return Err(MeshError::Invalid(format!(
                "field name {:?} is empty or holds whitespace, quotes or <>& (not allowed in VTK files)",
                self.name
            )));
        }
        if self.components == 0 {
            return Err(MeshError::Invalid(format!("field '{}' has 0 components", self.name)));
        }
        let (count, what) = match self.location {
            FieldLocation::Point => (num_points, "nodes"),
            FieldLocation::Cell => (num_cells, "cells"),
        };
        if Some(self.values.len()) != count.checked_mul(self.components) {
            return Err(MeshError::Invalid(format!(
                "field '{}' has {} values, but {} {what} × {} components need {}",
                self.name,
                self.values.len(),
                count,
                self.components,
                count.saturating_mul(self.components)
            )));
        }
        Ok(())
    }
}

/// How array data is stored in a VTK file.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Encoding {
    /// Human-readable decimal text (shortest exact form).
    Ascii,
    /// Binary doubles: base64 in `.vtu`, big-endian in legacy `.vtk`.
    #[default]
    Binary,
}

/// The extensions [`read_mesh`] reads, for messages.
const VOLUME_EXTENSIONS: &str = "expected .msh, .vtk, .vtu or .inp";

/// Reads a volume mesh, choosing the format by extension: `.msh` (Gmsh), `.vtk` (legacy VTK),
/// `.vtu` (VTK XML), `.inp` (an Abaqus or CalculiX input deck).
pub fn read_mesh(path: impl AsRef<Path>) -> Result<Mesh, MeshError> {
    let path = path.as_ref();
    let read = match extension(path).as_str() {
        "msh" => read_gmsh(path),
        "inp" => read_inp(path),
        "vtk" => read_vtk(path),
        "vtu" => read_vtu(path),
        _ => return Err(MeshError::parse(path, format!("unknown volume mesh extension ({VOLUME_EXTENSIONS})"))),
    };
    read.map_err(|e| named_if_lfs(path, e))
}

/// Reads a volume mesh and its point and cell data (`.vtk`, `.vtu`; a `.msh` or `.inp` file gives
/// no fields).
pub fn read_mesh_with_fields(path: impl AsRef<Path>) -> Result<(Mesh, Vec<Field>), MeshError> {
    let path = path.as_ref();
    let read = match extension(path).as_str() {
        "msh" => read_gmsh(path).map(|m| (m, Vec::new())),
        "inp" => read_inp(path).map(|m| (m, Vec::new())),
        "vtk" => read_vtk_with_fields(path),
        "vtu" => read_vtu_with_fields(path),
        _ => return Err(MeshError::parse(path, format!("unknown volume mesh extension ({VOLUME_EXTENSIONS})"))),
    };
    read.map_err(|e| named_if_lfs(path, e))
}

/// Writes a volume mesh and its regions, choosing the format by extension: `.vtu` and `.vtk`
/// (binary, with the fields, and the [`region_fields`] of the regions that `fields` does not
/// already hold under the same name) or `.msh` (Gmsh 2.2 ASCII, with the regions as physical
/// groups; it takes no fields but the mesh's own [`region_fields`]). Reading the file back gives
/// the same non-empty regions. [`write_vtu`] and [`write_vtk_legacy`] write only the fields given.
pub fn write_mesh(path: impl AsRef<Path>, mesh: &Mesh, fields: &[Field]) -> Result<(), MeshError> {
    let path = path.as_ref();
    match extension(path).as_str() {
        "vtu" => write_vtu(path, mesh, &with_region_fields(mesh, fields)),
        "vtk" => write_vtk_legacy(path, mesh, &with_region_fields(mesh, fields)),
        "msh" if fields.is_empty() => write_msh(path, mesh),
        "msh" if is_region_fields_of(mesh, fields) => write_msh(path, mesh),
        "msh" => Err(MeshError::Invalid(format!(
            "{}: Gmsh output carries no fields; write .vtu or .vtk to keep them",
            path.display()
        ))),
        _ => Err(MeshError::parse(path, "unknown volume mesh extension (expected .vtu, .vtk or .msh)")),
    }
}

/// [`write_mesh`], naming the mesh's frame when known: a `.vtu` in its field data
/// ([`write_vtu_in_frame`]), a `.vtk` in its title (`augsim SPACE=LPS`); Gmsh's `.msh` has no
/// place for it.
pub fn write_mesh_in_frame(
    path: impl AsRef<Path>,
    mesh: &Mesh,
    fields: &[Field],
    frame: Option<Frame>,
) -> Result<(), MeshError> {
    let path = path.as_ref();
    match (extension(path).as_str(), frame) {
        ("vtu", Some(frame)) => write_vtu_in_frame(path, mesh, &with_region_fields(mesh, fields), frame),
        ("vtk", Some(frame)) => legacy_vtk::write_vtk_legacy_titled(
            path,
            mesh,
            &with_region_fields(mesh, fields),
            Encoding::Binary,
            &format!("augsim SPACE={frame}"),
        ),
        _ => write_mesh(path, mesh, fields),
    }
}

/// The extensions [`read_surface`] reads.
pub const SURFACE_EXTENSIONS: [&str; 6] = ["obj", "stl", "ply", "vtk", "vtp", "vtu"];

/// The error of a surface reader given another extension.
const UNKNOWN_SURFACE: &str = "unknown surface extension (expected .obj, .stl, .ply, .vtk, .vtp or .vtu)";

/// Reads a triangle surface, choosing the format by extension: `.obj`, `.stl`, `.ply` (its
/// faces), `.vtk`, `.vtp`, `.vtu`.
pub fn read_surface(path: impl AsRef<Path>) -> Result<TriSurface, MeshError> {
    read_surface_noting(path.as_ref()).map(|(surface, _)| surface)
}

/// [`read_surface`], with what a user should know of the file as read (a binary STL's count that
/// its size belies: [`surface_io::read_stl_noting`]).
fn read_surface_noting(path: &Path) -> Result<(TriSurface, Vec<String>), MeshError> {
    let plain = |read: Result<TriSurface, MeshError>| read.map(|surface| (surface, Vec::new()));
    let read = match extension(path).as_str() {
        "obj" => plain(read_obj(path)),
        "stl" => surface_io::read_stl_noting(path),
        "ply" => plain(ply::read_ply_surface(path)),
        "vtk" => plain(read_vtk_surface(path)),
        "vtp" | "vtu" => plain(vtk_xml::read_xml_surface(path)),
        _ => return Err(MeshError::parse(path, UNKNOWN_SURFACE)),
    };
    read.map_err(|e| named_if_lfs(path, e))
}

/// The points of a surface or mesh file whatever its cells, as a point cloud saved in one of
/// these formats has them: `.obj` (its `v` lines), `.stl` (its triangles' corners, each shared one
/// once), `.ply` (its `vertex` element), `.vtk` (the `POINTS` of any dataset), `.vtp` and `.vtu`
/// (their `<Points>`).
pub fn read_vertices(path: impl AsRef<Path>) -> Result<Vec<Point>, MeshError> {
    let path = path.as_ref();
    let read = match extension(path).as_str() {
        "obj" => surface_io::read_obj_vertices(path),
        "stl" => read_stl(path).map(|s| s.vertices),
        "ply" => ply::read_ply_vertices(path),
        "vtk" => legacy_vtk::read_vtk_points(path),
        "vtp" | "vtu" => vtk_xml::read_xml_points(path),
        _ => return Err(MeshError::parse(path, UNKNOWN_SURFACE)),
    };
    read.map_err(|e| named_if_lfs(path, e))
}

/// Writes a triangle surface, choosing the format by extension: `.vtu` (binary), `.vtk` (binary
/// `POLYDATA`), `.obj`, `.stl` (binary, single precision).
pub fn write_surface(path: impl AsRef<Path>, surface: &TriSurface) -> Result<(), MeshError> {
    let path = path.as_ref();
    match extension(path).as_str() {
        "vtu" => vtk_xml::write_surface_vtu(path, surface),
        "vtk" => legacy_vtk::write_surface_vtk(path, surface),
        "obj" => write_obj(path, surface),
        "stl" => write_stl(path, surface),
        _ => Err(MeshError::parse(path, "unknown surface extension (expected .vtu, .vtk, .obj or .stl)")),
    }
}

/// Lower-case extension of a path ("" when none).
pub fn extension(path: &Path) -> String {
    path.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase()
}

/// Reads a whole file, mapping failures to [`MeshError::Io`].
fn read_bytes(path: &Path) -> Result<Vec<u8>, MeshError> {
    fs::read(path).map_err(|error| MeshError::Io { path: path.display().to_string(), error })
}

/// An atomic write that failed: the file it was to write and why (see [`write_atomic`]).
#[derive(Debug, thiserror::Error)]
#[error("{}: {error}", path.display())]
pub struct WriteError {
    /// The file that was to be written.
    pub path: PathBuf,
    /// The underlying error.
    pub error: std::io::Error,
}

impl From<WriteError> for MeshError {
    fn from(e: WriteError) -> Self {
        MeshError::Io { path: e.path.display().to_string(), error: e.error }
    }
}

/// Writes `path` atomically, the one helper for every file augsim writes: `write` fills a temporary sibling
/// (`tempfile`'s named temporary file in the same directory, so the rename cannot cross file systems), which is
/// synced and persisted (renamed) over `path`, so a reader sees the old file or the new one, never a part.
/// Missing parent directories are created; the file gets ordinary permissions (`0o666` less the umask on Unix),
/// not the owner-only ones of a temporary file. On failure the temporary file is removed and `path` is left as it
/// was; the error names `path`.
pub fn write_atomic(
    path: &Path,
    write: impl FnOnce(&mut BufWriter<File>) -> std::io::Result<()>,
) -> Result<(), WriteError> {
    persist_atomic(path, write).map_err(|error| WriteError { path: path.to_path_buf(), error })
}

/// Creates the folder `dir` and the folders above it; an error names it, and the file in the
/// way when a file holds its name or that of a folder above it (an `--out` given a file).
pub fn create_folder(dir: &Path) -> Result<(), MeshError> {
    std::fs::create_dir_all(dir).map_err(|error| {
        let error = match dir.ancestors().find(|a| a.is_file()) {
            Some(file) if file == dir => std::io::Error::new(error.kind(), "a file, not a folder"),
            Some(file) => std::io::Error::new(error.kind(), format!("{} is a file, not a folder", file.display())),
            None => error,
        };
        MeshError::Io { path: dir.display().to_string(), error }
    })
}

/// Removes the temporary files an atomic write leaves when its process is killed mid-write
/// (`.NAME.XXXXXX.tmp`, `.NAME.XXXXXX.tmp.png`) in `dir` and the folders in it; returns how many.
/// For a job that resumes in `dir`, which it alone writes.
pub fn remove_stale_temporaries(dir: &Path) -> usize {
    let Ok(entries) = std::fs::read_dir(dir) else { return 0 };
    let mut removed = 0;
    for entry in entries.flatten() {
        let (path, name) = (entry.path(), entry.file_name().to_string_lossy().into_owned());
        if entry.file_type().is_ok_and(|t| t.is_dir()) {
            removed += remove_stale_temporaries(&path);
        } else if name.starts_with('.') && (name.ends_with(".tmp") || name.ends_with(".tmp.png")) {
            removed += usize::from(std::fs::remove_file(&path).is_ok());
        }
    }
    removed
}

/// [`write_atomic`] of a whole buffer.
pub fn write_atomic_bytes(path: &Path, bytes: &[u8]) -> Result<(), WriteError> {
    write_atomic(path, |w| w.write_all(bytes))
}

/// How a Git LFS pointer begins: the few lines Git keeps in place of a large file until it is
/// fetched.
pub(crate) const LFS_POINTER: &[u8] = b"version https://git-lfs.github.com/spec/";

/// `error`, a reader's on the file at `path`, or, when its bytes could not be understood because
/// the file is a Git LFS pointer, the error that says so (read on the error path only).
pub(crate) fn named_if_lfs(path: &Path, error: MeshError) -> MeshError {
    let MeshError::Parse { .. } = error else { return error };
    let mut start = [0u8; LFS_POINTER.len()];
    let read = std::fs::File::open(path).and_then(|mut f| std::io::Read::read(&mut f, &mut start));
    match read.is_ok_and(|n| start[..n].starts_with(LFS_POINTER)) {
        true => lfs_error(path),
        false => error,
    }
}

/// What a Git LFS pointer read in place of a file is, and what to do.
pub(crate) const LFS_MESSAGE: &str =
    "a Git LFS pointer, not the file itself (cloned without its large files): fetch it, e.g. with `git lfs pull`";

/// The error for a Git LFS pointer read in place of the file at `path`.
pub(crate) fn lfs_error(path: &Path) -> MeshError {
    MeshError::parse(path, LFS_MESSAGE)
}

/// The file `path` names, as a key that two names of one file share: made absolute, with `.` and
/// `..` taken as written, then with its links resolved (its folder's, where the file is not there
/// yet).
pub fn file_key(path: &Path) -> PathBuf {
    let absolute = std::path::absolute(path).unwrap_or_else(|_| path.into());
    let mut plain = PathBuf::new();
    for part in absolute.components() {
        match part {
            std::path::Component::CurDir => {}
            std::path::Component::ParentDir => {
                plain.pop();
            }
            other => plain.push(other),
        }
    }
    let in_folder = || Some(fs::canonicalize(plain.parent()?).ok()?.join(plain.file_name()?));
    fs::canonicalize(&plain).ok().or_else(in_folder).unwrap_or(plain)
}

/// The first of the files a run is to write (`written`, in order) that names a file it reads
/// (`read`) or one it writes before, with that other file: a write that would replace an input.
/// `None` where every file written is a file of its own.
pub fn overwritten<'a>(written: &[&'a Path], read: &[&'a Path]) -> Option<(&'a Path, &'a Path)> {
    let mut named: Vec<(PathBuf, &Path)> = read.iter().map(|&p| (file_key(p), p)).collect();
    for &w in written {
        let key = file_key(w);
        if let Some(&(_, other)) = named.iter().find(|(n, _)| *n == key) {
            return Some((w, other));
        }
        named.push((key, w));
    }
    None
}

/// Whether [`write_atomic`] could write `path`, checked before long work whose result it is to hold:
/// its directory is created and a temporary file made there (and removed), as the write would.
pub fn check_writable(path: &Path) -> Result<(), WriteError> {
    let error = |error| WriteError { path: path.to_path_buf(), error };
    if path.is_dir() {
        let message = format!("{} is a directory: name a file", path.display());
        return Err(error(std::io::Error::new(std::io::ErrorKind::IsADirectory, message)));
    }
    temporary_beside(path).map(drop).map_err(error)
}

/// A temporary file in `path`'s directory (created when missing; an error naming the part of the
/// path that is a file where a directory should be), with ordinary permissions.
fn temporary_beside(path: &Path) -> std::io::Result<tempfile::NamedTempFile> {
    let name =
        path.file_name().ok_or_else(|| std::io::Error::new(std::io::ErrorKind::InvalidInput, "not a file name"))?;
    let dir = match path.parent().filter(|d| !d.as_os_str().is_empty()) {
        Some(dir) => {
            if let Some(file) = dir.ancestors().find(|a| a.is_file()) {
                let message = format!("{} is a file, not a directory", file.display());
                return Err(std::io::Error::new(std::io::ErrorKind::NotADirectory, message));
            }
            fs::create_dir_all(dir)?;
            dir
        }
        None => Path::new("."),
    };
    let prefix = format!(".{}.", name.to_string_lossy());
    let mut builder = tempfile::Builder::new();
    builder.prefix(&prefix).suffix(".tmp");
    #[cfg(unix)]
    builder.permissions(std::os::unix::fs::PermissionsExt::from_mode(0o666));
    builder.tempfile_in(dir)
}

/// The body of [`write_atomic`], with the bare I/O error.
fn persist_atomic(path: &Path, write: impl FnOnce(&mut BufWriter<File>) -> std::io::Result<()>) -> std::io::Result<()> {
    // Dropped on an early return, the temporary file removes itself.
    let tmp = temporary_beside(path)?;
    let (file, tmp_path) = tmp.into_parts();
    let mut writer = BufWriter::new(file);
    write(&mut writer)?;
    let file = writer.into_inner().map_err(|e| e.into_error())?;
    file.sync_all()?;
    tempfile::NamedTempFile::from_parts(file, tmp_path).persist(path).map_err(|e| e.error)?;
    Ok(())
}

/// Displays an `f64` in its shortest form that parses back to the same value: plain notation for
/// ordinary magnitudes, scientific otherwise; `nan`, `inf` and `-inf` for non-finite values.
pub(crate) struct Num(pub(crate) f64);

impl fmt::Display for Num {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let (x, a) = (self.0, self.0.abs());
        if x.is_nan() {
            f.write_str("nan")
        } else if x.is_infinite() {
            f.write_str(if x > 0.0 { "inf" } else { "-inf" })
        } else if a == 0.0 || (1e-4..1e15).contains(&a) {
            write!(f, "{x}")
        } else {
            write!(f, "{x:e}")
        }
    }
}

/// The cells of a mesh as VTK cell type, nodes per cell and flat connectivity.
fn mesh_cells_flat(mesh: &Mesh) -> (u8, usize, Vec<usize>) {
    match &mesh.cells {
        Cells::Tet4(c) => (VTK_TETRA, 4, c.iter().flatten().copied().collect()),
        Cells::Hex8(c) => (VTK_HEXAHEDRON, 8, c.iter().flatten().copied().collect()),
        Cells::Tet10(c) => (VTK_QUADRATIC_TETRA, 10, c.iter().flatten().copied().collect()),
    }
}

/// Checks what a writer needs so that it cannot fail half-way: cell indices in range and
/// fields of the right length.
fn check_for_writing(num_points: usize, num_cells: usize, conn: &[usize], fields: &[Field]) -> Result<(), MeshError> {
    if let Some(&bad) = conn.iter().find(|&&k| k >= num_points) {
        return Err(MeshError::Invalid(format!("a cell refers to node {bad}, but there are {num_points} nodes")));
    }
    for (i, f) in fields.iter().enumerate() {
        f.check(num_points, num_cells)?;
        if fields[..i].iter().any(|g| g.name == f.name && g.location == f.location) {
            return Err(MeshError::Invalid(format!("two fields are named '{}'", f.name)));
        }
    }
    Ok(())
}

/// Checks a surface before writing: triangle indices in range.
fn check_surface(surface: &TriSurface) -> Result<Vec<usize>, MeshError> {
    let conn: Vec<usize> = surface.triangles.iter().flatten().copied().collect();
    check_for_writing(surface.vertices.len(), surface.triangles.len(), &conn, &[])?;
    Ok(conn)
}

/// VTK cell type of a set of vertices.
const VTK_POLY_VERTEX: u8 = 2;
/// VTK cell type of a polyline.
const VTK_POLY_LINE: u8 = 4;
/// VTK cell type of a triangle.
const VTK_TRIANGLE: u8 = 5;
/// VTK cell type of a triangle strip.
const VTK_TRIANGLE_STRIP: u8 = 6;
/// VTK cell type of a polygon.
const VTK_POLYGON: u8 = 7;
/// VTK cell type of a linear tetrahedron.
const VTK_TETRA: u8 = 10;
/// VTK cell type of an axis-aligned voxel (a hexahedron with another node order).
const VTK_VOXEL: u8 = 11;
/// VTK cell type of a trilinear hexahedron.
const VTK_HEXAHEDRON: u8 = 12;
/// VTK cell type of a quadratic tetrahedron (corners, then mid-edge nodes of 0-1, 1-2, 0-2,
/// 0-3, 1-3, 2-3).
const VTK_QUADRATIC_TETRA: u8 = 24;

/// The kind of volume cell read from a file.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum VolumeKind {
    Tet,
    Hex,
    Tet10,
}

impl VolumeKind {
    fn nodes(self) -> usize {
        match self {
            VolumeKind::Tet => 4,
            VolumeKind::Hex => 8,
            VolumeKind::Tet10 => 10,
        }
    }

    fn plural(self) -> &'static str {
        match self {
            VolumeKind::Tet => "tetrahedra",
            VolumeKind::Hex => "hexahedra",
            VolumeKind::Tet10 => "quadratic tetrahedra",
        }
    }
}

/// A cell whose volume is at most this share of its longest side cubed is flat (a regular
/// tetrahedron's is 0.118): its nodes are repeated or coplanar, to the digits the file prints.
const FLAT_CELL: f64 = 1e-8;

/// A volume mesh as read from a file, made into a [`Mesh`]: keeps the nodes used by the cells
/// (in file order), renumbers them, orients every cell positively and validates the result.
/// `conn` holds `kind.nodes()` indices into `file_nodes` per cell; `describe(i)` names cell `i`
/// for error messages; `numbers` are the file's numbers of its nodes (their positions, from 0,
/// when `None`) and `cell_numbers` those of the cells, kept in [`Mesh::file_nodes`] and
/// [`Mesh::file_cells`] where they are not the mesh's own. Returns the mesh and, for each mesh
/// node, its index in `file_nodes`.
fn finish_volume(
    path: &Path,
    file_nodes: &[Point],
    kind: VolumeKind,
    mut conn: Vec<usize>,
    describe: &dyn Fn(usize) -> String,
    numbers: Option<&[usize]>,
    cell_numbers: &[usize],
) -> Result<(Mesh, Vec<usize>), MeshError> {
    let k = kind.nodes();
    if conn.is_empty() {
        return Err(MeshError::parse(path, "no tetrahedra or hexahedra: not a volume mesh"));
    }
    let mut new_index = vec![usize::MAX; file_nodes.len()];
    for &i in &conn {
        new_index[i] = 0;
    }
    let mut kept = Vec::new();
    for (i, slot) in new_index.iter_mut().enumerate() {
        if *slot == 0 {
            *slot = kept.len();
            kept.push(i);
        }
    }
    let nodes: Vec<Point> = kept.iter().map(|&i| file_nodes[i]).collect();
    if let Some((i, fault)) = crate::coordinate_fault(nodes.iter().enumerate(), crate::MAX_COORDINATE) {
        let number = numbers.map_or(kept[i], |numbers| numbers[kept[i]]);
        return Err(MeshError::parse(path, format!("node {number} {fault}")));
    }
    for i in &mut conn {
        *i = new_index[*i];
    }
    let mut flipped = vec![false; conn.len() / k];
    for (c, cell) in conn.chunks_exact_mut(k).enumerate() {
        let p = |j: usize| nodes[cell[j]];
        let volume = match kind {
            VolumeKind::Tet | VolumeKind::Tet10 => crate::tet_volume(p(0), p(1), p(2), p(3)),
            VolumeKind::Hex => HEX_TO_TETS.iter().map(|t| crate::tet_volume(p(t[0]), p(t[1]), p(t[2]), p(t[3]))).sum(),
        };
        let size = crate::longest_side(crate::bounds(&cell.iter().map(|&i| nodes[i]).collect::<Vec<_>>()));
        let zero = volume.is_nan() || volume.abs() <= FLAT_CELL * size * size * size;
        if zero {
            return Err(MeshError::parse(
                path,
                format!("{} has zero volume ({volume:.3e}): its nodes are repeated or coplanar", describe(c)),
            ));
        }
        if volume < 0.0 {
            flipped[c] = true;
            match kind {
                VolumeKind::Tet => cell.swap(2, 3),
                // Corners 2 and 3 swap, and with them the mid-edge nodes of 1-2 and 1-3, 0-2 and 0-3.
                VolumeKind::Tet10 => [(2, 3), (5, 8), (6, 7)].into_iter().for_each(|(a, b)| cell.swap(a, b)),
                VolumeKind::Hex => {
                    let (bottom, top) = cell.split_at_mut(4);
                    bottom.swap_with_slice(top);
                }
            }
        }
    }
    let cells = match kind {
        VolumeKind::Tet => Cells::Tet4(conn.chunks_exact(4).map(|c| [c[0], c[1], c[2], c[3]]).collect()),
        VolumeKind::Hex => Cells::Hex8(conn.chunks_exact(8).map(|c| std::array::from_fn(|j| c[j])).collect()),
        VolumeKind::Tet10 => Cells::Tet10(conn.chunks_exact(10).map(|c| std::array::from_fn(|j| c[j])).collect()),
    };
    let mut mesh = Mesh::new(nodes, cells).map_err(|e| MeshError::parse(path, e.to_string()))?;
    check_untangled(path, &mesh, &flipped, describe)?;
    // The cells of the orientation fewer cells came in (none when all came one way).
    let turned = flipped.iter().filter(|&&f| f).count();
    if turned > 0 && turned < flipped.len() {
        let odd_are_turned = turned <= flipped.len() - turned;
        mesh.odd_cells = (0..flipped.len()).filter(|&c| flipped[c] == odd_are_turned).collect();
    }
    let numbered: Vec<usize> = match numbers {
        Some(numbers) => kept.iter().map(|&f| numbers[f]).collect(),
        None => kept.clone(),
    };
    let own = |numbers: &[usize]| numbers.iter().enumerate().all(|(i, &n)| i == n);
    if !own(&numbered) {
        mesh.file_nodes = Some(numbered);
    }
    if !own(cell_numbers) {
        mesh.file_cells = Some(cell_numbers.to_vec());
    }
    Ok((mesh, kept))
}

/// Refuses a mesh whose cells came in both orientations where, turned positive, one of the
/// fewer orientation overlaps a neighbour across their shared face: that cell was inverted (its
/// nodes moved through the neighbour), not written in the other convention, and turning it
/// leaves the mesh folded over itself (CalculiX stops on such a cell's negative Jacobian).
/// `flipped[c]`: cell `c` came with a negative volume.
fn check_untangled(
    path: &Path,
    mesh: &Mesh,
    flipped: &[bool],
    describe: &dyn Fn(usize) -> String,
) -> Result<(), MeshError> {
    let turned = flipped.iter().filter(|&&f| f).count();
    let fewer = turned.min(flipped.len() - turned);
    if fewer == 0 {
        return Ok(());
    }
    let odd = |c: usize| flipped[c] == (turned == fewer);
    let fold = crate::folded_faces(mesh).into_iter().find_map(|[a, b]| match (odd(a), odd(b)) {
        (true, false) => Some((a, b)),
        (false, true) => Some((b, a)),
        _ => None,
    });
    let Some((cell, other)) = fold else { return Ok(()) };
    Err(MeshError::parse(
        path,
        format!(
            "{} is inverted: its nodes turn the other way from {} of the mesh's {} cells, and turned round it folds \
             over {} across the face they share, so the mesh is tangled there; remesh it, or move that cell's nodes \
             back",
            describe(cell),
            flipped.len() - fewer,
            flipped.len(),
            describe(other),
        ),
    ))
}

/// Restricts fields read from a file to the kept nodes and cells of a mesh.
fn restrict_fields(fields: Vec<Field>, kept_nodes: &[usize], kept_cells: &[usize]) -> Vec<Field> {
    fields
        .into_iter()
        .map(|f| {
            let kept = match f.location {
                FieldLocation::Point => kept_nodes,
                FieldLocation::Cell => kept_cells,
            };
            let values = kept.iter().flat_map(|&i| f.tuple(i).to_vec()).collect();
            Field { values, ..f }
        })
        .collect()
}

/// Triangles of a polygon (fan from its first vertex) appended to `out`.
fn fan(polygon: &[usize], out: &mut Vec<[usize; 3]>) {
    for j in 1..polygon.len().saturating_sub(1) {
        out.push([polygon[0], polygon[j], polygon[j + 1]]);
    }
}

/// Triangles of a triangle strip appended to `out`, every other one flipped so that all share
/// the orientation of the first.
fn strip(vertices: &[usize], out: &mut Vec<[usize; 3]>) {
    for j in 0..vertices.len().saturating_sub(2) {
        let (a, b, c) = (vertices[j], vertices[j + 1], vertices[j + 2]);
        out.push(if j % 2 == 0 { [a, b, c] } else { [b, a, c] });
    }
}

/// Writes a ParaView collection (`.pvd`) of time steps: (time, file path relative to the
/// collection's directory) pairs, atomically; [`read_pvd`] reads it back.
pub fn write_pvd(path: impl AsRef<Path>, steps: &[(f64, String)]) -> Result<(), MeshError> {
    let path = path.as_ref();
    write_atomic(path, |w| {
        writeln!(w, "<?xml version=\"1.0\"?>")?;
        writeln!(w, "<VTKFile type=\"Collection\" version=\"0.1\" byte_order=\"LittleEndian\">")?;
        writeln!(w, "  <Collection>")?;
        for (t, file) in steps {
            let file = file.replace('&', "&amp;").replace('"', "&quot;").replace('<', "&lt;");
            writeln!(w, "    <DataSet timestep=\"{t}\" group=\"\" part=\"0\" file=\"{file}\"/>")?;
        }
        writeln!(w, "  </Collection>")?;
        writeln!(w, "</VTKFile>")
    })?;
    Ok(())
}

/// The time steps of a ParaView collection (`.pvd`): (time, file) pairs in the collection's
/// order, each file's path resolved against the collection's directory. A collection with no
/// `<DataSet>`, or one without its `file`, is an error; a step without `timestep` takes its
/// position as its time.
pub fn read_pvd(path: impl AsRef<Path>) -> Result<Vec<(f64, PathBuf)>, MeshError> {
    let path = path.as_ref();
    let data = read_bytes(path)?;
    let parse = |message: String| MeshError::parse(path, message);
    let head = vtk_xml::find_tag(&data, 0, "VTKFile").map(|lt| vtk_xml::tag_attributes(&data, lt)).transpose();
    let kind = head.map_err(&parse)?.and_then(|(attrs, _)| attrs.into_iter().find(|(k, _)| k == "type"));
    if kind.is_none_or(|(_, v)| v != "Collection") {
        return Err(parse("not a ParaView collection (no <VTKFile type=\"Collection\">)".into()));
    }
    let dir = path.parent().unwrap_or(Path::new(""));
    let mut steps = Vec::new();
    let mut from = 0;
    while let Some(lt) = vtk_xml::find_tag(&data, from, "DataSet") {
        let (attrs, end) = vtk_xml::tag_attributes(&data, lt).map_err(&parse)?;
        let attr = |key: &str| attrs.iter().find(|(k, _)| k == key).map(|(_, v)| v.as_str());
        let file = attr("file").ok_or_else(|| parse(format!("<DataSet> {} names no file", steps.len() + 1)))?;
        let time = match attr("timestep") {
            Some(t) => t
                .trim()
                .parse()
                .ok()
                .filter(|t: &f64| t.is_finite())
                .ok_or_else(|| parse(format!("timestep=\"{t}\" is not a number")))?,
            None => steps.len() as f64,
        };
        steps.push((time, dir.join(file)));
        from = end;
    }
    if steps.is_empty() {
        return Err(parse("the collection holds no <DataSet>".into()));
    }
    Ok(steps)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A collection written is read back with its times and files, the files found beside it; a
    /// file that is not a collection, or names no step, is refused.
    #[test]
    fn a_paraview_collection_reads_back_its_steps() {
        let dir = tempfile::tempdir().unwrap();
        let pvd = dir.path().join("organ.pvd");
        write_pvd(&pvd, &[(0.0, "organ_0000.vtu".into()), (0.5, "a \"b\".vtu".into())]).unwrap();
        let steps = read_pvd(&pvd).unwrap();
        assert_eq!(steps, [(0.0, dir.path().join("organ_0000.vtu")), (0.5, dir.path().join("a \"b\".vtu"))]);
        let grid = dir.path().join("grid.vtu");
        std::fs::write(&grid, "<VTKFile type=\"UnstructuredGrid\"><DataSet file=\"x.vtu\"/></VTKFile>").unwrap();
        assert!(read_pvd(&grid).unwrap_err().to_string().contains("not a ParaView collection"));
        let empty = dir.path().join("empty.pvd");
        std::fs::write(&empty, "<VTKFile type=\"Collection\"><Collection></Collection></VTKFile>").unwrap();
        assert!(read_pvd(&empty).unwrap_err().to_string().contains("holds no <DataSet>"));
        std::fs::write(&empty, "<VTKFile type=\"Collection\"><DataSet timestep=\"x\" file=\"a\"/></VTKFile>").unwrap();
        assert!(read_pvd(&empty).unwrap_err().to_string().contains("timestep=\"x\" is not a number"));
        std::fs::write(&empty, "<VTKFile type=\"Collection\"><DataSet timestep=\"nan\" file=\"a\"/></VTKFile>")
            .unwrap();
        assert!(read_pvd(&empty).unwrap_err().to_string().contains("timestep=\"nan\" is not a number"));
    }

    /// What a killed write leaves is removed, in the folders below too; other files are kept.
    #[test]
    fn stale_temporaries_are_removed() {
        let dir = tempfile::tempdir().unwrap();
        let shard = dir.path().join("shard_00001");
        std::fs::create_dir_all(&shard).unwrap();
        for name in [".model.json.Ab12Cd.tmp", "shard_00001/.inputs.npy.x1Y2z3.tmp", ".curve.png.q9W8e7.tmp.png"] {
            std::fs::write(dir.path().join(name), "").unwrap();
        }
        for name in ["model.json", "shard_00001/inputs.npy", ".hidden"] {
            std::fs::write(dir.path().join(name), "").unwrap();
        }
        assert_eq!(remove_stale_temporaries(dir.path()), 3);
        assert_eq!(remove_stale_temporaries(dir.path()), 0);
        let kept = ["model.json", "shard_00001/inputs.npy", ".hidden"];
        assert!(kept.iter().all(|name| dir.path().join(name).exists()));
    }

    /// A folder is made with the folders above it; a file in the way is named.
    #[test]
    fn a_file_in_a_folder_s_way_is_named() {
        let dir = tempfile::tempdir().unwrap();
        create_folder(&dir.path().join("a/b")).unwrap();
        assert!(dir.path().join("a/b").is_dir());
        std::fs::write(dir.path().join("f"), "").unwrap();
        let e = create_folder(&dir.path().join("f")).unwrap_err().to_string();
        assert!(e.ends_with("f: a file, not a folder"), "{e}");
        let e = create_folder(&dir.path().join("f/g")).unwrap_err().to_string();
        assert!(e.ends_with(&format!("f/g: {} is a file, not a folder", dir.path().join("f").display())), "{e}");
    }

    /// Every extension of [`SURFACE_EXTENSIONS`] has a reader (a missing file is an I/O error,
    /// not an unknown extension), and no other.
    #[test]
    fn the_surface_extensions_are_those_read() {
        let dir = tempfile::tempdir().unwrap();
        for extension in SURFACE_EXTENSIONS {
            let e = read_surface(dir.path().join(format!("missing.{extension}"))).unwrap_err();
            assert!(matches!(e, MeshError::Io { .. }), "{extension}: {e}");
        }
        let e = read_surface(dir.path().join("missing.off")).unwrap_err().to_string();
        assert!(e.contains("unknown surface extension"), "{e}");
    }

    /// Rows of points or vectors come from a float array of their width; a mask (uint8) or another
    /// shape is refused, saying what a row holds.
    #[test]
    fn rows_come_from_a_float_array_of_their_width() {
        let dir = tempfile::tempdir().unwrap();
        let (floats, mask) = (dir.path().join("f.npy"), dir.path().join("m.npy"));
        npy::write_f64(&floats, &[2, 3], &[1.0, 2.0, 3.0, 4.0, 5.0, 6.0]).unwrap();
        npy::write_u8(&mask, &[2, 3], &[0, 1, 1, 0, 1, 0]).unwrap();
        let rows = npy::read_npy(&floats).unwrap().into_rows::<3>(&floats, "x, y, z").unwrap();
        assert_eq!(rows, [[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]);
        let e = npy::read_npy(&floats).unwrap().into_rows::<6>(&floats, "x, y, z and a vector").unwrap_err();
        assert!(e.to_string().contains("expected an array of shape [N, 6] (x, y, z and a vector per row)"), "{e}");
        let e = npy::read_npy(&mask).unwrap().into_rows::<3>(&mask, "x, y, z").unwrap_err();
        assert!(e.to_string().contains("found uint8 or bool (a mask?)"), "{e}");
    }

    /// A Git LFS pointer in place of a surface, a mesh, a labelmap or an array is named as such, whatever
    /// its extension; a damaged file is not.
    #[test]
    fn a_git_lfs_pointer_is_named() {
        let dir = tempfile::tempdir().unwrap();
        let pointer = "version https://git-lfs.github.com/spec/v1\noid sha256:4d7a2146\nsize 12345\n";
        let names = [
            "organ.stl",
            "organ.vtk",
            "organ.vtu",
            "organ.ply",
            "mesh.vtk",
            "liver.nii",
            "liver.nrrd",
            "t.csv",
            "a.npy",
        ];
        for name in names {
            let path = dir.path().join(name);
            std::fs::write(&path, pointer).unwrap();
            let e = match name.rsplit_once('.').unwrap().1 {
                "nii" | "nrrd" => crate::labelmap::read_labelmap(&path).unwrap_err().to_string(),
                "csv" => points::read_points(&path).unwrap_err().to_string(),
                "npy" => npy::read_npy(&path).unwrap_err().to_string(),
                _ if name.starts_with("mesh") => read_mesh(&path).unwrap_err().to_string(),
                _ => read_surface(&path).unwrap_err().to_string(),
            };
            assert!(e.contains("a Git LFS pointer, not the file itself"), "{name}: {e}");
        }
        let e = npy::read_shape(&dir.path().join("a.npy")).unwrap_err().to_string();
        assert!(e.contains("a Git LFS pointer, not the file itself"), "{e}");
        let damaged = dir.path().join("damaged.vtk");
        std::fs::write(&damaged, "# vtk DataFile Version 3.0\n").unwrap();
        assert!(!read_mesh(&damaged).unwrap_err().to_string().contains("LFS"));
    }

    #[test]
    fn atomic_writes_replace_whole_files_and_leave_nothing_behind_on_failure() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("sub/out.txt");
        write_atomic_bytes(&path, b"first").unwrap();
        write_atomic(&path, |w| w.write_all(b"second")).unwrap();
        assert_eq!(fs::read(&path).unwrap(), b"second");
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            // The mode of an ordinary new file (0o666 less the umask), not a temporary file's owner-only 0o600.
            let plain = dir.path().join("plain");
            File::create(&plain).unwrap();
            let mode = |p: &Path| fs::metadata(p).unwrap().permissions().mode() & 0o777;
            assert_eq!(mode(&path), mode(&plain));
            fs::remove_file(&plain).unwrap();
        }
        let e = write_atomic(&path, |w| {
            w.write_all(b"partial")?;
            Err(std::io::Error::other("disk full"))
        })
        .unwrap_err();
        assert_eq!(e.to_string(), format!("{}: disk full", path.display()));
        assert_eq!(fs::read(&path).unwrap(), b"second", "the old file stays");
        let names: Vec<_> = fs::read_dir(path.parent().unwrap()).unwrap().map(|e| e.unwrap().file_name()).collect();
        assert_eq!(names, ["out.txt"], "no temporary file is left");
        let e = MeshError::from(write_atomic_bytes(dir.path(), b"x").unwrap_err());
        assert!(e.to_string().contains(&dir.path().display().to_string()), "{e}");
    }

    /// A path that cannot be written is found before the work whose result it is to hold, the
    /// part of it that is a file named; a writable one is left as it was, no file made.
    #[test]
    fn a_path_is_checked_writable_before_the_work() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("afile");
        fs::write(&file, b"x").unwrap();
        let e = check_writable(&file.join("deeper/out.vtu")).unwrap_err().to_string();
        assert!(e.contains(&format!("{} is a file, not a directory", file.display())), "{e}");
        let fine = dir.path().join("new/out.vtu");
        check_writable(&fine).unwrap();
        assert!(!fine.exists());
        let names: Vec<_> = fs::read_dir(dir.path().join("new")).unwrap().collect();
        assert!(names.is_empty(), "no temporary file is left");
        // A directory named as the file (`-o out.vtu` where a folder of that name is).
        let e = check_writable(&dir.path().join("new")).unwrap_err().to_string();
        assert!(e.contains("new is a directory: name a file"), "{e}");
    }
}
