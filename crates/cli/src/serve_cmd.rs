//! `augsim serve`: registration on a stream, over OpenIGTLink (see the `augsim-live` crate).

use std::net::TcpListener;
use std::sync::atomic::{AtomicBool, Ordering};

use anyhow::{Context, Result};
use app::serving::ServeArgs;

use crate::bar::print_lines;

/// Set by SIGINT / SIGTERM: the server stops.
static STOP: AtomicBool = AtomicBool::new(false);

#[cfg(unix)]
extern "C" fn request_stop(_: libc::c_int) {
    STOP.store(true, Ordering::SeqCst);
}

/// Runs `augsim serve` until SIGINT or SIGTERM.
pub fn run(args: &ServeArgs) -> Result<()> {
    // The port first: one in use is said before the organ and the model load.
    let address = format!("{}:{}", args.host, args.port);
    let listener = TcpListener::bind(&address).with_context(|| format!("listening on {address}"))?;
    let setup = args.setup()?;
    print_lines(&setup.lines);
    let address = listener.local_addr().map_or(address, |a| a.to_string());
    #[cfg(unix)]
    crate::signals::on_stop_signals(request_stop);
    println!(
        "listening  {address} (OpenIGTLink; clouds as POLYDATA or POINT named `cloud`, in {}); Ctrl-C stops",
        setup.options.coordinates.unit
    );
    live::serve(listener, setup.registrations, setup.options, &STOP)?;
    println!("stopped");
    Ok(())
}
