//! Sparse symmetric positive-definite solves with faer: the symbolic
//! factorisation (supernodal) is computed once per pattern and reused by every
//! numeric factorisation. Two numeric factors can be held at once ([`Slot`]),
//! sharing the symbolic analysis and the workspace.
//!
//! The fill-reducing ordering is faer's approximate minimum degree (AMD) or, for
//! large systems, METIS's nested dissection of the node graph when that needs
//! less factorisation work ([`Ordering`]). The pattern's free dofs are renumbered in
//! that order, so that the factorisation reads the values as they are assembled.
//!
//! The factors are computed and applied in single precision: the Newton solver
//! uses them only as the initial inverse Hessian of its quasi-Newton iterations
//! (every residual is evaluated in double precision), where a factor accurate to
//! about cond(K) · 6e-8 serves as well as an exact one, at half the memory traffic
//! and twice the SIMD width. A positive-definite matrix too ill-conditioned for that
//! (single-precision LLᵀ meets a non-positive pivot, e.g. a slender beam at ν = 0.499)
//! is factorised in double precision instead, as is every matrix of a solve whose
//! iterations on a single-precision factor did not converge
//! ([`SparseCholesky::set_double_precision`]).

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::ldlt::factor::LdltRegularization;
use faer::linalg::cholesky::llt::factor::LltRegularization;
use faer::perm::PermRef;
use faer::sparse::linalg::amd;
use faer::sparse::linalg::cholesky::{
    factorize_symbolic_cholesky, CholeskySymbolicParams, LdltRef, LltRef, SymbolicCholesky, SymmetricOrdering,
};
use faer::sparse::{SparseColMatRef, SymbolicSparseColMatRef};
use faer::{Conj, MatMut, Par, Side};

use crate::assembly::Pattern;
use crate::{written_zeros, FemError};

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Factor {
    None,
    Llt,
    Ldlt,
    /// LLᵀ in double precision.
    Llt64,
    /// LLᵀ in double precision of the matrix with its diagonal raised ([`DIAGONAL_SHIFTS`]): the
    /// matrix was not positive definite.
    Shifted64,
}

/// Relative raises of the diagonal, tried in turn, that make an indefinite tangent positive
/// definite (A + τ diag(A), a modified Newton method): its factor then gives a direction along
/// which the energy decreases, which the line search can follow, where an LDLᵀ factor of the
/// indefinite tangent gives a direction that may climb. On a real liver hanging from a strip of
/// its back and pushed by 2.5 N, the tangent went indefinite half-way; the steps of unpivoted
/// LDLᵀ there were 26 m long, and every load step failed ("element inverted"), while CalculiX
/// solved the same problem (173 mm).
pub const DIAGONAL_SHIFTS: [f64; 7] = [1e-6, 1e-5, 1e-4, 1e-3, 1e-2, 1e-1, 1.0];

/// The index of the shift tried first on a solve's first indefinite matrix (1e-3, the middle of
/// [`DIAGONAL_SHIFTS`]).
const FIRST_SHIFT: usize = 3;

/// Which of the two numeric factors a call addresses.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Slot {
    /// The latest tangent's.
    Latest,
    /// The tangent at rest.
    Rest,
}

/// The fill-reducing ordering of a [`SparseCholesky`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Ordering {
    /// Approximate minimum degree (faer).
    Amd,
    /// Nested dissection of the node graph (METIS), 3 dofs per node.
    NestedDissection,
    /// AMD, or nested dissection where AMD's factorisation would cost more than
    /// [`ND_WORK`] multiply-adds and nested dissection costs less.
    Auto,
}

impl Ordering {
    /// The ordering's name, as printed.
    pub fn name(self) -> &'static str {
        match self {
            Ordering::Amd => "AMD",
            Ordering::NestedDissection => "nested-dissection",
            Ordering::Auto => "automatic",
        }
    }
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
    /// Position of each column's diagonal entry among the values.
    diagonal: Vec<usize>,
    /// Factor values per slot.
    l_values: [Vec<f32>; 2],
    /// Double-precision factor values per slot, allocated at their first use.
    l_values64: [Vec<f64>; 2],
    /// The values a diagonal shift's attempt factorises into (see [`SparseCholesky::factorize`]).
    spare64: Vec<f64>,
    /// Workspace of the double-precision factorisation and solves, allocated with them.
    mem64: Option<MemBuffer>,
    /// Factorise in double precision from the start ([`SparseCholesky::set_double_precision`]).
    double: bool,
    /// The index in [`DIAGONAL_SHIFTS`] where the search for an indefinite matrix's shift starts:
    /// one below the last shift needed.
    next_shift: usize,
    /// Matrix values or right-hand side in single precision.
    scratch: Vec<f32>,
    mem: MemBuffer,
    factor: [Factor; 2],
    /// Multiply-adds of one numeric factorisation.
    work: f64,
    /// Sequential or parallel, from `work`.
    par: Par,
    /// The ordering used.
    ordering: Ordering,
}

