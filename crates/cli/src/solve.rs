//! `augsim solve`: one static solve of a scenario, written as VTK.

use std::path::Path;

use anyhow::Result;
use app::solve::solve_scenario;

use crate::bar::print_lines;

/// Runs the scenario and writes the result; prints a summary.
pub fn run(path: &Path, output: Option<&Path>) -> Result<()> {
    let solved = solve_scenario(path)?;
    let out = output.map(Path::to_path_buf).unwrap_or_else(|| solved.scenario.output_path());
    solved.write(&out)?;
    print_lines(&solved.lines()?);
    println!("wrote      {}", out.display());
    Ok(())
}
