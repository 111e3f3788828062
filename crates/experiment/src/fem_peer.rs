//! augsim's static solver against CalculiX ([`crate::calculix`]) on the same problems: the same
//! mesh, elements, law, constraints and loads, solved by both; the nodal displacements compared.

use std::path::Path;
use std::time::Instant;

use anyhow::{Context, Result};
use fem::{verification, Formulation, Law, Material, Problem, SolverOptions, StaticSolver};
use mesh::length::mm;
use mesh::CellKind;
use scenario::StaticScenario;
use serde::{Deserialize, Serialize};

use crate::calculix;
use crate::{reference, ExperimentResult, Headline, Name, Progress, Row, Size};

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
    /// CalculiX: the whole run (s).
    pub calculix_seconds: f64,
    /// Where CalculiX's solution turns an element inside out (det F ≤ 0 at a quadrature point),
    /// which none of these laws admits; `None` when it does not.
    pub calculix_inverted: Option<String>,
    /// augsim's solution against CalculiX's, or why augsim found none.
    pub augsim: std::result::Result<Agreement, String>,
}

/// How close augsim's solution is to CalculiX's.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Agreement {
    /// The largest nodal displacement of augsim's solution (m).
    pub max_displacement: f64,
    /// The largest distance between the two solutions' displacements of a node (m).
    pub max_difference: f64,
    /// The root mean square of those distances over the nodes (m).
    pub rms_difference: f64,
    /// augsim: the solve (s), the solver's setup before it not counted.
    pub seconds: f64,
    /// The largest reaction force of a held node, augsim's (N).
    #[serde(default)]
    pub max_reaction: f64,
    /// The largest difference between the two solvers' reaction forces of a held node (N).
    #[serde(default)]
    pub max_reaction_difference: f64,
}

impl Agreement {
    /// The largest difference relative to the largest displacement.
    pub fn relative(&self) -> f64 {
        self.max_difference / self.max_displacement
    }

    /// The largest difference of the reaction forces relative to the largest (0 when nothing holds
    /// a node).
    pub fn reaction_relative(&self) -> f64 {
        match self.max_reaction {
            0.0 => 0.0,
            largest => self.max_reaction_difference / largest,
        }
    }
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
    // The pushed patch moved down by `depth` (m) instead of the push.
    let pressed = |depth: f64| -> Result<Problem> {
        let mut p = liver(5000, Law::Svk, 1)?;
        p.f_ext.fill(0.0);
        let push = p.mesh.regions.get("push").context("the phantom has no push region")?.clone();
        p.prescribe(&push, [0.0, 0.0, -depth]);
        Ok(p)
    };
    let mut out = vec![
        ("verification cantilever 10 × 1 × 1 m, H8, linear, ν = 0.3".to_string(), cantilever),
        (
            "beam 0.1 m bent by 0.05 N, H8, SVK, ν = 0.3".into(),
            verification::bent_beam(CellKind::Hex8, 1, Law::Svk, 0.3, 0.05)?,
        ),
        (
            "beam 0.1 m bent by 0.025 N, T10, SVK, ν = 0.49".into(),
            verification::bent_beam(CellKind::Tet4, 2, Law::Svk, 0.49, 0.025)?,
        ),
        ("liver phantom 5,000 T4, linear, ν = 0.48, 800 Pa push".into(), liver(5000, Law::Linear, 1)?),
        ("liver phantom 5,000 T4, SVK, ν = 0.48, 800 Pa push".into(), liver(5000, Law::Svk, 1)?),
        ("liver phantom 5,000 T4, SVK, held by springs (50 N/m a node), 800 Pa push".into(), on_springs),
        ("liver phantom 5,000 T4, SVK, ν = 0.48, a lobe pressed down by 8 mm (prescribed)".into(), pressed(0.008)?),
        ("liver phantom 5,000 T4, SVK, ν = 0.48, a lobe pressed down by 15 mm (prescribed)".into(), pressed(0.015)?),
        ("liver phantom 5,000 T10, SVK, ν = 0.48, 800 Pa push".into(), liver(5000, Law::Svk, 2)?),
    ];
    if size == Size::Paper {
        // Under the full push the fine mesh nears SVK's compressive limit point (CalculiX's increments stall at 0.9).
        let mut fine = liver(50_000, Law::Svk, 1)?;
        fine.f_ext.iter_mut().for_each(|f| *f *= 0.5);
        out.push(("liver phantom 50,000 T4, SVK, ν = 0.48, 400 Pa push".into(), fine));
    }
    Ok(out)
}

