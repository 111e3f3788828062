//! Meshes and geometry for augsim.
//!
//! Volume meshes are made of linear tetrahedra (T4), quadratic tetrahedra (T10) or trilinear
//! hexahedra (H8) and carry named node sets (regions). Coordinates are in metres.
//! Node numbering of an H8 cell follows VTK/Gmsh: the bottom face 0-1-2-3
//! counter-clockwise seen from above, then the top face 4-5-6-7; a T10 cell follows VTK:
//! its four corners, then the mid-edge nodes of edges 0-1, 1-2, 0-2, 0-3, 1-3, 2-3.

pub mod bvh;
pub mod decimate;
pub mod embedding;
pub mod generate;
pub mod immersed;
pub mod io;
pub mod isosurface;
pub mod labelmap;
pub mod length;
pub mod phantom;
pub mod pinch;
pub mod quadratic;
pub mod rebuild;
pub mod repair;
pub mod sampling;
pub mod select;
pub mod stats;
pub mod surface;
pub mod tetmesh;
pub mod topology;
pub mod volume;

use std::collections::BTreeMap;

pub use bvh::SurfaceBvh;
pub use embedding::{Embedding, Grid, Location, MeshLocator, MAX_CELL_NODES};
pub use generate::{box_hex, box_mesh, box_tet, icosphere};
pub use immersed::{immersed_grid, immersed_surface, ImmersedGrid, ImmersedOptions};
pub use phantom::{liver_phantom, PhantomSpec};
pub use quadratic::{tet10_shape, tet10_shape_derivatives, TET10_EDGES};
pub use sampling::{sample_visible, sample_visible_boundary, SurfaceSample};
pub use select::{boundary_node_areas, distance_holding_share, Ball, Camera, Near, NodeSelection, SpaceBall};
pub use surface::{check_closed_manifold, SurfaceReport};
pub use tetmesh::{
    mesh_surface, stuff, tet_quality, without_small_pieces, BoundaryFit, ImplicitDomain, SdfDomain, TetMeshOptions,
    TetQuality,
};
pub use topology::{
    boundary_faces, boundary_nodes, boundary_surface, face_connected_pieces, folded_faces, BoundaryFace,
};

/// A point or vector in 3D, in metres.
pub type Point = [f64; 3];

/// A triangle surface (closed or not), counter-clockwise seen from outside.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TriSurface {
    /// Vertex coordinates.
    pub vertices: Vec<Point>,
    /// Triangles as vertex indices.
    pub triangles: Vec<[usize; 3]>,
}

/// Errors of mesh construction, reading and writing.
#[derive(Debug, thiserror::Error)]
pub enum MeshError {
    /// An I/O failure on a named file.
    #[error("{path}: {error}")]
    Io {
        /// The file.
        path: String,
        /// The underlying error.
        error: std::io::Error,
    },
    /// A file that could be opened but not understood.
    #[error("{path}: {message}")]
    Parse {
        /// The file.
        path: String,
        /// What is wrong, with a line number where known.
        message: String,
    },
    /// A mesh whose content is inconsistent (bad index, degenerate cell, ...).
    #[error("invalid mesh: {0}")]
    Invalid(String),
    /// A file read as a volume mesh that holds a surface (VTK poly data).
    #[error("{path}: {dataset} holds a surface, not a volume mesh (read it as a surface)")]
    NotVolume {
        /// The file.
        path: String,
        /// What the file holds, as it names it (`DATASET POLYDATA`, `PolyData`).
        dataset: String,
    },
}

impl MeshError {
    /// A file at `path` that could not be understood: `message` says why.
    pub fn parse(path: &std::path::Path, message: impl Into<String>) -> MeshError {
        MeshError::Parse { path: path.display().to_string(), message: message.into() }
    }

    /// The error's text without the "invalid mesh: " prefix, for errors about an input that is
    /// not a mesh (a labelmap's label, a surface's voxels).
    pub fn message(&self) -> String {
        match self {
            MeshError::Invalid(m) => m.clone(),
            other => other.to_string(),
        }
    }
}

