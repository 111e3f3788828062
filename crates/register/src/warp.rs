//! A registration as a displacement field on a regular grid, as ITK and 3D Slicer store and apply
//! transforms to images: [`WarpField`]. Applied to the preoperative CT or to its segmentations
//! (tumours, vessels), it shows them as the registration deformed them.

use rayon::prelude::*;

use mesh::{bounds, MeshLocator, Point, SurfaceBvh};

use crate::{Organ, RegisterError, Result};

/// A displacement field on a grid aligned with the axes, in metres, in the organ's frame: at grid
/// point `y`, `d(y)` such that `y + d(y)` is where that point lay in the organ at rest. This is the
/// resampling direction in which ITK and 3D Slicer store a displacement-field transform, the organ
/// at rest (the CT) being the child and the registered organ's frame the parent (under the rigid
/// alignment's transform, when there is one).
#[derive(Clone, Debug, PartialEq)]
pub struct WarpField {
    /// The position of grid point (0, 0, 0).
    pub origin: Point,
    /// The grid's step along each axis.
    pub spacing: f64,
    /// Grid points along x, y and z.
    pub dims: [usize; 3],
    /// `d` at each grid point, x fastest, then y, then z.
    pub vectors: Vec<Point>,
    /// Cells of the registered organ turned inside out (at most [`MOST_INVERTED`] of them): where
    /// they overlap their neighbours, `y + d(y)` is one of the rest positions folded there.
    pub inverted: usize,
}

/// The margin of a field's grid around the registered organ, as a share of its largest extent.
const MARGIN: f64 = 0.15;

/// Outside the organ the deformation fades over at least this many times its largest
/// displacement: fading faster, a boundary pushed in by more than the distance it fades over
/// would fold the space around it (points outside mapped behind the boundary), and the field
/// would have no inverse, which 3D Slicer needs to move models and markups with it.
const FADE_OVER_MOTION: f64 = 2.0;

/// The largest share of a registered organ's cells that may be inverted for its field to be
/// made: a learned model's prediction may fold a cell or two; more is no map of the organ.
pub const MOST_INVERTED: f64 = 0.01;

impl WarpField {
    /// The field of displacement `u` of `organ` (node-major, m), in the organ's frame (a rigid
    /// alignment is a transform of its own, above it). The grid covers the registered organ with a
    /// margin of 15 % of its largest extent on every side, or twice its largest displacement where
    /// that is more (so that it never folds), in steps of that extent and its default margins divided
    /// into `cells_across`. Inside the registered organ, `y + d(y)` is the rest position of the
    /// point (exact in linear elements: the map is affine in each); outside, the deformation at
    /// the nearest point of the organ's boundary fades linearly to nothing across the margin, so
    /// that the tissue around the organ, which the model does not hold, stays where it was; beyond
    /// the first grid step from the organ it is smoothed ([`SMOOTHING_SWEEPS`] sweeps of Laplace's
    /// equation), where the nearest boundary point jumps from one part of the organ to another. An error when more than [`MOST_INVERTED`] of the
    /// registered organ's elements are inverted (its displacement is then no map).
    pub fn of_registration(organ: &Organ, u: &[f64], cells_across: usize) -> Result<WarpField> {
        WarpField::smoothed(organ, u, cells_across, SMOOTHING_SWEEPS)
    }

