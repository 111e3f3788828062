//! Regular grids embedded in volume meshes, point location and interpolation.
//!
//! # Grid layout (the one place it is defined)
//!
//! A [`Grid`] has `dims = [nx, ny, nz]` nodes; node (i, j, k) sits at
//! `origin + (i·sx, j·sy, k·sz)`. Node (i, j, k) has index
//! `(i·ny + j)·nz + k` (z fastest). A field of `C` channels on the grid is a
//! tensor `[channel, x, y, z]` stored flat with
//! `index = ((c·nx + i)·ny + j)·nz + k`.
//!
//! Fields on a mesh are node-major: value of channel c at node n is
//! `field[n·C + c]`; values at a list of points are point-major the same way.
//!
//! # Embedding
//!
//! Each grid node inside the mesh gets its containing element and weights:
//! barycentric coordinates for T4, trilinear shape functions at the
//! reference coordinates found by Newton's method for H8. Nodes outside the
//! mesh are masked (their mapped values are 0). Point location uses a
//! uniform bin grid over the elements' bounding boxes; a point on a shared
//! face belongs to the first element found that contains it (within 1e-10 in
//! barycentric / reference coordinates).

use rayon::prelude::*;

use crate::length::{mm, point_in_mm};
use crate::{bounds, Cells, Mesh, MeshError, Point, MAX_CELLS};

/// Tolerance on barycentric / reference coordinates for "inside".
const INSIDE_TOL: f64 = 1e-10;

/// How far (in grid cells) a point may lie outside the grid box and still be taken at its edge: a
/// point of the box's face written in single precision (a float32 `.npy` cloud) rounds off it by
/// about 1e-7 of its coordinate, some 1e-5 cells; a ten-thousandth of a cell is a micrometre
/// at a spacing of 1 cm.
pub const EDGE_TOLERANCE_CELLS: f64 = 1e-4;

/// A regular grid of nodes (see the module documentation for the layout).
#[derive(Clone, Debug, PartialEq)]
pub struct Grid {
    /// Position of node (0, 0, 0) (m).
    pub origin: Point,
    /// Node spacing along x, y, z (m).
    pub spacing: [f64; 3],
    /// Number of nodes along x, y, z.
    pub dims: [usize; 3],
}

impl Grid {
    /// A grid, checked: positive finite spacing, at least 2 nodes per axis, at most [`MAX_CELLS`]
    /// nodes.
    pub fn new(origin: Point, spacing: [f64; 3], dims: [usize; 3]) -> Result<Self, MeshError> {
        if origin.iter().any(|c| !c.is_finite()) || spacing.iter().any(|&s| !(s > 0.0 && s.is_finite())) {
            return Err(MeshError::Invalid(format!(
                "grid origin {origin:?} and spacing {spacing:?} must be finite, spacing positive"
            )));
        }
        if dims.iter().any(|&n| n < 2) {
            return Err(MeshError::Invalid(format!("grid needs at least 2 nodes per axis, got {dims:?}")));
        }
        let nodes = dims.iter().fold(1u128, |n, &k| n * k as u128);
        if nodes > MAX_CELLS as u128 {
            return Err(MeshError::Invalid(format!(
                "a grid of {dims:?} nodes has {nodes}, more than {MAX_CELLS} (the memory of a workstation)"
            )));
        }
        Ok(Grid { origin, spacing, dims })
    }

    /// The grid with `dims` nodes spanning the box [lo, hi] (first node at
    /// lo, last at hi).
    pub fn covering(lo: Point, hi: Point, dims: [usize; 3]) -> Result<Self, MeshError> {
        if dims.iter().any(|&n| n < 2) {
            return Err(MeshError::Invalid(format!("grid needs at least 2 nodes per axis, got {dims:?}")));
        }
        let spacing = std::array::from_fn(|d| (hi[d] - lo[d]) / (dims[d] - 1) as f64);
        Grid::new(lo, spacing, dims)
    }

    /// Number of nodes.
    pub fn num_nodes(&self) -> usize {
        self.dims[0] * self.dims[1] * self.dims[2]
    }

    /// Index of node (i, j, k): (i·ny + j)·nz + k.
    pub fn node_index(&self, i: usize, j: usize, k: usize) -> usize {
        (i * self.dims[1] + j) * self.dims[2] + k
    }

    /// Index of channel c at node (i, j, k) in a [channel, x, y, z] tensor.
    pub fn tensor_index(&self, c: usize, i: usize, j: usize, k: usize) -> usize {
        ((c * self.dims[0] + i) * self.dims[1] + j) * self.dims[2] + k
    }

