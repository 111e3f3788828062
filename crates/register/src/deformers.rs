//! The ways of turning observations into a volumetric displacement: the finite-element model
//! pulled by data springs, a trained U-Net, and the two in turn (the network's estimate, then a
//! few finite-element iterations from it).

use fem::{Continuation, PointSpring, Problem, SolverOptions, StaticSolver};
use learn::data::generate::normal_part;
use learn::{encode_points, GridToMesh, Model, ModelPredictor};
use mesh::embedding::Grid;

use crate::checks::check_setting;
use crate::frame::{Deformer, Observations};
use crate::organ::Organ;
use crate::{RegisterError, Result};

/// Finite-element registration: every matched surface point is tied by a zero-length spring
/// to its cloud point (a [`PointSpring`] on the nodes that move it, mostly point to plane);
/// the organ's own boundary conditions (fixed nodes, its springs and point springs) hold the
/// rest. The scenario's loads are dropped: the intraoperative loads are unknown, the data stand
/// in for them. The springs stiffen over the first iterations of a frame (`STIFFNESS_RAMP`): the
/// first matches of a large deformation are poor, and stiff springs pulling towards them would
/// crush elements.
pub struct FemDeformer {
    solver: StaticSolver,
    stiffness: f64,
    options: SolverOptions,
    /// The problem's own point springs (e.g. an elastic foundation) come first; the data
    /// springs follow them.
    own_springs: usize,
}

/// Share of the data stiffness that ties a point to its cloud point in every direction; the
/// rest acts along the surface normal only (point to plane), so that the surface can slide
/// along itself.
pub const ISOTROPIC_FRACTION: f64 = 0.05;

/// Iterations over which the data springs reach their stiffness, ×4 per iteration.
pub const STIFFNESS_RAMP: usize = 3;

/// Most quarterings of the data springs' stiffness a failed solve is made again with: below the
/// ramp's first stiffness too (to 4⁻⁶ of the stiffness), for a first match so poor that even the
/// ramp's first springs would invert an element.
pub const MAX_SOFTENING: usize = STIFFNESS_RAMP + 3;

/// The loosest relative residual a solve of the registration loop is taken to: the next
/// iteration matches again and solves again. On the press-and-release stream of the
/// registration case (40 frames, 4 iterations per frame) 1e-3, 1e-4 and 1e-6 gave the same TRE
/// (1.23 mm), 1e-6 at 1.6× the time per frame; 1e-2 lost 0.04 mm.
pub const REGISTRATION_RTOL: f64 = 1e-3;

impl FemDeformer {
    /// The deformer of `problem` (its mesh must be the organ's) with data springs of
    /// `stiffness` N/m in total, shared by the matched cloud points, solved with `options`, their
    /// residual tolerance relaxed to `REGISTRATION_RTOL` when tighter, and under force control
    /// alone, without load-step cuts ([`Continuation::ForceOnly`]): a solve that fails is made again
    /// with softer springs, then stiffened from the softer equilibrium, in a fraction of the seconds
    /// that halving the load from rest, or an arc-length continuation past the failure, can take (on
    /// the 2.5 N right-lobe press of `augsim experiment liver-ar`, 1.2 s a frame against 6.6 s with
    /// the continuation, the TRE within 0.05 mm).
    pub fn new(mut problem: Problem, stiffness: f64, mut options: SolverOptions) -> Result<FemDeformer> {
        options.rtol = options.rtol.max(REGISTRATION_RTOL);
        options.max_step_cuts = 0;
        options.continuation = Continuation::ForceOnly;
        if !(stiffness > 0.0 && stiffness.is_finite()) {
            return Err(RegisterError::Invalid(format!("data stiffness {stiffness} N/m must be positive")));
        }
        problem.f_ext.iter_mut().for_each(|f| *f = 0.0);
        let own_springs = problem.point_springs.len();
        Ok(FemDeformer { solver: StaticSolver::new(problem)?, stiffness, options, own_springs })
    }

    /// A data stiffness fifty times the organ's own scale E·L (L: the cube root of its volume):
    /// the surface follows the data within a millimetre where a small patch of it moves by
    /// centimetres; the model fills in the rest. Chosen on the design pushes of `augsim register
    /// --demo` (1 to 2.5 N) among 100, 50 and 25 E·L.
    pub fn default_stiffness(problem: &Problem) -> f64 {
        50.0 * problem.material.young * problem.mesh.volume().abs().cbrt()
    }
}

impl Deformer for FemDeformer {
    fn set_deadline(&mut self, deadline: Option<std::time::Instant>) {
        self.options.deadline = deadline;
    }

    fn deform(&mut self, observations: &Observations, previous: &[f64], iteration: usize) -> Result<Vec<f64>> {
        if observations.matches.is_empty() {
            return Err(RegisterError::Invalid("no cloud point matches the organ surface".into()));
        }
        // A solve that fails (no equilibrium: the data springs would invert an element) is
        // made again with springs a quarter as stiff, down to [`MAX_SOFTENING`], so that a
        // stream goes on where the model cannot follow the cloud all the way; from the softer
        // equilibrium the springs stiffen again, a quarter at a time, as far as a solve succeeds.
        let wanted = STIFFNESS_RAMP.saturating_sub(iteration);
        let (mut softening, mut reached): (usize, Option<Vec<f64>>) = (wanted, None);
        loop {
            let k = 0.25f64.powi(softening as i32) * self.stiffness / observations.matches.len() as f64;
            let springs = &mut self.solver.problem_mut().point_springs;
            springs.truncate(self.own_springs);
            springs.extend(observations.matches.iter().map(|m| PointSpring {
                nodes: m.stencil.0.clone(),
                target: m.shift,
                stiffness: ISOTROPIC_FRACTION * k,
                normal: m.normal,
                normal_stiffness: (1.0 - ISOTROPIC_FRACTION) * k,
            }));
            match self.solver.solve_from(Some(reached.as_deref().unwrap_or(previous)), &self.options) {
                // Past the frame's deadline: the best estimate so far.
                Err(fem::FemError::OutOfTime) => return Ok(reached.unwrap_or_else(|| previous.to_vec())),
                Ok(solution) if softening == wanted => return Ok(solution.u),
                Ok(solution) => {
                    softening -= 1;
                    reached = Some(solution.u);
                }
                Err(e) => match reached {
                    Some(u) => return Ok(u),
                    None if softening >= MAX_SOFTENING => return Err(e.into()),
                    None => softening += 1,
                },
            }
        }
    }
}

/// A learned model (a shape-space fit, or the U-Net) for the first iterations of a frame from rest,
/// then another deformer from its estimate, as on a frame warm-started from the last: the
/// finite-element model (the learned model brings the surface near the cloud in milliseconds, so
/// that the matches the springs pull on are already good, and the springs take their full stiffness
/// at once), or a learned model's match-and-membrane loop (predicting from the surface the shape
/// fit found). A warm-started frame (a stream) starts near the cloud already: the second deformer
/// alone registers it, or the second after the first's iterations from its last posterior
/// ([`HybridDeformer::first_on_warm_frames`]), or the first alone
/// ([`HybridDeformer::first_alone_on_warm_frames`]).
///
/// σ: the expected distance of the second's estimate to the truth under the first's posterior:
/// with the first's error of standard deviation σ₁ and the second's estimate Δ away from the
/// first's, √(σ₁² + |Δ|²); the second's own when the first predicts none. The first's estimate is
/// the one the second started from, or, on a warm-started frame that the second registers alone,
/// the first's fit (from its own last posterior, as on a stream) to the matches of the frame's
/// last iteration when σ is asked. A calibration factor may scale that σ
/// ([`HybridDeformer::sigma_scaled`]).
pub struct HybridDeformer {
    first: Box<dyn Deformer + Send>,
    then: Box<dyn Deformer + Send>,
    /// The first's iterations on a frame from rest before the second's.
    from_rest: usize,
    /// The first's iterations at the start of a warm-started frame (`None`: the first alone).
    warm_first: Option<usize>,
    /// The iteration of a frame from rest at which the second deformer takes over, when the
    /// first settled before its iterations were spent.
    handover: Option<usize>,
    /// Whether the frame under way is warm-started.
    warm: bool,
    /// Whether the second deformer has registered in the frame under way.
    then_ran: bool,
    /// Once the second deformer has taken over: the first's estimate, and (at the frame's end) the
    /// second's, whose difference widens the first's σ.
    first_estimate: Option<Vec<f64>>,
    then_estimate: Option<Vec<f64>>,
    /// At the end of a warm-started frame: the matches of its last iteration.
    last_observations: Option<Observations>,
    /// The factor on σ where the second's estimate widens the first's.
    sigma_factor: f64,
}

