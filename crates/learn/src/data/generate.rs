//! Dataset generation: random loads solved by the FEM model, encoded on a
//! regular grid as (input C, target U, mask) samples.
//!
//! Each sample `i` draws its loads from a generator seeded by the dataset seed
//! and `i` alone, so a resumed, split (`part i/n`) or re-ordered generation
//! produces the same samples. Samples are solved in parallel (rayon) by blocks
//! of `BLOCK` consecutive indices: a block's samples are solved in index order
//! by solvers created for that block (one per fixed set), which keep their
//! symbolic analysis and factorisations from one solve to the next, each on one
//! thread ([`StaticSolver::single_threaded`]: the blocks fill the threads). A
//! sample's solution thus depends on its index alone, bit for bit, whatever the
//! number of threads and wherever a resumed generation starts (it solves the
//! block's earlier samples again first); a split generation's parts are runs of whole blocks
//! ([`part_range`]). A sample whose solve fails is recorded
//! in the manifest with its reason. Draws chosen where a reduced-order model is least sure follow
//! the uniform ones ([`Generator::run_chosen`], in [`crate::choosing`]).

use std::collections::HashMap;
use std::ops::Range;
use std::path::Path;
use std::sync::atomic::{AtomicU64, Ordering};

use fem::{Material, Problem, SolverOptions, StaticSolver};
use mesh::embedding::{Embedding, Grid};
use mesh::{Mesh, NodeSelection, Point};
use rand::seq::index::sample as sample_indices;
use rand::Rng;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::data::chosen::CANDIDATE_BASE;
use crate::data::corrupt::item_rng;
use crate::data::dataset::{DatasetPart, DatasetSpec, DatasetWriter, Manifest, Sample};
use crate::data::grid::{encode_points, GridPlacement, GridShape};
use crate::data::response::RestResponse;
use crate::progress::Progress;
use crate::FieldUnit;
use crate::{LearnError, Result};

/// Stream number of the load generator in [`item_rng`].
const LOAD_STREAM: u64 = 1;

/// Samples per block: indices `b * BLOCK..(b + 1) * BLOCK` are solved in order by
/// the solvers of block `b` (independent of the thread count).
pub(crate) const BLOCK: u64 = 32;

/// How a dataset is generated (the `[dataset]` table of a scenario file).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DatasetConfig {
    /// Number of samples (generation indices `0..samples`).
    pub samples: usize,
    /// Base random seed.
    #[serde(default)]
    pub seed: u64,
    /// Samples per shard file.
    #[serde(default = "default_shard_size")]
    pub shard_size: usize,
    /// Grid nodes along x, y, z for a tetrahedral organ (embedded grid over its
    /// bounding box). Omitted for meshes whose nodes lie on a regular lattice
    /// (a box of hexahedra, an immersed grid): the lattice is the grid.
    pub grid: Option<[usize; 3]>,
    /// Alternative fixed node sets: each sample fixes one, drawn uniformly
    /// (one entry: always the same; e.g. the BC1/BC4/BC8 sets of the beam transfer-learning scenarios).
    /// May be left out when `attachment` holds the organ.
    #[serde(default)]
    pub fixed: Vec<NodeSelection>,
    /// Elastic foundations over regions of space ([`fem::Attachment`]), holding the organ in every
    /// sample (besides the fixed set drawn, if any): unlike a node set, the same problem on every
    /// mesh. Left out of the manifest when empty, so that a dataset without them keeps its source
    /// identity ([`crate::Manifest::source_id`]).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub attachment: Vec<fem::Attachment>,
    /// The random loads.
    pub load: Load,
    /// Adds a body force ρ·a to every sample, `a` of uniformly random direction and of
    /// magnitude drawn in this range (m/s²): gravity's pull on an organ whose supports and
    /// orientation changed since the preoperative scan (e.g. `[0.0, 9.81]`).
    /// Left out of the manifest when absent, so that a dataset without gravity keeps the source
    /// identity ([`crate::Manifest::source_id`]) it had before the option existed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gravity: Option<[f64; 2]>,
    /// What the network sees.
    pub input: Input,
}

fn default_shard_size() -> usize {
    100
}

