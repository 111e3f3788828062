//! Step 6 of `prepare`, the validation: held-out pushes of the organ solved on a quadratic truth
//! meshed anew and refined until converged, registered by the learned model, the FEM and the
//! hybrid, from rest and as streams; the set-up keeps the best of them.

use std::path::Path;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use mesh::io::points::read_points_csv;
use mesh::io::write_atomic_bytes;
use mesh::length::mm;
use mesh::tetmesh::{mesh_surface_to_count, BoundaryFit};
use mesh::{Camera, Mesh, Near, Point};

use super::{across_sight, hold_distance, swing_warning, tool_radius, PrepareOptions};
use crate::picture::{frame_notes, RegisteredFrame};
use crate::registration::RegistrationSpec;
use crate::setup::{read_organ_surface, Patient, PatientMethod, SigmaFactors, PATIENT_FILE, SURFACE_FILE};

/// Tool pushes of the validation: where along what the camera sees (its spread across the line of
/// sight, as a fraction) and the force (N).
const VALIDATION_LOADS: [(f64, f64); 4] = [(0.2, 1.5), (0.4, 2.5), (0.6, 2.0), (0.8, 3.0)];

/// The validation's truth: the organ's surface meshed anew with about `tets` tetrahedra made
/// quadratic, Neo-Hookean, held where the organ is attached.
struct Truth {
    mesh: Mesh,
    held: Vec<usize>,
    seen: Vec<usize>,
    stencils: Vec<register::Stencil>,
    /// The targets outside the mesh, which follow its nearest surface point, and how far out they lie.
    outside: Vec<(usize, f64)>,
    material: fem::Material,
}

impl Truth {
    fn new(
        surface: &mesh::TriSurface,
        tets: usize,
        camera: Point,
        landmarks: &[Point],
        targets: &[Point],
        attach: f64,
    ) -> Result<Truth> {
        let (coarse, _) =
            mesh_surface_to_count(surface, tets, BoundaryFit::default()).context("meshing the validation's truth")?;
        let mesh = coarse.quadratic()?;
        let held = Near { points: landmarks.to_vec(), file: None, distance: attach, surface: true }.nodes(&mesh)?;
        let seen = Camera { view: None, position: Some(camera), max_angle_deg: 90.0 }.seen_nodes(&mesh)?;
        if seen.is_empty() {
            bail!("the camera sees no node of the validation's truth, a mesh of the organ's surface made anew");
        }
        // A target near the surface may lie just outside this mesh, whose boundary is not the
        // organ mesh's: within an element's size it follows the nearest surface point.
        let size = (mesh.volume() / mesh.cells.len() as f64).cbrt();
        let located = register::Organ::new(mesh.clone(), None)?.locate_near(targets, size, "target")?;
        let outside = located.iter().enumerate().filter(|(_, (_, d))| *d > 0.0).map(|(i, (_, d))| (i, *d)).collect();
        let stencils = located.into_iter().map(|(s, _)| s).collect();
        let material = fem::Material {
            formulation: fem::Formulation::Standard,
            ..fem::Material::new(fem::Law::NeoHookean, super::ORGAN_YOUNG, super::ORGAN_POISSON).with_order(2)
        };
        Ok(Truth { mesh, held, seen, stencils, outside, material })
    }

    /// The displacement under a push of `force` (N) from `camera` on the seen nodes within
    /// `radius` of `centre`.
    fn push(&self, centre: Point, camera: Point, force: f64, radius: f64) -> Result<Vec<f64>> {
        let patch: Vec<usize> =
            self.seen.iter().copied().filter(|&n| mesh::distance(self.mesh.nodes[n], centre) < radius).collect();
        let mut problem = fem::Problem::new(self.mesh.clone(), self.material);
        problem.fix(&self.held);
        problem.add_force(&patch, mesh::unit(mesh::sub(centre, camera)).map(|x| x * force));
        let solver =
            fem::SolverOptions { load_steps: TRUTH_LOAD_STEPS, max_step_cuts: 6, ..fem::SolverOptions::default() };
        Ok(fem::StaticSolver::new(problem)?.solve(&solver).context("solving the validation's truth")?.u)
    }

    /// [`Truth::push`], kept in `dir` (`truth-<T10>-<push>-<force>N.npy`, or `.failed` with why it found
    /// no equilibrium) and read back from there when kept by an earlier run (then with `true`):
    /// the truths' solves are most of the validation's time. The error of a push without
    /// equilibrium is returned as the inner one; the outer one is an I/O error.
    fn push_kept(
        &self,
        dir: &Path,
        push: usize,
        centre: Point,
        camera: Point,
        force: f64,
        radius: f64,
    ) -> Result<(Solution, bool)> {
        let stem = format!("truth-{}-{push}-{force}N", self.mesh.cells.len());
        let (solved, failed) = (dir.join(format!("{stem}.npy")), dir.join(format!("{stem}.failed")));
        if let Ok(kept) = mesh::io::npy::read_npy(&solved) {
            let u = kept.into_f64();
            if u.len() == 3 * self.mesh.num_nodes() {
                return Ok((Ok(u), true));
            }
        }
        if let Ok(why) = std::fs::read_to_string(&failed) {
            return Ok((Err(why), true));
        }
        let solution = match self.push(centre, camera, force, radius) {
            Ok(u) => {
                mesh::io::npy::write_f64(&solved, &[u.len() / 3, 3], &u)?;
                Ok(u)
            }
            Err(e) => {
                let why = format!("{e:#}");
                write_atomic_bytes(&failed, why.as_bytes())?;
                Err(why)
            }
        };
        Ok((solution, false))
    }

