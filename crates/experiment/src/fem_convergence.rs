//! Convergence of the finite elements under mesh refinement: the error against a reference
//! versus degrees of freedom and versus solve time, for the linear tetrahedron (standard and
//! F-bar), the quadratic tetrahedron (standard and stabilised F-bar on the element's volume) and the F-bar
//! hexahedron, on a cantilever (ν = 0.3, 0.49, 0.499) and on the liver phantom.

use std::path::Path;
use std::time::Instant;

use anyhow::{Context, Result};
use fem::{verification, Formulation, Law, Material, Problem, SolverOptions, StaticSolver};
use mesh::{CellKind, Mesh, MeshLocator, PhantomSpec, Point};
use serde::{Deserialize, Serialize};

use crate::{reference, ExperimentResult, Name, Progress, Row, Size};

/// An element: its cells and formulation.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Element {
    kind: CellKind,
    formulation: Formulation,
}

impl Element {
    fn label(self) -> String {
        let form = if self.formulation == Formulation::Fbar { " F-bar" } else { "" };
        format!("{}{form}", self.kind.name())
    }
}

/// The elements compared.
const ELEMENTS: [Element; 5] = [
    Element { kind: CellKind::Tet4, formulation: Formulation::Standard },
    Element { kind: CellKind::Tet4, formulation: Formulation::Fbar },
    Element { kind: CellKind::Tet10, formulation: Formulation::Standard },
    Element { kind: CellKind::Tet10, formulation: Formulation::Fbar },
    Element { kind: CellKind::Hex8, formulation: Formulation::Fbar },
];

/// One solve of a convergence study.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ConvergencePoint {
    /// The problem (e.g. "cantilever, ν = 0.49").
    pub problem: String,
    /// The element (e.g. "T10 F-bar").
    pub element: String,
    /// The mesh (cells or target tetrahedra).
    pub mesh: String,
    /// Degrees of freedom (3 per node).
    pub dofs: usize,
    /// A new solver's setup and first solve (ms).
    pub ms: f64,
    /// The measured quantity (m): the tip deflection, or the RMS displacement at the probes.
    pub value: f64,
    /// Relative error against the problem's reference.
    pub error: f64,
    /// Whether the solve is not independent of the reference ([`shares_reference`]): its error
    /// is then no measure of its own, and it is no candidate for the cheapest element.
    #[serde(default)]
    pub in_reference: bool,
}

/// A problem's reference value and how it was obtained.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Reference {
    /// The problem.
    pub problem: String,
    /// The reference quantity (m).
    pub value: f64,
    /// How it was obtained.
    pub source: String,
}

/// The cheapest element (least time) within a tolerance on a problem.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Cheapest {
    /// The problem.
    pub problem: String,
    /// The relative tolerance.
    pub tolerance: f64,
    /// The element and mesh, or `None` when no solve reached it.
    pub choice: Option<ConvergencePoint>,
    /// The other solves within the tolerance that took at most [`TIE`] times the choice's time:
    /// as cheap within the timing's noise.
    #[serde(default)]
    pub ties: Vec<ConvergencePoint>,
}

/// How much longer than the cheapest solve another may take and still be told as cheap (a time
/// of a few milliseconds varies by more than a tenth from run to run).
const TIE: f64 = 1.25;

/// A solve faster than this (ms) is timed [`TIMED_RUNS`] times: the cheapest element is told
/// apart by a few milliseconds.
const SHORT_SOLVE_MS: f64 = 200.0;

/// How many times a short solve is timed (the median is kept).
const TIMED_RUNS: usize = 5;

/// Solves `problem` with a new solver, timing setup and solve: the median of [`TIMED_RUNS`] runs
/// for a solve under [`SHORT_SOLVE_MS`], one run otherwise.
fn timed_solve(problem: Problem) -> Result<(Vec<f64>, f64)> {
    let options = SolverOptions { rtol: 1e-10, ..Default::default() };
    let run = |problem: Problem| -> Result<(Vec<f64>, f64)> {
        let start = Instant::now();
        let u = StaticSolver::new(problem)?.solve(&options)?.u;
        Ok((u, mesh::stats::ms(start.elapsed())))
    };
    let (u, first) = run(problem.clone())?;
    if first >= SHORT_SOLVE_MS {
        return Ok((u, first));
    }
    let mut times = vec![first];
    for _ in 1..TIMED_RUNS {
        times.push(run(problem.clone())?.1);
    }
    Ok((u, mesh::stats::median(&mut times)))
}