/// Random loads of one sample.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub enum Load {
    /// One force along the inward surface normal at a random centre node (or within a cone
    /// around it), of random magnitude, shared by the surface nodes
    /// ([`mesh::Mesh::surface_nodes`]) within `radius` of the centre in proportion to their
    /// material share ([`mesh::Mesh::node_material_share`]: equal shares on a body-fitted
    /// mesh; little for immersed-grid nodes outside the organ). On quadratic tetrahedra the
    /// force is the uniform traction of that resultant on the patch ([`fem::force_shares`]):
    /// equal shares would load the corner nodes, which a uniform traction on a quadratic face
    /// leaves unloaded, and crush the elements around them.
    PatchForce {
        /// Nodes the patch centre is drawn from (default: surface nodes that are not fixed).
        centres: Option<NodeSelection>,
        /// Patch radius (m).
        radius: f64,
        /// Range of the total force magnitude (N).
        magnitude: [f64; 2],
        /// Half-angle (degrees, 0–180) of the cone around the inward normal the force's
        /// direction is drawn from, uniformly over its solid angle: oblique pushes, and pulls
        /// beyond 90°. Absent: along the inward normal (no draw, so that datasets without it
        /// keep their samples).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        cone: Option<f64>,
    },
    /// A surgical tool pressing the surface: the surface nodes within `radius` of a random
    /// centre node are moved by a random depth along the inward normal at the centre
    /// (prescribed displacements, the tool's face sticking to the tissue).
    Tool {
        /// Nodes the tool's centre is drawn from (default: surface nodes that are not fixed).
        centres: Option<NodeSelection>,
        /// Radius of the tool's face (m).
        radius: f64,
        /// Range of the indentation depth (m).
        depth: [f64; 2],
    },
    /// One of these loads (none of them `any`), drawn uniformly for each sample: e.g. tool
    /// presses and force pushes, so that a network meets both kinds of dent.
    Any(Vec<Load>),
    /// `count` simultaneous forces of random direction and magnitude on distinct random nodes.
    PointForces {
        /// Nodes the loaded nodes are drawn from.
        nodes: NodeSelection,
        /// Number of loaded nodes.
        count: usize,
        /// Range of each force's magnitude (N).
        magnitude: [f64; 2],
    },
}

/// The network input of a sample.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub enum Input {
    /// The applied nodal forces (N), spread to the grid by the adjoint of
    /// trilinear interpolation (total force preserved).
    Force,
    /// The displacement (m) of the observed nodes, optionally of a random
    /// connected sub-domain of them only.
    Displacement {
        /// Observed nodes (e.g. the visible surface).
        nodes: NodeSelection,
        /// Keep only a random sub-domain of between `sparse[0]` and `sparse[1]`
        /// observed nodes: those nearest to a random observed node.
        sparse: Option<[usize; 2]>,
        /// Keep only each observed node's displacement along the outward normal of the rest
        /// surface there, `(u·n) n`: what matching the organ's surface to a camera's point
        /// cloud measures (closest points give no tangential motion). The network then learns
        /// the tangential surface motion and the volume from the normal motion alone.
        #[serde(default)]
        normal: bool,
    },
}

/// The FEM model and grid encoding shared by all samples.
pub struct Generator {
    mesh: Mesh,
    material: Material,
    solver_options: SolverOptions,
    config: DatasetConfig,
    fixed_sets: Vec<Vec<usize>>,
    /// The point springs of the attachments ([`DatasetConfig::attachment`]).
    attachment_springs: Vec<fem::PointSpring>,
    /// The loads a sample draws from (one, or the alternatives of [`Load::Any`]).
    loads: Vec<LoadNodes>,
    normals: Vec<[f64; 3]>,
    /// Each node's share of material, weighting the patch force.
    material_share: Vec<f64>,
    /// The range of the body acceleration and each node's mass (kg).
    gravity: Option<([f64; 2], Vec<f64>)>,
    observed: Vec<usize>,
    encoding: Encoding,
    grid: GridShape,
    placement: GridPlacement,
    mask: Vec<u8>,
}

/// A load and the nodes it draws from.
struct LoadNodes {
    load: Load,
    /// Nodes a patch centre is drawn from (patch loads only).
    centres: Vec<usize>,
    /// Nodes a load may act on.
    nodes: Vec<usize>,
}

impl LoadNodes {
    /// Checks `load` against the mesh and selects its nodes (`select` resolves a selection); a
    /// patch centre drawn from the whole surface avoids the fixed nodes and the attachments.
    fn new(
        load: &Load,
        mesh: &Mesh,
        fixed_sets: &[Vec<usize>],
        attachments: &[mesh::Ball],
        select: &dyn Fn(&NodeSelection) -> Result<Vec<usize>>,
    ) -> Result<LoadNodes> {
        if let Load::PatchForce { cone: Some(cone), .. } = load {
            if !(0.0..=180.0).contains(cone) {
                return Err(invalid(format!("cone half-angle must lie in 0–180 degrees, got {cone}")));
            }
        }
        let (centres, nodes) = match load {
            Load::PatchForce { centres, radius, magnitude: range, .. }
            | Load::Tool { centres, radius, depth: range } => {
                check_range(range, if matches!(load, Load::Tool { .. }) { "depth" } else { "magnitude" })?;
                if !(*radius > 0.0) {
                    return Err(invalid(format!("patch radius must be positive, got {radius}")));
                }
                // Where a tool can push: the organ's surface (on an immersed grid, its cut cells' nodes).
                let surface = mesh.surface_nodes();
                let c: Vec<usize> = match centres {
                    Some(s) => select(s)?,
                    None => surface
                        .iter()
                        .copied()
                        .filter(|n| fixed_sets.iter().all(|f| f.binary_search(n).is_err()))
                        .filter(|&n| attachments.iter().all(|b| !b.contains(mesh.nodes[n])))
                        .collect(),
                };
                if c.is_empty() {
                    return Err(invalid("no candidate node for the patch centre"));
                }
                (c, surface)
            }
            Load::PointForces { nodes, count, magnitude } => {
                check_range(magnitude, "magnitude")?;
                let n = select(nodes)?;
                if *count == 0 || *count > n.len() {
                    return Err(invalid(format!("cannot load {count} distinct nodes out of {}", n.len())));
                }
                (Vec::new(), n)
            }
            Load::Any(_) => return Err(invalid("`any` lists single loads, not other `any`")),
        };
        Ok(LoadNodes { load: load.clone(), centres, nodes })
    }
}

