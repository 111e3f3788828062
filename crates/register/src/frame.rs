//! The registration loop: closest-point matches on the deformed surface,
//! turned into nodal displacement observations, explained by a [`Deformer`].

use std::time::{Duration, Instant};

use mesh::bvh::{ClosestPoint, SurfaceBvh};
use mesh::{sub, unit, Point, TriSurface};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::checks::check_setting;
use crate::organ::{Organ, Stencil};
use crate::outliers::PointTree;
use crate::plausibility::Verdict;
use crate::rigid::RigidOptions;
use crate::{RegisterError, Result};

/// What the cloud says of the organ's displacement: each kept match asks the surface point it
/// matched to move onto its cloud point.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Observations {
    /// The kept matches.
    pub matches: Vec<PointMatch>,
}

/// A kept match: a cloud point and the surface point it matched.
#[derive(Clone, Debug, PartialEq)]
pub struct PointMatch {
    /// The mesh nodes that move the matched surface point, with their weights (summing to 1).
    pub stencil: Stencil,
    /// Cloud point − rest position of the matched surface point (m).
    pub shift: Point,
    /// Unit normal of the matched triangle, deformed.
    pub normal: Point,
    /// The matched triangle of the organ's surface (its index).
    pub triangle: usize,
    /// The matched point's barycentric coordinates in that triangle.
    pub weights: [f64; 3],
}

/// A model that gives the organ's nodal displacement (3 per node) explaining observations.
pub trait Deformer {
    /// The nodal displacement explaining `observations` at iteration `iteration` of a frame
    /// (from 0 for a frame registered from rest, from [`WARM_START_ITERATION`] for one
    /// warm-started from a previous frame); `previous` is the last estimate (a warm start).
    fn deform(&mut self, observations: &Observations, previous: &[f64], iteration: usize) -> Result<Vec<f64>>;

    /// A frame begins: warm-started from the previous frame's estimate (`warm`) or from rest.
    fn start_frame(&mut self, _warm: bool) {}

    /// The time by which the frame should end (its time budget), if any: a deformer whose one
    /// step may take long (a FEM solve) stops there, with its best estimate so far.
    fn set_deadline(&mut self, _deadline: Option<Instant>) {}

    /// The estimate settled at iteration `iteration`: whether the deformer goes on to a next
    /// stage (a hybrid's second model) rather than end the frame there. Default: it ends.
    fn settled(&mut self, _iteration: usize) -> bool {
        false
    }

    /// A frame ends: `observations` are the matches of its last iteration, `u` its estimate.
    fn end_frame(&mut self, _observations: Observations, _u: &[f64]) {}

    /// The predicted standard deviation (m) of the last estimate's error at the points inside the
    /// organ that the mesh nodes of `stencils` move, for a deformer that predicts one (the learned
    /// models).
    fn uncertainty(&mut self, _stencils: &[Stencil]) -> Option<Result<Vec<f64>>> {
        None
    }
}

/// The first iteration of a frame warm-started from a previous frame's estimate: its matches are
/// already good from the start, so the loop starts where a frame from rest would have settled
/// (past the finite-element springs' stiffness ramp and the first, widest capture distances).
pub const WARM_START_ITERATION: usize = 3;

/// Which frames of a registration match both ways ([`RegistrationOptions::two_way`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum TwoWay {
    /// None: each cloud point is matched to the surface, and that is all.
    #[default]
    Never,
    /// The frames warm-started from the previous one (a stream).
    Streamed,
    /// Every frame.
    Always,
}

impl TwoWay {
    /// Whether a frame (`warm`: warm-started from the previous one) matches both ways.
    pub fn applies(self, warm: bool) -> bool {
        match self {
            TwoWay::Never => false,
            TwoWay::Streamed => warm,
            TwoWay::Always => true,
        }
    }
}

/// Most match-and-deform iterations of a frame: far more than any registration needs (tens),
/// few enough that a frame ends.
pub const MAX_ITERATIONS: usize = 10_000;

