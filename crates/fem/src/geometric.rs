//! Attachments and loads on regions of space rather than on node sets: each is integrated over
//! the exact region, cut cells and faces included, so that a finer mesh solves the same problem.
//! A node set changes with the mesh (a fixed ball of nodes clamps a different volume on every
//! mesh), which makes results jump between mesh sizes instead of converging.
//!
//! - [`Problem::add_foundation`]: an elastic foundation (energy ½ ∫ k |u|² dV over the part of
//!   the organ inside a ball), a ligament-like attachment with a stiffness per volume.
//! - [`Problem::add_patch_force`]: a total force spread as a uniform traction over the part of
//!   the boundary inside a ball (and facing a given way).

use mesh::{Ball, Cells, Point, SpaceBall};
use nalgebra::{DMatrix, SymmetricEigen};
use serde::{Deserialize, Serialize};

use crate::problem::{PointSpring, Problem};
use crate::FemError;

fn check(ball: &Ball) -> Result<(), FemError> {
    if ball.centre.iter().all(|c| c.is_finite()) && ball.radius > 0.0 && ball.radius.is_finite() {
        Ok(())
    } else {
        Err(FemError::Invalid(format!("ball {ball:?}: a finite centre and a positive radius")))
    }
}

/// An elastic foundation as a scenario gives it: the organ inside a ball tied to its rest position
/// with a stiffness per volume ([`Problem::attach_all`]); unlike fixed nodes, the same on every mesh.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Attachment {
    /// Where.
    #[serde(flatten)]
    pub region: SpaceBall,
    /// Stiffness per volume of tissue (N/m per m³).
    pub stiffness: f64,
}

/// Midpoints per direction of the collapsed-cube rule on a cell cut by the ball's sphere.
const CUT_POINTS: usize = 12;

/// Gauss–Legendre points and weights on [0, 1], 4 points: exact to degree 7 per direction, so
/// the collapsed-cube rule integrates N_a N_b of a T10 (degree 4) exactly on a cell inside the ball.
const GAUSS: [(f64, f64); 4] = [
    (0.069_431_844_202_973_7, 0.173_927_422_568_726_9),
    (0.330_009_478_207_571_9, 0.326_072_577_431_273_1),
    (0.669_990_521_792_428_1, 0.326_072_577_431_273_1),
    (0.930_568_155_797_026_3, 0.173_927_422_568_726_9),
];

/// Midpoints per side of the triangle rule on a boundary face near the patch.
const FACE_POINTS: usize = 16;

impl Problem {
    /// Adds each of `attachments` ([`Problem::add_foundation`] on its resolved ball); returns the
    /// balls. An error names the attachment (numbered from 1).
    pub fn attach_all(&mut self, attachments: &[Attachment]) -> Result<Vec<Ball>, FemError> {
        let mut balls = Vec::with_capacity(attachments.len());
        for (k, a) in attachments.iter().enumerate() {
            let numbered = |m: String| FemError::Invalid(format!("attachment {}: {m}", k + 1));
            let ball = a.region.resolve().map_err(numbered)?;
            self.add_foundation(&ball, a.stiffness).map_err(|e| match e {
                FemError::Invalid(m) => numbered(m),
                e => numbered(e.to_string()),
            })?;
            balls.push(ball);
        }
        Ok(balls)
    }

