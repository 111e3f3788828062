//! The OpenIGTLink server end to end, with clients speaking the protocol over TCP: a cloud in
//! millimetres registered into targets, organ and status; a bad cloud answered with an error; a
//! malformed or oversized message closing that client alone; a clean stop.

use std::net::TcpListener;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;

use augsim_live::client::{Answer, Client};
use augsim_live::igtl::{crc64, Header};
use augsim_live::polydata::PolyData;
use augsim_live::{encode_message, serve, Outputs, ServeOptions};
use fem::{Law, Material, Problem, SolverOptions, StaticSolver};
use mesh::io::{Frame, FrameChange, GivenCoordinates};
use mesh::length::LengthUnit;
use mesh::select::nodes_in_box;
use mesh::Point;
use register::{FemDeformer, Organ, Registration, RegistrationOptions};

const SIDE: f64 = 0.05;

/// A soft cube fixed at its base (the organ) and the target at its centre.
fn cube() -> (Problem, Point) {
    let mesh = mesh::box_tet([0.0; 3], [SIDE; 3], [4, 4, 4]).unwrap();
    let mut problem = Problem::new(mesh, Material::new(Law::Corotational, 5000.0, 0.45));
    let base = nodes_in_box(&problem.mesh.nodes, [-1.0, -1.0, -1e-6], [1.0, 1.0, 1e-6]);
    problem.fix(&base);
    (problem, [SIDE / 2.0; 3])
}

/// The cube's top face pressed down: the cloud a camera above sees (mm) and the centre's true
/// position (mm).
fn pressed_cloud(pressure: f64) -> (Vec<[f32; 3]>, Point) {
    let (mut problem, centre) = cube();
    let top = nodes_in_box(&problem.mesh.nodes, [-1.0, -1.0, SIDE - 1e-6], [1.0; 3]);
    problem.add_traction(&top, [0.0, 0.0, -pressure]);
    let u = StaticSolver::new(problem.clone()).unwrap().solve(&SolverOptions::default()).unwrap().u;
    let organ = Organ::new(problem.mesh.clone(), None).unwrap();
    let rest = organ.surface().vertices.clone();
    let deformed = organ.deformed_surface(&u).vertices;
    let cloud =
        deformed.iter().zip(&rest).filter(|(_, r)| r[2] > SIDE - 1e-6).map(|(p, _)| p.map(|x| (x * 1e3) as f32));
    let k = problem.mesh.nodes.iter().position(|p| (0..3).all(|d| (p[d] - centre[d]).abs() < 1e-9)).unwrap();
    (cloud.collect(), std::array::from_fn(|d| (centre[d] + u[3 * k + d]) * 1e3))
}

fn cube_registration() -> Result<Registration, String> {
    cube_registration_with(None)
}

/// The cube's registration, with a rigid pre-alignment when `rigid` is given.
fn cube_registration_with(rigid: Option<register::RigidOptions>) -> Result<Registration, String> {
    let (problem, centre) = cube();
    let organ = Organ::new(problem.mesh.clone(), None).map_err(|e| e.to_string())?;
    let stiffness = FemDeformer::default_stiffness(&problem);
    let deformer = FemDeformer::new(problem, stiffness, SolverOptions::default()).map_err(|e| e.to_string())?;
    let options = RegistrationOptions { view: Some([0.0, 0.0, -1.0]), rigid, ..RegistrationOptions::default() };
    Registration::new(organ, Box::new(deformer), "FEM", vec![centre], Vec::new(), options).map_err(|e| e.to_string())
}

/// A server's options with its stream in millimetres, the others the defaults.
fn in_mm() -> ServeOptions {
    ServeOptions { coordinates: LengthUnit::Millimetre.into(), ..ServeOptions::default() }
}

/// The cube's registration with a structure: a ball about its centre, named `tumour`.
fn with_tumour() -> Result<Registration, String> {
    let mut registration = cube_registration()?;
    let mut ball = mesh::generate::icosphere(0.005, 1);
    ball.transform([-SIDE / 2.0; 3], 1.0);
    registration.add_structure("tumour", ball).map_err(|e| e.to_string())?;
    Ok(registration)
}

fn status(message: Option<Answer>) -> serde_json::Value {
    match message {
        Some(Answer::Status(s)) => s,
        other => panic!("expected the status STRING, got {other:?}"),
    }
}

/// A server of the cube's registration on a free local port, run on a thread.
struct Server {
    port: u16,
    stop: Arc<AtomicBool>,
    thread: std::thread::JoinHandle<augsim_live::Result<()>>,
}

impl Server {
    fn start(options: ServeOptions) -> Server {
        Server::start_with(options, cube_registration)
    }

    /// A server of the registrations `factory` makes.
    fn start_with(options: ServeOptions, factory: fn() -> Result<Registration, String>) -> Server {
        let listener = TcpListener::bind("127.0.0.1:0").unwrap();
        let port = listener.local_addr().unwrap().port();
        let stop = Arc::new(AtomicBool::new(false));
        let flag = stop.clone();
        let thread = std::thread::spawn(move || serve(listener, Arc::new(factory), options, &flag));
        Server { port, stop, thread }
    }

