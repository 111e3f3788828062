//! A static scenario solved once, as `augsim solve` and Python's `augsim.solve` run it, and the
//! fields it writes for ParaView: the displacement, the Green strain and the von Mises stress.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use fem::{post, ElementGeometry, Law, Solution, StaticSolver};
use mesh::io::Field;
use mesh::stats::ms;
use scenario::StaticScenario;

/// The files a solve writes, by extension: VTK's, which hold its fields.
pub const SOLVE_FILE_EXTENSIONS: [&str; 2] = ["vtu", "vtk"];

/// A static scenario with its solution.
pub struct Solved {
    /// The scenario.
    pub scenario: StaticScenario,
    /// The solver, holding the problem, its geometry and its factorisation.
    pub solver: StaticSolver,
    /// The solution.
    pub solution: Solution,
    /// The forces the supports (holds, springs, attachments) exert on each node at the solution
    /// (N, 3 per node: [`StaticSolver::reaction_forces`]).
    pub reaction: Vec<f64>,
    /// The warning of the pieces of the mesh left out of the solve: pieces that hang on the rest
    /// by an edge or a vertex and carry nothing.
    pub hanging_warning: Option<String>,
    /// Whether the tangent stiffness at the solution is positive definite: a stable equilibrium
    /// ([`StaticSolver::stable_at`]).
    pub stable: bool,
}

/// Loads the static scenario `path` (a file or a built-in name), builds its problem and solves it.
pub fn solve_scenario(path: &Path, progress: impl Fn(f64, usize) + Send + Sync + 'static) -> Result<Solved> {
    let (scenario, dir) = StaticScenario::load(path)?;
    solve(scenario, &dir, progress)
}

/// [`solve_scenario`], written to `output` (by default the scenario's own output path), which is
/// checked before the solve: a path that cannot be written fails at once, not after minutes of
/// solving. Returns the solve and the file written.
pub fn solve_and_write(
    path: &Path,
    output: Option<&Path>,
    progress: impl Fn(f64, usize) + Send + Sync + 'static,
) -> Result<(Solved, PathBuf)> {
    let (scenario, dir) = StaticScenario::load(path)?;
    let out = output.map(Path::to_path_buf).unwrap_or_else(|| scenario.output_path());
    let mesh_file = scenario.mesh.file().map(|f| dir.join(f));
    let read: Vec<&Path> = [path].into_iter().filter(|p| p.is_file()).chain(mesh_file.as_deref()).collect();
    if let Some((_, input)) = mesh::io::overwritten(&[&out], &read) {
        bail!(
            "{} would be written over {}, which the solve reads: give another output",
            out.display(),
            input.display()
        );
    }
    mesh::io::check_writable(&out).context("the solution could not be written there")?;
    let solved = solve(scenario, &dir, progress)?;
    solved.write(&out)?;
    Ok((solved, out))
}

/// Warnings of a problem's set-up (its mesh built from `source`), whatever its solution: faces held
/// by half, doubtful units, cells the file numbers the other way round.
fn set_up_warnings(p: &fem::Problem, source: &scenario::MeshSource) -> Vec<String> {
    let mut lines = Vec::new();
    let half_held = mid_edge_nodes_left_free(p);
    if half_held > 0 {
        lines.push(format!(
            "{half_held} mid-edge node(s) lie between held corners and are free: a selection of \
             corners only (a linear mesh's group on this quadratic one) holds its faces by half; select their \
             mid-edge nodes too"
        ));
    }
    lines.extend(doubts(p, source));
    let coincident = mesh::coincident_points(&p.mesh.nodes);
    if let Some(&(a, b)) = coincident.first() {
        let at = p.mesh.nodes[a];
        lines.push(format!(
            "{} pair(s) of nodes lie at one place without being one node (the first: nodes {} and {}, at ({:.4}, \
             {:.4}, {:.4}) m): the cells on either side are joined nowhere there, as across a crack; an export that \
             did not merge its nodes (merge coincident nodes, e.g. Gmsh's Coherence)",
            coincident.len(),
            p.mesh.file_node(a),
            p.mesh.file_node(b),
            at[0],
            at[1],
            at[2]
        ));
    }
    if loads_the_whole_surface(p) {
        lines.push(
            "every boundary face carries a load, and no inner node: a [[force]] or [[traction]] whose \
             selection takes the whole surface (a ball or box larger than the body: its size in mm read as m?)"
                .into(),
        );
    }
    if let Some(&first) = p.mesh.odd_cells.first() {
        lines.push(format!(
            "{} of the file's {} cells are numbered the other way round from the others (the first: \
             cell {}); turned positive, as every cell is, they fold over no neighbour: the mesher's slip",
            p.mesh.odd_cells.len(),
            p.mesh.cells.len(),
            p.mesh.file_cell(first)
        ));
    }
    lines
}

/// Whether node `n` carries a load.
fn loaded(p: &fem::Problem, n: usize) -> bool {
    p.f_ext[3 * n..3 * n + 3].iter().any(|&f| f != 0.0)
}

/// Whether the loads cover every boundary face, each loaded at every node a traction on it loads
/// (a quadratic face's mid-edge nodes; a coarse mesh's faces that merely touch a loaded one are
/// not covered), and no inner node (gravity loads them all), on a body that has inner nodes.
fn loads_the_whole_surface(p: &fem::Problem) -> bool {
    let mut surface = vec![false; p.mesh.num_nodes()];
    let faces = mesh::boundary_faces(&p.mesh);
    faces.iter().flat_map(|f| &f.nodes).for_each(|&n| surface[n] = true);
    let inner_unloaded = (0..p.mesh.num_nodes()).all(|n| surface[n] || !loaded(p, n));
    // A quadratic face (6 nodes) loads its mid-edge nodes (the last 3) only.
    let covered =
        |f: &mesh::BoundaryFace| f.nodes.iter().skip(if f.nodes.len() == 6 { 3 } else { 0 }).all(|&n| loaded(p, n));
    surface.contains(&false) && inner_unloaded && faces.iter().all(covered)
}

/// What makes a problem's units doubtful (its mesh built from `source`): a mesh the size of a
/// room, a modulus far below soft tissues'.
fn doubts(problem: &fem::Problem, source: &scenario::MeshSource) -> Vec<String> {
    let young = scenario::source::young_hint(problem.material.young);
    scenario::source::unit_hint(&problem.mesh, source).into_iter().chain(young).collect()
}

/// Whether a load or modulus in the wrong unit can cause the solver's error `e`: a failure of the
/// solve itself, not a refusal of its input.
fn a_wrong_unit_can_cause(e: &fem::FemError) -> bool {
    use fem::FemError::{Interrupted, Invalid, Mesh, OutOfTime};
    !matches!(e, Invalid(_) | Mesh(_) | Interrupted | OutOfTime)
}

