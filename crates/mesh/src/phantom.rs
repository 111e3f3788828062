//! A procedural liver phantom: the default organ of every command.
//!
//! The shape is the smooth union of two ellipsoids, a thick right lobe and a
//! thin left lobe, about 0.2 m long along x, 0.14 m deep along y and 0.09 m
//! thick along z. Coordinates: x from the left lobe (−x) to the right lobe
//! (+x); z points towards the camera, which looks along −z by default
//! ([`PhantomSpec::view_direction`]): the top (+z) is the visible anterior
//! surface, the underside (−z) the hidden visceral one.
//!
//! Named regions (node sets), all chosen geometrically so that they scale
//! with the resolution:
//! - `fixed`: every node within [`PhantomSpec::fixed`]`.radius` of the
//!   underside point between the lobes (the attachment of the liver);
//!   about 67 nodes at 5,000 tetrahedra;
//! - `hidden`: boundary nodes facing away from the camera (outward normal ·
//!   view direction > 0) within the `hidden` patch on the underside of the
//!   right lobe: the region Σ for spring attachments; about 35 nodes on a
//!   300-node liver;
//! - `visible`: boundary nodes facing the camera (outward normal · view
//!   direction < 0);
//! - `push`: visible boundary nodes within the `push` patch on top of the
//!   left lobe, where loads are applied;
//! - `markers`: [`PhantomSpec::markers`] interior nodes spread through the
//!   volume (farthest-point sampling among interior nodes at least
//!   `marker_depth` below the surface, from the node nearest their centroid);
//! - `tumour`: interior nodes within [`PhantomSpec::tumour_radius`] of
//!   [`PhantomSpec::tumour_centre`] (at least the 4 nearest).
//!
//! Everything is deterministic: the same spec and target give the same mesh.

use std::collections::BTreeMap;

use rayon::prelude::*;

use crate::immersed::{immersed_grid, ImmersedGrid, ImmersedOptions};
use crate::select::{farthest_points, k_nearest};
use crate::tetmesh::{segment_root, stuff_to_count, BoundaryFit, ImplicitDomain};
use crate::{dot, sub, Mesh, MeshError, Point};

/// An axis-aligned ellipsoid.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ellipsoid {
    /// Centre (m).
    pub centre: Point,
    /// Semi-axes along x, y, z (m).
    pub radii: Point,
}

impl Ellipsoid {
    /// Approximate signed distance (exact on the surface and at first order
    /// near it): k0 (k0 − 1) / k1 with k0 = |q / r|, k1 = |q / r²|.
    pub fn value(&self, p: Point) -> f64 {
        let q = sub(p, self.centre);
        let k0 = (0..3).map(|d| (q[d] / self.radii[d]).powi(2)).sum::<f64>().sqrt();
        let k1 = (0..3).map(|d| (q[d] / (self.radii[d] * self.radii[d])).powi(2)).sum::<f64>().sqrt();
        if k1 == 0.0 {
            -self.radii.iter().cloned().fold(f64::INFINITY, f64::min)
        } else {
            k0 * (k0 - 1.0) / k1
        }
    }
}

/// A patch of the surface: the boundary point met going from `from` (an
/// interior point) along `direction`, and a radius around it.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SurfacePatch {
    /// An interior starting point (m).
    pub from: Point,
    /// Direction of the search (need not be normalised).
    pub direction: Point,
    /// Radius of the patch around the boundary point (m).
    pub radius: f64,
}

