//! A closed surface from a voxel mask: [`mask_surface`].
//!
//! 1. The mask keeps its largest piece (an organ's; a structure's every piece, see
//!    [`ExtractOptions::every_piece`]) and its cavities are filled ([`VoxelMask`]).
//! 2. The mask, as 0 and 1 at the voxels, is averaged over blocks of 3 voxels along each axis
//!    (weights ¼, ½, ¼), which rounds the staircase of the voxels. The average is then kept on
//!    the mask's side of ½ at every voxel (at least 0.55 inside, at most 0.45 outside): a bridge
//!    or a vessel one voxel thick, which the average alone would cut or erase, stays.
//! 3. The surface at level ½ is extracted by marching tetrahedra over the grid's Kuhn
//!    triangulation (six tetrahedra per cube around its main diagonal): the level set of a
//!    piecewise-linear function at a level that no voxel takes is a closed 2-manifold, with
//!    neither the holes nor the ambiguous cases of marching cubes. Its vertices are placed on the
//!    triangulation's edges by linear interpolation (kept off the voxels themselves, so that no two
//!    coincide). The triangulation's edges join a voxel to the 14 neighbours by which the mask's
//!    pieces and cavities are found, so the surface is one closed piece, as the kept mask is.
//! 4. It is mapped to world coordinates by the mask's voxel-to-world map (anisotropic voxels
//!    included) and turned outward.
//! 5. Taubin's λ|μ smoothing (λ = 0.5, μ = −0.53) smooths it without the shrinking of plain
//!    Laplacian smoothing.
//! 6. Quadric edge collapse ([`crate::decimate::decimate`]) brings it to a number of triangles.
//! 7. Where an organ's result overlaps itself (voxels that touch by an edge or a corner only, a
//!    checkerboard, give handles thinner than the smoothing), steps 2 to 6 run again on the mask
//!    closed by a voxel ([`VoxelMask::closed`]), and the voxels that added are reported.
//!
//! An organ on a single slice, or whose voxels are mostly one voxel thick (a garbled image's
//! stripes), is refused before step 2. The result passes [`check_closed_manifold`]; an organ's
//! overlaps itself on no more triangles than a mesh allows ([`crate::tetmesh::MAX_OVERLAP_FRACTION`]).

use crate::bvh::SurfaceBvh;
use crate::decimate::decimate;
use crate::length::LengthUnit;
use crate::surface::check_closed_manifold;
use crate::volume::VoxelMask;
use crate::{cross, dot, sub, MeshError, Point, TriSurface};

/// Options of [`mask_surface`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ExtractOptions {
    /// Taubin smoothing iterations (each a λ step and a μ step; default 20).
    pub smoothing_iterations: usize,
    /// Triangles of the result, about (default 20,000); a surface with fewer is kept as it is.
    pub target_triangles: usize,
    /// A second piece of at least this fraction of the largest's voxels means the mask is not
    /// one organ: refused (default 0.2). Smaller pieces are dropped.
    pub max_second_piece: f64,
    /// Keep every piece of at least a block of 3 × 3 × 3 voxels, each a closed surface of the
    /// result, instead of the largest (default false): a structure's label may hold several
    /// (tumours of one label, a vessel tree the segmentation cut), an organ's not.
    pub every_piece: bool,
}

impl Default for ExtractOptions {
    fn default() -> Self {
        ExtractOptions { smoothing_iterations: 20, target_triangles: 20_000, max_second_piece: 0.2, every_piece: false }
    }
}

impl ExtractOptions {
    /// The options of a structure's surface: every piece kept ([`ExtractOptions::every_piece`]).
    pub fn structure() -> ExtractOptions {
        ExtractOptions { every_piece: true, ..ExtractOptions::default() }
    }
}

/// What [`mask_surface`] did.
#[derive(Clone, Debug, PartialEq)]
pub struct ExtractReport {
    /// Voxels of the pieces kept, with their cavities filled and the gaps closed when the surface
    /// was closed ([`ExtractReport::closed_voxels`]).
    pub voxels: usize,
    /// The pieces kept: one, the largest, unless [`ExtractOptions::every_piece`].
    pub pieces: usize,
    /// Sizes (voxels) of the smaller pieces dropped, largest first.
    pub dropped_pieces: Vec<usize>,
    /// Voxels of the cavities filled.
    pub filled_voxels: usize,
    /// Voxels added by closing gaps of one voxel, when the surface of the voxels as given
    /// overlapped itself (voxels that touch by an edge or a corner only: a checkerboard).
    pub closed_voxels: usize,
    /// Triangles extracted, before decimation.
    pub extracted_triangles: usize,
    /// Triangles of the result.
    pub triangles: usize,
    /// The enclosed volume of the result (world unit cubed).
    pub volume: f64,
    /// The volume of the kept voxels (world unit cubed).
    pub voxel_volume: f64,
}