    /// Position of node (i, j, k).
    pub fn node(&self, i: usize, j: usize, k: usize) -> Point {
        [
            self.origin[0] + i as f64 * self.spacing[0],
            self.origin[1] + j as f64 * self.spacing[1],
            self.origin[2] + k as f64 * self.spacing[2],
        ]
    }

    /// All node positions in index order.
    pub fn nodes(&self) -> Vec<Point> {
        let [nx, ny, nz] = self.dims;
        let mut out = Vec::with_capacity(self.num_nodes());
        for i in 0..nx {
            for j in 0..ny {
                for k in 0..nz {
                    out.push(self.node(i, j, k));
                }
            }
        }
        out
    }

    /// The last node's position (the upper corner of the grid box).
    pub fn upper(&self) -> Point {
        self.node(self.dims[0] - 1, self.dims[1] - 1, self.dims[2] - 1)
    }

    /// The 8 corner nodes (grid node indices) of the grid cell holding point `p` and their
    /// trilinear weights (summing to 1); outside the grid box, an error naming point number
    /// `index` (the caller's numbering).
    pub fn corners(&self, index: usize, p: Point) -> Result<[(usize, f64); 8], MeshError> {
        let mut base = [0usize; 3];
        let mut t = [0.0f64; 3];
        for d in 0..3 {
            let f = (p[d] - self.origin[d]) / self.spacing[d];
            let last = (self.dims[d] - 1) as f64;
            if !(f >= -EDGE_TOLERANCE_CELLS && f <= last + EDGE_TOLERANCE_CELLS) {
                let (lo, hi) = (self.origin, self.upper());
                let out = (0..3).map(|d| (lo[d] - p[d]).max(p[d] - hi[d]).max(0.0)).fold(0.0, f64::max);
                return Err(MeshError::Invalid(format!(
                    "point {index} at {} lies {} mm outside the grid box {}..{}",
                    point_in_mm(p),
                    crate::length::number(mm(out)),
                    point_in_mm(lo),
                    point_in_mm(hi)
                )));
            }
            let f = f.clamp(0.0, last);
            base[d] = (f.floor() as usize).min(self.dims[d] - 2);
            t[d] = f - base[d] as f64;
        }
        Ok(std::array::from_fn(|corner| {
            let o = [corner & 1, corner >> 1 & 1, corner >> 2 & 1];
            let w: f64 = (0..3).map(|d| if o[d] == 1 { t[d] } else { 1.0 - t[d] }).product();
            (self.node_index(base[0] + o[0], base[1] + o[1], base[2] + o[2]), w)
        }))
    }

    /// Trilinear interpolation of a [channel, x, y, z] field with `channels`
    /// channels at `points`; the result is point-major (`out[p·C + c]`). A
    /// point outside the grid box is an error naming it.
    pub fn interpolate(&self, field: &[f64], channels: usize, points: &[Point]) -> Result<Vec<f64>, MeshError> {
        if field.len() != channels * self.num_nodes() {
            return Err(MeshError::Invalid(format!(
                "grid field has {} values, expected {} channels × {} nodes",
                field.len(),
                channels,
                self.num_nodes()
            )));
        }
        let n = self.num_nodes();
        let mut out = vec![0.0; points.len() * channels];
        for (p, pt) in points.iter().enumerate() {
            let corners = self.corners(p, *pt)?;
            for c in 0..channels {
                out[p * channels + c] = corners.iter().map(|&(g, w)| w * field[c * n + g]).sum();
            }
        }
        Ok(out)
    }
}

/// The most nodes a cell has (T10).
pub const MAX_CELL_NODES: usize = 10;

/// Where a point lies in a mesh: its element and the interpolation weights
/// of the element's nodes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Location {
    /// The containing element.
    pub cell: usize,
    /// Its nodes (the first `count`).
    pub nodes: [usize; MAX_CELL_NODES],
    /// The nodes' weights (barycentric for T4, trilinear for H8, quadratic for T10; sum 1).
    pub weights: [f64; MAX_CELL_NODES],
    /// Nodes per element: 4, 8 or 10.
    pub count: usize,
}

impl Location {
    /// Cell `cell`'s `nodes` with their `weights` (as many).
    fn new(cell: usize, nodes: &[usize], weights: &[f64]) -> Self {
        let mut location =
            Location { cell, nodes: [0; MAX_CELL_NODES], weights: [0.0; MAX_CELL_NODES], count: nodes.len() };
        location.nodes[..nodes.len()].copy_from_slice(nodes);
        location.weights[..weights.len()].copy_from_slice(weights);
        location
    }

