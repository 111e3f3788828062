//! Registration in a learned model's shape space: the organ's displacement is the model's mean
//! plus a combination of its modes, `u(c) = ū + Φ c`, linear in the coefficients `c`, and so is
//! every point of its surface. Each iteration of the registration loop matches the cloud to the
//! current surface; [`ShapeDeformer`] then solves the small Bayesian problem
//!
//! ```text
//! minimise over c   Σ_i ρ(n_i · (x_i − s_i(c)) / σ)  +  (c − μ)ᵀ Λ⁻¹ (c − μ)
//! ```
//!
//! (point to plane, `x_i` a cloud point, `s_i(c)` the surface point it matched, `n_i` its
//! normal, ρ Huber's loss at 2σ; `μ, Λ` the prior of the coefficients: the model's training
//! coefficients from rest; on a stream, the previous frame's posterior widened by
//! [`ShapeOptions::widening`], up to the model's own prior again). The modes are
//! fitted coarse to fine (the leading few first, then more) for the capture range of large
//! motions. The posterior covariance `(Jᵀ W J / σ² + Λ⁻¹)⁻¹` gives the standard deviation of every
//! target: the registration's own, not the regression's.

use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::checks::check_setting;
use crate::frame::{Deformer, Observations, TwoWay};
use crate::organ::{Organ, Stencil};
use crate::{RegisterError, Result};

/// A model's shape space on the organ's mesh: the mean displacement and the modes, whitened by the
/// prior of their coefficients (`u = mean + Σ_j z_j mode_j`, `z ~ N(0, I)` a priori), leading
/// directions of the prior first.
#[derive(Clone, Debug)]
pub struct ShapeSpace {
    /// The prior's mean displacement (m, 3 per mesh node).
    mean: Vec<f64>,
    /// The whitened modes, node-major rows: `basis[(3 n + d) · modes + j]` (m per unit of `z_j`).
    basis: Vec<f64>,
    modes: usize,
    /// What the modes cannot hold, per mesh node (m²).
    floor: Vec<f64>,
}

/// Rows of a displacement per parallel task ([`ShapeSpace::displacement`]).
const ROWS_PER_TASK: usize = 1024;

/// Eigenvalues of the prior covariance below this share of the largest are dropped.
const PRIOR_RANK_TOLERANCE: f64 = 1e-10;

impl ShapeSpace {
    /// The shape space of `mean` (3 per mesh node) and `modes` (each 3 per mesh node), the
    /// coefficients a priori of mean `prior_mean` and covariance `prior_covariance` (row-major,
    /// symmetric positive semi-definite); `floor`: the variance the modes leave out at each node
    /// (m²).
    pub fn new(
        mean: Vec<f64>,
        modes: &[Vec<f64>],
        prior_mean: &[f64],
        prior_covariance: &[f64],
        floor: Vec<f64>,
    ) -> Result<ShapeSpace> {
        let (r, ndof) = (modes.len(), mean.len());
        if r == 0 || prior_mean.len() != r || prior_covariance.len() != r * r || floor.len() * 3 != ndof {
            return Err(RegisterError::Invalid(format!(
                "a shape space of {r} modes needs {r} prior means, {r}×{r} covariances and a floor per node \
                 (got {}, {} and {} for {} values of the mean)",
                prior_mean.len(),
                prior_covariance.len(),
                floor.len(),
                ndof
            )));
        }
        if let Some(j) = modes.iter().position(|m| m.len() != ndof) {
            return Err(RegisterError::Invalid(format!("mode {j} has {} values, the mean {ndof}", modes[j].len())));
        }
        let values = mean.iter().chain(modes.iter().flatten()).chain(prior_mean).chain(prior_covariance);
        if values.chain(&floor).any(|v| !v.is_finite()) {
            return Err(RegisterError::Invalid("the shape space has a non-finite value".into()));
        }
        let covariance = DMatrix::from_row_slice(r, r, prior_covariance);
        let eigen = nalgebra::SymmetricEigen::new((&covariance + covariance.transpose()) * 0.5);
        let mut order: Vec<usize> = (0..r).collect();
        order.sort_by(|&a, &b| eigen.eigenvalues[b].total_cmp(&eigen.eigenvalues[a]));
        let largest = eigen.eigenvalues[order[0]];
        if !(largest > 0.0) {
            return Err(RegisterError::Invalid("the prior of the shape coefficients has no variance".into()));
        }
        order.retain(|&k| eigen.eigenvalues[k] > PRIOR_RANK_TOLERANCE * largest);
        // Whitened direction k: Σ_j V_jk √λ_k mode_j.
        let whitening: Vec<Vec<f64>> = order
            .iter()
            .map(|&k| {
                let scale = eigen.eigenvalues[k].sqrt();
                (0..r).map(|j| eigen.eigenvectors[(j, k)] * scale).collect()
            })
            .collect();
        let modes_kept = whitening.len();
        let mut basis = vec![0.0; ndof * modes_kept];
        let mut shifted = mean;
        for (j, mode) in modes.iter().enumerate() {
            for (row, &value) in mode.iter().enumerate() {
                shifted[row] += prior_mean[j] * value;
                if value != 0.0 {
                    let out = &mut basis[row * modes_kept..(row + 1) * modes_kept];
                    out.iter_mut().zip(&whitening).for_each(|(o, w)| *o += w[j] * value);
                }
            }
        }
        Ok(ShapeSpace { mean: shifted, basis, modes: modes_kept, floor })
    }