/// The cells of a volume mesh: all of one kind.
#[derive(Clone, Debug, PartialEq)]
pub enum Cells {
    /// Linear tetrahedra, positively oriented: (p1-p0)·((p2-p0)×(p3-p0)) > 0.
    Tet4(Vec<[usize; 4]>),
    /// Trilinear hexahedra in VTK order.
    Hex8(Vec<[usize; 8]>),
    /// Quadratic tetrahedra in VTK order: the corners of a positively oriented T4, then the
    /// mid-edge nodes of [`TET10_EDGES`].
    Tet10(Vec<[usize; 10]>),
}

/// The kind of a mesh's cells.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum CellKind {
    /// Linear tetrahedra.
    Tet4,
    /// Trilinear hexahedra.
    Hex8,
    /// Quadratic tetrahedra.
    Tet10,
}

impl CellKind {
    /// Short name ("T4", "H8" or "T10").
    pub fn name(self) -> &'static str {
        match self {
            CellKind::Tet4 => "T4",
            CellKind::Hex8 => "H8",
            CellKind::Tet10 => "T10",
        }
    }
}

impl Cells {
    /// Number of cells.
    pub fn len(&self) -> usize {
        match self {
            Cells::Tet4(c) => c.len(),
            Cells::Hex8(c) => c.len(),
            Cells::Tet10(c) => c.len(),
        }
    }

    /// True when there are no cells.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The node indices of cell `i`.
    pub fn cell(&self, i: usize) -> &[usize] {
        match self {
            Cells::Tet4(c) => &c[i],
            Cells::Hex8(c) => &c[i],
            Cells::Tet10(c) => &c[i],
        }
    }

    /// The kind of the cells.
    pub fn kind(&self) -> CellKind {
        match self {
            Cells::Tet4(_) => CellKind::Tet4,
            Cells::Hex8(_) => CellKind::Hex8,
            Cells::Tet10(_) => CellKind::Tet10,
        }
    }

    /// Short name of the cell kind ("T4", "H8" or "T10").
    pub fn kind_name(&self) -> &'static str {
        self.kind().name()
    }
}

/// A volume mesh with named node sets.
#[derive(Clone, Debug, PartialEq)]
pub struct Mesh {
    /// Node coordinates.
    pub nodes: Vec<Point>,
    /// Cells.
    pub cells: Cells,
    /// Named node sets (e.g. "fixed", "visible", "markers").
    pub regions: BTreeMap<String, Vec<usize>>,
    /// Optional per-cell stiffness scale in [0, 1]: the volume fraction of an
    /// immersed-boundary cell that lies inside the organ. `None` means 1 everywhere.
    pub cell_fraction: Option<Vec<f64>>,
    /// Optional outward unit normal of the organ's surface at each node (zero where it has none),
    /// where the mesh knows it better than its boundary faces do: on an immersed grid the surface
    /// cuts through cells, and its nodes are mostly inside the grid. `None`: see
    /// [`Mesh::surface_normals`].
    pub node_normals: Option<Vec<Point>>,
    /// The number each node has in the file the mesh was read from, where it is not its index:
    /// nodes that no cell uses were left out (the others renumbered), or the file numbers its
    /// nodes itself (Gmsh's tags, an Abaqus deck's numbers). Node `i` is the file's node
    /// `file_nodes[i]`. `None`: numbered as in its file, from 0, or made here. Selections by
    /// number (`list`) take the file's numbers.
    pub file_nodes: Option<Vec<usize>>,
    /// The number each cell has in the file the mesh was read from, where it is not its index
    /// (Gmsh's element tags, an Abaqus deck's element numbers, a VTK file's cells counted with
    /// those not kept); messages about a cell name it by this number.
    pub file_cells: Option<Vec<usize>>,
    /// The cells its file numbered the other way round from the others (their indices), turned
    /// positive as every cell is: a mesher's slip the file's author may want to know of.
    pub odd_cells: Vec<usize>,
}

