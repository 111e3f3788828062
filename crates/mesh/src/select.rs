//! Selecting nodes on any mesh: by axis-aligned box, by list, by named region (painted in
//! ParaView, 3D Slicer or Gmsh and read with the mesh), the boundary surface, what a camera sees,
//! a ball, the neighbourhood of landmarks, unions and intersections; the nearest node or the `k`
//! nearest nodes to a point (linear scans, for the few queries that need no spatial index).

use std::cmp::Ordering;
use std::collections::HashMap;
use std::path::PathBuf;

use crate::{dot, sub, Cells, Mesh, MeshError, Point};

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
    /// Explicit node numbers, as in the mesh's file (see [`crate::Mesh::file_nodes`]): from 0 in VTK
    /// files, Gmsh's node tags, Abaqus' and CalculiX's node numbers.
    List(Vec<usize>),
    /// A named region of the mesh.
    Region(String),
    /// Every node picked by any of the selections.
    Union(Vec<NodeSelection>),
    /// The nodes picked by every one of the selections (e.g. `surface` and a `ball`).
    Intersection(Vec<NodeSelection>),
    /// Every node of the boundary surface.
    Surface,
    /// The boundary nodes a camera sees ([`Camera`]).
    Facing(Camera),
    /// The nodes inside a ball.
    Ball(Ball),
    /// The nodes within a distance of landmarks ([`Near`]).
    Near(Near),
}

/// A camera looking at the organ: along a direction (far away) or from a position. A boundary
/// node is seen when its surface normal is within `max_angle_deg` of the direction to the camera
/// and the straight line from it to the camera crosses no other part of the surface
/// (self-occlusion).
#[derive(Clone, Debug, PartialEq, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields)]
pub struct Camera {
    /// The direction the camera looks along (from the camera towards the organ)...
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub view: Option<Point>,
    /// ... or the camera's position (m).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub position: Option<Point>,
    /// The largest angle between a node's normal and the direction to the camera (degrees; 90 by
    /// default: every node facing the camera).
    #[serde(default = "default_max_angle")]
    pub max_angle_deg: f64,
}

fn default_max_angle() -> f64 {
    90.0
}

/// Landmarks (e.g. where ligaments attach, the hilum) and a distance: the nodes within
/// `distance` of any of them; only boundary nodes with `surface = true`.
#[derive(Clone, Debug, PartialEq, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields)]
pub struct Near {
    /// The landmarks (m)...
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub points: Vec<Point>,
    /// ... and / or a CSV file of them (header x, y, z; m); in a scenario, a relative path starts
    /// at the scenario file's directory.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub file: Option<PathBuf>,
    /// The distance (m).
    pub distance: f64,
    /// Only nodes of the boundary surface.
    #[serde(default)]
    pub surface: bool,
}

impl std::fmt::Display for NodeSelection {
    /// The selection in words, for messages: `box [0.0, 0.0, 0.0] to [1.0, 1.0, 1.0]`, `ball of
    /// radius 0.03 m about [...]`, `region 'visible'`, `union of (...; ...)`.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let parts = |f: &mut std::fmt::Formatter<'_>, what: &str, parts: &[NodeSelection]| {
            let listed: Vec<String> = parts.iter().map(ToString::to_string).collect();
            write!(f, "{what} of ({})", listed.join("; "))
        };
        match self {
            NodeSelection::Box { min, max } => write!(f, "box {min:?} to {max:?}"),
            NodeSelection::List(list) if list.len() <= 6 => write!(f, "nodes {list:?}"),
            NodeSelection::List(list) => write!(f, "{} listed nodes (from {})", list.len(), list[0]),
            NodeSelection::Region(name) => write!(f, "region '{name}'"),
            NodeSelection::Union(list) => parts(f, "union", list),
            NodeSelection::Intersection(list) => parts(f, "intersection", list),
            NodeSelection::Surface => write!(f, "surface"),
            NodeSelection::Facing(camera) => match (camera.view, camera.position) {
                (Some(view), _) => write!(f, "surface facing a camera looking along {view:?}"),
                (None, Some(position)) => write!(f, "surface facing a camera at {position:?}"),
                (None, None) => write!(f, "surface facing a camera with neither view nor position"),
            },
            NodeSelection::Ball(ball) => write!(f, "ball of radius {} m about {:?}", ball.radius, ball.centre),
            NodeSelection::Near(near) => {
                let surface = if near.surface { "surface nodes" } else { "nodes" };
                let landmarks = match (near.points.len(), &near.file) {
                    (0, Some(file)) => format!("the landmarks of {}", file.display()),
                    (n, Some(file)) => format!("{n} landmarks and those of {}", file.display()),
                    (n, None) => format!("{n} landmarks"),
                };
                write!(f, "{surface} within {} m of {landmarks}", near.distance)
            }
        }
    }
}

