//! Static equilibrium: find u with f_int(u) + K_s u = λ f_ext on the free dofs,
//! for load factors λ stepping to 1 (a step that fails is halved, and the step
//! grows back after successes), with a line search on the energy; where that finds no
//! equilibrium, the path is followed on by arc length (Riks; see `docs/method.md` § 2.5).
//!
//! Each iteration solves with a kept factorisation of the tangent, corrected by
//! limited-memory BFGS updates (the factor is the initial inverse Hessian of the
//! two-loop recursion): an iteration costs one internal-force evaluation and one
//! pair of triangular solves. The tangent is reassembled and refactorised only
//! when that pays: when the iterations still needed at the observed rate of
//! convergence would cost more than a refactorisation and a few iterations
//! with the new factor (costs estimated from operation counts).

use std::time::{Duration, Instant};

use serde::{Deserialize, Serialize};

use crate::assembly::{assemble, Pattern, Workspace};
use crate::element::ElementGeometry;
use crate::linsolve::{Ordering, Slot, SparseCholesky};
use crate::material::{Law, Material, SVK_LIMIT_STRETCH};
use crate::post;
use crate::problem::{Pieces, PointSpring, Problem};
use crate::{written_zeros, FemError};

mod continuation;

/// Settings of the static solver (quasi-Newton iterations on a kept factorisation, see the module documentation).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SolverOptions {
    /// Initial number of load steps (halved adaptively on failure).
    pub load_steps: usize,
    /// Maximum Newton iterations per load step.
    pub max_iterations: usize,
    /// Convergence: ‖r‖ ≤ rtol · max(‖f_ext‖, ‖f_int‖).
    pub rtol: f64,
    /// Convergence also when ‖Δu‖ ≤ utol · ‖u‖ and the relative residual ‖r‖ / max(‖f_ext‖, ‖f_int‖)
    /// is at most √rtol.
    pub utol: f64,
    /// Backtracking line search on the residual norm.
    pub line_search: bool,
    /// How many times a failing load step may be halved before giving up.
    pub max_step_cuts: usize,
    /// Keep the last factorisation across iterations and solves, with BFGS
    /// updates; `false`: full Newton-Raphson, a new factorisation every iteration.
    pub reuse_factorization: bool,
    /// BFGS correction pairs kept (0: plain modified Newton on the kept factor).
    pub bfgs_memory: usize,
    /// How the load path is followed.
    pub continuation: Continuation,
    /// Whether a force-controlled step that softened as a snap does is followed again by arc
    /// length, to tell a limit point from a path that soft (see [`Solution::snapped_from`]): it
    /// may cost as many iterations again as the solve. Not a scenario's setting: for callers
    /// that report snaps.
    #[serde(skip)]
    pub confirm_snaps: bool,
    /// A wall-clock time past which the solve stops with [`FemError::OutOfTime`], at its next
    /// iteration (a frame's time budget on a stream). Not a scenario's setting.
    #[serde(skip)]
    pub deadline: Option<Instant>,
    /// Told the solve's advance at every iteration (for a progress bar). Not a scenario's setting.
    #[serde(skip)]
    pub progress: Option<SolveProgress>,
}

/// Where a solve tells how far it has come: the load factor of the last equilibrium reached and
/// the iterations made so far, at every iteration.
#[derive(Clone)]
pub struct SolveProgress(pub std::sync::Arc<dyn Fn(f64, usize) + Send + Sync>);

impl std::fmt::Debug for SolveProgress {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("SolveProgress")
    }
}

impl PartialEq for SolveProgress {
    /// The same observer.
    fn eq(&self, other: &Self) -> bool {
        std::sync::Arc::ptr_eq(&self.0, &other.0)
    }
}

/// How a solve follows the load path from rest to the whole load.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Continuation {
    /// Force control (load steps, cut where they fail, a patient attempt past a limit point);
    /// where it finds no equilibrium, an arc-length continuation from its last one.
    #[default]
    Force,
    /// Arc length from rest (Riks; `docs/method.md` § 2.5): the body moved by steps of a set length, the
    /// load factor following; for a soft body that swings from where it is held.
    ArcLength,
    /// Force control alone: a solve that fails there fails at once (cheaper where failures are
    /// expected and a failed sample is dropped).
    ForceOnly,
}

impl SolverOptions {
    /// Checks the values: at least one load step and one iteration, tolerances finite and not
    /// negative (a residual tolerance above zero).
    pub fn validate(&self) -> Result<(), FemError> {
        let bad = |m: String| Err(FemError::Invalid(format!("solver: {m}")));
        if self.load_steps == 0 || self.max_iterations == 0 {
            return bad(format!(
                "load_steps = {} and max_iterations = {} must be at least 1",
                self.load_steps, self.max_iterations
            ));
        }
        if !(self.rtol > 0.0 && self.rtol.is_finite() && self.utol >= 0.0 && self.utol.is_finite()) {
            return bad(format!("rtol = {} must be > 0 and utol = {} >= 0, both finite", self.rtol, self.utol));
        }
        if self.rtol > MAX_RTOL {
            return bad(format!(
                "rtol = {} would take a residual cut by less than a hundred times as converged (at 1 the rest \
                 state, at 0.5 a neo-Hookean bar 11 % short): give at most {MAX_RTOL} (the default is 1e-6)",
                self.rtol
            ));
        }
        Ok(())
    }
}

/// The loosest relative residual tolerance a solve takes.
pub const MAX_RTOL: f64 = 1e-2;

impl Default for SolverOptions {
    fn default() -> Self {
        SolverOptions {
            load_steps: 1,
            max_iterations: 40,
            rtol: 1e-6,
            utol: 1e-6,
            line_search: true,
            max_step_cuts: 8,
            reuse_factorization: true,
            bfgs_memory: 12,
            continuation: Continuation::Force,
            confirm_snaps: false,
            deadline: None,
            progress: None,
        }
    }
}

/// Wall time spent in each phase of a solve.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct Timings {
    /// Element evaluation and assembly (forces and tangents).
    pub assembly: Duration,
    /// Numeric factorisations.
    pub factorization: Duration,
    /// Triangular solves and BFGS updates.
    pub solve: Duration,
    /// Whole solve.
    pub total: Duration,
}

/// The result of a static solve.
#[derive(Clone, Debug, Serialize)]
pub struct Solution {
    /// Displacement, 3 per node (m).
    pub u: Vec<f64>,
    /// Iterations (each one force evaluation and one solve) over all load steps.
    pub iterations: usize,
    /// Load steps taken (including halved ones that succeeded).
    pub load_steps: usize,
    /// Numeric factorisations performed.
    pub factorizations: usize,
    /// Tangent assemblies performed.
    pub tangent_assemblies: usize,
    /// Relative residual ‖r‖ / max(‖f_ext‖, ‖f_int‖) at each iterate, in order.
    pub residuals: Vec<f64>,
    /// Time split.
    pub timings: Timings,
    /// The load factor from which a load step found the next equilibrium far away, the response
    /// over it half as stiff as before or less: past a limit point the body snapped (or gave way)
    /// to another branch of the load path, where an arc-length continuation stops instead, or the
    /// path is that soft there. With [`SolverOptions::confirm_snaps`], such a step is followed
    /// again by arc length, and so is one whose stiffness fell after the path had stiffened (a
    /// short snap near its end): where the path turns back, the load factor of that limit point; where
    /// it reaches the step's end, `None` (loads that cannot be scaled alone, with prescribed
    /// displacements, keep the first answer). `None` otherwise.
    pub snapped_from: Option<f64>,
}

/// A reusable static solver: element geometry, sparse pattern and symbolic
/// factorisation are computed once; every solve reuses them.
pub struct StaticSolver {
    problem: Problem,
    geometry: ElementGeometry,
    pattern: Pattern,
    cholesky: SparseCholesky,
    /// What the rest slot's factor was computed with (material, springs).
    rest_key: Option<(Material, Vec<f64>, Vec<PointSpring>)>,
    constrained_nodes: Vec<usize>,
    /// The pieces of the mesh that must each be held (see [`Problem::check_held`]).
    pieces: Pieces,
    /// The constrained nodes alone hold the body against rigid motion (the set is frozen).
    held_by_constraints: bool,
    work: Workspace,
    values: Vec<f64>,
    /// A tangent assembly and factorisation, in iterations (see [`refactorization_cost`]).
    refactorization_cost: f64,
    /// The latest factor's tangent was assembled at an iterate far from equilibrium (see
    /// [`STALE_RESIDUAL`]).
    latest_stale: bool,
    /// The last warm-started solve on the latest factor took more iterations than a
    /// refactorisation costs (see [`StaticSolver::solve_from`]).
    latest_slow: bool,
    /// The total stiffness of the point springs the latest factor was made with (see
    /// [`SPRING_SCALE_CHANGE`]).
    latest_spring_stiffness: f64,
}

impl std::fmt::Debug for StaticSolver {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("StaticSolver")
            .field("dofs", &self.problem.num_dofs())
            .field("free", &self.pattern.num_free)
            .finish()
    }
}

