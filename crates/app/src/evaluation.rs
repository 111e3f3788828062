//! A learned model evaluated on the samples of a dataset held out from it, as `augsim eval`
//! runs it, and what it writes: `errors.csv` (each sample's error, m), `summary.json` (the
//! figures) and `worst.vtu` (the worst sample's input, target and prediction on the grid).

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use learn::{Compute, Corruption, Dataset, EvalReport, LearnedModel, Model, PointErrors, Samples};
use mesh::io::write_atomic_bytes;
use mesh::length::mm;

/// A model's errors on the held-out samples of a dataset.
pub struct Evaluation {
    /// The dataset's directory.
    pub dataset_dir: PathBuf,
    /// How the inputs were corrupted.
    pub corruption: Corruption,
    /// Samples in the dataset.
    pub total: usize,
    /// The held-out samples.
    pub test: Samples,
    /// Whether they are the test split recorded in the model (otherwise: the samples no run
    /// behind the model trained or validated on).
    pub recorded_split: bool,
    /// Each sample's error and their statistics.
    pub report: EvalReport,
    /// The errors at the dataset's markers (their count and statistics), when it has markers and
    /// a placed grid.
    pub markers: Option<(usize, PointErrors)>,
    /// Share of the nodes' errors within twice the predicted standard deviation, for a model that
    /// predicts one.
    pub coverage: Option<f64>,
    /// Why the held-out figures may not be held out after all, when a sign says so.
    pub warning: Option<String>,
}

impl Evaluation {
    /// The evaluation in words: the held-out samples, the error statistics, the TRE at the
    /// markers and the σ coverage when known.
    pub fn lines(&self) -> Vec<String> {
        let s = &self.report.stats;
        let held_out = if self.recorded_split {
            "the test split recorded in the model"
        } else {
            "those no run behind the model trained or validated on"
        };
        let mut lines = vec![
            format!("held out   {} of {} samples ({held_out})", self.test.len(), self.total),
            format!("samples    {}", self.test.len()),
            format!("mean e     {:.4e} m ({:.3} mm)", s.mean, mm(s.mean)),
            format!("std e      {:.4e} m ({:.3} mm)", s.std, mm(s.std)),
            format!("max e      {:.4e} m ({:.3} mm), sample index {}", s.max, mm(s.max), self.report.worst_index()),
        ];
        if let Some((markers, t)) = &self.markers {
            lines.push(format!(
                "TRE        {markers} markers: mean {:.3} mm, std {:.3} mm, max {:.3} mm (no-motion baseline: mean \
                 {:.3} mm, max {:.3} mm)",
                mm(t.errors.mean),
                mm(t.errors.std),
                mm(t.errors.max),
                mm(t.no_motion.mean),
                mm(t.no_motion.max)
            ));
        }
        if let Some(c) = self.coverage {
            lines.push(format!(
                "2σ         {:.1} % of the nodes' errors within twice the predicted standard deviation",
                c * 100.0
            ));
        }
        lines.extend(self.warning.iter().map(|w| format!("warning    {w}")));
        lines
    }
}