    /// The number of (whitened) modes.
    pub fn modes(&self) -> usize {
        self.modes
    }

    /// The number of mesh nodes.
    pub fn nodes(&self) -> usize {
        self.floor.len()
    }

    /// The displacement (3 per mesh node) of the whitened coefficients `z` (the first `z.len()`
    /// modes; the others at their prior mean, 0).
    pub fn displacement(&self, z: &[f64]) -> Vec<f64> {
        let mut u = self.mean.clone();
        // Rows in parallel, each summed alone: the same bits on any number of threads. On the
        // liver's 14,889 rows, 64 modes: 0.3 ms on two threads against 0.65 ms on one.
        u.par_iter_mut().zip(self.basis.par_chunks(self.modes)).with_min_len(ROWS_PER_TASK).for_each(|(value, row)| {
            *value += row.iter().zip(z).map(|(b, z)| b * z).sum::<f64>();
        });
        u
    }

    /// The first `out.len()` modes at a point of stencil `stencil`, along `direction`: `Σ_j w_j
    /// dᵀ B_j` into `out`; returns `dᵀ` of the mean there.
    fn along(&self, stencil: &Stencil, direction: [f64; 3], out: &mut [f64]) -> f64 {
        combine(&self.mean, &self.basis, self.modes, stencil.0.iter().copied(), direction, out)
    }
}

/// The first `out.len()` columns of the weighted rows of a node-major field `mean` (3 per point)
/// and its `modes` columns `basis` (row-major), at the points and weights of `terms`, along
/// `direction`: into `out` the modes' part, returned the mean's.
fn combine(
    mean: &[f64],
    basis: &[f64],
    modes: usize,
    terms: impl Iterator<Item = (usize, f64)>,
    direction: [f64; 3],
    out: &mut [f64],
) -> f64 {
    out.iter_mut().for_each(|o| *o = 0.0);
    let mut along = 0.0;
    for (point, w) in terms {
        for (d, &nd) in direction.iter().enumerate() {
            let (row, f) = (3 * point + d, w * nd);
            if f == 0.0 {
                continue;
            }
            along += f * mean[row];
            let b = &basis[row * modes..row * modes + out.len()];
            out.iter_mut().zip(b).for_each(|(o, b)| *o += f * b);
        }
    }
    along
}

/// Iterations of a frame from rest: the six of [`ShapeOptions::schedule`]'s default, coarse to
/// fine, then four of the finest. On the design cases of the registration experiment (the
/// built-in case pressed at 1–2.5 N, lifted, dragged and pulled), 4, 8, 8, 16, 32, 32 then 64 modes
/// over 10 iterations registered them to 2.35 mm on average, 8, 8, 32, 32 then 64 over 8 to
/// 3.16 mm.
pub const SHAPE_ITERATIONS: usize = 10;