/// The cost of assembling and factorising the tangent, in iterations (one
/// force evaluation with its line search, two triangular solves), estimated
/// from operation counts. An element kernel with its tangent ≈ 3 force
/// evaluations. Dense supernodal factorisation runs more multiply-adds per
/// second than the memory-bound element loops and triangular solves, the more
/// so the larger its supernodes: measured on 2 cores, ≈ 0.45 √c̄ times faster,
/// with c̄ = Σc² / Σc the mean column count of the factor (7× at 3.5k dofs, c̄ = 250;
/// 13× at 29k dofs, c̄ = 1,200).
fn refactorization_cost(geometry: &ElementGeometry, pattern: &Pattern, cholesky: &SparseCholesky) -> f64 {
    let points = (geometry.len() * geometry.points_per_element) as f64;
    let force = 300.0 * points + pattern.nnz() as f64;
    let (work, factor_nnz) = (cholesky.factorization_work(), cholesky.factor_nnz() as f64);
    let iteration = 1.5 * force + 4.0 * factor_nnz;
    let speed = (0.45 * (work / factor_nnz.max(1.0)).sqrt()).max(1.0);
    (3.0 * force + work / speed) / iteration
}

/// The margin, in iterations, by which the iterations left must exceed a
/// refactorisation's cost before one is made: a new factor does not remove the
/// nonlinearity, so the iterations after it are not free either. Tuned on the
/// bench cases among 4, 8, 12, 20, 40 and no margin: 40 gave the shortest cold
/// solves on the 5k and 50k liver and the beam, within 10 % of the best each.
const REFRESH_ITERATIONS: f64 = 40.0;

/// A factor is judged on the rate of convergence of this many iterations. The rest tangent's
/// factor of a cold solve that applies the whole load at once is judged on this many iterations
/// whose step the line search took in full, or on [`JUDGE_ANY`] iterations: a damped step
/// measures the nonlinearity of the load, not the factor, and the first iterations of such a
/// solve are damped whatever the factor. Judging other factors so made more work: the ROUKF's
/// load ramps 20 % more (more iterations for fewer refactorisations), the load-stepped 10 cm
/// solve of `liver_large.toml` 199 iterations and 52 factorisations instead of 137 and 26.
const JUDGE_ITERATIONS: usize = 2;

/// See [`JUDGE_ITERATIONS`].
const JUDGE_ANY: usize = 4;

/// A factor whose tangent was assembled at an iterate with a relative residual above this (far
/// from equilibrium: an early iterate of a cold solve) is not kept for the next warm-started
/// solve, which refactorises at its start instead. A factor assembled where a solve or a load
/// step starts is kept whatever the residual there: that state is in equilibrium under the
/// previous load. The load steps within a solve keep their factor (replacing it there made
/// `liver_large.toml` 165 iterations and 34 factorisations instead of 137 and 26).
/// Measured on the bench's frame sequences: 4.2–5.3 iterations per frame instead of 4.2–7.0,
/// for one refactorisation at the first frame.
const STALE_RESIDUAL: f64 = 0.1;

/// A kept factor made with point springs whose total stiffness differs from the current one by
/// more than this ratio is replaced at a warm start (the point springs themselves may change at
/// every solve, as a registration's data springs do; their scale is what makes the factor a good
/// or a poor preconditioner). A registration stiffens its data springs ×4 per iteration over the
/// first iterations of a frame: on the held-out press-and-release stream each solve then took 13
/// iterations on the factor made at the softest springs, and frames 1–3 took 46–69 ms instead of
/// about 25.
const SPRING_SCALE_CHANGE: f64 = 2.0;

/// About the iterations of a warm-started solve on a factor made at its start (2–3 on the
/// press-and-release stream). A warm-started solve that took more than this plus a
/// refactorisation's cost on a kept factor would have been cheaper on a new one; the next warm
/// start makes one. On the held-out stream (39 warm frames of 4 solves), counting a factorisation
/// as the 4.9 iterations it costs there: 874 iterations without this rule; 608 iterations and 5
/// factorisations with it (632 in all); 494 and 29 with a margin of 0 (636); 750 and 2 with a
/// margin of 5 (760).
const FRESH_FACTOR_ITERATIONS: f64 = 2.0;

/// An iteration sequence has stalled when its last [`STALL_ITERATIONS`] residuals all stay above
/// [`STALL_PROGRESS`] times the smallest one before them: the load step is then cut at once
/// instead of after `max_iterations`. On `liver_large.toml` one step had taken 40 iterations
/// (and 20 refactorisations) at relative residuals of 0.5–0.97, with line-search steps of
/// 0.01–0.5, before it was cut: now 194 iterations and 39 factorisations in all instead of
/// 191 and 51 (`liver_tool.toml`: 122 and 13 instead of 117 and 19). A window of 8 cut a step
/// that was converging slowly towards SVK's limit point in `liver_ar_grid.toml` (a dataset
/// sample failed); 9–16 did not. Both constants were chosen on these three scenarios.
const STALL_ITERATIONS: usize = 12;

/// See [`STALL_ITERATIONS`].
const STALL_PROGRESS: f64 = 0.9;

/// The iterations left to shrink a residual by `factor` at a `rate` of convergence per iteration
/// (infinite when it does not converge).
fn iterations_left(rate: f64, factor: f64) -> f64 {
    if rate < 1.0 {
        (factor.ln() / rate.ln()).max(0.0)
    } else {
        f64::INFINITY
    }
}

/// The force scale under which loads count as none, as a fraction of E L² (Young's modulus times
/// the body's squared diagonal): the force that strains the body by a millionth, moving it by
/// about a millionth of its size (0.2 µm on a 20 cm liver). Rounding leaves internal forces near
/// 1e-16 E L², well below the 1e-12 E L² that the default relative tolerance then asks for.
const FORCE_FLOOR: f64 = 1e-6;

/// Whether an iterate has converged: its relative residual `rel` under `rtol`, or under √rtol
/// after a last increment of length `step` (`None` before the first) under `utol` of `u`'s.
fn converged(opt: &SolverOptions, rel: f64, step: Option<f64>, u: &[f64]) -> bool {
    let small_step = step.is_some_and(|s| s <= opt.utol * norm(u).max(f64::MIN_POSITIVE));
    rel <= opt.rtol || (small_step && rel <= opt.rtol.sqrt())
}

/// Whether the residuals of an iteration sequence (relative, in order) have stalled.
fn stalled(residuals: &[f64]) -> bool {
    let Some(split) = residuals.len().checked_sub(STALL_ITERATIONS).filter(|&s| s > 0) else {
        return false;
    };
    let least = |r: &[f64]| r.iter().copied().fold(f64::INFINITY, f64::min);
    least(&residuals[split..]) > STALL_PROGRESS * least(&residuals[..split])
}

/// The predictor of a load step from `lambda` to `target`: the load path extrapolated linearly
/// from the last two converged states (`previous` at its load factor, `u` at `lambda`); `u`
/// itself when there is no earlier state at a smaller load factor.
fn predict(u: &[f64], previous: Option<&(f64, Vec<f64>)>, lambda: f64, target: f64) -> Vec<f64> {
    let mut trial = u.to_vec();
    if let Some((l0, u0)) = previous.filter(|(l0, _)| *l0 < lambda) {
        let ratio = (target - lambda) / (lambda - l0);
        trial.iter_mut().zip(u0).for_each(|(t, p)| *t += ratio * (*t - p));
    }
    trial
}

/// How many times the line search may halve its step because the trial state inverts an
/// element, besides its eight evaluations of the energy's slope: a Newton step of a soft organ
/// far from equilibrium may be a hundred times too long before the energy (infinite at
/// inversion) bounds it. On 100 draws of a real liver hanging from its back (0.5–3.5 N), with the
/// eight evaluations alone (α ≥ 1/128) 94 were solved, five failing on an inverted element;
/// with these halvings, 97.
const MAX_INVERSION_HALVINGS: usize = 30;

/// A load step that fails after this many cuts gets a patient attempt at once, instead of after
/// `max_step_cuts`. On the first 64 draws of `liver_forces_large` (every one solved either way,
/// to the same displacements within 3e-8 m), with the attempt after 8 / 2 / 1 cuts: 4,340 / 3,029
/// / 2,474 iterations and 1,257 / 660 / 502 factorisations. Four draws near a limit point had
/// crept towards it by ever shorter steps, each failing after its 12 stalled iterations, for up
/// to 839 iterations each.
const EARLY_PATIENT_CUTS: usize = 1;

/// Iterations of a patient attempt at a load step (see [`Budget::Patient`]). The AMOS liver's
/// quadratic mesh pushed by 1 N (the experiment crate's `tests/real_organs.rs`) stops at load
/// factor 0.918 under force control; with such attempts it solves, in 853 iterations.
const PATIENT_ITERATIONS: usize = 1000;

