//! Sigma points of the unscented transform: the unit points `I(i)` and weights `α_i` of a set, and their sampling
//! from a factored covariance. Two sets, as in SOFA's Optimus plugin ([`SigmaPointSet`]):
//!
//! * **Simplex** (default, p + 1 points): the *spherical simplex* of Julier (2003, "The spherical simplex
//!   unscented transformation") with the central weight W0 = 0, i.e. the minimal simplex used by Moireau &
//!   Chapelle (2011): p + 1 unit sigma points `I(i)` with equal weights `α_i = 1/(p+1)`, built recursively
//!
//!   ```text
//!   p = 1 : I = [ -1/√(2α),  1/√(2α) ]
//!   j ≥ 2 : row j of I(0..j-1) = -1/√(j(j+1)α),  row j of I(j) = j/√(j(j+1)α),  row j of I(j+1..p) = 0
//!   ```
//!
//! * **Star** (2p + 1 points): the standard symmetric set of Julier & Uhlmann (1997), the centre and a pair of
//!   points on every axis,
//!
//!   ```text
//!   I(0) = 0,               α_0 = κ / (p + κ)
//!   I(j) = +√(p+κ) e_j,     α_j = 1 / (2 (p + κ))      j = 1..p
//!   I(p+j) = −√(p+κ) e_j,   α_{p+j} = 1 / (2 (p + κ))
//!   ```
//!
//!   with κ = ½ by default ([`SigmaPoints::star`]), which makes every weight 1/(2p+1) (the choice of Optimus'
//!   ROUKF: the centre counts as much as the others, and its weight stays positive for every p, unlike Julier's
//!   κ = 3 − p). Other κ > −p are available through [`SigmaPoints::star_with_kappa`]; κ < 0 gives the centre a
//!   negative weight.
//!
//! Both sets satisfy `Σ α_i = 1`, `Σ α_i I(i) = 0` and `P_α = Σ α_i I(i) I(i)^T = I_p` exactly (up to rounding),
//! so that the sampled points `x(i) = x̂ + S I(i)` of any square root `S S^T = P` have weighted mean x̂ and weighted
//! covariance P, and the filter's update (see [`crate::Roukf`]) is the same for both.

use std::fmt;
use std::str::FromStr;

use nalgebra::{Cholesky, DMatrix, DVector};
use serde::{Deserialize, Serialize};

use crate::FilterError;

/// Which set of sigma points the filter uses (see the module documentation).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum SigmaPointSet {
    /// p + 1 simplex points, equal weights 1/(p+1) (Moireau & Chapelle 2011).
    #[default]
    Simplex,
    /// 2p + 1 symmetric points: the centre and ±√(p+½) along every axis, equal weights 1/(2p+1).
    Star,
}

impl SigmaPointSet {
    /// Number of sigma points for p parameters: p + 1 (simplex) or 2p + 1 (star).
    pub fn count(self, p: usize) -> usize {
        match self {
            SigmaPointSet::Simplex => p + 1,
            SigmaPointSet::Star => 2 * p + 1,
        }
    }

    /// The unit sigma points of this set for p parameters.
    pub fn build(self, p: usize) -> Result<SigmaPoints, FilterError> {
        match self {
            SigmaPointSet::Simplex => SigmaPoints::simplex(p),
            SigmaPointSet::Star => SigmaPoints::star(p),
        }
    }

    /// The name used in scenario files and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            SigmaPointSet::Simplex => "simplex",
            SigmaPointSet::Star => "star",
        }
    }
}

impl fmt::Display for SigmaPointSet {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for SigmaPointSet {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "simplex" => Ok(SigmaPointSet::Simplex),
            "star" => Ok(SigmaPointSet::Star),
            other => Err(format!("unknown sigma-point set `{other}`: expected `simplex` or `star`")),
        }
    }
}

/// Unit sigma points of dimension p and their weights.
#[derive(Debug, Clone, PartialEq)]
pub struct SigmaPoints {
    set: SigmaPointSet,
    weights: Vec<f64>,
    points: DMatrix<f64>,
}

impl SigmaPoints {
    /// The p + 1 simplex points of dimension `p` (p ≥ 1).
    pub fn simplex(p: usize) -> Result<Self, FilterError> {
        check_dim(p)?;
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
        Ok(SigmaPoints { set: SigmaPointSet::Simplex, weights: vec![alpha; m], points })
    }

    /// The 2p + 1 star points of dimension `p` (p ≥ 1) with κ = ½: all weights 1/(2p+1).
    pub fn star(p: usize) -> Result<Self, FilterError> {
        Self::star_with_kappa(p, 0.5)
    }

    /// The 2p + 1 star points of dimension `p` (p ≥ 1) with the scaling κ > −p: the centre (weight κ/(p+κ)) first,
    /// then `+√(p+κ) e_j` for j = 1..p, then `−√(p+κ) e_j` (weights 1/(2(p+κ))).
    pub fn star_with_kappa(p: usize, kappa: f64) -> Result<Self, FilterError> {
        check_dim(p)?;
        let spread = p as f64 + kappa;
        if !(kappa.is_finite() && spread > 0.0) {
            return Err(FilterError::InvalidConfig(format!(
                "star sigma points need a finite κ > −p = −{p}, got {kappa}"
            )));
        }
        let scale = spread.sqrt();
        let mut points = DMatrix::zeros(p, 2 * p + 1);
        for j in 0..p {
            points[(j, 1 + j)] = scale;
            points[(j, 1 + p + j)] = -scale;
        }
        let mut weights = vec![1.0 / (2.0 * spread); 2 * p + 1];
        weights[0] = kappa / spread;
        Ok(SigmaPoints { set: SigmaPointSet::Star, weights, points })
    }

    /// Which set these points are.
    pub fn set(&self) -> SigmaPointSet {
        self.set
    }

    /// Dimension p of the reduced state.
    pub fn dim(&self) -> usize {
        self.points.nrows()
    }

    /// Number of sigma points: p + 1 (simplex) or 2p + 1 (star).
    pub fn count(&self) -> usize {
        self.points.ncols()
    }

    /// Weights α_i (sum 1).
    pub fn weights(&self) -> &[f64] {
        &self.weights
    }

    /// Unit sigma points I(i) as the columns of a p × count matrix.
    pub fn points(&self) -> &DMatrix<f64> {
        &self.points
    }

    /// Offsets `C^{-T} I(i)` (columns, p × count) for `U = C C^T`, where `c_lower` is the lower Cholesky factor C.
    pub(crate) fn offsets(&self, c_lower: &DMatrix<f64>) -> Option<DMatrix<f64>> {
        c_lower.tr_solve_lower_triangular(&self.points)
    }

    /// Sigma points `x(i) = mean + L C^{-T} I(i)` (columns, n × count) of the Gaussian with mean `mean` (n) and
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

fn check_dim(p: usize) -> Result<(), FilterError> {
    if p == 0 {
        return Err(FilterError::InvalidConfig("the reduced state needs at least one parameter".into()));
    }
    Ok(())
}