impl NodeSelection {
    /// The selected node indices, sorted and without repeats. An empty selection is an error:
    /// it is almost always a wrongly placed box or ball, or landmarks in another unit.
    pub fn select(&self, mesh: &Mesh) -> Result<Vec<usize>, MeshError> {
        let mut nodes = match self {
            NodeSelection::Box { min, max } => nodes_in_box(&mesh.nodes, *min, *max),
            NodeSelection::List(list) => mesh.with_mid_edge_nodes(match &mesh.file_nodes {
                None => {
                    if let Some(&bad) = list.iter().find(|&&k| k >= mesh.num_nodes()) {
                        return Err(MeshError::Invalid(format!(
                            "node {bad} selected, but the mesh has {} nodes",
                            mesh.num_nodes()
                        )));
                    }
                    list.clone()
                }
                Some(file_nodes) => {
                    let index: HashMap<usize, usize> = file_nodes.iter().enumerate().map(|(i, &k)| (k, i)).collect();
                    list.iter()
                        .map(|k| {
                            index.get(k).copied().ok_or_else(|| {
                                MeshError::Invalid(format!(
                                    "node {k} selected, but the mesh file has no such node used by a cell (nodes \
                                     are numbered as in the file, {} to {}; those no cell uses were left out)",
                                    file_nodes.iter().min().unwrap_or(&0),
                                    file_nodes.iter().max().unwrap_or(&0)
                                ))
                            })
                        })
                        .collect::<Result<_, _>>()?
                }
            }),
            NodeSelection::Region(name) => mesh.region(name)?.to_vec(),
            NodeSelection::Union(parts) => {
                parts.iter().map(|p| p.select(mesh)).collect::<Result<Vec<_>, _>>()?.into_iter().flatten().collect()
            }
            NodeSelection::Intersection(parts) => {
                let mut sets = parts.iter().map(|p| p.select(mesh));
                let mut common = sets.next().unwrap_or_else(|| Ok(Vec::new()))?;
                for set in sets {
                    let set = set?;
                    common.retain(|n| set.binary_search(n).is_ok());
                }
                common
            }
            NodeSelection::Surface => crate::topology::boundary_nodes(mesh),
            NodeSelection::Facing(camera) => camera.seen_nodes(mesh)?,
            NodeSelection::Ball(ball) => (0..mesh.num_nodes()).filter(|&n| ball.contains(mesh.nodes[n])).collect(),
            NodeSelection::Near(near) => near.nodes(mesh)?,
        };
        nodes.sort_unstable();
        nodes.dedup();
        if nodes.is_empty() {
            return Err(MeshError::Invalid(format!("selection {self} picks no node{}", self.unit_hint(mesh))));
        }
        Ok(nodes)
    }

    /// Where a ball or box that picked nothing is ten times the mesh's size or more, or it or the
    /// nearest of a [`Near`]'s landmarks lies that far from it, the question whether its
    /// coordinates are in another unit than the mesh's metres; empty otherwise.
    fn unit_hint(&self, mesh: &Mesh) -> String {
        let (lo, hi) = mesh.bounds();
        let size = crate::longest_side((lo, hi));
        let outside = |p: Point| (0..3).map(|k| (lo[k] - p[k]).max(p[k] - hi[k]).max(0.0)).fold(0.0, f64::max);
        let reach = match self {
            NodeSelection::Ball(ball) => ball.radius.max(outside(ball.centre)),
            NodeSelection::Box { min, max } => crate::longest_side((*min, *max)).max(outside(*min).min(outside(*max))),
            // The nearest landmark's distance from the mesh's box.
            NodeSelection::Near(near) => match near.landmarks() {
                Ok(landmarks) => landmarks.into_iter().map(outside).fold(f64::INFINITY, f64::min),
                Err(_) => return String::new(),
            },
            _ => return String::new(),
        };
        if !(size > 0.0 && reach >= 10.0 * size) {
            return String::new();
        }
        let header = match self {
            NodeSelection::Near(Near { file: Some(_), .. }) => {
                "; a landmarks file's header x_mm, y_mm, z_mm names its unit"
            }
            _ => "",
        };
        format!(
            " (the mesh spans {size:.3} m; a scenario's coordinates are in metres, whatever its mesh file's unit: are \
             these in millimetres?{header})"
        )
    }
}