/// How many iterations a Newton sequence may take.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Budget {
    /// `max_iterations`, cut short when the residuals stall ([`stalled`]).
    Normal,
    /// [`PATIENT_ITERATIONS`], never cut short: the residual of a descent towards an equilibrium
    /// far away (a snap past a limit point) may stay flat for long while the energy falls.
    Patient,
}

/// The converged states of a load-stepped solve, as far as the load's work-conjugate
/// displacement q = f·u / |f| tells: how much the response has softened.
#[derive(Clone)]
struct LoadPath {
    /// The load at load factor 1, normalised (empty when there is none).
    direction: Vec<f64>,
    /// The stiffness dλ/dq at rest, from the linear response at rest ([`LoadPath::record_rest`]).
    rest: Option<f64>,
    /// (load factor, q) of the first and the last four converged states, the latest last.
    first: Option<(f64, f64)>,
    last: [Option<(f64, f64)>; 4],
}

impl LoadPath {
    fn new(load: Vec<f64>) -> Self {
        let size = norm(&load);
        let direction = if size > 0.0 { load.iter().map(|f| f / size).collect() } else { Vec::new() };
        LoadPath { direction, rest: None, first: None, last: [None; 4] }
    }

    /// The displacement q of the state `u`.
    fn measure(&self, u: &[f64]) -> f64 {
        if self.direction.is_empty() {
            norm(u)
        } else {
            dot(&self.direction, u)
        }
    }

    /// Records the converged state `u` at load factor `lambda`.
    fn record(&mut self, lambda: f64, u: &[f64]) {
        let q = self.measure(u);
        self.first.get_or_insert((lambda, q));
        self.last = [self.last[1], self.last[2], self.last[3], Some((lambda, q))];
    }

    /// Records `u`, the linear response at rest to load factor `lambda` (a solve's first Newton
    /// iterate from rest): the stiffness at rest, which the first step is measured against
    /// (a first step that snapped is no measure of it). The first such record is kept.
    fn record_rest(&mut self, lambda: f64, u: &[f64]) {
        let q = self.measure(u);
        if self.rest.is_none() && lambda > 0.0 && q != 0.0 {
            self.rest = Some(lambda / q);
        }
    }

    /// The stiffness dλ/dq at rest: the linear response's where recorded, otherwise the first
    /// step's.
    fn at_rest(&self) -> Option<f64> {
        self.rest.or(self.first.filter(|&(_, q)| q != 0.0).map(|(l, q)| l / q))
    }

    /// The stiffnesses dλ/dq of the step before the last (the stiffness at rest before the first
    /// step) and of the last step; `None` before a step, or before two where the stiffness at
    /// rest is unknown.
    fn steps(&self) -> Option<(f64, f64)> {
        match self.last {
            [.., None, Some(only)] => Some((self.rest?, secant((0.0, 0.0), only))),
            [_, before, Some(previous), Some(latest)] => {
                Some((secant(before.unwrap_or((0.0, 0.0)), previous), secant(previous, latest)))
            }
            _ => None,
        }
    }

    /// The stiffness dλ/dq of the last step over that at rest, in per cent; NaN where either is
    /// unknown (before a step; before two where the stiffness at rest was not recorded).
    fn softening(&self) -> f64 {
        match (self.at_rest(), self.steps()) {
            (Some(rest), Some((_, latest))) if latest.is_finite() => 100.0 * latest / rest,
            _ => f64::NAN,
        }
    }

    /// The failure of force control to find an equilibrium beyond `load_factor` (after
    /// `iterations`), with the path's softening there.
    fn no_equilibrium(&self, load_factor: f64, iterations: usize) -> FemError {
        FemError::NoEquilibrium { load_factor, softening: self.softening(), indefinite: false, iterations }
    }

    /// Whether the last step found its equilibrium far away, past a limit point: its stiffness
    /// under [`crate::LIMIT_POINT_STIFFNESS`] per cent of that at rest and under half the step's
    /// before it (a path that softens gradually does not). A first step's stiffness, its secant
    /// from rest, averages the stiff stretch before a limit point with the snap: under half the
    /// stiffness at rest is enough.
    fn snapped(&self) -> bool {
        let Some((previous, latest)) = self.steps() else { return false };
        let first = self.last[2].is_none();
        (first || self.softening() < crate::LIMIT_POINT_STIFFNESS) && previous > 0.0 && latest < 0.5 * previous
    }

    /// Whether the last step may have passed a limit point close to its end: the path far softer
    /// than at rest (under [`crate::LIMIT_POINT_STIFFNESS`] per cent), its last step under
    /// [`TURN_FALL`] times as stiff as the step before, which had stiffened on the one before it.
    /// A short snap does so, softening its step less than [`LoadPath::snapped`] asks (the AMOS
    /// liver of the experiments' real-organ tests pushed by 1 N in 7 steps: 0.56 times the step
    /// before, its limit point at load factor 0.970 in the step from 0.938), and so does a path with an inflection: a sign
    /// that only a check by arc length makes a snap.
    fn turned(&self) -> bool {
        let [Some(a), Some(b), Some(c), Some(d)] = self.last else { return false };
        let (earlier, previous, latest) = (secant(a, b), secant(b, c), secant(c, d));
        self.softening() < crate::LIMIT_POINT_STIFFNESS
            && earlier > 0.0
            && previous > earlier
            && latest < TURN_FALL * previous
    }
}

/// The stiffness dλ/dq of the path from the state (λ₀, q₀) to (λ₁, q₁).
fn secant((l0, q0): (f64, f64), (l1, q1): (f64, f64)) -> f64 {
    (l1 - l0) / (q1 - q0)
}

/// How far a load step's stiffness falls below the step's before it, which had stiffened, for an
/// arc-length check of a limit point within it ([`LoadPath::turned`]).
const TURN_FALL: f64 = 0.8;

/// Between two iterations: the advance told ([`SolverOptions::progress`]), then
/// [`FemError::OutOfTime`] once the solve's [`SolverOptions::deadline`] has passed.
fn between_iterations(options: &SolverOptions, stats: &Stats) -> Result<(), FemError> {
    if let Some(progress) = &options.progress {
        (progress.0)(stats.reached, stats.iterations);
    }
    match options.deadline {
        Some(deadline) if Instant::now() >= deadline => Err(FemError::OutOfTime),
        _ => Ok(()),
    }
}

/// Euclidean norm.
pub fn norm(v: &[f64]) -> f64 {
    dot(v, v).sqrt()
}

/// Dot product.
fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

impl StaticSolver {
    /// [`StaticSolver::new`], its factorisations on one thread however large: its solutions do not
    /// depend on the number of threads, bit for bit. For many solves side by side (a dataset's
    /// draws), which fill the threads without help.
    pub fn single_threaded(problem: Problem) -> Result<Self, FemError> {
        let mut solver = StaticSolver::new(problem)?;
        solver.cholesky.set_single_threaded()?;
        Ok(solver)
    }

    /// Prepares geometry, pattern and symbolic factorisation for the problem.
    pub fn new(problem: Problem) -> Result<Self, FemError> {
        problem.validate()?;
        let geometry = ElementGeometry::new(&problem.mesh, problem.material.resolved_formulation())?;
        let mut constrained = vec![false; problem.num_dofs()];
        for &n in problem.dirichlet.keys() {
            constrained[3 * n..3 * n + 3].fill(true);
        }
        let mut pattern = Pattern::new(&geometry, problem.num_dofs(), &constrained)?;
        let cholesky = SparseCholesky::new(&mut pattern)?;
        let refactorization_cost = refactorization_cost(&geometry, &pattern, &cholesky);
        let values = written_zeros(pattern.nnz());
        let work = Workspace::for_pattern(&geometry, &pattern);
        let constrained_nodes = problem.dirichlet.keys().copied().collect();
        let pieces = Pieces::of(&problem.mesh);
        let held_by_constraints = problem.held_by_constraints(&pieces);
        Ok(StaticSolver {
            problem,
            geometry,
            pattern,
            cholesky,
            rest_key: None,
            constrained_nodes,
            pieces,
            held_by_constraints,
            work,
            values,
            refactorization_cost,
            latest_stale: false,
            latest_slow: false,
            latest_spring_stiffness: 0.0,
        })
    }

    /// The force below which the residual is measured against this floor rather than the loads
    /// ([`FORCE_FLOOR`] of Young's modulus times the body's squared size): under a load at the
    /// level of rounding (a registration's cloud that is the organ at rest, given in another
    /// unit), the relative residual is rounding noise and no iteration can bring it down.
    fn force_floor(&self) -> f64 {
        let (lo, hi) = self.problem.mesh.bounds();
        let size2: f64 = (0..3).map(|d| (hi[d] - lo[d]).powi(2)).sum();
        FORCE_FLOOR * self.problem.material.young.abs() * size2
    }

    /// The problem being solved.
    pub fn problem(&self) -> &Problem {
        &self.problem
    }

    /// Mutable access to the problem: material, springs, loads and prescribed
    /// values may change between solves; the set of constrained nodes may not.
    pub fn problem_mut(&mut self) -> &mut Problem {
        &mut self.problem
    }

