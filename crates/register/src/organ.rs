//! The preoperative organ: a volumetric mesh and its surface embedded in it.

use mesh::bvh::{triangle_barycentric, SurfaceBvh};
use mesh::embedding::MeshLocator;
use mesh::length::{mm, point_in_mm, LengthUnit, UnitMistake};
use mesh::{Mesh, Point, TriSurface};

use crate::rigid::in_cloud_frame;
use crate::{RegisterError, Result, RigidResult};

/// Interpolation weights below this are rounding errors (see [`Stencil`]'s constructor).
const NEGLIGIBLE_WEIGHT: f64 = 1e-12;

/// Interpolation weights of a point in the mesh: (node, weight) pairs summing to 1.
#[derive(Clone, Debug, PartialEq)]
pub struct Stencil(pub Vec<(usize, f64)>);

impl Stencil {
    /// The stencil of a location, its weights clipped to [0, 1], those below [`NEGLIGIBLE_WEIGHT`]
    /// dropped, and renormalised: a point on an element's face may get weights of ±1e−15 from
    /// the nodes off the face (on a T10 face, from the mid-edge nodes off it: kept, they had
    /// doubled the nodes a surface match moves).
    fn of(location: &mesh::embedding::Location) -> Stencil {
        let terms: Vec<(usize, f64)> =
            location.terms().map(|(n, w)| (n, w.clamp(0.0, 1.0))).filter(|t| t.1 > NEGLIGIBLE_WEIGHT).collect();
        let sum: f64 = terms.iter().map(|t| t.1).sum();
        Stencil(terms.into_iter().map(|(n, w)| (n, w / sum)).collect())
    }

    /// The interpolated value of a field with one value per node.
    pub fn scalar(&self, values: &[f64]) -> f64 {
        self.0.iter().map(|&(n, w)| w * values[n]).sum()
    }

    /// The interpolated vector of a node-major field with 3 components per node.
    pub fn vector(&self, u: &[f64]) -> Point {
        let mut v = [0.0; 3];
        for &(n, w) in &self.0 {
            for (d, x) in v.iter_mut().enumerate() {
                *x += w * u[3 * n + d];
            }
        }
        v
    }
}

/// A volumetric mesh (T4 or H8) with the surface the camera sees, each surface
/// vertex located in the mesh so that any nodal displacement moves the surface.
#[derive(Clone, Debug)]
pub struct Organ {
    mesh: Mesh,
    surface: TriSurface,
    stencils: Vec<Stencil>,
    locator: MeshLocator,
    /// The rest surface's bounding-volume hierarchy, built once.
    rest_bvh: SurfaceBvh,
}

impl Organ {
    /// The organ of `mesh` with the given surface (e.g. the smooth surface of an
    /// organ meshed by an immersed grid), or the mesh's own boundary when `None`.
    /// A surface vertex outside every element (an immersed grid may leave a sliver
    /// of the surface uncovered) takes the nearest mesh node.
    pub fn new(mesh: Mesh, surface: Option<TriSurface>) -> Result<Organ> {
        let locator = MeshLocator::new(&mesh)?;
        let surface = match surface {
            Some(s) => s,
            None => mesh::boundary_surface(&mesh).compacted(),
        };
        if surface.triangles.is_empty() {
            return Err(RegisterError::Invalid("the organ surface has no triangles".into()));
        }
        let nv = surface.vertices.len();
        if let Some(t) = surface.triangles.iter().position(|t| t.iter().any(|&k| k >= nv)) {
            return Err(RegisterError::Invalid(format!("surface triangle {t} refers to a missing vertex")));
        }
        let stencils = surface
            .vertices
            .iter()
            .map(|&p| match locator.locate(p) {
                Some(loc) => Stencil::of(&loc),
                None => Stencil(vec![(mesh::select::nearest(&mesh.nodes, 0..mesh.num_nodes(), p).unwrap_or(0), 1.0)]),
            })
            .collect();
        let rest_bvh = SurfaceBvh::new(&surface)?;
        Ok(Organ { mesh, surface, stencils, locator, rest_bvh })
    }