impl ExtractReport {
    /// The result's enclosed volume, in mL when the world `unit` is known, and how far it lies
    /// from the kept voxels' volume: "1569.0 mL (-0.2 % from the voxels)".
    pub fn volume_text(&self, unit: Option<LengthUnit>) -> String {
        let change = 100.0 * (self.volume / self.voxel_volume - 1.0);
        // A millilitre is a cubic centimetre.
        let centimetres = |unit: LengthUnit| LengthUnit::Centimetre.from_metres(unit.metres());
        match unit {
            Some(unit) => format!("{:.1} mL ({change:+.1} % from the voxels)", self.volume * centimetres(unit).powi(3)),
            None => {
                format!("{} (the world unit cubed; {change:+.1} % from the voxels)", crate::length::number(self.volume))
            }
        }
    }

    /// The voxels of the smaller pieces dropped, as a share of the kept piece's.
    pub fn dropped_share(&self) -> f64 {
        self.dropped_pieces.iter().sum::<usize>() as f64 / self.voxels.max(1) as f64
    }

    /// What was done to the mask before extraction, one line each: the smaller pieces dropped,
    /// the cavities filled (none when neither).
    pub fn cleaning_lines(&self) -> Vec<String> {
        let mut lines = Vec::new();
        let kept = match self.pieces {
            1 => "kept the largest piece".to_string(),
            n => format!("kept its {n} pieces"),
        };
        if let Some(largest) = self.dropped_pieces.first() {
            lines.push(format!(
                "{kept}; dropped {} smaller, {:.1} % of its voxels (the largest of {largest} voxels)",
                self.dropped_pieces.len(),
                100.0 * self.dropped_share()
            ));
        } else if self.pieces > 1 {
            lines.push(kept);
        }
        if self.filled_voxels > 0 {
            lines.push(format!("filled cavities of {} voxels", self.filled_voxels));
        }
        if self.closed_voxels > 0 {
            lines.push(format!(
                "closed gaps of a voxel ({} voxels added): the surface of the voxels as given overlapped itself \
                 (voxels that touch by an edge or a corner only)",
                self.closed_voxels
            ));
        }
        lines
    }
}

