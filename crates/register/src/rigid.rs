//! Rigid pre-alignment: trimmed iterative closest points (ICP) of the cloud to the organ's rest
//! surface, point-to-plane (default) or point-to-point.
//!
//! The cloud is partial (one side of the organ), noisy, has outliers, and the organ it shows is
//! deformed: each iteration matches every cloud point to the closest point of the rest surface
//! and keeps only the [`RigidOptions::keep`] fraction of the closest matches (trimmed ICP), so
//! that outliers and the most deformed parts do not pull the transform. The Gauss-Newton step
//! linearises the rotation about the centroid of the kept points and is applied exactly
//! (Rodrigues), with the rotation unknowns scaled by the cloud's size so that the 6 × 6 system is
//! well conditioned; a singular system (points that coincide or do not fix a rotation) is an
//! error.

use std::time::{Duration, Instant};

use mesh::bvh::SurfaceBvh;
use mesh::length::mm;
use mesh::length::LengthUnit;
use mesh::{cross, dot, sub, Mesh, Point, TriSurface};
use nalgebra::{Matrix6, Vector6};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::checks::check_setting;
use crate::{RegisterError, Result};

/// Fewest cloud points a rigid alignment accepts (6 unknowns, and trimming drops some).
pub const MIN_POINTS: usize = 10;

/// Fewest matches each step of the alignment keeps, however many the trimming drops: the 6 unknowns.
const MIN_KEPT: usize = 6;

/// A rigid transform `x ↦ R x + t` (R a rotation matrix, row-major; t in m).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct RigidTransform {
    /// The rotation matrix, rows.
    pub rotation: [[f64; 3]; 3],
    /// The translation (m).
    pub translation: Point,
}

impl Default for RigidTransform {
    fn default() -> Self {
        RigidTransform::identity()
    }
}

