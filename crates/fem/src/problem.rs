//! A static boundary-value problem: mesh, material, Dirichlet conditions,
//! springs and external loads.

use std::collections::BTreeMap;

use mesh::{boundary_faces, Cells, Mesh, Point};

use crate::element::ElementGeometry;
use crate::material::Material;
use crate::FemError;

/// Everything a static solve needs. Loads are dead loads (fixed in the
/// reference configuration) and are applied in full at load factor 1.
#[derive(Clone, Debug)]
pub struct Problem {
    /// The mesh (metres).
    pub mesh: Mesh,
    /// The material of every element.
    pub material: Material,
    /// Prescribed displacement per constrained node (all three components);
    /// a fixed node has the value `[0, 0, 0]`. The set of nodes is frozen when
    /// a solver is built; the values may change between solves.
    pub dirichlet: BTreeMap<usize, Point>,
    /// Stiffness (N/m) of a zero-length spring tying each node to its rest position; 0 for none.
    pub springs: Vec<f64>,
    /// External nodal forces (N), 3 per node.
    pub f_ext: Vec<f64>,
    /// Zero-length springs on points that move with several nodes (e.g. data terms on surface points).
    pub point_springs: Vec<PointSpring>,
    /// Why [`Problem::new`] could not make quadratic tetrahedra of the T4 mesh (order 2), for
    /// [`Problem::validate`] to tell.
    quadratic_error: Option<String>,
}

/// A zero-length spring on a point that moves with one or several nodes (its displacement
/// x = Σ w_j u_j, e.g. a point of a surface triangle): energy ½ (x − t)ᵀ (k I + k_n n nᵀ) (x − t),
/// with `stiffness` k in every direction and `normal_stiffness` k_n more along the unit `normal`
/// (point to plane when k = 0, letting the surface slide along itself). A data term that ties a
/// matched surface point to where a cloud point puts it. The pull K t is a load: load stepping
/// scales it with the forces. Couplings between nodes that share no element are left out of the
/// tangent: the forces are exact and the solver's quasi-Newton updates absorb the difference.
#[derive(Clone, Debug, PartialEq)]
pub struct PointSpring {
    /// The nodes and their interpolation weights.
    pub nodes: Vec<(usize, f64)>,
    /// The point's target displacement t (m).
    pub target: Point,
    /// Stiffness in every direction (N/m).
    pub stiffness: f64,
    /// Unit direction of the extra stiffness.
    pub normal: Point,
    /// Extra stiffness along `normal` (N/m).
    pub normal_stiffness: f64,
}

impl PointSpring {
    /// K v, with K = k I + k_n n nᵀ the spring's stiffness.
    pub fn stiffness_times(&self, v: Point) -> Point {
        let along = self.normal_stiffness * (0..3).map(|d| self.normal[d] * v[d]).sum::<f64>();
        std::array::from_fn(|d| self.stiffness * v[d] + along * self.normal[d])
    }
}

impl Problem {
    /// A problem without constraints or loads. When the material asks for quadratic elements
    /// (`order = 2`), a T4 mesh becomes a T10 mesh ([`Mesh::quadratic`]): its own nodes keep
    /// their indices, the mid-edge nodes follow and join the regions between two of their
    /// nodes; [`Problem::validate`] fails for order 2 on other cells, and tells why when the T4
    /// mesh could not be made quadratic.
    pub fn new(mesh: Mesh, material: Material) -> Self {
        let (mesh, quadratic_error) = match &mesh.cells {
            Cells::Tet4(_) if material.order == 2 => match mesh.quadratic() {
                Ok(quadratic) => (quadratic, None),
                Err(error) => (mesh, Some(error.to_string())),
            },
            _ => (mesh, None),
        };
        let n = mesh.num_nodes();
        Problem {
            mesh,
            material,
            dirichlet: BTreeMap::new(),
            springs: vec![0.0; n],
            f_ext: vec![0.0; 3 * n],
            point_springs: Vec::new(),
            quadratic_error,
        }
    }

    /// Number of degrees of freedom (3 per node).
    pub fn num_dofs(&self) -> usize {
        3 * self.mesh.num_nodes()
    }

    /// The total stiffness of the point springs (N/m: each spring's isotropic and normal parts).
    pub fn point_spring_stiffness(&self) -> f64 {
        self.point_springs.iter().map(|s| s.stiffness + s.normal_stiffness).sum()
    }

