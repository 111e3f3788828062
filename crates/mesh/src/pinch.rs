//! Pinched edges of a tetrahedral mesh bridged. Where an organ is thinner than the stuffing
//! lattice (a lobe's neck, a thin rim), two fans of tetrahedra may meet along an edge only: the
//! surface there is not a manifold (four boundary triangles share the edge) and, if nothing else
//! joins them, a lobe hangs on the rest by that edge and turns about it at no cost of energy, a
//! mechanism no FEM solve survives. Around such an edge the fans leave empty wedges; the
//! narrower one, filled with a tetrahedron on the edge and the two fans' facing corners, joins
//! them through faces, as the organ's tissue joins them there. Where a neck is thinner still, two
//! pieces meet at a vertex only: a tetrahedron on one piece's surface reaching the other's nearest
//! corner turns the vertex into a pinched edge, which the next pass bridges.

use std::collections::{HashMap, HashSet};

use crate::dihedral_angles;
use crate::{cross, dot, norm, sub, tet_volume, Cells, Mesh, Point};

/// The smallest dihedral angle (degrees) of a bridging tetrahedron: a wedge narrower than this is
/// left as it is (a sliver would invert under the first load), as is one wider than
/// 180° less this (its tetrahedron would be flat).
pub const MIN_BRIDGE_DIHEDRAL_DEG: f64 = 5.0;

/// Passes over the mesh: a bridge may leave a new pinched edge where its faces meet another fan,
/// and a vertex's bridge always leaves one.
const PASSES: usize = 4;

/// Bridges the pinched edges and vertices of a T4 mesh (other meshes are left as they are):
/// returns the tetrahedra added. An edge's is on the edge and the corners of the two fans that
/// face each other across the narrower empty wedge about it; a vertex's is on a boundary face of
/// one piece there and a boundary corner of the other, the best shaped of those that overlap no
/// cell (its edge on the other piece is bridged in the next pass). Vertices are bridged only where
/// no edge is left to bridge. A tetrahedron is added only when it is positive, has no dihedral
/// angle under [`MIN_BRIDGE_DIHEDRAL_DEG`], holds no node and gives no face a third cell. Nodes
/// are not moved.
pub fn bridge_pinched_edges(mesh: &mut Mesh) -> usize {
    let Cells::Tet4(tets) = &mut mesh.cells else { return 0 };
    let mut added = 0;
    for _ in 0..PASSES {
        let cells_of_face = cells_of_faces(tets);
        let mut bridges = bridges(&mesh.nodes, tets, &cells_of_face);
        if bridges.is_empty() {
            bridges = vertex_bridges(&mesh.nodes, tets, &cells_of_face);
        }
        if bridges.is_empty() {
            break;
        }
        added += bridges.len();
        tets.extend(bridges);
    }
    added
}

/// The number of pinched edges of a volume mesh: edges of its boundary surface shared by more
/// than two of the surface's triangles, where cells meet along an edge only (the surface is no
/// 2-manifold there, which surface tools refuse).
pub fn pinched_edge_count(mesh: &Mesh) -> usize {
    let mut triangles_of_edge: HashMap<[usize; 2], usize> = HashMap::new();
    for t in &crate::boundary_surface(mesh).triangles {
        for (a, b) in [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])] {
            *triangles_of_edge.entry([a.min(b), a.max(b)]).or_default() += 1;
        }
    }
    triangles_of_edge.values().filter(|&&n| n > 2).count()
}

/// The sorted corners of a face.
fn face_key(mut f: [usize; 3]) -> [usize; 3] {
    f.sort_unstable();
    f
}

/// The faces of `t`, each with its corners sorted.
fn faces_of(t: &[usize; 4]) -> [[usize; 3]; 4] {
    [[t[1], t[2], t[3]], [t[0], t[2], t[3]], [t[0], t[1], t[3]], [t[0], t[1], t[2]]].map(face_key)
}

