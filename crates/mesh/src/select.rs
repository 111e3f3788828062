//! Selecting nodes: by axis-aligned box, by list, by named region.

use crate::{Mesh, MeshError, Point};

/// A rule that picks a set of nodes of a mesh.
#[derive(Clone, Debug, PartialEq, serde::Deserialize, serde::Serialize)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub enum NodeSelection {
    /// Nodes inside the closed box [min, max].
    Box {
        /// Lower corner.
        min: Point,
        /// Upper corner.
        max: Point,
    },
    /// Explicit node indices.
    List(Vec<usize>),
    /// A named region of the mesh.
    Region(String),
    /// Every node picked by any of the selections.
    Union(Vec<NodeSelection>),
}

impl NodeSelection {
    /// The selected node indices, sorted and without repeats. An empty
    /// selection is an error: it is almost always a wrongly placed box.
    pub fn select(&self, mesh: &Mesh) -> Result<Vec<usize>, MeshError> {
        let mut nodes = match self {
            NodeSelection::Box { min, max } => nodes_in_box(&mesh.nodes, *min, *max),
            NodeSelection::List(list) => {
                if let Some(&bad) = list.iter().find(|&&k| k >= mesh.num_nodes()) {
                    return Err(MeshError::Invalid(format!(
                        "node {bad} selected, but the mesh has {} nodes",
                        mesh.num_nodes()
                    )));
                }
                list.clone()
            }
            NodeSelection::Region(name) => mesh.region(name)?.to_vec(),
            NodeSelection::Union(parts) => {
                parts.iter().map(|p| p.select(mesh)).collect::<Result<Vec<_>, _>>()?.into_iter().flatten().collect()
            }
        };
        nodes.sort_unstable();
        nodes.dedup();
        if nodes.is_empty() {
            return Err(MeshError::Invalid(format!("selection {self:?} picks no node")));
        }
        Ok(nodes)
    }
}

/// Indices of the points inside the closed box [min, max].
pub fn nodes_in_box(points: &[Point], min: Point, max: Point) -> Vec<usize> {
    points
        .iter()
        .enumerate()
        .filter(|(_, p)| (0..3).all(|d| p[d] >= min[d] && p[d] <= max[d]))
        .map(|(i, _)| i)
        .collect()
}