    /// Fixes the nodes (zero displacement).
    pub fn fix(&mut self, nodes: &[usize]) {
        self.prescribe(nodes, [0.0; 3]);
    }

    /// Prescribes the same displacement on every given node.
    pub fn prescribe(&mut self, nodes: &[usize], displacement: Point) {
        for &n in nodes {
            self.dirichlet.insert(n, displacement);
        }
    }

    /// Adds a spring of the given stiffness (N/m) to each node.
    pub fn add_springs(&mut self, nodes: &[usize], stiffness: f64) {
        for &n in nodes {
            self.springs[n] += stiffness;
        }
    }

    /// Adds the force `total` (N) spread over the nodes by [`force_shares`]: the uniform
    /// traction of that resultant on the boundary faces they span.
    pub fn add_force(&mut self, nodes: &[usize], total: Point) {
        for (n, share) in force_shares(&self.mesh, nodes) {
            for (f, t) in self.f_ext[3 * n..3 * n + 3].iter_mut().zip(total) {
                *f += t * share;
            }
        }
    }

    /// Adds a surface traction (Pa, a force per reference area) on every boundary
    /// face whose nodes all belong to `nodes`. Returns the loaded area (m²).
    pub fn add_traction(&mut self, nodes: &[usize], traction: Point) -> f64 {
        let areas = node_areas(&self.mesh, nodes);
        for &(n, w) in &areas {
            for (f, t) in self.f_ext[3 * n..3 * n + 3].iter_mut().zip(traction) {
                *f += w * t;
            }
        }
        areas.iter().map(|(_, w)| w).sum()
    }

    /// Adds the body force ρ·g of the material's density under acceleration `g` (m/s²).
    pub fn add_gravity(&mut self, g: Point) -> Result<(), FemError> {
        let masses = nodal_masses(&self.mesh, self.material.density)?;
        for (f, m) in self.f_ext.chunks_exact_mut(3).zip(masses) {
            (0..3).for_each(|d| f[d] += m * g[d]);
        }
        Ok(())
    }

    /// Checks sizes, indices and finiteness of the data.
    pub fn validate(&self) -> Result<(), FemError> {
        let n = self.mesh.num_nodes();
        self.material.validate().map_err(FemError::Invalid)?;
        if self.material.order == 2 && !matches!(self.mesh.cells, Cells::Tet10(_)) {
            return Err(FemError::Invalid(match (&self.mesh.cells, &self.quadratic_error) {
                (Cells::Tet4(_), Some(cause)) => format!(
                    "order = 2 makes quadratic tetrahedra from a T4 mesh, which failed on this one: {cause}; repair \
                     the mesh, or use order = 1"
                ),
                _ => format!(
                    "order = 2 makes quadratic tetrahedra from a T4 mesh; this mesh has {} cells",
                    self.mesh.cells.kind_name()
                ),
            }));
        }
        if self.springs.len() != n || self.f_ext.len() != 3 * n {
            return Err(FemError::Invalid(format!(
                "springs ({}) and f_ext ({}) must have {n} and {} entries",
                self.springs.len(),
                self.f_ext.len(),
                3 * n
            )));
        }
        if let Some((&k, _)) = self.dirichlet.iter().find(|(&k, _)| k >= n) {
            return Err(FemError::Invalid(format!("constrained node {k} does not exist ({n} nodes)")));
        }
        if self.dirichlet.values().flatten().chain(&self.f_ext).any(|v| !v.is_finite()) {
            return Err(FemError::NonFinite("prescribed displacement or external force".into()));
        }
        let stiffness_ok = |k: f64| k >= 0.0 && k.is_finite();
        if !self.springs.iter().all(|&k| stiffness_ok(k)) {
            return Err(FemError::Invalid("spring stiffnesses must be non-negative and finite".into()));
        }
        for (i, s) in self.point_springs.iter().enumerate() {
            let length = s.normal.iter().map(|x| x * x).sum::<f64>().sqrt();
            let nodes_ok = !s.nodes.is_empty() && s.nodes.iter().all(|&(k, w)| k < n && w.is_finite());
            let normal_ok = s.normal_stiffness == 0.0 || (length - 1.0).abs() < 1e-6;
            if !(nodes_ok
                && normal_ok
                && stiffness_ok(s.stiffness)
                && stiffness_ok(s.normal_stiffness)
                && s.target.iter().all(|x| x.is_finite()))
            {
                return Err(FemError::Invalid(format!(
                    "point spring {i}: nodes {:?} of {n}, target {:?}, stiffness {} and {} along a normal of \
                     length {length} (nodes must exist, stiffnesses be non-negative, the normal of length 1)",
                    s.nodes, s.target, s.stiffness, s.normal_stiffness
                )));
            }
        }
        Ok(())
    }

