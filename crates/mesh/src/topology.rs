//! Boundary faces of a volume mesh, and the pieces its cells form through shared faces.

use std::collections::HashMap;

use crate::{Cells, Mesh, TriSurface};

/// Outward faces of a positively oriented T4 (local node indices).
pub(crate) const TET_FACES: [[usize; 3]; 4] = [[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]];
/// Outward faces of a T10 (local node indices): a T4 face's corners, then the mid-edge nodes
/// of its edges in the same turn.
const TET10_FACES: [[usize; 6]; 4] = [[1, 2, 3, 5, 9, 8], [0, 3, 2, 7, 9, 6], [0, 1, 3, 4, 8, 7], [0, 2, 1, 6, 5, 4]];
/// Outward faces of an H8 in VTK order (local node indices).
const HEX_FACES: [[usize; 4]; 6] = [[0, 3, 2, 1], [4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]];

/// A face on the boundary of a volume mesh, oriented outward.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct BoundaryFace {
    /// The cell the face belongs to.
    pub cell: usize,
    /// Global node indices, counter-clockwise seen from outside: 3 for a triangle, 4 for a
    /// quadrilateral, 6 for a quadratic triangle (its corners, then the mid-edge nodes of
    /// edges 0-1, 1-2 and 2-0).
    pub nodes: Vec<usize>,
}

/// Every face of every cell, outward, with its cell, in cell order.
fn cell_faces(mesh: &Mesh) -> Vec<(usize, Vec<usize>)> {
    match &mesh.cells {
        Cells::Tet4(c) => c
            .iter()
            .enumerate()
            .flat_map(|(e, t)| TET_FACES.iter().map(move |f| (e, f.iter().map(|&k| t[k]).collect())))
            .collect(),
        Cells::Hex8(c) => c
            .iter()
            .enumerate()
            .flat_map(|(e, h)| HEX_FACES.iter().map(move |f| (e, f.iter().map(|&k| h[k]).collect())))
            .collect(),
        Cells::Tet10(c) => c
            .iter()
            .enumerate()
            .flat_map(|(e, t)| TET10_FACES.iter().map(move |f| (e, f.iter().map(|&k| t[k]).collect())))
            .collect(),
    }
}

/// All faces that belong to exactly one cell, in cell order.
pub fn boundary_faces(mesh: &Mesh) -> Vec<BoundaryFace> {
    let faces = cell_faces(mesh);
    let mut count: HashMap<Vec<usize>, u32> = HashMap::with_capacity(faces.len());
    for (_, f) in &faces {
        let mut key = f.clone();
        key.sort_unstable();
        *count.entry(key).or_default() += 1;
    }
    faces
        .into_iter()
        .filter(|(_, f)| {
            let mut key = f.clone();
            key.sort_unstable();
            count[&key] == 1
        })
        .map(|(cell, nodes)| BoundaryFace { cell, nodes })
        .collect()
}

/// Pairs of cells that lie on the same side of a face they share, found among positively
/// oriented cells: each turns the face the same way, where neighbours turn it opposite ways. The
/// mesh folds over itself there (a cell whose nodes were moved through a neighbour, turned
/// positive again, overlaps it); a face that three cells share always gives such a pair. Each
/// pair (lower cell first) once, in increasing order.
pub fn folded_faces(mesh: &Mesh) -> Vec<[usize; 2]> {
    /// The face's corners (a quadratic face's first three) turned to start at the smallest.
    fn turned(face: &[usize]) -> Vec<usize> {
        let corners = if face.len() == 6 { &face[..3] } else { face };
        let start = (0..corners.len()).min_by_key(|&k| corners[k]).unwrap_or(0);
        corners[start..].iter().chain(&corners[..start]).copied().collect()
    }
    let mut sharing: HashMap<Vec<usize>, Vec<(usize, Vec<usize>)>> = HashMap::new();
    for (cell, face) in cell_faces(mesh) {
        let turn = turned(&face);
        let mut key = turn.clone();
        key.sort_unstable();
        sharing.entry(key).or_default().push((cell, turn));
    }
    let mut pairs: Vec<[usize; 2]> = sharing
        .values()
        .filter(|cells| cells.len() > 1)
        .flat_map(|cells| {
            cells.iter().enumerate().flat_map(move |(i, (a, turn_a))| {
                cells[i + 1..]
                    .iter()
                    .filter(move |(_, turn_b)| turn_b == turn_a)
                    .map(move |(b, _)| [*a.min(b), *a.max(b)])
            })
        })
        .collect();
    pairs.sort_unstable();
    pairs.dedup();
    pairs
}

/// The root of `a`'s set in a union-find forest (`parent[k] == k` at a root), halving the path on
/// the way.
pub(crate) fn root(parent: &mut [usize], mut a: usize) -> usize {
    while parent[a] != a {
        parent[a] = parent[parent[a]];
        a = parent[a];
    }
    a
}