/// Iterations of a frame warm-started from the previous one (all modes). On the design cases
/// streamed (under the model's own prior, [`ShapeOptions::widening`] 1), 3 and 4 left 2.54 and
/// 2.58 mm at the peak (1.59 and 1.58 mm over the frames); 2 (the prior widened by 0.8) 2.60 mm.
pub const SHAPE_WARM_ITERATIONS: usize = 3;

/// Cloud points matched per iteration (an evenly spaced subset of a larger cloud): on the design
/// cases (1,500-point clouds) 1,000 points gave 3.10 mm, all of them 2.50 mm.
pub const SHAPE_POINTS: usize = 2000;

/// The registration loop's settings for a shape-space fit: `base` with its iteration budgets, the
/// points it matches, and matches both ways on a stream's frames ([`TwoWay::Streamed`]). On the
/// design cases streamed (21 frames each), matching both ways brought the TRE at the peak from 2.88
/// to 2.68 mm on average (over the frames 1.80 → 1.71 mm); from rest it did not pay (2.34 → 2.42 mm).
pub fn loop_options(base: &crate::RegistrationOptions) -> crate::RegistrationOptions {
    crate::RegistrationOptions {
        iterations: SHAPE_ITERATIONS,
        warm_iterations: SHAPE_WARM_ITERATIONS,
        max_points: Some(SHAPE_POINTS),
        two_way: TwoWay::Streamed,
        ..base.clone()
    }
}

/// Settings of the shape-space fit.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ShapeOptions {
    /// The standard deviation of a match's point-to-plane residual (m): the cloud's noise and
    /// what the model's modes cannot follow; the least, where the matches spread wider. On the
    /// design cases 4, 5, 7 and 10 mm gave 2.34, 2.35, 2.50 and 3.18 mm (the last two with fewer
    /// points).
    pub sigma: f64,
    /// The modes fitted at each iteration of a frame from rest, coarse to fine; past the list,
    /// `max_modes`.
    pub schedule: Vec<usize>,
    /// Most modes fitted (the leading ones of the prior).
    pub max_modes: usize,
    /// On a stream, the standard deviation (in units of the model's prior, 0 to 1) by which the
    /// coefficients may move from one frame to the next: the previous frame's posterior, shrunk
    /// towards the model's prior so that its spread stays within it, then widened by it, is the
    /// next frame's prior.
    pub widening: f64,
    /// The factor on the posterior's standard deviation at the targets. 1: on the design cases
    /// 86 % of the targets' errors fell within 2σ (median error 0.68σ), within the 80–99 % aimed
    /// at; a factor for 95 % (1.9) would have doubled σ for the few large errors of the hardest
    /// pushes.
    pub calibration: f64,
}

impl Default for ShapeOptions {
    fn default() -> Self {
        ShapeOptions {
            sigma: 0.005,
            schedule: vec![4, 8, 8, 16, 32, 32],
            max_modes: 64,
            widening: 0.3,
            calibration: 1.0,
        }
    }
}

impl ShapeOptions {
    /// Checks the values, naming the first that is out of its range.
    pub fn validate(&self) -> Result<()> {
        let positive = "positive and finite";
        check_setting("sigma", self.sigma, self.sigma > 0.0, positive)?;
        check_setting("widening", self.widening, (0.0..=1.0).contains(&self.widening), "between 0 and 1")?;
        check_setting("calibration", self.calibration, self.calibration > 0.0, positive)?;
        if self.max_modes == 0 || self.schedule.contains(&0) {
            return Err(RegisterError::Invalid("max_modes and the schedule's modes must be at least 1".into()));
        }
        Ok(())
    }
}

/// The prior of a frame's whitened coefficients: `N(mean, precision⁻¹)`.
#[derive(Clone, Debug)]
struct Prior {
    mean: DVector<f64>,
    precision: DMatrix<f64>,
}

impl Prior {
    /// The model's own prior on the first `k` coefficients: `N(0, I)`.
    fn standard(k: usize) -> Prior {
        Prior { mean: DVector::zeros(k), precision: DMatrix::identity(k, k) }
    }
}

