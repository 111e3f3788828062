//! Reference problems with known answers, shared by the tests and the
//! examples that print the README's verification tables.

use mesh::CellKind;

use crate::material::{Formulation, Law, Material};
use crate::problem::Problem;
use crate::solver::{SolverOptions, StaticSolver};
use crate::FemError;

/// Tip deflection of a 10 × 1 × 1 cantilever (Young's modulus 1,000 Pa) clamped
/// at x = 0 under a small downward end traction, divided by Timoshenko beam
/// theory's PL³/(3EI) + PL/(κGA) with Cowper's κ = 10(1 + ν)/(12 + 11ν).
/// `cells` divides the beam into cells of `kind` ([`mesh::box_mesh`]: H8, or 6 T4 or T10 per cell).
pub fn cantilever_deflection_ratio(
    kind: CellKind,
    cells: [usize; 3],
    law: Law,
    formulation: Formulation,
    poisson: f64,
) -> Result<f64, FemError> {
    let (length, young, load) = (10.0, 1000.0, 1e-4);
    let hi = [length, 1.0, 1.0];
    let m = mesh::box_mesh(kind, [0.0; 3], hi, cells)?;
    let clamp = mesh::select::nodes_in_box(&m.nodes, [-1e-9; 3], [1e-9, 1.0 + 1e-9, 1.0 + 1e-9]);
    let tip = mesh::select::nodes_in_box(&m.nodes, [length - 1e-9, -1e-9, -1e-9], [length + 1e-9, 1.1, 1.1]);
    let mut problem = Problem::new(m, Material::new(law, young, poisson).with_formulation(formulation));
    problem.fix(&clamp);
    problem.add_traction(&tip, [0.0, 0.0, -load]);
    let u = StaticSolver::new(problem)?.solve(&SolverOptions { rtol: 1e-10, ..Default::default() })?.u;
    let w = -tip.iter().map(|&n| u[3 * n + 2]).sum::<f64>() / tip.len() as f64;
    let (inertia, area) = (1.0 / 12.0, 1.0);
    let shear_coefficient = 10.0 * (1.0 + poisson) / (12.0 + 11.0 * poisson);
    let shear_modulus = young / (2.0 * (1.0 + poisson));
    let theory =
        load * length.powi(3) / (3.0 * young * inertia) + load * length / (shear_coefficient * shear_modulus * area);
    Ok(w / theory)
}
