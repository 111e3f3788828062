//! Tetrahedral meshing of a closed surface or an implicit (signed distance)
//! domain by isosurface stuffing (Labelle & Shewchuk, "Isosurface Stuffing:
//! Fast Tetrahedral Meshes with Good Dihedral Angles", SIGGRAPH 2007).
//!
//! The domain {f < 0} is covered by a body-centred cubic (BCC) lattice of
//! spacing `size`: the corners of cubes of side `size` plus the cube centres.
//! Axis-parallel lattice edges (length `size`) are *black*, the edges from a
//! corner to a neighbouring centre (length √3/2·`size`) are *red*; each BCC
//! tetrahedron has two black and four red edges. The algorithm:
//!
//! 1. evaluates f at every lattice vertex;
//! 2. puts a *cut point* on the boundary on every lattice edge whose ends have
//!    strictly opposite signs ([`ImplicitDomain::boundary_point`]: root finding
//!    on f, or the exact segment–triangle intersection for a surface), so every
//!    boundary vertex of the mesh lies on the surface;
//! 3. *warps*: a lattice vertex closer to a cut point on one of its edges than
//!    α·(edge length) (α_long = 0.24999 for black, α_short = 0.41189 for red
//!    edges, the paper's values) moves onto the nearest such cut point and its
//!    value becomes zero; the cut points on its other edges disappear. Vertices
//!    are visited in index order and only cut points that still exist count;
//! 4. fills every BCC tetrahedron with at least one inside vertex using the
//!    paper's stencils. Quadrilateral faces of the stencils are split
//!    consistently across neighbouring BCC tetrahedra: when the face's black
//!    edge carries a cut point, along the diagonal from that cut point; when
//!    the black edge joins the two inside vertices, by the parity rule (around
//!    each black edge the diagonal alternates between its two endpoints from
//!    one face to the next). The inner quadrilateral of the two-in/two-out
//!    stencil takes the diagonal that makes the prism triangulable.
//!
//! With cut points on the lattice edges the paper proves dihedral angles
//! between 10.7° and 164.8° (measured here: 11–19° minimum on the SOFA
//! liver, 22–37° on a sphere). Each output tetrahedron is oriented in the
//! unwarped reference geometry (where it is a non-degenerate part of its BCC
//! tetrahedron) and must keep a positive volume after warping; an inverted one
//! is reported as an error rather than silently flipped. Where the domain is
//! thinner than the element size, two parts of the boundary can touch along
//! an edge (the mesh stays conforming: one such edge in the SOFA liver at
//! 5,000 elements, none at 18,000).
//!
//! Boundary faces are chords of the surface, so with the boundary nodes on
//! the surface the mesh volume falls short of the enclosed volume by about
//! (size / radius of curvature)²: −1.9% for the SOFA liver (0.2 m) at 5,800
//! elements, −0.9% at 15,800. [`BoundaryFit::VolumePreserving`] (the
//! default) then moves the boundary nodes outward by the mean chord depth,
//! which brings the error to about −0.1% at 5,800 elements; [`TetQuality`]
//! reports it.

use std::fmt;

use rayon::prelude::*;

use crate::bvh::SurfaceBvh;
use crate::surface::check_closed_manifold;
use crate::topology::{face_connected_pieces, root};
use crate::{cross, dihedral_angles, dot, sub, Cells, Mesh, MeshError, Point, TriSurface, MAX_CELLS};

/// Warp threshold for black (axis-parallel) lattice edges, from the paper.
pub const ALPHA_LONG: f64 = 0.24999;
/// Warp threshold for red (diagonal) lattice edges, from the paper.
pub const ALPHA_SHORT: f64 = 0.41189;

/// A region of space {p : value(p) < 0}, for meshing and inside tests.
pub trait ImplicitDomain: Sync {
    /// Negative inside, positive outside, zero on the boundary. A signed
    /// distance is best; any continuous function with that zero set and those
    /// signs works.
    fn value(&self, p: Point) -> f64;

    /// An axis-aligned box (min, max) containing the whole domain.
    fn bounds(&self) -> (Point, Point);

    /// A boundary point on the segment [a, b], whose end values `fa`, `fb`
    /// have strictly opposite signs. The default finds a root of
    /// [`ImplicitDomain::value`] along the segment (Illinois method, to 1e-10
    /// of the segment length).
    fn boundary_point(&self, a: Point, fa: f64, b: Point, fb: f64) -> Point {
        segment_root(|p| self.value(p), a, fa, b, fb)
    }

    /// True when `p` is inside (value < 0).
    fn contains(&self, p: Point) -> bool {
        self.value(p) < 0.0
    }

    /// The value [`stuff`] uses at lattice vertices, where only its sign
    /// matters (a cheaper sign-only evaluation may override it). Defaults to
    /// [`ImplicitDomain::value`].
    fn lattice_value(&self, p: Point) -> f64 {
        self.value(p)
    }

    /// A bound L on the slope of [`ImplicitDomain::value`] (|value(p) −
    /// value(q)| ≤ L·|p − q|; 1 for a signed distance), when known: then a
    /// point with |value| > L·r is at least r from the boundary. `None`
    /// (the default) promises nothing.
    fn lipschitz(&self) -> Option<f64> {
        None
    }

    /// Signed distance from `m` to the boundary along the unit vector `n`
    /// (positive when the boundary lies on the +n side), searched within
    /// ±`range`; zero when no boundary is found there. The default searches
    /// on the side given by the sign at `m`.
    fn boundary_offset(&self, m: Point, n: Point, range: f64) -> f64 {
        let f0 = self.lattice_value(m);
        if f0 == 0.0 {
            return 0.0;
        }
        let dir = if f0 < 0.0 { range } else { -range };
        let e: Point = std::array::from_fn(|d| m[d] + dir * n[d]);
        let fe = self.lattice_value(e);
        if fe == 0.0 {
            return dir;
        }
        if (fe < 0.0) == (f0 < 0.0) {
            return 0.0;
        }
        let c = self.boundary_point(m, f0, e, fe);
        dot(sub(c, m), n)
    }
}

/// A root of `f` on the segment [a, b] with f(a) = fa and f(b) = fb of
/// opposite signs, by the Illinois variant of regula falsi.
pub fn segment_root(f: impl Fn(Point) -> f64, a: Point, fa: f64, b: Point, fb: f64) -> Point {
    let at = |t: f64| -> Point { std::array::from_fn(|d| a[d] + t * (b[d] - a[d])) };
    let (mut t0, mut f0, mut t1, mut f1) = (0.0f64, fa, 1.0f64, fb);
    let mut side = 0i8;
    let mut t = 0.5;
    for _ in 0..100 {
        t = if f0 != f1 { (t0 * f1 - t1 * f0) / (f1 - f0) } else { 0.5 * (t0 + t1) };
        if !(t > t0.min(t1) && t < t0.max(t1)) {
            t = 0.5 * (t0 + t1);
        }
        let ft = f(at(t));
        if ft == 0.0 || (t1 - t0).abs() < 1e-10 {
            break;
        }
        if (ft < 0.0) == (f0 < 0.0) {
            t0 = t;
            f0 = ft;
            if side == -1 {
                f1 *= 0.5;
            }
            side = -1;
        } else {
            t1 = t;
            f1 = ft;
            if side == 1 {
                f0 *= 0.5;
            }
            side = 1;
        }
    }
    at(t)
}

