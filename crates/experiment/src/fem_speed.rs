//! Static FEM solve times (the cases of `augsim bench`): a new solver's first solve, repeated
//! solves from rest, and warm-started frames of a slowly varying load.

use std::path::Path;

use anyhow::Result;
use fem::{Formulation, Law, Material, Problem, SolverOptions, StaticSolver};
use mesh::select::nodes_in_box;
use serde::{Deserialize, Serialize};

use mesh::stats::median;

use crate::{reference, ExperimentResult, Headline, Name, Progress, Row, Size};

/// Cases above this many dofs are timed at most [`LARGE_RUNS`] times (each solve takes seconds).
pub(crate) const LARGE_DOFS: usize = 20_000;
/// Most runs of a case above [`LARGE_DOFS`].
pub(crate) const LARGE_RUNS: usize = 3;

/// The timings of one case (ms, medians over the runs).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CaseTiming {
    /// The case.
    pub name: String,
    /// A short label for plots.
    pub label: String,
    /// The published time of the same kind of solve, where there is one.
    pub published: String,
    /// That time (ms).
    #[serde(default)]
    pub published_ms: Option<f64>,
    /// The mesh and law (e.g. "5k liver, Svk"): F-bar is compared with the standard element
    /// within a group.
    #[serde(default)]
    pub group: String,
    /// Whether the case uses the F-bar formulation.
    #[serde(default)]
    pub fbar: bool,
    /// The factor on the group's nominal load.
    #[serde(default = "one")]
    pub load: f64,
    /// Whether the case is the run's reference (see `reference_ms`).
    #[serde(default)]
    pub reference: bool,
    /// Degrees of freedom.
    pub dofs: usize,
    /// How many times the case was timed (at most 3 above 20,000 dofs).
    #[serde(default)]
    pub runs: usize,
    /// Newton iterations of the last solve from rest.
    pub iterations: usize,
    /// Factorisations of the last solve from rest.
    pub factorizations: usize,
    /// Tangent assemblies of the last solve from rest.
    pub assemblies: usize,
    /// Building a solver: sparse pattern, ordering, symbolic analysis, buffers (median over
    /// the new solvers built).
    #[serde(default)]
    pub setup_ms: f64,
    /// A new solver's first solve, setup excluded (median over the new solvers built).
    pub first_ms: f64,
    /// Repeated solves from rest (the rest tangent's factorisation kept).
    pub median_ms: f64,
    /// Its assembly part.
    pub assembly_ms: f64,
    /// Its factorisation part.
    pub factorization_ms: f64,
    /// Its triangular-solve part.
    pub solve_ms: f64,
    /// Maximum displacement (m).
    pub max_displacement: f64,
    /// A frame of a sequence whose load varies by [`FRAME_LOAD_STEP`] per frame, warm-started.
    pub frame_ms: f64,
    /// Mean Newton iterations per frame.
    pub frame_iterations: f64,
}

/// The load factor of a case in a result written before cases recorded it: the nominal load.
fn one() -> f64 {
    1.0
}

/// F-bar's time over the standard element's on one pair of cases of a group.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Ratio {
    /// The group and how the pair is matched: equal load, or equal deformation (the standard
    /// element under a larger load).
    pub pair: String,
    /// First solves.
    pub first: f64,
    /// Solves from rest.
    pub from_rest: f64,
    /// Frames.
    pub frame: f64,
}

/// F-bar over the standard element, per group: the F-bar case under the nominal load against
/// each standard case of its group.
pub fn fbar_ratios(cases: &[CaseTiming]) -> Vec<Ratio> {
    let mut out = Vec::new();
    for f in cases.iter().filter(|c| c.fbar && c.load == 1.0) {
        for s in cases.iter().filter(|c| !c.fbar && c.group == f.group) {
            let matched = if s.load == 1.0 {
                "equal load".to_string()
            } else {
                format!("equal deformation (standard under ×{})", s.load)
            };
            out.push(Ratio {
                pair: format!("{}, {matched}", f.group),
                first: f.first_ms / s.first_ms,
                from_rest: f.median_ms / s.median_ms,
                frame: f.frame_ms / s.frame_ms,
            });
        }
    }
    out
}

/// The reference time of a run (ms): the median solve from rest of its reference case, the
/// co-rotational standard 5k-tet liver (the law and element of the registration's FEM), measured
/// among the other cases.
/// Every time is also given as a multiple of it, which varies less than milliseconds from one
/// host (or day) to another, on a quiet host.
pub(crate) fn reference_ms(cases: &[CaseTiming]) -> Option<f64> {
    cases.iter().find(|c| c.reference).map(|c| c.median_ms)
}

