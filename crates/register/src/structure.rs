//! Structures inside the organ that the surgeon cannot see (a tumour, vessels), as surfaces that
//! move with the registered organ: [`Structure`].

use mesh::length::mm;
use mesh::{Point, TriSurface};

use crate::organ::{likely_mistake, moved_surface, Stencil, LANDMARK_REACH};
use crate::{Organ, RegisterError, Result, RigidResult};

/// A surface embedded in the organ (in m, in the organ's frame, at rest): each vertex inside the
/// organ moves as the organ's element that holds it; one outside (a vessel leaving the organ)
/// moves as the organ's nearest surface point.
#[derive(Clone, Debug)]
pub struct Structure {
    name: String,
    rest: TriSurface,
    stencils: Vec<Stencil>,
}

impl Structure {
    /// `surface`, named `name`, embedded in `organ`, with warnings (vertices outside the organ).
    /// An error for a vertex that is not finite, or for a surface most of which lies outside the
    /// organ by more than [`LANDMARK_REACH`] of its extent (naming the likely mistake: another
    /// unit, the other frame).
    pub fn new(organ: &Organ, name: &str, surface: TriSurface) -> Result<(Structure, Vec<String>)> {
        Structure::embed(organ, name, surface, true)
    }

    /// [`Structure::new`] for a surface known to be in the organ's frame (read from the organ's
    /// own labelmap, or from a file naming the frame the organ's names): one outside the organ is
    /// refused without the other of LPS and RAS suggested.
    pub fn in_organ_frame(organ: &Organ, name: &str, surface: TriSurface) -> Result<(Structure, Vec<String>)> {
        Structure::embed(organ, name, surface, false)
    }

    /// [`Structure::new`]; `frames_may_differ`: whether a surface outside the organ may be in the
    /// other of LPS and RAS, to be suggested.
    fn embed(
        organ: &Organ,
        name: &str,
        surface: TriSurface,
        frames_may_differ: bool,
    ) -> Result<(Structure, Vec<String>)> {
        if let Some((i, fault)) = mesh::measured_fault(&surface.vertices) {
            return Err(RegisterError::Invalid(format!("`{name}`: vertex {} {fault}", i + 1)));
        }
        if surface.triangles.is_empty() {
            return Err(RegisterError::Invalid(format!("`{name}`: a surface without triangles")));
        }
        let reach = LANDMARK_REACH * organ.extent();
        let held = |points: &[Point]| organ.locate_near(points, f64::INFINITY, "vertex");
        let mostly_near =
            |located: &[(Stencil, f64)]| 2 * located.iter().filter(|l| l.1 <= reach).count() > located.len();
        let located = held(&surface.vertices)?;
        // Only where a mistake is suspected are the vertices located again, moved as it would have them.
        let mostly_inside = |points: &[Point]| held(points).is_ok_and(|moved| mostly_near(&moved));
        if !mostly_near(&located) {
            return Err(RegisterError::Invalid(format!(
                "`{name}` lies outside the organ: most of its vertices are farther than {:.0} mm from it{}",
                mm(reach),
                likely_mistake(
                    &surface.vertices,
                    &organ.mesh().nodes,
                    "it lies in the organ",
                    frames_may_differ,
                    mostly_inside
                )
            )));
        }
        // A structure shrunk 1,000 times (in m where mm were expected) lies in the organ as a speck; a
        // small one in its unit (a vessel's branch) is not doubted.
        let what = format!("vertices of `{name}`");
        if let Some((shrunk, true)) = organ.spread_warning(&surface.vertices, &what, mostly_inside) {
            return Err(RegisterError::Invalid(shrunk));
        }
        let outside: Vec<f64> = located.iter().map(|l| l.1).filter(|&d| d > 0.0).collect();
        // Wholly outside yet near: most likely segmented apart from the organ (a tumour on its
        // capsule, taken out of the organ's label), which the organ then does not hold.
        let apart = match outside.len() == located.len() {
            true => {
                "; segmented apart from the organ? the organ's mesh holds it only when the organ's segment does \
                     (a labelmap's organ and structure together: `--label ORGAN+STRUCTURE`)"
            }
            false => "",
        };
        let warnings = match outside.iter().copied().reduce(f64::max) {
            Some(farthest) => vec![format!(
                "`{name}`: {} of its {} vertices lie outside the organ (up to {:.1} mm): they move as the organ's \
                 nearest surface point{apart}",
                outside.len(),
                located.len(),
                mm(farthest)
            )],
            None => Vec::new(),
        };
        let stencils = located.into_iter().map(|l| l.0).collect();
        Ok((Structure { name: name.to_string(), rest: surface, stencils }, warnings))
    }