    /// The volumetric mesh.
    pub fn mesh(&self) -> &Mesh {
        &self.mesh
    }

    /// The surface at rest.
    pub fn surface(&self) -> &TriSurface {
        &self.surface
    }

    /// The rest surface's bounding-volume hierarchy (closest points, distances).
    pub fn rest_bvh(&self) -> &SurfaceBvh {
        &self.rest_bvh
    }

    /// Where each surface vertex takes its displacement from.
    pub fn surface_stencils(&self) -> &[Stencil] {
        &self.stencils
    }

    /// The surface moved by the nodal displacement `u` (3 per mesh node).
    pub fn deformed_surface(&self, u: &[f64]) -> TriSurface {
        moved_surface(&self.surface, &self.stencils, u, None)
    }

    /// The stencil of the point with barycentric coordinates `weights` in surface triangle
    /// `triangle` (its vertices' stencils, weighted).
    pub fn surface_point_stencil(&self, triangle: usize, weights: [f64; 3]) -> Stencil {
        let corners = self.surface.triangles[triangle];
        Stencil(
            weights
                .iter()
                .zip(&corners)
                .flat_map(|(b, &k)| self.stencils[k].0.iter().map(move |&(node, w)| (node, b * w)))
                .collect(),
        )
    }

    /// The displacement `u` (3 per mesh node) at the points of the rest surface nearest to
    /// `points`: of another discretisation of the same organ, e.g. a model's surface nodes on a
    /// truth's finer surface.
    pub fn surface_displacement_at(&self, u: &[f64], points: &[Point]) -> Result<Vec<Point>> {
        let bvh = &self.rest_bvh;
        Ok(points.iter().map(|&p| self.nearest_surface_stencil(bvh, p).0.vector(u)).collect())
    }

    /// The stencil of the rest surface's point nearest to `p` (`bvh` over the surface), and its
    /// distance.
    fn nearest_surface_stencil(&self, bvh: &SurfaceBvh, p: Point) -> (Stencil, f64) {
        let closest = bvh.closest_point(p);
        let corners = self.surface.triangles[closest.triangle].map(|k| self.surface.vertices[k]);
        let stencil = self.surface_point_stencil(closest.triangle, triangle_barycentric(corners, closest.point));
        (stencil, closest.distance)
    }

    /// Stencils of points of the same organ's other discretisation (e.g. targets inside the
    /// organ a model was set up on, in a truth meshed anew), each with how far outside this mesh
    /// it lies (0 inside): a point outside, by at most `tolerance`, follows the surface's nearest
    /// point.
    pub fn locate_near(&self, points: &[Point], tolerance: f64, what: &str) -> Result<Vec<(Stencil, f64)>> {
        let bvh = &self.rest_bvh;
        points
            .iter()
            .enumerate()
            .map(|(i, &p)| {
                if let Some(location) = self.locator.locate(p) {
                    return Ok((Stencil::of(&location), 0.0));
                }
                let (stencil, distance) = self.nearest_surface_stencil(bvh, p);
                if !(distance <= tolerance) {
                    return Err(RegisterError::Invalid(format!(
                        "{what} {} at {} lies {:.2} mm outside the organ mesh",
                        i + 1,
                        point_in_mm(p),
                        mm(distance)
                    )));
                }
                Ok((stencil, distance))
            })
            .collect()
    }

    /// Stencils of points inside the organ (e.g. targets); a point outside, or not finite, is an
    /// error naming it.
    pub fn locate(&self, points: &[Point], what: &str) -> Result<Vec<Stencil>> {
        self.locate_labelled(points, &[], what)
    }