/// Geometry and region definitions of the liver phantom. `Default` is the
/// reference phantom.
#[derive(Clone, Debug, PartialEq)]
pub struct PhantomSpec {
    /// The right lobe (+x): centre (0.035, 0, 0), semi-axes (0.065, 0.07, 0.045).
    pub right_lobe: Ellipsoid,
    /// The left lobe (−x): centre (−0.045, 0.005, 0.005), semi-axes (0.055, 0.05, 0.026).
    pub left_lobe: Ellipsoid,
    /// Smooth-union blending width (m): 0.03.
    pub blend: f64,
    /// Camera viewing direction (unit): (0, 0, −1), looking down at the top.
    pub view_direction: Point,
    /// The fixed attachment: from (−0.015, 0, 0) down (−z), radius 0.0315 m.
    pub fixed: SurfacePatch,
    /// The hidden region Σ: from (0.05, 0, 0) down (−z), radius 0.058 m.
    pub hidden: SurfacePatch,
    /// The push patch: from (−0.06, 0.005, 0) up (+z), radius 0.02 m.
    pub push: SurfacePatch,
    /// Centre of the tumour (m): (0.05, −0.015, 0), inside the right lobe.
    pub tumour_centre: Point,
    /// Radius of the tumour (m): 0.012.
    pub tumour_radius: f64,
    /// Number of internal markers: 10.
    pub markers: usize,
    /// Least depth of a marker below the surface (m): 0.01.
    pub marker_depth: f64,
    /// Placement of the boundary nodes of the T4 mesh: volume preserving.
    pub fit: BoundaryFit,
}

impl Default for PhantomSpec {
    fn default() -> Self {
        PhantomSpec {
            right_lobe: Ellipsoid { centre: [0.035, 0.0, 0.0], radii: [0.065, 0.07, 0.045] },
            left_lobe: Ellipsoid { centre: [-0.045, 0.005, 0.005], radii: [0.055, 0.05, 0.026] },
            blend: 0.03,
            view_direction: [0.0, 0.0, -1.0],
            fixed: SurfacePatch { from: [-0.015, 0.0, 0.0], direction: [0.0, 0.0, -1.0], radius: 0.0315 },
            hidden: SurfacePatch { from: [0.05, 0.0, 0.0], direction: [0.0, 0.0, -1.0], radius: 0.058 },
            push: SurfacePatch { from: [-0.06, 0.005, 0.0], direction: [0.0, 0.0, 1.0], radius: 0.02 },
            tumour_centre: [0.05, -0.015, 0.0],
            tumour_radius: 0.012,
            markers: 10,
            marker_depth: 0.01,
            fit: BoundaryFit::VolumePreserving,
        }
    }
}

/// The reference liver phantom meshed with about `target_tets` tetrahedra
/// (at least 100), with its named regions. Same call, same mesh.
pub fn liver_phantom(target_tets: usize) -> Result<Mesh, MeshError> {
    PhantomSpec::default().mesh(target_tets)
}

/// Polynomial smooth minimum of width k.
fn smooth_min(a: f64, b: f64, k: f64) -> f64 {
    if k <= 0.0 {
        return a.min(b);
    }
    let h = (k - (a - b).abs()).max(0.0) / k;
    a.min(b) - 0.25 * h * h * k
}

impl ImplicitDomain for PhantomSpec {
    fn value(&self, p: Point) -> f64 {
        self.signed_distance(p)
    }
    fn bounds(&self) -> (Point, Point) {
        let m = 0.25 * self.blend + 1e-3;
        let lo = std::array::from_fn(|d| {
            (self.right_lobe.centre[d] - self.right_lobe.radii[d])
                .min(self.left_lobe.centre[d] - self.left_lobe.radii[d])
                - m
        });
        let hi = std::array::from_fn(|d| {
            (self.right_lobe.centre[d] + self.right_lobe.radii[d])
                .max(self.left_lobe.centre[d] + self.left_lobe.radii[d])
                + m
        });
        (lo, hi)
    }
}

impl PhantomSpec {
    /// The phantom's (approximate) signed distance: negative inside; exact on
    /// the surface, a distance to first order near it.
    pub fn signed_distance(&self, p: Point) -> f64 {
        smooth_min(self.right_lobe.value(p), self.left_lobe.value(p), self.blend)
    }

    /// Outward unit normal (normalised gradient of the signed distance, by
    /// central differences).
    pub fn normal(&self, p: Point) -> Point {
        let e = 1e-6;
        let g: Point = std::array::from_fn(|d| {
            let (mut a, mut b) = (p, p);
            a[d] += e;
            b[d] -= e;
            (self.signed_distance(a) - self.signed_distance(b)) / (2.0 * e)
        });
        let len = dot(g, g).sqrt();
        if len > 0.0 {
            g.map(|c| c / len)
        } else {
            g
        }
    }

