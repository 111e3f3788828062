//! Evaluation of a model over a sample set: per-sample errors on the grid and errors at given
//! points (target registration errors), with reproducible input corruption. Training uses it
//! for validation, `eval` for the test figures.

use std::path::Path;

use mesh::io::Field;
use serde::{Deserialize, Serialize};

use crate::data::corrupt::{item_rng, Corruption, STREAM_EVAL_CORRUPTION};
use crate::data::dataset::Samples;
use crate::data::grid::{GridMesh, CHANNELS};
use crate::model::LearnedModel;
use crate::training::metrics::{mean_euclidean_error, ErrorStats, EvalReport};
use crate::{Compute, LearnError, Result};
use mesh::embedding::Grid;
use mesh::Point;

/// Writes one sample on the placed `grid` as a hexahedral mesh ([`GridMesh`]; `.vtu`, `.vtk` or `.msh` by the
/// extension, see [`mesh::io::write_mesh`]) with the point fields `input`, `reference` (the target),
/// `prediction` (3 components each, tensor layout) and `mask`, as `augsim eval` writes its worst sample.
pub fn write_grid_sample(
    path: &Path,
    grid: &Grid,
    input: &[f32],
    target: &[f32],
    prediction: &[f32],
    mask: &[u8],
) -> Result<()> {
    let grid_mesh = GridMesh::new(grid)?;
    let mask: Vec<f32> = mask.iter().map(|&m| f32::from(m)).collect();
    let fields = [
        Field::point("input", CHANNELS, grid_mesh.field(input, CHANNELS)?),
        Field::point("reference", CHANNELS, grid_mesh.field(target, CHANNELS)?),
        Field::point("prediction", CHANNELS, grid_mesh.field(prediction, CHANNELS)?),
        Field::point("mask", 1, grid_mesh.field(&mask, 1)?),
    ];
    mesh::io::write_mesh(path, &grid_mesh.mesh, &fields).map_err(|e| match e {
        mesh::MeshError::Io { error, .. } => LearnError::io(path, error),
        e => e.into(),
    })
}

/// Runs `predictor` on the inputs of `samples` (each corrupted with its own generator, derived
/// from `seed` and the sample position) and returns the per-sample errors (m);
/// `visit(position, prediction)` sees each prediction (m). A prediction that is not finite is an
/// error: its figures would mean nothing.
pub(crate) fn evaluate_net(
    predict: impl Fn(&[f32]) -> Result<Vec<f32>>,
    samples: &Samples,
    corruption: &Corruption,
    seed: u64,
    mut visit: impl FnMut(usize, &[f32]) -> Result<()>,
) -> Result<EvalReport> {
    if samples.is_empty() {
        return Err(LearnError::InvalidInput("no samples to evaluate".into()));
    }
    let grid = samples.grid;
    let mut errors = Vec::with_capacity(samples.len());
    for p in 0..samples.len() {
        let pred = predict(&evaluation_input(samples, p, corruption, seed)?)?;
        let error = mean_euclidean_error(&pred, samples.target(p), samples.mask(p), grid)
            .map_err(|e| LearnError::InvalidInput(format!("sample {} (index {}): {e}", p, samples.indices[p])))?;
        if !error.is_finite() {
            return Err(LearnError::InvalidInput(format!(
                "sample {p} (index {}): the model predicts non-finite values (error {error}): its weights are \
                 damaged, or the input lies far outside what it learned",
                samples.indices[p]
            )));
        }
        visit(p, &pred)?;
        errors.push(error);
    }
    EvalReport::new(errors, samples.indices.clone())
}

/// The input evaluation gives the sample at `position`: corrupted with `corruption`, with that
/// sample's own reproducible draw from `seed`.
pub fn evaluation_input(samples: &Samples, position: usize, corruption: &Corruption, seed: u64) -> Result<Vec<f32>> {
    let mut input = samples.input(position).to_vec();
    if !corruption.is_identity() {
        corruption.apply(&mut input, samples.grid, &mut item_rng(seed, STREAM_EVAL_CORRUPTION, position as u64))?;
    }
    Ok(input)
}

/// Evaluates `model` on `samples`, run on `compute`: per-sample mean Euclidean errors (m), mean,
/// std, max and the worst sample. Inputs are corrupted with `corruption`, one reproducible draw
/// per sample from `seed`.
pub fn evaluate(
    model: &impl LearnedModel,
    samples: &Samples,
    corruption: &Corruption,
    seed: u64,
    compute: Compute,
) -> Result<EvalReport> {
    corruption.validate()?;
    check_samples(model, samples)?;
    let predictor = model.predictor(compute)?;
    evaluate_net(|x| predictor.predict(x), samples, corruption, seed, |_, _| Ok(()))
}

/// The samples must lie on the model's grid and be held out from its training and selection.
fn check_samples(model: &impl LearnedModel, samples: &Samples) -> Result<()> {
    if samples.grid != model.grid_shape() {
        return Err(LearnError::InvalidInput(format!(
            "samples are on grid {}, the model on grid {}",
            samples.grid,
            model.grid_shape()
        )));
    }
    model.check_unseen(samples)
}

/// Errors at given points (e.g. internal markers: target registration errors), over all
/// samples and points (m).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PointErrors {
    /// `|u_pred(x) − u_ref(x)|` over all (sample, point) pairs, both fields interpolated
    /// trilinearly on the grid (its `worst`: the pair's position, sample position × points +
    /// point; see `worst_sample`, `worst_point`).
    pub errors: ErrorStats,
    /// `|u_ref(x)|`: the error of assuming the organ did not move, for comparison.
    pub no_motion: ErrorStats,
    /// Mean error of each point over the samples.
    pub per_point_mean: Vec<f64>,
    /// The generation index of the sample with the largest error...
    #[serde(default)]
    pub worst_sample: u64,
    /// ... and the point (from 0) where it is.
    #[serde(default)]
    pub worst_point: usize,
}

