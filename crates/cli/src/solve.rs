//! `augsim solve`: one static solve of a scenario, written as VTK.

use std::path::Path;

use anyhow::Result;
use app::solve::solve_scenario;

use crate::bar::{print_lines, Bar};

/// Runs the scenario and writes the result; prints a summary.
pub fn run(path: &Path, output: Option<&Path>) -> Result<()> {
    let solved = Bar::during("% of the load", |bar| {
        let report = bar.reporter();
        solve_scenario(path, move |reached, iterations| {
            report((100.0 * reached) as u64, 100, &format!("{iterations} iterations"))
        })
    })?;
    let out = output.map(Path::to_path_buf).unwrap_or_else(|| solved.scenario.output_path());
    solved.write(&out)?;
    print_lines(&solved.lines()?);
    println!("wrote      {}", out.display());
    Ok(())
}