/// The reference case, as [`liver`]'s arguments (tets, order, law, formulation, load): the
/// co-rotational standard 5k-tet liver under the nominal load.
const REFERENCE: (usize, u8, Law, Formulation, f64) = (5000, 1, Law::Corotational, Formulation::Standard, 1.0);

/// The reference problem: the case whose solve from rest is every run's reference time
/// ([`reference`]), fem-speed's case flagged `reference`.
pub(crate) fn reference_problem() -> Result<Problem> {
    let (tets, order, law, formulation, load) = REFERENCE;
    Ok(liver(tets, order, law, formulation, load)?.problem)
}

/// A case to time: its name, its label for plots, the published time it compares with, its
/// group (mesh and law), formulation and load factor, whether it is the reference, the problem.
struct Case {
    name: String,
    label: String,
    published: &'static str,
    published_ms: Option<f64>,
    group: String,
    fbar: bool,
    load: f64,
    reference: bool,
    problem: Problem,
}

/// The short name of a law and formulation, for plot labels.
fn short(law: Law, formulation: Formulation) -> String {
    let law = if law == Law::Corotational { "co-rot" } else { law.display_name() };
    let formulation = if formulation == Formulation::Fbar { "F-bar" } else { "std" };
    format!("{law} {formulation}")
}

/// The beam's cells (4 × 1 × 1 m, H8).
const BEAM_CELLS: [usize; 3] = [20, 5, 5];
/// The beam's material: Young's modulus (Pa) and Poisson's ratio.
const BEAM_MATERIAL: (f64, f64) = (300.0, 0.4);

/// The beam, fixed at the bottom of its first metre, its last metre's top pulled down by 1 Pa.
fn beam(law: Law, formulation: Formulation) -> Result<Case> {
    let m = mesh::box_hex([0.0; 3], [4.0, 1.0, 1.0], BEAM_CELLS)?;
    let material = Material::new(law, BEAM_MATERIAL.0, BEAM_MATERIAL.1).with_formulation(formulation);
    let mut p = Problem::new(m, material);
    p.fix(&nodes_in_box(&p.mesh.nodes, [-1e-9; 3], [1.0 + 1e-9, 1.0 + 1e-9, 1e-9]));
    let top_end = nodes_in_box(&p.mesh.nodes, [3.0 - 1e-9, -1e-9, 1.0 - 1e-9], [4.0 + 1e-9, 1.0 + 1e-9, 1.0 + 1e-9]);
    p.add_traction(&top_end, [0.0, 0.0, -1.0]);
    let form = p.material.resolved_formulation();
    Ok(Case {
        name: format!(
            "beam {}x{}x{} H8, {}, {}",
            BEAM_CELLS[0],
            BEAM_CELLS[1],
            BEAM_CELLS[2],
            law.display_name(),
            form.display_name()
        ),
        label: format!("beam {}", short(law, form)),
        published: "",
        published_ms: None,
        group: format!("beam H8, {}", law.display_name()),
        fbar: form == Formulation::Fbar,
        load: 1.0,
        reference: false,
        problem: p,
    })
}

/// The liver phantom's material: Young's modulus (Pa) and Poisson's ratio.
const LIVER_MATERIAL: (f64, f64) = (5000.0, 0.48);
/// The traction (Pa) pressing one lobe of the liver phantom down.
const LIVER_TRACTION: f64 = 800.0;

/// The load factor under which the standard element deforms the 5k-tet phantom as far as
/// F-bar does under the nominal load (SVK: max |u| 15.9 against 15.8 mm), so that the two
/// formulations are also compared on equally nonlinear solves.
const EQUAL_DEFORMATION_LOAD: f64 = 1.2;

