//! The sparse Cholesky factorisation: its fill-reducing orderings (METIS's nested dissection
//! against faer's approximate minimum degree) and its diagonal shift of indefinite matrices.

use augsim_fem as fem;
use fem::assembly::Pattern;
use fem::linsolve::{Ordering, Slot, SparseCholesky, BOTH_ORDERINGS_DOFS, DIAGONAL_SHIFTS, ND_WORK};
use fem::{ElementGeometry, Formulation};
use mesh::box_tet;

/// The tangent pattern of a cube of `n`³ cells of T4, its bottom face fixed.
fn cube_pattern(n: usize) -> Pattern {
    let m = box_tet([0.0; 3], [1.0; 3], [n; 3]).unwrap();
    let geometry = ElementGeometry::new(&m, Formulation::Standard).unwrap();
    let mut constrained = vec![false; 3 * m.nodes.len()];
    for (i, p) in m.nodes.iter().enumerate() {
        if p[2] == 0.0 {
            constrained[3 * i..3 * i + 3].fill(true);
        }
    }
    Pattern::new(&geometry, 3 * m.nodes.len(), &constrained).unwrap()
}

/// A symmetric positive-definite matrix on the pattern (stored lower triangle): −1 between
/// coupled dofs, each diagonal one more than its number of couplings.
fn dominant_values(p: &Pattern) -> Vec<f64> {
    let mut values = vec![-1.0; p.nnz()];
    let mut degree = vec![0.0; p.num_free];
    for c in 0..p.num_free {
        for &r in &p.row_idx[p.col_ptr[c] as usize..p.col_ptr[c + 1] as usize] {
            if r as usize != c {
                degree[c] += 1.0;
                degree[r as usize] += 1.0;
            }
        }
    }
    for (i, d) in degree.iter().enumerate() {
        values[p.diag(i)] = d + 1.0;
    }
    values
}

/// y = A x for the symmetric matrix stored as the pattern's lower triangle.
fn multiply(p: &Pattern, values: &[f64], x: &[f64]) -> Vec<f64> {
    let mut y = vec![0.0; x.len()];
    for c in 0..p.num_free {
        let range = p.col_ptr[c] as usize..p.col_ptr[c + 1] as usize;
        for (&r, &v) in p.row_idx[range.clone()].iter().zip(&values[range]) {
            let r = r as usize;
            y[r] += v * x[c];
            if r != c {
                y[c] += v * x[r];
            }
        }
    }
    y
}

/// A right-hand side by global dof, in the pattern's numbering, so that solutions in
/// different numberings compare.
fn global_rhs(p: &Pattern) -> Vec<f64> {
    let mut rhs = vec![0.0; p.num_free];
    for (dof, &i) in p.free_index.iter().enumerate().filter(|(_, &i)| i != u32::MAX) {
        rhs[i as usize] = ((dof * 7919) % 101) as f64 / 50.0 - 1.0;
    }
    rhs
}

/// The cube's pattern renumbered in `ordering`, its factorisation, and the dominant system
/// solved with [`global_rhs`]: `(pattern, factorisation, right-hand side, solution)`.
fn solve(n: usize, ordering: Ordering) -> (Pattern, SparseCholesky, Vec<f64>, Vec<f64>) {
    let mut p = cube_pattern(n);
    let mut cholesky = SparseCholesky::with_ordering(&mut p, ordering).unwrap();
    cholesky.factorize(Slot::Latest, &dominant_values(&p)).unwrap();
    let rhs = global_rhs(&p);
    let mut x = rhs.clone();
    cholesky.solve_in_place(Slot::Latest, &mut x).unwrap();
    (p, cholesky, rhs, x)
}

#[test]
fn nested_dissection_solves_as_amd_does_with_less_work_on_a_cube() {
    let norm = |v: &[f64]| v.iter().map(|x| x * x).sum::<f64>().sqrt();
    let mut solutions = Vec::new();
    for ordering in [Ordering::Amd, Ordering::NestedDissection] {
        let (p, cholesky, rhs, x) = solve(14, ordering);
        assert_eq!(cholesky.ordering(), ordering);
        let r: Vec<f64> = multiply(&p, &dominant_values(&p), &x).iter().zip(&rhs).map(|(a, b)| a - b).collect();
        assert!(norm(&r) < 1e-5 * norm(&rhs), "{ordering:?}: relative residual {:.2e}", norm(&r) / norm(&rhs));
        // The solution by global dof.
        let by_dof: Vec<f64> = p.free_index.iter().filter(|&&i| i != u32::MAX).map(|&i| x[i as usize]).collect();
        solutions.push((cholesky, x, by_dof));
    }
    let ((amd, _, x_amd), (nd, x_nd_own, x_nd)) = (&solutions[0], &solutions[1]);
    let (w_amd, w_nd) = (amd.factorization_work(), nd.factorization_work());
    println!("AMD: work {w_amd:.3e}, factor {}; ND: work {w_nd:.3e}, factor {}", amd.factor_nnz(), nd.factor_nnz());
    assert!(w_nd < 0.9 * w_amd, "nested dissection work {w_nd:.3e} against AMD's {w_amd:.3e}");
    // The two orderings solve the same system (to single precision).
    let gap = x_amd.iter().zip(x_nd).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
    assert!(gap < 1e-4 * norm(x_amd) / (x_amd.len() as f64).sqrt(), "AMD and ND solutions differ by {gap:.2e}");
    // Above the threshold, the automatic choice takes the ordering with less work.
    assert!(w_amd > ND_WORK);
    assert_eq!(SparseCholesky::new(&mut cube_pattern(14)).unwrap().ordering(), Ordering::NestedDissection);
    // METIS runs with a fixed seed: the same ordering, hence the same bits, every time.
    assert_eq!(&solve(14, Ordering::NestedDissection).3, x_nd_own);
}