impl RigidTransform {
    /// The identity.
    pub fn identity() -> RigidTransform {
        RigidTransform { rotation: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]], translation: [0.0; 3] }
    }

    /// The rotation by `angle` radians about `axis` (through the origin; need not be
    /// normalised, may be zero when the angle is), then the translation `translation`.
    pub fn from_axis_angle(axis: Point, angle: f64, translation: Point) -> Result<RigidTransform> {
        let len = dot(axis, axis).sqrt();
        if !(angle.is_finite() && translation.iter().all(|x| x.is_finite()) && len.is_finite()) {
            return Err(RegisterError::Invalid(format!(
                "rigid transform: axis {axis:?}, angle {angle}, translation {translation:?} must be finite"
            )));
        }
        if angle == 0.0 {
            return Ok(RigidTransform { translation, ..RigidTransform::identity() });
        }
        if !(len > 0.0) {
            return Err(RegisterError::Invalid(format!("rigid transform: rotation axis {axis:?} is zero")));
        }
        Ok(RigidTransform { rotation: rotation_matrix(axis.map(|x| x * angle / len)), translation })
    }

    /// The image of point `p`.
    pub fn apply(&self, p: Point) -> Point {
        let r = self.rotate(p);
        [r[0] + self.translation[0], r[1] + self.translation[1], r[2] + self.translation[2]]
    }

    /// The 4 × 4 homogeneous matrix, rows, its translation in `unit`.
    pub fn homogeneous(&self, unit: LengthUnit) -> [[f64; 4]; 4] {
        let row = |i: usize| {
            let r = self.rotation[i];
            [r[0], r[1], r[2], unit.from_metres(self.translation[i])]
        };
        [row(0), row(1), row(2), [0.0, 0.0, 0.0, 1.0]]
    }

    /// The rotated vector `v` (no translation: for displacements and normals).
    pub fn rotate(&self, v: Point) -> Point {
        std::array::from_fn(|i| dot(self.rotation[i], v))
    }

    /// The inverse transform.
    pub fn inverse(&self) -> RigidTransform {
        let r = self.rotation;
        let rotation = std::array::from_fn(|i| std::array::from_fn(|j| r[j][i]));
        let inv = RigidTransform { rotation, translation: [0.0; 3] };
        let t = inv.rotate(self.translation);
        RigidTransform { rotation, translation: [-t[0], -t[1], -t[2]] }
    }

    /// `other` after `self`: `x ↦ other(self(x))`.
    pub fn then(&self, other: &RigidTransform) -> RigidTransform {
        let (a, b) = (self.rotation, other.rotation);
        let rotation = std::array::from_fn(|i| std::array::from_fn(|j| (0..3).map(|k| b[i][k] * a[k][j]).sum()));
        RigidTransform { rotation, translation: other.apply(self.translation) }
    }

    /// The rotation angle (radians, in [0, π]).
    pub fn angle(&self) -> f64 {
        let r = self.rotation;
        let v = [r[2][1] - r[1][2], r[0][2] - r[2][0], r[1][0] - r[0][1]];
        // atan2(sin, cos): accurate for small angles too, unlike acos of the trace.
        (0.5 * dot(v, v).sqrt()).atan2(0.5 * (r[0][0] + r[1][1] + r[2][2] - 1.0))
    }

    /// The length of the translation (m).
    pub fn translation_norm(&self) -> f64 {
        dot(self.translation, self.translation).sqrt()
    }

    /// How far `self` is from `truth` (two transforms of the same direction): the rotation angle
    /// (radians) and translation (m) of `truth⁻¹ ∘ self`, i.e. of what is left when `self`'s
    /// result is moved back by the truth.
    pub fn error_to(&self, truth: &RigidTransform) -> (f64, f64) {
        let residual = self.then(&truth.inverse());
        (residual.angle(), residual.translation_norm())
    }

    /// `mesh` with its nodes moved.
    pub fn move_mesh(&self, mesh: &Mesh) -> Mesh {
        let mut moved = mesh.clone();
        moved.nodes.iter_mut().for_each(|p| *p = self.apply(*p));
        moved
    }

    /// A node-major vector field (3 per node, e.g. a displacement) rotated.
    pub fn rotate_field(&self, u: &[f64]) -> Vec<f64> {
        u.chunks_exact(3).flat_map(|v| self.rotate([v[0], v[1], v[2]])).collect()
    }
}

/// The rotation matrix of the rotation vector `w` (axis × angle), by Rodrigues' formula.
fn rotation_matrix(w: Point) -> [[f64; 3]; 3] {
    let angle = dot(w, w).sqrt();
    let mut r = RigidTransform::identity().rotation;
    if angle == 0.0 {
        return r;
    }
    let k = w.map(|x| x / angle);
    let (s, c) = angle.sin_cos();
    let kx = [[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]];
    for i in 0..3 {
        for j in 0..3 {
            r[i][j] = if i == j { c } else { 0.0 } + s * kx[i][j] + (1.0 - c) * k[i] * k[j];
        }
    }
    r
}

/// What ICP minimises.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum IcpMetric {
    /// The distance of each point to the tangent plane at its match (fast convergence; lets
    /// the cloud slide along the surface where the surface allows it).
    #[default]
    PointToPlane,
    /// The distance of each point to its match.
    PointToPoint,
}

/// Settings of the rigid pre-alignment.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RigidOptions {
    /// Point-to-plane or point-to-point.
    pub metric: IcpMetric,
    /// Most ICP iterations.
    pub iterations: usize,
    /// Fraction of the matches kept at each iteration, the closest (trimmed ICP): the rest are
    /// outliers or the most deformed parts.
    pub keep: f64,
    /// Matches farther than this multiple of the median match distance are dropped too
    /// (outliers; 1 mm noise leaves most points within 3 medians).
    pub outlier_factor: f64,
    /// Stop once an iteration moves no kept point by more than this (m).
    pub tolerance: f64,
}

