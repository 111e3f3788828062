//! `augsim bench`: prints the tables of `experiment::bench` (static-solve, U-Net prediction and
//! registration-frame times) as they are measured.

use anyhow::Result;
use experiment::bench::Table;

/// Runs every case of `tables` (all of them when none is named) `runs` times and prints the
/// medians.
pub fn run(runs: usize, tables: &[Table]) -> Result<()> {
    let tables = if tables.is_empty() { &Table::ALL[..] } else { tables };
    experiment::bench::bench(runs, tables, &mut |line| println!("{line}"))
}