/// The built-in phantom (the liver-forces experiment's organ), fixed between the lobes, pressed down on one
/// lobe by `load` × [`LIVER_TRACTION`], on elements of `order` 1 (T4) or 2 (T10). Only the ~5k-tet T4
/// phantom has published times (the published liver's size).
fn liver(tets: usize, order: u8, law: Law, formulation: Formulation, load: f64) -> Result<Case> {
    let m = mesh::phantom::liver_phantom(tets)?;
    let material =
        Material::new(law, LIVER_MATERIAL.0, LIVER_MATERIAL.1).with_formulation(formulation).with_order(order);
    let mut p = Problem::new(m, material);
    let fixed = p.mesh.region("fixed")?.to_vec();
    let push = p.mesh.region("push")?.to_vec();
    p.fix(&fixed);
    p.add_traction(&push, [0.0, 0.0, -LIVER_TRACTION * load]);
    let form = material.resolved_formulation();
    let cells = p.mesh.cells.len();
    let (published, published_ms) = match (tets, order, law, load == 1.0) {
        (5000, 1, Law::Svk, true) => ("1,550 ms (SVK, ~5k T4)", Some(1550.0)),
        (5000, 1, Law::Corotational, true) => ("25 ms (co-rotational, ~5k T4)", Some(25.0)),
        _ => ("", None),
    };
    let scaled = if load == 1.0 { String::new() } else { format!(", load ×{load}") };
    let thousands = (cells as f64 / 1000.0).round();
    let (kind, quadratic) = (p.mesh.cells.kind_name(), if order == 2 { " T10" } else { "" });
    Ok(Case {
        name: format!("liver {cells} {kind}, {}, {}{scaled}", law.display_name(), form.display_name()),
        label: format!("{thousands}k{quadratic} {}{}", short(law, form), scaled.replace(", load ", " ")),
        published,
        published_ms,
        group: format!("{thousands}k liver{quadratic}, {}", law.display_name()),
        fbar: form == Formulation::Fbar,
        load,
        reference: (tets, order, law, form, load) == REFERENCE,
        problem: p,
    })
}

/// A case being timed: its runs, the setup and first-solve times of its new solvers, the
/// last solver built and its repeated solves from rest.
struct Timed {
    case: Case,
    runs: usize,
    solver: StaticSolver,
    setups: Vec<f64>,
    firsts: Vec<f64>,
    rows: Vec<fem::Solution>,
}

/// A new solver for `problem`, its setup time and the time of its first solve (ms).
fn new_solver(problem: &Problem, opts: &SolverOptions) -> Result<(StaticSolver, f64, f64)> {
    let problem = problem.clone();
    let clock = std::time::Instant::now();
    let mut solver = StaticSolver::new(problem)?;
    let setup = mesh::stats::ms(clock.elapsed());
    let first = mesh::stats::ms(solver.solve(opts)?.timings.total);
    Ok((solver, setup, first))
}

/// How much the load factor of a frame moves from the last frame's (the load swings between
/// 1 ± 5 steps).
pub const FRAME_LOAD_STEP: f64 = 0.02;

/// Median time (ms) and mean Newton iterations of `runs` frames whose load factor moves by
/// [`FRAME_LOAD_STEP`] per frame between 0.9 and 1.1, each warm-started from the last.
fn frames(solver: &mut StaticSolver, opts: &SolverOptions, u_full: &[f64], runs: usize) -> Result<(f64, f64)> {
    let base = solver.problem().f_ext.clone();
    let mut u = u_full.to_vec();
    let (mut times, mut iterations) = (Vec::new(), 0);
    for k in 0..runs {
        // From the solved load 1 (phase 5) on, a step of FRAME_LOAD_STEP each frame, the first frame's too.
        let phase = ((k + 6) % 20) as f64;
        let factor = 1.0 + FRAME_LOAD_STEP * if phase < 10.0 { phase - 5.0 } else { 15.0 - phase };
        solver.problem_mut().f_ext.iter_mut().zip(&base).for_each(|(f, b)| *f = factor * b);
        let s = solver.solve_from(Some(&u), opts)?;
        times.push(mesh::stats::ms(s.timings.total));
        iterations += s.iterations;
        u = s.u;
    }
    solver.problem_mut().f_ext = base;
    Ok((median(&mut times), iterations as f64 / runs as f64))
}

