//! `augsim serve`: registration on a stream, over OpenIGTLink (see the `augsim-live` crate).

use std::net::TcpListener;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};

use anyhow::{Context, Result};
use app::registration::{RegistrationChoice, RegistrationSpec};
use app::serving::serve_setup;
use live::Outputs;

use crate::bar::print_lines;

/// Options of `augsim serve`.
#[derive(Debug, clap::Args)]
pub struct ServeArgs {
    #[command(flatten)]
    registration: RegistrationChoice,
    /// TCP port (OpenIGTLink's is 18944).
    #[arg(long, default_value_t = 18944)]
    port: u16,
    /// Address to listen on (0.0.0.0: every interface).
    #[arg(long, default_value = "127.0.0.1")]
    host: String,
    /// The answers to each cloud, comma-separated: targets (POINT), organ (POLYDATA), transform
    /// (TRANSFORM `rigid`, with --rigid), status (STRING; a refused cloud's error is sent
    /// whatever the list), structures (a POLYDATA per --structure, named by it). Default: every
    /// one.
    #[arg(long, value_name = "LIST", value_parser = Outputs::parse)]
    outputs: Option<Outputs>,
    /// Identification on the stream: the ROUKF of this assimilation scenario (its model, unknowns
    /// and observed points) steps with each POINT `features` message (the observed points'
    /// positions, in the stream's unit, in the scenario's order) and answers a STRING `estimate`.
    #[arg(long, value_name = "SCENARIO")]
    assimilate: Option<PathBuf>,
    /// Most wall time of a cloud's registration (ms), its rigid pre-alignment included: a frame past it stops at the end of its
    /// iteration under way, answers with its estimate so far and a warning, and the next cloud
    /// goes on from it, so that no cloud holds the stream for long (the FEMs' first frames on the
    /// demo take 0.25–0.41 s; a stream's next frames tens of ms).
    #[arg(long, default_value_t = live::TIME_BUDGET_MS, value_name = "MS")]
    time_budget_ms: f64,
}

/// Set by SIGINT / SIGTERM: the server stops.
static STOP: AtomicBool = AtomicBool::new(false);

#[cfg(unix)]
extern "C" fn request_stop(_: libc::c_int) {
    STOP.store(true, Ordering::SeqCst);
}

/// Runs `augsim serve` until SIGINT or SIGTERM.
pub fn run(args: &ServeArgs) -> Result<()> {
    let spec = RegistrationSpec { time_budget_ms: Some(args.time_budget_ms), ..args.registration.spec()? };
    let units = spec.given_units;
    let setup = serve_setup(spec, args.outputs, args.assimilate.as_deref())?;
    print_lines(&setup.lines);
    let address = format!("{}:{}", args.host, args.port);
    let listener = TcpListener::bind(&address).with_context(|| format!("listening on {address}"))?;
    let address = listener.local_addr().map_or(address, |a| a.to_string());
    #[cfg(unix)]
    // SAFETY: the handler only stores to an atomic, which is async-signal-safe.
    unsafe {
        libc::signal(libc::SIGINT, request_stop as *const () as libc::sighandler_t);
        libc::signal(libc::SIGTERM, request_stop as *const () as libc::sighandler_t);
    }
    println!("listening  {address} (OpenIGTLink; clouds as POLYDATA or POINT named `cloud`, in {units}); Ctrl-C stops");
    live::serve(listener, setup.registrations, setup.options, &STOP)?;
    println!("stopped");
    Ok(())
}
