//! Fill-reducing orderings of the sparse Cholesky factorisation: METIS's nested dissection
//! against faer's approximate minimum degree.

use augsim_fem as fem;
use fem::assembly::Pattern;
use fem::linsolve::{Ordering, Slot, SparseCholesky, ND_WORK};
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
        values[p.diag[i] as usize] = d + 1.0;
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

fn solve(p: &Pattern, ordering: Ordering, values: &[f64], rhs: &[f64]) -> (SparseCholesky, Vec<f64>) {
    let mut cholesky = SparseCholesky::with_ordering(p, ordering).unwrap();
    cholesky.factorize(Slot::Latest, values).unwrap();
    let mut x = rhs.to_vec();
    cholesky.solve_in_place(Slot::Latest, &mut x).unwrap();
    (cholesky, x)
}

#[test]
fn nested_dissection_solves_as_amd_does_with_less_work_on_a_cube() {
    let p = cube_pattern(14);
    let values = dominant_values(&p);
    let rhs: Vec<f64> = (0..p.num_free).map(|i| ((i * 7919) % 101) as f64 / 50.0 - 1.0).collect();
    let (amd, x_amd) = solve(&p, Ordering::Amd, &values, &rhs);
    let (nd, x_nd) = solve(&p, Ordering::NestedDissection, &values, &rhs);
    assert_eq!(amd.ordering(), Ordering::Amd);
    assert_eq!(nd.ordering(), Ordering::NestedDissection);
    let (w_amd, w_nd) = (amd.factorization_work(), nd.factorization_work());
    println!("AMD: work {w_amd:.3e}, factor {}; ND: work {w_nd:.3e}, factor {}", amd.factor_nnz(), nd.factor_nnz());
    assert!(w_nd < 0.9 * w_amd, "nested dissection work {w_nd:.3e} against AMD's {w_amd:.3e}");
    // Above the threshold, the automatic choice takes the ordering with less work.
    assert!(w_amd > ND_WORK);
    assert_eq!(SparseCholesky::new(&p).unwrap().ordering(), Ordering::NestedDissection);
    // METIS runs with a fixed seed: the same ordering, hence the same bits, every time.
    assert_eq!(solve(&p, Ordering::NestedDissection, &values, &rhs).1, x_nd);
    let norm = |v: &[f64]| v.iter().map(|x| x * x).sum::<f64>().sqrt();
    for x in [&x_amd, &x_nd] {
        let r: Vec<f64> = multiply(&p, &values, x).iter().zip(&rhs).map(|(a, b)| a - b).collect();
        assert!(norm(&r) < 1e-5 * norm(&rhs), "relative residual {:.2e}", norm(&r) / norm(&rhs));
    }
}

#[test]
fn auto_keeps_amd_below_the_work_threshold() {
    let p = cube_pattern(6);
    let auto = SparseCholesky::new(&p).unwrap();
    assert!(auto.factorization_work() < ND_WORK);
    assert_eq!(auto.ordering(), Ordering::Amd);
}
