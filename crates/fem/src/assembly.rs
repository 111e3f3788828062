//! Parallel assembly of the internal force and the tangent stiffness into a
//! sparse pattern built once per mesh and constraint set.
//!
//! The matrix holds the free degrees of freedom only (Dirichlet dofs are
//! eliminated) and stores the lower triangle in compressed sparse columns,
//! as the sparse Cholesky factorisation expects.

use rayon::prelude::*;

use crate::element::{ElementGeometry, ForceScratch};
use crate::fbar;
use crate::material::{Formulation, Material};
use crate::FemError;

/// Marks a dof that is constrained, or a matrix entry that is not stored.
const NONE: u32 = u32::MAX;

/// Sparse pattern of the free-dof tangent and the map from the patches' dense tangents to its values.
#[derive(Clone, Debug)]
pub struct Pattern {
    /// For each global dof, its free index or `u32::MAX` when constrained.
    pub free_index: Vec<u32>,
    /// Number of free dofs.
    pub num_free: usize,
    /// CSC column pointers (lower triangle).
    pub col_ptr: Vec<u32>,
    /// CSC row indices, sorted within each column.
    pub row_idx: Vec<u32>,
    /// Start of each patch's dense tangent in the concatenation of all of them.
    matrix_ptr: Vec<usize>,
    /// The entries of the patches' dense tangents (index `matrix_ptr[p] + r * ndof_p + c` for
    /// patch p and local pair (r, c)) summed into value position v:
    /// `gather[gather_ptr[v]..gather_ptr[v + 1]]`, in patch order.
    gather_ptr: Vec<u32>,
    gather: Vec<u32>,
}

impl Pattern {
    /// Builds the pattern for the geometry's patches and constrained global dofs, column by
    /// column: each free dof's column gathers the rows of the patches around its node, and the
    /// patch entries summing into each value are listed in patch order.
    pub fn new(geometry: &ElementGeometry, num_dofs: usize, constrained: &[bool]) -> Result<Self, FemError> {
        let mut free_index = vec![NONE; num_dofs];
        let mut num_free = 0usize;
        for (dof, slot) in free_index.iter_mut().enumerate() {
            if !constrained[dof] {
                *slot = num_free as u32;
                num_free += 1;
            }
        }
        if num_free == 0 {
            return Err(FemError::Invalid("every degree of freedom is constrained: nothing to solve".into()));
        }
        let patches = &geometry.patches;
        let np = patches.len();
        let mut matrix_ptr = Vec::with_capacity(np + 1);
        matrix_ptr.push(0usize);
        for p in 0..np {
            let nd = 3 * patches.nodes(p).len();
            matrix_ptr.push(matrix_ptr[p] + nd * nd);
        }
        let entries = matrix_ptr[np];
        if entries > NONE as usize {
            return Err(FemError::Invalid(format!("the element tangents hold {entries} entries, more than 2³² − 1")));
        }
        // The patches around each node, in patch order, with the node's place in each.
        let num_nodes = num_dofs / 3;
        let mut around_ptr = vec![0usize; num_nodes + 1];
        for p in 0..np {
            for &n in patches.nodes(p) {
                around_ptr[n + 1] += 1;
            }
        }
        for n in 0..num_nodes {
            around_ptr[n + 1] += around_ptr[n];
        }
        let mut fill = around_ptr.clone();
        let mut around = vec![(0u32, 0u16); around_ptr[num_nodes]];
        for p in 0..np {
            for (a, &n) in patches.nodes(p).iter().enumerate() {
                around[fill[n]] = (p as u32, a as u16);
                fill[n] += 1;
            }
        }
        let (mut col_ptr, mut row_idx) = (Vec::with_capacity(num_free + 1), Vec::new());
        let (mut gather_ptr, mut gather) = (vec![0u32], Vec::new());
        col_ptr.push(0u32);
        let mut entries_of_column = Vec::new();
        for (dof, &c) in free_index.iter().enumerate().filter(|(_, &c)| c != NONE) {
            let (node, i) = (dof / 3, dof % 3);
            // The (row, patch entry) pairs of rows r ≥ c in the patches around the node, sorted
            // stably by row: each value's patch entries in patch order.
            entries_of_column.clear();
            for &(p, a) in &around[around_ptr[node]..around_ptr[node + 1]] {
                let (nodes, start) = (patches.nodes(p as usize), matrix_ptr[p as usize]);
                let (nd, cl) = (3 * nodes.len(), 3 * a as usize + i);
                for (rl, row_dof) in nodes.iter().flat_map(|&m| 3 * m..3 * m + 3).enumerate() {
                    let r = free_index[row_dof];
                    if r != NONE && r >= c {
                        entries_of_column.push((r, (start + rl * nd + cl) as u32));
                    }
                }
            }
            entries_of_column.sort_by_key(|&(r, _)| r);
            // A node in no patch still has its (empty) diagonal.
            if entries_of_column.is_empty() {
                row_idx.push(c);
                gather_ptr.push(gather.len() as u32);
            }
            for run in entries_of_column.chunk_by(|x, y| x.0 == y.0) {
                row_idx.push(run[0].0);
                gather.extend(run.iter().map(|&(_, entry)| entry));
                gather_ptr.push(gather.len() as u32);
            }
            col_ptr.push(row_idx.len() as u32);
        }
        Ok(Pattern { free_index, num_free, col_ptr, row_idx, matrix_ptr, gather_ptr, gather })
    }