/// A system large enough for the automatic choice to compute both orderings at once makes the
/// choice the sequential path makes, and numbers the pattern as nested dissection alone does.
#[test]
fn auto_on_a_large_system_computes_both_orderings_and_takes_nested_dissection() {
    let (mut auto, mut nested) = (cube_pattern(15), cube_pattern(15));
    assert!(auto.num_free >= BOTH_ORDERINGS_DOFS);
    let chosen = SparseCholesky::new(&mut auto).unwrap();
    let reference = SparseCholesky::with_ordering(&mut nested, Ordering::NestedDissection).unwrap();
    assert_eq!(chosen.ordering(), Ordering::NestedDissection);
    assert_eq!(chosen.factorization_work(), reference.factorization_work());
    assert_eq!(
        (&auto.free_index, &auto.col_ptr, &auto.row_idx),
        (&nested.free_index, &nested.col_ptr, &nested.row_idx)
    );
    let amd = SparseCholesky::with_ordering(&mut cube_pattern(15), Ordering::Amd).unwrap();
    assert!(amd.factorization_work() > ND_WORK && chosen.factorization_work() < amd.factorization_work());
}

/// Renumbering keeps the matrix: the values assembled through a renumbered pattern are those
/// of the original one, bit for bit, each at its renumbered place; a non-permutation is refused.
#[test]
fn renumbering_moves_every_entry_with_its_dofs() {
    use fem::assembly::{assemble, Workspace};
    use fem::{Law, Material};
    let m = box_tet([0.0; 3], [1.0, 0.6, 0.4], [4, 3, 2]).unwrap();
    let material = Material::new(Law::NeoHookean, 1000.0, 0.45);
    let geometry = ElementGeometry::new(&m, Formulation::Fbar).unwrap();
    let constrained: Vec<bool> = (0..3 * m.nodes.len()).map(|d| m.nodes[d / 3][0] == 0.0).collect();
    let original = Pattern::new(&geometry, constrained.len(), &constrained).unwrap();
    let n = original.num_free;
    // A scrambling permutation: forward[new] = old.
    let forward: Vec<u32> = (0..n as u32).map(|i| (i * 7 + 3) % n as u32).collect();
    let mut inverse = vec![0u32; n];
    forward.iter().enumerate().for_each(|(new, &old)| inverse[old as usize] = new as u32);
    let mut renumbered = original.clone();
    assert!(renumbered.renumber(&forward[1..], &inverse).is_err());
    assert!(renumbered.renumber(&vec![0; n], &inverse).is_err());
    renumbered.renumber(&forward, &inverse).unwrap();
    let u: Vec<f64> = (0..constrained.len()).map(|i| 0.01 * ((i * 13 % 7) as f64 - 3.0)).collect();
    let values = |p: &Pattern| {
        let (mut f, mut k) = (vec![0.0; u.len()], vec![0.0; p.nnz()]);
        assemble(&geometry, p, &material, &u, &mut f, Some(&mut k), &mut Workspace::for_pattern(&geometry, p)).unwrap();
        k
    };
    let (before, after) = (values(&original), values(&renumbered));
    assert_eq!(renumbered.nnz(), original.nnz());
    for (dof, &i) in original.free_index.iter().enumerate() {
        let expected = if i == u32::MAX { u32::MAX } else { inverse[i as usize] };
        assert_eq!(renumbered.free_index[dof], expected);
    }
    for c in 0..n {
        for v in original.col_ptr[c] as usize..original.col_ptr[c + 1] as usize {
            let (r, c) = (inverse[original.row_idx[v] as usize] as usize, inverse[c] as usize);
            let w = renumbered.find(r.max(c), r.min(c)).expect("entry renumbered");
            assert_eq!(after[w].to_bits(), before[v].to_bits());
        }
    }
    assert!((0..n).all(|i| renumbered.row_idx[renumbered.diag(i)] == i as u32));
}

#[test]
fn auto_keeps_amd_below_the_work_threshold() {
    let mut p = cube_pattern(6);
    let auto = SparseCholesky::new(&mut p).unwrap();
    assert!(auto.factorization_work() < ND_WORK);
    assert_eq!(auto.ordering(), Ordering::Amd);
}