// The second deformer goes on as on a warm-started frame: past the data springs' stiffness ramp.
const _: () = assert!(crate::frame::WARM_START_ITERATION >= STIFFNESS_RAMP);

impl HybridDeformer {
    /// `first` (a learned model's deformer) for the first `first_iterations` iterations of a frame
    /// from rest (at least 1), or until it settles, `then` (on the same organ) after them and on
    /// warm-started frames.
    pub fn new(
        first: Box<dyn Deformer + Send>,
        then: Box<dyn Deformer + Send>,
        first_iterations: usize,
    ) -> Result<HybridDeformer> {
        if first_iterations == 0 {
            return Err(RegisterError::Invalid(
                "a hybrid registration needs at least one iteration of its first model".into(),
            ));
        }
        Ok(HybridDeformer {
            first,
            then,
            from_rest: first_iterations,
            warm_first: Some(0),
            handover: None,
            warm: false,
            then_ran: false,
            first_estimate: None,
            then_estimate: None,
            last_observations: None,
            sigma_factor: 1.0,
        })
    }

    /// On a warm-started frame, `iterations` of the first deformer (from its last posterior) before
    /// the second takes over from its estimate (default: none, the second alone).
    pub fn first_on_warm_frames(mut self, iterations: usize) -> HybridDeformer {
        self.warm_first = Some(iterations);
        self
    }

    /// On a warm-started frame, the first deformer alone (from its last posterior), as it
    /// registers a stream's frames on its own; σ is then its own.
    pub fn first_alone_on_warm_frames(mut self) -> HybridDeformer {
        self.warm_first = None;
        self
    }

    /// σ where the second's estimate widens the first's, times `factor` (positive): a
    /// calibration on registrations whose truth is known.
    pub fn sigma_scaled(mut self, factor: f64) -> Result<HybridDeformer> {
        check_setting("sigma_factor", factor, factor > 0.0, "positive")?;
        self.sigma_factor = factor;
        Ok(self)
    }

    /// The iteration of the frame under way at which the second deformer takes over (`None`: it
    /// does not).
    fn takeover(&self) -> Option<usize> {
        match self.warm {
            true => self.warm_first.map(|first| crate::frame::WARM_START_ITERATION + first),
            false => Some(self.handover.unwrap_or(self.from_rest)),
        }
    }
}

impl Deformer for HybridDeformer {
    fn start_frame(&mut self, warm: bool) {
        self.warm = warm;
        self.then_ran = false;
        self.handover = None;
        self.first_estimate = None;
        self.then_estimate = None;
        self.last_observations = None;
        self.first.start_frame(warm);
        self.then.start_frame(warm);
    }

    fn set_deadline(&mut self, deadline: Option<std::time::Instant>) {
        self.first.set_deadline(deadline);
        self.then.set_deadline(deadline);
    }

    fn deform(&mut self, observations: &Observations, previous: &[f64], iteration: usize) -> Result<Vec<f64>> {
        let then = match (self.warm, self.takeover().and_then(|at| iteration.checked_sub(at))) {
            (_, None) => None,
            (false, Some(k)) => Some(crate::frame::WARM_START_ITERATION + k),
            (true, Some(_)) => Some(iteration),
        };
        let Some(iteration) = then else { return self.first.deform(observations, previous, iteration) };
        if !self.warm || self.warm_first != Some(0) {
            self.first_estimate.get_or_insert_with(|| previous.to_vec());
        }
        self.then_ran = true;
        self.then.deform(observations, previous, iteration)
    }

    fn settled(&mut self, iteration: usize) -> bool {
        // The first deformer settled (on a frame from rest) or ended its part (on a warm-started
        // frame): the second takes over from its estimate, where it takes over at all.
        let first_settled = self.takeover().is_some_and(|at| iteration < at);
        if first_settled && !self.warm {
            self.handover = Some(iteration + 1);
        }
        first_settled
    }

    fn end_frame(&mut self, observations: Observations, u: &[f64]) {
        // Kept for σ once the second deformer has registered: on a frame from rest after the
        // first's iterations; on a warm-started frame, unless the first registered it alone.
        if self.then_ran {
            self.then_estimate = Some(u.to_vec());
            if self.warm && self.first_estimate.is_none() {
                self.last_observations = Some(observations);
            }
        }
    }

    fn uncertainty(&mut self, stencils: &[crate::Stencil]) -> Option<Result<Vec<f64>>> {
        if self.then_estimate.is_none() {
            return self.first.uncertainty(stencils);
        }
        if let (Some(observations), Some(then)) = (self.last_observations.take(), &self.then_estimate) {
            match self.first.deform(&observations, then, crate::WARM_START_ITERATION) {
                Ok(u) => self.first_estimate = Some(u),
                Err(e) => return Some(Err(e)),
            }
        }
        let (first, then) = (self.first_estimate.as_ref()?, self.then_estimate.as_ref()?);
        let sigma = match self.first.uncertainty(stencils) {
            Some(Ok(sigma)) => sigma,
            Some(Err(e)) => return Some(Err(e)),
            None => return self.then.uncertainty(stencils),
        };
        Some(Ok(sigma
            .iter()
            .zip(stencils)
            .map(|(s, stencil)| {
                let moved = mesh::sub(stencil.vector(then), stencil.vector(first));
                self.sigma_factor * (s * s + mesh::dot(moved, moved)).sqrt()
            })
            .collect()))
    }
}

/// U-Net registration. The displacement of the network's input nodes (the visible surface) is
/// first fitted to the matches: the surface it interpolates passes near each matched cloud
/// point (least squares), with a membrane penalty on neighbouring nodes' differences, unseen
/// nodes interpolated. A network trained on the normal motion of its input nodes (`normal =
/// true` in the dataset's input, as the built-in `liver_ar` scenario) gets the normal part of that fit,
/// which is what closest-point matching measures, and infers the tangential motion and the
/// volume. A network trained on the full displacement gets the fit itself, and its input nodes
/// keep the fit (fed back, its own predictions at its inputs would drift along the surface,
/// where no match corrects them).
pub struct NetworkDeformer {
    predictor: ModelPredictor,
    grid: Grid,
    to_mesh: GridToMesh,
    /// The input nodes (mesh numbering) and their positions.
    inputs: Vec<usize>,
    points: Vec<mesh::Point>,
    /// The nodes the surface fit may move: the inputs, then the other nodes of the surface.
    /// Each mesh node's index among them (`usize::MAX`: none), and how many there are.
    local: Vec<usize>,
    fit_count: usize,
    /// Mesh edges between those nodes, as their indices.
    edges: Vec<(usize, usize)>,
    /// For a network of normal motion: the outward unit normal of the rest surface at each
    /// input node.
    normals: Option<Vec<mesh::Point>>,
    /// Whether the network was trained on part of its input nodes (a sparsity corruption): it
    /// then takes the input nodes the cloud observes, the others absent, rather than the
    /// surface fit's extrapolation to them.
    partial: bool,
    /// The input field of the last prediction, whose predicted standard deviation
    /// [`Deformer::uncertainty`] gives (computed there: the iterations need the displacement only).
    last_input: Option<Vec<f32>>,
    /// When the surface fit holds the input nodes no match moves at their current estimate
    /// ([`NetworkDeformer::holding_unseen`], [`NetworkDeformer::holding_unseen_on_warm_frames`]).
    hold_unseen: HoldUnseen,
    /// Whether the frame under way is warm-started.
    warm: bool,
}