/// How many of `tets` each face (its corners sorted) belongs to.
fn cells_of_faces(tets: &[[usize; 4]]) -> HashMap<[usize; 3], u8> {
    let mut cells_of_face: HashMap<[usize; 3], u8> = HashMap::with_capacity(2 * tets.len());
    for t in tets {
        for f in faces_of(t) {
            *cells_of_face.entry(f).or_default() += 1;
        }
    }
    cells_of_face
}

/// One pass: the bridging tetrahedra of the pinched edges of `tets` (`cells_of_face`: their
/// [`cells_of_faces`]), at most one about any node.
fn bridges(nodes: &[Point], tets: &[[usize; 4]], cells_of_face: &HashMap<[usize; 3], u8>) -> Vec<[usize; 4]> {
    let mut boundary_faces_of_edge: HashMap<[usize; 2], u8> = HashMap::new();
    for (f, _) in cells_of_face.iter().filter(|(_, &n)| n == 1) {
        for e in [[f[0], f[1]], [f[1], f[2]], [f[0], f[2]]] {
            *boundary_faces_of_edge.entry(e).or_default() += 1;
        }
    }
    let mut pinched: Vec<[usize; 2]> =
        boundary_faces_of_edge.into_iter().filter(|&(_, n)| n > 2).map(|(e, _)| e).collect();
    if pinched.is_empty() {
        return Vec::new();
    }
    pinched.sort_unstable();
    let wanted: HashSet<[usize; 2]> = pinched.iter().copied().collect();
    let mut around: HashMap<[usize; 2], Vec<[usize; 2]>> = HashMap::new();
    for t in tets {
        for (i, j) in [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)] {
            let edge = [t[i].min(t[j]), t[i].max(t[j])];
            if wanted.contains(&edge) {
                let others: Vec<usize> = t.iter().copied().filter(|&n| n != t[i] && n != t[j]).collect();
                around.entry(edge).or_default().push([others[0], others[1]]);
            }
        }
    }
    let mut used = HashSet::new();
    let mut out = Vec::new();
    for edge in pinched {
        let Some(tet) = narrowest_wedge(nodes, edge, &around[&edge]) else { continue };
        if tet.iter().any(|n| used.contains(n)) || !acceptable(nodes, &tet, cells_of_face) {
            continue;
        }
        used.extend(tet);
        out.push(tet);
    }
    out
}

/// The tetrahedron filling the narrowest empty wedge about `edge` (a, b) between the fans of
/// the cells around it (each given by its two other corners), positively oriented; `None` when
/// the cells form one fan or the wedge is too narrow or too wide.
fn narrowest_wedge(nodes: &[Point], [a, b]: [usize; 2], cells: &[[usize; 2]]) -> Option<[usize; 4]> {
    let axis = sub(nodes[b], nodes[a]);
    let length = norm(axis);
    if length == 0.0 {
        return None;
    }
    let axis = axis.map(|x| x / length);
    // A reference direction across the edge, then each corner's angle about it.
    let helper = if axis[0].abs() < 0.9 { [1.0, 0.0, 0.0] } else { [0.0, 1.0, 0.0] };
    let u = cross(axis, helper);
    let u = u.map(|x| x / norm(u));
    let v = cross(axis, u);
    let angle = |n: usize| {
        let d = sub(nodes[n], nodes[a]);
        dot(d, v).atan2(dot(d, u)).rem_euclid(std::f64::consts::TAU)
    };
    let ccw = |from: f64, to: f64| (to - from).rem_euclid(std::f64::consts::TAU);
    // Each cell spans an arc under half a turn, from one corner to the other counter-clockwise.
    let arcs: Vec<(usize, usize)> = cells
        .iter()
        .map(|&[c, d]| if ccw(angle(c), angle(d)) < std::f64::consts::PI { (c, d) } else { (d, c) })
        .collect();
    let starts: HashSet<usize> = arcs.iter().map(|a| a.0).collect();
    let ends: HashSet<usize> = arcs.iter().map(|a| a.1).collect();
    // A fan ends where no cell starts, and the next fan counter-clockwise starts where none ends.
    let mut fan_ends: Vec<usize> = ends.difference(&starts).copied().collect();
    let mut fan_starts: Vec<usize> = starts.difference(&ends).copied().collect();
    if fan_ends.len() < 2 || fan_ends.len() != fan_starts.len() {
        return None;
    }
    fan_ends.sort_unstable();
    fan_starts.sort_unstable();
    let (limit, turn) = (MIN_BRIDGE_DIHEDRAL_DEG.to_radians(), std::f64::consts::PI);
    let (gap, end, start) = fan_ends
        .iter()
        .map(|&end| {
            // The wedge from a fan's end to the nearest start counter-clockwise.
            let start = fan_starts
                .iter()
                .copied()
                .min_by(|&p, &q| ccw(angle(end), angle(p)).total_cmp(&ccw(angle(end), angle(q))));
            (start.map_or(f64::INFINITY, |s| ccw(angle(end), angle(s))), end, start.unwrap_or(end))
        })
        .min_by(|x, y| x.0.total_cmp(&y.0))?;
    if !(limit..turn - limit).contains(&gap) {
        return None;
    }
    let mut tet = [a, b, end, start];
    if tet_volume(nodes[tet[0]], nodes[tet[1]], nodes[tet[2]], nodes[tet[3]]) < 0.0 {
        tet.swap(2, 3);
    }
    Some(tet)
}

