//! Binary voxel masks: an organ as the voxels inside it, in a grid with its voxel-to-world map.
//!
//! A mask comes from a labelmap ([`crate::labelmap::Labelmap::select`]) or from a surface
//! ([`voxelise_surface`], robust to holes, self-intersections and non-manifold parts). Before its
//! surface is extracted ([`crate::isosurface::mask_surface`]) it keeps its largest piece
//! ([`VoxelMask::keep_largest`]) and its cavities are filled ([`VoxelMask::fill_cavities`]).
//!
//! Voxels are the lattice points (i, j, k) of the grid; two are neighbours when they share an
//! edge of the grid's Kuhn triangulation, that is, when they differ by one of ±(1,0,0), ±(0,1,0),
//! ±(0,0,1), ±(1,1,0), ±(1,0,1), ±(0,1,1), ±(1,1,1) (14 neighbours). The surface extracted from
//! the triangulation separates exactly these pieces, so one piece without cavities gives one
//! closed surface.

use std::collections::VecDeque;

use rayon::prelude::*;

use crate::bvh::SurfaceBvh;
use crate::{bounds, MeshError, Point, TriSurface};

/// The 14 neighbours of a voxel (see the module's documentation).
const NEIGHBOURS: [[i64; 3]; 14] = [
    [1, 0, 0],
    [-1, 0, 0],
    [0, 1, 0],
    [0, -1, 0],
    [0, 0, 1],
    [0, 0, -1],
    [1, 1, 0],
    [-1, -1, 0],
    [1, 0, 1],
    [-1, 0, -1],
    [0, 1, 1],
    [0, -1, -1],
    [1, 1, 1],
    [-1, -1, -1],
];

/// The determinant of a voxel-to-world affine's linear part (the voxel volume, signed).
pub fn determinant(a: &[[f64; 4]; 3]) -> f64 {
    a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1]) - a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0])
        + a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0])
}

/// The voxels inside an organ.
#[derive(Clone, Debug, PartialEq)]
pub struct VoxelMask {
    /// Voxels along i, j, k.
    pub dims: [usize; 3],
    /// True inside, i fastest, then j, then k.
    pub inside: Vec<bool>,
    /// Voxel index (i, j, k) to world: `x = A[..3] · (i, j, k) + A[3]`, row by row.
    pub affine: [[f64; 4]; 3],
}

impl VoxelMask {
    /// The same voxels in the scanner's order: axes permuted and reversed so that voxel axis `r`
    /// runs along world axis `r` (L, P, S), increasing; `ras`: the affine maps to RAS (x and y
    /// negated from LPS). The voxels then meet the surface extraction in one order whatever the
    /// file's (an LPS `.seg.nrrd` and a RAS `.nii.gz` of the same voxels, or an image stored with
    /// flipped axes, give the same surface).
    pub fn in_scanner_order(&self, ras: bool) -> VoxelMask {
        let a = &self.affine;
        let lps = |r: usize, d: usize| if ras && r < 2 { -a[r][d] } else { a[r][d] };
        // The voxel axis of each world axis: the permutation with the largest alignment.
        let permutations = [[0, 1, 2], [0, 2, 1], [1, 0, 2], [1, 2, 0], [2, 0, 1], [2, 1, 0]];
        let alignment = |p: &[usize; 3]| -> f64 {
            (0..3).map(|r| lps(r, p[r]).abs() / (0..3).map(|q| lps(q, p[r]).powi(2)).sum::<f64>().sqrt()).sum()
        };
        let perm = permutations.into_iter().max_by(|p, q| alignment(p).total_cmp(&alignment(q))).unwrap_or([0, 1, 2]);
        let flip: [bool; 3] = std::array::from_fn(|r| lps(r, perm[r]) < 0.0);
        let dims: [usize; 3] = std::array::from_fn(|r| self.dims[perm[r]]);
        // Voxel (0, 0, 0) of the new order, in the old one.
        let mut first = [0.0; 3];
        (0..3).filter(|&r| flip[r]).for_each(|r| first[perm[r]] = (self.dims[perm[r]] - 1) as f64);
        let origin = self.world(first);
        let affine = std::array::from_fn(|row| {
            std::array::from_fn(|c| match c {
                3 => origin[row],
                _ if flip[c] => -a[row][perm[c]],
                _ => a[row][perm[c]],
            })
        });
        let mut inside = vec![false; self.inside.len()];
        for k in 0..dims[2] {
            for j in 0..dims[1] {
                for i in 0..dims[0] {
                    let new = [i, j, k];
                    let mut old = [0; 3];
                    (0..3).for_each(|r| old[perm[r]] = if flip[r] { dims[r] - 1 - new[r] } else { new[r] });
                    inside[i + dims[0] * (j + dims[1] * k)] = self.inside[self.index(old[0], old[1], old[2])];
                }
            }
        }
        VoxelMask { dims, inside, affine }
    }