    /// The targets moved by the displacement `u`.
    fn targets(&self, targets: &[Point], u: &[f64]) -> Vec<Point> {
        register::organ::displaced(targets, &self.stencils, u)
    }

    /// The cloud the camera gives of the truth displaced by `u`: its seen nodes, each coordinate
    /// with a draw of `noise`.
    fn cloud(&self, u: &[f64], noise: &rand_distr::Normal<f64>, rng: &mut rand::rngs::StdRng) -> Vec<Point> {
        use rand_distr::Distribution;
        let nodes = &self.mesh.nodes;
        self.seen.iter().map(|&n| std::array::from_fn(|d| nodes[n][d] + u[3 * n + d] + noise.sample(rng))).collect()
    }
}

/// A tool push of the validation: where along what the camera sees (a fraction, see
/// [`VALIDATION_LOADS`]), its force (N) and the seen node it is centred on.
#[derive(Clone, Copy)]
struct Push {
    at: f64,
    force: f64,
    centre: Point,
}

/// Load steps of a truth's solve. The pushes move the organ by centimetres, where a whole push at
/// once costs more Newton iterations (and factorisations) than quarters of it: on the tour's
/// organ, the 3 N push on 3,046 T10 took 13.0 s at once, 5.2 s in quarters, and on 6,037 T10
/// 43.4 against 36.5 s.
const TRUTH_LOAD_STEPS: usize = 4;

/// The truth's meshes, in multiples of the organ's tetrahedra, coarsest first.
const TRUTH_LEVELS: [usize; 3] = [3, 6, 12];

/// A truth is converged when, meshed twice as finely, its targets move by at most this share of
/// their motion.
const TRUTH_TOLERANCE: f64 = 0.1;

/// The sub-directory where the validation keeps its truths' solutions.
pub const TRUTH_DIR: &str = "validation";

/// The pictures of the chosen method's registration of the strongest push, beside the report:
/// this name's side view (.png) and 3D page (.html).
pub const PICTURE: &str = "validation";

/// The table of the validation's figures beside the report: each method's registrations of each
/// push and of all of them, from rest and as streams.
pub const TABLE: &str = "validation.csv";

/// [`TABLE`]'s columns.
const TABLE_COLUMNS: [&str; 11] = [
    "method",
    "registered",
    "push_n",
    "targets",
    "tre_mm",
    "largest_mm",
    "sigma_mm",
    "within_2sigma",
    "sigma_factor",
    "within_2sigma_calibrated",
    "ms_per_frame",
];

/// A push's displacement on a truth, or why it found no equilibrium under it.
type Solution = std::result::Result<Vec<f64>, String>;

/// Each push's [`Solution`].
type Solutions = Vec<Solution>;

/// The validation's truth refined until converged, from `truth` (the coarsest of
/// [`TRUTH_LEVELS`], `truth_of` meshing the others): of its pushes that a mesh twice as fine
/// also solves, the one that moves the targets most is solved again there; while the `targets`
/// move by more than [`TRUTH_TOLERANCE`] of their motion, the finer mesh becomes the truth.
/// Returns the truth, its solutions of the `pushes` by `solve`, and a report line per check; a
/// check that meshes the truth more finely is told to `progress` as it is made (the finer solves
/// that follow may take long).
fn converged_truth(
    mut truth: Truth,
    truth_of: &dyn Fn(usize) -> Result<Truth>,
    solve: &dyn Fn(&Truth, usize) -> Result<Solution>,
    targets: &[Point],
    pushes: &[Push],
    progress: &dyn learn::Progress,
) -> Result<(Truth, Solutions, Vec<String>)> {
    let mut solutions: Solutions = (0..pushes.len()).map(|p| solve(&truth, p)).collect::<Result<_>>()?;
    let mut lines = Vec::new();
    for (i, &level) in TRUTH_LEVELS.iter().enumerate().skip(1) {
        let finer = truth_of(level)?;
        // The push that moves the targets most is the check: a push that hardly moves them would
        // judge the mesh on a motion of the order of its own discretisation error.
        let mut by_motion: Vec<(usize, &Vec<f64>, f64)> = solutions
            .iter()
            .enumerate()
            .filter_map(|(p, s)| {
                let u = s.as_ref().ok()?;
                Some((p, u, mesh::stats::mean(&register::target_errors(targets, &truth.targets(targets, u)))))
            })
            .collect();
        by_motion.sort_by(|a, b| b.2.total_cmp(&a.2));
        let mut finer_solutions: Vec<Option<Solution>> = vec![None; pushes.len()];
        let mut unsolved = Vec::new();
        let mut checked = None;
        for (p, u, _) in by_motion {
            match solve(&finer, p)? {
                Ok(finer_u) => {
                    finer_solutions[p] = Some(Ok(finer_u.clone()));
                    checked = Some((p, u, finer_u));
                    break;
                }
                Err(e) => {
                    unsolved.push(format!("{} N ({e})", pushes[p].force));
                    finer_solutions[p] = Some(Err(e));
                }
            }
        }
        let unsolved = if unsolved.is_empty() {
            String::new()
        } else {
            format!("; the finer mesh found no equilibrium under {}", unsolved.join(", "))
        };
        let Some((p, u, finer_u)) = checked else {
            lines.push(format!(
                "validation: the truth's convergence not checked: meshed twice as finely again ({} T10){unsolved}",
                finer.mesh.cells.len()
            ));
            break;
        };
        let moved = truth.targets(targets, u);
        let finer_moved = finer.targets(targets, &finer_u);
        let change = register::target_errors(&moved, &finer_moved);
        let motion = mesh::stats::mean(&register::target_errors(targets, &finer_moved));
        let share = mesh::stats::mean(&change) / motion.max(f64::MIN_POSITIVE);
        let converged = share <= TRUTH_TOLERANCE;
        let last = i + 1 == TRUTH_LEVELS.len();
        let verdict = match (converged, last) {
            (true, _) => format!("converged (at most {:.0} %)", 100.0 * TRUTH_TOLERANCE),
            (false, false) => "not converged: the truth is meshed twice as finely".into(),
            (false, true) => format!(
                "not converged to {:.0} %: the truth is the finer mesh, the finest tried",
                100.0 * TRUTH_TOLERANCE
            ),
        };
        let line = format!(
            "validation: the truth's convergence under the {} N push: {} T10 against {} T10, its targets move by \
             {:.2} mm more or less (largest {:.2} mm; {:.1} % of their mean motion of {:.2} mm){unsolved}; {verdict}",
            pushes[p].force,
            truth.mesh.cells.len(),
            finer.mesh.cells.len(),
            mm(mesh::stats::mean(&change)),
            mm(mesh::stats::max(&change)),
            100.0 * share,
            mm(motion)
        );
        if converged {
            lines.push(line);
            break;
        }
        progress.line(&line);
        lines.push(line);
        // The finer mesh becomes the truth: its pushes not yet solved are solved now.
        solutions = finer_solutions
            .into_iter()
            .enumerate()
            .map(|(p, known)| known.map_or_else(|| solve(&finer, p), Ok))
            .collect::<Result<_>>()?;
        truth = finer;
    }
    Ok((truth, solutions, lines))
}