    /// [`Organ::locate`] of points with labels (one each, "" for none; or none at all), which an
    /// error names beside the point's number: "target 2 (`T3`)".
    fn locate_labelled(&self, points: &[Point], labels: &[String], what: &str) -> Result<Vec<Stencil>> {
        let name = |i: usize| point_name(what, i, labels);
        if let Some((i, fault)) = mesh::measured_fault(points) {
            return Err(RegisterError::Invalid(format!("{} {fault}", name(i))));
        }
        points
            .iter()
            .enumerate()
            .map(|(i, &p)| {
                self.locator.locate(p).map(|l| Stencil::of(&l)).ok_or_else(|| {
                    RegisterError::Invalid(format!("{} at {} is outside the organ mesh", name(i), point_in_mm(p)))
                })
            })
            .collect()
    }
}

/// The share of the organ's extent below which a set of several targets (or landmarks) is
/// suspected of a unit mistake (metres read as millimetres shrink it 1,000 times).
pub const SMALL_TARGET_EXTENT: f64 = 0.01;

/// Landmarks outside the organ by more than this share of its extent are refused: they are
/// points on its surface, where it is held.
pub const LANDMARK_REACH: f64 = 0.15;

/// Targets outside the organ's mesh by less than this share of its extent are near it (in a part
/// of the organ its mesh leaves out, or just past its surface): their error names no unit or frame
/// mistake, which would put some of them far off.
pub const NEAR_OUTSIDE: f64 = 0.1;

impl Organ {
    /// Stencils of the targets in the organ, and warnings about them. A target outside the organ
    /// is an error, which names it (by its label too, where `labels` give one) and, when one of
    /// them lies farther than [`NEAR_OUTSIDE`], the likely mistake (millimetres given for metres
    /// or the reverse; the other of RAS and LPS, also for targets near it: an organ about the
    /// origin keeps them so); a set of targets whose extent is under [`SMALL_TARGET_EXTENT`] of the
    /// organ's is warned about, and refused when, read 1,000 times larger, it lies in the organ
    /// (metres given for millimetres, which would register every target at one point).
    pub fn locate_targets(&self, targets: &[Point], labels: &[String]) -> Result<(Vec<Stencil>, Vec<String>)> {
        let inside = |moved: &[Point]| self.locate(moved, "target").is_ok();
        let stencils = self.locate_labelled(targets, labels, "target").map_err(|e| {
            let near = targets.iter().all(|&p| self.rest_bvh.signed_distance(p) <= NEAR_OUTSIDE * self.extent());
            let claim = "every target lies inside";
            let hint = match near {
                true => likely_frame_mistake(targets, claim, inside).unwrap_or_default(),
                false => likely_mistake(targets, &self.mesh.nodes, claim, true, inside),
            };
            RegisterError::Invalid(format!("{e}{hint}"))
        })?;
        match self.spread_warning(targets, "targets", inside) {
            Some((warning, true)) => Err(RegisterError::Invalid(warning)),
            warning => Ok((stencils, warning.into_iter().map(|(w, _)| w).collect())),
        }
    }

    /// Checks that the landmarks where the organ is held lie on its surface or inside it: one
    /// outside by more than [`LANDMARK_REACH`] of its extent is an error naming it and the likely
    /// mistake (another unit, the other frame); so is a set of landmarks spread over less than
    /// [`SMALL_TARGET_EXTENT`] of the organ that, read 1,000 times larger, lies on it. Returns
    /// warnings: a set of landmarks so small otherwise.
    pub fn check_landmarks(&self, landmarks: &[Point], labels: &[String]) -> Result<Vec<String>> {
        let name = |i: usize| point_name("landmark", i, labels);
        if let Some((i, fault)) = mesh::measured_fault(landmarks) {
            return Err(RegisterError::Invalid(format!("{} {fault}", name(i))));
        }
        let bvh = &self.rest_bvh;
        let reach = LANDMARK_REACH * self.extent();
        let outside = |p: Point| bvh.signed_distance(p).max(0.0);
        let held = |moved: &[Point]| moved.iter().all(|&p| outside(p) <= reach);
        let farthest = landmarks.iter().map(|&p| outside(p)).enumerate().max_by(|a, b| a.1.total_cmp(&b.1));
        if let Some((i, distance)) = farthest.filter(|&(_, d)| !(d <= reach)) {
            return Err(RegisterError::Invalid(format!(
                "{} at {} lies {:.1} mm outside the organ, farther than {:.0} % of its {:.0} mm (its box's \
                 diagonal; landmarks are points on its surface, where it is held){}",
                name(i),
                point_in_mm(landmarks[i]),
                mm(distance),
                LANDMARK_REACH * 100.0,
                mm(self.extent()),
                likely_mistake(landmarks, &self.mesh.nodes, "every landmark lies on the organ", true, held)
            )));
        }
        match self.spread_warning(landmarks, "landmarks", held) {
            Some((warning, true)) => Err(RegisterError::Invalid(warning)),
            warning => Ok(warning.into_iter().map(|(w, _)| w).collect()),
        }
    }

