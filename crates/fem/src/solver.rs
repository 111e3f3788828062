//! Static equilibrium by Newton-Raphson: find u with f_int(u) + K_s u = λ f_ext
//! on the free dofs, for load factors λ stepping to 1 (adaptive: a step that
//! fails is halved), with a backtracking line search on the residual norm.

use std::time::{Duration, Instant};

use serde::{Deserialize, Serialize};

use crate::assembly::{assemble, Pattern, Workspace};
use crate::element::ElementGeometry;
use crate::linsolve::{symmetric_matvec, SparseCholesky};
use crate::problem::Problem;
use crate::FemError;

/// Settings of the Newton-Raphson solver.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SolverOptions {
    /// Initial number of load steps (halved adaptively on failure).
    pub load_steps: usize,
    /// Maximum Newton iterations per load step.
    pub max_iterations: usize,
    /// Convergence: ‖r‖ ≤ rtol · max(‖f_ext‖, ‖f_int‖).
    pub rtol: f64,
    /// Convergence: ‖Δu‖ ≤ utol · ‖u‖.
    pub utol: f64,
    /// Backtracking line search on the residual norm.
    pub line_search: bool,
    /// How many times a failing load step may be halved before giving up.
    pub max_step_cuts: usize,
    /// Newton systems: preconditioned conjugate gradients on the last
    /// factorisation (kept across iterations and solves), refactorising only
    /// when CG needs more than `cg_max_iterations`; `false` factorises every iteration.
    pub reuse_factorization: bool,
    /// CG iterations allowed before the tangent is refactorised.
    pub cg_max_iterations: usize,
    /// CG stops at ‖K du + r‖ ≤ cg_tolerance · ‖r‖ (inexact Newton forcing term).
    pub cg_tolerance: f64,
}

