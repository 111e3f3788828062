//! `augsim solve`: one static solve of a scenario, written as VTK.

use std::path::Path;

use anyhow::{Context, Result};
use fem::{post, StaticSolver};
use mesh::io::Field;

use scenario::StaticScenario;

/// Runs the scenario and writes the result; prints a summary.
pub fn run(path: &Path, output: Option<&Path>) -> Result<()> {
    let (scenario, dir) = StaticScenario::load(path)?;
    let problem = scenario.build_problem(&dir)?;
    println!(
        "scenario   {}{}",
        scenario.name,
        if scenario.description.is_empty() { String::new() } else { format!(": {}", scenario.description) }
    );
    println!(
        "mesh       {} nodes, {} {} cells, {:.4e} m³",
        problem.mesh.num_nodes(),
        problem.mesh.cells.len(),
        problem.mesh.cells.kind_name(),
        problem.mesh.volume()
    );
    let mut solver = StaticSolver::new(problem)?;
    let (free, nnz) = solver.system_size();
    let sol = solver.solve(&scenario.solver).context("static solve")?;
    let out = output.map(Path::to_path_buf).unwrap_or_else(|| scenario.output_path());
    let geo = solver.geometry();
    let p = solver.problem();
    let fields = [
        Field::point("displacement", 3, sol.u.clone()),
        Field::cell("green_strain", 6, post::green_strain(geo, &p.material, &sol.u)?),
        Field::cell("von_mises", 1, post::von_mises(geo, &p.material, &sol.u)?),
    ];
    if let Some(dir) = out.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    mesh::io::write_mesh(&out, &p.mesh, &fields).with_context(|| format!("writing {}", out.display()))?;
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