    /// The element geometry.
    pub fn geometry(&self) -> &ElementGeometry {
        &self.geometry
    }

    /// The fill-reducing ordering of the tangent's factorisations.
    pub fn ordering(&self) -> Ordering {
        self.cholesky.ordering()
    }

    /// Number of free dofs and stored non-zeros of the tangent.
    pub fn system_size(&self) -> (usize, usize) {
        (self.pattern.num_free, self.pattern.nnz())
    }

    /// Internal force f_int(u) + K_s u over all dofs (springs included; a point spring's pull
    /// towards its target counts as an external load).
    pub fn internal_force(&mut self, u: &[f64]) -> Result<Vec<f64>, FemError> {
        let mut f = vec![0.0; u.len()];
        self.evaluate(u, &mut f, false).map_err(|e| e.in_file_numbers(&self.problem.mesh))?;
        Ok(f)
    }

    /// Whether the tangent stiffness at `u` (an equilibrium a solve found) is positive definite:
    /// a stable equilibrium. An indefinite one is unstable (past a bifurcation: a straight column
    /// pressed beyond its buckling load, which a disturbance would bend). One assembly and
    /// factorisation, kept as the solver's latest factor.
    pub fn stable_at(&mut self, u: &[f64]) -> Result<bool, FemError> {
        let mut f_int = vec![0.0; u.len()];
        let mut stats = Stats::default();
        self.refactorize(u, &mut f_int, false, &mut stats)?;
        Ok(!stats.indefinite)
    }

    /// The forces the supports exert on the body at `u` (N, 3 per node): a node's springs (node
    /// springs, −k u, and point springs, −Σ w K (x − t): an attachment's foundation) and at a held
    /// dof (fixed or prescribed) the hold, f_int − f_ext less the springs' part (CalculiX's RF
    /// there, where no spring acts on the node and no load: its RF is f_int alone); zero
    /// elsewhere. At an equilibrium they balance the
    /// loads: Σ R = −Σ f_ext.
    pub fn reaction_forces(&mut self, u: &[f64]) -> Result<Vec<f64>, FemError> {
        // `internal_force` holds the springs' k u and K x, `loads` the point springs' pull K t.
        let (f_int, loads) = (self.internal_force(u)?, self.loads());
        let p = &self.problem;
        let mut reaction: Vec<f64> = (0..u.len()).map(|dof| -p.springs[dof / 3] * u[dof]).collect();
        for s in &p.point_springs {
            let mut x = [0.0; 3];
            for &(n, w) in &s.nodes {
                (0..3).for_each(|d| x[d] += w * u[3 * n + d]);
            }
            let pull = s.stiffness_times(mesh::sub(x, s.target));
            for &(n, w) in &s.nodes {
                (0..3).for_each(|d| reaction[3 * n + d] -= w * pull[d]);
            }
        }
        for (dof, r) in reaction.iter_mut().enumerate().filter(|(dof, _)| self.pattern.free_index[*dof] == u32::MAX) {
            *r += f_int[dof] - loads[dof];
        }
        Ok(reaction)
    }

    /// The free-dof tangent at u as a dense matrix (for tests and small problems).
    pub fn tangent_dense(&mut self, u: &[f64]) -> Result<Vec<Vec<f64>>, FemError> {
        let mut f = vec![0.0; u.len()];
        self.evaluate(u, &mut f, true)?;
        let n = self.pattern.num_free;
        let mut k = vec![vec![0.0; n]; n];
        for (c, column) in self.pattern.col_ptr.windows(2).enumerate() {
            for p in column[0] as usize..column[1] as usize {
                let r = self.pattern.row_idx[p] as usize;
                k[r][c] = self.values[p];
                k[c][r] = self.values[p];
            }
        }
        Ok(k)
    }

    /// Global dof → free index (`None` when constrained).
    pub fn free_index(&self, dof: usize) -> Option<usize> {
        let i = self.pattern.free_index[dof];
        (i != u32::MAX).then_some(i as usize)
    }

    /// The free dofs' values of a vector over all dofs.
    fn free_part(&self, full: &[f64]) -> Vec<f64> {
        let mut free = vec![0.0; self.pattern.num_free];
        for (dof, value) in full.iter().enumerate() {
            if let Some(i) = self.free_index(dof) {
                free[i] = *value;
            }
        }
        free
    }

    /// `full += scale × free` on the free dofs.
    fn add_free(&self, full: &mut [f64], free: &[f64], scale: f64) {
        for (dof, value) in full.iter_mut().enumerate() {
            if let Some(i) = self.free_index(dof) {
                *value += scale * free[i];
            }
        }
    }

    /// Keeps the first Newton iterate from rest, `u + du` at load factor `lambda`: the linear
    /// response at rest ([`LoadPath::record_rest`]), the first only.
    fn keep_rest_response(&self, u: &[f64], du: &[f64], lambda: f64, stats: &mut Stats) {
        if stats.rest_response.is_none() {
            let mut first = u.to_vec();
            self.add_free(&mut first, du, 1.0);
            stats.rest_response = Some((lambda, first));
        }
    }

    fn evaluate(&mut self, u: &[f64], f: &mut [f64], tangent: bool) -> Result<(), FemError> {
        crate::interrupt::check()?;
        let values = tangent.then_some(self.values.as_mut_slice());
        assemble(&self.geometry, &self.pattern, &self.problem.material, u, f, values, &mut self.work)?;
        for (n, &k) in self.problem.springs.iter().enumerate().filter(|(_, k)| **k != 0.0) {
            for d in 0..3 {
                f[3 * n + d] += k * u[3 * n + d];
                if let (true, Some(i)) = (tangent, self.free_index(3 * n + d)) {
                    self.values[self.pattern.diag(i)] += k;
                }
            }
        }
        for s in &self.problem.point_springs {
            // K x, K = k I + k_n n nᵀ (the target's pull K t is an external load: see `loads`).
            let mut r = [0.0; 3];
            for &(n, w) in &s.nodes {
                (0..3).for_each(|d| r[d] += w * u[3 * n + d]);
            }
            let kr = s.stiffness_times(r);
            for &(n, w) in &s.nodes {
                (0..3).for_each(|d| f[3 * n + d] += w * kr[d]);
            }
            if !tangent {
                continue;
            }
            for &(a, wa) in &s.nodes {
                for &(b, wb) in &s.nodes {
                    for p in 0..3 {
                        for q in 0..3 {
                            let (Some(row), Some(col)) = (self.free_index(3 * a + p), self.free_index(3 * b + q))
                            else {
                                continue;
                            };
                            // Each stored (lower) entry once: from the ordered pair with row ≥ col.
                            if row < col {
                                continue;
                            }
                            let k = f64::from(p == q) * s.stiffness + s.normal_stiffness * s.normal[p] * s.normal[q];
                            if let Some(position) = self.pattern.find(row, col) {
                                self.values[position] += wa * wb * k;
                            }
                        }
                    }
                }
            }
        }
        Ok(())
    }

    /// The external load at load factor 1: the nodal forces and the point springs' pull towards
    /// their targets (Σ w_j K t on each node j), so that load stepping scales both.
    fn loads(&self) -> Vec<f64> {
        let mut f = self.problem.f_ext.clone();
        for s in &self.problem.point_springs {
            let kt = s.stiffness_times(s.target);
            for &(n, w) in &s.nodes {
                (0..3).for_each(|d| f[3 * n + d] += w * kt[d]);
            }
        }
        f
    }

    /// The linear response at rest: overwrites `f` (a load on every dof) with `u = K₀⁻¹ f`, `K₀` the
    /// tangent at `u = 0` with the springs (the rest factor, made in double precision when not
    /// current and kept); constrained dofs get 0. An error when `K₀` is not positive definite.
    pub fn rest_solve(&mut self, f: &mut [f64]) -> Result<(), FemError> {
        if f.len() != self.problem.num_dofs() {
            return Err(FemError::Invalid(format!(
                "a load of {} values for {} dofs",
                f.len(),
                self.problem.num_dofs()
            )));
        }
        if !(self.rest_factor_current() && self.cholesky.is_double(Slot::Rest)) {
            self.rest_key = None;
            self.cholesky.set_double_precision(true);
            let made = self.prepare_rest_factor(&mut Stats::default());
            self.cholesky.set_double_precision(false);
            made?;
        }
        if !self.cholesky.is_double(Slot::Rest) {
            return Err(FemError::Factorization("the tangent at rest is not positive definite".into()));
        }
        let mut free = self.free_part(f);
        self.cholesky.solve_in_place(Slot::Rest, &mut free)?;
        for (dof, value) in f.iter_mut().enumerate() {
            *value = self.free_index(dof).map_or(0.0, |i| free[i]);
        }
        Ok(())
    }

    /// Solves from the rest configuration.
    pub fn solve(&mut self, options: &SolverOptions) -> Result<Solution, FemError> {
        self.solve_from(None, options)
    }