    /// Refuses a body that nothing holds against rigid motion (its stiffness would be
    /// singular): the nodes that are prescribed or tied by a spring must include three not on
    /// one line, and so must every piece of the mesh that hangs on the rest by an edge or a
    /// vertex ([`Pieces`]), counting the nodes it shares with pieces already held. Without this,
    /// a forgotten `[[fixed]]` or a tetrahedron hanging by a vertex surfaces as a failed Newton
    /// solve ("element inverted").
    pub(crate) fn check_held(&self, pieces: &Pieces) -> Result<(), FemError> {
        self.check_anchored(pieces, self.anchored())
    }

    /// The nodes prescribed or tied by a spring (a node spring, or a point spring's node).
    fn anchored(&self) -> Vec<bool> {
        let mut anchored = vec![false; self.mesh.num_nodes()];
        let tied = (0..self.mesh.num_nodes()).filter(|&n| self.springs[n] > 0.0);
        let pulled = self
            .point_springs
            .iter()
            .filter(|s| s.stiffness + s.normal_stiffness > 0.0)
            .flat_map(|s| s.nodes.iter().filter(|(_, w)| *w != 0.0).map(|&(n, _)| n));
        self.dirichlet.keys().copied().chain(tied).chain(pulled).for_each(|n| anchored[n] = true);
        anchored
    }

    /// The pieces of the mesh that nothing holds although the rest is held, that hang on it by an
    /// edge or a vertex, and that carry nothing: no load, hold or spring acts on the nodes they
    /// alone have (each its cells). Such a piece (a mesher's slip) turns about its hinge at no
    /// cost of energy but carries no force: the rest deforms as without it. One that carries
    /// something is a mechanism, which a solve refuses, naming it.
    pub fn idle_hanging_pieces(&self) -> Vec<Vec<usize>> {
        let pieces = Pieces::of(&self.mesh);
        let anchored = self.anchored();
        let loose = self.loose_pieces(&pieces, anchored.clone());
        if pieces.nodes.len() == 1 || loose.len() == pieces.nodes.len() {
            return Vec::new();
        }
        let owners = pieces.owners(self.mesh.num_nodes());
        let loaded = |n: usize| self.f_ext[3 * n..3 * n + 3].iter().any(|&f| f != 0.0);
        let carries = |p: usize| pieces.nodes[p].iter().any(|&n| owners[n] == 1 && (anchored[n] || loaded(n)));
        loose
            .into_iter()
            .filter(|&p| pieces.nodes[p].iter().any(|&n| owners[n] > 1) && !carries(p))
            .map(|p| pieces.cells[p].clone())
            .collect()
    }

    /// The pieces not held, given the anchored nodes: pieces are held one after the other, each
    /// by three anchored nodes not on one line, its nodes then anchoring the pieces that share
    /// them.
    fn loose_pieces(&self, pieces: &Pieces, mut anchored: Vec<bool>) -> Vec<usize> {
        let mut held = vec![false; pieces.nodes.len()];
        while let Some(p) =
            (0..held.len()).find(|&p| !held[p] && held_by(&self.anchored_points(&pieces.nodes[p], &anchored)).is_ok())
        {
            held[p] = true;
            pieces.nodes[p].iter().for_each(|&n| anchored[n] = true);
        }
        (0..held.len()).filter(|&p| !held[p]).collect()
    }

    /// The positions of those of `nodes` that are `anchored`.
    fn anchored_points(&self, nodes: &[usize], anchored: &[bool]) -> Vec<Point> {
        nodes.iter().filter(|&&n| anchored[n]).map(|&n| self.mesh.nodes[n]).collect()
    }

    /// Whether the prescribed nodes alone hold the body (then it stays held whatever its springs).
    pub(crate) fn held_by_constraints(&self, pieces: &Pieces) -> bool {
        let mut anchored = vec![false; self.mesh.num_nodes()];
        self.dirichlet.keys().for_each(|&n| anchored[n] = true);
        self.check_anchored(pieces, anchored).is_ok()
    }