/// A method whose TRE is within this share of the FEM's is on par with it, not worse.
const ON_PAR: f64 = 0.05;

/// The shares of a push's force at the frames of its stream: the tool pressing in by quarters.
const STREAM_SHARES: [f64; 4] = [0.25, 0.5, 0.75, 1.0];

/// The standard deviation of the validation clouds' noise (m).
const CLOUD_NOISE: f64 = 0.0005;

/// The share of the targets a calibrated σ puts within 2σ: a Gaussian's.
const SIGMA_COVERAGE: f64 = 0.95;

/// A method's σ calibrated on the validation's registrations, from rest and on streams.
struct SigmaCalibration {
    /// The least factor on σ, at least 1, that puts [`SIGMA_COVERAGE`] of the targets within 2σ.
    /// Only widened: on SOFA's liver, where σ covered more, narrowing it (×0.69 for the ROM, ×0.59
    /// for the hybrid) left 85 % and 82 % of each push's targets within 2σ from rest under the
    /// other pushes' factor (92 % on streams): four pushes are too few to narrow it.
    factor: f64,
    /// The mean σ (m) so calibrated.
    mean_std: f64,
    /// Each target of each frame (its push, its kind) and whether it lies within 2σ under the
    /// factor calibrated on the other pushes; empty with a single push.
    held_out: Vec<(usize, Kind, bool)>,
}

/// How a method registered a push: from rest, or as the frames of a stream.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Kind {
    Rest,
    Stream,
}

impl Kind {
    /// Its name in [`TABLE`]'s `registered` column.
    fn name(self) -> &'static str {
        match self {
            Kind::Rest => "rest",
            Kind::Stream => "stream",
        }
    }
}

impl SigmaCalibration {
    /// The share of the targets of `kind` (of push `push`, else all) within 2σ under the factor
    /// calibrated on the other pushes; none without such targets.
    fn held_out_share(&self, kind: Kind, push: Option<usize>) -> Option<f64> {
        let of = |&&(p, k, _): &&(usize, Kind, bool)| k == kind && push.is_none_or(|push| p == push);
        let targets = self.held_out.iter().filter(of).count();
        let within = self.held_out.iter().filter(of).filter(|t| t.2).count();
        (targets > 0).then(|| within as f64 / targets as f64)
    }
}

/// A method's registrations of one kind: each push from rest, or each push as a stream.
#[derive(Default)]
struct Registered {
    /// The target errors (m) of the frames it registered.
    errors: Vec<f64>,
    /// The push (its index) of each of those errors.
    push_of: Vec<usize>,
    /// The predicted σ (m) at the targets of those frames, for a method that predicts one.
    std: Vec<f64>,
    /// The time of each frame timed (ms).
    times_ms: Vec<f64>,
    /// The pushes it failed on, and why.
    failed: Vec<String>,
}

impl Registered {
    /// Adds a registered frame of push `push`: its targets' errors against their true positions
    /// `moved`, their σ and, when `timed`, its time.
    fn add(&mut self, push: usize, tracked: &register::Tracked, moved: &[Point], timed: bool) {
        self.errors.extend(register::target_errors(&tracked.targets, moved));
        self.push_of.resize(self.errors.len(), push);
        self.std.extend(tracked.target_std.iter().flatten());
        if timed {
            self.times_ms.push(mesh::stats::ms(tracked.registration.time));
        }
    }

    /// The mean TRE (m); infinite with no frame registered.
    fn tre(&self) -> f64 {
        if self.errors.is_empty() {
            f64::INFINITY
        } else {
            mesh::stats::mean(&self.errors)
        }
    }

    /// The pushes it registered (their indices), in order.
    fn pushes(&self) -> std::collections::BTreeSet<usize> {
        self.push_of.iter().copied().collect()
    }

    /// The target errors (m) of push `push`'s frames, and their σ where the method gives one.
    fn of_push(&self, push: usize) -> (Vec<f64>, Vec<f64>) {
        let at: Vec<usize> = (0..self.errors.len()).filter(|&k| self.push_of[k] == push).collect();
        (at.iter().map(|&k| self.errors[k]).collect(), at.iter().filter_map(|&k| self.std.get(k).copied()).collect())
    }

