//! A static finite-element problem as a filter [`Model`]: the uncertain parameters (Young's modulus, boundary
//! spring stiffnesses) are set on the problem, time-dependent loads are applied for step k, and the static
//! equilibrium is solved by [`StaticSolver`] (quasi-Newton) warm-started from the sigma point's own previous
//! displacement.
//! The observation is the current position of tracked points (barycentric in the mesh).
//!
//! Every sigma point owns a [`StaticSolver`] (its slot, set by [`Model::assign_sigma_point`]), created on first
//! use, so that its symbolic analysis and last numeric factorisation (the preconditioner of the next Newton
//! systems) are reused from step to step, and so that the results do not depend on the order in which the sigma
//! points run: parallel and sequential filters give the same numbers.

use std::sync::{Mutex, PoisonError};

use fem::{Problem, SolverOptions, StaticSolver, Timings};
use mesh::Point;
use nalgebra::DVector;
use serde::{Deserialize, Serialize};

use crate::error::FemModelError;
use crate::observation::{tracked_positions, TrackedPoint};
use crate::{Model, SigmaPointSet};

/// How the physical value θ_j of one filter parameter enters the problem.
#[derive(Debug, Clone, PartialEq)]
pub enum FemParameter {
    /// Young's modulus of the material (Pa) = θ_j.
    Young,
    /// Zero-length springs on `nodes`, each of stiffness θ_j (N/m), added to the problem's own springs. (A filter
    /// value in units of a typical stiffness is the parameter's [`crate::ParameterSpec::scale`].)
    Springs {
        /// The nodes tied to their rest position by this parameter.
        nodes: Vec<usize>,
    },
}

/// Time profile of a [`LoadPattern`]: its amplitude at time step k, with τ = k / period.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub enum Profile {
    /// a = ½(1 − cos 2πτ): from 0 up to 1 at half a period and back, repeated every `period` steps.
    RaisedCosine {
        /// Steps per cycle (> 0).
        period: usize,
    },
    /// a = sin(2πτ + phase).
    Sine {
        /// Steps per cycle (> 0).
        period: usize,
        /// Phase (rad).
        #[serde(default)]
        phase: f64,
    },
}

impl Profile {
    /// Amplitude at time step `step`.
    pub fn amplitude(&self, step: usize) -> f64 {
        let two_pi = 2.0 * std::f64::consts::PI;
        match *self {
            Profile::RaisedCosine { period } => 0.5 * (1.0 - (two_pi * (step % period) as f64 / period as f64).cos()),
            Profile::Sine { period, phase } => (two_pi * (step % period) as f64 / period as f64 + phase).sin(),
        }
    }

    fn period(&self) -> usize {
        match *self {
            Profile::RaisedCosine { period } | Profile::Sine { period, .. } => period,
        }
    }
}

/// Loads scaled by a time profile: at step k, nodal forces `a(k) · f` are added to the problem's forces and
/// displacements `a(k) · d` to the prescribed values of constrained nodes.
#[derive(Debug, Clone, PartialEq)]
pub struct LoadPattern {
    /// The time profile a(k).
    pub profile: Profile,
    /// Nodal forces at amplitude 1 (N).
    pub forces: Vec<(usize, Point)>,
    /// Prescribed displacements at amplitude 1 (m); the nodes must be constrained in the problem.
    pub displacements: Vec<(usize, Point)>,
}

/// A prescribed displacement that follows measured data step by step (e.g. a tracked tool): at time step k the
/// constrained `node` moves by `displacements[k - 1]` on top of its base value and any load pattern.
#[derive(Debug, Clone, PartialEq)]
pub struct ControlPath {
    /// The node; it must be constrained in the problem.
    pub node: usize,
    /// Displacement (m) at steps 1, 2, ….
    pub displacements: Vec<Point>,
}

/// State of one sigma point (or of a plain simulation): the last equilibrium.
#[derive(Debug, Clone, PartialEq)]
pub struct FemState {
    /// Displacement, 3 per node (m): the last solution and the warm start of the next solve.
    pub u: Vec<f64>,
    /// Newton iterations of the last solve.
    pub newton_iterations: usize,
    /// Numeric factorisations of the last solve.
    pub factorizations: usize,
    /// Time split of the last solve (assembly, factorisation, triangular solves; total).
    pub timings: Timings,
    /// Index of the solver this state is solved with.
    slot: usize,
}

/// A static FEM problem driven by the filter (see the module documentation).
pub struct FemModel {
    problem: Problem,
    parameters: Vec<FemParameter>,
    loads: Vec<LoadPattern>,
    controls: Vec<ControlPath>,
    observed: Vec<TrackedPoint>,
    options: SolverOptions,
    solvers: Vec<Mutex<Option<StaticSolver>>>,
}