/// An implicit domain given by a closure (e.g. an analytic signed distance)
/// and a bounding box.
pub struct SdfDomain<F> {
    f: F,
    lo: Point,
    hi: Point,
}

impl<F: Fn(Point) -> f64 + Sync> SdfDomain<F> {
    /// The domain {p : f(p) < 0} inside the box [lo, hi].
    pub fn new(f: F, lo: Point, hi: Point) -> Self {
        SdfDomain { f, lo, hi }
    }
}

impl<F: Fn(Point) -> f64 + Sync> ImplicitDomain for SdfDomain<F> {
    fn value(&self, p: Point) -> f64 {
        (self.f)(p)
    }
    fn bounds(&self) -> (Point, Point) {
        (self.lo, self.hi)
    }
}

/// A closed, outward-oriented surface as a domain: value = signed distance,
/// boundary points = exact segment–triangle intersections.
impl ImplicitDomain for SurfaceBvh {
    fn value(&self, p: Point) -> f64 {
        self.signed_distance(p)
    }
    fn bounds(&self) -> (Point, Point) {
        SurfaceBvh::bounds(self)
    }
    fn boundary_point(&self, a: Point, fa: f64, b: Point, fb: f64) -> Point {
        // Of the crossings, the one nearest the middle of the segment.
        let hits = self.segment_hits(a, b);
        match hits.iter().min_by(|x, y| (**x - 0.5).abs().total_cmp(&(**y - 0.5).abs())) {
            Some(&t) => std::array::from_fn(|d| a[d] + t * (b[d] - a[d])),
            None => segment_root(|p| self.signed_distance(p), a, fa, b, fb),
        }
    }
    fn contains(&self, p: Point) -> bool {
        self.is_inside(p)
    }
    fn lattice_value(&self, p: Point) -> f64 {
        if self.is_inside(p) {
            -1.0
        } else {
            1.0
        }
    }
    fn lipschitz(&self) -> Option<f64> {
        Some(1.0)
    }
    fn boundary_offset(&self, m: Point, n: Point, range: f64) -> f64 {
        // The crossing of the line m ± range·n nearest to m.
        let a: Point = std::array::from_fn(|d| m[d] - range * n[d]);
        let b: Point = std::array::from_fn(|d| m[d] + range * n[d]);
        let hits = self.segment_hits(a, b);
        hits.iter().map(|&t| (2.0 * t - 1.0) * range).min_by(|x, y| x.abs().total_cmp(&y.abs())).unwrap_or(0.0)
    }
}

/// Where the boundary nodes of a stuffed mesh are put.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum BoundaryFit {
    /// Exactly on the boundary of the domain (the cut points). The boundary
    /// faces are chords, so the mesh volume falls short of the domain's by
    /// about (size / curvature radius)²: 1% needs about five elements across
    /// a sphere's radius (~7,000 elements for a sphere, ~15,000 for the SOFA
    /// liver).
    OnSurface,
    /// Each boundary node is then moved outward along its normal by the
    /// area-weighted mean depth of the surface above its chord faces (the
    /// depth measured at edge midpoints, exact for a quadratic surface), so
    /// that the faces straddle the surface and the volume matches the
    /// domain's to second order. Boundary nodes end up off the surface by
    /// about a third of the chord sagitta (a fraction of a millimetre for a
    /// liver at 5,000 elements). A move that would shrink an element below a
    /// fifth of its volume is halved, up to four times, then dropped.
    /// The default: it keeps the volume within 0.3% at 2,000 elements.
    #[default]
    VolumePreserving,
}

/// Parameters of [`stuff`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TetMeshOptions {
    /// Lattice spacing h (m): the length of the black lattice edges. Interior
    /// elements have edges of h and √3/2·h; a region of volume V gets about
    /// 12·V/h³ elements plus the boundary layer.
    pub size: f64,
    /// Warp threshold for black edges (paper: 0.24999).
    pub alpha_long: f64,
    /// Warp threshold for red edges (paper: 0.41189).
    pub alpha_short: f64,
    /// Placement of the boundary nodes.
    pub fit: BoundaryFit,
}

impl TetMeshOptions {
    /// Options with lattice spacing `size` (m), the paper's thresholds and
    /// the default boundary fit ([`BoundaryFit::VolumePreserving`]).
    pub fn with_size(size: f64) -> Self {
        TetMeshOptions { size, alpha_long: ALPHA_LONG, alpha_short: ALPHA_SHORT, fit: BoundaryFit::default() }
    }

    /// The same options with boundary placement `fit`.
    pub fn with_fit(self, fit: BoundaryFit) -> Self {
        TetMeshOptions { fit, ..self }
    }
}

/// Lattice spacing that gives about `count` elements for a volume `volume`
/// (12 BCC tetrahedra per cube of side h, boundary layer ignored).
fn size_for_count(volume: f64, count: usize) -> f64 {
    (12.0 * volume / count.max(1) as f64).cbrt()
}

/// Quality measures of a tetrahedral mesh.
#[derive(Clone, Debug, PartialEq)]
pub struct TetQuality {
    /// Number of tetrahedra.
    pub elements: usize,
    /// Number of nodes.
    pub nodes: usize,
    /// Smallest dihedral angle (degrees).
    pub min_dihedral_deg: f64,
    /// Largest dihedral angle (degrees).
    pub max_dihedral_deg: f64,
    /// Number of tetrahedra with non-positive volume.
    pub inverted: usize,
    /// Total mesh volume (m³).
    pub volume: f64,
    /// Volume of the meshed domain where known (e.g. a surface's enclosed volume).
    pub reference_volume: Option<f64>,
    /// (volume − reference) / reference, where the reference is known.
    pub relative_volume_error: Option<f64>,
    /// Pieces of tetrahedra joined through faces ([`face_connected_pieces`]): 1 for a mesh in one
    /// piece; more when a part hangs on the rest by an edge or a vertex only.
    pub pieces: usize,
    /// How much of the meshed surface the mesh covers, when meshed from one
    /// ([`mesh_surface`], [`mesh_surface_to_count`]).
    pub coverage: Option<Coverage>,
}

impl fmt::Display for TetQuality {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{} tetrahedra, {} nodes, dihedral angles {:.1}°..{:.1}°, {} inverted, volume {:.4e} m³",
            self.elements, self.nodes, self.min_dihedral_deg, self.max_dihedral_deg, self.inverted, self.volume
        )?;
        if self.pieces > 1 {
            write!(f, ", in {} pieces joined only by edges or vertices", self.pieces)?;
        }
        if let (Some(r), Some(e)) = (self.reference_volume, self.relative_volume_error) {
            write!(f, " (reference {r:.4e} m³, error {:+.3}%)", 100.0 * e)?;
        }
        if let Some(c) = self.coverage.filter(|c| c.uncovered > 0.0) {
            write!(f, ", {:.1}% of the surface farther than {:.4} m from it", 100.0 * c.uncovered, c.distance)?;
        }
        Ok(())
    }
}

