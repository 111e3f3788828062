//! `augsim assimilate`: parses the command line, runs a [`app::assimilation::Experiment`] and prints its
//! setup, progress and results.

use anyhow::Result;
use app::assimilation::{AssimilationChoice, Experiment};

use crate::bar::{print_lines, Bar};

/// Runs `augsim assimilate`.
pub fn run(args: &AssimilationChoice) -> Result<()> {
    let (sc, dir) = args.scenario()?;
    let out_dir = args.output.clone().unwrap_or_else(|| sc.output_dir());
    let files = args.files();
    println!(
        "scenario     {}{}",
        sc.name,
        if sc.description.is_empty() { String::new() } else { format!(": {}", sc.description) }
    );
    let sigma_set = sc.filter.sigma_points;
    let experiment = Experiment::prepare(sc, &dir, files.as_ref())?;
    print_lines(&experiment.setup().lines(sigma_set, files.as_ref()));
    print_lines(&Bar::during("iterations", |bar| experiment.run(&out_dir, bar))?.lines());
    println!(
        "wrote        {}/{{trace.csv, trace.json, summary.json, deformation.pvd, *.png}}{}",
        out_dir.display(),
        if files.is_none() { ", tracks/*.csv (the synthetic observations)" } else { "" }
    );
    Ok(())
}
