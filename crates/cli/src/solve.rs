//! `augsim solve`: one static solve of a scenario, written as VTK.

use std::path::Path;

use anyhow::Result;
use app::solve::solve_scenario;
use fem::post;

/// Runs the scenario and writes the result; prints a summary.
pub fn run(path: &Path, output: Option<&Path>) -> Result<()> {
    let solved = solve_scenario(path)?;
    let (scenario, solver, sol) = (&solved.scenario, &solved.solver, &solved.solution);
    let (geo, p) = (solver.geometry(), solver.problem());
    println!(
        "scenario   {}{}",
        scenario.name,
        if scenario.description.is_empty() { String::new() } else { format!(": {}", scenario.description) }
    );
    println!(
        "mesh       {} nodes, {} {} cells, {:.4e} m³",
        p.mesh.num_nodes(),
        p.mesh.cells.len(),
        p.mesh.cells.kind_name(),
        p.mesh.volume()
    );
    let (free, nnz) = solver.system_size();
    let out = output.map(Path::to_path_buf).unwrap_or_else(|| scenario.output_path());
    solved.write(&out)?;
    let t = sol.timings;
    println!(
        "material   {:?} ({:?} elements), E = {} Pa, nu = {}",
        p.material.law, geo.formulation, p.material.young, p.material.poisson
    );
    println!(
        "system     {} dofs, {} free, {} stored non-zeros, {} ordering",
        p.num_dofs(),
        free,
        nnz,
        solver.ordering().name()
    );
    println!(
        "solver     {} iterations, {} factorisation(s), {} load step(s), final relative residual {:.2e}",
        sol.iterations,
        sol.factorizations,
        sol.load_steps,
        sol.residuals.last().copied().unwrap_or(0.0)
    );
    println!("max |u|    {:.4e} m", post::max_displacement(&sol.u));
    println!(
        "time       {:.1} ms (assembly {:.1}, factorisation {:.1}, solve {:.1})",
        ms(t.total),
        ms(t.assembly),
        ms(t.factorization),
        ms(t.solve)
    );
    println!("wrote      {}", out.display());
    Ok(())
}

/// Milliseconds of a duration.
pub fn ms(d: std::time::Duration) -> f64 {
    d.as_secs_f64() * 1e3
}
