//! Learning commands: `generate`, `merge`, `train`, `eval`, `predict`.

use std::path::Path;

use anyhow::Result;
use app::generation::GenerateArgs;
use app::prediction::predict_file;
use app::training::{CorruptionArgs, DeviceArgs, TrainArgs};

use crate::bar::{print_lines, Bar};

/// `augsim generate`.
pub fn generate(args: &GenerateArgs) -> Result<()> {
    print_lines(&Bar::during("samples", |bar| app::generation::generate(args, bar))?);
    Ok(())
}

/// `augsim train`; Ctrl-C (or SIGTERM) stops it at its next step with its checkpoint written.
pub fn train(args: &TrainArgs) -> Result<()> {
    #[cfg(unix)]
    crate::signals::on_stop_signals(crate::signals::request_interrupt);
    print_lines(&Bar::during("steps", |bar| app::training::train(args, bar))?);
    Ok(())
}

/// `augsim eval`.
pub fn eval(
    model: &Path,
    dataset: &Path,
    project: Option<&Path>,
    corruption: &CorruptionArgs,
    device: DeviceArgs,
    out: Option<&Path>,
) -> Result<()> {
    let (compute, line) = device.described_for(model)?;
    println!("{line}");
    print_lines(&app::evaluation::eval(model, dataset, project, &corruption.corruption(), compute, out)?);
    Ok(())
}

/// `augsim predict`: a grid tensor (.npy `[3, nx, ny, nz]`) or a point cloud (.csv or .npy
/// `[N, 6]`: x, y, z and the vector in the model's input unit) to a displacement tensor, timed;
/// with `mesh`, the displacement interpolated to that mesh's nodes is written beside the tensor.
pub fn predict(
    model_path: &Path,
    input: &Path,
    output: &Path,
    mesh_path: Option<&Path>,
    runs: usize,
    device: DeviceArgs,
) -> Result<()> {
    let (compute, line) = device.described_for(model_path)?;
    println!("{line}");
    print_lines(&predict_file(model_path, input, output, mesh_path, runs, compute)?);
    Ok(())
}
