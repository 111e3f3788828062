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
/// on `compute`, writes the displacement tensor to `output` (and the predicted standard deviation
/// beside it, for a model that predicts one), times `runs` predictions, and with `mesh_path`
/// writes both interpolated to that mesh's nodes beside the tensor (`.vtu`). Everything is
/// computed before anything is written: a failing prediction leaves no file. Returns what it did,
/// in lines.
pub fn predict_file(
    model_path: &Path,
    input: &Path,
    output: &Path,
    mesh_path: Option<&Path>,
    runs: usize,
    compute: Compute,
) -> Result<Vec<String>> {
    let vtu = mesh_path.map(|_| output.with_extension("vtu"));
    let model = Model::load(model_path)?;
    let written: Vec<std::path::PathBuf> =
        [Some(output.to_path_buf()), matches!(model, Model::Reduced(_)).then(|| sigma_path(output)), vtu.clone()]
            .into_iter()
            .flatten()
            .collect();
    let model_files = model_files(model_path);
    let read: Vec<&Path> =
        [input].into_iter().chain(mesh_path).chain(model_files.iter().map(|p| p.as_path())).collect();
    check_distinct(&written, &read)?;
    let g = model.grid();
    let read = PredictInput::read(input)?;
    let points = match &read {
        PredictInput::Points(cloud) => Some(cloud.len()),
        PredictInput::Grid(_) => None,
    };
    let t0 = Instant::now();
    let learn::NetworkInput { field: data, given_nodes, unread_nodes } = read
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
    if unread_nodes > 0 {
        lines.push(format!(
            "warning    {unread_nodes} of the input's {given_nodes} non-zero grid nodes lie where the model reads no \
             input (the surface it was trained to see): left out"
        ));
    }
    let predictor = model.predictor(compute)?;
    let (prediction, sigma) = predictor.predict_with_std(&data)?;
    if let Some(v) = prediction.iter().chain(sigma.iter().flatten()).find(|v| !v.is_finite()) {
        anyhow::bail!(
            "{} predicts a non-finite value ({v}) from {}: its weights are damaged, or the input lies far outside \
             what it learned",
            model_path.display(),
            input.display()
        );
    }
    let on_mesh =
        mesh_path.map(|m| prediction_on_mesh(&model, model_path, (&prediction, sigma.as_deref()), m)).transpose()?;
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
    mesh::io::npy::write_f32(output, &[3, g.nx, g.ny, g.nz], &prediction)?;
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
    if let (Some((organ, fields, line)), Some(vtu)) = (on_mesh, vtu) {
        mesh::io::write_mesh(&vtu, &organ, &fields).with_context(|| format!("writing {}", vtu.display()))?;
        lines.extend([line, format!("wrote      {}", vtu.display())]);
    }
    Ok(lines)
}

/// The files of the model at `model_path` (its directory or its model.json): those of its folder.
fn model_files(model_path: &Path) -> Vec<std::path::PathBuf> {
    let folder = if model_path.is_dir() { Some(model_path) } else { model_path.parent() };
    let entries =
        folder.and_then(|f| std::fs::read_dir(if f.as_os_str().is_empty() { Path::new(".") } else { f }).ok());
    entries.into_iter().flatten().flatten().map(|e| e.path()).filter(|p| p.is_file()).collect()
}

/// Refuses a prediction whose files to write (`written`) name a file it reads (`read`) or each
/// other, before any work (`-o organ.npy --mesh organ.vtu` writes the mesh's fields to `organ.vtu`).
fn check_distinct(written: &[std::path::PathBuf], read: &[&Path]) -> Result<()> {
    let written: Vec<&Path> = written.iter().map(|p| p.as_path()).collect();
    if let Some((w, other)) = mesh::io::overwritten(&written, read) {
        anyhow::bail!(
            "{} would be written over {}: give another --output (the tensor's name also names the σ and mesh \
             files written beside it)",
            w.display(),
            other.display()
        );
    }
    Ok(())
}

/// Where `predict` writes the predicted standard deviation beside its `output` tensor:
/// `NAME_sigma.npy` (`[nx, ny, nz]`, m).
fn sigma_path(output: &Path) -> std::path::PathBuf {
    let stem = output.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    output.with_file_name(format!("{stem}_sigma.npy"))
}

/// A prediction of `model` (from `model_path`) and its standard deviation, where it has one,
/// interpolated alike ([`learn::GridToMesh`]: grid nodes inside the organ, half a cell of
/// tolerance around the grid's box) to the nodes of the volume mesh in `mesh_path` (in the
/// training mesh's frame): the mesh, its point fields `displacement` and `sigma` (m), and the
/// line that describes them (nodes, largest displacement).
fn prediction_on_mesh(
    model: &Model,
    model_path: &Path,
    (prediction, sigma): (&[f32], Option<&[f32]>),
    mesh_path: &Path,
) -> Result<(mesh::Mesh, Vec<mesh::io::Field>, String)> {
    let organ = mesh::io::read_mesh(mesh_path).with_context(|| format!("reading {}", mesh_path.display()))?;
    let on_mesh = || format!("{} on {}", model_path.display(), mesh_path.display());
    let to_mesh = model.to_mesh(&organ).with_context(on_mesh)?;
    let u = to_mesh.apply(prediction).with_context(on_mesh)?;
    let line = format!("mesh       {} nodes, max |u| {:.3} mm", organ.num_nodes(), mm(fem::post::max_displacement(&u)));
    let mut fields = vec![mesh::io::Field::point("displacement", 3, u)];
    if let Some(sigma) = sigma {
        fields.push(mesh::io::Field::point("sigma", 1, to_mesh.apply_channels(sigma, 1).with_context(on_mesh)?));
    }
    Ok((organ, fields, line))
}