impl Camera {
    /// The boundary nodes this camera sees, sorted.
    pub fn seen_nodes(&self, mesh: &Mesh) -> Result<Vec<usize>, MeshError> {
        let to_camera: Box<dyn Fn(Point) -> Point> = match (self.view, self.position) {
            (Some(v), None) if v.iter().all(|x| x.is_finite()) && dot(v, v) > 0.0 => {
                let away = crate::unit(v).map(|x| -x);
                Box::new(move |_| away)
            }
            (None, Some(c)) if c.iter().all(|x| x.is_finite()) => Box::new(move |p| sub(c, p)),
            _ => {
                let given = |p: Option<Point>| p.map_or_else(|| "none".to_string(), |p| format!("{p:?}"));
                return Err(MeshError::Invalid(format!(
                    "a camera needs either a finite, non-zero `view` direction or a `position`, got view {} and \
                     position {}",
                    given(self.view),
                    given(self.position)
                )));
            }
        };
        if !(self.max_angle_deg > 0.0 && self.max_angle_deg <= 180.0) {
            return Err(MeshError::Invalid(format!("max_angle_deg = {} must be in (0, 180]", self.max_angle_deg)));
        }
        let surface = crate::topology::boundary_surface(mesh);
        let bvh = crate::SurfaceBvh::new(&surface)?;
        let (lo, hi) = mesh.bounds();
        let diagonal = crate::norm(sub(hi, lo));
        // Vertex normals: the area vectors of the triangles around each node, summed.
        let mut normals = vec![[0.0; 3]; mesh.num_nodes()];
        for t in 0..surface.triangles.len() {
            let a = crate::surface::triangle_area_vector(&surface, t);
            for &k in &surface.triangles[t] {
                normals[k] = along(normals[k], a, 1.0);
            }
        }
        let cos_max = self.max_angle_deg.to_radians().cos();
        // Boundary nodes are those with a normal (interior nodes are in no boundary triangle).
        let seen = (0..mesh.num_nodes())
            .filter(|&n| {
                let (p, d) = (mesh.nodes[n], to_camera(mesh.nodes[n]));
                let (ln, ld) = (crate::norm(normals[n]), crate::norm(d));
                if !(ln > 0.0 && ld > 0.0) || dot(normals[n], d) <= cos_max * ln * ld {
                    return false;
                }
                // The line of sight, from just off the surface to the camera (or far beyond the
                // organ for a camera at infinity), must cross no triangle.
                let dir = d.map(|x| x / ld);
                let start = along(p, dir, 1e-6 * diagonal);
                let end = match self.position {
                    Some(c) => c,
                    None => along(p, dir, 2.0 * diagonal),
                };
                bvh.segment_hits(start, end).is_empty()
            })
            .collect();
        Ok(seen)
    }
}

/// p + s d.
fn along(p: Point, d: Point, s: f64) -> Point {
    [p[0] + s * d[0], p[1] + s * d[1], p[2] + s * d[2]]
}

impl Near {
    /// The nodes within the distance of the landmarks, sorted.
    pub fn nodes(&self, mesh: &Mesh) -> Result<Vec<usize>, MeshError> {
        if !(self.distance >= 0.0 && self.distance.is_finite()) {
            return Err(MeshError::Invalid(format!("near: distance = {} must be non-negative", self.distance)));
        }
        let landmarks = self.landmarks()?;
        if landmarks.is_empty() {
            return Err(MeshError::Invalid("near: no landmark (give `points` or a `file`)".into()));
        }
        let candidates =
            if self.surface { crate::topology::boundary_nodes(mesh) } else { (0..mesh.num_nodes()).collect() };
        Ok(candidates
            .into_iter()
            .filter(|&n| landmarks.iter().any(|&l| crate::distance(mesh.nodes[n], l) <= self.distance))
            .collect())
    }