/// Element count, node count, dihedral angle range, inverted elements and
/// volume of a T4 mesh, compared with `reference_volume` when given.
pub fn tet_quality(mesh: &Mesh, reference_volume: Option<f64>) -> Result<TetQuality, MeshError> {
    let Cells::Tet4(tets) = &mesh.cells else {
        return Err(MeshError::Invalid(format!("tet_quality needs a T4 mesh, got {}", mesh.cells.kind_name())));
    };
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    let mut volume = 0.0;
    let mut inverted = 0;
    for t in tets {
        let p = t.map(|k| mesh.nodes[k]);
        let v = crate::tet_volume(p[0], p[1], p[2], p[3]);
        volume += v;
        if !(v > 0.0) {
            inverted += 1;
        }
        for a in dihedral_angles(p) {
            lo = lo.min(a);
            hi = hi.max(a);
        }
    }
    let relative_volume_error = reference_volume.map(|r| (volume - r) / r);
    Ok(TetQuality {
        elements: tets.len(),
        nodes: mesh.num_nodes(),
        min_dihedral_deg: lo.to_degrees(),
        max_dihedral_deg: hi.to_degrees(),
        inverted,
        volume,
        reference_volume,
        relative_volume_error,
        pieces: face_connected_pieces(mesh).len(),
        coverage: None,
    })
}

/// Meshes a closed surface: checks that it is a closed manifold
/// ([`check_closed_manifold`]) that overlaps itself at most near 1% of its
/// triangles ([`SurfaceBvh::check_winding`]; small folds, as in some scanned
/// organ surfaces, are tolerated and count as inside), orients it outward,
/// and stuffs it with
/// lattice spacing `opts.size`. The quality report compares the mesh volume
/// with the enclosed volume.
pub fn mesh_surface(surface: &TriSurface, opts: &TetMeshOptions) -> Result<(Mesh, TetQuality), MeshError> {
    let (bvh, volume) = surface_domain(surface)?;
    let mesh = stuff(&bvh, opts)?;
    let quality = TetQuality { coverage: Some(surface_coverage(&mesh, surface)?), ..tet_quality(&mesh, Some(volume))? };
    Ok((mesh, quality))
}

/// Like [`mesh_surface`] but choosing the lattice spacing so that the mesh
/// has about `target` tetrahedra (see [`stuff_to_count`]).
pub fn mesh_surface_to_count(
    surface: &TriSurface,
    target: usize,
    fit: BoundaryFit,
) -> Result<(Mesh, TetQuality), MeshError> {
    let (bvh, volume) = surface_domain(surface)?;
    let mesh = stuff_to_count(&bvh, target, Some(volume), fit)?;
    let quality = TetQuality { coverage: Some(surface_coverage(&mesh, surface)?), ..tet_quality(&mesh, Some(volume))? };
    Ok((mesh, quality))
}

/// Largest fraction of self-overlapping triangles a surface may have to be meshed.
pub const MAX_OVERLAP_FRACTION: f64 = 0.01;

/// Validates a surface for meshing and returns its BVH (over an outward
/// oriented copy) and its enclosed volume.
pub fn surface_domain(surface: &TriSurface) -> Result<(SurfaceBvh, f64), MeshError> {
    check_closed_manifold(surface)?;
    let mut s = surface.clone();
    s.orient_outward();
    let bvh = SurfaceBvh::new(&s)?;
    bvh.check_winding(MAX_OVERLAP_FRACTION)?;
    Ok((bvh, s.enclosed_volume()))
}

/// Most lattice cubes over a domain's bounding box per tetrahedron asked for: an organ's box holds
/// about a third of a cube per tetrahedron (12 tetrahedra a cube of its volume, 3 to 4 times its
/// volume in its box); 50 lets through a domain 600 times smaller than its box (a curved vessel),
/// not a sheet a voxel thick, whose lattice would fill the memory.
const LATTICE_PER_TET: f64 = 50.0;

/// Stuffs `domain` with lattice spacings chosen so that the mesh has about
/// `target` tetrahedra: a first guess from `volume` (or half the bounding
/// box), then secant steps on log(count) against log(size), at most six
/// meshings; returns the mesh whose count is nearest the target (within 2%
/// it stops early), one in one piece when one is within [`PIECE_SLACK`] of the
/// target (a lattice a little finer or coarser, up to [`PIECE_TRIES`] more, is
/// tried for one when none is). Boundary nodes are placed by `fit`. Deterministic.
pub fn stuff_to_count(
    domain: &dyn ImplicitDomain,
    target: usize,
    volume: Option<f64>,
    fit: BoundaryFit,
) -> Result<Mesh, MeshError> {
    if target < 10 {
        return Err(MeshError::Invalid(format!("target element count {target} is too small (at least 10)")));
    }
    if target > MAX_CELLS {
        return Err(MeshError::Invalid(format!(
            "target element count {target} is too large (at most {MAX_CELLS}: meshing takes about 600 bytes a \
             tetrahedron, a FEM on them many times more)"
        )));
    }
    let (lo, hi) = domain.bounds();
    let size = sub(hi, lo);
    let bounding = size[0] * size[1] * size[2];
    let vol = volume.unwrap_or(0.5 * bounding);
    let mut h = size_for_count(vol, target);
    let mut best: Option<(Mesh, f64)> = None;
    let mut whole: Option<Mesh> = None;
    let mut prev: Option<(f64, f64)> = None; // (ln h, ln count)
    let miss = |mesh: &Mesh| (mesh.cells.len().max(1) as f64 / target as f64).ln().abs();
    let near = |mesh: &Mesh| miss(mesh) <= PIECE_SLACK.ln_1p();
    let keep_whole = |mesh: &Mesh, whole: &mut Option<Mesh>| {
        if face_connected_pieces(mesh).len() == 1 && whole.as_ref().is_none_or(|w| miss(mesh) < miss(w)) {
            *whole = Some(mesh.clone());
        }
    };
    for _ in 0..6 {
        let cubes = bounding / (h * h * h);
        if cubes > LATTICE_PER_TET * target as f64 {
            return Err(MeshError::Invalid(format!(
                "the surface encloses {vol:.3e} m³, {:.0} times less than its bounding box ({bounding:.3e} m³): too \
                 thin or flat to fill with {target} tetrahedra (it would take a lattice of {cubes:.1e} cubes); a \
                 segment a voxel or two thick (a sheet, a line) has no volume to mesh",
                bounding / vol
            )));
        }
        let mesh = stuff(domain, &TetMeshOptions::with_size(h).with_fit(fit))?;
        let n = mesh.cells.len().max(1) as f64;
        let err = miss(&mesh);
        keep_whole(&mesh, &mut whole);
        if best.as_ref().is_none_or(|b| err < miss(&b.0)) {
            best = Some((mesh, h));
        }
        if err < 0.02 {
            break;
        }
        // Slope d ln n / d ln h: −3 in theory, measured once two meshes exist.
        let slope = match prev {
            Some((lh, ln)) if (h.ln() - lh).abs() > 1e-9 => ((n.ln() - ln) / (h.ln() - lh)).clamp(-6.0, -1.5),
            _ => -3.0,
        };
        prev = Some((h.ln(), n.ln()));
        h = (h.ln() + ((target as f64).ln() - n.ln()) / slope).exp();
    }
    let (best, h_best) = best.ok_or_else(|| MeshError::Invalid("stuffing produced no mesh".into()))?;
    if !whole.as_ref().is_some_and(near) {
        // Pieces joined by a vertex only (a neck thinner than the lattice) come and go with the
        // lattice's size: a few sizes about the best's.
        for k in 1..=PIECE_TRIES {
            let step = 1.0 + 0.02 * k.div_ceil(2) as f64;
            let size = if k % 2 == 1 { h_best * step } else { h_best / step };
            let mesh = stuff(domain, &TetMeshOptions::with_size(size).with_fit(fit))?;
            keep_whole(&mesh, &mut whole);
            if whole.as_ref().is_some_and(near) {
                break;
            }
        }
    }
    Ok(whole.filter(near).unwrap_or(best))
}

