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
        let n = self.grid_nodes;
        let mut f = vec![0.0; CHANNELS * self.pull.len()];
        for (m, terms) in self.pull.iter().enumerate() {
            for &(g, share) in terms {
                (0..CHANNELS).for_each(|c| f[CHANNELS * m + c] += share * force[c * n + g]);
            }
        }
        self.solver.rest_solve(&mut f)?;
        let mut out = vec![0.0; CHANNELS * n];
        for (g, terms) in self.push.iter().enumerate() {
            for &(m, w) in terms {
                (0..CHANNELS).for_each(|c| out[c * n + g] += w * f[CHANNELS * m + c]);
            }
        }
        Ok(out)
    }

    /// The transpose: for weights `b` on the displacement field, the weights `a` on the force
    /// field with `a · x = b · apply(x)` for every force field `x`.
    pub fn adjoint(&mut self, b: &[f64]) -> Result<Vec<f64>> {
        self.check(b.len())?;
        let n = self.grid_nodes;
        let mut v = vec![0.0; CHANNELS * self.pull.len()];
        for (g, terms) in self.push.iter().enumerate() {
            for &(m, w) in terms {
                (0..CHANNELS).for_each(|c| v[CHANNELS * m + c] += w * b[c * n + g]);
            }
        }
        self.solver.rest_solve(&mut v)?;
        let mut out = vec![0.0; CHANNELS * n];
        for (m, terms) in self.pull.iter().enumerate() {
            for &(g, share) in terms {
                (0..CHANNELS).for_each(|c| out[c * n + g] += share * v[CHANNELS * m + c]);
            }
        }
        Ok(out)
    }
}
