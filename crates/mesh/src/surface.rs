//! Checks and measures of closed triangle surfaces.
//!
//! A surface that bounds a volume must be a closed 2-manifold: every edge is
//! shared by exactly two triangles that traverse it in opposite directions,
//! every vertex is surrounded by a single fan of triangles, and no triangle is
//! degenerate. [`check_closed_manifold`] verifies this and says what is wrong
//! and where. The enclosed volume follows from the divergence theorem; it is
//! positive when the triangles are counter-clockwise seen from outside.

use std::collections::HashMap;

use rayon::prelude::*;

use crate::{bounds, cross, dot, sub, unit, MeshError, Point, TriSurface};

/// Triangles per parallel task of [`TriSurface::corner_normals`].
const CORNERS_PER_TASK: usize = 2048;

/// Summary of a surface that passed [`check_closed_manifold`].
#[derive(Clone, Debug, PartialEq)]
pub struct SurfaceReport {
    /// Number of vertices (including unused ones).
    pub vertices: usize,
    /// Number of vertices used by at least one triangle.
    pub used_vertices: usize,
    /// Number of triangles.
    pub triangles: usize,
    /// Number of distinct edges.
    pub edges: usize,
    /// Total area (m²).
    pub area: f64,
    /// Signed enclosed volume (m³): positive when the triangles face outward.
    pub volume: f64,
    /// Bounding box (min, max) of the used vertices.
    pub bounds: (Point, Point),
}

