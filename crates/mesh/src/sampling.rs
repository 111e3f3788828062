//! Random points on the part of a surface that a camera sees.
//!
//! A triangle is *visible* from a camera looking along `view_direction`
//! when its outward normal n faces the camera: n · view_direction < 0
//! (back-face culling; occlusion by other parts of the organ is not
//! considered). Points are drawn uniformly by area over the visible
//! triangles with a seeded [`StdRng`], so the same seed gives the same
//! points. Each sample carries its triangle and barycentric coordinates, so
//! any nodal field can be interpolated there.

use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

use crate::surface::triangle_area_vector;
use crate::{dot, Mesh, MeshError, Point, TriSurface};

/// A point on a surface triangle.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfaceSample {
    /// Position (m).
    pub point: Point,
    /// Index of the triangle in the surface.
    pub triangle: usize,
    /// The triangle's vertices (mesh node indices for a mesh boundary).
    pub nodes: [usize; 3],
    /// Barycentric coordinates of the point (sum 1).
    pub barycentric: [f64; 3],
}

/// Indices of the triangles facing a camera that looks along
/// `view_direction` (outward normal · direction < 0).
fn visible_triangles(surface: &TriSurface, view_direction: Point) -> Vec<usize> {
    (0..surface.triangles.len()).filter(|&t| dot(triangle_area_vector(surface, t), view_direction) < 0.0).collect()
}

/// `count` points drawn uniformly by area on the visible triangles of
/// `surface` (outward oriented), reproducibly from `seed`.
pub fn sample_visible(
    surface: &TriSurface,
    view_direction: Point,
    count: usize,
    seed: u64,
) -> Result<Vec<SurfaceSample>, MeshError> {
    let len = dot(view_direction, view_direction).sqrt();
    if !(len > 0.0 && len.is_finite()) {
        return Err(MeshError::Invalid(format!("view direction {view_direction:?} must be non-zero and finite")));
    }
    let nv = surface.vertices.len();
    if let Some((t, _)) = surface.triangles.iter().enumerate().find(|(_, tri)| tri.iter().any(|&k| k >= nv)) {
        return Err(MeshError::Invalid(format!("triangle {t} refers to a vertex beyond the {nv} vertices")));
    }
    let visible = visible_triangles(surface, view_direction);
    let mut cumulative = Vec::with_capacity(visible.len());
    let mut total = 0.0;
    for &t in &visible {
        let a = triangle_area_vector(surface, t);
        total += dot(a, a).sqrt();
        cumulative.push(total);
    }
    if !(total > 0.0) {
        return Err(MeshError::Invalid(format!(
            "no surface is visible along {view_direction:?}: is the surface outward oriented?"
        )));
    }
    let mut rng = StdRng::seed_from_u64(seed);
    let mut out = Vec::with_capacity(count);
    for _ in 0..count {
        let u: f64 = rng.random::<f64>() * total;
        let i = cumulative.partition_point(|&c| c <= u).min(visible.len() - 1);
        let t = visible[i];
        let (mut r1, mut r2): (f64, f64) = (rng.random(), rng.random());
        if r1 + r2 > 1.0 {
            r1 = 1.0 - r1;
            r2 = 1.0 - r2;
        }
        let barycentric = [1.0 - r1 - r2, r1, r2];
        let nodes = surface.triangles[t];
        let p = nodes.map(|k| surface.vertices[k]);
        let point =
            std::array::from_fn(|d| barycentric[0] * p[0][d] + barycentric[1] * p[1][d] + barycentric[2] * p[2][d]);
        out.push(SurfaceSample { point, triangle: t, nodes, barycentric });
    }
    Ok(out)
}

/// [`sample_visible`] on the boundary of a volume mesh
/// ([`crate::boundary_surface`]: triangle indices refer to it, node indices
/// to the mesh).
pub fn sample_visible_boundary(
    mesh: &Mesh,
    view_direction: Point,
    count: usize,
    seed: u64,
) -> Result<Vec<SurfaceSample>, MeshError> {
    sample_visible(&crate::boundary_surface(mesh), view_direction, count, seed)
}

/// A node-major field (`channels` per node) interpolated at the samples;
/// point-major result (`out[s·C + c]`).
pub fn interpolate_samples(samples: &[SurfaceSample], field: &[f64], channels: usize) -> Result<Vec<f64>, MeshError> {
    if channels == 0 || !field.len().is_multiple_of(channels) {
        return Err(MeshError::Invalid(format!("field of {} values is not {channels} channels per node", field.len())));
    }
    let n = field.len() / channels;
    let mut out = Vec::with_capacity(samples.len() * channels);
    for (s, smp) in samples.iter().enumerate() {
        if let Some(&bad) = smp.nodes.iter().find(|&&k| k >= n) {
            return Err(MeshError::Invalid(format!("sample {s} uses node {bad}, but the field has {n} nodes")));
        }
        for c in 0..channels {
            out.push((0..3).map(|i| smp.barycentric[i] * field[smp.nodes[i] * channels + c]).sum());
        }
    }
    Ok(out)
}
