//! `augsim serve`: registration on a stream, over OpenIGTLink (see the `augsim-live` crate).

use std::net::TcpListener;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use anyhow::{bail, Context, Result};
use app::assimilation::{Experiment, OnlineFilter};
use app::registration::{MethodSpec, RegistrationSpec, TargetsSpec};
use live::{Outputs, ServeOptions};
use register::Registration;

/// Options of `augsim serve`.
#[derive(Debug, clap::Args)]
pub struct ServeArgs {
    /// The registration set-up of a patient's organ, written by `augsim prepare`: its learned
    /// model or its FEM, whichever it found the better on its validation, and its targets.
    #[arg(long, conflicts_with_all = ["fem", "model", "scenario", "targets"])]
    patient: Option<PathBuf>,
    /// With --patient: register with the patient's FEM, whichever its set-up names.
    #[arg(long, requires = "patient")]
    use_fem: bool,
    /// With --patient: register with the patient's learned model, whichever its set-up names.
    #[arg(long, requires = "patient", conflicts_with = "use_fem")]
    use_model: bool,
    /// FEM registration on this static scenario (a file or a built-in name).
    #[arg(long, conflicts_with = "model", required_unless_present_any = ["model", "patient"])]
    fem: Option<PathBuf>,
    /// Registration with this learned model (a U-Net's or a reduced-order model's directory, or its
    /// model.json); the organ comes from --scenario.
    #[arg(long, requires = "scenario")]
    model: Option<PathBuf>,
    /// The dataset scenario the model was trained on (a file or a built-in name, e.g. liver_ar_t10).
    #[arg(long)]
    scenario: Option<PathBuf>,
    /// Targets at rest (CSV x,y,z, in --units); default: the mesh's `markers` and `tumour` regions.
    #[arg(long)]
    targets: Option<PathBuf>,
    /// TCP port (OpenIGTLink's is 18944).
    #[arg(long, default_value_t = 18944)]
    port: u16,
    /// Address to listen on (0.0.0.0: every interface).
    #[arg(long, default_value = "127.0.0.1")]
    host: String,
    /// Unit of every coordinate exchanged: clouds, targets, organ (mm, as 3D Slicer uses, or m).
    #[arg(long, default_value = "mm")]
    units: String,
    /// The answers to each cloud, comma-separated: targets (POINT), organ (POLYDATA), transform
    /// (TRANSFORM `rigid`, with --rigid), status (STRING).
    #[arg(long, default_value = "targets,organ,transform,status")]
    outputs: String,
    /// Most match-and-deform iterations of a client's first frame (default: the library's for --fem,
    /// the `iterations` and `warm_iterations` of the built-in registration case's network for --model).
    #[arg(long)]
    iterations: Option<usize>,
    /// Rigid pre-alignment: each client's first cloud is aligned to the organ's rest surface
    /// (trimmed point-to-plane ICP), the pose kept for its next clouds; targets and organ are sent
    /// in the cloud's frame, with the organ-to-cloud TRANSFORM `rigid`.
    #[arg(long)]
    rigid: bool,
    /// Identification on the stream: the ROUKF of this assimilation scenario (its model, unknowns
    /// and observed points) steps with each POINT `features` message (the observed points'
    /// positions, in the stream's unit, in the scenario's order) and answers a STRING `estimate`.
    #[arg(long, value_name = "SCENARIO")]
    assimilate: Option<PathBuf>,
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
fn identification(path: &std::path::Path, unit: f64) -> Result<Arc<live::IdentificationFactory>> {
    let (scenario, dir) = scenario::AssimilationScenario::load(path)?;
    let experiment = Arc::new(Experiment::prepare(scenario, &dir, None)?);
    let filter = OnlineFilter::new(&experiment)?;
    println!(
        "identify   {} ({}) from {} features per step (POINT `features`, in the stream's unit of {unit} m)",
        path.display(),
        filter.names().join(", "),
        filter.features()
    );
    // The first client takes the filter built here; the others build their own.
    let first = std::sync::Mutex::new(Some(filter));
    Ok(Arc::new(move || -> std::result::Result<Box<dyn live::Identification>, String> {
        let filter = match first.lock().map_err(|e| e.to_string())?.take() {
            Some(f) => f,
            None => OnlineFilter::new(&experiment).map_err(|e| e.to_string())?,
        };
        Ok(Box::new(StreamFilter(filter)))
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
    let unit = register::cloud::metres_per_unit(&args.units).map_err(anyhow::Error::msg).context("--units")?;
    let outputs = Outputs::parse(&args.outputs).map_err(anyhow::Error::msg).context("--outputs")?;
    let spec = match &args.patient {
        Some(dir) => RegistrationSpec::patient(
            dir,
            app::registration::PatientMethod::asked(args.use_fem, args.use_model),
            args.iterations,
            args.rigid,
        )?,
        None => {
            let method = match (&args.fem, &args.model, &args.scenario) {
                (Some(fem), _, _) => MethodSpec::Fem(fem.clone()),
                (None, Some(model), Some(scenario)) => {
                    MethodSpec::Learned { model: model.clone(), scenario: scenario.clone() }
                }
                _ => bail!("give --patient DIR, --fem SCENARIO, or --model MODEL with --scenario SCENARIO"),
            };
            let targets = args.targets.clone().map_or(TargetsSpec::Regions, TargetsSpec::File);
            RegistrationSpec { method, targets, unit, iterations: args.iterations, rigid: args.rigid }
        }
    };
    // Built once here so that a bad model, scenario or targets file stops the command before it
    // listens.
    let first = spec.build()?;
    println!("method     {}", first.method());
    println!("organ      {} nodes, {} targets", first.organ().mesh().num_nodes(), first.targets().len());
    for w in first.warnings() {
        eprintln!("warning    {w}");
    }
    let first = std::sync::Mutex::new(Some(first));
    let factory = move || -> std::result::Result<Registration, String> {
        // The first client takes the registration built above; the others build their own.
        match first.lock().map_err(|e| e.to_string())?.take() {
            Some(r) => Ok(r),
            None => spec.build().map_err(|e| format!("{e:#}")),
        }
    };
    let identification = match &args.assimilate {
        Some(path) => Some(identification(path, unit)?),
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
    println!(
        "listening  {address} (OpenIGTLink; clouds as POLYDATA or POINT named `cloud`, in {}); Ctrl-C stops",
        args.units
    );
    let serve_options = ServeOptions { unit, outputs, identification, ..ServeOptions::default() };
    live::serve(listener, Arc::new(factory), serve_options, &STOP)?;
    println!("stopped");
    Ok(())
}