impl Mesh {
    /// A mesh from nodes and cells, checked with [`Mesh::validate`].
    pub fn new(nodes: Vec<Point>, cells: Cells) -> Result<Self, MeshError> {
        let mesh = Mesh {
            nodes,
            cells,
            regions: BTreeMap::new(),
            cell_fraction: None,
            node_normals: None,
            file_nodes: None,
            file_cells: None,
            odd_cells: Vec::new(),
        };
        mesh.validate()?;
        Ok(mesh)
    }

    /// The number node `i` has in the mesh's file ([`Mesh::file_nodes`]), `i` where none is kept.
    pub fn file_node(&self, i: usize) -> usize {
        self.file_nodes.as_ref().and_then(|f| f.get(i).copied()).unwrap_or(i)
    }

    /// The number cell `i` has in the mesh's file ([`Mesh::file_cells`]), `i` where none is kept.
    pub fn file_cell(&self, i: usize) -> usize {
        self.file_cells.as_ref().and_then(|f| f.get(i).copied()).unwrap_or(i)
    }

    /// The outward unit normal of the organ's surface at each node: [`Mesh::node_normals`] when
    /// the mesh has them, otherwise the area-weighted normals of its boundary faces (zero for a
    /// node on none).
    pub fn surface_normals(&self) -> Vec<Point> {
        match &self.node_normals {
            Some(normals) => normals.clone(),
            None => topology::boundary_surface(self).vertex_normals(),
        }
    }

    /// The nodes on the organ's surface, sorted: on an immersed grid (with cell fractions) the
    /// nodes of its cut cells, where the surface passes (most of them inside the grid); otherwise
    /// the nodes of its boundary faces.
    pub fn surface_nodes(&self) -> Vec<usize> {
        let Some(fraction) = &self.cell_fraction else { return topology::boundary_nodes(self) };
        let mut nodes: Vec<usize> = fraction
            .iter()
            .enumerate()
            .filter(|(_, &f)| f < 1.0)
            .flat_map(|(c, _)| self.cells.cell(c).iter().copied())
            .collect();
        nodes.sort_unstable();
        nodes.dedup();
        nodes
    }

    /// The mesh without the cells `dropped` (indices) and the nodes only they use: the others
    /// renumbered in their order, with their regions, cell fractions and normals; nodes and cells
    /// keep their file's numbers ([`Mesh::file_nodes`], [`Mesh::file_cells`]), so that selections
    /// by number and messages still name them as the file does.
    pub fn without_cells(&self, dropped: &[usize]) -> Result<Mesh, MeshError> {
        let mut keep = vec![true; self.cells.len()];
        let count = keep.len();
        dropped.iter().filter(|&&c| c < count).for_each(|&c| keep[c] = false);
        let kept_cells: Vec<usize> = (0..self.cells.len()).filter(|&c| keep[c]).collect();
        let mut id = vec![usize::MAX; self.nodes.len()];
        kept_cells.iter().flat_map(|&c| self.cells.cell(c)).for_each(|&n| id[n] = 0);
        let old: Vec<usize> = (0..self.nodes.len()).filter(|&n| id[n] == 0).collect();
        old.iter().enumerate().for_each(|(new, &n)| id[n] = new);
        let remap = |cell: &[usize]| -> Vec<usize> { cell.iter().map(|&n| id[n]).collect() };
        let cells = match &self.cells {
            Cells::Tet4(c) => Cells::Tet4(kept_cells.iter().map(|&k| remap(&c[k]).try_into().unwrap()).collect()),
            Cells::Hex8(c) => Cells::Hex8(kept_cells.iter().map(|&k| remap(&c[k]).try_into().unwrap()).collect()),
            Cells::Tet10(c) => Cells::Tet10(kept_cells.iter().map(|&k| remap(&c[k]).try_into().unwrap()).collect()),
        };
        let mut mesh = Mesh::new(old.iter().map(|&n| self.nodes[n]).collect(), cells)?;
        mesh.regions = self
            .regions
            .iter()
            .map(|(name, nodes)| {
                (name.clone(), nodes.iter().filter(|&&n| id[n] != usize::MAX).map(|&n| id[n]).collect())
            })
            .collect();
        mesh.cell_fraction = self.cell_fraction.as_ref().map(|f| kept_cells.iter().map(|&c| f[c]).collect());
        mesh.node_normals = self.node_normals.as_ref().map(|v| old.iter().map(|&n| v[n]).collect());
        mesh.file_nodes = Some(old.iter().map(|&n| self.file_node(n)).collect());
        mesh.file_cells = Some(kept_cells.iter().map(|&c| self.file_cell(c)).collect());
        let mut new_cell = vec![usize::MAX; self.cells.len()];
        kept_cells.iter().enumerate().for_each(|(new, &c)| new_cell[c] = new);
        mesh.odd_cells = self.odd_cells.iter().map(|&c| new_cell[c]).filter(|&c| c != usize::MAX).collect();
        Ok(mesh)
    }

