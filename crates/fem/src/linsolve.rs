//! Sparse symmetric positive-definite solves with faer: the symbolic
//! factorisation (AMD ordering, supernodal) is computed once per pattern and
//! reused by every numeric factorisation.

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::ldlt::factor::LdltRegularization;
use faer::linalg::cholesky::llt::factor::LltRegularization;
use faer::sparse::linalg::cholesky::{
    factorize_symbolic_cholesky, CholeskySymbolicParams, LdltRef, LltRef, SymbolicCholesky, SymmetricOrdering,
};
use faer::sparse::{SparseColMatRef, SymbolicSparseColMatRef};
use faer::{Conj, MatMut, Par, Side};

use crate::assembly::Pattern;
use crate::FemError;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Factor {
    None,
    Llt,
    Ldlt,
}

/// A sparse Cholesky factorisation bound to one pattern.
pub struct SparseCholesky {
    symbolic: SymbolicCholesky<u32>,
    col_ptr: Vec<u32>,
    row_idx: Vec<u32>,
    l_values: Vec<f64>,
    mem: MemBuffer,
    factor: Factor,
}

impl std::fmt::Debug for SparseCholesky {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SparseCholesky").field("n", &self.symbolic.nrows()).field("factor", &self.factor).finish()
    }
}

fn par() -> Par {
    Par::rayon(0)
}

impl SparseCholesky {
    /// Symbolic analysis of the pattern (lower triangle, CSC).
    pub fn new(pattern: &Pattern) -> Result<Self, FemError> {
        let n = pattern.num_free;
        let sym = SymbolicSparseColMatRef::new_checked(n, n, &pattern.col_ptr, None, &pattern.row_idx);
        let symbolic =
            factorize_symbolic_cholesky(sym, Side::Lower, SymmetricOrdering::Amd, CholeskySymbolicParams::default())
                .map_err(|e| FemError::Factorization(format!("symbolic analysis failed: {e:?}")))?;
        let req = symbolic
            .factorize_numeric_llt_scratch::<f64>(par(), Default::default())
            .or(symbolic.factorize_numeric_ldlt_scratch::<f64>(par(), Default::default()))
            .or(symbolic.solve_in_place_scratch::<f64>(1, par()));
        let mem = MemBuffer::try_new(req)
            .map_err(|_| FemError::Factorization("out of memory for the factorisation workspace".into()))?;
        let l_values = vec![0.0; symbolic.len_val()];
        Ok(SparseCholesky {
            symbolic,
            col_ptr: pattern.col_ptr.clone(),
            row_idx: pattern.row_idx.clone(),
            l_values,
            mem,
            factor: Factor::None,
        })
    }

    /// Whether the last factorisation was LLᵀ (the matrix was positive definite);
    /// false after the LDLᵀ fallback or before any factorisation.
    pub fn is_positive_definite(&self) -> bool {
        self.factor == Factor::Llt
    }

    /// Multiply-adds of one numeric factorisation, Σ_j c_j² over the column
    /// counts c_j of the factor (from the symbolic structure).
    pub fn factorization_work(&self) -> f64 {
        use faer::sparse::linalg::cholesky::SymbolicCholeskyRaw;
        match self.symbolic.raw() {
            SymbolicCholeskyRaw::Supernodal(sn) => {
                let (begin, end, rows) = (sn.supernode_begin(), sn.supernode_end(), sn.col_ptr_for_row_idx());
                (0..sn.n_supernodes())
                    .map(|s| {
                        let width = end[s] as usize - begin[s] as usize;
                        let below = (rows[s + 1] - rows[s]) as usize;
                        (0..width).map(|j| ((width - j + below) as f64).powi(2)).sum::<f64>()
                    })
                    .sum()
            }
            // Simplicial factors are used for tiny systems: nnz(L) × mean column count.
            SymbolicCholeskyRaw::Simplicial(_) => {
                let n = self.symbolic.nrows().max(1) as f64;
                let nnz = self.l_values.len() as f64;
                nnz * nnz / n
            }
        }
    }

    /// Number of non-zeros in the factor.
    pub fn factor_nnz(&self) -> usize {
        self.l_values.len()
    }

    /// Numeric factorisation of the matrix with the given values (pattern order).
    /// Tries LLᵀ; if the matrix is not positive definite (e.g. a buckling
    /// tangent) falls back to LDLᵀ with the same symbolic structure.
    pub fn factorize(&mut self, values: &[f64]) -> Result<(), FemError> {
        let n = self.symbolic.nrows();
        let sym = SymbolicSparseColMatRef::new_checked(n, n, &self.col_ptr, None, &self.row_idx);
        let a = SparseColMatRef::new(sym, values);
        let stack = MemStack::new(&mut self.mem);
        self.factor = Factor::None;
        let llt = self.symbolic.factorize_numeric_llt(
            &mut self.l_values,
            a,
            Side::Lower,
            LltRegularization::default(),
            par(),
            stack,
            Default::default(),
        );
        if llt.is_ok() {
            self.factor = Factor::Llt;
            return Ok(());
        }
        let stack = MemStack::new(&mut self.mem);
        self.symbolic
            .factorize_numeric_ldlt(
                &mut self.l_values,
                a,
                Side::Lower,
                LdltRegularization::default(),
                par(),
                stack,
                Default::default(),
            )
            .map_err(|e| FemError::Factorization(format!("tangent stiffness is singular: {e:?}")))?;
        self.factor = Factor::Ldlt;
        Ok(())
    }

    /// Solves A x = b in place with the last factorisation.
    pub fn solve_in_place(&mut self, rhs: &mut [f64]) -> Result<(), FemError> {
        let n = rhs.len();
        let stack = MemStack::new(&mut self.mem);
        let mat = MatMut::from_column_major_slice_mut(rhs, n, 1);
        match self.factor {
            Factor::Llt => {
                LltRef::new(&self.symbolic, &self.l_values).solve_in_place_with_conj(Conj::No, mat, par(), stack)
            }
            Factor::Ldlt => {
                LdltRef::new(&self.symbolic, &self.l_values).solve_in_place_with_conj(Conj::No, mat, par(), stack)
            }
            Factor::None => return Err(FemError::Factorization("solve before a successful factorisation".into())),
        }
        if rhs.iter().any(|v| !v.is_finite()) {
            return Err(FemError::NonFinite("solution of the linear system".into()));
        }
        Ok(())
    }
}
