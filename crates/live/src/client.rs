//! An OpenIGTLink client of the server, for tests, benchmarks and Rust programs: it sends clouds
//! and reads the server's answers ([`Answer`]).

use std::io::{ErrorKind, Read, Write};
use std::net::{TcpStream, ToSocketAddrs};
use std::time::Duration;

use crate::igtl::{decode_body, encode_message, Header, PointElement, PointMessage, StringMessage, TransformMessage};
use crate::polydata::PolyData;

/// A message from the server.
#[derive(Debug)]
pub enum Answer {
    /// POINT `targets`: the registered targets, in the stream's unit.
    Targets(Vec<[f32; 3]>),
    /// POINT `targets_implausible`: the registered targets of a result that is not plausible.
    ImplausibleTargets(Vec<[f32; 3]>),
    /// POLYDATA `organ`: the registered organ surface.
    Organ(PolyData),
    /// POLYDATA `organ_implausible`: the registered organ surface of a result that is not
    /// plausible.
    ImplausibleOrgan(PolyData),
    /// A POLYDATA of another name: a structure moved with the organ, by its name.
    Structure(String, PolyData),
    /// TRANSFORM `rigid`: the organ-to-cloud transform, row-major 4 × 4.
    Rigid([[f32; 4]; 4]),
    /// STRING `status`: one line of JSON.
    Status(serde_json::Value),
    /// STRING `estimate`: an identification step's estimate, one line of JSON.
    Estimate(serde_json::Value),
    /// STRING `warning`: messages the server ignores, one line of JSON (`warnings`).
    Warning(serde_json::Value),
}

/// The answers to one cloud that [`Client::until_status`] keeps.
#[derive(Debug)]
pub struct Frame {
    /// The registered targets, when the server sends them (plausible or not: the status says).
    pub targets: Option<Vec<[f32; 3]>>,
    /// The status line.
    pub status: serde_json::Value,
}

/// The largest answer body the client reads (an organ of a million nodes as POLYDATA is some
/// tens of MB): a larger size is a stream that is not augsim's server, not an allocation to make.
const MAX_ANSWER_BYTES: u64 = 1 << 30;

/// A connection to `augsim serve`.
pub struct Client {
    stream: TcpStream,
}

impl Client {
    /// Connects to the server at `address`; reads wait at most `timeout` for an answer.
    pub fn connect(address: impl ToSocketAddrs, timeout: Duration) -> std::result::Result<Client, String> {
        let stream = TcpStream::connect(address).map_err(|e| format!("connecting to the server: {e}"))?;
        stream.set_read_timeout(Some(timeout)).map_err(|e| e.to_string())?;
        stream.set_nodelay(true).map_err(|e| e.to_string())?;
        Ok(Client { stream })
    }

    /// Sends a cloud (in the server's unit) as a POLYDATA message of device `cloud`.
    pub fn send_cloud(&mut self, points: Vec<[f32; 3]>) -> std::result::Result<(), String> {
        self.send_bytes(&encode_message(&PolyData { points, triangles: Vec::new() }, "cloud")?)
    }

    /// Sends points (in the server's unit) as a POINT message of device `device` (e.g. the
    /// observed features of an identification step, device `features`).
    pub fn send_points(&mut self, device: &str, points: &[[f32; 3]]) -> std::result::Result<(), String> {
        let elements =
            points.iter().enumerate().map(|(k, &p)| PointElement::new(format!("{device} {}", k + 1), device, p));
        self.send_bytes(&encode_message(&PointMessage { points: elements.collect() }, device)?)
    }

    /// Sends a STRING of device `reset`: the next cloud starts from rest.
    pub fn send_reset(&mut self) -> std::result::Result<(), String> {
        self.send_bytes(&encode_message(&StringMessage::utf8("reset"), "reset")?)
    }

    /// Closes the sending side: the server answers what was sent, then closes the connection.
    pub fn finish(&mut self) -> std::result::Result<(), String> {
        self.stream.shutdown(std::net::Shutdown::Write).map_err(|e| format!("closing: {e}"))
    }

    /// Sends raw bytes (e.g. a malformed message).
    pub fn send_bytes(&mut self, bytes: &[u8]) -> std::result::Result<(), String> {
        self.stream.write_all(bytes).map_err(|e| format!("sending: {e}"))
    }

    /// The next message from the server; `None` when the connection is closed.
    pub fn receive(&mut self) -> std::result::Result<Option<Answer>, String> {
        Ok(self.receive_stamped()?.map(|(answer, _)| answer))
    }