    /// The diagonal of the bounding box of the organ's mesh.
    pub fn extent(&self) -> f64 {
        diagonal(&self.mesh.nodes)
    }

    /// The warning when several `points` (`what`: "targets") span less than
    /// [`SMALL_TARGET_EXTENT`] of the organ, and whether, read 1,000 times larger, they lie where
    /// `fits` wants them (metres given for millimetres, which it then asks).
    pub(crate) fn spread_warning(
        &self,
        points: &[Point],
        what: &str,
        fits: impl Fn(&[Point]) -> bool,
    ) -> Option<(String, bool)> {
        let (organ_extent, extent) = (self.extent(), diagonal(points));
        if points.len() < 2 || extent >= SMALL_TARGET_EXTENT * organ_extent {
            return None;
        }
        let metres = UnitMistake { given: LengthUnit::Metre, expected: LengthUnit::Millimetre };
        let mistaken = scaled_fits(points, metres.factor(), &OrganBox::of(&self.mesh.nodes), &fits);
        let warning = format!(
            "the {} {what} span {:.3} mm, under {:.0} % of the organ's {:.0} mm (its box's diagonal){}",
            points.len(),
            mm(extent),
            SMALL_TARGET_EXTENT * 100.0,
            mm(organ_extent),
            if mistaken { format!(": were they {}?", metres.question()) } else { String::new() }
        );
        Some((warning, mistaken))
    }
}

/// Whether `points` scaled by `scale` lie where `fits` wants them, spread (when several) over at
/// least [`SMALL_TARGET_EXTENT`] of the organ's extent: points merely shrunk onto an organ around
/// the origin tell nothing. Read smaller (`scale` < 1), they must lie farther than the organ's
/// extent from its centre, as points too large by a unit's factor do: near it, shrunk towards an
/// origin the organ holds, any of them would fit.
fn scaled_fits(points: &[Point], scale: f64, organ: &OrganBox, fits: impl Fn(&[Point]) -> bool) -> bool {
    let spread = points.len() < 2 || scale * diagonal(points) >= SMALL_TARGET_EXTENT * organ.extent;
    let far = scale >= 1.0 || points.iter().any(|&p| mesh::norm(mesh::sub(p, organ.centre)) > organ.extent);
    spread && far && fits(&points.iter().map(|p| p.map(|x| x * scale)).collect::<Vec<_>>())
}

/// The centre and extent (diagonal) of the box of an organ's nodes.
struct OrganBox {
    centre: Point,
    extent: f64,
}

impl OrganBox {
    fn of(nodes: &[Point]) -> OrganBox {
        let (lo, hi) = mesh::bounds(nodes);
        OrganBox { centre: std::array::from_fn(|d| 0.5 * (lo[d] + hi[d])), extent: mesh::box_diagonal((lo, hi)) }
    }
}

