//! Decimation of a closed triangle surface by quadric edge collapse (Garland & Heckbert 1997).
//!
//! Each vertex carries the quadric of the planes of its triangles (weighted by area); the edge
//! whose collapse to the point of least quadric error costs least is collapsed first. A collapse
//! is made only when it keeps the surface a closed 2-manifold (the link condition: the two ends
//! of the edge share exactly the two neighbours across its triangles) and keeps its triangles
//! facing as they did (no triangle turns by more than 60°) and not too thin.

use std::cmp::Ordering;
use std::collections::BinaryHeap;

use crate::{cross, dot, norm, sub, Point, TriSurface};

/// The surface with about `target` triangles (never fewer than 8; unchanged when it has no more
/// than `target`, or too many vertices to number in 32 bits), by quadric edge collapse. The surface must be a closed 2-manifold; the result
/// is one too.
pub fn decimate(surface: &TriSurface, target: usize) -> TriSurface {
    if surface.triangles.len() <= target || surface.vertices.len() >= u32::MAX as usize {
        return surface.clone();
    }
    let mut state = Decimator::new(surface);
    state.run(target.max(8));
    state.result()
}

/// A symmetric 4 × 4 matrix: a², ab, ac, ad, b², bc, bd, c², cd, d².
type Quadric = [f64; 10];

fn error(q: &Quadric, p: Point) -> f64 {
    let [x, y, z] = p;
    q[0] * x * x
        + 2.0 * q[1] * x * y
        + 2.0 * q[2] * x * z
        + 2.0 * q[3] * x
        + q[4] * y * y
        + 2.0 * q[5] * y * z
        + 2.0 * q[6] * y
        + q[7] * z * z
        + 2.0 * q[8] * z
        + q[9]
}

/// A candidate collapse of edge (a, b) (to the point [`Decimator::best`] gives), valid while
/// both ends keep their versions. Small, as the heap holds millions.
struct Candidate {
    cost: f64,
    a: u32,
    b: u32,
    versions: (u32, u32),
}

impl PartialEq for Candidate {
    fn eq(&self, other: &Self) -> bool {
        self.cmp(other) == Ordering::Equal
    }
}

impl Eq for Candidate {}

impl PartialOrd for Candidate {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for Candidate {
    /// The cheapest first out of the (max-)heap; ties by vertex numbers, for determinism.
    fn cmp(&self, other: &Self) -> Ordering {
        other.cost.total_cmp(&self.cost).then_with(|| (other.a, other.b).cmp(&(self.a, self.b)))
    }
}

struct Decimator {
    points: Vec<Point>,
    quadrics: Vec<Quadric>,
    triangles: Vec<[usize; 3]>,
    alive: Vec<bool>,
    /// The triangles around each vertex (dead ones among them until cleaned).
    around: Vec<Vec<usize>>,
    version: Vec<u32>,
    heap: BinaryHeap<Candidate>,
    live: usize,
}

impl Decimator {
    fn new(surface: &TriSurface) -> Self {
        let n = surface.vertices.len();
        let mut quadrics = vec![[0.0; 10]; n];
        let mut around = vec![Vec::new(); n];
        for (t, tri) in surface.triangles.iter().enumerate() {
            let [p, q, r] = tri.map(|k| surface.vertices[k]);
            let normal = cross(sub(q, p), sub(r, p));
            let length = norm(normal);
            if length > 0.0 {
                let [a, b, c] = normal.map(|x| x / length);
                let d = -dot([a, b, c], p);
                let w = 0.5 * length;
                let plane = [a * a, a * b, a * c, a * d, b * b, b * c, b * d, c * c, c * d, d * d];
                for &k in tri {
                    (0..10).for_each(|i| quadrics[k][i] += w * plane[i]);
                }
            }
            tri.iter().for_each(|&k| around[k].push(t));
        }
        let mut state = Decimator {
            points: surface.vertices.clone(),
            quadrics,
            triangles: surface.triangles.clone(),
            alive: vec![true; surface.triangles.len()],
            around,
            version: vec![0; n],
            heap: BinaryHeap::new(),
            live: surface.triangles.len(),
        };
        for tri in &surface.triangles {
            for e in 0..3 {
                let (a, b) = (tri[e], tri[(e + 1) % 3]);
                if a < b {
                    state.push(a, b);
                }
            }
        }
        state
    }

    /// Queues the collapse of edge (a, b).
    fn push(&mut self, a: usize, b: usize) {
        let (_, cost) = self.best(a, b);
        let versions = (self.version[a], self.version[b]);
        self.heap.push(Candidate { cost, a: a as u32, b: b as u32, versions });
    }

    /// The point to collapse edge (a, b) to, and its quadric error.
    fn best(&self, a: usize, b: usize) -> (Point, f64) {
        let q: Quadric = std::array::from_fn(|i| self.quadrics[a][i] + self.quadrics[b][i]);
        let (pa, pb) = (self.points[a], self.points[b]);
        let middle = std::array::from_fn(|d| 0.5 * (pa[d] + pb[d]));
        let optimal = optimum(&q).filter(|&p| norm(sub(p, middle)) <= norm(sub(pa, pb)));
        let candidates = optimal.into_iter().chain([pa, pb, middle]);
        candidates
            .into_iter()
            .map(|p| (p, error(&q, p)))
            .min_by(|x, y| x.1.total_cmp(&y.1))
            .expect("candidates are never empty")
    }