/// One pass: a bridging tetrahedron for each pinched vertex of `tets` (whose cells fall in groups
/// that share no face about it; `cells_of_face`: their [`cells_of_faces`]), at most one about any
/// node.
fn vertex_bridges(nodes: &[Point], tets: &[[usize; 4]], cells_of_face: &HashMap<[usize; 3], u8>) -> Vec<[usize; 4]> {
    let mut cells_at: Vec<Vec<usize>> = vec![Vec::new(); nodes.len()];
    for (c, t) in tets.iter().enumerate() {
        for &n in t {
            cells_at[n].push(c);
        }
    }
    // Only a boundary node can be pinched: an inner one's cells fill a ball about it.
    let mut on_boundary = vec![false; nodes.len()];
    for (f, _) in cells_of_face.iter().filter(|(_, &n)| n == 1) {
        f.iter().for_each(|&n| on_boundary[n] = true);
    }
    let mut used = HashSet::new();
    let mut out = Vec::new();
    for (v, cells) in cells_at.iter().enumerate() {
        if !on_boundary[v] || cells.len() < 2 || used.contains(&v) {
            continue;
        }
        let groups = groups_about(v, cells, tets);
        if groups.len() < 2 {
            continue;
        }
        let best = groups
            .iter()
            .enumerate()
            .flat_map(|(i, from)| {
                groups.iter().enumerate().filter(move |&(j, _)| j != i).map(move |(_, to)| (from, to))
            })
            .flat_map(|(from, to)| vertex_candidates(nodes, tets, v, from, to, cells_of_face))
            .filter(|tet| !tet.iter().any(|n| used.contains(n)) && acceptable(nodes, tet, cells_of_face))
            .filter(|tet| !overlaps_a_cell(nodes, tets, tet))
            .map(|tet| (least_dihedral(nodes, &tet), tet))
            .max_by(|a, b| a.0.total_cmp(&b.0));
        if let Some((_, tet)) = best {
            used.extend(tet);
            out.push(tet);
        }
    }
    out
}