/// Evaluates `model` on the samples of `dataset` (opened from `dataset_dir`) held out from it,
/// inputs corrupted by `corruption`. An error when the grids differ or no sample is held out.
fn evaluate_held_out(
    model: &impl LearnedModel,
    dataset: &Dataset,
    dataset_dir: &Path,
    corruption: &Corruption,
    compute: Compute,
) -> Result<Evaluation> {
    if dataset.manifest().grid != model.grid_shape() {
        bail!(
            "the model was trained on grid {} but the dataset is on grid {}",
            model.grid_shape(),
            dataset.manifest().grid
        );
    }
    if let (Ok(grid), Some(data)) = (model.placed_grid(), dataset.manifest().placement()) {
        learn::GridPlacement { origin: grid.origin, spacing: grid.spacing }.check_matches(&data)?;
    }
    let input = dataset.manifest().units.input;
    if model.takes_forces() != input.is_force() {
        bail!(
            "the model takes {} as input, the dataset's inputs are {} (in {input}): a model is evaluated on inputs of \
             its own kind",
            if model.takes_forces() { "forces" } else { "displacements" },
            if input.is_force() { "forces" } else { "displacements" }
        );
    }
    corruption.check_scale(dataset.manifest().statistics.inputs.rms_norm, input)?;
    // A record without a source (a split lost, or data of unknown origin) cannot tell them either.
    let Some(provenance) = model.provenance().filter(|p| p.own.source.is_some()) else {
        bail!(
            "the model records no split of the data it was trained on (model.json: training.split), so the samples \
             it trained and was validated on cannot be told from held-out ones"
        );
    };
    let all = dataset.load_all()?;
    let test = model.held_out(&all)?;
    if test.is_empty() {
        let why = match model.trained_on(&all) {
            true => format!(
                "it holds none of the {} test samples recorded in the model, only samples it trained or was \
                 validated on",
                provenance.own.test.len()
            ),
            false => "every sample is one a run behind the model (its pre-training) trained or was validated on".into(),
        };
        bail!("{} holds no sample held out from this model: {why}", dataset_dir.display());
    }
    corruption.check_sparsity(&test)?;
    let markers = dataset.manifest().markers();
    let (report, at_markers) = match dataset.manifest().placement() {
        Some(placement) if !markers.is_empty() => {
            let grid = placement.grid(model.grid_shape())?;
            let (report, errors) = learn::evaluate_at_points(model, &test, corruption, 0, &grid, &markers, compute)?;
            (report, Some((markers.len(), errors)))
        }
        _ => (learn::evaluate(model, &test, corruption, 0, compute)?, None),
    };
    let coverage = learn::uncertainty_coverage(model, &test, corruption, 0)?;
    let near_copies =
        learn::data::split::same_seed_other_settings(all.source.as_deref(), provenance.own.source.as_deref());
    let warning = near_copies.then(|| {
        format!(
            "the dataset was drawn with the seed of the model's training data ({}) but other settings (whatever its \
             scenario is called): its draws may be near copies of the model's training draws of the same index, and \
             these figures not held out; generate it with another seed",
            provenance.own.source.as_deref().unwrap_or_default()
        )
    });
    Ok(Evaluation {
        dataset_dir: dataset_dir.to_path_buf(),
        corruption: corruption.clone(),
        total: all.len(),
        recorded_split: model.trained_on(&all),
        test,
        report,
        markers: at_markers,
        coverage,
        warning,
    })
}

/// The basis a model's predictions were projected on (`eval --project`): the reduced-order model's
/// path and its modes.
type Projection<'a> = Option<(&'a Path, usize)>;

/// The model evaluated: loaded, with its path and the projection of its predictions, if any.
struct UnderTest<'a, M> {
    model: &'a M,
    path: &'a Path,
    projection: Projection<'a>,
}

/// Writes an evaluation into `out` (created): errors.csv, summary.json (with the projection,
/// when the predictions were projected) and worst.vtu (the worst sample predicted again); returns
/// their paths.
fn write_evaluation(
    out: &Path,
    UnderTest { model, path: model_path, projection }: &UnderTest<impl LearnedModel>,
    dataset: &Dataset,
    evaluation: &Evaluation,
    compute: Compute,
) -> Result<[PathBuf; 3]> {
    let (report, s) = (&evaluation.report, &evaluation.report.stats);
    let corruption = &evaluation.corruption;
    mesh::io::create_folder(out)?;
    let errors = out.join("errors.csv");
    let rows = report.indices.iter().zip(&report.errors).map(|(i, e)| [i.to_string(), format!("{e:e}")]);
    mesh::io::csv::write_csv(&errors, &[], &["index", "error_m"], rows)?;
    let summary = serde_json::json!({
        "model": model_path, "dataset": evaluation.dataset_dir, "samples": evaluation.test.len(),
        "mean_m": s.mean, "std_m": s.std, "max_m": s.max, "worst_index": report.worst_index(),
        "corruption": corruption, "marker_errors": evaluation.markers.as_ref().map(|(_, e)| e),
        "within_2_std": evaluation.coverage,
        "projection": projection.map(|(basis, modes)| serde_json::json!({"basis": basis, "modes": modes})),
    });
    let summary_path = out.join(crate::output::SUMMARY_FILE);
    write_atomic_bytes(&summary_path, serde_json::to_string_pretty(&summary)?.as_bytes())?;
    let worst = evaluation.test.get(s.worst);
    let input = learn::evaluation_input(&evaluation.test, s.worst, corruption, 0)?;
    let prediction = model.predictor(compute)?.predict(&input)?;
    let vtu = out.join("worst.vtu");
    let grid = dataset
        .manifest()
        .placement()
        .context("the dataset manifest has no grid_origin/grid_spacing")?
        .grid(dataset.manifest().grid)?;
    learn::write_grid_sample(&vtu, &grid, &input, &worst.target, &prediction, &worst.mask)?;
    Ok([errors, summary_path, vtu])
}

