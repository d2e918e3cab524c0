//! The static server behind `scribblefield serve`, spoken to over real sockets.
use std::io::{Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::path::Path;

use scribblefield::serve::{Server, localhost};

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