    /// Its name (a file's stem: `tumour`, `portal_vein`).
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The surface at rest (m, the organ's frame).
    pub fn rest(&self) -> &TriSurface {
        &self.rest
    }

    /// The surface moved by the organ's displacement `u`, in the cloud's frame (moved by the
    /// rigid alignment, if any).
    pub fn deformed(&self, u: &[f64], rigid: Option<&RigidResult>) -> TriSurface {
        moved_surface(&self.rest, &self.stencils, u, rigid)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use mesh::generate::icosphere;
    use mesh::norm;

    fn cube() -> Organ {
        Organ::new(mesh::box_tet([0.0; 3], [0.04; 3], [4, 4, 4]).unwrap(), None).unwrap()
    }

    /// A ball inside a cube that the registration stretches moves as the cube does; a vessel
    /// leaving it is warned about and follows its surface; a ball given in mm is refused, naming
    /// the unit; one beside the cube is refused naming none.
    #[test]
    fn a_structure_moves_with_the_organ_and_one_outside_it_is_named() {
        let organ = cube();
        let mut ball = icosphere(0.008, 2);
        ball.transform([-0.02; 3], 1.0);
        let (tumour, warnings) = Structure::new(&organ, "tumour", ball.clone()).unwrap();
        assert!(warnings.is_empty(), "{warnings:?}");
        let stretch: Vec<f64> = organ.mesh().nodes.iter().flat_map(|p| [0.1 * p[0], 0.0, -0.05 * p[2]]).collect();
        let moved = tumour.deformed(&stretch, None);
        let worst = moved
            .vertices
            .iter()
            .zip(&ball.vertices)
            .map(|(m, p)| norm([m[0] - 1.1 * p[0], m[1] - p[1], m[2] - 0.95 * p[2]]))
            .fold(0.0, f64::max);
        assert!(worst < 1e-12, "{worst}");
        // A surface reaching 5 mm out of the cube: warned, its outer vertices moving with the surface.
        let mut vessel = icosphere(0.01, 2);
        vessel.transform([-0.035, -0.02, -0.02], 1.0);
        let out = 1e3 * (vessel.vertices.iter().map(|p| p[0]).fold(0.0, f64::max) - 0.04);
        let (_, warnings) = Structure::new(&organ, "vessel", vessel).unwrap();
        assert!(
            warnings[0].starts_with("`vessel`: ") && warnings[0].contains(&format!("(up to {out:.1} mm)")),
            "{warnings:?}"
        );
        let mut in_mm = ball.clone();
        in_mm.vertices.iter_mut().for_each(|p| *p = p.map(|x| x * 1e3));
        let e = Structure::new(&organ, "tumour", in_mm).unwrap_err().to_string();
        assert!(
            e.contains("`tumour` lies outside the organ") && e.contains("given in mm where m were expected"),
            "{e}"
        );
        // Beside the cube (another organ of the same labelmap): outside, in the right unit, though
        // read 10 times smaller it would lie at the cube's corner, which holds the origin.
        let mut beside = ball.clone();
        beside.transform([0.0, 0.035, 0.035], 1.0);
        let e = Structure::new(&organ, "kidney", beside).unwrap_err().to_string();
        assert!(e.contains("`kidney` lies outside the organ") && !e.contains("times"), "{e}");
    }

    /// A structure in metres read as millimetres, a speck in the organ, is refused naming the unit;
    /// a small one in the organ's unit is kept.
    #[test]
    fn a_structure_shrunk_by_a_unit_mistake_is_refused() {
        let organ = cube();
        let mut tumour = icosphere(0.008, 2);
        tumour.transform([-0.02; 3], 1.0);
        let mut speck = tumour.clone();
        speck.vertices.iter_mut().for_each(|p| *p = p.map(|x| x * 1e-3));
        let e = Structure::new(&organ, "tumour", speck).map(|_| ()).unwrap_err().to_string();
        assert!(e.contains("vertices of `tumour` span") && e.ends_with("given in m where mm were expected?"), "{e}");
        let mut small = icosphere(0.0002, 2);
        small.transform([-0.02; 3], 1.0);
        assert!(Structure::new(&organ, "branch", small).is_ok(), "a 0.4 mm structure in the organ's unit");
    }

    /// A structure outside the organ that x and y negated would put in it: the other frame is
    /// suggested where the frames may differ, not where the structure is in the organ's.
    #[test]
    fn the_other_frame_is_suggested_only_where_the_frames_may_differ() {
        let organ = cube();
        let mut mirrored = icosphere(0.008, 2);
        mirrored.transform([0.02, 0.02, -0.02], 1.0);
        let e = Structure::new(&organ, "tumour", mirrored.clone()).unwrap_err().to_string();
        assert!(e.contains("(with x and y negated it lies in the organ: are they in LPS"), "{e}");
        let e = Structure::in_organ_frame(&organ, "tumour", mirrored).unwrap_err().to_string();
        assert!(e.contains("`tumour` lies outside the organ") && !e.contains("negated"), "{e}");
    }
}
