//! The regular grid and the one tensor layout used everywhere.

use mesh::embedding::Grid;
use mesh::length::point_in_mm;
use mesh::Point;
use serde::{Deserialize, Serialize};

use crate::{LearnError, Result};

/// Number of channels of input and target fields (x, y, z components).
pub const CHANNELS: usize = 3;

/// The grid tensor layout, as written into manifests and model files.
pub const LAYOUT: &str = "[channel, x, y, z], C order, z fastest: index = ((c*nx + i)*ny + j)*nz + k; \
                          shards prepend the sample axis; masks are [x, y, z]";

/// Number of nodes of a regular grid along x, y and z (serialized as `[nx, ny, nz]`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(try_from = "[usize; 3]", into = "[usize; 3]")]
pub struct GridShape {
    /// Nodes along x.
    pub nx: usize,
    /// Nodes along y.
    pub ny: usize,
    /// Nodes along z.
    pub nz: usize,
}

/// The most nodes a grid may have: 2^26, a field of 768 MiB in 32-bit floats, far above any
/// network's grid.
pub const MAX_GRID_NODES: usize = 1 << 26;

impl TryFrom<[usize; 3]> for GridShape {
    type Error = String;

    /// A grid of at least one node along each axis and at most [`MAX_GRID_NODES`] nodes (a model or
    /// manifest of another is damaged).
    fn try_from([nx, ny, nz]: [usize; 3]) -> std::result::Result<Self, String> {
        let nodes = nx.checked_mul(ny).and_then(|n| n.checked_mul(nz));
        match (nx.min(ny).min(nz), nodes) {
            (0, _) => Err(format!("grid [{nx}, {ny}, {nz}]: every axis needs at least one node")),
            (_, Some(n)) if n <= MAX_GRID_NODES => Ok(GridShape { nx, ny, nz }),
            _ => Err(format!("grid [{nx}, {ny}, {nz}]: more than {MAX_GRID_NODES} nodes (a damaged file?)")),
        }
    }
}

impl From<GridShape> for [usize; 3] {
    fn from(g: GridShape) -> Self {
        [g.nx, g.ny, g.nz]
    }
}

impl std::fmt::Display for GridShape {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}x{}x{}", self.nx, self.ny, self.nz)
    }
}

impl GridShape {
    /// A grid of `nx × ny × nz` nodes.
    pub fn new(nx: usize, ny: usize, nz: usize) -> Self {
        GridShape { nx, ny, nz }
    }

    /// `[nx, ny, nz]`.
    pub fn dims(&self) -> [usize; 3] {
        [self.nx, self.ny, self.nz]
    }

    /// Number of grid nodes.
    pub fn nodes(&self) -> usize {
        self.nx * self.ny * self.nz
    }

    /// Number of values of a 3-channel field on the grid.
    pub fn field_len(&self) -> usize {
        CHANNELS * self.nodes()
    }

    /// Linear index of node `(i, j, k)` in a mask (`[x, y, z]`, z fastest).
    pub fn node_index(&self, i: usize, j: usize, k: usize) -> usize {
        (i * self.ny + j) * self.nz + k
    }

    /// Linear index of channel `c` at node `(i, j, k)` in a field (`[channel, x, y, z]`).
    pub fn field_index(&self, c: usize, i: usize, j: usize, k: usize) -> usize {
        ((c * self.nx + i) * self.ny + j) * self.nz + k
    }

    /// Grid coordinates `(i, j, k)` of a node index.
    pub fn node_coords(&self, node: usize) -> [usize; 3] {
        let k = node % self.nz;
        let j = (node / self.nz) % self.ny;
        let i = node / (self.nz * self.ny);
        [i, j, k]
    }
}

/// Where a grid lies in space: the position of node (0, 0, 0) and the node spacing along x, y
/// and z (m). Stored in models so that point clouds can be mapped onto their grid.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GridPlacement {
    /// Position of node (0, 0, 0) (m).
    pub origin: [f64; 3],
    /// Node spacing (m).
    pub spacing: [f64; 3],
}

impl GridPlacement {
    /// The placed grid of `shape` nodes (checked: finite origin, positive spacing, ≥ 2 nodes
    /// per axis).
    pub fn grid(&self, shape: GridShape) -> Result<Grid> {
        Ok(Grid::new(self.origin, self.spacing, shape.dims())?)
    }

