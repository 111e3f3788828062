//! How a long computation (a dataset's generation, a training, a filter run) tells its caller how
//! far it has come. The library only reports; the caller (the command line, a notebook) draws it,
//! or passes [`Silent`].

/// Where a long computation reports how far it has come. Called from worker threads.
pub trait Progress: Sync {
    /// `done` of `total` units of work are done; `note` is the current state in words (e.g. the
    /// training loss), empty when there is none.
    fn advance(&self, done: u64, total: u64, note: &str);

    /// A line for the user to read (a stage starts or ends). Dropped unless the caller shows it.
    fn line(&self, _text: &str) {}
}

/// A closure `(done, total, note)` reports the advance and drops the lines.
impl<F: Fn(u64, u64, &str) + Sync> Progress for F {
    fn advance(&self, done: u64, total: u64, note: &str) {
        self(done, total, note)
    }
}

/// Reports nothing.
#[derive(Debug, Clone, Copy, Default)]
pub struct Silent;

impl Progress for Silent {
    fn advance(&self, _done: u64, _total: u64, _note: &str) {}
}

#[cfg(test)]
mod tests {
    use std::sync::Mutex;

    use super::*;

    #[test]
    fn a_closure_receives_the_advance_and_drops_lines() {
        let seen = Mutex::new(Vec::new());
        let record = |done: u64, total: u64, note: &str| seen.lock().unwrap().push(format!("{done}/{total} {note}"));
        let progress: &dyn Progress = &record;
        progress.advance(3, 10, "loss 1e-3");
        progress.line("ignored");
        Silent.advance(1, 2, "nothing");
        assert_eq!(*seen.lock().unwrap(), vec!["3/10 loss 1e-3".to_string()]);
    }
}