/// How nodal fields reach the grid.
enum Encoding {
    /// Mesh node n is grid node `node[n]` (flat index i*ny*nz + j*nz + k).
    Lattice(Vec<usize>),
    /// A tetrahedral mesh embedded in a grid (`embedding.grid`).
    Embedded(Embedding),
}

/// The part of `u` along the unit vector `n`: `(u·n) n`.
pub fn normal_part(u: &[f64], n: [f64; 3]) -> [f64; 3] {
    let along = u[0] * n[0] + u[1] * n[1] + u[2] * n[2];
    n.map(|c| along * c)
}

fn invalid(msg: impl Into<String>) -> LearnError {
    LearnError::InvalidInput(msg.into())
}

/// What a draw applies: its fixed set, nodal forces, the nodes a tool moves and by how much,
/// and the nodes it observes.
struct Draw {
    fixed: usize,
    f: Vec<f64>,
    tool: Option<(Vec<usize>, Point)>,
    observed: Vec<usize>,
}

impl Generator {
    /// Prepares the encoding and node sets; checks the configuration against the mesh. With
    /// quadratic elements (`material.order = 2`) the samples are solved, loaded and observed on
    /// the T10 mesh ([`Mesh::quadratic`]: the mesh's nodes, then its mid-edge nodes).
    pub fn new(mesh: Mesh, material: Material, solver_options: SolverOptions, config: DatasetConfig) -> Result<Self> {
        let mesh = if material.order == 2 { mesh.quadratic()? } else { mesh };
        if config.samples == 0 {
            return Err(invalid("a dataset needs at least one sample"));
        }
        if config.samples as u64 > CANDIDATE_BASE {
            return Err(invalid(format!("a dataset holds at most {CANDIDATE_BASE} uniform draws")));
        }
        if config.fixed.is_empty() && config.attachment.is_empty() {
            return Err(invalid(
                "at least one fixed node set or attachment is needed (a free organ has rigid-body modes)",
            ));
        }
        let select = |s: &NodeSelection| s.select(&mesh).map_err(|e| invalid(format!("selection {s}: {e}")));
        // Selections are sorted and free of repeats: membership tests below use binary search. Held
        // by attachments alone, every sample "draws" the one empty set.
        let mut fixed_sets = config.fixed.iter().map(select).collect::<Result<Vec<_>>>()?;
        if fixed_sets.is_empty() {
            fixed_sets.push(Vec::new());
        }
        // The attachments' springs, integrated once for every sample.
        let mut held = Problem::new(mesh.clone(), material);
        let attachment_balls = held.attach_all(&config.attachment)?;
        let attachment_springs = held.point_springs;
        let normals = mesh.surface_normals();
        let loads = match &config.load {
            Load::Any(list) if list.is_empty() => return Err(invalid("`any` needs at least one load")),
            Load::Any(list) => {
                list.iter().map(|l| LoadNodes::new(l, &mesh, &fixed_sets, &attachment_balls, &select)).collect()
            }
            one => LoadNodes::new(one, &mesh, &fixed_sets, &attachment_balls, &select).map(|l| vec![l]),
        }?;
        let observed = match &config.input {
            Input::Force => Vec::new(),
            Input::Displacement { nodes, sparse, .. } => {
                let o = select(nodes)?;
                if let Some([lo, hi]) = sparse {
                    if lo > hi || *lo == 0 || *hi > o.len() {
                        return Err(invalid(format!("sparse range [{lo}, {hi}] must lie in [1, {}]", o.len())));
                    }
                }
                o
            }
        };
        let (encoding, grid, placement) = match config.grid {
            None => lattice_encoding(&mesh)?,
            Some(dims) => embedded_encoding(&mesh, dims)?,
        };
        let mut mask = vec![0u8; grid.nodes()];
        match &encoding {
            Encoding::Lattice(node) => node.iter().for_each(|&g| mask[g] = 1),
            Encoding::Embedded(embedding) => {
                embedding.mask().iter().enumerate().filter(|(_, &b)| b).for_each(|(g, _)| mask[g] = 1)
            }
        }
        let material_share = mesh.node_material_share();
        let gravity = match config.gravity {
            Some(range) => {
                check_range(&range, "gravity")?;
                Some((range, fem::nodal_masses(&mesh, material.density)?))
            }
            None => None,
        };
        Ok(Generator {
            mesh,
            material,
            solver_options,
            config,
            fixed_sets,
            attachment_springs,
            loads,
            normals,
            material_share,
            gravity,
            observed,
            encoding,
            grid,
            placement,
            mask,
        })
    }

