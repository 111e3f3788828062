//! augsim's static solver against CalculiX ([`crate::calculix`]) on the same problems: the same
//! mesh, elements, law, constraints and loads, solved by both; the nodal displacements compared.

use std::path::Path;
use std::time::Instant;

use anyhow::{Context, Result};
use fem::{verification, Formulation, Law, Material, Problem, SolverOptions, StaticSolver};
use mesh::CellKind;
use scenario::StaticScenario;
use serde::{Deserialize, Serialize};

use crate::calculix;
use crate::{ExperimentResult, Headline, Name, Progress, Row, Size};

/// The largest difference, relative to the largest displacement, under which the two solutions
/// are the same: CalculiX prints 7 significant digits, and both solve to tight tolerances.
pub const SAME_SOLUTION: f64 = 1e-5;

/// One problem solved by both.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PeerCase {
    /// The problem.
    pub problem: String,
    /// Degrees of freedom (3 per node).
    pub dofs: usize,
    /// The largest nodal displacement of augsim's solution (m).
    pub max_displacement: f64,
    /// The largest distance between the two solutions' displacements of a node (m).
    pub max_difference: f64,
    /// The root mean square of those distances over the nodes (m).
    pub rms_difference: f64,
    /// augsim: a new solver's setup and solve (s).
    pub augsim_seconds: f64,
    /// CalculiX: the whole run (s).
    pub calculix_seconds: f64,
}

