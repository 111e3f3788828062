//! Sparse symmetric positive-definite solves with faer: the symbolic
//! factorisation (AMD ordering, supernodal) is computed once per pattern and
//! reused by every numeric factorisation. Two numeric factors can be held at
//! once ([`Slot`]), sharing the symbolic analysis and the workspace.
//!
//! The factors are computed and applied in single precision: the Newton solver
//! uses them only as the initial inverse Hessian of its quasi-Newton iterations
//! (every residual is evaluated in double precision), where a factor accurate to
//! about cond(K) · 6e-8 serves as well as an exact one, at half the memory traffic
//! and twice the SIMD width.

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

/// Which of the two numeric factors a call addresses.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Slot {
    /// The latest tangent's.
    Latest,
    /// The tangent at rest.
    Rest,
}

impl Slot {
    fn index(self) -> usize {
        self as usize
    }
}

/// Sparse Cholesky factorisations bound to one pattern.
pub struct SparseCholesky {
    symbolic: SymbolicCholesky<u32>,
    col_ptr: Vec<u32>,
    row_idx: Vec<u32>,
    /// Factor values per slot (allocated at the slot's first factorisation).
    l_values: [Vec<f32>; 2],
    /// Matrix values or right-hand side in single precision.
    scratch: Vec<f32>,
    mem: MemBuffer,
    factor: [Factor; 2],
    /// Multiply-adds of one numeric factorisation.
    work: f64,
    /// Sequential or parallel, from `work`.
    par: Par,
}

impl std::fmt::Debug for SparseCholesky {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SparseCholesky").field("n", &self.symbolic.nrows()).field("factor", &self.factor).finish()
    }
}

/// Factorisations with fewer multiply-adds than this run on one thread: below
/// it, faer's parallel supernodal factorisation spends more on scheduling small
/// supernodes than it gains (measured: 3.5k dofs, 0.2 G multiply-adds, 2.5×
/// faster sequential on 2 cores; 29k dofs faster in parallel).
const PARALLEL_WORK: f64 = 2e9;

impl SparseCholesky {
    /// Symbolic analysis of the pattern (lower triangle, CSC).
    pub fn new(pattern: &Pattern) -> Result<Self, FemError> {
        let n = pattern.num_free;
        let sym = SymbolicSparseColMatRef::new_checked(n, n, &pattern.col_ptr, None, &pattern.row_idx);
        let symbolic =
            factorize_symbolic_cholesky(sym, Side::Lower, SymmetricOrdering::Amd, CholeskySymbolicParams::default())
                .map_err(|e| FemError::Factorization(format!("symbolic analysis failed: {e:?}")))?;
        let work = factorization_work(&symbolic);
        let par = if work < PARALLEL_WORK { Par::Seq } else { Par::rayon(0) };
        let req = symbolic
            .factorize_numeric_llt_scratch::<f32>(par, Default::default())
            .or(symbolic.factorize_numeric_ldlt_scratch::<f32>(par, Default::default()))
            .or(symbolic.solve_in_place_scratch::<f32>(1, par));
        let mem = MemBuffer::try_new(req)
            .map_err(|_| FemError::Factorization("out of memory for the factorisation workspace".into()))?;
        Ok(SparseCholesky {
            symbolic,
            col_ptr: pattern.col_ptr.clone(),
            row_idx: pattern.row_idx.clone(),
            l_values: [Vec::new(), Vec::new()],
            scratch: Vec::new(),
            mem,
            factor: [Factor::None; 2],
            work,
            par,
        })
    }

    /// Whether the slot's factorisation is LLᵀ (the matrix was positive definite);
    /// false after the LDLᵀ fallback or before any factorisation.
    pub fn is_positive_definite(&self, slot: Slot) -> bool {
        self.factor[slot.index()] == Factor::Llt
    }

    /// Whether the slot holds a factorisation.
    pub fn is_factorized(&self, slot: Slot) -> bool {
        self.factor[slot.index()] != Factor::None
    }

    /// Multiply-adds of one numeric factorisation, Σ_j c_j² over the column
    /// counts c_j of the factor (from the symbolic structure).
    pub fn factorization_work(&self) -> f64 {
        self.work
    }

    /// Number of non-zeros in the factor.
    pub fn factor_nnz(&self) -> usize {
        self.symbolic.len_val()
    }

    /// Numeric factorisation of the matrix with the given values (pattern order).
    /// Tries LLᵀ; if the matrix is not positive definite (e.g. a buckling
    /// tangent) falls back to LDLᵀ with the same symbolic structure.
    pub fn factorize(&mut self, slot: Slot, values: &[f64]) -> Result<(), FemError> {
        let n = self.symbolic.nrows();
        let sym = SymbolicSparseColMatRef::new_checked(n, n, &self.col_ptr, None, &self.row_idx);
        self.scratch.clear();
        self.scratch.extend(values.iter().map(|&v| v as f32));
        let a = SparseColMatRef::new(sym, self.scratch.as_slice());
        let stack = MemStack::new(&mut self.mem);
        let (l_values, factor) = (&mut self.l_values[slot.index()], &mut self.factor[slot.index()]);
        l_values.resize(self.symbolic.len_val(), 0.0);
        *factor = Factor::None;
        let llt = self.symbolic.factorize_numeric_llt(
            l_values,
            a,
            Side::Lower,
            LltRegularization::default(),
            self.par,
            stack,
            Default::default(),
        );
        if llt.is_ok() {
            *factor = Factor::Llt;
            return Ok(());
        }
        let stack = MemStack::new(&mut self.mem);
        self.symbolic
            .factorize_numeric_ldlt(
                l_values,
                a,
                Side::Lower,
                LdltRegularization::default(),
                self.par,
                stack,
                Default::default(),
            )
            .map_err(|e| FemError::Factorization(format!("tangent stiffness is singular: {e:?}")))?;
        *factor = Factor::Ldlt;
        Ok(())
    }

    /// Solves A x = b in place with the slot's factorisation.
    pub fn solve_in_place(&mut self, slot: Slot, rhs: &mut [f64]) -> Result<(), FemError> {
        let n = rhs.len();
        self.scratch.clear();
        self.scratch.extend(rhs.iter().map(|&v| v as f32));
        let stack = MemStack::new(&mut self.mem);
        let mat = MatMut::from_column_major_slice_mut(self.scratch.as_mut_slice(), n, 1);
        let l_values = &self.l_values[slot.index()];
        match self.factor[slot.index()] {
            Factor::Llt => {
                LltRef::new(&self.symbolic, l_values).solve_in_place_with_conj(Conj::No, mat, self.par, stack)
            }
            Factor::Ldlt => {
                LdltRef::new(&self.symbolic, l_values).solve_in_place_with_conj(Conj::No, mat, self.par, stack)
            }
            Factor::None => return Err(FemError::Factorization("solve before a successful factorisation".into())),
        }
        rhs.iter_mut().zip(&self.scratch).for_each(|(r, &x)| *r = f64::from(x));
        if rhs.iter().any(|v| !v.is_finite()) {
            return Err(FemError::NonFinite("solution of the linear system".into()));
        }
        Ok(())
    }
}

/// Σ_j c_j² over the column counts c_j of the factor.
fn factorization_work(symbolic: &SymbolicCholesky<u32>) -> f64 {
    use faer::sparse::linalg::cholesky::SymbolicCholeskyRaw;
    match symbolic.raw() {
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
            let n = symbolic.nrows().max(1) as f64;
            let nnz = symbolic.len_val() as f64;
            nnz * nnz / n
        }
    }
}