impl std::fmt::Debug for FemModel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("FemModel")
            .field("nodes", &self.problem.mesh.num_nodes())
            .field("parameters", &self.parameters)
            .field("observed_points", &self.observed.len())
            .finish()
    }
}

impl FemModel {
    /// A model over `problem` (its material, springs, forces and prescribed values are the base that the
    /// parameters and loads modify at every step). One solver slot per sigma point, `2 parameters.len() + 1`
    /// slots: enough for either sigma-point set (a slot's solver is only created when its sigma point first runs).
    pub fn new(
        problem: Problem,
        parameters: Vec<FemParameter>,
        loads: Vec<LoadPattern>,
        observed: Vec<TrackedPoint>,
        options: SolverOptions,
    ) -> Result<Self, FemModelError> {
        problem.validate()?;
        let n = problem.mesh.num_nodes();
        let invalid = |m: String| Err(FemModelError::Invalid(m));
        for (j, p) in parameters.iter().enumerate() {
            if let FemParameter::Springs { nodes } = p {
                if nodes.is_empty() {
                    return invalid(format!("spring parameter #{j} has no node"));
                }
                if let Some(&k) = nodes.iter().find(|&&k| k >= n) {
                    return invalid(format!("spring parameter #{j} refers to node {k}, but the mesh has {n} nodes"));
                }
            }
        }
        for (j, load) in loads.iter().enumerate() {
            if load.profile.period() == 0 {
                return invalid(format!("load #{j}: the period of its profile must be at least one step"));
            }
            for (k, v) in load.forces.iter().chain(&load.displacements) {
                if *k >= n || v.iter().any(|c| !c.is_finite()) {
                    return invalid(format!("load #{j}: node {k} (of {n}) with value {v:?} is not usable"));
                }
            }
            if let Some((k, _)) = load.displacements.iter().find(|(k, _)| !problem.dirichlet.contains_key(k)) {
                return invalid(format!("load #{j} prescribes a displacement on node {k}, which is not constrained"));
            }
        }
        if observed.is_empty() {
            return invalid("no observed point".into());
        }
        for t in &observed {
            t.validate(n)?;
        }
        let solvers = (0..SigmaPointSet::Star.count(parameters.len())).map(|_| Mutex::new(None)).collect();
        Ok(FemModel { problem, parameters, loads, controls: Vec::new(), observed, options, solvers })
    }

    /// The model with displacements prescribed step by step on constrained nodes (see [`ControlPath`]).
    pub fn with_controls(mut self, controls: Vec<ControlPath>) -> Result<Self, FemModelError> {
        let n = self.problem.mesh.num_nodes();
        for c in &controls {
            if !self.problem.dirichlet.contains_key(&c.node) {
                return Err(FemModelError::Invalid(format!(
                    "control path on node {} (of {n}), which is not constrained",
                    c.node
                )));
            }
            if c.displacements.iter().flatten().any(|v| !v.is_finite()) {
                return Err(FemModelError::Invalid(format!("control path on node {} is not finite", c.node)));
            }
        }
        self.controls = controls;
        Ok(self)
    }

    /// The rest state (zero displacement), solved with the first solver slot.
    pub fn initial_state(&self) -> FemState {
        FemState {
            u: vec![0.0; self.problem.num_dofs()],
            newton_iterations: 0,
            factorizations: 0,
            timings: Timings::default(),
            slot: 0,
        }
    }

    /// The base problem.
    pub fn problem(&self) -> &Problem {
        &self.problem
    }

    /// The uncertain parameters, in filter order.
    pub fn parameters(&self) -> &[FemParameter] {
        &self.parameters
    }

    /// The observed points.
    pub fn observed_points(&self) -> &[TrackedPoint] {
        &self.observed
    }