/// Settings of the registration loop.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RegistrationOptions {
    /// Most match-and-deform iterations per frame.
    pub iterations: usize,
    /// Most iterations of a frame warm-started from the previous one (a stream), when fewer than
    /// `iterations`: the clouds of a stream move little from frame to frame, and the next frame
    /// goes on from where this one stopped. Rarely does a frame meet `tolerance` anyway: on the
    /// press-and-release stream of the registration case, with noise drawn anew at each frame,
    /// most frames ran to 30 iterations for a TRE of 1.16 mm; 4 gave 1.23 mm at 0.2× the time.
    pub warm_iterations: usize,
    /// Stop once no surface vertex moved by more than this between iterations (m).
    pub tolerance: f64,
    /// Cloud points whose mean distance to their 8 nearest neighbours exceeds this multiple
    /// of the cloud's median are isolated (flying pixels) and never matched ([`crate::outliers`]).
    pub isolation_factor: f64,
    /// Matches farther than this multiple of the median match distance are outliers...
    pub outlier_factor: f64,
    /// ... but a match within this distance (m) is never one.
    pub min_outlier_distance: f64,
    /// ... nor, at the first iteration, one within this distance (m), which shrinks by
    /// `capture_decay` at each iteration: the most deformed parts are far from the model at
    /// first, and a deep push needs several iterations to be reached.
    pub capture_distance: f64,
    /// Factor (0–1] applied to the capture distance at each iteration.
    pub capture_decay: f64,
    /// Rigid pre-alignment of the cloud to the rest surface (ICP, [`crate::rigid`]) before the
    /// deformable iterations; `None`: the cloud is taken as rigidly aligned. In a sequence it is
    /// estimated on a frame and kept for the next ones while they register without a warning.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub rigid: Option<RigidOptions>,
    /// The direction the camera looks along, in the organ's frame: cloud points are matched
    /// only to the surface that faces it (a point on a thin lobe pushed down must not match
    /// the lobe's underside). `None`: estimated from the cloud at the first iteration.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub view: Option<Point>,
    /// Most cloud points matched at each iteration and in the frame's residual: an evenly spaced
    /// subset of the cloud when it has more (`None`: every point; [`MAX_POINTS`] by default). A
    /// fit of a few dozen shape coefficients needs far fewer points than a cloud holds, and
    /// matching is most of its time.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub max_points: Option<usize>,
    /// Which frames match both ways: besides each cloud point to the surface, each vertex of the
    /// surface that faces the camera to its nearest cloud point, where that point lies within the
    /// cloud's spacing of the vertex's normal line (over the cloud, not beyond its edge), so that
    /// the seen part of the organ is held to the cloud as well as the cloud to the organ.
    pub two_way: TwoWay,
    /// Most wall time of a frame (ms), its rigid pre-alignment included: once an iteration ends
    /// past it (a deformer's step under way is told the deadline, [`Deformer::set_deadline`]: a
    /// FEM's solve stops at its next Newton iteration), the frame stops with the estimate so far,
    /// and a warning says so (a stream's next frame goes on from it). `None`: no limit.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub time_budget_ms: Option<f64>,
}

/// Most cloud points a registration matches by default: a depth camera's full frame (10⁵ points
/// and more) takes seconds to match and says no more. On a real liver's prepared patient (FEM,
/// 100,000 points of its seen surface) 10,000 of them moved its targets by 0.17 mm at most, in
/// 0.16 times the time of a warm frame.
pub const MAX_POINTS: usize = 10_000;

impl Default for RegistrationOptions {
    fn default() -> Self {
        RegistrationOptions {
            iterations: 30,
            warm_iterations: 4,
            tolerance: 1e-4,
            isolation_factor: 3.0,
            outlier_factor: 3.0,
            min_outlier_distance: 5e-3,
            capture_distance: 0.05,
            capture_decay: 0.93,
            rigid: None,
            view: None,
            max_points: Some(MAX_POINTS),
            two_way: TwoWay::Never,
            time_budget_ms: None,
        }
    }
}

impl RegistrationOptions {
    /// Checks the values, naming the first that is out of its range.
    pub fn validate(&self) -> Result<()> {
        let counts = [("iterations", self.iterations), ("warm_iterations", self.warm_iterations)];
        if let Some((name, n)) = counts.iter().find(|(_, n)| !(1..=MAX_ITERATIONS).contains(n)) {
            return Err(RegisterError::Invalid(format!(
                "{name} = {n} must be 1 to {MAX_ITERATIONS} (a frame's iterations, each a deformation)"
            )));
        }
        let (nonnegative, positive) = ("non-negative and finite", "positive and finite");
        check_setting("tolerance", self.tolerance, self.tolerance >= 0.0, nonnegative)?;
        check_setting("isolation_factor", self.isolation_factor, self.isolation_factor > 0.0, positive)?;
        check_setting("outlier_factor", self.outlier_factor, self.outlier_factor > 0.0, positive)?;
        check_setting(
            "min_outlier_distance",
            self.min_outlier_distance,
            self.min_outlier_distance >= 0.0,
            nonnegative,
        )?;
        check_setting("capture_distance", self.capture_distance, self.capture_distance >= 0.0, nonnegative)?;
        let decay = self.capture_decay;
        check_setting("capture_decay", decay, decay > 0.0 && decay <= 1.0, "in (0, 1]")?;
        if let Some(budget) = self.time_budget_ms {
            check_setting("time_budget_ms", budget, budget > 0.0, positive)?;
        }
        if self.max_points == Some(0) {
            return Err(RegisterError::Invalid("max_points = 0 must be at least 1".into()));
        }
        if let Some(v) = self.view.filter(|v| !(v.iter().all(|x| x.is_finite()) && mesh::dot(*v, *v) > 0.0)) {
            return Err(RegisterError::Invalid(format!("view = {v:?} must be a finite, non-zero direction")));
        }
        self.rigid.as_ref().map_or(Ok(()), RigidOptions::validate)
    }
}