/// How far (a share of the count asked for) a mesh in one piece may miss it to be taken before
/// a nearer one in several ([`stuff_to_count`]).
pub const PIECE_SLACK: f64 = 0.1;

/// Lattices tried about the best one when no mesh in one piece is within [`PIECE_SLACK`] of the
/// count asked for ([`stuff_to_count`]).
pub const PIECE_TRIES: usize = 4;

/// The BCC lattice: corner vertices (nx+1)(ny+1)(nz+1) then centre vertices
/// nx·ny·nz. Doubled integer coordinates: corners at 2(i, j, k), centres at
/// 2(i, j, k) + 1; position = origin + h/2 · doubled.
struct Lattice {
    origin: Point,
    h: f64,
    n: [usize; 3],
    num_corners: usize,
}

impl Lattice {
    fn num_vertices(&self) -> usize {
        self.num_corners + self.n[0] * self.n[1] * self.n[2]
    }
    fn corner(&self, i: usize, j: usize, k: usize) -> u32 {
        (i + (self.n[0] + 1) * (j + (self.n[1] + 1) * k)) as u32
    }
    fn centre(&self, i: usize, j: usize, k: usize) -> u32 {
        (self.num_corners + i + self.n[0] * (j + self.n[1] * k)) as u32
    }
    fn doubled(&self, v: u32) -> [i64; 3] {
        let v = v as usize;
        if v < self.num_corners {
            let (nx, ny) = (self.n[0] + 1, self.n[1] + 1);
            [2 * (v % nx) as i64, 2 * ((v / nx) % ny) as i64, 2 * (v / (nx * ny)) as i64]
        } else {
            let w = v - self.num_corners;
            let (nx, ny) = (self.n[0], self.n[1]);
            [2 * (w % nx) as i64 + 1, 2 * ((w / nx) % ny) as i64 + 1, 2 * (w / (nx * ny)) as i64 + 1]
        }
    }
    fn at_doubled(&self, d: [i64; 3]) -> Option<u32> {
        if d[0] % 2 == 0 {
            let c = [d[0] / 2, d[1] / 2, d[2] / 2];
            ((0..3).all(|a| c[a] >= 0 && c[a] <= self.n[a] as i64))
                .then(|| self.corner(c[0] as usize, c[1] as usize, c[2] as usize))
        } else {
            let c = [(d[0] - 1) / 2, (d[1] - 1) / 2, (d[2] - 1) / 2];
            ((0..3).all(|a| d[a] >= 1 && c[a] < self.n[a] as i64))
                .then(|| self.centre(c[0] as usize, c[1] as usize, c[2] as usize))
        }
    }
    fn position(&self, v: u32) -> Point {
        let d = self.doubled(v);
        std::array::from_fn(|a| self.origin[a] + 0.5 * self.h * d[a] as f64)
    }
}

/// Black edges join vertices of the same grid (both corners or both centres).
fn is_black(l: &Lattice, u: u32, v: u32) -> bool {
    ((u as usize) < l.num_corners) == ((v as usize) < l.num_corners)
}

/// A cut point: the boundary point on lattice edge (u, v).
struct Cut {
    u: u32,
    v: u32,
    point: Point,
}

/// Meshes `domain` by isosurface stuffing with lattice spacing `opts.size`
/// (see the module documentation). All elements are positively oriented and
/// every boundary node lies on the boundary of the domain.
pub fn stuff(domain: &dyn ImplicitDomain, opts: &TetMeshOptions) -> Result<Mesh, MeshError> {
    let lat = Lattice::covering(domain, opts)?;
    let stuffing = Stuffing::new(domain, lat, opts)?;
    let (nodes, tets) = stuffing.compact(&stuffing.tetrahedra(domain)?)?;
    if tets.is_empty() {
        return Err(MeshError::Invalid(format!(
            "the domain produced no element at size {:.1} mm: is it empty, or thinner than the elements (mesh \
             finer)?",
            crate::length::mm(opts.size)
        )));
    }
    let mut mesh = Mesh::new(nodes, Cells::Tet4(tets))?;
    crate::pinch::bridge_pinched_edges(&mut mesh);
    let mut mesh = without_small_pieces(mesh)?;
    if opts.fit == BoundaryFit::VolumePreserving {
        preserve_volume(&mut mesh, domain);
    }
    Ok(mesh)
}

impl Lattice {
    /// The lattice of spacing `opts.size` over the domain's bounds, a cube beyond them on every
    /// side; checks the options and the bounds.
    fn covering(domain: &dyn ImplicitDomain, opts: &TetMeshOptions) -> Result<Lattice, MeshError> {
        let h = opts.size;
        if !(h > 0.0 && h.is_finite()) {
            return Err(MeshError::Invalid(format!("element size must be positive and finite, got {h}")));
        }
        for (name, a, max) in [("alpha_long", opts.alpha_long, 0.5), ("alpha_short", opts.alpha_short, 0.5)] {
            if !(0.0..max).contains(&a) {
                return Err(MeshError::Invalid(format!("{name} must be in [0, {max}), got {a}")));
            }
        }
        let (lo, hi) = domain.bounds();
        if (0..3).any(|d| !(lo[d].is_finite() && hi[d].is_finite() && hi[d] >= lo[d])) {
            return Err(MeshError::Invalid(format!("domain bounds {lo:?}..{hi:?} are not a finite box")));
        }
        let n: [usize; 3] = std::array::from_fn(|d| ((hi[d] - lo[d]) / h).ceil() as usize + 2);
        let cells = n[0] as f64 * n[1] as f64 * n[2] as f64;
        if cells > 2.0e8 {
            return Err(MeshError::Invalid(format!(
                "element size {h} m is too small for the domain ({:.0} lattice cubes)",
                cells
            )));
        }
        let origin = std::array::from_fn(|d| lo[d] - h);
        Ok(Lattice { origin, h, n, num_corners: (n[0] + 1) * (n[1] + 1) * (n[2] + 1) })
    }
}