/// The likely mistake behind `points` that do not lie where `fits` wants them (in an organ of
/// nodes `organ`), as the end of an error message: that with x and y negated (a frame mix-up,
/// RAS and LPS; only where `frames_may_differ`), or read 1,000 or 10 times smaller or larger (a
/// unit mistake: m and mm, cm and mm), `claim` holds. Empty when none of these fits.
pub(crate) fn likely_mistake(
    points: &[Point],
    organ: &[Point],
    claim: &str,
    frames_may_differ: bool,
    fits: impl Fn(&[Point]) -> bool,
) -> String {
    let organ = &OrganBox::of(organ);
    if let Some(hint) = likely_frame_mistake(points, claim, &fits).filter(|_| frames_may_differ) {
        return hint;
    }
    match UnitMistake::COMMON.into_iter().find(|m| scaled_fits(points, m.factor(), organ, &fits)) {
        Some(mistake) => {
            format!(" (read as {}, {claim}: were they {}?)", mistake.undone_words(), mistake.question())
        }
        None => String::new(),
    }
}

/// The end of an error message when `points` with x and y negated lie where `fits` wants them (the
/// other of RAS and LPS), saying that `claim` then holds.
fn likely_frame_mistake(points: &[Point], claim: &str, fits: impl Fn(&[Point]) -> bool) -> Option<String> {
    let negated: Vec<Point> = points.iter().map(|p| [-p[0], -p[1], p[2]]).collect();
    fits(&negated)
        .then(|| format!(" (with x and y negated {claim}: are they in LPS where the organ is in RAS, or the reverse?)"))
}

/// The diagonal of the bounding box of `points`.
fn diagonal(points: &[Point]) -> f64 {
    mesh::box_diagonal(mesh::bounds(points))
}

/// Positions of located points after the displacement `u`.
pub fn displaced(rest: &[Point], stencils: &[Stencil], u: &[f64]) -> Vec<Point> {
    rest.iter()
        .zip(stencils)
        .map(|(p, s)| {
            let d = s.vector(u);
            [p[0] + d[0], p[1] + d[1], p[2] + d[2]]
        })
        .collect()
}

/// `rest` with each vertex moved by its stencil over `u`, in the cloud's frame (moved by the rigid
/// alignment `rigid`, if any).
pub(crate) fn moved_surface(
    rest: &TriSurface,
    stencils: &[Stencil],
    u: &[f64],
    rigid: Option<&RigidResult>,
) -> TriSurface {
    TriSurface {
        vertices: in_cloud_frame(displaced(&rest.vertices, stencils, u), rigid),
        triangles: rest.triangles.clone(),
    }
}

