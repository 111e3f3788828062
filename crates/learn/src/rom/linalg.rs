//! Dense linear algebra of the reduced-order model, on faer: principal components by the
//! method of snapshots and the kernels of the Gaussian-process regression.

use faer::linalg::matmul::matmul;
use faer::{Accum, Mat, MatRef, Par, Side};
use serde::{Deserialize, Serialize};

use crate::{LearnError, Result};

/// Parallelism of the training-time products (all cores).
pub(crate) fn training_par() -> Par {
    Par::rayon(0)
}

/// `a · bᵀ`.
pub(crate) fn mul_t(a: MatRef<'_, f64>, b: MatRef<'_, f64>, par: Par) -> Mat<f64> {
    let mut out = Mat::zeros(a.nrows(), b.nrows());
    matmul(out.as_mut(), Accum::Replace, a, b.transpose(), 1.0, par);
    out
}

/// `a · b`.
pub(crate) fn mul(a: MatRef<'_, f64>, b: MatRef<'_, f64>, par: Par) -> Mat<f64> {
    let mut out = Mat::zeros(a.nrows(), b.ncols());
    matmul(out.as_mut(), Accum::Replace, a, b, 1.0, par);
    out
}

/// The leading eigenpairs of a symmetric positive semi-definite matrix, largest first: those
/// whose eigenvalue exceeds `relative` times the largest, at most `max` of them.
pub(crate) fn leading_eigen(m: MatRef<'_, f64>, max: usize, relative: f64) -> Result<(Vec<f64>, Mat<f64>)> {
    let evd = m
        .self_adjoint_eigen(Side::Lower)
        .map_err(|e| LearnError::InvalidInput(format!("eigendecomposition failed: {e:?}")))?;
    let (s, u) = (evd.S(), evd.U());
    let n = m.nrows();
    let largest = if n == 0 { 0.0 } else { s[n - 1].max(0.0) };
    let mut values = Vec::new();
    for i in (0..n).rev() {
        if values.len() == max || !(s[i] > relative * largest) || largest == 0.0 {
            break;
        }
        values.push(s[i]);
    }
    let vectors = Mat::from_fn(n, values.len(), |r, c| u[(r, n - 1 - c)]);
    Ok((values, vectors))
}

/// Principal directions of the rows of `x` (centred): the right singular vectors by the method of
/// snapshots (eigenpairs of `x xᵀ`), as the rows of the result, with the squared singular values.
/// Directions whose singular value is below `relative` of the largest are dropped, and always those
/// within the Gram matrix's round-off (eigenvalues below 1e-12 of the largest); at most `max`.
pub(crate) fn principal_directions(x: MatRef<'_, f64>, max: usize, relative: f64) -> Result<(Vec<f64>, Mat<f64>)> {
    let gram = mul_t(x, x, training_par());
    let (values, vectors) = leading_eigen(gram.as_ref(), max, (relative * relative).max(1e-12))?;
    // Row j of the directions: xᵀ v_j / σ_j.
    let mut directions = mul(vectors.transpose(), x, training_par());
    for (j, &v) in values.iter().enumerate() {
        let inv = 1.0 / v.sqrt();
        directions.row_mut(j).iter_mut().for_each(|d| *d *= inv);
    }
    Ok((values, directions))
}

/// The covariance function of the regression, of unit variance (`k(x, x) = 1`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Kernel {
    /// Squared exponential: `exp(−d² / 2ℓ²)`.
    Rbf,
    /// Matérn ν = 5/2: `(1 + √5 d/ℓ + 5d²/3ℓ²) exp(−√5 d/ℓ)`.
    Matern52,
}

impl Kernel {
    /// The covariance of two points at squared distance `d2`, length scale `scale`.
    pub fn eval(self, d2: f64, scale: f64) -> f64 {
        let r2 = d2.max(0.0) / (scale * scale);
        match self {
            Kernel::Rbf => (-0.5 * r2).exp(),
            Kernel::Matern52 => {
                let r = (5.0 * r2).sqrt();
                (1.0 + r + r * r / 3.0) * (-r).exp()
            }
        }
    }