/// `augsim eval`: `model_path`'s model (projected on the basis of the reduced-order model
/// `project`, when given) evaluated on the samples of `dataset_dir` held out from it, inputs
/// corrupted by `corruption`, and written into `out` (errors.csv, summary.json and worst.vtu, the
/// worst sample predicted again; a folder of an earlier run's results is refused, and without
/// `out` a fresh numbered folder under `out/eval` is taken: [`crate::output::run_dir`]); returns
/// it in lines.
pub fn eval(
    model_path: &Path,
    dataset_dir: &Path,
    project: Option<&Path>,
    corruption: &Corruption,
    compute: Compute,
    out: Option<&Path>,
) -> Result<Vec<String>> {
    crate::output::in_run_dir(out, Path::new("out/eval"), |out| {
        evaluate_in(model_path, dataset_dir, project, corruption, compute, out)
    })
}

/// [`eval`] into the folder `out`.
fn evaluate_in(
    model_path: &Path,
    dataset_dir: &Path,
    project: Option<&Path>,
    corruption: &Corruption,
    compute: Compute,
    out: &Path,
) -> Result<Vec<String>> {
    let model = Model::load(model_path)?;
    let dataset = Dataset::open_with_samples(dataset_dir)?;
    match project {
        Some(basis) => {
            let projected = learn::Projected::new(model, &Model::load(basis)?)?;
            let modes = projected.basis.info.modes;
            let mut lines = vec![format!("projected  on the basis of {} ({modes} modes)", basis.display())];
            let model = UnderTest { model: &projected, path: model_path, projection: Some((basis, modes)) };
            lines.extend(evaluate_into(model, &dataset, dataset_dir, corruption, compute, out)?);
            Ok(lines)
        }
        None => {
            let model = UnderTest { model: &model, path: model_path, projection: None };
            evaluate_into(model, &dataset, dataset_dir, corruption, compute, out)
        }
    }
}

/// [`eval`] for a loaded model (with its path and the projection of its predictions, if any):
/// evaluated, written, in lines.
fn evaluate_into(
    model: UnderTest<impl LearnedModel>,
    dataset: &Dataset,
    dataset_dir: &Path,
    corruption: &Corruption,
    compute: Compute,
    out: &Path,
) -> Result<Vec<String>> {
    let e = evaluate_held_out(model.model, dataset, dataset_dir, corruption, compute)?;
    let [errors, summary, vtu] = write_evaluation(out, &model, dataset, &e, compute)?;
    let mut lines = e.lines();
    lines.push(format!("wrote      {}, {}, {}", errors.display(), summary.display(), vtu.display()));
    Ok(lines)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_evaluation_in_words() {
        let evaluation = Evaluation {
            dataset_dir: PathBuf::from("data"),
            corruption: Corruption::none(),
            total: 10,
            test: Samples::new(learn::GridShape::new(2, 2, 2)),
            recorded_split: true,
            report: EvalReport::new(vec![0.001, 0.003], vec![8, 9]).unwrap(),
            markers: None,
            coverage: Some(0.9),
            warning: None,
        };
        let lines = evaluation.lines();
        assert_eq!(lines[0], "held out   0 of 10 samples (the test split recorded in the model)");
        assert_eq!(lines[2], "mean e     2.0000e-3 m (2.000 mm)");
        assert_eq!(lines[4], "max e      3.0000e-3 m (3.000 mm), sample index 9");
        assert_eq!(
            lines.last().unwrap(),
            "2σ         90.0 % of the nodes' errors within twice the predicted standard deviation"
        );
    }
}