impl std::fmt::Debug for SparseCholesky {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SparseCholesky").field("n", &self.symbolic.nrows()).field("factor", &self.factor).finish()
    }
}

/// The single-precision factorisation's and solve's workspace with `par`, every page written once
/// (so that the first factorisations do not pay for the operating system's first touch).
fn workspace(symbolic: &SymbolicCholesky<u32>, par: Par) -> Result<MemBuffer, FemError> {
    let req = symbolic
        .factorize_numeric_llt_scratch::<f32>(par, Default::default())
        .or(symbolic.factorize_numeric_ldlt_scratch::<f32>(par, Default::default()))
        .or(symbolic.solve_in_place_scratch::<f32>(1, par));
    let mut mem = MemBuffer::try_new(req)
        .map_err(|_| FemError::Factorization("out of memory for the factorisation workspace".into()))?;
    mem.fill(std::mem::MaybeUninit::new(0));
    Ok(mem)
}

/// Factorisations with fewer multiply-adds than this run on one thread: below
/// it, faer's parallel supernodal factorisation spends more on scheduling small
/// supernodes than it gains (measured: 3.5k dofs, 0.2 G multiply-adds, 2.5×
/// faster sequential on 2 cores; 29k dofs faster in parallel).
const PARALLEL_WORK: f64 = 2e9;

/// Above this many multiply-adds of an AMD factorisation, [`Ordering::Auto`] tries nested
/// dissection. On the 50k-tet liver phantom (29k dofs, F-bar) it cuts the work by 38 % and the
/// factor by 23 %; on the 5k-tet one (3.4k dofs) it saves 4–17 % of the work but its factor
/// was no faster, so small systems keep AMD.
pub const ND_WORK: f64 = PARALLEL_WORK;

/// From this many free dofs, [`Ordering::Auto`] computes AMD and nested dissection at once, on two
/// threads, instead of nested dissection only once AMD's analysis has found more than
/// [`ND_WORK`] multiply-adds (the 5k-tet liver has 3.4k free dofs and 1–2·10⁸, the 50k-tet one
/// 28k and 2.6–3.3·10¹⁰). The choice is the same either way.
pub const BOTH_ORDERINGS_DOFS: usize = 10_000;

/// Whether nested dissection replaces AMD: AMD's factorisation costs more than [`ND_WORK`]
/// multiply-adds and nested dissection's less.
fn prefer_nested(amd_work: f64, nd_work: f64) -> bool {
    amd_work > ND_WORK && nd_work < amd_work
}

impl SparseCholesky {
    /// [`SparseCholesky::with_ordering`] with [`Ordering::Auto`].
    pub fn new(pattern: &mut Pattern) -> Result<Self, FemError> {
        SparseCholesky::with_ordering(pattern, Ordering::Auto)
    }