    /// The TRE, σ, each push's TRE and failures in words, after `what` (how the pushes were
    /// registered) and the time of a frame (`timing`: which frames were timed); `forces`: each
    /// push's (N).
    fn words(&self, what: &str, timing: &str, forces: &[f64]) -> String {
        let failed = match self.failed.len() {
            0 => String::new(),
            n => format!(", failed on {n}: {}", self.failed.join("; ")),
        };
        match (self.errors.is_empty(), self.failed.is_empty()) {
            (true, true) => return format!("{what}: none registered"),
            (true, false) => return format!("{what} failed on every push: {}", self.failed.join("; ")),
            _ => {}
        }
        // σ, where the method predicts it at every target: how well it held on these pushes.
        let sigma = register::within_two_std(&self.errors, &self.std).map_or(String::new(), |within| {
            format!(
                ", σ {:.2} mm mean, {:.0} % of the targets within 2σ",
                mm(mesh::stats::mean(&self.std)),
                100.0 * within
            )
        });
        format!(
            "{what} TRE {:.2} mm (largest {:.2} mm), {:.0} ms {timing}{sigma}; {}{failed}",
            mm(mesh::stats::mean(&self.errors)),
            mm(mesh::stats::max(&self.errors)),
            mesh::stats::mean(&self.times_ms),
            push_figures(self.pushes().into_iter().map(|p| (forces[p], mesh::stats::mean(&self.of_push(p).0))))
        )
    }
}

/// One method's registrations of the validation's pushes.
#[derive(Default)]
struct MethodRun {
    method: PatientMethod,
    /// Each push registered from rest.
    rest: Registered,
    /// Each push registered as a stream of [`STREAM_SHARES`] of its force.
    streamed: Registered,
    /// Its registration from rest of the strongest push it registered, for the picture.
    strongest: Option<Strongest>,
}

/// A registration from rest of one push, as its picture shows it.
struct Strongest {
    force: f64,
    registration: register::Registration,
    tracked: register::Tracked,
    cloud: Vec<Point>,
    /// The targets' true positions.
    moved: Vec<Point>,
}

impl MethodRun {
    /// Registers the frames of push `push` of `force` (each the targets' true positions and the
    /// cloud), the first from rest and each next one warm-started from the last: a single frame
    /// from rest, timed, or a stream (into `streamed`), whose warm-started frames alone are
    /// timed. A failed frame ends them. σ is the method's own, which the validation calibrates.
    fn register(&mut self, dir: &Path, (push, force): (usize, f64), frames: &[(&[Point], &[Point])]) -> Result<()> {
        let spec = RegistrationSpec::patient(dir, Some(self.method), None, false)?;
        let mut registration = RegistrationSpec { sigma_factor: 1.0, ..spec }.build()?;
        let stream = frames.len() > 1;
        let into = if stream { &mut self.streamed } else { &mut self.rest };
        let mut last = None;
        for (k, &(moved, cloud)) in frames.iter().enumerate() {
            match registration.register(cloud) {
                Ok(tracked) => {
                    into.add(push, &tracked, moved, !stream || k > 0);
                    last = Some(tracked);
                }
                Err(e) => {
                    let frame = if stream { format!(", frame {}", k + 1) } else { String::new() };
                    into.failed.push(format!("{force} N{frame} ({e:#})"));
                    break;
                }
            }
        }
        if let (false, Some(tracked)) = (stream, last) {
            if self.strongest.as_ref().is_none_or(|s| force > s.force) {
                let (moved, cloud) = frames[0];
                let (cloud, moved) = (cloud.to_vec(), moved.to_vec());
                self.strongest = Some(Strongest { force, registration, tracked, cloud, moved });
            }
        }
        Ok(())
    }

    /// Draws its registration from rest of the strongest push into `dir` ([`PICTURE`] .png and
    /// .html), its σ times `sigma_factor`; returns the report's line on them, none when it
    /// registered no push.
    fn picture(&self, dir: &Path, sigma_factor: f64) -> Result<Option<String>> {
        let Some(s) = &self.strongest else { return Ok(None) };
        let errors = register::target_errors(&s.tracked.targets, &s.moved);
        let headline = format!(
            "TRE at the {} targets: mean {:.2} mm, max {:.2} mm; the truth: the organ meshed anew (T10, Neo-Hookean)",
            errors.len(),
            mm(mesh::stats::mean(&errors)),
            mm(mesh::stats::max(&errors))
        );
        let std: Option<Vec<f64>> =
            s.tracked.target_std.as_ref().map(|std| std.iter().map(|v| v * sigma_factor).collect());
        let notes = frame_notes(headline, std.as_deref(), &s.tracked.registration.warnings);
        let name = method_name(self.method);
        let targets = (s.registration.targets(), s.tracked.targets.as_slice());
        let (organ, u) = (s.registration.organ(), &s.tracked.registration.u);
        RegisteredFrame::new(organ, u, s.tracked.rigid.as_ref(), &s.cloud, targets, Some(&s.moved)).write(
            &dir.join(PICTURE),
            &format!("{name}: the {} N push of the validation, from rest", s.force),
            notes,
        )?;
        Ok(Some(format!("validation: the {name} on the strongest push, pictured: {PICTURE}.png, {PICTURE}.html")))
    }