/// When a [`NetworkDeformer`]'s surface fit holds the unseen input nodes at their estimate.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum HoldUnseen {
    /// Never: the membrane carries the seen part's motion over them.
    Never,
    /// On a stream's warm-started frames: at the last frame's estimate.
    OnWarmFrames,
    /// On every frame: at the estimate the loop starts from (a shape fit's).
    Always,
}

/// Weight of the membrane penalty, relative to a matched cloud point's. Chosen on the design
/// pushes of `augsim register --demo` (1 to 2.5 N): of 0.3, 0.1, 0.03, 0.01 and 0.003, 0.03 gave
/// the lowest TRE; below it the fit follows the noise and the loop no longer settles at 2.5 N.
pub const MEMBRANE_WEIGHT: f64 = 0.03;

/// Relative residual at which the surface fit stops (its error is then well below a micrometre).
const FIT_TOLERANCE: f64 = 1e-6;

/// Weight pulling an input node towards its current estimate (keeps nodes without data or
/// neighbours determined).
const ANCHOR_WEIGHT: f64 = 1e-3;

/// Weight holding an unseen input node at its current estimate, when held
/// ([`NetworkDeformer::holding_unseen`]): a match's (its interpolation weights sum to one). On
/// the design case streamed and on a still half view 0.1 to 1000 gave the same TRE within 0.05 mm.
const HOLD_WEIGHT: f64 = 1.0;

impl NetworkDeformer {
    /// Most match-and-deform iterations of a frame from rest by default: the real-time budget
    /// (the loop's tolerance alone would often take it to 10–30 iterations). On the cases a
    /// network is chosen on (the built-in registration case and the three beyond pushes of
    /// `augsim experiment liver-ar`), 6, 5, 4, 3 and 2 iterations gave a mean TRE of 1.44, 1.42,
    /// 1.45, 1.65 and 2.16 mm: 4 is the fewest within 0.03 mm of the best, at three quarters of
    /// 6's time. Those cases hold no deep press; on the deep held-out presses 4 loses accuracy
    /// (`augsim experiment held-out`).
    pub const ITERATIONS: usize = 4;

    /// Most iterations of a frame warm-started from the previous one by default: on the built-in
    /// case as a 40-frame press and release of 3,000-point clouds, 4, 3 and 2 gave the same TRE
    /// (1.04, 1.04, 1.03 mm) at 39, 31 and 25 ms per frame.
    pub const WARM_ITERATIONS: usize = 2;

    /// The loop's settings of the match-and-membrane loop: `base` with the
    /// [`NetworkDeformer::ITERATIONS`] and [`NetworkDeformer::WARM_ITERATIONS`] budgets.
    pub fn loop_options(base: &crate::RegistrationOptions) -> crate::RegistrationOptions {
        crate::RegistrationOptions {
            iterations: Self::ITERATIONS,
            warm_iterations: Self::WARM_ITERATIONS,
            ..base.clone()
        }
    }

    /// The deformer of `model` for `organ` (meshed on the model's grid, or embedded in it);
    /// `input_nodes`: the mesh nodes whose displacement the network was trained to take, along
    /// the rest surface's normal only when `normal` (boundary nodes then).
    pub fn new(model: &Model, organ: &Organ, input_nodes: &[usize], normal: bool) -> Result<NetworkDeformer> {
        if model.takes_forces() {
            return Err(RegisterError::Invalid(format!(
                "the model takes {} on its input, registration needs a displacement model (m)",
                model.input_unit()
            )));
        }
        let grid = model.placed_grid()?;
        let mesh = organ.mesh();
        // The nodes the fit may move: the inputs first, then the other nodes that move the surface.
        let mut local = vec![usize::MAX; mesh.num_nodes()];
        for (i, &n) in input_nodes.iter().enumerate() {
            *local.get_mut(n).ok_or_else(|| RegisterError::Invalid(format!("input node {n} is not a mesh node")))? = i;
        }
        let mut fit_count = input_nodes.len();
        for &(n, _) in organ.surface_stencils().iter().flat_map(|s| &s.0) {
            if local[n] == usize::MAX {
                local[n] = fit_count;
                fit_count += 1;
            }
        }
        let mut edges = Vec::new();
        for c in 0..mesh.cells.len() {
            let cell = mesh.cells.cell(c);
            for (a, &p) in cell.iter().enumerate() {
                for &q in &cell[a + 1..] {
                    let (i, j) = (local[p], local[q]);
                    if i != usize::MAX && j != usize::MAX {
                        edges.push((i.min(j), i.max(j)));
                    }
                }
            }
        }
        edges.sort_unstable();
        edges.dedup();
        let normals = if normal {
            let all = mesh.surface_normals();
            let picked: Vec<mesh::Point> = input_nodes.iter().map(|&n| all[n]).collect();
            if let Some(i) = picked.iter().position(|n| *n == [0.0; 3]) {
                return Err(RegisterError::Invalid(format!(
                    "input node {} is not on the surface: it has no normal",
                    input_nodes[i]
                )));
            }
            Some(picked)
        } else {
            None
        };
        Ok(NetworkDeformer {
            predictor: model.predictor(learn::Compute::Cpu)?,
            to_mesh: GridToMesh::new(mesh, &grid)?,
            grid,
            inputs: input_nodes.to_vec(),
            local,
            fit_count,
            points: input_nodes.iter().map(|&n| mesh.nodes[n]).collect(),
            edges,
            normals,
            partial: model.training_corruption().sparsity.is_some(),
            last_input: None,
            hold_unseen: HoldUnseen::Never,
            warm: false,
        })
    }

    /// The surface fit holds the input nodes no match moves at their current estimate, as firmly
    /// as a match holds a seen one (`HOLD_WEIGHT`), rather than letting the membrane carry the
    /// seen part's motion over them: for a loop that starts from a shape fit, whose estimate there
    /// is its extrapolation from the whole view. Spread by the membrane, the unseen part of a half
    /// view fed back frame after frame took the reduced-order model's TRE from 4.95 to 14.87 mm on a
    /// still cloud.
    pub fn holding_unseen(mut self) -> NetworkDeformer {
        self.hold_unseen = HoldUnseen::Always;
        self
    }

    /// The surface fit holds the input nodes no match moves at their current estimate on a
    /// stream's warm-started frames only: what the camera no longer sees stays where the last
    /// frames put it, rather than follow the seen part through the membrane (from rest the
    /// membrane spreads the seen motion, as before). On the design cases streamed (21 frames) the
    /// U-Net's TRE over the frames went from 1.54 to 1.52 mm (no case worse); on streams whose
    /// camera turns 30° a frame, or looks obliquely, from 17.97 to 2.76 mm and from 5.29 to 3.05 mm.
    pub fn holding_unseen_on_warm_frames(mut self) -> NetworkDeformer {
        self.hold_unseen = HoldUnseen::OnWarmFrames;
        self
    }