    /// [`Problem::check_held`] with the anchored nodes given: the pieces [`Problem::loose_pieces`]
    /// leaves are named in the error.
    fn check_anchored(&self, pieces: &Pieces, anchored: Vec<bool>) -> Result<(), FemError> {
        if pieces.nodes.len() == 1 {
            return held_by(&self.anchored_points(&pieces.nodes[0], &anchored));
        }
        let loose = self.loose_pieces(pieces, anchored.clone());
        let Some(&first) = loose.first() else { return Ok(()) };
        if loose.len() == pieces.nodes.len() {
            // Nothing holds any piece: say so as for a body in one piece.
            let all: Vec<usize> = (0..self.mesh.num_nodes()).collect();
            held_by(&self.anchored_points(&all, &anchored))?;
        }
        let cells: usize = loose.iter().map(|&p| pieces.cells[p].len()).sum();
        let volume: f64 = loose.iter().flat_map(|&p| &pieces.cells[p]).map(|&c| self.mesh.cell_volume(c)).sum();
        // How each loose piece meets the rest: by shared nodes (an edge or a vertex), or not at all.
        let owners = pieces.owners(self.mesh.num_nodes());
        let touching = loose.iter().filter(|&&p| pieces.nodes[p].iter().any(|&n| owners[n] > 1)).count();
        // Or at nodes of their own where the rest has its own (an export that did not merge them).
        let mut unmerged = vec![false; self.mesh.num_nodes()];
        mesh::coincident_points(&self.mesh.nodes)
            .into_iter()
            .for_each(|(a, b)| (unmerged[a], unmerged[b]) = (true, true));
        let at_unmerged = loose.iter().filter(|&&p| pieces.nodes[p].iter().any(|&n| unmerged[n])).count();
        let how = match touching {
            0 if at_unmerged == loose.len() => {
                "meet the rest only at nodes that lie where its own do but are not merged with them (an export \
                 that kept them apart: merge coincident nodes)"
            }
            0 => "lie apart from the rest, touching it nowhere",
            t if t == loose.len() => "hang on the rest by an edge or a vertex",
            _ => "hang on the rest by an edge or a vertex, or lie apart from it",
        };
        let corner = pieces.nodes[first][0];
        let at = self.mesh.nodes[corner];
        Err(FemError::Invalid(format!(
            "{cells} element(s) ({:.2} % of the volume) in {} piece(s) of the mesh {how}, and nothing else holds \
             them: they can move freely (the first, of {} element(s) from element {}, at node {} ({:.4}, {:.4}, \
             {:.4}) m); remesh the organ (e.g. more tetrahedra: `augsim mesh` and `prepare` drop such small pieces), \
             or fix or tie nodes of each piece",
            100.0 * volume / self.mesh.volume(),
            loose.len(),
            pieces.cells[first].len(),
            self.mesh.file_cell(pieces.cells[first][0]),
            self.mesh.file_node(corner),
            at[0],
            at[1],
            at[2],
        )))
    }
}

/// The pieces of a mesh that must each be held: its cells joined through shared faces
/// ([`mesh::face_connected_pieces`]), with each piece's nodes.
#[derive(Clone, Debug)]
pub(crate) struct Pieces {
    cells: Vec<Vec<usize>>,
    nodes: Vec<Vec<usize>>,
}

impl Pieces {
    pub(crate) fn of(mesh: &Mesh) -> Self {
        let cells = mesh::face_connected_pieces(mesh);
        let nodes = cells
            .iter()
            .map(|piece| {
                let mut nodes: Vec<usize> = piece.iter().flat_map(|&c| mesh.cells.cell(c).iter().copied()).collect();
                nodes.sort_unstable();
                nodes.dedup();
                nodes
            })
            .collect();
        Pieces { cells, nodes }
    }

    /// How many pieces each of the mesh's `nodes` belongs to.
    fn owners(&self, nodes: usize) -> Vec<u32> {
        let mut owners = vec![0u32; nodes];
        self.nodes.iter().flatten().for_each(|&n| owners[n] += 1);
        owners
    }
}