/// The lattice with the domain's values at its vertices, the cut points on its edges, and the
/// vertices warped onto a cut point. Candidate node ids: lattice vertex `v`, or `nv + e` for cut
/// point `e`.
struct Stuffing {
    lat: Lattice,
    /// The domain's value at each vertex (0 once warped).
    val: Vec<f64>,
    cuts: Vec<Cut>,
    /// The cut points incident to vertex `v`: `incident[start[v]..start[v + 1]]`.
    start: Vec<usize>,
    incident: Vec<u32>,
    /// The cut point each vertex is warped to (`u32::MAX`: not warped).
    warped_to: Vec<u32>,
}

impl Stuffing {
    /// Steps 1 to 3: the values at the lattice vertices, the cut points on the edges with a
    /// strict sign change, and the warping of vertices near a cut point onto it.
    fn new(domain: &dyn ImplicitDomain, lat: Lattice, opts: &TetMeshOptions) -> Result<Stuffing, MeshError> {
        let nv = lat.num_vertices();
        let val: Vec<f64> = (0..nv as u32).into_par_iter().map(|v| domain.lattice_value(lat.position(v))).collect();
        if let Some(v) = val.iter().position(|f| !f.is_finite()) {
            return Err(MeshError::Invalid(format!(
                "the domain function is not finite at {:?}",
                lat.position(v as u32)
            )));
        }
        let cuts = cut_points(domain, &lat, &val);
        let mut start = vec![0usize; nv + 1];
        for c in &cuts {
            start[c.u as usize + 1] += 1;
            start[c.v as usize + 1] += 1;
        }
        for i in 0..nv {
            start[i + 1] += start[i];
        }
        let mut fill = start.clone();
        let mut incident = vec![0u32; start[nv]];
        for (e, c) in cuts.iter().enumerate() {
            for w in [c.u, c.v] {
                incident[fill[w as usize]] = e as u32;
                fill[w as usize] += 1;
            }
        }
        let mut stuffing = Stuffing { lat, val, cuts, start, incident, warped_to: vec![u32::MAX; nv] };
        stuffing.warp(opts);
        Ok(stuffing)
    }

    /// Warps each vertex onto its nearest cut point closer than `alpha` times its edge's length,
    /// among the edges whose ends are not warped yet.
    fn warp(&mut self, opts: &TetMeshOptions) {
        let h = self.lat.h;
        for v in 0..self.lat.num_vertices() {
            let pv = self.lat.position(v as u32);
            let mut best: Option<(f64, u32)> = None;
            for &e in &self.incident[self.start[v]..self.start[v + 1]] {
                let c = &self.cuts[e as usize];
                if self.warped_to[c.u as usize] != u32::MAX || self.warped_to[c.v as usize] != u32::MAX {
                    continue;
                }
                let (alpha, len) = if is_black(&self.lat, c.u, c.v) {
                    (opts.alpha_long, h)
                } else {
                    (opts.alpha_short, 0.5 * 3f64.sqrt() * h)
                };
                let dv = sub(c.point, pv);
                let dist = dot(dv, dv).sqrt();
                if dist < alpha * len && best.is_none_or(|(b, _)| dist < b) {
                    best = Some((dist, e));
                }
            }
            if let Some((_, e)) = best {
                self.warped_to[v] = e;
                self.val[v] = 0.0;
            }
        }
    }

    /// Whether cut point `e` survives the warping (neither end of its edge warped).
    fn alive(&self, e: u32) -> bool {
        let c = &self.cuts[e as usize];
        self.warped_to[c.u as usize] == u32::MAX && self.warped_to[c.v as usize] == u32::MAX
    }

    /// The sign of the domain's value at vertex `v`.
    fn sign(&self, v: u32) -> i8 {
        let f = self.val[v as usize];
        if f < 0.0 {
            -1
        } else if f > 0.0 {
            1
        } else {
            0
        }
    }

    /// The candidate node id of the surviving cut point on lattice edge (u, v).
    fn cut(&self, u: u32, v: u32) -> Result<u32, MeshError> {
        self.incident[self.start[u as usize]..self.start[u as usize + 1]]
            .iter()
            .copied()
            .find(|&e| {
                let c = &self.cuts[e as usize];
                (c.u == v || c.v == v) && self.alive(e)
            })
            .map(|e| self.lat.num_vertices() as u32 + e)
            .ok_or_else(|| {
                MeshError::Invalid(format!("isosurface stuffing: missing cut point on lattice edge ({u}, {v})"))
            })
    }

    /// Where lattice vertex `v` lies after the warping.
    fn warped_pos(&self, v: u32) -> Point {
        match self.warped_to[v as usize] {
            u32::MAX => self.lat.position(v),
            e => self.cuts[e as usize].point,
        }
    }

    /// Step 4: fills the BCC tetrahedra (each pair of neighbouring centres with the four corners
    /// around their shared face), in candidate node ids.
    fn tetrahedra(&self, domain: &dyn ImplicitDomain) -> Result<Vec<[u32; 4]>, MeshError> {
        let (lat, n) = (&self.lat, self.lat.n);
        let mut out: Vec<[u32; 4]> = Vec::new();
        for axis in 0..3 {
            let (b, c) = ((axis + 1) % 3, (axis + 2) % 3);
            let mut m = n;
            m[axis] -= 1;
            for k in 0..m[2] {
                for j in 0..m[1] {
                    for i in 0..m[0] {
                        let c1 = [i, j, k];
                        let mut c2 = c1;
                        c2[axis] += 1;
                        let v1 = lat.centre(c1[0], c1[1], c1[2]);
                        let v2 = lat.centre(c2[0], c2[1], c2[2]);
                        let mut f = [0usize; 3];
                        let corners: [u32; 4] = std::array::from_fn(|q| {
                            let (db, dc) = [(0, 0), (1, 0), (1, 1), (0, 1)][q];
                            f[axis] = c1[axis] + 1;
                            f[b] = c1[b] + db;
                            f[c] = c1[c] + dc;
                            lat.corner(f[0], f[1], f[2])
                        });
                        for q in 0..4 {
                            let tet = [v1, v2, corners[q], corners[(q + 1) % 4]];
                            let s = tet.map(|v| self.sign(v));
                            if s.iter().all(|&x| x > 0) {
                                continue;
                            }
                            fill_bcc_tet(lat, tet, s, &|u, v| self.cut(u, v), &mut out, |t| {
                                let p = t.map(|v| self.warped_pos(v));
                                let centre: Point =
                                    std::array::from_fn(|d| 0.25 * (p[0][d] + p[1][d] + p[2][d] + p[3][d]));
                                domain.contains(centre)
                            })?;
                        }
                    }
                }
            }
        }
        Ok(out)
    }