/// The closed surface of a voxel mask in world coordinates (see the module's documentation).
/// An empty mask is an error.
pub fn mask_surface(mask: &VoxelMask, options: &ExtractOptions) -> Result<(TriSurface, ExtractReport), MeshError> {
    if mask.inside.len() != mask.dims.iter().product::<usize>() {
        return Err(MeshError::Invalid(format!("mask of {} voxels for a grid of {:?}", mask.inside.len(), mask.dims)));
    }
    let mut mask = mask.clone();
    let (kept, dropped) = if options.every_piece {
        mask.keep_pieces_of_at_least(MIN_VOXELS)
    } else {
        let mut sizes = mask.keep_largest();
        if let [first, second, ..] = sizes[..] {
            if second as f64 >= options.max_second_piece * first as f64 {
                let shown: Vec<String> = sizes.iter().take(5).map(|n| n.to_string()).collect();
                return Err(MeshError::Invalid(format!(
                    "several pieces of similar size ({} voxels; the second {:.0} % of the largest, {:.0} % or more): \
                     not one organ; keep the organ only, or join its pieces in the segmentation",
                    shown.join(", "),
                    100.0 * second as f64 / first as f64,
                    100.0 * options.max_second_piece
                )));
            }
        }
        let largest = if sizes.is_empty() { Vec::new() } else { vec![sizes.remove(0)] };
        (largest, sizes)
    };
    let Some(&largest) = kept.first().or(dropped.first()) else {
        return Err(MeshError::Invalid("the mask is empty: no voxel is inside".into()));
    };
    if largest < MIN_VOXELS {
        return Err(MeshError::Invalid(format!(
            "the largest piece, {largest} voxel(s), is too small to give a surface (fewer than {MIN_VOXELS}): \
             not an organ (the wrong label?)"
        )));
    }
    let voxels: usize = kept.iter().sum();
    let filled_voxels = mask.fill_cavities();
    let mask = mask.cropped(PAD).ok_or_else(|| MeshError::Invalid("the mask is empty".into()))?;
    if !options.every_piece {
        if let Some(axis) = (0..3).find(|&d| mask.dims[d] == 1 + 2 * PAD) {
            return Err(MeshError::Invalid(format!(
                "it lies on a single slice of the image (one voxel along {}): drawn on one slice, it has no volume; \
                 segment the organ on every slice it crosses",
                ["i", "j", "k"][axis]
            )));
        }
        let thin = mask.thin_share();
        if voxels >= JUDGED_VOXELS && thin > MAX_THIN_SHARE {
            return Err(MeshError::Invalid(format!(
                "its voxels do not hold together as an organ's: {:.0} % of them are one voxel thick (an organ's \
                 hardly any), as in stripes or noise; is the image's size in its header right (rows read with \
                 another length, the voxels garbled)?",
                100.0 * thin
            )));
        }
    }
    if mask.inside.len() > 400_000_000 {
        return Err(MeshError::Invalid(format!("the organ spans too many voxels ({:?})", mask.dims)));
    }
    let (mut surface, mut extracted_triangles, mut volume) = extracted(&mask, options)?;
    let mut closed_voxels = 0;
    // An organ's: a structure (a vessel tree stepping diagonally) keeps its voxels as drawn.
    if !options.every_piece && overlaps(&surface)? {
        let mut closed = mask.closed();
        closed.fill_cavities();
        let given = mask.count();
        closed_voxels = closed.count() - given;
        let added = closed_voxels as f64 / given as f64;
        if added > MAX_CLOSED_SHARE {
            return Err(MeshError::Invalid(format!(
                "the surface of the voxels overlaps itself, and closing the gaps of a voxel would add {:.0} % to \
                 them: voxels that touch by an edge or a corner only, all over (a dithered or garbled mask); smooth \
                 the segment, or check the image's size in its header",
                100.0 * added
            )));
        }
        (surface, extracted_triangles, volume) = extracted(&closed, options)?;
        if overlaps(&surface)? {
            return Err(MeshError::Invalid(
                "the surface of the voxels overlaps itself, even with gaps of a voxel closed: the segmentation's \
                 voxels join in ways no surface follows (voxels that touch by an edge or a corner only, over a \
                 large part); smooth the segment (a closing or a median filter in the segmentation editor)"
                    .into(),
            ));
        }
    }
    let report = ExtractReport {
        voxels: voxels + filled_voxels + closed_voxels,
        pieces: kept.len(),
        dropped_pieces: dropped,
        filled_voxels,
        closed_voxels,
        extracted_triangles,
        triangles: surface.triangles.len(),
        volume,
        voxel_volume: (voxels + filled_voxels + closed_voxels) as f64 * mask.voxel_volume(),
    };
    Ok((surface, report))
}

/// Steps 2 to 6 of the module's documentation on a mask cut to its voxels: the surface, the
/// triangles extracted before decimation, and the volume it encloses.
fn extracted(mask: &VoxelMask, options: &ExtractOptions) -> Result<(TriSurface, usize, f64), MeshError> {
    let surface = march(&smoothed(mask), mask.dims, 0.5);
    let extracted_triangles = surface.triangles.len();
    let mut surface = TriSurface { vertices: surface.vertices.iter().map(|&p| mask.world(p)).collect(), ..surface };
    surface.orient_outward();
    taubin_smooth(&mut surface, options.smoothing_iterations);
    let surface = decimate(&surface, options.target_triangles);
    let checked = check_closed_manifold(&surface).map_err(|e| {
        MeshError::Invalid(format!("the extracted surface is not closed and manifold: {}", e.message()))
    })?;
    Ok((surface, extracted_triangles, checked.volume))
}

/// Whether `surface` overlaps itself on more triangles than a mesh may
/// ([`crate::tetmesh::MAX_OVERLAP_FRACTION`]).
fn overlaps(surface: &TriSurface) -> Result<bool, MeshError> {
    Ok(SurfaceBvh::new(surface)?.check_winding(crate::tetmesh::MAX_OVERLAP_FRACTION).is_err())
}

