//! `augsim mesh`: a closed surface, a segmentation's labelmap (or the built-in liver phantom) to
//! a T4 mesh or an immersed-boundary H8 grid (see `app::meshing`), with a quality report.

use std::path::Path;

use anyhow::Result;
use app::meshing::{check_mesh_output, mesh_organ, write_mesh_file, MeshOptions};

use crate::bar::print_lines;

/// Runs the command: meshes, prints the report and writes `output`.
pub fn run(options: &MeshOptions, output: &Path) -> Result<()> {
    check_mesh_output(options, output)?;
    let meshed = mesh_organ(options)?;
    print_lines(&meshed.lines()?);
    let written = write_mesh_file(output, &meshed.mesh, meshed.frame)?;
    println!("wrote      {} ({written})", output.display());
    Ok(())
}
