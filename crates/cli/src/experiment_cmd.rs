//! `augsim experiment`: runs the published experiments and writes their report.

use std::path::PathBuf;

use anyhow::Result;
use clap::Args;
use experiment::{Name, Size};

use crate::bar::{print_lines, Bar};

/// Arguments of `augsim experiment`.
#[derive(Debug, Args)]
pub struct ExperimentArgs {
    /// fem-speed, fem-convergence, fem-peer (needs CalculiX), young, springs, liver-forces, liver-ar, beam-transfer, beam-sparse, stream,
    /// held-out, or all.
    pub name: String,
    /// quick (minutes on 2 cores) or paper (the published data sizes).
    #[arg(long, default_value = "quick", value_parser = str::parse::<Size>)]
    pub size: Size,
    /// Output directory: one sub-directory per experiment, report.md and report.html.
    #[arg(long, default_value = "out/experiments")]
    pub out: PathBuf,
    /// Also rewrite the headline summary of this Markdown file (e.g. README.md, between its markers) from every
    /// result under --out.
    #[arg(long)]
    pub readme: Option<PathBuf>,
    /// Also write the full results page (e.g. docs/results.md: the summary, then every table) from every result
    /// under --out.
    #[arg(long)]
    pub results: Option<PathBuf>,
}

/// Runs `augsim experiment`.
pub fn run(args: &ExperimentArgs) -> Result<()> {
    let names = Name::chosen(&args.name)?;
    experiment::report::check_publish_paths(args.readme.as_deref(), args.results.as_deref())?;
    for name in names {
        println!("== {} ({})", name.as_str(), args.size.as_str());
        let bar = Bar::new("steps", "   ");
        let result = experiment::run(name, args.size, &args.out, &bar);
        bar.finish();
        let result = result?;
        result.lines().iter().for_each(|l| println!("   {l}"));
    }
    print_lines(&experiment::report::publish(&args.out, args.readme.as_deref(), args.results.as_deref())?);
    Ok(())
}