/// The name of point `i` of a set of `what` ("target") in messages: its number from 1, and its
/// label, when it has one, as in "target 2 (`T3`)".
fn point_name(what: &str, i: usize, labels: &[String]) -> String {
    match labels.get(i).filter(|l| !l.is_empty()) {
        Some(label) => format!("{what} {} (`{label}`)", i + 1),
        None => format!("{what} {}", i + 1),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The corners of the box of the tests (m).
    const BOX: (Point, Point) = ([0.0, 0.0, 0.0], [0.04, 0.02, 0.01]);

    /// A linear displacement field.
    fn field(p: Point) -> Point {
        [0.1 * p[0] + 0.02 * p[2], -0.05 * p[1], 0.03 * p[0] + 0.2 * p[1] - 0.1 * p[2]]
    }

    /// The box meshed by 4 × 2 × 1 cubes of tetrahedra, and [`field`] at its nodes.
    fn box_organ() -> (Organ, Vec<f64>) {
        let organ = Organ::new(mesh::generate::box_tet(BOX.0, BOX.1, [4, 2, 1]).unwrap(), None).unwrap();
        let u = organ.mesh().nodes.iter().flat_map(|&p| field(p)).collect();
        (organ, u)
    }

    /// A linear displacement field is linear on each flat surface triangle: read at the surface
    /// nodes of a finer mesh of the same box, it is the field itself there, and a point off the
    /// surface takes the value at its nearest surface point.
    #[test]
    fn the_surface_displacement_of_a_linear_field_is_exact_at_another_meshes_surface() {
        let (lo, hi) = BOX;
        let (organ, u) = box_organ();
        let finer = mesh::generate::box_tet(lo, hi, [7, 5, 3]).unwrap();
        let points: Vec<Point> = finer.surface_nodes().iter().map(|&n| finer.nodes[n]).collect();
        let got = organ.surface_displacement_at(&u, &points).unwrap();
        for (p, g) in points.iter().zip(&got) {
            let want = field(*p);
            assert!((0..3).all(|d| (g[d] - want[d]).abs() < 1e-12), "at {p:?}: {g:?} against {want:?}");
        }
        // 5 mm above the top face, over its interior: the value on the face below.
        let above = organ.surface_displacement_at(&u, &[[0.015, 0.007, 0.015]]).unwrap()[0];
        let below = field([0.015, 0.007, 0.01]);
        assert!((0..3).all(|d| (above[d] - below[d]).abs() < 1e-12), "{above:?} against {below:?}");
    }

    /// Landmarks on the surface or inside pass; one far outside is refused by name and distance; the same
    /// landmarks 1,000 times too small (metres read as millimetres, all at the box's corner) or
    /// with x and y negated (LPS for RAS) are refused with the likely mistake.
    #[test]
    fn landmarks_outside_the_organ_are_refused_with_the_likely_mistake() {
        let (organ, _) = box_organ();
        let on = vec![[0.0, 0.01, 0.005], [0.04, 0.012, 0.005], [0.02, 0.02, 0.004], [0.02, 0.01, 0.005]];
        assert_eq!(organ.check_landmarks(&on, &[]).unwrap(), Vec::<String>::new());
        let refused = |points: &[Point]| organ.check_landmarks(points, &[]).unwrap_err().to_string();
        let mut far = on.clone();
        far.push([0.02, 0.01, 0.05]);
        let error = refused(&far);
        assert!(error.starts_with("landmark 5 at (20, 10, 50) mm lies 40.0 mm outside the organ"), "{error}");
        // Labelled (3D Slicer's markups), by its label too.
        let labels = ["", "", "", "", "left triangular"].map(String::from);
        let error = organ.check_landmarks(&far, &labels).unwrap_err().to_string();
        assert!(error.starts_with("landmark 5 (`left triangular`) at (20, 10, 50) mm lies 40.0 mm"), "{error}");
        let small: Vec<Point> = on.iter().map(|p| p.map(|x| x * 1e-3)).collect();
        assert!(refused(&small).ends_with("were they given in m where mm were expected?"), "{}", refused(&small));
        let negated: Vec<Point> = on.iter().map(|p| [-p[0], -p[1], p[2]]).collect();
        assert!(refused(&negated).contains("with x and y negated every landmark lies on the organ"));
        // Millimetres against an organ in cm taken as mm: 10 times too large.
        let large: Vec<Point> = on.iter().map(|p| p.map(|x| x * 10.0)).collect();
        assert!(refused(&large).contains("read as 10 times smaller, every landmark"), "{}", refused(&large));
    }

    /// A point inside is located in its element; one 2 mm above the top face follows the face's
    /// point below it when the tolerance allows 3 mm, and is refused, with its distance, when it
    /// allows 1 mm.
    #[test]
    fn a_point_just_outside_follows_the_nearest_surface_point_within_the_tolerance() {
        let (organ, u) = box_organ();
        let (inside, above) = ([0.013, 0.011, 0.004], [0.013, 0.011, 0.012]);
        let located = organ.locate_near(&[inside, above], 0.003, "target").unwrap();
        assert_eq!(located[0].1, 0.0);
        assert!((located[1].1 - 0.002).abs() < 1e-12, "{}", located[1].1);
        for ((stencil, _), at) in located.iter().zip([inside, [0.013, 0.011, 0.01]]) {
            let (got, want) = (stencil.vector(&u), field(at));
            assert!((0..3).all(|d| (got[d] - want[d]).abs() < 1e-12), "{got:?} against {want:?}");
        }
        let error = organ.locate_near(&[inside, above], 0.001, "target").unwrap_err().to_string();
        assert!(error.contains("target 2") && error.contains("2.00 mm outside"), "{error}");
    }
}