/// The registration of one frame.
#[derive(Clone, Debug)]
pub struct FrameResult {
    /// Nodal displacement of the organ mesh (m, 3 per node).
    pub u: Vec<f64>,
    /// Match-and-deform iterations run.
    pub iterations: usize,
    /// The frame started from rest, not from a previous frame's displacement.
    pub from_rest: bool,
    /// Mean distance from the cloud points to the registered surface (m), all points (those of
    /// [`RegistrationOptions::max_points`] when it limits them).
    pub surface_residual: f64,
    /// The share of the cloud's points left farther than [`crate::plausibility::FAR_DISTANCE`] from the
    /// registered surface.
    pub far_share: f64,
    /// Why the result may not be believed ([`crate::plausibility::verdict`]), and whether the
    /// frame stopped at its time budget; empty when plausible and converged.
    pub warnings: Vec<String>,
    /// The registered organ changes its volume as tissue cannot (a cloud in another frame or
    /// unit): no start for a stream's next frame ([`crate::Registration::register`]).
    pub distorted: bool,
    /// The cloud lies on the organ at rest in the other frame (RAS for LPS: x and y negated; one
    /// of the warnings says so): no start for a stream's next frame either.
    pub other_frame: bool,
    /// The cloud spans under a tenth of the organ ([`crate::plausibility::SMALL_VIEW`]; one of the
    /// warnings says so), as a cloud in centimetres read as millimetres does: no start for a
    /// stream's next frame either.
    pub small_view: bool,
    /// The frame stopped at [`RegistrationOptions::time_budget_ms`] before its iterations ran out
    /// (one of the warnings says so).
    pub out_of_time: bool,
    /// Cloud points (matched: see [`RegistrationOptions::max_points`]).
    pub points: usize,
    /// Cloud points kept as matches in the last iteration.
    pub inliers: usize,
    /// Wall time of the frame, matching included.
    pub time: Duration,
}

impl FrameResult {
    /// [`IMPLAUSIBLE`] for a result that is not plausible, nothing for one that is: the end of
    /// the names its answers are given (files, a stream's messages), so that a viewer showing them
    /// by name shows the verdict too.
    pub fn verdict_suffix(&self) -> &'static str {
        if self.plausible() {
            ""
        } else {
            IMPLAUSIBLE
        }
    }

    /// Whether the result passed the plausibility checks: no warning but the time budget's.
    pub fn plausible(&self) -> bool {
        self.warnings.len() == usize::from(self.out_of_time)
    }
}

/// The end of the names given to the answers of a registration that is not plausible
/// (`targets_implausible.mrk.json`, a stream's `targets_implausible`): 3D Slicer names the
/// nodes it loads or receives after them.
pub const IMPLAUSIBLE: &str = "_implausible";

/// A deformer's refusal `e` of a cloud spanning `extent` of the organ: a tenth of it or less asks
/// what so small a cloud may be, as the frame's verdict would have.
fn with_unit_hint(e: RegisterError, extent: f64) -> RegisterError {
    match e {
        RegisterError::Invalid(why) if extent < crate::plausibility::SMALL_VIEW => RegisterError::Invalid(format!(
            "{why}; the cloud spans {:.0} % of the organ: if it is in centimetres, convert it to mm",
            100.0 * extent
        )),
        e => e,
    }
}

/// Registers `organ` to `cloud` (positions only, rigidly aligned: `options.rigid` only words the
/// warnings here, see [`crate::Registration`]), starting from `start` (a previous frame's
/// displacement) or from rest.
pub fn register_frame(
    organ: &Organ,
    deformer: &mut dyn Deformer,
    cloud: &[Point],
    start: Option<&[f64]>,
    options: &RegistrationOptions,
) -> Result<FrameResult> {
    register_frame_begun(Instant::now(), organ, deformer, cloud, start, options)
}