/// The shape-space registration of a [`ShapeSpace`] (see the module documentation).
pub struct ShapeDeformer {
    space: ShapeSpace,
    options: ShapeOptions,
    /// The mean displacement and the modes at the organ's surface vertices (as [`ShapeSpace`]'s
    /// at the mesh nodes): a match's row of the fit is read from its triangle's three vertices.
    surface_mean: Vec<f64>,
    surface_basis: Vec<f64>,
    triangles: Vec<[usize; 3]>,
    /// The current whitened coefficients (all modes fitted so far; the rest at 0).
    z: Vec<f64>,
    /// Their posterior covariance after the last fit.
    posterior: Option<DMatrix<f64>>,
    /// The prior of the frame under way, over [`ShapeDeformer::fitted`] modes.
    prior: Prior,
    /// Whether the frame under way is warm-started (all modes from its first iteration).
    warm: bool,
}

/// Huber's threshold, in units of σ.
const HUBER: f64 = 2.0;

/// The robust spread of `residuals` (m): 1.4826 times their median absolute value, a Gaussian's
/// standard deviation. A fit's σ is at least this, so that matches far off at a large motion's
/// first iterations (the model not yet near it) pull less than the prior holds. On the design cases
/// it changed the TRE by +0.01 mm from rest (the spread stays under the 5 mm given there but for
/// the 2.5 N press) and +0.04 mm at the streams' peak; on a CT liver (AMOS, held within 50 mm of
/// three landmarks; `prepare`'s validation) it brought the TRE from rest from 3.99 to 2.83 mm,
/// where σ fixed at 10 and 20 mm gave 2.81 and 3.18 mm.
fn residual_scale(residuals: &[f64]) -> f64 {
    let mut magnitudes: Vec<f64> = residuals.iter().map(|r| r.abs()).collect();
    1.4826 * mesh::stats::median(&mut magnitudes)
}

impl ShapeDeformer {
    /// The deformer of `space` (on `organ`'s mesh) with `options`.
    pub fn new(space: ShapeSpace, organ: &Organ, options: ShapeOptions) -> Result<ShapeDeformer> {
        options.validate()?;
        if space.nodes() != organ.mesh().num_nodes() {
            return Err(RegisterError::Invalid(format!(
                "the shape space has {} nodes, the organ's mesh {}",
                space.nodes(),
                organ.mesh().num_nodes()
            )));
        }
        let r = space.modes;
        let stencils = organ.surface_stencils();
        let mut surface_mean = vec![0.0; 3 * stencils.len()];
        let mut surface_basis = vec![0.0; 3 * stencils.len() * r];
        for (v, stencil) in stencils.iter().enumerate() {
            for d in 0..3 {
                let mut direction = [0.0; 3];
                direction[d] = 1.0;
                let row = 3 * v + d;
                surface_mean[row] = space.along(stencil, direction, &mut surface_basis[row * r..(row + 1) * r]);
            }
        }
        let k = options.max_modes.min(r);
        Ok(ShapeDeformer {
            surface_mean,
            surface_basis,
            triangles: organ.surface().triangles.clone(),
            space,
            options,
            z: Vec::new(),
            posterior: None,
            prior: Prior::standard(k),
            warm: false,
        })
    }

    /// The first `out.len()` modes at a match (the point of barycentric `weights` in surface
    /// `triangle`) along `normal`, into `out`; returns the mean's part along it.
    fn surface_row(&self, triangle: usize, weights: [f64; 3], normal: [f64; 3], out: &mut [f64]) -> f64 {
        let corners = self.triangles[triangle].into_iter().zip(weights);
        combine(&self.surface_mean, &self.surface_basis, self.space.modes, corners, normal, out)
    }

    /// The modes fitted at all.
    fn fitted(&self) -> usize {
        self.options.max_modes.min(self.space.modes)
    }

    /// The modes fitted at `iteration` of the frame under way.
    fn active(&self, iteration: usize) -> usize {
        let wanted = match self.warm {
            true => self.fitted(),
            false => self.options.schedule.get(iteration).copied().unwrap_or(self.fitted()),
        };
        wanted.min(self.fitted())
    }