/// The fewest voxels a piece needs to give a surface: a block of 3 × 3 × 3.
const MIN_VOXELS: usize = 27;

/// Outside voxels kept around the mask's box for the extraction.
const PAD: usize = 2;

/// The largest share of an organ's voxels that may be one voxel thick along some axis
/// ([`VoxelMask::thin_share`]): a liver's, a pancreas's or a gallbladder's on 5 mm slices hold
/// hardly any; stripes of a garbled image's rows, most.
pub(crate) const MAX_THIN_SHARE: f64 = 0.5;

/// The fewest voxels an organ needs for its thin voxels' share to say whether it holds together.
const JUDGED_VOXELS: usize = 10_000;

/// The largest share of voxels that closing the gaps of a voxel may add: 0.2 % across a liver cut
/// by a checkerboard plane; 61 % to a garbled image's stripes.
const MAX_CLOSED_SHARE: f64 = 0.05;

/// The mask as 0 and 1, averaged with weights ¼, ½, ¼ along each axis (zero beyond the grid),
/// then kept at least 0.55 at inside voxels and at most 0.45 at outside ones.
fn smoothed(mask: &VoxelMask) -> Vec<f32> {
    let dims = mask.dims;
    let mut field: Vec<f32> = mask.inside.iter().map(|&b| if b { 1.0 } else { 0.0 }).collect();
    let stride = [1, dims[0], dims[0] * dims[1]];
    for axis in 0..3 {
        let previous = field.clone();
        for (n, value) in field.iter_mut().enumerate() {
            let s = (n / stride[axis]) % dims[axis];
            let before = if s > 0 { previous[n - stride[axis]] } else { 0.0 };
            let after = if s + 1 < dims[axis] { previous[n + stride[axis]] } else { 0.0 };
            *value = 0.25 * before + 0.5 * previous[n] + 0.25 * after;
        }
    }
    for (value, &inside) in field.iter_mut().zip(&mask.inside) {
        *value = if inside { value.max(0.55) } else { value.min(0.45) };
    }
    field
}

/// The six tetrahedra of a cube: paths from corner (0,0,0) to (1,1,1) along the axes in each
/// order.
const ORDERS: [[usize; 3]; 6] = [[0, 1, 2], [0, 2, 1], [1, 0, 2], [1, 2, 0], [2, 0, 1], [2, 1, 0]];

/// The surface `field = level` over the Kuhn triangulation of the grid, in voxel coordinates,
/// its triangles turned towards the lower values.
fn march(field: &[f32], dims: [usize; 3], level: f32) -> TriSurface {
    let [nx, ny, nz] = dims;
    let index = |p: [usize; 3]| p[0] + nx * (p[1] + ny * p[2]);
    let mut surface = TriSurface::default();
    // The vertex on each edge of the triangulation, by its lower end and its direction.
    let mut on_edge = vec![u32::MAX; 7 * field.len()];
    for k in 0..nz.saturating_sub(1) {
        for j in 0..ny.saturating_sub(1) {
            for i in 0..nx.saturating_sub(1) {
                let corner = [i, j, k];
                let above = (0..8).filter(|c| field[index([i + (c & 1), j + (c >> 1 & 1), k + (c >> 2)])] > level);
                if matches!(above.count(), 0 | 8) {
                    continue;
                }
                for order in ORDERS {
                    let mut tet = [corner; 4];
                    for s in 0..3 {
                        tet[s + 1] = tet[s];
                        tet[s + 1][order[s]] += 1;
                    }
                    tetrahedron(&tet, field, level, &index, &mut surface, &mut on_edge);
                }
            }
        }
    }
    surface
}