/// Nested dissection computed on several threads at once gives every thread the ordering it
/// gives alone (METIS's random generator is shared by the process: its calls must not overlap).
#[test]
fn nested_dissection_on_several_threads_at_once_is_the_sequential_one() {
    let numbering = |p: &Pattern| (p.free_index.clone(), p.col_ptr.clone(), p.row_idx.clone());
    let mut alone = cube_pattern(10);
    SparseCholesky::with_ordering(&mut alone, Ordering::NestedDissection).unwrap();
    let want = numbering(&alone);
    for _ in 0..4 {
        let got: Vec<_> = std::thread::scope(|s| {
            let threads: Vec<_> = (0..4)
                .map(|_| {
                    s.spawn(|| {
                        let mut p = cube_pattern(10);
                        SparseCholesky::with_ordering(&mut p, Ordering::NestedDissection).unwrap();
                        numbering(&p)
                    })
                })
                .collect();
            threads.into_iter().map(|t| t.join().unwrap()).collect()
        });
        assert!(got.iter().all(|g| *g == want), "an ordering computed beside others differs from the lone one");
    }
}

/// A factorisation set to one thread gives the same bits in a pool of one thread and in one of
/// three, on a system large enough to be factorised in parallel otherwise.
#[test]
fn a_single_threaded_factorisation_does_not_depend_on_the_pool() {
    let solve_in = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        pool.install(|| {
            let mut p = cube_pattern(15);
            let mut cholesky = SparseCholesky::with_ordering(&mut p, Ordering::Amd).unwrap();
            assert!(cholesky.factorization_work() > ND_WORK, "parallel by default");
            cholesky.set_single_threaded().unwrap();
            cholesky.factorize(Slot::Latest, &dominant_values(&p)).unwrap();
            let mut x = global_rhs(&p);
            cholesky.solve_in_place(Slot::Latest, &mut x).unwrap();
            x
        })
    };
    let one = solve_in(1);
    assert!(one == solve_in(3), "one thread and three must give the same bits");
}

/// An indefinite matrix is factorised with the smallest of [`DIAGONAL_SHIFTS`] that makes it
/// positive definite, wherever the search starts: the same bits after matrices that needed a
/// larger shift, a smaller one or none, and a factor that solves the shifted system.
#[test]
fn an_indefinite_matrix_gets_the_smallest_shift_whatever_came_before() {
    // Each factoriser renumbers its pattern in the same order (AMD, deterministic).
    let mut p = cube_pattern(6);
    let mut history = SparseCholesky::new(&mut p).unwrap();
    // The dominant matrix's smallest eigenvalue is 1: lowering its diagonal by `c` > 1 makes it
    // indefinite, the more so the larger `c`.
    let lowered = |c: f64| {
        let mut values = dominant_values(&p);
        (0..p.num_free).for_each(|i| values[p.diag(i)] -= c);
        values
    };
    let shifted = |values: &[f64], tau: f64| {
        let mut values = values.to_vec();
        (0..p.num_free).for_each(|i| values[p.diag(i)] += tau * values[p.diag(i)].abs());
        values
    };
    // The smallest shift, by factorising every shifted matrix on a factoriser of its own (one
    // that is not positive definite is shifted again, or fails).
    let smallest = |values: &[f64]| {
        DIAGONAL_SHIFTS.into_iter().find(|&tau| {
            let mut alone = SparseCholesky::new(&mut cube_pattern(6)).unwrap();
            alone.factorize(Slot::Latest, &shifted(values, tau)).is_ok() && alone.is_positive_definite(Slot::Latest)
        })
    };
    let solve = |cholesky: &mut SparseCholesky, values: &[f64]| {
        cholesky.factorize(Slot::Latest, values).unwrap();
        let mut x = global_rhs(&p);
        cholesky.solve_in_place(Slot::Latest, &mut x).unwrap();
        x
    };
    let norm = |v: &[f64]| v.iter().map(|x| x * x).sum::<f64>().sqrt();
    let mut seen = Vec::new();
    for c in [1.02, 6.0, 1.5, 1.02, 0.5, 12.0, 1.5] {
        let values = lowered(c);
        let x = solve(&mut history, &values);
        let fresh = solve(&mut SparseCholesky::new(&mut cube_pattern(6)).unwrap(), &values);
        assert!(x == fresh, "c = {c}: the factor depends on the matrices factorised before");
        let rhs = global_rhs(&p);
        // A positive-definite matrix is factorised in single precision, a shifted one in double.
        let (solved, tolerance) = if c < 1.0 {
            (values.clone(), 1e-5)
        } else {
            let tau =
                smallest(&values).unwrap_or_else(|| panic!("c = {c}: no shift makes the matrix positive definite"));
            assert!(!history.is_positive_definite(Slot::Latest), "c = {c}: taken as positive definite");
            seen.push(tau);
            (shifted(&values, tau), 1e-9)
        };
        let r: Vec<f64> = multiply(&p, &solved, &x).iter().zip(&rhs).map(|(a, b)| a - b).collect();
        assert!(norm(&r) < tolerance * norm(&rhs), "c = {c}: relative residual {:.2e}", norm(&r) / norm(&rhs));
    }
    println!("shifts needed: {seen:?}");
    seen.sort_by(f64::total_cmp);
    seen.dedup();
    assert!(seen.len() >= 3, "the cases must need different shifts: {seen:?}");
}