    /// Number of nodes.
    pub fn num_nodes(&self) -> usize {
        self.nodes.len()
    }

    /// Checks indices, finiteness, cell orientation and region indices.
    /// Tetrahedra must have positive volume; hexahedra a positive Jacobian at the
    /// centre and corners. Cells and nodes are named by their numbers in the mesh's file.
    pub fn validate(&self) -> Result<(), MeshError> {
        self.validate_connectivity()?;
        for i in 0..self.cells.len() {
            let vol = self.cell_volume(i);
            if !(vol > 0.0) {
                let cell = self.file_cell(i);
                return Err(MeshError::Invalid(format!("cell {cell} is inverted or degenerate (volume {vol:.3e})")));
            }
        }
        if let Cells::Hex8(hexes) = &self.cells {
            for (i, h) in hexes.iter().enumerate() {
                if !hex_corner_jacobians_positive(&self.nodes, h) {
                    let cell = self.file_cell(i);
                    return Err(MeshError::Invalid(format!("hexahedron {cell} has a non-positive corner Jacobian")));
                }
            }
        }
        Ok(())
    }

    /// [`Mesh::validate`] but for the cells' orientation: indices, finiteness, region indices
    /// (e.g. of a deformed mesh, whose cells may have been turned inside out).
    pub fn validate_connectivity(&self) -> Result<(), MeshError> {
        let n = self.nodes.len();
        if let Some(i) = self.nodes.iter().position(|p| p.iter().any(|c| !c.is_finite())) {
            return Err(MeshError::Invalid(format!("node {} has a non-finite coordinate", self.file_node(i))));
        }
        for i in 0..self.cells.len() {
            if let Some(&bad) = self.cells.cell(i).iter().find(|&&k| k >= n) {
                let cell = self.file_cell(i);
                return Err(MeshError::Invalid(format!("cell {cell} refers to node {bad}, but there are {n} nodes")));
            }
        }
        for (name, set) in &self.regions {
            if let Some(&bad) = set.iter().find(|&&k| k >= n) {
                return Err(MeshError::Invalid(format!(
                    "region '{name}' refers to node {bad}, but there are {n} nodes"
                )));
            }
        }
        if self.file_nodes.as_ref().is_some_and(|f| f.len() != n)
            || self.file_cells.as_ref().is_some_and(|f| f.len() != self.cells.len())
        {
            return Err(MeshError::Invalid("file_nodes and file_cells must hold one number per node and cell".into()));
        }
        if let Some(f) = &self.cell_fraction {
            if f.len() != self.cells.len() || f.iter().any(|x| !(0.0..=1.0).contains(x)) {
                return Err(MeshError::Invalid("cell_fraction must hold one value in [0, 1] per cell".into()));
            }
        }
        if let Some(normals) = &self.node_normals {
            let unit_or_none = |v: &Point| *v == [0.0; 3] || (norm(*v) - 1.0).abs() < 1e-6;
            if normals.len() != n || !normals.iter().all(unit_or_none) {
                return Err(MeshError::Invalid("node_normals must hold one unit (or zero) vector per node".into()));
            }
        }
        Ok(())
    }