/// The part of the level surface inside one tetrahedron (corners as grid points): one triangle
/// or a quadrilateral (two).
fn tetrahedron(
    tet: &[[usize; 3]; 4],
    field: &[f32],
    level: f32,
    index: &impl Fn([usize; 3]) -> usize,
    surface: &mut TriSurface,
    on_edge: &mut [u32],
) {
    let ids = tet.map(index);
    let (inside, outside): (Vec<usize>, Vec<usize>) = (0..4).partition(|&c| field[ids[c]] > level);
    let mut vertex = |a: usize, b: usize| -> usize {
        // Corners along the path from (0,0,0) to (1,1,1): the later one is above in every axis.
        let (low, high) = (a.min(b), a.max(b));
        let direction: usize = (0..3).map(|d| (tet[high][d] - tet[low][d]) << d).sum();
        let key = 7 * ids[low] + direction - 1;
        if on_edge[key] == u32::MAX {
            let (fa, fb) = (field[ids[a]] as f64, field[ids[b]] as f64);
            let t = ((level as f64 - fa) / (fb - fa)).clamp(0.02, 0.98);
            let p = std::array::from_fn(|d| tet[a][d] as f64 + t * (tet[b][d] as f64 - tet[a][d] as f64));
            on_edge[key] = surface.vertices.len() as u32;
            surface.vertices.push(p);
        }
        on_edge[key] as usize
    };
    let polygon: Vec<usize> = match (inside.len(), outside.len()) {
        (1, 3) => outside.iter().map(|&o| vertex(inside[0], o)).collect(),
        (3, 1) => inside.iter().map(|&i| vertex(i, outside[0])).collect(),
        (2, 2) => {
            let (a, b, c, d) = (inside[0], inside[1], outside[0], outside[1]);
            vec![vertex(a, c), vertex(a, d), vertex(b, d), vertex(b, c)]
        }
        _ => return,
    };
    let centre = |cs: &[usize]| -> Point {
        std::array::from_fn(|d| cs.iter().map(|&c| tet[c][d] as f64).sum::<f64>() / cs.len() as f64)
    };
    let outward = sub(centre(&outside), centre(&inside));
    let mut push = |t: [usize; 3]| {
        let [p, q, r] = t.map(|v| surface.vertices[v]);
        let facing = dot(cross(sub(q, p), sub(r, p)), outward) >= 0.0;
        surface.triangles.push(if facing { t } else { [t[0], t[2], t[1]] });
    };
    push([polygon[0], polygon[1], polygon[2]]);
    if polygon.len() == 4 {
        push([polygon[0], polygon[2], polygon[3]]);
    }
}