    /// An error when `self` (a model's placement) and `data`'s (a dataset's) lie apart: the same
    /// grid shape placed elsewhere or spaced otherwise (an organ scaled or moved) would be read as
    /// another organ's. Equal within a millionth of the spacing.
    pub fn check_matches(&self, data: &GridPlacement) -> Result<()> {
        let size = self.spacing.iter().fold(0.0f64, |a, &s| a.max(s));
        let far = |a: [f64; 3], b: [f64; 3]| a.iter().zip(b).any(|(x, y)| !((x - y).abs() <= 1e-6 * size));
        if !far(self.origin, data.origin) && !far(self.spacing, data.spacing) {
            return Ok(());
        }
        let mm = |v: [f64; 3]| format!("({:.3}, {:.3}, {:.3}) mm", 1e3 * v[0], 1e3 * v[1], 1e3 * v[2]);
        Err(LearnError::InvalidInput(format!(
            "the model's grid lies elsewhere than the dataset's: origin {} and spacing {} against {} and {} (another \
             organ, or the same scaled or moved)",
            mm(self.origin),
            mm(self.spacing),
            mm(data.origin),
            mm(data.spacing)
        )))
    }

    /// Checks a model file's placement (`json_path`'s), if it has one, on its grid of `shape`
    /// nodes: an error naming the file and its `placement`.
    pub(crate) fn check_in(
        placement: Option<&GridPlacement>,
        shape: GridShape,
        json_path: &std::path::Path,
    ) -> Result<()> {
        match placement.map(|p| p.grid(shape)) {
            Some(Err(e)) => Err(crate::LearnError::model(json_path, format!("placement: {e}"))),
            _ => Ok(()),
        }
    }
}

/// Encodes vectors given at points (e.g. a tracked point cloud, or mesh nodes) as a network
/// input on `grid` (`[3, nx, ny, nz]`). Forces are spread to the 8 corners of each point's grid
/// cell by the adjoint of trilinear interpolation, so the total force is preserved.
/// Displacements go to the nearest grid node (the largest trilinear weight); points sharing a
/// node are averaged. A point outside the grid box or a non-finite value is an error.
pub fn encode_points(grid: &Grid, points: &[Point], values: &[[f64; 3]], force: bool) -> Result<Vec<f32>> {
    if points.len() != values.len() {
        return Err(LearnError::InvalidInput(format!("{} points but {} vectors", points.len(), values.len())));
    }
    let n = grid.num_nodes();
    let mut sum = vec![0.0f64; CHANNELS * n];
    let mut count = vec![0u32; n];
    for (p, (pt, v)) in points.iter().zip(values).enumerate() {
        if pt.iter().chain(v).any(|x| !x.is_finite()) {
            return Err(LearnError::InvalidInput(format!("point {p}: non-finite position or value")));
        }
        let corners = grid.corners(p, *pt).map_err(|e| {
            LearnError::InvalidInput(format!(
                "{}: is it in the model's frame and unit (m; a CSV header x_mm, y_mm, z_mm names millimetres)?",
                e.message()
            ))
        })?;
        if force {
            for (g, w) in corners {
                for c in 0..CHANNELS {
                    sum[c * n + g] += w * v[c];
                }
            }
        } else {
            let (g, _) = corners.into_iter().fold((0, f64::NEG_INFINITY), |a, b| if b.1 > a.1 { b } else { a });
            count[g] += 1;
            for c in 0..CHANNELS {
                sum[c * n + g] += v[c];
            }
        }
    }
    if !force {
        for (g, &k) in count.iter().enumerate().filter(|(_, &k)| k > 1) {
            for c in 0..CHANNELS {
                sum[c * n + g] /= f64::from(k);
            }
        }
    }
    Ok(sum.into_iter().map(|x| x as f32).collect())
}

/// Interpolation of grid fields (`[3, nx, ny, nz]`) to the nodes of a mesh embedded in the
/// grid, weights computed once. Grid nodes outside the organ carry no trained value, so each
/// mesh node uses only the corners of its grid cell that lie inside the organ (weights
/// renormalised), or, when none does (the tip of a thin lobe), the nearest grid nodes inside it.
#[derive(Clone, Debug)]
pub struct GridToMesh {
    grid_nodes: usize,
    /// Per mesh node, its (grid node, weight) terms.
    terms: Vec<Vec<(usize, f64)>>,
}