    /// Ties the part of the organ inside `ball` to its rest position with an elastic foundation
    /// of `stiffness` (N/m per m³ of tissue): energy ½ ∫ k |u|² dV over the exact intersection.
    /// Cells inside the ball are integrated exactly, cells cut by its sphere with a 12³-point
    /// rule on the indicator; each cell's matrix ∫ k N_a N_b dV is kept as at most as many
    /// rank-one [`PointSpring`]s as the cell has nodes (its eigen-decomposition). Tetrahedra (T4,
    /// T10) only. Returns the volume covered (m³); an error when the ball misses the mesh.
    pub fn add_foundation(&mut self, ball: &Ball, stiffness: f64) -> Result<f64, FemError> {
        check(ball)?;
        if !(stiffness > 0.0 && stiffness.is_finite()) {
            return Err(FemError::Invalid(format!("foundation stiffness {stiffness} must be positive")));
        }
        let cells: Vec<Vec<usize>> = match &self.mesh.cells {
            Cells::Tet4(c) => c.iter().map(|t| t.to_vec()).collect(),
            Cells::Tet10(c) => c.iter().map(|t| t.to_vec()).collect(),
            Cells::Hex8(_) => {
                return Err(FemError::Invalid("a foundation needs a tetrahedral mesh (T4 or T10)".into()))
            }
        };
        let mut covered = 0.0;
        for cell in &cells {
            let x: [Point; 4] = std::array::from_fn(|a| self.mesh.nodes[cell[a]]);
            let far = x.iter().map(|&p| mesh::distance(p, ball.centre)).fold(f64::INFINITY, f64::min);
            let diameter =
                (0..4).flat_map(|a| (a + 1..4).map(move |b| (a, b))).map(|(a, b)| mesh::distance(x[a], x[b]));
            if far > ball.radius + diameter.fold(0.0, f64::max) {
                continue;
            }
            let inside = x.iter().all(|&p| ball.contains(p));
            let (matrix, volume) = foundation_matrix(&x, cell.len(), ball, inside);
            if volume == 0.0 {
                continue;
            }
            covered += volume;
            let eigen = SymmetricEigen::new(matrix);
            let top = eigen.eigenvalues.iter().copied().fold(0.0, f64::max);
            for (k, &lambda) in eigen.eigenvalues.iter().enumerate() {
                if lambda > 1e-12 * top {
                    let v = eigen.eigenvectors.column(k);
                    self.point_springs.push(PointSpring {
                        nodes: cell.iter().zip(v.iter()).map(|(&n, &w)| (n, w)).collect(),
                        target: [0.0; 3],
                        stiffness: stiffness * lambda,
                        normal: [0.0, 0.0, 1.0],
                        normal_stiffness: 0.0,
                    });
                }
            }
        }
        if covered == 0.0 {
            return Err(FemError::Invalid(format!("the foundation's ball {ball:?} holds no part of the mesh")));
        }
        Ok(covered)
    }

    /// Adds `total` (N) spread as a uniform traction over the part of the boundary inside
    /// `ball`, on the faces whose outward normal points against `facing` when given (e.g. the
    /// side a camera looking along `facing` sees): [`Problem::patch_force_shares`] times `total`.
    /// Returns the loaded area (m²); an error when it is empty.
    pub fn add_patch_force(&mut self, ball: &Ball, facing: Option<Point>, total: Point) -> Result<f64, FemError> {
        if !total.iter().all(|t| t.is_finite()) {
            return Err(FemError::Invalid(format!("patch force {total:?} must be finite")));
        }
        let (shares, area) = self.patch_force_shares(ball, facing)?;
        for (n, s) in shares {
            for (f, t) in self.f_ext[3 * n..3 * n + 3].iter_mut().zip(total) {
                *f += t * s;
            }
        }
        Ok(area)
    }

