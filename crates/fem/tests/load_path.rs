//! Load paths that force control finds hard. A shallow clamped arch pushed down at its crown has
//! a limit point: force control follows it up to the limit load; past it, the solver must find the
//! equilibrium the arch snaps to, and say so clearly where it finds none. A soft block swinging
//! from the strip that holds it. On both, the arc-length continuation against force control: where
//! both find the equilibrium, the same one; past a limit point it stops there and says so; it
//! refuses what it cannot scale.

use augsim_fem as fem;
use fem::{Continuation, FemError, Formulation, Law, Material, Problem, Solution, SolverOptions, StaticSolver};

/// Span, rise and thickness of the arch (m).
const SPAN: f64 = 0.2;
const RISE: f64 = 0.03;
const THICK: f64 = 0.01;

/// The arch (20 cm span, 3 cm rise, 1 cm thick, 2 cm wide; Neo-Hookean, E 1 MPa, ν 0.3; 960 T4),
/// clamped at both ends and pushed down at its crown by `force` newtons (its limit load lies
/// between 1.5 and 2 N); and its crown's nodes.
fn arch_problem(force: f64) -> (Problem, Vec<usize>) {
    let mut mesh = mesh::box_tet([-SPAN / 2.0, 0.0, 0.0], [SPAN / 2.0, THICK, 0.02], [40, 2, 2]).unwrap();
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
    (problem, crown)
}

/// The crown's mean downward deflection (m) in `u`.
fn crown_deflection(u: &[f64], crown: &[usize]) -> f64 {
    -crown.iter().map(|&n| u[3 * n + 1]).sum::<f64>() / crown.len() as f64
}

/// The arch pushed by `force` newtons in `load_steps` load steps: the crown's downward deflection
/// (m) and the solution, or the solver's error.
fn arch(force: f64, load_steps: usize) -> Result<(f64, Solution), FemError> {
    let (problem, crown) = arch_problem(force);
    let solution = StaticSolver::new(problem)?.solve(&SolverOptions { load_steps, ..SolverOptions::default() })?;
    Ok((crown_deflection(&solution.u, &crown), solution))
}

/// A soft block (12 × 6 × 4 cm, Neo-Hookean, E 5 kPa, ν 0.49, 1,728 T4) held by a 2 cm strip of
/// its back, and pushed sideways at its far end by `force` newtons: it swings from the strip.
fn hanging_block(force: f64) -> Problem {
    let mesh = mesh::box_tet([0.0; 3], [0.12, 0.06, 0.04], [12, 6, 4]).unwrap();
    let held: Vec<usize> =
        (0..mesh.num_nodes()).filter(|&n| mesh.nodes[n][1] > 0.06 - 1e-9 && mesh.nodes[n][0] < 0.02 + 1e-9).collect();
    let end: Vec<usize> =
        (0..mesh.num_nodes()).filter(|&n| mesh.nodes[n][0] > 0.12 - 1e-9 && mesh.nodes[n][1] < 1e-9).collect();
    let material = Material::new(Law::NeoHookean, 5000.0, 0.49).with_formulation(Formulation::Standard);
    let mut problem = Problem::new(mesh, material);
    problem.fix(&held);
    problem.add_force(&end, [0.0, 0.0, force]);
    problem
}

fn solve(problem: Problem, continuation: Continuation) -> Result<Solution, FemError> {
    StaticSolver::new(problem)?.solve(&SolverOptions { continuation, ..SolverOptions::default() })
}

/// The largest difference between two displacement fields over the largest motion.
fn relative_difference(a: &[f64], b: &[f64]) -> f64 {
    let largest = a.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    a.iter().zip(b).fold(0.0f64, |m, (x, y)| m.max((x - y).abs())) / largest
}

