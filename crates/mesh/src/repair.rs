//! Repair of triangle surfaces as image segmentations give them, and their length unit.
//!
//! A surface segmented from CT or MRI images (OBJ from MeshLab, STL, PLY, VTK) often has
//! duplicated vertices (an STL file stores each triangle's corners apart), degenerate and
//! repeated triangles, triangles facing the wrong way and small holes. [`repair_surface`] fixes
//! these, in this order:
//!
//! 1. refuses non-finite or absurdly large coordinates and out-of-range indices;
//! 2. merges vertices closer than a tolerance (spatial hashing, in index order: deterministic);
//! 3. drops triangles that repeat a vertex or have no area, and triangles that repeat another's
//!    three vertices; then the vertices no triangle uses;
//! 4. refuses non-manifold edges (of more than two triangles) and vertices (joining several
//!    fans of triangles): there is no unique repair of these;
//! 5. orients the triangles consistently, breadth-first over shared edges (the orientation of
//!    the majority is kept), and refuses a surface in several pieces: an organ is one piece;
//! 6. fills each hole with the minimum-area triangulation of its boundary loop, by dynamic
//!    programming in O(n³) (Barequet & Sharir 1995, Liepa 2003); a hole of 16 edges or more
//!    (an organ cut open) then has its patch refined to the size of its boundary's edges and
//!    faired into a membrane (Liepa 2003), its new vertices after the others;
//! 7. turns the surface outward, checks it with [`check_closed_manifold`] and looks for
//!    self-intersections ([`self_intersections`]): they are refused when more than a fraction of
//!    the triangles cross others (by default the 1 % the mesher tolerates,
//!    [`MAX_OVERLAP_FRACTION`]), otherwise reported and left in place.
//!
//! What local repair cannot mend goes through voxels instead: see [`crate::rebuild`].
//!
//! [`detect_unit`] tells a surface in metres from one in millimetres by the size of an organ.

use std::collections::{BTreeMap, BTreeSet, HashMap, HashSet};

use rayon::prelude::*;

use crate::length::LengthUnit;
use crate::length::{number, ORGAN_EXTENT_M};
use crate::surface::{area_vector, check_closed_manifold};
use crate::tetmesh::MAX_OVERLAP_FRACTION;
use crate::topology::root;
use crate::{bounds, cross, dot, norm, sub, MeshError, Point, TriSurface};

/// Options of [`repair_surface`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RepairOptions {
    /// Vertices closer than this fraction of the bounding-box diagonal are merged (default 1e-6).
    pub merge_tolerance: f64,
    /// Largest hole filled, in boundary edges (default 200); a larger one is refused.
    pub max_hole_edges: usize,
    /// Largest fraction of triangles that may cross others (default [`MAX_OVERLAP_FRACTION`],
    /// 0.01, what the mesher tolerates); fewer are reported in [`RepairReport::crossings`], more
    /// are refused. Zero refuses any crossing.
    pub max_crossing_fraction: f64,
}

impl Default for RepairOptions {
    fn default() -> Self {
        RepairOptions { merge_tolerance: 1e-6, max_hole_edges: 200, max_crossing_fraction: MAX_OVERLAP_FRACTION }
    }
}

/// The share of a repaired surface's area above which the holes filled are said to be large: the
/// organ was cut open, by the image's field of view or a clipped export.
pub const LARGE_FILL_SHARE: f64 = 0.05;

/// What [`repair_surface`] changed.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RepairReport {
    /// Vertices merged into an earlier one at (nearly) the same place.
    pub merged_vertices: usize,
    /// Triangles dropped because they repeat a vertex (after merging) or have no area.
    pub removed_degenerate: usize,
    /// Triangles dropped because an earlier one has the same three vertices.
    pub removed_duplicate: usize,
    /// Vertices dropped because no triangle uses them.
    pub removed_unused_vertices: usize,
    /// Triangles turned to agree with their neighbours.
    pub flipped_triangles: usize,
    /// True when the whole surface was turned outward (it was inside out).
    pub reversed: bool,
    /// The number of edges of each hole filled, in the order they were filled.
    pub holes_filled: Vec<usize>,
    /// Triangles added to fill the holes. A hole of three edges along a line (left by a
    /// zero-area triangle) is closed by splitting the triangle across its longest edge: one more.
    pub added_triangles: usize,
    /// Vertices added inside the patches of holes of 16 edges or more (refined and faired).
    pub added_vertices: usize,
    /// The share of the repaired surface's area that the holes' patches make up.
    pub filled_share: f64,
    /// Pairs of triangles of the repaired surface that cross (see [`self_intersections`]), few
    /// enough to be tolerated: not a change, left in place (see [`RepairReport::warnings`]).
    pub crossings: Vec<(usize, usize)>,
}

impl RepairReport {
    /// One line per change, e.g. "merged 312 duplicate vertices", "filled 3 holes (12, 8, 5
    /// edges) with 19 triangles"; empty when nothing changed.
    pub fn lines(&self) -> Vec<String> {
        let count = |n: usize, one: &str, many: &str| format!("{n} {}", if n == 1 { one } else { many });
        let mut lines = Vec::new();
        if self.merged_vertices > 0 {
            lines.push(format!("merged {}", count(self.merged_vertices, "duplicate vertex", "duplicate vertices")));
        }
        if self.removed_degenerate > 0 {
            lines.push(format!(
                "removed {}",
                count(self.removed_degenerate, "degenerate triangle", "degenerate triangles")
            ));
        }
        if self.removed_duplicate > 0 {
            lines.push(format!(
                "removed {}",
                count(self.removed_duplicate, "duplicate triangle", "duplicate triangles")
            ));
        }
        if self.removed_unused_vertices > 0 {
            lines.push(format!("removed {}", count(self.removed_unused_vertices, "unused vertex", "unused vertices")));
        }
        if self.flipped_triangles > 0 {
            lines.push(format!("turned {}", count(self.flipped_triangles, "flipped triangle", "flipped triangles")));
        }
        if !self.holes_filled.is_empty() {
            let sizes: Vec<String> = self.holes_filled.iter().map(|n| n.to_string()).collect();
            let vertices = match self.added_vertices {
                0 => String::new(),
                n => format!(" and {}", count(n, "new vertex", "new vertices")),
            };
            lines.push(format!(
                "filled {} ({} edges) with {}{vertices}",
                count(self.holes_filled.len(), "hole", "holes"),
                sizes.join(", "),
                count(self.added_triangles, "triangle", "triangles")
            ));
        }
        if self.reversed {
            lines.push("turned the surface outward (it was inside out)".into());
        }
        lines
    }

    /// True when the repair changed anything (tolerated crossings are not a change).
    pub fn changed(&self) -> bool {
        let unchanged = RepairReport { crossings: self.crossings.clone(), ..RepairReport::default() };
        *self != unchanged
    }

    /// One line per problem left in place: holes filled over more than [`LARGE_FILL_SHARE`] of
    /// the surface, tolerated crossings ("7 pairs of triangles cross (9 triangles, first 810 and
    /// 811): left in place"); empty when there is none.
    pub fn warnings(&self) -> Vec<String> {
        let mut warnings = Vec::new();
        if self.filled_share > LARGE_FILL_SHARE {
            warnings.push(format!(
                "the holes filled make up {:.0} % of the surface: the organ seems cut open (by the image's field of \
                 view, or a clipped export) and is closed there by a membrane across the cut, not by its own shape",
                100.0 * self.filled_share
            ));
        }
        if let Some(&(a, b)) = self.crossings.first() {
            let pairs = self.crossings.len();
            warnings.push(format!(
                "{pairs} {} of triangles {} ({} triangles, first {a} and {b}): left in place",
                if pairs == 1 { "pair" } else { "pairs" },
                if pairs == 1 { "crosses" } else { "cross" },
                crossing_triangles(&self.crossings)
            ));
        }
        warnings
    }
}