    /// Each node's share (summing to 1) of a total force spread as a uniform traction over the
    /// part of the boundary inside `ball`, on the faces whose outward normal points against
    /// `facing` when given, and the loaded area (m²). Integrated with a 256-point rule on each
    /// face near the ball (linear or quadratic triangles); an error when the area is empty.
    pub fn patch_force_shares(&self, ball: &Ball, facing: Option<Point>) -> Result<(Vec<(usize, f64)>, f64), FemError> {
        check(ball)?;
        let mut shares = std::collections::BTreeMap::<usize, f64>::new();
        let mut area = 0.0;
        for face in mesh::boundary_faces(&self.mesh) {
            if face.nodes.len() == 4 {
                return Err(FemError::Invalid("a patch force needs triangular boundary faces (T4 or T10)".into()));
            }
            let x: [Point; 3] = std::array::from_fn(|a| self.mesh.nodes[face.nodes[a]]);
            let normal = mesh::cross(mesh::sub(x[1], x[0]), mesh::sub(x[2], x[0]));
            if facing.is_some_and(|f| mesh::dot(normal, f) >= 0.0) {
                continue;
            }
            let near = x.iter().map(|&p| mesh::distance(p, ball.centre)).fold(f64::INFINITY, f64::min);
            let side = (0..3).map(|a| mesh::distance(x[a], x[(a + 1) % 3])).fold(0.0, f64::max);
            if near > ball.radius + side {
                continue;
            }
            let weight = 0.5 * mesh::norm(normal) / (FACE_POINTS * FACE_POINTS) as f64;
            for l in triangle_points(FACE_POINTS) {
                let p: Point = std::array::from_fn(|d| (0..3).map(|a| l[a] * x[a][d]).sum());
                if ball.contains(p) {
                    area += weight;
                    for (&n, s) in face.nodes.iter().zip(face_shape(l, face.nodes.len())) {
                        *shares.entry(n).or_default() += weight * s;
                    }
                }
            }
        }
        if area == 0.0 {
            return Err(FemError::Invalid(format!("the patch's ball {ball:?} holds no boundary face")));
        }
        Ok((shares.into_iter().map(|(n, s)| (n, s / area)).collect(), area))
    }
}

/// ∫ N_a N_b dV over the part of the tetrahedron with corners `x` inside `ball` (a matrix over
/// its `nodes` = 4 or 10 nodes), and that part's volume. On the collapsed cube (Duffy):
/// λ1 = u, λ2 = v (1 − u), λ3 = w (1 − u)(1 − v), dV = 6 V (1 − u)² (1 − v) du dv dw.
fn foundation_matrix(x: &[Point; 4], nodes: usize, ball: &Ball, inside: bool) -> (DMatrix<f64>, f64) {
    let e = |a: usize| mesh::sub(x[a], x[0]);
    let six_volume = mesh::dot(mesh::cross(e(1), e(2)), e(3)).abs();
    let rule: Vec<(f64, f64)> = if inside {
        GAUSS.to_vec()
    } else {
        (0..CUT_POINTS).map(|i| ((i as f64 + 0.5) / CUT_POINTS as f64, 1.0 / CUT_POINTS as f64)).collect()
    };
    let mut matrix = DMatrix::zeros(nodes, nodes);
    let mut volume = 0.0;
    for &(u, wu) in &rule {
        for &(v, wv) in &rule {
            for &(w, ww) in &rule {
                let l = [0.0, u, v * (1.0 - u), w * (1.0 - u) * (1.0 - v)];
                let l = [1.0 - l[1] - l[2] - l[3], l[1], l[2], l[3]];
                let p: Point = std::array::from_fn(|d| (0..4).map(|a| l[a] * x[a][d]).sum());
                if !inside && !ball.contains(p) {
                    continue;
                }
                let weight = wu * wv * ww * six_volume * (1.0 - u).powi(2) * (1.0 - v);
                volume += weight;
                let shape: Vec<f64> = if nodes == 10 { mesh::tet10_shape(l).to_vec() } else { l.to_vec() };
                for a in 0..nodes {
                    for b in 0..nodes {
                        matrix[(a, b)] += weight * shape[a] * shape[b];
                    }
                }
            }
        }
    }
    (matrix, volume)
}

/// Barycentric centroids of the n² triangles of a triangle cut n times along each side.
fn triangle_points(n: usize) -> Vec<[f64; 3]> {
    let mut points = Vec::with_capacity(n * n);
    let f = n as f64;
    for i in 0..n {
        for j in 0..n - i {
            let (a, b) = (i as f64, j as f64);
            points.push([(a + 1.0 / 3.0) / f, (b + 1.0 / 3.0) / f]);
            if i + j + 1 < n {
                points.push([(a + 2.0 / 3.0) / f, (b + 2.0 / 3.0) / f]);
            }
        }
    }
    points.into_iter().map(|[a, b]| [1.0 - a - b, a, b]).collect()
}