    /// Solves from a warm start `u0` (e.g. the previous frame's solution) when
    /// given: the full load is applied at once from `u0`; if that fails, the
    /// solve restarts from rest with load stepping. A warm start keeps the
    /// latest factor unless it was made far from equilibrium, with point
    /// springs of another scale, or the last warm start on it took more
    /// iterations than a refactorisation costs (over a stream of solves a
    /// factor made at another state costs more and more iterations).
    pub fn solve_from(&mut self, u0: Option<&[f64]>, options: &SolverOptions) -> Result<Solution, FemError> {
        let start = Instant::now();
        // The whole solve runs on a rayon worker (in place when called from one), so that each
        // parallel assembly starts at once on the solving thread, the other workers joining as
        // they wake. Called from outside the pool, every assembly would instead wait for a
        // sleeping worker to wake: on the 2-core bench host, one assembly in three then ran on
        // a single thread, and solves from rest of the 5k-tet liver took 15 % longer (F-bar
        // 25.4 against 21.8 ms, standard 15.2 against 13.1 ms, medians of 60).
        rayon::scope(|_| self.solve_on_worker(u0, options, start)).map_err(|e| e.in_file_numbers(&self.problem.mesh))
    }

    /// [`StaticSolver::solve_from`] on the current thread; its time counts from `start`.
    fn solve_on_worker(
        &mut self,
        u0: Option<&[f64]>,
        options: &SolverOptions,
        start: Instant,
    ) -> Result<Solution, FemError> {
        options.validate()?;
        self.check_problem()?;
        self.cholesky.forget_history();
        let ndof = self.problem.num_dofs();
        let mut stats = Stats::default();
        if let Some(u0) = u0 {
            if let Some(u) = self.warm_attempt(u0, options, &mut stats)? {
                return Ok(stats.finish(u, 1, start));
            }
        }
        // The latest factor is that of a converged state (or none): a failed
        // attempt leaves one of a state that is no use as a preconditioner.
        let mut latest_converged = u0.is_none();
        let mut u = vec![0.0; ndof];
        let mut previous: Option<(f64, Vec<f64>)> = None;
        let mut lambda = 0.0;
        let full_step = 1.0 / options.load_steps as f64;
        let mut step = full_step;
        let smallest_step = full_step * 0.5f64.powi(options.max_step_cuts.min(60) as i32);
        let mut cuts = 0;
        let mut steps = 0;
        let mut path = LoadPath::new(self.loads());
        if options.continuation == Continuation::ArcLength {
            if !self.arc_length_applies() {
                return Err(FemError::Invalid(
                    "an arc-length continuation scales loads, not prescribed displacements".into(),
                ));
            }
            return match self.arc_length(&mut u, &mut lambda, 1.0, &mut path, options, &mut stats) {
                Ok(steps) => Ok(stats.finish(u, steps, start)),
                Err(e) => Err(self.diagnose(e, lambda, &u, &u, &stats)),
            };
        }
        // Whether the early patient attempt is still to be made; the last failed patient attempt
        // (the load factor it started from, its iterations).
        let (mut early_patient, mut patient_failed) = (true, None);
        while lambda < 1.0 {
            let target = (lambda + step).min(1.0);
            let tried = target - lambda;
            let mut trial = predict(&u, previous.as_ref(), lambda, target);
            // Start from the rest tangent unless this solve already refactorised
            // at a converged state; after a failure, from a new tangent at the last
            // converged state.
            let from = match (stats.refactorized && latest_converged, lambda > 0.0) {
                (true, _) => Start::Kept,
                (false, true) => Start::Fresh,
                (false, false) => Start::Rest,
            };
            let mut attempt = self.newton(&mut trial, target, from, options, Budget::Normal, &mut stats);
            // Near a limit point of the load path, a step cut once fails again. Past it the body
            // snaps to an equilibrium far away, which a descent may need hundreds of iterations to
            // reach, and which ever shorter steps only creep towards: a patient attempt at the
            // step that failed, once early (see [`EARLY_PATIENT_CUTS`]), and as the last resort
            // when the smallest step (a whole one halved `max_step_cuts` times) failed. Not a
            // longer step: a descent over more of the load may leave the path where it is soft
            // and end on another branch (`docs/method.md` § 2.5).
            let last_resort = tried <= 1.5 * smallest_step;
            let retry = patient_failed.is_none_or(|(at, _)| at != lambda);
            let patient = attempt.is_err()
                && lambda > 0.0
                && ((cuts >= EARLY_PATIENT_CUTS && early_patient) || (last_resort && retry));
            if patient {
                early_patient = false;
                trial.copy_from_slice(&u);
                let before = stats.iterations;
                attempt = self.newton(&mut trial, target, Start::Fresh, options, Budget::Patient, &mut stats);
                if attempt.is_err() {
                    patient_failed = Some((lambda, stats.iterations - before));
                }
            }
            match attempt {
                Ok(()) => {
                    latest_converged =
                        self.record_step(&mut path, (lambda, &u), (target, &trial), options, &mut stats)?;
                    previous = Some((lambda, std::mem::replace(&mut u, trial)));
                    lambda = target;
                    stats.reached = lambda;
                    steps += 1;
                    // Grow back towards the requested step after a cut.
                    step = if patient { full_step } else { (2.0 * step).min(full_step) };
                    cuts = 0;
                }
                Err(
                    e @ (FemError::NotConverged { .. } | FemError::InvertedElement { .. } | FemError::Factorization(_)),
                ) if !last_resort => {
                    latest_converged = false;
                    cuts += 1;
                    // Half the step tried (shorter than `step` where the end of the load clipped it).
                    step = 0.5 * tried;
                    // Iterations that did not converge may have been held back by a single-precision
                    // factor too inaccurate for the tangent's conditioning: the retries factorise in
                    // double precision (the load's nonlinearity is what the cut itself addresses).
                    if matches!(e, FemError::NotConverged { .. }) {
                        self.cholesky.set_double_precision(true);
                    }
                }
                Err(e @ (FemError::NotConverged { .. } | FemError::InvertedElement { .. })) => {
                    let failure = match patient_failed {
                        Some((at, iterations)) => path.no_equilibrium(at, iterations),
                        None => e,
                    };
                    return match self.past_force_control(failure, &mut u, &mut lambda, &mut path, options, &mut stats) {
                        Ok(arc_steps) => Ok(stats.finish(u, steps + arc_steps, start)),
                        // Saint-Venant-Kirchhoff's own limit point is told as such.
                        Err(e) => Err(self.diagnose(e, lambda, &trial, &u, &stats)),
                    };
                }
                Err(e) => return Err(self.diagnose(e, lambda, &trial, &u, &stats)),
            }
        }
        Ok(stats.finish(u, steps, start))
    }

    /// Where force control found no equilibrium beyond load factor `lambda` (`failure`), the
    /// path followed on by arc length from the last one, `u` (see [`continuation`]): the steps it
    /// took; `failure` where the continuation is not to be made, does not apply or made no step.
    fn past_force_control(
        &mut self,
        failure: FemError,
        u: &mut Vec<f64>,
        lambda: &mut f64,
        path: &mut LoadPath,
        options: &SolverOptions,
        stats: &mut Stats,
    ) -> Result<usize, FemError> {
        if options.continuation != Continuation::Force || !self.arc_length_applies() {
            return Err(failure);
        }
        let (from, indefinite) = (*lambda, stats.indefinite);
        match self.arc_length(u, lambda, 1.0, path, options, stats) {
            // Not a step further: force control's own failure says more (a tolerance below
            // round-off, too few iterations allowed), and what its last attempt found.
            Err(FemError::NoEquilibrium { load_factor, .. }) if load_factor <= from => {
                stats.indefinite = indefinite;
                Err(failure)
            }
            other => other,
        }
    }

    /// Records force control's step from the equilibrium `u` at load factor `lambda` to `trial` at
    /// `target` on the load `path`; where it softened as a snap does ([`LoadPath::snapped`]) and
    /// no snap was told yet, tells it ([`Solution::snapped_from`]): checked by arc length with
    /// [`SolverOptions::confirm_snaps`] where the loads can be scaled alone, which also checks a
    /// step that fell after the path had stiffened ([`LoadPath::turned`]). Returns whether the
    /// latest factor is still that of a converged state (a check factorises along its own path).
    fn record_step(
        &mut self,
        path: &mut LoadPath,
        (lambda, u): (f64, &[f64]),
        (target, trial): (f64, &[f64]),
        options: &SolverOptions,
        stats: &mut Stats,
    ) -> Result<bool, FemError> {
        if let Some((at, first)) = stats.rest_response.take() {
            path.record_rest(at, &first);
        }
        path.record(target, trial);
        let checked = options.confirm_snaps && self.arc_length_applies();
        if stats.snapped_from.is_some() || !(path.snapped() || checked && path.turned()) {
            return Ok(true);
        }
        if !checked {
            stats.snapped_from = Some(lambda);
            return Ok(true);
        }
        stats.snapped_from = self.limit_point_between(u, lambda, target, path, options, stats)?;
        Ok(false)
    }