/// Repairs a triangle surface as a segmentation gives it into a closed, outward oriented
/// 2-manifold without degenerate triangles or self-intersections (see the module's
/// documentation for the steps), and says what was changed.
///
/// Refused, with a message that says what and where (vertex numbers are those of the input):
/// non-finite or absurdly large coordinates, out-of-range indices, non-manifold edges and
/// vertices, a non-orientable surface, several pieces, a hole of more than `max_hole_edges` edges,
/// self-intersections of more than `max_crossing_fraction` of the triangles. The vertices keep
/// their coordinates and their order; the new vertices of large holes' patches follow them.
pub fn repair_surface(surface: &TriSurface, options: &RepairOptions) -> Result<(TriSurface, RepairReport), MeshError> {
    let nv = surface.vertices.len();
    let used = check_input(surface, options)?;
    let used_points: Vec<Point> = (0..nv).filter(|&v| used[v]).map(|v| surface.vertices[v]).collect();
    let (lo, hi) = bounds(&used_points);
    let diagonal = norm(sub(hi, lo));
    // The area below which a triangle is degenerate, as in `check_closed_manifold`.
    let min_area = 1e-14 * diagonal * diagonal;
    let mut report = RepairReport::default();

    // Merge vertices, then drop degenerate and repeated triangles.
    let (representative, merged) = merge_vertices(&surface.vertices, &used, options.merge_tolerance * diagonal);
    report.merged_vertices = merged;
    let mut seen: HashSet<[usize; 3]> = HashSet::with_capacity(surface.triangles.len());
    let mut triangles = Vec::with_capacity(surface.triangles.len());
    for tri in &surface.triangles {
        let t = tri.map(|k| representative[k]);
        if t[0] == t[1] || t[1] == t[2] || t[0] == t[2] || !(area(&surface.vertices, t) > min_area) {
            report.removed_degenerate += 1;
            continue;
        }
        let mut key = t;
        key.sort_unstable();
        if !seen.insert(key) {
            report.removed_duplicate += 1;
            continue;
        }
        triangles.push(t);
    }
    if triangles.is_empty() {
        return Err(invalid("surface has no triangle with a non-zero area"));
    }

    // Keep the used vertices, in their order; `origin` maps back to the input's numbering.
    let mut kept = vec![false; nv];
    triangles.iter().flatten().for_each(|&k| kept[k] = true);
    let mut index = vec![usize::MAX; nv];
    let mut vertices = Vec::new();
    let mut origin = Vec::new();
    for v in 0..nv {
        if kept[v] {
            index[v] = vertices.len();
            vertices.push(surface.vertices[v]);
            origin.push(v);
        }
    }
    report.removed_unused_vertices = nv - merged - vertices.len();
    triangles.iter_mut().for_each(|t| *t = t.map(|k| index[k]));
    let mut repaired = TriSurface { vertices, triangles };

    let neighbours = edge_neighbours(&repaired, &origin)?;
    check_fans(&repaired, &neighbours, &origin)?;
    let (flipped, pieces) = orient_consistently(&mut repaired, &neighbours, &origin)?;
    report.flipped_triangles = flipped;
    if pieces.len() > 1 {
        let mut sizes = pieces;
        sizes.sort_unstable_by(|a, b| b.cmp(a));
        let shown: Vec<String> = sizes.iter().take(5).map(|n| n.to_string()).collect();
        let more = if sizes.len() > 5 { ", ..." } else { "" };
        return Err(invalid(format!(
            "{} separate pieces ({}{more} triangles): keep the organ only (an organ surface is one piece)",
            sizes.len(),
            shown.join(", ")
        )));
    }
    let before = repaired.triangles.len();
    fill_holes(&mut repaired, options.max_hole_edges, min_area, &origin, &mut report)?;
    let area_of = |triangles: &[[usize; 3]]| triangles.iter().map(|&t| area(&repaired.vertices, t)).sum::<f64>();
    if report.added_triangles > 0 {
        report.filled_share = area_of(&repaired.triangles[before..]) / area_of(&repaired.triangles);
    }
    report.reversed = repaired.orient_outward();

    let checked = check_closed_manifold(&repaired).map_err(|e| invalid(format!("after repair: {}", e.message())))?;
    if !(checked.volume > 0.0) {
        return Err(invalid("after repair: the surface encloses no volume"));
    }
    let crossings = self_intersections(&repaired);
    let involved = crossing_triangles(&crossings);
    if let Some(&(a, b)) =
        crossings.first().filter(|_| involved as f64 > options.max_crossing_fraction * repaired.triangles.len() as f64)
    {
        let centre = crate::surface::centroid(repaired.triangles[a].map(|k| repaired.vertices[k]));
        // Crossings mostly of the triangles that filled its holes: the fill of a large hole, not the export.
        let of_fill = crossings.iter().filter(|&&(a, b)| a >= before || b >= before).count();
        let filled = match 2 * of_fill > crossings.len() {
            true => format!(
                " where its holes were filled (holes of {} edges, the fill {:.0} % of its area: a part missing, cut \
                 off?)",
                report.holes_filled.iter().map(usize::to_string).collect::<Vec<_>>().join(", "),
                100.0 * report.filled_share
            ),
            false => String::new(),
        };
        return Err(invalid(format!(
            "self-intersecting{filled}: triangles {a} and {b} cross ({} {}, {involved} of {} triangles, more than {} % \
             tolerated) near {} (numbering of the repaired surface); cannot be repaired automatically",
            crossings.len(),
            if crossings.len() == 1 { "pair" } else { "pairs" },
            repaired.triangles.len(),
            number(100.0 * options.max_crossing_fraction),
            point_text(centre)
        )));
    }
    report.crossings = crossings;
    Ok((repaired, report))
}

/// Refuses what no repair can use: no triangles, out-of-range indices, non-finite coordinates or
/// ones beyond [`crate::MAX_COORDINATE`], a bad merge tolerance. Returns which vertices the
/// triangles use.
pub(crate) fn check_input(surface: &TriSurface, options: &RepairOptions) -> Result<Vec<bool>, MeshError> {
    let nv = surface.vertices.len();
    if surface.triangles.is_empty() {
        return Err(invalid("surface has no triangles"));
    }
    if !(options.merge_tolerance >= 0.0 && options.merge_tolerance.is_finite()) {
        return Err(invalid(format!(
            "merge tolerance must be finite and non-negative, got {}",
            options.merge_tolerance
        )));
    }
    for (t, tri) in surface.triangles.iter().enumerate() {
        if let Some(&bad) = tri.iter().find(|&&k| k >= nv) {
            return Err(invalid(format!("triangle {t} refers to vertex {bad}, but there are {nv} vertices")));
        }
    }
    let mut used = vec![false; nv];
    for tri in &surface.triangles {
        tri.iter().for_each(|&k| used[k] = true);
    }
    let used_vertices = surface.vertices.iter().enumerate().filter(|&(v, _)| used[v]);
    if let Some((v, fault)) = crate::coordinate_fault(used_vertices, crate::MAX_COORDINATE) {
        return Err(invalid(format!("vertex {v} {fault}")));
    }
    Ok(used)
}

/// The pairs (i < j, sorted) of triangles that intersect, other than neighbours.
///
/// Candidate pairs come from a bounding-box hierarchy over the triangles (about O(n log n) for a
/// surface). Triangles that share an edge are not tested (a fold between two neighbours is not
/// found). Triangles that share exactly one vertex s, (s, a, b) and (s, c, d), are tested with
/// care: they meet beyond s only if segment ab meets the second triangle or segment cd the first,
/// since the far end of their common part lies on one of these edges. Other pairs intersect when
/// an edge of one meets the other (touching counts). A segment crosses a triangle's plane at a
/// computed point that is tested inside the triangle, so nearly coplanar neighbours in a flat
/// region do not raise false alarms; triangles whose corners lie within 1e-12 of their size from
/// each other's plane are tested in that plane. Triangles with bad indices, non-finite
/// coordinates or no area are skipped.
pub fn self_intersections(surface: &TriSurface) -> Vec<(usize, usize)> {
    let nv = surface.vertices.len();
    let valid: Vec<bool> = surface
        .triangles
        .iter()
        .map(|t| {
            t.iter().all(|&k| k < nv && surface.vertices[k].iter().all(|c| c.is_finite()))
                && norm(area_vector(t.map(|k| surface.vertices[k]))) > 0.0
        })
        .collect();
    let boxes: Vec<(Point, Point)> = surface
        .triangles
        .iter()
        .zip(&valid)
        .map(|(t, &ok)| if ok { bounds(&t.map(|k| surface.vertices[k])) } else { ([f64::NAN; 3], [f64::NAN; 3]) })
        .collect();
    let tree = BoxTree::new(&boxes, &valid);
    let mut pairs: Vec<(usize, usize)> = (0..surface.triangles.len())
        .into_par_iter()
        .filter(|&i| valid[i])
        .flat_map_iter(|i| {
            let mut found = Vec::new();
            tree.overlapping(boxes[i], |j| {
                if j > i && triangles_cross(surface, i, j) {
                    found.push((i, j));
                }
            });
            found
        })
        .collect();
    pairs.sort_unstable();
    pairs
}

/// The largest extent of the bounding box of the vertices the triangles use (0 when none;
/// out-of-range indices are ignored).
pub fn largest_extent(surface: &TriSurface) -> f64 {
    extent_of(surface, &surface.triangles)
}

/// The largest extent of the bounding box of the vertices of `surface` that `triangles` use.
fn extent_of(surface: &TriSurface, triangles: &[[usize; 3]]) -> f64 {
    let points: Vec<Point> = triangles.iter().flatten().filter_map(|&k| surface.vertices.get(k).copied()).collect();
    if points.is_empty() {
        return 0.0;
    }
    crate::longest_side(bounds(&points))
}