/// The cells about node `v` (indices into `tets`) in groups joined through faces that hold `v`.
fn groups_about(v: usize, cells: &[usize], tets: &[[usize; 4]]) -> Vec<Vec<usize>> {
    let mut group: Vec<usize> = (0..cells.len()).collect();
    // Each cell's corners other than `v`: two cells share a face about `v` when they share two.
    let others: Vec<Vec<usize>> = cells.iter().map(|&c| tets[c].into_iter().filter(|&n| n != v).collect()).collect();
    for i in 0..cells.len() {
        for j in i + 1..cells.len() {
            if others[i].iter().filter(|n| others[j].contains(n)).count() == 2 {
                let (gi, gj) = (group[i], group[j]);
                group.iter_mut().filter(|g| **g == gj).for_each(|g| *g = gi);
            }
        }
    }
    let mut groups: HashMap<usize, Vec<usize>> = HashMap::new();
    for (i, &g) in group.iter().enumerate() {
        groups.entry(g).or_default().push(cells[i]);
    }
    let mut groups: Vec<Vec<usize>> = groups.into_values().collect();
    groups.sort_unstable();
    groups
}

/// The tetrahedra on a boundary face about `v` of a cell in `from`, on its outer side, and a
/// corner of a boundary face about `v` of a cell in `to`, positively oriented.
fn vertex_candidates(
    nodes: &[Point],
    tets: &[[usize; 4]],
    v: usize,
    from: &[usize],
    to: &[usize],
    cells_of_face: &HashMap<[usize; 3], u8>,
) -> Vec<[usize; 4]> {
    let boundary_faces = |cells: &[usize]| -> Vec<([usize; 3], usize)> {
        cells
            .iter()
            .flat_map(|&c| {
                let t = tets[c];
                faces_of(&t)
                    .into_iter()
                    .filter(move |f| f.contains(&v) && cells_of_face.get(f) == Some(&1))
                    .map(move |f| (f, t.into_iter().find(|n| !f.contains(n)).unwrap_or(v)))
            })
            .collect()
    };
    let mut corners: Vec<usize> = boundary_faces(to).iter().flat_map(|(f, _)| *f).filter(|&n| n != v).collect();
    corners.sort_unstable();
    corners.dedup();
    let side = |f: &[usize; 3], n: usize| tet_volume(nodes[f[0]], nodes[f[1]], nodes[f[2]], nodes[n]);
    let mut out = Vec::new();
    for (face, inner) in boundary_faces(from) {
        for &c in &corners {
            // On the other side of the face from its cell.
            if face.contains(&c) || side(&face, c) * side(&face, inner) >= 0.0 {
                continue;
            }
            let mut tet = [face[0], face[1], face[2], c];
            if side(&face, c) < 0.0 {
                tet.swap(1, 2);
            }
            out.push(tet);
        }
    }
    out
}

/// The smallest dihedral angle (radians) of the tetrahedron `tet`.
fn least_dihedral(nodes: &[Point], tet: &[usize; 4]) -> f64 {
    dihedral_angles(tet.map(|n| nodes[n])).into_iter().fold(f64::INFINITY, f64::min)
}

/// Whether the tetrahedron `tet` overlaps (shares interior with) a cell of `tets`: touching at
/// corners, edges or faces is not overlapping. Separating axes: the two tetrahedra's face normals
/// and the cross products of their edges.
fn overlaps_a_cell(nodes: &[Point], tets: &[[usize; 4]], tet: &[usize; 4]) -> bool {
    let p = tet.map(|n| nodes[n]);
    let (lo, hi) = crate::bounds(&p);
    let scale = norm(sub(hi, lo));
    tets.iter().any(|t| {
        let q = t.map(|n| nodes[n]);
        let (qlo, qhi) = crate::bounds(&q);
        (0..3).all(|d| qlo[d] < hi[d] && lo[d] < qhi[d]) && !separated(&p, &q, 1e-9 * scale)
    })
}

