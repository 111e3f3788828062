//! `augsim solve`: one static solve of a scenario, written as VTK.

use std::path::Path;

use anyhow::Result;
use app::solve::solve_and_write;

use crate::bar::{print_lines, Bar};

/// Runs the scenario and writes the result; prints a summary.
pub fn run(path: &Path, output: Option<&Path>) -> Result<()> {
    let (solved, out) = Bar::during("% of the load", |bar| {
        let report = bar.reporter();
        solve_and_write(path, output, move |reached, iterations| {
            report((100.0 * reached) as u64, 100, &format!("{iterations} iterations"))
        })
    })?;
    print_lines(&solved.lines()?);
    println!("wrote      {}", out.display());
    Ok(())
}