    /// Its σ calibrated ([`SigmaCalibration`]), for a method that gives one at every target it
    /// registered.
    fn sigma_calibration(&self) -> Option<SigmaCalibration> {
        let runs = [(Kind::Rest, &self.rest), (Kind::Stream, &self.streamed)];
        if runs.iter().any(|(_, run)| run.std.len() != run.errors.len()) {
            return None;
        }
        // Each target's error in units of 2σ, with its push and its kind.
        let ratios: Vec<(usize, Kind, f64)> = runs
            .iter()
            .flat_map(|&(kind, run)| {
                let pushes = run.push_of.iter().zip(&run.errors).zip(&run.std);
                pushes.map(move |((&p, e), s)| (p, kind, e / (2.0 * s)))
            })
            .collect();
        let factor_of = |ratios: Vec<f64>| mesh::stats::percentile(&ratios, 100.0 * SIGMA_COVERAGE).max(1.0);
        let factor = factor_of(ratios.iter().map(|r| r.2).collect());
        if !factor.is_finite() {
            return None;
        }
        let pushes: std::collections::BTreeSet<usize> = ratios.iter().map(|r| r.0).collect();
        let mut held_out = Vec::new();
        if pushes.len() > 1 {
            for &p in &pushes {
                let others = factor_of(ratios.iter().filter(|r| r.0 != p).map(|r| r.2).collect());
                let of_push = ratios.iter().filter(|r| r.0 == p);
                held_out.extend(of_push.map(|&(_, kind, ratio)| (p, kind, ratio <= others)));
            }
        }
        let std: Vec<f64> = runs.iter().flat_map(|(_, run)| &run.std).copied().collect();
        Some(SigmaCalibration { factor, mean_std: factor * mesh::stats::mean(&std), held_out })
    }

    /// Lower is better: the pushes it failed on (from rest and as streams); then whether it is
    /// worse than the FEM's run `fem` from rest or on the streams (its TRE over the FEM's by more
    /// than [`ON_PAR`]); then the mean of its TRE's ratios to the FEM's, from rest and on the
    /// streams.
    fn rank(&self, fem: &MethodRun) -> (usize, bool, f64) {
        let ratio = |a: &Registered, b: &Registered| {
            let r = a.tre() / b.tre();
            if r.is_nan() {
                1.0
            } else {
                r
            }
        };
        let mut ratios = vec![ratio(&self.rest, &fem.rest)];
        if !(self.streamed.errors.is_empty() && fem.streamed.errors.is_empty()) {
            ratios.push(ratio(&self.streamed, &fem.streamed));
        }
        let failures = self.rest.failed.len() + self.streamed.failed.len();
        (failures, ratios.iter().any(|&r| r > 1.0 + ON_PAR), mesh::stats::mean(&ratios))
    }
}

/// Each push's figure in words: `1.5 N 2.10 mm, 2.5 N 3.40 mm` (`(force, m)` pairs), after "per push".
fn push_figures(pushes: impl IntoIterator<Item = (f64, f64)>) -> String {
    let figures: Vec<String> =
        pushes.into_iter().map(|(force, value)| format!("{force} N {:.2} mm", mm(value))).collect();
    format!("per push {}", figures.join(", "))
}

/// How the report names a method.
fn method_name(method: PatientMethod) -> &'static str {
    match method {
        PatientMethod::Fem => "FEM",
        PatientMethod::Learned => "learned model",
        PatientMethod::Hybrid => "learned model, then FEM (hybrid)",
    }
}

/// The validation's pushes ([`VALIDATION_LOADS`]), at seen nodes of the `coarsest` truth ordered
/// across the line of sight from `camera`.
fn validation_pushes(coarsest: &Truth, camera: Point) -> Vec<Push> {
    let mesh = &coarsest.mesh;
    let centroid: Point =
        std::array::from_fn(|d| mesh.nodes.iter().map(|p| p[d]).sum::<f64>() / mesh.num_nodes() as f64);
    let (across, _) = across_sight(mesh::unit(mesh::sub(centroid, camera)));
    let mut order = coarsest.seen.clone();
    order.sort_by(|&a, &b| mesh::dot(mesh.nodes[a], across).total_cmp(&mesh::dot(mesh.nodes[b], across)));
    VALIDATION_LOADS
        .iter()
        .map(|&(at, force)| Push { at, force, centre: mesh.nodes[order[((order.len() - 1) as f64 * at) as usize]] })
        .collect()
}

