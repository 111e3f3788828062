//! The preoperative organ: a volumetric mesh and its surface embedded in it.

use mesh::bvh::{triangle_barycentric, SurfaceBvh};
use mesh::embedding::MeshLocator;
use mesh::{Mesh, Point, TriSurface};

use crate::{RegisterError, Result};

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
        Ok(Organ { mesh, surface, stencils, locator })
    }

    /// The volumetric mesh.
    pub fn mesh(&self) -> &Mesh {
        &self.mesh
    }

    /// The surface at rest.
    pub fn surface(&self) -> &TriSurface {
        &self.surface
    }

    /// Where each surface vertex takes its displacement from.
    pub fn surface_stencils(&self) -> &[Stencil] {
        &self.stencils
    }

    /// The surface moved by the nodal displacement `u` (3 per mesh node).
    pub fn deformed_surface(&self, u: &[f64]) -> TriSurface {
        TriSurface {
            vertices: displaced(&self.surface.vertices, &self.stencils, u),
            triangles: self.surface.triangles.clone(),
        }
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
        let bvh = SurfaceBvh::new(&self.surface)?;
        Ok(points.iter().map(|&p| self.nearest_surface_stencil(&bvh, p).0.vector(u)).collect())
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
        let bvh = SurfaceBvh::new(&self.surface)?;
        points
            .iter()
            .enumerate()
            .map(|(i, &p)| {
                if let Some(location) = self.locator.locate(p) {
                    return Ok((Stencil::of(&location), 0.0));
                }
                let (stencil, distance) = self.nearest_surface_stencil(&bvh, p);
                if !(distance <= tolerance) {
                    return Err(RegisterError::Invalid(format!(
                        "{what} {i} at {p:?} lies {:.2} mm outside the organ mesh",
                        distance * 1e3
                    )));
                }
                Ok((stencil, distance))
            })
            .collect()
    }

    /// Stencils of points inside the organ (e.g. targets); a point outside, or not finite, is an
    /// error naming it.
    pub fn locate(&self, points: &[Point], what: &str) -> Result<Vec<Stencil>> {
        if let Some((i, fault)) = mesh::measured_fault(points) {
            return Err(RegisterError::Invalid(format!("{what} {i} {fault}")));
        }
        points
            .iter()
            .enumerate()
            .map(|(i, &p)| {
                self.locator
                    .locate(p)
                    .map(|l| Stencil::of(&l))
                    .ok_or_else(|| RegisterError::Invalid(format!("{what} {i} at {p:?} is outside the organ mesh")))
            })
            .collect()
    }
}

/// The share of the organ's extent below which a set of several targets is suspected of a unit
/// mistake (metres read as millimetres shrink it 1,000 times).
pub const SMALL_TARGET_EXTENT: f64 = 0.01;

impl Organ {
    /// Stencils of the targets in the organ, and warnings about them. A target outside the organ
    /// is an error, which names the likely mistake when every target lies inside with x and y
    /// negated (a frame mix-up, RAS and LPS), or read 1,000 times smaller or larger (a unit
    /// mistake) and spread over at least [`SMALL_TARGET_EXTENT`] of the organ (points merely
    /// shrunk onto an organ around the origin tell nothing); a set of targets whose extent is
    /// under [`SMALL_TARGET_EXTENT`] of the organ's is warned about.
    pub fn locate_targets(&self, targets: &[Point]) -> Result<(Vec<Stencil>, Vec<String>)> {
        let organ = self;
        let (organ_extent, extent) = (diagonal(&organ.mesh().nodes), diagonal(targets));
        let inside = |moved: Vec<Point>| organ.locate(&moved, "target").is_ok();
        let fits = |scale: f64| {
            let spread = targets.len() < 2 || scale * extent >= SMALL_TARGET_EXTENT * organ_extent;
            spread && inside(targets.iter().map(|p| p.map(|x| x * scale)).collect())
        };
        let stencils = match organ.locate(targets, "target") {
            Ok(s) => s,
            Err(e) => {
                let hint = if inside(targets.iter().map(|p| [-p[0], -p[1], p[2]]).collect()) {
                    " (with x and y negated every target lies inside: are they in LPS where the organ is in RAS, \
                     or the reverse?)"
                } else if fits(1e-3) {
                    " (read as 1,000 times smaller, every target lies inside: were they given in mm where m were expected?)"
                } else if fits(1e3) {
                    " (read as 1,000 times larger, every target lies inside: were they given in m where mm were expected?)"
                } else {
                    ""
                };
                return Err(RegisterError::Invalid(format!("{e}{hint}")));
            }
        };
        let mut warnings = Vec::new();
        if targets.len() > 1 && extent < SMALL_TARGET_EXTENT * organ_extent {
            warnings.push(format!(
                "the {} targets span {:.3} mm, under {:.0} % of the organ's {:.0} mm{}",
                targets.len(),
                extent * 1e3,
                SMALL_TARGET_EXTENT * 100.0,
                organ_extent * 1e3,
                if fits(1e3) { ": were they given in m where mm were expected?" } else { "" }
            ));
        }
        Ok((stencils, warnings))
    }
}

/// The diagonal of the bounding box of `points`.
fn diagonal(points: &[Point]) -> f64 {
    let (lo, hi) = mesh::bounds(points);
    mesh::norm(mesh::sub(hi, lo))
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
        assert!(error.contains("target 1") && error.contains("2.00 mm outside"), "{error}");
    }
}
