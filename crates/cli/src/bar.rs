//! The terminal: every command draws the progress of its long runs through [`Bar`] and prints
//! the lines the application layer builds through [`print_lines`].

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressState, ProgressStyle};

/// A progress bar on the terminal counting `unit`s, with the library's note beside it; lines are
/// printed above it, indented.
pub struct Bar {
    bar: ProgressBar,
    indent: &'static str,
}

impl Bar {
    /// A bar counting `unit` (e.g. "samples"; none when empty), drawn from the first report on (lines
    /// printed before it draw no empty bar); lines printed after `indent`.
    pub fn new(unit: &str, indent: &'static str) -> Self {
        let unit = if unit.is_empty() { String::new() } else { format!(" {unit}") };
        let template = format!("{indent}{{bar:40}} {{pos}}/{{len}}{unit}, {{rate}}, {{eta}} left  {{msg}}");
        let style = ProgressStyle::with_template(&template)
            .map(|s| {
                s.with_key("rate", |state: &ProgressState, w: &mut dyn std::fmt::Write| {
                    let _ = w.write_str(&rate(state.per_sec()));
                })
            })
            .unwrap_or_else(|_| ProgressStyle::default_bar());
        Bar { bar: ProgressBar::with_draw_target(None, ProgressDrawTarget::hidden()).with_style(style), indent }
    }

    /// Runs `work` under a new bar counting `unit` (see [`Bar::new`]), which is removed from the
    /// terminal when the work ends, whether it failed or not.
    pub fn during<T>(unit: &str, work: impl FnOnce(&Bar) -> T) -> T {
        let bar = Bar::new(unit, "");
        let result = work(&bar);
        bar.finish();
        result
    }

    /// The bar's advance as a closure `(done, total, note)` that outlives the borrow (for work
    /// that keeps its observer).
    pub fn reporter(&self) -> impl Fn(u64, u64, &str) + Send + Sync + 'static {
        let bar = self.bar.clone();
        move |done, total, note| show(&bar, done, total, note)
    }

    /// Prints `text` above the bar, not indented.
    pub fn print(&self, text: &str) {
        self.bar.suspend(|| println!("{text}"));
    }

    /// Removes the bar from the terminal.
    pub fn finish(&self) {
        self.bar.finish_and_clear();
    }
}

/// A rate per second with three significant digits or so: `187/s`, `12.3/s`, `0.33/s`.
fn rate(per_sec: f64) -> String {
    match per_sec {
        r if r >= 100.0 => format!("{r:.0}/s"),
        r if r >= 10.0 => format!("{r:.1}/s"),
        r => format!("{r:.2}/s"),
    }
}

/// Draws `done` of `total` on `bar`, with `note` beside it; the first report shows the bar.
fn show(bar: &ProgressBar, done: u64, total: u64, note: &str) {
    if bar.length().is_none() {
        bar.set_draw_target(ProgressDrawTarget::stderr());
    }
    bar.set_length(total);
    bar.set_position(done);
    bar.set_message(note.to_string());
}

/// Prints lines built by the application layer ([`print_line`]).
pub fn print_lines(lines: &[String]) {
    lines.iter().for_each(|l| print_line(l));
}

/// Prints a line for the user: a warning (starting with `warning`) to standard error, any other
/// to standard output.
pub fn print_line(line: &str) {
    match line.starts_with("warning") {
        true => eprintln!("{line}"),
        false => println!("{line}"),
    }
}

impl learn::Progress for Bar {
    fn advance(&self, done: u64, total: u64, note: &str) {
        show(&self.bar, done, total, note)
    }

    fn line(&self, text: &str) {
        self.print(&format!("{}{text}", self.indent));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rates_are_given_to_about_three_digits() {
        assert_eq!(rate(187.6805), "188/s");
        assert_eq!(rate(12.345), "12.3/s");
        assert_eq!(rate(0.3312), "0.33/s");
        assert_eq!(rate(0.0), "0.00/s");
    }

    /// No report, no bar: lines printed before the work reports leave no empty `0/0` bar.
    #[test]
    fn the_bar_is_hidden_until_the_first_report() {
        let bar = Bar::new("steps", "");
        assert!(bar.bar.is_hidden() && bar.bar.length().is_none());
        show(&bar.bar, 0, 10, "");
        assert_eq!(bar.bar.length(), Some(10));
        bar.finish();
    }
}