/// Step 6: registration of held-out cases against a quadratic truth on another mesh, refined
/// until converged: meshed with 3, 6 or 12 times the organ's tetrahedra, the first whose targets
/// move by at most [`TRUTH_TOLERANCE`] on a mesh twice as fine under the push that moves them most
/// (the finest reached otherwise, and the report says so).
pub(super) fn validation_step(
    options: &PrepareOptions,
    dir: &Path,
    progress: &dyn learn::Progress,
) -> Result<Vec<String>> {
    let organ = mesh::io::read_mesh(dir.join("organ.vtu"))?;
    let surface = read_organ_surface(&dir.join(SURFACE_FILE), &organ)?;
    let camera = super::read_camera(dir)?;
    let landmarks = read_points_csv(&dir.join("attach.csv"))?;
    let targets = read_points_csv(&dir.join("targets.csv"))?;
    let distance = hold_distance(options, &organ, &landmarks)?;
    let truth_of = |level: usize| Truth::new(&surface, level * options.tets, camera, &landmarks, &targets, distance);
    let truth = truth_of(TRUTH_LEVELS[0])?;
    let pushes = validation_pushes(&truth, camera);
    let radius = tool_radius(&truth.mesh);
    let kept = dir.join(TRUTH_DIR);
    mesh::io::create_folder(&kept)?;
    let read_back = std::cell::Cell::new(0);
    // Each solve is told as it ends: on the finest truths one takes an hour.
    let solve_at = |truth: &Truth, push: usize, force: f64| -> Result<Solution> {
        let centre = pushes[push].centre;
        let start = Instant::now();
        let (solution, kept) = truth.push_kept(&kept, push, centre, camera, force, radius)?;
        read_back.set(read_back.get() + usize::from(kept));
        if !kept {
            progress.line(&format!(
                "validation: the {force} N push on a truth of {} T10 {} in {:.0} s",
                truth.mesh.cells.len(),
                if solution.is_ok() { "solved" } else { "found no equilibrium" },
                start.elapsed().as_secs_f64()
            ));
        }
        Ok(solution)
    };
    let solve = |truth: &Truth, push: usize| solve_at(truth, push, pushes[push].force);
    let (truth, solutions, mut lines) = converged_truth(truth, &truth_of, &solve, &targets, &pushes, progress)?;

    let Registrations { methods, rest_errors, motions, left_out, streams_left_out } =
        register_pushes(dir, options.seed, &truth, &targets, (&pushes, &solutions), &solve_at)?;
    if motions.is_empty() {
        bail!("the validation's truth found no equilibrium under any push: {}", left_out.join("; "));
    }
    lines.push(format!(
        "validation: {} pushes of {}–{} N on a truth of {} T10 ({} nodes, Neo-Hookean) meshed anew; clouds of {} \
         seen nodes with {:.1} mm noise; TRE without deformation {:.2} mm ({})",
        motions.len(),
        motions.iter().map(|m| m.0).fold(f64::INFINITY, f64::min),
        motions.iter().map(|m| m.0).fold(0.0, f64::max),
        truth.mesh.cells.len(),
        truth.mesh.num_nodes(),
        truth.seen.len(),
        mm(CLOUD_NOISE),
        mm(mesh::stats::mean(&rest_errors)),
        push_figures(motions.iter().copied())
    ));
    lines.extend(
        swing_warning("the targets", mesh::stats::mean(&rest_errors), &organ).map(|w| format!("validation: {w}")),
    );
    for &(target, distance) in &truth.outside {
        lines.push(format!(
            "validation: target {target} lies {:.2} mm outside the truth's mesh and follows its nearest surface point",
            mm(distance)
        ));
    }
    if read_back.get() > 0 {
        lines.push(format!(
            "validation: {} of the truths' solves read back from {TRUTH_DIR}/, made by an earlier run (this step's \
             time leaves them out)",
            read_back.get()
        ));
    }
    for (what, pushes) in [("", &left_out), ("streams ", &streams_left_out)].into_iter().filter(|(_, p)| !p.is_empty())
    {
        lines.push(format!(
            "validation: {what}left out, the truth finding no equilibrium under them: {}",
            pushes.join("; ")
        ));
    }
    let forces: Vec<f64> = pushes.iter().map(|p| p.force).collect();
    lines.extend(methods.iter().flat_map(|run| method_lines(run, &forces)));
    let calibrations: Vec<(PatientMethod, SigmaCalibration)> =
        methods.iter().filter_map(|run| Some((run.method, run.sigma_calibration()?))).collect();
    lines.extend(calibrations.iter().map(|(method, calibration)| calibration_line(*method, calibration)));
    write_table(dir, &methods, &calibrations, &forces)?;
    let (line, chosen) = record_set_up(dir, &methods, &calibrations)?;
    lines.push(line);
    let factor = calibrations.iter().find(|(method, _)| *method == chosen).map_or(1.0, |(_, c)| c.factor);
    let chosen = methods.iter().find(|run| run.method == chosen).context("the chosen method was not validated")?;
    lines.extend(chosen.picture(dir, factor)?);
    Ok(lines)
}

/// What the validation's registrations gave: each method's runs, the targets' motion under each
/// push (their TRE without deformation) and its mean per push registered (force, m), and the
/// pushes and streams left out (the truth finding no equilibrium under them), in words.
struct Registrations {
    methods: [MethodRun; 3],
    rest_errors: Vec<f64>,
    motions: Vec<(f64, f64)>,
    left_out: Vec<String>,
    streams_left_out: Vec<String>,
}

/// Registers each push the truth solved (`solutions` of `pushes`) with the learned model, the FEM
/// and the hybrid of the set-up in `dir`, from rest and as a stream of [`STREAM_SHARES`] of its
/// force (the stream's truths by `solve_at`), the clouds' noise drawn from `seed`.
fn register_pushes(
    dir: &Path,
    seed: u64,
    truth: &Truth,
    targets: &[Point],
    (pushes, solutions): (&[Push], &[Solution]),
    solve_at: &dyn Fn(&Truth, usize, f64) -> Result<Solution>,
) -> Result<Registrations> {
    use rand::SeedableRng;

    let mut methods = [PatientMethod::Learned, PatientMethod::Fem, PatientMethod::Hybrid]
        .map(|method| MethodRun { method, ..MethodRun::default() });
    let mut rest_errors = Vec::new();
    let mut motions = Vec::new();
    // The streams' noise is drawn apart, so that the clouds from rest do not depend on them.
    let (mut rng, mut stream_rng) =
        (rand::rngs::StdRng::seed_from_u64(seed), rand::rngs::StdRng::seed_from_u64(seed ^ 1));
    let noise = rand_distr::Normal::new(0.0, CLOUD_NOISE).context("noise")?;
    let mut left_out = Vec::new();
    let mut streams_left_out = Vec::new();
    for (p, (&Push { at, force, .. }, solution)) in pushes.iter().zip(solutions).enumerate() {
        let u = match solution {
            Ok(u) => u,
            Err(e) => {
                left_out.push(format!("{force} N at {:.0} % across the view ({e})", 100.0 * at));
                continue;
            }
        };
        let moved = truth.targets(targets, u);
        let motion = register::target_errors(targets, &moved);
        motions.push((force, mesh::stats::mean(&motion)));
        rest_errors.extend(motion);
        let cloud = truth.cloud(u, &noise, &mut rng);
        methods.iter_mut().try_for_each(|run| run.register(dir, (p, force), &[(&moved, &cloud)]))?;
        // The same push as a stream: the tool pressing in by quarters of its force.
        let mut frames = Vec::new();
        for share in STREAM_SHARES {
            let solution = if share == 1.0 { Ok(u.clone()) } else { solve_at(truth, p, share * force)? };
            match solution {
                Ok(u) => frames.push((truth.targets(targets, &u), truth.cloud(&u, &noise, &mut stream_rng))),
                Err(e) => {
                    streams_left_out.push(format!("{force} N's stream, its {} N frame ({e})", share * force));
                    break;
                }
            }
        }
        if frames.len() == STREAM_SHARES.len() {
            let frames: Vec<(&[Point], &[Point])> = frames.iter().map(|(m, c)| (m.as_slice(), c.as_slice())).collect();
            methods.iter_mut().try_for_each(|run| run.register(dir, (p, force), &frames))?;
        }
    }
    Ok(Registrations { methods, rest_errors, motions, left_out, streams_left_out })
}

