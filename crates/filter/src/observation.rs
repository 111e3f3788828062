//! Observation operators for finite-element models: points tracked through the shape functions of the mesh cell
//! that holds them, and synthetic measurements (a reference run plus Gaussian noise).

use mesh::{MeshLocator, Point, MAX_CELL_NODES};
use nalgebra::DVector;
use rand::rngs::StdRng;
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};
use serde::{Deserialize, Serialize};

use crate::error::FemModelError;

/// A material point of the mesh: a fixed combination of the displacements of the nodes of the cell that holds it
/// (e.g. a surface feature point), or a node itself.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TrackedPoint {
    /// The nodes that carry the point (the first `count`).
    pub nodes: [usize; MAX_CELL_NODES],
    /// Their weights (sum 1): barycentric in a linear tetrahedron (non-negative), the quadratic shape functions
    /// in a T10 (negative at corners inside the cell).
    pub weights: [f64; MAX_CELL_NODES],
    /// The number of nodes.
    pub count: usize,
    /// From where the point was located to where it was tracked (m): a point just outside the
    /// mesh (a feature of a finer or smoother surface) is located on the mesh's surface and keeps
    /// this offset, so that the model sees it where its tracks are. Zero for a point located as it
    /// is.
    pub offset: Point,
}

impl TrackedPoint {
    /// The point that moves with node `node`.
    pub fn at_node(node: usize) -> Self {
        let mut weights = [0.0; MAX_CELL_NODES];
        weights[0] = 1.0;
        TrackedPoint { nodes: [node; MAX_CELL_NODES], weights, count: 1, offset: [0.0; 3] }
    }

    /// The nodes and their weights.
    pub fn terms(&self) -> impl Iterator<Item = (usize, f64)> + '_ {
        self.nodes[..self.count].iter().copied().zip(self.weights[..self.count].iter().copied())
    }

    /// Locates `p` with a locator built on a tetrahedral mesh, linear or quadratic ([`MeshLocator::new`]); in a
    /// linear tetrahedron, weights on faces, up to rounding, are clamped to zero and renormalised. Errors when the
    /// mesh is not tetrahedral or `p` lies outside.
    pub fn locate(locator: &MeshLocator, p: Point) -> Result<Self, FemModelError> {
        if p.iter().any(|c| !c.is_finite()) {
            return Err(FemModelError::Invalid(format!("tracked point {p:?} is not finite")));
        }
        let location = locator
            .locate(p)
            .ok_or_else(|| FemModelError::Invalid(format!("tracked point {p:?} lies outside the mesh")))?;
        let point =
            TrackedPoint { nodes: location.nodes, weights: location.weights, count: location.count, offset: [0.0; 3] };
        match location.count {
            4 => {
                let w = point.weights.map(|v| v.max(0.0));
                let sum: f64 = w.iter().sum();
                Ok(TrackedPoint { weights: w.map(|v| v / sum), ..point })
            }
            10 => Ok(point),
            n => Err(FemModelError::Invalid(format!(
                "tracked points need a tetrahedral mesh, this one has {n}-node cells"
            ))),
        }
    }

    /// The point located at `located` and tracked at `tracked`: it keeps the offset between them.
    pub fn tracked_at(self, located: Point, tracked: Point) -> Self {
        TrackedPoint { offset: std::array::from_fn(|d| tracked[d] - located[d]), ..self }
    }

    /// Current position of the point: reference position plus interpolated displacement `u` (3 per node), plus its
    /// [`offset`](Self::offset).
    pub fn position(&self, nodes: &[Point], u: &[f64]) -> Point {
        let mut x = self.offset;
        for (n, w) in self.terms() {
            for d in 0..3 {
                x[d] += w * (nodes[n][d] + u[3 * n + d]);
            }
        }
        x
    }

    /// Checks the node indices against a mesh of `num_nodes` nodes and the weights (finite, sum 1; ≥ 0 but for a
    /// T10's ten).
    pub fn validate(&self, num_nodes: usize) -> Result<(), FemModelError> {
        if !(1..=MAX_CELL_NODES).contains(&self.count) {
            return Err(FemModelError::Invalid(format!("tracked point with {} nodes", self.count)));
        }
        if let Some(&n) = self.nodes[..self.count].iter().find(|&&n| n >= num_nodes) {
            return Err(FemModelError::Invalid(format!(
                "tracked point refers to node {n}, but the mesh has {num_nodes} nodes"
            )));
        }
        let weights = &self.weights[..self.count];
        let sum: f64 = weights.iter().sum();
        let signed = self.count == MAX_CELL_NODES;
        if weights.iter().any(|w| !(w.is_finite() && (signed || *w >= 0.0))) || (sum - 1.0).abs() > 1e-9 {
            return Err(FemModelError::Invalid(format!(
                "tracked point weights {weights:?} must be finite, sum to 1 and, but in a T10, be non-negative"
            )));
        }
        Ok(())
    }
}

/// Current positions of `points` for the displacement `u`, stacked as (x, y, z) per point.
pub fn tracked_positions(nodes: &[Point], points: &[TrackedPoint], u: &[f64]) -> DVector<f64> {
    DVector::from_iterator(3 * points.len(), points.iter().flat_map(|t| t.position(nodes, u)))
}

/// Synthetic measurements: every component of every clean observation plus independent Gaussian noise of
/// standard deviation `std` (≥ 0; 0 gives the clean data), from a generator seeded with `seed`.
pub fn add_noise(clean: &[DVector<f64>], std: f64, seed: u64) -> Result<Vec<DVector<f64>>, FemModelError> {
    let invalid = || FemModelError::Invalid(format!("noise standard deviation must be finite and ≥ 0, got {std}"));
    if !(std.is_finite() && std >= 0.0) {
        return Err(invalid());
    }
    let normal = Normal::new(0.0, std).map_err(|_| invalid())?;
    let mut rng = StdRng::seed_from_u64(seed);
    Ok(clean.iter().map(|z| z.map(|v| v + normal.sample(&mut rng))).collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// In a T10 mesh a tracked point carries the ten quadratic shape functions: it follows a quadratic
    /// displacement field exactly; in the T4 mesh of the same corners it does not.
    #[test]
    fn tracked_points_follow_quadratic_fields_in_quadratic_tetrahedra() {
        let t4 = mesh::box_tet([0.0; 3], [0.2, 0.1, 0.1], [3, 2, 2]).unwrap();
        let t10 = t4.quadratic().unwrap();
        let u_at = |p: Point| [p[0] * p[1], -p[2] * p[2], 0.5 * p[0] * p[2]];
        let p = [0.071, 0.033, 0.058];
        let exact: Point = std::array::from_fn(|d| p[d] + u_at(p)[d]);
        let mut errors = Vec::new();
        for m in [&t10, &t4] {
            let u: Vec<f64> = m.nodes.iter().flat_map(|&x| u_at(x)).collect();
            let t = TrackedPoint::locate(&MeshLocator::new(m).unwrap(), p).unwrap();
            t.validate(m.num_nodes()).unwrap();
            let x = t.position(&m.nodes, &u);
            errors.push((0..3).map(|d| (x[d] - exact[d]).abs()).fold(0.0, f64::max));
        }
        assert!(errors[0] < 1e-15, "T10: {errors:?}");
        assert!(errors[1] > 1e-6, "T4 follows a quadratic field? {errors:?}");
        assert_eq!(TrackedPoint::at_node(5).terms().collect::<Vec<_>>(), [(5, 1.0)]);
    }
}