/// The length unit of an organ's surface, from its size: a largest extent within an organ's
/// ([`ORGAN_EXTENT_M`]) is in metres, and one within it in millimetres is in millimetres.
/// Any other extent is an error that gives it and asks for the unit.
/// A surface of several pieces is told as such when its largest piece alone would be an organ
/// ([`scattered_pieces`]).
pub fn detect_unit(surface: &TriSurface) -> Result<LengthUnit, MeshError> {
    let extent = largest_extent(surface);
    if let Some(unit) = unit_of_organ_extent(extent) {
        return Ok(unit);
    }
    if let Some(pieces) = scattered_pieces(surface) {
        return Err(invalid(pieces));
    }
    let (low, high) = (*ORGAN_EXTENT_M.start(), *ORGAN_EXTENT_M.end());
    let mm = |metres: f64| number(LengthUnit::Millimetre.from_metres(metres));
    Err(invalid(format!(
        "cannot tell the length unit: the largest extent is {}, which is neither an organ in metres ({} to {}) \
         nor in millimetres ({} to {}); give the unit explicitly",
        number(extent),
        number(low),
        number(high),
        mm(low),
        mm(high)
    )))
}

/// What is wrong with a surface of several pieces too large together to be an organ in metres or
/// millimetres, whose largest piece alone would be one (two organs exported together, far apart):
/// the pieces, not the unit; `None` for any other surface.
pub fn scattered_pieces(surface: &TriSurface) -> Option<String> {
    let extent = largest_extent(surface);
    let pieces = surface.pieces();
    if pieces.len() < 2 || unit_of_organ_extent(extent).is_some() {
        return None;
    }
    let largest = pieces.iter().max_by_key(|p| p.len())?;
    let largest = extent_of(surface, &largest.iter().map(|&t| surface.triangles[t]).collect::<Vec<_>>());
    let unit = unit_of_organ_extent(largest)?;
    Some(format!(
        "it is {} separate pieces spread over {}; its largest, {} across, would be an organ in {}: keep the organ \
         only (an organ surface is one piece)",
        pieces.len(),
        number(extent),
        number(largest),
        unit.name()
    ))
}

/// The unit in which a surface whose largest extent is `extent` (in the file's numbers) is an
/// organ: metres, else millimetres; `None` for neither.
fn unit_of_organ_extent(extent: f64) -> Option<LengthUnit> {
    [LengthUnit::Metre, LengthUnit::Millimetre].into_iter().find(|u| ORGAN_EXTENT_M.contains(&u.to_metres(extent)))
}

/// The number of distinct triangles in a list of pairs.
fn crossing_triangles(pairs: &[(usize, usize)]) -> usize {
    let mut triangles: Vec<usize> = pairs.iter().flat_map(|&(a, b)| [a, b]).collect();
    triangles.sort_unstable();
    triangles.dedup();
    triangles.len()
}

fn invalid(message: impl Into<String>) -> MeshError {
    MeshError::Invalid(message.into())
}

fn point_text(p: Point) -> String {
    format!("({}, {}, {})", number(p[0]), number(p[1]), number(p[2]))
}

/// Where vertex `v` (of the repaired numbering) is: its input number and coordinates.
fn vertex_text(surface: &TriSurface, origin: &[usize], v: usize) -> String {
    format!("{} at {}", origin[v], point_text(surface.vertices[v]))
}

fn area(vertices: &[Point], t: [usize; 3]) -> f64 {
    norm(area_vector(t.map(|k| vertices[k])))
}

/// Maps each used vertex to the first vertex (in index order) within `tolerance` of it, found by
/// spatial hashing in cells of that size (exactly equal coordinates when it is zero); returns
/// the map (identity for unused vertices) and the number of vertices merged.
fn merge_vertices(vertices: &[Point], used: &[bool], tolerance: f64) -> (Vec<usize>, usize) {
    let mut representative: Vec<usize> = (0..vertices.len()).collect();
    let mut merged = 0;
    if tolerance > 0.0 {
        let cell = |p: Point| p.map(|c| (c / tolerance).floor() as i64);
        let mut grid: HashMap<[i64; 3], Vec<usize>> = HashMap::new();
        for v in (0..vertices.len()).filter(|&v| used[v]) {
            let p = vertices[v];
            let c = cell(p);
            let mut best = usize::MAX;
            for dx in -1..=1 {
                for dy in -1..=1 {
                    for dz in -1..=1 {
                        let key = [c[0] + dx, c[1] + dy, c[2] + dz];
                        for &r in grid.get(&key).into_iter().flatten() {
                            if r < best && norm(sub(vertices[r], p)) < tolerance {
                                best = r;
                            }
                        }
                    }
                }
            }
            if best == usize::MAX {
                grid.entry(c).or_default().push(v);
            } else {
                representative[v] = best;
                merged += 1;
            }
        }
    } else {
        // -0.0 and 0.0 are the same place.
        let key = |p: Point| p.map(|c| if c == 0.0 { 0 } else { c.to_bits() });
        let mut first: HashMap<[u64; 3], usize> = HashMap::new();
        for v in (0..vertices.len()).filter(|&v| used[v]) {
            let r = *first.entry(key(vertices[v])).or_insert(v);
            if r != v {
                representative[v] = r;
                merged += 1;
            }
        }
    }
    (representative, merged)
}

/// For each triangle and each of its edges (k, k+1), the triangle across it (`usize::MAX` on
/// the boundary); an edge of more than two triangles is an error.
fn edge_neighbours(surface: &TriSurface, origin: &[usize]) -> Result<Vec<[usize; 3]>, MeshError> {
    let mut edges: Vec<(usize, usize, usize, usize)> = Vec::with_capacity(3 * surface.triangles.len());
    for (t, tri) in surface.triangles.iter().enumerate() {
        for e in 0..3 {
            let (a, b) = (tri[e], tri[(e + 1) % 3]);
            edges.push((a.min(b), a.max(b), t, e));
        }
    }
    edges.sort_unstable();
    let mut neighbours = vec![[usize::MAX; 3]; surface.triangles.len()];
    for group in edges.chunk_by(|x, y| (x.0, x.1) == (y.0, y.1)) {
        match group {
            [_] => {}
            [(_, _, t, e), (_, _, u, f)] => {
                neighbours[*t][*e] = *u;
                neighbours[*u][*f] = *t;
            }
            _ => {
                let (a, b) = (group[0].0, group[0].1);
                return Err(invalid(format!(
                    "non-manifold edge between vertices {} and {}: shared by {} triangles; \
                     cannot be repaired automatically",
                    vertex_text(surface, origin, a),
                    vertex_text(surface, origin, b),
                    group.len()
                )));
            }
        }
    }
    Ok(neighbours)
}

/// Each vertex's triangles must form one fan, linked through the edges at the vertex; a vertex
/// where two fans touch (two cones tip to tip, a pinched hole) is an error.
fn check_fans(surface: &TriSurface, neighbours: &[[usize; 3]], origin: &[usize]) -> Result<(), MeshError> {
    // Corner 3t + k: triangle t at its k-th vertex. Neighbours across an edge join the corners at
    // both ends of the edge.
    let tris = &surface.triangles;
    let mut parent: Vec<usize> = (0..3 * tris.len()).collect();
    let corner = |t: usize, v: usize| 3 * t + tris[t].iter().position(|&k| k == v).unwrap_or(0);
    for (t, tri) in tris.iter().enumerate() {
        for e in 0..3 {
            let u = neighbours[t][e];
            if u == usize::MAX || u < t {
                continue;
            }
            for v in [tri[e], tri[(e + 1) % 3]] {
                let x = root(&mut parent, corner(t, v));
                let y = root(&mut parent, corner(u, v));
                parent[x] = y;
            }
        }
    }
    let nv = surface.vertices.len();
    let mut fan = vec![usize::MAX; nv];
    let mut bad = usize::MAX;
    for (t, tri) in tris.iter().enumerate() {
        for (k, &v) in tri.iter().enumerate() {
            let r = root(&mut parent, 3 * t + k);
            if fan[v] == usize::MAX {
                fan[v] = r;
            } else if fan[v] != r {
                bad = bad.min(v);
            }
        }
    }
    if bad == usize::MAX {
        return Ok(());
    }
    let corners: Vec<usize> = tris
        .iter()
        .enumerate()
        .flat_map(|(t, tri)| (0..3).filter(move |&k| tri[k] == bad).map(move |k| 3 * t + k))
        .collect();
    let mut fans: Vec<usize> = corners.into_iter().map(|c| root(&mut parent, c)).collect();
    fans.sort_unstable();
    fans.dedup();
    Err(invalid(format!(
        "non-manifold vertex {}: its triangles form {} separate fans; cannot be repaired automatically",
        vertex_text(surface, origin, bad),
        fans.len()
    )))
}

