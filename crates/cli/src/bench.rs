//! `augsim bench`: prints the tables of `experiment::bench` (static-solve and U-Net prediction
//! times) as they are measured.

use anyhow::Result;

/// Runs every case `runs` times and prints the medians.
pub fn run(runs: usize) -> Result<()> {
    experiment::bench::bench(runs, &mut |line| println!("{line}"))
}