    /// The number of voxels inside.
    pub fn count(&self) -> usize {
        self.inside.iter().filter(|&&b| b).count()
    }

    /// The volume of one voxel (world unit cubed).
    pub fn voxel_volume(&self) -> f64 {
        determinant(&self.affine).abs()
    }

    /// The world position of voxel (i, j, k) (fractional indices allowed).
    pub fn world(&self, index: Point) -> Point {
        let a = &self.affine;
        std::array::from_fn(|r| a[r][0] * index[0] + a[r][1] * index[1] + a[r][2] * index[2] + a[r][3])
    }

    fn index(&self, i: usize, j: usize, k: usize) -> usize {
        i + self.dims[0] * (j + self.dims[1] * k)
    }

    /// The neighbours of voxel `n` inside the grid.
    fn neighbours(&self, n: usize) -> impl Iterator<Item = usize> + '_ {
        let [nx, ny, nz] = self.dims;
        let (i, j, k) = ((n % nx) as i64, ((n / nx) % ny) as i64, (n / (nx * ny)) as i64);
        NEIGHBOURS.iter().filter_map(move |d| {
            let (a, b, c) = (i + d[0], j + d[1], k + d[2]);
            let inside = a >= 0 && b >= 0 && c >= 0 && a < nx as i64 && b < ny as i64 && c < nz as i64;
            inside.then(|| self.index(a as usize, b as usize, c as usize))
        })
    }

    /// The pieces of voxels whose `inside` equals `value`, as a piece number per voxel
    /// (`usize::MAX` for the others) and each piece's size.
    fn pieces(&self, value: bool) -> (Vec<usize>, Vec<usize>) {
        let mut piece = vec![usize::MAX; self.inside.len()];
        let mut sizes = Vec::new();
        let mut queue = VecDeque::new();
        for start in 0..self.inside.len() {
            if self.inside[start] != value || piece[start] != usize::MAX {
                continue;
            }
            let id = sizes.len();
            piece[start] = id;
            queue.push_back(start);
            let mut size = 0;
            while let Some(n) = queue.pop_front() {
                size += 1;
                for m in self.neighbours(n) {
                    if self.inside[m] == value && piece[m] == usize::MAX {
                        piece[m] = id;
                        queue.push_back(m);
                    }
                }
            }
            sizes.push(size);
        }
        (piece, sizes)
    }

    /// Keeps the pieces of inside voxels of at least `min` voxels; returns the sizes of those kept
    /// and of those dropped, each largest first.
    pub fn keep_pieces_of_at_least(&mut self, min: usize) -> (Vec<usize>, Vec<usize>) {
        let (piece, sizes) = self.pieces(true);
        for (b, &p) in self.inside.iter_mut().zip(&piece) {
            *b = p != usize::MAX && sizes[p] >= min;
        }
        let (mut kept, mut dropped): (Vec<usize>, Vec<usize>) = sizes.into_iter().partition(|&n| n >= min);
        kept.sort_unstable_by(|a, b| b.cmp(a));
        dropped.sort_unstable_by(|a, b| b.cmp(a));
        (kept, dropped)
    }

    /// Keeps the largest piece of inside voxels; returns the sizes (voxels) of all pieces,
    /// largest first (empty when no voxel is inside).
    pub fn keep_largest(&mut self) -> Vec<usize> {
        let (piece, sizes) = self.pieces(true);
        let Some(largest) = (0..sizes.len()).max_by_key(|&p| (sizes[p], std::cmp::Reverse(p))) else {
            return Vec::new();
        };
        for (b, &p) in self.inside.iter_mut().zip(&piece) {
            *b = p == largest;
        }
        let mut sorted = sizes;
        sorted.sort_unstable_by(|a, b| b.cmp(a));
        sorted
    }

    /// Fills the cavities: outside voxels that no path of outside voxels joins to the grid's
    /// border. Returns the number of voxels filled.
    pub fn fill_cavities(&mut self) -> usize {
        let (piece, _) = self.pieces(false);
        let [nx, ny, nz] = self.dims;
        let mut open = vec![false; piece.len().max(1)];
        for k in 0..nz {
            for j in 0..ny {
                for i in 0..nx {
                    if i == 0 || j == 0 || k == 0 || i == nx - 1 || j == ny - 1 || k == nz - 1 {
                        let p = piece[self.index(i, j, k)];
                        if p != usize::MAX {
                            open[p] = true;
                        }
                    }
                }
            }
        }
        let mut filled = 0;
        for (b, &p) in self.inside.iter_mut().zip(&piece) {
            if p != usize::MAX && !open[p] {
                *b = true;
                filled += 1;
            }
        }
        filled
    }

    /// The face neighbours of voxel `n`, in pairs along i, j and k (`None` beyond the grid).
    fn face_neighbours(&self, n: usize) -> [[Option<usize>; 2]; 3] {
        let [nx, ny, nz] = self.dims;
        let (i, j, k) = (n % nx, (n / nx) % ny, n / (nx * ny));
        [
            [(i > 0).then(|| n - 1), (i + 1 < nx).then(|| n + 1)],
            [(j > 0).then(|| n - nx), (j + 1 < ny).then(|| n + nx)],
            [(k > 0).then(|| n - nx * ny), (k + 1 < nz).then(|| n + nx * ny)],
        ]
    }

    /// The share of the inside voxels that are one voxel thick along some axis (both face
    /// neighbours along it outside, or beyond the grid): stripes and noise, not the top slice
    /// of an organ on thick slices, whose slice below holds it.
    pub fn thin_share(&self) -> f64 {
        let outside = |m: Option<usize>| m.is_none_or(|m| !self.inside[m]);
        let thin = (0..self.inside.len())
            .into_par_iter()
            .filter(|&n| self.inside[n] && self.face_neighbours(n).iter().any(|pair| pair.iter().all(|&m| outside(m))))
            .count();
        thin as f64 / self.count().max(1) as f64
    }

    /// The mask closed by one voxel: dilated, then eroded, over the six face neighbours (voxels
    /// outside the grid count as outside; an inside voxel stays inside). A gap of one voxel
    /// between inside voxels is filled, and so are voxels that join others only by an edge or a
    /// corner (a checkerboard, a brush's dithering); the mask's outline elsewhere stays.
    pub fn closed(&self) -> VoxelMask {
        let faces = |n: usize| self.face_neighbours(n).into_iter().flatten();
        let dilated: Vec<bool> = (0..self.inside.len())
            .into_par_iter()
            .map(|n| self.inside[n] || faces(n).any(|m| m.is_some_and(|m| self.inside[m])))
            .collect();
        let inside = (0..dilated.len())
            .into_par_iter()
            .map(|n| self.inside[n] || (dilated[n] && faces(n).all(|m| m.is_some_and(|m| dilated[m]))))
            .collect();
        VoxelMask { inside, ..self.clone() }
    }

    /// The mask cut to the box of its inside voxels with `pad` outside voxels around (beyond
    /// the original grid where needed), with the voxel-to-world map moved to match. `None` when
    /// no voxel is inside.
    pub fn cropped(&self, pad: usize) -> Option<VoxelMask> {
        let [nx, ny, _] = self.dims;
        let mut lo = [usize::MAX; 3];
        let mut hi = [0usize; 3];
        for (n, _) in self.inside.iter().enumerate().filter(|(_, &b)| b) {
            let ijk = [n % nx, (n / nx) % ny, n / (nx * ny)];
            for d in 0..3 {
                lo[d] = lo[d].min(ijk[d]);
                hi[d] = hi[d].max(ijk[d]);
            }
        }
        if lo[0] == usize::MAX {
            return None;
        }
        let start: [i64; 3] = std::array::from_fn(|d| lo[d] as i64 - pad as i64);
        let dims: [usize; 3] = std::array::from_fn(|d| hi[d] - lo[d] + 1 + 2 * pad);
        let mut inside = vec![false; dims.iter().product()];
        for k in lo[2]..=hi[2] {
            for j in lo[1]..=hi[1] {
                for i in lo[0]..=hi[0] {
                    let (a, b, c) = (i + pad - lo[0], j + pad - lo[1], k + pad - lo[2]);
                    inside[a + dims[0] * (b + dims[1] * c)] = self.inside[i + nx * (j + ny * k)];
                }
            }
        }
        let shift = self.world(start.map(|s| s as f64));
        let mut affine = self.affine;
        (0..3).for_each(|r| affine[r][3] = shift[r]);
        Some(VoxelMask { dims, inside, affine })
    }
}