/// Taubin's λ|μ smoothing (λ = 0.5, μ = −0.53) with uniform weights, `iterations` times: a
/// low-pass filter that, unlike Laplacian smoothing, does not shrink the surface.
fn taubin_smooth(surface: &mut TriSurface, iterations: usize) {
    let mut neighbours: Vec<Vec<usize>> = vec![Vec::new(); surface.vertices.len()];
    for t in &surface.triangles {
        for e in 0..3 {
            let (a, b) = (t[e], t[(e + 1) % 3]);
            neighbours[a].push(b);
            neighbours[b].push(a);
        }
    }
    for n in neighbours.iter_mut() {
        n.sort_unstable();
        n.dedup();
    }
    for _ in 0..iterations {
        for factor in [0.5, -0.53] {
            let moved: Vec<Point> = surface
                .vertices
                .iter()
                .zip(&neighbours)
                .map(|(&p, around)| {
                    if around.is_empty() {
                        return p;
                    }
                    let mean: Point = std::array::from_fn(|d| {
                        around.iter().map(|&v| surface.vertices[v][d]).sum::<f64>() / around.len() as f64
                    });
                    std::array::from_fn(|d| p[d] + factor * (mean[d] - p[d]))
                })
                .collect();
            surface.vertices = moved;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::norm;
    use rand::rngs::StdRng;
    use rand::{Rng, SeedableRng};

    /// The voxels of `grid` (spacing `h`, origin `origin`) whose centres satisfy `inside`.
    fn mask(dims: [usize; 3], h: [f64; 3], origin: Point, inside: impl Fn(Point) -> bool) -> VoxelMask {
        let affine: [[f64; 4]; 3] = std::array::from_fn(|r| {
            std::array::from_fn(|c| {
                if c == r {
                    h[r]
                } else if c == 3 {
                    origin[r]
                } else {
                    0.0
                }
            })
        });
        let mut m = VoxelMask { dims, inside: Vec::new(), affine };
        for k in 0..dims[2] {
            for j in 0..dims[1] {
                for i in 0..dims[0] {
                    let p = m.world([i as f64, j as f64, k as f64]);
                    m.inside.push(inside(p));
                }
            }
        }
        m
    }

    #[test]
    fn a_voxelised_sphere_gives_back_its_volume_and_radius() {
        let (r, centre) = (12.0, [3.3, -2.1, 40.4]);
        let m = mask([40; 3], [1.0; 3], [-16.0, -22.0, 20.0], |p| norm(sub(p, centre)) <= r);
        let (s, report) = mask_surface(&m, &ExtractOptions::default()).unwrap();
        check_closed_manifold(&s).unwrap();
        let exact = 4.0 / 3.0 * std::f64::consts::PI * r.powi(3);
        let radii: Vec<f64> = s.vertices.iter().map(|&p| norm(sub(p, centre))).collect();
        let mean = radii.iter().sum::<f64>() / radii.len() as f64;
        let worst = radii.iter().map(|x| (x - r).abs()).fold(0.0, f64::max);
        let volume_error = report.volume / exact - 1.0;
        eprintln!(
            "sphere: volume {volume_error:+.4}, mean radius {mean:.3}, worst {worst:.3}, {} triangles",
            s.triangles.len()
        );
        // Within a voxel: the volume of a shell half a voxel thick, the radius within half a voxel.
        assert!((report.volume - exact).abs() < 0.5 * 4.0 * std::f64::consts::PI * r * r, "{}", report.volume);
        assert!(volume_error.abs() < 0.03, "{volume_error}");
        assert!((mean - r).abs() < 0.25 && worst < 0.5, "mean {mean}, worst {worst}");
        assert!(report.dropped_pieces.is_empty() && report.filled_voxels == 0);
    }

    #[test]
    fn an_ellipsoid_in_anisotropic_voxels_gives_back_its_volume_and_axes() {
        let axes = [40.0, 30.0, 25.0];
        let h = [0.8, 0.8, 2.5];
        let inside = |p: Point| (0..3).map(|d| (p[d] / axes[d]).powi(2)).sum::<f64>() <= 1.0;
        let m = mask([110, 85, 26], h, [-44.0, -34.0, -31.25], inside);
        let options = ExtractOptions { target_triangles: 5000, ..ExtractOptions::default() };
        let (s, report) = mask_surface(&m, &options).unwrap();
        check_closed_manifold(&s).unwrap();
        assert!(s.triangles.len() <= 5000);
        let exact = 4.0 / 3.0 * std::f64::consts::PI * axes.iter().product::<f64>();
        let volume_error = report.volume / exact - 1.0;
        let (lo, hi) = crate::bounds(&s.vertices);
        let half: Vec<f64> = (0..3).map(|d| 0.5 * (hi[d] - lo[d])).collect();
        eprintln!("ellipsoid: volume {volume_error:+.4}, semi-axes {half:?}");
        assert!(volume_error.abs() < 0.03, "{volume_error}");
        for d in 0..3 {
            assert!((half[d] - axes[d]).abs() < h[d], "axis {d}: {} vs {}", half[d], axes[d]);
        }
    }

    #[test]
    fn pieces_and_cavities_are_reported_and_an_empty_mask_or_a_speck_refused() {
        let big = |p: Point| norm(p) <= 8.0 && norm(p) > 3.0;
        let small = |p: Point| norm(sub(p, [13.0, 0.0, 0.0])) <= 2.0;
        let m = mask([36, 20, 20], [1.0; 3], [-10.0, -10.0, -10.0], |p| big(p) || small(p));
        let (s, report) = mask_surface(&m, &ExtractOptions::default()).unwrap();
        assert_eq!(report.dropped_pieces.len(), 1);
        assert!(report.filled_voxels > 100);
        // One closed surface, the cavity filled: the volume of the whole ball.
        let exact = 4.0 / 3.0 * std::f64::consts::PI * 512.0;
        assert!((check_closed_manifold(&s).unwrap().volume / exact - 1.0).abs() < 0.05);
        let empty = mask([5; 3], [1.0; 3], [0.0; 3], |_| false);
        assert!(mask_surface(&empty, &ExtractOptions::default()).unwrap_err().to_string().contains("empty"));
        let speck = mask([5; 3], [1.0; 3], [0.0; 3], |p| p == [2.0; 3]);
        let e = mask_surface(&speck, &ExtractOptions::default()).unwrap_err().to_string();
        assert!(e.contains("1 voxel(s), is too small to give a surface"), "{e}");
    }

    /// An organ drawn on a single slice is refused as having no volume; a structure there is
    /// meshed (a tumour marked on one slice).
    #[test]
    fn an_organ_on_a_single_slice_is_refused() {
        let slice = mask([30, 30, 5], [1.0, 1.0, 5.0], [-15.0, -15.0, -10.0], |p| p[2] == 0.0 && norm(p) <= 12.0);
        let e = mask_surface(&slice, &ExtractOptions::default()).unwrap_err().to_string();
        assert!(e.contains("it lies on a single slice of the image (one voxel along k)"), "{e}");
        assert!(mask_surface(&slice, &ExtractOptions::structure()).is_ok());
    }

    /// Voxels in stripes (a garbled image's rows: here plates a voxel thick, joined at one edge),
    /// nearly all one voxel thick, are refused as no organ's before any surface is extracted; a
    /// ball of as many voxels is not, nor a thin organ on thick slices (a pancreas).
    #[test]
    fn an_organ_of_stripes_is_refused() {
        let stripes = mask([40, 40, 22], [1.0; 3], [0.0; 3], |p| {
            let inside = (1.0..39.0).contains(&p[0]) && (1.0..39.0).contains(&p[1]) && (1.0..21.0).contains(&p[2]);
            inside && ((p[0] as usize).is_multiple_of(2) || p[1] == 1.0)
        });
        assert!(stripes.count() >= JUDGED_VOXELS && stripes.thin_share() > 0.95, "{}", stripes.thin_share());
        let e = mask_surface(&stripes, &ExtractOptions::default()).unwrap_err().to_string();
        assert!(e.contains("its voxels do not hold together as an organ's: 97 % of them are one voxel thick"), "{e}");
        let ball = mask([40; 3], [1.0; 3], [-20.0; 3], |p| norm(p) <= 15.0);
        assert!(ball.count() >= JUDGED_VOXELS && ball.thin_share() < 0.01, "{}", ball.thin_share());
        assert!(mask_surface(&ball, &ExtractOptions::default()).is_ok());
        // A pancreas on 5 mm slices: most of its voxels on its top or bottom slice, none thin.
        let pancreas = mask([230, 70, 8], [0.7, 0.7, 5.0], [-80.0, -24.0, -17.5], |p| {
            (p[0] / 75.0).powi(2) + (p[1] / 20.0).powi(2) + (p[2] / 12.0).powi(2) <= 1.0
        });
        assert!(pancreas.count() >= JUDGED_VOXELS && pancreas.thin_share() < 0.05, "{}", pancreas.thin_share());
        assert!(mask_surface(&pancreas, &ExtractOptions::default()).is_ok());
    }

    /// Two tumours of one label, a speck beside them: an organ's extraction refuses the label (two
    /// pieces of similar size), a structure's keeps both balls, each a closed surface, and drops
    /// the speck.
    #[test]
    fn a_structure_keeps_every_piece_an_organ_only_its_largest() {
        let ball = |p: Point, c: Point, r: f64| norm(sub(p, c)) <= r;
        let m = mask([40, 20, 20], [1.0; 3], [-10.0; 3], |p| {
            ball(p, [-3.0, 0.0, 0.0], 5.0) || ball(p, [13.0, 0.0, 0.0], 4.0) || p == [5.0, 8.0, 8.0]
        });
        let e = mask_surface(&m, &ExtractOptions::default()).unwrap_err().to_string();
        assert!(e.contains("several pieces of similar size"), "{e}");
        let (s, report) = mask_surface(&m, &ExtractOptions::structure()).unwrap();
        assert_eq!((report.pieces, report.dropped_pieces.as_slice()), (2, &[1][..]));
        assert_eq!(
            report.cleaning_lines()[0],
            "kept its 2 pieces; dropped 1 smaller, 0.1 % of its voxels (the largest of 1 voxels)"
        );
        let exact = 4.0 / 3.0 * std::f64::consts::PI * (125.0 + 64.0);
        let volume = check_closed_manifold(&s).unwrap().volume;
        // Balls of radius 4 and 5 voxels lose about a tenth to the smoothing.
        assert!((volume / exact - 1.0).abs() < 0.12, "{volume} vs {exact}");
        // Two closed surfaces, one about each centre.
        let near = |c: Point, r: f64| s.vertices.iter().filter(|&&v| norm(sub(v, c)) < r + 1.5).count();
        assert_eq!(near([-3.0, 0.0, 0.0], 5.0) + near([13.0, 0.0, 0.0], 4.0), s.vertices.len());
        assert!(near([-3.0, 0.0, 0.0], 5.0) > 0 && near([13.0, 0.0, 0.0], 4.0) > 0);
    }

    /// Two balls joined by a bridge one voxel thick, and a ball with a vessel one voxel thick,
    /// are meshed whole: the smoothing neither cuts the bridge nor erases the vessel.
    #[test]
    fn a_bridge_or_a_vessel_one_voxel_thick_is_kept() {
        let (r, h) = (6.0, 1.0);
        let ball = |p: Point, x: f64| norm(sub(p, [x, 0.0, 0.0])) <= r;
        let line = |p: Point, from: f64, to: f64| p[0] >= from && p[0] <= to && p[1] == 0.0 && p[2] == 0.0;
        let dumbbell =
            mask([40, 17, 17], [h; 3], [-10.0, -8.0, -8.0], |p| ball(p, 0.0) || ball(p, 20.0) || line(p, 0.0, 20.0));
        let (s, report) = mask_surface(&dumbbell, &ExtractOptions::default()).unwrap();
        let checked = check_closed_manifold(&s).unwrap();
        // One piece, a sphere's topology: V − E + F = 2.
        assert_eq!(checked.used_vertices + checked.triangles, checked.edges + 2, "not one piece");
        let volume = checked.volume;
        let two_balls = 2.0 * 4.0 / 3.0 * std::f64::consts::PI * r.powi(3);
        eprintln!(
            "dumbbell: volume {:+.4} from two balls, {:+.4} from the voxels",
            volume / two_balls - 1.0,
            volume / report.voxel_volume - 1.0
        );
        assert!((volume / two_balls - 1.0).abs() < 0.06, "{volume} vs {two_balls}");
        let (lo, hi) = crate::bounds(&s.vertices);
        assert!(lo[0] < -r + 1.0 && hi[0] > 20.0 + r - 1.0, "{lo:?} {hi:?}");
        let vessel = mask([40, 17, 17], [h; 3], [-10.0, -8.0, -8.0], |p| ball(p, 0.0) || line(p, 0.0, 25.0));
        let (s, _) = mask_surface(&vessel, &ExtractOptions::default()).unwrap();
        check_closed_manifold(&s).unwrap();
        let (_, hi) = crate::bounds(&s.vertices);
        assert!(hi[0] > 23.0, "the vessel ends at {}", hi[0]);
    }

    #[test]
    fn a_dithered_rim_is_closed_and_a_dithered_organ_refused() {
        // A ball of 30 voxels' radius whose outer 2 voxels are drawn at random (a dithered rim):
        // its voxels touching by an edge or a corner only make a surface that overlaps itself.
        let ball = |keep: f64| {
            let draws = std::cell::RefCell::new(StdRng::seed_from_u64(7));
            let kept = move || draws.borrow_mut().random::<f64>() < keep;
            mask([70; 3], [1.0; 3], [-35.0; 3], move |p| norm(p) <= 30.0 || (norm(p) <= 32.0 && kept()))
        };
        let rim = ball(0.7);
        let (drawn, _, _) = extracted(&rim.cropped(PAD).unwrap(), &ExtractOptions::default()).unwrap();
        assert!(overlaps(&drawn).unwrap(), "the dithered rim as drawn should overlap itself");
        // Closing the gaps of a voxel mends it, and says so.
        let (s, report) = mask_surface(&rim, &ExtractOptions::default()).unwrap();
        assert!(!overlaps(&s).unwrap());
        let checked = check_closed_manifold(&s).unwrap();
        let added = report.closed_voxels as f64 / rim.count() as f64;
        assert!(added > 0.0 && added <= MAX_CLOSED_SHARE, "closing added {added}");
        assert!(report.cleaning_lines().iter().any(|l| l.starts_with("closed gaps of a voxel")));
        // The mended surface encloses the closed voxels: between the solid ball and its rim.
        let volume = |r: f64| 4.0 / 3.0 * std::f64::consts::PI * r.powi(3);
        assert!(checked.volume > volume(30.0) && checked.volume < volume(32.5), "{}", checked.volume);
        assert!((checked.volume / report.voxel_volume - 1.0).abs() < 0.03);
        // Half the rim's voxels left out: closing would add more than an organ's gaps; refused.
        let e = mask_surface(&ball(0.5), &ExtractOptions::default()).unwrap_err().to_string();
        assert!(e.contains("overlaps itself, and closing the gaps of a voxel would add"), "{e}");
    }
}