    /// Renumbers the free dofs: free dof `forward[new]` becomes `new` (`inverse` is the inverse
    /// permutation). Numbered in a factorisation's fill-reducing order, the values are
    /// assembled in the order the factorisation reads them, so that it need not permute them.
    pub fn renumber(&mut self, forward: &[u32], inverse: &[u32]) -> Result<(), FemError> {
        let n = self.num_free;
        let is_inverse = |(new, &old): (usize, &u32)| inverse.get(old as usize) == Some(&(new as u32));
        if forward.len() != n || inverse.len() != n || !forward.iter().enumerate().all(is_inverse) {
            return Err(FemError::Invalid(format!("a renumbering of the {n} free dofs must be a permutation")));
        }
        for i in self.free_index.iter_mut().filter(|i| **i != NONE) {
            *i = inverse[*i as usize];
        }
        // Each stored entry (r, c) moves to (inverse[r], inverse[c]), taken into the lower
        // triangle; it keeps the patch entries that sum into it. Entries (new row, old position)
        // are bucketed by new column, then sorted within each column.
        let moved = |v: usize, c: usize| {
            let (r, c) = (inverse[self.row_idx[v] as usize], inverse[c]);
            (r.max(c), r.min(c))
        };
        let mut col_ptr = vec![0u32; n + 1];
        for c in 0..n {
            for v in self.col_ptr[c] as usize..self.col_ptr[c + 1] as usize {
                col_ptr[moved(v, c).1 as usize + 1] += 1;
            }
        }
        for c in 0..n {
            col_ptr[c + 1] += col_ptr[c];
        }
        let mut fill = col_ptr.clone();
        let mut entries = vec![(0u32, 0u32); self.nnz()];
        for c in 0..n {
            for v in self.col_ptr[c] as usize..self.col_ptr[c + 1] as usize {
                let (r, new_c) = moved(v, c);
                entries[fill[new_c as usize] as usize] = (r, v as u32);
                fill[new_c as usize] += 1;
            }
        }
        let (mut gather_ptr, mut gather) = (Vec::with_capacity(self.nnz() + 1), Vec::with_capacity(self.gather.len()));
        gather_ptr.push(0u32);
        for c in 0..n {
            entries[col_ptr[c] as usize..col_ptr[c + 1] as usize].sort_unstable();
        }
        for &(_, v) in &entries {
            let v = v as usize;
            gather.extend_from_slice(&self.gather[self.gather_ptr[v] as usize..self.gather_ptr[v + 1] as usize]);
            gather_ptr.push(gather.len() as u32);
        }
        let row_idx: Vec<u32> = entries.iter().map(|&(r, _)| r).collect();
        (self.col_ptr, self.row_idx, self.gather_ptr, self.gather) = (col_ptr, row_idx, gather_ptr, gather);
        Ok(())
    }

    /// The value position of entry (row, col) with row ≥ col, if it is stored.
    pub fn find(&self, row: usize, col: usize) -> Option<usize> {
        let (lo, hi) = (self.col_ptr[col] as usize, self.col_ptr[col + 1] as usize);
        self.row_idx[lo..hi].binary_search(&(row as u32)).ok().map(|i| lo + i)
    }

    /// The value position of free dof `i`'s diagonal entry: the first of its column, whose rows
    /// are sorted and start at the diagonal.
    pub fn diag(&self, i: usize) -> usize {
        self.col_ptr[i] as usize
    }

    /// Number of stored (lower-triangle) entries.
    pub fn nnz(&self) -> usize {
        self.row_idx.len()
    }
}

/// Reusable buffers for patch results.
#[derive(Debug, Default)]
pub struct Workspace {
    forces: Vec<f64>,
    stiffness: Vec<f64>,
}

