//! Assembly units ("patches"): groups of elements whose quadrature points share
//! one volume ratio under F-bar, and which are evaluated and assembled together.
//! A standard element is a patch of one.

use std::collections::HashMap;

/// Target number of tetrahedra per F-bar patch. With about 4–6 tetrahedra per
/// node, patches of six leave roughly one volume constraint per node, i.e. three
/// displacement unknowns per constraint, the continuum's ratio (Hughes' count).
pub const TET_PATCH_SIZE: usize = 6;

/// Elements grouped into patches, with each patch's node list.
#[derive(Clone, Debug)]
pub struct Patches {
    elem_ptr: Vec<usize>,
    elements: Vec<usize>,
    node_ptr: Vec<usize>,
    nodes: Vec<usize>,
    /// For each element slot of a patch and each of the element's nodes, the
    /// node's index in the patch's node list.
    local: Vec<u16>,
    nodes_per_element: usize,
}

impl Patches {
    /// One patch per element, node lists in element order.
    pub fn singletons(connectivity: &[usize], nodes_per_element: usize) -> Self {
        let ne = connectivity.len() / nodes_per_element;
        Patches {
            elem_ptr: (0..=ne).collect(),
            elements: (0..ne).collect(),
            node_ptr: (0..=ne).map(|e| e * nodes_per_element).collect(),
            nodes: connectivity.to_vec(),
            local: (0..ne).flat_map(|_| 0..nodes_per_element as u16).collect(),
            nodes_per_element,
        }
    }