    /// Its landmarks: its points and its file's (m).
    fn landmarks(&self) -> Result<Vec<Point>, MeshError> {
        let mut landmarks = self.points.clone();
        if let Some(file) = &self.file {
            landmarks.extend(crate::io::points::read_points_csv(file)?);
        }
        Ok(landmarks)
    }
}

/// The smallest distance from the `landmarks` within which the boundary nodes carry `share` (0–1]
/// of the boundary's area ([`boundary_node_areas`]): the distance of [`Near`] that holds that
/// share of an organ's surface, whatever the organ's size. It lies half-way between the last node
/// it takes and the next, so that [`Near`] selects the same nodes whatever the rounding.
pub fn distance_holding_share(mesh: &Mesh, landmarks: &[Point], share: f64) -> Result<f64, MeshError> {
    if !(share > 0.0 && share <= 1.0) {
        return Err(MeshError::Invalid(format!("the share of the surface to hold must be in (0, 1], got {share}")));
    }
    if landmarks.is_empty() {
        return Err(MeshError::Invalid("no landmark to hold the surface near".into()));
    }
    let area = boundary_node_areas(mesh);
    let mut by_distance: Vec<(f64, usize)> = (0..mesh.num_nodes())
        .filter(|&n| area[n] > 0.0)
        .map(|n| (landmarks.iter().map(|&l| crate::distance(mesh.nodes[n], l)).fold(f64::INFINITY, f64::min), n))
        .collect();
    by_distance.sort_unstable_by(closer);
    let total: f64 = area.iter().sum();
    if !(total > 0.0) {
        return Err(MeshError::Invalid("the mesh's boundary has no area".into()));
    }
    let mut held = 0.0;
    for (i, &(d, n)) in by_distance.iter().enumerate() {
        held += area[n];
        if held >= share * total * (1.0 - 1e-12) {
            return Ok(by_distance.get(i + 1).map_or(d, |&(next, _)| 0.5 * (d + next)));
        }
    }
    Ok(by_distance.last().map_or(0.0, |&(d, _)| d))
}

