//! `augsim mesh`: a closed surface, a segmentation's labelmap (or the built-in liver phantom) to
//! a T4 mesh or an immersed-boundary H8 grid (see `app::meshing`), with a quality report.

use std::path::Path;
use std::time::Instant;

use anyhow::Result;
use app::meshing::{mesh_organ, write_mesh_file, MeshOptions};

use crate::bar::print_lines;

/// Runs the command: meshes, prints the report and writes `output`.
pub fn run(options: &MeshOptions, output: &Path) -> Result<()> {
    let start = Instant::now();
    let meshed = mesh_organ(options)?;
    let elapsed = start.elapsed();
    for (topic, line) in &meshed.notes {
        println!("{topic:<10} {line}");
    }
    print_lines(&meshed.report()?);
    println!("time       {:.1} ms", elapsed.as_secs_f64() * 1e3);
    let written = write_mesh_file(output, &meshed.mesh, meshed.frame)?;
    println!("wrote      {} ({written})", output.display());
    Ok(())
}
