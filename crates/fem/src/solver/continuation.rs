//! Arc-length continuation (Riks 1979, with Crisfield's cylindrical constraint): the load path
//! followed by steps of a given length in displacement rather than in load.
//!
//! Force control fails where the body is soft along one mode: an organ that swings from the strip
//! by which it is held. There the Newton direction is far too long along that mode (10⁴–10⁶
//! times on a real liver meshed with 17,830 quadratic tetrahedra and pushed by 2 N), its trial
//! states invert elements far from the load, and ever shorter load steps stall. Each step here
//! moves the body by a set arc length along the tangent of the path, the load factor following;
//! the corrections are then kept orthogonal to that step (Riks's normal plane), the load factor
//! absorbing what would have been the soft mode's share of them, and no correction is longer than
//! the arc itself.
//!
//! It follows stable equilibria only (the tangent positive definite where a step starts): past a
//! limit point the body snaps, which the patient attempt of force control finds.

use super::{converged, dot, norm, Budget, LoadPath, Start, StaticSolver, Stats};
use crate::linsolve::Slot;
use crate::{FemError, SolverOptions};

/// Most steps of one continuation.
const MAX_STEPS: usize = 400;

/// Corrector iterations a step may take before its arc is halved (fewer where the solver's
/// `max_iterations` says so).
const STEP_ITERATIONS: usize = 20;

/// The iterations a step should take: after a step the arc is scaled by √(this / taken), by at
/// most ×2 and at least ×½ (Crisfield's rule).
const WANTED_ITERATIONS: f64 = 5.0;

/// The first arc, as a fraction of the length of the linear response to the whole load at the
/// state the continuation starts from.
const FIRST_ARC: f64 = 1.0 / 32.0;

/// The shortest arc, as a fraction of the first: a step that fails at it ends the continuation.
const SMALLEST_ARC: f64 = 1.0 / 1024.0;

/// Halvings of a correction whose trial state inverts an element.
const INVERSION_HALVINGS: usize = 20;

/// A correction whose residual fell by less than this ratio is followed by a new tangent at the
/// trial state (modified Newton otherwise: the factor made where the step started).
const REFRESH_RATIO: f64 = 0.25;

/// The whole load (at load factor 1): over all dofs, its free part, and that part's norm.
struct Load {
    full: Vec<f64>,
    free: Vec<f64>,
    norm: f64,
}

/// A corrector step: the state, its load factor and the iterations taken.
struct Corrected {
    u: Vec<f64>,
    lambda: f64,
    iterations: usize,
}

impl StaticSolver {
    /// Whether the load path can be followed by arc length: every prescribed displacement is zero
    /// (the load factor then scales the loads alone).
    pub(super) fn arc_length_applies(&self) -> bool {
        self.problem.dirichlet.values().all(|v| v.iter().all(|&x| x == 0.0))
    }

    /// Follows the load path by arc length from the equilibrium `u` at load factor `lambda` to
    /// load factor `end`, updating both (they stay at the last equilibrium reached on failure);
    /// returns the steps taken. It ends with [`FemError::NoEquilibrium`] where the path turns back
    /// (a step ends at a lower load factor, or the tangent is indefinite where one starts) or the
    /// shortest arc fails.
    pub(super) fn arc_length(
        &mut self,
        u: &mut Vec<f64>,
        lambda: &mut f64,
        end: f64,
        path: &mut LoadPath,
        opt: &SolverOptions,
        stats: &mut Stats,
    ) -> Result<usize, FemError> {
        let full = self.loads();
        let free = self.free_part(&full);
        let load = Load { norm: norm(&free), full, free };
        let mut f_int = vec![0.0; u.len()];
        let (mut arc, mut smallest) = (f64::NAN, 0.0);
        let (start_iterations, mut steps) = (stats.iterations, 0);
        let none = |lambda: f64, path: &LoadPath, stats: &Stats, indefinite: bool| FemError::NoEquilibrium {
            load_factor: lambda,
            softening: path.softening(),
            indefinite,
            iterations: stats.iterations - start_iterations,
        };
        // `current`: the latest factor is the tangent's at `u` (an attempt that failed without
        // refactorising leaves it so), and `tangent` its response to the load.
        let (mut tangent, mut current) = (load.free.clone(), false);
        while steps < MAX_STEPS {
            if !current {
                self.refactorize(u, &mut f_int, false, stats)?;
                if !self.cholesky.is_positive_definite(Slot::Latest) {
                    return Err(none(*lambda, path, stats, true));
                }
                tangent.copy_from_slice(&load.free);
                self.cholesky.solve_in_place(Slot::Latest, &mut tangent)?;
                if *lambda == 0.0 {
                    // From rest: the linear response at rest to the whole load.
                    let mut response = vec![0.0; u.len()];
                    self.add_free(&mut response, &tangent, 1.0);
                    path.record_rest(1.0, &response);
                }
            }
            let length = norm(&tangent);
            if !(length > 0.0) {
                return Err(FemError::Invalid("an arc-length continuation without a load".into()));
            }
            if arc.is_nan() {
                arc = FIRST_ARC * length * (end - *lambda);
                smallest = SMALLEST_ARC * arc;
            }
            if *lambda + arc / length >= end {
                // The rest of the load in one force-controlled step from the tangent's prediction.
                let mut trial = u.clone();
                self.add_free(&mut trial, &tangent, end - *lambda);
                let factorizations = stats.factorizations;
                let finished = self.newton(&mut trial, end, Start::Kept, opt, Budget::Normal, stats);
                current = stats.factorizations == factorizations;
                if finished.is_ok() {
                    path.record(end, &trial);
                    *u = trial;
                    *lambda = end;
                    stats.reached = end;
                    return Ok(steps + 1);
                }
                arc = 0.5 * (end - *lambda) * length;
                continue;
            }
            let factorizations = stats.factorizations;
            let step = self.arc_step(u, *lambda, &tangent, arc / length, &load, opt, stats);
            current = stats.factorizations == factorizations;
            match step {
                // The path turns back: a limit point of the load (past it the body snaps).
                Ok(step) if step.lambda < *lambda => {
                    path.record(step.lambda, &step.u);
                    return Err(none(*lambda, path, stats, false));
                }
                Ok(step) => {
                    path.record(step.lambda, &step.u);
                    *u = step.u;
                    *lambda = step.lambda;
                    stats.reached = step.lambda;
                    (steps, current) = (steps + 1, false);
                    arc *= (WANTED_ITERATIONS / step.iterations.max(1) as f64).sqrt().clamp(0.5, 2.0);
                }
                Err(FemError::NotConverged { .. } | FemError::InvertedElement { .. }) if arc > smallest => {
                    arc *= 0.5;
                }
                Err(FemError::NotConverged { .. } | FemError::InvertedElement { .. }) => {
                    return Err(none(*lambda, path, stats, false));
                }
                Err(e) => return Err(e),
            }
        }
        Err(none(*lambda, path, stats, false))
    }