    /// Groups tetrahedra (4 nodes each) into compact patches of about `size`
    /// face-adjacent elements: a seed takes its unassigned face neighbours
    /// breadth first; patches left with fewer than `size / 2` elements join
    /// the smallest adjacent patch. Deterministic for a given mesh.
    pub fn tetrahedra(connectivity: &[usize], size: usize) -> Self {
        let ne = connectivity.len() / 4;
        let tet = |e: usize| &connectivity[4 * e..4 * e + 4];
        // Face adjacency through sorted node triples.
        let mut faces: HashMap<[usize; 3], usize> = HashMap::with_capacity(2 * ne);
        let mut neighbours = vec![[usize::MAX; 4]; ne];
        for e in 0..ne {
            for skip in 0..4 {
                let mut f = [0; 3];
                let mut k = 0;
                for (i, &n) in tet(e).iter().enumerate() {
                    if i != skip {
                        f[k] = n;
                        k += 1;
                    }
                }
                f.sort_unstable();
                if let Some(other) = faces.remove(&f) {
                    let slot_other = neighbours[other].iter().position(|&x| x == usize::MAX).expect("≤ 4 faces");
                    neighbours[other][slot_other] = e;
                    neighbours[e][skip] = other;
                } else {
                    faces.insert(f, e);
                }
            }
        }
        let mut owner = vec![usize::MAX; ne];
        let mut groups: Vec<Vec<usize>> = Vec::new();
        let mut queue = std::collections::VecDeque::new();
        for seed in 0..ne {
            if owner[seed] != usize::MAX {
                continue;
            }
            let id = groups.len();
            let mut group = vec![seed];
            owner[seed] = id;
            queue.clear();
            queue.push_back(seed);
            'grow: while let Some(e) = queue.pop_front() {
                for &n in &neighbours[e] {
                    if n != usize::MAX && owner[n] == usize::MAX {
                        owner[n] = id;
                        group.push(n);
                        queue.push_back(n);
                        if group.len() == size {
                            break 'grow;
                        }
                    }
                }
            }
            groups.push(group);
        }
        // Merge small groups into their smallest neighbouring group.
        for id in 0..groups.len() {
            if groups[id].is_empty() || groups[id].len() >= size.div_ceil(2) {
                continue;
            }
            let target = groups[id]
                .iter()
                .flat_map(|&e| neighbours[e])
                .filter(|&n| n != usize::MAX && owner[n] != id)
                .map(|n| owner[n])
                .min_by_key(|&g| (groups[g].len(), g));
            if let Some(g) = target {
                let moved = std::mem::take(&mut groups[id]);
                for &e in &moved {
                    owner[e] = g;
                }
                groups[g].extend(moved);
            }
        }
        let mut patches = Patches {
            elem_ptr: vec![0],
            elements: Vec::with_capacity(ne),
            node_ptr: vec![0],
            nodes: Vec::new(),
            local: Vec::with_capacity(connectivity.len()),
            nodes_per_element: 4,
        };
        for mut group in groups.into_iter().filter(|g| !g.is_empty()) {
            group.sort_unstable();
            let mut nodes: Vec<usize> = group.iter().flat_map(|&e| tet(e).iter().copied()).collect();
            nodes.sort_unstable();
            nodes.dedup();
            for &e in &group {
                patches.local.extend(tet(e).iter().map(|n| nodes.binary_search(n).expect("patch node") as u16));
            }
            patches.elements.extend_from_slice(&group);
            patches.elem_ptr.push(patches.elements.len());
            patches.nodes.extend_from_slice(&nodes);
            patches.node_ptr.push(patches.nodes.len());
        }
        patches
    }

    /// Number of patches.
    pub fn len(&self) -> usize {
        self.elem_ptr.len() - 1
    }

    /// True when there is no patch.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The elements of patch `p`.
    pub fn elements(&self, p: usize) -> &[usize] {
        &self.elements[self.elem_ptr[p]..self.elem_ptr[p + 1]]
    }

    /// The nodes of patch `p` (the order of its local degrees of freedom).
    pub fn nodes(&self, p: usize) -> &[usize] {
        &self.nodes[self.node_ptr[p]..self.node_ptr[p + 1]]
    }

    /// Offset of patch `p`'s first node in the concatenation of all node lists.
    pub fn node_offset(&self, p: usize) -> usize {
        self.node_ptr[p]
    }

    /// Patch-local node indices of the `slot`-th element of patch `p`.
    pub fn local_nodes(&self, p: usize, slot: usize) -> &[u16] {
        let start = (self.elem_ptr[p] + slot) * self.nodes_per_element;
        &self.local[start..start + self.nodes_per_element]
    }

    /// Largest number of nodes in a patch.
    pub fn max_nodes(&self) -> usize {
        self.node_ptr.windows(2).map(|w| w[1] - w[0]).max().unwrap_or(0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tetrahedra_are_partitioned_into_connected_patches() {
        let m = mesh::box_tet([0.0; 3], [1.0, 1.0, 1.0], [4, 3, 3]).unwrap();
        let conn: Vec<usize> = (0..m.cells.len()).flat_map(|e| m.cells.cell(e).to_vec()).collect();
        let p = Patches::tetrahedra(&conn, TET_PATCH_SIZE);
        let mut seen: Vec<usize> = (0..p.len()).flat_map(|i| p.elements(i).to_vec()).collect();
        seen.sort_unstable();
        assert_eq!(seen, (0..m.cells.len()).collect::<Vec<_>>(), "every element in exactly one patch");
        let sizes: Vec<usize> = (0..p.len()).map(|i| p.elements(i).len()).collect();
        assert!(sizes.iter().all(|&s| s >= TET_PATCH_SIZE / 2), "sizes {sizes:?}");
        let mean = m.cells.len() as f64 / p.len() as f64;
        assert!((5.0..=8.0).contains(&mean), "mean patch size {mean}");
        for i in 0..p.len() {
            for (slot, &e) in p.elements(i).iter().enumerate() {
                let global: Vec<usize> = p.local_nodes(i, slot).iter().map(|&l| p.nodes(i)[l as usize]).collect();
                assert_eq!(global, m.cells.cell(e).to_vec());
            }
        }
    }
}