    /// [`WarpField::of_registration`] with `sweeps` sweeps of [`smoothed_outside`].
    fn smoothed(organ: &Organ, u: &[f64], cells_across: usize, sweeps: usize) -> Result<WarpField> {
        let rest = organ.mesh();
        if u.len() != 3 * rest.nodes.len() {
            return Err(RegisterError::Invalid(format!(
                "a displacement of {} values for {} nodes",
                u.len(),
                rest.nodes.len()
            )));
        }
        let mut deformed = rest.clone();
        deformed.nodes.iter_mut().zip(u.chunks_exact(3)).for_each(|(p, v)| (0..3).for_each(|d| p[d] += v[d]));
        let cells = deformed.cells.len();
        let inverted = (0..cells).filter(|&c| !(deformed.cell_volume(c) > 0.0)).count();
        if inverted as f64 > MOST_INVERTED * cells as f64 {
            return Err(RegisterError::Invalid(format!(
                "{inverted} of the registered organ's {cells} cells are inverted: it is no map of the organ at rest"
            )));
        }
        let locator = MeshLocator::allowing_inverted(&deformed)?;
        let boundary = mesh::boundary_surface(&deformed);
        let bvh = SurfaceBvh::new(&boundary)?;
        let (lo, hi) = bounds(&deformed.nodes);
        let extent = mesh::longest_side((lo, hi));
        let spacing = (1.0 + 2.0 * MARGIN) * extent / cells_across.max(1) as f64;
        let most = u.chunks_exact(3).map(|v| mesh::norm([v[0], v[1], v[2]])).fold(0.0, f64::max);
        let margin = (MARGIN * extent).max(FADE_OVER_MOTION * most);
        let origin: Point = std::array::from_fn(|d| lo[d] - margin);
        let dims: [usize; 3] = std::array::from_fn(|d| ((hi[d] - lo[d] + 2.0 * margin) / spacing).ceil() as usize + 1);
        let point = |n: usize| -> Point {
            let ijk = [n % dims[0], (n / dims[0]) % dims[1], n / (dims[0] * dims[1])];
            std::array::from_fn(|d| origin[d] + spacing * ijk[d] as f64)
        };
        let (vectors, distances): (Vec<Point>, Vec<f64>) = (0..dims.iter().product::<usize>())
            .into_par_iter()
            .map(|n| {
                let z = point(n);
                let (x, distance) = match locator.locate(z) {
                    Some(location) => {
                        let mut x = [0.0; 3];
                        for (node, weight) in location.terms() {
                            (0..3).for_each(|d| x[d] += weight * rest.nodes[node][d]);
                        }
                        (x, 0.0)
                    }
                    None => {
                        // The motion of the nearest boundary point, fading away from it.
                        let closest = bvh.closest_point(z);
                        let corners = boundary.triangles[closest.triangle];
                        let weights =
                            mesh::bvh::triangle_barycentric(corners.map(|c| deformed.nodes[c]), closest.point);
                        let fade = (1.0 - closest.distance / margin).max(0.0);
                        let x = std::array::from_fn(|d| {
                            let back: f64 = (0..3).map(|k| weights[k] * u[3 * corners[k] + d]).sum();
                            z[d] - fade * back
                        });
                        (x, closest.distance)
                    }
                };
                (std::array::from_fn(|d| x[d] - z[d]), distance)
            })
            .unzip();
        // The organ and the first grid step around it hold the organ's own motion.
        let held: Vec<bool> = distances.iter().map(|&distance| distance <= spacing).collect();
        let vectors = smoothed_outside(vectors, &held, dims, sweeps);
        Ok(WarpField { origin, spacing, dims, vectors, inverted })
    }

    /// `d` at `p` by trilinear interpolation of the grid, as ITK resamples it; `None` outside the
    /// grid.
    pub fn at(&self, p: Point) -> Option<Point> {
        let mut base = [0usize; 3];
        let mut t = [0.0; 3];
        for d in 0..3 {
            let f = (p[d] - self.origin[d]) / self.spacing;
            if !(f >= 0.0 && f <= (self.dims[d] - 1) as f64) {
                return None;
            }
            base[d] = (f.floor() as usize).min(self.dims[d].saturating_sub(2));
            t[d] = f - base[d] as f64;
        }
        let mut value = [0.0; 3];
        for corner in 0..8 {
            let offset = [corner & 1, corner >> 1 & 1, corner >> 2];
            let weight: f64 = (0..3).map(|d| if offset[d] == 1 { t[d] } else { 1.0 - t[d] }).product();
            let [i, j, k]: [usize; 3] = std::array::from_fn(|d| (base[d] + offset[d]).min(self.dims[d] - 1));
            let v = self.vectors[i + self.dims[0] * (j + self.dims[1] * k)];
            (0..3).for_each(|d| value[d] += weight * v[d]);
        }
        Some(value)
    }