/// Each node's share of the boundary's area (m²): a third of each boundary triangle it is a corner
/// of ([`crate::topology::boundary_surface`]'s, quadratic faces split in four); 0 off the boundary.
pub fn boundary_node_areas(mesh: &Mesh) -> Vec<f64> {
    let surface = crate::topology::boundary_surface(mesh);
    let mut area = vec![0.0; mesh.num_nodes()];
    for (t, triangle) in surface.triangles.iter().enumerate() {
        let third = crate::norm(crate::surface::triangle_area_vector(&surface, t)) / 3.0;
        triangle.iter().for_each(|&k| area[k] += third);
    }
    area
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

/// `count` of the `candidates` (indices into `nodes`) spread out by farthest-point sampling, in
/// the order chosen: first the candidate nearest their centroid, then each time the one farthest
/// from those chosen (ties go to the earlier candidate).
pub fn farthest_points(nodes: &[Point], candidates: &[usize], count: usize) -> Vec<usize> {
    let n = candidates.len() as f64;
    let centroid: Point = std::array::from_fn(|d| candidates.iter().map(|&k| nodes[k][d]).sum::<f64>() / n);
    let Some(first) = nearest(nodes, candidates.iter().copied(), centroid) else { return Vec::new() };
    let mut chosen = Vec::with_capacity(count.min(candidates.len()));
    if count > 0 {
        chosen.push(first);
    }
    let mut gap: Vec<f64> = candidates.iter().map(|&k| distance2(nodes[k], nodes[first])).collect();
    while chosen.len() < count.min(candidates.len()) {
        let (i, _) = gap.iter().enumerate().max_by(|a, b| a.1.total_cmp(b.1).then(b.0.cmp(&a.0))).unwrap_or((0, &0.0));
        let k = candidates[i];
        chosen.push(k);
        for (j, &c) in candidates.iter().enumerate() {
            gap[j] = gap[j].min(distance2(nodes[c], nodes[k]));
        }
    }
    chosen
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

impl Mesh {
    /// `nodes` and, on a quadratic mesh, the mid-edge nodes between two of them (as a region
    /// gains them, [`Mesh::quadratic`]): a list of a face's corners holds the whole quadratic face.
    pub fn with_mid_edge_nodes(&self, mut nodes: Vec<usize>) -> Vec<usize> {
        let Cells::Tet10(cells) = &self.cells else { return nodes };
        let mut member = vec![false; self.num_nodes()];
        nodes.iter().for_each(|&n| member[n] = true);
        for cell in cells {
            for (slot, [i, j]) in crate::quadratic::TET10_EDGES.iter().enumerate() {
                if member[cell[*i]] && member[cell[*j]] && !member[cell[4 + slot]] {
                    member[cell[4 + slot]] = true;
                    nodes.push(cell[4 + slot]);
                }
            }
        }
        nodes
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// On a quadratic mesh a list of nodes gains the mid-edge nodes between two of them, as a
    /// region does: the corners of the bottom face select the whole quadratic face.
    #[test]
    fn a_list_of_corners_on_a_quadratic_mesh_holds_the_mid_edge_nodes_between_them() {
        let linear = crate::box_mesh(crate::CellKind::Tet4, [0.0; 3], [1.0; 3], [2, 2, 2]).unwrap();
        let bottom: Vec<usize> = (0..linear.num_nodes()).filter(|&n| linear.nodes[n][2] == 0.0).collect();
        let quadratic = linear.quadratic().unwrap();
        let listed = NodeSelection::List(bottom.clone()).select(&quadratic).unwrap();
        let on_face: Vec<usize> = (0..quadratic.num_nodes()).filter(|&n| quadratic.nodes[n][2] == 0.0).collect();
        assert!(on_face.len() > bottom.len());
        assert_eq!(listed, on_face, "the face's corners and mid-edge nodes, nothing else");
        assert_eq!(NodeSelection::List(bottom.clone()).select(&linear).unwrap(), bottom, "T4: the list itself");
    }

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

    #[test]
    fn a_share_of_a_face_is_held_within_the_disc_of_that_area() {
        // A unit cube held near the centre of its bottom face: within r < 0.5 only that face is
        // near, and the disc of radius r holds π r² of the 6 m² boundary.
        let cube = crate::box_mesh(crate::CellKind::Tet4, [0.0; 3], [1.0; 3], [20, 20, 20]).unwrap();
        let centre = [0.5, 0.5, 0.0];
        let h = 0.05;
        for share in [0.02, 0.05, 0.1] {
            let exact = (6.0 * share / std::f64::consts::PI).sqrt();
            let r = distance_holding_share(&cube, &[centre], share).unwrap();
            assert!((r - exact).abs() < h, "share {share}: {r} against the disc's {exact}");
            // Near at that distance holds the nodes that make up the share, and none farther.
            let held = Near { points: vec![centre], file: None, distance: r, surface: true }.nodes(&cube).unwrap();
            let farthest = held.iter().map(|&n| crate::distance(cube.nodes[n], centre)).fold(0.0, f64::max);
            assert!(farthest <= r && r - farthest < h, "{farthest} {r}");
        }
        // The quadratic mesh of the same cube holds the same disc.
        let quadratic = cube.quadratic().unwrap();
        let (r1, r2) = (
            distance_holding_share(&cube, &[centre], 0.05).unwrap(),
            distance_holding_share(&quadratic, &[centre], 0.05).unwrap(),
        );
        assert!((r1 - r2).abs() < h, "{r1} {r2}");
        // The whole surface is held at the farthest corner's distance.
        let all = distance_holding_share(&cube, &[centre], 1.0).unwrap();
        assert!((all - 1.5f64.sqrt()).abs() < 1e-12, "{all}");
        assert!(distance_holding_share(&cube, &[centre], 0.0).is_err());
        assert!(distance_holding_share(&cube, &[], 0.1).is_err());
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
