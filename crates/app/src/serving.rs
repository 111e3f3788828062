//! `augsim serve`'s set-up: the registration each client gets, the coordinates of the stream,
//! the answers chosen and checked, and the ROUKF stepped with tracked features (see the
//! `augsim-live` crate for the server itself).

use std::path::{Path, PathBuf};
use std::sync::Arc;

use anyhow::Result;
use live::{IdentificationFactory, Outputs, RegistrationFactory, ServeOptions};

use crate::assimilation::{AssimilationChoice, OnlineFilter};
use crate::printout::setup_lines;
use crate::registration::{RegistrationChoice, RegistrationSpec};

/// Options of `augsim serve`.
#[derive(Debug, clap::Args)]
pub struct ServeArgs {
    /// The registration every client's frames go through.
    #[command(flatten)]
    pub registration: RegistrationChoice,
    /// TCP port (OpenIGTLink's is 18944).
    #[arg(long, default_value_t = 18944)]
    pub port: u16,
    /// Address to listen on (0.0.0.0: every interface).
    #[arg(long, default_value = "127.0.0.1")]
    pub host: String,
    /// The answers to each cloud, comma-separated: targets (POINT), organ (POLYDATA), transform
    /// (TRANSFORM `rigid`, with --rigid), status (STRING; a refused cloud's error is sent
    /// whatever the list), structures (a POLYDATA per --structure, named by it). Default: every
    /// one.
    #[arg(long, value_name = "LIST", value_parser = Outputs::parse)]
    pub outputs: Option<Outputs>,
    /// Identification on the stream: the ROUKF of this assimilation scenario (its model, unknowns
    /// and observed points) steps with each POINT `features` message (the observed points'
    /// positions, in the stream's unit, in the scenario's order) and answers a STRING `estimate`.
    #[arg(long, value_name = "SCENARIO")]
    pub assimilate: Option<PathBuf>,
    /// Most wall time of a cloud's registration (ms), its rigid pre-alignment included: a frame past it stops (a FEM's
    /// solve under way at its next iteration), answers with its estimate so far and a warning, and the next cloud
    /// goes on from it, so that no cloud holds the stream for long (a FEM's first frame, from rest,
    /// takes several times as long as a stream's next frames).
    #[arg(long, default_value_t = live::TIME_BUDGET_MS, value_name = "MS")]
    pub time_budget_ms: f64,
    /// Records each client's stream in this folder, as it goes: `client-NNN.jsonl`, one line of
    /// JSON per answer (each cloud's status with its timestamp and registered targets, each error,
    /// each estimate), in the stream's unit and frame.
    #[arg(long, value_name = "DIR")]
    pub record: Option<PathBuf>,
    /// Most clients served at once (each has a registration of its own, its memory and threads): a
    /// connection beyond them is answered by a STRING `status` error and closed.
    #[arg(long, default_value_t = ServeOptions::default().max_clients, value_name = "N",
          value_parser = crate::values::count)]
    pub max_clients: usize,
}

impl ServeArgs {
    /// The server's set-up ([`serve_setup`]) of the registration chosen, with the time budget given.
    pub fn setup(&self) -> Result<ServeSetup> {
        let spec = RegistrationSpec { time_budget_ms: Some(self.time_budget_ms), ..self.registration.spec()? };
        let mut setup = serve_setup(spec, self.outputs, self.assimilate.as_deref())?;
        setup.options.max_clients = self.max_clients;
        if let Some(dir) = &self.record {
            mesh::io::create_folder(dir)?;
            setup.lines.push(format!("record     each client's stream in {}/client-NNN.jsonl", dir.display()));
            setup.options.record = Some(dir.clone());
        }
        Ok(setup)
    }
}

/// A server set up: its options, the registration of each client, and the lines that say what
/// it does (a warning's starting with `warning`).
pub struct ServeSetup {
    /// The server's options.
    pub options: ServeOptions,
    /// Each client's registration.
    pub registrations: Arc<RegistrationFactory>,
    /// What it does, a line each.
    pub lines: Vec<String>,
}