/// Builds `scenario`'s problem (its files relative to `dir`) and solves it, telling `progress` the
/// load factor reached and the iterations so far.
fn solve(
    scenario: StaticScenario,
    dir: &Path,
    progress: impl Fn(f64, usize) + Send + Sync + 'static,
) -> Result<Solved> {
    let (problem, hanging_warning) = crate::models::solvable_problem(&scenario, dir)?;
    let hints = doubts(&problem, &scenario.mesh);
    let mut solver = StaticSolver::new(problem)?;
    // Its lines say whether the body snapped past a limit point: made sure of.
    let options = fem::SolverOptions {
        confirm_snaps: true,
        progress: Some(fem::SolveProgress(std::sync::Arc::new(progress))),
        ..scenario.solver.clone()
    };
    let solution = solver.solve(&options).map_err(|e| {
        let hint = match hints.is_empty() || !a_wrong_unit_can_cause(&e) {
            true => String::new(),
            false => format!(" ({})", hints.join("; ")),
        };
        anyhow::Error::new(e).context(format!("static solve{hint}"))
    })?;
    let reaction = solver.reaction_forces(&solution.u)?;
    // The linear law's tangent is its constant stiffness, positive definite on a held body.
    let stable = scenario.material.law == Law::Linear || solver.stable_at(&solution.u)?;
    Ok(Solved { scenario, solver, solution, reaction, hanging_warning, stable })
}

impl Solved {
    /// The fields written with the mesh: point `displacement` (3 per node) and `reaction_force`
    /// (N, 3 per node: [`Solved::reaction`]), cell `green_strain`
    /// (`small_strain` under the linear law; 6 per cell) and cell `von_mises` (1 per cell); where
    /// the mesh has them, its file's numbers (`file_node`, `file_cell`) and an immersed grid's cell
    /// fractions (`volume_fraction`).
    pub fn fields(&self) -> Result<Vec<Field>> {
        let (geometry, material, u) = (self.solver.geometry(), &self.solver.problem().material, &self.solution.u);
        let mut fields = vec![
            Field::point("displacement", 3, u.clone()),
            Field::point("reaction_force", 3, self.reaction.clone()),
            Field::cell(post::strain_name(material.law), 6, post::strain(geometry, material, u)?),
            Field::cell("von_mises", 1, post::von_mises(geometry, material, u)?),
        ];
        let mesh = &self.solver.problem().mesh;
        if let Some(file_nodes) = &mesh.file_nodes {
            fields.push(Field::point("file_node", 1, file_nodes.iter().map(|&i| i as f64).collect()));
        }
        if let Some(file_cells) = &mesh.file_cells {
            fields.push(Field::cell("file_cell", 1, file_cells.iter().map(|&i| i as f64).collect()));
        }
        if let Some(fractions) = &mesh.cell_fraction {
            fields.push(Field::cell(mesh::io::FRACTION_FIELD, 1, fractions.clone()));
        }
        Ok(fields)
    }

    /// Writes the mesh with [`Solved::fields`] to `path` (.vtu or .vtk), its directory created.
    pub fn write(&self, path: &Path) -> Result<()> {
        mesh::io::write_mesh(path, &self.solver.problem().mesh, &self.fields()?)
            .with_context(|| format!("writing {}", path.display()))
    }
}