/// The verification cantilever ([`fem::verification::cantilever`], linear law) of `cells`: the
/// mean tip deflection (m), dofs and ms.
fn cantilever(element: Element, cells: [usize; 3], poisson: f64) -> Result<(f64, usize, f64)> {
    let (problem, tip) = verification::cantilever(element.kind, cells, Law::Linear, element.formulation, poisson)?;
    let dofs = problem.num_dofs();
    let (u, ms) = timed_solve(problem)?;
    Ok((verification::tip_deflection(&u, &tip), dofs, ms))
}

/// Richardson extrapolation of three values on meshes of sizes `h` (coarse to fine): the order p
/// solves (v₃ − v₂)/(v₂ − v₁) = (h₂ᵖ − h₃ᵖ)/(h₁ᵖ − h₂ᵖ) (clamped to at most 4), and the limit is
/// v₃ + c (v₃ − v₂) with c = h₃ᵖ / (h₂ᵖ − h₃ᵖ). `None` when the values do not converge
/// monotonically at an order of at least 1 (the meshes are not in the asymptotic range). Returns
/// (p, c).
fn richardson(values: [f64; 3], h: [f64; 3]) -> Option<(f64, f64)> {
    let (d1, d2) = (values[1] - values[0], values[2] - values[1]);
    let ratio = |p: f64| (h[1].powf(p) - h[2].powf(p)) / (h[0].powf(p) - h[1].powf(p));
    let target = d2 / d1;
    if !(d1 * d2 > 0.0) || target > ratio(1.0) {
        return None;
    }
    // The ratio falls as p grows: bisection on [1, 4].
    let (mut lo, mut hi) = (1.0, 4.0);
    if target < ratio(hi) {
        lo = hi;
    }
    while hi - lo > 1e-12 {
        let mid = 0.5 * (lo + hi);
        if ratio(mid) > target {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    Some((lo, h[2].powf(lo) / (h[1].powf(lo) - h[2].powf(lo))))
}

/// The phantom's probes: points of a regular grid at least 5 mm inside the organ and inside
/// every mesh of `meshes`.
fn probes(spec: &PhantomSpec, meshes: &[Mesh]) -> Result<Vec<Point>> {
    let locators = meshes.iter().map(MeshLocator::new).collect::<Result<Vec<_>, _>>()?;
    let (lo, hi) = meshes[0].bounds();
    let n = 12;
    let mut out = Vec::new();
    for i in 0..n {
        for j in 0..n {
            for k in 0..n {
                let t = [i, j, k].map(|c| (c as f64 + 0.5) / n as f64);
                let p: Point = std::array::from_fn(|d| lo[d] + t[d] * (hi[d] - lo[d]));
                if spec.signed_distance(p) < -0.005 && locators.iter().all(|l| l.locate(p).is_some()) {
                    out.push(p);
                }
            }
        }
    }
    Ok(out)
}

/// Stiffness of the phantom's attachment per volume, in units of E / r² (r: the `fixed` ball's
/// radius): a ligament-like foundation, stiff against the tissue over the ball's size.
const ATTACHMENT: f64 = 100.0;

/// The phantom (SVK, E = 5 kPa, ν = 0.48) held by an elastic foundation over its `fixed` ball,
/// 0.3 N down spread over the visible boundary inside its `push` ball: the same problem on every
/// mesh (regions of space, not node sets). The displacement at `probes` (m, 3 each), dofs and ms.
fn phantom(element: Element, m: Mesh, probes: &[Point]) -> Result<(Vec<Point>, usize, f64)> {
    let young = 5000.0;
    let material = Material::new(Law::Svk, young, 0.48)
        .with_formulation(element.formulation)
        .with_order(if element.kind == CellKind::Tet10 { 2 } else { 1 });
    let mut problem = Problem::new(m, material);
    let spec = PhantomSpec::default();
    let fixed = spec.region_ball("fixed")?;
    problem.add_foundation(&fixed, ATTACHMENT * young / fixed.radius.powi(2))?;
    problem.add_patch_force(&spec.region_ball("push")?, Some(spec.view_direction), [0.0, 0.0, -0.3])?;
    let dofs = problem.num_dofs();
    let mesh = problem.mesh.clone();
    let (u, ms) = timed_solve(problem)?;
    let locator = MeshLocator::new(&mesh)?;
    let at = probes
        .iter()
        .map(|&p| {
            let loc = locator.locate(p).with_context(|| format!("probe {p:?} outside the phantom"))?;
            Ok(std::array::from_fn(|d| loc.terms().map(|(n, w)| w * u[3 * n + d]).sum()))
        })
        .collect::<Result<Vec<Point>>>()?;
    Ok((at, dofs, ms))
}

fn rms(v: &[Point]) -> f64 {
    (v.iter().map(|p| mesh::dot(*p, *p)).sum::<f64>() / v.len().max(1) as f64).sqrt()
}

/// Runs the study (see the module documentation) and writes its plots into `dir`.
pub fn run(size: Size, dir: &Path, progress: Progress) -> Result<ExperimentResult> {
    let levels: &[usize] = match size {
        Size::Quick => &[1, 2, 3],
        Size::Paper => &[1, 2, 3, 4],
    };
    let sizes: &[usize] = match size {
        Size::Quick => &[3000, 5000, 11000],
        Size::Paper => &[3000, 5000, 11000, 20000],
    };
    let reference_ms = reference::measure()?;
    let mut points = Vec::new();
    let mut references = Vec::new();
    for poisson in [0.3, 0.49, 0.499] {
        references.push(cantilever_study(poisson, levels, progress, &mut points)?);
    }
    // The phantom: the probes lie inside every mesh; the reference is the Richardson extrapolation
    // of T10 at each probe, with h ∝ (cells)^(-1/3) (the meshes are not nested), or the finest T10.
    references.push(phantom_study(sizes, progress, &mut points)?);
    let problems: Vec<String> = references.iter().map(|r| r.problem.clone()).collect();
    let cheapest = cheapest(&problems, &points);
    let figures = plot_studies(dir, &problems, &points)?;
    let rows = rows(&cheapest, &points, reference_ms);
    let notes = vec![
        "Cantilever 10 × 1 × 1 m, E = 1 kPa, linear law (B-bar for F-bar), clamped at x = 0, a small downward end \
         traction; quantity: mean tip deflection; meshes of 10k × k × k cells (H8, or 6 T4 / T10 per cell)."
            .to_string(),
        format!(
            "Phantom: SVK, E = 5 kPa, ν = 0.48, held by an elastic foundation of {ATTACHMENT} E / r² over its `fixed` \
             ball (radius r), 0.3 N downward as a uniform traction on the visible boundary inside its `push` ball: \
             regions of space, integrated exactly, so every mesh solves the same problem (the meshes are not nested); \
             quantity: the displacement at the probes (relative RMS error against the reference)."
        ),
        format!(
            "Times: a new solver's setup and first solve (ms), on this machine: the median of {TIMED_RUNS} runs for a \
             solve under {SHORT_SOLVE_MS} ms, one run otherwise; a solve within {:.0} % of the cheapest one's time \
             is named beside it. {}",
            100.0 * (TIE - 1.0),
            reference::note(Some(reference_ms))
        ),
        "Solves not independent of a reference are marked, and are no candidates for the cheapest element: the \
         three finest T10 solves its Richardson extrapolation is made of, or, where those do not converge at an \
         order of at least 1 and the finest T10 is the reference, every solve on that finest mesh (they share its \
         geometry)."
            .to_string(),
    ];
    let mut values = serde_json::Map::new();
    values.insert("points".into(), serde_json::to_value(&points)?);
    values.insert("references".into(), serde_json::to_value(&references)?);
    values.insert("cheapest".into(), serde_json::to_value(&cheapest)?);
    values.insert("reference_ms".into(), reference_ms.into());
    Ok(ExperimentResult {
        name: Name::FemConvergence,
        size,
        seconds: 0.0,
        build: String::new(),
        headlines: Vec::new(),
        rows,
        figures,
        page_figures: vec!["cantilever_049.png".into(), "phantom.png".into()],
        notes: notes
            .into_iter()
            .chain(references.iter().map(|r| format!("Reference, {}: {:.5e} m, {}", r.problem, r.value, r.source)))
            .collect(),
        values,
    })
}

/// The cantilever of Poisson's ratio `poisson` on every element and refinement of `levels`: its
/// solves pushed on `points`, and its reference (the Richardson extrapolation of T10, or its
/// finest mesh).
fn cantilever_study(
    poisson: f64,
    levels: &[usize],
    progress: Progress,
    points: &mut Vec<ConvergencePoint>,
) -> Result<Reference> {
    let problem = format!("cantilever, ν = {poisson}");
    let mut solved = Vec::new();
    for element in ELEMENTS {
        for &k in levels {
            let cells = [10 * k, k, k];
            progress.line(&format!("fem-convergence: {problem}, {} on {}x{}x{}", element.label(), cells[0], k, k));
            let (value, dofs, ms) = cantilever(element, cells, poisson)?;
            solved.push((element, format!("{}x{}x{}", cells[0], k, k), value, dofs, ms));
        }
    }
    let t10: Vec<f64> = solved.iter().filter(|s| s.0 == ELEMENTS[2]).map(|s| s.2).collect();
    let n = t10.len();
    let h = [n - 3, n - 2, n - 1].map(|i| 1.0 / levels[i] as f64);
    let last = [t10[n - 3], t10[n - 2], t10[n - 1]];
    let (value, source, extrapolated) = match richardson(last, h) {
        Some((p, c)) => {
            (last[2] + c * (last[2] - last[1]), format!("Richardson extrapolation of T10, order {p:.2}"), true)
        }
        None => (last[2], "finest T10 mesh (no monotone convergence of order ≥ 1: no extrapolation)".into(), false),
    };
    let source = format!(
        "{source}; Timoshenko beam theory {:.4e} m ({:+.2} %)",
        verification::timoshenko_deflection(poisson),
        100.0 * (verification::timoshenko_deflection(poisson) / value - 1.0)
    );
    points.extend(solved.into_iter().enumerate().map(|(i, (e, mesh, v, dofs, ms))| ConvergencePoint {
        problem: problem.clone(),
        element: e.label(),
        mesh,
        dofs,
        ms,
        value: v,
        error: (v / value - 1.0).abs(),
        in_reference: shares_reference(e, i % levels.len(), n, extrapolated),
    }));
    Ok(Reference { problem, value, source })
}

/// The phantom on every tetrahedral element and mesh of `sizes` tetrahedra: its solves pushed on
/// `points`, and its reference (the RMS displacement at the probes of the Richardson
/// extrapolation of T10 at each probe, or of the finest T10).
fn phantom_study(sizes: &[usize], progress: Progress, points: &mut Vec<ConvergencePoint>) -> Result<Reference> {
    let meshes = sizes.iter().map(|&t| mesh::liver_phantom(t)).collect::<Result<Vec<_>, _>>()?;
    let probe_points = probes(&PhantomSpec::default(), &meshes)?;
    let problem = "liver phantom, SVK, ν = 0.48".to_string();
    let mut solved = Vec::new();
    for element in ELEMENTS.into_iter().filter(|e| e.kind != CellKind::Hex8) {
        for (level, (&tets, m)) in sizes.iter().zip(&meshes).enumerate() {
            progress.line(&format!("fem-convergence: phantom, {} on {tets} tetrahedra", element.label()));
            let (at, dofs, ms) = phantom(element, m.clone(), &probe_points)?;
            solved.push((element, level, at, dofs, ms));
        }
    }
    let n = sizes.len();
    let t10: Vec<&Vec<Point>> = solved.iter().filter(|s| s.0 == ELEMENTS[2]).map(|s| &s.2).collect();
    let h = [n - 3, n - 2, n - 1].map(|i| (meshes[i].cells.len() as f64).powf(-1.0 / 3.0));
    let (reference, extrapolated, how) = match richardson([n - 3, n - 2, n - 1].map(|i| rms(t10[i])), h) {
        Some((p, c)) => {
            let field = t10[n - 1].iter().zip(t10[n - 2]).map(|(f, m)| std::array::from_fn(|d| f[d] + c * (f[d] - m[d])));
            let meshes = format!("{}, {} and {} tetrahedra", sizes[n - 3], sizes[n - 2], sizes[n - 1]);
            (field.collect::<Vec<Point>>(), true, format!("Richardson extrapolation of T10 on {meshes} (h ∝ cells^-1/3), order {p:.2}, at each probe"))
        }
        None => (t10[n - 1].clone(), false, format!("T10 on the finest phantom ({} tetrahedra; no monotone convergence of order ≥ 1 on the three finest: no extrapolation)", sizes[n - 1])),
    };
    let scale = rms(&reference);
    let source = format!("{how}; RMS displacement at {} probes 5 mm or more inside", probe_points.len());
    for (e, level, at, dofs, ms) in solved {
        let diff: Vec<Point> = at.iter().zip(&reference).map(|(a, r)| mesh::sub(*a, *r)).collect();
        points.push(ConvergencePoint {
            problem: problem.clone(),
            element: e.label(),
            mesh: format!("{} tets", sizes[level]),
            dofs,
            ms,
            value: rms(&at),
            error: rms(&diff) / scale,
            in_reference: shares_reference(e, level, n, extrapolated),
        });
    }
    Ok(Reference { problem, value: scale, source })
}

/// Whether a solve of `element` on the mesh of refinement `level` (0-based, coarse to fine, of
/// `n`) is not independent of its problem's reference: a T10 solve that entered the Richardson
/// extrapolation (the three finest), or, where the reference is the finest T10 alone
/// (`extrapolated` false), any solve on that finest mesh (the same geometry: its error would
/// count only the element's difference on it).
fn shares_reference(element: Element, level: usize, n: usize, extrapolated: bool) -> bool {
    if extrapolated {
        element == ELEMENTS[2] && level + 3 >= n
    } else {
        level + 1 == n
    }
}

/// The cheapest solve (not sharing the reference) within 1 % and within 5 % on each problem.
fn cheapest(problems: &[String], points: &[ConvergencePoint]) -> Vec<Cheapest> {
    let mut cheapest = Vec::new();
    for p in problems {
        for tolerance in [0.01, 0.05] {
            let within: Vec<&ConvergencePoint> =
                points.iter().filter(|c| &c.problem == p && c.error <= tolerance && !c.in_reference).collect();
            let choice = within.iter().min_by(|a, b| a.ms.total_cmp(&b.ms)).map(|&c| c.clone());
            let ties = match &choice {
                Some(best) => within.into_iter().filter(|c| *c != best && c.ms <= TIE * best.ms).cloned().collect(),
                None => Vec::new(),
            };
            cheapest.push(Cheapest { problem: p.clone(), tolerance, choice, ties });
        }
    }
    cheapest
}

/// The error plots of the cantilever at ν = 0.49 and of the phantom, against the dofs and against
/// the time; returns their file names.
fn plot_studies(dir: &Path, problems: &[String], points: &[ConvergencePoint]) -> Result<Vec<String>> {
    let mut figures = Vec::new();
    for (file, p) in [("cantilever_049.png", &problems[1]), ("phantom.png", &problems[3])] {
        for (suffix, x_label, x) in [
            (
                "",
                "degrees of freedom (log10)",
                (|c: &ConvergencePoint| (c.dofs as f64).log10()) as fn(&ConvergencePoint) -> f64,
            ),
            ("_time", "setup and solve time, ms (log10)", |c: &ConvergencePoint| c.ms.log10()),
        ] {
            let name = file.replace(".png", &format!("{suffix}.png"));
            plot_errors(&dir.join(&name), p, x_label, x, points)?;
            figures.push(name);
        }
    }
    Ok(figures)
}

/// The rows: the cheapest solve within each tolerance, and a table of errors per problem; times
/// with their multiple of the run's reference time.
fn rows(cheapest: &[Cheapest], points: &[ConvergencePoint], reference_ms: f64) -> Vec<Row> {
    let ms = |p: &ConvergencePoint| reference::ms(p.ms, 0, Some(reference_ms));
    let mut rows = Vec::new();
    for c in cheapest {
        let solve = |p: &ConvergencePoint| {
            format!("{} ({}, {} dofs, {}, error {:.2} %)", p.element, p.mesh, p.dofs, ms(p), 100.0 * p.error)
        };
        let mut ours = c.choice.as_ref().map_or("none of the meshes".into(), solve);
        if !c.ties.is_empty() {
            let ties: Vec<String> = c.ties.iter().map(solve).collect();
            ours = format!("{ours}; as cheap within {:.0} % of its time: {}", 100.0 * (TIE - 1.0), ties.join(", "));
        }
        rows.push(
            Row::new(format!("cheapest within {:.0} %", 100.0 * c.tolerance), ours, "").of("problem", &c.problem),
        );
    }
    // A table of errors per problem: a line per element, a column per mesh.
    for p in points {
        rows.push(
            Row::new(
                &p.mesh,
                format!(
                    "{:.2} % ({} dofs, {}){}",
                    100.0 * p.error,
                    p.dofs,
                    ms(p),
                    if p.in_reference { ", enters the reference" } else { "" }
                ),
                "",
            )
            .of(format!("{}: error", p.problem), &p.element),
        );
    }
    rows
}

/// The relative error (%) of every element on `problem` against `x` of each solve, one line per element.
fn plot_errors(
    path: &Path,
    problem: &str,
    x_label: &str,
    x: fn(&ConvergencePoint) -> f64,
    points: &[ConvergencePoint],
) -> Result<()> {
    let series: Vec<plot::Series> = ELEMENTS
        .iter()
        .map(|e| e.label())
        .filter_map(|label| {
            let pts: Vec<(f64, f64)> = points
                .iter()
                .filter(|c| c.problem == problem && c.element == label && c.error > 0.0)
                .map(|c| (x(c), 100.0 * c.error))
                .collect();
            (!pts.is_empty()).then_some(plot::Series { name: label, points: pts, band: None })
        })
        .collect();
    let spec = plot::PlotSpec {
        title: format!("Convergence: {problem}"),
        x_label: x_label.into(),
        y_label: "relative error (%)".into(),
        log_y: true,
    };
    plot::line_plot(path, &spec, &series)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::{richardson, shares_reference, ELEMENTS};

    /// Values e(h) = 1 + a hᵖ on unequal mesh sizes: the order and the limit are found; values that
    /// do not converge monotonically, or converge slower than first order, are not extrapolated.
    /// The solves that are no measure of their own: the T10 solves an extrapolation is made of,
    /// or every solve on the mesh of a reference that is that mesh's T10 alone.
    #[test]
    fn solves_sharing_the_reference_are_no_candidates() {
        let (t4, t10, t10_fbar) = (ELEMENTS[0], ELEMENTS[2], ELEMENTS[3]);
        assert!(shares_reference(t10, 2, 5, true) && shares_reference(t10, 4, 5, true));
        assert!(!shares_reference(t10, 1, 5, true) && !shares_reference(t10_fbar, 4, 5, true));
        assert!(shares_reference(t10_fbar, 4, 5, false) && shares_reference(t4, 4, 5, false));
        assert!(!shares_reference(t10, 3, 5, false) && !shares_reference(t10, 2, 5, false));
    }

    #[test]
    fn richardson_recovers_the_limit_and_order_on_unequal_meshes() {
        let h: [f64; 3] = [0.1, 0.06, 0.045];
        let values = |p: f64| h.map(|x| 1.0 + 0.3 * x.powf(p));
        let (p, c) = richardson(values(2.5), h).unwrap();
        let v = values(2.5);
        assert!((p - 2.5).abs() < 1e-9, "order {p}");
        assert!((v[2] + c * (v[2] - v[1]) - 1.0).abs() < 1e-12);
        assert!(richardson(values(0.5), h).is_none(), "order 0.5 extrapolated");
        assert!(richardson([1.0, 1.1, 1.05], h).is_none(), "oscillating values extrapolated");
        assert_eq!(richardson(values(6.0), h).unwrap().0, 4.0);
    }
}
