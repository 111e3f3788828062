//! The two ways of turning observations into a volumetric displacement: the
//! finite-element model pulled by data springs, and a trained U-Net.

use fem::{NormalSpring, Problem, SolverOptions, StaticSolver};
use learn::generate::normal_part;
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

/// U-Net registration. The observed displacements of the network's input nodes (the visible
/// surface) are first fitted by a smooth field: each node's match offsets with a membrane
/// penalty on neighbouring nodes' differences, unseen nodes interpolated. A network trained on
/// the normal motion of its input nodes (`normal = true` in the dataset's input, as
/// `scenarios/liver_ar.toml`) gets the normal part of that fit, which is what closest-point
/// matching measures, and infers the tangential motion and the volume. A network trained on the
/// full displacement gets the fit itself, and its input nodes keep the fit (fed back, its own
/// predictions at its inputs would drift along the surface, where no match corrects them).
pub struct NetworkDeformer {
    predictor: Predictor,
    grid: Grid,
    to_mesh: GridToMesh,
    /// The input nodes (mesh numbering) and their positions.
    inputs: Vec<usize>,
    points: Vec<mesh::Point>,
    /// Mesh edges between input nodes, as positions in `inputs`.
    edges: Vec<(usize, usize)>,
    /// For a network of normal motion: the outward unit normal of the rest surface at each
    /// input node.
    normals: Option<Vec<mesh::Point>>,
}

/// Weight of the membrane penalty, relative to one matched cloud point's weight.
pub const MEMBRANE_WEIGHT: f64 = 1.0;

/// Weight pulling an input node towards its current estimate (keeps nodes without data or
/// neighbours determined).
const ANCHOR_WEIGHT: f64 = 1e-3;

impl NetworkDeformer {
    /// The deformer of `model` for `organ` (meshed on the model's grid, or embedded in it);
    /// `input_nodes`: the mesh nodes whose displacement the network was trained to take, along
    /// the rest surface's normal only when `normal` (boundary nodes then).
    pub fn new(model: &TrainedModel, organ: &Organ, input_nodes: &[usize], normal: bool) -> Result<NetworkDeformer> {
        if model.input_unit != "m" {
            return Err(RegisterError::Invalid(format!(
                "the model takes {} on its input, registration needs a displacement model (m)",
                model.input_unit
            )));
        }
        let grid = model.placed_grid()?;
        let mesh = organ.mesh();
        let mut local = vec![usize::MAX; mesh.num_nodes()];
        for (i, &n) in input_nodes.iter().enumerate() {
            *local.get_mut(n).ok_or_else(|| RegisterError::Invalid(format!("input node {n} is not a mesh node")))? = i;
        }
        let mut edges = Vec::new();
        for c in 0..mesh.cells.len() {
            let cell = mesh.cells.cell(c);
            for (a, &p) in cell.iter().enumerate() {
                for &q in &cell[a + 1..] {
                    let (i, j) = (local[p], local[q]);
                    if i != usize::MAX && j != usize::MAX {
                        edges.push((i.min(j), i.max(j)));
                    }
                }
            }
        }
        edges.sort_unstable();
        edges.dedup();
        let normals = if normal {
            let all = mesh::boundary_surface(mesh).vertex_normals();
            let picked: Vec<mesh::Point> = input_nodes.iter().map(|&n| all[n]).collect();
            if let Some(i) = picked.iter().position(|n| *n == [0.0; 3]) {
                return Err(RegisterError::Invalid(format!(
                    "input node {} is not on the surface: it has no normal",
                    input_nodes[i]
                )));
            }
            Some(picked)
        } else {
            None
        };
        Ok(NetworkDeformer {
            predictor: Predictor::new(model, learn::Compute::Cpu)?,
            to_mesh: GridToMesh::new(mesh, &grid)?,
            grid,
            inputs: input_nodes.to_vec(),
            points: input_nodes.iter().map(|&n| mesh.nodes[n]).collect(),
            edges,
            normals,
        })
    }