/// Below its limit load (between 1.5 and 2 N) the arch bends by a fraction of its rise; above it,
/// it snaps through to hang below its supports. Load-stepped in 20 steps (or more, where a step is
/// cut), the solve passes the limit point, says so, and reaches the same snapped equilibrium as one full
/// step does.
#[test]
fn a_shallow_arch_snaps_through_past_its_limit_load_whether_load_stepped_or_not() {
    let (before, _) = arch(1.5, 1).unwrap();
    assert!(before < RISE / 2.0, "below the limit load the crown moves {before} m");
    let (at_once, once) = arch(2.0, 1).unwrap();
    assert!(at_once > RISE + THICK, "past the limit load the crown moves {at_once} m: not snapped through");
    // In one step too, the solve says it snapped: measured against the stiffness at rest.
    assert!(once.snapped_from.is_some(), "a snap in a single load step not told");
    assert_eq!(arch(1.5, 1).unwrap().1.snapped_from, None);
    let (stepped, solution) = arch(2.0, 20).unwrap();
    assert!(solution.load_steps >= 20, "{} load steps", solution.load_steps);
    // Load-stepped, the solution says where it snapped: from an equilibrium short of the limit
    // point; below the limit load it did not.
    assert!(solution.snapped_from.is_some_and(|l| (0.7..1.0).contains(&l)), "{:?}", solution.snapped_from);
    assert_eq!(arch(1.5, 20).unwrap().1.snapped_from, None);
    // Followed again by arc length, the step is seen to pass the limit point, which lies above
    // the equilibrium it started from.
    let (problem, _) = arch_problem(2.0);
    let options = SolverOptions { load_steps: 20, confirm_snaps: true, ..SolverOptions::default() };
    let limit = StaticSolver::new(problem).unwrap().solve(&options).unwrap().snapped_from;
    assert!(limit.is_some_and(|l| l > solution.snapped_from.unwrap() && l < 1.0), "{limit:?}");
    assert!((stepped - at_once).abs() < 1e-6 * at_once, "stepped {stepped} m, at once {at_once} m");
}

/// A solve that finds no equilibrium names a limit point only where its load path was seen to
/// soften (two converged steps at least, the last far less stiff than the first), and says what
/// to change either way.
#[test]
fn no_equilibrium_names_a_limit_point_only_where_the_path_was_seen_to_soften() {
    let softened = FemError::NoEquilibrium { load_factor: 0.918, softening: 2.04, indefinite: false, iterations: 1000 }
        .to_string();
    assert!(softened.contains("0.918") && softened.contains("2.0 % as stiff") && softened.contains("limit point"));
    let stiff =
        FemError::NoEquilibrium { load_factor: 0.094, softening: 69.2, indefinite: false, iterations: 10 }.to_string();
    assert!(stiff.contains("69.2 % as stiff") && stiff.contains("no sign of a limit point"), "{stiff}");
    assert!(stiff.contains("[solver] max_iterations"), "{stiff}");
    let turned =
        FemError::NoEquilibrium { load_factor: 0.96, softening: -0.6, indefinite: false, iterations: 681 }.to_string();
    assert!(turned.contains("the load path had turned there") && !turned.contains("-0.6 % as stiff"), "{turned}");
    let lost = FemError::NoEquilibrium { load_factor: 0.634, softening: 119.7, indefinite: true, iterations: 69 };
    let lost = lost.to_string();
    assert!(lost.contains("turned indefinite") && !lost.contains("no sign of a limit point"), "{lost}");
    let unknown =
        FemError::NoEquilibrium { load_factor: 0.125, softening: f64::NAN, indefinite: false, iterations: 74 }
            .to_string();
    assert!(!unknown.contains("NaN") && !unknown.contains("limit point"), "{unknown}");
    for message in [softened, stiff, turned, lost, unknown] {
        assert!(message.contains("further iterations found none") && message.contains("lower the load"), "{message}");
    }
}

