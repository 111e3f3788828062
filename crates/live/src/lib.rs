//! Registration on a stream, for navigation systems (3D Slicer with SlicerIGT, PLUS, an AR
//! headset application): an OpenIGTLink server that registers every point cloud it receives and
//! answers with the registered targets, the deformed organ surface and a status line.
//!
//! Protocol (OpenIGTLink version 1–3, messages of [`igtl`] and [`polydata`]):
//! - in: a point cloud as POLYDATA (its points; vertices optional) or POINT, device name `cloud`;
//! - out, per cloud, in this order and as chosen by [`Outputs`]: POINT `targets` (the registered
//!   targets, in the order given to the server, each named by its label, else `target-k`), POLYDATA
//!   `organ` (the registered surface with its triangles), a POLYDATA per structure that moves with
//!   the organ (a tumour, vessels: [`register::Structure`]), named as it, TRANSFORM `rigid` (the
//!   organ-to-cloud transform, when the registration options ask for a rigid pre-alignment: estimated
//!   on a client's first cloud and kept while its clouds register plausibly, estimated again after
//!   one that does not; targets and organ are then in the cloud's frame), STRING `status` (one line
//!   of JSON: `frame`, `skipped` (the clouds received since the last one registered that a newer
//!   one replaced), `ms`, `unit` (the stream's length unit, that of the lengths here),
//!   `surface_residual`, `plausible` and `warnings` (see `register::plausibility`), `inliers`,
//!   `points` (the cloud's points matched), `received` (its points as received), `iterations`,
//!   `from_rest` (the frame did not start from the previous one's displacement), and `target_sigma`
//!   (the predicted standard deviation σ at each target, for the reduced-order model; else null);
//!   or `frame` and `error`). An error is answered whatever the outputs, so that a client never waits
//!   for answers that will not come. A result that is not plausible comes as `targets_implausible`,
//!   `organ_implausible` and `rigid_implausible`, without its structures: a viewer's `targets`,
//!   `organ`, `rigid` and structures keep the last plausible answer.
//! - in: a STRING of device `reset` (any text): the next cloud registered starts from rest, its
//!   pose (with a rigid pre-alignment) estimated again, as a new client's first cloud would (after
//!   the camera or the patient moved). It has no answer of its own: the next status says
//!   `from_rest`.
//!
//! The answers to a cloud (its targets, organ, structures, rigid transform and status, or its
//! error status) carry the cloud's header timestamp, and an estimate that of its `features`, so
//! that a client tells which message each answers (one stamped 0 gets answers stamped with the
//! server's clock).
//!
//! Each client has its own registration, taken at its first cloud from one built ahead (see
//! [`built_ahead`]) and warm-started from its previous frame (from rest after one that left the
//! organ distorted, lay on it in the other frame or spanned under a tenth of it, or after a
//! `reset`). A
//! client's clouds are registered one at a time; a cloud that arrives while one
//! is being registered replaces any cloud still waiting (the newest wins: the backlog never
//! grows). A message whose header is malformed, whose body exceeds the size limit, or that stalls
//! mid-way ([`ServeOptions::stall`]), closes that client's connection (after a STRING `status`
//! error where the connection still allows it): what follows cannot be told apart; so does a
//! client that leaves its answers unread. A `cloud` whose body, its size as its header says, does
//! not decode (a CRC mismatch, a malformed POLYDATA) gets an error status, and a `features` an
//! error estimate, as does a cloud with no point, too many points or a non-finite coordinate;
//! the stream goes on. Messages of other types or devices (a navigation system's transforms, images)
//! are skipped, whatever their size, each type and device said once in a STRING `warning` (one
//! line of JSON: `warnings`; past [`MAX_IGNORED_KINDS`] of them, once that further ones are
//! ignored silently). A client that closes its side after sending still gets the answers to what
//! it sent. Other clients are never affected; at most [`ServeOptions::max_clients`] are served at
//! once, one more answered by a STRING `status` error and closed. The server's log (standard
//! error) has a line per connection, per error, per connection refused and per connection closed.
//!
//! Identification on the stream, when the server has one ([`ServeOptions::identification`], e.g.
//! the ROUKF of an assimilation scenario): POINT (or POLYDATA) `features`, the observed
//! features' positions in the scenario's order (NaN for one not seen), make one filter step each,
//! in order, answered by a STRING `estimate` (one line of JSON: `step`, `ms` and the
//! identification's fields, or `step` and `error`). A client's filter is built at its first
//! `features`; steps waiting beyond [`MAX_PENDING_STEPS`] are refused at once, so that the
//! backlog stays bounded (their refusals may thus arrive before the estimates of earlier steps).

pub mod client;
pub mod igtl;
pub mod polydata;

use std::io::{Read, Write};
use std::net::{Shutdown, TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Condvar, Mutex};
use std::time::{Duration, Instant};

pub use igtl::{decode_body, encode_message, encode_message_stamped, timestamp_seconds};
use igtl::{Content, Header, PointElement, PointMessage, StringMessage, TransformMessage};
use mesh::io::{Frame, GivenCoordinates};
use mesh::length::LengthUnit;
use mesh::Point;
use polydata::PolyData;
use register::Registration;

/// Errors of the server.
#[derive(Debug, thiserror::Error)]
pub enum LiveError {
    /// A socket could not be set up.
    #[error("{what}: {error}")]
    Io {
        /// What was being done.
        what: String,
        /// Why it failed.
        error: std::io::Error,
    },
}

/// Result type of this crate.
pub type Result<T> = std::result::Result<T, LiveError>;

/// The answers sent for each cloud.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Outputs {
    /// POINT `targets`.
    pub targets: bool,
    /// POLYDATA `organ`.
    pub organ: bool,
    /// TRANSFORM `rigid`: the organ-to-cloud transform, when a rigid pre-alignment is on.
    pub transform: bool,
    /// STRING `status` of a registered cloud (an error's status is sent whatever this says).
    pub status: bool,
    /// POLYDATA of each structure that moves with the organ, named as the structure
    /// ([`register::Structure`]).
    pub structures: bool,
}

impl Outputs {
    /// Every output.
    pub const ALL: Outputs = Outputs { targets: true, organ: true, transform: true, status: true, structures: true };
    /// No output.
    pub const NONE: Outputs =
        Outputs { targets: false, organ: false, transform: false, status: false, structures: false };

