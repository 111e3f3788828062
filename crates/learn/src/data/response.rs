//! The linear-elastic response at rest of a dataset's problem, as a map between grid fields: a
//! physics prior for a model of force inputs ([`crate::rom`]).
//!
//! An input force field on the grid is pulled back to the organ's surface nodes (each grid node's
//! force shared among the surface nodes whose force the encoding spread to it, in proportion to
//! their trilinear weights: the total force is kept), solved by the tangent at rest (`K₀⁻¹`, one
//! factorisation kept for every solve), and interpolated to the grid as the targets are. The map
//! is linear; its transpose ([`RestResponse::adjoint`]) costs one solve too, since `K₀` is
//! symmetric.

use fem::StaticSolver;

use crate::data::grid::CHANNELS;
use crate::{LearnError, Result};

/// The linear response at rest between grid fields (see the module documentation).
pub struct RestResponse {
    solver: StaticSolver,
    grid_nodes: usize,
    /// Per mesh node, the grid nodes whose force it takes, with its share of each.
    pull: Vec<Vec<(usize, f64)>>,
    /// Per grid node, the mesh nodes its displacement interpolates, with their weights.
    push: Vec<Vec<(usize, f64)>>,
    description: String,
}

impl RestResponse {
    /// The response of `solver`'s problem, with the pull-back and interpolation weights (see the
    /// fields), described in `description`.
    pub(crate) fn new(
        solver: StaticSolver,
        grid_nodes: usize,
        pull: Vec<Vec<(usize, f64)>>,
        push: Vec<Vec<(usize, f64)>>,
        description: String,
    ) -> RestResponse {
        RestResponse { solver, grid_nodes, pull, push, description }
    }

    /// What the response is (law, modulus, elements), for a model's record.
    pub fn description(&self) -> &str {
        &self.description
    }

    fn check(&self, field: usize) -> Result<()> {
        if field != CHANNELS * self.grid_nodes {
            return Err(LearnError::InvalidInput(format!(
                "a grid field of {field} values, expected {CHANNELS} × {}",
                self.grid_nodes
            )));
        }
        Ok(())
    }

    /// The displacement field (`[3, nx, ny, nz]`, m) of the force field `force` (N).
    pub fn apply(&mut self, force: &[f64]) -> Result<Vec<f64>> {
        self.check(force.len())?;
        let mut f = to_mesh(pairs_of_mesh(&self.pull), force, self.grid_nodes, self.pull.len());
        self.solver.rest_solve(&mut f)?;
        Ok(to_grid(pairs_of_grid(&self.push), &f, self.grid_nodes))
    }

    /// The transpose: for weights `b` on the displacement field, the weights `a` on the force
    /// field with `a · x = b · apply(x)` for every force field `x`.
    pub fn adjoint(&mut self, b: &[f64]) -> Result<Vec<f64>> {
        self.check(b.len())?;
        let mut v = to_mesh(pairs_of_grid(&self.push), b, self.grid_nodes, self.pull.len());
        self.solver.rest_solve(&mut v)?;
        Ok(to_grid(pairs_of_mesh(&self.pull), &v, self.grid_nodes))
    }
}

/// The (grid node, mesh node, weight) pairs of terms listed per mesh node.
fn pairs_of_mesh(terms: &[Vec<(usize, f64)>]) -> impl Iterator<Item = (usize, usize, f64)> + '_ {
    terms.iter().enumerate().flat_map(|(m, t)| t.iter().map(move |&(g, w)| (g, m, w)))
}

/// The (grid node, mesh node, weight) pairs of terms listed per grid node.
fn pairs_of_grid(terms: &[Vec<(usize, f64)>]) -> impl Iterator<Item = (usize, usize, f64)> + '_ {
    terms.iter().enumerate().flat_map(|(g, t)| t.iter().map(move |&(m, w)| (g, m, w)))
}

/// A grid field (`[3, n]`) carried to the `nodes` mesh nodes (`[nodes, 3]`) through `pairs`:
/// mesh(m) += w · grid(g).
fn to_mesh(pairs: impl Iterator<Item = (usize, usize, f64)>, grid: &[f64], n: usize, nodes: usize) -> Vec<f64> {
    let mut mesh = vec![0.0; CHANNELS * nodes];
    for (g, m, w) in pairs {
        (0..CHANNELS).for_each(|c| mesh[CHANNELS * m + c] += w * grid[c * n + g]);
    }
    mesh
}

/// A mesh field (`[nodes, 3]`) carried to the grid's `n` nodes (`[3, n]`) through `pairs`:
/// grid(g) += w · mesh(m).
fn to_grid(pairs: impl Iterator<Item = (usize, usize, f64)>, mesh: &[f64], n: usize) -> Vec<f64> {
    let mut grid = vec![0.0; CHANNELS * n];
    for (g, m, w) in pairs {
        (0..CHANNELS).for_each(|c| grid[c * n + g] += w * mesh[CHANNELS * m + c]);
    }
    grid
}