    /// Stops the server and waits for it.
    fn stop(self) {
        self.stop.store(true, Ordering::SeqCst);
        self.thread.join().unwrap().unwrap();
    }
}

fn connect(port: u16) -> Client {
    Client::connect(("127.0.0.1", port), Duration::from_secs(60)).unwrap()
}

#[test]
fn clouds_in_targets_organ_and_status_out_and_bad_input_hurts_no_one_else() {
    let options = ServeOptions { max_message_bytes: 1 << 20, ..in_mm() };
    let server = Server::start(options);
    let port = server.port;

    // A cloud in millimetres: the registered target is the pressed centre.
    let (cloud, truth) = pressed_cloud(300.0);
    let motion = (truth[2] - SIDE * 1e3 / 2.0).abs();
    let mut client = connect(port);
    client.send_cloud(cloud.clone()).unwrap();
    let target = match client.receive().unwrap() {
        Some(Answer::Targets(m)) => {
            assert_eq!(m.len(), 1);
            m[0].map(f64::from)
        }
        other => panic!("expected the targets POINT, got {other:?}"),
    };
    let error = (0..3).map(|d| (target[d] - truth[d]).powi(2)).sum::<f64>().sqrt();
    assert!(motion > 0.5 && error < 0.25 * motion, "target off by {error:.3} mm, the centre moved {motion:.3} mm");
    match client.receive().unwrap() {
        Some(Answer::Organ(m)) => {
            assert_eq!(m.points.len(), 98, "the cube's surface nodes");
            assert_eq!(m.triangles.len(), 192, "the cube's 192 surface triangles");
            assert!(m.points.iter().all(|p| p.iter().all(|x| (-1.0..=51.0).contains(x))), "in mm");
        }
        other => panic!("expected the organ POLYDATA, got {other:?}"),
    }
    let s = status(client.receive().unwrap());
    assert_eq!(s["frame"], 1);
    assert!(s["ms"].as_f64().unwrap() > 0.0 && s["surface_residual"].as_f64().unwrap() < 0.5, "{s}");
    assert_eq!(s["unit"], "mm", "the lengths' unit: the stream's");
    assert!(s["plausible"] == true && s["warnings"].as_array().unwrap().is_empty(), "{s}");

    // A cloud with a NaN: an error status for that frame, the stream goes on.
    let mut bad = cloud.clone();
    bad[3][1] = f32::NAN;
    client.send_cloud(bad).unwrap();
    let s = status(client.receive().unwrap());
    assert!(s["frame"] == 2 && s["error"].as_str().unwrap().contains("finite"), "{s}");
    client.send_cloud(Vec::new()).unwrap();
    let s = status(client.receive().unwrap());
    assert!(s["frame"] == 3 && s["error"].is_string(), "{s}");
    // The same cloud in metres to a server in millimetres, then in micrometres: refused, saying why.
    client.send_cloud(cloud.iter().map(|p| p.map(|x| x * 1e-3)).collect()).unwrap();
    let s = status(client.receive().unwrap());
    assert!(s["frame"] == 4 && s["error"].as_str().unwrap().contains("too small"), "{s}");
    client.send_cloud(cloud.iter().map(|p| p.map(|x| x * 1e3)).collect()).unwrap();
    let s = status(client.receive().unwrap());
    assert!(s["frame"] == 5 && s["error"].as_str().unwrap().contains("millimetres?"), "{s}");
    // Points from another device: said once (the targets of the next cloud come next), ignored.
    // So is a message of another type, even beyond the size limit of clouds (a CT volume).
    for _ in 0..2 {
        client.send_points("tool", &cloud[..3]).unwrap();
    }
    let volume = vec![0u8; 3 << 20];
    let header = Header::new("IMAGE", "CT", &volume).encode().unwrap();
    client.send_bytes(&[&header[..], &volume].concat()).unwrap();
    for expected in ["POINT messages from device 'tool' are ignored", "IMAGE messages from device 'CT' are ignored"] {
        match client.receive().unwrap() {
            Some(Answer::Warning(w)) => assert!(w["warnings"][0].as_str().unwrap().starts_with(expected), "{w}"),
            other => panic!("expected the warning STRING, got {other:?}"),
        }
    }

    // Another client sends an oversized message, a third garbage: each is closed alone.
    let mut huge = encode_message(&PolyData { points: cloud.clone(), triangles: Vec::new() }, "cloud").unwrap();
    huge[42..50].copy_from_slice(&u64::MAX.to_be_bytes());
    let mut other = connect(port);
    other.send_bytes(&huge[..Header::SIZE]).unwrap();
    let s = status(other.receive().unwrap());
    assert!(s["error"].as_str().unwrap().contains("exceeds"), "{s}");
    assert!(other.receive().unwrap().is_none(), "the connection is closed");
    // A POLYDATA that claims 1,000 points and holds 2, with a correct CRC; then a corrupted one:
    // each answered with an error, stamped as it was, and the stream goes on where its header
    // said the next message starts.
    let mut lying = encode_message(&PolyData { points: vec![[0.0; 3]; 2], triangles: Vec::new() }, "cloud").unwrap();
    lying[Header::SIZE..Header::SIZE + 4].copy_from_slice(&1000u32.to_be_bytes());
    lying[34..42].copy_from_slice(&(77u64 << 32).to_be_bytes());
    let crc = crc64(&lying[Header::SIZE..]);
    lying[50..58].copy_from_slice(&crc.to_be_bytes());
    let mut corrupted = huge.clone();
    let body_size = (corrupted.len() - Header::SIZE) as u64;
    corrupted[42..50].copy_from_slice(&body_size.to_be_bytes());
    corrupted[Header::SIZE + 10] ^= 0x55;
    let mut garbage = connect(port);
    garbage.send_bytes(&[&lying[..], &corrupted[..]].concat()).unwrap();
    let (answer, at) = garbage.receive_stamped().unwrap().unwrap();
    let s = status(Some(answer));
    assert!(s["frame"] == 1 && s["error"].as_str().unwrap().contains("malformed POLYDATA") && at == 77 << 32, "{s}");
    let s = status(garbage.receive().unwrap());
    assert!(s["frame"] == 2 && s["error"].as_str().unwrap().contains("CRC"), "{s}");
    garbage.send_cloud(cloud.clone()).unwrap();
    assert_eq!(garbage.until_status().unwrap().status["frame"], 3, "the connection goes on");

    // The first client is still served, warm-started; only the status is asked of a new server
    // setting, so here the three answers again.
    client.send_cloud(cloud).unwrap();
    assert!(matches!(client.receive().unwrap(), Some(Answer::Targets(_))));
    assert!(matches!(client.receive().unwrap(), Some(Answer::Organ(_))));
    assert_eq!(status(client.receive().unwrap())["frame"], 6);

    server.stop();
    assert!(client.receive().unwrap().is_none(), "the server closed the connection when it stopped");
}

