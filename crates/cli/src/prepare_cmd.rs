//! `augsim prepare`: a patient's organ from its segmented surface to a registration set-up
//! (see `augsim_app::prepare`).

use std::time::Instant;

use anyhow::Result;
use app::prepare::{prepare, PrepareArgs, PrepareProgress, STEPS};

use crate::bar::Bar;

/// Prints the steps, with a bar and the time left over the dataset's draws and the training.
struct Printer {
    start: Instant,
    bar: Bar,
}

impl learn::Progress for Printer {
    fn advance(&self, done: u64, total: u64, note: &str) {
        self.bar.advance(done, total, note);
    }

    fn line(&self, text: &str) {
        self.bar.line(text);
    }
}

impl PrepareProgress for Printer {
    fn step(&self, index: usize, name: &str) {
        let at = self.start.elapsed().as_secs_f64();
        self.bar.print(&format!("step {}/{} {name} (at {at:.0} s)", index + 1, STEPS.len()));
    }
}

/// Runs `augsim prepare`.
pub fn run(args: &PrepareArgs) -> Result<()> {
    let printer = Printer { start: Instant::now(), bar: Bar::new("", "           ") };
    let state = prepare(&args.options(), &args.out, &printer)?;
    printer.bar.finish();
    println!("time       {:.0} s over the steps ({} s this run)", state.seconds(), printer.start.elapsed().as_secs());
    println!("wrote      {} (report.md; register with `augsim register CLOUD --patient {0}`)", args.out.display());
    Ok(())
}