impl Default for RigidOptions {
    fn default() -> Self {
        RigidOptions {
            metric: IcpMetric::PointToPlane,
            iterations: 100,
            keep: 0.7,
            outlier_factor: 3.0,
            tolerance: 1e-6,
        }
    }
}

impl RigidOptions {
    /// Checks the values, naming the first that is out of its range.
    pub fn validate(&self) -> Result<()> {
        if self.iterations == 0 {
            return Err(RegisterError::Invalid("rigid.iterations = 0 must be at least 1".into()));
        }
        check_setting("rigid.keep", self.keep, self.keep > 0.0 && self.keep <= 1.0, "in (0, 1]")?;
        let factor = self.outlier_factor;
        check_setting("rigid.outlier_factor", factor, factor > 0.0, "positive and finite")?;
        check_setting("rigid.tolerance", self.tolerance, self.tolerance >= 0.0, "non-negative and finite")
    }
}

/// The rigid alignment of a cloud to a surface.
#[derive(Clone, Debug, PartialEq)]
pub struct RigidResult {
    /// Cloud frame → organ frame: moves the cloud onto the surface.
    pub cloud_to_organ: RigidTransform,
    /// ICP iterations run.
    pub iterations: usize,
    /// Whether the last update was below the tolerance (else the iterations ran out).
    pub converged: bool,
    /// Root mean square distance of the kept matches after alignment (m).
    pub rms: f64,
    /// Matches kept at the end (at most the `keep` fraction of the points, outliers dropped).
    pub kept: usize,
    /// Cloud points.
    pub points: usize,
    /// Wall time.
    pub time: Duration,
}

impl RigidResult {
    /// Organ frame → cloud frame: where the preoperative model lies in the camera's frame.
    pub fn organ_to_cloud(&self) -> RigidTransform {
        self.cloud_to_organ.inverse()
    }
}

/// `points` of the organ's frame in the cloud's: moved by the rigid alignment `rigid`, if any.
pub fn in_cloud_frame(mut points: Vec<Point>, rigid: Option<&RigidResult>) -> Vec<Point> {
    if let Some(r) = rigid {
        let t = r.organ_to_cloud();
        points.iter_mut().for_each(|p| *p = t.apply(*p));
    }
    points
}

