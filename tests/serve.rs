//! The static server behind `scribblefield serve`, spoken to over real sockets.
use std::io::{Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::path::Path;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use scribblefield::serve::{Log, MAX_LOGGED_BYTES, ServeConfig, Server, localhost};

/// Sends a raw request and returns (status code, headers lower-cased, body).
fn request(addr: SocketAddr, raw: &str) -> (u16, String, Vec<u8>) {
    let mut stream = TcpStream::connect(addr).expect("connect to the test server");
    stream.write_all(raw.as_bytes()).unwrap();
    let mut response = Vec::new();
    stream.read_to_end(&mut response).unwrap();
    let split = response
        .windows(4)
        .position(|w| w == b"\r\n\r\n")
        .expect("a response head");
    let head = String::from_utf8(response[..split].to_vec())
        .unwrap()
        .to_ascii_lowercase();
    let body = response[split + 4..].to_vec();
    let code = head
        .split_whitespace()
        .nth(1)
        .and_then(|c| c.parse().ok())
        .expect("a status code");
    (code, head, body)
}

fn get(addr: SocketAddr, target: &str) -> (u16, String, Vec<u8>) {
    request(addr, &format!("GET {target} HTTP/1.1\r\nHost: localhost\r\n\r\n"))
}

fn served_dir() -> (tempfile::TempDir, Server) {
    let dir = tempfile::tempdir().unwrap();
    std::fs::create_dir(dir.path().join("pkg")).unwrap();
    std::fs::write(dir.path().join("index.html"), "<!doctype html><title>t</title>").unwrap();
    std::fs::write(dir.path().join("pkg/app_bg.wasm"), b"\0asm\x01\0\0\0").unwrap();
    std::fs::write(dir.path().join("pkg/app.js"), "export {};").unwrap();
    std::fs::write(dir.path().join("demo.scene.zip"), b"PK\x05\x06").unwrap();
    let server = Server::start(dir.path(), localhost(0)).expect("start the server on a free port");
    (dir, server)
}

#[test]
fn serves_files_with_their_content_types() {
    let (_dir, server) = served_dir();
    let addr = server.addr();
    assert!(addr.ip().is_loopback(), "bound to {addr}, expected loopback");

    let (code, head, body) = get(addr, "/pkg/app_bg.wasm");
    assert_eq!(code, 200);
    assert!(head.contains("content-type: application/wasm"), "{head}");
    assert!(head.contains("cache-control: no-cache"), "{head}");
    assert!(head.contains("content-length: 8"), "{head}");
    assert_eq!(body, b"\0asm\x01\0\0\0");

    let (code, head, _) = get(addr, "/pkg/app.js");
    assert_eq!(code, 200);
    assert!(head.contains("content-type: text/javascript"), "{head}");

    let (code, head, body) = get(addr, "/");
    assert_eq!(code, 200, "the folder's index.html");
    assert!(head.contains("content-type: text/html"), "{head}");
    assert!(body.starts_with(b"<!doctype html>"));

    let (code, head, _) = get(addr, "/demo.scene.zip?cache=1");
    assert_eq!(code, 200);
    assert!(head.contains("content-type: application/zip"), "{head}");
}

#[test]
fn head_sends_headers_without_a_body() {
    let (_dir, server) = served_dir();
    let (code, head, body) = request(server.addr(), "HEAD /pkg/app.js HTTP/1.1\r\nHost: localhost\r\n\r\n");
    assert_eq!(code, 200);
    assert!(head.contains("content-length: 10"), "{head}");
    assert!(body.is_empty());
}

#[test]
fn missing_files_are_404() {
    let (_dir, server) = served_dir();
    let (code, _, body) = get(server.addr(), "/pkg/missing.wasm");
    assert_eq!(code, 404);
    assert!(String::from_utf8_lossy(&body).contains("/pkg/missing.wasm"));
}

#[test]
fn paths_that_escape_the_directory_are_refused() {
    // Serve the crate's tests/ folder so that /../Cargo.toml names a real file next to it.
    let tests_dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests");
    let server = Server::start(&tests_dir, localhost(0)).unwrap();
    for target in ["/../Cargo.toml", "/%2e%2e/Cargo.toml", "/x/../../Cargo.toml"] {
        let (code, _, body) = get(server.addr(), target);
        assert_eq!(code, 403, "{target} must be refused");
        assert!(
            !String::from_utf8_lossy(&body).contains("[package]"),
            "{target} leaked Cargo.toml"
        );
    }
}

#[test]
fn other_methods_and_garbage_are_rejected() {
    let (_dir, server) = served_dir();
    let (code, _, _) = request(server.addr(), "POST /index.html HTTP/1.1\r\nContent-Length: 0\r\n\r\n");
    assert_eq!(code, 405);
    let (code, _, _) = request(server.addr(), "NONSENSE\r\n\r\n");
    assert_eq!(code, 400);
}

#[test]
fn a_file_cannot_be_served_as_a_directory() {
    let file = tempfile::NamedTempFile::new().unwrap();
    let err = Server::start(file.path(), localhost(0))
        .err()
        .expect("serving a plain file must fail");
    assert!(err.to_string().contains("not a directory"), "{err}");
}

#[test]
fn stopping_frees_the_port() {
    let (_dir, server) = served_dir();
    let addr = server.addr();
    server.stop();
    assert!(
        TcpStream::connect(addr).is_err(),
        "still accepting on {addr} after stop"
    );
}

// ---- Hostile clients. Limits are set small (a 1-2 s deadline) so the tests are quick; the
// bounds they assert are many times larger, and they check what happened, not how fast.

/// Log lines the server wrote, collected.
#[derive(Clone, Default)]
struct Lines(Arc<Mutex<Vec<String>>>);

impl Lines {
    fn log(&self) -> Log {
        let lines = self.0.clone();
        Log::to(move |l| lines.lock().unwrap().push(l.to_string()))
    }

    fn all(&self) -> Vec<String> {
        self.0.lock().unwrap().clone()
    }
}

fn small_server(workers: usize, queue: usize, deadline: Duration, lines: &Lines) -> (tempfile::TempDir, Server) {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("index.html"), "<!doctype html><title>t</title>").unwrap();
    let config = ServeConfig {
        workers,
        queue,
        request_deadline: deadline,
        write_timeout: Duration::from_secs(1),
        log: lines.log(),
    };
    let server = Server::start_with(dir.path(), localhost(0), config).expect("start the server");
    (dir, server)
}