    /// The boundary point of a patch: the first crossing from `from` along
    /// `direction` (searched up to the size of the bounding box).
    pub fn patch_centre(&self, patch: &SurfacePatch) -> Result<Point, MeshError> {
        let dir = patch.direction;
        let len = dot(dir, dir).sqrt();
        let f0 = self.signed_distance(patch.from);
        if !(len > 0.0) || !(f0 < 0.0) {
            return Err(MeshError::Invalid(format!(
                "phantom patch {patch:?}: `from` must be inside and `direction` non-zero"
            )));
        }
        let (lo, hi) = self.bounds();
        let reach = dot(sub(hi, lo), sub(hi, lo)).sqrt();
        let steps = 400;
        let at = |t: f64| -> Point { std::array::from_fn(|d| patch.from[d] + t * reach * dir[d] / len) };
        let mut prev = (0.0, f0);
        for s in 1..=steps {
            let t = s as f64 / steps as f64;
            let f = self.signed_distance(at(t));
            if f >= 0.0 {
                return Ok(segment_root(|p| self.signed_distance(p), at(prev.0), prev.1, at(t), f));
            }
            prev = (t, f);
        }
        Err(MeshError::Invalid(format!("phantom patch {patch:?} never reaches the surface")))
    }

    /// Volume of the phantom (m³), integrated on a grid of spacing length/200
    /// with a linear ramp of the signed distance across each sample (it
    /// differs from the integral at length/320 by 5e-5 relative); summed in a
    /// fixed order, so reproducible to the last bit.
    pub fn volume(&self) -> f64 {
        let (lo, hi) = self.bounds();
        let dx = crate::longest_side((lo, hi)) / 200.0;
        let n: [usize; 3] = std::array::from_fn(|d| ((hi[d] - lo[d]) / dx).ceil() as usize + 1);
        (0..n[2])
            .into_par_iter()
            .map(|k| {
                let mut s = 0.0;
                for j in 0..n[1] {
                    for i in 0..n[0] {
                        let p = [
                            lo[0] + (i as f64 + 0.5) * dx,
                            lo[1] + (j as f64 + 0.5) * dx,
                            lo[2] + (k as f64 + 0.5) * dx,
                        ];
                        s += (0.5 - self.signed_distance(p) / dx).clamp(0.0, 1.0);
                    }
                }
                s
            })
            .collect::<Vec<f64>>()
            .iter()
            .sum::<f64>()
            * dx
            * dx
            * dx
    }

    /// The phantom meshed with about `target_tets` tetrahedra (at least 100)
    /// by isosurface stuffing, with the named regions.
    pub fn mesh(&self, target_tets: usize) -> Result<Mesh, MeshError> {
        if target_tets < 100 {
            return Err(MeshError::Invalid(format!("the phantom needs at least 100 tetrahedra, asked {target_tets}")));
        }
        let mut mesh = stuff_to_count(self, target_tets, None, self.fit)?;
        self.attach_t4_regions(&mut mesh)?;
        Ok(mesh)
    }

    fn attach_t4_regions(&self, mesh: &mut Mesh) -> Result<(), MeshError> {
        if !matches!(mesh.cells, crate::Cells::Tet4(_)) {
            return Err(MeshError::Invalid("phantom regions: expected a T4 mesh".into()));
        }
        let surface = crate::boundary_surface(mesh);
        let normals = surface.vertex_normals();
        let mut on_surface = vec![false; mesh.num_nodes()];
        for t in &surface.triangles {
            for &k in t {
                on_surface[k] = true;
            }
        }
        mesh.regions = self.regions(&mesh.nodes, &on_surface, &normals)?;
        Ok(())
    }

    /// The phantom as an immersed-boundary hex grid of cubic cells of side
    /// `spacing` (m), with volume fractions and the named regions. On the grid
    /// the surface nodes are the nodes of cells partly inside the organ
    /// (0 < fraction < 1) and their normals the phantom's normal at the node.
    pub fn immersed(&self, spacing: f64) -> Result<ImmersedGrid, MeshError> {
        self.immersed_with(&ImmersedOptions::with_spacing(spacing))
    }

