//! `augsim serve`: registration on a stream, over OpenIGTLink (see the `augsim-live` crate).

use std::net::TcpListener;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use anyhow::{Context, Result};
use app::assimilation::{AssimilationChoice, OnlineFilter};
use app::printout::organ_line;
use app::registration::{RegistrationChoice, RegistrationSpec};
use live::{Outputs, ServeOptions};
use mesh::length::LengthUnit;

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

/// The ROUKF on a stream: one step per `features` message.
struct StreamFilter(OnlineFilter);

impl live::Identification for StreamFilter {
    fn features(&self) -> usize {
        self.0.features()
    }

    fn step(
        &mut self,
        positions: &[mesh::Point],
    ) -> std::result::Result<serde_json::Map<String, serde_json::Value>, String> {
        self.0.step_points(positions)
    }
}

/// The ROUKF of an assimilation scenario for each client (its experiment, with the reference run
/// of synthetic observations, prepared once here).
fn identification(path: &std::path::Path, units: LengthUnit) -> Result<Arc<live::IdentificationFactory>> {
    let (experiment, filter) =
        AssimilationChoice { scenario: path.to_path_buf(), ..AssimilationChoice::default() }.online()?;
    let experiment = Arc::new(experiment);
    println!(
        "identify   {} ({}) from {} features per step (POINT `features`, in {units})",
        path.display(),
        filter.names().join(", "),
        filter.features()
    );
    let filters =
        live::first_then_build(Some(filter), move || OnlineFilter::new(&experiment).map_err(|e| e.to_string()));
    Ok(Arc::new(move || -> std::result::Result<Box<dyn live::Identification>, String> {
        Ok(Box::new(StreamFilter(filters()?)))
    }))
}

/// Set by SIGINT / SIGTERM: the server stops.
static STOP: AtomicBool = AtomicBool::new(false);

#[cfg(unix)]
extern "C" fn request_stop(_: libc::c_int) {
    STOP.store(true, Ordering::SeqCst);
}

/// Runs `augsim serve` until SIGINT or SIGTERM.
pub fn run(args: &ServeArgs) -> Result<()> {
    let (chosen, outputs) = (args.outputs, args.outputs.unwrap_or(Outputs::ALL));
    let spec = RegistrationSpec { time_budget_ms: Some(args.time_budget_ms), ..args.registration.spec()? };
    let units = spec.given_units;
    // Built once here so that a bad model, scenario or targets file stops the command before it
    // listens.
    let first = spec.build()?;
    if let Some(chosen) = chosen {
        for warning in chosen.check(&first).map_err(anyhow::Error::msg)? {
            eprintln!("warning    {warning}");
        }
    }
    let (coordinates, frame_line) = spec.stream_coordinates(&first);
    println!("method     {}", first.method());
    println!("{}", organ_line(first.organ(), first.targets().len()));
    println!("frame      {frame_line}");
    for w in first.warnings() {
        eprintln!("warning    {w}");
    }
    let factory = live::first_then_build(Some(first), move || spec.build().map_err(|e| format!("{e:#}")));
    let identification = match &args.assimilate {
        Some(path) => Some(identification(path, units)?),
        None => None,
    };
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
    let serve_options = ServeOptions { coordinates, outputs, identification, ..ServeOptions::default() };
    live::serve(listener, Arc::new(factory), serve_options, &STOP)?;
    println!("stopped");
    Ok(())
}
