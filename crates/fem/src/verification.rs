//! Reference problems with known answers, shared by the tests and the
//! examples that print the README's verification tables.

use mesh::CellKind;

use crate::material::{Formulation, Law, Material};
use crate::problem::Problem;
use crate::solver::{SolverOptions, StaticSolver};
use crate::FemError;

/// The reference cantilever: length (m), Young's modulus (Pa) and end traction (Pa), small
/// enough for a linear response.
const CANTILEVER: (f64, f64, f64) = (10.0, 1000.0, 1e-4);

/// A 10 × 1 × 1 cantilever (Young's modulus 1,000 Pa) clamped at x = 0 under a small downward
/// end traction, divided into cells of `kind` ([`mesh::box_mesh`]: H8, or 6 T4 or T10 per
/// cell): the problem and its tip nodes.
pub fn cantilever(
    kind: CellKind,
    cells: [usize; 3],
    law: Law,
    formulation: Formulation,
    poisson: f64,
) -> Result<(Problem, Vec<usize>), FemError> {
    let (length, young, load) = CANTILEVER;
    let m = mesh::box_mesh(kind, [0.0; 3], [length, 1.0, 1.0], cells)?;
    let clamp = mesh::select::nodes_in_box(&m.nodes, [-1e-9; 3], [1e-9, 1.0 + 1e-9, 1.0 + 1e-9]);
    let tip = mesh::select::nodes_in_box(&m.nodes, [length - 1e-9, -1e-9, -1e-9], [length + 1e-9, 1.1, 1.1]);
    let mut problem = Problem::new(m, Material::new(law, young, poisson).with_formulation(formulation));
    problem.fix(&clamp);
    problem.add_traction(&tip, [0.0, 0.0, -load]);
    Ok((problem, tip))
}

/// A cantilever of 10 × 2 × 2 cells of `kind` (T4 made T10 for `order` 2), 0.1 × 0.02 × 0.02 m
/// (E = 5 kPa), clamped at x = 0, a downward `load` (N) on its free end: bent by centimetres
/// under a few hundredths of a newton.
pub fn bent_beam(kind: CellKind, order: u8, law: Law, poisson: f64, load: f64) -> Result<Problem, FemError> {
    let (length, side) = (0.1, 0.02);
    let m = mesh::box_mesh(kind, [0.0; 3], [length, side, side], [10, 2, 2])?;
    let end =
        |x: f64| mesh::select::nodes_in_box(&m.nodes, [x - 1e-9, -1e-9, -1e-9], [x + 1e-9, side + 1e-9, side + 1e-9]);
    let (clamp, tip) = (end(0.0), end(length));
    let material = Material::new(law, 5000.0, poisson).with_order(order).with_formulation(Formulation::Standard);
    let mut p = Problem::new(m, material);
    p.fix(&clamp);
    p.add_force(&tip, [0.0, 0.0, -load]);
    Ok(p)
}

/// The mean downward deflection of the `tip` nodes under the displacement `u`.
pub fn tip_deflection(u: &[f64], tip: &[usize]) -> f64 {
    -tip.iter().map(|&n| u[3 * n + 2]).sum::<f64>() / tip.len() as f64
}

/// Timoshenko beam theory's tip deflection of the [`cantilever`], PL³/(3EI) + PL/(κGA) with
/// Cowper's κ = 10(1 + ν)/(12 + 11ν).
pub fn timoshenko_deflection(poisson: f64) -> f64 {
    let (length, young, load) = CANTILEVER;
    let (inertia, area) = (1.0 / 12.0, 1.0);
    let shear_coefficient = 10.0 * (1.0 + poisson) / (12.0 + 11.0 * poisson);
    let shear_modulus = young / (2.0 * (1.0 + poisson));
    load * length.powi(3) / (3.0 * young * inertia) + load * length / (shear_coefficient * shear_modulus * area)
}

/// The [`cantilever`]'s tip deflection over [`timoshenko_deflection`].
pub fn cantilever_deflection_ratio(
    kind: CellKind,
    cells: [usize; 3],
    law: Law,
    formulation: Formulation,
    poisson: f64,
) -> Result<f64, FemError> {
    let (problem, tip) = cantilever(kind, cells, law, formulation, poisson)?;
    let u = StaticSolver::new(problem)?.solve(&SolverOptions { rtol: 1e-10, ..Default::default() })?.u;
    Ok(tip_deflection(&u, &tip) / timoshenko_deflection(poisson))
}