/// [`register_frame`] for a frame whose work began at `t0` (its rigid pre-alignment before the
/// loop): its time budget and its time count from there.
pub(crate) fn register_frame_begun(
    t0: Instant,
    organ: &Organ,
    deformer: &mut dyn Deformer,
    cloud: &[Point],
    start: Option<&[f64]>,
    options: &RegistrationOptions,
) -> Result<FrameResult> {
    options.validate()?;
    let ndof = 3 * organ.mesh().num_nodes();
    let mut u = match start {
        Some(s) if s.len() == ndof => s.to_vec(),
        Some(s) => {
            return Err(RegisterError::Invalid(format!("start displacement has {} values, expected {ndof}", s.len())))
        }
        None => vec![0.0; ndof],
    };
    let extent = crate::plausibility::check_extent(organ, cloud)?;
    let subset: Vec<Point>;
    let cloud = match options.max_points {
        Some(most) if cloud.len() > most => {
            subset = (0..most).map(|i| cloud[i * cloud.len() / most]).collect();
            &subset
        }
        _ => cloud,
    };
    deformer.start_frame(start.is_some());
    deformer.set_deadline(options.time_budget_ms.map(|budget| t0 + Duration::from_secs_f64(budget / 1e3)));
    let mut surface = organ.deformed_surface(&u);
    let mut iterations = 0;
    let mut inliers = 0;
    let mut view = options.view.map(unit);
    // The points that may be matched: all but the isolated ones.
    let (isolated, spacing) = crate::outliers::isolation(cloud, options.isolation_factor);
    let kept: Vec<Point> = cloud.iter().zip(&isolated).filter(|(_, &i)| !i).map(|(p, _)| *p).collect();
    let candidates = if kept.is_empty() { cloud } else { &kept };
    let cloud_tree = options.two_way.applies(start.is_some()).then(|| CloudTree::new(candidates, spacing));
    let (first, most) = match start {
        Some(_) => (WARM_START_ITERATION, options.iterations.min(options.warm_iterations)),
        None => (0, options.iterations),
    };
    // Whether any iteration moved the organ's surface: one stopped at its deadline gives it back unmoved.
    let mut moved_at_all = false;
    let mut last_observations = None;
    let mut out_of_time = false;
    while iterations < most {
        fem::interrupt::check()?;
        iterations += 1;
        let iteration = first + iterations - 1;
        let capture = options.capture_distance * options.capture_decay.powi(iteration as i32);
        let mut observations = if view.is_none() && iterations == 1 {
            // The view is estimated from the matches to every triangle; those that fall on a
            // facing triangle are the facing part's own.
            let whole = closest_points(&surface, candidates)?;
            view = estimate_view(&surface, &whole, outlier_limit(whole.iter().map(|m| m.distance), options, capture));
            let (facing, original) = facing_part(&surface, view);
            let matches = facing_matches(&facing, &original, surface.triangles.len(), candidates, whole)?;
            observations(
                organ,
                &surface,
                candidates,
                &matches,
                &original,
                outlier_limit(matches.iter().map(|m| m.distance), options, capture),
            )
        } else {
            observe(organ, &surface, candidates, options, capture, view)?
        };
        inliers = observations.matches.len();
        if let Some(tree) = &cloud_tree {
            observations.matches.extend(seen_surface_matches(organ, &surface, tree, view, options, capture));
        }
        u = deformer.deform(&observations, &u, iteration).map_err(|e| with_unit_hint(e, extent))?;
        if u.len() != ndof || u.iter().any(|v| !v.is_finite()) {
            return Err(RegisterError::Invalid("the deformer returned a displacement that is not finite".into()));
        }
        last_observations = Some(observations);
        let next = organ.deformed_surface(&u);
        let moved =
            next.vertices.iter().zip(&surface.vertices).map(|(a, b)| mesh::distance(*a, *b)).fold(0.0, f64::max);
        surface = next;
        moved_at_all |= moved > 0.0;
        // The budget first: a deformer stopped at the deadline gives back its estimate unmoved.
        if options.time_budget_ms.is_some_and(|budget| mesh::stats::ms(t0.elapsed()) >= budget) && iterations < most {
            out_of_time = true;
            break;
        }
        if moved <= options.tolerance && !deformer.settled(iteration) {
            break;
        }
    }
    if let Some(observations) = last_observations {
        deformer.end_frame(observations, &u);
    }
    let bvh = SurfaceBvh::new(&surface)?;
    let distances: Vec<f64> = cloud.par_iter().map(|&c| bvh.distance(c)).collect();
    let surface_residual = distances.iter().sum::<f64>() / cloud.len() as f64;
    let far_share = crate::plausibility::far_share(&distances);
    let mut verdict = crate::plausibility::verdict(organ, &u, far_share, (cloud, extent), options.rigid.is_some());
    if let (true, Some(budget)) = (out_of_time, options.time_budget_ms) {
        verdict = cut_short(verdict, budget, (iterations, most), !moved_at_all);
    }
    let Verdict { warnings, distorted, other_frame, small_view } = verdict;
    Ok(FrameResult {
        u,
        iterations,
        from_rest: start.is_none(),
        surface_residual,
        far_share,
        warnings,
        distorted,
        other_frame,
        small_view,
        out_of_time,
        points: cloud.len(),
        inliers,
        time: t0.elapsed(),
    })
}

/// `verdict` of a frame its time budget (`budget`, ms) stopped after `iterations` of its `most`:
/// said among the warnings; when no iteration finished (`unmoved`: none moved the organ's surface),
/// there is no registration to judge, the organ left where the frame began: the verdict's own
/// findings give way to that.
fn cut_short(verdict: Verdict, budget: f64, (iterations, most): (usize, usize), unmoved: bool) -> Verdict {
    let mut verdict = if unmoved { Verdict::default() } else { verdict };
    verdict.warnings.push(format!(
        "the frame stopped after {iterations} of its {most} iterations, past its time budget of {budget:.0} ms: the \
         estimate may not have converged"
    ));
    if unmoved {
        verdict.warnings.push(format!(
            "no iteration finished within the time budget of {budget:.0} ms (one takes longer): the organ is left as \
             the frame began, not registered to this cloud; give a larger budget"
        ));
    }
    verdict
}

/// Matches each cloud point to the closest point of the deformed `surface` (of its triangles
/// facing a camera looking along `view`, when given), drops outliers (farther than the larger
/// of `capture` and the options' limits), and keeps each match's displacement (cloud point −
/// rest position of the matched surface point) with the mesh nodes that move it.
pub fn observe(
    organ: &Organ,
    surface: &TriSurface,
    cloud: &[Point],
    options: &RegistrationOptions,
    capture: f64,
    view: Option<Point>,
) -> Result<Observations> {
    let (facing, original) = facing_part(surface, view);
    let matches = closest_points(&facing, cloud)?;
    Ok(observations(
        organ,
        surface,
        cloud,
        &matches,
        &original,
        outlier_limit(matches.iter().map(|m| m.distance), options, capture),
    ))
}