    /// One arc-length step from the equilibrium `u` at `lambda`: the predictor `dlambda` ×
    /// `tangent` (the tangent's response to the free part of `load`), then
    /// corrections on the plane normal to it, each refactorising where the last converged slowly.
    #[allow(clippy::too_many_arguments)]
    fn arc_step(
        &mut self,
        u: &[f64],
        lambda: f64,
        tangent: &[f64],
        dlambda: f64,
        load: &Load,
        opt: &SolverOptions,
        stats: &mut Stats,
    ) -> Result<Corrected, FemError> {
        let predictor: Vec<f64> = tangent.iter().map(|t| dlambda * t).collect();
        let arc = norm(&predictor);
        let floor = self.force_floor();
        let mut trial = u.to_vec();
        self.add_free(&mut trial, &predictor, 1.0);
        let mut lam = lambda + dlambda;
        let mut f_int = vec![0.0; u.len()];
        self.evaluate(&trial, &mut f_int, false)?;
        let mut response = tangent.to_vec();
        let (mut r, mut last, mut last_rel) = (vec![0.0; load.free.len()], f64::INFINITY, f64::INFINITY);
        let (mut f_ext, mut candidate) = (vec![0.0; u.len()], trial.clone());
        let mut step_norm = None;
        let iterations = STEP_ITERATIONS.min(opt.max_iterations);
        for it in 0..iterations {
            f_ext.iter_mut().zip(&load.full).for_each(|(e, f)| *e = lam * f);
            let res = self.residual(&f_int, &f_ext, &mut r);
            let rel = res / (lam.abs() * load.norm).max(norm(&f_int)).max(floor);
            stats.residuals.push(rel);
            if !rel.is_finite() {
                return Err(FemError::NonFinite(format!("residual of an arc-length step at load factor {lam:.4}")));
            }
            if converged(opt, rel, step_norm, &trial) {
                return Ok(Corrected { u: trial, lambda: lam, iterations: it });
            }
            super::between_iterations(opt, stats)?;
            stats.iterations += 1;
            if it > 0 && res > REFRESH_RATIO * last {
                self.refactorize(&trial, &mut f_int, false, stats)?;
                response.copy_from_slice(&load.free);
                self.cholesky.solve_in_place(Slot::Latest, &mut response)?;
            }
            (last, last_rel) = (res, rel);
            let mut correction: Vec<f64> = r.iter().map(|x| -x).collect();
            self.cholesky.solve_in_place(Slot::Latest, &mut correction)?;
            // Riks's normal plane: the correction orthogonal to the predictor, the load factor
            // taking up the rest; then no longer than the arc.
            let dlam = -dot(&predictor, &correction) / dot(&predictor, &response);
            correction.iter_mut().zip(&response).for_each(|(c, v)| *c += dlam * v);
            let mut scale = (arc / norm(&correction)).min(1.0);
            for halving in 0..=INVERSION_HALVINGS {
                candidate.copy_from_slice(&trial);
                self.add_free(&mut candidate, &correction, scale);
                match self.evaluate(&candidate, &mut f_int, false) {
                    Ok(()) => break,
                    Err(e) if halving == INVERSION_HALVINGS => return Err(e),
                    Err(_) => scale *= 0.5,
                }
            }
            step_norm = Some(scale * norm(&correction));
            std::mem::swap(&mut trial, &mut candidate);
            lam += scale * dlam;
        }
        Err(FemError::NotConverged { load_factor: lam, iterations, residual: last_rel })
    }
}