    /// Computes the fill-reducing ordering of the pattern (lower triangle, CSC), renumbers the
    /// pattern's free dofs in that order ([`Pattern::renumber`]) and analyses it. Every
    /// factorisation then reads the values as assembled, where faer would otherwise permute
    /// them each time (measured on the 5k-tet liver, F-bar: 0.5–0.7 ms of a 6.8 ms factorisation).
    /// Where nested dissection cannot be computed, AMD is used.
    pub fn with_ordering(pattern: &mut Pattern, ordering: Ordering) -> Result<Self, FemError> {
        let amd =
            |pattern: &mut Pattern| Ok::<_, FemError>((renumbered(pattern, amd_permutation(pattern)?)?, Ordering::Amd));
        let nested =
            |pattern: &mut Pattern, perm| Ok::<_, FemError>((renumbered(pattern, perm)?, Ordering::NestedDissection));
        let (symbolic, chosen) = match ordering {
            Ordering::Amd => amd(pattern)?,
            Ordering::NestedDissection => match nested_dissection(pattern) {
                Some(perm) => nested(pattern, perm)?,
                None => amd(pattern)?,
            },
            Ordering::Auto if pattern.num_free < BOTH_ORDERINGS_DOFS => {
                let (symbolic, chosen) = amd(pattern)?;
                let amd_work = factorization_work(&symbolic);
                match (amd_work > ND_WORK).then(|| nested_dissection(pattern)).flatten() {
                    Some(perm) if prefer_nested(amd_work, work_in_order(pattern, &perm)?) => nested(pattern, perm)?,
                    _ => (symbolic, chosen),
                }
            }
            Ordering::Auto => {
                // Both orderings at once, each analysed in the pattern's present numbering.
                let (by_amd, by_nested) = rayon::join(
                    || amd_permutation(pattern).and_then(|perm| Ok((work_in_order(pattern, &perm)?, perm))),
                    || nested_dissection(pattern).map(|perm| Ok::<_, FemError>((work_in_order(pattern, &perm)?, perm))),
                );
                let (amd_work, amd_perm) = by_amd?;
                match by_nested.transpose()? {
                    Some((nd_work, perm)) if prefer_nested(amd_work, nd_work) => nested(pattern, perm)?,
                    _ => (renumbered(pattern, amd_perm)?, Ordering::Amd),
                }
            }
        };
        let work = factorization_work(&symbolic);
        let par = if work < PARALLEL_WORK { Par::Seq } else { Par::rayon(0) };
        let mem = workspace(&symbolic, par)?;
        // Every buffer is written once here, so that the first factorisations do not pay for the
        // operating system's first touch of their pages.
        let l_values = [written_zeros(symbolic.len_val()), written_zeros(symbolic.len_val())];
        let scratch = written_zeros(pattern.nnz().max(pattern.num_free));
        let diagonal = (0..pattern.num_free).map(|c| pattern.diag(c)).collect();
        Ok(SparseCholesky {
            diagonal,
            col_ptr: pattern.col_ptr.clone(),
            row_idx: pattern.row_idx.clone(),
            symbolic,
            l_values,
            l_values64: [Vec::new(), Vec::new()],
            spare64: Vec::new(),
            mem64: None,
            double: false,
            next_shift: FIRST_SHIFT,
            scratch,
            mem,
            factor: [Factor::None; 2],
            work,
            par,
            ordering: chosen,
        })
    }

    /// Factorises and solves on one thread, however large the work: the results then do not depend
    /// on the number of threads (faer's parallel factorisation splits its sums by it). For callers
    /// that run many solves side by side, as dataset generation does.
    pub fn set_single_threaded(&mut self) -> Result<(), FemError> {
        if self.par != Par::Seq {
            self.par = Par::Seq;
            self.mem = workspace(&self.symbolic, Par::Seq)?;
            self.mem64 = None;
        }
        Ok(())
    }

    /// The fill-reducing ordering in use ([`Ordering::Amd`] or [`Ordering::NestedDissection`]).
    pub fn ordering(&self) -> Ordering {
        self.ordering
    }