/// A mesh node outside the grid's box by at most this many grid spacings takes the values at the
/// box's nearest point: another mesh of the training organ (finer or coarser) may stick out of the
/// box fitted around the training mesh by a fraction of a cell.
pub const OUTSIDE_CELLS: f64 = 0.5;

/// How many rings of grid cells around a mesh node's own cell [`GridToMesh`] searches for grid
/// nodes inside the organ, when none of its cell's corners is (the tip of a thin lobe).
const NEAREST_RINGS: usize = 3;

/// The grid nodes inside the organ (`inside`) nearest to `p`, weighted by their inverse squared
/// distance (summing to 1): those of the smallest block of cells around `p`'s cell, grown ring by
/// ring up to [`NEAREST_RINGS`], that holds any; `None` if none does.
fn nearest_inside(grid: &Grid, inside: &[bool], p: mesh::Point) -> Option<Vec<(usize, f64)>> {
    let cell: [i64; 3] = std::array::from_fn(|d| ((p[d] - grid.origin[d]) / grid.spacing[d]).floor() as i64);
    for ring in 1..=NEAREST_RINGS as i64 {
        let range = |d: usize| (cell[d] - ring + 1).max(0)..=(cell[d] + ring).min(grid.dims[d] as i64 - 1);
        let mut terms = Vec::new();
        for i in range(0) {
            for j in range(1) {
                for k in range(2) {
                    let g = grid.node_index(i as usize, j as usize, k as usize);
                    if inside[g] {
                        let d2 = mesh::distance(p, grid.node(i as usize, j as usize, k as usize)).powi(2);
                        terms.push((g, 1.0 / d2.max(1e-30)));
                    }
                }
            }
        }
        if !terms.is_empty() {
            let total: f64 = terms.iter().map(|(_, w)| w).sum();
            return Some(terms.into_iter().map(|(g, w)| (g, w / total)).collect());
        }
    }
    None
}

impl GridToMesh {
    /// The weights for the nodes of `organ` in `grid`; every node must lie in the grid's box, or
    /// outside it by at most [`OUTSIDE_CELLS`].
    pub fn new(organ: &mesh::Mesh, grid: &Grid) -> Result<Self> {
        let inside = mesh::embedding::Embedding::new(organ, grid.clone())?.mask();
        let (lo, hi) = (grid.origin, grid.upper());
        let terms = organ
            .nodes
            .iter()
            .enumerate()
            .map(|(m, p)| {
                let beyond = (0..3)
                    .map(|d| (lo[d] - p[d]).max(p[d] - hi[d]) - OUTSIDE_CELLS * grid.spacing[d])
                    .fold(f64::NEG_INFINITY, f64::max);
                if !(beyond <= 0.0) {
                    return Err(LearnError::InvalidInput(format!(
                        "mesh node {m} at {} lies outside the model's grid box {}..{}, by more than half a cell: \
                         is the mesh the organ the model was trained on, in metres?",
                        point_in_mm(*p),
                        point_in_mm(lo),
                        point_in_mm(hi)
                    )));
                }
                let corners = grid.corners(m, std::array::from_fn(|d| p[d].clamp(lo[d], hi[d])))?;
                let kept: f64 = corners.iter().filter(|(g, _)| inside[*g]).map(|(_, w)| w).sum();
                if kept <= 1e-12 {
                    return nearest_inside(grid, &inside, *p).ok_or_else(|| {
                        LearnError::InvalidInput(format!(
                            "mesh node {m} at {} has no grid node inside the organ within {NEAREST_RINGS} cells: is \
                             the mesh the organ the model was trained on?",
                            point_in_mm(*p)
                        ))
                    });
                }
                Ok(corners.into_iter().filter(|&(g, w)| w != 0.0 && inside[g]).map(|(g, w)| (g, w / kept)).collect())
            })
            .collect::<Result<_>>()?;
        Ok(GridToMesh { grid_nodes: grid.num_nodes(), terms })
    }

    /// The field at the mesh nodes, node-major (`3 × nodes`).
    pub fn apply(&self, field: &[f32]) -> Result<Vec<f64>> {
        self.apply_channels(field, CHANNELS)
    }