/// A client that closes its side after its last cloud still gets the answers; a message that
/// stalls mid-way closes its connection with an error.
#[test]
fn a_half_closed_client_is_answered_and_a_stalled_message_is_dropped() {
    let stall = Duration::from_millis(300);
    let server = Server::start(ServeOptions { stall, ..in_mm() });
    let (cloud, _) = pressed_cloud(300.0);
    let mut client = connect(server.port);
    client.send_cloud(cloud.clone()).unwrap();
    client.finish().unwrap();
    assert_eq!(client.until_status().unwrap().status["frame"], 1);
    assert!(client.receive().unwrap().is_none(), "then the connection is closed");

    let mut slow = connect(server.port);
    let message = encode_message(&PolyData { points: cloud, triangles: Vec::new() }, "cloud").unwrap();
    slow.send_bytes(&message[..Header::SIZE + 10]).unwrap();
    let s = status(slow.receive().unwrap());
    assert!(s["error"].as_str().unwrap().contains("truncated message body: nothing more came for 0.3 s"), "{s}");
    assert!(slow.receive().unwrap().is_none(), "the connection is closed");
    server.stop();
}

/// A connection beyond `max_clients` is answered by an error status and closed, and said in the
/// log; the clients served go on, and a place that frees is taken by the next connection.
#[test]
fn a_connection_beyond_max_clients_is_refused() {
    let server = Server::start(ServeOptions { max_clients: 2, ..in_mm() });
    // A client served answers an ignored message with a warning.
    let served = |client: &mut Client, device: &str| {
        client.send_points(device, &[[0.0; 3]]).unwrap();
        assert!(matches!(client.receive().unwrap(), Some(Answer::Warning(_))), "{device}");
    };
    let (mut first, mut second) = (connect(server.port), connect(server.port));
    served(&mut first, "tool");
    served(&mut second, "tool");
    let mut third = connect(server.port);
    let s = status(third.receive().unwrap());
    assert!(s["error"].as_str().unwrap().contains("most clients (2): connection refused"), "{s}");
    assert!(third.receive().unwrap().is_none(), "the connection is closed");
    served(&mut first, "pointer");
    served(&mut second, "pointer");
    // The first leaves: a next connection is served (once the server saw it leave), answering nothing
    // unasked.
    drop(first);
    let started = std::time::Instant::now();
    loop {
        let mut next = Client::connect(("127.0.0.1", server.port), Duration::from_millis(200)).unwrap();
        match next.receive() {
            Err(e) if e.contains("the server sent nothing within") => break,
            Ok(Some(Answer::Status(s))) if s["error"].is_string() => {}
            other => panic!("expected a refusal or silence, got {other:?}"),
        }
        assert!(started.elapsed() < Duration::from_secs(3), "the first client's place was not freed");
        std::thread::sleep(Duration::from_millis(20));
    }
    drop(second);
    server.stop();
}

