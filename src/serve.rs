//! A tiny static file server for the web app (native only).
//!
//! Just enough HTTP/1.1 to serve `www/` on localhost: GET and HEAD of files under one directory,
//! the content types browsers insist on (`application/wasm` for streaming compilation),
//! `Cache-Control: no-cache` so a rebuild is picked up on reload, and nothing outside the
//! directory. One thread per connection and `Connection: close`: a development server, not a
//! production one; the built folder can be hosted by any static host.
use std::fs::File;
use std::io::{self, BufRead, BufReader, Read, Write};
use std::net::{Ipv4Addr, Shutdown, SocketAddr, TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;
use std::time::Duration;

/// Longest request head (request line + headers) accepted; real browsers send a few hundred bytes.
const MAX_HEAD_BYTES: usize = 16 * 1024;
/// A client that sends nothing for this long is dropped, so idle connections do not pin threads.
const READ_TIMEOUT: Duration = Duration::from_secs(15);

/// The loopback address on `port`: the server is for the developer's own browser by default.
pub fn localhost(port: u16) -> SocketAddr {
    SocketAddr::from((Ipv4Addr::LOCALHOST, port))
}

/// Serves `dir` on `addr` until the process ends, logging each request to stderr. (The caller
/// prints the URL; [`Server::url`] has it when `addr` has port 0.)
pub fn serve(dir: &Path, addr: SocketAddr) -> io::Result<()> {
    Server::start(dir, addr)?.wait()
}

/// A running server; stops when dropped or on [`Server::stop`].
pub struct Server {
    addr: SocketAddr,
    root: PathBuf,
    stopping: Arc<AtomicBool>,
    accept_thread: Option<JoinHandle<()>>,
}

impl Server {
    /// Binds `addr` (port 0 picks a free one) and serves `dir` from a background thread.
    pub fn start(dir: &Path, addr: SocketAddr) -> io::Result<Server> {
        let root = dir
            .canonicalize()
            .map_err(|e| io::Error::new(e.kind(), format!("{}: cannot serve this directory: {e}", dir.display())))?;
        if !root.is_dir() {
            return Err(io::Error::new(
                io::ErrorKind::NotADirectory,
                format!("{}: not a directory", dir.display()),
            ));
        }
        let listener =
            TcpListener::bind(addr).map_err(|e| io::Error::new(e.kind(), format!("cannot listen on {addr}: {e}")))?;
        let addr = listener.local_addr()?;
        let stopping = Arc::new(AtomicBool::new(false));
        let accept_thread = {
            let (root, stopping) = (root.clone(), stopping.clone());
            std::thread::Builder::new()
                .name("serve-accept".into())
                .spawn(move || accept_loop(listener, root, stopping))?
        };
        Ok(Server {
            addr,
            root,
            stopping,
            accept_thread: Some(accept_thread),
        })
    }

    pub fn addr(&self) -> SocketAddr {
        self.addr
    }

    /// The directory being served, canonicalized.
    pub fn root(&self) -> &Path {
        &self.root
    }

    /// `http://host:port/`, the URL to open in a browser.
    pub fn url(&self) -> String {
        format!("http://{}/", self.addr)
    }

    /// Blocks until the server stops (it only stops when told to, so in practice: forever).
    pub fn wait(mut self) -> io::Result<()> {
        if let Some(thread) = self.accept_thread.take() {
            thread
                .join()
                .map_err(|_| io::Error::other("the server's accept thread panicked"))?;
        }
        Ok(())
    }

    /// Stops accepting connections and waits for the accept thread; requests in flight finish.
    pub fn stop(mut self) {
        self.shut_down();
    }

    fn shut_down(&mut self) {
        self.stopping.store(true, Ordering::SeqCst);
        // `accept` has no timeout: wake it with a connection of our own so it sees the flag.
        let _ = TcpStream::connect_timeout(&wake_address(self.addr), Duration::from_secs(1));
        if let Some(thread) = self.accept_thread.take() {
            let _ = thread.join();
        }
    }
}

impl Drop for Server {
    fn drop(&mut self) {
        if self.accept_thread.is_some() {
            self.shut_down();
        }
    }
}

/// An address that reaches a listener bound to `addr` (a wildcard address cannot be dialled).
fn wake_address(addr: SocketAddr) -> SocketAddr {
    if addr.ip().is_unspecified() {
        localhost(addr.port())
    } else {
        addr
    }
}

fn accept_loop(listener: TcpListener, root: PathBuf, stopping: Arc<AtomicBool>) {
    for stream in listener.incoming() {
        if stopping.load(Ordering::SeqCst) {
            break;
        }
        let stream = match stream {
            Ok(s) => s,
            Err(e) => {
                eprintln!("serve: accept failed: {e}");
                continue;
            }
        };
        let root = root.clone();
        let spawned = std::thread::Builder::new().name("serve-conn".into()).spawn(move || {
            if let Err(e) = handle_connection(stream, &root) {
                // Clients hanging up mid-response are routine (reloads, cancelled fetches).
                if !matches!(e.kind(), io::ErrorKind::BrokenPipe | io::ErrorKind::ConnectionReset) {
                    eprintln!("serve: {e}");
                }
            }
        });
        if let Err(e) = spawned {
            eprintln!("serve: cannot start a connection thread: {e}");
        }
    }
}

/// What a request asks for, once its head is parsed.
struct Request {
    method: String,
    target: String,
}

fn handle_connection(stream: TcpStream, root: &Path) -> io::Result<()> {
    stream.set_read_timeout(Some(READ_TIMEOUT))?;
    let mut reader = BufReader::new(stream.try_clone()?);
    let mut out = stream;
    let request = match read_request_head(&mut reader) {
        Ok(Some(r)) => r,
        Ok(None) => return Ok(()), // closed before sending anything (e.g. our own wake-up)
        Err(problem) => {
            eprintln!("400 {problem}");
            return send_error(&mut out, 400, "Bad Request", &problem, false);
        }
    };
    let head_only = match request.method.as_str() {
        "GET" => false,
        "HEAD" => true,
        _ => {
            return send_error(
                &mut out,
                405,
                "Method Not Allowed",
                "only GET and HEAD are served",
                false,
            );
        }
    };
    let status = respond(&mut out, root, &request.target, head_only)?;
    eprintln!("{status} {} {}", request.method, request.target);
    out.flush()?;
    let _ = out.shutdown(Shutdown::Write);
    Ok(())
}

/// Reads the request line and skips the headers. `Ok(None)`: the client closed without a request.
fn read_request_head(reader: &mut impl BufRead) -> Result<Option<Request>, String> {
    let mut total = 0usize;
    let mut request_line = String::new();
    let n = read_limited_line(reader, &mut request_line, &mut total)?;
    if n == 0 {
        return Ok(None);
    }
    loop {
        let mut header = String::new();
        if read_limited_line(reader, &mut header, &mut total)? == 0 || header.trim_end().is_empty() {
            break;
        }
    }
    let mut parts = request_line.split_whitespace();
    match (parts.next(), parts.next(), parts.next()) {
        (Some(method), Some(target), Some(version)) if version.starts_with("HTTP/1.") => Ok(Some(Request {
            method: method.to_string(),
            target: target.to_string(),
        })),
        _ => Err(format!("malformed request line {:?}", request_line.trim_end())),
    }
}

fn read_limited_line(reader: &mut impl BufRead, line: &mut String, total: &mut usize) -> Result<usize, String> {
    let budget = MAX_HEAD_BYTES.saturating_sub(*total) as u64 + 1;
    let n = reader
        .take(budget)
        .read_line(line)
        .map_err(|e| format!("cannot read the request: {e}"))?;
    *total += n;
    if *total > MAX_HEAD_BYTES {
        return Err(format!("request head longer than {MAX_HEAD_BYTES} bytes"));
    }
    Ok(n)
}

/// Sends the file `target` names (or an error page) and returns the status code sent.
fn respond(out: &mut TcpStream, root: &Path, target: &str, head_only: bool) -> io::Result<u16> {
    let file_path = match resolve_target(root, target) {
        Ok(p) => p,
        Err(Refusal::BadPath(problem)) => {
            send_error(out, 400, "Bad Request", &problem, head_only)?;
            return Ok(400);
        }
        Err(Refusal::Outside) => {
            send_error(out, 403, "Forbidden", "path leaves the served directory", head_only)?;
            return Ok(403);
        }
        Err(Refusal::NotFound) => {
            send_error(out, 404, "Not Found", &format!("{target} does not exist"), head_only)?;
            return Ok(404);
        }
    };
    let mut file = match File::open(&file_path) {
        Ok(f) => f,
        Err(e) => {
            send_error(out, 404, "Not Found", &format!("{target}: {e}"), head_only)?;
            return Ok(404);
        }
    };
    let len = file.metadata()?.len();
    write!(
        out,
        "HTTP/1.1 200 OK\r\nContent-Type: {}\r\nContent-Length: {len}\r\nCache-Control: no-cache\r\n\
         X-Content-Type-Options: nosniff\r\nConnection: close\r\n\r\n",
        content_type(&file_path)
    )?;
    if !head_only {
        io::copy(&mut file, out)?;
    }
    Ok(200)
}

fn send_error(out: &mut TcpStream, code: u16, reason: &str, detail: &str, head_only: bool) -> io::Result<()> {
    let body = format!("{code} {reason}: {detail}\n");
    write!(
        out,
        "HTTP/1.1 {code} {reason}\r\nContent-Type: text/plain; charset=utf-8\r\nContent-Length: {}\r\n\
         Cache-Control: no-cache\r\nConnection: close\r\n\r\n",
        body.len()
    )?;
    if !head_only {
        out.write_all(body.as_bytes())?;
    }
    out.flush()
}

/// Why a request target does not map to a file that may be served.
#[derive(Debug, PartialEq)]
enum Refusal {
    BadPath(String),
    Outside,
    NotFound,
}

/// Maps a request target to a file under `root`. `..` segments are refused outright rather than
/// normalized, and the final path is canonicalized so a symlink cannot lead out of `root` either.
fn resolve_target(root: &Path, target: &str) -> Result<PathBuf, Refusal> {
    let path = target.split(['?', '#']).next().unwrap_or("");
    if !path.starts_with('/') {
        return Err(Refusal::BadPath(format!(
            "request target {target:?} is not an absolute path"
        )));
    }
    let decoded = crate::percent::decode_strict(path)
        .ok_or_else(|| Refusal::BadPath(format!("bad percent-encoding in {target:?}")))?;
    let mut relative = PathBuf::new();
    for segment in decoded.split('/') {
        match segment {
            "" | "." => {}
            ".." => return Err(Refusal::Outside),
            s if s.contains(['\\', '\0', ':']) => {
                return Err(Refusal::BadPath(format!("path segment {s:?} is not allowed")));
            }
            s => relative.push(s),
        }
    }
    let mut candidate = root.join(&relative);
    if candidate.is_dir() {
        candidate.push("index.html");
    }
    let real = candidate.canonicalize().map_err(|_| Refusal::NotFound)?;
    if !real.starts_with(root) {
        return Err(Refusal::Outside);
    }
    if !real.is_file() {
        return Err(Refusal::NotFound);
    }
    Ok(real)
}

/// The Content-Type for a file, by extension. Browsers refuse to stream-compile wasm and to run
/// module scripts served with the wrong type, so these must be right.
pub fn content_type(path: &Path) -> &'static str {
    let ext = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
    match ext.as_deref() {
        Some("html" | "htm") => "text/html; charset=utf-8",
        Some("js" | "mjs") => "text/javascript; charset=utf-8",
        Some("wasm") => "application/wasm",
        Some("json") => "application/json",
        Some("css") => "text/css; charset=utf-8",
        Some("zip") => "application/zip",
        Some("png") => "image/png",
        Some("jpg" | "jpeg") => "image/jpeg",
        Some("svg") => "image/svg+xml",
        Some("ico") => "image/x-icon",
        Some("txt" | "md" | "wgsl") => "text/plain; charset=utf-8",
        _ => "application/octet-stream",
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percent_decoding() {
        assert_eq!(
            crate::percent::decode_strict("/a%20b/c%2Fd").as_deref(),
            Some("/a b/c/d")
        );
        assert_eq!(crate::percent::decode_strict("/plain").as_deref(), Some("/plain"));
        assert_eq!(crate::percent::decode_strict("/bad%2"), None);
        assert_eq!(crate::percent::decode_strict("/bad%zz"), None);
        assert_eq!(crate::percent::decode_strict("/notutf8%ff"), None);
    }

    #[test]
    fn targets_map_inside_the_root_only() {
        let dir = tempfile::tempdir().unwrap();
        let root = dir.path().canonicalize().unwrap();
        std::fs::create_dir(root.join("sub")).unwrap();
        std::fs::write(root.join("index.html"), "home").unwrap();
        std::fs::write(root.join("sub/a b.txt"), "x").unwrap();

        assert_eq!(resolve_target(&root, "/"), Ok(root.join("index.html")));
        assert_eq!(
            resolve_target(&root, "/index.html?v=2#top"),
            Ok(root.join("index.html"))
        );
        assert_eq!(resolve_target(&root, "/sub/a%20b.txt"), Ok(root.join("sub/a b.txt")));
        assert_eq!(
            resolve_target(&root, "/sub"),
            Err(Refusal::NotFound),
            "a folder without index.html"
        );
        assert_eq!(resolve_target(&root, "/missing.js"), Err(Refusal::NotFound));
        assert_eq!(resolve_target(&root, "/../etc/passwd"), Err(Refusal::Outside));
        assert_eq!(resolve_target(&root, "/sub/%2e%2e/%2e%2e/x"), Err(Refusal::Outside));
        assert!(matches!(resolve_target(&root, "/a\\..\\b"), Err(Refusal::BadPath(_))));
        assert!(matches!(resolve_target(&root, "relative"), Err(Refusal::BadPath(_))));
    }

    #[cfg(unix)]
    #[test]
    fn symlinks_out_of_the_root_are_refused() {
        let outside = tempfile::tempdir().unwrap();
        std::fs::write(outside.path().join("secret.txt"), "s").unwrap();
        let dir = tempfile::tempdir().unwrap();
        let root = dir.path().canonicalize().unwrap();
        std::os::unix::fs::symlink(outside.path().join("secret.txt"), root.join("link.txt")).unwrap();
        assert_eq!(resolve_target(&root, "/link.txt"), Err(Refusal::Outside));
    }

    #[test]
    fn content_types() {
        assert_eq!(content_type(Path::new("pkg/x_bg.wasm")), "application/wasm");
        assert_eq!(content_type(Path::new("pkg/x.js")), "text/javascript; charset=utf-8");
        assert_eq!(content_type(Path::new("INDEX.HTML")), "text/html; charset=utf-8");
        assert_eq!(content_type(Path::new("demo.scene.zip")), "application/zip");
        assert_eq!(content_type(Path::new("noext")), "application/octet-stream");
    }
}
