//! Builds a problem in code and solves it: a soft cantilever (10 × 1 × 1 cm, Neo-Hookean,
//! E = 5 kPa, ν = 0.49, locking-free F-bar hexahedra) fixed at one end and bent by its own weight
//! under 0.01 m/s², compared with Euler-Bernoulli beam theory, written as VTK for ParaView.
//!
//! `cargo run --release -p augsim-fem --example solve_beam [out.vtu]`

use augsim_fem::{post, Law, Material, Problem, SolverOptions, StaticSolver};
use mesh::io::Field;
use mesh::select::nodes_in_box;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let out = std::env::args().nth(1).unwrap_or_else(|| "out/solve_beam.vtu".into());
    let (length, side, young, poisson) = (0.1, 0.01, 5000.0, 0.49);
    let mesh = mesh::box_hex([0.0; 3], [length, side, side], [40, 4, 4])?;
    let material = Material::new(Law::NeoHookean, young, poisson);
    let mut problem = Problem::new(mesh, material);
    let root = nodes_in_box(&problem.mesh.nodes, [-1e-6; 3], [1e-6, 1.0, 1.0]);
    problem.fix(&root);
    let g = 0.01; // m/s²: a small load (deflection ~3 % of the length), so that beam theory applies
    problem.add_gravity([0.0, 0.0, -g])?;

    let mut solver = StaticSolver::new(problem)?;
    let solution = solver.solve(&SolverOptions::default())?;
    let tip = nodes_in_box(&solver.problem().mesh.nodes, [length - 1e-6, -1.0, -1.0], [1.0, 1.0, 1.0]);
    let deflection = -tip.iter().map(|&n| solution.u[3 * n + 2]).sum::<f64>() / tip.len() as f64;
    // Euler-Bernoulli, uniform load q = ρ g A: w = q L⁴ / (8 E I).
    let (area, inertia) = (side * side, side.powi(4) / 12.0);
    let theory = material.density * g * area * length.powi(4) / (8.0 * young * inertia);
    println!("elements   {} H8, {:?} formulation", solver.problem().mesh.cells.len(), material.resolved_formulation());
    println!("solver     {} iterations, {} factorisation(s)", solution.iterations, solution.factorizations);
    println!(
        "tip        {:.4} mm (Euler-Bernoulli {:.4} mm, ratio {:.3})",
        deflection * 1e3,
        theory * 1e3,
        deflection / theory
    );

    let fields = [
        Field::point("displacement", 3, solution.u.clone()),
        Field::cell("von_mises", 1, post::von_mises(solver.geometry(), &material, &solution.u)?),
    ];
    if let Some(dir) = std::path::Path::new(&out).parent() {
        std::fs::create_dir_all(dir)?;
    }
    mesh::io::write_mesh(&out, &solver.problem().mesh, &fields)?;
    println!("wrote      {out}");
    Ok(())
}