    /// Whether force control's step from the equilibrium `u` at load factor `lambda` to `target`,
    /// seen to soften as a snap does ([`LoadPath::snapped`]), passed a limit point: the path
    /// followed by arc length from `u` turns back before `target`, at the load factor returned, or
    /// reaches it (`None`: the path is that soft there, and the body follows it without
    /// snapping).
    fn limit_point_between(
        &mut self,
        u: &[f64],
        lambda: f64,
        target: f64,
        path: &LoadPath,
        options: &SolverOptions,
        stats: &mut Stats,
    ) -> Result<Option<f64>, FemError> {
        let (mut along, mut reached, indefinite) = (u.to_vec(), lambda, stats.indefinite);
        let followed = self.arc_length(&mut along, &mut reached, target, &mut path.clone(), options, stats);
        stats.indefinite = indefinite;
        match followed {
            Ok(_) => Ok(None),
            Err(FemError::NoEquilibrium { load_factor, .. }) => Ok(Some(load_factor)),
            // A check that could not be made keeps what the softening said.
            Err(FemError::NotConverged { .. } | FemError::InvertedElement { .. } | FemError::Factorization(_)) => {
                Ok(Some(lambda))
            }
            Err(e) => Err(e),
        }
    }

    /// The whole load applied at once from the warm start `u0`: the equilibrium, or `None` where
    /// the attempt failed.
    fn warm_attempt(
        &mut self,
        u0: &[f64],
        options: &SolverOptions,
        stats: &mut Stats,
    ) -> Result<Option<Vec<f64>>, FemError> {
        let ndof = self.problem.num_dofs();
        if u0.len() != ndof || u0.iter().any(|v| !v.is_finite()) {
            return Err(FemError::Invalid(format!("warm start must hold {ndof} finite values")));
        }
        let mut u = u0.to_vec();
        // A kept factor assembled far from equilibrium, or with point springs of another
        // scale, is replaced by one at the warm start.
        let from = if self.latest_stale || self.latest_slow || self.spring_scale_changed() {
            Start::Fresh
        } else {
            Start::Kept
        };
        match self.newton(&mut u, 1.0, from, options, Budget::Normal, stats) {
            Err(FemError::OutOfTime) => return Err(FemError::OutOfTime),
            Err(_) => return Ok(None),
            Ok(()) => {}
        }
        self.latest_slow =
            !stats.refactorized && stats.iterations as f64 > self.refactorization_cost + FRESH_FACTOR_ITERATIONS;
        Ok(Some(u))
    }

    /// Checks the problem (valid, every piece held) and that its constrained nodes and element
    /// formulation are still those the solver was built for.
    fn check_problem(&self) -> Result<(), FemError> {
        self.problem.validate()?;
        if !self.held_by_constraints {
            self.problem.check_held(&self.pieces)?;
        }
        if !self.problem.dirichlet.keys().copied().eq(self.constrained_nodes.iter().copied()) {
            return Err(FemError::Invalid("the set of constrained nodes changed after the solver was built".into()));
        }
        if self.problem.material.resolved_formulation() != self.geometry.formulation {
            return Err(FemError::Invalid("the element formulation changed after the solver was built".into()));
        }
        Ok(())
    }

    /// Turns the failure of a solve by compression into what it is ([`compression_failure`]).
    /// `lambda` is the last converged load factor, `trial` the failing iterate and `u` the last
    /// converged state.
    fn diagnose(&self, error: FemError, lambda: f64, trial: &[f64], u: &[f64], stats: &Stats) -> FemError {
        let law = self.problem.material.law;
        if !matches!(law, Law::Svk | Law::Corotational) || matches!(error, FemError::Interrupted | FemError::OutOfTime)
        {
            return error;
        }
        // The smallest principal stretch of a state, and the element where it is.
        let most_compressed = |state: &[f64]| -> Option<(usize, f64)> {
            post::over_compressed_cells(&self.geometry, self.problem.material.law, state).ok()?.1
        };
        // Whether the iterate that failed went past the limit; told of the last equilibrium, which
        // does not depend on how far the failed iterate strayed.
        let Some((_, strayed)) = most_compressed(trial).or_else(|| most_compressed(u)) else { return error };
        // With no load step converged the last equilibrium is the rest state: the failing
        // iterate tells where the body gave way.
        let at = if lambda > 0.0 { most_compressed(u) } else { most_compressed(trial) };
        compression_failure(law, stats.indefinite, strayed, at, lambda).unwrap_or(error)
    }

    /// Iterations at load factor `lambda`, updating `u` in place.
    fn newton(
        &mut self,
        u: &mut [f64],
        lambda: f64,
        from: Start,
        opt: &SolverOptions,
        budget: Budget,
        stats: &mut Stats,
    ) -> Result<(), FemError> {
        let ndof = u.len();
        stats.indefinite = false;
        for (&n, v) in &self.problem.dirichlet {
            for d in 0..3 {
                u[3 * n + d] = lambda * v[d];
            }
        }
        let f_ext: Vec<f64> = self.loads().iter().map(|f| lambda * f).collect();
        let ext_norm = norm(&f_ext).max(self.force_floor());
        let mut f_int = vec![0.0; ndof];
        let nf = self.pattern.num_free;
        let mut r = vec![0.0; nf];
        let t = Instant::now();
        self.evaluate(u, &mut f_int, false)?;
        stats.timings.assembly += t.elapsed();
        let mut res = self.residual(&f_int, &f_ext, &mut r);
        let mut du = vec![0.0; nf];
        let mut r_old = vec![0.0; nf];
        let mut trial = u.to_vec();
        let mut bfgs = Bfgs::new(if opt.reuse_factorization { opt.bfgs_memory } else { 0 });
        // The first factor: the rest tangent's (kept while the material and springs are unchanged,
        // it serves every solve from rest), or the last factor computed. A warm start without a
        // last factor takes the rest factor only while it is current: one to be made anew is made
        // at the warm start instead, where it is a better preconditioner, and kept (the springs of
        // a registration change at every solve: a rest factor made for each would never serve).
        let latest = self.cholesky.is_factorized(Slot::Latest);
        let want_rest = from == Start::Rest || (!latest && self.rest_factor_current());
        let mut slot = Slot::Latest;
        if want_rest && opt.reuse_factorization && self.prepare_rest_factor(stats)? {
            slot = Slot::Rest;
        }
        let mut refresh = from == Start::Fresh || !(slot == Slot::Rest || (opt.reuse_factorization && latest));
        let (mut last_ratio, mut since_refresh, mut undamped) = (1.0f64, 0usize, 0usize);
        let first_residual = stats.residuals.len();
        let (last_iteration, stall_rule) = match budget {
            Budget::Normal => (opt.max_iterations, true),
            Budget::Patient => (PATIENT_ITERATIONS, false),
        };
        for it in 0..=last_iteration {
            let scale = ext_norm.max(norm(&f_int));
            let rel = if scale > 0.0 { res / scale } else { 0.0 };
            stats.residuals.push(rel);
            if !rel.is_finite() {
                return Err(FemError::NonFinite(format!("residual at iteration {it}")));
            }
            if converged(opt, rel, (it > 0).then(|| norm(&du)), u) {
                return Ok(());
            }
            if it == last_iteration || (stall_rule && stalled(&stats.residuals[first_residual..])) {
                return Err(FemError::NotConverged { load_factor: lambda, iterations: it, residual: rel });
            }
            between_iterations(opt, stats)?;
            stats.iterations += 1;
            if refresh {
                self.refactorize(u, &mut f_int, it > 0 && rel > STALE_RESIDUAL, stats)?;
                bfgs.clear();
                refresh = !opt.reuse_factorization;
                slot = Slot::Latest;
            }
            let t = Instant::now();
            du.iter_mut().zip(&r).for_each(|(d, r)| *d = -r);
            let cholesky = &mut self.cholesky;
            bfgs.apply(&mut du, |v| cholesky.solve_in_place(slot, v))?;
            stats.timings.solve += t.elapsed();
            if from == Start::Rest && it == 0 {
                self.keep_rest_response(u, &du, lambda, stats);
            }
            r_old.copy_from_slice(&r);
            let alpha = self.line_search(u, &du, &mut trial, &mut f_int, &f_ext, &mut r, opt, stats)?;
            let res_new = norm(&r);
            if alpha != 1.0 {
                du.iter_mut().for_each(|d| *d *= alpha);
            }
            // Refactorise when the iterations left at the rate of the last two
            // would cost more than a refactorisation plus a few iterations. The
            // costs are estimated from operation counts, not timed, so that the
            // path of a solve (and its last bits) never depends on the machine's load.
            let ratio = res_new / res;
            since_refresh += 1;
            undamped += usize::from(alpha == 1.0);
            let judged = if slot == Slot::Rest && lambda == 1.0 {
                undamped >= JUDGE_ITERATIONS || since_refresh >= JUDGE_ANY
            } else {
                since_refresh >= JUDGE_ITERATIONS
            };
            if opt.reuse_factorization && judged {
                let left =
                    iterations_left((ratio * last_ratio).sqrt(), opt.rtol * ext_norm.max(norm(&f_int)) / res_new);
                // Iterations whose residual does not shrink (far from equilibrium, near a limit
                // point) tell nothing of what a new factor would save: one is made only once the
                // iterations on the last have cost as much, so that factorisations take at most
                // about half the time. Refactorising after every `JUDGE_ITERATIONS` of them made
                // factorisations ≈ 80 % of the time of the draws of `liver_forces_large` near a
                // limit point. On its first 64 draws (every one solved, to the same displacements):
                // 2,815 iterations and 393 factorisations instead of 2,474 and 502, in 25 % less
                // time (one run after the other on the same host).
                let due = left.is_finite() || since_refresh as f64 >= self.refactorization_cost;
                if due && left > self.refactorization_cost + REFRESH_ITERATIONS {
                    refresh = true;
                    since_refresh = 0;
                }
            }
            last_ratio = ratio;
            let t = Instant::now();
            bfgs.push(&du, &r, &r_old);
            stats.timings.solve += t.elapsed();
            res = res_new;
            u.copy_from_slice(&trial);
        }
        unreachable!("the loop returns at its last iteration")
    }

