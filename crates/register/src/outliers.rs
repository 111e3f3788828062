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
/// than any surface sample. Returns `true` for an outlier; a cloud of at most [`NEIGHBOURS`]
/// points has none.
pub fn isolated_points(cloud: &[Point], factor: f64) -> Vec<bool> {
    if cloud.len() <= NEIGHBOURS {
        return vec![false; cloud.len()];
    }
    let grid = PointGrid::new(cloud);
    let spread: Vec<f64> = cloud.par_iter().map(|&p| grid.mean_neighbour_distance(cloud, p)).collect();
    let mut sorted = spread.clone();
    let median = mesh::stats::median(&mut sorted);
    spread.iter().map(|&d| d > factor * median).collect()
}

/// Most cells along one axis of a [`PointGrid`].
const MAX_CELLS: i64 = 1024;

/// Cubic cells of side `cell` over the box of `dims` cells from `origin`; a point beyond the box
/// belongs to the nearest cell.
#[derive(Clone, Copy)]
struct Cells {
    origin: Point,
    cell: f64,
    dims: [i64; 3],
}

impl Cells {
    fn new(origin: Point, extent: Point, cell: f64) -> Cells {
        Cells { origin, cell, dims: extent.map(|e| ((e / cell).ceil() as i64).clamp(1, MAX_CELLS)) }
    }

    fn index(&self, key: [i64; 3]) -> usize {
        ((key[0] * self.dims[1] + key[1]) * self.dims[2] + key[2]) as usize
    }

    fn key(&self, p: Point) -> [i64; 3] {
        std::array::from_fn(|d| (((p[d] - self.origin[d]) / self.cell).floor() as i64).clamp(0, self.dims[d] - 1))
    }
}

/// Points sorted into cubic cells over the cloud's bulk (the box of its 1st to 99th
/// percentiles, widened by a tenth); a point beyond that box goes to the nearest cell.
struct PointGrid {
    cells: Cells,
    /// The points of cell c are `order[starts[c]..starts[c + 1]]` (cells numbered x-major).
    starts: Vec<u32>,
    order: Vec<u32>,
}

impl PointGrid {
    /// Cells sized to hold a few points each where the cloud lies (in a volume, on a surface or
    /// along a line).
    fn new(cloud: &[Point]) -> Self {
        let (mut origin, mut extent) = ([0.0; 3], [0.0; 3]);
        for d in 0..3 {
            let mut x: Vec<f64> = cloud.iter().map(|p| p[d]).collect();
            x.sort_by(f64::total_cmp);
            let (lo, hi) = (x[x.len() / 100], x[x.len() - 1 - x.len() / 100]);
            let margin = 0.1 * (hi - lo);
            origin[d] = lo - margin;
            extent[d] = (hi - lo + 2.0 * margin).max(1e-9);
        }
        // A few points per cell whether the cloud fills a volume, a surface or a line: at most the
        // largest of the spacings it would have spread over its 3, 2 or 1 largest extents...
        let mut sorted = extent;
        sorted.sort_by(|a, b| b.total_cmp(a));
        let n = cloud.len() as f64;
        let coarse =
            (1..=3).map(|d| (4.0 * sorted[..d].iter().product::<f64>() / n).powf(1.0 / d as f64)).fold(1e-9, f64::max);
        // ... and, where the points crowd into a few of those cells (a camera's cloud is a
        // surface in its box), less, as for a surface, down to the spacing of 8 cells per point
        // over the box's volume.
        let keys_at = |cell: f64| {
            let cells = Cells::new(origin, extent, cell);
            (cells, cloud.iter().map(|&p| cells.index(cells.key(p))).collect::<Vec<usize>>())
        };
        let mut occupied = keys_at(coarse).1;
        occupied.sort_unstable();
        occupied.dedup();
        let per_cell = n / occupied.len() as f64;
        let finest = (extent.iter().product::<f64>() / (8.0 * n)).cbrt();
        let (cells, keys) = keys_at((coarse * (4.0 / per_cell).sqrt()).clamp(finest.min(coarse), coarse));
        let count = cells.dims.iter().product::<i64>() as usize;
        let mut grid = PointGrid { cells, starts: vec![0; count + 1], order: vec![0; cloud.len()] };
        for &k in &keys {
            grid.starts[k + 1] += 1;
        }
        for c in 0..count {
            grid.starts[c + 1] += grid.starts[c];
        }
        let mut next = grid.starts.clone();
        for (i, &k) in keys.iter().enumerate() {
            grid.order[next[k] as usize] = i as u32;
            next[k] += 1;
        }
        grid
    }