    /// The linear-elastic response at rest of the dataset's problem (its material's tangent at
    /// rest, fixed nodes and attachments), between the input's force field and the target's
    /// displacement field on the grid: a physics prior for a reduced-order model. Force inputs and
    /// a single fixed set only.
    pub fn rest_response(&self) -> Result<RestResponse> {
        if self.config.input != Input::Force {
            return Err(invalid("the linear response at rest is a prior for force inputs only"));
        }
        if self.fixed_sets.len() != 1 {
            return Err(invalid(format!(
                "the linear response at rest needs one set of fixed nodes; the dataset draws among {}",
                self.fixed_sets.len()
            )));
        }
        let solver = StaticSolver::new(self.problem(0))?;
        let grid_nodes = self.grid.nodes();
        let nn = self.mesh.num_nodes();
        let mut pull = vec![Vec::new(); nn];
        let mut push = vec![Vec::new(); grid_nodes];
        match &self.encoding {
            Encoding::Lattice(node) => {
                for (m, &g) in node.iter().enumerate() {
                    pull[m].push((g, 1.0));
                    push[g].push((m, 1.0));
                }
            }
            Encoding::Embedded(embedding) => {
                // The nodes a load may act on spread their forces to the corners of their grid cells:
                // each grid node's force goes back to them by their shares of it.
                let mut loaded: Vec<usize> = self.loads.iter().flat_map(|l| l.nodes.iter().copied()).collect();
                loaded.sort_unstable();
                loaded.dedup();
                let mut spread = vec![0.0; grid_nodes];
                let mut corners = Vec::with_capacity(loaded.len());
                for &m in &loaded {
                    let c = embedding.grid.corners(m, self.mesh.nodes[m])?;
                    c.iter().for_each(|&(g, w)| spread[g] += w);
                    corners.push((m, c));
                }
                for (m, c) in corners {
                    pull[m] = c.into_iter().filter(|&(_, w)| w > 0.0).map(|(g, w)| (g, w / spread[g])).collect();
                }
                for (g, location) in embedding.locations.iter().enumerate() {
                    if let Some(l) = location {
                        push[g] = l.terms().collect();
                    }
                }
            }
        }
        let m = &self.material;
        let description = format!(
            "the linear-elastic response at rest (E = {} Pa, ν = {}, {} nodes)",
            m.young,
            m.poisson,
            self.mesh.num_nodes()
        );
        Ok(RestResponse::new(solver, grid_nodes, pull, push, description))
    }

    /// The mesh the samples are solved on (quadratic with `order = 2`).
    pub fn mesh(&self) -> &Mesh {
        &self.mesh
    }

    /// The grid shape of the samples.
    pub fn grid(&self) -> GridShape {
        self.grid
    }

    /// The configuration.
    pub fn config(&self) -> &DatasetConfig {
        &self.config
    }

    /// The mask of grid nodes inside the organ (1 inside, 0 outside).
    pub fn mask(&self) -> &[u8] {
        &self.mask
    }

    /// Encodes a nodal vector field (3 per mesh node) on the grid.
    /// Forces are spread (sum-preserving); displacements are interpolated.
    pub fn encode(&self, field: &[f64], is_force: bool) -> Result<Vec<f32>> {
        let n = self.grid.nodes();
        let mut out = vec![0f32; 3 * n];
        match &self.encoding {
            Encoding::Lattice(node) => {
                for (m, &g) in node.iter().enumerate() {
                    for c in 0..3 {
                        out[c * n + g] = field[3 * m + c] as f32;
                    }
                }
            }
            Encoding::Embedded(embedding) => {
                if is_force {
                    let forces: Vec<[f64; 3]> = field.chunks_exact(3).map(|f| [f[0], f[1], f[2]]).collect();
                    out = encode_points(&embedding.grid, &self.mesh.nodes, &forces, true)?;
                } else {
                    let grid_field = embedding.map_nodal(field, 3)?;
                    out.iter_mut().zip(&grid_field).for_each(|(o, v)| *o = *v as f32);
                }
            }
        }
        Ok(out)
    }