/// The voxels inside a triangle surface that may be broken (holes, self-intersections,
/// non-manifold or inconsistently oriented parts), in a grid of cubic voxels of side `voxel`
/// aligned with the axes around the surface.
///
/// A voxel is inside when rays through it along at least two of the three axes cross the
/// surface an odd number of times before it: a hole or a doubled part spoils the parity along
/// the rays through it, which the two other axes outvote. The grid is shifted by a fraction of a
/// voxel so that no ray runs through the vertices of a surface built on round coordinates.
/// Where shells overlap (a lobe exported as its own closed surface, crossing the rest), parity
/// sees an even number of crossings; a voxel that the surface surrounds along every axis is
/// then inside when the surface winds around it at least twice (its generalised winding number,
/// signed by the surface's enclosed volume, is at least 1.5).
pub fn voxelise_surface(surface: &TriSurface, voxel: f64) -> Result<VoxelMask, MeshError> {
    let nv = surface.vertices.len();
    if surface.triangles.is_empty() {
        return Err(MeshError::Invalid("surface has no triangles".into()));
    }
    if surface.triangles.iter().flatten().any(|&k| k >= nv) {
        return Err(MeshError::Invalid("a triangle refers to a vertex that does not exist".into()));
    }
    let used: Vec<Point> = surface.triangles.iter().flatten().map(|&k| surface.vertices[k]).collect();
    if used.iter().flatten().any(|c| !c.is_finite()) {
        return Err(MeshError::Invalid("a vertex has a non-finite coordinate".into()));
    }
    if !(voxel > 0.0 && voxel.is_finite()) {
        return Err(MeshError::Invalid(format!("voxel size must be positive, got {voxel}")));
    }
    let (lo, hi) = bounds(&used);
    const PAD: f64 = 2.0;
    const SHIFT: [f64; 3] = [0.1379, 0.2711, 0.3917];
    let origin: Point = std::array::from_fn(|d| lo[d] - (PAD + SHIFT[d]) * voxel);
    let dims: [usize; 3] = std::array::from_fn(|d| ((hi[d] - lo[d]) / voxel).ceil() as usize + 2 * PAD as usize + 2);
    if dims.iter().map(|&n| n as f64).product::<f64>() > 2e8 {
        return Err(MeshError::Invalid(format!("voxel size {voxel} is too small for the surface: {dims:?} voxels")));
    }
    let affine: [[f64; 4]; 3] = std::array::from_fn(|r| {
        std::array::from_fn(|c| {
            if c == r {
                voxel
            } else if c == 3 {
                origin[r]
            } else {
                0.0
            }
        })
    });
    let mask = VoxelMask { dims, inside: vec![false; dims.iter().product()], affine };
    // Corners in voxel units.
    let corners: Vec<[Point; 3]> = surface
        .triangles
        .iter()
        .map(|t| t.map(|k| std::array::from_fn(|d| (surface.vertices[k][d] - origin[d]) / voxel)))
        .collect();
    let mut votes = vec![0u8; mask.inside.len()];
    let mut enclosed = vec![0u8; mask.inside.len()];
    for axis in 0..3 {
        for (n, (odd, between)) in parities(&corners, dims, axis).into_iter().enumerate() {
            votes[n] += odd as u8;
            enclosed[n] += between as u8;
        }
    }
    let mut inside: Vec<bool> = votes.iter().map(|&v| v >= 2).collect();
    // Where shells overlap, parity counts two crossings: outside. The winding number (of the
    // surface as oriented, its sign taken from its volume) counts two: inside.
    let candidates: Vec<usize> = (0..inside.len()).filter(|&n| !inside[n] && enclosed[n] == 3).collect();
    if !candidates.is_empty() {
        let sign = surface.enclosed_volume().signum();
        let bvh = SurfaceBvh::new(surface)?;
        let wound: Vec<bool> = candidates
            .par_iter()
            .map(|&n| {
                let ijk = [n % dims[0], (n / dims[0]) % dims[1], n / (dims[0] * dims[1])];
                sign * bvh.winding_number(mask.world(ijk.map(|x| x as f64))) >= 1.5
            })
            .collect();
        candidates.iter().zip(wound).filter(|(_, w)| *w).for_each(|(&n, _)| inside[n] = true);
    }
    Ok(VoxelMask { inside, ..mask })
}