/// [`evaluate`], plus the errors at `points` (positions on `grid`, the model grid placed in
/// space).
pub fn evaluate_at_points(
    model: &impl LearnedModel,
    samples: &Samples,
    corruption: &Corruption,
    seed: u64,
    grid: &Grid,
    points: &[Point],
    compute: Compute,
) -> Result<(EvalReport, PointErrors)> {
    corruption.validate()?;
    check_samples(model, samples)?;
    if points.is_empty() || grid.dims != samples.grid.dims() {
        return Err(LearnError::InvalidInput(format!(
            "{} evaluation points on a {:?} grid (samples on {})",
            points.len(),
            grid.dims,
            samples.grid
        )));
    }
    let at = |field: &[f32]| -> Result<Vec<f64>> {
        let f: Vec<f64> = field.iter().map(|v| f64::from(*v)).collect();
        Ok(grid.interpolate(&f, CHANNELS, points)?)
    };
    let norm3 = |v: &[f64]| (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    let (mut errors, mut no_motion) = (Vec::new(), Vec::new());
    let predictor = model.predictor(compute)?;
    let report = evaluate_net(
        |x| predictor.predict(x),
        samples,
        corruption,
        seed,
        |p, pred| {
            let (pred, reference) = (at(pred)?, at(samples.target(p))?);
            for (a, b) in pred.chunks_exact(3).zip(reference.chunks_exact(3)) {
                errors.push(norm3(&[a[0] - b[0], a[1] - b[1], a[2] - b[2]]));
                no_motion.push(norm3(b));
            }
            Ok(())
        },
    )?;
    let per_point_mean = (0..points.len())
        .map(|k| errors.iter().skip(k).step_by(points.len()).sum::<f64>() / samples.len() as f64)
        .collect();
    let errors = ErrorStats::from_errors(&errors)?;
    let (worst_sample, worst_point) = (samples.indices[errors.worst / points.len()], errors.worst % points.len());
    Ok((
        report,
        PointErrors {
            errors,
            no_motion: ErrorStats::from_errors(&no_motion)?,
            per_point_mean,
            worst_sample,
            worst_point,
        },
    ))
}

/// For a model that predicts its uncertainty (the reduced-order model): the share of the nodes
/// of `samples` (inside their masks) whose error lies within twice the predicted standard
/// deviation, inputs corrupted as [`evaluate`] corrupts them; `None` for a model that predicts
/// none.
pub fn uncertainty_coverage(
    model: &impl LearnedModel,
    samples: &Samples,
    corruption: &Corruption,
    seed: u64,
) -> Result<Option<f64>> {
    check_samples(model, samples)?;
    let predictor = model.predictor(Compute::Cpu)?;
    if !predictor.predicts_std() {
        return Ok(None);
    }
    let n = samples.grid.nodes();
    let (mut within, mut total) = (0usize, 0usize);
    for p in 0..samples.len() {
        let (field, std) = predictor.predict_with_std(&evaluation_input(samples, p, corruption, seed)?)?;
        // `predicts_std` said it gives one with every field.
        let std = std.ok_or_else(|| LearnError::InvalidInput("the model gave a field without its σ".into()))?;
        let target = samples.target(p);
        for v in (0..n).filter(|&v| samples.mask(p)[v] == 1) {
            let e2: f32 = (0..CHANNELS).map(|c| (field[c * n + v] - target[c * n + v]).powi(2)).sum();
            within += usize::from(e2.sqrt() <= 2.0 * std[v]);
            total += 1;
        }
    }
    Ok((total > 0).then(|| within as f64 / total as f64))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::dataset::{FieldUnit, Normalization, Sample};
    use crate::data::grid::GridShape;
    use crate::net::unet::{TrainedModel, UNet, UNetConfig};

    /// A U-Net predicts no σ: it has no coverage, told without a forward pass (the samples here
    /// hold no fields, so predicting one would fail).
    #[test]
    fn a_unet_has_no_coverage_and_is_not_run_for_it() {
        let grid = GridShape::new(4, 4, 4);
        let config = UNetConfig { base_channels: 2, depth: 1, ..UNetConfig::default() };
        let model = TrainedModel {
            net: UNet::new(&config, 1).unwrap(),
            config,
            normalization: Normalization::identity(),
            grid,
            placement: None,
            input_unit: FieldUnit::Newton,
            target_unit: FieldUnit::Metre,
            training: None,
        };
        let unread = Samples { indices: vec![0, 1], ..Samples::new(grid) };
        assert_eq!(uncertainty_coverage(&model, &unread, &Corruption::none(), 0).unwrap(), None);
    }

    /// A prediction that is not finite (damaged weights) gives no figures, but an error naming
    /// the sample.
    #[test]
    fn a_non_finite_prediction_is_an_error() {
        let grid = GridShape::new(2, 2, 2);
        let n = grid.nodes();
        let mut samples = Samples::new(grid);
        for index in [4, 7] {
            let input = vec![1.0; 3 * n];
            samples.push(&Sample { index, input, target: vec![0.0; 3 * n], mask: vec![1; n] }).unwrap();
        }
        let none = Corruption::none();
        let fine = |x: &[f32]| Ok(x.to_vec());
        assert!(evaluate_net(fine, &samples, &none, 0, |_, _| Ok(())).is_ok());
        let broken = |x: &[f32]| Ok(x.iter().map(|v| v * f32::NAN).collect());
        let e = evaluate_net(broken, &samples, &none, 0, |_, _| Ok(())).unwrap_err().to_string();
        assert!(e.contains("sample 0 (index 4): the model predicts non-finite values"), "{e}");
    }
}