/// Ignored messages are warned about once per type and device, up to `MAX_IGNORED_KINDS` pairs;
/// past them, once that further ones are ignored silently.
#[test]
fn ignored_messages_are_warned_about_up_to_a_bound() {
    let server = Server::start(in_mm());
    let mut client = connect(server.port);
    let bound = augsim_live::MAX_IGNORED_KINDS;
    for k in 0..bound + 5 {
        client.send_points(&format!("tool {k}"), &[[0.0; 3]]).unwrap();
    }
    client.send_points("tool 0", &[[0.0; 3]]).unwrap();
    // Answered by an error estimate (no identification): after every warning.
    client.send_points("features", &[[0.0; 3]; 2]).unwrap();
    let mut warnings = Vec::new();
    loop {
        match client.receive().unwrap() {
            Some(Answer::Warning(w)) => warnings.push(w["warnings"][0].as_str().unwrap().to_string()),
            Some(Answer::Estimate(_)) => break,
            other => panic!("expected a warning or an estimate, got {other:?}"),
        }
    }
    assert_eq!(warnings.len(), bound + 1, "the last: {:?}", warnings.last());
    assert!(warnings[bound - 1].starts_with(&format!("POINT messages from device 'tool {}'", bound - 1)));
    let last = &warnings[bound];
    assert!(last.contains(&format!("'tool {bound}' first) are ignored without a warning")), "{last}");
    drop(client);
    server.stop();
}

/// With the targets alone as outputs, a refused cloud is still answered by its error status (a
/// client would otherwise wait for targets that never come); a registered one by its targets only.
#[test]
fn a_refused_cloud_is_answered_whatever_the_outputs() {
    let outputs = Outputs::parse("targets").unwrap();
    let server = Server::start(ServeOptions { outputs, ..in_mm() });
    let (cloud, _) = pressed_cloud(300.0);
    let mut client = connect(server.port);
    let mut bad = cloud.clone();
    bad[0][2] = f32::INFINITY;
    client.send_cloud(bad).unwrap();
    let s = status(client.receive().unwrap());
    assert!(s["frame"] == 1 && s["error"].as_str().unwrap().contains("finite"), "{s}");
    client.send_cloud(cloud).unwrap();
    assert!(matches!(client.receive().unwrap(), Some(Answer::Targets(_))));
    client.send_cloud(Vec::new()).unwrap();
    let s = status(client.receive().unwrap());
    assert!(s["frame"] == 3 && s["error"].is_string(), "no status for frame 2, which registered: {s}");
    drop(client);
    server.stop();
}

/// Every answer to a cloud, its error status included, carries the cloud's header timestamp.
#[test]
fn answers_carry_the_timestamp_of_the_cloud_they_answer() {
    let server = Server::start(in_mm());
    let (cloud, _) = pressed_cloud(300.0);
    let mut client = connect(server.port);
    let stamped = |points: Vec<[f32; 3]>, stamp: u64| {
        augsim_live::encode_message_stamped(&PolyData { points, triangles: Vec::new() }, "cloud", Some(stamp)).unwrap()
    };
    let stamp = 1_234_567 << 32 | 0x8000_0000;
    client.send_bytes(&stamped(cloud.clone(), stamp)).unwrap();
    for expected in ["targets", "organ", "status"] {
        let (answer, at) = client.receive_stamped().unwrap().unwrap();
        assert_eq!(at, stamp, "{expected}: {answer:?}");
    }
    client.send_bytes(&stamped(Vec::new(), stamp + 1)).unwrap();
    let (answer, at) = client.receive_stamped().unwrap().unwrap();
    assert!(matches!(answer, Answer::Status(ref s) if s["error"].is_string()) && at == stamp + 1, "{answer:?}");
    drop(client);
    server.stop();
}