/// The validation's lines on one method's registrations: from rest, and as streams; `forces`:
/// each push's (N).
fn method_lines(run: &MethodRun, forces: &[f64]) -> [String; 2] {
    let name = method_name(run.method);
    let streams = format!("{name} as streams of {} frames", STREAM_SHARES.len());
    [
        format!("validation: {}", run.rest.words(name, "per registration from rest", forces)),
        format!("validation: {}", run.streamed.words(&streams, "per warm-started frame", forces)),
    ]
}

/// Writes [`TABLE`]: a row for each method, kind of registration (`rest`, `stream`) and push
/// (`push_n` its force), then one for all the pushes (`push_n` `all`); `forces`: each push's (N).
fn write_table(
    dir: &Path,
    methods: &[MethodRun],
    calibrations: &[(PatientMethod, SigmaCalibration)],
    forces: &[f64],
) -> Result<()> {
    let figure = |value: Option<f64>, digits: usize| value.map_or(String::new(), |v| format!("{v:.digits$}"));
    let mut rows = Vec::new();
    for run in methods {
        let calibration = calibrations.iter().find(|(method, _)| *method == run.method).map(|(_, c)| c);
        for (kind, registered) in [(Kind::Rest, &run.rest), (Kind::Stream, &run.streamed)] {
            let pushes = registered.pushes().into_iter().map(Some);
            for push in pushes.chain(std::iter::once(None)) {
                let (errors, std) = match push {
                    Some(p) => registered.of_push(p),
                    None => (registered.errors.clone(), registered.std.clone()),
                };
                if errors.is_empty() {
                    continue;
                }
                let given = (std.len() == errors.len()).then_some(std);
                rows.push(vec![
                    run.method.name().to_string(),
                    kind.name().to_string(),
                    push.map_or("all".into(), |p| forces[p].to_string()),
                    errors.len().to_string(),
                    format!("{:.3}", mm(mesh::stats::mean(&errors))),
                    format!("{:.3}", mm(mesh::stats::max(&errors))),
                    figure(given.as_ref().map(|std| mm(mesh::stats::mean(std))), 3),
                    figure(given.as_ref().and_then(|std| register::within_two_std(&errors, std)), 4),
                    figure(calibration.map(|c| c.factor), 3),
                    figure(calibration.and_then(|c| c.held_out_share(kind, push)), 4),
                    figure(push.is_none().then(|| mesh::stats::mean(&registered.times_ms)), 1),
                ]);
            }
        }
    }
    let comments = [
        format!(
            "augsim prepare's validation: the targets' errors registering its pushes (rest: each from rest; stream: \
             each as a stream of {} frames, its warm-started frames timed)",
            STREAM_SHARES.len()
        ),
        "sigma_mm, within_2sigma: the mean σ the method gives and the share of the targets within 2σ; \
         sigma_factor: its calibration (registration.toml); within_2sigma_calibrated: the share within 2σ under \
         the factor calibrated on the other pushes"
            .to_string(),
    ];
    mesh::io::csv::write_csv(&dir.join(TABLE), &comments, &TABLE_COLUMNS, rows)?;
    Ok(())
}

/// The report's table of the validation's figures, from [`TABLE`] in `dir` (its rows over all
/// the pushes); none when the validation has not written it.
pub(super) fn report_table(dir: &Path) -> Result<Option<String>> {
    let path = dir.join(TABLE);
    if !path.exists() {
        return Ok(None);
    }
    let text = std::fs::read_to_string(&path).with_context(|| format!("reading {}", path.display()))?;
    let table = mesh::io::csv::Table::parse(&text, &mesh::io::csv::Dialect::CSV)
        .and_then(|table| table.check_widths().map(|()| table))
        .with_context(|| format!("reading {}", path.display()))?;
    let column = |name: &str| table.column(name).with_context(|| format!("{} has no column {name}", path.display()));
    let [method, registered, push, tre, largest, factor, calibrated, ms] = [
        "method",
        "registered",
        "push_n",
        "tre_mm",
        "largest_mm",
        "sigma_factor",
        "within_2sigma_calibrated",
        "ms_per_frame",
    ]
    .map(column);
    let (method, registered, push, tre, largest) = (method?, registered?, push?, tre?, largest?);
    let (factor, calibrated, ms) = (factor?, calibrated?, ms?);
    let mut text = String::from(
        "| method | from rest: TRE (largest) | as streams: TRE (largest) | ms per frame (from rest; warm-started) | σ \
         factor | within 2σ, each push under the others' factor (from rest; streams) |\n| --- | --- | --- | ---: | \
         ---: | --- |\n",
    );
    for name in [PatientMethod::Learned, PatientMethod::Fem, PatientMethod::Hybrid] {
        let row = |kind: &str| {
            table
                .rows
                .iter()
                .find(|r| r.fields[method] == name.name() && r.fields[registered] == kind && r.fields[push] == "all")
        };
        let (rest, stream) = (row(Kind::Rest.name()), row(Kind::Stream.name()));
        let Some(any) = rest.or(stream) else { continue };
        // A number of the row in `column` as `form` writes it; a dash where there is none.
        let figure = |row: Option<&mesh::io::csv::Row>, column: usize, form: &dyn Fn(f64) -> String| {
            row.and_then(|r| r.fields[column].parse::<f64>().ok()).map_or("—".into(), form)
        };
        let tre = |row| {
            format!(
                "{} ({})",
                figure(row, tre, &|v| format!("{v:.2} mm")),
                figure(row, largest, &|v| format!("{v:.2} mm"))
            )
        };
        let share = |row| figure(row, calibrated, &|v| format!("{:.0} %", 100.0 * v));
        let ms = |row| figure(row, ms, &|v| format!("{v:.0}"));
        text.push_str(&format!(
            "| {} | {} | {} | {}; {} | {} | {}; {} |\n",
            method_name(name),
            tre(rest),
            tre(stream),
            ms(rest),
            ms(stream),
            figure(Some(any), factor, &|v| format!("×{v:.2}")),
            share(rest),
            share(stream)
        ));
    }
    Ok(Some(text))
}