    fn problem(&self, fixed: usize) -> Problem {
        let mut p = Problem::new(self.mesh.clone(), self.material);
        p.fix(&self.fixed_sets[fixed]);
        p.point_springs.extend_from_slice(&self.attachment_springs);
        p
    }

    /// The loads and observed nodes of draw `index` (a function of the seed and the index alone).
    fn draw(&self, index: u64) -> std::result::Result<Draw, String> {
        let mut rng = item_rng(self.config.seed, LOAD_STREAM, index);
        let fixed = rng.random_range(0..self.fixed_sets.len());
        let nn = self.mesh.num_nodes();
        let mut f = vec![0.0; 3 * nn];
        // Nodes moved by a tool, and by how much.
        let mut tool = None;
        // A draw among alternatives only: a single load's samples stay those of before `any`.
        let loads = &self.loads[if self.loads.len() > 1 { rng.random_range(0..self.loads.len()) } else { 0 }];
        match &loads.load {
            Load::PatchForce { radius, magnitude, cone, .. } => {
                let (centre, patch) = self.patch(loads, &mut rng, *radius, fixed)?;
                let mag = rng.random_range(magnitude[0]..=magnitude[1]);
                // The force pushes along −outward: the outward normal, or a direction within the cone around it.
                let outward = match cone {
                    Some(cone) => direction_in_cone(&mut rng, self.normals[centre], cone.to_radians()),
                    None => self.normals[centre],
                };
                let shares: Vec<(usize, f64)> = if matches!(self.mesh.cells, mesh::Cells::Tet10(_)) {
                    fem::force_shares(&self.mesh, &patch)
                } else {
                    let total: f64 = patch.iter().map(|&n| self.material_share[n]).sum();
                    if !(total > 0.0) {
                        return Err(format!("the patch around node {centre} has no material"));
                    }
                    patch.iter().map(|&n| (n, self.material_share[n] / total)).collect()
                };
                for (n, share) in shares {
                    for d in 0..3 {
                        f[3 * n + d] -= mag * outward[d] * share;
                    }
                }
            }
            Load::Tool { radius, depth, .. } => {
                let (centre, patch) = self.patch(loads, &mut rng, *radius, fixed)?;
                let depth = rng.random_range(depth[0]..=depth[1]);
                tool = Some((patch, self.normals[centre].map(|c| -depth * c)));
            }
            Load::PointForces { count, magnitude, .. } => {
                for k in sample_indices(&mut rng, loads.nodes.len(), *count) {
                    let n = loads.nodes[k];
                    let dir = random_unit(&mut rng);
                    let mag = rng.random_range(magnitude[0]..=magnitude[1]);
                    for d in 0..3 {
                        f[3 * n + d] += mag * dir[d];
                    }
                }
            }
            Load::Any(_) => unreachable!("alternatives are resolved in Generator::new"),
        }
        if let Some((range, masses)) = &self.gravity {
            let direction = random_unit(&mut rng);
            let a = rng.random_range(range[0]..=range[1]);
            for (f, m) in f.chunks_exact_mut(3).zip(masses) {
                (0..3).for_each(|d| f[d] += a * direction[d] * m);
            }
        }
        let observed = match &self.config.input {
            Input::Displacement { sparse: Some([lo, hi]), .. } => {
                let count = rng.random_range(*lo..=*hi);
                let seed = self.mesh.nodes[self.observed[rng.random_range(0..self.observed.len())]];
                mesh::select::k_nearest(&self.mesh.nodes, self.observed.iter().copied(), seed, count)
            }
            _ => self.observed.clone(),
        };
        Ok(Draw { fixed, f, tool, observed })
    }

    /// The network input of draw `index` without solving it (force inputs only): the drawn forces
    /// on the grid. Cheap: how candidates are ranked before any is solved.
    pub fn draw_input(&self, index: u64) -> Result<Vec<f32>> {
        if self.config.input != Input::Force {
            return Err(invalid("only a force input is known before the draw is solved"));
        }
        let draw = self.draw(index).map_err(|reason| invalid(format!("draw {index}: {reason}")))?;
        self.encode(&draw.f, true)
    }