    /// Step 5: the nodes used by `out`, numbered compactly, and its tetrahedra oriented in the
    /// reference (unwarped) geometry; an error when one is inverted after the warping.
    fn compact(&self, out: &[[u32; 4]]) -> Result<(Vec<Point>, Vec<[usize; 4]>), MeshError> {
        let nv = self.lat.num_vertices();
        let mut id = vec![u32::MAX; nv + self.cuts.len()];
        for t in out {
            for &v in t {
                id[v as usize] = 0;
            }
        }
        let mut nodes = Vec::new();
        let mut ref_pos = Vec::new();
        for (cand, slot) in id.iter_mut().enumerate() {
            if *slot == u32::MAX {
                continue;
            }
            *slot = nodes.len() as u32;
            if cand < nv {
                nodes.push(self.warped_pos(cand as u32));
                ref_pos.push(self.lat.position(cand as u32));
            } else {
                let p = self.cuts[cand - nv].point;
                nodes.push(p);
                ref_pos.push(p);
            }
        }
        let mut tets = Vec::with_capacity(out.len());
        let mut inverted = Vec::new();
        for t in out {
            let mut t = t.map(|v| id[v as usize] as usize);
            let r = t.map(|k| ref_pos[k]);
            if crate::tet_volume(r[0], r[1], r[2], r[3]) < 0.0 {
                t.swap(2, 3);
            }
            let p = t.map(|k| nodes[k]);
            let vol = crate::tet_volume(p[0], p[1], p[2], p[3]);
            if !(vol > 0.0) {
                inverted.push((tets.len(), vol));
            }
            tets.push(t);
        }
        if let Some(&(e, vol)) = inverted.first() {
            return Err(MeshError::Invalid(format!(
                "isosurface stuffing produced {} inverted tetrahedra (first: element {e}, volume {vol:.3e}); \
                 try another element size",
                inverted.len()
            )));
        }
        Ok((nodes, tets))
    }
}

/// The cut points: the boundary point on each lattice edge whose ends have strictly opposite
/// signs (`val`: the domain's values at the vertices).
fn cut_points(domain: &dyn ImplicitDomain, lat: &Lattice, val: &[f64]) -> Vec<Cut> {
    let edges: Vec<(u32, u32)> = (0..lat.num_vertices() as u32)
        .into_par_iter()
        .flat_map_iter(|u| {
            let d = lat.doubled(u);
            let mut out = Vec::new();
            let mut consider = |dd: [i64; 3]| {
                if let Some(v) = lat.at_doubled(dd) {
                    let (fu, fv) = (val[u as usize], val[v as usize]);
                    if (fu < 0.0 && fv > 0.0) || (fu > 0.0 && fv < 0.0) {
                        out.push((u.min(v), u.max(v)));
                    }
                }
            };
            for a in 0..3 {
                let mut dd = d;
                dd[a] += 2;
                consider(dd);
            }
            if (u as usize) < lat.num_corners {
                for s in 0..8 {
                    let sg = |b: usize| if s >> b & 1 == 1 { 1 } else { -1 };
                    consider([d[0] + sg(0), d[1] + sg(1), d[2] + sg(2)]);
                }
            }
            out
        })
        .collect();
    edges
        .par_iter()
        .map(|&(u, v)| {
            let point = domain.boundary_point(lat.position(u), val[u as usize], lat.position(v), val[v as usize]);
            Cut { u, v, point }
        })
        .collect()
}

/// A piece of a stuffed mesh (its tetrahedra joined through faces: [`face_connected_pieces`])
/// with less than this share of the mesh's volume is dropped. Where the organ is thinner than
/// the lattice, stuffing leaves tetrahedra that hang on the rest by an edge or a vertex: a
/// mechanism that no FEM solve survives (a real liver's 3,058-tetrahedron mesh had two, one
/// hanging by a vertex, 0.08 % of the volume). A larger piece joined by an edge or a vertex (a
/// lobe behind a neck thinner than the lattice, whose nodes the rest shares) is kept, and
/// [`TetQuality::pieces`] counts it.
pub const SMALL_PIECE: f64 = 0.01;

/// The share of the volume above which a part of the mesh apart from its main body (joined to it
/// through a neck thinner than the lattice, so that nothing of the mesh joins them) is refused,
/// not dropped, at this share or more: the mesh would lose a lobe.
pub const PART_APART: f64 = 0.05;

/// A T4 mesh without its pieces smaller than [`SMALL_PIECE`] (the largest piece of the body kept
/// is always kept), nor those that share no node with the largest body of pieces (a part cut off where
/// the organ is thinner than the lattice: nothing would hold it), its nodes renumbered in their
/// order and its regions with them; other meshes as they are. What is lost shows in
/// [`TetQuality::coverage`]. A part cut off of [`PART_APART`] of the volume or more is an error
/// that names it.
pub fn without_small_pieces(mesh: Mesh) -> Result<Mesh, MeshError> {
    let pieces = face_connected_pieces(&mesh);
    if pieces.len() == 1 {
        return Ok(mesh);
    }
    let Cells::Tet4(tets) = &mesh.cells else { return Ok(mesh) };
    let volumes: Vec<f64> = pieces.iter().map(|p| p.iter().map(|&c| mesh.cell_volume(c)).sum()).collect();
    let total = volumes.iter().sum::<f64>();
    let body = bodies(&pieces, tets, mesh.nodes.len());
    let mut body_volume = vec![0.0; pieces.len()];
    body.iter().zip(&volumes).for_each(|(&b, v)| body_volume[b] += v);
    let main = (0..body_volume.len()).max_by(|&a, &b| body_volume[a].total_cmp(&body_volume[b])).unwrap_or(0);
    let largest = volumes.iter().zip(&body).filter(|(_, &b)| b == main).map(|(&v, _)| v).fold(0.0, f64::max);
    // A part apart from the main body is joined to it only through a neck thinner than the
    // lattice: a large one is half an organ lost, not a mesher's crumb.
    if let Some((part, &volume)) =
        body_volume.iter().enumerate().filter(|&(b, _)| b != main).max_by(|a, b| a.1.total_cmp(b.1))
    {
        if volume >= PART_APART * total {
            let cells: Vec<usize> =
                pieces.iter().zip(&body).filter(|(_, &b)| b == part).flat_map(|(p, _)| p.iter().copied()).collect();
            let at = cells
                .iter()
                .flat_map(|&c| tets[c].map(|n| mesh.nodes[n]))
                .fold([0.0; 3], |s, p| [s[0] + p[0], s[1] + p[1], s[2] + p[2]]);
            let at = at.map(|x| x / (4 * cells.len()) as f64);
            return Err(MeshError::Invalid(format!(
                "the mesh falls apart: a part of {:.0} % of the volume ({:.1} mL) around {} joins the rest \
                 only through a neck thinner than the tetrahedra, which meshing cannot keep; if the organ's parts \
                 meet through a thin bridge (a few voxels of a segmentation), join them more broadly or keep one \
                 of them; otherwise mesh finer (more tetrahedra)",
                100.0 * volume / total,
                volume * 1e6,
                crate::length::point_in_mm(at),
            )));
        }
    }
    let dropped: Vec<usize> = pieces
        .iter()
        .zip(&volumes)
        .zip(&body)
        .filter(|((_, &v), &b)| !(b == main && (v >= SMALL_PIECE * total || v == largest)))
        .flat_map(|((p, _), _)| p.iter().copied())
        .collect();
    let mut kept = mesh.without_cells(&dropped)?;
    // Numbered afresh, as a mesh made here is.
    (kept.file_nodes, kept.file_cells) = (None, None);
    Ok(kept)
}