/// Solves `problem` with augsim and compares the solution with CalculiX's, `peer`; checks
/// CalculiX's solution for inverted elements.
fn compare(description: &str, problem: Problem, peer: &calculix::PeerSolution) -> Result<PeerCase> {
    let dofs = problem.num_dofs();
    let mut solver = StaticSolver::new(problem)?;
    let calculix_inverted = match solver.internal_force(&peer.u) {
        Err(fem::FemError::InvertedElement { element, det }) => Some(format!("element {element}, det F = {det:.2}")),
        other => {
            other.map(|_| None).with_context(|| format!("augsim's forces at CalculiX's solution of {description}"))?
        }
    };
    let start = Instant::now();
    // A tight tolerance on the residual alone (no stop on a small step).
    let options = SolverOptions { rtol: 1e-9, utol: 0.0, ..Default::default() };
    let solved = solver.solve(&options).map_err(|e| e.to_string());
    let seconds = start.elapsed().as_secs_f64();
    let augsim = match solved {
        Ok(solution) => {
            let reaction = solver.reaction_forces(&solution.u)?;
            let point = |v: &[f64], n: usize| [v[3 * n], v[3 * n + 1], v[3 * n + 2]];
            let nodes = 0..solver.problem().mesh.num_nodes();
            let distances: Vec<f64> =
                nodes.clone().map(|n| mesh::distance(point(&solution.u, n), point(&peer.u, n))).collect();
            let held: Vec<usize> = solver.problem().dirichlet.keys().copied().collect();
            let reaction_gaps = held.iter().map(|&n| mesh::distance(point(&reaction, n), point(&peer.reaction, n)));
            Ok(Agreement {
                max_displacement: nodes.map(|n| mesh::norm(point(&solution.u, n))).fold(0.0, f64::max),
                max_difference: distances.iter().copied().fold(0.0, f64::max),
                rms_difference: (distances.iter().map(|d| d * d).sum::<f64>() / distances.len() as f64).sqrt(),
                seconds,
                max_reaction: held.iter().map(|&n| mesh::norm(point(&reaction, n))).fold(0.0, f64::max),
                max_reaction_difference: reaction_gaps.fold(0.0, f64::max),
            })
        }
        Err(e) => Err(e),
    };
    Ok(PeerCase { problem: description.to_string(), dofs, calculix_seconds: peer.seconds, calculix_inverted, augsim })
}

/// The table line of a case, its times with their multiple of the reference (`reference_ms`).
fn row(c: &PeerCase, reference_ms: f64) -> Row {
    let reference_ms = Some(reference_ms);
    let calculix_time = reference::seconds(c.calculix_seconds, 2, reference_ms);
    let calculix = match &c.calculix_inverted {
        Some(at) => format!("CalculiX {calculix_time}, its solution inverted ({at})"),
        None => format!("CalculiX {calculix_time}"),
    };
    let ours = match &c.augsim {
        Ok(a) => format!(
            "largest difference {:.2e} m at most {:.1} mm displacement ({:.1e} of it; RMS {:.1e} m); reaction forces: \
             {}; {} dofs, augsim {}, {calculix}",
            a.max_difference,
            mm(a.max_displacement),
            a.relative(),
            a.rms_difference,
            match a.max_reaction {
                0.0 => "no held node".to_string(),
                largest => format!("{:.1e} of the largest, {largest:.3e} N", a.reaction_relative()),
            },
            c.dofs,
            reference::seconds(a.seconds, 2, reference_ms)
        ),
        Err(e) => format!("augsim finds no solution: {e}; {} dofs, {calculix}", c.dofs),
    };
    Row::new(c.problem.clone(), ours, "")
}