    /// Generates sample `index`: draws loads, solves, encodes.
    /// `solvers` caches one solver per fixed set for the block of `index`.
    fn sample(&self, index: u64, solvers: &mut HashMap<usize, StaticSolver>) -> std::result::Result<Sample, String> {
        let Draw { fixed, f, tool, observed } = self.draw(index)?;
        let nn = self.mesh.num_nodes();
        let solution = match tool {
            // The tool's nodes change from one sample to the next, and with them the system's
            // pattern: a solver of its own.
            Some((nodes, displacement)) => {
                let mut problem = self.problem(fixed);
                problem.prescribe(&nodes, displacement);
                problem.f_ext.copy_from_slice(&f);
                StaticSolver::single_threaded(problem).and_then(|mut s| s.solve(&self.solver_options))
            }
            None => {
                let solver = match solvers.entry(fixed) {
                    std::collections::hash_map::Entry::Occupied(e) => e.into_mut(),
                    std::collections::hash_map::Entry::Vacant(v) => {
                        v.insert(StaticSolver::single_threaded(self.problem(fixed)).map_err(|e| e.to_string())?)
                    }
                };
                solver.problem_mut().f_ext.copy_from_slice(&f);
                solver.solve(&self.solver_options)
            }
        }
        .map_err(|e| e.to_string())?;
        let input = match &self.config.input {
            Input::Force => self.encode(&f, true),
            Input::Displacement { normal, .. } => {
                let mut partial = vec![0.0; 3 * nn];
                for &n in &observed {
                    let u = &solution.u[3 * n..3 * n + 3];
                    let kept = if *normal { normal_part(u, self.normals[n]) } else { [u[0], u[1], u[2]] };
                    partial[3 * n..3 * n + 3].copy_from_slice(&kept);
                }
                self.encode_observed(&partial, &observed)
            }
        }
        .map_err(|e| e.to_string())?;
        let target = self.encode(&solution.u, false).map_err(|e| e.to_string())?;
        Ok(Sample { index, input, target, mask: self.mask.clone() })
    }

    /// Draws a patch of `load`: a random centre and its free nodes within `radius` of it.
    fn patch(
        &self,
        load: &LoadNodes,
        rng: &mut impl Rng,
        radius: f64,
        fixed: usize,
    ) -> std::result::Result<(usize, Vec<usize>), String> {
        let centre = load.centres[rng.random_range(0..load.centres.len())];
        let c = self.mesh.nodes[centre];
        let patch: Vec<usize> = load
            .nodes
            .iter()
            .copied()
            .filter(|&n| {
                let d = mesh::sub(self.mesh.nodes[n], c);
                mesh::dot(d, d) <= radius * radius
            })
            .filter(|n| self.fixed_sets[fixed].binary_search(n).is_err())
            .collect();
        if patch.is_empty() {
            return Err(format!("the patch around node {centre} has no free surface node"));
        }
        Ok((centre, patch))
    }

    /// Generates the indices of block `block` that lie in `keep`, in order. All the
    /// block's samples before `keep.end` are solved, in order and by solvers created
    /// here, so that each solution depends on its index alone.
    fn block(&self, block: u64, keep: &Range<u64>) -> Vec<(u64, std::result::Result<Sample, String>)> {
        let indices: Vec<u64> = (block * BLOCK..((block + 1) * BLOCK).min(keep.end)).collect();
        self.solve_in_order(&indices, keep.start.saturating_sub(block * BLOCK) as usize)
    }

    /// Generates `indices` in order, by solvers created here (which keep their factorisations
    /// from one solve to the next), and returns the samples from position `from` on: each
    /// solution depends on the indices up to its own alone.
    pub(crate) fn solve_in_order(
        &self,
        indices: &[u64],
        from: usize,
    ) -> Vec<(u64, std::result::Result<Sample, String>)> {
        let mut solvers = HashMap::new();
        let mut out = Vec::new();
        for (position, &i) in indices.iter().enumerate() {
            let sample = self.sample(i, &mut solvers);
            if position >= from {
                out.push((i, sample));
            }
        }
        out
    }

    /// Displacements of observed nodes only, on the grid: exact on a lattice; for an
    /// embedded mesh see [`encode_points`] (nearest grid node, averaged).
    fn encode_observed(&self, partial: &[f64], observed: &[usize]) -> Result<Vec<f32>> {
        match &self.encoding {
            Encoding::Lattice(_) => self.encode(partial, false),
            Encoding::Embedded(embedding) => {
                let points: Vec<Point> = observed.iter().map(|&m| self.mesh.nodes[m]).collect();
                let values: Vec<[f64; 3]> =
                    observed.iter().map(|&m| [partial[3 * m], partial[3 * m + 1], partial[3 * m + 2]]).collect();
                encode_points(&embedding.grid, &points, &values, false)
            }
        }
    }

    /// What a dataset of scenario `name` generated by this generator is (of part `part`, if any).
    pub(crate) fn spec(&self, name: &str, part: Option<DatasetPart>) -> DatasetSpec {
        DatasetSpec {
            scenario: name.to_string(),
            seed: self.config.seed,
            part,
            grid: self.grid,
            input_unit: match self.config.input {
                Input::Force => FieldUnit::Newton,
                Input::Displacement { .. } => FieldUnit::Metre,
            },
            target_unit: FieldUnit::Metre,
            shard_size: self.config.shard_size,
            metadata: serde_json::json!({
                "generator": "augsim",
                "material": self.material,
                "dataset": self.config,
                "mesh_nodes": self.mesh.num_nodes(),
                "mesh_cells": self.mesh.cells.len(),
                "grid_origin": self.placement.origin,
                "grid_spacing": self.placement.spacing,
                "markers": self.mesh.regions.get("markers").map(|m| m.iter().map(|&n| self.mesh.nodes[n]).collect::<Vec<_>>()),
            }),
        }
    }