    /// Whether the slot's factorisation is LLᵀ (the matrix was positive definite);
    /// false after the LDLᵀ fallback or before any factorisation.
    pub fn is_positive_definite(&self, slot: Slot) -> bool {
        matches!(self.factor[slot.index()], Factor::Llt | Factor::Llt64)
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
    /// Tries LLᵀ, in single then in double precision; if the matrix is not positive
    /// definite (past a limit or bifurcation point, or far from equilibrium), LLᵀ of the matrix
    /// with its diagonal raised by the first of [`DIAGONAL_SHIFTS`] that makes it positive
    /// definite; failing all, LDLᵀ with the same symbolic structure.
    pub fn factorize(&mut self, slot: Slot, values: &[f64]) -> Result<(), FemError> {
        let i = slot.index();
        self.factor[i] = Factor::None;
        let n = self.symbolic.nrows();
        let sym = SymbolicSparseColMatRef::new_checked(n, n, &self.col_ptr, None, &self.row_idx);
        self.scratch.clear();
        self.scratch.extend(values.iter().map(|&v| v as f32));
        let single = SparseColMatRef::new(sym, self.scratch.as_slice());
        if !self.double && llt(&self.symbolic, &mut self.l_values[i], single, self.par, &mut self.mem) {
            self.factor[i] = Factor::Llt;
            return Ok(());
        }
        let mem64 = match &mut self.mem64 {
            Some(mem) => mem,
            None => {
                let req = self
                    .symbolic
                    .factorize_numeric_llt_scratch::<f64>(self.par, Default::default())
                    .or(self.symbolic.solve_in_place_scratch::<f64>(1, self.par));
                self.mem64.insert(
                    MemBuffer::try_new(req)
                        .map_err(|_| FemError::Factorization("out of memory for the factorisation workspace".into()))?,
                )
            }
        };
        self.l_values64[i].resize(self.symbolic.len_val(), 0.0);
        let double = SparseColMatRef::new(sym, values);
        if llt(&self.symbolic, &mut self.l_values64[i], double, self.par, mem64) {
            self.factor[i] = Factor::Llt64;
            return Ok(());
        }
        let mut shifted = values.to_vec();
        self.spare64.resize(self.symbolic.len_val(), 0.0);
        // An attempt factorises into the spare values, which become the slot's on success: the
        // slot holds the smallest shift's factor found so far, whatever attempt failed after it.
        let mut positive = |k: usize| {
            let tau = DIAGONAL_SHIFTS[k];
            for &p in &self.diagonal {
                shifted[p] = values[p] + tau * values[p].abs();
            }
            let matrix = SparseColMatRef::new(sym, shifted.as_slice());
            let ok = llt(&self.symbolic, &mut self.spare64, matrix, self.par, mem64);
            if ok {
                std::mem::swap(&mut self.spare64, &mut self.l_values64[i]);
            }
            ok
        };
        // The smallest shift that makes the matrix positive definite, searched from one below the
        // last shift needed: down while a smaller one succeeds, else up. A larger shift only adds
        // to a positive diagonal, so where the search starts changes its cost, never the shift it
        // finds. On 16 T10 draws of `liver_ar_t10` (52 indefinite tangents, where a failed attempt
        // costs about a third of a successful one), the search from the smallest shift up took
        // 4.6 failed attempts per tangent, this one 1.6 failed and 1.3 successful: the draws were
        // 12 % faster, their results the same bits.
        let start = self.next_shift;
        let found = if positive(start) {
            let mut k = start;
            while k > 0 && positive(k - 1) {
                k -= 1;
            }
            Some(k)
        } else {
            (start + 1..DIAGONAL_SHIFTS.len()).find(|&k| positive(k))
        };
        self.next_shift = found.map_or(DIAGONAL_SHIFTS.len() - 1, |k| k.saturating_sub(1));
        if found.is_some() {
            self.factor[i] = Factor::Shifted64;
            return Ok(());
        }
        self.symbolic
            .factorize_numeric_ldlt(
                &mut self.l_values[i],
                single,
                Side::Lower,
                LdltRegularization::default(),
                self.par,
                MemStack::new(&mut self.mem),
                Default::default(),
            )
            .map_err(|e| FemError::Factorization(format!("tangent stiffness is singular: {e:?}")))?;
        self.factor[i] = Factor::Ldlt;
        Ok(())
    }

    /// Whether the slot holds a double-precision factor of the matrix itself.
    pub fn is_double(&self, slot: Slot) -> bool {
        self.factor[slot.index()] == Factor::Llt64
    }

    /// Whether the next factorisations of positive-definite matrices are made in double
    /// precision from the start: for a solve whose single-precision factor, though it exists,
    /// is too inaccurate for its iterations to converge.
    pub fn set_double_precision(&mut self, double: bool) {
        self.double = double;
    }

    /// Forgets what the earlier factorisations taught: double precision from the start, and
    /// where the search for a diagonal shift starts. A new solve's factors then depend on its
    /// own matrices alone, not on the solves before it.
    pub fn forget_history(&mut self) {
        self.double = false;
        self.next_shift = FIRST_SHIFT;
    }

    /// Solves A x = b in place with the slot's factorisation.
    pub fn solve_in_place(&mut self, slot: Slot, rhs: &mut [f64]) -> Result<(), FemError> {
        let n = rhs.len();
        if matches!(self.factor[slot.index()], Factor::Llt64 | Factor::Shifted64) {
            let stack = MemStack::new(self.mem64.as_mut().expect("allocated with the factor"));
            let mat = MatMut::from_column_major_slice_mut(rhs, n, 1);
            LltRef::new(&self.symbolic, &self.l_values64[slot.index()]).solve_in_place_with_conj(
                Conj::No,
                mat,
                self.par,
                stack,
            );
            return check_solution(rhs);
        }
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
            Factor::Llt64 | Factor::Shifted64 => unreachable!("solved above"),
            Factor::None => return Err(FemError::Factorization("solve before a successful factorisation".into())),
        }
        rhs.iter_mut().zip(&self.scratch).for_each(|(r, &x)| *r = f64::from(x));
        check_solution(rhs)
    }
}

