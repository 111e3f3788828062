//! Immersed-boundary hexahedral grids.
//!
//! A regular grid of cubic H8 cells covers the organ's bounding box plus a
//! margin. Each cell's volume fraction inside the organ is estimated with
//! `samples`³ sub-cell midpoints and the domain's inside test (cells whose
//! centre is farther from the boundary than their half diagonal are decided
//! at once when the domain's value is a distance, see
//! [`ImplicitDomain::lipschitz`]). Cells with a fraction above
//! `min_fraction` (default: any sample inside) are active; only they and
//! their nodes are kept, with the fractions in [`Mesh::cell_fraction`] (the
//! FEM scales each cell's stiffness by it).
//!
//! Node and cell order: lexicographic in the full grid's (k, j, i) with i
//! (x) fastest, as in [`crate::box_hex`]; [`ImmersedGrid`] keeps each node's
//! and cell's grid index.

use std::collections::BTreeMap;

use rayon::prelude::*;

use crate::tetmesh::{surface_domain, ImplicitDomain};
use crate::{Cells, Mesh, MeshError, Point, TriSurface};

/// Parameters of [`immersed_grid`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ImmersedOptions {
    /// Side of the cubic cells (m).
    pub spacing: f64,
    /// Space added around the bounding box on every side before the grid is
    /// laid out (m); the grid is centred on the box.
    pub margin: f64,
    /// Sub-samples per axis for the volume fraction (4 → 64 per cell).
    pub samples: usize,
    /// Cells whose fraction is at most this are dropped (0: keep any cell
    /// with a sample inside).
    pub min_fraction: f64,
}

impl ImmersedOptions {
    /// Cells of side `spacing`, a margin of half a cell, 4³ samples, every
    /// cell with a sample inside kept.
    pub fn with_spacing(spacing: f64) -> Self {
        ImmersedOptions { spacing, margin: 0.5 * spacing, samples: 4, min_fraction: 0.0 }
    }
}

/// An immersed-boundary grid: the active cells as an H8 mesh plus their
/// place in the full regular grid.
#[derive(Clone, Debug, PartialEq)]
pub struct ImmersedGrid {
    /// Active cells and their nodes; `cell_fraction` holds the volume fractions.
    pub mesh: Mesh,
    /// Lower corner of the full grid (m).
    pub origin: Point,
    /// Cell side (m).
    pub spacing: f64,
    /// Number of cells of the full grid along x, y, z.
    pub dims: [usize; 3],
    /// Grid index (i, j, k) of each active cell.
    pub cell_index: Vec<[usize; 3]>,
    /// Grid index (i, j, k) of each node (its position is origin + spacing·(i, j, k)).
    pub node_index: Vec<[usize; 3]>,
}

impl ImmersedGrid {
    /// Copies the regions of `source` (e.g. a T4 mesh of the same organ) to
    /// the grid: a grid region holds the nodes of every active cell that
    /// contains a node of the source region. Suited to surface patches
    /// (fixed, push, hidden); point sets such as markers are better located
    /// with [`crate::embedding::MeshLocator`]. Source regions with no node in
    /// an active cell are skipped; returns their names.
    pub fn transfer_regions(&mut self, source: &Mesh) -> Vec<String> {
        let mut lookup: BTreeMap<[usize; 3], usize> = BTreeMap::new();
        for (c, &ijk) in self.cell_index.iter().enumerate() {
            lookup.insert(ijk, c);
        }
        let mut skipped = Vec::new();
        for (name, set) in &source.regions {
            let mut nodes: Vec<usize> = Vec::new();
            for &k in set {
                let p = source.nodes[k];
                let f: [f64; 3] = std::array::from_fn(|d| (p[d] - self.origin[d]) / self.spacing);
                if f.iter().any(|x| !x.is_finite() || *x < 0.0) {
                    continue;
                }
                // The cell holding p, and its neighbours when p lies on a cell face.
                let base: [usize; 3] = std::array::from_fn(|d| f[d].floor() as usize);
                for corner in 0..8usize {
                    let ijk: [usize; 3] = std::array::from_fn(|d| {
                        let on_face = f[d] == f[d].floor() && base[d] > 0;
                        if corner >> d & 1 == 1 && on_face {
                            base[d] - 1
                        } else {
                            base[d]
                        }
                    });
                    if let Some(&c) = lookup.get(&ijk) {
                        nodes.extend_from_slice(self.mesh.cells.cell(c));
                    }
                }
            }
            nodes.sort_unstable();
            nodes.dedup();
            if nodes.is_empty() {
                skipped.push(name.clone());
            } else {
                self.mesh.regions.insert(name.clone(), nodes);
            }
        }
        skipped
    }
}