/// For each voxel, whether the ray along `axis` from the grid's start crosses the triangles
/// (corners in voxel units) an odd number of times before reaching it, and whether the surface
/// lies both before and after it along the ray.
fn parities(corners: &[[Point; 3]], dims: [usize; 3], axis: usize) -> Vec<(bool, bool)> {
    let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
    let (nu, nv) = (dims[u], dims[v]);
    let mut hits: Vec<Vec<f64>> = vec![Vec::new(); nu * nv];
    for p in corners {
        let q: [[f64; 2]; 3] = p.map(|c| [c[u], c[v]]);
        let area = orient(q[0], q[1], q[2]);
        if area == 0.0 {
            continue;
        }
        let (u0, u1) =
            (q.iter().map(|c| c[0]).fold(f64::MAX, f64::min), q.iter().map(|c| c[0]).fold(f64::MIN, f64::max));
        let (v0, v1) =
            (q.iter().map(|c| c[1]).fold(f64::MAX, f64::min), q.iter().map(|c| c[1]).fold(f64::MIN, f64::max));
        for a in (u0.ceil().max(0.0) as usize)..=(u1.floor().min(nu as f64 - 1.0) as usize) {
            for b in (v0.ceil().max(0.0) as usize)..=(v1.floor().min(nv as f64 - 1.0) as usize) {
                let x = [a as f64, b as f64];
                let w0 = orient(x, q[1], q[2]) / area;
                let w1 = orient(q[0], x, q[2]) / area;
                let w2 = 1.0 - w0 - w1;
                if w0 >= 0.0 && w1 >= 0.0 && w2 >= 0.0 {
                    hits[a + nu * b].push(w0 * p[0][axis] + w1 * p[1][axis] + w2 * p[2][axis]);
                }
            }
        }
    }
    let lines: Vec<Vec<(bool, bool)>> = hits
        .into_par_iter()
        .map(|mut line| {
            line.sort_unstable_by(f64::total_cmp);
            let mut crossed = 0;
            (0..dims[axis])
                .map(|s| {
                    while crossed < line.len() && line[crossed] < s as f64 {
                        crossed += 1;
                    }
                    (crossed % 2 == 1, crossed > 0 && crossed < line.len())
                })
                .collect()
        })
        .collect();
    let mut odd = vec![(false, false); dims.iter().product()];
    for (line, values) in lines.iter().enumerate() {
        let (a, b) = (line % nu, line / nu);
        for (s, &o) in values.iter().enumerate() {
            let mut ijk = [0; 3];
            ijk[axis] = s;
            ijk[u] = a;
            ijk[v] = b;
            odd[ijk[0] + dims[0] * (ijk[1] + dims[1] * ijk[2])] = o;
        }
    }
    odd
}