/// The body of each piece (cells of `tets`): pieces sharing a node are in one body.
fn bodies(pieces: &[Vec<usize>], tets: &[[usize; 4]], nodes: usize) -> Vec<usize> {
    let mut parent: Vec<usize> = (0..pieces.len()).collect();
    let mut piece_of_node = vec![usize::MAX; nodes];
    for (p, cells) in pieces.iter().enumerate() {
        for n in cells.iter().flat_map(|&c| tets[c]) {
            match piece_of_node[n] {
                usize::MAX => piece_of_node[n] = p,
                other => {
                    let (a, b) = (root(&mut parent, other), root(&mut parent, p));
                    parent[a.max(b)] = a.min(b);
                }
            }
        }
    }
    (0..pieces.len()).map(|p| root(&mut parent, p)).collect()
}

/// How much of a surface a mesh of it covers: the share of the surface's area farther than
/// [`Coverage::distance`] from the mesh's boundary (parts thinner than the elements, which
/// stuffing leaves out), and the farthest of its vertices.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Coverage {
    /// The distance beyond which a part of the surface counts as left out (m):
    /// [`UNCOVERED_DISTANCE`] of the surface's largest extent.
    pub distance: f64,
    /// The share of the surface's area farther than `distance` from the mesh.
    pub uncovered: f64,
    /// The largest distance of a surface vertex from the mesh (m).
    pub farthest: f64,
}

/// A part of a surface farther than this share of its largest extent from its mesh is left out
/// of it ([`Coverage`]): 5 mm on a liver of 25 cm, where the boundary's chords lie within a
/// millimetre or so of the surface at the default sizes.
pub const UNCOVERED_DISTANCE: f64 = 0.02;

/// [`Coverage`] of `surface` by `mesh` (each triangle counted by its centroid).
fn surface_coverage(mesh: &Mesh, surface: &TriSurface) -> Result<Coverage, MeshError> {
    let boundary = SurfaceBvh::new(&crate::boundary_surface(mesh))?;
    let distance = UNCOVERED_DISTANCE * crate::longest_side(crate::bounds(&surface.vertices));
    let (area, left_out) = surface
        .triangles
        .par_iter()
        .map(|t| {
            let p = t.map(|k| surface.vertices[k]);
            let area = crate::norm(crate::surface::area_vector(p));
            (area, if boundary.distance(crate::surface::centroid(p)) > distance { area } else { 0.0 })
        })
        .reduce(|| (0.0, 0.0), |a, b| (a.0 + b.0, a.1 + b.1));
    let farthest = surface.vertices.par_iter().map(|&v| boundary.distance(v)).reduce(|| 0.0, f64::max);
    Ok(Coverage { distance, uncovered: if area > 0.0 { left_out / area } else { 0.0 }, farthest })
}

/// Moves the boundary nodes outward by the mean depth of the boundary above
/// their faces ([`BoundaryFit::VolumePreserving`]).
fn preserve_volume(mesh: &mut Mesh, domain: &dyn ImplicitDomain) {
    let Cells::Tet4(tets) = &mesh.cells else { return };
    let faces = boundary_triangles(tets);
    let nodes = &mesh.nodes;
    // (area, unit normal, mean depth) per boundary face.
    let data: Vec<(f64, Point, f64)> = faces
        .par_iter()
        .map(|f| {
            let p = f.map(|k| nodes[k]);
            let nv = cross(sub(p[1], p[0]), sub(p[2], p[0]));
            let len = dot(nv, nv).sqrt();
            if len == 0.0 {
                return (0.0, [0.0; 3], 0.0);
            }
            let n = nv.map(|c| c / len);
            let depth: f64 = (0..3)
                .map(|i| {
                    let (a, b) = (p[i], p[(i + 1) % 3]);
                    let m: Point = std::array::from_fn(|d| 0.5 * (a[d] + b[d]));
                    let e = sub(b, a);
                    domain.boundary_offset(m, n, dot(e, e).sqrt())
                })
                .sum();
            (0.5 * len, n, depth / 3.0)
        })
        .collect();
    let nn = mesh.nodes.len();
    let mut num = vec![0.0; nn];
    let mut den = vec![0.0; nn];
    let mut normal = vec![[0.0; 3]; nn];
    for (f, &(a, n, d)) in faces.iter().zip(&data) {
        for &k in f {
            num[k] += a * d;
            den[k] += a;
            for c in 0..3 {
                normal[k][c] += a * n[c];
            }
        }
    }
    let mut moves: Vec<Point> = vec![[0.0; 3]; nn];
    for k in 0..nn {
        let len = dot(normal[k], normal[k]).sqrt();
        if den[k] > 0.0 && len > 0.0 {
            let delta = num[k] / den[k];
            moves[k] = normal[k].map(|c| c / len * delta);
        }
    }
    let original: Vec<Point> = mesh.nodes.clone();
    let old_vol: Vec<f64> = tets.iter().map(|t| tet_volume_of(&original, t)).collect();
    let mut scale = vec![1.0f64; nn];
    // Halve the moves around a failing element four times, then drop them;
    // each dropping round zeroes at least one move, so the loop ends.
    let mut round = 0;
    loop {
        for k in 0..nn {
            mesh.nodes[k] = std::array::from_fn(|d| original[k][d] + scale[k] * moves[k][d]);
        }
        let mut ok = true;
        for (t, &v0) in tets.iter().zip(&old_vol) {
            if tet_volume_of(&mesh.nodes, t) < 0.2 * v0 {
                ok = false;
                for &k in t {
                    scale[k] = if round < 4 { 0.5 * scale[k] } else { 0.0 };
                }
            }
        }
        if ok {
            return;
        }
        round += 1;
    }
}

/// Signed volume of tetrahedron `t` of `nodes`.
fn tet_volume_of(nodes: &[Point], t: &[usize; 4]) -> f64 {
    crate::tet_volume(nodes[t[0]], nodes[t[1]], nodes[t[2]], nodes[t[3]])
}

/// The lattice vertex, p or q, from which the diagonal of the quadrilateral
/// cut from face (p, q, r) starts (p, q inside, r outside); the diagonal
/// joins it to the cut point on the edge from the other one to r.
fn quad_diagonal_start(l: &Lattice, p: u32, q: u32, r: u32) -> u32 {
    if is_black(l, p, r) {
        // Diagonal from the cut point on the black edge p–r to q.
        q
    } else if is_black(l, q, r) {
        p
    } else {
        // Black edge p–q: parity rule, alternating around the edge.
        let (dp, dq, dr) = (l.doubled(p), l.doubled(q), l.doubled(r));
        let axis = (0..3).find(|&a| dp[a] != dq[a]).unwrap_or(0);
        let (b, c) = ((axis + 1) % 3, (axis + 2) % 3);
        let parity = (dr[b] > dp[b]) != (dr[c] > dp[c]);
        let (lower, upper) = if dp[axis] < dq[axis] { (p, q) } else { (q, p) };
        if parity {
            upper
        } else {
            lower
        }
    }
}

