//! The two ways of turning observations into a volumetric displacement: the
//! finite-element model pulled by data springs, and a trained U-Net.

use fem::{NormalSpring, Problem, SolverOptions, StaticSolver};
use learn::{encode_points, GridToMesh, Predictor, TrainedModel};
use mesh::embedding::Grid;

use crate::organ::Organ;
use crate::register::{Deformer, Observations};
use crate::{RegisterError, Result};

/// Finite-element registration: every observed node is tied by a zero-length
/// spring to its observed position; the organ's own boundary conditions
/// (fixed nodes, its springs) hold the rest. The scenario's loads are dropped:
/// the intraoperative loads are unknown, the data stand in for them. The springs
/// stiffen over the first iterations of a frame ([`STIFFNESS_RAMP`]): the first
/// matches of a large deformation are poor, and stiff springs pulling towards them
/// would crush elements.
pub struct FemDeformer {
    solver: StaticSolver,
    base_springs: Vec<f64>,
    stiffness: f64,
    options: SolverOptions,
}

/// Share of the data stiffness that ties a node to its observed position in
/// every direction; the rest acts along the surface normal only (point to
/// plane), so that the surface can slide along itself.
pub const ISOTROPIC_FRACTION: f64 = 0.05;

/// Iterations over which the data springs reach their stiffness, ×4 per iteration.
pub const STIFFNESS_RAMP: usize = 3;

impl FemDeformer {
    /// The deformer of `problem` (its mesh must be the organ's) with data springs of
    /// `stiffness` N/m in total, shared by the matched cloud points.
    pub fn new(mut problem: Problem, stiffness: f64, options: SolverOptions) -> Result<FemDeformer> {
        if !(stiffness > 0.0 && stiffness.is_finite()) {
            return Err(RegisterError::Invalid(format!("data stiffness {stiffness} N/m must be positive")));
        }
        problem.f_ext.iter_mut().for_each(|f| *f = 0.0);
        let base_springs = problem.springs.clone();
        Ok(FemDeformer { solver: StaticSolver::new(problem)?, base_springs, stiffness, options })
    }

    /// A data stiffness a hundred times the organ's own scale E·L (L: the cube root of its
    /// volume): the surface follows the data within a millimetre where a small patch of it
    /// moves by centimetres; the model fills in the rest.
    pub fn default_stiffness(problem: &Problem) -> f64 {
        100.0 * problem.material.young * problem.mesh.volume().abs().cbrt()
    }
}

impl Deformer for FemDeformer {
    fn deform(&mut self, observations: &Observations, previous: &[f64], iteration: usize) -> Result<Vec<f64>> {
        let total: f64 = observations.weight.iter().sum();
        if !(total > 0.0) {
            return Err(RegisterError::Invalid("no cloud point matches the organ surface".into()));
        }
        let ramp = 0.25f64.powi(STIFFNESS_RAMP.saturating_sub(iteration) as i32);
        let k = ramp * self.stiffness / total;
        let problem = self.solver.problem_mut();
        problem.normal_springs.clear();
        for (n, (&w, t)) in observations.weight.iter().zip(&observations.target).enumerate() {
            let (k_all, k_normal) = (ISOTROPIC_FRACTION * k * w, (1.0 - ISOTROPIC_FRACTION) * k * w);
            let normal = observations.normal[n];
            let along = mesh::dot(normal, *t);
            problem.springs[n] = self.base_springs[n] + k_all;
            for d in 0..3 {
                problem.f_ext[3 * n + d] = k_all * t[d] + k_normal * along * normal[d];
            }
            if k_normal > 0.0 {
                problem.normal_springs.push(NormalSpring { node: n, normal, stiffness: k_normal });
            }
        }
        Ok(self.solver.solve_from(Some(previous), &self.options)?.u)
    }
}

/// U-Net registration: the observed displacements of the network's input nodes
/// go to the grid as in training; the predicted field is read back at the mesh nodes.
pub struct NetworkDeformer {
    predictor: Predictor,
    grid: Grid,
    to_mesh: GridToMesh,
    nodes: Vec<mesh::Point>,
    input: Vec<bool>,
}

impl NetworkDeformer {
    /// The deformer of `model` for `organ` (meshed on the model's grid, or embedded in it);
    /// `input_nodes`: the mesh nodes whose displacement the network was trained to take.
    pub fn new(model: &TrainedModel, organ: &Organ, input_nodes: &[usize]) -> Result<NetworkDeformer> {
        let placement = model.placement.ok_or_else(|| {
            RegisterError::Invalid("the model does not record where its grid lies: retrain it".into())
        })?;
        if model.input_unit != "m" {
            return Err(RegisterError::Invalid(format!(
                "the model takes {} on its input, registration needs a displacement model (m)",
                model.input_unit
            )));
        }
        let grid = placement.grid(model.grid)?;
        let mesh = organ.mesh();
        let mut input = vec![false; mesh.num_nodes()];
        for &n in input_nodes {
            *input.get_mut(n).ok_or_else(|| RegisterError::Invalid(format!("input node {n} is not a mesh node")))? =
                true;
        }
        Ok(NetworkDeformer {
            predictor: Predictor::new(model)?,
            to_mesh: GridToMesh::new(mesh, &grid)?,
            grid,
            nodes: mesh.nodes.clone(),
            input,
        })
    }
}

impl Deformer for NetworkDeformer {
    fn deform(&mut self, observations: &Observations, previous: &[f64], _iteration: usize) -> Result<Vec<f64>> {
        if !observations.weight.iter().zip(&self.input).any(|(&w, &input)| w > 0.0 && input) {
            return Err(RegisterError::Invalid("no cloud point matches the network's input surface".into()));
        }
        // The network was trained on the full displacement of every input node, but a closest-point
        // match measures only the offset along the surface normal: each observed input node takes
        // the current estimate moved along its normal by the observed offset (point to plane); an
        // input node that no cloud point reaches keeps its current estimate (zero would read as
        // "did not move").
        let (mut points, mut values) = (Vec::new(), Vec::new());
        for (n, (&w, t)) in observations.weight.iter().zip(&observations.target).enumerate() {
            if self.input[n] {
                let current = [previous[3 * n], previous[3 * n + 1], previous[3 * n + 2]];
                let value = if w > 0.0 {
                    let normal = observations.normal[n];
                    let along: f64 = (0..3).map(|d| (t[d] - current[d]) * normal[d]).sum();
                    std::array::from_fn(|d| current[d] + along * normal[d])
                } else {
                    current
                };
                points.push(self.nodes[n]);
                values.push(value);
            }
        }
        let input = encode_points(&self.grid, &points, &values, false)?;
        Ok(self.to_mesh.apply(&self.predictor.predict(&input)?)?)
    }
}
