//! Quadratic tetrahedra (T10): a T4 mesh's edges get mid-edge nodes, numbered after the
//! mesh's own nodes, and the quadratic shape functions.

use std::collections::HashMap;

use crate::{unit, Cells, Mesh, MeshError, Point};

/// The edges of a tetrahedron whose mid-edge nodes are a T10's nodes 4–9 (VTK order).
pub const TET10_EDGES: [[usize; 2]; 6] = [[0, 1], [1, 2], [0, 2], [0, 3], [1, 3], [2, 3]];

/// The ten quadratic shape functions at barycentric coordinates `l` (corners λᵢ(2λᵢ − 1), then
/// 4 λᵢ λⱼ for the edges of [`TET10_EDGES`]); they sum to 1 where Σ λ = 1.
pub fn tet10_shape(l: [f64; 4]) -> [f64; 10] {
    std::array::from_fn(|a| match a {
        0..4 => l[a] * (2.0 * l[a] - 1.0),
        _ => {
            let [i, j] = TET10_EDGES[a - 4];
            4.0 * l[i] * l[j]
        }
    })
}

/// The derivatives ∂N_a/∂λ_k of [`tet10_shape`] at barycentric coordinates `l`, treating the four
/// λ as independent (a gradient in space is Σ_k ∂N_a/∂λ_k ∇λ_k).
pub fn tet10_shape_derivatives(l: [f64; 4]) -> [[f64; 4]; 10] {
    std::array::from_fn(|a| {
        let mut d = [0.0; 4];
        if a < 4 {
            d[a] = 4.0 * l[a] - 1.0;
        } else {
            let [i, j] = TET10_EDGES[a - 4];
            d[i] = 4.0 * l[j];
            d[j] = 4.0 * l[i];
        }
        d
    })
}