    /// Assembles the tangent at `u` (and the internal force into `f_int`) and factorises it into
    /// the latest slot; `stale`: the iterate is far from equilibrium (see [`STALE_RESIDUAL`]).
    fn refactorize(&mut self, u: &[f64], f_int: &mut [f64], stale: bool, stats: &mut Stats) -> Result<(), FemError> {
        let t = Instant::now();
        self.evaluate(u, f_int, true)?;
        stats.tangent_assemblies += 1;
        stats.timings.assembly += t.elapsed();
        let t = Instant::now();
        self.latest_stale = stale;
        self.latest_spring_stiffness = self.problem.point_spring_stiffness();
        self.latest_slow = false;
        self.cholesky.factorize(Slot::Latest, &self.values)?;
        stats.indefinite |= !self.cholesky.is_positive_definite(Slot::Latest);
        stats.refactorized = true;
        stats.factorizations += 1;
        stats.timings.factorization += t.elapsed();
        Ok(())
    }

    /// Whether the point springs' total stiffness left the range of [`SPRING_SCALE_CHANGE`]
    /// around the one the latest factor was made with.
    fn spring_scale_changed(&self) -> bool {
        let (now, then) = (self.problem.point_spring_stiffness(), self.latest_spring_stiffness);
        now > SPRING_SCALE_CHANGE * then || then > SPRING_SCALE_CHANGE * now
    }

    /// Whether the rest-state factor was made with the current material and springs.
    fn rest_factor_current(&self) -> bool {
        let p = &self.problem;
        self.rest_key.as_ref().is_some_and(|(material, springs, point_springs)| {
            *material == p.material && *springs == p.springs && *point_springs == p.point_springs
        })
    }

    /// Makes sure the rest-state factor matches the current material and springs,
    /// factorising the tangent at u = 0 if not. Returns false when the rest
    /// tangent is not positive definite (then it is no use as a preconditioner).
    fn prepare_rest_factor(&mut self, stats: &mut Stats) -> Result<bool, FemError> {
        if self.rest_factor_current() {
            return Ok(self.cholesky.is_positive_definite(Slot::Rest));
        }
        self.rest_key = None;
        let zero = vec![0.0; self.problem.num_dofs()];
        let mut f = vec![0.0; zero.len()];
        let t = Instant::now();
        self.evaluate(&zero, &mut f, true)?;
        stats.tangent_assemblies += 1;
        stats.timings.assembly += t.elapsed();
        let t = Instant::now();
        self.cholesky.factorize(Slot::Rest, &self.values)?;
        stats.factorizations += 1;
        stats.timings.factorization += t.elapsed();
        let p = &self.problem;
        self.rest_key = Some((p.material, p.springs.clone(), p.point_springs.clone()));
        Ok(self.cholesky.is_positive_definite(Slot::Rest))
    }

    /// Line search along `du` on s(α) = du · r(u + α du), the directional
    /// derivative of the potential energy: accepts α = 1 when |s(1)| ≤ ½|s(0)|,
    /// otherwise seeks the root of s by safeguarded secant steps (Crisfield).
    /// A trial state with an inverted element halves α (up to [`MAX_INVERSION_HALVINGS`] times). On return `trial`
    /// holds u + α du, `f_int` and `r` are evaluated there.
    #[allow(clippy::too_many_arguments)]
    fn line_search(
        &mut self,
        u: &[f64],
        du: &[f64],
        trial: &mut [f64],
        f_int: &mut [f64],
        f_ext: &[f64],
        r: &mut [f64],
        opt: &SolverOptions,
        stats: &mut Stats,
    ) -> Result<f64, FemError> {
        let s0 = dot(du, r);
        let (mut a_lo, mut s_lo) = (0.0, s0);
        let mut alpha: f64 = 1.0;
        let (mut attempt, mut halvings) = (0, 0);
        loop {
            trial.copy_from_slice(u);
            self.add_free(trial, du, alpha);
            let t = Instant::now();
            let eval = self.evaluate(trial, f_int, false);
            stats.timings.assembly += t.elapsed();
            match eval {
                Err(e) if !opt.line_search || halvings == MAX_INVERSION_HALVINGS => return Err(e),
                Err(_) => {
                    // An inverted element: the energy is infinite there; the root lies nearer.
                    halvings += 1;
                    alpha = 0.5 * (a_lo + alpha);
                    continue;
                }
                Ok(()) => {}
            }
            let last = !opt.line_search || attempt == 7;
            attempt += 1;
            self.residual(f_int, f_ext, r);
            let s = dot(du, r);
            // Not a descent direction (indefinite tangent) or close enough to the root: accept.
            if last || s0 >= 0.0 || s.abs() <= 0.5 * s0.abs() {
                return Ok(alpha);
            }
            let next = if s > 0.0 {
                // Root bracketed in (a_lo, alpha): regula falsi.
                a_lo + (alpha - a_lo) * s_lo / (s_lo - s)
            } else {
                // Still descending: extrapolate by secant, at most doubling.
                let ext = alpha - s * (alpha - a_lo) / (s - s_lo);
                a_lo = alpha;
                s_lo = s;
                if ext.is_finite() {
                    ext.min(2.0 * alpha).max(alpha * 1.1)
                } else {
                    2.0 * alpha
                }
            };
            alpha = next.clamp(0.02, 4.0);
        }
    }

    /// Free-dof residual r = f_int − f_ext into `r`; returns ‖r‖.
    fn residual(&self, f_int: &[f64], f_ext: &[f64], r: &mut [f64]) -> f64 {
        for (dof, (fi, fe)) in f_int.iter().zip(f_ext).enumerate() {
            if let Some(i) = self.free_index(dof) {
                r[i] = fi - fe;
            }
        }
        norm(r)
    }
}

/// Where an iteration sequence takes its first factor from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Start {
    /// The factor of the tangent at rest.
    Rest,
    /// The last factor computed (the rest tangent's if there is none).
    Kept,
    /// A new factor of the tangent at the starting iterate.
    Fresh,
}

/// Limited-memory BFGS on top of a kept factorisation: the inverse Hessian
/// approximation starts from the factor's inverse and takes the curvature
/// pairs (s, y) = (step, change of the residual) of the last iterations.
struct Bfgs {
    memory: usize,
    pairs: std::collections::VecDeque<(Vec<f64>, Vec<f64>, f64)>,
}

impl Bfgs {
    fn new(memory: usize) -> Self {
        Bfgs { memory, pairs: std::collections::VecDeque::with_capacity(memory) }
    }

    fn clear(&mut self) {
        self.pairs.clear();
    }

    /// Records the step `s` that moved the residual from `r_old` to `r`; pairs
    /// without positive curvature are skipped (they would break positivity).
    fn push(&mut self, s: &[f64], r: &[f64], r_old: &[f64]) {
        if self.memory == 0 {
            return;
        }
        let y: Vec<f64> = r.iter().zip(r_old).map(|(a, b)| a - b).collect();
        let sy = dot(s, &y);
        if !(sy > 1e-12 * norm(s) * norm(&y)) {
            return;
        }
        if self.pairs.len() == self.memory {
            self.pairs.pop_front();
        }
        self.pairs.push_back((s.to_vec(), y, 1.0 / sy));
    }

    /// v ← H v by the two-loop recursion, H₀ applied by `solve`.
    fn apply(&self, v: &mut [f64], mut solve: impl FnMut(&mut [f64]) -> Result<(), FemError>) -> Result<(), FemError> {
        let mut alphas = Vec::with_capacity(self.pairs.len());
        for (s, y, rho) in self.pairs.iter().rev() {
            let a = rho * dot(s, v);
            v.iter_mut().zip(y).for_each(|(x, y)| *x -= a * y);
            alphas.push(a);
        }
        solve(v)?;
        for ((s, y, rho), a) in self.pairs.iter().zip(alphas.iter().rev()) {
            let b = rho * dot(y, v);
            v.iter_mut().zip(s).for_each(|(x, s)| *x += (a - b) * s);
        }
        Ok(())
    }
}