/// Swung by 1 N through about 16 cm, the block reaches the same equilibrium by arc length from rest
/// as by force control, in many more, shorter steps.
#[test]
fn an_arc_length_continuation_reaches_the_equilibrium_that_force_control_finds() {
    let force = solve(hanging_block(1.0), Continuation::ForceOnly).unwrap();
    let arc = solve(hanging_block(1.0), Continuation::ArcLength).unwrap();
    let largest = force.u.chunks(3).map(|d| (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt()).fold(0.0, f64::max);
    assert!(largest > 0.1, "the block moved {largest} m: not a large motion");
    let difference = relative_difference(&force.u, &arc.u);
    assert!(difference < 1e-5, "arc length and force control differ by {difference:e} of the motion");
    assert!(arc.load_steps > 10 * force.load_steps, "{} arc steps, {} load steps", arc.load_steps, force.load_steps);
    // The arch below its limit load, likewise.
    let arch_force = solve(arch_problem(1.5).0, Continuation::ForceOnly).unwrap().u;
    let arch_arc = solve(arch_problem(1.5).0, Continuation::ArcLength).unwrap();
    let difference = relative_difference(&arch_force, &arch_arc.u);
    assert!(difference < 1e-5, "the arch by arc length and by force control differs by {difference:e}");
}

/// Past the arch's limit load the continuation, which follows stable equilibria only, stops at the
/// limit point (between 1.5 and 2 N, so between load factors 0.75 and 1 of a 2 N push) and names
/// it; force control's patient attempt finds the equilibrium the arch snaps to.
#[test]
fn the_continuation_stops_at_a_limit_point_and_names_it() {
    let (problem, crown) = arch_problem(2.0);
    match solve(problem.clone(), Continuation::ArcLength) {
        Err(e @ FemError::NoEquilibrium { load_factor, .. }) => {
            assert!((0.75..1.0).contains(&load_factor), "stopped at load factor {load_factor}");
            assert!(e.to_string().contains("a limit point"), "{e}");
        }
        other => panic!("the arch went past its limit load by arc length: {:?}", other.map(|s| s.load_steps)),
    }
    let snapped = solve(problem, Continuation::Force).unwrap();
    let crown_down = crown_deflection(&snapped.u, &crown);
    assert!(crown_down > 0.04, "the crown moved down {crown_down} m: not snapped through");
}

/// The load factor scales loads: a prescribed displacement is refused with a clear error.
#[test]
fn an_arc_length_continuation_refuses_prescribed_displacements() {
    let mut problem = hanging_block(0.1);
    problem.prescribe(&[0], [0.001, 0.0, 0.0]);
    match solve(problem, Continuation::ArcLength) {
        Err(FemError::Invalid(message)) => assert!(message.contains("prescribed displacements"), "{message}"),
        other => panic!("expected a refusal, got {:?}", other.map(|s| s.load_steps)),
    }
}

/// Solver settings that cannot follow a load path are refused, naming the setting.
#[test]
fn settings_that_cannot_solve_are_refused() {
    let default = SolverOptions::default();
    for (options, what) in [
        (SolverOptions { load_steps: 0, ..default.clone() }, "load_steps = 0"),
        (SolverOptions { max_iterations: 0, ..default.clone() }, "max_iterations = 0"),
        (SolverOptions { rtol: 0.0, ..default.clone() }, "rtol = 0"),
        (SolverOptions { rtol: 0.5, ..default.clone() }, "rtol = 0.5 would take a residual cut by less than"),
        (SolverOptions { utol: f64::NAN, ..default.clone() }, "utol = NaN"),
    ] {
        let mut solver = StaticSolver::new(hanging_block(0.01)).unwrap();
        match solver.solve(&options) {
            Err(FemError::Invalid(message)) => assert!(message.contains(what), "{message}"),
            other => panic!("{what}: expected a refusal, got {:?}", other.map(|s| s.load_steps)),
        }
    }
}

/// A slender column (20 × 1 × 1 cm, Neo-Hookean, E 1 MPa, ν 0.3, 40 × 2 × 2 H8) clamped at its
/// base and pressed down at its top by `force` newtons, pushed sideways by a hundredth of it (an
/// imperfection); and its top's nodes.
fn column_problem(force: f64) -> (Problem, Vec<usize>) {
    let mesh = mesh::box_hex([0.0; 3], [0.01, 0.01, 0.2], [2, 2, 40]).unwrap();
    let base: Vec<usize> = (0..mesh.num_nodes()).filter(|&n| mesh.nodes[n][2] < 1e-9).collect();
    let top: Vec<usize> = (0..mesh.num_nodes()).filter(|&n| mesh.nodes[n][2] > 0.2 - 1e-9).collect();
    let material = Material::new(Law::NeoHookean, 1e6, 0.3).with_formulation(Formulation::Fbar);
    let mut problem = Problem::new(mesh, material);
    problem.fix(&base);
    problem.add_force(&top, [0.01 * force, 0.0, -force]);
    (problem, top)
}

/// Past its buckling load (about 0.05 N) the column bends over, its top sinking fast under a
/// load that still grows: a path as soft as a snap's, without a limit point. Force-controlled in
/// ten steps, the solve finds that soft stretch, follows it by arc length, and does not say the
/// column snapped; the arch, checked the same way, did (above).
#[test]
fn a_column_bending_over_past_its_buckling_load_is_not_said_to_snap() {
    let (problem, top) = column_problem(0.08);
    let options = SolverOptions { load_steps: 10, confirm_snaps: true, ..SolverOptions::default() };
    let solution = StaticSolver::new(problem.clone()).unwrap().solve(&options).unwrap();
    let sideways = top.iter().map(|&n| solution.u[3 * n]).sum::<f64>() / top.len() as f64;
    assert!(sideways > 0.1, "the column's top moved sideways by {sideways} m: it did not bend over");
    assert_eq!(solution.snapped_from, None);
    // Without the check, the first soft step is taken for a snap.
    let unchecked = SolverOptions { confirm_snaps: false, ..options };
    assert!(StaticSolver::new(problem).unwrap().solve(&unchecked).unwrap().snapped_from.is_some());
}

/// A 10 cm Neo-Hookean cube (E 5 kPa, ν 0.3, 2 × 2 × 2 cubes of 6 T4) clamped at x = 0 and pressed
/// at x = 10 cm by a dead traction of `pressure` pascals.
fn pressed_cube(pressure: f64) -> Problem {
    let mesh = mesh::box_tet([0.0; 3], [0.1; 3], [2, 2, 2]).unwrap();
    let face = |x: f64| -> Vec<usize> { (0..mesh.num_nodes()).filter(|&n| mesh.nodes[n][0] == x).collect() };
    let (held, pressed) = (face(0.0), face(0.1));
    let material = Material::new(Law::NeoHookean, 5000.0, 0.3).with_formulation(Formulation::Standard);
    let mut problem = Problem::new(mesh, material);
    problem.fix(&held);
    problem.add_traction(&pressed, [-pressure, 0.0, 0.0]);
    problem
}

/// Pressed by 3 kPa the cube gives way (it folds back through its clamp) past a loss of
/// stability: said so whether the load is applied in one step or in twenty, at a load factor the
/// arc-length check finds; the continuation stops there and says the tangent turned indefinite,
/// not that the path shows no sign of a limit point. Pressed by 500 Pa, it does not give way.
#[test]
fn a_body_that_gives_way_in_its_first_load_step_is_said_to_snap() {
    for load_steps in [1, 20] {
        let options = SolverOptions { load_steps, confirm_snaps: true, ..SolverOptions::default() };
        let solution = StaticSolver::new(pressed_cube(3000.0)).unwrap().solve(&options).unwrap();
        let snapped = solution.snapped_from;
        assert!(snapped.is_some_and(|l| (0.5..1.0).contains(&l)), "{load_steps} step(s): {snapped:?}");
        let options = SolverOptions { load_steps, ..options };
        assert_eq!(StaticSolver::new(pressed_cube(500.0)).unwrap().solve(&options).unwrap().snapped_from, None);
    }
    match solve(pressed_cube(3000.0), Continuation::ArcLength) {
        Err(e @ FemError::NoEquilibrium { indefinite: true, .. }) => {
            let message = e.to_string();
            assert!(message.contains("turned indefinite") && !message.contains("no sign"), "{message}");
        }
        other => panic!("the cube by arc length: {:?}", other.map(|s| s.load_steps)),
    }
}