    /// The posterior of the first `k` coefficients given `observations`, from the current
    /// coefficients (Huber's weights at their residuals; σ at least the residuals' robust spread,
    /// [`residual_scale`]): its mean and covariance.
    fn fit(&self, observations: &Observations, k: usize) -> Result<(DVector<f64>, DMatrix<f64>)> {
        let n = observations.matches.len();
        let mut jacobian = faer::Mat::<f64>::zeros(n, k);
        let (mut targets, mut residuals) = (vec![0.0; n], vec![0.0; n]);
        let mut row = vec![0.0; k];
        let current: Vec<f64> = (0..k).map(|j| self.z.get(j).copied().unwrap_or(0.0)).collect();
        for (i, m) in observations.matches.iter().enumerate() {
            let mean = self.surface_row(m.triangle, m.weights, m.normal, &mut row);
            targets[i] = mesh::dot(m.normal, m.shift) - mean;
            residuals[i] = targets[i] - row.iter().zip(&current).map(|(a, b)| a * b).sum::<f64>();
            row.iter().enumerate().for_each(|(j, r)| jacobian[(i, j)] = *r);
        }
        let sigma = self.options.sigma.max(residual_scale(&residuals));
        let mut rhs = targets;
        for (i, (y, residual)) in rhs.iter_mut().zip(&residuals).enumerate() {
            // Huber: weight 1 within the threshold, threshold / |residual| beyond.
            let weight = (HUBER * sigma / residual.abs()).min(1.0).sqrt() / sigma;
            (0..k).for_each(|j| jacobian[(i, j)] *= weight);
            *y *= weight;
        }
        let mut product = faer::Mat::<f64>::zeros(k, k);
        let jt = jacobian.transpose();
        faer::linalg::matmul::matmul(
            product.as_mut(),
            faer::Accum::Replace,
            jt,
            jacobian.as_ref(),
            1.0,
            faer::Par::rayon(0),
        );
        let jty: Vec<f64> = (0..k).map(|j| jacobian.col(j).iter().zip(&rhs).map(|(a, b)| a * b).sum()).collect();
        let prior = self.prior_of(k);
        let hessian = DMatrix::from_fn(k, k, |a, b| product[(a, b)]) + &prior.precision;
        let gradient = DVector::from_vec(jty) + &prior.precision * &prior.mean;
        let cholesky = hessian.cholesky().ok_or_else(|| {
            RegisterError::Invalid("the shape fit's normal equations are not positive definite".into())
        })?;
        let z = cholesky.solve(&gradient);
        Ok((z, cholesky.inverse()))
    }

    /// The frame's prior of its first `k` coefficients: the frame's own over all the fitted
    /// modes, the model's over fewer (a frame from rest, coarse to fine).
    fn prior_of(&self, k: usize) -> Prior {
        match k == self.prior.mean.len() {
            true => self.prior.clone(),
            false => Prior::standard(k),
        }
    }
}

impl Deformer for ShapeDeformer {
    fn start_frame(&mut self, warm: bool) {
        let k = self.fitted();
        self.warm = warm && self.posterior.is_some();
        self.prior = match (&self.posterior, self.warm) {
            (Some(posterior), true) => {
                // The coefficients move from frame to frame as z' = a z + w, w ~ N(0, (1 − a²) I), with
                // 1 − a² the widening's square: a process whose spread stays that of the model's own
                // prior N(0, I), so that a mode the cloud no longer pins down returns to it rather than
                // wander and widen without bound (a random walk, z' = z + w: on a still half view σ
                // grew from 4.9 to 9.4 mm over 100 frames and the TRE from 4.3 to 6.4 mm).
                let w2 = self.options.widening.powi(2);
                let widened = posterior * (1.0 - w2) + DMatrix::identity(k, k) * w2;
                let a = (1.0 - w2).sqrt();
                let mean = DVector::from_iterator(k, (0..k).map(|j| a * self.z.get(j).copied().unwrap_or(0.0)));
                let precision = widened.try_inverse().unwrap_or_else(|| DMatrix::identity(k, k));
                Prior { mean, precision }
            }
            _ => {
                self.z.clear();
                Prior::standard(k)
            }
        };
    }