/// The rigid transform that moves `cloud` onto `surface` (trimmed ICP from the identity: the
/// cloud must be roughly aligned already, within some degrees and centimetres).
pub fn rigid_align(surface: &TriSurface, cloud: &[Point], options: &RigidOptions) -> Result<RigidResult> {
    let t0 = Instant::now();
    options.validate()?;
    crate::checks::check_cloud(cloud)?;
    let n = cloud.len();
    let kept = ((options.keep * n as f64).ceil() as usize).min(n);
    if n < MIN_POINTS || kept < MIN_KEPT {
        return Err(RegisterError::Invalid(format!(
            "rigid alignment needs at least {MIN_POINTS} cloud points (and {MIN_KEPT} kept), got {n} ({kept} kept)"
        )));
    }
    let bvh = SurfaceBvh::new(surface)?;
    // Point-to-plane uses the surface's smooth normal at the match (vertex normals interpolated):
    // facet normals jump from triangle to triangle, and noisy points then chatter between planes.
    let vertex_normals = surface.vertex_normals();
    let smooth_normal = |triangle: usize, p: Point| {
        let tri = surface.triangles[triangle];
        let b = mesh::bvh::triangle_barycentric(tri.map(|k| surface.vertices[k]), p);
        mesh::blend_unit(tri.map(|k| vertex_normals[k]), b)
    };
    let mut transform = RigidTransform::identity();
    let mut iterations = 0;
    let mut converged = false;
    let mut order: Vec<usize> = (0..n).collect();
    let (rms, used) = loop {
        let moved: Vec<Point> = cloud.par_iter().map(|&p| transform.apply(p)).collect();
        let matches: Vec<_> = moved.par_iter().map(|&q| bvh.closest_point(q)).collect();
        // The `kept` closest matches, in a deterministic order, without those beyond the outlier
        // limit (but never fewer than MIN_KEPT).
        order.sort_unstable_by(|&a, &b| matches[a].distance.total_cmp(&matches[b].distance).then(a.cmp(&b)));
        let limit = options.outlier_factor * matches[order[n / 2]].distance;
        let within = order.partition_point(|&i| matches[i].distance <= limit);
        let chosen = &order[..kept.min(within).max(MIN_KEPT)];
        let rms = (chosen.iter().map(|&i| matches[i].distance.powi(2)).sum::<f64>() / chosen.len() as f64).sqrt();
        if converged || iterations == options.iterations {
            break (rms, chosen.len());
        }
        iterations += 1;
        let centroid: Point =
            std::array::from_fn(|d| chosen.iter().map(|&i| moved[i][d]).sum::<f64>() / chosen.len() as f64);
        let radius = chosen.iter().map(|&i| dot(sub(moved[i], centroid), sub(moved[i], centroid))).fold(0.0, f64::max);
        let radius = radius.sqrt();
        if !(radius > 1e-9) {
            return Err(RegisterError::Invalid(format!(
                "rigid alignment is not determined: the {} kept cloud points coincide",
                chosen.len()
            )));
        }
        // Normal equations of the linearised step x = (ω·radius, δ):
        // q' = c + R(ω)(q − c) + δ ≈ q + ω × (q − c) + δ.
        let mut h = [[0.0; 6]; 6];
        let mut g = [0.0; 6];
        let mut add = |a: Point, normal: Point, r: f64| {
            let an = cross(a, normal);
            let j = [an[0], an[1], an[2], normal[0], normal[1], normal[2]];
            for p in 0..6 {
                g[p] += j[p] * r;
                for q in 0..6 {
                    h[p][q] += j[p] * j[q];
                }
            }
        };
        for &i in chosen {
            let (q, m) = (moved[i], &matches[i]);
            let a = sub(q, centroid).map(|x| x / radius);
            let e = sub(q, m.point);
            match options.metric {
                IcpMetric::PointToPlane => {
                    let normal = smooth_normal(m.triangle, m.point);
                    add(a, normal, dot(e, normal))
                }
                IcpMetric::PointToPoint => {
                    for (d, &ed) in e.iter().enumerate() {
                        let mut axis = [0.0; 3];
                        axis[d] = 1.0;
                        add(a, axis, ed);
                    }
                }
            }
        }
        let x = solve_spd(h, g.map(|v| -v)).ok_or_else(|| {
            RegisterError::Invalid(format!(
                "rigid alignment is not determined: the {} kept cloud points do not fix a rotation and \
                 translation (degenerate geometry, e.g. collinear points, or a flat patch with point-to-plane)",
                chosen.len()
            ))
        })?;
        let w: Point = [x[0] / radius, x[1] / radius, x[2] / radius];
        let delta = [x[3], x[4], x[5]];
        let step = RigidTransform { rotation: rotation_matrix(w), translation: [0.0; 3] };
        let c = step.rotate(centroid);
        let update = RigidTransform {
            translation: [centroid[0] - c[0] + delta[0], centroid[1] - c[1] + delta[1], centroid[2] - c[2] + delta[2]],
            ..step
        };
        transform = transform.then(&update);
        let motion = dot(w, w).sqrt() * radius + dot(delta, delta).sqrt();
        if !motion.is_finite() {
            return Err(RegisterError::Invalid("rigid alignment diverged (non-finite update)".into()));
        }
        converged = motion <= options.tolerance;
    };
    Ok(RigidResult { cloud_to_organ: transform, iterations, converged, rms, kept: used, points: n, time: t0.elapsed() })
}