    /// (node, weight) pairs.
    pub fn terms(&self) -> impl Iterator<Item = (usize, f64)> + '_ {
        self.nodes[..self.count].iter().copied().zip(self.weights[..self.count].iter().copied())
    }

    /// The weighted sum of a node-major field with `channels` channels into `out`.
    fn interpolate_into(&self, field: &[f64], channels: usize, out: &mut [f64]) {
        for (c, o) in out.iter_mut().enumerate().take(channels) {
            *o = self.terms().map(|(n, w)| w * field[n * channels + c]).sum();
        }
    }
}

/// Fast point location in a T4 or H8 mesh (its own copy of the geometry).
#[derive(Clone, Debug)]
pub struct MeshLocator {
    nodes: Vec<Point>,
    cells: Cells,
    num_nodes: usize,
    lo: Point,
    bin: [f64; 3],
    dims: [usize; 3],
    start: Vec<u32>,
    items: Vec<u32>,
}

impl MeshLocator {
    /// Bins the elements of `mesh` (checked with [`Mesh::validate`]).
    pub fn new(mesh: &Mesh) -> Result<Self, MeshError> {
        mesh.validate()?;
        Self::binned(mesh)
    }

    /// Bins the elements of a mesh some of whose cells may be inverted (checked with
    /// [`Mesh::validate_connectivity`]), e.g. a deformed mesh folding over itself: a point where
    /// cells overlap is located in one of them; a degenerate (flat) cell holds none.
    pub fn allowing_inverted(mesh: &Mesh) -> Result<Self, MeshError> {
        mesh.validate_connectivity()?;
        Self::binned(mesh)
    }

    fn binned(mesh: &Mesh) -> Result<Self, MeshError> {
        if mesh.cells.is_empty() {
            return Err(MeshError::Invalid("cannot locate points in a mesh without cells".into()));
        }
        let (lo, hi) = bounds(&mesh.nodes);
        let n = mesh.cells.len();
        let volume = mesh.volume().max(f64::MIN_POSITIVE);
        let size = (volume / n as f64).cbrt() * 1.5;
        let dims: [usize; 3] = std::array::from_fn(|d| (((hi[d] - lo[d]) / size).ceil() as usize).clamp(1, 256));
        let bin: [f64; 3] = std::array::from_fn(|d| ((hi[d] - lo[d]) / dims[d] as f64).max(f64::MIN_POSITIVE));
        let cell_range = |c: usize| -> ([usize; 3], [usize; 3]) {
            let pts: Vec<Point> = mesh.cells.cell(c).iter().map(|&k| mesh.nodes[k]).collect();
            let (a, b) = bounds(&pts);
            let idx = |x: f64, d: usize| (((x - lo[d]) / bin[d]).floor().max(0.0) as usize).min(dims[d] - 1);
            (std::array::from_fn(|d| idx(a[d], d)), std::array::from_fn(|d| idx(b[d], d)))
        };
        let nbins = dims[0] * dims[1] * dims[2];
        let mut count = vec![0u32; nbins + 1];
        let ranges: Vec<([usize; 3], [usize; 3])> = (0..n).map(cell_range).collect();
        let bin_id = |i: usize, j: usize, k: usize| i + dims[0] * (j + dims[1] * k);
        for (a, b) in &ranges {
            for k in a[2]..=b[2] {
                for j in a[1]..=b[1] {
                    for i in a[0]..=b[0] {
                        count[bin_id(i, j, k) + 1] += 1;
                    }
                }
            }
        }
        for i in 0..nbins {
            count[i + 1] += count[i];
        }
        let mut fill = count.clone();
        let mut items = vec![0u32; count[nbins] as usize];
        for (c, (a, b)) in ranges.iter().enumerate() {
            for k in a[2]..=b[2] {
                for j in a[1]..=b[1] {
                    for i in a[0]..=b[0] {
                        let s = &mut fill[bin_id(i, j, k)];
                        items[*s as usize] = c as u32;
                        *s += 1;
                    }
                }
            }
        }
        Ok(MeshLocator {
            nodes: mesh.nodes.clone(),
            cells: mesh.cells.clone(),
            num_nodes: mesh.num_nodes(),
            lo,
            bin,
            dims,
            start: count,
            items,
        })
    }

    /// Number of nodes of the mesh.
    pub fn num_nodes(&self) -> usize {
        self.num_nodes
    }