/// Orients the triangles of each piece (triangles linked through shared edges) alike,
/// breadth-first from its first triangle, then keeps the orientation of the majority. Returns
/// the number of triangles turned and the number of triangles of each piece.
fn orient_consistently(
    surface: &mut TriSurface,
    neighbours: &[[usize; 3]],
    origin: &[usize],
) -> Result<(usize, Vec<usize>), MeshError> {
    let n = surface.triangles.len();
    // +1: keep, -1: turn, 0: not reached yet.
    let mut sign = vec![0i8; n];
    let mut pieces = Vec::new();
    let mut flipped = 0;
    let mut queue = std::collections::VecDeque::new();
    let mut piece = Vec::new();
    for seed in 0..n {
        if sign[seed] != 0 {
            continue;
        }
        sign[seed] = 1;
        queue.push_back(seed);
        piece.clear();
        while let Some(t) = queue.pop_front() {
            piece.push(t);
            let tri = surface.triangles[t];
            for e in 0..3 {
                let u = neighbours[t][e];
                if u == usize::MAX {
                    continue;
                }
                // Consistent neighbours traverse the shared edge in opposite directions.
                let (a, b) = (tri[e], tri[(e + 1) % 3]);
                let same_direction =
                    (0..3).any(|f| surface.triangles[u][f] == a && surface.triangles[u][(f + 1) % 3] == b);
                let wanted = if same_direction { -sign[t] } else { sign[t] };
                if sign[u] == 0 {
                    sign[u] = wanted;
                    queue.push_back(u);
                } else if sign[u] != wanted {
                    return Err(invalid(format!(
                        "the surface is not orientable (like a Möbius strip): triangles {t} and {u} cannot agree \
                         across the edge between vertices {} and {}; cannot be repaired automatically",
                        vertex_text(surface, origin, a),
                        vertex_text(surface, origin, b)
                    )));
                }
            }
        }
        let turned = piece.iter().filter(|&&t| sign[t] < 0).count();
        if 2 * turned > piece.len() {
            piece.iter().for_each(|&t| sign[t] = -sign[t]);
        }
        flipped += turned.min(piece.len() - turned);
        pieces.push(piece.len());
    }
    for (tri, &s) in surface.triangles.iter_mut().zip(&sign) {
        if s < 0 {
            tri.swap(1, 2);
        }
    }
    Ok((flipped, pieces))
}

/// Fills every boundary loop of a consistently oriented, vertex-manifold surface (see
/// [`min_area_fill`]); a loop of more than `max_edges` edges is an error.
fn fill_holes(
    surface: &mut TriSurface,
    max_edges: usize,
    min_area: f64,
    origin: &[usize],
    report: &mut RepairReport,
) -> Result<(), MeshError> {
    let nv = surface.vertices.len();
    let mut edges: Vec<(usize, usize, usize)> = Vec::with_capacity(3 * surface.triangles.len());
    for (t, tri) in surface.triangles.iter().enumerate() {
        for e in 0..3 {
            let (a, b) = (tri[e], tri[(e + 1) % 3]);
            edges.push((a.min(b), a.max(b), t));
        }
    }
    edges.sort_unstable();
    // The holes run against their triangles' edges: boundary edge a -> b of triangle t is
    // b -> a around the hole; `owner` maps the hole's edge to t.
    let mut next = vec![usize::MAX; nv];
    let mut owner: HashMap<(usize, usize), usize> = HashMap::new();
    let mut existing: HashSet<(usize, usize)> = HashSet::with_capacity(edges.len() / 2);
    for group in edges.chunk_by(|x, y| (x.0, x.1) == (y.0, y.1)) {
        existing.insert((group[0].0, group[0].1));
        if let [(lo, hi, t)] = *group {
            let tri = surface.triangles[t];
            let forward = (0..3).any(|e| tri[e] == lo && tri[(e + 1) % 3] == hi);
            let (a, b) = if forward { (lo, hi) } else { (hi, lo) };
            if next[b] != usize::MAX {
                return Err(invalid(format!(
                    "non-manifold vertex {}: two holes meet there; cannot be repaired automatically",
                    vertex_text(surface, origin, b)
                )));
            }
            next[b] = a;
            owner.insert((b, a), t);
        }
    }
    let mut loops: Vec<Vec<usize>> = Vec::new();
    let mut visited = vec![false; nv];
    for start in 0..nv {
        if next[start] == usize::MAX || visited[start] {
            continue;
        }
        let mut hole = vec![start];
        visited[start] = true;
        let mut v = next[start];
        while v != start {
            if v == usize::MAX || visited[v] {
                return Err(invalid(format!(
                    "the boundary through vertex {} does not close; cannot be repaired automatically",
                    vertex_text(surface, origin, start)
                )));
            }
            visited[v] = true;
            hole.push(v);
            v = next[v];
        }
        loops.push(hole);
    }
    if let Some(largest) = loops.iter().max_by_key(|h| h.len()).filter(|h| h.len() > max_edges) {
        let others = loops.len() - 1;
        return Err(invalid(format!(
            "hole of {} edges (through vertex {}) is larger than the {max_edges} edges filled automatically{}; \
             cannot be repaired automatically: is the surface cut open?",
            largest.len(),
            vertex_text(surface, origin, largest[0]),
            if others > 0 { format!(" ({others} other holes)") } else { String::new() }
        )));
    }
    let faces: HashSet<[usize; 3]> = surface
        .triangles
        .iter()
        .map(|t| {
            let mut k = *t;
            k.sort_unstable();
            k
        })
        .collect();
    for hole in &loops {
        let n = hole.len();
        if let Some(mut fill) = min_area_fill(&surface.vertices, hole, &existing, &faces, min_area) {
            if n >= REFINED_HOLE_EDGES {
                let before = surface.vertices.len();
                fill = refine_patch(&mut surface.vertices, hole, fill, &existing);
                report.added_vertices += surface.vertices.len() - before;
            }
            report.added_triangles += fill.len();
            surface.triangles.extend(fill);
        } else if let Some((t, split)) = split_across_slit(surface, hole, &owner, &existing, min_area) {
            surface.triangles[t] = split[0];
            surface.triangles.push(split[1]);
            report.added_triangles += 1;
        } else {
            return Err(invalid(format!(
                "hole of {n} edges through vertex {} cannot be filled without degenerate or non-manifold \
                 triangles; cannot be repaired automatically",
                vertex_text(surface, origin, hole[0])
            )));
        }
        report.holes_filled.push(n);
    }
    Ok(())
}

/// Holes of at least this many edges get their patch refined and faired ([`refine_patch`]):
/// the least-area triangulation of a large hole is a fan of slivers, which meshes badly.
const REFINED_HOLE_EDGES: usize = 16;

/// Refines the patch `fill` that closes `hole` (Liepa 2003, "Filling holes in meshes"): a
/// triangle is split at its centroid while the centroid lies farther than its local edge length
/// (interpolated from the hole's boundary edges) times √2 from each corner, the patch's inner
/// edges are flipped towards Delaunay triangles after each round, and the new vertices are moved
/// to the mean of their neighbours (a membrane spanned by the hole's boundary, which stays
/// fixed). Returns the patch's triangles; the new vertices are appended to `vertices`.
fn refine_patch(
    vertices: &mut Vec<Point>,
    hole: &[usize],
    fill: Vec<[usize; 3]>,
    existing: &HashSet<(usize, usize)>,
) -> Vec<[usize; 3]> {
    let first_new = vertices.len();
    let n = hole.len();
    let mut scale: HashMap<usize, f64> = HashMap::new();
    for (i, &v) in hole.iter().enumerate() {
        let length = |a: usize, b: usize| norm(sub(vertices[a], vertices[b]));
        let (before, after) = (hole[(i + n - 1) % n], hole[(i + 1) % n]);
        scale.insert(v, 0.5 * (length(before, v) + length(v, after)));
    }
    let mut patch = fill;
    for _ in 0..MAX_REFINE_ROUNDS {
        let mut split = false;
        let mut next = Vec::with_capacity(patch.len());
        for t in patch {
            let corners = t.map(|v| vertices[v]);
            let centre: Point = std::array::from_fn(|d| corners.iter().map(|p| p[d]).sum::<f64>() / 3.0);
            let sigma = t.iter().map(|v| scale[v]).sum::<f64>() / 3.0;
            let far = (0..3).all(|k| {
                let reach = std::f64::consts::SQRT_2 * norm(sub(centre, corners[k]));
                reach > sigma && reach > scale[&t[k]]
            });
            if far {
                let c = vertices.len();
                vertices.push(centre);
                scale.insert(c, sigma);
                next.extend([[t[0], t[1], c], [t[1], t[2], c], [t[2], t[0], c]]);
                split = true;
            } else {
                next.push(t);
            }
        }
        patch = next;
        flip_to_delaunay(vertices, &mut patch, existing);
        if !split {
            break;
        }
    }
    // The membrane: each new vertex at the mean of its neighbours, the boundary fixed.
    let mut neighbours: BTreeMap<usize, BTreeSet<usize>> = BTreeMap::new();
    for t in &patch {
        for k in 0..3 {
            if t[k] >= first_new {
                neighbours.entry(t[k]).or_default().extend([t[(k + 1) % 3], t[(k + 2) % 3]]);
            }
        }
    }
    let order: Vec<(usize, Vec<usize>)> = neighbours.into_iter().map(|(v, n)| (v, n.into_iter().collect())).collect();
    for _ in 0..FAIRING_SWEEPS {
        for (v, around) in &order {
            let mean =
                std::array::from_fn(|d| around.iter().map(|&u| vertices[u][d]).sum::<f64>() / around.len() as f64);
            vertices[*v] = mean;
        }
    }
    flip_to_delaunay(vertices, &mut patch, existing);
    patch
}