    /// The base problem with the physical parameter values `theta` and the loads of time step `step` applied.
    pub fn configure(&self, problem: &mut Problem, theta: &[f64], step: usize) -> Result<(), FemModelError> {
        if theta.len() != self.parameters.len() {
            return Err(FemModelError::Invalid(format!(
                "{} parameter values given, the model has {}",
                theta.len(),
                self.parameters.len()
            )));
        }
        problem.material = self.problem.material;
        problem.springs.clone_from(&self.problem.springs);
        problem.f_ext.clone_from(&self.problem.f_ext);
        problem.dirichlet.clone_from(&self.problem.dirichlet);
        for (p, &value) in self.parameters.iter().zip(theta) {
            match p {
                FemParameter::Young => problem.material.young = value,
                FemParameter::Springs { nodes } => {
                    for &k in nodes {
                        problem.springs[k] += value;
                    }
                }
            }
        }
        for load in &self.loads {
            let a = load.profile.amplitude(step);
            for (k, f) in &load.forces {
                for (target, f) in problem.f_ext[3 * k..3 * k + 3].iter_mut().zip(f) {
                    *target += a * f;
                }
            }
            for (k, v) in &load.displacements {
                if let Some(x) = problem.dirichlet.get_mut(k) {
                    for (x, v) in x.iter_mut().zip(v) {
                        *x += a * v;
                    }
                }
            }
        }
        for c in &self.controls {
            let v = step.checked_sub(1).and_then(|i| c.displacements.get(i)).ok_or_else(|| {
                FemModelError::Invalid(format!(
                    "the control path on node {} has {} steps, step {step} asked",
                    c.node,
                    c.displacements.len()
                ))
            })?;
            if let Some(x) = problem.dirichlet.get_mut(&c.node) {
                for (x, v) in x.iter_mut().zip(v) {
                    *x += v;
                }
            }
        }
        Ok(())
    }

    /// Runs the model alone with fixed parameters `theta` over time steps `1..=steps` (a new solver, each step
    /// warm-started from the previous one) and hands every state to `visit` with its step.
    pub fn simulate(
        &self,
        theta: &[f64],
        steps: usize,
        mut visit: impl FnMut(usize, &FemState),
    ) -> Result<(), FemModelError> {
        let mut solver = StaticSolver::new(self.problem.clone())?;
        let mut state = self.initial_state();
        for k in 1..=steps {
            self.solve_step(&mut solver, &mut state, theta, k)?;
            visit(k, &state);
        }
        Ok(())
    }

    fn solve_step(
        &self,
        solver: &mut StaticSolver,
        state: &mut FemState,
        theta: &[f64],
        step: usize,
    ) -> Result<(), FemModelError> {
        self.configure(solver.problem_mut(), theta, step)?;
        let solution = solver.solve_from(Some(&state.u), &self.options)?;
        state.u = solution.u;
        state.newton_iterations = solution.iterations;
        state.factorizations = solution.factorizations;
        state.timings = solution.timings;
        Ok(())
    }
}

impl Model for FemModel {
    type State = FemState;
    type Error = FemModelError;

    /// A positive, finite Young's modulus; springs that leave every node's stiffness finite and
    /// non-negative.
    fn admissible(&self, theta: &[f64]) -> Result<(), FemModelError> {
        for (p, &value) in self.parameters.iter().zip(theta) {
            let fault = match p {
                FemParameter::Young if !(value > 0.0 && value.is_finite()) => {
                    format!(
                        "Young's modulus {value:.6e} Pa is not positive and finite: the filter, on the modulus \
                         itself, stepped past zero (a prior far from the data), or spread its sigma points past it \
                         (a prior_std not well below prior_mean); `transform = \"exp\"` in the parameter's section \
                         keeps it positive"
                    )
                }
                FemParameter::Springs { nodes }
                    if !nodes.iter().all(|&k| (0.0..f64::INFINITY).contains(&(self.problem.springs[k] + value))) =>
                {
                    format!(
                        "a spring stiffness of {value:.6e} N/m leaves a node's stiffness negative: the filter, on the \
                         stiffness itself, stepped past zero, or spread its sigma points past it; \
                         `transform = \"exp\"` in the parameter's section keeps it positive"
                    )
                }
                _ => continue,
            };
            return Err(FemModelError::Invalid(fault));
        }
        Ok(())
    }

    fn step(&self, state: &mut FemState, theta: &[f64], step: usize) -> Result<(), FemModelError> {
        let slot = self.solvers.get(state.slot).ok_or_else(|| {
            FemModelError::Invalid(format!(
                "state of solver slot {} (the model has {})",
                state.slot,
                self.solvers.len()
            ))
        })?;
        let mut guard = slot.lock().unwrap_or_else(PoisonError::into_inner);
        let solver = match &mut *guard {
            Some(solver) => solver,
            empty => empty.insert(StaticSolver::new(self.problem.clone())?),
        };
        self.solve_step(solver, state, theta, step)
    }

    fn observe(&self, state: &FemState) -> DVector<f64> {
        tracked_positions(&self.problem.mesh.nodes, &self.observed, &state.u)
    }

    fn assign_sigma_point(&self, state: &mut FemState, sigma_point: usize) {
        state.slot = sigma_point;
    }
}