    /// The element containing `p` and its weights, or `None` when `p` is
    /// outside the mesh.
    pub fn locate(&self, p: Point) -> Option<Location> {
        let mut idx = [0usize; 3];
        for d in 0..3 {
            let f = (p[d] - self.lo[d]) / self.bin[d];
            let tol = 1e-9 * self.dims[d] as f64;
            if !(f >= -tol && f <= self.dims[d] as f64 + tol) {
                return None;
            }
            idx[d] = (f.max(0.0) as usize).min(self.dims[d] - 1);
        }
        let b = idx[0] + self.dims[0] * (idx[1] + self.dims[1] * idx[2]);
        let mut best: Option<(f64, Location)> = None;
        for &c in &self.items[self.start[b] as usize..self.start[b + 1] as usize] {
            let c = c as usize;
            if let Some((margin, loc)) = self.try_cell(c, p) {
                if margin >= 0.0 {
                    return Some(loc);
                }
                if margin >= -INSIDE_TOL && best.as_ref().is_none_or(|(m, _)| margin > *m) {
                    best = Some((margin, loc));
                }
            }
        }
        best.map(|(_, l)| l)
    }

    /// [`MeshLocator::locate`] for many points, in parallel.
    pub fn locate_all(&self, points: &[Point]) -> Vec<Option<Location>> {
        points.par_iter().map(|&p| self.locate(p)).collect()
    }

    /// Weights of `p` in cell `c` and how far inside it is (smallest
    /// barycentric coordinate, or 1 − max |ξ|); `None` when it cannot tell.
    fn try_cell(&self, c: usize, p: Point) -> Option<(f64, Location)> {
        match &self.cells {
            Cells::Tet4(t) => {
                let t = t[c];
                let lambda = barycentric(t.map(|k| self.nodes[k]), p)?;
                Some((margin(&lambda), Location::new(c, &t, &lambda)))
            }
            // Located in the tetrahedron of its corners: exact for straight edges.
            Cells::Tet10(t) => {
                let t = t[c];
                let lambda = barycentric(std::array::from_fn(|k| self.nodes[t[k]]), p)?;
                Some((margin(&lambda), Location::new(c, &t, &crate::tet10_shape(lambda))))
            }
            Cells::Hex8(h) => {
                let h = h[c];
                let x = h.map(|k| self.nodes[k]);
                let (lo, hi) = bounds(&x);
                let pad = crate::longest_side((lo, hi)) * 1e-9;
                if (0..3).any(|d| p[d] < lo[d] - pad || p[d] > hi[d] + pad) {
                    return None;
                }
                let xi = hex_reference(&x, p)?;
                let margin = 1.0 - xi.iter().map(|v| v.abs()).fold(0.0, f64::max);
                Some((margin, Location::new(c, &h, &hex_shape(xi))))
            }
        }
    }
}

/// How far inside a tetrahedron barycentric coordinates are: the smallest.
fn margin(lambda: &[f64; 4]) -> f64 {
    lambda.iter().cloned().fold(f64::INFINITY, f64::min)
}

/// Barycentric coordinates of p in tetrahedron t (None if degenerate).
fn barycentric(t: [Point; 4], p: Point) -> Option<[f64; 4]> {
    let e: [Point; 3] = std::array::from_fn(|i| crate::sub(t[i + 1], t[0]));
    let r = crate::sub(p, t[0]);
    let det = crate::dot(e[0], crate::cross(e[1], e[2]));
    if det == 0.0 || !det.is_finite() {
        return None;
    }
    // Cramer's rule: r = l1 e0 + l2 e1 + l3 e2.
    let l1 = crate::dot(r, crate::cross(e[1], e[2])) / det;
    let l2 = crate::dot(e[0], crate::cross(r, e[2])) / det;
    let l3 = crate::dot(e[0], crate::cross(e[1], r)) / det;
    Some([1.0 - l1 - l2 - l3, l1, l2, l3])
}

/// Reference coordinates (ξ, η, ζ) ∈ [−1, 1]³ of the corners in VTK order.
const HEX_REF: [[f64; 3]; 8] = [
    [-1.0, -1.0, -1.0],
    [1.0, -1.0, -1.0],
    [1.0, 1.0, -1.0],
    [-1.0, 1.0, -1.0],
    [-1.0, -1.0, 1.0],
    [1.0, -1.0, 1.0],
    [1.0, 1.0, 1.0],
    [-1.0, 1.0, 1.0],
];

/// Trilinear shape functions of an H8 at reference point ξ.
pub fn hex_shape(xi: [f64; 3]) -> [f64; 8] {
    std::array::from_fn(|a| {
        let r = HEX_REF[a];
        0.125 * (1.0 + r[0] * xi[0]) * (1.0 + r[1] * xi[1]) * (1.0 + r[2] * xi[2])
    })
}

