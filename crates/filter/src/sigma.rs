//! Simplex sigma points (p + 1 points for p reduced-state dimensions) and their sampling from a factored covariance.
//!
//! Construction: the *spherical simplex* of Julier (2003, "The spherical simplex unscented transformation") with the
//! central weight W0 = 0, i.e. the minimal simplex used by Moireau & Chapelle (2011): p + 1 unit sigma points
//! `I(i)` with equal weights `α_i = 1/(p+1)`, built recursively
//!
//! ```text
//! p = 1 : I = [ -1/√(2α),  1/√(2α) ]
//! j ≥ 2 : row j of I(0..j-1) = -1/√(j(j+1)α),  row j of I(j) = j/√(j(j+1)α),  row j of I(j+1..p) = 0
//! ```
//!
//! so that `Σ α_i I(i) = 0` and `P_α = Σ α_i I(i) I(i)^T = I_p` exactly (up to rounding).

use nalgebra::{Cholesky, DMatrix, DVector};

use crate::FilterError;

/// The unit simplex sigma points of dimension p and their (equal) weights.
#[derive(Debug, Clone, PartialEq)]
pub struct SimplexSigmaPoints {
    weights: Vec<f64>,
    points: DMatrix<f64>,
}

impl SimplexSigmaPoints {
    /// Builds the p + 1 simplex points of dimension `p` (p ≥ 1).
    pub fn new(p: usize) -> Result<Self, FilterError> {
        if p == 0 {
            return Err(FilterError::InvalidConfig("the reduced state needs at least one parameter".into()));
        }
        let m = p + 1;
        let alpha = 1.0 / m as f64;
        let mut points = DMatrix::zeros(p, m);
        let a1 = 1.0 / (2.0 * alpha).sqrt();
        points[(0, 0)] = -a1;
        points[(0, 1)] = a1;
        for j in 2..=p {
            let s = 1.0 / ((j * (j + 1)) as f64 * alpha).sqrt();
            for i in 0..j {
                points[(j - 1, i)] = -s;
            }
            points[(j - 1, j)] = j as f64 * s;
        }
        Ok(SimplexSigmaPoints { weights: vec![alpha; m], points })
    }

    /// Dimension p of the reduced state.
    pub fn dim(&self) -> usize {
        self.points.nrows()
    }

    /// Number of sigma points, p + 1.
    pub fn count(&self) -> usize {
        self.points.ncols()
    }

    /// Weights α_i (all equal to 1/(p+1)).
    pub fn weights(&self) -> &[f64] {
        &self.weights
    }

    /// Unit sigma points I(i) as the columns of a p × (p+1) matrix.
    pub fn points(&self) -> &DMatrix<f64> {
        &self.points
    }

    /// Offsets `C^{-T} I(i)` (columns, p × (p+1)) for `U = C C^T`, where `c_lower` is the lower Cholesky factor C.
    pub(crate) fn offsets(&self, c_lower: &DMatrix<f64>) -> Option<DMatrix<f64>> {
        c_lower.tr_solve_lower_triangular(&self.points)
    }

    /// Sigma points `x(i) = mean + L C^{-T} I(i)` (columns, n × (p+1)) of the Gaussian with mean `mean` (n) and
    /// factored covariance `P = L U^{-1} L^T`, `L` n × p, `U` p × p symmetric positive definite, `U = C C^T`.
    /// Their weighted mean is `mean` and their weighted covariance is `P`.
    pub fn sample(&self, mean: &DVector<f64>, l: &DMatrix<f64>, u: &DMatrix<f64>) -> Result<DMatrix<f64>, FilterError> {
        let p = self.dim();
        let n = mean.len();
        if l.nrows() != n || l.ncols() != p {
            return Err(FilterError::DimensionMismatch {
                what: "factor L (rows × columns)".into(),
                expected: n * p,
                found: l.nrows() * l.ncols(),
            });
        }
        if u.nrows() != p || u.ncols() != p {
            return Err(FilterError::DimensionMismatch {
                what: "factor U (rows × columns)".into(),
                expected: p * p,
                found: u.nrows() * u.ncols(),
            });
        }
        let not_pd = || FilterError::NotPositiveDefinite { what: "U".into(), iteration: 0 };
        if u.iter().any(|v| !v.is_finite()) {
            return Err(not_pd());
        }
        let chol = Cholesky::new(u.clone()).ok_or_else(not_pd)?;
        let offsets = self.offsets(&chol.l()).ok_or_else(not_pd)?;
        let mut out = l * offsets;
        for mut col in out.column_iter_mut() {
            col += mean;
        }
        Ok(out)
    }
}