    /// Generates indices `range` into `dir` (resuming an unfinished dataset there from its last
    /// complete shard), reporting the draws done to `progress` as each block of them is solved (and
    /// the draws a resumed dataset holds, in a line, once it is accepted). Stops with an error when
    /// most of its first draws fail ([`EARLY_DRAWS`]), saying why and what to change.
    pub fn run(&self, dir: &Path, name: &str, part: Option<DatasetPart>, progress: &dyn Progress) -> Result<Manifest> {
        let range = part_range(self.config.samples, part.as_ref())?;
        let spec = self.spec(name, part);
        // A complete dataset of this very spec (a shard run again) has nothing left to draw.
        if let Ok(done) = crate::Dataset::open(dir) {
            if done.manifest().complete && done.manifest().spec() == spec {
                return Ok(done.manifest().clone());
            }
        }
        let mut writer = DatasetWriter::create_or_resume(dir, spec)?;
        if let Some(line) = writer.resumed() {
            progress.line(&line);
        }
        let start = writer.resume_from().max(range.start as u64);
        let total = range.end as u64;
        // Blocks per batch: at least a shard, and as many for every thread.
        let threads = rayon::current_num_threads() as u64;
        let batch = (self.config.shard_size as u64).div_ceil(BLOCK).div_ceil(threads) * threads;
        let mut next = start;
        let mut failures: Vec<String> = Vec::new();
        progress.advance(next - range.start as u64, total - range.start as u64, "");
        while next < total {
            let end = ((next / BLOCK + batch) * BLOCK).min(total);
            let keep = next..end;
            // The draws solved so far are reported block by block (a batch takes minutes).
            let solved = AtomicU64::new(next - range.start as u64);
            let results: Vec<_> = (next / BLOCK..end.div_ceil(BLOCK))
                .into_par_iter()
                .map(|b| {
                    let drawn = self.block(b, &keep);
                    let done = solved.fetch_add(drawn.len() as u64, Ordering::Relaxed) + drawn.len() as u64;
                    progress.advance(done, total - range.start as u64, "");
                    drawn
                })
                .collect();
            for (i, r) in results.into_iter().flatten() {
                match r {
                    Ok(s) => writer.push(&s)?,
                    Err(reason) => {
                        failures.push(reason.clone());
                        writer.push_failure(i, reason)?;
                    }
                }
            }
            if let Some(why) = failing_early(&failures, end - start) {
                writer.stop()?;
                return Err(invalid(why));
            }
            next = end;
            progress.advance(next - range.start as u64, total - range.start as u64, "");
        }
        writer.finish()
    }
}

/// A generation stops when, after at least this many draws, more than half of them failed: the
/// draws fail for a reason of the set-up (loads, attachments, mesh), and the rest would fail too.
pub const EARLY_DRAWS: u64 = 16;

/// Why a generation that has failed on most of its first `done` draws should stop (at least
/// [`EARLY_DRAWS`] draws, more than half failed), with the most common reason and what to change;
/// `None` while it goes well.
fn failing_early(failures: &[String], done: u64) -> Option<String> {
    if done < EARLY_DRAWS || 2 * failures.len() as u64 <= done {
        return None;
    }
    // Reasons of one kind differ only by their numbers (element, load factor, residual).
    let kind = |reason: &str| -> String { reason.chars().filter(|c| !c.is_ascii_digit()).collect() };
    let mut counts: HashMap<String, (usize, &str)> = HashMap::new();
    for reason in failures {
        counts.entry(kind(reason)).or_insert((0, reason)).0 += 1;
    }
    let (count, example) = counts.into_values().max_by_key(|(count, _)| *count)?;
    let advice = if example.contains("hang on the rest") || example.contains("held") {
        "the attachments or the mesh: hold the organ at three places or more, not on one line, and mesh it \
         again (more tetrahedra)"
    } else if example.contains("inverted") || example.contains("did not converge") || example.contains("limit point") {
        "the loads (a smaller force or tool depth range in the scenario's [dataset.load]), or the attachments \
         (an organ held at one small place swings far); check one draw's problem with `augsim solve`"
    } else {
        "the scenario's loads, attachments or mesh"
    };
    Some(format!(
        "{} of the first {done} draws failed, {count} of them as \"{example}\": stopped, the rest would fail \
         too (every reason is in the dataset's manifest.json). Change {advice}",
        failures.len()
    ))
}