    /// Parses a comma-separated list of `targets`, `organ`, `transform`, `status`, `structures`
    /// (e.g. `targets,status`).
    pub fn parse(list: &str) -> std::result::Result<Outputs, String> {
        let mut out = Outputs::NONE;
        for name in list.split(',').map(str::trim).filter(|s| !s.is_empty()) {
            match name {
                "targets" => out.targets = true,
                "organ" => out.organ = true,
                "transform" => out.transform = true,
                "status" => out.status = true,
                "structures" => out.structures = true,
                other => {
                    return Err(format!("unknown output '{other}' (targets, organ, transform, status, structures)"))
                }
            }
        }
        if out == Outputs::NONE {
            return Err("no output chosen (targets, organ, transform, status, structures)".into());
        }
        Ok(out)
    }

    /// Checks outputs chosen by name against what `registration` can send: the transform needs a
    /// rigid pre-alignment, `structures` a structure. Such an output is an error when nothing
    /// else was chosen, else a warning (returned).
    pub fn check(&self, registration: &Registration) -> std::result::Result<Vec<String>, String> {
        let mut sendable = Outputs { transform: false, structures: false, ..*self };
        let mut unsendable = Vec::new();
        if self.transform {
            match registration.options().rigid.is_some() {
                true => sendable.transform = true,
                false => unsendable.push("transform: the rigid pre-alignment's, sent with --rigid only"),
            }
        }
        if self.structures {
            match registration.structures().is_empty() {
                false => sendable.structures = true,
                true => unsendable.push("structures: none given (--structure, or a patient's structures)"),
            }
        }
        let lines = unsendable.into_iter().map(|why| format!("--outputs {why}")).collect::<Vec<_>>();
        match sendable == Outputs::NONE {
            true => Err(lines.join("; ")),
            false => Ok(lines),
        }
    }
}

/// Checks the targets' names (a registration's [`Registration::target_names`]) against the POINT
/// message's name field ([`igtl::POINT_NAME_BYTES`]): a name cut there is a warning (returned);
/// two names that are one once cut are an error (a client tells targets by name).
pub fn check_target_names(names: &[String]) -> std::result::Result<Vec<String>, String> {
    let sent: Vec<&str> = names.iter().map(|n| igtl::sent_text(n, igtl::POINT_NAME_BYTES)).collect();
    for (i, a) in sent.iter().enumerate() {
        if let Some(j) = sent[..i].iter().position(|b| b == a) {
            return Err(format!(
                "the targets `{}` and `{}` are both named `{a}` on the stream, where a name is cut to {} bytes: \
                 shorten their labels",
                names[j],
                names[i],
                igtl::POINT_NAME_BYTES - 1
            ));
        }
    }
    let cut: Vec<String> =
        names.iter().zip(&sent).filter(|(n, s)| n.len() > s.len()).map(|(_, s)| format!("`{s}`")).collect();
    Ok(match cut.is_empty() {
        true => Vec::new(),
        false => vec![format!(
            "{} target name(s) longer than {} bytes are cut on the stream: {}",
            cut.len(),
            igtl::POINT_NAME_BYTES - 1,
            cut.join(", ")
        )],
    })
}

/// Identification on the stream: a filter that takes one set of observed feature positions per
/// step (e.g. the ROUKF of an assimilation scenario).
pub trait Identification: Send {
    /// Features per step.
    fn features(&self) -> usize;
    /// One step with the features' positions (m; NaN for a feature not seen); the estimate
    /// after it, as JSON fields.
    fn step(&mut self, positions: &[Point]) -> std::result::Result<serde_json::Map<String, serde_json::Value>, String>;
}

/// Builds a new client's [`Identification`].
pub type IdentificationFactory = dyn Fn() -> std::result::Result<Box<dyn Identification>, String> + Send + Sync;

/// Most `features` messages waiting for their step; more are refused with an error estimate.
pub const MAX_PENDING_STEPS: usize = 16;

/// The wall time a cloud's registration may take on a stream unless told otherwise (ms): a
/// frame past it answers with its estimate so far ([`RegistrationOptions::time_budget_ms`]).
///
/// [`RegistrationOptions::time_budget_ms`]: register::RegistrationOptions::time_budget_ms
pub const TIME_BUDGET_MS: f64 = 1000.0;

/// Settings of the server.
#[derive(Clone)]
pub struct ServeOptions {
    /// The coordinates on the wire: their unit (3D Slicer sends millimetres) and the change
    /// from their frame (3D Slicer sends RAS) to the organ's, and back.
    pub coordinates: GivenCoordinates,
    /// The frame the coordinates on the wire are in, where named (recorded with them).
    pub frame: Option<Frame>,
    /// The answers sent for each cloud.
    pub outputs: Outputs,
    /// Largest message body accepted (bytes); a larger one closes the connection.
    pub max_message_bytes: u64,
    /// Largest cloud registered (points); a larger one gets an error status.
    pub max_points: usize,
    /// How long a message may stall between two of its bytes, and an answer wait for a client
    /// that does not read, before the connection is closed.
    pub stall: Duration,
    /// Identification on the stream (`features` in, `estimate` out); `None`: `features` are
    /// answered with an error.
    pub identification: Option<Arc<IdentificationFactory>>,
    /// A folder where each client's stream is recorded, as it goes, in a file of its own
    /// (`client-NNN.jsonl`, the first number free): one line of JSON per event, flushed at once,
    /// so that a server stopped in any way leaves every answer it sent. The first line names the
    /// client (`peer`, `connected`: seconds since 1970, `unit` and `frame`, the stream's; the frame
    /// null where unnamed); then each cloud's status with its `timestamp` (the cloud's header
    /// timestamp in seconds since 1970, null for 0), `targets` (in the stream's unit and frame) and
    /// `cloud`, the file that holds the cloud as it came (`client-NNN/cloud-NNNNNN.npy`, float32
    /// `[n, 3]` in the stream's unit and frame, relative to the record's folder; written once the
    /// cloud is answered, a refused one too), each error status and each estimate. `None`: nothing
    /// is written.
    pub record: Option<PathBuf>,
    /// Most clients served at once; a connection beyond them is answered by a STRING `status`
    /// error and closed (each client has a registration of its own: its memory and its threads).
    pub max_clients: usize,
}

impl Default for ServeOptions {
    fn default() -> Self {
        ServeOptions {
            coordinates: GivenCoordinates::default(),
            frame: None,
            outputs: Outputs::ALL,
            max_message_bytes: 64 << 20,
            max_points: 1_000_000,
            stall: Duration::from_secs(10),
            identification: None,
            record: None,
            max_clients: 8,
        }
    }
}

