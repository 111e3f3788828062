//! A learned model's prediction from a file, as `augsim predict` makes it: a grid tensor or a
//! point cloud in, the displacement tensor out (`.npy`), timed, and interpolated to a mesh's nodes
//! where one is given.

use std::path::Path;
use std::time::Instant;

use anyhow::{Context, Result};
use learn::{Compute, Model, PredictInput};
use mesh::length::mm;

/// Predicts with the model at `model_path` from `input` (a grid tensor, `.npy` `[3, nx, ny, nz]`,
/// or a point cloud, `.csv` or `.npy` `[N, 6]`: x, y, z and the vector in the model's input unit)
/// on `compute`, writes the displacement tensor to `output`, times `runs` predictions, and with
/// `mesh_path` writes the displacement interpolated to that mesh's nodes beside the tensor
/// (`.vtu`). Returns what it did, in lines.
pub fn predict_file(
    model_path: &Path,
    input: &Path,
    output: &Path,
    mesh_path: Option<&Path>,
    runs: usize,
    compute: Compute,
) -> Result<Vec<String>> {
    let model = Model::load(model_path)?;
    let g = model.grid();
    let read = PredictInput::read(input)?;
    let points = match &read {
        PredictInput::Points(cloud) => Some(cloud.len()),
        PredictInput::Grid(_) => None,
    };
    let t0 = Instant::now();
    let data = read
        .into_network_input(&model)
        .with_context(|| format!("{} as the input of {}", input.display(), model_path.display()))?;
    let mut lines = Vec::new();
    if let Some(n) = points {
        let what = if model.takes_forces() {
            "forces spread to the grid"
        } else {
            "displacements on their nearest grid nodes"
        };
        lines.push(format!("points     {n} ({what}, {:.2} ms)", mesh::stats::ms(t0.elapsed())));
    }
    let predictor = model.predictor(compute)?;
    let (prediction, sigma) = predictor.predict_with_std(&data)?;
    mesh::io::npy::write_f32(output, &[3, g.nx, g.ny, g.nz], &prediction)?;
    let t = learn::time_prediction(|x| predictor.predict(x), &data, 3, runs)?;
    lines.push(format!(
        "prediction {} runs: median {:.2} ms, mean {:.2} ± {:.2} ms, min {:.2}, max {:.2}",
        t.runs,
        t.median * 1e3,
        t.mean * 1e3,
        t.std * 1e3,
        t.min * 1e3,
        t.max * 1e3
    ));
    lines.push(format!("wrote      {}", output.display()));
    if let Some(sigma) = &sigma {
        let path = sigma_path(output);
        mesh::io::npy::write_f32(&path, &[g.nx, g.ny, g.nz], sigma)?;
        let inside: Vec<f64> = sigma.iter().filter(|&&s| s > 0.0).map(|&s| f64::from(s)).collect();
        let mean = inside.iter().sum::<f64>() / inside.len().max(1) as f64;
        lines.push(format!(
            "sigma      predicted at the organ's grid nodes: mean {:.3} mm, max {:.3} mm",
            mm(mean),
            mm(inside.iter().copied().fold(0.0, f64::max))
        ));
        lines.push(format!("wrote      {}", path.display()));
    }
    if let Some(mesh_path) = mesh_path {
        let vtu = output.with_extension("vtu");
        lines.push(prediction_on_mesh(&model, model_path, (&prediction, sigma.as_deref()), mesh_path, &vtu)?);
        lines.push(format!("wrote      {}", vtu.display()));
    }
    Ok(lines)
}

/// Where `predict` writes the predicted standard deviation beside its `output` tensor:
/// `NAME_sigma.npy` (`[nx, ny, nz]`, m).
fn sigma_path(output: &Path) -> std::path::PathBuf {
    let stem = output.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    output.with_file_name(format!("{stem}_sigma.npy"))
}

/// Interpolates a prediction of `model` (from `model_path`) and its standard deviation, where it
/// has one, to the nodes of the volume mesh in `mesh_path` (in the training mesh's frame) and
/// writes them as the point fields `displacement` and `sigma` (m) into `vtu`; returns the line
/// that describes it (nodes, largest displacement).
fn prediction_on_mesh(
    model: &Model,
    model_path: &Path,
    (prediction, sigma): (&[f32], Option<&[f32]>),
    mesh_path: &Path,
    vtu: &Path,
) -> Result<String> {
    let organ = mesh::io::read_mesh(mesh_path).with_context(|| format!("reading {}", mesh_path.display()))?;
    let on_mesh = || format!("{} on {}", model_path.display(), mesh_path.display());
    let u = model.field_on_mesh(prediction, &organ).with_context(on_mesh)?;
    let max = fem::post::max_displacement(&u);
    let mut fields = vec![mesh::io::Field::point("displacement", 3, u)];
    if let Some(sigma) = sigma {
        let values: Vec<f64> = sigma.iter().map(|&s| f64::from(s)).collect();
        let at_nodes = model.placed_grid()?.interpolate(&values, 1, &organ.nodes).with_context(on_mesh)?;
        fields.push(mesh::io::Field::point("sigma", 1, at_nodes));
    }
    mesh::io::write_mesh(vtu, &organ, &fields).with_context(|| format!("writing {}", vtu.display()))?;
    Ok(format!("mesh       {} nodes, max |u| {:.3} mm", organ.num_nodes(), mm(max)))
}