fn check_range(r: &[f64; 2], what: &str) -> Result<()> {
    if !(r[0] >= 0.0 && r[1] >= r[0] && r[1].is_finite()) {
        return Err(invalid(format!("{what} range {r:?} must satisfy 0 ≤ min ≤ max")));
    }
    Ok(())
}

/// A unit vector drawn uniformly over the spherical cap of half-angle `half_angle` (radians)
/// around the unit vector `axis`.
fn direction_in_cone(rng: &mut impl Rng, axis: [f64; 3], half_angle: f64) -> [f64; 3] {
    let cos = rng.random_range(half_angle.cos()..=1.0);
    let azimuth = rng.random_range(0.0..std::f64::consts::TAU);
    let sin = (1.0 - cos * cos).max(0.0).sqrt();
    // An orthonormal pair across the axis, from the coordinate axis least aligned with it.
    let least = (0..3).min_by(|&a, &b| axis[a].abs().total_cmp(&axis[b].abs())).unwrap_or(0);
    let mut e = [0.0; 3];
    e[least] = 1.0;
    let u = mesh::unit(mesh::cross(axis, e));
    let v = mesh::cross(axis, u);
    std::array::from_fn(|d| cos * axis[d] + sin * (azimuth.cos() * u[d] + azimuth.sin() * v[d]))
}

fn random_unit(rng: &mut impl Rng) -> [f64; 3] {
    loop {
        let v: [f64; 3] = std::array::from_fn(|_| rng.random_range(-1.0..=1.0));
        let l = mesh::dot(v, v).sqrt();
        if l > 1e-3 && l <= 1.0 {
            return v.map(|c| c / l);
        }
    }
}

/// Indices generated by worker `part` of `samples` in total: a contiguous run of whole blocks
/// (`BLOCK`), the blocks shared out as evenly as they go, so that no part solves another's draws
/// again to start inside a block. A part with no block of its own (more parts than blocks) is empty.
pub fn part_range(samples: usize, part: Option<&DatasetPart>) -> Result<Range<usize>> {
    Ok(match part {
        None => 0..samples,
        Some(p) if p.count > 0 && p.index < p.count => {
            let blocks = samples.div_ceil(BLOCK as usize);
            let edge = |i: usize| (blocks * i / p.count * BLOCK as usize).min(samples);
            edge(p.index)..edge(p.index + 1)
        }
        Some(p) => return Err(invalid(format!("invalid part {}/{}", p.index, p.count))),
    })
}

/// The lattice of a mesh whose nodes lie on a regular grid (box of hexahedra,
/// immersed grid): spacing from the smallest node separation per axis.
fn lattice_encoding(mesh: &Mesh) -> Result<(Encoding, GridShape, GridPlacement)> {
    let (lo, hi) = mesh.bounds();
    let mut spacing = [f64::INFINITY; 3];
    for c in 0..mesh.cells.len() {
        let cell = mesh.cells.cell(c);
        for &a in cell {
            for &b in cell {
                for d in 0..3 {
                    let s = (mesh.nodes[a][d] - mesh.nodes[b][d]).abs();
                    if s > 1e-12 * (hi[d] - lo[d]) {
                        spacing[d] = spacing[d].min(s);
                    }
                }
            }
        }
    }
    let dims: [usize; 3] = std::array::from_fn(|d| ((hi[d] - lo[d]) / spacing[d]).round() as usize + 1);
    let shape = GridShape::new(dims[0], dims[1], dims[2]);
    let mut node = Vec::with_capacity(mesh.num_nodes());
    for (m, p) in mesh.nodes.iter().enumerate() {
        let ijk: [f64; 3] = std::array::from_fn(|d| (p[d] - lo[d]) / spacing[d]);
        if ijk.iter().any(|x| (x - x.round()).abs() > 1e-6) {
            return Err(invalid(format!(
                "mesh node {m} is not on a regular lattice: give `grid = [nx, ny, nz]` to embed the mesh instead"
            )));
        }
        let [i, j, k] = ijk.map(|x| x.round() as usize);
        node.push((i * shape.ny + j) * shape.nz + k);
    }
    Ok((Encoding::Lattice(node), shape, GridPlacement { origin: lo, spacing }))
}

fn embedded_encoding(mesh: &Mesh, dims: [usize; 3]) -> Result<(Encoding, GridShape, GridPlacement)> {
    let (lo, hi) = mesh.bounds();
    let grid = Grid::covering(lo, hi, dims)?;
    let placement = GridPlacement { origin: grid.origin, spacing: grid.spacing };
    let embedding = Embedding::new(mesh, grid)?;
    Ok((Encoding::Embedded(embedding), GridShape::new(dims[0], dims[1], dims[2]), placement))
}
