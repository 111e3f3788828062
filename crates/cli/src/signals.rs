//! Ctrl-C (SIGINT) and SIGTERM turned into a request that a command acts on, rather than an end
//! that loses its work.

/// Has SIGINT and SIGTERM call `handler` (which must only store to atomics, or do what is as
/// safe in a signal handler).
#[cfg(unix)]
pub fn on_stop_signals(handler: extern "C" fn(libc::c_int)) {
    // SAFETY: installing a handler that is async-signal-safe, as the caller promises.
    unsafe {
        libc::signal(libc::SIGINT, handler as *const () as libc::sighandler_t);
        libc::signal(libc::SIGTERM, handler as *const () as libc::sighandler_t);
    }
}

/// A handler for [`on_stop_signals`] that asks the computations under way to stop
/// ([`fem::interrupt::request`]: a training writes its checkpoint and returns) and gives the
/// signals back their default, so that a second Ctrl-C ends the process at once.
#[cfg(unix)]
pub extern "C" fn request_interrupt(_: libc::c_int) {
    fem::interrupt::request();
    // SAFETY: signal() is async-signal-safe.
    unsafe {
        libc::signal(libc::SIGINT, libc::SIG_DFL);
        libc::signal(libc::SIGTERM, libc::SIG_DFL);
    }
}