    /// Signed volume of cell `i` (exact for tetrahedra, of a T10 that of its corners: exact for
    /// straight edges; for hexahedra the sum of a 6-tetrahedron split of the trilinear cell,
    /// exact for parallelepipeds).
    pub fn cell_volume(&self, i: usize) -> f64 {
        self.cell_volume_at(i, |node| self.nodes[node])
    }

    /// Signed volume of cell `i` moved by the nodal displacement `u` (3 per node), computed as
    /// [`Mesh::cell_volume`].
    pub fn displaced_cell_volume(&self, i: usize, u: &[f64]) -> f64 {
        self.cell_volume_at(i, |node| {
            let p = self.nodes[node];
            [p[0] + u[3 * node], p[1] + u[3 * node + 1], p[2] + u[3 * node + 2]]
        })
    }

    /// Signed volume of cell `i` with its nodes at `position(node)`.
    fn cell_volume_at(&self, i: usize, position: impl Fn(usize) -> Point) -> f64 {
        let p = |k: usize| position(self.cells.cell(i)[k]);
        match &self.cells {
            Cells::Tet4(_) | Cells::Tet10(_) => tet_volume(p(0), p(1), p(2), p(3)),
            Cells::Hex8(_) => HEX_TO_TETS.iter().map(|t| tet_volume(p(t[0]), p(t[1]), p(t[2]), p(t[3]))).sum(),
        }
    }

    /// Each node's share of material: the mean volume fraction of the cells
    /// around it (1 for every node of a body-fitted mesh; small for a node of an
    /// immersed grid whose cells barely reach into the organ).
    pub fn node_material_share(&self) -> Vec<f64> {
        let Some(fraction) = &self.cell_fraction else { return vec![1.0; self.nodes.len()] };
        let mut sum = vec![0.0; self.nodes.len()];
        let mut count = vec![0usize; self.nodes.len()];
        for (c, f) in fraction.iter().enumerate() {
            for &k in self.cells.cell(c) {
                sum[k] += f;
                count[k] += 1;
            }
        }
        sum.iter().zip(&count).map(|(s, &n)| if n > 0 { s / n as f64 } else { 0.0 }).collect()
    }

    /// Total volume of the mesh.
    pub fn volume(&self) -> f64 {
        (0..self.cells.len()).map(|i| self.cell_volume(i)).sum()
    }

    /// The volume of the body the mesh models: its cells' volumes, each weighted by the share of
    /// it inside the organ on an immersed grid ([`Mesh::cell_fraction`]).
    pub fn body_volume(&self) -> f64 {
        match &self.cell_fraction {
            Some(fraction) => (0..self.cells.len()).map(|i| fraction[i] * self.cell_volume(i)).sum(),
            None => self.volume(),
        }
    }

    /// Axis-aligned bounding box (min, max) of the nodes.
    pub fn bounds(&self) -> (Point, Point) {
        bounds(&self.nodes)
    }

    /// The named region, or an error listing the regions that exist.
    pub fn region(&self, name: &str) -> Result<&[usize], MeshError> {
        self.regions.get(name).map(|v| v.as_slice()).ok_or_else(|| {
            let names: Vec<&str> = self.regions.keys().map(|s| s.as_str()).collect();
            match names.is_empty() {
                true => MeshError::Invalid(format!("no region named '{name}': the mesh has no region")),
                false => MeshError::Invalid(format!("no region named '{name}' (regions: {})", names.join(", "))),
            }
        })
    }

    /// Translates and scales the nodes in place: x ← (x − centre) · scale.
    pub fn transform(&mut self, centre: Point, scale: f64) {
        for p in &mut self.nodes {
            for d in 0..3 {
                p[d] = (p[d] - centre[d]) * scale;
            }
        }
    }
}

/// Axis-aligned bounding box (min, max) of a point set; infinities when empty.
pub fn bounds(points: &[Point]) -> (Point, Point) {
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for p in points {
        for d in 0..3 {
            lo[d] = lo[d].min(p[d]);
            hi[d] = hi[d].max(p[d]);
        }
    }
    (lo, hi)
}

