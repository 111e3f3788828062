//! A load path with a limit point: a shallow clamped arch pushed down at its crown snaps through.
//! Force control follows it up to the limit load; past it, the solver must find the equilibrium
//! the arch snaps to, and say so clearly where it finds none.

use augsim_fem as fem;
use fem::{FemError, Formulation, Law, Material, Problem, Solution, SolverOptions, StaticSolver};

/// Span, rise and thickness of the arch (m).
const SPAN: f64 = 0.2;
const RISE: f64 = 0.03;
const THICK: f64 = 0.01;

/// The arch (20 cm span, 3 cm rise, 1 cm thick, 2 cm wide; Neo-Hookean, E 1 MPa, ν 0.3; 960 T4),
/// clamped at both ends and pushed down at its crown by `force` newtons: the crown's downward
/// deflection (m) and the solution, or the solver's error.
fn arch(force: f64, load_steps: usize) -> Result<(f64, Solution), FemError> {
    let mut mesh = mesh::box_tet([-SPAN / 2.0, 0.0, 0.0], [SPAN / 2.0, THICK, 0.02], [40, 2, 2])?;
    for p in &mut mesh.nodes {
        p[1] += RISE * (1.0 - (2.0 * p[0] / SPAN).powi(2));
    }
    let ends: Vec<usize> = (0..mesh.num_nodes()).filter(|&n| mesh.nodes[n][0].abs() > SPAN / 2.0 - 1e-9).collect();
    let crown: Vec<usize> = (0..mesh.num_nodes())
        .filter(|&n| mesh.nodes[n][0].abs() < 1e-9 && mesh.nodes[n][1] > RISE + THICK - 1e-9)
        .collect();
    let material = Material::new(Law::NeoHookean, 1e6, 0.3).with_formulation(Formulation::Standard);
    let mut problem = Problem::new(mesh, material);
    problem.fix(&ends);
    problem.add_force(&crown, [0.0, -force, 0.0]);
    let solution = StaticSolver::new(problem)?.solve(&SolverOptions { load_steps, ..SolverOptions::default() })?;
    let deflection = -crown.iter().map(|&n| solution.u[3 * n + 1]).sum::<f64>() / crown.len() as f64;
    Ok((deflection, solution))
}

/// Below its limit load (between 1.5 and 2 N) the arch bends by a fraction of its rise; above it,
/// it snaps through to hang below its supports. Load-stepped in 20 steps (or more, where a step is
/// cut), the solve passes the limit point and reaches the same snapped equilibrium as one full step does.
#[test]
fn a_shallow_arch_snaps_through_past_its_limit_load_whether_load_stepped_or_not() {
    let (before, _) = arch(1.5, 1).unwrap();
    assert!(before < RISE / 2.0, "below the limit load the crown moves {before} m");
    let (at_once, _) = arch(2.0, 1).unwrap();
    assert!(at_once > RISE + THICK, "past the limit load the crown moves {at_once} m: not snapped through");
    let (stepped, solution) = arch(2.0, 20).unwrap();
    assert!(solution.load_steps >= 20, "{} load steps", solution.load_steps);
    assert!((stepped - at_once).abs() < 1e-6 * at_once, "stepped {stepped} m, at once {at_once} m");
}

/// A solve that finds no equilibrium names a limit point only where its load path was seen to
/// soften (two converged steps at least, the last far less stiff than the first), and says what
/// to change either way.
#[test]
fn no_equilibrium_names_a_limit_point_only_where_the_path_was_seen_to_soften() {
    let softened = FemError::NoEquilibrium { load_factor: 0.918, softening: 2.04, iterations: 1000 }.to_string();
    assert!(softened.contains("0.918") && softened.contains("2.0 % as stiff") && softened.contains("limit point"));
    let stiff = FemError::NoEquilibrium { load_factor: 0.094, softening: 69.2, iterations: 10 }.to_string();
    assert!(stiff.contains("69.2 % as stiff") && stiff.contains("no sign of a limit point"), "{stiff}");
    let unknown = FemError::NoEquilibrium { load_factor: 0.125, softening: f64::NAN, iterations: 74 }.to_string();
    assert!(!unknown.contains("NaN") && !unknown.contains("limit point"), "{unknown}");
    for message in [softened, stiff, unknown] {
        assert!(message.contains("further iterations found none") && message.contains("lower the load"), "{message}");
    }
}