    /// Grid cells where the map `y ↦ y + d(y)` folds, as ITK and 3D Slicer interpolate it
    /// (trilinearly): those with a corner where its Jacobian's determinant is not positive. There
    /// the field's inverse, with which 3D Slicer moves models and markups, is ambiguous.
    pub fn folded_cells(&self) -> usize {
        let [nx, ny, nz] = self.dims;
        if nx < 2 || ny < 2 || nz < 2 {
            return 0;
        }
        let image = |i: usize, j: usize, k: usize| -> Point {
            let v = self.vectors[i + nx * (j + ny * k)];
            [self.spacing * i as f64 + v[0], self.spacing * j as f64 + v[1], self.spacing * k as f64 + v[2]]
        };
        (0..(nx - 1) * (ny - 1) * (nz - 1))
            .into_par_iter()
            .filter(|&c| {
                let (i, j, k) = (c % (nx - 1), (c / (nx - 1)) % (ny - 1), c / ((nx - 1) * (ny - 1)));
                (0..8).any(|corner| {
                    let [a, b, e] = [corner & 1, corner >> 1 & 1, corner >> 2];
                    let columns = [
                        mesh::sub(image(i + 1, j + b, k + e), image(i, j + b, k + e)),
                        mesh::sub(image(i + a, j + 1, k + e), image(i + a, j, k + e)),
                        mesh::sub(image(i + a, j + b, k + 1), image(i + a, j + b, k)),
                    ];
                    !(mesh::dot(columns[0], mesh::cross(columns[1], columns[2])) > 0.0)
                })
            })
            .count()
    }
}

/// Sweeps of Laplace smoothing over the field around the organ ([`WarpField::of_registration`]): on the shipped models'
/// registrations of `examples/cloud.csv`, the cells where the field folds fell from 3,623 (U-Net:
/// 4,276) of 820,000, up to 85 mm from the organ, to 38 (44), within 8 mm of it; more sweeps fold
/// more cells at the organ's side (50: 70), where the smoothed field falls off faster than the
/// organ moves.
pub const SMOOTHING_SWEEPS: usize = 10;

/// `vectors` (on a grid of `dims` points) smoothed off the `held` points and the grid's faces by
/// `sweeps` Jacobi sweeps of Laplace's equation: the nearest boundary point's motion jumps where
/// two parts of the boundary are equally near (across a notch, between lobes), and the field folds
/// there; the sweeps spread the jump, and leave an affine motion (a rigid one) as it is.
fn smoothed_outside(mut vectors: Vec<Point>, held: &[bool], dims: [usize; 3], sweeps: usize) -> Vec<Point> {
    let [nx, ny, nz] = dims;
    let free: Vec<usize> = (0..vectors.len())
        .filter(|&n| {
            let (i, j, k) = (n % nx, (n / nx) % ny, n / (nx * ny));
            !held[n] && i > 0 && j > 0 && k > 0 && i + 1 < nx && j + 1 < ny && k + 1 < nz
        })
        .collect();
    let strides = [1, nx, nx * ny];
    for _ in 0..sweeps {
        let next: Vec<Point> = free
            .par_iter()
            .map(|&n| {
                let mut sum = [0.0; 3];
                for stride in strides {
                    for m in [n - stride, n + stride] {
                        (0..3).for_each(|d| sum[d] += vectors[m][d]);
                    }
                }
                sum.map(|v| v / 6.0)
            })
            .collect();
        free.iter().zip(next).for_each(|(&n, v)| vectors[n] = v);
    }
    vectors
}

#[cfg(test)]
mod tests {
    use super::*;
    use mesh::norm;