    /// A field of `channels` channels in the tensor layout (3 for a displacement, 1 for a
    /// standard deviation) at the mesh nodes, node-major (`channels × nodes`).
    pub fn apply_channels(&self, field: &[f32], channels: usize) -> Result<Vec<f64>> {
        let n = self.grid_nodes;
        if field.len() != channels * n {
            return Err(LearnError::InvalidInput(format!(
                "grid field has {} values, expected {channels} × {n}",
                field.len()
            )));
        }
        let mut u = vec![0.0; channels * self.terms.len()];
        for (m, terms) in self.terms.iter().enumerate() {
            for &(g, w) in terms {
                for c in 0..channels {
                    u[channels * m + c] += w * f64::from(field[c * n + g]);
                }
            }
        }
        Ok(u)
    }
}

/// A placed grid seen as a hexahedral mesh, to write grid fields as VTK: one H8 cell per grid cell, nodes numbered
/// x fastest as [`mesh::box_hex`] numbers them (the tensors are z fastest, see [`LAYOUT`]).
#[derive(Clone, Debug)]
pub struct GridMesh {
    /// The mesh of the grid's cells.
    pub mesh: mesh::Mesh,
    shape: GridShape,
}

impl GridMesh {
    /// The mesh of `grid`.
    pub fn new(grid: &Grid) -> Result<Self> {
        let [nx, ny, nz] = grid.dims;
        let mesh = mesh::box_hex(grid.origin, grid.upper(), [nx - 1, ny - 1, nz - 1])?;
        Ok(GridMesh { mesh, shape: GridShape::new(grid.dims[0], grid.dims[1], grid.dims[2]) })
    }

    /// A field of `channels` channels in the tensor layout (`[c, x, y, z]`, e.g. 3 for a displacement, 1 for a
    /// mask) as node-major values at the mesh nodes (`channels × nodes`).
    pub fn field(&self, field: &[f32], channels: usize) -> Result<Vec<f64>> {
        let g = self.shape;
        let n = g.nodes();
        if field.len() != channels * n {
            return Err(LearnError::InvalidInput(format!(
                "grid field has {} values, expected {channels} × {n}",
                field.len()
            )));
        }
        let mut out = vec![0.0; channels * n];
        for k in 0..g.nz {
            for j in 0..g.ny {
                for i in 0..g.nx {
                    let node = i + g.nx * (j + g.ny * k);
                    for c in 0..channels {
                        out[channels * node + c] = f64::from(field[c * n + g.node_index(i, j, k)]);
                    }
                }
            }
        }
        Ok(out)
    }
}

/// Checks one prediction input: a `[3, nx, ny, nz]` field on `grid`, every value finite.
pub(crate) fn check_prediction_input(input: &[f32], grid: GridShape) -> Result<()> {
    let f = grid.field_len();
    if input.len() != f {
        return Err(LearnError::InvalidInput(format!(
            "prediction input has {} values, expected {f} (3 channels on grid {grid})",
            input.len()
        )));
    }
    match unfit_value(input) {
        Some(i) => Err(unfit_input(i, input[i])),
        None => Ok(()),
    }
}

/// The error for prediction input value `i`, `value`, that no field on the grid holds.
pub(crate) fn unfit_input(i: usize, value: impl std::fmt::LowerExp) -> LearnError {
    LearnError::InvalidInput(format!(
        "prediction input value {i} is {value:e}: inputs are finite displacements (m) or forces (N) within \
         {MAX_FIELD_VALUE:e}"
    ))
}

/// The largest magnitude a value of a field on the grid (a dataset's, a prediction's input) may
/// have: no displacement (m) or force (N) of an organ comes near it, a damaged file does.
pub(crate) const MAX_FIELD_VALUE: f32 = 1e6;

/// The place of the first of `values` that no field on the grid holds: not finite, or beyond
/// [`MAX_FIELD_VALUE`].
pub(crate) fn unfit_value(values: &[f32]) -> Option<usize> {
    values.iter().position(|v| !(v.is_finite() && v.abs() <= MAX_FIELD_VALUE))
}

