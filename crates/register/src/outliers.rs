//! Isolated points of a cloud (a depth camera's flying pixels, specular spots, instruments
//! seen edge-on): a statistical outlier filter on the distances to the nearest neighbours,
//! the test of PCL's `StatisticalOutlierRemoval`, made scale-free by the median.

use mesh::Point;
use rayon::prelude::*;

/// Neighbours whose mean distance measures how isolated a point is.
pub const NEIGHBOURS: usize = 8;

/// Marks the points whose mean distance to their [`NEIGHBOURS`] nearest neighbours exceeds
/// `factor` times the median of that distance over the cloud: on a surface sampled every few
/// millimetres, a point floating in the volume is several times farther from its neighbours
/// than any surface sample. Returns `true` for an outlier (a cloud of at most [`NEIGHBOURS`]
/// points has none), and the spacing of the points kept: the median of their mean distance to
/// their nearest neighbours (of all the points' when none is kept; 0 for a cloud of at most
/// [`NEIGHBOURS`] points).
pub fn isolation(cloud: &[Point], factor: f64) -> (Vec<bool>, f64) {
    if cloud.len() <= NEIGHBOURS {
        return (vec![false; cloud.len()], 0.0);
    }
    let tree = PointTree::new(cloud);
    let spread: Vec<f64> = cloud.par_iter().map(|&p| tree.mean_neighbour_distance(p)).collect();
    let median = mesh::stats::median(&mut spread.clone());
    let flags: Vec<bool> = spread.iter().map(|&d| d > factor * median).collect();
    let mut kept: Vec<f64> = spread.iter().zip(&flags).filter(|(_, &f)| !f).map(|(&d, _)| d).collect();
    let spacing = if kept.is_empty() { median } else { mesh::stats::median(&mut kept) };
    (flags, spacing)
}

/// Points per leaf of a [`PointTree`].
const LEAF: usize = 8;

/// A node of a [`PointTree`]; an inner node's left child follows it.
#[derive(Clone, Copy)]
enum TreeNode {
    /// The points `start..end` of the tree's order.
    Leaf { start: u32, end: u32 },
    /// Points at most `at` along `axis` on the left, at least `at` from node `right` on.
    Split { axis: u8, at: f64, right: u32 },
}

/// A k-d tree over a cloud (median splits along the widest axis) for the nearest-neighbour
/// search. Its splits follow the points, so a camera's surface, a volume or a line needs no cell size.
pub(crate) struct PointTree {
    /// The cloud's points, each leaf's contiguous.
    points: Vec<Point>,
    nodes: Vec<TreeNode>,
}

impl PointTree {
    /// The tree of `cloud`'s points.
    pub(crate) fn new(cloud: &[Point]) -> Self {
        let mut tree = PointTree { points: cloud.to_vec(), nodes: Vec::with_capacity(2 * cloud.len() / LEAF + 2) };
        tree.split(0, cloud.len());
        tree
    }

    /// Adds the subtree of the points `start..end`.
    fn split(&mut self, start: usize, end: usize) {
        let node = self.nodes.len();
        self.nodes.push(TreeNode::Leaf { start: start as u32, end: end as u32 });
        if end - start <= LEAF {
            return;
        }
        let part = &mut self.points[start..end];
        let (mut lo, mut hi) = (part[0], part[0]);
        for p in part.iter() {
            for d in 0..3 {
                lo[d] = lo[d].min(p[d]);
                hi[d] = hi[d].max(p[d]);
            }
        }
        let axis = (0..3).max_by(|&a, &b| (hi[a] - lo[a]).total_cmp(&(hi[b] - lo[b]))).unwrap_or(0);
        let mid = part.len() / 2;
        part.select_nth_unstable_by(mid, |a, b| a[axis].total_cmp(&b[axis]));
        let at = part[mid][axis];
        self.split(start, start + mid);
        let right = self.nodes.len() as u32;
        self.nodes[node] = TreeNode::Split { axis: axis as u8, at, right };
        self.split(start + mid, end);
    }

    /// Mean distance from `p` (a point of the cloud) to its [`NEIGHBOURS`] nearest other points.
    fn mean_neighbour_distance(&self, p: Point) -> f64 {
        // The point itself is the first entry, at distance 0.
        let best = self.nearest_k::<{ NEIGHBOURS + 1 }>(p);
        best[1..].iter().map(|(d2, _)| d2.sqrt()).sum::<f64>() / NEIGHBOURS as f64
    }

    /// The cloud's point nearest to `p`, and its distance.
    pub(crate) fn nearest(&self, p: Point) -> (Point, f64) {
        let [(d2, at)] = self.nearest_k::<1>(p);
        (self.points[at], d2.sqrt())
    }