#[derive(Default)]
struct Stats {
    iterations: usize,
    factorizations: usize,
    tangent_assemblies: usize,
    /// A factorisation of the latest Newton attempt found the tangent indefinite (past a limit or
    /// bifurcation point); an earlier attempt's, made far from equilibrium, says nothing of the failure.
    indefinite: bool,
    /// The kept factor was recomputed during this solve.
    refactorized: bool,
    residuals: Vec<f64>,
    timings: Timings,
    /// See [`Solution::snapped_from`].
    snapped_from: Option<f64>,
    /// The load factor of the last equilibrium reached.
    reached: f64,
    /// The first Newton iterate from rest and its load factor: the linear response at rest
    /// ([`LoadPath::record_rest`]).
    rest_response: Option<(f64, Vec<f64>)>,
}

impl Stats {
    fn finish(self, u: Vec<f64>, load_steps: usize, start: Instant) -> Solution {
        let mut timings = self.timings;
        timings.total = start.elapsed();
        Solution {
            u,
            iterations: self.iterations,
            load_steps,
            factorizations: self.factorizations,
            tangent_assemblies: self.tangent_assemblies,
            residuals: self.residuals,
            timings,
            snapped_from: self.snapped_from,
        }
    }
}

/// A smallest principal stretch under which an element is crushed flat (a twentieth of its
/// length left in that direction).
const FLAT_STRETCH: f64 = 0.05;

/// The margin (5 %) above [`SVK_LIMIT_STRETCH`] within which a failing iterate's stretch counts as
/// past SVK's compressive limit point: an iterate that fails there has reached the limit point,
/// even if it has not quite crossed it.
const SVK_LIMIT_MARGIN: f64 = 1.05;

/// What stopped a solve under `law` (Saint-Venant-Kirchhoff or co-rotational, whose energies stay
/// finite for an element crushed flat) that failed with the tangent found `indefinite` or not,
/// its failing iterate compressed to the stretch `strayed`, the last equilibrium's most
/// compressed element `last` (index, stretch) at load factor `lambda`:
/// - [`FemError::CrushedFlat`] when that element was already flat and the tangent stayed
///   positive definite: the body is still stiff, and what stops it is an element that can only
///   go on by turning inside out (SVK, the voxel liver of 2,133 H8 under gravity: stretch 2e-6
///   at load factor 0.944, where CalculiX's equilibrium beyond has 15 quadrature points with
///   det F < 0; co-rotational, the AMOS liver turned by 90° through its held nodes, which a
///   prescribed displacement moves along the chord, squeezing the organ between them);
/// - [`FemError::LimitPoint`] under SVK when the tangent turned indefinite, or the failing
///   iterate was compressed past the stretch 1/√3 where SVK's stress peaks (within
///   [`SVK_LIMIT_MARGIN`]): the compressive limit point;
/// - none otherwise (the failure is told as it came).
fn compression_failure(
    law: Law,
    indefinite: bool,
    strayed: f64,
    last: Option<(usize, f64)>,
    lambda: f64,
) -> Option<FemError> {
    let (element, stretch) = last?;
    if stretch < FLAT_STRETCH && !indefinite {
        return Some(FemError::CrushedFlat { law: law.display_name(), element, stretch, load_factor: lambda });
    }
    (law == Law::Svk && (indefinite || strayed < SVK_LIMIT_STRETCH * SVK_LIMIT_MARGIN))
        .then_some(FemError::LimitPoint { element, stretch, load_factor: lambda })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An element flat at the last equilibrium of a still-stiff body is told as crushed, not as
    /// the body's limit point; SVK's limit point as before; anything else as it came.
    #[test]
    fn a_failure_by_compression_is_told_by_what_stopped_it() {
        let crushed = compression_failure(Law::Svk, false, 3e-5, Some((1070, 2e-6)), 0.944).unwrap();
        assert!(matches!(crushed, FemError::CrushedFlat { element: 1070, load_factor: 0.944, .. }), "{crushed:?}");
        let text = crushed.to_string();
        assert!(
            text.contains("SVK crushed element 1070 flat by load factor 0.944 (its smallest principal stretch 2.0e-6")
        );
        assert!(text.contains("turn inside out") && text.contains("neo_hookean"), "{text}");
        let crushed = compression_failure(Law::Corotational, false, 0.0, Some((1317, 1e-3)), 0.414).unwrap();
        assert!(crushed.to_string().starts_with("co-rotational crushed element 1317 flat"), "{crushed}");
        // A flat element in a body whose tangent turned indefinite: SVK's limit point.
        let limit = compression_failure(Law::Svk, true, 0.9, Some((7, 0.01)), 0.5).unwrap();
        assert!(matches!(limit, FemError::LimitPoint { element: 7, .. }), "{limit:?}");
        assert!(!limit.to_string().contains("buckled"), "{limit}");
        // Indefinite with no element compressed by a fifth: a slender column's buckling is named too.
        let column = compression_failure(Law::Svk, true, 0.83, Some((21, 0.836)), 0.012).unwrap();
        assert!(
            column.to_string().contains("0.836 (SVK's uniaxial stress")
                && column.to_string().contains(", or the body buckled")
        );
        // Short of the peak at equilibrium, the failing iterate past it (the block crushed by a force).
        let limit = compression_failure(Law::Svk, false, 0.3, Some((3, 0.7)), 0.4).unwrap();
        assert!(matches!(limit, FemError::LimitPoint { element: 3, .. }), "{limit:?}");
        // Nothing compressed near the limit, no element at all, or no SVK limit to pass.
        assert!(compression_failure(Law::Svk, false, 0.9, Some((3, 0.95)), 0.4).is_none());
        assert!(compression_failure(Law::Svk, true, 0.1, None, 0.4).is_none());
        assert!(compression_failure(Law::Corotational, true, 0.1, Some((3, 0.3)), 0.4).is_none());
    }

    #[test]
    fn the_predictor_extrapolates_a_straight_path_and_never_divides_by_a_zero_step() {
        let path = |l: f64| vec![2.0 * l, -l];
        let ahead = predict(&path(0.5), Some(&(0.25, path(0.25))), 0.5, 0.75);
        assert!(ahead.iter().zip(path(0.75)).all(|(a, b)| (a - b).abs() < 1e-15), "{ahead:?}");
        // Two states at the same load factor (a step below its resolution): no extrapolation.
        let same = predict(&path(0.5), Some(&(0.5, path(0.25))), 0.5, 0.5);
        assert_eq!(same, path(0.5));
        assert_eq!(predict(&path(0.5), None, 0.5, 0.75), path(0.5));
    }

    /// The last states of the AMOS liver pushed by 1 N in 7 load steps (F-bar): the path stiffened
    /// again after a soft stretch, then its last step, which holds a limit point, fell to 0.56
    /// times the step before: too little for a snap, enough for a check. A path softening
    /// steadily, or one far from softened, asks for none.
    #[test]
    fn a_step_that_softens_after_the_path_stiffened_asks_for_a_check() {
        let path = |states: &[(f64, f64)]| {
            let mut path = LoadPath::new(vec![1.0]);
            path.rest = Some(24.0);
            for &(lambda, q) in states {
                path.record(lambda, &[q]);
            }
            path
        };
        let liver = [(0.8125, 0.28789), (0.875, 0.34022), (0.9375, 0.38090), (1.0, 0.45415)];
        assert!(path(&liver).turned() && !path(&liver).snapped());
        assert!(!path(&liver[..3]).turned(), "three states tell no turn");
        let softening = [(0.25, 0.05), (0.5, 0.15), (0.75, 0.3), (1.0, 0.5)];
        assert!(!path(&softening).turned());
        let stiff = path(&liver.map(|(l, q)| (l, q / 10.0)));
        assert!(stiff.softening() > crate::LIMIT_POINT_STIFFNESS && !stiff.turned());
    }

    #[test]
    fn a_sequence_stalls_when_its_last_residuals_stay_near_the_best_before_them() {
        let decreasing: Vec<f64> = (0..30).map(|i| 0.8f64.powi(i)).collect();
        assert!(!stalled(&decreasing));
        // Too short to judge: at least one residual before the window.
        assert!(!stalled(&[1.0; STALL_ITERATIONS]));
        let mut flat = vec![1.0; STALL_ITERATIONS + 1];
        assert!(stalled(&flat));
        // One residual in the window below 0.9 × the best before it is progress.
        flat[STALL_ITERATIONS] = 0.89;
        assert!(!stalled(&flat));
        // The best before the window counts, not the first.
        let mut dip = vec![1.0, 0.5];
        dip.extend(std::iter::repeat_n(0.46, STALL_ITERATIONS));
        assert!(stalled(&dip));
    }
}