    /// A cube stretched by 10 % along x and sheared: inside, the field takes every registered
    /// point back to its rest position (to rounding for this affine map, between grid points to
    /// the grid's interpolation); far outside it is nothing.
    #[test]
    fn the_field_takes_registered_points_back_to_rest() {
        let cube = mesh::box_tet([0.0; 3], [0.04; 3], [4, 4, 4]).unwrap();
        let organ = Organ::new(cube.clone(), None).unwrap();
        let motion = |p: Point| -> Point { [0.1 * p[0] + 0.05 * p[2], 0.02 * p[0], 0.0] };
        let u: Vec<f64> = cube.nodes.iter().flat_map(|&p| motion(p)).collect();
        let field = WarpField::of_registration(&organ, &u, 40).unwrap();
        // The registered cube spans 46 mm along x: 40 steps across it and its default margins.
        assert!((field.spacing - 1.3 * 0.046 / 40.0).abs() < 1e-15, "{}", field.spacing);
        let mut worst: f64 = 0.0;
        for &x in &[[0.01, 0.02, 0.03], [0.035, 0.005, 0.02], [0.02, 0.02, 0.02]] {
            let y: Point = std::array::from_fn(|d| x[d] + motion(x)[d]);
            let d = field.at(y).unwrap();
            worst = worst.max(norm(std::array::from_fn(|k| y[k] + d[k] - x[k])));
        }
        // Trilinear interpolation of an affine field is exact; the grid points themselves are
        // exact inside: what is left is rounding.
        assert!(worst < 1e-12, "{worst}");
        // Far from the organ: no deformation.
        let corner = field.origin;
        assert!(norm(field.at(corner).unwrap()) < 1e-15);
    }

    /// The smallest Jacobian determinant of the map y ↦ y + d(y) over the grid's cells (central
    /// differences at each inner grid point): positive where the field has an inverse.
    fn smallest_jacobian(field: &WarpField) -> f64 {
        let [nx, ny, nz] = field.dims;
        let at = |i: usize, j: usize, k: usize| field.vectors[i + nx * (j + ny * k)];
        let mut smallest = f64::INFINITY;
        for k in 1..nz - 1 {
            for j in 1..ny - 1 {
                for i in 1..nx - 1 {
                    let pairs = [
                        (at(i + 1, j, k), at(i - 1, j, k)),
                        (at(i, j + 1, k), at(i, j - 1, k)),
                        (at(i, j, k + 1), at(i, j, k - 1)),
                    ];
                    let g: [[f64; 3]; 3] = std::array::from_fn(|r| {
                        std::array::from_fn(|c| {
                            f64::from(u8::from(r == c)) + (pairs[c].0[r] - pairs[c].1[r]) / (2.0 * field.spacing)
                        })
                    });
                    let det = g[0][0] * (g[1][1] * g[2][2] - g[1][2] * g[2][1])
                        - g[0][1] * (g[1][0] * g[2][2] - g[1][2] * g[2][0])
                        + g[0][2] * (g[1][0] * g[2][1] - g[1][1] * g[2][0]);
                    smallest = smallest.min(det);
                }
            }
        }
        smallest
    }

    /// A face pushed in by a quarter of the organ's size, more than the default margin (15 %):
    /// the space outside it, fading over twice the push, does not fold.
    #[test]
    fn a_deep_push_leaves_a_field_without_folds() {
        let cube = mesh::box_tet([0.0; 3], [0.04; 3], [6, 6, 6]).unwrap();
        let organ = Organ::new(cube.clone(), None).unwrap();
        let u: Vec<f64> = cube.nodes.iter().flat_map(|&p| [-0.25 * p[0], 0.0, 0.0]).collect();
        let field = WarpField::of_registration(&organ, &u, 40).unwrap();
        let det = smallest_jacobian(&field);
        assert!(det > 0.3, "the field folds: Jacobian down to {det}");
        assert!((field.spacing - 1.3 * 0.04 / 40.0).abs() < 1e-15, "the step is kept: {}", field.spacing);
    }