/// Times every case `runs` times (those above [`LARGE_DOFS`] at most [`LARGE_RUNS`] times): as
/// many new solvers (setup and first solve), then as many repeated solves from rest and
/// frames; calls `each` with each case's timing once all are done. The cases take turns,
/// so that a burst of load from elsewhere on the machine falls on all of them alike and
/// their ratios stay meaningful.
pub fn measure(runs: usize, large: bool, each: &mut dyn FnMut(&CaseTiming)) -> Result<Vec<CaseTiming>> {
    let runs = runs.max(1);
    let mut cases = vec![
        beam(Law::Svk, Formulation::Standard)?,
        beam(Law::Svk, Formulation::Fbar)?,
        beam(Law::Corotational, Formulation::Standard)?,
        liver(5000, 1, Law::Svk, Formulation::Standard, 1.0)?,
        liver(5000, 1, Law::Svk, Formulation::Fbar, 1.0)?,
        liver(5000, 1, Law::Svk, Formulation::Standard, EQUAL_DEFORMATION_LOAD)?,
        liver(5000, 1, Law::Corotational, Formulation::Standard, 1.0)?,
        liver(5000, 1, Law::Corotational, Formulation::Fbar, 1.0)?,
        liver(5000, 2, Law::Svk, Formulation::Standard, 1.0)?,
        liver(5000, 2, Law::Corotational, Formulation::Standard, 1.0)?,
    ];
    if large {
        cases.push(liver(50000, 1, Law::Svk, Formulation::Fbar, 1.0)?);
    }
    let opts = SolverOptions::default();
    let runs_of = |case: &Case| if case.problem.num_dofs() > LARGE_DOFS { runs.min(LARGE_RUNS) } else { runs };
    // New solvers (setup and first solve), then repeated solves from rest on the last one; the
    // cases take turns in both.
    let mut timed = Vec::new();
    for case in cases {
        let (solver, setup, first) = new_solver(&case.problem, &opts)?;
        let runs = runs_of(&case);
        timed.push(Timed { case, runs, solver, setups: vec![setup], firsts: vec![first], rows: Vec::new() });
    }
    for k in 1..runs {
        for t in timed.iter_mut().filter(|t| k < t.runs) {
            let (solver, setup, first) = new_solver(&t.case.problem, &opts)?;
            t.solver = solver;
            t.setups.push(setup);
            t.firsts.push(first);
        }
    }
    for k in 0..runs {
        for t in timed.iter_mut().filter(|t| k < t.runs) {
            t.rows.push(t.solver.solve(&opts)?);
        }
    }
    let mut out = Vec::new();
    for Timed {
        case: Case { name, label, published, published_ms, group, fbar, load, reference, problem },
        runs,
        mut solver,
        mut setups,
        mut firsts,
        rows,
    } in timed
    {
        let dofs = problem.num_dofs();
        let med = |f: &dyn Fn(&fem::Solution) -> std::time::Duration| {
            median(&mut rows.iter().map(|s| mesh::stats::ms(f(s))).collect::<Vec<_>>())
        };
        let last = rows.last().expect("at least one run");
        let (frame_ms, frame_iterations) = frames(&mut solver, &opts, &last.u, runs)?;
        let timing = CaseTiming {
            name,
            label,
            published: published.into(),
            published_ms,
            group,
            fbar,
            load,
            reference,
            dofs,
            runs,
            iterations: last.iterations,
            factorizations: last.factorizations,
            assemblies: last.tangent_assemblies,
            setup_ms: median(&mut setups),
            first_ms: median(&mut firsts),
            median_ms: med(&|s| s.timings.total),
            assembly_ms: med(&|s| s.timings.assembly),
            factorization_ms: med(&|s| s.timings.factorization),
            solve_ms: med(&|s| s.timings.solve),
            max_displacement: fem::post::max_displacement(&last.u),
            frame_ms,
            frame_iterations,
        };
        each(&timing);
        out.push(timing);
    }
    Ok(out)
}

/// How many times the cases were timed, as they were: "5 runs", or "5 runs, 3 for the cases
/// above 20000 dofs".
fn runs_text(cases: &[CaseTiming]) -> String {
    let most = cases.iter().map(|c| c.runs).max().unwrap_or(0);
    let fewest = cases.iter().map(|c| c.runs).min().unwrap_or(0);
    match most == fewest {
        true => format!("{most} runs"),
        false => format!("{most} runs, {fewest} for the cases above {LARGE_DOFS} dofs"),
    }
}

/// `timings.csv`: a line per case, with its counts and times.
fn write_timings(path: &Path, cases: &[CaseTiming]) -> Result<()> {
    let header = [
        "case",
        "dofs",
        "iterations",
        "factorizations",
        "assemblies",
        "setup_ms",
        "first_ms",
        "median_ms",
        "assembly_ms",
        "factorization_ms",
        "solve_ms",
        "max_u_m",
        "frame_ms",
        "frame_iterations",
    ];
    let timings = cases.iter().map(|c| {
        let counts = [c.dofs, c.iterations, c.factorizations, c.assemblies].map(|n| n.to_string());
        let times = [c.setup_ms, c.first_ms, c.median_ms, c.assembly_ms, c.factorization_ms, c.solve_ms];
        let tail = [c.max_displacement.to_string(), c.frame_ms.to_string(), c.frame_iterations.to_string()];
        std::iter::once(c.name.clone())
            .chain(counts)
            .chain(times.map(|t| t.to_string()))
            .chain(tail)
            .collect::<Vec<_>>()
    });
    mesh::io::csv::write_csv(path, &[], &header, timings)?;
    Ok(())
}