/// Whatever the server sends until it closes (or resets) the connection, waiting at most `limit`.
fn read_until_closed(stream: &mut TcpStream, limit: Duration) -> Vec<u8> {
    stream.set_read_timeout(Some(limit)).unwrap();
    let mut got = Vec::new();
    let _ = stream.read_to_end(&mut got);
    got
}

fn status_of(response: &[u8]) -> Option<u16> {
    let text = String::from_utf8_lossy(response);
    text.strip_prefix("HTTP/1.1 ")?.get(..3)?.parse().ok()
}

/// A generous bound for anything the server does within its deadline of a second or two.
const PATIENCE: Duration = Duration::from_secs(60);

#[test]
fn a_slow_loris_is_cut_off_at_the_request_deadline() {
    let lines = Lines::default();
    let (_dir, server) = small_server(2, 2, Duration::from_secs(1), &lines);
    let mut loris = TcpStream::connect(server.addr()).unwrap();
    loris.write_all(b"GET / HTTP/1.1\r\n").unwrap();
    // One header byte every 100 ms: each read succeeds long before a per-read timeout would
    // fire, so only a deadline on the whole head ends this.
    loris.set_read_timeout(Some(Duration::from_millis(100))).unwrap();
    let started = Instant::now();
    let mut response = Vec::new();
    let cut_off = loop {
        if started.elapsed() > PATIENCE {
            break false;
        }
        if loris.write_all(b"X").is_err() {
            break true; // reset by the server
        }
        let mut buf = [0u8; 1024];
        match loris.read(&mut buf) {
            Ok(0) => break true,
            Ok(n) => response.extend_from_slice(&buf[..n]),
            Err(e) if matches!(e.kind(), std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut) => {}
            Err(_) => break true, // reset by the server
        }
    };
    assert!(cut_off, "still connected after {PATIENCE:?} of dribbling");
    if !response.is_empty() {
        assert_eq!(
            status_of(&response),
            Some(408),
            "{}",
            String::from_utf8_lossy(&response)
        );
    }
    assert!(
        lines
            .all()
            .iter()
            .any(|l| l.starts_with("408 ") && l.contains("not complete within 1s")),
        "{:?}",
        lines.all()
    );
    // The worker it held is free again.
    let (code, _, _) = get(server.addr(), "/");
    assert_eq!(code, 200);
}

