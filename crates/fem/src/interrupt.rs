//! A request to stop the computations under way in this process (Ctrl-C in Python, where the
//! native code runs without the interpreter's signal handling): every assembly of the internal
//! forces, and every registration iteration, checks it and fails with [`FemError::Interrupted`].

use std::sync::atomic::{AtomicBool, Ordering};

use crate::FemError;

static REQUESTED: AtomicBool = AtomicBool::new(false);

/// Asks every computation under way to stop at its next check.
pub fn request() {
    REQUESTED.store(true, Ordering::SeqCst);
}

/// Withdraws the request, once the interrupted computations have returned.
pub fn clear() {
    REQUESTED.store(false, Ordering::SeqCst);
}

/// [`FemError::Interrupted`] while a stop is requested.
pub fn check() -> Result<(), FemError> {
    match REQUESTED.load(Ordering::Relaxed) {
        true => Err(FemError::Interrupted),
        false => Ok(()),
    }
}
