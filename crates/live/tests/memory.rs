//! The server's memory grows with the bytes a client sends, not with the sizes its headers
//! announce: a cloud announced at 48 MiB of which a few bytes came holds no 48 MiB. A test binary
//! of its own: its allocator counts the bytes held, which other tests would disturb.

use std::alloc::{GlobalAlloc, Layout, System};
use std::net::TcpListener;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::Arc;
use std::time::Duration;

use augsim_live::client::{Answer, Client};
use augsim_live::igtl::Header;
use augsim_live::{serve, ServeOptions};

/// The system's allocator, counting the bytes held and their peak.
struct Counting;

static HELD: AtomicUsize = AtomicUsize::new(0);
static PEAK: AtomicUsize = AtomicUsize::new(0);

fn held(more: usize) {
    let now = HELD.fetch_add(more, Ordering::SeqCst) + more;
    PEAK.fetch_max(now, Ordering::SeqCst);
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        let p = unsafe { System.alloc(layout) };
        if !p.is_null() {
            held(layout.size());
        }
        p
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        let p = unsafe { System.alloc_zeroed(layout) };
        if !p.is_null() {
            held(layout.size());
        }
        p
    }

    unsafe fn dealloc(&self, p: *mut u8, layout: Layout) {
        unsafe { System.dealloc(p, layout) };
        HELD.fetch_sub(layout.size(), Ordering::SeqCst);
    }

    unsafe fn realloc(&self, p: *mut u8, layout: Layout, size: usize) -> *mut u8 {
        let q = unsafe { System.realloc(p, layout, size) };
        if !q.is_null() {
            HELD.fetch_sub(layout.size(), Ordering::SeqCst);
            held(size);
        }
        q
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

/// A client announces a cloud of 48 MiB (under the 64 MiB limit), sends 1,000 bytes of it and
/// closes its side: the server held about what came, answers that the body is truncated, saying
/// how much came, and goes on serving.
#[test]
fn an_announced_body_holds_memory_only_as_it_arrives() {
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let port = listener.local_addr().unwrap().port();
    let stop = Arc::new(AtomicBool::new(false));
    let flag = stop.clone();
    let factory: Arc<augsim_live::RegistrationFactory> = Arc::new(|| Err("no registration in this test".into()));
    let server = std::thread::spawn(move || serve(listener, factory, ServeOptions::default(), &flag));
    let connect = || Client::connect(("127.0.0.1", port), Duration::from_secs(10)).unwrap();

    let mut client = connect();
    let announced = 48u64 << 20;
    let header = Header { body_size: announced, ..Header::new("POLYDATA", "cloud", &[]) }.encode().unwrap();
    PEAK.store(HELD.load(Ordering::SeqCst), Ordering::SeqCst);
    let before = PEAK.load(Ordering::SeqCst);
    client.send_bytes(&[&header[..], &[0u8; 1000][..]].concat()).unwrap();
    client.finish().unwrap();
    let status = match client.receive().unwrap() {
        Some(Answer::Status(s)) => s,
        other => panic!("expected the status STRING, got {other:?}"),
    };
    let grown = PEAK.load(Ordering::SeqCst) - before;
    assert!(grown < 8 << 20, "{grown} bytes held at the peak for 1,000 received");
    let error = status["error"].as_str().unwrap();
    assert!(error.contains(&format!("truncated message body: 1000 of {announced} bytes")), "{error}");
    assert!(client.receive().unwrap().is_none(), "the connection is closed");

    // The server goes on.
    let mut next = connect();
    next.send_points("tool", &[[0.0; 3]]).unwrap();
    assert!(matches!(next.receive().unwrap(), Some(Answer::Warning(_))));
    stop.store(true, Ordering::SeqCst);
    server.join().unwrap().unwrap();
}