/// The pairs of distinct points that coincide (within a billionth of their box's diagonal), each
/// `(i, j)` with `i < j`, in order: a mesh's nodes that an exporter did not merge.
pub fn coincident_points(points: &[Point]) -> Vec<(usize, usize)> {
    let tolerance = 1e-9 * box_diagonal(bounds(points));
    let mut order: Vec<usize> = (0..points.len()).collect();
    order.sort_by(|&a, &b| points[a][0].total_cmp(&points[b][0]));
    let mut pairs = Vec::new();
    for (k, &i) in order.iter().enumerate() {
        for &j in order[k + 1..].iter().take_while(|&&j| points[j][0] - points[i][0] <= tolerance) {
            if distance(points[i], points[j]) <= tolerance {
                pairs.push((i.min(j), i.max(j)));
            }
        }
    }
    pairs.sort_unstable();
    pairs
}

/// The diagonal of the box `(lo, hi)` (e.g. of [`bounds`]): the size of an organ, or of a set of points.
pub fn box_diagonal((lo, hi): (Point, Point)) -> f64 {
    norm(sub(hi, lo))
}

/// The longest side of the box `(lo, hi)` (e.g. of [`bounds`]).
pub fn longest_side((lo, hi): (Point, Point)) -> f64 {
    (0..3).map(|d| hi[d] - lo[d]).fold(0.0, f64::max)
}

/// The largest coordinate magnitude a mesh or a surface to repair may have (in its own unit,
/// whatever it is: a million kilometres in m, a thousand in mm). Beyond about 1e75 the products of
/// four coordinates that geometric tests form overflow to infinity, and repair then never ends.
pub(crate) const MAX_COORDINATE: f64 = 1e9;

/// The largest coordinate magnitude of a measured point (a cloud's, a tracked feature's), in its
/// unit (m or mm): a thousand kilometres in m, one in mm, beyond any tracker's or camera's reach.
/// One such point, from a damaged file, would make every distance to it meaningless.
pub const MAX_MEASURED_COORDINATE: f64 = 1e6;

/// The first of measured `points` (a cloud, tracked features, targets, landmarks) that is not
/// finite or lies beyond [`MAX_MEASURED_COORDINATE`], with its index, as [`coordinate_fault`].
pub fn measured_fault(points: &[Point]) -> Option<(usize, String)> {
    coordinate_fault(points.iter().enumerate(), MAX_MEASURED_COORDINATE)
}

/// The first of `points` (each with its number) that is no point of an organ's in any length unit,
/// with what is wrong with it: a non-finite coordinate, or one beyond `bound` (a damaged file), in
/// words that follow the point's name ("vertex 7 has a non-finite coordinate …"); `None` when
/// every point is sound.
pub fn coordinate_fault<'a>(
    points: impl IntoIterator<Item = (usize, &'a Point)>,
    bound: f64,
) -> Option<(usize, String)> {
    points.into_iter().find_map(|(i, p)| point_fault(p, bound).map(|fault| (i, fault)))
}

/// What is wrong with one point for [`coordinate_fault`], `None` when nothing is.
fn point_fault(p: &Point, bound: f64) -> Option<String> {
    // The non-finite value alone, not the point: a reader's caller may have scaled it into another unit.
    if let Some((axis, c)) = ["x", "y", "z"].iter().zip(p).find(|(_, c)| !c.is_finite()) {
        Some(format!("has a non-finite coordinate: {axis} = {c}"))
    } else if p.iter().any(|c| c.abs() > bound) {
        Some(format!("lies at {p:?}: a coordinate beyond {bound:e}, out of reach (a damaged file?)"))
    } else {
        None
    }
}

/// Signed volume of the tetrahedron (a, b, c, d): positive when
/// (b−a)·((c−a)×(d−a)) > 0.
pub fn tet_volume(a: Point, b: Point, c: Point, d: Point) -> f64 {
    let u = sub(b, a);
    let v = sub(c, a);
    let w = sub(d, a);
    dot(u, cross(v, w)) / 6.0
}

