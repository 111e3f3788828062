//! Observation operators for finite-element models: points tracked through barycentric weights in a tetrahedral
//! mesh, and synthetic measurements (a reference run plus Gaussian noise).

use mesh::{MeshLocator, Point};
use nalgebra::DVector;
use rand::rngs::StdRng;
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};
use serde::{Deserialize, Serialize};

use crate::FemModelError;

/// A material point of the mesh: a fixed combination of the displacements of (up to) four nodes, e.g. a surface
/// feature point inside the tetrahedron that contains it, or a node itself.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TrackedPoint {
    /// The nodes that carry the point.
    pub nodes: [usize; 4],
    /// Barycentric weights of the nodes (non-negative, sum 1).
    pub weights: [f64; 4],
}

impl TrackedPoint {
    /// The point that moves with node `node`.
    pub fn at_node(node: usize) -> Self {
        TrackedPoint { nodes: [node; 4], weights: [1.0, 0.0, 0.0, 0.0] }
    }

    /// Locates `p` with a locator built on a tetrahedral mesh ([`MeshLocator::new`]); weights on faces, up to
    /// rounding, are clamped to zero and renormalised. Errors when the mesh is not tetrahedral or `p` lies outside.
    pub fn locate(locator: &MeshLocator, p: Point) -> Result<Self, FemModelError> {
        if p.iter().any(|c| !c.is_finite()) {
            return Err(FemModelError::Invalid(format!("tracked point {p:?} is not finite")));
        }
        let location = locator
            .locate(p)
            .ok_or_else(|| FemModelError::Invalid(format!("tracked point {p:?} lies outside the mesh")))?;
        if location.count != 4 {
            return Err(FemModelError::Invalid(format!(
                "tracked points need a tetrahedral mesh, this one has {}-node cells",
                location.count
            )));
        }
        let w: [f64; 4] = std::array::from_fn(|i| location.weights[i].max(0.0));
        let sum: f64 = w.iter().sum();
        Ok(TrackedPoint { nodes: std::array::from_fn(|i| location.nodes[i]), weights: w.map(|v| v / sum) })
    }

    /// Current position of the point: reference position plus interpolated displacement `u` (3 per node).
    pub fn position(&self, nodes: &[Point], u: &[f64]) -> Point {
        let mut x = [0.0; 3];
        for (&n, &w) in self.nodes.iter().zip(&self.weights) {
            for d in 0..3 {
                x[d] += w * (nodes[n][d] + u[3 * n + d]);
            }
        }
        x
    }

    /// Checks the node indices against a mesh of `num_nodes` nodes and the weights (finite, ≥ 0, sum 1).
    pub fn validate(&self, num_nodes: usize) -> Result<(), FemModelError> {
        if let Some(&n) = self.nodes.iter().find(|&&n| n >= num_nodes) {
            return Err(FemModelError::Invalid(format!(
                "tracked point refers to node {n}, but the mesh has {num_nodes} nodes"
            )));
        }
        let sum: f64 = self.weights.iter().sum();
        if self.weights.iter().any(|w| !(w.is_finite() && *w >= 0.0)) || (sum - 1.0).abs() > 1e-9 {
            return Err(FemModelError::Invalid(format!(
                "tracked point weights {:?} must be non-negative and sum to 1",
                self.weights
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