/// With a record folder, each client's stream is written as it goes, one line of JSON per
/// answer: the client, then each cloud's status with its timestamp (seconds), targets (in the stream's
/// unit, as sent) and the file of the cloud as it came, and each error; a second client gets a file of
/// its own.
#[test]
fn each_client_s_stream_is_recorded_as_it_goes() {
    let dir = tempfile::tempdir().unwrap();
    let record = Some(dir.path().join("record"));
    let frame = Some(mesh::io::Frame::Ras);
    let server = Server::start(ServeOptions { frame, record, ..in_mm() });
    let (cloud, _) = pressed_cloud(300.0);
    let mut client = connect(server.port);
    client.send_cloud(cloud.clone()).unwrap();
    let answered = match client.receive().unwrap() {
        Some(Answer::Targets(points)) => points,
        other => panic!("expected targets, got {other:?}"),
    };
    let _organ = client.receive().unwrap();
    let _status = status(client.receive().unwrap());
    // An empty cloud, stamped 1,234,567.5 s since 1970 in its header.
    let empty = PolyData { points: Vec::new(), triangles: Vec::new() };
    let stamp = Some(1_234_567 << 32 | 0x8000_0000);
    client.send_bytes(&augsim_live::encode_message_stamped(&empty, "cloud", stamp).unwrap()).unwrap();
    assert!(status(client.receive().unwrap())["error"].is_string());
    let mut second = connect(server.port);
    second.send_cloud(cloud.clone()).unwrap();
    assert!(matches!(second.receive().unwrap(), Some(Answer::Targets(_))));
    let _organ = second.receive().unwrap();
    let _status = status(second.receive().unwrap());
    drop((client, second));
    server.stop();
    let read = |name: &str| -> Vec<serde_json::Value> {
        let text = std::fs::read_to_string(dir.path().join("record").join(name)).unwrap();
        text.lines().map(|l| serde_json::from_str(l).unwrap()).collect()
    };
    let lines = read("client-001.jsonl");
    assert!(lines[0]["peer"].as_str().unwrap().starts_with("127.0.0.1:") && lines[0]["unit"] == "mm", "{}", lines[0]);
    assert_eq!(lines[0]["frame"], "RAS", "the stream's frame is recorded with its unit: {}", lines[0]);
    assert!(lines[1]["status"]["frame"] == 1 && lines[1]["status"]["plausible"] == true, "{}", lines[1]);
    let recorded: Vec<Vec<f64>> = serde_json::from_value(lines[1]["targets"].clone()).unwrap();
    assert_eq!(recorded.len(), answered.len());
    for (r, s) in recorded.iter().zip(&answered) {
        assert!(r.iter().zip(s).all(|(a, b)| (a - f64::from(*b)).abs() < 1e-3), "{r:?} against {s:?}");
    }
    // The cloud as it came, in the stream's unit and frame (mm: to the f32's precision).
    assert_eq!(lines[1]["cloud"], "client-001/cloud-000001.npy", "{}", lines[1]);
    let kept = mesh::io::npy::read_npy(&dir.path().join("record/client-001/cloud-000001.npy")).unwrap();
    assert_eq!(kept.shape, [cloud.len(), 3]);
    let flat: Vec<f32> = cloud.iter().flatten().copied().collect();
    assert!(kept.into_f32().iter().zip(&flat).all(|(a, b)| (a - b).abs() <= 1e-4 * b.abs().max(1.0)));
    // A cloud refused is kept too, under its frame's number.
    let refused = mesh::io::npy::read_npy(&dir.path().join("record/client-001/cloud-000002.npy")).unwrap();
    assert_eq!(refused.shape, [0, 3]);
    assert!(lines[2]["status"]["frame"] == 2 && lines[2]["status"]["error"].is_string(), "{}", lines[2]);
    assert_eq!(lines[2]["timestamp"], 1_234_567.5, "the header's timestamp in seconds, as pyigtl gives it");
    assert_eq!(read("client-002.jsonl").len(), 2, "the second client's record: its header and its cloud");
}

/// Clouds sent faster than they are registered: the newest wins, and each status counts the
/// clouds a newer one replaced since the last answer (`skipped`), so that every cloud sent is
/// either answered or counted.
#[test]
fn clouds_a_newer_one_replaced_are_counted() {
    let outputs = Outputs::parse("status").unwrap();
    let server = Server::start(ServeOptions { outputs, ..in_mm() });
    let (cloud, _) = pressed_cloud(300.0);
    let mut client = connect(server.port);
    const SENT: u64 = 6;
    for _ in 0..SENT {
        client.send_cloud(cloud.clone()).unwrap();
    }
    let (mut answered, mut skipped, mut last) = (0, 0, 0);
    while last < SENT {
        let s = status(client.receive().unwrap());
        (answered, skipped, last) =
            (answered + 1, skipped + s["skipped"].as_u64().unwrap(), s["frame"].as_u64().unwrap());
    }
    assert_eq!(answered + skipped, SENT, "{answered} answered, {skipped} skipped");
    assert!(skipped > 0, "six clouds at once, each registration taking milliseconds: some are replaced");
    drop(client);
    server.stop();
}

/// A STRING `reset` has the next cloud start from rest, as the client's first did: the same cloud
/// then registers as it did first, where a warm frame went on from the last one.
#[test]
fn a_reset_has_the_next_cloud_start_from_rest() {
    let outputs = Outputs::parse("targets,status").unwrap();
    let server = Server::start(ServeOptions { outputs, ..in_mm() });
    let (cloud, _) = pressed_cloud(300.0);
    let mut client = connect(server.port);
    let frame = |client: &mut augsim_live::client::Client| {
        client.send_cloud(cloud.clone()).unwrap();
        let answer = client.until_status().unwrap();
        (answer.targets.expect("targets"), answer.status)
    };
    let (first, s) = frame(&mut client);
    assert!(s["from_rest"] == true && s["iterations"].as_u64().unwrap() > 4, "{s}");
    let (_, s) = frame(&mut client);
    assert!(s["from_rest"] == false && s["iterations"].as_u64().unwrap() <= 4, "warm: {s}");
    client.send_reset().unwrap();
    let (again, s) = frame(&mut client);
    assert_eq!(s["from_rest"], true, "{s}");
    let gap = again.iter().zip(&first).flat_map(|(a, b)| (0..3).map(move |d| (a[d] - b[d]).abs())).fold(0.0, f32::max);
    assert!(gap < 1e-3, "registered as the first cloud was: {gap} mm apart");
    drop(client);
    server.stop();
}