impl Default for SolverOptions {
    fn default() -> Self {
        SolverOptions {
            load_steps: 1,
            max_iterations: 20,
            rtol: 1e-6,
            utol: 1e-6,
            line_search: true,
            max_step_cuts: 8,
            reuse_factorization: true,
            cg_max_iterations: 20,
            cg_tolerance: 1e-3,
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
    /// Triangular solves and conjugate-gradient iterations.
    pub solve: Duration,
    /// Whole solve.
    pub total: Duration,
}

/// The result of a static solve.
#[derive(Clone, Debug, Serialize)]
pub struct Solution {
    /// Displacement, 3 per node (m).
    pub u: Vec<f64>,
    /// Newton iterations over all load steps.
    pub iterations: usize,
    /// Load steps taken (including halved ones that succeeded).
    pub load_steps: usize,
    /// Numeric factorisations performed.
    pub factorizations: usize,
    /// Conjugate-gradient iterations performed.
    pub cg_iterations: usize,
    /// Relative residual ‖r‖ / max(‖f_ext‖, ‖f_int‖) at each iterate, in order.
    pub residuals: Vec<f64>,
    /// Time split.
    pub timings: Timings,
}

/// A reusable static solver: element geometry, sparse pattern and symbolic
/// factorisation are computed once; every solve reuses them.
pub struct StaticSolver {
    problem: Problem,
    geometry: ElementGeometry,
    pattern: Pattern,
    cholesky: SparseCholesky,
    constrained_nodes: Vec<usize>,
    work: Workspace,
    values: Vec<f64>,
    factorized: bool,
}

impl std::fmt::Debug for StaticSolver {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("StaticSolver")
            .field("dofs", &self.problem.num_dofs())
            .field("free", &self.pattern.num_free)
            .finish()
    }
}

/// Euclidean norm.
pub fn norm(v: &[f64]) -> f64 {
    v.iter().map(|x| x * x).sum::<f64>().sqrt()
}

impl StaticSolver {
    /// Prepares geometry, pattern and symbolic factorisation for the problem.
    pub fn new(problem: Problem) -> Result<Self, FemError> {
        problem.validate()?;
        let geometry = ElementGeometry::new(&problem.mesh, problem.material.resolved_formulation())?;
        let mut constrained = vec![false; problem.num_dofs()];
        for &n in problem.dirichlet.keys() {
            constrained[3 * n..3 * n + 3].fill(true);
        }
        let pattern = Pattern::new(&geometry, problem.num_dofs(), &constrained)?;
        let cholesky = SparseCholesky::new(&pattern)?;
        let values = vec![0.0; pattern.nnz()];
        let constrained_nodes = problem.dirichlet.keys().copied().collect();
        Ok(StaticSolver {
            problem,
            geometry,
            pattern,
            cholesky,
            constrained_nodes,
            work: Workspace::default(),
            values,
            factorized: false,
        })
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

    /// Number of free dofs and stored non-zeros of the tangent.
    pub fn system_size(&self) -> (usize, usize) {
        (self.pattern.num_free, self.pattern.nnz())
    }

    /// Internal force f_int(u) + K_s u over all dofs (springs included).
    pub fn internal_force(&mut self, u: &[f64]) -> Result<Vec<f64>, FemError> {
        let mut f = vec![0.0; u.len()];
        self.evaluate(u, &mut f, false)?;
        Ok(f)
    }

    /// The free-dof tangent at u as a dense matrix (for tests and small problems).
    pub fn tangent_dense(&mut self, u: &[f64]) -> Result<Vec<Vec<f64>>, FemError> {
        let mut f = vec![0.0; u.len()];
        self.evaluate(u, &mut f, true)?;
        let n = self.pattern.num_free;
        let mut k = vec![vec![0.0; n]; n];
        for c in 0..n {
            for p in self.pattern.col_ptr[c] as usize..self.pattern.col_ptr[c + 1] as usize {
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

    fn evaluate(&mut self, u: &[f64], f: &mut [f64], tangent: bool) -> Result<(), FemError> {
        let values = tangent.then_some(self.values.as_mut_slice());
        assemble(&self.geometry, &self.pattern, &self.problem.material, u, f, values, &mut self.work)?;
        for (n, &k) in self.problem.springs.iter().enumerate().filter(|(_, k)| **k != 0.0) {
            for d in 0..3 {
                f[3 * n + d] += k * u[3 * n + d];
                if let (true, Some(i)) = (tangent, self.free_index(3 * n + d)) {
                    self.values[self.pattern.diag[i] as usize] += k;
                }
            }
        }
        Ok(())
    }

    /// Solves from the rest configuration.
    pub fn solve(&mut self, options: &SolverOptions) -> Result<Solution, FemError> {
        self.solve_from(None, options)
    }

    /// Solves from a warm start `u0` (e.g. the previous frame's solution) when
    /// given: the full load is applied at once from `u0`; if that fails, the
    /// solve restarts from rest with load stepping.
    pub fn solve_from(&mut self, u0: Option<&[f64]>, options: &SolverOptions) -> Result<Solution, FemError> {
        let start = Instant::now();
        self.problem.validate()?;
        if !self.problem.dirichlet.keys().copied().eq(self.constrained_nodes.iter().copied()) {
            return Err(FemError::Invalid("the set of constrained nodes changed after the solver was built".into()));
        }
        if self.problem.material.resolved_formulation() != self.geometry.formulation {
            return Err(FemError::Invalid("the element formulation changed after the solver was built".into()));
        }
        let ndof = self.problem.num_dofs();
        let mut stats = Stats::default();
        if let Some(u0) = u0 {
            if u0.len() != ndof || u0.iter().any(|v| !v.is_finite()) {
                return Err(FemError::Invalid(format!("warm start must hold {ndof} finite values")));
            }
            let mut u = u0.to_vec();
            if self.newton(&mut u, 1.0, options, &mut stats).is_ok() {
                return Ok(stats.finish(u, 1, start));
            }
        }
        let mut u = vec![0.0; ndof];
        let mut previous: Option<(f64, Vec<f64>)> = None;
        let mut lambda = 0.0;
        let mut step = 1.0 / options.load_steps.max(1) as f64;
        let mut cuts = 0;
        let mut steps = 0;
        while lambda < 1.0 {
            let target = (lambda + step).min(1.0);
            // Predictor: extrapolate the load path linearly from the last two states.
            let mut trial = u.clone();
            if let Some((l0, u0)) = &previous {
                let ratio = (target - lambda) / (lambda - l0);
                trial.iter_mut().zip(u0).for_each(|(t, p)| *t += ratio * (*t - p));
            }
            match self.newton(&mut trial, target, options, &mut stats) {
                Ok(()) => {
                    previous = Some((lambda, std::mem::replace(&mut u, trial)));
                    lambda = target;
                    steps += 1;
                }
                Err(FemError::NotConverged { .. } | FemError::InvertedElement { .. } | FemError::Factorization(_))
                    if cuts < options.max_step_cuts =>
                {
                    cuts += 1;
                    step *= 0.5;
                }
                Err(e) => return Err(e),
            }
        }
        Ok(stats.finish(u, steps, start))
    }

    /// Newton iterations at load factor `lambda`, updating `u` in place.
    fn newton(&mut self, u: &mut [f64], lambda: f64, opt: &SolverOptions, stats: &mut Stats) -> Result<(), FemError> {
        let ndof = u.len();
        for (&n, v) in &self.problem.dirichlet {
            for d in 0..3 {
                u[3 * n + d] = lambda * v[d];
            }
        }
        let f_ext: Vec<f64> = self.problem.f_ext.iter().map(|f| lambda * f).collect();
        let mut f_int = vec![0.0; ndof];
        let mut r = vec![0.0; self.pattern.num_free];
        let t = Instant::now();
        self.evaluate(u, &mut f_int, false)?;
        stats.timings.assembly += t.elapsed();
        let mut res = self.residual(&f_int, &f_ext, &mut r);
        let mut du = vec![0.0; self.pattern.num_free];
        let mut trial = u.to_vec();
        for it in 0..=opt.max_iterations {
            let scale = norm(&f_ext).max(norm(&f_int));
            let rel = if scale > 0.0 { res / scale } else { 0.0 };
            stats.residuals.push(rel);
            if !rel.is_finite() {
                return Err(FemError::NonFinite(format!("residual at iteration {it}")));
            }
            let inc_ok = it > 0 && norm(&du) <= opt.utol * norm(u).max(f64::MIN_POSITIVE);
            if rel <= opt.rtol || (inc_ok && rel <= opt.rtol.sqrt()) {
                return Ok(());
            }
            if it == opt.max_iterations {
                return Err(FemError::NotConverged { load_factor: lambda, iterations: it, residual: rel });
            }
            stats.iterations += 1;
            let t = Instant::now();
            self.evaluate(u, &mut f_int, true)?;
            stats.timings.assembly += t.elapsed();
            let t = Instant::now();
            let solved = opt.reuse_factorization && self.factorized && self.pcg(&r, &mut du, opt, stats);
            stats.timings.solve += t.elapsed();
            if !solved {
                let t = Instant::now();
                self.factorized = false;
                self.cholesky.factorize(&self.values)?;
                self.factorized = true;
                stats.factorizations += 1;
                stats.timings.factorization += t.elapsed();
                let t = Instant::now();
                du.iter_mut().zip(&r).for_each(|(d, r)| *d = -r);
                self.cholesky.solve_in_place(&mut du)?;
                stats.timings.solve += t.elapsed();
            }
            let alpha = self.line_search(u, &du, &mut trial, &mut f_int, &f_ext, &mut r, opt, stats)?;
            res = norm(&r);
            if alpha != 1.0 {
                du.iter_mut().for_each(|d| *d *= alpha);
            }
            u.copy_from_slice(&trial);
        }
        unreachable!("the loop returns at its last iteration")
    }

    /// Solves K du = −r by conjugate gradients preconditioned with the stored
    /// factorisation. Returns false when it needs more than the allowed iterations.
    fn pcg(&mut self, r: &[f64], du: &mut [f64], opt: &SolverOptions, stats: &mut Stats) -> bool {
        let n = r.len();
        let target = opt.cg_tolerance * norm(r);
        du.fill(0.0);
        let mut res: Vec<f64> = r.iter().map(|v| -v).collect();
        let mut z = res.clone();
        if self.cholesky.solve_in_place(&mut z).is_err() {
            return false;
        }
        let mut p = z.clone();
        let mut kp = vec![0.0; n];
        let mut rz: f64 = res.iter().zip(&z).map(|(a, b)| a * b).sum();
        for _ in 0..opt.cg_max_iterations {
            stats.cg_iterations += 1;
            symmetric_matvec(&self.pattern, &self.values, &p, &mut kp);
            let pkp: f64 = p.iter().zip(&kp).map(|(a, b)| a * b).sum();
            if !(pkp > 0.0) {
                return false;
            }
            let a = rz / pkp;
            du.iter_mut().zip(&p).for_each(|(x, p)| *x += a * p);
            res.iter_mut().zip(&kp).for_each(|(r, kp)| *r -= a * kp);
            if norm(&res) <= target {
                return true;
            }
            z.copy_from_slice(&res);
            if self.cholesky.solve_in_place(&mut z).is_err() {
                return false;
            }
            let rz_new: f64 = res.iter().zip(&z).map(|(a, b)| a * b).sum();
            let beta = rz_new / rz;
            rz = rz_new;
            p.iter_mut().zip(&z).for_each(|(p, z)| *p = z + beta * *p);
        }
        false
    }

    /// Line search along `du` on s(α) = du · r(u + α du), the directional
    /// derivative of the potential energy: accepts α = 1 when |s(1)| ≤ ½|s(0)|,
    /// otherwise seeks the root of s by safeguarded secant steps (Crisfield).
    /// A trial state with an inverted element halves α. On return `trial`
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
        let s0: f64 = du.iter().zip(r.iter()).map(|(d, r)| d * r).sum();
        let (mut a_lo, mut s_lo) = (0.0, s0);
        let mut alpha: f64 = 1.0;
        for attempt in 0..8 {
            trial.copy_from_slice(u);
            for (dof, t) in trial.iter_mut().enumerate() {
                if let Some(i) = self.free_index(dof) {
                    *t += alpha * du[i];
                }
            }
            let t = Instant::now();
            let eval = self.evaluate(trial, f_int, false);
            stats.timings.assembly += t.elapsed();
            let last = !opt.line_search || attempt == 7;
            match eval {
                Err(e) if last => return Err(e),
                Err(_) => {
                    alpha = 0.5 * (a_lo + alpha);
                    continue;
                }
                Ok(()) => {}
            }
            self.residual(f_int, f_ext, r);
            let s: f64 = du.iter().zip(r.iter()).map(|(d, r)| d * r).sum();
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
        unreachable!("the last attempt returns")
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

#[derive(Default)]
struct Stats {
    iterations: usize,
    factorizations: usize,
    cg_iterations: usize,
    residuals: Vec<f64>,
    timings: Timings,
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
            cg_iterations: self.cg_iterations,
            residuals: self.residuals,
            timings,
        }
    }
}