#[test]
fn idle_connections_cannot_starve_the_server() {
    let lines = Lines::default();
    let (_dir, server) = small_server(2, 2, Duration::from_secs(2), &lines);
    // Far more idle connections than workers and queue together: the rest must be answered 503
    // at once, not given threads of their own.
    let mut idle: Vec<TcpStream> = (0..12).map(|_| TcpStream::connect(server.addr()).unwrap()).collect();
    // A normal request meanwhile: answered, either served or told 503 (never left hanging).
    let mut normal = TcpStream::connect(server.addr()).unwrap();
    normal.write_all(b"GET / HTTP/1.1\r\nHost: localhost\r\n\r\n").unwrap();
    let response = read_until_closed(&mut normal, PATIENCE);
    let code = status_of(&response);
    assert!(
        matches!(code, Some(200 | 503)),
        "{}",
        String::from_utf8_lossy(&response)
    );
    if code == Some(503) {
        assert!(String::from_utf8_lossy(&response).contains("Retry-After: 1"));
    }
    // Every idle connection ends: 503 for those beyond the workers and the queue, 408 for those
    // a worker took and waited on until the deadline.
    let codes: Vec<Option<u16>> = idle
        .iter_mut()
        .map(|s| status_of(&read_until_closed(s, PATIENCE)))
        .collect();
    assert!(codes.iter().all(|c| matches!(c, Some(408 | 503))), "{codes:?}");
    assert!(
        codes.contains(&Some(503)),
        "12 idle connections must overflow 2 workers + 2 queued: {codes:?}"
    );
    assert!(codes.contains(&Some(408)), "{codes:?}");
    // And the server is whole afterwards.
    let (code, _, _) = get(server.addr(), "/");
    assert_eq!(code, 200);
}

#[test]
fn a_client_that_stops_reading_loses_its_worker_at_the_write_timeout() {
    let lines = Lines::default();
    // Room for two waiting: the stalled request may still be queued when the second arrives.
    let (dir, server) = small_server(1, 2, Duration::from_secs(2), &lines);
    // Far more than the loopback socket buffers hold, so the server's writes block.
    std::fs::write(dir.path().join("big.bin"), vec![7u8; 64 << 20]).unwrap();
    let mut stalled = TcpStream::connect(server.addr()).unwrap();
    stalled.write_all(b"GET /big.bin HTTP/1.1\r\n\r\n").unwrap();
    // The only worker is stuck writing to `stalled` until its write timeout (1 s) fires; this
    // request waits in the queue and is served after.
    let (code, _, body) = get(server.addr(), "/");
    assert_eq!(code, 200);
    assert!(body.starts_with(b"<!doctype html>"));
    drop(stalled);
}

#[test]
fn request_targets_are_logged_escaped_and_capped() {
    let lines = Lines::default();
    let (_dir, server) = small_server(2, 2, Duration::from_secs(5), &lines);
    let hostile = "/\x1b[2J\x1b[31mred\x07\x7f\u{202e}txt.exe";
    let (code, _, body) = get(server.addr(), hostile);
    assert_eq!(code, 404);
    assert!(!body.contains(&0x1b), "the error page echoes the target raw");
    let long = format!("/{}", "a".repeat(10_000));
    let (code, _, _) = get(server.addr(), &long);
    assert_eq!(code, 404);
    let (code, _, _) = request(server.addr(), "\x1b]0;pwned\x07 / HTTP/1.1\r\n\r\n");
    assert_eq!(code, 405, "an unknown method");
    let (code, _, _) = request(server.addr(), "GET\x1b[1m\r\n\r\n");
    assert_eq!(code, 400);

    let all = lines.all();
    for line in &all {
        assert!(
            line.bytes().all(|b| (0x20..0x7f).contains(&b)),
            "a log line with raw control or non-ASCII bytes: {line:?}"
        );
        assert!(
            line.len() < 4 * MAX_LOGGED_BYTES + 200,
            "a log line of {} bytes",
            line.len()
        );
    }
    let has = |needle: &str| all.iter().any(|l| l.contains(needle));
    assert!(
        has("404 GET /\\x1b[2J\\x1b[31mred\\x07\\x7f\\xe2\\x80\\xaetxt.exe"),
        "{all:?}"
    );
    assert!(has("404 GET /aaaa") && has("more bytes)"), "{all:?}");
    assert!(has("405 \\x1b]0;pwned\\x07 /"), "{all:?}");
    assert!(has("400") && has("GET\\x1b[1m"), "{all:?}");
}