    /// [`PhantomSpec::immersed`] with any grid options (e.g. a minimum cell fraction).
    pub fn immersed_with(&self, options: &ImmersedOptions) -> Result<ImmersedGrid, MeshError> {
        let mut grid = immersed_grid(self, options)?;
        let mesh = &grid.mesh;
        let mut on_surface = vec![false; mesh.num_nodes()];
        mesh.surface_nodes().into_iter().for_each(|k| on_surface[k] = true);
        let normals: Vec<Point> = mesh.nodes.par_iter().map(|&p| self.normal(p)).collect();
        grid.mesh.regions = self.regions(&mesh.nodes, &on_surface, &normals)?;
        grid.mesh.node_normals = Some(normals);
        Ok(grid)
    }

    /// The ball of space behind a named region, for attachments and loads that stay the same
    /// on every mesh ([`crate::Ball`]): `fixed` (the attachment), `hidden` (Σ) and `push` (the
    /// tool's patch; with `hidden` and `push` only the boundary facing away from, or towards,
    /// the camera belongs to the region: see [`PhantomSpec::view_direction`]).
    pub fn region_ball(&self, name: &str) -> Result<crate::Ball, MeshError> {
        let patch = match name {
            "fixed" => &self.fixed,
            "hidden" => &self.hidden,
            "push" => &self.push,
            other => {
                return Err(MeshError::Invalid(format!(
                    "the phantom has no ball behind region '{other}' (fixed, hidden, push)"
                )))
            }
        };
        Ok(crate::Ball { centre: self.patch_centre(patch)?, radius: patch.radius })
    }

    /// The named regions for nodes `nodes`, given which nodes are on the
    /// surface and their outward normals (see the module documentation).
    pub fn regions(
        &self,
        nodes: &[Point],
        on_surface: &[bool],
        normals: &[Point],
    ) -> Result<BTreeMap<String, Vec<usize>>, MeshError> {
        let view = self.view_direction;
        let within = |c: Point, r: f64, p: Point| dot(sub(p, c), sub(p, c)) <= r * r;
        let facing = |k: usize| dot(normals[k], view);
        let fixed_c = self.patch_centre(&self.fixed)?;
        let hidden_c = self.patch_centre(&self.hidden)?;
        let push_c = self.patch_centre(&self.push)?;
        let all = 0..nodes.len();
        let fixed: Vec<usize> = all.clone().filter(|&k| within(fixed_c, self.fixed.radius, nodes[k])).collect();
        let hidden: Vec<usize> = all
            .clone()
            .filter(|&k| on_surface[k] && facing(k) > 0.0 && within(hidden_c, self.hidden.radius, nodes[k]))
            .collect();
        let visible: Vec<usize> = all.clone().filter(|&k| on_surface[k] && facing(k) < 0.0).collect();
        let push: Vec<usize> = all
            .clone()
            .filter(|&k| on_surface[k] && facing(k) < 0.0 && within(push_c, self.push.radius, nodes[k]))
            .collect();
        let interior: Vec<usize> =
            all.clone().filter(|&k| !on_surface[k] && self.signed_distance(nodes[k]) < 0.0).collect();
        let deep: Vec<usize> =
            interior.iter().copied().filter(|&k| self.signed_distance(nodes[k]) < -self.marker_depth).collect();
        let candidates = if deep.len() >= self.markers { deep } else { interior.clone() };
        let mut markers = farthest_points(nodes, &candidates, self.markers);
        markers.sort_unstable();
        let mut tumour: Vec<usize> =
            interior.iter().copied().filter(|&k| within(self.tumour_centre, self.tumour_radius, nodes[k])).collect();
        if tumour.len() < 4 {
            tumour = k_nearest(nodes, interior.iter().copied(), self.tumour_centre, 4);
            tumour.sort_unstable();
        }
        let mut regions = BTreeMap::new();
        for (name, set) in [
            ("fixed", fixed),
            ("hidden", hidden),
            ("visible", visible),
            ("push", push),
            ("markers", markers),
            ("tumour", tumour),
        ] {
            if set.is_empty() {
                return Err(MeshError::Invalid(format!(
                    "phantom region '{name}' is empty: the mesh is too coarse ({} nodes)",
                    nodes.len()
                )));
            }
            regions.insert(name.to_string(), set);
        }
        Ok(regions)
    }
}