/// The experiment: quick = 5 runs of the 5k-tet cases; paper = 20 runs plus the 50k-tet phantom.
pub(crate) fn run(size: Size, dir: &Path, progress: Progress) -> Result<ExperimentResult> {
    let (runs, large) = match size {
        Size::Quick => (5, false),
        Size::Paper => (20, true),
    };
    let cases = measure(runs, large, &mut |c| {
        progress.line(&format!(
            "{}: first {:.1} ms, median {:.1} ms, frame {:.1} ms",
            c.name, c.first_ms, c.median_ms, c.frame_ms
        ))
    })?;
    // One line per case (the published time beside its first solve), then F-bar over the standard element.
    let reference = reference_ms(&cases);
    let rows = cases
        .iter()
        .flat_map(|c| {
            [
                Row::new("setup", reference::ms(c.setup_ms, 1, reference), ""),
                Row::new("first", reference::ms(c.first_ms, 1, reference), &c.published),
                Row::new("from rest", reference::ms(c.median_ms, 1, reference), ""),
                Row::new("frame", reference::ms(c.frame_ms, 1, reference), ""),
            ]
            .map(|row| row.of("case", &c.name))
        })
        .chain(fbar_ratios(&cases).iter().flat_map(|r| {
            [("first", r.first), ("from rest", r.from_rest), ("frame", r.frame)]
                .map(|(quantity, ratio)| Row::new(quantity, format!("{ratio:.2}×"), "").of("F-bar / standard", &r.pair))
        }))
        .collect();
    write_timings(&dir.join("timings.csv"), &cases)?;
    let categories: Vec<String> = cases.iter().map(|c| c.label.clone()).collect();
    let series = |name: &str, f: fn(&CaseTiming) -> f64| plot::BarSeries {
        name: name.into(),
        values: cases.iter().map(|c| Some(f(c))).collect(),
    };
    plot::bar_chart(
        &dir.join("timings.png"),
        &plot::PlotSpec {
            title: format!("Static solves ({}; medians)", runs_text(&cases)),
            x_label: String::new(),
            y_label: "ms".into(),
            log_y: true,
        },
        &categories,
        &[series("first solve", |c| c.first_ms), series("from rest", |c| c.median_ms), series("frame", |c| c.frame_ms)],
    )?;
    // A whole solve from nothing (setup and first solve) against the published solve time.
    // Quadratic tetrahedra have no published time: their whole solve and frame, measured.
    let headlines = cases
        .iter()
        .filter_map(|c| {
            let figure = format!("static solve, {}: setup + first solve", c.name);
            match c.published_ms {
                Some(published) => {
                    let whole = c.setup_ms + c.first_ms;
                    let headline = Headline::lower_is_better(figure, whole, published, 0, "ms");
                    Some(Headline { ours: reference::ms(whole, 0, reference), ..headline })
                }
                None if c.group.contains("T10") => Some(Headline::measured(
                    format!("{figure}; a frame"),
                    format!(
                        "{}; {}",
                        reference::ms(c.setup_ms + c.first_ms, 0, reference),
                        reference::ms(c.frame_ms, 0, reference)
                    ),
                )),
                None => None,
            }
        })
        .collect();
    let mut values = serde_json::Map::new();
    values.insert("cases".into(), serde_json::to_value(&cases)?);
    Ok(ExperimentResult {
        headlines,
        name: Name::FemSpeed,
        size,
        seconds: 0.0,
        build: String::new(),
        rows,
        figures: vec!["timings.png".into()],
        page_figures: Vec::new(),
        notes: vec![
            format!("Each case timed on this machine ({}), medians; 'setup': building a solver (sparse pattern, ordering, symbolic analysis, buffers) and 'first': its first solve from rest, medians over as many new solvers; 'from rest': repeated solves with the rest tangent's factor kept, the cases taking turns; 'frame': one frame of a load varying by {:.0} % per frame, warm-started. {}", runs_text(&cases), 100.0 * FRAME_LOAD_STEP, reference::note(reference)),
            format!(
                "Liver: the built-in phantom, E = {} Pa, ν = {}, {} Pa on one lobe. The published times are for a \
                 ~5k-tet liver on the authors' machine.",
                LIVER_MATERIAL.0, LIVER_MATERIAL.1, LIVER_TRACTION
            ),
            format!(
                "Beam: {} × {} × {} H8, E = {} Pa, ν = {}, pulled down at its free end. H8 F-bar averages J over \
                 each element (one element per patch), so its tangent has the standard element's pattern; T4 F-bar \
                 averages over patches of about {} tetrahedra, which couples their nodes and fills the factor more.",
                BEAM_CELLS[0],
                BEAM_CELLS[1],
                BEAM_CELLS[2],
                BEAM_MATERIAL.0,
                BEAM_MATERIAL.1,
                fem::patch::TET_PATCH_SIZE
            ),
            format!(
                "'load ×{EQUAL_DEFORMATION_LOAD}': the standard element under {EQUAL_DEFORMATION_LOAD} times the load, \
                 which deforms it as far as F-bar under the nominal load (max |u| in timings.csv): the two \
                 formulations compared on equally nonlinear solves."
            ),
        ],
        values,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// F-bar is compared within its group only, at equal load and against each scaled
    /// standard case; F-bar cases under other loads are not compared.
    #[test]
    fn fbar_ratios_pair_cases_within_a_group() {
        let case = |group: &str, fbar: bool, load: f64, ms: f64| CaseTiming {
            name: format!("{group} {fbar} {load}"),
            label: String::new(),
            published: String::new(),
            published_ms: None,
            group: group.into(),
            fbar,
            load,
            reference: false,
            dofs: 1,
            runs: 1,
            iterations: 1,
            factorizations: 1,
            assemblies: 1,
            setup_ms: 1.0,
            first_ms: 2.0 * ms,
            median_ms: ms,
            assembly_ms: 0.0,
            factorization_ms: 0.0,
            solve_ms: 0.0,
            max_displacement: 0.0,
            frame_ms: ms / 4.0,
            frame_iterations: 1.0,
        };
        let cases = [
            case("liver", false, 1.0, 10.0),
            case("liver", true, 1.0, 15.0),
            case("liver", false, 1.2, 12.0),
            case("liver", true, 1.2, 99.0),
            case("beam", false, 1.0, 8.0),
            case("beam", true, 1.0, 10.0),
        ];
        let ratios = fbar_ratios(&cases);
        let pairs: Vec<&str> = ratios.iter().map(|r| r.pair.as_str()).collect();
        assert_eq!(pairs, ["liver, equal load", "liver, equal deformation (standard under ×1.2)", "beam, equal load"]);
        let expected = [1.5, 1.25, 1.25];
        for (r, e) in ratios.iter().zip(expected) {
            assert!((r.from_rest - e).abs() < 1e-12 && (r.first - e).abs() < 1e-12 && (r.frame - e).abs() < 1e-12);
        }
    }

    /// Of the liver cases, only the co-rotational standard T4 one under the nominal load is the
    /// reference.
    #[test]
    fn one_liver_case_is_the_reference() {
        let cases = [
            (1, Law::Corotational, Formulation::Standard, 1.0),
            (1, Law::Corotational, Formulation::Fbar, 1.0),
            (1, Law::Svk, Formulation::Standard, 1.0),
            (1, Law::Corotational, Formulation::Standard, EQUAL_DEFORMATION_LOAD),
            (2, Law::Corotational, Formulation::Standard, 1.0),
        ];
        let flags = cases.map(|(order, law, form, load)| liver(5000, order, law, form, load).unwrap().reference);
        assert_eq!(flags, [true, false, false, false, false]);
    }

    /// The equal-deformation case must deform the standard element as far as F-bar (within
    /// 2 %), or its comparison means nothing.
    #[test]
    fn the_scaled_standard_case_deforms_as_far_as_fbar() {
        let max_u = |formulation, load| {
            let Case { problem, .. } = liver(5000, 1, Law::Svk, formulation, load).unwrap();
            let u = StaticSolver::new(problem).unwrap().solve(&SolverOptions::default()).unwrap().u;
            fem::post::max_displacement(&u)
        };
        let (fbar, standard, scaled) = (
            max_u(Formulation::Fbar, 1.0),
            max_u(Formulation::Standard, 1.0),
            max_u(Formulation::Standard, EQUAL_DEFORMATION_LOAD),
        );
        assert!(standard < 0.9 * fbar, "the standard element locks less than expected: {standard} against {fbar} m");
        assert!((scaled / fbar - 1.0).abs() < 0.02, "{scaled} against {fbar} m");
    }
}