    fn deform(&mut self, observations: &Observations, _previous: &[f64], iteration: usize) -> Result<Vec<f64>> {
        if observations.matches.is_empty() {
            return Err(RegisterError::Invalid("no cloud point matches the organ surface".into()));
        }
        let k = self.active(iteration);
        let (z, covariance) = self.fit(observations, k)?;
        self.z = z.iter().copied().collect();
        // The modes not fitted yet keep their prior: unit variance, no correlation.
        let all = self.fitted();
        let mut posterior = DMatrix::identity(all, all);
        posterior.view_mut((0, 0), (k, k)).copy_from(&covariance);
        self.posterior = Some(posterior);
        Ok(self.space.displacement(&self.z))
    }

    fn uncertainty(&mut self, stencils: &[Stencil]) -> Option<Result<Vec<f64>>> {
        let posterior = self.posterior.as_ref()?;
        let k = posterior.nrows();
        let mut rows = vec![vec![0.0; k]; 3];
        let std = stencils
            .iter()
            .map(|s| {
                for (d, row) in rows.iter_mut().enumerate() {
                    let mut direction = [0.0; 3];
                    direction[d] = 1.0;
                    self.space.along(s, direction, row);
                }
                let variance: f64 = rows
                    .iter()
                    .map(|r| {
                        let v = DVector::from_column_slice(r);
                        (v.transpose() * posterior * &v)[(0, 0)]
                    })
                    .sum();
                let floor = s.scalar(&self.space.floor);
                self.options.calibration * (variance + floor).max(0.0).sqrt()
            })
            .collect();
        Some(Ok(std))
    }
}