    /// The surface estimate: the displacement `s` of the input nodes and of the other matched
    /// nodes minimising, per coordinate, Σ_matches (Σ_j a_j s_j − shift)² + λ Σ_edges (s_i −
    /// s_j)² + Σ ε_i |s_i − s₀_i|², where a_j are a match's interpolation weights, λ the membrane
    /// weight, s₀ the current estimate and ε_i `ANCHOR_WEIGHT` (`HOLD_WEIGHT` at a held unseen
    /// node); by Jacobi-preconditioned conjugate gradients from s₀. Returns
    /// the input nodes' part. Fitting the matches themselves, not each node's mean match offset,
    /// keeps the depth of a push: a mean over the triangles around a node flattens a dent.
    pub fn surface_estimate(&self, observations: &Observations, previous: &[f64]) -> Vec<[f64; 3]> {
        // The unknowns: the inputs, then the other fit nodes that a match moves.
        let mut unknown = vec![usize::MAX; self.fit_count];
        let mut nodes: Vec<usize> = self.inputs.clone();
        unknown[..nodes.len()].iter_mut().enumerate().for_each(|(i, u)| *u = i);
        let mut rows: Vec<FitRow> = Vec::with_capacity(observations.matches.len());
        for matched in &observations.matches {
            let mut weights = Vec::with_capacity(matched.stencil.0.len());
            for &(node, w) in &matched.stencil.0 {
                let f = self.local[node];
                if unknown[f] == usize::MAX {
                    unknown[f] = nodes.len();
                    nodes.push(node);
                }
                weights.push((unknown[f], w));
            }
            rows.push((weights, matched.shift));
        }
        let n = nodes.len();
        let edges: Vec<(usize, usize)> = self
            .edges
            .iter()
            .map(|&(i, j)| (unknown[i], unknown[j]))
            .filter(|&(i, j)| i != usize::MAX && j != usize::MAX)
            .collect();
        // Each unknown's weight towards its current estimate: held where unseen, if so asked.
        let mut anchor = vec![ANCHOR_WEIGHT; n];
        let hold = match self.hold_unseen {
            HoldUnseen::Never => false,
            HoldUnseen::OnWarmFrames => self.warm,
            HoldUnseen::Always => true,
        };
        if hold {
            let mut seen = vec![false; n];
            rows.iter().flat_map(|(a, _)| a).filter(|(_, w)| *w > 0.0).for_each(|&(i, _)| seen[i] = true);
            anchor.iter_mut().zip(&seen).filter(|(_, &seen)| !seen).for_each(|(a, _)| *a = HOLD_WEIGHT);
        }
        // A x for the three coordinates at once (the matrix is the same for each).
        let apply = |x: &[[f64; 3]], out: &mut [[f64; 3]]| {
            for ((o, x), a) in out.iter_mut().zip(x).zip(&anchor) {
                *o = x.map(|v| a * v);
            }
            for (a, _) in &rows {
                let mut ax = [0.0; 3];
                for &(i, w) in a {
                    (0..3).for_each(|d| ax[d] += w * x[i][d]);
                }
                for &(i, w) in a {
                    (0..3).for_each(|d| out[i][d] += w * ax[d]);
                }
            }
            for &(i, j) in &edges {
                for d in 0..3 {
                    let f = MEMBRANE_WEIGHT * (x[i][d] - x[j][d]);
                    out[i][d] += f;
                    out[j][d] -= f;
                }
            }
        };
        let mut diagonal = anchor.clone();
        for &(i, w) in rows.iter().flat_map(|(a, _)| a) {
            diagonal[i] += w * w;
        }
        for &(i, j) in &edges {
            diagonal[i] += MEMBRANE_WEIGHT;
            diagonal[j] += MEMBRANE_WEIGHT;
        }
        let start: Vec<[f64; 3]> = nodes.iter().map(|&k| std::array::from_fn(|d| previous[3 * k + d])).collect();
        let mut rhs: Vec<[f64; 3]> = start.iter().zip(&anchor).map(|(s, a)| s.map(|v| a * v)).collect();
        for (a, shift) in &rows {
            for &(i, w) in a {
                (0..3).for_each(|d| rhs[i][d] += w * shift[d]);
            }
        }
        let mut x = conjugate_gradients(apply, &diagonal, &rhs, start, FIT_TOLERANCE);
        x.truncate(self.inputs.len());
        x
    }

    /// The input nodes' rest positions, in the order of [`NetworkDeformer::predict`]'s surface.
    pub fn input_points(&self) -> &[mesh::Point] {
        &self.points
    }

    /// The network's displacement of the organ (3 per mesh node) from the displacement of its
    /// input nodes: along their normals only for a network of normal motion; a network of the
    /// full displacement keeps `surface` at its input nodes.
    pub fn predict(&self, surface: &[[f64; 3]]) -> Result<Vec<f64>> {
        Ok(self.predict_seen(surface, None)?.0)
    }

    /// [`NetworkDeformer::predict`] from the input nodes marked in `seen` only (all: `None`), with
    /// the input field it gave the model.
    fn predict_seen(&self, surface: &[[f64; 3]], seen: Option<&[bool]>) -> Result<(Vec<f64>, Vec<f32>)> {
        if surface.len() != self.inputs.len() {
            return Err(RegisterError::Invalid(format!(
                "{} input displacements for {} input nodes",
                surface.len(),
                self.inputs.len()
            )));
        }
        let kept: Vec<usize> = (0..surface.len()).filter(|&i| seen.is_none_or(|s| s[i])).collect();
        let points: Vec<mesh::Point> = kept.iter().map(|&i| self.points[i]).collect();
        let values: Vec<mesh::Point> = match &self.normals {
            Some(normals) => kept.iter().map(|&i| normal_part(&surface[i], normals[i])).collect(),
            None => kept.iter().map(|&i| surface[i]).collect(),
        };
        let input = encode_points(&self.grid, &points, &values, false)?;
        let mut u = self.to_mesh.apply(&self.predictor.predict(&input)?)?;
        if self.normals.is_none() {
            for (&n, s) in self.inputs.iter().zip(surface) {
                u[3 * n..3 * n + 3].copy_from_slice(s);
            }
        }
        Ok((u, input))
    }

    /// Which input nodes a match of `observations` moves.
    fn observed_inputs(&self, observations: &Observations) -> Vec<bool> {
        let mut seen = vec![false; self.inputs.len()];
        for &(n, w) in observations.matches.iter().flat_map(|m| &m.stencil.0) {
            let i = self.local[n];
            if w > 0.0 && i < seen.len() {
                seen[i] = true;
            }
        }
        seen
    }
}

/// A match in the surface fit: its interpolation weights on the unknowns and its shift.
type FitRow = (Vec<(usize, f64)>, [f64; 3]);