impl Mesh {
    /// The same mesh with quadratic tetrahedra: each edge of a T4 mesh gets a node at its
    /// midpoint, numbered after the mesh's own nodes (which keep their indices) in the order
    /// the cells first meet the edges. A region gains the mid-edge nodes between two of its
    /// nodes; per-cell fractions are kept; a mid-edge node's surface normal (when the mesh has
    /// them) is the mean of its ends'; where the file numbers its nodes ([`Mesh::file_nodes`]),
    /// the mid-edge nodes are numbered after its largest number. A T10 mesh is returned as it is;
    /// H8 meshes fail.
    pub fn quadratic(&self) -> Result<Mesh, MeshError> {
        let tets = match &self.cells {
            Cells::Tet4(tets) => tets,
            Cells::Tet10(_) => return Ok(self.clone()),
            Cells::Hex8(_) => {
                return Err(MeshError::Invalid("quadratic elements need a tetrahedral mesh, got H8 cells".into()))
            }
        };
        let mut nodes = self.nodes.clone();
        let mut ends: Vec<[usize; 2]> = Vec::new();
        let mut mid_of: HashMap<[usize; 2], usize> = HashMap::with_capacity(tets.len() * 2);
        let cells: Vec<[usize; 10]> = tets
            .iter()
            .map(|t| {
                let mut cell = [0; 10];
                cell[..4].copy_from_slice(t);
                for (slot, [i, j]) in TET10_EDGES.iter().enumerate() {
                    let key = [t[*i].min(t[*j]), t[*i].max(t[*j])];
                    cell[4 + slot] = *mid_of.entry(key).or_insert_with(|| {
                        let (a, b) = (self.nodes[key[0]], self.nodes[key[1]]);
                        nodes.push(std::array::from_fn(|d| 0.5 * (a[d] + b[d])));
                        ends.push(key);
                        nodes.len() - 1
                    });
                }
                cell
            })
            .collect();
        let node_normals = self.node_normals.as_ref().map(|normals| {
            let mid = |[a, b]: [usize; 2]| -> Point {
                if normals[a] == [0.0; 3] || normals[b] == [0.0; 3] {
                    return [0.0; 3];
                }
                unit(std::array::from_fn(|d| normals[a][d] + normals[b][d]))
            };
            normals.iter().copied().chain(ends.iter().map(|&e| mid(e))).collect()
        });
        let mut mesh = Mesh {
            nodes,
            cells: Cells::Tet10(cells),
            regions: Default::default(),
            cell_fraction: self.cell_fraction.clone(),
            node_normals,
            file_nodes: self.file_nodes.as_ref().map(|numbers| {
                let after = numbers.iter().max().map_or(0, |&m| m + 1);
                numbers.iter().copied().chain(after..after + ends.len()).collect()
            }),
            file_cells: self.file_cells.clone(),
            odd_cells: self.odd_cells.clone(),
        };
        mesh.regions =
            self.regions.iter().map(|(name, set)| (name.clone(), mesh.with_mid_edge_nodes(set.clone()))).collect();
        mesh.validate()?;
        Ok(mesh)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shape_functions_are_a_partition_of_unity_and_interpolate_their_nodes() {
        let l = [0.1, 0.2, 0.3, 0.4];
        assert!((tet10_shape(l).iter().sum::<f64>() - 1.0).abs() < 1e-15);
        // Node a's barycentric coordinates: a corner, or the midpoint of an edge.
        for a in 0..10 {
            let mut at = [0.0; 4];
            match a {
                0..4 => at[a] = 1.0,
                _ => TET10_EDGES[a - 4].iter().for_each(|&k| at[k] = 0.5),
            }
            let n = tet10_shape(at);
            for (b, v) in n.iter().enumerate() {
                assert!((v - f64::from(a == b)).abs() < 1e-15, "N_{b} at node {a} = {v}");
            }
        }
        // Derivatives against central differences.
        let d = tet10_shape_derivatives(l);
        for k in 0..4 {
            let (mut p, mut m) = (l, l);
            p[k] += 1e-6;
            m[k] -= 1e-6;
            let (np, nm) = (tet10_shape(p), tet10_shape(m));
            for a in 0..10 {
                assert!(((np[a] - nm[a]) / 2e-6 - d[a][k]).abs() < 1e-8);
            }
        }
    }

    #[test]
    fn quadratic_mesh_keeps_nodes_first_and_shares_mid_edge_nodes() {
        let mut m = crate::box_tet([0.0; 3], [1.0, 1.0, 1.0], [2, 1, 1]).unwrap();
        let face: Vec<usize> = crate::select::nodes_in_box(&m.nodes, [-0.1; 3], [0.1, 1.1, 1.1]);
        m.regions.insert("x0".into(), face.clone());
        let q = m.quadratic().unwrap();
        let Cells::Tet10(cells) = &q.cells else { panic!("{}", q.cells.kind_name()) };
        assert_eq!(q.nodes[..m.num_nodes()], m.nodes[..]);
        // Euler: the vertices, edges, faces and cells of a tetrahedral mesh of a ball satisfy
        // V − E + F − C = 1, and every edge has exactly one mid-edge node.
        let mut faces: Vec<[usize; 3]> = cells
            .iter()
            .flat_map(|c| [[c[0], c[1], c[2]], [c[0], c[1], c[3]], [c[0], c[2], c[3]], [c[1], c[2], c[3]]])
            .map(|mut f| {
                f.sort_unstable();
                f
            })
            .collect();
        faces.sort_unstable();
        faces.dedup();
        let edges = q.num_nodes() - m.num_nodes();
        assert_eq!(m.num_nodes() as i64 - edges as i64 + faces.len() as i64 - cells.len() as i64, 1);
        for c in cells {
            for (slot, [i, j]) in TET10_EDGES.iter().enumerate() {
                let (a, b, mid) = (q.nodes[c[*i]], q.nodes[c[*j]], q.nodes[c[4 + slot]]);
                assert!((0..3).all(|d| (mid[d] - 0.5 * (a[d] + b[d])).abs() < 1e-15));
            }
        }
        // The face x = 0 of the unit cube holds 4 corners and, split into 2 triangles, 5 edges.
        let region = q.region("x0").unwrap();
        assert_eq!(region.len(), face.len() + 5);
        assert!(region.iter().all(|&k| q.nodes[k][0].abs() < 1e-12));
        assert!(crate::box_hex([0.0; 3], [1.0; 3], [1, 1, 1]).unwrap().quadratic().is_err());
        assert_eq!(q.quadratic().unwrap(), q);
        // A file's own node numbers (Gmsh tags, a deck's): the mid-edge nodes come after them.
        let tags: Vec<usize> = (0..m.num_nodes()).map(|i| 10 + 3 * i).collect();
        let numbered = Mesh { file_nodes: Some(tags.clone()), ..m.clone() }.quadratic().unwrap();
        let after = tags.last().unwrap() + 1;
        let want: Vec<usize> = tags.iter().copied().chain(after..after + edges).collect();
        assert_eq!(numbered.file_nodes, Some(want));
    }

    #[test]
    fn located_points_interpolate_quadratic_fields_exactly() {
        let q = crate::box_tet([0.0; 3], [1.0, 0.7, 0.5], [3, 2, 2]).unwrap().quadratic().unwrap();
        let field = |p: Point| p[0] * p[1] - 2.0 * p[2] * p[2] + 0.5 * p[0] + 1.0;
        let values: Vec<f64> = q.nodes.iter().map(|&p| field(p)).collect();
        let locator = crate::MeshLocator::new(&q).unwrap();
        for i in 0..50 {
            let t = i as f64 / 50.0;
            let p = [0.02 + 0.95 * t, 0.68 * (0.5 + 0.45 * (7.0 * t).sin()), 0.49 * (0.5 + 0.45 * (5.0 * t).cos())];
            let location = locator.locate(p).unwrap();
            assert_eq!(location.count, 10);
            let value: f64 = location.terms().map(|(n, w)| w * values[n]).sum();
            assert!((value - field(p)).abs() < 1e-12, "at {p:?}: {value} vs {}", field(p));
        }
    }
}