/// The immersed grid of `domain` (see the module documentation).
pub fn immersed_grid(domain: &dyn ImplicitDomain, opts: &ImmersedOptions) -> Result<ImmersedGrid, MeshError> {
    let h = opts.spacing;
    if !(h > 0.0 && h.is_finite()) {
        return Err(MeshError::Invalid(format!("immersed grid spacing must be positive and finite, got {h}")));
    }
    if !(opts.margin >= 0.0 && opts.margin.is_finite()) {
        return Err(MeshError::Invalid(format!("immersed grid margin must be non-negative, got {}", opts.margin)));
    }
    if opts.samples == 0 || opts.samples > 64 {
        return Err(MeshError::Invalid(format!("samples per axis must be in 1..=64, got {}", opts.samples)));
    }
    if !(0.0..1.0).contains(&opts.min_fraction) {
        return Err(MeshError::Invalid(format!("min_fraction must be in [0, 1), got {}", opts.min_fraction)));
    }
    let (lo, hi) = domain.bounds();
    if (0..3).any(|d| !(lo[d].is_finite() && hi[d].is_finite() && hi[d] >= lo[d])) {
        return Err(MeshError::Invalid(format!("domain bounds {lo:?}..{hi:?} are not a finite box")));
    }
    let dims: [usize; 3] =
        std::array::from_fn(|d| (((hi[d] - lo[d]) + 2.0 * opts.margin) / h).ceil().max(1.0) as usize);
    let total = dims[0] as f64 * dims[1] as f64 * dims[2] as f64;
    if total > 5.0e7 {
        return Err(MeshError::Invalid(format!("immersed grid spacing {h} m gives too many cells ({total:.0})")));
    }
    let origin: Point = std::array::from_fn(|d| 0.5 * (lo[d] + hi[d]) - 0.5 * dims[d] as f64 * h);
    let ns = opts.samples;
    let half_diag = 0.5 * 3f64.sqrt() * h;
    let lipschitz = domain.lipschitz();
    let cell_fraction = |i: usize, j: usize, k: usize| -> f64 {
        let corner = [origin[0] + i as f64 * h, origin[1] + j as f64 * h, origin[2] + k as f64 * h];
        if let Some(l) = lipschitz {
            let c = corner.map(|x| x + 0.5 * h);
            let f = domain.value(c);
            if f > l * half_diag {
                return 0.0;
            }
            if f < -l * half_diag {
                return 1.0;
            }
        }
        let mut inside = 0usize;
        for a in 0..ns {
            for b in 0..ns {
                for c in 0..ns {
                    let p = [
                        corner[0] + (a as f64 + 0.5) / ns as f64 * h,
                        corner[1] + (b as f64 + 0.5) / ns as f64 * h,
                        corner[2] + (c as f64 + 0.5) / ns as f64 * h,
                    ];
                    if domain.contains(p) {
                        inside += 1;
                    }
                }
            }
        }
        inside as f64 / (ns * ns * ns) as f64
    };
    let ncell = dims[0] * dims[1] * dims[2];
    let fractions: Vec<f64> = (0..ncell)
        .into_par_iter()
        .map(|c| cell_fraction(c % dims[0], (c / dims[0]) % dims[1], c / (dims[0] * dims[1])))
        .collect();
    let active: Vec<usize> = (0..ncell).filter(|&c| fractions[c] > opts.min_fraction).collect();
    if active.is_empty() {
        return Err(MeshError::Invalid(format!(
            "no cell of the immersed grid (spacing {h} m) has a sample inside the domain"
        )));
    }
    let nn = [dims[0] + 1, dims[1] + 1, dims[2] + 1];
    let lattice = |i: usize, j: usize, k: usize| i + nn[0] * (j + nn[1] * k);
    let mut node_id = vec![u32::MAX; nn[0] * nn[1] * nn[2]];
    let cell_ijk = |c: usize| [c % dims[0], (c / dims[0]) % dims[1], c / (dims[0] * dims[1])];
    let corners = |[i, j, k]: [usize; 3]| -> [usize; 8] {
        [
            lattice(i, j, k),
            lattice(i + 1, j, k),
            lattice(i + 1, j + 1, k),
            lattice(i, j + 1, k),
            lattice(i, j, k + 1),
            lattice(i + 1, j, k + 1),
            lattice(i + 1, j + 1, k + 1),
            lattice(i, j + 1, k + 1),
        ]
    };
    for &c in &active {
        for v in corners(cell_ijk(c)) {
            node_id[v] = 0;
        }
    }
    let mut nodes = Vec::new();
    let mut node_index = Vec::new();
    for (v, id) in node_id.iter_mut().enumerate() {
        if *id == u32::MAX {
            continue;
        }
        *id = nodes.len() as u32;
        let ijk = [v % nn[0], (v / nn[0]) % nn[1], v / (nn[0] * nn[1])];
        nodes.push(std::array::from_fn(|d| origin[d] + ijk[d] as f64 * h));
        node_index.push(ijk);
    }
    let hexes: Vec<[usize; 8]> = active.iter().map(|&c| corners(cell_ijk(c)).map(|v| node_id[v] as usize)).collect();
    let mut mesh = Mesh::new(nodes, Cells::Hex8(hexes))?;
    mesh.cell_fraction = Some(active.iter().map(|&c| fractions[c]).collect());
    Ok(ImmersedGrid {
        mesh,
        origin,
        spacing: h,
        dims,
        cell_index: active.iter().map(|&c| cell_ijk(c)).collect(),
        node_index,
    })
}

/// The immersed grid of a closed surface (checked and oriented as in
/// [`crate::tetmesh::mesh_surface`]).
pub fn immersed_surface(surface: &TriSurface, opts: &ImmersedOptions) -> Result<ImmersedGrid, MeshError> {
    let (bvh, _) = surface_domain(surface)?;
    immersed_grid(&bvh, opts)
}