/// Whether a plane separates the tetrahedra `p` and `q` (`tolerance`: a gap of at most this much
/// length counts as touching).
fn separated(p: &[Point; 4], q: &[Point; 4], tolerance: f64) -> bool {
    const EDGES: [(usize, usize); 6] = [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)];
    const FACES: [[usize; 3]; 4] = [[1, 2, 3], [0, 2, 3], [0, 1, 3], [0, 1, 2]];
    let normals = |x: &[Point; 4]| FACES.map(|[a, b, c]| cross(sub(x[b], x[a]), sub(x[c], x[a])));
    let edges = |x: &[Point; 4]| EDGES.map(|(a, b)| sub(x[b], x[a]));
    let (ep, eq) = (edges(p), edges(q));
    // An axis from nearly parallel edges has no direction to trust.
    let longest = ep.iter().chain(&eq).map(|&e| dot(e, e)).fold(0.0, f64::max);
    let axes =
        normals(p).into_iter().chain(normals(q)).chain(ep.iter().flat_map(|&a| eq.iter().map(move |&b| cross(a, b))));
    axes.filter_map(|axis| {
        let length = norm(axis);
        (length > 1e-9 * longest).then(|| axis.map(|x| x / length))
    })
    .any(|axis| {
        let span = |x: &[Point; 4]| {
            x.iter().map(|&y| dot(y, axis)).fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), d| (a.min(d), b.max(d)))
        };
        let ((p0, p1), (q0, q1)) = (span(p), span(q));
        p1 <= q0 + tolerance || q1 <= p0 + tolerance
    })
}