/// A stream in the other frame (RAS against an LPS organ): the cloud is brought into the organ's
/// frame, and the target and the organ go back in the stream's.
#[test]
fn clouds_in_another_frame_are_answered_in_theirs() {
    let frame = FrameChange::between(Some(Frame::Ras), Some(Frame::Lps));
    let coordinates = GivenCoordinates { unit: LengthUnit::Millimetre, change: frame };
    let server = Server::start(ServeOptions { coordinates, ..ServeOptions::default() });
    let (cloud, truth) = pressed_cloud(300.0);
    let flip = |p: [f32; 3]| frame.point(p.map(f64::from));
    let mut client = connect(server.port);
    client.send_cloud(cloud.iter().map(|&p| flip(p).map(|x| x as f32)).collect()).unwrap();
    let target = match client.receive().unwrap() {
        Some(Answer::Targets(m)) => m[0].map(f64::from),
        other => panic!("expected the targets POINT, got {other:?}"),
    };
    let motion = (truth[2] - SIDE * 1e3 / 2.0).abs();
    let truth = frame.point(truth);
    let error = (0..3).map(|d| (target[d] - truth[d]).powi(2)).sum::<f64>().sqrt();
    assert!(error < 0.25 * motion, "target {target:?} for {truth:?} in the stream's frame");
    match client.receive().unwrap() {
        Some(Answer::Organ(m)) => assert!(m.points.iter().all(|p| p[0] <= 1.0 && p[1] <= 1.0), "in the stream's frame"),
        other => panic!("expected the organ POLYDATA, got {other:?}"),
    }
    drop(client);
    server.stop();
}

/// A cloud in the other frame (x and y negated), which the registration flags, is answered under
/// names that say so (`targets_implausible`, `organ_implausible`, no structure), so that a
/// viewer's `targets` keeps the last plausible answer; the next cloud, in the right frame, comes
/// back under the plain names.
#[test]
fn an_implausible_result_is_answered_under_names_that_say_so() {
    let server = Server::start_with(in_mm(), with_tumour);
    let (cloud, _) = pressed_cloud(300.0);
    let mut client = connect(server.port);
    client.send_cloud(cloud.iter().map(|p| [-p[0], -p[1], p[2]]).collect()).unwrap();
    assert!(matches!(client.receive().unwrap(), Some(Answer::ImplausibleTargets(_))));
    assert!(matches!(client.receive().unwrap(), Some(Answer::ImplausibleOrgan(_))));
    let flagged = status(client.receive().unwrap());
    assert_eq!(flagged["plausible"], false, "{flagged}");
    client.send_cloud(cloud).unwrap();
    assert!(matches!(client.receive().unwrap(), Some(Answer::Targets(_))));
    assert!(matches!(client.receive().unwrap(), Some(Answer::Organ(_))));
    assert!(matches!(client.receive().unwrap(), Some(Answer::Structure(name, _)) if name == "tumour"));
    assert_eq!(status(client.receive().unwrap())["plausible"], true);
    drop(client);
    server.stop();
}

/// A structure of the registration (a ball about the cube's centre, named `tumour`) comes after
/// the organ as a POLYDATA of its name, moved with the organ: its centre where the registered
/// target is.
#[test]
fn a_structure_is_answered_as_a_polydata_of_its_name() {
    let server = Server::start_with(in_mm(), with_tumour);
    let (cloud, _) = pressed_cloud(300.0);
    let mut client = connect(server.port);
    client.send_cloud(cloud).unwrap();
    let mut target = None;
    let tumour = loop {
        match client.receive().unwrap() {
            Some(Answer::Targets(t)) => target = Some(t[0]),
            Some(Answer::Organ(_)) => {}
            Some(Answer::Structure(name, polydata)) => break (name, polydata),
            other => panic!("expected the tumour's POLYDATA, got {other:?}"),
        }
    };
    assert_eq!((tumour.0.as_str(), tumour.1.points.len(), tumour.1.triangles.len()), ("tumour", 42, 80));
    let n = tumour.1.points.len() as f32;
    let centre: Vec<f32> = (0..3).map(|d| tumour.1.points.iter().map(|p| p[d]).sum::<f32>() / n).collect();
    let target = target.expect("the targets before the structures");
    let off = (0..3).map(|d| (centre[d] - target[d]).powi(2)).sum::<f32>().sqrt();
    assert!(off < 0.05, "the tumour's centre {centre:?} mm, the target {target:?} mm");
    assert!(matches!(client.receive().unwrap(), Some(Answer::Status(_))));
    drop(client);
    server.stop();
}

#[test]
fn outputs_parse_and_refuse_unknown_names() {
    assert_eq!(
        Outputs::parse("targets,status").unwrap(),
        Outputs { targets: true, organ: false, transform: false, status: true, structures: false }
    );
    assert_eq!(Outputs::parse("targets, organ, transform, status, structures").unwrap(), Outputs::ALL);
    assert!(Outputs::parse("targets,mesh").unwrap_err().contains("mesh"));
    assert!(Outputs::parse("").is_err());
    let structures = Outputs::parse("structures").unwrap();
    assert_eq!(structures, Outputs { structures: true, ..Outputs::NONE });
}