/// LLᵀ of `a` into `l_values` with the symbolic structure; false when `a` is not positive definite.
fn llt<T: faer::traits::ComplexField>(
    symbolic: &SymbolicCholesky<u32>,
    l_values: &mut [T],
    a: SparseColMatRef<'_, u32, T>,
    par: Par,
    mem: &mut MemBuffer,
) -> bool {
    let regularization = LltRegularization::default();
    let stack = MemStack::new(mem);
    symbolic.factorize_numeric_llt(l_values, a, Side::Lower, regularization, par, stack, Default::default()).is_ok()
}

/// Fails when a solution of the linear system is not finite.
fn check_solution(x: &[f64]) -> Result<(), FemError> {
    if x.iter().any(|v| !v.is_finite()) {
        return Err(FemError::NonFinite("solution of the linear system".into()));
    }
    Ok(())
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

/// Symbolic analysis of the pattern in the permutation `perm`, or in its own order when `None`
/// (then faer reads the upper triangle: the pattern's lower one, transposed).
fn analyse(pattern: &Pattern, perm: Option<PermRef<'_, u32>>) -> Result<SymbolicCholesky<u32>, FemError> {
    let n = pattern.num_free;
    let params = CholeskySymbolicParams::default();
    let symbolic = match perm {
        Some(perm) => {
            let sym = SymbolicSparseColMatRef::new_checked(n, n, &pattern.col_ptr, None, &pattern.row_idx);
            factorize_symbolic_cholesky(sym, Side::Lower, SymmetricOrdering::Custom(perm), params)
        }
        None => {
            let (col_ptr, row_idx) = transpose(pattern);
            let sym = SymbolicSparseColMatRef::new_checked(n, n, &col_ptr, None, &row_idx);
            factorize_symbolic_cholesky(sym, Side::Upper, SymmetricOrdering::Identity, params)
        }
    };
    symbolic.map_err(|e| FemError::Factorization(format!("symbolic analysis failed: {e:?}")))
}

/// Renumbers the pattern in the order `(forward, inverse)` and analyses it.
fn renumbered(
    pattern: &mut Pattern,
    (forward, inverse): (Vec<u32>, Vec<u32>),
) -> Result<SymbolicCholesky<u32>, FemError> {
    pattern.renumber(&forward, &inverse)?;
    analyse(pattern, None)
}

/// Multiply-adds of a factorisation of the pattern in the order `(forward, inverse)`.
fn work_in_order(pattern: &Pattern, (forward, inverse): &(Vec<u32>, Vec<u32>)) -> Result<f64, FemError> {
    let perm = PermRef::new_checked(forward, inverse, pattern.num_free);
    Ok(factorization_work(&analyse(pattern, Some(perm))?))
}

/// faer's approximate minimum degree ordering of the pattern: `(forward, inverse)`.
fn amd_permutation(pattern: &Pattern) -> Result<(Vec<u32>, Vec<u32>), FemError> {
    let n = pattern.num_free;
    let sym = SymbolicSparseColMatRef::new_checked(n, n, &pattern.col_ptr, None, &pattern.row_idx);
    let (mut forward, mut inverse) = (vec![0u32; n], vec![0u32; n]);
    let mut mem = MemBuffer::try_new(amd::order_scratch::<u32>(n, pattern.nnz()))
        .map_err(|_| FemError::Factorization("out of memory for the ordering".into()))?;
    amd::order(&mut forward, &mut inverse, sym, amd::Control::default(), MemStack::new(&mut mem))
        .map_err(|e| FemError::Factorization(format!("minimum degree ordering failed: {e:?}")))?;
    Ok((forward, inverse))
}

/// The pattern's lower triangle transposed (the upper triangle), as CSC `(col_ptr, row_idx)`.
fn transpose(pattern: &Pattern) -> (Vec<u32>, Vec<u32>) {
    let n = pattern.num_free;
    let mut col_ptr = vec![0u32; n + 1];
    for &r in &pattern.row_idx {
        col_ptr[r as usize + 1] += 1;
    }
    for c in 0..n {
        col_ptr[c + 1] += col_ptr[c];
    }
    let mut fill = col_ptr.clone();
    let mut row_idx = vec![0u32; pattern.row_idx.len()];
    // Columns in increasing order: each transposed column's rows come out sorted.
    for c in 0..n {
        for &r in &pattern.row_idx[pattern.col_ptr[c] as usize..pattern.col_ptr[c + 1] as usize] {
            row_idx[fill[r as usize] as usize] = c as u32;
            fill[r as usize] += 1;
        }
    }
    (col_ptr, row_idx)
}

/// Serialises the calls into METIS, whose random generator is one per process.
static METIS: std::sync::Mutex<()> = std::sync::Mutex::new(());

/// METIS's nested-dissection ordering of the nodes with free dofs, each node's free dofs taken
/// together: `(forward, inverse)` with `forward[new] = old` over the free dofs. `None` when
/// METIS fails.
fn nested_dissection(pattern: &Pattern) -> Option<(Vec<u32>, Vec<u32>)> {
    let n = pattern.num_free;
    if n == 0 || i32::try_from(n).is_err() {
        return None;
    }
    // The free dofs of each node (global dof / 3), in the order of the global dofs.
    let mut node_of = vec![0usize; n];
    let mut dofs_of: Vec<Vec<u32>> = Vec::new();
    let mut last = usize::MAX;
    for (dof, &free) in pattern.free_index.iter().enumerate().filter(|(_, &f)| f != u32::MAX) {
        if dof / 3 != last {
            last = dof / 3;
            dofs_of.push(Vec::new());
        }
        let node = dofs_of.len() - 1;
        dofs_of[node].push(free);
        node_of[free as usize] = node;
    }
    let nodes = dofs_of.len();
    // The free dofs of two nodes that share a patch all couple, so the column of each node's
    // first free dof (in the present numbering) holds every later neighbour.
    let mut neighbours: Vec<Vec<i32>> = vec![Vec::new(); nodes];
    for (b, dofs) in dofs_of.iter().enumerate() {
        let c = *dofs.iter().min().expect("a node has a free dof") as usize;
        for &r in &pattern.row_idx[pattern.col_ptr[c] as usize..pattern.col_ptr[c + 1] as usize] {
            let a = node_of[r as usize];
            if a != b {
                neighbours[a].push(b as i32);
                neighbours[b].push(a as i32);
            }
        }
    }
    let mut xadj = Vec::with_capacity(nodes + 1);
    let mut adjncy = Vec::new();
    xadj.push(0);
    for list in &mut neighbours {
        list.sort_unstable();
        list.dedup();
        adjncy.extend_from_slice(list);
        xadj.push(i32::try_from(adjncy.len()).ok()?);
    }
    let mut count = nodes as i32;
    let (mut perm, mut iperm) = (vec![0i32; nodes], vec![0i32; nodes]);
    let mut options = [0; metis_sys::METIS_NOPTIONS as usize];
    // METIS draws from one random generator per process (GKlib's), reseeded by each call: calls
    // at once on several threads would interleave their draws and their orderings would depend
    // on timing. One at a time, each ordering depends on its graph alone.
    let _one_at_a_time = METIS.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
    // SAFETY: the arrays have the lengths METIS_NodeND reads and writes (xadj: nodes + 1,
    // adjncy: xadj[nodes], perm and iperm: nodes, options: METIS_NOPTIONS); METIS keeps no
    // pointer after returning.
    let status = unsafe {
        metis_sys::METIS_SetDefaultOptions(options.as_mut_ptr());
        options[metis_sys::moptions_et_METIS_OPTION_NUMBERING as usize] = 0;
        metis_sys::METIS_NodeND(
            &mut count,
            xadj.as_mut_ptr(),
            adjncy.as_mut_ptr(),
            std::ptr::null_mut(),
            options.as_mut_ptr(),
            perm.as_mut_ptr(),
            iperm.as_mut_ptr(),
        )
    };
    if status != metis_sys::rstatus_et_METIS_OK {
        return None;
    }
    let forward: Vec<u32> = perm.iter().flat_map(|&p| dofs_of[p as usize].iter().copied()).collect();
    let mut inverse = vec![u32::MAX; n];
    for (new, &old) in forward.iter().enumerate() {
        *inverse.get_mut(old as usize)? = new as u32;
    }
    // A permutation sets every entry.
    inverse.iter().all(|&i| i != u32::MAX).then_some((forward, inverse))
}