impl Workspace {
    /// Buffers sized for the geometry's patches and written once, so that the first assembly
    /// does not pay for the operating system's first touch of their pages.
    pub fn for_pattern(geometry: &ElementGeometry, pattern: &Pattern) -> Self {
        let mut work = Workspace::default();
        work.fit(geometry, pattern, true);
        work
    }

    /// Sizes the patch forces and, with `tangent`, the patch stiffnesses for the geometry (a
    /// force evaluation leaves the stiffness buffer as it is).
    fn fit(&mut self, geometry: &ElementGeometry, pattern: &Pattern, tangent: bool) {
        let np = geometry.patches.len();
        self.forces.resize(3 * geometry.patches.node_offset(np), 0.0);
        if tangent {
            self.stiffness.resize(pattern.matrix_ptr[np], 0.0);
        }
    }
}

/// Patches evaluated per parallel task.
const CHUNK: usize = 64;

/// Tangent values summed per parallel task.
const VALUE_CHUNK: usize = 4096;

/// Internal force over all dofs (`f_int`, length 3n) and, when `values` is
/// given, the free-dof tangent values in the pattern's order. Patches are
/// evaluated in parallel; their contributions are summed in patch order,
/// so the result does not depend on the number of threads.
pub fn assemble(
    geometry: &ElementGeometry,
    pattern: &Pattern,
    material: &Material,
    u: &[f64],
    f_int: &mut [f64],
    values: Option<&mut [f64]>,
    work: &mut Workspace,
) -> Result<(), FemError> {
    let patches = &geometry.patches;
    let np = patches.len();
    let want_k = values.is_some();
    work.fit(geometry, pattern, want_k);
    // Split the buffers into one (forces, stiffness) pair of slices per chunk of patches.
    let mut tasks = Vec::with_capacity(np.div_ceil(CHUNK));
    let (mut forces, mut stiffness) = (work.forces.as_mut_slice(), work.stiffness.as_mut_slice());
    for first in (0..np).step_by(CHUNK) {
        let last = (first + CHUNK).min(np);
        let (fc, rest) = forces.split_at_mut(3 * (patches.node_offset(last) - patches.node_offset(first)));
        forces = rest;
        let kc = if want_k {
            let (kc, rest) = stiffness.split_at_mut(pattern.matrix_ptr[last] - pattern.matrix_ptr[first]);
            stiffness = rest;
            Some(kc)
        } else {
            None
        };
        tasks.push((first, last, fc, kc));
    }
    // Scratch space per rayon job (reused by the chunks a job takes), not per chunk.
    let scratch = || (ForceScratch::default(), fbar::PatchScratch::default());
    tasks.into_par_iter().try_for_each_init(scratch, |(element_scratch, patch_scratch), (first, last, fc, kc)| {
        // Forces alone: all of the chunk's stresses at once (a standard element is the patch of
        // the same index).
        let Some(kc) = kc else {
            return match geometry.formulation {
                Formulation::Fbar => fbar::patch_forces(geometry, first..last, material, u, fc, patch_scratch),
                _ => geometry.forces(first..last, material, u, fc, element_scratch),
            };
        };
        let (mut fo, mut ko) = (0, 0);
        for p in first..last {
            let nd = 3 * patches.nodes(p).len();
            let fe = &mut fc[fo..fo + nd];
            let ke = &mut kc[ko..ko + nd * nd];
            match geometry.formulation {
                Formulation::Fbar => fbar::patch_force_tangent(geometry, p, material, u, fe, ke, patch_scratch)?,
                _ => geometry.force_tangent(patches.elements(p)[0], material, u, fe, Some(ke))?,
            }
            fo += nd;
            ko += nd * nd;
        }
        Ok::<(), FemError>(())
    })?;
    f_int.fill(0.0);
    for p in 0..np {
        let offset = 3 * patches.node_offset(p);
        for (a, &n) in patches.nodes(p).iter().enumerate() {
            for i in 0..3 {
                f_int[3 * n + i] += work.forces[offset + 3 * a + i];
            }
        }
    }
    if let Some(values) = values {
        // Each value sums its entries in patch order, whatever the number of threads.
        let stiffness = &work.stiffness;
        values.par_chunks_mut(VALUE_CHUNK).enumerate().for_each(|(chunk, out)| {
            for (i, v) in out.iter_mut().enumerate() {
                let at = chunk * VALUE_CHUNK + i;
                let range = pattern.gather_ptr[at] as usize..pattern.gather_ptr[at + 1] as usize;
                *v = pattern.gather[range].iter().fold(0.0, |sum, &e| sum + stiffness[e as usize]);
            }
        });
    }
    Ok(())
}