/// The server of `spec`'s registration (given the stream's time budget,
/// [`live::TIME_BUDGET_MS`], unless it has one), answering with `outputs` (checked against the
/// registration: [`Outputs::check`]; default: every one), stepping the ROUKF of the assimilation
/// scenario `assimilate` with tracked features when given. The first registration is built here,
/// so that a bad model, scenario or targets file fails before the server listens.
pub fn serve_setup(spec: RegistrationSpec, outputs: Option<Outputs>, assimilate: Option<&Path>) -> Result<ServeSetup> {
    let spec = RegistrationSpec { time_budget_ms: spec.time_budget_ms.or(Some(live::TIME_BUDGET_MS)), ..spec };
    let first = spec.build()?;
    let mut lines = Vec::new();
    if let Some(chosen) = outputs {
        lines.extend(chosen.check(&first).map_err(anyhow::Error::msg)?.into_iter().map(|w| format!("warning    {w}")));
    }
    lines.extend(
        live::check_target_names(&first.target_names())
            .map_err(anyhow::Error::msg)?
            .into_iter()
            .map(|w| format!("warning    {w}")),
    );
    let (coordinates, frame_line) = spec.stream_coordinates(&first);
    let frame = spec.stream_frame();
    lines.extend(setup_lines(&first, &frame_line));
    let identification = match assimilate {
        Some(path) => Some(stream_filters(path, &mut lines)?),
        None => None,
    };
    let registrations = live::built_ahead(Some(first), move || spec.build().map_err(|e| format!("{e:#}")));
    let options = ServeOptions {
        coordinates,
        frame: Some(frame),
        outputs: outputs.unwrap_or(Outputs::ALL),
        identification,
        ..ServeOptions::default()
    };
    Ok(ServeSetup { options, registrations: Arc::new(registrations), lines })
}

/// The ROUKF on a stream: one step per `features` message.
struct StreamFilter(OnlineFilter);

impl live::Identification for StreamFilter {
    fn features(&self) -> usize {
        self.0.features()
    }

    fn step(&mut self, positions: &[mesh::Point]) -> Result<serde_json::Map<String, serde_json::Value>, String> {
        self.0.step_points(positions)
    }
}

/// The ROUKF of the assimilation scenario at `path` for each client (its experiment, with the
/// reference run of synthetic observations, prepared once here); a line says what it observes.
fn stream_filters(path: &Path, lines: &mut Vec<String>) -> Result<Arc<IdentificationFactory>> {
    let (experiment, filter) =
        AssimilationChoice { scenario: path.to_path_buf(), ..AssimilationChoice::default() }.online()?;
    lines.push(format!(
        "identify   {} ({}) from {} features per step (POINT `features`, in the stream's unit)",
        path.display(),
        filter.names().join(", "),
        filter.features()
    ));
    let experiment = Arc::new(experiment);
    let filters = live::built_ahead(Some(filter), move || OnlineFilter::new(&experiment).map_err(|e| e.to_string()));
    Ok(Arc::new(move || -> Result<Box<dyn live::Identification>, String> { Ok(Box::new(StreamFilter(filters()?))) }))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::registration::{MethodSpec, TargetsSpec};

    /// The stream's time budget unless the spec has one; the chosen outputs checked against the
    /// registration; the lines say the method, the organ and the frame.
    #[test]
    fn a_server_is_set_up_with_its_budget_its_checked_outputs_and_its_lines() {
        let spec = || RegistrationSpec::new(MethodSpec::fem("beam"), TargetsSpec::Points(vec![[2.5, 0.5, 0.5]]));
        let setup = serve_setup(spec(), None, None).unwrap();
        assert_eq!(setup.options.outputs, Outputs::ALL);
        let registration = (setup.registrations)().unwrap();
        assert_eq!(registration.options().time_budget_ms, Some(live::TIME_BUDGET_MS));
        assert!(setup.lines[0].starts_with("method     FEM") && setup.lines[2].starts_with("space      "));
        let budget = serve_setup(RegistrationSpec { time_budget_ms: Some(50.0), ..spec() }, None, None).unwrap();
        assert_eq!((budget.registrations)().unwrap().options().time_budget_ms, Some(50.0));
        let only_transform = Outputs { transform: true, ..Outputs::NONE };
        let e = serve_setup(spec(), Some(only_transform), None).err().unwrap().to_string();
        assert!(e.contains("--rigid"), "{e}");
        let targets_and_transform = Outputs { targets: true, ..only_transform };
        let warned = serve_setup(spec(), Some(targets_and_transform), None).unwrap();
        assert!(warned.lines[0].starts_with("warning    --outputs transform"), "{:?}", warned.lines);
    }
}