/// Rounds of splitting in [`refine_patch`] (each at most triples a triangle's count).
const MAX_REFINE_ROUNDS: usize = 30;

/// Gauss–Seidel sweeps of the membrane in [`refine_patch`].
const FAIRING_SWEEPS: usize = 200;

/// Flips the inner edges of `patch` (edges two of its triangles share) whose opposite angles sum
/// to more than π, until none does, unless the flipped edge is already an edge of the surface
/// (`existing`) or of the patch.
fn flip_to_delaunay(vertices: &[Point], patch: &mut [[usize; 3]], existing: &HashSet<(usize, usize)>) {
    let angle = |at: usize, a: usize, b: usize| {
        let (u, v) = (sub(vertices[a], vertices[at]), sub(vertices[b], vertices[at]));
        norm(cross(u, v)).atan2(dot(u, v))
    };
    for _ in 0..patch.len() {
        let mut edges: BTreeMap<(usize, usize), Vec<usize>> = BTreeMap::new();
        for (i, t) in patch.iter().enumerate() {
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                edges.entry((a.min(b), a.max(b))).or_default().push(i);
            }
        }
        let mut flipped = false;
        let mut touched = vec![false; patch.len()];
        for (&(lo, hi), owners) in &edges {
            let &[i, j] = owners.as_slice() else { continue };
            if touched[i] || touched[j] {
                continue;
            }
            // t1 = (a, b, c), t2 = (b, a, d).
            let t1 = patch[i];
            let Some(k) = (0..3).find(|&k| {
                let (a, b) = (t1[k], t1[(k + 1) % 3]);
                (a.min(b), a.max(b)) == (lo, hi)
            }) else {
                continue;
            };
            let (a, b, c) = (t1[k], t1[(k + 1) % 3], t1[(k + 2) % 3]);
            let Some(&d) = patch[j].iter().find(|&&v| v != a && v != b) else { continue };
            let diagonal = (c.min(d), c.max(d));
            if c == d || existing.contains(&diagonal) || edges.contains_key(&diagonal) {
                continue;
            }
            if angle(c, a, b) + angle(d, b, a) > std::f64::consts::PI + 1e-9 {
                let (n1, n2) = (
                    area_vector([vertices[a], vertices[d], vertices[c]]),
                    area_vector([vertices[d], vertices[b], vertices[c]]),
                );
                if dot(n1, n2) > 0.0 {
                    patch[i] = [a, d, c];
                    patch[j] = [d, b, c];
                    touched[i] = true;
                    touched[j] = true;
                    flipped = true;
                }
            }
        }
        if !flipped {
            break;
        }
    }
}

/// The minimum-area triangulation of the polygon `hole` (vertex indices, in the direction the
/// new triangles traverse them), by dynamic programming over its sub-polygons: W(i, j) = min over
/// i < m < j of W(i, m) + W(m, j) + area(i, m, j). Triangles without area and diagonals that are
/// already edges of the surface are not allowed; `None` when no triangulation is left.
fn min_area_fill(
    vertices: &[Point],
    hole: &[usize],
    existing: &HashSet<(usize, usize)>,
    faces: &HashSet<[usize; 3]>,
    min_area: f64,
) -> Option<Vec<[usize; 3]>> {
    let n = hole.len();
    if n < 3 {
        return None;
    }
    if n == 3 {
        let mut key = [hole[0], hole[1], hole[2]];
        key.sort_unstable();
        if faces.contains(&key) {
            return None;
        }
    }
    let at = |i: usize, j: usize| i * n + j;
    let mut weight = vec![f64::INFINITY; n * n];
    let mut choice = vec![0usize; n * n];
    for i in 0..n - 1 {
        weight[at(i, i + 1)] = 0.0;
    }
    for span in 2..n {
        for i in 0..n - span {
            let j = i + span;
            let (a, b) = (hole[i], hole[j]);
            if span < n - 1 && existing.contains(&(a.min(b), a.max(b))) {
                continue;
            }
            for m in i + 1..j {
                let w = weight[at(i, m)] + weight[at(m, j)];
                if w >= weight[at(i, j)] {
                    continue;
                }
                let s = area(vertices, [hole[i], hole[m], hole[j]]);
                if s > min_area && w + s < weight[at(i, j)] {
                    weight[at(i, j)] = w + s;
                    choice[at(i, j)] = m;
                }
            }
        }
    }
    if !weight[at(0, n - 1)].is_finite() {
        return None;
    }
    let mut fill = Vec::with_capacity(n - 2);
    let mut stack = vec![(0, n - 1)];
    while let Some((i, j)) = stack.pop() {
        if j - i < 2 {
            continue;
        }
        let m = choice[at(i, j)];
        fill.push([hole[i], hole[m], hole[j]]);
        stack.push((i, m));
        stack.push((m, j));
    }
    Some(fill)
}

/// A hole of three edges whose corners lie on a line (left by a zero-area triangle): the
/// triangle across its longest edge, split at the opposite corner into two that close it.
fn split_across_slit(
    surface: &TriSurface,
    hole: &[usize],
    owner: &HashMap<(usize, usize), usize>,
    existing: &HashSet<(usize, usize)>,
    min_area: f64,
) -> Option<(usize, [[usize; 3]; 2])> {
    if hole.len() != 3 {
        return None;
    }
    let length = |k: usize| norm(sub(surface.vertices[hole[(k + 1) % 3]], surface.vertices[hole[k]]));
    let k = (0..3).max_by(|&a, &b| length(a).total_cmp(&length(b)))?;
    let (w, u, c) = (hole[k], hole[(k + 1) % 3], hole[(k + 2) % 3]);
    // The hole runs w -> u, so triangle t runs u -> w: rotate it to (u, w, x).
    let t = *owner.get(&(w, u))?;
    let tri = surface.triangles[t];
    let r = (0..3).find(|&r| tri[r] == u && tri[(r + 1) % 3] == w)?;
    let x = tri[(r + 2) % 3];
    let split = [[u, c, x], [c, w, x]];
    let ok = !existing.contains(&(c.min(x), c.max(x))) && split.iter().all(|&s| area(&surface.vertices, s) > min_area);
    ok.then_some((t, split))
}

/// Whether triangles i and j of a surface intersect (see [`self_intersections`]).
fn triangles_cross(surface: &TriSurface, i: usize, j: usize) -> bool {
    let (ti, tj) = (surface.triangles[i], surface.triangles[j]);
    let p = |t: [usize; 3]| t.map(|k| surface.vertices[k]);
    let shared: Vec<usize> = ti.iter().copied().filter(|k| tj.contains(k)).collect();
    match shared[..] {
        [] => {
            let (a, b) = (p(ti), p(tj));
            (0..3).any(|e| segment_meets_triangle(a[e], a[(e + 1) % 3], b))
                || (0..3).any(|e| segment_meets_triangle(b[e], b[(e + 1) % 3], a))
        }
        [s] => {
            // Rotate each so that the shared vertex comes first; test the opposite edges.
            let rotate = |t: [usize; 3]| {
                let r = t.iter().position(|&k| k == s).unwrap_or(0);
                [t[r], t[(r + 1) % 3], t[(r + 2) % 3]]
            };
            let (a, b) = (p(rotate(ti)), p(rotate(tj)));
            segment_meets_triangle(a[1], a[2], b) || segment_meets_triangle(b[1], b[2], a)
        }
        _ => false,
    }
}