    /// Mean distance from `p` (a point of `cloud`) to its [`NEIGHBOURS`] nearest other points:
    /// cells are visited in growing cubic shells until the shell's inner distance exceeds the
    /// farthest of the best found.
    fn mean_neighbour_distance(&self, cloud: &[Point], p: Point) -> f64 {
        let centre = self.cells.key(p);
        // Squared distances of the nearest found so far, sorted, the point itself included.
        let mut best: Vec<f64> = Vec::with_capacity(NEIGHBOURS + 2);
        let mut ring = 0i64;
        loop {
            // The cells of the shell inside the grid (its faces, each cell once): a whole column
            // on the shell's sides, its two ends inside.
            let span = |d: usize| (centre[d] - ring).max(0)..=(centre[d] + ring).min(self.cells.dims[d] - 1);
            for x in span(0) {
                for y in span(1) {
                    if (x - centre[0]).abs() == ring || (y - centre[1]).abs() == ring {
                        span(2).for_each(|z| self.scan_cell([x, y, z], cloud, p, &mut best));
                    } else {
                        for z in [centre[2] - ring, centre[2] + ring] {
                            if (0..self.cells.dims[2]).contains(&z) {
                                self.scan_cell([x, y, z], cloud, p, &mut best);
                            }
                        }
                    }
                }
            }
            // Every point not yet visited is at least `ring * cell` away (farther still if
            // it lies beyond the grid); past the largest dimension, every cell was visited.
            let reach = ring as f64 * self.cells.cell;
            let all = ring >= self.cells.dims.into_iter().max().unwrap_or(1);
            if all || (best.len() > NEIGHBOURS && best[NEIGHBOURS] <= reach * reach) {
                break;
            }
            ring += 1;
        }
        // The point itself is the first entry, at distance 0.
        best[1..].iter().map(|d| d.sqrt()).sum::<f64>() / NEIGHBOURS as f64
    }

    /// Merges the squared distances from `p` to the points of cell `key` into `best` (sorted,
    /// the [`NEIGHBOURS`] + 1 smallest kept).
    fn scan_cell(&self, key: [i64; 3], cloud: &[Point], p: Point, best: &mut Vec<f64>) {
        let c = self.cells.index(key);
        for &j in &self.order[self.starts[c] as usize..self.starts[c + 1] as usize] {
            let q = cloud[j as usize];
            let d2 = (0..3).map(|d| (q[d] - p[d]).powi(2)).sum::<f64>();
            if best.len() <= NEIGHBOURS || d2 < best[NEIGHBOURS] {
                let at = best.partition_point(|&b| b < d2);
                best.insert(at, d2);
                best.truncate(NEIGHBOURS + 1);
            }
        }
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
        let flags = isolated_points(&cloud, 3.0);
        assert_eq!(flags[..surface].iter().filter(|&&f| f).count(), 0, "a surface point was flagged");
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

    /// The grid search returns the exact mean distance to the nearest neighbours, in a thin
    /// volume and on a sampled surface (where the grid's cells shrink to the surface's spacing).
    #[test]
    fn neighbour_distances_match_brute_force() {
        let slab: Vec<Point> = (0..300)
            .map(|k| {
                let s = k as f64;
                [(s * 0.618).fract(), (s * 0.414).fract() * 0.3, (s * 0.732).fract() * 0.05]
            })
            .collect();
        for cloud in [slab, plane_with_floating_points()] {
            let grid = PointGrid::new(&cloud);
            for &p in cloud.iter().step_by(7) {
                let mut d: Vec<f64> =
                    cloud.iter().map(|q| (0..3).map(|i| (q[i] - p[i]).powi(2)).sum::<f64>().sqrt()).collect();
                d.sort_by(f64::total_cmp);
                let brute = d[1..=NEIGHBOURS].iter().sum::<f64>() / NEIGHBOURS as f64;
                assert!((grid.mean_neighbour_distance(&cloud, p) - brute).abs() < 1e-12);
            }
        }
    }

    /// A tiny cloud has no outliers; a point a kilometre away is one (and costs no more
    /// than any other).
    #[test]
    fn tiny_clouds_and_far_points() {
        assert_eq!(isolated_points(&[[0.0; 3], [1.0, 0.0, 0.0]], 3.0), vec![false, false]);
        let mut cloud: Vec<Point> = (0..400).map(|k| [(k % 20) as f64 * 1e-3, (k / 20) as f64 * 1e-3, 0.0]).collect();
        cloud.push([1000.0, 0.0, 0.0]);
        let flags = isolated_points(&cloud, 3.0);
        assert!(flags[400] && !flags[..400].iter().any(|&f| f));
    }
}