/// Surface normals are interpolated across an edge between triangles that turn by less than
/// 80° (this cosine): an organ's surface; a sharper edge (a box's) keeps its sides' normals. On the
/// demo case (a design case), 60° left the shape fit at 2.84 mm, 80° at 2.37 mm, as no split did.
const SHARP_EDGE_COS: f64 = 0.17;

/// The observations of the cloud points' `matches` on the triangles `original` of `surface`
/// (a match's triangle indexes `original`), those farther than `limit` left out.
fn observations(
    organ: &Organ,
    surface: &TriSurface,
    cloud: &[Point],
    matches: &[ClosestPoint],
    original: &[usize],
    limit: f64,
) -> Observations {
    let mut obs = Observations { matches: Vec::with_capacity(cloud.len()) };
    let rest = &organ.surface().vertices;
    let corner_normals = surface.corner_normals(SHARP_EDGE_COS);
    for (c, m) in cloud.iter().zip(matches) {
        if m.distance > limit {
            continue;
        }
        let triangle = original[m.triangle];
        let tri = surface.triangles[triangle];
        let corners = tri.map(|k| surface.vertices[k]);
        let bary = mesh::bvh::triangle_barycentric(corners, m.point);
        // The corner normals interpolated: on a smooth edge or vertex, which of its triangles a
        // point matched does not change its normal.
        let normal = mesh::blend_unit(corner_normals[triangle], bary);
        let mut p0 = [0.0; 3];
        for (b, &k) in bary.iter().zip(&tri) {
            for d in 0..3 {
                p0[d] += b * rest[k][d];
            }
        }
        let shift = [c[0] - p0[0], c[1] - p0[1], c[2] - p0[2]];
        obs.matches.push(PointMatch {
            stencil: organ.surface_point_stencil(triangle, bary),
            shift,
            normal,
            triangle,
            weights: bary,
        });
    }
    obs
}

/// A cloud's points for the nearest-point search, with their spacing ([`crate::outliers::isolation`]).
struct CloudTree {
    tree: PointTree,
    spacing: f64,
}

impl CloudTree {
    /// The tree of `cloud` (at least one point), whose spacing is `spacing`.
    fn new(cloud: &[Point], spacing: f64) -> CloudTree {
        CloudTree { tree: PointTree::new(cloud), spacing }
    }
}

/// The matches of the seen surface to the cloud: each vertex of `surface` on a triangle facing a
/// camera looking along `view` (every vertex without one) to its nearest cloud point, kept when
/// that point lies within the cloud's spacing of the vertex's normal line (the vertex is over the
/// cloud, not beyond its edge, where the nearest point would drag it sideways) and within the
/// outlier limit of the options and `capture`. A match's normal is the vertex's, its surface point
/// the vertex (weight 1 at one corner of a facing triangle).
fn seen_surface_matches(
    organ: &Organ,
    surface: &TriSurface,
    cloud: &CloudTree,
    view: Option<Point>,
    options: &RegistrationOptions,
    capture: f64,
) -> Vec<PointMatch> {
    let mut corner = vec![None; surface.vertices.len()];
    for t in facing_triangles(surface, view) {
        for (k, &v) in surface.triangles[t].iter().enumerate() {
            corner[v].get_or_insert((t, k));
        }
    }
    let normals = surface.vertex_normals();
    let seen: Vec<(usize, (usize, usize))> = corner.iter().enumerate().filter_map(|(v, c)| c.map(|c| (v, c))).collect();
    let over: Vec<(usize, (usize, usize), Point, f64)> = seen
        .par_iter()
        .filter_map(|&(v, c)| {
            let (x, distance) = cloud.tree.nearest(surface.vertices[v]);
            let offset = sub(x, surface.vertices[v]);
            let along = mesh::dot(offset, normals[v]);
            let across = (distance * distance - along * along).max(0.0).sqrt();
            (across <= cloud.spacing).then_some((v, c, x, distance))
        })
        .collect();
    let limit = outlier_limit(over.iter().map(|m| m.3), options, capture);
    let rest = &organ.surface().vertices;
    over.into_iter()
        .filter(|m| m.3 <= limit)
        .map(|(v, (triangle, k), x, _)| {
            let mut weights = [0.0; 3];
            weights[k] = 1.0;
            PointMatch {
                stencil: organ.surface_point_stencil(triangle, weights),
                shift: sub(x, rest[v]),
                normal: normals[v],
                triangle,
                weights,
            }
        })
        .collect()
}

/// The closest point of `surface` to each cloud point.
fn closest_points(surface: &TriSurface, cloud: &[Point]) -> Result<Vec<ClosestPoint>> {
    let bvh = SurfaceBvh::new(surface)?;
    Ok(cloud.par_iter().map(|&c| bvh.closest_point(c)).collect())
}