/// Builds a new client's [`Registration`] (its organ, method, targets and settings).
pub type RegistrationFactory = dyn Fn() -> std::result::Result<Registration, String> + Send + Sync;

/// A factory of a client's object (a registration, an identification): the first client takes
/// `first` (built beforehand, e.g. to stop on a bad set-up before listening), each next one the
/// object `build` made ahead, on a thread of its own, from the moment the one before was taken
/// (or from now): a client that connects gets its registration at once rather than after loading
/// the model and the organ, at the cost of one object built but not yet used. A build's error
/// reaches the client that takes it.
pub fn built_ahead<T: Send + 'static>(
    first: Option<T>,
    build: impl Fn() -> std::result::Result<T, String> + Send + Sync + 'static,
) -> impl Fn() -> std::result::Result<T, String> + Send + Sync {
    type Ahead<T> = std::thread::JoinHandle<std::result::Result<T, String>>;
    let build = Arc::new(build);
    let start = move || -> Ahead<T> {
        let build = Arc::clone(&build);
        std::thread::spawn(move || build())
    };
    let first = Mutex::new(first);
    let next: Mutex<Ahead<T>> = Mutex::new(start());
    move || {
        if let Some(made) = first.lock().map_err(|e| e.to_string())?.take() {
            return Ok(made);
        }
        let mut next = next.lock().map_err(|e| e.to_string())?;
        let ready = std::mem::replace(&mut *next, start());
        ready.join().map_err(|_| "the build made ahead for this client panicked".to_string())?
    }
}

/// TCP keepalive of a client's connection: a probe after 30 s of silence, then every 10 s, until
/// the system's count of unanswered probes (9 on Linux: about 2 minutes) ends it.
const KEEPALIVE: socket2::TcpKeepalive =
    socket2::TcpKeepalive::new().with_time(Duration::from_secs(30)).with_interval(Duration::from_secs(10));

/// Most records in a record folder ([`ServeOptions::record`]): `client-001` to `client-999999`.
const MAX_RECORDS: u32 = 999_999;

/// Most distinct (type, device) pairs of ignored messages a client is warned about, one warning
/// each; further ones are ignored silently (after one warning saying so), so that a client that
/// invents device names does not grow the server's memory and log without bound.
pub const MAX_IGNORED_KINDS: usize = 64;

/// How long the accept loop sleeps between checks of the stop flag.
const POLL: Duration = Duration::from_millis(20);

/// One line of the server's log (standard error), with the time of day (UTC).
fn log(line: impl std::fmt::Display) {
    let now = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).unwrap_or_default();
    let (seconds, ms) = (now.as_secs() % 86_400, now.subsec_millis());
    eprintln!("augsim serve: {:02}:{:02}:{:02}.{ms:03} {line}", seconds / 3600, seconds / 60 % 60, seconds % 60);
}

/// A client's stream written as it goes, in a file of its own in [`ServeOptions::record`] (its
/// format there).
pub(crate) struct Record {
    file: Mutex<std::io::BufWriter<std::fs::File>>,
    /// The file, for the log.
    path: PathBuf,
}

impl Record {
    /// A new record in `dir` (created) for the client `peer`.
    fn create(dir: &Path, peer: &str, (unit, frame): (LengthUnit, Option<Frame>)) -> std::io::Result<Record> {
        std::fs::create_dir_all(dir)?;
        let (file, path) = (1..=MAX_RECORDS)
            .find_map(|n| {
                let path = dir.join(format!("client-{n:03}.jsonl"));
                match std::fs::OpenOptions::new().write(true).create_new(true).open(&path) {
                    Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => None,
                    opened => Some(opened.map(|f| (f, path))),
                }
            })
            .unwrap_or_else(|| Err(std::io::Error::other(format!("{} holds {MAX_RECORDS} records", dir.display()))))?;
        let record = Record { file: Mutex::new(std::io::BufWriter::new(file)), path };
        let connected = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).unwrap_or_default();
        let header = serde_json::json!({
            "peer": peer,
            "connected": connected.as_secs_f64(),
            "unit": unit.symbol(),
            "frame": frame.map(|f| f.to_string()),
        });
        record.write(&header)?;
        Ok(record)
    }

    /// The file of cloud `frame` ([`Record::write_cloud`]), relative to the record's folder: in
    /// a folder named as the record's file.
    fn cloud_file(&self, frame: u64) -> String {
        let stem = self.path.file_stem().map(|f| f.to_string_lossy().into_owned()).unwrap_or_default();
        format!("{stem}/cloud-{frame:06}.npy")
    }

    /// Writes cloud `frame`'s points as they came (float32 `[n, 3]`, 3 values a point) into its
    /// [`Record::cloud_file`].
    fn write_cloud(&self, frame: u64, points: &[f32]) -> std::result::Result<(), mesh::MeshError> {
        let path = self.path.with_file_name(self.cloud_file(frame));
        mesh::io::npy::write_f32(&path, &[points.len() / 3, 3], points)
    }

    /// Appends `line`.
    fn write(&self, line: &serde_json::Value) -> std::io::Result<()> {
        let mut file = self.file.lock().map_err(|_| std::io::Error::other("record poisoned"))?;
        serde_json::to_writer(&mut *file, line)?;
        file.write_all(b"\n")?;
        file.flush()
    }
}

/// Serves clients on `listener` until `stop` is set, then closes every connection and returns.
pub fn serve(
    listener: TcpListener,
    factory: Arc<RegistrationFactory>,
    options: ServeOptions,
    stop: &AtomicBool,
) -> Result<()> {
    let io = |what: &str| {
        let what = what.to_string();
        move |error| LiveError::Io { what, error }
    };
    listener.set_nonblocking(true).map_err(io("listening"))?;
    let mut clients: Vec<Client> = Vec::new();
    // An error accepting a client (out of file descriptors, a connection reset before it was
    // accepted) is the system's state of the moment: said once, and the clients served go on.
    let mut last_error = None;
    while !stop.load(Ordering::SeqCst) {
        match listener.accept() {
            Ok((stream, peer)) => {
                log(format_args!("{peer}: connected"));
                last_error = None;
                clients.retain(|c| !c.finished());
                if clients.len() >= options.max_clients {
                    refuse(stream, &peer.to_string(), &options);
                } else {
                    match Client::start(stream, peer.to_string(), factory.clone(), options.clone()) {
                        Ok(client) => clients.push(client),
                        Err(e) => log(format_args!("{peer}: the connection could not be set up: {e}")),
                    }
                }
            }
            Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => std::thread::sleep(POLL),
            Err(e) => {
                let text = e.to_string();
                if last_error.as_ref() != Some(&text) {
                    log(format_args!("accepting a client: {text}; still serving the {} connected", clients.len()));
                }
                last_error = Some(text);
                std::thread::sleep(POLL);
            }
        }
        clients.retain(|c| !c.finished());
    }
    for client in clients {
        client.stop();
    }
    Ok(())
}