    /// A U whose arms move apart: in the notch between them the nearest boundary point jumps from
    /// one arm to the other, and the field of the nearest point's motion folds along the notch's
    /// middle; smoothed, it does not, and the organ's own motion is kept.
    #[test]
    fn the_field_does_not_fold_between_arms_moving_apart() {
        let block = mesh::box_tet([0.0; 3], [0.07, 0.02, 0.04], [7, 2, 4]).unwrap();
        let notch: Vec<usize> = (0..block.cells.len())
            .filter(|&c| {
                let corners = block.cells.cell(c);
                let centre = |d: usize| corners.iter().map(|&n| block.nodes[n][d]).sum::<f64>() / corners.len() as f64;
                centre(0) > 0.03 && centre(0) < 0.04 && centre(2) > 0.01
            })
            .collect();
        let u_shape = block.without_cells(&notch).unwrap();
        let organ = Organ::new(u_shape.clone(), None).unwrap();
        // The arms spread from the base: 5 mm at the top of each arm's inner face.
        let u: Vec<f64> = u_shape.nodes.iter().flat_map(|&p| [(p[0] - 0.035) * p[2] / 0.04, 0.0, 0.0]).collect();
        let nearest = WarpField::smoothed(&organ, &u, 40, 0).unwrap();
        assert!(nearest.folded_cells() > 0, "the nearest point's motion does not fold");
        let field = WarpField::of_registration(&organ, &u, 40).unwrap();
        assert_eq!(field.folded_cells(), 0, "the smoothed field folds");
        // Inside an arm, the organ's motion, to the grid's interpolation of it.
        let x = [0.01, 0.01, 0.03];
        let y: Point = std::array::from_fn(|d| x[d] + u_at(&u_shape, &u, x)[d]);
        let d = field.at(y).unwrap();
        let error = norm(std::array::from_fn(|k| y[k] + d[k] - x[k]));
        assert!(error < 1e-5, "{error}");
    }

    /// The displacement `u` at the node of `mesh` at `x`.
    fn u_at(mesh: &mesh::Mesh, u: &[f64], x: Point) -> Point {
        let node = mesh.nodes.iter().position(|p| norm(std::array::from_fn(|d| p[d] - x[d])) < 1e-9).unwrap();
        [u[3 * node], u[3 * node + 1], u[3 * node + 2]]
    }

    /// An inverted organ has no field.
    #[test]
    fn an_inverted_organ_is_refused() {
        let cube = mesh::box_tet([0.0; 3], [0.04; 3], [2, 2, 2]).unwrap();
        let organ = Organ::new(cube.clone(), None).unwrap();
        let u: Vec<f64> = cube.nodes.iter().flat_map(|&p| [-2.0 * p[0], 0.0, 0.0]).collect();
        let e = WarpField::of_registration(&organ, &u, 10).unwrap_err().to_string();
        assert!(e.contains("48 of the registered organ's 48 cells are inverted"), "{e}");
    }

    /// A fold of a few cells (one inner node pushed past its neighbours, as a learned model's
    /// prediction may do) leaves the field exact away from it, and is counted.
    #[test]
    fn a_local_fold_is_counted_and_the_field_exact_elsewhere() {
        let cube = mesh::box_tet([0.0; 3], [0.04; 3], [8, 8, 8]).unwrap();
        let organ = Organ::new(cube.clone(), None).unwrap();
        let motion = |p: Point| -> Point { [0.1 * p[0], 0.0, 0.05 * p[1]] };
        let mut u: Vec<f64> = cube.nodes.iter().flat_map(|&p| motion(p)).collect();
        let centre = cube.nodes.iter().position(|p| norm(std::array::from_fn(|d| p[d] - 0.02)) < 1e-9).unwrap();
        u[3 * centre] += 0.008;
        let field = WarpField::of_registration(&organ, &u, 40).unwrap();
        assert!(field.inverted > 0 && field.inverted <= 24, "{} inverted", field.inverted);
        let x = [0.006, 0.005, 0.034];
        let y: Point = std::array::from_fn(|d| x[d] + motion(x)[d]);
        let d = field.at(y).unwrap();
        assert!(norm(std::array::from_fn(|k| y[k] + d[k] - x[k])) < 1e-12);
    }
}