/// The shape functions of a boundary face at barycentric `l`: a linear triangle, or a quadratic
/// one (corners, then the mid-edge nodes of edges 0-1, 1-2, 2-0).
fn face_shape(l: [f64; 3], nodes: usize) -> Vec<f64> {
    if nodes == 3 {
        return l.to_vec();
    }
    let corner = |a: usize| l[a] * (2.0 * l[a] - 1.0);
    vec![corner(0), corner(1), corner(2), 4.0 * l[0] * l[1], 4.0 * l[1] * l[2], 4.0 * l[2] * l[0]]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Law, Material};

    fn block(order: u8) -> Problem {
        let mesh = mesh::box_tet([0.0; 3], [0.1, 0.1, 0.05], [6, 6, 3]).unwrap();
        Problem::new(mesh, Material::new(Law::Linear, 5000.0, 0.45).with_order(order))
    }

    /// A rigid translation d of the foundation stores ½ k V |d|²: its springs' weights sum to
    /// the covered volume, which is the ball's cap in the block.
    #[test]
    fn a_foundation_covers_the_exact_volume_and_holds_a_translation_with_k_v() {
        for order in [1, 2] {
            let mut p = block(order);
            let ball = Ball { centre: [0.05, 0.05, 0.05], radius: 0.03 };
            let k = 1e6;
            let volume = p.add_foundation(&ball, k).unwrap();
            let half = 2.0 / 3.0 * std::f64::consts::PI * 0.03f64.powi(3);
            assert!((volume / half - 1.0).abs() < 5e-3, "order {order}: {volume} against {half}");
            let held: f64 =
                p.point_springs.iter().map(|s| s.stiffness * s.nodes.iter().map(|(_, w)| w).sum::<f64>().powi(2)).sum();
            assert!((held / (k * volume) - 1.0).abs() < 1e-9, "order {order}: {held} against {}", k * volume);
        }
    }

    /// A patch on the top face: the loaded area is the disc and the nodal forces sum to the total;
    /// seen from below, the top face is not loaded.
    #[test]
    fn a_patch_force_sums_to_its_total_over_the_discs_area() {
        for order in [1, 2] {
            let mut p = block(order);
            let ball = Ball { centre: [0.05, 0.05, 0.05], radius: 0.02 };
            let area = p.add_patch_force(&ball, Some([0.0, 0.0, -1.0]), [0.1, 0.0, -0.3]).unwrap();
            let disc = std::f64::consts::PI * 0.02f64.powi(2);
            assert!((area / disc - 1.0).abs() < 5e-3, "order {order}: {area} against {disc}");
            let sum: Vec<f64> = (0..3).map(|d| p.f_ext.iter().skip(d).step_by(3).sum()).collect();
            assert!((sum[0] - 0.1).abs() < 1e-12 && sum[1].abs() < 1e-12 && (sum[2] + 0.3).abs() < 1e-12, "{sum:?}");
            // Facing the other way: the top face is not seen, the bottom is out of the ball.
            let e = block(order).add_patch_force(&ball, Some([0.0, 0.0, 1.0]), [0.0, 0.0, 1.0]).unwrap_err();
            assert!(e.to_string().contains("no boundary face"), "{e}");
        }
    }

    #[test]
    fn bad_regions_are_errors() {
        let mut p = block(1);
        let far = Ball { centre: [1.0, 1.0, 1.0], radius: 0.01 };
        assert!(p.add_foundation(&far, 1e6).unwrap_err().to_string().contains("no part"));
        let ball = Ball { centre: [0.05; 3], radius: -1.0 };
        assert!(p.add_foundation(&ball, 1e6).is_err() && p.add_patch_force(&ball, None, [0.0; 3]).is_err());
        let good = Ball { centre: [0.05; 3], radius: 0.01 };
        assert!(p.add_foundation(&good, 0.0).is_err());
        let mut hex = Problem::new(
            mesh::box_hex([0.0; 3], [0.1; 3], [2, 2, 2]).unwrap(),
            Material::new(Law::Linear, 5000.0, 0.3),
        );
        assert!(hex.add_foundation(&good, 1e6).unwrap_err().to_string().contains("tetrahedral"));
    }
}