/// The closest point of `facing` (the triangles `original` of a surface of `triangles`
/// triangles) to each cloud point, from the cloud's closest points on the whole surface: the
/// closest of all triangles, when it faces the camera, is the closest facing one; only the
/// points matched elsewhere are searched again.
fn facing_matches(
    facing: &TriSurface,
    original: &[usize],
    triangles: usize,
    cloud: &[Point],
    mut whole: Vec<ClosestPoint>,
) -> Result<Vec<ClosestPoint>> {
    let mut index = vec![None; triangles];
    for (i, &t) in original.iter().enumerate() {
        index[t] = Some(i);
    }
    let mut again = Vec::new();
    for (i, m) in whole.iter_mut().enumerate() {
        match index[m.triangle] {
            Some(f) => m.triangle = f,
            None => again.push(i),
        }
    }
    if !again.is_empty() {
        let points: Vec<Point> = again.iter().map(|&i| cloud[i]).collect();
        for (i, m) in again.into_iter().zip(closest_points(facing, &points)?) {
            whole[i] = m;
        }
    }
    Ok(whole)
}

/// The distance beyond which a match is an outlier: the largest of `capture` and the options'
/// limits, the one relative to the median of the matches' `distances` included.
fn outlier_limit(distances: impl Iterator<Item = f64>, options: &RegistrationOptions, capture: f64) -> f64 {
    let mut distances: Vec<f64> = distances.collect();
    let median = mesh::stats::median(&mut distances);
    (options.outlier_factor * median).max(options.min_outlier_distance).max(capture)
}

/// The triangles of `surface` that face a camera looking along `view` (all of them
/// when there is no view), as a surface of their own, with each one's index in `surface`.
fn facing_part(surface: &TriSurface, view: Option<Point>) -> (TriSurface, Vec<usize>) {
    let original = facing_triangles(surface, view);
    let triangles = original.iter().map(|&t| surface.triangles[t]).collect();
    (TriSurface { vertices: surface.vertices.clone(), triangles }, original)
}

/// The triangles of `surface` that face a camera looking along `view` (all of them when there is
/// no view).
fn facing_triangles(surface: &TriSurface, view: Option<Point>) -> Vec<usize> {
    match view {
        Some(v) => (0..surface.triangles.len())
            .filter(|&t| mesh::dot(mesh::surface::triangle_area_vector(surface, t), v) < 0.0)
            .collect(),
        None => (0..surface.triangles.len()).collect(),
    }
}

/// Smallest length of the mean unit normal of the matched triangles for the cloud to count
/// as seen from one side (a cloud all around the organ has none).
const ONE_SIDED: f64 = 0.2;