/// Solves `A X = B` for a symmetric positive definite `A` given by its product and three
/// right-hand sides (the columns of `B`, each its own conjugate-gradient sequence sharing the
/// products), from `X`, to a relative residual of `tolerance` per column (at most `b.len()`
/// iterations), preconditioned by the inverse of `A`'s `diagonal`.
fn conjugate_gradients(
    apply: impl Fn(&[[f64; 3]], &mut [[f64; 3]]),
    diagonal: &[f64],
    b: &[[f64; 3]],
    mut x: Vec<[f64; 3]>,
    tolerance: f64,
) -> Vec<[f64; 3]> {
    let n = b.len();
    let dot = |a: &[[f64; 3]], b: &[[f64; 3]]| {
        a.iter().zip(b).fold([0.0; 3], |s, (a, b)| std::array::from_fn(|d| s[d] + a[d] * b[d]))
    };
    let mut ax = vec![[0.0; 3]; n];
    apply(&x, &mut ax);
    let mut r: Vec<[f64; 3]> = b.iter().zip(&ax).map(|(b, a)| std::array::from_fn(|d| b[d] - a[d])).collect();
    let mut z: Vec<[f64; 3]> = r.iter().zip(diagonal).map(|(r, d)| r.map(|v| v / d)).collect();
    let mut p = z.clone();
    let mut rz = dot(&r, &z);
    let stop = dot(b, b).map(|bb| tolerance * tolerance * bb.max(f64::MIN_POSITIVE));
    let mut ap = vec![[0.0; 3]; n];
    for _ in 0..n {
        let rr = dot(&r, &r);
        // A converged column stops moving (its step is zero).
        let active: [bool; 3] = std::array::from_fn(|d| rr[d] > stop[d]);
        if !active.contains(&true) {
            break;
        }
        apply(&p, &mut ap);
        let pap = dot(&p, &ap);
        let alpha: [f64; 3] = std::array::from_fn(|d| if active[d] { rz[d] / pap[d] } else { 0.0 });
        for i in 0..n {
            for d in 0..3 {
                x[i][d] += alpha[d] * p[i][d];
                r[i][d] -= alpha[d] * ap[i][d];
                z[i][d] = r[i][d] / diagonal[i];
            }
        }
        let next = dot(&r, &z);
        let beta: [f64; 3] = std::array::from_fn(|d| if active[d] { next[d] / rz[d] } else { 0.0 });
        for i in 0..n {
            for d in 0..3 {
                p[i][d] = if active[d] { z[i][d] + beta[d] * p[i][d] } else { 0.0 };
            }
        }
        rz = next;
    }
    x
}

impl Deformer for NetworkDeformer {
    fn start_frame(&mut self, warm: bool) {
        self.warm = warm;
    }

    fn deform(&mut self, observations: &Observations, previous: &[f64], _iteration: usize) -> Result<Vec<f64>> {
        let seen = self.observed_inputs(observations);
        if !seen.contains(&true) {
            return Err(RegisterError::Invalid(
                "no cloud point lies near the network's input surface: the cloud is away from the organ (in another \
                 frame, or shifted: a rigid pre-alignment, --rigid, aligns it first)"
                    .into(),
            ));
        }
        let surface = self.surface_estimate(observations, previous);
        let (u, input) = self.predict_seen(&surface, self.partial.then_some(seen.as_slice()))?;
        self.last_input = Some(input);
        Ok(u)
    }

