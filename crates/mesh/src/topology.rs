//! Boundary faces of a volume mesh.

use std::collections::HashMap;

use crate::{Cells, Mesh, TriSurface};

/// Outward faces of a positively oriented T4 (local node indices).
const TET_FACES: [[usize; 3]; 4] = [[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]];
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

/// All faces that belong to exactly one cell, in cell order.
pub fn boundary_faces(mesh: &Mesh) -> Vec<BoundaryFace> {
    let faces: Vec<(usize, Vec<usize>)> = match &mesh.cells {
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
    };
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
