//! Parallel assembly of the internal force and the tangent stiffness into a
//! sparse pattern built once per mesh and constraint set.
//!
//! The matrix holds the free degrees of freedom only (Dirichlet dofs are
//! eliminated) and stores the lower triangle in compressed sparse columns,
//! as the sparse Cholesky factorisation expects.

use rayon::prelude::*;

use crate::element::ElementGeometry;
use crate::material::Material;
use crate::FemError;

/// Marks a dof that is constrained, or a matrix entry that is not stored.
const NONE: u32 = u32::MAX;

/// Sparse pattern of the free-dof tangent and the element → value scatter map.
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
    /// Position of each free dof's diagonal entry in the value array.
    pub diag: Vec<u32>,
    /// For element e and local pair (p, q), the value position, or `u32::MAX`:
    /// index `e * ndof² + p * ndof + q`.
    scatter: Vec<u32>,
    /// Local dofs per element.
    ndof: usize,
}

impl Pattern {
    /// Builds the pattern for the given elements and constrained global dofs.
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
        let npe = geometry.nodes_per_element;
        let ndof = 3 * npe;
        let local_free = |e: usize| -> Vec<u32> {
            geometry
                .element_nodes(e)
                .iter()
                .flat_map(|&n| (0..3).map(move |i| 3 * n + i))
                .map(|d| free_index[d])
                .collect()
        };
        // Column lists of the lower triangle.
        let mut cols: Vec<Vec<u32>> = vec![Vec::new(); num_free];
        for (c, col) in cols.iter_mut().enumerate() {
            col.push(c as u32);
        }
        for e in 0..geometry.len() {
            let dofs = local_free(e);
            for &r in &dofs {
                for &c in &dofs {
                    if r != NONE && c != NONE && r > c {
                        cols[c as usize].push(r);
                    }
                }
            }
        }
        let mut col_ptr = Vec::with_capacity(num_free + 1);
        let mut row_idx = Vec::new();
        col_ptr.push(0u32);
        for col in &mut cols {
            col.sort_unstable();
            col.dedup();
            row_idx.extend_from_slice(col);
            col_ptr.push(row_idx.len() as u32);
        }
        let position = |r: u32, c: u32| -> u32 {
            let (lo, hi) = (col_ptr[c as usize] as usize, col_ptr[c as usize + 1] as usize);
            lo as u32 + row_idx[lo..hi].binary_search(&r).expect("entry in pattern") as u32
        };
        let diag = (0..num_free as u32).map(|c| position(c, c)).collect();
        let mut scatter = vec![NONE; geometry.len() * ndof * ndof];
        for e in 0..geometry.len() {
            let dofs = local_free(e);
            for p in 0..ndof {
                for q in 0..ndof {
                    let (r, c) = (dofs[p], dofs[q]);
                    if r != NONE && c != NONE && r >= c {
                        scatter[(e * ndof + p) * ndof + q] = position(r, c);
                    }
                }
            }
        }
        Ok(Pattern { free_index, num_free, col_ptr, row_idx, diag, scatter, ndof })
    }

    /// Number of stored (lower-triangle) entries.
    pub fn nnz(&self) -> usize {
        self.row_idx.len()
    }
}

/// Reusable buffers for element results.
#[derive(Debug, Default)]
pub struct Workspace {
    forces: Vec<f64>,
    stiffness: Vec<f64>,
}

/// Internal force over all dofs (`f_int`, length 3n) and, when `values` is
/// given, the free-dof tangent values in the pattern's order. Elements are
/// evaluated in parallel; their contributions are summed in element order,
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
    let ne = geometry.len();
    let ndof = pattern.ndof;
    let want_k = values.is_some();
    work.forces.resize(ne * ndof, 0.0);
    work.stiffness.resize(if want_k { ne * ndof * ndof } else { 0 }, 0.0);
    let chunk = 64;
    let run = |c: usize, fc: &mut [f64], mut kc: Option<&mut [f64]>| {
        for (i, fe) in fc.chunks_mut(ndof).enumerate() {
            let ke = kc.as_deref_mut().map(|k| &mut k[i * ndof * ndof..(i + 1) * ndof * ndof]);
            geometry.force_tangent(c * chunk + i, material, u, fe, ke)?;
        }
        Ok::<(), FemError>(())
    };
    if want_k {
        work.forces
            .par_chunks_mut(chunk * ndof)
            .zip(work.stiffness.par_chunks_mut(chunk * ndof * ndof))
            .enumerate()
            .try_for_each(|(c, (fc, kc))| run(c, fc, Some(kc)))?;
    } else {
        work.forces.par_chunks_mut(chunk * ndof).enumerate().try_for_each(|(c, fc)| run(c, fc, None))?;
    }
    f_int.fill(0.0);
    for e in 0..ne {
        for (a, &n) in geometry.element_nodes(e).iter().enumerate() {
            for i in 0..3 {
                f_int[3 * n + i] += work.forces[e * ndof + 3 * a + i];
            }
        }
    }
    if let Some(values) = values {
        values.fill(0.0);
        for (s, k) in pattern.scatter.iter().zip(&work.stiffness) {
            if *s != NONE {
                values[*s as usize] += k;
            }
        }
    }
    Ok(())
}