    /// The squared distances from `p` to its `K` nearest points of the cloud, nearest first, with
    /// their places in the tree's order: depth first, the nearer side first, skipping a side
    /// farther than the farthest kept.
    fn nearest_k<const K: usize>(&self, p: Point) -> [(f64, usize); K] {
        let mut best = [(f64::INFINITY, 0); K];
        // Nodes to visit with a lower bound of their squared distance: at most one more than the
        // depth, which median splits keep below log2(n) + 1.
        let mut stack = [(0u32, 0.0f64); 128];
        let mut top = 1;
        while top > 0 {
            top -= 1;
            let (node, bound) = stack[top];
            if bound >= best[K - 1].0 {
                continue;
            }
            match self.nodes[node as usize] {
                TreeNode::Leaf { start, end } => {
                    for at in start as usize..end as usize {
                        let q = self.points[at];
                        let d2 = (0..3).map(|d| (q[d] - p[d]).powi(2)).sum::<f64>();
                        if d2 < best[K - 1].0 {
                            let slot = best.partition_point(|&(b, _)| b < d2);
                            best.copy_within(slot..K - 1, slot + 1);
                            best[slot] = (d2, at);
                        }
                    }
                }
                TreeNode::Split { axis, at, right } => {
                    let offset = p[axis as usize] - at;
                    let (near, far) = if offset < 0.0 { (node + 1, right) } else { (right, node + 1) };
                    stack[top] = (far, bound.max(offset * offset));
                    stack[top + 1] = (near, bound);
                    top += 2;
                }
            }
        }
        best
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A sampled plane keeps all its points; the points floating well above it (a tenth of
    /// the cloud) are found.
    #[test]
    fn floating_points_over_a_sampled_plane_are_isolated() {
        let cloud = plane_with_floating_points();
        let surface = 40 * 40;
        let (flags, spacing) = isolation(&cloud, 3.0);
        assert_eq!(flags[..surface].iter().filter(|&&f| f).count(), 0, "a surface point was flagged");
        // The spacing is the kept points' median mean distance to their nearest neighbours, by brute
        // force (the floating points left out).
        let mut kept: Vec<f64> = (0..cloud.len())
            .filter(|&i| !flags[i])
            .map(|i| {
                let mut d: Vec<f64> = cloud.iter().map(|q| mesh::distance(*q, cloud[i])).collect();
                d.sort_by(f64::total_cmp);
                d[1..=NEIGHBOURS].iter().sum::<f64>() / NEIGHBOURS as f64
            })
            .collect();
        assert!((spacing - mesh::stats::median(&mut kept)).abs() < 1e-12, "spacing {spacing}");
        // Every point more than 2 cm (five sample spacings) off the plane; nearer ones may
        // pass for samples (they are then ordinary far matches).
        let far: Vec<bool> = (surface..cloud.len()).filter(|&i| cloud[i][2] > 0.02).map(|i| flags[i]).collect();
        assert!(
            far.len() > 90 && far.iter().all(|&f| f),
            "{} of {} far points flagged",
            far.iter().filter(|&&f| f).count(),
            far.len()
        );
    }

    /// A sampled plane with points floating above it (a tenth of the cloud), as a camera sees
    /// a surface.
    fn plane_with_floating_points() -> Vec<Point> {
        let mut cloud = Vec::new();
        for i in 0..40 {
            for j in 0..40 {
                let jitter = ((i * 7 + j * 13) % 10) as f64 * 1e-4;
                cloud.push([i as f64 * 4e-3 + jitter, j as f64 * 4e-3, jitter]);
            }
        }
        for k in 0..160 {
            let s = k as f64;
            cloud.push([(s * 0.618).fract() * 0.16, (s * 0.414).fract() * 0.16, 0.01 + (s * 0.732).fract() * 0.05]);
        }
        cloud
    }

    /// The tree search returns the exact mean distance to the nearest neighbours and the exact
    /// nearest point, in a thin volume, on a sampled surface and along a line of doubled points.
    #[test]
    fn neighbour_distances_match_brute_force() {
        let slab: Vec<Point> = (0..300)
            .map(|k| {
                let s = k as f64;
                [(s * 0.618).fract(), (s * 0.414).fract() * 0.3, (s * 0.732).fract() * 0.05]
            })
            .collect();
        // Points on a line, each twice: splits among equal coordinates.
        let line: Vec<Point> = (0..200).map(|k| [(k / 2) as f64 * 1e-3, 0.0, 0.0]).collect();
        for cloud in [slab, plane_with_floating_points(), line] {
            let tree = PointTree::new(&cloud);
            for &p in cloud.iter().step_by(7) {
                let mut d: Vec<f64> =
                    cloud.iter().map(|q| (0..3).map(|i| (q[i] - p[i]).powi(2)).sum::<f64>().sqrt()).collect();
                d.sort_by(f64::total_cmp);
                let brute = d[1..=NEIGHBOURS].iter().sum::<f64>() / NEIGHBOURS as f64;
                assert!((tree.mean_neighbour_distance(p) - brute).abs() < 1e-12);
            }
            // The nearest point to places off the cloud, as a brute-force search finds it.
            for k in 0..50 {
                let s = k as f64;
                let p = [(s * 0.377).fract() * 1.2 - 0.1, (s * 0.291).fract() * 0.5, (s * 0.853).fract() * 0.2 - 0.1];
                let distance = |q: &Point| (0..3).map(|i| (q[i] - p[i]).powi(2)).sum::<f64>().sqrt();
                let brute = cloud.iter().map(distance).fold(f64::INFINITY, f64::min);
                let (q, d) = tree.nearest(p);
                assert!((d - brute).abs() < 1e-12 && (distance(&q) - d).abs() < 1e-12, "{d} against {brute}");
            }
        }
    }

    /// A tiny cloud has no outliers; a point a kilometre away is one (and costs no more
    /// than any other).
    #[test]
    fn tiny_clouds_and_far_points() {
        assert_eq!(isolation(&[[0.0; 3], [1.0, 0.0, 0.0]], 3.0).0, vec![false, false]);
        let mut cloud: Vec<Point> = (0..400).map(|k| [(k % 20) as f64 * 1e-3, (k / 20) as f64 * 1e-3, 0.0]).collect();
        cloud.push([1000.0, 0.0, 0.0]);
        let flags = isolation(&cloud, 3.0).0;
        assert!(flags[400] && !flags[..400].iter().any(|&f| f));
    }
}