/// Whether the closed segment pq meets the closed triangle t (of non-zero area).
fn segment_meets_triangle(p: Point, q: Point, t: [Point; 3]) -> bool {
    let normal = cross(sub(t[1], t[0]), sub(t[2], t[0]));
    let length = norm(normal).sqrt().max(norm(sub(q, p)));
    let unit_normal = normal.map(|c| c / norm(normal));
    let dp = dot(unit_normal, sub(p, t[0]));
    let dq = dot(unit_normal, sub(q, t[0]));
    let tolerance = 1e-12 * length;
    let side = |d: f64| {
        if d > tolerance {
            1
        } else if d < -tolerance {
            -1
        } else {
            0
        }
    };
    let (sp, sq) = (side(dp), side(dq));
    if sp * sq > 0 {
        return false;
    }
    // Project onto the coordinate plane most nearly parallel to the triangle.
    let axis = (0..3).max_by(|&a, &b| normal[a].abs().total_cmp(&normal[b].abs())).unwrap_or(2);
    let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
    let flat = |x: Point| [x[u], x[v]];
    let tri = t.map(flat);
    if sp == 0 && sq == 0 {
        let (a, b) = (flat(p), flat(q));
        return inside_2d(a, tri)
            || inside_2d(b, tri)
            || (0..3).any(|e| segments_meet_2d(a, b, tri[e], tri[(e + 1) % 3]));
    }
    let s = if sp == 0 {
        0.0
    } else if sq == 0 {
        1.0
    } else {
        (dp / (dp - dq)).clamp(0.0, 1.0)
    };
    let x = std::array::from_fn(|d| p[d] + s * (q[d] - p[d]));
    inside_2d(flat(x), tri)
}