    /// The name used in model files and reports.
    pub fn name(self) -> &'static str {
        match self {
            Kernel::Rbf => "rbf",
            Kernel::Matern52 => "matern52",
        }
    }
}

/// Squared norms of the rows of `x`.
pub(crate) fn row_norms2(x: MatRef<'_, f64>) -> Vec<f64> {
    (0..x.nrows()).map(|i| x.row(i).iter().map(|v| v * v).sum()).collect()
}

/// The kernel matrix `k(a_i, b_j)`, with the rows' squared norms given.
pub(crate) fn kernel_matrix(
    kernel: Kernel,
    scale: f64,
    a: MatRef<'_, f64>,
    a2: &[f64],
    b: MatRef<'_, f64>,
    b2: &[f64],
    par: Par,
) -> Mat<f64> {
    let mut k = mul_t(a, b, par);
    for j in 0..k.ncols() {
        for i in 0..k.nrows() {
            let d2 = a2[i] + b2[j] - 2.0 * k[(i, j)];
            k[(i, j)] = kernel.eval(d2, scale);
        }
    }
    k
}

/// Median of the pairwise distances between the rows of `x` (at most the first 500 rows).
pub(crate) fn median_distance(x: MatRef<'_, f64>) -> f64 {
    let n = x.nrows().min(500);
    let x = x.subrows(0, n);
    let norms = row_norms2(x);
    let g = mul_t(x, x, Par::Seq);
    let mut d: Vec<f64> = (0..n)
        .flat_map(|i| (0..i).map(move |j| (i, j)))
        .map(|(i, j)| (norms[i] + norms[j] - 2.0 * g[(i, j)]).max(0.0).sqrt())
        .collect();
    if d.is_empty() {
        return 1.0;
    }
    let mid = d.len() / 2;
    *d.select_nth_unstable_by(mid, f64::total_cmp).1
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn principal_directions_recover_a_low_rank_basis() {
        // Rows spanned by two orthogonal directions in 5-D, with variances 9 and 1.
        let u = [[1.0, 0.0, 0.0, 0.0, 0.0], [0.0, 0.6, 0.8, 0.0, 0.0]];
        let x = Mat::from_fn(40, 5, |i, d| {
            let (a, b) = (3.0 * ((i as f64) * 0.7).sin(), ((i as f64) * 1.3).cos());
            a * u[0][d] + b * u[1][d]
        });
        let (values, dirs) = principal_directions(x.as_ref(), 5, 1e-9).unwrap();
        assert_eq!(values.len(), 2, "rank two: {values:?}");
        // Each row of x is reproduced by its projection on the two directions.
        let coeffs = mul_t(x.as_ref(), dirs.as_ref(), Par::Seq);
        let back = mul(coeffs.as_ref(), dirs.as_ref(), Par::Seq);
        let err = (&back - &x).norm_l2() / x.norm_l2();
        assert!(err < 1e-10, "relative reconstruction error {err}");
        // The directions are orthonormal.
        let gram = mul_t(dirs.as_ref(), dirs.as_ref(), Par::Seq);
        assert!((&gram - Mat::<f64>::identity(2, 2)).norm_l2() < 1e-10);
    }

    #[test]
    fn kernels_are_one_at_zero_distance_and_decay() {
        for k in [Kernel::Rbf, Kernel::Matern52] {
            assert!((k.eval(0.0, 0.3) - 1.0).abs() < 1e-15);
            let (near, far) = (k.eval(0.01, 0.3), k.eval(1.0, 0.3));
            assert!(near > far && far > 0.0, "{k:?}: {near} {far}");
        }
        // The squared exponential at one length scale.
        assert!((Kernel::Rbf.eval(4.0, 2.0) - (-0.5f64).exp()).abs() < 1e-15);
    }
}