/// Answers a connection beyond [`ServeOptions::max_clients`] with a STRING `status` error, then
/// closes it; says so in the log.
fn refuse(mut stream: TcpStream, peer: &str, options: &ServeOptions) {
    let error = format!(
        "the server already serves its most clients ({}): connection refused, try again later",
        options.max_clients
    );
    log(format_args!("{peer}: {error}"));
    // A fresh connection's send buffer holds the line: the write does not wait on the client.
    let status = serde_json::json!({ "error": error }).to_string();
    let sent = configure(&stream, options)
        .map_err(|e| e.to_string())
        .and_then(|()| encode_message(&StringMessage::utf8(status), "status"))
        .and_then(|bytes| stream.write_all(&bytes).map_err(|e| e.to_string()));
    if let Err(e) = sent {
        log(format_args!("{peer}: the refusal could not be sent: {e}"));
    }
    let _ = stream.shutdown(Shutdown::Both);
    log(format_args!("{peer}: connection closed"));
}

/// A connected client: its reader and registration threads.
struct Client {
    shared: Arc<Shared>,
    threads: Vec<std::thread::JoinHandle<()>>,
}

/// The newest cloud waiting, whether a reset came after it (for the next cloud), and the features
/// of the steps to come, in order, with their step numbers.
#[derive(Default)]
struct Mailbox {
    cloud: Option<Waiting>,
    reset: bool,
    features: std::collections::VecDeque<(u64, Vec<Point>, Option<u64>)>,
}

/// A cloud waiting for the registration thread (points in m).
struct Waiting {
    cloud: Cloud,
    points: Vec<Point>,
    /// Whether a reset came before it and after the last cloud registered.
    from_rest: bool,
    /// How many clouds it replaced, received after the last cloud registered.
    replaced: u64,
}

impl Mailbox {
    /// Puts a cloud in, in place of the one waiting: a reset that came before either holds for it.
    fn put_cloud(&mut self, cloud: Cloud, points: Vec<Point>) {
        let (from_rest, replaced) = self.cloud.take().map_or((false, 0), |w| (w.from_rest, w.replaced + 1));
        let from_rest = from_rest || std::mem::take(&mut self.reset);
        self.cloud = Some(Waiting { cloud, points, from_rest, replaced });
    }
}

/// What a client's two threads share.
struct Shared {
    /// The client's address, for the log.
    peer: String,
    /// What waits for the registration thread.
    waiting: Mutex<Mailbox>,
    arrived: Condvar,
    /// Set when the connection ends (either side, or the server stops).
    closed: AtomicBool,
    /// Set when the client has closed its side: what it sent is answered, then the connection ends.
    input_ended: AtomicBool,
    /// The socket, for writing (answers from the registration thread, errors from the reader).
    writer: Mutex<TcpStream>,
    /// The socket, for reading, and to shut it down without waiting for a write under way.
    socket: TcpStream,
    options: ServeOptions,
    /// The client's stream, written as it goes (see [`ServeOptions::record`]).
    record: Option<Record>,
}

impl Shared {
    fn close(&self) {
        if !self.closed.swap(true, Ordering::SeqCst) {
            log(format_args!("{}: connection closed", self.peer));
        }
        let _ = self.socket.shutdown(Shutdown::Both);
        self.arrived.notify_all();
    }

    /// Writes cloud `frame`'s `points` (m, the organ's frame) into the client's record, if any, as
    /// they came (the stream's unit and frame); a failed write is logged, and the stream goes on.
    fn record_cloud(&self, frame: u64, points: &[Point]) {
        if let Some(record) = &self.record {
            let given = self.options.coordinates;
            let wire: Vec<f32> = points.iter().flat_map(|p| given.point_out(*p).map(|x| x as f32)).collect();
            if let Err(e) = record.write_cloud(frame, &wire) {
                log(format_args!("{}: recording in {}: {e}", self.peer, record.path.display()));
            }
        }
    }

    /// Writes `line` into the client's record, if any; a failed write is logged, and the
    /// stream goes on.
    fn record(&self, line: serde_json::Value) {
        if let Some(record) = &self.record {
            if let Err(e) = record.write(&line) {
                log(format_args!("{}: recording in {}: {e}", self.peer, record.path.display()));
            }
        }
    }

    /// Logs an error of this client's and sends it as a status, whether or not the status is an
    /// output (a client told nothing would wait for answers that never come), unless the
    /// connection has ended; records it.
    /// `timestamp` is that of the cloud it answers, if any.
    fn report(&self, status: &serde_json::Value, timestamp: Option<u64>) {
        self.record(serde_json::json!({ "status": status, "timestamp": timestamp.map(timestamp_seconds) }));
        if !self.closed.load(Ordering::SeqCst) {
            log(format_args!("{}: {}", self.peer, status));
            self.send_line("status", status.to_string(), timestamp);
        }
    }

    /// Sends a message, its header stamped `timestamp` (now for `None`); a failed send (answers
    /// left unread for the stall time, a client gone) ends the connection, saying why.
    fn send<T: Content>(&self, content: &T, device: &str, timestamp: Option<u64>) -> std::result::Result<(), String> {
        let bytes = encode_message_stamped(content, device, timestamp)?;
        let mut w = self.writer.lock().map_err(|_| "writer poisoned".to_string())?;
        write_within(&mut w, &bytes, self.options.stall).map_err(|e| {
            let why = match e.kind() {
                std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut => {
                    format!("the client left its answers unread for {:.1} s", self.options.stall.as_secs_f64())
                }
                _ => format!("sending: {e}"),
            };
            drop(w);
            if !self.closed.load(Ordering::SeqCst) {
                log(format_args!("{}: {why}", self.peer));
            }
            self.close();
            why
        })
    }