/// Solves the symmetric positive definite 6 × 6 system `h x = b` by Cholesky; `None` when `h` is
/// singular (a pivot below 1e-10 of the largest diagonal entry).
fn solve_spd(h: [[f64; 6]; 6], b: [f64; 6]) -> Option<[f64; 6]> {
    let h = Matrix6::from_fn(|i, j| h[i][j]);
    let scale = h.diagonal().max();
    if !(scale > 0.0 && scale.is_finite()) {
        return None;
    }
    let cholesky = h.cholesky()?;
    // The pivots are the squares of the factor's diagonal.
    if cholesky.l().diagonal().iter().any(|d| !(d * d > 1e-10 * scale)) {
        return None;
    }
    Some(cholesky.solve(&Vector6::from(b)).into())
}

/// The rigid alignment in summary.json: the organ → cloud transform and the ICP's figures.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RigidSummary {
    /// Organ (preoperative) frame → cloud frame, homogeneous 4 × 4, rows: `x_cloud = M x_organ`,
    /// its translation in mm as every length of the summary.
    pub organ_to_cloud: [[f64; 4]; 4],
    /// Its rotation angle (degrees).
    pub rotation_deg: f64,
    /// Its translation length (mm).
    pub translation_mm: f64,
    /// ICP iterations.
    pub iterations: usize,
    /// Whether ICP met its tolerance.
    pub converged: bool,
    /// RMS distance of the kept matches to the rest surface after alignment (mm).
    pub rms_mm: f64,
    /// Matches kept (of `points`).
    pub kept: usize,
    /// Cloud points.
    pub points: usize,
    /// Wall time of the alignment (ms).
    pub time_ms: f64,
}

impl From<&RigidResult> for RigidSummary {
    fn from(r: &RigidResult) -> Self {
        let t = r.organ_to_cloud();
        RigidSummary {
            organ_to_cloud: t.homogeneous(LengthUnit::Millimetre),
            rotation_deg: t.angle().to_degrees(),
            translation_mm: mm(t.translation_norm()),
            iterations: r.iterations,
            converged: r.converged,
            rms_mm: mm(r.rms),
            kept: r.kept,
            points: r.points,
            time_ms: mesh::stats::ms(r.time),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn transforms_compose_and_invert() {
        let t = RigidTransform::from_axis_angle([1.0, 2.0, 3.0], 0.3, [0.01, -0.02, 0.03]).unwrap();
        let p = [0.1, -0.05, 0.02];
        let back = t.inverse().apply(t.apply(p));
        assert!(back.iter().zip(&p).all(|(a, b)| (a - b).abs() < 1e-15), "{back:?}");
        assert!((t.angle() - 0.3).abs() < 1e-12);
        let (angle, shift) = t.then(&t.inverse()).error_to(&RigidTransform::identity());
        assert!(angle < 1e-15 && shift < 1e-15, "{angle} {shift}");
        let two = t.then(&t);
        assert!((two.angle() - 0.6).abs() < 1e-12);
        let q = two.apply(p);
        let expected = t.apply(t.apply(p));
        assert!(q.iter().zip(&expected).all(|(a, b)| (a - b).abs() < 1e-15));
        assert!(RigidTransform::from_axis_angle([0.0; 3], 0.1, [0.0; 3]).is_err());
        assert_eq!(
            RigidTransform::from_axis_angle([0.0; 3], 0.0, [1.0, 0.0, 0.0]).unwrap().translation,
            [1.0, 0.0, 0.0]
        );
    }

    #[test]
    fn cholesky_solves_and_refuses_singular_systems() {
        let mut h = [[0.0; 6]; 6];
        for i in 0..6 {
            h[i][i] = 2.0 + i as f64;
            if i > 0 {
                h[i][i - 1] = 0.5;
                h[i - 1][i] = 0.5;
            }
        }
        let x = solve_spd(h, [1.0; 6]).unwrap();
        for row in &h {
            let r: f64 = row.iter().zip(&x).map(|(a, b)| a * b).sum();
            assert!((r - 1.0).abs() < 1e-12);
        }
        h[5] = [0.0; 6];
        (0..6).for_each(|i| h[i][5] = 0.0);
        assert!(solve_spd(h, [1.0; 6]).is_none());
    }
}