/// Whether points tied to their rest positions hold a body against rigid motion: three of them
/// not on one line.
fn held_by(anchors: &[Point]) -> Result<(), FemError> {
    let Some(&first) = anchors.first() else {
        return Err(FemError::Invalid(
            "nothing holds the body: no node is fixed, prescribed or tied by a spring, so it can move as a rigid \
             body; fix nodes (`[[fixed]]` in a scenario) or add springs"
                .into(),
        ));
    };
    let far = anchors.iter().copied().max_by(|a, b| mesh::distance(first, *a).total_cmp(&mesh::distance(first, *b)));
    let span = far.map_or(0.0, |p| mesh::distance(first, p));
    let axis = far.map_or([0.0; 3], |p| mesh::sub(p, first));
    let off_axis = anchors
        .iter()
        .map(|&p| mesh::norm(mesh::cross(axis, mesh::sub(p, first))) / span.max(f64::MIN_POSITIVE))
        .fold(0.0, f64::max);
    if off_axis <= 1e-6 * span {
        let held = if span == 0.0 { "at a single point" } else { "only along one line" };
        return Err(FemError::Invalid(format!(
            "the body is held {held}: it can still rotate about it; fix (or tie by springs) at least three nodes \
             not on one line"
        )));
    }
    Ok(())
}

/// Each node's share (summing to 1) of a total force applied as the uniform traction of
/// that resultant on the boundary faces wholly made of the nodes: its lumped area on them
/// over their area, so that the load does not depend on how many nodes sample the patch.
/// Nodes on no such face get no share; when the nodes span no boundary face (a single
/// node, interior nodes), the shares are equal.
pub fn force_shares(mesh: &Mesh, nodes: &[usize]) -> Vec<(usize, f64)> {
    let areas = node_areas(mesh, nodes);
    let total: f64 = areas.iter().map(|(_, w)| w).sum();
    if total > 0.0 {
        return areas.into_iter().map(|(n, w)| (n, w / total)).collect();
    }
    let share = 1.0 / nodes.len().max(1) as f64;
    nodes.iter().map(|&n| (n, share)).collect()
}

/// The nodes of `nodes` that a force on them ([`force_shares`]) leaves out and that share no
/// boundary face with a node it loads: selected apart from the patch it acts on (a node of a
/// list, a second region), not at the patch's rim, each carrying none of it.
pub fn force_strays(mesh: &Mesh, nodes: &[usize]) -> Vec<usize> {
    let mut loaded = vec![false; mesh.num_nodes()];
    force_shares(mesh, nodes).into_iter().for_each(|(n, _)| loaded[n] = true);
    let mut beside = loaded.clone();
    for face in boundary_faces(mesh).iter().filter(|f| f.nodes.iter().any(|&n| loaded[n])) {
        face.nodes.iter().for_each(|&n| beside[n] = true);
    }
    nodes.iter().copied().filter(|&n| !beside[n]).collect()
}

/// Lumped area (m²) of each node on the boundary faces wholly made of `nodes`, in order of
/// first appearance; nodes on no such face are left out.
fn node_areas(mesh: &Mesh, nodes: &[usize]) -> Vec<(usize, f64)> {
    let mut member = vec![false; mesh.num_nodes()];
    for &n in nodes {
        member[n] = true;
    }
    let mut slot = vec![usize::MAX; mesh.num_nodes()];
    let mut areas: Vec<(usize, f64)> = Vec::new();
    for face in boundary_faces(mesh).into_iter().filter(|f| f.nodes.iter().all(|&n| member[n])) {
        let x: Vec<Point> = face.nodes.iter().map(|&n| mesh.nodes[n]).collect();
        for (&n, w) in face.nodes.iter().zip(face_node_areas(&x)) {
            if slot[n] == usize::MAX {
                slot[n] = areas.len();
                areas.push((n, 0.0));
            }
            areas[slot[n]].1 += w;
        }
    }
    areas
}

/// ∫ N_a dA of each node of a boundary face: a flat triangle (A/3 each), a quadratic triangle
/// (3-point rule, exact on flat faces: 0 at the corners, A/3 at the mid-edge nodes) or a
/// bilinear quadrilateral (2×2 Gauss rule).
fn face_node_areas(x: &[Point]) -> Vec<f64> {
    use mesh::{cross, dot, sub};
    if x.len() == 3 {
        let n = cross(sub(x[1], x[0]), sub(x[2], x[0]));
        return vec![dot(n, n).sqrt() / 6.0; 3];
    }
    if x.len() == 6 {
        return quadratic_triangle_node_areas(x);
    }
    let gp = 1.0 / 3f64.sqrt();
    let corners = [[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]];
    let mut w = vec![0.0; 4];
    for s in [-gp, gp] {
        for t in [-gp, gp] {
            let mut dxs = [0.0; 3];
            let mut dxt = [0.0; 3];
            for (a, c) in corners.iter().enumerate() {
                for d in 0..3 {
                    dxs[d] += x[a][d] * c[0] * (1.0 + c[1] * t) / 4.0;
                    dxt[d] += x[a][d] * c[1] * (1.0 + c[0] * s) / 4.0;
                }
            }
            let n = cross(dxs, dxt);
            let da = dot(n, n).sqrt();
            for (a, c) in corners.iter().enumerate() {
                w[a] += da * (1.0 + c[0] * s) * (1.0 + c[1] * t) / 4.0;
            }
        }
    }
    w
}