/// The most cells a mesh that augsim makes (tetrahedra stuffed into a domain, a box's cells) may
/// have: about 12 GB while meshing (measured: 120 MB for 200,000 tetrahedra), and far beyond what
/// the FEM's direct solver handles on a workstation. Also the most nodes of a [`Grid`].
pub const MAX_CELLS: usize = 20_000_000;

/// A split of an H8 cell (VTK order) into 6 positively oriented tetrahedra
/// around the diagonal 0–6. Conforming between neighbouring cells of a
/// structured grid with the same split.
pub const HEX_TO_TETS: [[usize; 4]; 6] =
    [[0, 1, 2, 6], [0, 2, 3, 6], [0, 3, 7, 6], [0, 7, 4, 6], [0, 4, 5, 6], [0, 5, 1, 6]];

fn hex_corner_jacobians_positive(nodes: &[Point], h: &[usize; 8]) -> bool {
    // Corner k of the reference cube and its three neighbours along +ξ, +η, +ζ
    // (or −, with the sign accounted for so that the triple product is positive).
    const NEIGH: [[usize; 3]; 8] =
        [[1, 3, 4], [2, 0, 5], [3, 1, 6], [0, 2, 7], [7, 5, 0], [4, 6, 1], [5, 7, 2], [6, 4, 3]];
    NEIGH.iter().enumerate().all(|(k, nb)| {
        let o = nodes[h[k]];
        let a = sub(nodes[h[nb[0]]], o);
        let b = sub(nodes[h[nb[1]]], o);
        let c = sub(nodes[h[nb[2]]], o);
        dot(a, cross(b, c)) > 0.0
    })
}

/// a − b.
pub fn sub(a: Point, b: Point) -> Point {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

/// a · b.
pub fn dot(a: Point, b: Point) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// |a|.
pub fn norm(a: Point) -> f64 {
    dot(a, a).sqrt()
}

/// `v` scaled to unit length (zero stays zero).
pub fn unit(v: Point) -> Point {
    let l = norm(v);
    if l > 0.0 {
        v.map(|x| x / l)
    } else {
        v
    }
}

/// The unit vector of `vectors` weighted by `weights`: a normal interpolated over a triangle from
/// normals at its corners, at the point of barycentric `weights`.
pub fn blend_unit(vectors: [Point; 3], weights: [f64; 3]) -> Point {
    unit(std::array::from_fn(|d| (0..3).map(|j| weights[j] * vectors[j][d]).sum()))
}

/// |a − b|.
pub fn distance(a: Point, b: Point) -> f64 {
    norm(sub(a, b))
}

/// |aᵢ − bᵢ| for each pair of two lists of points (as long as the shorter).
pub fn distances(a: &[Point], b: &[Point]) -> Vec<f64> {
    a.iter().zip(b).map(|(p, q)| distance(*p, *q)).collect()
}

/// a × b.
pub fn cross(a: Point, b: Point) -> Point {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

/// The six dihedral angles (radians) of the tetrahedron (a, b, c, d).
pub fn dihedral_angles(p: [Point; 4]) -> [f64; 6] {
    // Outward normals of the faces opposite each vertex.
    let n: [Point; 4] = std::array::from_fn(|k| {
        let [i, j, l] = topology::TET_FACES[k];
        let mut v = cross(sub(p[j], p[i]), sub(p[l], p[i]));
        if dot(v, sub(p[k], p[i])) > 0.0 {
            v = v.map(|c| -c);
        }
        let len = dot(v, v).sqrt();
        if len > 0.0 {
            v.map(|c| c / len)
        } else {
            v
        }
    });
    let mut out = [0.0; 6];
    let mut m = 0;
    for k in 0..4 {
        for l in k + 1..4 {
            out[m] = std::f64::consts::PI - dot(n[k], n[l]).clamp(-1.0, 1.0).acos();
            m += 1;
        }
    }
    out
}