fn orient_2d(a: [f64; 2], b: [f64; 2], c: [f64; 2]) -> f64 {
    (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
}

/// Whether x lies in the closed triangle t (either orientation).
fn inside_2d(x: [f64; 2], t: [[f64; 2]; 3]) -> bool {
    let o = [orient_2d(t[0], t[1], x), orient_2d(t[1], t[2], x), orient_2d(t[2], t[0], x)];
    o.iter().all(|&s| s >= 0.0) || o.iter().all(|&s| s <= 0.0)
}

/// Whether the closed segments ab and cd meet.
fn segments_meet_2d(a: [f64; 2], b: [f64; 2], c: [f64; 2], d: [f64; 2]) -> bool {
    let (d1, d2) = (orient_2d(c, d, a), orient_2d(c, d, b));
    let (d3, d4) = (orient_2d(a, b, c), orient_2d(a, b, d));
    if d1 * d2 < 0.0 && d3 * d4 < 0.0 {
        return true;
    }
    let within =
        |p: [f64; 2], q: [f64; 2], x: [f64; 2]| (0..2).all(|k| p[k].min(q[k]) <= x[k] && x[k] <= p[k].max(q[k]));
    (d1 == 0.0 && within(c, d, a))
        || (d2 == 0.0 && within(c, d, b))
        || (d3 == 0.0 && within(a, b, c))
        || (d4 == 0.0 && within(a, b, d))
}

/// A bounding-box hierarchy over a list of boxes (median splits on the longest axis), for the
/// pairs of overlapping boxes.
struct BoxTree {
    nodes: Vec<BoxNode>,
    order: Vec<usize>,
    boxes: Vec<(Point, Point)>,
}

#[derive(Clone, Copy)]
struct BoxNode {
    lo: Point,
    hi: Point,
    /// Range of `order` in a leaf; for an inner node `start` is its first child (the second
    /// follows) and `end` is zero.
    start: usize,
    end: usize,
}

const BOX_LEAF: usize = 4;

impl BoxTree {
    /// The hierarchy over the boxes whose `keep` is true.
    fn new(boxes: &[(Point, Point)], keep: &[bool]) -> Self {
        let order: Vec<usize> = (0..boxes.len()).filter(|&i| keep[i]).collect();
        let mut tree = BoxTree { nodes: Vec::new(), order, boxes: boxes.to_vec() };
        if !tree.order.is_empty() {
            tree.nodes.push(BoxNode { lo: [0.0; 3], hi: [0.0; 3], start: 0, end: 0 });
            tree.build(0, 0, tree.order.len());
        }
        tree
    }

    fn build(&mut self, node: usize, start: usize, end: usize) {
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        let mut clo = [f64::INFINITY; 3];
        let mut chi = [f64::NEG_INFINITY; 3];
        for &i in &self.order[start..end] {
            let (a, b) = self.boxes[i];
            for d in 0..3 {
                lo[d] = lo[d].min(a[d]);
                hi[d] = hi[d].max(b[d]);
                clo[d] = clo[d].min(a[d] + b[d]);
                chi[d] = chi[d].max(a[d] + b[d]);
            }
        }
        if end - start <= BOX_LEAF {
            self.nodes[node] = BoxNode { lo, hi, start, end };
            return;
        }
        let axis = (0..3).max_by(|&a, &b| (chi[a] - clo[a]).total_cmp(&(chi[b] - clo[b]))).unwrap_or(0);
        let mid = (start + end) / 2;
        let boxes = &self.boxes;
        let key = |i: usize| boxes[i].0[axis] + boxes[i].1[axis];
        self.order[start..end].select_nth_unstable_by(mid - start, |&a, &b| key(a).total_cmp(&key(b)));
        let left = self.nodes.len();
        self.nodes.push(BoxNode { lo, hi, start: 0, end: 0 });
        self.nodes.push(BoxNode { lo, hi, start: 0, end: 0 });
        self.build(left, start, mid);
        self.build(left + 1, mid, end);
        self.nodes[node] = BoxNode { lo, hi, start: left, end: 0 };
    }

    /// Calls `f` with every box that overlaps `query` (touching counts).
    fn overlapping(&self, query: (Point, Point), mut f: impl FnMut(usize)) {
        if self.nodes.is_empty() {
            return;
        }
        let meets = |lo: Point, hi: Point| (0..3).all(|d| lo[d] <= query.1[d] && query.0[d] <= hi[d]);
        let mut stack = vec![0usize];
        while let Some(i) = stack.pop() {
            let node = self.nodes[i];
            if !meets(node.lo, node.hi) {
                continue;
            }
            if node.end > 0 {
                for &k in &self.order[node.start..node.end] {
                    let (lo, hi) = self.boxes[k];
                    if meets(lo, hi) {
                        f(k);
                    }
                }
            } else {
                stack.push(node.start);
                stack.push(node.start + 1);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::icosphere;

    /// Level 2: 162 vertices, 320 triangles.
    fn sphere() -> TriSurface {
        icosphere(1.0, 2)
    }

    fn repair(surface: &TriSurface) -> Result<(TriSurface, RepairReport), MeshError> {
        repair_surface(surface, &RepairOptions::default())
    }

    fn error(surface: &TriSurface) -> String {
        repair(surface).expect_err("the repair should refuse").to_string()
    }

    /// The surface is closed and outward, with the given counts and a volume within 1 % of `volume`.
    fn assert_closed(s: &TriSurface, vertices: usize, triangles: usize, volume: f64) {
        let checked = check_closed_manifold(s).unwrap();
        assert_eq!(s.vertices.len(), vertices);
        assert_eq!(s.triangles.len(), triangles);
        assert!((checked.volume - volume).abs() < 0.01 * volume, "volume {} instead of {volume}", checked.volume);
        assert!(self_intersections(s).is_empty());
    }

    /// The triangles whose centroid lies within `r` of `p`.
    fn near(s: &TriSurface, p: Point, r: f64) -> Vec<usize> {
        (0..s.triangles.len())
            .filter(|&t| {
                let c: Point =
                    std::array::from_fn(|d| s.triangles[t].iter().map(|&k| s.vertices[k][d]).sum::<f64>() / 3.0);
                norm(sub(c, p)) < r
            })
            .collect()
    }

    fn without(s: &TriSurface, removed: &[usize]) -> TriSurface {
        let triangles = (0..s.triangles.len()).filter(|t| !removed.contains(t)).map(|t| s.triangles[t]).collect();
        TriSurface { vertices: s.vertices.clone(), triangles }
    }

    #[test]
    fn a_closed_surface_is_unchanged() {
        let s = sphere();
        let (repaired, report) = repair(&s).unwrap();
        assert_eq!(repaired, s);
        assert!(!report.changed());
        assert!(report.lines().is_empty() && report.warnings().is_empty());
        assert!(self_intersections(&s).is_empty());
    }

    #[test]
    fn a_hole_of_one_triangle_is_filled() {
        let s = sphere();
        let volume = s.enclosed_volume();
        let (repaired, report) = repair(&without(&s, &[17])).unwrap();
        assert_closed(&repaired, 162, 320, volume);
        assert_eq!(report.holes_filled, vec![3]);
        assert_eq!(report.added_triangles, 1);
        assert_eq!(report.lines(), vec!["filled 1 hole (3 edges) with 1 triangle"]);
    }

    #[test]
    fn holes_of_several_triangles_are_filled_without_new_vertices() {
        let s = sphere();
        let volume = s.enclosed_volume();
        // A cap around a vertex of the icosahedron (valence 5): its fan and the ring beyond.
        let cap = near(&s, s.vertices[0], 0.45);
        // Two triangles on the other side.
        let pair = vec![near(&s, s.vertices[3], 0.2)[0], near(&s, s.vertices[3], 0.2)[1]];
        let removed: Vec<usize> = cap.iter().chain(&pair).copied().collect();
        let damaged = without(&s, &removed);
        let (repaired, report) = repair(&damaged).unwrap();
        // The cap's interior vertices are gone; each hole of n edges takes n - 2 triangles.
        let unused = report.removed_unused_vertices;
        assert!(unused >= 1, "{report:?}");
        assert_eq!(report.holes_filled.len(), 2, "{report:?}");
        let added: usize = report.holes_filled.iter().map(|n| n - 2).sum();
        assert_eq!(report.added_triangles, added);
        assert_closed(&repaired, 162 - unused, 320 - removed.len() + added, volume);
        // The cap is flattened: the volume drops a little, less than 1 %.
        assert!(repaired.enclosed_volume() < volume);
        assert_eq!(report.flipped_triangles, 0);
        assert!(!report.reversed);
    }

    /// A sphere cut by a plane (as an image's field of view cuts an organ) is closed, and the
    /// patch's share of the surface is said when it is large, not when a triangle is missing.
    #[test]
    fn a_large_hole_filled_is_said_to_be_large() {
        let s = sphere();
        let (_, report) = repair(&without(&s, &[17])).unwrap();
        assert!(report.filled_share > 0.0 && report.filled_share < 0.01, "{}", report.filled_share);
        assert!(report.warnings().is_empty());
        let above: Vec<usize> =
            (0..s.triangles.len()).filter(|&t| s.triangles[t].iter().all(|&k| s.vertices[k][2] > 0.6)).collect();
        let (repaired, report) = repair(&without(&s, &above)).unwrap();
        // The cap above z = 0.6 is 20 % of the sphere's area (2πr·h / 4πr²); its flat patch less.
        let share = report.filled_share;
        assert!(share > 0.1 && share < 0.2, "{share}");
        assert!(repaired.enclosed_volume() < 0.98 * s.enclosed_volume(), "closed flat, lower than the sphere");
        let warnings = report.warnings();
        assert!(warnings[0].starts_with(&format!("the holes filled make up {:.0} % of the surface", 100.0 * share)));
    }

    /// Half a fine sphere, cut open, is closed by a membrane of triangles the size of its
    /// boundary's edges, flat where the cut is, that the mesher's inside test accepts.
    #[test]
    fn a_large_hole_is_closed_by_a_refined_membrane() {
        let s = icosphere(1.0, 4);
        let lower: Vec<usize> =
            (0..s.triangles.len()).filter(|&t| s.triangles[t].iter().any(|&k| s.vertices[k][2] < 0.0)).collect();
        let (repaired, report) = repair(&without(&s, &lower)).unwrap();
        let [n] = report.holes_filled[..] else { panic!("{report:?}") };
        assert!(n >= REFINED_HOLE_EDGES && report.added_vertices > 0, "{report:?}");
        assert_eq!(repaired.vertices.len() - report.added_vertices, s.vertices.len() - report.removed_unused_vertices);
        let checked = check_closed_manifold(&repaired).unwrap();
        let half = 2.0 / 3.0 * std::f64::consts::PI;
        assert!((checked.volume / half - 1.0).abs() < 0.03, "{} vs {half}", checked.volume);
        assert!(self_intersections(&repaired).is_empty());
        crate::bvh::SurfaceBvh::new(&repaired).unwrap().check_winding(0.0).unwrap();
        // The rim lies at z = 0 (the equator's vertices): the membrane is flat there, and its
        // edges are no longer than a few of the rim's.
        let new = repaired.vertices.len() - report.added_vertices..repaired.vertices.len();
        let first = repaired.vertices.len() - report.added_vertices;
        let on_rim = |v: &usize| *v < first;
        let rim_z: Vec<f64> = patch(&repaired, &report)
            .iter()
            .flatten()
            .filter(|v| on_rim(v))
            .map(|&v| repaired.vertices[v][2])
            .collect();
        let (low, high) = rim_z.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &z| (l.min(z), h.max(z)));
        assert!(high - low < 0.05, "the cut's vertices lie within {} of z = 0", high - low);
        assert!(
            new.clone().all(|v| (low - 1e-6..=high + 1e-6).contains(&repaired.vertices[v][2])),
            "a membrane between its rim's heights"
        );
        let rim = 2.0 * std::f64::consts::PI / n as f64;
        let longest = patch(&repaired, &report)
            .iter()
            .flat_map(|t| (0..3).map(|k| norm(sub(repaired.vertices[t[k]], repaired.vertices[t[(k + 1) % 3]]))))
            .fold(0.0, f64::max);
        assert!(longest < 3.0 * rim, "{longest} vs the rim's {rim}");
        let line = format!(
            "filled 1 hole ({n} edges) with {} triangles and {} new vertices",
            report.added_triangles, report.added_vertices
        );
        assert!(report.lines().contains(&line), "{:?}", report.lines());
    }

    /// The triangles a repair added, at the end of its triangles.
    fn patch<'a>(repaired: &'a TriSurface, report: &RepairReport) -> &'a [[usize; 3]] {
        &repaired.triangles[repaired.triangles.len() - report.added_triangles..]
    }

    #[test]
    fn a_triangle_soup_is_welded() {
        let s = sphere();
        let mut soup = TriSurface::default();
        for (t, tri) in s.triangles.iter().enumerate() {
            for &k in tri {
                // Within the tolerance (1e-6 of the diagonal, 3.5e-6 here).
                let wobble = 1e-7 * ((t * 3 + k) % 7) as f64;
                soup.vertices.push(s.vertices[k].map(|c| c + wobble));
            }
            let n = soup.vertices.len();
            soup.triangles.push([n - 3, n - 2, n - 1]);
        }
        let (repaired, report) = repair(&soup).unwrap();
        assert_closed(&repaired, 162, 320, s.enclosed_volume());
        assert_eq!(report.merged_vertices, 3 * 320 - 162);
        assert_eq!(report.lines(), vec!["merged 798 duplicate vertices"]);
        // Exact duplicates merge with a zero tolerance too.
        let mut exact = soup.clone();
        exact.vertices = s.triangles.iter().flat_map(|t| t.map(|k| s.vertices[k])).collect();
        let (repaired, report) =
            repair_surface(&exact, &RepairOptions { merge_tolerance: 0.0, ..Default::default() }).unwrap();
        assert_eq!((repaired.vertices.len(), report.merged_vertices), (162, 798));
    }

    #[test]
    fn flipped_triangles_are_turned() {
        let s = sphere();
        let mut damaged = s.clone();
        for t in [3, 40, 41, 100, 200, 201, 319] {
            damaged.triangles[t].swap(0, 1);
        }
        let (repaired, report) = repair(&damaged).unwrap();
        assert_closed(&repaired, 162, 320, s.enclosed_volume());
        assert_eq!(report.flipped_triangles, 7);
        assert!(!report.reversed);
        assert_eq!(report.lines(), vec!["turned 7 flipped triangles"]);
    }

    #[test]
    fn an_inside_out_surface_is_reversed() {
        let s = sphere();
        let mut inverted = s.clone();
        inverted.flip();
        let (repaired, report) = repair(&inverted).unwrap();
        assert_closed(&repaired, 162, 320, s.enclosed_volume());
        assert!(report.reversed);
        assert_eq!(report.flipped_triangles, 0);
        assert_eq!(report.lines(), vec!["turned the surface outward (it was inside out)"]);
        // Inside out with a few flipped the right way: the majority is inside out.
        inverted.triangles[5].swap(1, 2);
        inverted.triangles[9].swap(1, 2);
        let (repaired, report) = repair(&inverted).unwrap();
        assert_closed(&repaired, 162, 320, s.enclosed_volume());
        assert!(report.reversed);
        assert_eq!(report.flipped_triangles, 2);
    }

    #[test]
    fn degenerate_duplicate_and_unused_are_removed() {
        let s = sphere();
        let mut damaged = s.clone();
        damaged.triangles.push([4, 4, 9]);
        damaged.triangles.push(s.triangles[10]);
        damaged.triangles.push([s.triangles[11][1], s.triangles[11][0], s.triangles[11][2]]);
        damaged.vertices.push([5.0, 5.0, 5.0]);
        let (repaired, report) = repair(&damaged).unwrap();
        assert_closed(&repaired, 162, 320, s.enclosed_volume());
        assert_eq!((report.removed_degenerate, report.removed_duplicate, report.removed_unused_vertices), (1, 2, 1));
        assert_eq!(
            report.lines(),
            vec!["removed 1 degenerate triangle", "removed 2 duplicate triangles", "removed 1 unused vertex"]
        );
    }

    #[test]
    fn a_zero_area_triangle_along_an_edge_is_closed_by_a_split() {
        // Triangle t = (a, b, x) split at the midpoint c of ab into (a, c, x), (c, b, x), with the
        // cap (a, b, c) of no area closing it: a T-junction across edge ab.
        let s = sphere();
        let mut damaged = s.clone();
        let [a, b, x] = s.triangles[0];
        let c = damaged.vertices.len();
        damaged.vertices.push(std::array::from_fn(|d| 0.5 * (s.vertices[a][d] + s.vertices[b][d])));
        damaged.triangles[0] = [a, c, x];
        damaged.triangles.push([c, b, x]);
        damaged.triangles.push([a, b, c]);
        let (repaired, report) = repair(&damaged).unwrap();
        assert_closed(&repaired, 163, 322, s.enclosed_volume());
        assert_eq!(report.removed_degenerate, 1);
        assert_eq!((report.holes_filled.clone(), report.added_triangles), (vec![3], 1));
    }

    #[test]
    fn a_fin_is_refused_as_non_manifold() {
        let mut s = sphere();
        let [a, b, _] = s.triangles[0];
        s.vertices.push([3.0, 3.0, 3.0]);
        s.triangles.push([a, b, 162]);
        let e = error(&s);
        assert!(e.contains("non-manifold edge"), "{e}");
        assert!(e.contains("shared by 3 triangles") && e.contains("cannot be repaired"), "{e}");
        assert!(e.contains(&format!("vertices {} at", a.min(b))), "{e}");
    }

    #[test]
    fn spheres_touching_at_a_vertex_are_refused_as_non_manifold() {
        let s = sphere();
        let mut twin = s.clone();
        // A second sphere, shifted so that its vertex 3 lands on the first one's vertex 0.
        let shift = sub(s.vertices[0], s.vertices[3]);
        let n = s.vertices.len();
        twin.vertices.extend(s.vertices.iter().map(|p| std::array::from_fn(|d| p[d] + shift[d])));
        twin.triangles.extend(s.triangles.iter().map(|t| t.map(|k| if k == 3 { 0 } else { k + n })));
        let e = error(&twin);
        assert!(e.contains("non-manifold vertex 0 at") && e.contains("2 separate fans"), "{e}");
    }

    #[test]
    fn separate_pieces_are_refused() {
        let s = sphere();
        let mut two = s.clone();
        let small = icosphere(0.3, 1);
        let n = two.vertices.len();
        two.vertices.extend(small.vertices.iter().map(|p| [p[0] + 0.9, p[1], p[2]]));
        two.triangles.extend(small.triangles.iter().map(|t| t.map(|k| k + n)));
        let e = error(&two);
        assert!(e.contains("2 separate pieces (320, 80 triangles): keep the organ only"), "{e}");
        // The small sphere crosses the big one.
        assert!(!self_intersections(&two).is_empty());
    }

    #[test]
    fn a_self_intersecting_surface_is_refused() {
        // A vertex pushed through the far side of the sphere: its triangles cross the far side.
        let mut s = sphere();
        s.vertices[0] = s.vertices[0].map(|c| -1.5 * c);
        let crossings = self_intersections(&s);
        assert!(!crossings.is_empty());
        assert!(crossings.windows(2).all(|w| w[0] < w[1]) && crossings.iter().all(|(i, j)| i < j));
        let e = error(&s);
        let (i, j) = crossings[0];
        let expected = format!("self-intersecting: triangles {i} and {j} cross ({} pairs, ", crossings.len());
        assert!(e.contains(&expected) && e.contains("cannot be repaired automatically"), "{e}\n{expected}");
        // Tolerated, the crossings are reported and left in place.
        let tolerant = RepairOptions { max_crossing_fraction: 1.0, ..Default::default() };
        let (repaired, report) = repair_surface(&s, &tolerant).unwrap();
        assert_eq!(repaired, s);
        assert_eq!(report.crossings, crossings);
        assert!(!report.changed() && report.lines().is_empty());
        let warning = format!("{} pairs of triangles cross (", crossings.len());
        assert!(report.warnings()[0].starts_with(&warning), "{:?}", report.warnings());
        assert!(report.warnings()[0].ends_with(&format!("first {i} and {j}): left in place")));
        // A sphere dented inward without crossing is fine.
        let mut dented = sphere();
        dented.vertices[0] = dented.vertices[0].map(|c| 0.5 * c);
        assert!(self_intersections(&dented).is_empty());
        repair(&dented).unwrap();
    }

    #[test]
    fn a_large_hole_is_refused_with_its_size() {
        let s = sphere();
        let cap = near(&s, s.vertices[0], 0.45);
        let damaged = without(&s, &cap);
        let (_, report) = repair(&damaged).unwrap();
        let size = report.holes_filled[0];
        let options = RepairOptions { max_hole_edges: size - 1, ..Default::default() };
        let e = repair_surface(&damaged, &options).unwrap_err().to_string();
        assert!(e.contains(&format!("hole of {size} edges")), "{e}");
        assert!(e.contains(&format!("larger than the {} edges", size - 1)), "{e}");
        // Half a sphere: one hole of as many edges as the boundary has.
        let half: Vec<usize> = (0..s.triangles.len()).filter(|&t| s.vertices[s.triangles[t][0]][2] > 0.1).collect();
        let open = without(&s, &half);
        let mut edges: HashMap<(usize, usize), usize> = HashMap::new();
        for t in &open.triangles {
            for e in 0..3 {
                let (a, b) = (t[e], t[(e + 1) % 3]);
                *edges.entry((a.min(b), a.max(b))).or_default() += 1;
            }
        }
        let boundary = edges.values().filter(|&&n| n == 1).count();
        let e =
            repair_surface(&open, &RepairOptions { max_hole_edges: 20, ..Default::default() }).unwrap_err().to_string();
        assert!(e.contains(&format!("hole of {boundary} edges")) && e.contains("cut open"), "{e}");
    }

    #[test]
    fn bad_input_is_refused() {
        let mut s = sphere();
        s.vertices[7][1] = f64::NAN;
        assert!(error(&s).contains("vertex 7 has a non-finite coordinate"));
        // Every vertex far out (as a damaged file gives): refused at once, where repair never ended.
        let mut s = sphere();
        s.transform([0.0; 3], 1e160);
        assert!(error(&s).contains("vertex 0 lies at") && error(&s).contains("a damaged file?"), "{}", error(&s));
        let mut s = sphere();
        s.triangles[4][2] = 500;
        assert!(error(&s).contains("triangle 4 refers to vertex 500, but there are 162 vertices"));
        assert!(error(&TriSurface::default()).contains("no triangles"));
        let flat =
            TriSurface { vertices: vec![[0.0; 3], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]], triangles: vec![[0, 1, 2]] };
        assert!(error(&flat).contains("no triangle with a non-zero area"));
    }

    #[test]
    fn units_follow_from_the_size_of_an_organ() {
        let s = icosphere(0.05, 1);
        assert_eq!(detect_unit(&s).unwrap(), LengthUnit::Metre);
        let mut mm = s.clone();
        mm.transform([0.0; 3], 1000.0);
        assert_eq!(detect_unit(&mm).unwrap(), LengthUnit::Millimetre);
        assert!((largest_extent(&mm) - 100.0).abs() < 1e-9);
        let mut cm = s.clone();
        cm.transform([0.0; 3], 100.0);
        let e = detect_unit(&cm).unwrap_err().to_string();
        assert!(e.contains("largest extent is 10,") && e.contains("give the unit explicitly"), "{e}");
        assert!(e.contains("in metres (0.02 to 0.6) nor in millimetres (20 to 600)"), "{e}");
        // Two organ-sized pieces far apart: the pieces are the fault, not the unit.
        let mut two = mm.clone();
        let mut far = mm.clone();
        far.vertices.iter_mut().for_each(|p| p[0] += 700.0);
        let offset = two.vertices.len();
        two.vertices.extend(far.vertices);
        two.triangles.extend(far.triangles.iter().map(|t| t.map(|k| k + offset)));
        assert_eq!(two.pieces().len(), 2);
        let e = detect_unit(&two).unwrap_err().to_string();
        assert!(
            e.contains("it is 2 separate pieces spread over 800; its largest, 100 across, would be an organ in"),
            "{e}"
        );
        assert!(e.contains("millimetres: keep the organ only"), "{e}");
    }
}