impl Solved {
    /// The solve in words: scenario, mesh, material, system, solver, largest displacement, time
    /// and its warnings ([`Solved::warnings`]), each a line of its own.
    pub fn lines(&self) -> Result<Vec<String>> {
        let (scenario, solver, sol) = (&self.scenario, &self.solver, &self.solution);
        let (geo, p) = (solver.geometry(), solver.problem());
        let (free, nnz) = solver.system_size();
        let t = sol.timings;
        let about = if scenario.description.is_empty() { String::new() } else { format!(": {}", scenario.description) };
        let left_out = match &p.mesh.file_nodes {
            Some(_) => " (numbered as in its file: `list` selections and the field file_node give the file's numbers)",
            None => "",
        };
        let inside = match p.mesh.cell_fraction {
            Some(_) => format!(" ({:.4e} m³ of them inside the organ)", p.mesh.body_volume()),
            None => String::new(),
        };
        let mut lines = vec![
            format!("scenario   {}{about}", scenario.name),
            format!(
                "mesh       {} nodes, {} {} cells, {:.4e} m³{inside}{left_out}",
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
            self.reaction_line(),
            format!(
                "time       {:.1} ms (assembly {:.1}, factorisation {:.1}, solve {:.1})",
                ms(t.total),
                ms(t.assembly),
                ms(t.factorization),
                ms(t.solve)
            ),
        ];
        lines.extend(self.warnings()?.into_iter().map(|w| format!("warning    {w}")));
        Ok(lines)
    }

    /// What to know of the solve, each in words: a residual far above its tolerance, a snap past a
    /// limit point, loads that move nothing, pieces left out, the set-up's doubts, cells turned
    /// inside out or strained beyond the law's or the tissue's range; empty when there is none.
    pub fn warnings(&self) -> Result<Vec<String>> {
        let (scenario, solver, sol) = (&self.scenario, &self.solver, &self.solution);
        let (geo, p) = (solver.geometry(), solver.problem());
        let mut lines = Vec::new();
        let residual = sol.residuals.last().copied().unwrap_or(0.0);
        if residual > RESIDUAL_OVER_TOLERANCE * scenario.solver.rtol {
            lines.push(format!(
                "the solve ended at a relative residual of {residual:.2e}, far above rtol = {:.0e}: it was taken \
                 after a last increment under utol = {:.0e} of the displacement (the residual may fall no further); \
                 the loads' balance is in the reaction line; a smaller utol asks for more",
                scenario.solver.rtol, scenario.solver.utol
            ));
        }
        let loaded = |n: usize| loaded(p, n);
        let moved = p.dirichlet.values().any(|d| *d != [0.0; 3]);
        match sol.snapped_from {
            Some(lambda) if moved => lines.push(format!(
                "from load factor {lambda:.3} a load step found its equilibrium far away, the response over \
                 it half as stiff as before or less: past a limit point of the load path the body snapped to \
                 another branch (as under a real push it gives way), or the path is that soft there"
            )),
            Some(lambda) => lines.push(format!(
                "the load path turns back at load factor {lambda:.3}, a limit point: past it the body snapped to \
                 an equilibrium far away (as under a real push it gives way); `[solver] continuation = \"arc_length\"` \
                 follows the path and stops there"
            )),
            None => {}
        }
        if !self.stable {
            lines.push(
                "the tangent stiffness at the equilibrium found is indefinite: it is unstable, past a bifurcation \
                 (a column pressed straight beyond its buckling load: a slight disturbance would bend it); a small \
                 sideways load shows the shape the body takes"
                    .into(),
            );
        }
        if !moved && !(0..p.mesh.num_nodes()).any(loaded) {
            lines.push(
                "nothing loads the body ([[force]], [[traction]], [[patch_force]], gravity or a [[prescribed]] \
                 displacement): the solution is its rest state (a scenario made to be loaded elsewhere, as \
                 registration does?)"
                    .into(),
            );
        }
        if !moved
            && (0..p.mesh.num_nodes()).any(loaded)
            && (0..p.mesh.num_nodes()).all(|n| !loaded(n) || p.dirichlet.contains_key(&n))
        {
            lines.push(
                "every load acts on held nodes ([[fixed]] or [[prescribed]]): nothing moves; do the \
                 selections of the loads and of the held nodes overlap?"
                    .into(),
            );
        }
        lines.extend(self.hanging_warning.iter().cloned());
        lines.extend(set_up_warnings(p, &scenario.mesh));
        for (k, force) in scenario.force.iter().enumerate() {
            let Ok(nodes) = scenario::source::select_nodes(&force.select, &p.mesh, &scenario.mesh, "force") else {
                continue;
            };
            let strays = fem::force_strays(&p.mesh, &nodes);
            if let Some(&first) = strays.first() {
                lines.push(format!(
                    "force {}: {} of its {} selected nodes lie apart from the boundary faces it acts on (the first: \
                     node {}) and carry none of it: a force spreads over the faces its selection wholly covers",
                    k + 1,
                    strays.len(),
                    nodes.len(),
                    p.mesh.file_node(first)
                ));
            }
        }
        let (inverted, smallest) = post::inverted_cells(geo, p.material.law, &sol.u)?;
        if inverted > 0 {
            lines.push(format!(
                "{inverted} of {} cells are turned inside out (det F down to {smallest:.2}): the {} law \
                 holds for small strains only: use a finite-strain law (co-rotational, SVK, Neo-Hookean) or a \
                 smaller load",
                p.mesh.cells.len(),
                p.material.law.display_name()
            ));
        }
        if let Some(line) = volume_change_line(geo, p, &sol.u)? {
            lines.push(line);
        }
        lines.extend(beyond_tissue_lines(geo, p, &sol.u)?);
        if p.material.law == Law::Svk {
            if let (over @ 1.., Some((cell, stretch))) = post::over_compressed_cells(geo, p.material.law, &sol.u)? {
                lines.push(format!(
                    "{over} of {} cells are compressed past Saint-Venant-Kirchhoff's limit stretch \
                     1/sqrt(3) = {:.3} (down to {stretch:.3} in cell {}), where its stress falls as the \
                     compression grows (no tissue's does): the equilibrium found holds for that law alone; \
                     law = \"neo_hookean\" holds under large compression",
                    p.mesh.cells.len(),
                    fem::material::SVK_LIMIT_STRETCH,
                    p.mesh.file_cell(cell)
                ));
            }
        }
        Ok(lines)
    }

    /// The supports' forces in total, held nodes and the others apart, beside the loads' total they
    /// balance (the field `reaction_force` gives them node by node).
    fn reaction_line(&self) -> String {
        let p = self.solver.problem();
        // The total of `f` (3 per node) over the nodes `held` says.
        let total = |f: &[f64], held: Option<bool>| {
            let nodes = (0..p.mesh.num_nodes()).filter(|n| held.is_none_or(|h| p.dirichlet.contains_key(n) == h));
            nodes.fold([0.0; 3], |s, n| [s[0] + f[3 * n], s[1] + f[3 * n + 1], s[2] + f[3 * n + 2]])
        };
        let newtons = |f: [f64; 3]| format!("({:.4e}, {:.4e}, {:.4e}) N", f[0], f[1], f[2]);
        // What a node neither fixed nor prescribed takes, its springs and attachments take.
        let (held, springs) = (total(&self.reaction, Some(true)), total(&self.reaction, Some(false)));
        let loads = total(&p.f_ext, None);
        format!(
            "reaction   held nodes {}, springs and attachments {} (field reaction_force); the loads: {}",
            newtons(held),
            newtons(springs),
            newtons(loads)
        )
    }
}

/// The share of its volume a cell may gain or lose in a nearly incompressible material
/// ([`fem::material::FBAR_POISSON`] and above) before the solve warns.
const VOLUME_CHANGE: f64 = 0.1;

/// The warning for a nearly incompressible material (ν ≥ [`fem::material::FBAR_POISSON`]) under a
/// law whose volume response is not finite-strain (linear, co-rotational, Saint-Venant-Kirchhoff:
/// a null trace of the strain keeps the volume to first order only) whose cells changed volume by
/// more than [`VOLUME_CHANGE`] (a co-rotational cube of hexahedra at ν = 0.499 pressed by a
/// quarter of its height: 21 of 27 cells, det F down to 0.55). A Neo-Hookean solid's volume
/// change is its law's own (at ν = 0.48 the built-in `liver_large` loses up to 16 % in a few cells
/// under its tool).
fn volume_change_line(geometry: &ElementGeometry, p: &fem::Problem, u: &[f64]) -> Result<Option<String>> {
    if p.material.poisson < fem::material::FBAR_POISSON || p.material.law == Law::NeoHookean {
        return Ok(None);
    }
    let ratios = post::volume_ratios(geometry, p.material.law, u)?;
    let changed = ratios.iter().filter(|&&j| (j - 1.0).abs() > VOLUME_CHANGE).count();
    if changed == 0 {
        return Ok(None);
    }
    let (least, most) = (ratios.iter().copied().fold(f64::INFINITY, f64::min), mesh::stats::max(&ratios));
    Ok(Some(format!(
        "{changed} of {} cells changed volume by more than {:.0} % (det F from {least:.3} to {most:.3}) \
         where nu = {} makes the material nearly incompressible: the {} law keeps the volume to first order in the \
         strain only; law = \"neo_hookean\" holds it under large strains",
        p.mesh.cells.len(),
        100.0 * VOLUME_CHANGE,
        p.material.poisson,
        p.material.law.display_name(),
    )))
}

/// How far over its tolerance `rtol` a solve's last residual may lie, taken on a small last step
/// (as the solver accepts up to √rtol), before the solve warns: the built-in beam ends at twice
/// it, a nearly incompressible liver under 50 N at 37 times.
const RESIDUAL_OVER_TOLERANCE: f64 = 10.0;

/// The principal stretch past which (or under whose inverse) a cell is strained beyond what soft
/// tissue bears (a liver tears at about 1.5): the solve warns of a load out of range, or in the
/// wrong unit.
const TISSUE_STRETCH: f64 = 3.0;

/// The warnings of a solution far beyond soft tissue's range, whatever the law found: cells
/// stretched past [`TISSUE_STRETCH`] or compressed under its inverse, and a body moved by more
/// than its own size (a nearly incompressible Neo-Hookean liver under 50 N on F-bar elements: 1.7
/// m on a 20 cm organ, a cell stretched 54 times, with no limit point to tell).
fn beyond_tissue_lines(geometry: &ElementGeometry, p: &fem::Problem, u: &[f64]) -> Result<Vec<String>> {
    let mut lines = Vec::new();
    let stretches = post::principal_stretches(geometry, p.material.law, u)?;
    let beyond = |&(least, most): &(f64, f64)| most > TISSUE_STRETCH || least < 1.0 / TISSUE_STRETCH;
    let count = stretches.iter().filter(|s| beyond(s)).count();
    let extreme = |(least, most): (f64, f64)| most.max(1.0 / least.max(f64::MIN_POSITIVE));
    if let Some((cell, &worst)) =
        stretches.iter().enumerate().filter(|(_, s)| beyond(s)).max_by(|a, b| extreme(*a.1).total_cmp(&extreme(*b.1)))
    {
        let least = stretches.iter().map(|s| s.0).fold(f64::INFINITY, f64::min);
        let most = stretches.iter().map(|s| s.1).fold(0.0, f64::max);
        lines.push(format!(
            "{count} of {} cells are stretched past {TISSUE_STRETCH} times their length or compressed under \
             1/{TISSUE_STRETCH} (principal stretches from {least:.3} to {most:.3}; the most strained, cell {}: {:.3} to \
             {:.3}), far beyond what soft tissue bears: is the load right (N, Pa; its unit, its size)?",
            p.mesh.cells.len(),
            p.mesh.file_cell(cell),
            worst.0,
            worst.1
        ));
    }
    let size = mesh::longest_side(p.mesh.bounds());
    let moved = post::max_displacement(u);
    if moved > size {
        lines.push(format!(
            "the body moved by up to {moved:.4e} m, {:.1} times its own size ({size:.4e} m): is the load \
             right?",
            moved / size
        ));
    }
    Ok(lines)
}

/// The mid-edge nodes of a T10 mesh that are not held on a boundary face whose three corners are
/// ([[fixed]] or [[prescribed]]): a held face's; corners held one by one that share an edge hold
/// no face.
fn mid_edge_nodes_left_free(p: &fem::Problem) -> usize {
    if !matches!(p.mesh.cells, mesh::Cells::Tet10(_)) {
        return 0;
    }
    let held = |n: usize| p.dirichlet.contains_key(&n);
    let mut free: Vec<usize> = mesh::boundary_faces(&p.mesh)
        .iter()
        .filter(|f| f.nodes[..3].iter().all(|&n| held(n)))
        .flat_map(|f| f.nodes[3..].iter().copied().filter(|&m| !held(m)))
        .collect();
    free.sort_unstable();
    free.dedup();
    free.len()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The lines of the static scenario `text` solved, written as `scenario.toml` into `dir`
    /// (where its mesh files lie).
    fn solved_lines(dir: &Path, text: &str) -> Vec<String> {
        let path = dir.join("scenario.toml");
        std::fs::write(&path, text).unwrap();
        solve_scenario(&path, |_, _| {}).unwrap().lines().unwrap()
    }

    /// Loads that act on held nodes only move nothing: said so.
    #[test]
    fn loads_on_held_nodes_only_are_warned_about() {
        let dir = tempfile::tempdir().unwrap();
        let text = "kind = \"static\"\nname = \"held\"\n[mesh.box]\nmin = [0.0, 0.0, 0.0]\nmax = [0.1, 0.02, 0.02]\n\
                    cells = [4, 1, 1]\nelement = \"hex\"\n[material]\nlaw = \"linear\"\nyoung = 5000.0\npoisson = 0.3\n\
                    [[fixed]]\nselect = { box = { min = [-1.0, -1.0, -1.0], max = [1e-9, 1.0, 1.0] } }\n\
                    [[force]]\nselect = { box = { min = [-1.0, -1.0, -1.0], max = [1e-9, 1.0, 1.0] } }\n\
                    total = [0.0, 0.0, -0.1]\n";
        let lines = solved_lines(dir.path(), text);
        assert!(lines.iter().any(|l| l.starts_with("warning    every load acts on held nodes")), "{lines:?}");
        let beam = solve_scenario(Path::new("beam"), |_, _| {}).unwrap().lines().unwrap();
        assert!(!beam.iter().any(|l| l.starts_with("warning")), "{beam:?}");
    }

    /// A load whose selection takes the whole surface (a 50 m ball about a 10 cm bar) is warned
    /// about, on H8 and on T10 (whose faces carry a traction on their mid-edge nodes only);
    /// gravity, which loads every node, is not.
    #[test]
    fn a_load_on_the_whole_surface_is_warned_about() {
        let dir = tempfile::tempdir().unwrap();
        for element in ["element = \"hex\"\n[material]\n", "element = \"tet\"\n[material]\norder = 2\n"] {
            let lines = |load: &str| {
                // A top-level key (gravity) before the tables, the others after.
                let (top, load) = if load.starts_with("gravity") { (load, "") } else { ("", load) };
                let text = format!(
                    "kind = \"static\"\nname = \"ball\"\n{top}[mesh.box]\nmin = [0.0, 0.0, 0.0]\n\
                     max = [0.1, 0.02, 0.02]\ncells = [6, 3, 3]\n{element}law = \"linear\"\nyoung = 5000.0\n\
                     poisson = 0.3\n[[fixed]]\nselect = {{ box = {{ min = [-1.0, -1.0, -1.0], max = [1e-9, 1.0, 1.0] }} }}\n\
                     {load}"
                );
                solved_lines(dir.path(), &text)
            };
            let warned = |lines: &[String]| lines.iter().any(|l| l.contains("every boundary face carries a load"));
            let ball = "[[traction]]\nselect = { ball = { centre = [0.05, 0.01, 0.01], radius = 50.0 } }\n\
                        traction = [0.0, 0.0, -1.0]\n";
            assert!(warned(&lines(ball)), "{element}: {:?}", lines(ball));
            let tip = "[[traction]]\nselect = { box = { min = [0.0999, -1.0, -1.0], max = [1.0, 1.0, 1.0] } }\n\
                       traction = [0.0, 0.0, -1.0]\n";
            assert!(!warned(&lines(tip)), "{element}: {:?}", lines(tip));
            assert!(!warned(&lines("gravity = [0.0, 0.0, -9.81]\n")), "{element}");
        }
    }

    /// A node listed with a force's end face but apart from it carries none of the force: said;
    /// the face alone, or a ball's rim (nodes beside the faces it loads), is not. A scenario that
    /// loads nothing is said to.
    #[test]
    fn a_force_s_stray_nodes_and_a_body_loaded_by_nothing_are_warned_about() {
        let dir = tempfile::tempdir().unwrap();
        let bar = mesh::box_hex([0.0; 3], [0.1, 0.02, 0.02], [4, 1, 1]).unwrap();
        let end: Vec<usize> = (0..bar.num_nodes()).filter(|&n| bar.nodes[n][0] > 0.0999).collect();
        let middle = (0..bar.num_nodes()).find(|&n| (bar.nodes[n][0] - 0.05).abs() < 1e-9).unwrap();
        let lines = |force: &str| {
            let text = format!(
                "kind = \"static\"\nname = \"bar\"\n[mesh.box]\nmin = [0.0, 0.0, 0.0]\nmax = [0.1, 0.02, 0.02]\n\
                 cells = [4, 1, 1]\nelement = \"hex\"\n[material]\nlaw = \"linear\"\nyoung = 5000.0\n\
                 poisson = 0.3\n[[fixed]]\n\
                 select = {{ box = {{ min = [-1.0, -1.0, -1.0], max = [1e-9, 1.0, 1.0] }} }}\n{force}"
            );
            solved_lines(dir.path(), &text)
        };
        let force =
            |nodes: &[usize]| format!("[[force]]\nselect = {{ list = {nodes:?} }}\ntotal = [0.0, 0.0, -0.01]\n");
        let stray = |lines: &[String]| lines.iter().find(|l| l.contains("lie apart from the boundary faces")).cloned();
        let with_middle = lines(&force(&[end.clone(), vec![middle]].concat()));
        let warning = stray(&with_middle).expect("warned");
        assert!(warning.starts_with("warning    force 1: 1 of its 5 selected nodes"), "{warning}");
        assert!(warning.contains(&format!("(the first: node {middle})")), "{warning}");
        assert_eq!(stray(&lines(&force(&end))), None);
        let ball = "[[force]]\nselect = { ball = { centre = [0.05, 0.02, 0.01], radius = 0.03 } }\n\
                    total = [0.0, 0.0, -0.01]\n";
        assert_eq!(stray(&lines(ball)), None);
        let nothing = lines("");
        assert!(nothing.iter().any(|l| l.starts_with("warning    nothing loads the body")), "{nothing:?}");
    }

    /// A straight column pressed past its buckling load (Euler's, about 21 N here) is found in its
    /// straight equilibrium, unstable: warned about; under half that load, not.
    #[test]
    fn an_unstable_equilibrium_is_warned_about() {
        let dir = tempfile::tempdir().unwrap();
        let lines = |force: f64| {
            let text = format!(
                "kind = \"static\"\nname = \"column\"\n[mesh.box]\nmin = [0.0, 0.0, 0.0]\nmax = [1.0, 0.1, 0.1]\n\
                 cells = [20, 2, 2]\nelement = \"hex\"\n[material]\nlaw = \"neo_hookean\"\nyoung = 1.0e6\n\
                 poisson = 0.3\n[[fixed]]\n\
                 select = {{ box = {{ min = [-1.0, -1.0, -1.0], max = [1e-9, 1.0, 1.0] }} }}\n\
                 [[force]]\nselect = {{ box = {{ min = [0.999, -1.0, -1.0], max = [2.0, 1.0, 1.0] }} }}\n\
                 total = [{force}, 0.0, 0.0]\n"
            );
            solved_lines(dir.path(), &text)
        };
        let unstable = |lines: &[String]| lines.iter().any(|l| l.contains("at the equilibrium found is indefinite"));
        assert!(unstable(&lines(-30.0)), "{:?}", lines(-30.0));
        assert!(!unstable(&lines(-10.0)), "{:?}", lines(-10.0));
    }

    /// A bar exported in two halves whose nodes at the cut were not merged: held at both ends it
    /// solves as two cantilevers, warned about; held at one end its loose half is named as such.
    #[test]
    fn nodes_an_export_left_unmerged_are_warned_about() {
        let dir = tempfile::tempdir().unwrap();
        let half = |x0: f64| mesh::box_tet([x0, 0.0, 0.0], [x0 + 0.05, 0.02, 0.02], [2, 1, 1]).unwrap();
        let (left, right) = (half(0.0), half(0.05));
        let (mesh::Cells::Tet4(a), mesh::Cells::Tet4(b)) = (&left.cells, &right.cells) else { panic!("tetrahedra") };
        let n = left.num_nodes();
        let nodes = [left.nodes.clone(), right.nodes.clone()].concat();
        let cells = a.iter().copied().chain(b.iter().map(|t| t.map(|k| k + n))).collect();
        let bar = mesh::Mesh::new(nodes, mesh::Cells::Tet4(cells)).unwrap();
        mesh::io::write_mesh(dir.path().join("bar.vtu"), &bar, &[]).unwrap();
        let scenario = |held: &str| {
            format!(
                "kind = \"static\"\nname = \"cut\"\ngravity = [0.0, 0.0, -9.81]\n[mesh.file]\npath = \"bar.vtu\"\n\
                 [material]\nlaw = \"linear\"\nyoung = 5000.0\npoisson = 0.3\n{held}"
            )
        };
        let ends = "[[fixed]]\nselect = { box = { min = [-1.0, -1.0, -1.0], max = [1e-9, 1.0, 1.0] } }\n\
                    [[fixed]]\nselect = { box = { min = [0.0999, -1.0, -1.0], max = [1.0, 1.0, 1.0] } }\n";
        let lines = solved_lines(dir.path(), &scenario(ends));
        let warning = lines.iter().find(|l| l.contains("lie at one place without being one node")).expect("warned");
        assert!(warning.starts_with("warning    4 pair(s) of nodes") && warning.contains("at (0.0500,"), "{warning}");
        let one_end = &ends[..ends.rfind("[[fixed]]").unwrap()];
        std::fs::write(dir.path().join("scenario.toml"), scenario(one_end)).unwrap();
        let e = format!("{:#}", solve_scenario(&dir.path().join("scenario.toml"), |_, _| {}).err().unwrap());
        assert!(e.contains("meet the rest only at nodes that lie where its own do but are not merged"), "{e}");
    }

    /// A quadratic mesh held at the corners of a face only (landmarks near the corners: a linear
    /// mesh's points) is warned about; held at the whole face, or by a list of the corners (which
    /// gains the mid-edge nodes between them), not.
    #[test]
    fn a_quadratic_face_held_at_its_corners_only_is_warned_about() {
        let dir = tempfile::tempdir().unwrap();
        let linear = mesh::box_tet([0.0; 3], [0.1, 0.02, 0.02], [4, 1, 1]).unwrap();
        let corners: Vec<usize> = (0..linear.num_nodes()).filter(|&n| linear.nodes[n][0] < 1e-9).collect();
        let quadratic = linear.quadratic().unwrap();
        let face: Vec<usize> = (0..quadratic.num_nodes()).filter(|&n| quadratic.nodes[n][0] < 1e-9).collect();
        mesh::io::write_mesh(dir.path().join("beam.vtu"), &quadratic, &[]).unwrap();
        let lines = |held: &str| {
            let text = format!(
                "kind = \"static\"\nname = \"t10\"\n[mesh.file]\npath = \"beam.vtu\"\n[material]\nlaw = \"linear\"\n\
                 young = 5000.0\npoisson = 0.3\n[[fixed]]\nselect = {held}\n[[force]]\n\
                 select = {{ box = {{ min = [0.099, -1.0, -1.0], max = [1.0, 1.0, 1.0] }} }}\ntotal = [0.0, 0.0, -0.01]\n"
            );
            solved_lines(dir.path(), &text)
        };
        let points: Vec<mesh::Point> = corners.iter().map(|&n| linear.nodes[n]).collect();
        let half = lines(&format!("{{ near = {{ points = {points:?}, distance = 0.001 }} }}"));
        let warning = half.iter().find(|l| l.contains("mid-edge node(s) lie between held corners")).expect("warned");
        // The face x = 0 of one cube: 4 corners, 5 edges between them (4 sides and a diagonal).
        assert!(warning.starts_with("warning    5 mid-edge node(s)"), "{warning}");
        for held in [&face, &corners] {
            let listed = lines(&format!("{{ list = {held:?} }}"));
            assert!(!listed.iter().any(|l| l.contains("mid-edge")), "held at the whole face: {listed:?}");
        }
    }

    /// A coarse cube (2 × 2 × 2 cells) held at three single nodes, each by its own ball, and
    /// pulled at both ends: every side face touches a loaded end, yet the load does not cover
    /// the surface; on T10, two of the held nodes share an edge, yet no face is held. Neither is
    /// warned about, on H8, T4 or T10.
    #[test]
    fn a_coarse_cube_pulled_at_its_ends_and_held_at_single_nodes_is_not_warned_about() {
        let dir = tempfile::tempdir().unwrap();
        let ball = |c: [f64; 3]| format!("[[fixed]]\nselect = {{ ball = {{ centre = {c:?}, radius = 1e-4 }} }}\n");
        let end = |x: f64, sign: f64| {
            format!(
                "[[traction]]\nselect = {{ box = {{ min = [{}, -1.0, -1.0], max = [{}, 1.0, 1.0] }} }}\n\
                 traction = [{}, 0.0, 0.0]\n",
                x - 1e-6,
                x + 1e-6,
                sign * 100.0
            )
        };
        for element in [
            "element = \"hex\"\n[material]\n",
            "element = \"tet\"\n[material]\n",
            "element = \"tet\"\n[material]\norder = 2\n",
        ] {
            let text = format!(
                "kind = \"static\"\nname = \"cube\"\n[mesh.box]\nmin = [0.0, 0.0, 0.0]\nmax = [0.1, 0.1, 0.1]\n\
                 cells = [2, 2, 2]\n{element}law = \"linear\"\nyoung = 5000.0\npoisson = 0.3\n{}{}{}{}{}",
                ball([0.05, 0.05, 0.05]),
                ball([0.1, 0.05, 0.05]),
                ball([0.05, 0.1, 0.05]),
                end(0.0, -1.0),
                end(0.1, 1.0)
            );
            let lines = solved_lines(dir.path(), &text);
            assert!(!lines.iter().any(|l| l.starts_with("warning")), "{element}: {lines:?}");
        }
    }

    /// A box mesh 10 m long: a refused setting is said without a word of units; a solve that
    /// fails (turned inside out) asks whether the mesh is in centimetres, without naming a key
    /// the box lacks.
    #[test]
    fn a_unit_hint_goes_with_failures_a_wrong_unit_can_cause_only() {
        let dir = tempfile::tempdir().unwrap();
        let error = |solver: &str, force: f64| {
            let text = format!(
                "kind = \"static\"\nname = \"long\"\n[mesh.box]\nmin = [0.0, 0.0, 0.0]\nmax = [10.0, 1.0, 1.0]\n\
                 cells = [10, 1, 1]\nelement = \"tet\"\n[material]\nlaw = \"neo_hookean\"\nyoung = 1000.0\n\
                 poisson = 0.3\n[solver]\n{solver}\n\
                 [[fixed]]\nselect = {{ box = {{ min = [-1.0, -1.0, -1.0], max = [1e-9, 2.0, 2.0] }} }}\n\
                 [[force]]\nselect = {{ box = {{ min = [9.99, -1.0, -1.0], max = [11.0, 2.0, 2.0] }} }}\n\
                 total = [{force}, 0.0, 0.0]\n"
            );
            let path = dir.path().join("long.toml");
            std::fs::write(&path, text).unwrap();
            format!("{:#}", solve_scenario(&path, |_, _| {}).err().expect("an error"))
        };
        let refused = error("load_steps = 0", 1.0);
        assert!(refused.contains("load_steps = 0") && !refused.contains("the mesh spans"), "{refused}");
        let failed = error("max_iterations = 1\nload_steps = 1\nmax_step_cuts = 0", -1e6);
        assert!(failed.contains("the mesh spans 10 m: is it in centimetres?"), "{failed}");
        assert!(!failed.contains("[mesh.file]"), "{failed}");
    }

    #[test]
    fn the_beam_bends_and_its_fields_fit_its_mesh() {
        // The solve tells its advance at every iteration: the equilibria reached, in order.
        let told = std::sync::Arc::new(std::sync::Mutex::new(Vec::new()));
        let record = told.clone();
        let solved = solve_scenario(Path::new("beam"), move |reached, iterations| {
            record.lock().unwrap().push((reached, iterations));
        })
        .unwrap();
        let told = told.lock().unwrap().clone();
        assert_eq!(told.len(), solved.solution.iterations, "{told:?}");
        assert!(told.windows(2).all(|w| w[0].0 <= w[1].0 && w[0].1 < w[1].1), "{told:?}");
        assert!(told.iter().all(|&(reached, _)| (0.0..1.0).contains(&reached)), "{told:?}");
        let mesh = &solved.solver.problem().mesh;
        let fields = solved.fields().unwrap();
        let names: Vec<&str> = fields.iter().map(|f| f.name.as_str()).collect();
        assert_eq!(names, ["displacement", "reaction_force", "green_strain", "von_mises"]);
        // The clamp takes the loads (the beam has no springs): their totals cancel.
        let p = solved.solver.problem();
        let load: Vec<f64> = (0..3).map(|d| p.f_ext.iter().skip(d).step_by(3).sum()).collect();
        let held: Vec<f64> = (0..3).map(|d| p.dirichlet.keys().map(|&n| solved.reaction[3 * n + d]).sum()).collect();
        let scale = mesh::norm([load[0], load[1], load[2]]);
        assert!(scale > 0.0 && (0..3).all(|d| (held[d] + load[d]).abs() < 1e-3 * scale), "{held:?} vs {load:?}");
        assert_eq!(solved.solution.u.len(), 3 * mesh.num_nodes());
        assert!(fem::post::max_displacement(&solved.solution.u) > 0.0);
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("sub/beam.vtu");
        solved.write(&out).unwrap();
        assert_eq!(mesh::io::read_mesh(&out).unwrap().num_nodes(), mesh.num_nodes());
        let lines = solved.lines().unwrap();
        assert!(lines[0].starts_with("scenario   beam"), "{lines:?}");
        assert!(lines[1].starts_with(&format!("mesh       {} nodes", mesh.num_nodes())), "{lines:?}");
        assert!(lines.iter().any(|l| l.starts_with("max |u|    ")) && lines.len() == 8, "{lines:?}");
        let reaction = lines.iter().find(|l| l.starts_with("reaction   held nodes (")).expect("a reaction line");
        assert!(reaction.contains("springs and attachments (0.0000e0, 0.0000e0, 0.0000e0) N"), "{reaction}");
    }

    /// A cube of Saint-Venant-Kirchhoff (ν 0.49: F-bar) held at its base and pushed down at its
    /// centre by a point force: at 0.1 N no cell is compressed past the law's limit stretch; at
    /// 1 N the solve converges with a third of them past it, and says so.
    #[test]
    fn cells_compressed_past_svk_s_limit_are_warned_about() {
        let dir = tempfile::tempdir().unwrap();
        let lines = |force: f64| {
            let text = format!(
                "kind = \"static\"\nname = \"svk\"\n[mesh.box]\nmin = [0.0, 0.0, 0.0]\nmax = [0.02, 0.02, 0.02]\n\
                 cells = [4, 4, 4]\nelement = \"tet\"\n[material]\nlaw = \"svk\"\nyoung = 5000.0\npoisson = 0.49\n\
                 [[fixed]]\nselect = {{ box = {{ min = [-1.0, -1.0, -1.0], max = [1.0, 1.0, 1e-9] }} }}\n\
                 [[force]]\nselect = {{ list = [62] }}\ntotal = [0.0, 0.0, -{force}]\n"
            );
            solved_lines(dir.path(), &text)
        };
        let warned = |lines: &[String]| lines.iter().any(|l| l.contains("past Saint-Venant-Kirchhoff's limit stretch"));
        let small = lines(0.1);
        assert!(!warned(&small), "{small:?}");
        let large = lines(1.0);
        assert!(large.iter().any(|l| l.starts_with("material   SVK (F-bar")), "{large:?}");
        let warning = large.iter().find(|l| warned(std::slice::from_ref(*l))).expect("no warning");
        assert!(warning.contains("of 384 cells") && warning.contains("neo_hookean"), "{warning}");
    }

    /// A cube of ν = 0.499 held at its base and pressed down by a quarter of its height: the
    /// co-rotational law on standard elements loses volume and says so; pressed by a fiftieth, it
    /// keeps it, without a word.
    #[test]
    fn a_nearly_incompressible_body_that_changes_volume_is_warned_about() {
        let dir = tempfile::tempdir().unwrap();
        let lines = |press: f64| {
            let text = format!(
                "kind = \"static\"\nname = \"press\"\n[mesh.box]\nmin = [0.0, 0.0, 0.0]\nmax = [0.02, 0.02, 0.02]\n\
                 cells = [3, 3, 3]\nelement = \"hex\"\n[material]\nlaw = \"corotational\"\nyoung = 5000.0\n\
                 poisson = 0.499\nformulation = \"standard\"\n\
                 [[fixed]]\nselect = {{ box = {{ min = [-1.0, -1.0, -1.0], max = [1.0, 1.0, 1e-9] }} }}\n\
                 [[prescribed]]\nselect = {{ box = {{ min = [-1.0, -1.0, 0.02], max = [1.0, 1.0, 1.0] }} }}\n\
                 displacement = [0.0, 0.0, -{press}]\n"
            );
            solved_lines(dir.path(), &text)
        };
        let warned = |lines: &[String]| lines.iter().find(|l| l.contains("changed volume by more than")).cloned();
        let pressed = lines(0.005);
        let warning = warned(&pressed).expect("the co-rotational standard cube warned");
        assert!(
            warning.contains("the co-rotational law keeps the volume to first order")
                && warning.contains("neo_hookean"),
            "{warning}"
        );
        let touched = lines(0.0004);
        assert_eq!(warned(&touched), None, "{touched:?}");
    }

    /// A bar in a file with a tetrahedron hanging on its free end by a vertex (as a mesher left one
    /// in a real liver): pulled, it solves as the bar alone, the tetrahedron left out and named;
    /// under its weight, which loads the tetrahedron too, the mechanism is refused.
    #[test]
    fn a_piece_hanging_by_a_vertex_that_carries_nothing_is_left_out() {
        let dir = tempfile::tempdir().unwrap();
        let bar = mesh::box_tet([0.0; 3], [0.1, 0.02, 0.02], [5, 1, 1]).unwrap();
        let mesh::Cells::Tet4(tets) = &bar.cells else { unreachable!("a tetrahedral bar") };
        let corner = bar.nodes.iter().position(|p| *p == [0.1, 0.02, 0.02]).unwrap();
        let (mut nodes, mut with_tip) = (bar.nodes.clone(), tets.clone());
        let k = nodes.len();
        nodes.extend([[0.105, 0.02, 0.02], [0.105, 0.025, 0.02], [0.105, 0.02, 0.025]]);
        with_tip.push([corner, k, k + 1, k + 2]);
        let hanging = mesh::Mesh::new(nodes, mesh::Cells::Tet4(with_tip)).unwrap();
        let solve = |mesh: &mesh::Mesh, name: &str, load: &str| {
            mesh::io::write_mesh(dir.path().join(format!("{name}.vtu")), mesh, &[]).unwrap();
            let scenario = format!(
                "kind = \"static\"\nname = \"{name}\"\n{load}[mesh.file]\npath = \"{name}.vtu\"\n[material]\n\
                 law = \"neo_hookean\"\nyoung = 5000.0\npoisson = 0.3\n\
                 [[fixed]]\nselect = {{ box = {{ min = [-1.0, -1.0, -1.0], max = [1e-9, 1.0, 1.0] }} }}\n\
                 [[force]]\nselect = {{ box = {{ min = [0.0999, -1.0, -1.0], max = [0.1001, 1.0, 1.0] }} }}\n\
                 total = [0.0, 0.0, -0.01]\n"
            );
            let path = dir.path().join(format!("{name}.toml"));
            std::fs::write(&path, scenario).unwrap();
            solve_scenario(&path, |_, _| {})
        };
        let alone = solve(&bar, "bar", "").unwrap();
        let with = solve(&hanging, "hanging", "").unwrap();
        assert_eq!(with.solution.u, alone.solution.u, "the rest deforms as the bar alone");
        let lines = with.lines().unwrap();
        let warning = lines.iter().find(|l| l.contains("hang on the rest by an edge or a vertex")).expect("said");
        assert!(warning.contains("1 element(s)") && warning.contains("element 30 of the file"), "{warning}");
        assert!(warning.contains("the 3 node(s) only they have"), "{warning}");
        let error = solve(&hanging, "heavy", "gravity = [0.0, 0.0, -9.81]\n").err().expect("refused");
        assert!(format!("{error:#}").contains("hang on the rest by an edge or a vertex"), "{error:#}");
        // A FEM registration on that scenario leaves the piece out too, and says so.
        use crate::registration::{MethodSpec, RegistrationSpec, TargetsSpec};
        let method = MethodSpec::fem(dir.path().join("hanging.toml"));
        let registration =
            RegistrationSpec::new(method, TargetsSpec::Points(vec![[0.05, 0.01, 0.01]])).build().unwrap();
        assert_eq!(registration.organ().mesh().num_nodes(), bar.num_nodes());
        assert!(
            registration.warnings().iter().any(|w| w.contains("element 30 of the file")),
            "{:?}",
            registration.warnings()
        );
    }

    /// The selection of the free end of [`neo_hookean_bar`].
    const BAR_END: &str = "select = { box = { min = [0.04, -1.0, -1.0], max = [1.0, 1.0, 1.0] } }\n";

    /// A Neo-Hookean bar of four hexahedra, 4 cm long, held at x = 0, with the `solver` table
    /// and what acts on its free end ([`BAR_END`]).
    fn neo_hookean_bar(solver: &str, end: &str) -> String {
        format!(
            "kind = \"static\"\nname = \"bar\"\n[mesh.box]\nmin = [0.0, 0.0, 0.0]\nmax = [0.04, 0.01, 0.01]\n\
             cells = [4, 1, 1]\nelement = \"hex\"\n[material]\nlaw = \"neo_hookean\"\nyoung = 5000.0\n\
             poisson = 0.3\n{solver}[[fixed]]\nselect = {{ box = {{ min = [-1.0, -1.0, -1.0], max = [1e-9, 1.0, 1.0] }} }}\n\
             {end}"
        )
    }

    /// A bar pulled to four times its length: warned of as beyond soft tissue (stretch and
    /// motion); pulled by a tenth of it, not.
    #[test]
    fn a_solution_beyond_soft_tissue_is_warned_about() {
        let dir = tempfile::tempdir().unwrap();
        let lines = |pull: f64| {
            let end = format!("[[prescribed]]\n{BAR_END}displacement = [{pull}, 0.0, 0.0]\n");
            solved_lines(dir.path(), &neo_hookean_bar("", &end))
        };
        let pulled = lines(0.12);
        let stretched = pulled.iter().find(|l| l.contains("far beyond what soft tissue bears")).expect("warned");
        assert!(stretched.starts_with("warning    4 of 4 cells are stretched past 3"), "{stretched}");
        assert!(pulled.iter().any(|l| l.contains("3.0 times its own size")), "{pulled:?}");
        let touched = lines(0.004);
        assert!(!touched.iter().any(|l| l.starts_with("warning")), "{touched:?}");
    }

    /// A solve taken on a small last increment above its residual tolerance says so; the same
    /// within it does not.
    #[test]
    fn a_residual_above_the_tolerance_is_warned_about() {
        let dir = tempfile::tempdir().unwrap();
        let lines = |solver: &str| {
            let end = format!("[[force]]\n{BAR_END}total = [0.0, 0.0, -0.02]\n");
            solved_lines(dir.path(), &neo_hookean_bar(&format!("[solver]\n{solver}\n"), &end))
        };
        let warned = |lines: &[String]| lines.iter().any(|l| l.contains("far above rtol = 1e-14"));
        let loose = lines("rtol = 1e-14\nutol = 0.5");
        assert!(warned(&loose), "{loose:?}");
        let tight = lines("rtol = 1e-14\nutol = 0.0\nmax_iterations = 60");
        assert!(!warned(&tight), "{tight:?}");
    }

    /// A bar in a file, held at one end and pulled at the other by node numbers: the same solve
    /// when the file holds a node that no cell uses before them (the numbers stay the file's),
    /// which the output names; pulled as far as the linear law turns cells inside out, it says so.
    #[test]
    fn nodes_are_numbered_as_in_the_file_and_inverted_cells_are_named() {
        let dir = tempfile::tempdir().unwrap();
        let bar = mesh::box_tet([0.0; 3], [0.1, 0.02, 0.02], [5, 1, 1]).unwrap();
        let ends = |x: f64| -> Vec<usize> { (0..bar.num_nodes()).filter(|&i| bar.nodes[i][0] == x).collect() };
        let (held, pulled) = (ends(0.0), ends(0.1));
        let mut orphaned = bar.clone();
        orphaned.nodes.insert(0, [0.5, 0.5, 0.5]);
        let mesh::Cells::Tet4(tets) = &bar.cells else { unreachable!("a tetrahedral bar") };
        orphaned.cells = mesh::Cells::Tet4(tets.iter().map(|t| t.map(|i| i + 1)).collect());
        let solve = |mesh: &mesh::Mesh, shift: usize, force: f64, name: &str| {
            let file = dir.path().join(format!("{name}.vtu"));
            mesh::io::write_mesh(&file, mesh, &[]).unwrap();
            let list = |nodes: &[usize]| format!("{:?}", nodes.iter().map(|i| i + shift).collect::<Vec<_>>());
            let scenario = format!(
                "kind = \"static\"\nname = \"{name}\"\n[mesh.file]\npath = \"{name}.vtu\"\n[material]\nlaw = \"linear\"\n\
                 young = 5000.0\npoisson = 0.3\n[[fixed]]\nselect = {{ list = {} }}\n[[force]]\nselect = {{ list = {} }}\n\
                 total = [{force}, 0.0, 0.0]\n",
                list(&held),
                list(&pulled)
            );
            let path = dir.path().join(format!("{name}.toml"));
            std::fs::write(&path, scenario).unwrap();
            solve_scenario(&path, |_, _| {}).unwrap()
        };
        let (plain, shifted) = (solve(&bar, 0, 0.01, "plain"), solve(&orphaned, 1, 0.01, "orphaned"));
        assert_eq!(plain.solution.u, shifted.solution.u);
        assert_eq!(shifted.solver.problem().mesh.file_nodes, Some((1..=bar.num_nodes()).collect()));
        let fields = shifted.fields().unwrap();
        assert_eq!(fields.last().unwrap().values[..3], [1.0, 2.0, 3.0], "file_node");
        assert!(shifted.lines().unwrap()[1].contains("numbered as in its file"));
        assert!(!plain.lines().unwrap().iter().any(|l| l.starts_with("warning")));
        let crushed = solve(&bar, 0, -40.0, "crushed").lines().unwrap();
        let warning = crushed.iter().find(|l| l.contains("cells are turned inside out")).expect("warned");
        assert!(warning.starts_with("warning    "), "{crushed:?}");
        // One cell numbered the other way round in the file: the same solve, the cell named.
        let mut odd = bar.clone();
        let mesh::Cells::Tet4(tets) = &mut odd.cells else { unreachable!("a tetrahedral bar") };
        tets[3].swap(2, 3);
        let turned = solve(&odd, 0, 0.01, "odd");
        assert_eq!(turned.solution.u, plain.solution.u);
        let lines = turned.lines().unwrap();
        let warning = lines.iter().find(|l| l.starts_with("warning")).expect("the odd cell said");
        assert!(
            warning.contains("1 of the file's 30 cells are numbered the other way round") && warning.contains("cell 3"),
            "{warning}"
        );
    }
}
