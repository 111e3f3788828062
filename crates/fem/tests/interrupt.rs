//! A stop request ends a solve at its next iteration; withdrawn, solves run again. In a binary of
//! its own: the request is the whole process's.

use augsim_fem as fem;
use fem::{FemError, Law, Material, Problem, SolverOptions, StaticSolver};
use mesh::CellKind;

#[test]
fn a_requested_stop_ends_the_solve_and_its_withdrawal_lets_the_next_run() {
    let (l, h) = (4.0, 1.0);
    let m = mesh::box_mesh(CellKind::Hex8, [0.0; 3], [l, h, h], [8, 2, 2]).unwrap();
    let clamp = mesh::select::nodes_in_box(&m.nodes, [-1e-9; 3], [1e-9, h + 1e-9, h + 1e-9]);
    let tip = mesh::select::nodes_in_box(&m.nodes, [l - 1e-9, -1e-9, -1e-9], [l + 1e-9, h + 1e-9, h + 1e-9]);
    let mut problem = Problem::new(m, Material::new(Law::NeoHookean, 300.0, 0.3));
    problem.fix(&clamp);
    problem.add_traction(&tip, [0.0, 0.0, -5.0]);
    let mut solver = StaticSolver::new(problem).unwrap();
    let options = SolverOptions { load_steps: 4, ..Default::default() };
    fem::interrupt::request();
    let stopped = solver.solve(&options);
    fem::interrupt::clear();
    assert!(matches!(stopped, Err(FemError::Interrupted)), "{:?}", stopped.map(|s| s.iterations));
    let solved = solver.solve(&options).unwrap();
    assert!(solved.u.iter().any(|&v| v < -0.1), "the tip must move down");
}