/// A model's grid where it lies in space; an error for a model that does not record it.
pub(crate) fn placed_model_grid(placement: Option<GridPlacement>, grid: GridShape) -> Result<Grid> {
    placement
        .ok_or_else(|| {
            LearnError::InvalidInput(
                "the model does not record where its grid lies (trained before grid placement was stored): retrain it"
                    .into(),
            )
        })?
        .grid(grid)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A placement matches itself within rounding; the same grid spaced twice as wide (an organ
    /// scaled) or moved is refused, in mm.
    #[test]
    fn placements_apart_are_refused() {
        let p = GridPlacement { origin: [0.01, -0.02, 0.0], spacing: [0.005; 3] };
        p.check_matches(&GridPlacement { origin: [0.01 + 1e-12, -0.02, 0.0], ..p }).unwrap();
        let scaled = GridPlacement { spacing: [0.01; 3], ..p };
        let e = p.check_matches(&scaled).unwrap_err().to_string();
        assert!(e.contains("spacing (5.000, 5.000, 5.000) mm against (10.000, -20.000, 0.000) mm and (10.000"), "{e}");
        assert!(p.check_matches(&GridPlacement { origin: [0.02, -0.02, 0.0], ..p }).is_err());
    }

    /// A grid read from a file has a node along each axis and no more nodes than fit in memory:
    /// sizes whose product overflows are refused, not wrapped.
    #[test]
    fn a_damaged_grid_shape_is_refused() {
        assert_eq!(GridShape::try_from([4, 5, 3]), Ok(GridShape::new(4, 5, 3)));
        assert!(GridShape::try_from([4, 0, 3]).unwrap_err().contains("at least one node"));
        let huge = usize::MAX / 2;
        assert!(GridShape::try_from([huge, huge, 3]).unwrap_err().contains("more than"));
        assert!(serde_json::from_str::<GridShape>("[100000, 100000, 100000]").is_err());
    }

    fn grid() -> Grid {
        Grid::new([0.0, -1.0, 2.0], [0.5, 0.25, 1.0], [4, 5, 3]).unwrap()
    }

    #[test]
    fn point_forces_keep_their_sum_and_their_moment() {
        let g = grid();
        let points = [[0.3, -0.6, 2.2], [1.49, 0.0, 3.9], [0.0, -1.0, 2.0]];
        let forces = [[1.0, -2.0, 0.5], [0.25, 0.0, -3.0], [2.0, 1.0, 1.0]];
        let field = encode_points(&g, &points, &forces, true).unwrap();
        let n = g.num_nodes();
        let nodes = g.nodes();
        for c in 0..3 {
            let total: f64 = (0..n).map(|i| f64::from(field[c * n + i])).sum();
            let want: f64 = forces.iter().map(|f| f[c]).sum();
            assert!((total - want).abs() < 1e-5, "channel {c}: {total} vs {want}");
            // First moment Σ x_d f_c: trilinear spreading is exact for linear functions.
            for d in 0..3 {
                let m: f64 = (0..n).map(|i| nodes[i][d] * f64::from(field[c * n + i])).sum();
                let want: f64 = points.iter().zip(&forces).map(|(p, f)| p[d] * f[c]).sum();
                assert!((m - want).abs() < 1e-5, "moment x{d} f{c}: {m} vs {want}");
            }
        }
    }

    #[test]
    fn displacements_go_to_the_nearest_node_and_are_averaged() {
        let g = grid();
        let near = g.node(1, 2, 1);
        let points = [[near[0] + 0.1, near[1], near[2]], [near[0], near[1] - 0.05, near[2] + 0.2], g.node(3, 4, 2)];
        let values = [[1.0, 2.0, 3.0], [3.0, 0.0, -1.0], [0.5, 0.5, 0.5]];
        let field = encode_points(&g, &points, &values, false).unwrap();
        let n = g.num_nodes();
        let (a, b) = (g.node_index(1, 2, 1), g.node_index(3, 4, 2));
        for c in 0..3 {
            assert_eq!(field[c * n + a], ((values[0][c] + values[1][c]) / 2.0) as f32);
            assert_eq!(field[c * n + b], values[2][c] as f32);
        }
        assert_eq!(field.iter().filter(|v| **v != 0.0).count(), 6, "only the two nodes are written");
    }

    /// A mesh sticking out of the grid's box by less than half a cell (another mesh of the same
    /// organ) takes the values at the box's nearest point; by more, it is refused, in mm.
    #[test]
    fn mesh_nodes_just_outside_the_grid_take_the_nearest_values_and_farther_ones_are_refused() {
        let g = grid();
        // A field linear in x: x itself, in every channel.
        let field: Vec<f32> = (0..3).flat_map(|_| g.nodes().into_iter().map(|p| p[0] as f32)).collect();
        let cube = |x0: f64, x1: f64| mesh::box_tet([x0, -0.9, 2.1], [x1, -0.1, 3.9], [2, 2, 2]).unwrap();
        let to_mesh = GridToMesh::new(&cube(-0.2, 1.7), &g).unwrap();
        let u = to_mesh.apply(&field).unwrap();
        let xs: Vec<f64> = u.chunks(3).map(|c| c[0]).collect();
        let (min, max) = (xs.iter().copied().fold(f64::MAX, f64::min), xs.iter().copied().fold(f64::MIN, f64::max));
        assert!(min.abs() < 1e-6 && (max - 1.5).abs() < 1e-6, "clamped to the box: {min} to {max}");
        // One channel (a standard deviation) lands as each channel of the three does.
        assert_eq!(to_mesh.apply_channels(&field[..g.num_nodes()], 1).unwrap(), xs);
        assert!(to_mesh.apply_channels(&field, 1).is_err(), "three channels are not one");
        let error = GridToMesh::new(&cube(-0.3, 1.5), &g).unwrap_err().to_string();
        assert!(error.contains("at (-300, -900, 2100) mm lies outside the model's grid box"), "{error}");
    }

    /// A mesh vertex none of whose grid cell's corners lies inside the organ (a tip) takes the
    /// values of the nearest grid nodes inside it, not the zero the grid holds outside.
    #[test]
    fn a_tip_outside_every_corner_of_its_cell_takes_the_nearest_inside_values() {
        let g = Grid::new([-0.1; 3], [0.2; 3], [7, 7, 7]).unwrap();
        let tet = mesh::Mesh::new(
            vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            mesh::Cells::Tet4(vec![[0, 1, 2, 3]]),
        )
        .unwrap();
        let inside = mesh::embedding::Embedding::new(&tet, g.clone()).unwrap().mask();
        // Linear in x inside the organ, zero outside (as a trained model gives it).
        let nodes = g.nodes();
        let field: Vec<f32> = (0..3)
            .flat_map(|_| nodes.iter().zip(&inside).map(|(p, &i)| if i { 1.0 + p[0] as f32 } else { 0.0 }))
            .collect();
        let u = GridToMesh::new(&tet, &g).unwrap().apply(&field).unwrap();
        // The tip at x = 1: its cell's corners (x = 0.9 or 1.1, y and z = ±0.1) are all outside.
        let tip = u[3];
        assert!(tip > 1.5 && tip <= 2.0, "the tip takes its neighbours' values (1.5 to 1.9): {tip}");
        assert!(u.chunks(3).all(|c| c[0] > 0.9), "no node left at zero: {u:?}");
    }

    #[test]
    fn grid_fields_land_on_the_grid_mesh_nodes_at_the_same_place() {
        let g = grid();
        let grid_mesh = GridMesh::new(&g).unwrap();
        assert_eq!(grid_mesh.mesh.num_nodes(), g.num_nodes());
        // A field holding each grid node's own coordinates reads back as the mesh nodes' positions.
        let n = g.num_nodes();
        let nodes = g.nodes();
        let field: Vec<f32> = (0..3).flat_map(|c| nodes.iter().map(move |p| p[c] as f32)).collect();
        let on_mesh = grid_mesh.field(&field, 3).unwrap();
        for (m, p) in grid_mesh.mesh.nodes.iter().enumerate() {
            for c in 0..3 {
                assert!((on_mesh[3 * m + c] - p[c]).abs() < 1e-6, "node {m} channel {c}");
            }
        }
        let mask: Vec<f32> = (0..n).map(|i| i as f32).collect();
        assert_eq!(grid_mesh.field(&mask, 1).unwrap().len(), n);
        assert!(grid_mesh.field(&mask, 3).is_err());
    }

    #[test]
    fn points_outside_the_grid_and_bad_values_are_errors() {
        let g = grid();
        let e = encode_points(&g, &[[0.0, 0.0, 5.0]], &[[1.0, 0.0, 0.0]], true).unwrap_err().to_string();
        assert!(e.contains("point 0") && e.contains("outside"), "{e}");
        assert!(!e.contains("invalid mesh") && e.ends_with("names millimetres)?"), "a point, not a mesh: {e}");
        let e = encode_points(&g, &[[0.1, 0.0, 2.5]], &[[f64::NAN, 0.0, 0.0]], false).unwrap_err().to_string();
        assert!(e.contains("non-finite"), "{e}");
        assert!(encode_points(&g, &[[0.1, 0.0, 2.5]], &[], false).is_err());
    }
}