/// Checks that `surface` is a closed, consistently oriented 2-manifold without
/// degenerate triangles and returns its measures.
///
/// The error names the first problem found, e.g. "edge (12, 40) belongs to 3
/// triangles", "surface is open: 17 boundary edges (first: edge (3, 9) of
/// triangle 5)", "triangle 17 is flipped relative to its three neighbours".
/// The orientation sign itself is not an error: a closed surface whose
/// triangles all face inward has a negative `volume` (see
/// [`TriSurface::orient_outward`]).
pub fn check_closed_manifold(surface: &TriSurface) -> Result<SurfaceReport, MeshError> {
    let nv = surface.vertices.len();
    if surface.triangles.is_empty() {
        return Err(MeshError::Invalid("surface has no triangles".into()));
    }
    for (t, tri) in surface.triangles.iter().enumerate() {
        if let Some(&bad) = tri.iter().find(|&&k| k >= nv) {
            return Err(MeshError::Invalid(format!(
                "triangle {t} refers to vertex {bad}, but there are {nv} vertices"
            )));
        }
    }
    let mut used = vec![false; nv];
    for tri in &surface.triangles {
        for &k in tri {
            used[k] = true;
        }
    }
    let used_points: Vec<Point> = surface.vertices.iter().zip(&used).filter(|(_, &u)| u).map(|(p, _)| *p).collect();
    // A vertex no organ has (a damaged file) is named before the tolerances it would scale.
    let vertices = surface.vertices.iter().enumerate().zip(&used).filter(|(_, &u)| u).map(|(v, _)| v);
    if let Some((i, fault)) = crate::coordinate_fault(vertices, crate::MAX_COORDINATE) {
        return Err(MeshError::Invalid(format!("vertex {i} {fault}")));
    }
    let (lo, hi) = bounds(&used_points);
    let diag2 = dot(sub(hi, lo), sub(hi, lo));
    for (t, tri) in surface.triangles.iter().enumerate() {
        if tri[0] == tri[1] || tri[1] == tri[2] || tri[0] == tri[2] {
            return Err(MeshError::Invalid(format!("triangle {t} {tri:?} repeats a vertex")));
        }
        let a = triangle_area_vector(surface, t);
        let area = dot(a, a).sqrt();
        if !(area > 1e-14 * diag2) {
            return Err(MeshError::Invalid(format!("triangle {t} {tri:?} is degenerate (area {area:.3e})")));
        }
    }

    // Directed edge (a, b) -> triangles that traverse it in that direction.
    let mut directed: HashMap<(usize, usize), Vec<usize>> = HashMap::with_capacity(3 * surface.triangles.len());
    for (t, tri) in surface.triangles.iter().enumerate() {
        for e in 0..3 {
            directed.entry((tri[e], tri[(e + 1) % 3])).or_default().push(t);
        }
    }
    // Undirected edges in a deterministic order.
    let mut undirected: Vec<(usize, usize)> = directed.keys().map(|&(a, b)| (a.min(b), a.max(b))).collect();
    undirected.sort_unstable();
    undirected.dedup();

    let mut boundary: Vec<(usize, usize, usize)> = Vec::new();
    let mut inconsistent: Vec<(usize, usize, usize, usize)> = Vec::new();
    for &(a, b) in &undirected {
        let fwd = directed.get(&(a, b)).map_or(&[][..], |v| v.as_slice());
        let bwd = directed.get(&(b, a)).map_or(&[][..], |v| v.as_slice());
        let n = fwd.len() + bwd.len();
        if n > 2 {
            return Err(MeshError::Invalid(format!("edge ({a}, {b}) belongs to {n} triangles (non-manifold)")));
        }
        if n == 1 {
            let t = fwd.first().or(bwd.first()).copied().unwrap_or(0);
            boundary.push((a, b, t));
        } else if fwd.len() == 2 || bwd.len() == 2 {
            let pair = if fwd.len() == 2 { fwd } else { bwd };
            inconsistent.push((a, b, pair[0], pair[1]));
        }
    }
    if let Some(&(a, b, t)) = boundary.first() {
        return Err(MeshError::Invalid(format!(
            "surface is open: {} boundary edges (first: edge ({a}, {b}) of triangle {t})",
            boundary.len()
        )));
    }
    if let Some(&(a, b, t1, t2)) = inconsistent.first() {
        // A triangle whose three edges all disagree with its neighbours is flipped.
        let mut count: HashMap<usize, usize> = HashMap::new();
        for &(_, _, t1, t2) in &inconsistent {
            *count.entry(t1).or_default() += 1;
            *count.entry(t2).or_default() += 1;
        }
        let mut flipped: Vec<usize> = count.iter().filter(|(_, &c)| c == 3).map(|(&t, _)| t).collect();
        flipped.sort_unstable();
        return Err(match flipped.first() {
            Some(&t) => MeshError::Invalid(format!(
                "triangle {t} {:?} is flipped relative to its three neighbours ({} inconsistently oriented edges)",
                surface.triangles[t],
                inconsistent.len()
            )),
            None => MeshError::Invalid(format!(
                "triangles {t1} and {t2} are inconsistently oriented across edge ({a}, {b}) \
                 ({} such edges)",
                inconsistent.len()
            )),
        });
    }

    // Every vertex must be surrounded by a single fan: the triangles around it,
    // linked through shared edges, form one cycle.
    check_vertex_fans(surface, &used)?;

    Ok(SurfaceReport {
        vertices: nv,
        used_vertices: used.iter().filter(|&&u| u).count(),
        triangles: surface.triangles.len(),
        edges: undirected.len(),
        area: surface.area(),
        volume: surface.enclosed_volume(),
        bounds: (lo, hi),
    })
}

/// Each vertex's incident triangles must form one cycle through shared edges
/// (two cones touching at a vertex, for example, form two).
fn check_vertex_fans(surface: &TriSurface, used: &[bool]) -> Result<(), MeshError> {
    let nv = surface.vertices.len();
    // For each vertex: the "next" map of its link: in triangle (v, a, b), a -> b.
    let mut start = vec![0usize; nv + 1];
    for tri in &surface.triangles {
        for &k in tri {
            start[k + 1] += 1;
        }
    }
    for i in 0..nv {
        start[i + 1] += start[i];
    }
    let mut fill = start.clone();
    let mut link = vec![(0usize, 0usize); start[nv]];
    for tri in &surface.triangles {
        for e in 0..3 {
            let v = tri[e];
            link[fill[v]] = (tri[(e + 1) % 3], tri[(e + 2) % 3]);
            fill[v] += 1;
        }
    }
    for v in 0..nv {
        if !used[v] {
            continue;
        }
        let fan = &link[start[v]..start[v + 1]];
        // Walk the cycle from the first link edge; the manifold edge check
        // guarantees each link vertex has exactly one successor.
        let mut steps = 1;
        let first = fan[0].0;
        let mut cur = fan[0].1;
        while cur != first && steps <= fan.len() {
            match fan.iter().find(|(a, _)| *a == cur) {
                Some(&(_, b)) => cur = b,
                None => break,
            }
            steps += 1;
        }
        if steps != fan.len() {
            return Err(MeshError::Invalid(format!(
                "vertex {v} is non-manifold: its {} triangles form more than one fan",
                fan.len()
            )));
        }
    }
    Ok(())
}