    /// The next message from the server and its header timestamp (that of the cloud it
    /// answers); `None` when the connection is closed between messages, an error when it is cut
    /// within one or nothing came within the timeout.
    pub fn receive_stamped(&mut self) -> std::result::Result<Option<(Answer, u64)>, String> {
        let mut header = [0u8; Header::SIZE];
        // Closed between messages, the connection ends cleanly; within a header, it is cut.
        let first = loop {
            match self.stream.read(&mut header[..1]) {
                Err(e) if e.kind() == ErrorKind::Interrupted => continue,
                read => break read.map_err(|e| self.failed("receiving", &e))?,
            }
        };
        if first == 0 {
            return Ok(None);
        }
        self.stream.read_exact(&mut header[1..]).map_err(|e| self.failed("truncated header", &e))?;
        let parsed = Header::decode(&header).map_err(|e| format!("malformed header: {e}"))?;
        if parsed.body_size > MAX_ANSWER_BYTES {
            return Err(format!(
                "an answer of {} bytes, over the {MAX_ANSWER_BYTES} an organ's answer may take: not augsim's server?",
                parsed.body_size
            ));
        }
        let mut body = vec![0; parsed.body_size as usize];
        self.stream.read_exact(&mut body).map_err(|e| self.failed("truncated answer", &e))?;
        let answer = match parsed.type_name.as_str() {
            "POINT" => {
                let points = decode_body::<PointMessage>(&parsed, &body)?.points.iter().map(|p| p.position).collect();
                match parsed.device_name.strip_suffix(register::IMPLAUSIBLE) {
                    Some(_) => Answer::ImplausibleTargets(points),
                    None => Answer::Targets(points),
                }
            }
            "POLYDATA" => match parsed.device_name.as_str() {
                "organ" => Answer::Organ(decode_body(&parsed, &body)?),
                name if name.strip_suffix(register::IMPLAUSIBLE) == Some("organ") => {
                    Answer::ImplausibleOrgan(decode_body(&parsed, &body)?)
                }
                name => Answer::Structure(name.to_string(), decode_body(&parsed, &body)?),
            },
            "TRANSFORM" => Answer::Rigid(decode_body::<TransformMessage>(&parsed, &body)?.matrix),
            "STRING" => {
                let text: StringMessage = decode_body(&parsed, &body)?;
                let json = serde_json::from_str(&text.text).map_err(|e| format!("a STRING is not JSON: {e}"))?;
                match parsed.device_name.as_str() {
                    "estimate" => Answer::Estimate(json),
                    "warning" => Answer::Warning(json),
                    _ => Answer::Status(json),
                }
            }
            other => return Err(format!("unexpected {other} message")),
        };
        Ok(Some((answer, parsed.timestamp)))
    }

    /// Why a read failed: a timeout says how long nothing came.
    fn failed(&self, what: &str, e: &std::io::Error) -> String {
        match e.kind() {
            ErrorKind::WouldBlock | ErrorKind::TimedOut => match self.stream.read_timeout() {
                Ok(Some(timeout)) => format!("{what}: the server sent nothing within {:.1} s", timeout.as_secs_f64()),
                _ => format!("{what}: the server sent nothing within the timeout"),
            },
            _ => format!("{what}: {e}"),
        }
    }

    /// Reads answers up to and including the next status.
    pub fn until_status(&mut self) -> std::result::Result<Frame, String> {
        let mut targets = None;
        loop {
            match self.receive()? {
                Some(Answer::Status(status)) => return Ok(Frame { targets, status }),
                Some(Answer::Targets(t) | Answer::ImplausibleTargets(t)) => targets = Some(t),
                Some(_) => {}
                None => return Err("the server closed the connection".into()),
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A peer on a local port that serves its first connection with `serve`.
    fn peer(serve: impl FnOnce(TcpStream) + Send + 'static) -> (std::net::SocketAddr, std::thread::JoinHandle<()>) {
        let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
        let address = listener.local_addr().unwrap();
        (address, std::thread::spawn(move || serve(listener.accept().unwrap().0)))
    }

    /// A peer announcing an answer of an exabyte is refused, not allocated for.
    #[test]
    fn an_oversized_answer_is_refused() {
        let (address, peer) = peer(|mut stream| {
            let mut wire = encode_message(&StringMessage::utf8("{}"), "status").unwrap();
            wire[42..50].copy_from_slice(&(1u64 << 60).to_be_bytes());
            stream.write_all(&wire[..Header::SIZE]).unwrap();
        });
        let mut client = Client::connect(address, Duration::from_secs(10)).unwrap();
        let error = client.receive().unwrap_err();
        assert!(error.contains("an answer of 1152921504606846976 bytes"), "{error}");
        peer.join().unwrap();
    }

    /// A server that sends nothing within the timeout is an error that says so, not a connection
    /// closed; one that closes is `None`.
    #[test]
    fn a_read_timing_out_is_not_a_closed_connection() {
        let (done, finished) = std::sync::mpsc::channel::<()>();
        let (address, peer) = peer(move |stream| {
            let _ = finished.recv_timeout(Duration::from_secs(10));
            drop(stream);
        });
        let mut client = Client::connect(address, Duration::from_millis(100)).unwrap();
        let error = client.receive().unwrap_err();
        assert!(error.contains("the server sent nothing within 0.1 s"), "{error}");
        done.send(()).unwrap();
        peer.join().unwrap();
        assert!(client.receive().unwrap().is_none(), "the server closed the connection");
    }

    /// A server that closes within a message's header has cut it: an error, not a clean close.
    #[test]
    fn a_header_cut_short_is_an_error() {
        let (address, peer) = peer(|mut stream| {
            let wire = encode_message(&StringMessage::utf8("{}"), "status").unwrap();
            stream.write_all(&wire[..20]).unwrap();
        });
        let mut client = Client::connect(address, Duration::from_secs(10)).unwrap();
        peer.join().unwrap();
        let error = client.receive().unwrap_err();
        assert!(error.starts_with("truncated header: "), "{error}");
    }
}