    /// The surface estimate: per coordinate, `(W + ε I + λ L) s = W d + ε s₀` (W: match weights,
    /// d: observed displacements, L: the graph Laplacian of the input nodes, s₀: the current
    /// estimate), solved by conjugate gradients from s₀.
    fn surface_estimate(&self, observations: &Observations, previous: &[f64]) -> Vec<[f64; 3]> {
        let m = self.inputs.len();
        let w: Vec<f64> = self.inputs.iter().map(|&n| observations.weight[n]).collect();
        let diagonal: Vec<f64> = w.iter().map(|w| w + ANCHOR_WEIGHT).collect();
        let apply = |x: &[f64], out: &mut [f64]| {
            for i in 0..m {
                out[i] = diagonal[i] * x[i];
            }
            for &(i, j) in &self.edges {
                let f = MEMBRANE_WEIGHT * (x[i] - x[j]);
                out[i] += f;
                out[j] -= f;
            }
        };
        let mut estimate = vec![[0.0; 3]; m];
        for d in 0..3 {
            let start: Vec<f64> = self.inputs.iter().map(|&n| previous[3 * n + d]).collect();
            let rhs: Vec<f64> =
                (0..m).map(|i| w[i] * observations.target[self.inputs[i]][d] + ANCHOR_WEIGHT * start[i]).collect();
            let x = conjugate_gradients(apply, &rhs, start, 1e-10);
            for i in 0..m {
                estimate[i][d] = x[i];
            }
        }
        estimate
    }
}

/// Solves `A x = b` for a symmetric positive definite `A` given by its product, from `x`, to a
/// relative residual of `tolerance` (at most `b.len()` iterations).
fn conjugate_gradients(apply: impl Fn(&[f64], &mut [f64]), b: &[f64], mut x: Vec<f64>, tolerance: f64) -> Vec<f64> {
    let n = b.len();
    let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
    let mut ax = vec![0.0; n];
    apply(&x, &mut ax);
    let mut r: Vec<f64> = b.iter().zip(&ax).map(|(b, a)| b - a).collect();
    let mut p = r.clone();
    let mut rr = dot(&r, &r);
    let stop = tolerance * tolerance * dot(b, b).max(f64::MIN_POSITIVE);
    let mut ap = vec![0.0; n];
    for _ in 0..n {
        if rr <= stop {
            break;
        }
        apply(&p, &mut ap);
        let alpha = rr / dot(&p, &ap);
        for i in 0..n {
            x[i] += alpha * p[i];
            r[i] -= alpha * ap[i];
        }
        let next = dot(&r, &r);
        for i in 0..n {
            p[i] = r[i] + next / rr * p[i];
        }
        rr = next;
    }
    x
}

impl Deformer for NetworkDeformer {
    fn deform(&mut self, observations: &Observations, previous: &[f64], _iteration: usize) -> Result<Vec<f64>> {
        if !self.inputs.iter().any(|&n| observations.weight[n] > 0.0) {
            return Err(RegisterError::Invalid("no cloud point matches the network's input surface".into()));
        }
        let surface = self.surface_estimate(observations, previous);
        match &self.normals {
            Some(normals) => {
                let along: Vec<mesh::Point> = surface.iter().zip(normals).map(|(s, &n)| normal_part(s, n)).collect();
                let input = encode_points(&self.grid, &self.points, &along, false)?;
                Ok(self.to_mesh.apply(&self.predictor.predict(&input)?)?)
            }
            None => {
                let input = encode_points(&self.grid, &self.points, &surface, false)?;
                let mut u = self.to_mesh.apply(&self.predictor.predict(&input)?)?;
                for (&n, s) in self.inputs.iter().zip(&surface) {
                    u[3 * n..3 * n + 3].copy_from_slice(s);
                }
                Ok(u)
            }
        }
    }
}