/// Appends the stencil tetrahedra of one BCC tetrahedron with vertex signs `s`
/// (−1 inside, 0 on the boundary, +1 outside). `all_zero_inside` decides a
/// tetrahedron whose four vertices all lie on the boundary.
fn fill_bcc_tet(
    l: &Lattice,
    v: [u32; 4],
    s: [i8; 4],
    cut: &dyn Fn(u32, u32) -> Result<u32, MeshError>,
    out: &mut Vec<[u32; 4]>,
    all_zero_inside: impl Fn([u32; 4]) -> bool,
) -> Result<(), MeshError> {
    let neg: Vec<u32> = (0..4).filter(|&i| s[i] < 0).map(|i| v[i]).collect();
    let pos: Vec<u32> = (0..4).filter(|&i| s[i] > 0).map(|i| v[i]).collect();
    let zero: Vec<u32> = (0..4).filter(|&i| s[i] == 0).map(|i| v[i]).collect();
    if pos.is_empty() {
        if !neg.is_empty() || all_zero_inside(v) {
            out.push(v);
        }
        return Ok(());
    }
    match (neg.len(), pos.len()) {
        (0, _) => {}
        (1, _) => {
            // One inside vertex: a single tetrahedron with the boundary
            // vertices and the cut points towards the outside vertices.
            let a = neg[0];
            let mut t = [a, 0, 0, 0];
            let mut k = 1;
            for &z in &zero {
                t[k] = z;
                k += 1;
            }
            for &p in &pos {
                t[k] = cut(a, p)?;
                k += 1;
            }
            out.push(t);
        }
        (2, 1) => {
            // Pyramid: apex z over the quadrilateral (a, b, cut_bc, cut_ac).
            let (a, b, c, z) = (neg[0], neg[1], pos[0], zero[0]);
            let (ac, bc) = (cut(a, c)?, cut(b, c)?);
            if quad_diagonal_start(l, a, b, c) == a {
                out.push([z, a, b, bc]);
                out.push([z, a, bc, ac]);
            } else {
                out.push([z, b, a, ac]);
                out.push([z, b, ac, bc]);
            }
        }
        (2, 2) => {
            // Prism: bottom (a, cut_ac, cut_ad), top (b, cut_bc, cut_bd).
            let (a, b, c, d) = (neg[0], neg[1], pos[0], pos[1]);
            let bottom = [a, cut(a, c)?, cut(a, d)?];
            let top = [b, cut(b, c)?, cut(b, d)?];
            let q0 = if quad_diagonal_start(l, a, b, c) == a { 0 } else { 1 };
            let q2 = if quad_diagonal_start(l, a, b, d) == a { 1 } else { 0 };
            prism(bottom, top, [Some(q0), None, Some(q2)], out)?;
        }
        (3, 1) => {
            // Prism: bottom (a, b, c), top (cut_ad, cut_bd, cut_cd).
            let d = pos[0];
            let bottom = [neg[0], neg[1], neg[2]];
            let top = [cut(neg[0], d)?, cut(neg[1], d)?, cut(neg[2], d)?];
            let q: [Option<u8>; 3] = std::array::from_fn(|i| {
                let (p, r) = (bottom[i], bottom[(i + 1) % 3]);
                Some(if quad_diagonal_start(l, p, r, d) == p { 0 } else { 1 })
            });
            prism(bottom, top, q, out)?;
        }
        _ => {
            return Err(MeshError::Invalid(format!(
                "isosurface stuffing: no stencil for lattice tetrahedron {v:?} with signs {s:?}"
            )))
        }
    }
    Ok(())
}

/// Splits the prism with bottom B and top T (T[i] above B[i]) into three
/// tetrahedra. The lateral quadrilateral i = (B[i], B[i+1], T[i+1], T[i]) is
/// split along B[i]–T[i+1] (type 0) or B[i+1]–T[i] (type 1); `None` means free.
fn prism(b: [u32; 3], t: [u32; 3], q: [Option<u8>; 3], out: &mut Vec<[u32; 4]>) -> Result<(), MeshError> {
    let mut d = q.map(|x| x.unwrap_or(0));
    if d[0] == d[1] && d[1] == d[2] {
        // Cyclic diagonals cannot be triangulated: flip a free one.
        match q.iter().position(|x| x.is_none()) {
            Some(i) => d[i] = 1 - d[i],
            None => {
                return Err(MeshError::Invalid(format!(
                    "isosurface stuffing: cyclic quadrilateral diagonals in prism {b:?}/{t:?}"
                )))
            }
        }
    }
    // A vertex where two diagonals meet sees the opposite triangle: one
    // tetrahedron, then a pyramid over the remaining quadrilateral.
    for i in 0..3 {
        let prev = (i + 2) % 3;
        let apex_bottom = d[i] == 0 && d[prev] == 1;
        let apex_top = d[i] == 1 && d[prev] == 0;
        if !(apex_bottom || apex_top) {
            continue;
        }
        let (i1, i2) = ((i + 1) % 3, (i + 2) % 3);
        let apex = if apex_bottom { b[i] } else { t[i] };
        out.push(if apex_bottom { [b[i], t[0], t[1], t[2]] } else { [t[i], b[0], b[1], b[2]] });
        // Pyramid over quadrilateral i+1 = (B[i1], B[i2], T[i2], T[i1]).
        if d[i1] == 0 {
            out.push([apex, b[i1], b[i2], t[i2]]);
            out.push([apex, b[i1], t[i2], t[i1]]);
        } else {
            out.push([apex, b[i1], b[i2], t[i1]]);
            out.push([apex, b[i2], t[i2], t[i1]]);
        }
        return Ok(());
    }
    Err(MeshError::Invalid(format!("isosurface stuffing: prism {b:?}/{t:?} has no apex")))
}

/// Outward boundary triangles of positively oriented tetrahedra (faces that
/// belong to one tetrahedron only), in tetrahedron order.
pub(crate) fn boundary_triangles(tets: &[[usize; 4]]) -> Vec<[usize; 3]> {
    use crate::topology::TET_FACES;
    let mut keys: Vec<([usize; 3], u32)> = Vec::with_capacity(4 * tets.len());
    for (e, t) in tets.iter().enumerate() {
        for (f, face) in TET_FACES.iter().enumerate() {
            let mut k = face.map(|i| t[i]);
            k.sort_unstable();
            keys.push((k, (4 * e + f) as u32));
        }
    }
    keys.par_sort_unstable();
    let mut out: Vec<u32> = Vec::new();
    let mut i = 0;
    while i < keys.len() {
        let mut j = i + 1;
        while j < keys.len() && keys[j].0 == keys[i].0 {
            j += 1;
        }
        if j == i + 1 {
            out.push(keys[i].1);
        }
        i = j;
    }
    out.sort_unstable();
    out.iter().map(|&id| TET_FACES[id as usize % 4].map(|i| tets[id as usize / 4][i])).collect()
}