/// Reference coordinates of p in the hexahedron with corners x, by Newton's
/// method from the centre (None when it does not converge).
fn hex_reference(x: &[Point; 8], p: Point) -> Option<[f64; 3]> {
    let mut xi = [0.0f64; 3];
    for _ in 0..30 {
        let n = hex_shape(xi);
        let mut r = p;
        let mut jac = [[0.0f64; 3]; 3]; // jac[d][e] = ∂x_d / ∂ξ_e
        for a in 0..8 {
            let rf = HEX_REF[a];
            let dn = [
                0.125 * rf[0] * (1.0 + rf[1] * xi[1]) * (1.0 + rf[2] * xi[2]),
                0.125 * rf[1] * (1.0 + rf[0] * xi[0]) * (1.0 + rf[2] * xi[2]),
                0.125 * rf[2] * (1.0 + rf[0] * xi[0]) * (1.0 + rf[1] * xi[1]),
            ];
            for d in 0..3 {
                r[d] -= n[a] * x[a][d];
                for e in 0..3 {
                    jac[d][e] += dn[e] * x[a][d];
                }
            }
        }
        let m = nalgebra::Matrix3::from_fn(|i, j| jac[i][j]);
        let step = m.lu().solve(&nalgebra::Vector3::new(r[0], r[1], r[2]))?;
        for d in 0..3 {
            xi[d] += step[d];
        }
        if xi.iter().any(|v| !v.is_finite() || v.abs() > 10.0) {
            return None;
        }
        if step.amax() < 1e-14 {
            return Some(xi);
        }
    }
    Some(xi)
}

/// Weighted sums of a node-major mesh field (`channels` per node) at
/// located points; point-major result.
pub fn interpolate_at(locations: &[Location], field: &[f64], channels: usize) -> Result<Vec<f64>, MeshError> {
    let max_node = locations.iter().flat_map(|l| l.nodes[..l.count].iter()).copied().max().unwrap_or(0);
    if channels == 0
        || (!locations.is_empty() && field.len() < (max_node + 1) * channels)
        || !field.len().is_multiple_of(channels)
    {
        return Err(MeshError::Invalid(format!(
            "mesh field of {} values does not hold {channels} channels for node {max_node}",
            field.len()
        )));
    }
    let mut out = vec![0.0; locations.len() * channels];
    for (l, o) in locations.iter().zip(out.chunks_mut(channels)) {
        l.interpolate_into(field, channels, o);
    }
    Ok(out)
}

/// A grid embedded in a mesh: for every grid node, its location in the mesh
/// or `None` (masked) when outside. Reusable for any number of fields.
#[derive(Clone, Debug)]
pub struct Embedding {
    /// The grid.
    pub grid: Grid,
    /// Location of each grid node (grid node order), `None` outside the mesh.
    pub locations: Vec<Option<Location>>,
    num_mesh_nodes: usize,
}

impl Embedding {
    /// Locates every node of `grid` in `mesh`.
    pub fn new(mesh: &Mesh, grid: Grid) -> Result<Self, MeshError> {
        Ok(Self::with_locator(&MeshLocator::new(mesh)?, grid))
    }

    /// Locates every node of `grid` with an existing locator.
    pub fn with_locator(locator: &MeshLocator, grid: Grid) -> Self {
        let locations = locator.locate_all(&grid.nodes());
        Embedding { grid, locations, num_mesh_nodes: locator.num_nodes() }
    }

    /// True for the grid nodes inside the mesh (grid node order).
    pub fn mask(&self) -> Vec<bool> {
        self.locations.iter().map(|l| l.is_some()).collect()
    }

    /// Number of grid nodes inside the mesh.
    pub fn num_inside(&self) -> usize {
        self.locations.iter().filter(|l| l.is_some()).count()
    }

    /// Maps a node-major mesh field (`channels` per node) to the grid: a
    /// [channel, x, y, z] tensor, zero at masked nodes.
    pub fn map_nodal(&self, field: &[f64], channels: usize) -> Result<Vec<f64>, MeshError> {
        if channels == 0 || field.len() != self.num_mesh_nodes * channels {
            return Err(MeshError::Invalid(format!(
                "mesh field has {} values, expected {channels} channels × {} nodes",
                field.len(),
                self.num_mesh_nodes
            )));
        }
        let n = self.grid.num_nodes();
        let mut out = vec![0.0; channels * n];
        let mut tmp = vec![0.0; channels];
        for (g, loc) in self.locations.iter().enumerate() {
            if let Some(l) = loc {
                l.interpolate_into(field, channels, &mut tmp);
                for c in 0..channels {
                    out[c * n + g] = tmp[c];
                }
            }
        }
        Ok(out)
    }
}