/// The shape space of a learned model with a basis (the reduced-order model), its leading `modes`
/// modes at most, on `organ`'s mesh, which must lie in the model's grid.
pub fn model_shape_space(model: &learn::Model, organ: &Organ, modes: usize) -> Result<ShapeSpace> {
    let learn::Model::Reduced(rom) = model else {
        return Err(RegisterError::Invalid("a shape-space registration needs a model with a basis (a ROM)".into()));
    };
    let space = rom.shape_space(modes)?;
    let to_mesh = learn::GridToMesh::new(organ.mesh(), &model.placed_grid()?)?;
    let mean = to_mesh.apply(&space.mean_field)?;
    let modes: Vec<Vec<f64>> = space.mode_fields.iter().map(|f| to_mesh.apply(f)).collect::<learn::Result<_>>()?;
    // The floor as the first channel of a field, interpolated like the modes.
    let cells = space.floor.len();
    let mut floor_field = vec![0f32; 3 * cells];
    floor_field[..cells].copy_from_slice(&space.floor);
    let floor: Vec<f64> = to_mesh.apply(&floor_field)?.chunks(3).map(|c| c[0].max(0.0)).collect();
    ShapeSpace::new(mean, &modes, &space.prior_mean, &space.prior_covariance, floor)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frame::{register_frame, RegistrationOptions};

    /// A 4 cm cube and three smooth modes of it: a vertical press growing with height, a shear,
    /// and a bulge of the top; the prior correlates the first two.
    fn cube_space() -> (Organ, Vec<Vec<f64>>, ShapeSpace) {
        let cube = mesh::box_tet([0.0; 3], [0.04; 3], [4, 4, 4]).unwrap();
        let organ = Organ::new(cube, None).unwrap();
        let field = |f: &dyn Fn(mesh::Point) -> mesh::Point| -> Vec<f64> {
            organ.mesh().nodes.iter().flat_map(|&p| f(p)).collect()
        };
        let modes = vec![
            field(&|p| [0.0, 0.0, -0.2 * p[2]]),
            field(&|p| [0.2 * p[2], 0.0, 0.0]),
            field(&|p| [0.0, 0.0, 0.01 * (p[2] / 0.04).powi(2) * (1.0 - ((p[0] - 0.02) / 0.02).powi(2))]),
        ];
        let covariance = [1.0, 0.5, 0.0, 0.5, 1.0, 0.0, 0.0, 0.0, 0.25];
        let nodes = organ.mesh().num_nodes();
        let space =
            ShapeSpace::new(vec![0.0; 3 * nodes], &modes, &[0.1, 0.0, 0.0], &covariance, vec![0.0; nodes]).unwrap();
        (organ, modes, space)
    }

    /// Whitening keeps the prior: the whitened modes' outer products sum to Φ Λ Φᵀ, and the mean
    /// is shifted by Φ μ.
    #[test]
    fn the_whitened_modes_hold_the_prior_covariance() {
        let (organ, modes, space) = cube_space();
        assert_eq!(space.modes(), 3);
        let covariance = [[1.0, 0.5, 0.0], [0.5, 1.0, 0.0], [0.0, 0.0, 0.25]];
        let top = organ.mesh().nodes.iter().position(|p| p == &[0.04, 0.04, 0.04]).unwrap();
        for (a, b) in [(3 * top, 3 * top), (3 * top + 2, 3 * top), (3 * top + 2, 3 * top + 2)] {
            let whitened: f64 = (0..3).map(|k| space.basis[a * 3 + k] * space.basis[b * 3 + k]).sum();
            let prior: f64 = (0..3)
                .flat_map(|i| (0..3).map(move |j| (i, j)))
                .map(|(i, j)| modes[i][a] * covariance[i][j] * modes[j][b])
                .sum();
            assert!((whitened - prior).abs() < 1e-15, "rows {a}, {b}: {whitened} against {prior}");
        }
        assert!((space.mean[3 * top + 2] - 0.1 * modes[0][3 * top + 2]).abs() < 1e-15);
    }

    /// A cube deformed within its shape space and seen from above (positions only): the fit
    /// finds the displacement of its hidden centre, and the posterior's σ there is smaller than
    /// the prior's.
    #[test]
    fn a_displacement_in_the_shape_space_is_recovered_from_a_cloud() {
        let (organ, modes, space) = cube_space();
        let truth: Vec<f64> = (0..modes[0].len())
            .map(|i| 0.1 * modes[0][i] + 0.6 * modes[0][i] - 0.4 * modes[1][i] + 0.3 * modes[2][i])
            .collect();
        let rest = organ.surface().vertices.clone();
        let cloud: Vec<mesh::Point> = organ
            .deformed_surface(&truth)
            .vertices
            .into_iter()
            .zip(&rest)
            .filter(|(_, r)| r[2] > 0.04 - 1e-9)
            .map(|(p, _)| p)
            .collect();
        let options = ShapeOptions { sigma: 2e-4, schedule: vec![1, 2], ..ShapeOptions::default() };
        let mut deformer = ShapeDeformer::new(space, &organ, options).unwrap();
        assert!(deformer.uncertainty(&[]).is_none(), "no σ before a fit");
        let loop_options = RegistrationOptions { view: Some([0.0, 0.0, -1.0]), iterations: 8, ..Default::default() };
        let frame = register_frame(&organ, &mut deformer, &cloud, None, &loop_options).unwrap();
        let centre = organ.mesh().nodes.iter().position(|p| p == &[0.02, 0.02, 0.02]).unwrap();
        let error: f64 = (0..3).map(|d| (frame.u[3 * centre + d] - truth[3 * centre + d]).powi(2)).sum::<f64>().sqrt();
        let motion: f64 = (0..3).map(|d| truth[3 * centre + d].powi(2)).sum::<f64>().sqrt();
        assert!(
            motion > 2e-3 && error < 0.05 * motion,
            "error {error:.2e} m at the centre, which moved {motion:.2e} m"
        );
        let stencil = Stencil(vec![(centre, 1.0)]);
        let sigma = deformer.uncertainty(std::slice::from_ref(&stencil)).unwrap().unwrap()[0];
        let mut prior = ShapeDeformer::new(deformer.space.clone(), &organ, ShapeOptions::default()).unwrap();
        prior.posterior = Some(DMatrix::identity(3, 3));
        let prior_sigma = prior.uncertainty(&[stencil]).unwrap().unwrap()[0];
        assert!(sigma < 0.5 * prior_sigma, "σ {sigma:.2e} m after the fit, {prior_sigma:.2e} m before");
    }

    /// On a stream the next frame starts from the last one's posterior: the same cloud seen again
    /// adds to what the first frame knew, so the estimate comes no farther from the truth and its σ
    /// shrinks.
    /// On a stream that never shows a mode (the top of a cube, blind to its shear along x), that
    /// mode's σ settles near the model's prior, rather than grow frame after frame as a random
    /// walk's would (by √(1 + 0.09 k) after k frames: 31 % from the 30th frame to the 60th).
    #[test]
    fn a_mode_no_frame_sees_keeps_its_prior_spread_on_a_stream() {
        let (organ, _, space) = cube_space();
        // The top's inner vertices: their matches fall on the top, whose normal is blind to x.
        let inner = |p: &&mesh::Point| p[2] > 0.04 - 1e-9 && (0..2).all(|d| p[d] > 0.005 && p[d] < 0.035);
        let cloud: Vec<mesh::Point> = organ.surface().vertices.iter().filter(inner).copied().collect();
        let mut deformer = ShapeDeformer::new(space, &organ, ShapeOptions::default()).unwrap();
        let options = RegistrationOptions { view: Some([0.0, 0.0, -1.0]), ..Default::default() };
        let top = Stencil(vec![(organ.mesh().nodes.iter().position(|p| p == &[0.04, 0.04, 0.04]).unwrap(), 1.0)]);
        let mut last: Option<Vec<f64>> = None;
        let mut sigma = Vec::new();
        for _ in 0..60 {
            let r = register_frame(&organ, &mut deformer, &cloud, last.as_deref(), &options).unwrap();
            sigma.push(deformer.uncertainty(std::slice::from_ref(&top)).unwrap().unwrap()[0]);
            last = Some(r.u);
        }
        let (first, settled, last) = (sigma[0], sigma[29], sigma[59]);
        assert!(
            last <= 1.01 * settled && last <= 1.1 * first,
            "σ {first:.2e}, {settled:.2e}, {last:.2e} m at frames 1, 30, 60"
        );
    }

    /// The residuals' robust spread is a Gaussian's standard deviation, and a tenth of the matches
    /// far off hardly moves it (where their standard deviation would be theirs).
    #[test]
    fn the_residuals_robust_spread_is_a_gaussian_s_standard_deviation_despite_outliers() {
        use rand::SeedableRng;
        use rand_distr::Distribution;
        let mut rng = rand::rngs::StdRng::seed_from_u64(12345);
        let normal = rand_distr::Normal::new(0.0, 0.003).unwrap();
        let mut residuals: Vec<f64> = (0..20_000).map(|_| normal.sample(&mut rng)).collect();
        let clean = residual_scale(&residuals);
        assert!((clean - 0.003).abs() < 0.03 * 0.003, "{clean} m against 3 mm");
        residuals.iter_mut().step_by(10).for_each(|r| *r = 0.1);
        let with_outliers = residual_scale(&residuals);
        assert!(with_outliers > clean && with_outliers < 1.2 * clean, "{with_outliers} m against {clean} m");
    }

    #[test]
    fn a_warm_frame_starts_from_the_last_posterior() {
        let (organ, modes, space) = cube_space();
        let truth: Vec<f64> = modes[0].iter().zip(&modes[2]).map(|(a, b)| 0.8 * a + 0.5 * b).collect();
        let cloud = organ.deformed_surface(&truth).vertices;
        let options = ShapeOptions { widening: 0.0, ..ShapeOptions::default() };
        let mut deformer = ShapeDeformer::new(space, &organ, options).unwrap();
        let loop_options =
            RegistrationOptions { iterations: 40, warm_iterations: 40, tolerance: 1e-7, ..Default::default() };
        let error = |u: &[f64]| u.iter().zip(&truth).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
        let top = Stencil(vec![(organ.mesh().nodes.iter().position(|p| p == &[0.04, 0.04, 0.04]).unwrap(), 1.0)]);
        let first = register_frame(&organ, &mut deformer, &cloud, None, &loop_options).unwrap();
        let sigma_first = deformer.uncertainty(std::slice::from_ref(&top)).unwrap().unwrap()[0];
        let second = register_frame(&organ, &mut deformer, &cloud, Some(&first.u), &loop_options).unwrap();
        let sigma_second = deformer.uncertainty(&[top]).unwrap().unwrap()[0];
        assert!(error(&second.u) <= error(&first.u) + 1e-9, "{} then {}", error(&first.u), error(&second.u));
        // A frame from rest would give the same σ again (same cloud, same prior).
        assert!(sigma_second < 0.95 * sigma_first, "σ {sigma_first:.2e} m, then {sigma_second:.2e} m");
    }
}