    /// The model's σ at the organ's nodes, as its displacement is taken there (the grid nodes
    /// inside the organ only: those outside carry no σ), then at each point by its stencil.
    fn uncertainty(&mut self, stencils: &[crate::Stencil]) -> Option<Result<Vec<f64>>> {
        let std = self.predictor.predict_std(self.last_input.as_ref()?).transpose()?;
        let at_nodes = std.and_then(|std| self.to_mesh.apply_channels(&std, 1)).map_err(RegisterError::from);
        Some(at_nodes.map(|at| stencils.iter().map(|s| s.scalar(&at)).collect()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frame::{observe, register_frame, RegistrationOptions};

    /// A block held only by an elastic foundation over its bottom centimetre, its top pressed
    /// down 5 mm: the
    /// registration keeps the foundation beside its data springs, so the base stays where it
    /// is while the top follows the cloud, frame after frame.
    #[test]
    fn the_problems_own_point_springs_stay_beside_the_data_springs() {
        let mesh = mesh::box_tet([0.0; 3], [0.04, 0.04, 0.04], [4, 4, 4]).unwrap();
        let mut problem = Problem::new(mesh, fem::Material::new(fem::Law::Corotational, 5000.0, 0.45));
        let base = mesh::Ball { centre: [0.02, 0.02, -0.5], radius: 0.51 };
        problem.add_foundation(&base, 1e10).unwrap();
        let own = problem.point_springs.len();
        let organ = Organ::new(problem.mesh.clone(), None).unwrap();
        let stiffness = FemDeformer::default_stiffness(&problem);
        let mut deformer = FemDeformer::new(problem, stiffness, SolverOptions::default()).unwrap();
        let press = |p: &mesh::Point| [p[0], p[1], p[2] - 0.005 * p[2] / 0.04];
        let cloud: Vec<mesh::Point> =
            organ.surface().vertices.iter().filter(|p| p[2] > 0.04 - 1e-9).map(press).collect();
        let options = RegistrationOptions { view: Some([0.0, 0.0, -1.0]), ..RegistrationOptions::default() };
        let mut start: Option<Vec<f64>> = None;
        for frame in 0..2 {
            let r = register_frame(&organ, &mut deformer, &cloud, start.as_deref(), &options).unwrap();
            let springs = &deformer.solver.problem().point_springs;
            assert_eq!(springs.len(), own + r.inliers, "frame {frame}: the foundation, then one spring per match");
            let node_z = |at: f64| -> f64 {
                let n = organ.mesh().nodes.iter().position(|p| (p[2] - at).abs() < 1e-9 && p[0] == 0.02).unwrap();
                r.u[3 * n + 2]
            };
            assert!(node_z(0.0).abs() < 2e-4, "frame {frame}: the base moved by {} m", node_z(0.0));
            assert!((node_z(0.04) + 0.005).abs() < 1e-3, "frame {frame}: the top moved by {} m", node_z(0.04));
            start = Some(r.u);
        }
    }

    /// A frame's time budget stops the FEM's solve under way, not only the iterations after it:
    /// with a budget already spent, the first solve gives back its start (rest) and the frame
    /// ends after one iteration, saying so; with a budget to spare, the same frame follows the
    /// cloud.
    #[test]
    fn a_frame_s_time_budget_stops_the_solve_under_way() {
        let mesh = mesh::box_tet([0.0; 3], [0.04, 0.04, 0.04], [4, 4, 4]).unwrap();
        let mut problem = Problem::new(mesh, fem::Material::new(fem::Law::Corotational, 5000.0, 0.45));
        let base: Vec<usize> = (0..problem.mesh.num_nodes()).filter(|&n| problem.mesh.nodes[n][2] < 1e-9).collect();
        problem.fix(&base);
        let organ = Organ::new(problem.mesh.clone(), None).unwrap();
        let stiffness = FemDeformer::default_stiffness(&problem);
        let cloud: Vec<mesh::Point> = organ
            .surface()
            .vertices
            .iter()
            .filter(|p| p[2] > 0.04 - 1e-9)
            .map(|p| [p[0], p[1], p[2] - 0.005])
            .collect();
        let frame = |budget: f64| {
            let mut deformer = FemDeformer::new(problem.clone(), stiffness, SolverOptions::default()).unwrap();
            let options = RegistrationOptions {
                view: Some([0.0, 0.0, -1.0]),
                time_budget_ms: Some(budget),
                ..Default::default()
            };
            register_frame(&organ, &mut deformer, &cloud, None, &options).unwrap()
        };
        let spent = frame(1e-9);
        assert!(spent.out_of_time && spent.iterations == 1, "{:?}", spent.warnings);
        assert!(spent.u.iter().all(|&v| v == 0.0), "the solve went on past the deadline");
        // Not registered, and said so: not as if the cloud did not fit the organ.
        assert!(!spent.plausible(), "{:?}", spent.warnings);
        assert!(
            spent.warnings.len() == 2 && spent.warnings[1].starts_with("no iteration finished"),
            "{:?}",
            spent.warnings
        );
        let spare = frame(1e6);
        assert!(!spare.out_of_time && spare.u.iter().any(|&v| v.abs() > 1e-3), "{:?}", spare.warnings);
    }

    /// A block fixed at its base whose whole top is seen 5 cm lower, deeper than the block is
    /// tall: at their full stiffness the data springs would crush it through itself, and a solve
    /// of the loop finds no equilibrium (the frame would end with that error); the springs are
    /// softened, and the frame ends with the top pressed down, by more than a millimetre, short of
    /// going through the block.
    #[test]
    fn a_cloud_the_model_cannot_follow_softens_the_data_springs() {
        let mesh = mesh::box_tet([0.0; 3], [0.04, 0.04, 0.04], [4, 4, 4]).unwrap();
        let mut problem = Problem::new(mesh, fem::Material::new(fem::Law::Corotational, 5000.0, 0.45));
        let base: Vec<usize> = (0..problem.mesh.nodes.len()).filter(|&n| problem.mesh.nodes[n][2] < 1e-9).collect();
        problem.fix(&base);
        let organ = Organ::new(problem.mesh.clone(), None).unwrap();
        let stiffness = FemDeformer::default_stiffness(&problem);
        let mut deformer = FemDeformer::new(problem, stiffness, SolverOptions::default()).unwrap();
        let top = |p: &&mesh::Point| p[2] > 0.04 - 1e-9;
        let cloud: Vec<mesh::Point> =
            organ.surface().vertices.iter().filter(top).map(|p| [p[0], p[1], p[2] - 0.05]).collect();
        let options = RegistrationOptions { view: Some([0.0, 0.0, -1.0]), ..RegistrationOptions::default() };
        let r = register_frame(&organ, &mut deformer, &cloud, None, &options).unwrap();
        let sunk: Vec<f64> = (0..organ.mesh().num_nodes())
            .filter(|&n| organ.mesh().nodes[n][2] > 0.04 - 1e-9)
            .map(|n| -r.u[3 * n + 2])
            .collect();
        let (mean, most) = (mesh::stats::mean(&sunk), mesh::stats::max(&sunk));
        assert!(mean > 0.001 && most < 0.04, "the top sank by {mean} m on average, {most} m at most");
    }

    /// A deformer that moves every node by its own constant offset along z.
    #[derive(Clone)]
    struct Offset(f64);

    impl Deformer for Offset {
        fn deform(&mut self, _: &Observations, previous: &[f64], _: usize) -> Result<Vec<f64>> {
            Ok((0..previous.len()).map(|i| if i % 3 == 2 { self.0 } else { 0.0 }).collect())
        }
    }

    /// A hybrid's warm-started frame is the second deformer's, or, with the first's iterations on
    /// warm-started frames, the first's for those iterations, then the second's from its estimate,
    /// or the first's alone.
    #[test]
    fn a_hybrid_s_warm_frame_is_the_second_s_after_the_first_s_iterations_there() {
        let organ = Organ::new(mesh::box_tet([0.0; 3], [0.04; 3], [2, 2, 2]).unwrap(), None).unwrap();
        let cloud = organ.surface().vertices.clone();
        let (first, then) = (Box::new(Offset(1e-3)), Box::new(Offset(2e-3)));
        let frames = |deformer: &mut HybridDeformer, iterations: usize| {
            let options = RegistrationOptions { warm_iterations: iterations, ..RegistrationOptions::default() };
            let rest = register_frame(&organ, deformer, &cloud, None, &options).unwrap();
            let warm = register_frame(&organ, deformer, &cloud, Some(&rest.u), &options).unwrap();
            ((rest.u[2], rest.iterations), (warm.u[2], warm.iterations))
        };
        let mut hybrid = HybridDeformer::new(first.clone(), then.clone(), 5).unwrap();
        assert_eq!(frames(&mut hybrid, 1), ((2e-3, 4), (2e-3, 1)), "handed over from rest; the second alone");
        let first_on_warm = || HybridDeformer::new(first.clone(), then.clone(), 5).unwrap().first_on_warm_frames(1);
        assert_eq!(frames(&mut first_on_warm(), 1).1, (1e-3, 1), "the first's iteration only");
        // The first does not settle the warm frame: the second goes on from its estimate.
        assert_eq!(frames(&mut first_on_warm(), 3).1, (2e-3, 3), "the first's, then the second's");
        let mut first_alone = HybridDeformer::new(first, then, 5).unwrap().first_alone_on_warm_frames();
        assert_eq!(frames(&mut first_alone, 3), ((2e-3, 4), (1e-3, 2)), "then the first alone, to where it settles");
    }

    /// A hybrid whose first deformer settles before its iterations are spent hands over to the
    /// second then, rather than end the frame with the first's estimate.
    #[test]
    fn a_hybrid_hands_over_when_its_first_deformer_settles() {
        let organ = Organ::new(mesh::box_tet([0.0; 3], [0.04; 3], [2, 2, 2]).unwrap(), None).unwrap();
        let cloud = organ.surface().vertices.clone();
        let mut hybrid = HybridDeformer::new(Box::new(Offset(1e-3)), Box::new(Offset(2e-3)), 5).unwrap();
        let options = RegistrationOptions { iterations: 10, ..RegistrationOptions::default() };
        let r = register_frame(&organ, &mut hybrid, &cloud, None, &options).unwrap();
        assert_eq!(r.u[2], 2e-3, "the second deformer's estimate");
        assert_eq!(r.iterations, 4, "the first settles at its second iteration, the second at its second");
    }

    /// The observations of a block's top pressed down 2 mm, seen from above.
    fn top_pressed(organ: &Organ) -> Observations {
        let top = organ.surface().vertices.iter().filter(|p| p[2] > 0.04 - 1e-9);
        let cloud: Vec<mesh::Point> = top.map(|p| [p[0], p[1], p[2] - 0.002]).collect();
        observe(organ, organ.surface(), &cloud, &RegistrationOptions::default(), 0.05, Some([0.0, 0.0, -1.0])).unwrap()
    }

    /// A hybrid whose second deformer predicts no σ gives, from rest, the first's σ widened by how
    /// far the second moved each point: √(σ₁² + |Δ|²); on a stream's frame, the first's σ widened
    /// by the distance from the first's fit to the last matches to the second's estimate; a
    /// calibration factor scales the widened σ.
    #[test]
    fn a_hybrid_widens_its_first_deformer_s_sigma_by_the_second_s_move() {
        /// Moves every node by `by` from the last estimate; σ 1 mm at every point when `sigma`.
        struct Shift {
            by: mesh::Point,
            sigma: bool,
        }
        impl Deformer for Shift {
            fn deform(&mut self, _: &Observations, previous: &[f64], _: usize) -> Result<Vec<f64>> {
                Ok(previous.iter().enumerate().map(|(k, u)| u + self.by[k % 3]).collect())
            }
            fn uncertainty(&mut self, stencils: &[crate::Stencil]) -> Option<Result<Vec<f64>>> {
                self.sigma.then(|| Ok(vec![1e-3; stencils.len()]))
            }
        }
        let organ = Organ::new(mesh::box_tet([0.0; 3], [0.04; 3], [2, 2, 2]).unwrap(), None).unwrap();
        let observations = top_pressed(&organ);
        let hybrid = || {
            let (first, then) =
                (Shift { by: [0.0, 0.0, -1e-3], sigma: true }, Shift { by: [3e-3, 0.0, 0.0], sigma: false });
            HybridDeformer::new(Box::new(first), Box::new(then), 1).unwrap()
        };
        let stencils = [crate::Stencil(vec![(0, 0.5), (1, 0.5)])];
        let sigma = |hybrid: &mut HybridDeformer| hybrid.uncertainty(&stencils).map(|s| s.unwrap()[0]);
        let rest = vec![0.0; 3 * organ.mesh().num_nodes()];
        // A frame from rest: σ after the first deformer's iteration, then at the frame's end.
        let from_rest = |hybrid: &mut HybridDeformer| {
            hybrid.start_frame(false);
            let fitted = hybrid.deform(&observations, &rest, 0).unwrap();
            let first = sigma(hybrid);
            let moved = hybrid.deform(&observations, &fitted, 1).unwrap();
            let last = hybrid.deform(&observations, &moved, 2).unwrap();
            hybrid.end_frame(observations.clone(), &last);
            (first, sigma(hybrid).unwrap(), last)
        };
        let mut plain = hybrid();
        let (first, widened, last) = from_rest(&mut plain);
        assert_eq!(first, Some(1e-3), "the first deformer's own");
        let expected = (1e-3f64.powi(2) + 6e-3f64.powi(2)).sqrt();
        assert!((widened - expected).abs() < 1e-12, "{widened} against {expected}");
        plain.start_frame(true);
        let streamed = plain.deform(&observations, &last, crate::WARM_START_ITERATION).unwrap();
        plain.end_frame(observations.clone(), &streamed);
        // The first fits from the second's estimate, 1 mm down: Δ is that 1 mm.
        let expected = (1e-3f64.powi(2) + 1e-3f64.powi(2)).sqrt();
        let on_stream = sigma(&mut plain).unwrap();
        assert!((on_stream - expected).abs() < 1e-12, "{on_stream} against {expected}");
        assert_eq!(sigma(&mut plain), Some(on_stream), "asked again, the same σ");
        // The first alone on a stream's frame: its own σ, nothing widens it.
        let mut alone = hybrid().first_alone_on_warm_frames();
        let (_, _, last) = from_rest(&mut alone);
        alone.start_frame(true);
        let fitted = alone.deform(&observations, &last, crate::WARM_START_ITERATION).unwrap();
        alone.end_frame(observations.clone(), &fitted);
        assert_eq!(sigma(&mut alone), Some(1e-3), "the first's own");
        // Scaled: the widened σ, not the first's own.
        let (first, scaled, _) = from_rest(&mut hybrid().sigma_scaled(0.5).unwrap());
        assert_eq!(first, Some(1e-3), "the first deformer's own, unscaled");
        assert!((scaled - 0.5 * widened).abs() < 1e-12);
        let e = HybridDeformer::new(Box::new(Offset(0.0)), Box::new(Offset(0.0)), 1).unwrap().sigma_scaled(0.0).err();
        assert_eq!(e.map(|e| e.to_string()).as_deref(), Some("sigma_factor = 0 must be positive"));
    }

    /// A hybrid deforms a frame from rest with the learned model for its first iterations, then
    /// with the FEM, its springs stiff at once; a warm-started frame (a stream) with the FEM alone.
    #[test]
    fn a_hybrid_gives_a_stream_s_frames_to_the_fem_alone() {
        use std::sync::atomic::{AtomicUsize, Ordering};
        use std::sync::Arc;
        /// A learned model that counts its calls and leaves the estimate where it is.
        struct Counting(Arc<AtomicUsize>);
        impl Deformer for Counting {
            fn deform(&mut self, _: &Observations, previous: &[f64], _: usize) -> Result<Vec<f64>> {
                self.0.fetch_add(1, Ordering::SeqCst);
                Ok(previous.to_vec())
            }
        }
        let mesh = mesh::box_tet([0.0; 3], [0.04; 3], [3, 3, 3]).unwrap();
        let mut problem = Problem::new(mesh, fem::Material::new(fem::Law::Corotational, 5000.0, 0.45));
        problem.fix(&mesh::select::nodes_in_box(&problem.mesh.nodes, [-1.0, -1.0, -1e-6], [1.0, 1.0, 1e-6]));
        let organ = Organ::new(problem.mesh.clone(), None).unwrap();
        let stiffness = FemDeformer::default_stiffness(&problem);
        let fem = || FemDeformer::new(problem.clone(), stiffness, SolverOptions::default()).unwrap();
        let calls = Arc::new(AtomicUsize::new(0));
        let network_iterations = 5;
        let mut hybrid =
            HybridDeformer::new(Box::new(Counting(calls.clone())), Box::new(fem()), network_iterations).unwrap();
        let observations = top_pressed(&organ);
        let rest = vec![0.0; 3 * organ.mesh().num_nodes()];
        let same = |a: &[f64], b: &[f64]| a.iter().zip(b).all(|(a, b)| (a - b).abs() < 1e-12);
        let lowest = |u: &[f64]| u.iter().skip(2).step_by(3).copied().fold(0.0, f64::min);
        hybrid.start_frame(false);
        for iteration in 0..network_iterations {
            assert_eq!(hybrid.deform(&observations, &rest, iteration).unwrap(), rest);
        }
        let polished = hybrid.deform(&observations, &rest, network_iterations).unwrap();
        assert_eq!(calls.load(Ordering::SeqCst), network_iterations, "the FEM after the network's iterations");
        assert!(same(&polished, &fem().deform(&observations, &rest, STIFFNESS_RAMP).unwrap()), "springs stiff at once");
        assert!(lowest(&polished) < -1e-3, "the FEM presses the top: {} m", lowest(&polished));
        hybrid.start_frame(true);
        let warm = hybrid.deform(&observations, &rest, crate::WARM_START_ITERATION).unwrap();
        assert_eq!(calls.load(Ordering::SeqCst), network_iterations, "no network on a stream's frame");
        assert!(same(&warm, &polished), "the FEM alone, its springs stiff");
    }

    /// The shipped network on the 3k-T4 phantom of the `liver_ar` dataset scenario, the normal
    /// displacement of its visible nodes as input.
    fn shipped_network_on_phantom() -> (Organ, NetworkDeformer) {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../../models/liver_ar/model.json");
        let model = Model::load(std::path::Path::new(path)).unwrap();
        let phantom = mesh::phantom::liver_phantom(3000).unwrap();
        let visible = phantom.region("visible").unwrap().to_vec();
        let organ = Organ::new(phantom, None).unwrap();
        let deformer = NetworkDeformer::new(&model, &organ, &visible, true).unwrap();
        (organ, deformer)
    }

    /// A smooth dent (2 cm deep at the deepest visible node) pressed into the top of the left
    /// lobe, seen by a camera from above without noise: fitted to the matches themselves, the
    /// visible surface keeps the dent's depth (measured: 20.8 mm, fit 20.5 mm); each node's mean
    /// match offset, the fit before, flattens it (16.7 mm).
    #[test]
    fn the_surface_fit_keeps_the_depth_of_a_dent() {
        // The fit under test comes before the network.
        let (organ, deformer) = shipped_network_on_phantom();
        let mesh = organ.mesh();
        let top = mesh.nodes.iter().map(|p| p[2]).fold(f64::MIN, f64::max);
        let centre = [-0.06, 0.005];
        let dent = |p: &mesh::Point| {
            let r2 = (p[0] - centre[0]).powi(2) + (p[1] - centre[1]).powi(2);
            -0.03 * (-r2 / (2.0 * 0.015f64.powi(2))).exp() * ((p[2] - top + 0.05) / 0.05).clamp(0.0, 1.0)
        };
        let u: Vec<f64> = mesh.nodes.iter().flat_map(|p| [0.0, 0.0, dent(p)]).collect();
        let deformed = organ.deformed_surface(&u);
        let view = [0.0, 0.0, -1.0];
        let cloud: Vec<mesh::Point> =
            mesh::sampling::sample_visible(&deformed, view, 3000, 5).unwrap().into_iter().map(|s| s.point).collect();
        let observations =
            observe(&organ, &deformed, &cloud, &RegistrationOptions::default(), 0.05, Some(view)).unwrap();
        let fit = deformer.surface_estimate(&observations, &vec![0.0; u.len()]);
        // A node's total interpolation weight over the matches (0: unobserved).
        let weight = |node: usize| -> f64 {
            observations.matches.iter().flat_map(|m| &m.stencil.0).filter(|&&(k, _)| k == node).map(|&(_, w)| w).sum()
        };
        let deepest = (0..deformer.inputs.len())
            .filter(|&i| weight(deformer.inputs[i]) > 0.0)
            .min_by(|&a, &b| u[3 * deformer.inputs[a] + 2].total_cmp(&u[3 * deformer.inputs[b] + 2]))
            .unwrap();
        let node = deformer.inputs[deepest];
        // Each node's mean match offset: the matches' shifts weighted by the node's share in them.
        let mean = observations
            .matches
            .iter()
            .flat_map(|m| m.stencil.0.iter().filter(|&&(k, _)| k == node).map(move |&(_, w)| w * m.shift[2]))
            .sum::<f64>()
            / weight(node);
        let (truth, fitted) = (u[3 * node + 2], fit[deepest][2]);
        eprintln!(
            "deepest visible node: {:.2} mm, fit {:.2} mm, mean offset {:.2} mm",
            truth * 1e3,
            fitted * 1e3,
            mean * 1e3
        );
        assert!(truth < -0.015, "the dent reaches a visible node: {truth}");
        assert!((fitted - truth).abs() < 0.05 * truth.abs(), "fit {fitted} against {truth}");
        assert!((fitted - truth).abs() < 0.5 * (mean - truth).abs(), "fit {fitted}, mean offset {mean}, truth {truth}");
    }

    /// The membrane loop's σ at a point inside the organ is the model's own σ field (the reduced-order
    /// model's, for the input of the frame's last prediction) there, read here by trilinear
    /// interpolation of the grid directly: at the mesh's nodes to rounding; at element centroids,
    /// where the deformer interpolates the nodes' values over the element, to within the field's
    /// curvature over an element (measured: at most 8.3 %, above it, as a convex field's chords lie).
    #[test]
    fn the_membrane_loop_s_sigma_at_a_point_is_the_model_s_sigma_there() {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../../models/liver_ar_rom");
        let model = Model::load(std::path::Path::new(path)).unwrap();
        let phantom = mesh::phantom::liver_phantom(3000).unwrap();
        let visible = phantom.region("visible").unwrap().to_vec();
        let organ = Organ::new(phantom, None).unwrap();
        let mut deformer = NetworkDeformer::new(&model, &organ, &visible, false).unwrap();
        let cloud: Vec<mesh::Point> = organ.surface().vertices.iter().map(|p| [p[0], p[1], p[2] - 0.004]).collect();
        let view = Some([0.0, 0.0, -1.0]);
        let observations = observe(&organ, organ.surface(), &cloud, &RegistrationOptions::default(), 0.05, view);
        deformer.deform(&observations.unwrap(), &vec![0.0; 3 * organ.mesh().num_nodes()], 0).unwrap();
        let std = deformer.predictor.predict_std(deformer.last_input.as_ref().unwrap()).unwrap().unwrap();
        let grid = deformer.grid.clone();
        // The trilinear value at `p`, where all eight grid corners carry a σ (inside the organ).
        let trilinear = |p: &mesh::Point| -> Option<f64> {
            let t: [f64; 3] = std::array::from_fn(|d| (p[d] - grid.origin[d]) / grid.spacing[d]);
            let i: [usize; 3] = std::array::from_fn(|d| (t[d].floor().max(0.0) as usize).min(grid.dims[d] - 2));
            let mut value = 0.0;
            for corner in 0..8 {
                let c: [usize; 3] = std::array::from_fn(|d| i[d] + (corner >> d & 1));
                let w: f64 = (0..3).map(|d| 1.0 - (t[d] - c[d] as f64).abs()).product();
                let sigma = f64::from(std[(c[0] * grid.dims[1] + c[1]) * grid.dims[2] + c[2]]);
                (sigma > 0.0).then_some(())?;
                value += w * sigma;
            }
            Some(value)
        };
        // (worst relative difference, signed; the smallest and largest σ) at `points`.
        let mut compare = |points: &[mesh::Point]| -> (f64, f64, f64) {
            let stencils = organ.locate(points, "target").unwrap();
            let reported = deformer.uncertainty(&stencils).unwrap().unwrap();
            let direct: Vec<f64> = points.iter().map(|p| trilinear(p).unwrap()).collect();
            let worst =
                reported.iter().zip(&direct).map(|(r, d)| (r - d) / d).max_by(|a, b| a.abs().total_cmp(&b.abs()));
            let (low, high) = direct.iter().fold((f64::MAX, 0.0f64), |(l, h), &d| (l.min(d), h.max(d)));
            (worst.unwrap(), low, high)
        };
        let mesh = organ.mesh();
        let nodes: Vec<mesh::Point> = mesh.nodes.iter().filter(|p| trilinear(p).is_some()).copied().collect();
        // Element centroids whose element's nodes all lie where every corner carries a σ.
        let deep = |c: usize| mesh.cells.cell(c).iter().all(|&n| trilinear(&mesh.nodes[n]).is_some());
        let centroid = |c: usize| -> mesh::Point {
            let cell = mesh.cells.cell(c);
            std::array::from_fn(|d| cell.iter().map(|&n| mesh.nodes[n][d]).sum::<f64>() / cell.len() as f64)
        };
        let centroids: Vec<mesh::Point> = (0..mesh.cells.len()).filter(|&c| deep(c)).map(centroid).collect();
        assert!(nodes.len() > 100 && centroids.len() > 100, "{} nodes, {} centroids", nodes.len(), centroids.len());
        let (at_nodes, low, high) = compare(&nodes);
        let (at_centroids, ..) = compare(&centroids);
        eprintln!(
            "σ {:.3}–{:.3} mm; reported against the grid's: {at_nodes:+.1e} at {} nodes, {at_centroids:+.3} at {} \
             centroids (worst relative differences)",
            low * 1e3,
            high * 1e3,
            nodes.len(),
            centroids.len()
        );
        assert!(high > 1.5 * low, "a σ that varies over the organ: {low}–{high} m");
        assert!(at_nodes.abs() < 1e-9, "the σ reported at the mesh nodes differs from the model's by {at_nodes}");
        assert!(at_centroids.abs() < 0.1, "the σ reported at the centroids differs from the model's: {at_centroids}");
    }

    /// Input nodes left out of `seen` are absent from a partial prediction: moving one of them
    /// changes nothing, moving a seen one changes the organ's displacement.
    #[test]
    fn a_partial_prediction_takes_the_seen_input_nodes_only() {
        let (_, deformer) = shipped_network_on_phantom();
        // The left half of the visible surface is seen; every input node pushed 1 cm down.
        let seen: Vec<bool> = deformer.points.iter().map(|p| p[0] < 0.0).collect();
        let (a, b) = (seen.iter().position(|&s| s).unwrap(), seen.iter().position(|&s| !s).unwrap());
        let surface = vec![[0.0, 0.0, -0.01]; deformer.inputs.len()];
        let base = deformer.predict_seen(&surface, Some(&seen)).unwrap().0;
        let moved = |i: usize| {
            let mut s = surface.clone();
            s[i] = [0.0, 0.0, -0.03];
            deformer.predict_seen(&s, Some(&seen)).unwrap().0
        };
        assert_eq!(moved(b), base, "an unseen input node changed the prediction");
        let change = moved(a).iter().zip(&base).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max);
        assert!(change > 1e-5, "a seen input node moved 2 cm changed the prediction by {change} m only");
        assert_ne!(deformer.predict(&surface).unwrap(), base, "the whole input and its left half predict the same");
    }
}