/// An output the registration has nothing to send for (the transform without a rigid
/// pre-alignment, structures without structures) is refused when it is the only one chosen, and
/// warned about beside others.
#[test]
fn outputs_the_registration_cannot_send_are_named() {
    let plain = cube_registration_with(None).unwrap();
    let only = |list: &str| Outputs::parse(list).unwrap().check(&plain);
    assert!(only("transform").unwrap_err().contains("--rigid"));
    assert!(only("structures").unwrap_err().contains("--structure"));
    let warnings = only("targets,transform,structures").unwrap();
    assert_eq!(warnings.len(), 2, "{warnings:?}");
    assert_eq!(only("targets,status").unwrap(), Vec::<String>::new());
    let rigid = cube_registration_with(Some(register::RigidOptions::default())).unwrap();
    assert_eq!(Outputs::parse("transform").unwrap().check(&rigid).unwrap(), Vec::<String>::new());
    let mut with_tumour = cube_registration_with(None).unwrap();
    let mut ball = mesh::generate::icosphere(0.005, 1);
    ball.transform([-SIDE / 2.0; 3], 1.0);
    with_tumour.add_structure("tumour", ball).unwrap();
    assert_eq!(Outputs::parse("structures").unwrap().check(&with_tumour).unwrap(), Vec::<String>::new());
}

/// With a rigid pre-alignment, a cloud of the cube's sides and top moved by a few millimetres is
/// aligned on the first frame: the target comes back in the cloud's frame, the organ-to-cloud
/// transform is the move (to the ICP's accuracy on the cube's 98 surface nodes), and the next
/// frame keeps the pose.
#[test]
fn a_rigid_pre_alignment_answers_in_the_clouds_frame() {
    let mut warm = cube_registration_with(Some(register::RigidOptions::default())).unwrap();
    let shift = [0.004, -0.003, 0.002];
    let cloud: Vec<Point> = warm
        .organ()
        .surface()
        .vertices
        .iter()
        .filter(|p| p[2] > 1e-6)
        .map(|p| std::array::from_fn(|d| p[d] + shift[d]))
        .collect();
    let centre = warm.targets()[0];
    let mut poses = Vec::new();
    for frame in 0..2 {
        let answer = warm.register(&cloud).unwrap();
        let t = answer.rigid.expect("a rigid transform").organ_to_cloud();
        let moved = (0..3).map(|d| (t.translation[d] - shift[d]).abs()).fold(0.0, f64::max);
        assert!(moved < 1.5e-3, "frame {frame}: translation {:?} for a move of {shift:?}", t.translation);
        let target = answer.targets[0];
        let off = (0..3).map(|d| (target[d] - centre[d] - shift[d]).abs()).fold(0.0, f64::max);
        assert!(off < 1.5e-3, "frame {frame}: target {target:?}, expected the centre moved by {shift:?}");
        assert!(off < 0.5 * mesh::norm(shift), "the target must follow the cloud");
        poses.push(t);
    }
    assert_eq!(poses[0], poses[1], "the pose of the first frame is kept");
    warm.reset();
    assert!(warm.register(&cloud).unwrap().rigid.is_some(), "a reset estimates the pose again");
}

/// An identification that takes 20 ms a step and reports the mean height of its features.
struct SlowMean;

impl augsim_live::Identification for SlowMean {
    fn features(&self) -> usize {
        2
    }

    fn step(&mut self, positions: &[Point]) -> Result<serde_json::Map<String, serde_json::Value>, String> {
        std::thread::sleep(Duration::from_millis(20));
        let z = positions.iter().map(|p| p[2]).sum::<f64>() / 2.0;
        Ok(serde_json::Map::from_iter([("z".to_string(), z.into())]))
    }
}

/// An identification that counts its steps and the features seen at the last one.
#[derive(Default)]
struct Counting {
    steps: usize,
}

impl augsim_live::Identification for Counting {
    fn features(&self) -> usize {
        2
    }

    fn step(&mut self, positions: &[Point]) -> Result<serde_json::Map<String, serde_json::Value>, String> {
        self.steps += 1;
        let seen = positions.iter().filter(|p| !p[0].is_nan()).count();
        Ok(serde_json::Map::from_iter([("steps".to_string(), self.steps.into()), ("seen".to_string(), seen.into())]))
    }
}

/// A step refused (features it cannot take) is taken as one with no feature seen: the filter's
/// clock stays on the stream's step numbers, so that the load of each later step is the right one.
#[test]
fn a_refused_step_keeps_the_identification_s_clock() {
    let factory: Arc<augsim_live::IdentificationFactory> = Arc::new(|| Ok(Box::new(Counting::default())));
    let server = Server::start(ServeOptions { identification: Some(factory), ..in_mm() });
    let mut client = connect(server.port);
    client.send_points("features", &[[0.0; 3]; 2]).unwrap();
    client.send_points("features", &[[0.0; 3]; 1]).unwrap();
    client.send_points("features", &[[0.0; 3]; 2]).unwrap();
    let mut estimates = Vec::new();
    for _ in 0..3 {
        match client.receive().unwrap() {
            Some(Answer::Estimate(e)) => estimates.push(e),
            other => panic!("expected an estimate, got {other:?}"),
        }
    }
    let e = estimates[1]["error"].as_str().unwrap();
    assert!(e.contains("1 features sent, the identification observes 2: taken as a step with no feature seen"), "{e}");
    assert_eq!((estimates[2]["step"].as_u64(), estimates[2]["steps"].as_u64()), (Some(3), Some(3)), "{}", estimates[2]);
    assert_eq!(estimates[2]["seen"], 2);
    server.stop();
}