/// The cells grouped into pieces joined through shared faces: two cells sharing a face are in
/// the same piece, two that share only an edge or a vertex may not be. A piece that hangs on the
/// rest by an edge or a vertex can rotate about it at no cost of energy (a mechanism), unless
/// something else holds it. Each piece's cells in increasing order; the pieces ordered by their
/// first cell.
pub fn face_connected_pieces(mesh: &Mesh) -> Vec<Vec<usize>> {
    let faces = cell_faces(mesh);
    let mut parent: Vec<usize> = (0..mesh.cells.len()).collect();
    let mut first_cell: HashMap<Vec<usize>, usize> = HashMap::with_capacity(faces.len());
    for (cell, mut key) in faces {
        key.sort_unstable();
        match first_cell.entry(key) {
            std::collections::hash_map::Entry::Occupied(o) => {
                let (a, b) = (root(&mut parent, *o.get()), root(&mut parent, cell));
                parent[a.max(b)] = a.min(b);
            }
            std::collections::hash_map::Entry::Vacant(v) => {
                v.insert(cell);
            }
        }
    }
    let mut index = vec![usize::MAX; parent.len()];
    let mut pieces: Vec<Vec<usize>> = Vec::new();
    for cell in 0..parent.len() {
        let r = root(&mut parent, cell);
        if index[r] == usize::MAX {
            index[r] = pieces.len();
            pieces.push(Vec::new());
        }
        pieces[index[r]].push(cell);
    }
    pieces
}

/// Sorted indices of the nodes on the boundary.
pub fn boundary_nodes(mesh: &Mesh) -> Vec<usize> {
    let mut nodes: Vec<usize> = boundary_faces(mesh).into_iter().flat_map(|f| f.nodes).collect();
    nodes.sort_unstable();
    nodes.dedup();
    nodes
}

/// The boundary as a triangle surface over the mesh's own node indices (quadrilaterals split
/// along their 0–2 diagonal, quadratic triangles into four at their mid-edge nodes).
pub fn boundary_surface(mesh: &Mesh) -> TriSurface {
    if let Cells::Tet4(tets) = &mesh.cells {
        // The same triangles in the same order, found by sorting rather than hashing.
        return TriSurface { vertices: mesh.nodes.clone(), triangles: crate::tetmesh::boundary_triangles(tets) };
    }
    let triangles = boundary_faces(mesh)
        .into_iter()
        .flat_map(|f| match f.nodes[..] {
            [a, b, c] => vec![[a, b, c]],
            [a, b, c, d] => vec![[a, b, c], [a, c, d]],
            [a, b, c, ab, bc, ca] => vec![[a, ab, ca], [ab, b, bc], [ca, bc, c], [ab, bc, ca]],
            _ => unreachable!("boundary faces have 3, 4 or 6 nodes"),
        })
        .collect();
    TriSurface { vertices: mesh.nodes.clone(), triangles }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A T4 mesh of the given tetrahedra, each turned to positive orientation.
    fn oriented(nodes: &[crate::Point], tets: &[[usize; 4]]) -> Mesh {
        let tets = tets
            .iter()
            .map(|&t| {
                let q = t.map(|k| nodes[k]);
                if crate::tet_volume(q[0], q[1], q[2], q[3]) < 0.0 {
                    [t[0], t[1], t[3], t[2]]
                } else {
                    t
                }
            })
            .collect();
        Mesh::new(nodes.to_vec(), Cells::Tet4(tets)).unwrap()
    }

    #[test]
    fn cells_sharing_only_an_edge_or_a_vertex_are_separate_pieces() {
        let nodes = [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0],
            [1.0, 1.0, 1.0],
            [-1.0, 0.0, 0.0],
            [0.0, -1.0, 0.0],
            [0.0, 0.0, -1.0],
            [1.0, 1.0, -1.0],
        ];
        // Tetrahedra 0 and 1 share the face 1-2-3, 3 shares 1-2-4 with 1; 2 hangs on node 0 alone.
        let mesh = oriented(&nodes, &[[0, 1, 2, 3], [1, 2, 4, 3], [0, 5, 7, 6], [1, 2, 8, 4]]);
        assert_eq!(face_connected_pieces(&mesh), vec![vec![0, 1, 3], vec![2]]);
        // Now 3 shares only the edge 1-2 with the others.
        let mesh = oriented(&nodes, &[[0, 1, 2, 3], [1, 2, 4, 3], [0, 5, 7, 6], [1, 2, 8, 5]]);
        assert_eq!(face_connected_pieces(&mesh), vec![vec![0, 1], vec![2], vec![3]]);
    }
}
