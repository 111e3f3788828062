//! `augsim assimilate`: parses the command line, runs a [`app::assimilation::Experiment`] and prints its
//! setup, progress and results.

use anyhow::Result;
use app::assimilation::AssimilationChoice;

use crate::bar::{print_lines, Bar};

/// Runs `augsim assimilate`.
pub fn run(args: &AssimilationChoice) -> Result<()> {
    let prepared = args.prepare()?;
    print_lines(&prepared.lines);
    print_lines(&Bar::during("iterations", |bar| prepared.run(bar))?);
    Ok(())
}
