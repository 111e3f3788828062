//! `augsim bench`: prints the tables of `experiment::bench` (static-solve, U-Net prediction and
//! registration-frame times) as they are measured.

use anyhow::Result;
use experiment::bench::Table;

/// Runs every case of `tables` (all of them when none is named) `runs` times and prints the
/// medians.
pub fn run(runs: usize, tables: &[Table]) -> Result<()> {
    // Each table once, in the order named (`bench solves solves` is one table).
    let mut chosen: Vec<Table> = Vec::new();
    for &table in if tables.is_empty() { &Table::ALL[..] } else { tables } {
        if !chosen.contains(&table) {
            chosen.push(table);
        }
    }
    experiment::bench::bench(runs, &chosen, &mut |line| println!("{line}"))
}