/// Whether a bridging `tet` is positive, has no dihedral angle under
/// [`MIN_BRIDGE_DIHEDRAL_DEG`], holds no other node and gives no face a third cell.
fn acceptable(nodes: &[Point], tet: &[usize; 4], cells_of_face: &HashMap<[usize; 3], u8>) -> bool {
    let p = tet.map(|n| nodes[n]);
    if !(tet_volume(p[0], p[1], p[2], p[3]) > 0.0) {
        return false;
    }
    let limit = MIN_BRIDGE_DIHEDRAL_DEG.to_radians();
    if dihedral_angles(p).iter().any(|&angle| angle < limit) {
        return false;
    }
    if faces_of(tet).iter().any(|f| cells_of_face.get(f).is_some_and(|&n| n >= 2)) {
        return false;
    }
    // No node inside: its four barycentric volumes all positive.
    !nodes.iter().enumerate().any(|(n, &q)| {
        !tet.contains(&n)
            && [[q, p[1], p[2], p[3]], [p[0], q, p[2], p[3]], [p[0], p[1], q, p[3]], [p[0], p[1], p[2], q]]
                .iter()
                .all(|s| tet_volume(s[0], s[1], s[2], s[3]) > 0.0)
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::face_connected_pieces;

    /// Two tetrahedra on the edge from (0, 0, 0) to (0, 0, 1), their other corners at the angles
    /// (degrees) about it given, the second's rotated by `apart`.
    fn two_fans(apart: f64) -> Mesh {
        let at = |deg: f64| {
            let r = deg.to_radians();
            [r.cos(), r.sin(), 0.5]
        };
        let nodes = vec![[0.0, 0.0, 0.0], [0.0, 0.0, 1.0], at(0.0), at(60.0), at(60.0 + apart), at(120.0 + apart)];
        let orient = |mut t: [usize; 4]| {
            if tet_volume(nodes[t[0]], nodes[t[1]], nodes[t[2]], nodes[t[3]]) < 0.0 {
                t.swap(2, 3);
            }
            t
        };
        let cells = vec![orient([0, 1, 2, 3]), orient([0, 1, 4, 5])];
        Mesh::new(nodes, Cells::Tet4(cells)).unwrap()
    }

    /// A box of tetrahedra has no pinched edge; two tetrahedra meeting along an edge only have one.
    #[test]
    fn pinched_edges_are_counted_on_the_boundary() {
        assert_eq!(pinched_edge_count(&crate::box_tet([0.0; 3], [1.0; 3], [2, 2, 2]).unwrap()), 0);
        assert_eq!(pinched_edge_count(&two_fans(40.0)), 1);
    }

    /// Two tetrahedra meeting along an edge only, 40° apart: bridged by one tetrahedron on that
    /// edge and their facing corners, the mesh is one piece joined through faces, its surface a
    /// manifold, every cell positive.
    #[test]
    fn two_fans_meeting_along_an_edge_are_bridged() {
        let mut mesh = two_fans(40.0);
        assert_eq!((pinched_edge_count(&mesh), face_connected_pieces(&mesh).len()), (1, 2));
        assert_eq!(bridge_pinched_edges(&mut mesh), 1);
        let Cells::Tet4(cells) = &mesh.cells else { unreachable!() };
        assert_eq!(cells.len(), 3);
        let mut bridge = cells[2];
        bridge.sort_unstable();
        assert_eq!(bridge, [0, 1, 3, 4], "the corners facing each other across the 40° wedge");
        assert!((0..3).all(|c| mesh.cell_volume(c) > 0.0));
        assert_eq!((pinched_edge_count(&mesh), face_connected_pieces(&mesh).len()), (0, 1));
        // Nothing more to bridge.
        assert_eq!(bridge_pinched_edges(&mut mesh), 0);
    }

    /// Two tetrahedra meeting at a vertex only, in opposite octants: a tetrahedron on a face of
    /// one reaching a corner of the other, then one on the edge that leaves, join them through
    /// faces; every cell positive, no edge or vertex pinched.
    #[test]
    fn two_tetrahedra_meeting_at_a_vertex_are_bridged() {
        let nodes = vec![
            [0.0; 3],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0],
            [-1.0, 0.0, 0.0],
            [0.0, -1.0, 0.0],
            [0.0, 0.0, -1.0],
        ];
        let mut mesh = Mesh::new(nodes, Cells::Tet4(vec![[0, 1, 2, 3], [0, 5, 4, 6]])).unwrap();
        assert!((0..2).all(|c| mesh.cell_volume(c) > 0.0));
        assert_eq!(face_connected_pieces(&mesh).len(), 2);
        assert_eq!(bridge_pinched_edges(&mut mesh), 2);
        let cells = mesh.cells.len();
        assert!((0..cells).all(|c| mesh.cell_volume(c) > 0.0));
        assert_eq!((pinched_edge_count(&mesh), face_connected_pieces(&mesh).len()), (0, 1));
        let Cells::Tet4(tets) = &mesh.cells else { unreachable!() };
        assert!(groups_about(0, &(0..cells).collect::<Vec<_>>(), tets).len() == 1, "the vertex is no longer pinched");
    }

    /// Tetrahedra that share a face, an edge or a corner do not overlap; one pushed into another
    /// does.
    #[test]
    fn touching_tetrahedra_do_not_overlap_crossing_ones_do() {
        let a = [[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        let face = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 1.0, 1.0]];
        let corner = [[0.0; 3], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]];
        let into = [[0.2, 0.2, 0.2], [1.0, 1.0, 1.0], [2.0, 0.0, 1.0], [0.0, 2.0, 1.0]];
        assert!(separated(&a, &face, 1e-12) && separated(&a, &corner, 1e-12));
        assert!(!separated(&a, &into, 1e-12));
    }

    /// A wedge narrower than [`MIN_BRIDGE_DIHEDRAL_DEG`] is left (its tetrahedron a sliver), as
    /// is one that a node lies in.
    #[test]
    fn a_sliver_or_a_wedge_holding_a_node_is_not_bridged() {
        let mut narrow = two_fans(3.0);
        assert_eq!(bridge_pinched_edges(&mut narrow), 0);
        let mut blocked = two_fans(40.0);
        // A node at the centre of the tetrahedron that would bridge the wedge.
        let corners = [0, 1, 3, 4].map(|n| blocked.nodes[n]);
        blocked.nodes.push(std::array::from_fn(|d| corners.iter().map(|p| p[d]).sum::<f64>() / 4.0));
        assert_eq!(bridge_pinched_edges(&mut blocked), 0);
    }
}