/// The validation's line on a method's σ calibrated.
fn calibration_line(method: PatientMethod, c: &SigmaCalibration) -> String {
    let shares: Vec<String> = [(Kind::Rest, "from rest"), (Kind::Stream, "on streams")]
        .into_iter()
        .filter_map(|(kind, words)| c.held_out_share(kind, None).map(|share| format!("{:.0} % {words}", 100.0 * share)))
        .collect();
    let held_out = match shares.is_empty() {
        true => String::new(),
        false => format!("; each push's targets with the factor of the other pushes: within 2σ {}", shares.join(", ")),
    };
    format!(
        "validation: σ of the {} calibrated on these pushes: ×{:.2}, the least factor (at least 1) that puts \
         {:.0} % of their targets within 2σ (σ {:.2} mm mean){held_out}",
        method_name(method),
        c.factor,
        100.0 * SIGMA_COVERAGE,
        mm(c.mean_std)
    )
}

/// Writes into the patient file the method that did the best on the validation's pushes and the
/// factors of the methods' σ `calibrations`; returns the validation's line on the method, and
/// the method.
fn record_set_up(
    dir: &Path,
    methods: &[MethodRun],
    calibrations: &[(PatientMethod, SigmaCalibration)],
) -> Result<(String, PatientMethod)> {
    // The set-up registers with the method that did the best on these pushes, from rest and
    // on streams ([`MethodRun::rank`]); on a tie the first.
    let fem = methods.iter().find(|run| run.method == PatientMethod::Fem).context("the FEM was not validated")?;
    let chosen = methods
        .iter()
        .min_by(|a, b| a.rank(fem).partial_cmp(&b.rank(fem)).unwrap_or(std::cmp::Ordering::Equal))
        .context("no method was validated")?
        .method;
    let mut patient = Patient::read(dir)?;
    patient.method = chosen;
    patient.sigma = SigmaFactors::default();
    calibrations.iter().for_each(|(method, calibration)| patient.sigma.set(*method, calibration.factor));
    patient.write(dir)?;
    let line = format!(
        "validation: {PATIENT_FILE} registers with the {} (method = \"{}\"), the best on these pushes, from rest \
         and as streams",
        method_name(chosen),
        chosen.name()
    );
    Ok((line, chosen))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Registrations from rest of pushes 0 and 1, each target's error `ratio` × 2σ (σ 1 mm).
    fn registered(ratios: &[(usize, f64)]) -> Registered {
        Registered {
            errors: ratios.iter().map(|r| 2e-3 * r.1).collect(),
            push_of: ratios.iter().map(|r| r.0).collect(),
            std: vec![1e-3; ratios.len()],
            ..Registered::default()
        }
    }

    /// The factor is the nearest-rank 95th percentile of the errors in units of 2σ, at least 1;
    /// each push's share within 2σ takes the factor of the others; a method without σ has none.
    #[test]
    fn sigma_is_calibrated_on_the_pushes_and_checked_on_each_left_out() {
        let rest = registered(&[(0, 0.5), (0, 3.0), (1, 0.5), (1, 1.5)]);
        let run = MethodRun { rest, ..MethodRun::default() };
        let c = run.sigma_calibration().unwrap();
        assert!((c.factor - 3.0).abs() < 1e-12 && (c.mean_std - 3e-3).abs() < 1e-12, "×{}", c.factor);
        // Push 0 under push 1's factor 1.5 keeps 1 of 2; push 1 under push 0's 3, both.
        assert_eq!(c.held_out_share(Kind::Rest, None), Some(0.75));
        let shares = (c.held_out_share(Kind::Rest, Some(0)), c.held_out_share(Kind::Rest, Some(1)));
        assert_eq!(shares, (Some(0.5), Some(1.0)));
        assert_eq!(c.held_out_share(Kind::Stream, None), None, "no stream registered");
        let narrow = MethodRun { rest: registered(&[(0, 0.2), (1, 0.3)]), ..MethodRun::default() };
        assert_eq!(narrow.sigma_calibration().unwrap().factor, 1.0, "σ is only ever widened");
        let single = MethodRun { rest: registered(&[(0, 0.2), (0, 0.3)]), ..MethodRun::default() };
        assert!(single.sigma_calibration().unwrap().held_out.is_empty(), "one push: nothing to leave out");
        let fem = MethodRun { rest: Registered { std: Vec::new(), ..registered(&[(0, 0.5)]) }, ..MethodRun::default() };
        assert!(fem.sigma_calibration().is_none());
    }
}
