//! Selecting nodes: by axis-aligned box, by list, by named region; the nearest node or the `k` nearest nodes
//! to a point (linear scans, for the few queries that need no spatial index).

use std::cmp::Ordering;

use crate::{dot, sub, Mesh, MeshError, Point};

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

/// The `k` of the `candidates` (indices into `points`) nearest to `p` by Euclidean distance, nearest first
/// (all of them when there are fewer). Ties go to the smaller index, so the result does not depend on the
/// candidates' order; a NaN distance counts as the largest (`f64::total_cmp`).
pub fn k_nearest(points: &[Point], candidates: impl IntoIterator<Item = usize>, p: Point, k: usize) -> Vec<usize> {
    let mut by_distance: Vec<(f64, usize)> = candidates.into_iter().map(|i| (distance2(points[i], p), i)).collect();
    if k < by_distance.len() {
        by_distance.select_nth_unstable_by(k, closer);
        by_distance.truncate(k);
    }
    by_distance.sort_unstable_by(closer);
    by_distance.into_iter().map(|(_, i)| i).collect()
}

/// The one of the `candidates` (indices into `points`) nearest to `p`, as in [`k_nearest`] with `k = 1` (ties go
/// to the smaller index); `None` when there is no candidate.
pub fn nearest(points: &[Point], candidates: impl IntoIterator<Item = usize>, p: Point) -> Option<usize> {
    candidates.into_iter().map(|i| (distance2(points[i], p), i)).min_by(closer).map(|(_, i)| i)
}

/// Squared Euclidean distance.
fn distance2(a: Point, b: Point) -> f64 {
    let d = sub(a, b);
    dot(d, d)
}

/// Order of (squared distance, index) pairs: by distance, then by index.
fn closer(a: &(f64, usize), b: &(f64, usize)) -> Ordering {
    a.0.total_cmp(&b.0).then(a.1.cmp(&b.1))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nearest_nodes_come_nearest_first_with_ties_to_the_smaller_index() {
        let points = [[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [-1.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 5.0, 0.0]];
        let p = [0.0, 0.0, 0.0];
        // 2 and 3 are equally far: the smaller index comes first, whatever the candidates' order.
        assert_eq!(k_nearest(&points, [4, 3, 2, 1, 0], p, 3), vec![0, 2, 3]);
        assert_eq!(k_nearest(&points, [3, 2], p, 1), vec![2]);
        assert_eq!(k_nearest(&points, 0..5, p, 9), vec![0, 2, 3, 1, 4]);
        assert_eq!(k_nearest(&points, [1, 4], p, 0), Vec::<usize>::new());
        assert_eq!(nearest(&points, [4, 3, 2], p), Some(2));
        assert_eq!(nearest(&points, [1, 4], [0.0, 4.0, 0.0]), Some(4));
        assert_eq!(nearest(&points, [], p), None);
        // A NaN coordinate puts a point last.
        let with_nan = [[f64::NAN, 0.0, 0.0], [9.0, 0.0, 0.0]];
        assert_eq!(k_nearest(&with_nan, 0..2, p, 2), vec![1, 0]);
        assert_eq!(nearest(&with_nan, 0..2, p), Some(1));
    }
}

/// A ball of space: a region that stays the same whatever the mesh.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Ball {
    /// Centre (m).
    pub centre: Point,
    /// Radius (m).
    pub radius: f64,
}

impl Ball {
    /// Whether `x` lies inside (strictly).
    pub fn contains(&self, x: Point) -> bool {
        crate::distance(x, self.centre) < self.radius
    }
}

/// A ball of space given in a scenario: explicitly, or the built-in phantom's ball behind one of its
/// regions ([`crate::PhantomSpec::region_ball`]).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SpaceBall {
    /// The ball: `{ centre = [x, y, z], radius = r }` (m)...
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ball: Option<Ball>,
    /// ... or the built-in phantom's ball behind `fixed`, `hidden` or `push`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub phantom: Option<String>,
}

impl SpaceBall {
    /// The ball; an error unless exactly one of `ball` and `phantom` is given, or for an unknown
    /// phantom region.
    pub fn resolve(&self) -> Result<Ball, String> {
        match (&self.ball, &self.phantom) {
            (Some(b), None) => Ok(*b),
            (None, Some(name)) => crate::PhantomSpec::default().region_ball(name).map_err(|e| e.to_string()),
            _ => Err("give either `ball = { centre, radius }` or `phantom = \"fixed\" | \"hidden\" | \"push\"`".into()),
        }
    }
}