    /// Sends one line of JSON as a STRING of `device` ([`Shared::send_line`]), timestamped now.
    fn send_json(&self, device: &str, json: &serde_json::Value) {
        self.send_line(device, json.to_string(), None);
    }

    /// Sends one line of text as a STRING of `device`; a failed send ends the connection, and a
    /// line a STRING cannot hold is logged.
    fn send_line(&self, device: &str, line: String, timestamp: Option<u64>) {
        if let Err(why) = self.send(&StringMessage::utf8(line), device, timestamp) {
            if !self.closed.load(Ordering::SeqCst) {
                log(format_args!("{}: {device} not sent: {why}", self.peer));
            }
        }
    }

    /// Sends an estimate (one line of JSON), stamped `timestamp` (that of its `features`), and
    /// records it.
    fn send_estimate(&self, estimate: &serde_json::Value, timestamp: Option<u64>) {
        self.record(serde_json::json!({ "estimate": estimate, "timestamp": timestamp.map(timestamp_seconds) }));
        self.send_line("estimate", estimate.to_string(), timestamp);
    }
}

/// Writes all of `bytes` within `stall` (a write timeout alone starts again at each part of a
/// message the socket takes, so a client that reads a little now and then holds a write longer).
fn write_within(stream: &mut TcpStream, mut bytes: &[u8], stall: Duration) -> std::io::Result<()> {
    let deadline = Instant::now() + stall;
    while !bytes.is_empty() {
        let left = deadline.saturating_duration_since(Instant::now());
        if left.is_zero() {
            return Err(std::io::ErrorKind::TimedOut.into());
        }
        stream.set_write_timeout(Some(left))?;
        match stream.write(bytes) {
            Ok(0) => return Err(std::io::ErrorKind::WriteZero.into()),
            Ok(n) => bytes = &bytes[n..],
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(())
}

/// Sets up an accepted connection: blocking, unbuffered, a write waits at most `options.stall`,
/// and a client gone without closing (a crash of its machine, a pulled cable) is noticed by the
/// system's probes of the idle connection ([`KEEPALIVE`]): its read fails and the connection closes.
fn configure(stream: &TcpStream, options: &ServeOptions) -> std::io::Result<()> {
    stream.set_nonblocking(false)?;
    stream.set_nodelay(true)?;
    stream.set_write_timeout(Some(options.stall))?;
    socket2::SockRef::from(stream).set_tcp_keepalive(&KEEPALIVE)
}

impl Client {
    fn start(
        stream: TcpStream,
        peer: String,
        factory: Arc<RegistrationFactory>,
        options: ServeOptions,
    ) -> std::io::Result<Client> {
        configure(&stream, &options)?;
        let socket = stream.try_clone()?;
        // A record that cannot be written is said, and the client served all the same.
        let record = options.record.as_ref().and_then(|dir| {
            match Record::create(dir, &peer, (options.coordinates.unit, options.frame)) {
                Ok(record) => {
                    log(format_args!("{peer}: recorded in {}", record.path.display()));
                    Some(record)
                }
                Err(e) => {
                    log(format_args!("{peer}: not recorded in {}: {e}", dir.display()));
                    None
                }
            }
        });
        let shared = Arc::new(Shared {
            peer,
            waiting: Mutex::new(Mailbox::default()),
            arrived: Condvar::new(),
            closed: AtomicBool::new(false),
            input_ended: AtomicBool::new(false),
            writer: Mutex::new(stream),
            socket,
            options,
            record,
        });
        let (s1, s2) = (shared.clone(), shared.clone());
        let threads = vec![
            std::thread::spawn(move || read_messages(&s1)),
            std::thread::spawn(move || serve_client(&s2, &*factory)),
        ];
        Ok(Client { shared, threads })
    }

    fn finished(&self) -> bool {
        self.threads.iter().all(|t| t.is_finished())
    }

    fn stop(self) {
        self.shared.close();
        for t in self.threads {
            let _ = t.join();
        }
    }
}

/// Reads messages until the connection ends; keeps the newest cloud, and the features of the
/// steps to come, for the registration thread.
fn read_messages(shared: &Shared) {
    let (mut frame, mut step) = (0u64, 0u64);
    let mut ignored = Ignored::default();
    let to_metres = |points: Vec<[f32; 3]>| -> Vec<Point> {
        points.into_iter().map(|p| shared.options.coordinates.point_in(p.map(f64::from))).collect()
    };
    while !shared.closed.load(Ordering::SeqCst) {
        match read_message(&shared.socket, &shared.options) {
            Ok(Incoming::Cloud(points, timestamp)) => {
                frame += 1;
                let cloud = to_metres(points);
                let stamp = Cloud { frame, timestamp: stamped(timestamp) };
                shared.waiting.lock().unwrap_or_else(|e| e.into_inner()).put_cloud(stamp, cloud);
                shared.arrived.notify_one();
            }
            // The features are points of the assimilation scenario's own mesh, in its frame: only their
            // unit is converted, not the registration organ's frame.
            Ok(Incoming::Features(points, timestamp)) => {
                step += 1;
                let mut waiting = shared.waiting.lock().unwrap_or_else(|e| e.into_inner());
                if waiting.features.len() >= MAX_PENDING_STEPS {
                    drop(waiting);
                    let error = format!(
                        "{MAX_PENDING_STEPS} steps are already waiting: step refused (taken as one with no feature \
                         seen)"
                    );
                    log(format_args!("{}: step {step}: {error}", shared.peer));
                    shared.send_estimate(&serde_json::json!({ "step": step, "error": error }), stamped(timestamp));
                    continue;
                }
                let units = shared.options.coordinates.unit;
                let features = points.into_iter().map(|p| units.point_to_metres(p.map(f64::from))).collect();
                waiting.features.push_back((step, features, stamped(timestamp)));
                drop(waiting);
                shared.arrived.notify_one();
            }
            // Its body does not decode, but the next message starts where its header says: answered
            // with an error, the stream goes on.
            Ok(Incoming::Undecodable { cloud, error, timestamp }) => {
                if cloud {
                    frame += 1;
                    shared.report(&serde_json::json!({ "frame": frame, "error": error }), stamped(timestamp));
                } else {
                    step += 1;
                    log(format_args!("{}: step {step}: {error}", shared.peer));
                    shared.send_estimate(&serde_json::json!({ "step": step, "error": error }), stamped(timestamp));
                }
            }
            Ok(Incoming::Reset) => {
                log(format_args!("{}: reset: the next cloud starts from rest", shared.peer));
                shared.waiting.lock().unwrap_or_else(|e| e.into_inner()).reset = true;
            }
            Ok(Incoming::Other { kind, device }) => ignored.warn(shared, kind, device),
            Ok(Incoming::Closed) => {
                // What the client sent is still answered; the registration thread then closes.
                shared.input_ended.store(true, Ordering::SeqCst);
                shared.arrived.notify_all();
                return;
            }
            // A connection the server ended (stopping, a client that did not read) is no error.
            Err(_) if shared.closed.load(Ordering::SeqCst) => break,
            Err(e) => {
                shared.report(&serde_json::json!({ "error": e }), None);
                break;
            }
        }
    }
    shared.close();
}

/// The messages of a client's that are ignored, said once per type and device: a navigation
/// system may send other messages often. Past [`MAX_IGNORED_KINDS`] pairs, once that the next
/// ones are ignored silently.
#[derive(Default)]
struct Ignored {
    /// The (type, device) pairs said so.
    said: std::collections::HashSet<(String, String)>,
    /// Whether a pair past them came (and was said to be ignored silently).
    silent: bool,
}

impl Ignored {
    /// Warns the client (and logs) that messages of `kind` from `device` are ignored, unless said.
    fn warn(&mut self, shared: &Shared, kind: String, device: String) {
        let pair = (kind, device);
        if self.silent || self.said.contains(&pair) {
            return;
        }
        let warning = if self.said.len() >= MAX_IGNORED_KINDS {
            self.silent = true;
            format!(
                "messages of {MAX_IGNORED_KINDS} types and devices are ignored: further ones ({} from device '{}' \
                 first) are ignored without a warning",
                pair.0, pair.1
            )
        } else {
            let features = match shared.options.identification {
                Some(_) => ", tracked features from 'features'",
                None => "",
            };
            let warning = format!(
                "{} messages from device '{}' are ignored: clouds come as POLYDATA or POINT from device 'cloud'\
                 {features}, and a STRING from device 'reset' restarts from rest",
                pair.0, pair.1
            );
            self.said.insert(pair);
            warning
        };
        log(format_args!("{}: {warning}", shared.peer));
        shared.send_json("warning", &serde_json::json!({ "warnings": [warning] }));
    }
}

/// What the next message of a stream is.
enum Incoming {
    /// The points of a `cloud` POLYDATA or POINT message (wire units) and its header timestamp.
    Cloud(Vec<[f32; 3]>, u64),
    /// The points of a `features` POLYDATA or POINT message (wire units) and its header timestamp.
    Features(Vec<[f32; 3]>, u64),
    /// A `cloud` (or else `features`) message whose body, read whole, does not decode: why, and
    /// its header timestamp.
    Undecodable { cloud: bool, error: String, timestamp: u64 },
    /// A STRING of device `reset` (its text ignored): the next cloud starts from rest.
    Reset,
    /// Any other message (ignored): its type and device name.
    Other { kind: String, device: String },
    /// The peer closed the connection between messages.
    Closed,
}

/// The next message from the stream; an error for a truncated, stalled or oversized one, or one
/// whose header is malformed (a body that does not decode is [`Incoming::Undecodable`]). Between
/// messages the stream may wait for as long as the client likes; within one, no longer than
/// [`ServeOptions::stall`] between bytes. A message that is not a `cloud` or `features` is skipped
/// unread, whatever its size (a STRING `reset` too: its text is not read); the body of one that is
/// grows with the bytes received, not with the size its header announces.
fn read_message(mut stream: &TcpStream, options: &ServeOptions) -> std::result::Result<Incoming, String> {
    let (max_body, stall) = (options.max_message_bytes, options.stall);
    let mut header = [0u8; Header::SIZE];
    stream.set_read_timeout(None).map_err(|e| format!("reading a message: {e}"))?;
    match stream.read(&mut header[..1]) {
        Ok(0) => return Ok(Incoming::Closed),
        Ok(_) => {}
        Err(e) => return Err(format!("reading a message: {e}")),
    }
    stream.set_read_timeout(Some(stall)).map_err(|e| format!("reading a message: {e}"))?;
    let stalled = |what: &str, e: std::io::Error| match e.kind() {
        std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut => {
            format!("{what}: nothing more came for {:.1} s", stall.as_secs_f64())
        }
        _ => format!("{what}: {e}"),
    };
    stream.read_exact(&mut header[1..]).map_err(|e| stalled("truncated message header", e))?;
    let header = Header::decode(&header).map_err(|e| format!("malformed message header: {e}"))?;
    let (kind, device) = (header.type_name.as_str(), header.device_name.as_str());
    if !matches!(device, "cloud" | "features") || !matches!(kind, "POLYDATA" | "POINT") {
        let skipped = std::io::copy(&mut stream.take(header.body_size), &mut std::io::sink())
            .map_err(|e| stalled("truncated message body", e))?;
        if skipped < header.body_size {
            return Err(format!("truncated message body: {skipped} of {} bytes", header.body_size));
        }
        if (kind, device) == ("STRING", "reset") {
            return Ok(Incoming::Reset);
        }
        return Ok(Incoming::Other { kind: kind.to_string(), device: device.to_string() });
    }
    if header.body_size > max_body {
        return Err(format!("message body of {} bytes exceeds the limit of {max_body}", header.body_size));
    }
    let size = header.body_size;
    let mut body = Vec::with_capacity(size.min(1 << 20) as usize);
    let read = stream.take(size).read_to_end(&mut body).map_err(|e| stalled("truncated message body", e))?;
    if (read as u64) < size {
        return Err(format!("truncated message body: {read} of {size} bytes"));
    }
    let points = match kind {
        "POLYDATA" => decode_body::<PolyData>(&header, &body).map(|p| p.points),
        _ => decode_body::<PointMessage>(&header, &body).map(|p| p.points.iter().map(|p| p.position).collect()),
    };
    let (cloud, timestamp) = (device == "cloud", header.timestamp);
    Ok(match points {
        Ok(points) if cloud => Incoming::Cloud(points, timestamp),
        Ok(points) => Incoming::Features(points, timestamp),
        Err(error) => Incoming::Undecodable { cloud, error, timestamp },
    })
}

/// Registers the newest cloud, frame after frame, and makes the identification steps, until the
/// connection ends (or the client has closed its side and everything it sent is answered).
fn serve_client(shared: &Shared, factory: &RegistrationFactory) {
    // Built at the first cloud: a client that only connects, or only sends features, costs none.
    let mut registration: Option<Registration> = None;
    let mut identification: Option<Box<dyn Identification>> = None;
    // The steps the filter has made: its clock, kept on the stream's step numbers.
    let mut taken = 0;
    loop {
        let work = {
            let mut waiting = shared.waiting.lock().unwrap_or_else(|e| e.into_inner());
            loop {
                if shared.closed.load(Ordering::SeqCst) {
                    return;
                }
                // Steps first, in order: they are few and each counts; then the newest cloud.
                if let Some((step, features, timestamp)) = waiting.features.pop_front() {
                    break Work::Step(step, features, timestamp);
                }
                if let Some(cloud) = waiting.cloud.take() {
                    break Work::Cloud(cloud);
                }
                if shared.input_ended.load(Ordering::SeqCst) {
                    drop(waiting);
                    shared.close();
                    return;
                }
                waiting = shared.arrived.wait(waiting).unwrap_or_else(|e| e.into_inner());
            }
        };
        match work {
            Work::Cloud(Waiting { cloud: frame, points: cloud, from_rest, replaced }) => {
                let registration = match &mut registration {
                    Some(r) => r,
                    None => match factory() {
                        Ok(r) => registration.insert(r),
                        Err(e) => {
                            let error = format!("setting up the registration: {e}");
                            shared.report(&serde_json::json!({ "error": error }), frame.timestamp);
                            shared.close();
                            return;
                        }
                    },
                };
                if from_rest {
                    registration.reset();
                }
                if let Err(e) = answer(shared, registration, (frame, replaced), &cloud) {
                    shared.report(&serde_json::json!({ "frame": frame.frame, "error": e }), frame.timestamp);
                }
                // Once answered (its latency untouched), the cloud is kept, refused or not.
                shared.record_cloud(frame.frame, &cloud);
            }
            Work::Step(step, features, timestamp) => {
                let start = Instant::now();
                let estimate =
                    identify(&shared.options, &mut identification, (&mut taken, step), &features).map(|mut fields| {
                        fields.insert("ms".into(), mesh::stats::ms(start.elapsed()).into());
                        fields
                    });
                let mut answer = match estimate {
                    Ok(fields) => fields,
                    Err(e) => {
                        log(format_args!("{}: step {step}: {e}", shared.peer));
                        serde_json::Map::from_iter([("error".to_string(), e.into())])
                    }
                };
                answer.insert("step".into(), step.into());
                shared.send_estimate(&serde_json::Value::Object(answer), timestamp);
            }
        }
    }
}

/// A header timestamp as the answers carry it: `None` (the server's clock) for 0.
fn stamped(timestamp: u64) -> Option<u64> {
    (timestamp != 0).then_some(timestamp)
}

/// Which cloud of a client's: its frame number, counted by the server from 1, and its header
/// timestamp (`None` for 0), which the answers to it carry.
#[derive(Clone, Copy, Debug)]
struct Cloud {
    frame: u64,
    timestamp: Option<u64>,
}

/// What the registration thread does next.
enum Work {
    /// Register a cloud.
    Cloud(Waiting),
    /// Make an identification step (step number, features in m, the header timestamp of its
    /// message).
    Step(u64, Vec<Point>, Option<u64>),
}

/// One identification step with `features`, building the client's filter at its first step.
fn identify(
    options: &ServeOptions,
    identification: &mut Option<Box<dyn Identification>>,
    (taken, step): (&mut u64, u64),
    features: &[Point],
) -> std::result::Result<serde_json::Map<String, serde_json::Value>, String> {
    if identification.is_none() {
        let factory = options.identification.as_ref().ok_or("this server has no identification (features)")?;
        *identification = Some(factory().map_err(|e| format!("setting up the identification: {e}"))?);
    }
    let filter = identification.as_mut().ok_or("no identification")?;
    // The filter's clock follows the stream's steps: a step refused (features that did not decode,
    // a backlog full, features it cannot take) is taken as one with no feature seen, so that the
    // load of every later step stays the one its number says.
    let unseen = vec![[f64::NAN; 3]; filter.features()];
    while *taken + 1 < step {
        filter.step(&unseen)?;
        *taken += 1;
    }
    *taken = step;
    let refused = if features.len() != filter.features() {
        Some(format!("{} features sent, the identification observes {}", features.len(), filter.features()))
    } else if features.iter().flatten().any(|x| x.is_infinite()) {
        Some("a feature has an infinite coordinate (NaN marks one not seen)".to_string())
    } else {
        None
    };
    let why = match refused {
        None => match filter.step(features) {
            Ok(estimate) => return Ok(estimate),
            // The filter stays as it was.
            Err(why) => why,
        },
        Some(why) => why,
    };
    filter.step(&unseen)?;
    Err(format!("{why}: taken as a step with no feature seen"))
}

/// The status as one line of JSON; the targets' σ left out, saying so in its warnings, when the
/// line would be longer than a STRING holds (thousands of targets).
fn status_line(mut status: serde_json::Value) -> String {
    let line = status.to_string();
    if line.len() <= usize::from(u16::MAX) || status["target_sigma"].is_null() {
        return line;
    }
    status["target_sigma"] = serde_json::Value::Null;
    let why = format!(
        "target_sigma left out: the status ({} bytes) would not fit in an OpenIGTLink STRING ({} bytes)",
        line.len(),
        u16::MAX
    );
    if let Some(warnings) = status["warnings"].as_array_mut() {
        warnings.push(why.into());
    }
    status.to_string()
}

/// Registers one cloud, `points` (`skipped`: the clouds it replaced), and sends the chosen
/// answers, stamped as the cloud.
fn answer(
    shared: &Shared,
    registration: &mut Registration,
    (cloud, skipped): (Cloud, u64),
    points: &[Point],
) -> std::result::Result<(), String> {
    let options = &shared.options;
    if points.len() > options.max_points {
        return Err(format!(
            "cloud of {} points exceeds the limit of {}: thin it before sending (a frame matches a few thousand \
             points of a cloud, evenly spaced)",
            points.len(),
            options.max_points
        ));
    }
    let start = Instant::now();
    let tracked = registration.register(points).map_err(|e| e.to_string())?;
    let (result, given) = (&tracked.registration, options.coordinates);
    let back = tracked.given_back(given);
    let to_wire = |p: &Point| given.point_out(*p).map(|x| x as f32);
    // The status and the record of the registration itself, before any answer is sent (a send
    // that fails ends the connection, not the record).
    let status = serde_json::json!({
        "frame": cloud.frame,
        "skipped": skipped,
        "ms": mesh::stats::ms(start.elapsed()),
        "unit": given.unit.symbol(),
        "surface_residual": back.surface_residual,
        "plausible": result.plausible(),
        "warnings": result.warnings,
        "inliers": result.inliers,
        "points": result.points,
        "received": points.len(),
        "iterations": result.iterations,
        "from_rest": result.from_rest,
        "target_sigma": back.target_std,
    });
    if let Some(record) = &shared.record {
        let (timestamp, targets) = (cloud.timestamp.map(timestamp_seconds), &back.targets);
        let file = record.cloud_file(cloud.frame);
        shared
            .record(serde_json::json!({ "status": status, "timestamp": timestamp, "targets": targets, "cloud": file }));
    }
    // A result that is not plausible comes under names that say so (`targets_implausible`,
    // `organ_implausible`, `rigid_implausible`), without its structures (whose names fill a device
    // name's 20 bytes): a viewer's `targets`, `organ`, `rigid` and structures keep the last
    // plausible answer.
    let verdict = result.verdict_suffix();
    if options.outputs.targets {
        let device = format!("targets{verdict}");
        let points = back
            .targets
            .iter()
            .zip(registration.target_names())
            .map(|(p, name)| PointElement::new(name, &device, p.map(|x| x as f32)))
            .collect();
        shared.send(&PointMessage { points }, &device, cloud.timestamp)?;
    }
    let polydata = |surface: mesh::TriSurface| PolyData {
        points: surface.vertices.iter().map(to_wire).collect(),
        triangles: surface.triangles.iter().map(|t| t.map(|i| i as u32)).collect(),
    };
    if options.outputs.organ {
        let organ = polydata(tracked.organ_surface(registration));
        shared.send(&organ, &format!("organ{verdict}"), cloud.timestamp)?;
    }
    if options.outputs.structures && result.plausible() {
        for (name, moved) in registration.structure_surfaces(&result.u, tracked.rigid.as_ref()) {
            shared.send(&polydata(moved), name, cloud.timestamp)?;
        }
    }
    if let (true, Some(organ_to_cloud)) = (options.outputs.transform, back.organ_to_cloud) {
        let matrix = organ_to_cloud.map(|row| row.map(|x| x as f32));
        shared.send(&TransformMessage { matrix }, &format!("rigid{verdict}"), cloud.timestamp)?;
    }
    if options.outputs.status {
        shared.send_line("status", status_line(status), cloud.timestamp);
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A reset holds for the first cloud received after it, not for one already waiting when it
    /// came; a cloud that replaces a waiting one counts it, and keeps its reset.
    #[test]
    fn a_reset_holds_for_the_next_cloud_received() {
        let mut mailbox = Mailbox::default();
        let put = |m: &mut Mailbox, frame| m.put_cloud(Cloud { frame, timestamp: None }, vec![[0.0; 3]]);
        let take = |m: &mut Mailbox| m.cloud.take().map(|w| (w.cloud.frame, w.from_rest, w.replaced));
        put(&mut mailbox, 1);
        mailbox.reset = true;
        assert_eq!(take(&mut mailbox), Some((1, false, 0)));
        put(&mut mailbox, 2);
        assert_eq!(take(&mut mailbox), Some((2, true, 0)));
        // A cloud, a reset, a cloud in its place; a reset, two clouds; then a cloud with none.
        put(&mut mailbox, 3);
        mailbox.reset = true;
        put(&mut mailbox, 4);
        assert_eq!(take(&mut mailbox), Some((4, true, 1)));
        mailbox.reset = true;
        put(&mut mailbox, 5);
        put(&mut mailbox, 6);
        assert_eq!(take(&mut mailbox), Some((6, true, 1)));
        put(&mut mailbox, 7);
        assert_eq!(take(&mut mailbox), Some((7, false, 0)));
        assert_eq!(take(&mut mailbox), None);
    }

    /// A target's name cut on the stream is warned about; two that the cut makes one are refused.
    #[test]
    fn target_names_cut_on_the_stream_are_told() {
        let long = |end: &str| format!("{}{end}", "t".repeat(62));
        let names = |list: &[&str]| list.iter().map(|s| s.to_string()).collect::<Vec<_>>();
        assert_eq!(check_target_names(&names(&["a", "b"])).unwrap(), Vec::<String>::new());
        let warned = check_target_names(&[long("ab"), "b".into()]).unwrap();
        assert!(
            warned.len() == 1 && warned[0].starts_with("1 target name(s) longer than 63 bytes are cut"),
            "{warned:?}"
        );
        let e = check_target_names(&[long("ab"), long("ac")]).unwrap_err();
        assert!(e.contains(&format!("are both named `{}` on the stream", long("a"))), "{e}");
    }

    /// A status of thousands of targets' σ would not fit in a STRING: σ is left out, with a
    /// warning; a short one is sent as it is.
    #[test]
    fn an_oversized_status_leaves_sigma_out() {
        let status = |k: usize| serde_json::json!({"frame": 1, "warnings": [], "target_sigma": vec![1.234_567_89; k]});
        let short: serde_json::Value = serde_json::from_str(&status_line(status(3))).unwrap();
        assert_eq!(short, status(3));
        let line = status_line(status(10_000));
        assert!(line.len() <= usize::from(u16::MAX), "{} bytes", line.len());
        let long: serde_json::Value = serde_json::from_str(&line).unwrap();
        assert!(long["target_sigma"].is_null(), "{long}");
        assert!(long["warnings"][0].as_str().unwrap().starts_with("target_sigma left out"), "{long}");
    }

    #[test]
    fn an_accepted_connection_is_probed_when_idle() {
        let listener = TcpListener::bind("127.0.0.1:0").unwrap();
        let _client = TcpStream::connect(listener.local_addr().unwrap()).unwrap();
        let (accepted, _) = listener.accept().unwrap();
        let options = ServeOptions::default();
        configure(&accepted, &options).unwrap();
        let socket = socket2::SockRef::from(&accepted);
        assert!(socket.keepalive().unwrap());
        assert_eq!(accepted.write_timeout().unwrap(), Some(options.stall));
        assert!(accepted.nodelay().unwrap());
    }
}
