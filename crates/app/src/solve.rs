//! A static scenario solved once, as `augsim solve` and Python's `augsim.solve` run it, and the
//! fields it writes for ParaView: the displacement, the Green strain and the von Mises stress.

use std::path::Path;

use anyhow::{Context, Result};
use fem::{post, Solution, StaticSolver};
use mesh::io::Field;
use mesh::stats::ms;
use scenario::StaticScenario;

/// A static scenario with its solution.
pub struct Solved {
    /// The scenario.
    pub scenario: StaticScenario,
    /// The solver, holding the problem, its geometry and its factorisation.
    pub solver: StaticSolver,
    /// The solution.
    pub solution: Solution,
}

/// Loads the static scenario `path` (a file or a built-in name), builds its problem and solves it.
pub fn solve_scenario(path: &Path) -> Result<Solved> {
    let (scenario, dir) = StaticScenario::load(path)?;
    let problem = scenario.build_problem(&dir)?;
    let mut solver = StaticSolver::new(problem)?;
    let solution = solver.solve(&scenario.solver).context("static solve")?;
    Ok(Solved { scenario, solver, solution })
}

impl Solved {
    /// The fields written with the mesh: point `displacement` (3 per node), cell `green_strain`
    /// (6 per cell) and cell `von_mises` (1 per cell).
    pub fn fields(&self) -> Result<Vec<Field>> {
        let (geometry, material, u) = (self.solver.geometry(), &self.solver.problem().material, &self.solution.u);
        Ok(vec![
            Field::point("displacement", 3, u.clone()),
            Field::cell("green_strain", 6, post::green_strain(geometry, material, u)?),
            Field::cell("von_mises", 1, post::von_mises(geometry, material, u)?),
        ])
    }

    /// Writes the mesh with [`Solved::fields`] to `path` (.vtu or .vtk), its directory created.
    pub fn write(&self, path: &Path) -> Result<()> {
        mesh::io::write_mesh(path, &self.solver.problem().mesh, &self.fields()?)
            .with_context(|| format!("writing {}", path.display()))
    }
}

impl Solved {
    /// The solve in words: scenario, mesh, material, system, solver, largest displacement and
    /// time.
    pub fn lines(&self) -> Vec<String> {
        let (scenario, solver, sol) = (&self.scenario, &self.solver, &self.solution);
        let (geo, p) = (solver.geometry(), solver.problem());
        let (free, nnz) = solver.system_size();
        let t = sol.timings;
        let about = if scenario.description.is_empty() { String::new() } else { format!(": {}", scenario.description) };
        vec![
            format!("scenario   {}{about}", scenario.name),
            format!(
                "mesh       {} nodes, {} {} cells, {:.4e} m³",
                p.mesh.num_nodes(),
                p.mesh.cells.len(),
                p.mesh.cells.kind_name(),
                p.mesh.volume()
            ),
            format!(
                "material   {} ({} elements), E = {} Pa, nu = {}",
                p.material.law.display_name(),
                geo.formulation.display_name(),
                p.material.young,
                p.material.poisson
            ),
            format!(
                "system     {} dofs, {free} free, {nnz} stored non-zeros, {} ordering",
                p.num_dofs(),
                solver.ordering().name()
            ),
            format!(
                "solver     {} iterations, {} factorisation(s), {} load step(s), final relative residual {:.2e}",
                sol.iterations,
                sol.factorizations,
                sol.load_steps,
                sol.residuals.last().copied().unwrap_or(0.0)
            ),
            format!("max |u|    {:.4e} m", post::max_displacement(&sol.u)),
            format!(
                "time       {:.1} ms (assembly {:.1}, factorisation {:.1}, solve {:.1})",
                ms(t.total),
                ms(t.assembly),
                ms(t.factorization),
                ms(t.solve)
            ),
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_beam_bends_and_its_fields_fit_its_mesh() {
        let solved = solve_scenario(Path::new("beam")).unwrap();
        let mesh = &solved.solver.problem().mesh;
        let fields = solved.fields().unwrap();
        let names: Vec<&str> = fields.iter().map(|f| f.name.as_str()).collect();
        assert_eq!(names, ["displacement", "green_strain", "von_mises"]);
        assert_eq!(solved.solution.u.len(), 3 * mesh.num_nodes());
        assert!(fem::post::max_displacement(&solved.solution.u) > 0.0);
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("sub/beam.vtu");
        solved.write(&out).unwrap();
        assert_eq!(mesh::io::read_mesh(&out).unwrap().num_nodes(), mesh.num_nodes());
        let lines = solved.lines();
        assert!(lines[0].starts_with("scenario   beam"), "{lines:?}");
        assert!(lines[1].starts_with(&format!("mesh       {} nodes", mesh.num_nodes())), "{lines:?}");
        assert!(lines.iter().any(|l| l.starts_with("max |u|    ")) && lines.len() == 7, "{lines:?}");
    }
}