fn orient(a: [f64; 2], b: [f64; 2], c: [f64; 2]) -> f64 {
    (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cube_mask(n: usize, filled: impl Fn(usize, usize, usize) -> bool) -> VoxelMask {
        let mut inside = Vec::new();
        for k in 0..n {
            for j in 0..n {
                for i in 0..n {
                    inside.push(filled(i, j, k));
                }
            }
        }
        let affine = [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]];
        VoxelMask { dims: [n; 3], inside, affine }
    }

    /// Closing by a voxel fills a plane of voxels that only a checkerboard holds (they touch by
    /// edges) and a slot a voxel high, inside a block, and leaves the block's faces, edges and
    /// corners where they are, at the grid's border too.
    #[test]
    fn closing_fills_a_checkerboard_and_a_slot_and_keeps_a_block() {
        let block = |i: usize, j: usize, k: usize| (2..10).contains(&i) && (2..10).contains(&j) && (2..10).contains(&k);
        let within = |j: usize, k: usize| (3..9).contains(&j) && (3..9).contains(&k);
        let mask = cube_mask(12, |i, j, k| match i {
            5 => block(i, j, k) && !(within(j, k) && (j + k) % 2 == 1),
            _ => block(i, j, k) && !((3..9).contains(&i) && (7..9).contains(&j) && k == 6),
        });
        assert_eq!(mask.count(), 512 - 18 - 2 * 5);
        assert!(mask.closed().inside == cube_mask(12, block).inside);
        let whole = cube_mask(6, |_, _, _| true);
        assert!(whole.closed() == whole, "a mask filling its grid stays whole");
        let corner = cube_mask(6, |i, j, k| i < 3 && j < 3 && k < 3);
        assert!(corner.closed() == corner);
    }

    #[test]
    fn the_largest_piece_is_kept_and_cavities_filled() {
        // A 6³ block with a 2³ hole inside, and a lone voxel apart.
        let mut mask = cube_mask(12, |i, j, k| {
            let block = (2..8).contains(&i) && (2..8).contains(&j) && (2..8).contains(&k);
            let hole = (4..6).contains(&i) && (4..6).contains(&j) && (4..6).contains(&k);
            (block && !hole) || (i, j, k) == (10, 10, 10)
        });
        assert_eq!(mask.keep_largest(), vec![208, 1]);
        assert_eq!(mask.fill_cavities(), 8);
        assert_eq!(mask.count(), 216);
        let cropped = mask.cropped(1).unwrap();
        assert_eq!(cropped.dims, [8, 8, 8]);
        assert_eq!(cropped.count(), 216);
        assert_eq!(cropped.world([1.0, 1.0, 1.0]), [2.0, 2.0, 2.0]);
    }

    #[test]
    fn diagonal_voxels_along_the_triangulation_are_one_piece() {
        let mut along = cube_mask(4, |i, j, k| (i, j, k) == (1, 1, 1) || (i, j, k) == (2, 2, 2));
        assert_eq!(along.keep_largest(), vec![2]);
        let mut across = cube_mask(4, |i, j, k| (i, j, k) == (2, 1, 1) || (i, j, k) == (1, 2, 1));
        assert_eq!(across.keep_largest(), vec![1, 1]);
    }

    #[test]
    fn a_sphere_with_holes_is_voxelised_by_voting() {
        let sphere = crate::generate::icosphere(10.0, 3);
        let whole = voxelise_surface(&sphere, 0.5).unwrap();
        let volume = whole.count() as f64 * whole.voxel_volume();
        let exact = sphere.enclosed_volume();
        assert!((volume / exact - 1.0).abs() < 0.03, "{volume} vs {exact}");
        // Remove every 50th triangle: the rays through the holes are outvoted.
        let holed = TriSurface {
            vertices: sphere.vertices.clone(),
            triangles: sphere.triangles.iter().enumerate().filter(|(t, _)| t % 50 != 7).map(|(_, t)| *t).collect(),
        };
        let mut mask = voxelise_surface(&holed, 0.5).unwrap();
        mask.keep_largest();
        mask.fill_cavities();
        let holed_volume = mask.count() as f64 * mask.voxel_volume();
        assert!((holed_volume / volume - 1.0).abs() < 0.01, "{holed_volume} vs {volume}");
    }
}