/// Runs the comparison.
pub fn run(size: Size, dir: &Path, progress: Progress) -> Result<ExperimentResult> {
    let version = calculix::version()?;
    let reference_ms = reference::measure()?;
    let mut cases = Vec::new();
    for (k, (description, problem)) in problems(size)?.into_iter().enumerate() {
        progress.line(&format!("fem-peer: {description} ({} dofs)", problem.num_dofs()));
        let case_dir = dir.join(format!("case{}", k + 1));
        let peer = calculix::solve(&problem, &case_dir).with_context(|| format!("CalculiX on {description}"))?;
        cases.push(compare(&description, problem, &peer)?);
    }
    let solved: Vec<&Agreement> = cases.iter().filter_map(|c| c.augsim.as_ref().ok()).collect();
    let worst = solved.iter().map(|a| a.relative()).fold(0.0, f64::max);
    let worst_reaction = solved.iter().map(|a| a.reaction_relative()).fold(0.0, f64::max);
    let largest = solved.iter().map(|a| a.max_displacement).fold(0.0, f64::max);
    // A problem augsim finds no solution of is explained when CalculiX's turns an element inside out.
    let unexplained = cases.iter().filter(|c| c.augsim.is_err() && c.calculix_inverted.is_none()).count();
    let refused = cases.len() - solved.len();
    let headline = Headline::finding(
        format!(
            "static solves against CalculiX {version}: {} problems, T4, T10, H8, up to {:.0} mm",
            cases.len(),
            mm(largest)
        ),
        format!(
            "largest difference {worst:.1e} of the largest displacement, {worst_reaction:.1e} of the largest reaction \
             force, on {}{}",
            solved.len(),
            match refused {
                0 => String::new(),
                n => format!("; on {n} CalculiX's solution is inverted, augsim finds none"),
            }
        ),
        "the same solution",
        worst <= SAME_SOLUTION && worst_reaction <= SAME_SOLUTION && unexplained == 0,
    );
    let rows = cases.iter().map(|c| row(c, reference_ms)).collect();
    let notes = vec![
        format!(
            "CalculiX {version} (`ccx`, C3D4 / C3D10 / C3D8 with the same quadrature as augsim's elements: 1, 4 and 8 \
             points) on the very mesh, constraints and nodal loads: linear elasticity is `*ELASTIC`, Saint-Venant-Kirchhoff \
             `*ELASTIC` under `NLGEOM`, the springs `SPRING1` elements, the loads `*CLOAD`; the load in increments \
             CalculiX sizes itself from 5 %, then a second step of equilibrium iterations under the same load."
        ),
        "An inverted solution: augsim's element evaluation finds det F ≤ 0 at a quadrature point of CalculiX's \
         displacement. Saint-Venant-Kirchhoff's energy stays finite for an element turned inside out, so CalculiX's \
         Newton iterations may converge there; augsim refuses such states and reports the compressive limit point or the \
         element crushed flat it stopped at."
            .to_string(),
        format!(
            "augsim: the standard formulation, residual tolerance 1e-9 (no stop on a small step); the same solution means a largest nodal \
             difference at most {SAME_SOLUTION:.0e} of the largest displacement, and of the held nodes' reaction forces \
             (CalculiX's RF) at most that of the largest (CalculiX prints 7 significant digits)."
        ),
        "Times: one run each on this machine; CalculiX's include reading its deck and writing its results, and it \
         steps the load in increments, then iterates again under the full load, where augsim solves in one Newton \
         solve: they say nothing of either solver's speed."
            .to_string(),
        reference::note(Some(reference_ms)),
    ];
    let mut values = serde_json::Map::new();
    values.insert("calculix_version".into(), version.clone().into());
    values.insert("cases".into(), serde_json::to_value(&cases)?);
    values.insert("reference_ms".into(), reference_ms.into());
    Ok(ExperimentResult {
        name: Name::FemPeer,
        size,
        seconds: 0.0,
        build: String::new(),
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
            ("beam_h8_svk", verification::bent_beam(CellKind::Hex8, 1, Law::Svk, 0.3, 0.05).unwrap()),
            ("beam_t10_svk", verification::bent_beam(CellKind::Tet4, 2, Law::Svk, 0.49, 0.025).unwrap()),
        ];
        for (name, problem) in beams {
            let stored = |ext: &str| std::fs::read_to_string(data.join(format!("{name}.{ext}"))).unwrap();
            let deck = calculix::input_deck(&problem).unwrap();
            assert!(deck == stored("inp"), "{name}: the deck is not the one CalculiX solved (see the data's README)");
            let u = calculix::read_displacements(&stored("dat"), problem.mesh.nodes.len()).unwrap();
            let reaction = calculix::read_reaction_forces(&stored("dat"), problem.mesh.nodes.len()).unwrap();
            let case = compare(name, problem, &calculix::PeerSolution { u, reaction, seconds: 0.0 }).unwrap();
            assert_eq!(case.calculix_inverted, None);
            let case = case.augsim.unwrap();
            assert!(case.max_displacement > 0.08, "{name}: {case:?}");
            // CalculiX prints 7 significant digits.
            assert!(case.max_difference < 1e-6 * case.max_displacement, "{name}: {case:?}");
            assert!(case.max_reaction > 0.0 && case.reaction_relative() < 1e-5, "{name}: {case:?}");
        }
    }
}