/// `features` make identification steps in order, each answered by an `estimate`; a burst
/// larger than the server keeps waiting gets errors for the steps beyond it, never a backlog;
/// a server without identification says so.
#[test]
fn features_step_the_identification_in_order_with_a_bounded_backlog() {
    let factory: Arc<augsim_live::IdentificationFactory> = Arc::new(|| Ok(Box::new(SlowMean)));
    let server = Server::start(ServeOptions { identification: Some(factory), ..in_mm() });
    let mut client = connect(server.port);
    let burst = 3 * augsim_live::MAX_PENDING_STEPS;
    for k in 0..burst {
        client.send_points("features", &[[0.0, 0.0, k as f32], [0.0, 0.0, k as f32 + 2.0]]).unwrap();
    }
    let mut answered = vec![None; burst];
    for _ in 0..burst {
        match client.receive().unwrap() {
            Some(Answer::Estimate(e)) => {
                let step = e["step"].as_u64().unwrap() as usize;
                assert!(answered[step - 1].is_none(), "step {step} answered twice");
                answered[step - 1] = Some(e);
            }
            other => panic!("expected an estimate, got {other:?}"),
        }
    }
    let refused = answered.iter().flatten().filter(|e| e["error"].is_string()).count();
    // An estimate carries the timestamp of its features; features that do not decode get an error
    // estimate, and the steps go on.
    let features = |stamp: u64| {
        let points = vec![[0.0, 0.0, 1.0], [0.0, 0.0, 3.0]];
        augsim_live::encode_message_stamped(&PolyData { points, triangles: Vec::new() }, "features", Some(stamp))
    };
    let mut corrupted = features(5 << 32).unwrap();
    corrupted[Header::SIZE + 6] ^= 0x55;
    client.send_bytes(&[corrupted, features(6 << 32).unwrap()].concat()).unwrap();
    for (step, stamp, error) in [(burst + 1, 5 << 32, true), (burst + 2, 6 << 32, false)] {
        match client.receive_stamped().unwrap() {
            Some((Answer::Estimate(e), at)) => {
                assert!(e["step"] == step && at == stamp && e["error"].is_string() == error, "{e} at {at}")
            }
            other => panic!("expected an estimate, got {other:?}"),
        }
    }
    assert!(refused > 0 && refused <= burst - augsim_live::MAX_PENDING_STEPS, "{refused} of {burst} refused");
    // The first step was made at once: 1 mm, in metres.
    assert!((answered[0].as_ref().unwrap()["z"].as_f64().unwrap() - 1e-3).abs() < 1e-12);
    // Clouds are still registered.
    let (cloud, _) = pressed_cloud(300.0);
    client.send_cloud(cloud).unwrap();
    assert_eq!(client.until_status().unwrap().status["frame"], 1);
    // A server without identification answers features with an error.
    server.stop();
    let server = Server::start(in_mm());
    let mut client = connect(server.port);
    client.send_points("features", &[[0.0; 3]; 2]).unwrap();
    match client.receive().unwrap() {
        Some(Answer::Estimate(e)) => assert!(e["error"].as_str().unwrap().contains("no identification"), "{e}"),
        other => panic!("expected an estimate, got {other:?}"),
    }
    server.stop();
}

/// The factory hands the prebuilt object to the first client and to each next one the object
/// built ahead for it (one is always ready: the builds run before they are asked for); a build's
/// error reaches the client that asked.
#[test]
fn the_first_client_takes_the_prebuilt_object_and_the_next_ones_their_own_built_ahead() {
    // Each build says so on a channel: the test waits for it, not for a time.
    let (said, builds) = std::sync::mpsc::channel();
    let count = std::sync::atomic::AtomicUsize::new(0);
    let factory = augsim_live::built_ahead(Some("prebuilt".to_string()), move || {
        let n = count.fetch_add(1, Ordering::SeqCst) + 1;
        let _ = said.send(n); // the last build ahead may outlive the test's receiver
        if n < 3 {
            Ok(format!("built {n}"))
        } else {
            Err("no more".to_string())
        }
    });
    let next_build = || builds.recv_timeout(Duration::from_secs(60)).unwrap();
    assert_eq!(next_build(), 1, "one built ahead before any client asks");
    assert_eq!(factory().unwrap(), "prebuilt");
    assert_eq!(factory().unwrap(), "built 1");
    assert_eq!(next_build(), 2, "the next one built as soon as one is taken");
    assert_eq!(factory().unwrap(), "built 2");
    assert_eq!(factory().unwrap_err(), "no more");
    let without = augsim_live::built_ahead(None, || Ok(7));
    assert_eq!((without().unwrap(), without().unwrap()), (7, 7));
}