/// Area vector of triangle `t`: half the cross product, normal to the
/// triangle, pointing outward for a counter-clockwise triangle.
pub fn triangle_area_vector(surface: &TriSurface, t: usize) -> Point {
    area_vector(surface.triangles[t].map(|k| surface.vertices[k]))
}

/// The area vector of the triangle of corners `p`: half the cross product of its edges, its area
/// times its unit normal (counter-clockwise seen from where it points).
pub(crate) fn area_vector(p: [Point; 3]) -> Point {
    cross(sub(p[1], p[0]), sub(p[2], p[0])).map(|c| 0.5 * c)
}

/// The centroid of the triangle of corners `p`.
pub(crate) fn centroid(p: [Point; 3]) -> Point {
    std::array::from_fn(|d| (p[0][d] + p[1][d] + p[2][d]) / 3.0)
}

impl TriSurface {
    /// Total area of the triangles (m²).
    pub fn area(&self) -> f64 {
        (0..self.triangles.len())
            .map(|t| {
                let a = triangle_area_vector(self, t);
                dot(a, a).sqrt()
            })
            .sum()
    }

    /// Signed enclosed volume by the divergence theorem (m³): positive when
    /// the triangles are counter-clockwise seen from outside. Meaningful for
    /// closed surfaces only.
    pub fn enclosed_volume(&self) -> f64 {
        // Sum of signed tetrahedra (centre, a, b, c); the centre keeps the
        // terms small and the sum well conditioned.
        let (lo, hi) = bounds(&self.vertices);
        let o = if lo[0].is_finite() {
            [0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1]), 0.5 * (lo[2] + hi[2])]
        } else {
            [0.0; 3]
        };
        self.triangles
            .iter()
            .map(|tri| {
                let [a, b, c] = tri.map(|k| sub(self.vertices[k], o));
                dot(a, cross(b, c)) / 6.0
            })
            .sum()
    }

    /// Reverses every triangle (inside out).
    pub fn flip(&mut self) {
        for tri in &mut self.triangles {
            tri.swap(1, 2);
        }
    }

    /// Makes the triangles face outward: flips them all when the enclosed
    /// volume is negative. Returns true when the surface was flipped.
    pub fn orient_outward(&mut self) -> bool {
        if self.enclosed_volume() < 0.0 {
            self.flip();
            true
        } else {
            false
        }
    }

    /// Translates and scales the vertices in place: x ← (x − centre) · scale.
    pub fn transform(&mut self, centre: Point, scale: f64) {
        for p in &mut self.vertices {
            for d in 0..3 {
                p[d] = (p[d] - centre[d]) * scale;
            }
        }
    }

    /// Centres the surface's bounding box at the origin and scales it so that
    /// its largest extent equals `length` (m). Returns the (centre, scale)
    /// that was applied, as in [`TriSurface::transform`].
    pub fn fit_to(&mut self, length: f64) -> Result<(Point, f64), MeshError> {
        if !(length > 0.0 && length.is_finite()) {
            return Err(MeshError::Invalid(format!("fit_to: length must be positive and finite, got {length}")));
        }
        let (lo, hi) = bounds(&self.vertices);
        let extent = crate::longest_side((lo, hi));
        if !(extent > 0.0 && extent.is_finite()) {
            return Err(MeshError::Invalid("fit_to: the surface has no finite extent".into()));
        }
        let centre = [0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1]), 0.5 * (lo[2] + hi[2])];
        let scale = length / extent;
        self.transform(centre, scale);
        Ok((centre, scale))
    }

    /// The triangles grouped into pieces joined through shared vertices, each piece's triangles in
    /// increasing order, the pieces ordered by their first triangle. A triangle with a vertex out
    /// of range is left out.
    pub fn pieces(&self) -> Vec<Vec<usize>> {
        let n = self.vertices.len();
        let mut parent: Vec<usize> = (0..n).collect();
        for t in self.triangles.iter().filter(|t| t.iter().all(|&k| k < n)) {
            for k in [t[1], t[2]] {
                let (a, b) = (crate::topology::root(&mut parent, t[0]), crate::topology::root(&mut parent, k));
                parent[a.max(b)] = a.min(b);
            }
        }
        let mut piece_of_root = std::collections::HashMap::new();
        let mut pieces: Vec<Vec<usize>> = Vec::new();
        for (i, t) in self.triangles.iter().enumerate().filter(|(_, t)| t.iter().all(|&k| k < n)) {
            let root = crate::topology::root(&mut parent, t[0]);
            let piece = *piece_of_root.entry(root).or_insert_with(|| {
                pieces.push(Vec::new());
                pieces.len() - 1
            });
            pieces[piece].push(i);
        }
        pieces
    }

    /// The surface restricted to the vertices its triangles use (in order of first use).
    pub fn compacted(&self) -> TriSurface {
        let mut index = vec![usize::MAX; self.vertices.len()];
        let mut vertices = Vec::new();
        let triangles = self
            .triangles
            .iter()
            .map(|t| {
                t.map(|k| {
                    if index[k] == usize::MAX {
                        index[k] = vertices.len();
                        vertices.push(self.vertices[k]);
                    }
                    index[k]
                })
            })
            .collect();
        TriSurface { vertices, triangles }
    }

    /// The normal at each corner of each triangle: the area-weighted mean of the normals of the
    /// triangles around the corner's vertex that turn from this triangle's by less than the angle
    /// whose cosine is `sharp_cos`. On a smooth surface every triangle around a vertex gets the
    /// vertex's normal, so that normals interpolated over the triangles vary continuously; a sharp
    /// edge (a box's) keeps the normals of its two sides apart.
    pub fn corner_normals(&self, sharp_cos: f64) -> Vec<[Point; 3]> {
        let areas: Vec<Point> = (0..self.triangles.len()).map(|t| triangle_area_vector(self, t)).collect();
        let units: Vec<Point> = areas.iter().map(|&a| unit(a)).collect();
        let (start, around) = self.triangles_around();
        self.triangles
            .par_iter()
            .enumerate()
            .with_min_len(CORNERS_PER_TASK)
            .map(|(t, tri)| {
                tri.map(|k| {
                    let mut n = [0.0; 3];
                    let near = around[start[k]..start[k + 1]].iter().copied();
                    for u in near.filter(|&u| u == t || dot(units[u], units[t]) > sharp_cos) {
                        (0..3).for_each(|d| n[d] += areas[u][d]);
                    }
                    match unit(n) {
                        [0.0, 0.0, 0.0] => units[t],
                        n => n,
                    }
                })
            })
            .collect()
    }

    /// The triangles around each vertex, compressed: those of vertex `k` are
    /// `around[start[k]..start[k + 1]]`.
    fn triangles_around(&self) -> (Vec<usize>, Vec<usize>) {
        let mut start = vec![0usize; self.vertices.len() + 1];
        self.triangles.iter().flatten().for_each(|&k| start[k + 1] += 1);
        (0..self.vertices.len()).for_each(|k| start[k + 1] += start[k]);
        let mut next = start.clone();
        let mut around = vec![0; start[self.vertices.len()]];
        for (t, tri) in self.triangles.iter().enumerate() {
            for &k in tri {
                around[next[k]] = t;
                next[k] += 1;
            }
        }
        (start, around)
    }

    /// Area-weighted outward unit normal at each vertex (zero for unused vertices).
    pub fn vertex_normals(&self) -> Vec<Point> {
        let mut n = vec![[0.0; 3]; self.vertices.len()];
        for (t, tri) in self.triangles.iter().enumerate() {
            let a = triangle_area_vector(self, t);
            for &k in tri {
                for d in 0..3 {
                    n[k][d] += a[d];
                }
            }
        }
        for v in &mut n {
            let len = dot(*v, *v).sqrt();
            if len > 0.0 {
                *v = v.map(|c| c / len);
            }
        }
        n
    }
}