/// [`face_node_areas`] of a quadratic triangle: corners, then the mid-edge nodes of 0-1, 1-2, 2-0.
fn quadratic_triangle_node_areas(x: &[Point]) -> Vec<f64> {
    use mesh::{cross, dot};
    // Shape functions of barycentric l and their derivatives along ξ = l1 and η = l2.
    let shape = |l: [f64; 3]| -> [f64; 6] {
        [
            l[0] * (2.0 * l[0] - 1.0),
            l[1] * (2.0 * l[1] - 1.0),
            l[2] * (2.0 * l[2] - 1.0),
            4.0 * l[0] * l[1],
            4.0 * l[1] * l[2],
            4.0 * l[2] * l[0],
        ]
    };
    let dshape = |l: [f64; 3]| -> [[f64; 2]; 6] {
        let d0 = 4.0 * l[0] - 1.0;
        [
            [-d0, -d0],
            [4.0 * l[1] - 1.0, 0.0],
            [0.0, 4.0 * l[2] - 1.0],
            [4.0 * (l[0] - l[1]), -4.0 * l[1]],
            [4.0 * l[2], 4.0 * l[1]],
            [-4.0 * l[2], 4.0 * (l[0] - l[2])],
        ]
    };
    let mut w = vec![0.0; 6];
    for q in 0..3 {
        let l: [f64; 3] = std::array::from_fn(|k| if k == q { 2.0 / 3.0 } else { 1.0 / 6.0 });
        let (n, dn) = (shape(l), dshape(l));
        let tangent = |t: usize| -> Point { std::array::from_fn(|d| (0..6).map(|a| x[a][d] * dn[a][t]).sum()) };
        let normal = cross(tangent(0), tangent(1));
        let da = dot(normal, normal).sqrt() / 6.0;
        for a in 0..6 {
            w[a] += da * n[a];
        }
    }
    w
}

/// Each node's lumped mass (kg): ρ ∫ N_a over the elements around node a (the row sums of the
/// consistent mass matrix), with the elements' quadrature weights (scaled by each cell's volume
/// fraction on an immersed grid).
pub fn nodal_masses(mesh: &Mesh, density: f64) -> Result<Vec<f64>, FemError> {
    let geo = ElementGeometry::new(mesh, crate::Formulation::Standard)?;
    let (npe, nqp) = (geo.nodes_per_element, geo.points_per_element);
    let mut masses = vec![0.0; mesh.num_nodes()];
    for e in 0..geo.len() {
        for q in 0..nqp {
            let w = geo.weights[e * nqp + q] * density;
            for (a, &n) in geo.element_nodes(e).iter().enumerate() {
                masses[n] += w * geo.shape[q * npe + a];
            }
        }
    }
    Ok(masses)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Law;

    /// Order 2 makes a T4 mesh quadratic; where that fails, validation tells the mesh's fault.
    #[test]
    fn order_two_tells_why_a_t4_mesh_could_not_be_made_quadratic() {
        let mut material = Material::new(Law::Linear, 1000.0, 0.3);
        material.order = 2;
        let mut mesh = mesh::box_tet([0.0; 3], [1.0; 3], [1, 1, 1]).unwrap();
        let good = Problem::new(mesh.clone(), material);
        assert!(matches!(good.mesh.cells, Cells::Tet10(_)) && good.validate().is_ok());
        if let Cells::Tet4(tets) = &mut mesh.cells {
            tets[0].swap(0, 1);
        }
        let err = Problem::new(mesh, material).validate().unwrap_err().to_string();
        assert!(err.contains("which failed on this one: invalid mesh: cell 0 is inverted"), "{err}");
    }
}