/// A cantilever of 10 × 2 × 2 cells of `kind` (T4 made T10 for `order` 2), 0.1 × 0.02 × 0.02 m
/// (E = 5 kPa), clamped at x = 0, a downward `load` (N) on its free end.
fn bent_beam(kind: CellKind, order: u8, law: Law, poisson: f64, load: f64) -> Result<Problem> {
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

/// The built-in `liver` scenario (the phantom fixed between its lobes, an 800 Pa push on one
/// lobe) on about `tets` tetrahedra with the standard formulation on elements of `order`, its
/// law replaced by `law`.
fn liver(tets: usize, law: Law, order: u8) -> Result<Problem> {
    let (mut scenario, dir) = StaticScenario::load(Path::new("liver"))?;
    scenario.mesh = scenario::source::MeshSource::Phantom { tets };
    scenario.material = Material { law, ..scenario.material }.with_order(order).with_formulation(Formulation::Standard);
    Ok(scenario.build_problem(&dir)?)
}

/// The problems compared: (description, problem).
fn problems(size: Size) -> Result<Vec<(String, Problem)>> {
    let (cantilever, _) =
        verification::cantilever(CellKind::Hex8, [10, 2, 2], Law::Linear, Formulation::Standard, 0.3)?;
    let mut on_springs = liver(5000, Law::Svk, 1)?;
    let held: Vec<usize> = std::mem::take(&mut on_springs.dirichlet).into_keys().collect();
    on_springs.add_springs(&held, 50.0);
    let mut out = vec![
        ("verification cantilever 10 × 1 × 1 m, H8, linear, ν = 0.3".to_string(), cantilever),
        ("beam 0.1 m bent by 0.05 N, H8, SVK, ν = 0.3".into(), bent_beam(CellKind::Hex8, 1, Law::Svk, 0.3, 0.05)?),
        ("beam 0.1 m bent by 0.025 N, T10, SVK, ν = 0.49".into(), bent_beam(CellKind::Tet4, 2, Law::Svk, 0.49, 0.025)?),
        ("liver phantom 5,000 T4, linear, ν = 0.48, 800 Pa push".into(), liver(5000, Law::Linear, 1)?),
        ("liver phantom 5,000 T4, SVK, ν = 0.48, 800 Pa push".into(), liver(5000, Law::Svk, 1)?),
        ("liver phantom 5,000 T4, SVK, held by springs (50 N/m a node), 800 Pa push".into(), on_springs),
        ("liver phantom 5,000 T10, SVK, ν = 0.48, 800 Pa push".into(), liver(5000, Law::Svk, 2)?),
    ];
    if size == Size::Paper {
        out.push(("liver phantom 50,000 T10, SVK, ν = 0.48, 800 Pa push".into(), liver(50_000, Law::Svk, 2)?));
    }
    Ok(out)
}

/// Solves `problem` with augsim and compares the solution with CalculiX's, `peer`.
fn compare(description: &str, problem: Problem, peer: &calculix::PeerSolution) -> Result<PeerCase> {
    let dofs = problem.num_dofs();
    let start = Instant::now();
    // A tight tolerance on the residual alone (no stop on a small step).
    let options = SolverOptions { rtol: 1e-9, utol: 0.0, ..Default::default() };
    let u = StaticSolver::new(problem)?.solve(&options).with_context(|| format!("augsim on {description}"))?.u;
    let augsim_seconds = start.elapsed().as_secs_f64();
    let point = |d: &[f64]| [d[0], d[1], d[2]];
    let distances: Vec<f64> =
        u.chunks_exact(3).zip(peer.u.chunks_exact(3)).map(|(a, b)| mesh::distance(point(a), point(b))).collect();
    Ok(PeerCase {
        problem: description.to_string(),
        dofs,
        max_displacement: u.chunks_exact(3).map(|d| mesh::norm(point(d))).fold(0.0, f64::max),
        max_difference: distances.iter().copied().fold(0.0, f64::max),
        rms_difference: (distances.iter().map(|d| d * d).sum::<f64>() / distances.len() as f64).sqrt(),
        augsim_seconds,
        calculix_seconds: peer.seconds,
    })
}

/// Runs the comparison.
pub fn run(size: Size, dir: &Path, progress: Progress) -> Result<ExperimentResult> {
    let version = calculix::version()?;
    let mut cases = Vec::new();
    for (k, (description, problem)) in problems(size)?.into_iter().enumerate() {
        progress(&format!("fem-peer: {description} ({} dofs)", problem.num_dofs()));
        let case_dir = dir.join(format!("case{}", k + 1));
        let peer = calculix::solve(&problem, &case_dir).with_context(|| format!("CalculiX on {description}"))?;
        cases.push(compare(&description, problem, &peer)?);
    }
    let worst = cases.iter().map(|c| c.max_difference / c.max_displacement).fold(0.0, f64::max);
    let largest = cases.iter().map(|c| c.max_displacement).fold(0.0, f64::max);
    let rows = cases
        .iter()
        .map(|c| {
            Row::new(
                c.problem.clone(),
                format!(
                    "largest difference {:.2e} m at most {:.1} mm displacement ({:.1e} of it; RMS {:.1e} m); {} dofs, \
                     augsim {:.2} s, CalculiX {:.2} s",
                    c.max_difference,
                    1e3 * c.max_displacement,
                    c.max_difference / c.max_displacement,
                    c.rms_difference,
                    c.dofs,
                    c.augsim_seconds,
                    c.calculix_seconds
                ),
                "",
            )
        })
        .collect();
    let headline = Headline::finding(
        format!(
            "static solves against CalculiX {version}: {} problems, T4, T10, H8, up to {:.0} mm",
            cases.len(),
            1e3 * largest
        ),
        format!("largest difference {worst:.1e} of the largest displacement"),
        "the same solution",
        worst <= SAME_SOLUTION,
    );
    let notes = vec![
        format!(
            "CalculiX {version} (`ccx`, C3D4 / C3D10 / C3D8 with the same quadrature as augsim's elements: 1, 4 and 8 \
             points) on the very mesh, constraints and nodal loads: linear elasticity is `*ELASTIC`, Saint-Venant-Kirchhoff \
             `*ELASTIC` under `NLGEOM`, the springs `SPRING1` elements, the loads `*CLOAD`, in increments of at most 5 % \
             of the load."
        ),
        format!(
            "augsim: the standard formulation, residual tolerance 1e-9 (no stop on a small step); the same solution means a largest nodal \
             difference at most {SAME_SOLUTION:.0e} of the largest displacement (CalculiX prints 7 significant digits)."
        ),
        "Times: one run each on this machine; CalculiX's include reading its deck and writing its results, and it \
         steps the load in at least 20 increments where augsim solves in one Newton solve, so they say nothing of \
         either solver's speed."
            .to_string(),
    ];
    let mut values = serde_json::Map::new();
    values.insert("calculix_version".into(), version.clone().into());
    values.insert("cases".into(), serde_json::to_value(&cases)?);
    Ok(ExperimentResult {
        name: Name::FemPeer,
        size,
        seconds: 0.0,
        headlines: vec![headline],
        rows,
        figures: Vec::new(),
        page_figures: Vec::new(),
        notes,
        values,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two bent beams (H8 at ν = 0.3 and T10 at ν = 0.49, SVK, about 9 cm at the tip) solved by
    /// augsim equal what CalculiX 2.20 computed from the very deck [`calculix::input_deck`]
    /// writes for them (stored in `tests/data/calculix`: CalculiX is not needed here).
    #[test]
    fn bent_beams_match_the_stored_calculix_solutions() {
        let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/calculix");
        let beams = [
            ("beam_h8_svk", bent_beam(CellKind::Hex8, 1, Law::Svk, 0.3, 0.05).unwrap()),
            ("beam_t10_svk", bent_beam(CellKind::Tet4, 2, Law::Svk, 0.49, 0.025).unwrap()),
        ];
        for (name, problem) in beams {
            let stored = |ext: &str| std::fs::read_to_string(data.join(format!("{name}.{ext}"))).unwrap();
            let deck = calculix::input_deck(&problem).unwrap();
            assert!(deck == stored("inp"), "{name}: the deck is not the one CalculiX solved (see the data's README)");
            let u = calculix::read_displacements(&stored("dat"), problem.mesh.nodes.len()).unwrap();
            let case = compare(name, problem, &calculix::PeerSolution { u, seconds: 0.0 }).unwrap();
            assert!(case.max_displacement > 0.08, "{name}: {case:?}");
            // CalculiX prints 7 significant digits.
            assert!(case.max_difference < 1e-6 * case.max_displacement, "{name}: {case:?}");
        }
    }
}