    /// The live vertices around `v` (without `v`), sorted.
    fn ring(&self, v: usize) -> Vec<usize> {
        let mut ring: Vec<usize> = self.around[v]
            .iter()
            .filter(|&&t| self.alive[t])
            .flat_map(|&t| self.triangles[t])
            .filter(|&k| k != v)
            .collect();
        ring.sort_unstable();
        ring.dedup();
        ring
    }

    /// True when collapsing (a, b) to `target` keeps the surface manifold and its triangles
    /// facing as they did and not too thin.
    fn allowed(&self, a: usize, b: usize, target: Point) -> bool {
        let (ring_a, ring_b) = (self.ring(a), self.ring(b));
        let shared = ring_a.iter().filter(|v| ring_b.binary_search(v).is_ok()).count();
        let on_edge = self.around[a].iter().filter(|&&t| self.alive[t] && self.triangles[t].contains(&b)).count();
        if shared != 2 || on_edge != 2 || self.live <= 8 {
            return false;
        }
        for &v in &[a, b] {
            for &t in self.around[v].iter().filter(|&&t| self.alive[t]) {
                let tri = self.triangles[t];
                if tri.contains(&a) && tri.contains(&b) {
                    continue;
                }
                let old = tri.map(|k| self.points[k]);
                let new = tri.map(|k| if k == a || k == b { target } else { self.points[k] });
                let (n0, n1) =
                    (cross(sub(old[1], old[0]), sub(old[2], old[0])), cross(sub(new[1], new[0]), sub(new[2], new[0])));
                if dot(n0, n1) <= 0.5 * norm(n0) * norm(n1) || quality(new) < 0.05 {
                    return false;
                }
            }
        }
        true
    }

    /// Collapses b into a, moved to `target`.
    fn collapse(&mut self, a: usize, b: usize, target: Point) {
        for t in std::mem::take(&mut self.around[b]) {
            if !self.alive[t] {
                continue;
            }
            if self.triangles[t].contains(&a) {
                self.alive[t] = false;
                self.live -= 1;
            } else {
                self.triangles[t].iter_mut().filter(|k| **k == b).for_each(|k| *k = a);
                self.around[a].push(t);
            }
        }
        let alive = &self.alive;
        self.around[a].retain(|&t| alive[t]);
        self.points[a] = target;
        self.quadrics[a] = std::array::from_fn(|i| self.quadrics[a][i] + self.quadrics[b][i]);
        self.version[a] += 1;
        self.version[b] += 1;
        for c in self.ring(a) {
            self.push(a.min(c), a.max(c));
        }
    }

    fn run(&mut self, target: usize) {
        while self.live > target {
            let Some(c) = self.heap.pop() else { break };
            let (a, b) = (c.a as usize, c.b as usize);
            if (self.version[a], self.version[b]) != c.versions {
                continue;
            }
            let (target, _) = self.best(a, b);
            if self.allowed(a, b, target) {
                self.collapse(a, b, target);
            }
        }
    }

    fn result(&self) -> TriSurface {
        let triangles = self.triangles.iter().zip(&self.alive).filter(|(_, &a)| a).map(|(t, _)| *t).collect();
        TriSurface { vertices: self.points.clone(), triangles }.compacted()
    }
}

/// The point of least error of a quadric, when its 3 × 3 part is well conditioned.
fn optimum(q: &Quadric) -> Option<Point> {
    let m = [[q[0], q[1], q[2]], [q[1], q[4], q[5]], [q[2], q[5], q[7]]];
    let rhs = [-q[3], -q[6], -q[8]];
    let det = |m: &[[f64; 3]; 3]| {
        m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
    };
    let d = det(&m);
    let scale = q[0] + q[4] + q[7];
    if !(d.abs() > 1e-9 * scale * scale * scale) {
        return None;
    }
    let solution: Point = std::array::from_fn(|c| {
        let mut mc = m;
        (0..3).for_each(|r| mc[r][c] = rhs[r]);
        det(&mc) / d
    });
    solution.iter().all(|x| x.is_finite()).then_some(solution)
}

/// A triangle's shape: 4√3 area over the sum of its squared edges (1 equilateral, 0 flat).
fn quality(p: [Point; 3]) -> f64 {
    let area = norm(crate::surface::area_vector(p));
    let edges: f64 = (0..3).map(|e| norm(sub(p[(e + 1) % 3], p[e])).powi(2)).sum();
    if edges > 0.0 {
        4.0 * 3f64.sqrt() * area / edges
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::surface::check_closed_manifold;

    #[test]
    fn a_sphere_is_decimated_closed_and_keeps_its_volume() {
        let sphere = crate::generate::icosphere(1.0, 5);
        let exact = sphere.enclosed_volume();
        let small = decimate(&sphere, 1000);
        let report = check_closed_manifold(&small).unwrap();
        assert!(small.triangles.len() <= 1000 && small.triangles.len() > 900, "{}", small.triangles.len());
        assert!((report.volume / exact - 1.0).abs() < 0.01, "{} vs {exact}", report.volume);
        let far = small.vertices.iter().map(|p| (norm(*p) - 1.0).abs()).fold(0.0, f64::max);
        assert!(far < 0.01, "{far}");
        assert_eq!(decimate(&sphere, 1_000_000), sphere);
    }
}