/// The direction a camera looks along, estimated from the cloud's `matches` on every triangle
/// of `surface`: the opposite of the mean outward normal of the triangles matched within
/// `limit`; `None` when the matched normals have no clear mean (a cloud all around the organ).
fn estimate_view(surface: &TriSurface, matches: &[ClosestPoint], limit: f64) -> Option<Point> {
    let (mut sum, mut count) = ([0.0; 3], 0usize);
    for m in matches.iter().filter(|m| m.distance <= limit) {
        let n = unit(mesh::surface::triangle_area_vector(surface, m.triangle));
        (0..3).for_each(|d| sum[d] -= n[d]);
        count += 1;
    }
    let length = mesh::norm(sum);
    (count > 0 && length >= ONE_SIDED * count as f64).then(|| sum.map(|x| x / length))
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use mesh::sampling::sample_visible;

    /// A point whose closest surface point lies on a smooth edge gets the same normal whichever
    /// of the edge's triangles it matched: points a rounding error apart on either side of the
    /// edge's bisector are matched along one normal, between the two faces'. At a sharp edge (a
    /// box's, 90°) each side keeps its own.
    #[test]
    fn a_match_on_a_smooth_edge_has_one_normal() {
        let organ = Organ::new(mesh::box_tet([0.0; 3], [0.05; 3], [2, 2, 2]).unwrap(), None).unwrap();
        // The cube's nodes pushed onto a sphere: a rounded surface, its edges turning by 45° or less.
        let c = 0.025;
        let u: Vec<f64> = organ
            .mesh()
            .nodes
            .iter()
            .flat_map(|p| {
                let r = mesh::norm(p.map(|x| x - c));
                p.map(|x| if r > 0.0 { (x - c) * (0.03 / r - 1.0) } else { 0.0 })
            })
            .collect();
        let options = RegistrationOptions::default();
        for (surface, smooth) in [(organ.deformed_surface(&u), true), (organ.surface().clone(), false)] {
            let face = |t: usize| {
                let [a, b, c] = surface.triangles[t].map(|k| surface.vertices[k]);
                unit(mesh::cross(sub(b, a), sub(c, a)))
            };
            // Two triangles sharing an edge, folded by 11 to 60° (smooth) or by 90° (sharp).
            let n = surface.triangles.len();
            let (t1, t2, edge) = (0..n)
                .flat_map(|a| (a + 1..n).map(move |b| (a, b)))
                .find_map(|(a, b)| {
                    let shared: Vec<usize> =
                        surface.triangles[a].into_iter().filter(|k| surface.triangles[b].contains(k)).collect();
                    let turn = mesh::dot(face(a), face(b));
                    let wanted = if smooth { turn > 0.5 && turn < 0.98 } else { turn.abs() < 1e-9 };
                    (shared.len() == 2 && wanted).then(|| (a, b, [shared[0], shared[1]]))
                })
                .expect("such an edge");
            let middle = edge.map(|k| surface.vertices[k]);
            let middle: Point = std::array::from_fn(|d| 0.5 * (middle[0][d] + middle[1][d]));
            let (n1, n2) = (face(t1), face(t2));
            let normal = |side: f64| {
                let point: Point =
                    std::array::from_fn(|d| middle[d] + 0.005 * (n1[d] + n2[d]) + side * (n1[d] - n2[d]));
                observe(&organ, &surface, &[point], &options, 1.0, None).unwrap().matches[0].normal
            };
            if smooth {
                let (a, b) = (normal(1e-12), normal(-1e-12));
                assert!(mesh::distance(a, b) < 1e-9, "{a:?} against {b:?}");
            } else {
                // Over the first side, a hair from the edge: that side's normal.
                let point: Point = std::array::from_fn(|d| middle[d] + 0.001 * n1[d] - 1e-9 * n2[d]);
                let a = observe(&organ, &surface, &[point], &options, 1.0, None).unwrap().matches[0].normal;
                assert!(mesh::distance(a, n1) < 1e-6, "{a:?} against {n1:?}");
            }
        }
    }

    fn phantom_surface() -> TriSurface {
        mesh::boundary_surface(&mesh::phantom::liver_phantom(1500).unwrap()).compacted()
    }

    /// A deformer that moves every value by 0.1 mm at each iteration.
    pub(crate) struct Creeping;

    impl Deformer for Creeping {
        fn deform(&mut self, _: &Observations, previous: &[f64], _: usize) -> Result<Vec<f64>> {
            Ok(previous.iter().map(|u| u + 1e-4).collect())
        }
    }

    /// The time budget counts from the frame's start, work before the loop (a rigid
    /// pre-alignment) included: a frame begun 200 ms ago, with a budget of 100 ms, stops after its
    /// first iteration, and its time covers the 200 ms.
    #[test]
    fn the_time_budget_counts_from_the_frame_start() {
        let organ = Organ::new(mesh::box_tet([0.0; 3], [0.05; 3], [3, 3, 3]).unwrap(), None).unwrap();
        let cloud = organ.surface().vertices.clone();
        let options =
            RegistrationOptions { iterations: 5, tolerance: 0.0, time_budget_ms: Some(100.0), ..Default::default() };
        let fresh = register_frame(&organ, &mut Creeping, &cloud, None, &options).unwrap();
        assert_eq!((fresh.iterations, fresh.out_of_time), (5, false), "{:?}", fresh.warnings);
        let begun = Instant::now() - Duration::from_millis(200);
        let late = register_frame_begun(begun, &organ, &mut Creeping, &cloud, None, &options).unwrap();
        assert_eq!((late.iterations, late.out_of_time), (1, true), "{:?}", late.warnings);
        assert!(late.time >= Duration::from_millis(200), "{:?}", late.time);
    }

    /// Out-of-range options are refused by the setting's name, its value and its range.
    #[test]
    fn invalid_options_name_the_setting() {
        let base = RegistrationOptions::default();
        assert!(base.validate().is_ok());
        let cases = [
            (RegistrationOptions { iterations: 0, ..base.clone() }, "iterations = 0 must be 1 to 10000"),
            (
                RegistrationOptions { warm_iterations: 1 << 40, ..base.clone() },
                "warm_iterations = 1099511627776 must be",
            ),
            (RegistrationOptions { capture_decay: 1.5, ..base.clone() }, "capture_decay = 1.5 must be in (0, 1]"),
            (RegistrationOptions { tolerance: f64::NAN, ..base.clone() }, "tolerance = NaN must be non-negative"),
            (RegistrationOptions { view: Some([0.0; 3]), ..base.clone() }, "view = [0.0, 0.0, 0.0] must be"),
            (
                RegistrationOptions {
                    rigid: Some(RigidOptions { keep: 0.0, ..RigidOptions::default() }),
                    ..base.clone()
                },
                "rigid.keep = 0 must be in (0, 1]",
            ),
            (
                RegistrationOptions {
                    rigid: Some(RigidOptions { iterations: 0, ..RigidOptions::default() }),
                    ..base.clone()
                },
                "rigid.iterations = 0 must be at least 1",
            ),
        ];
        for (options, message) in cases {
            let err = options.validate().unwrap_err().to_string();
            assert!(err.starts_with(message), "{err}");
        }
    }

    /// A cloud seen from above gives a view close to straight down; a cloud all around the
    /// organ gives none (every triangle may then be matched).
    #[test]
    fn the_view_is_estimated_from_a_one_sided_cloud_only() {
        let surface = phantom_surface();
        let options = RegistrationOptions::default();
        let top: Vec<Point> =
            sample_visible(&surface, [0.0, 0.0, -1.0], 800, 3).unwrap().into_iter().map(|s| s.point).collect();
        let view_of = |cloud: &[Point]| {
            let matches = closest_points(&surface, cloud).unwrap();
            estimate_view(&surface, &matches, outlier_limit(matches.iter().map(|m| m.distance), &options, 0.05))
        };
        let view = view_of(&top).expect("a view");
        assert!(view[2] < -0.95, "{view:?}");
        let all: Vec<Point> = surface.vertices.clone();
        assert_eq!(view_of(&all), None);
        // Matching is then restricted to the triangles facing the camera.
        let (facing, original) = facing_part(&surface, Some(view));
        assert!(facing.triangles.len() < surface.triangles.len() * 3 / 4);
        for (t, &o) in original.iter().enumerate() {
            assert_eq!(facing.triangles[t], surface.triangles[o]);
            assert!(mesh::dot(mesh::surface::triangle_area_vector(&surface, o), view) < 0.0);
        }
        assert_eq!(facing_part(&surface, None).0.triangles.len(), surface.triangles.len());
    }

    /// Matching to the facing triangles from the matches to the whole surface finds the same
    /// closest points as a search of the facing triangles alone, for points near the facing side,
    /// near the far side (matched elsewhere first) and inside.
    #[test]
    fn facing_matches_from_the_whole_surface_are_the_facing_search() {
        let surface = phantom_surface();
        let view = [0.0, 0.0, -1.0];
        let (facing, original) = facing_part(&surface, Some(view));
        let cloud: Vec<Point> = surface
            .vertices
            .iter()
            .enumerate()
            .map(|(k, p)| {
                let s = k as f64;
                [p[0] + 4e-3 * (s * 0.618).fract() - 2e-3, p[1] + 4e-3 * (s * 0.414).fract() - 2e-3, p[2]]
            })
            .collect();
        let whole = closest_points(&surface, &cloud).unwrap();
        let elsewhere = whole.iter().filter(|m| !original.contains(&m.triangle)).count();
        assert!(elsewhere > 100 && elsewhere < cloud.len() - 100, "{elsewhere} of {} matched elsewhere", cloud.len());
        let reused = facing_matches(&facing, &original, surface.triangles.len(), &cloud, whole).unwrap();
        let searched = closest_points(&facing, &cloud).unwrap();
        for (a, b) in reused.iter().zip(&searched) {
            assert!((a.distance - b.distance).abs() < 1e-15 && mesh::distance(a.point, b.point) < 1e-12, "{a:?} {b:?}");
        }
    }

    /// A partial view (the top of the phantom's left half, lifted by 3 mm): the seen surface is
    /// matched to the cloud where it lies under the cloud, with the lift along each vertex's
    /// normal, and nowhere beyond the cloud's edge, where the nearest cloud point lies aside.
    #[test]
    fn the_seen_surface_is_matched_to_the_cloud_over_the_cloud_only() {
        let organ = Organ::new(mesh::phantom::liver_phantom(1500).unwrap(), None).unwrap();
        let surface = organ.surface().clone();
        let view = [0.0, 0.0, -1.0];
        let (lo, hi) = mesh::bounds(&surface.vertices);
        let edge = 0.5 * (lo[0] + hi[0]);
        let lift = [0.0, 0.0, 3e-3];
        let options = RegistrationOptions::default();
        let cloud: Vec<Point> = sample_visible(&surface, view, 1500, 5)
            .unwrap()
            .into_iter()
            .map(|s| s.point)
            .filter(|p| p[0] < edge)
            .map(|p| [p[0] + lift[0], p[1] + lift[1], p[2] + lift[2]])
            .collect();
        let (isolated, spacing) = crate::outliers::isolation(&cloud, options.isolation_factor);
        assert!(!isolated.contains(&true));
        let tree = CloudTree::new(&cloud, spacing);
        assert!(tree.spacing > 1e-3 && tree.spacing < 1e-2, "spacing {}", tree.spacing);
        let matches = seen_surface_matches(&organ, &surface, &tree, Some(view), &options, 0.05);
        let rest = &surface.vertices;
        let vertex = |m: &PointMatch| surface.triangles[m.triangle][m.weights.iter().position(|&w| w == 1.0).unwrap()];
        // Every match is a vertex under the cloud: none beyond its edge by more than its spacing.
        let beyond = matches.iter().filter(|m| rest[vertex(m)][0] > edge + tree.spacing).count();
        assert_eq!(beyond, 0, "{beyond} of {} matches beyond the cloud's edge", matches.len());
        // Most of the facing vertices well inside the cloud's part are matched.
        let facing: std::collections::BTreeSet<usize> =
            facing_triangles(&surface, Some(view)).into_iter().flat_map(|t| surface.triangles[t]).collect();
        let inside = facing.iter().filter(|&&v| rest[v][0] < edge - 0.02).count();
        assert!(matches.len() > inside * 3 / 4, "{} matches, {inside} facing vertices inside", matches.len());
        // Each match asks for the lift along its normal (point to plane), to the sampling's error.
        let mut errors: Vec<f64> =
            matches.iter().map(|m| (mesh::dot(m.shift, m.normal) - mesh::dot(lift, m.normal)).abs()).collect();
        let median = mesh::stats::median(&mut errors);
        assert!(median < 5e-4, "median point-to-plane error {median}");
    }
}
