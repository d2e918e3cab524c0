//! A tiny static file server for the web app (native only).
//!
//! Just enough HTTP/1.1 to serve `www/` on localhost: GET and HEAD of files under one directory,
//! the content types browsers insist on (`application/wasm` for streaming compilation),
//! `Cache-Control: no-cache` so a rebuild is picked up on reload, and nothing outside the
//! directory. A development server, not a production one (the built folder can be hosted by any
//! static host), but one that a misbehaving client cannot take down:
//! - a fixed pool of worker threads and a bounded queue (`pool.rs`); a connection that finds
//!   both full is answered 503 at once by a separate refuser, never given a thread of its own;
//! - a deadline for the whole request head (`request.rs`), not a timeout per read, so a client
//!   that dribbles bytes (slow loris) loses its worker after [`ServeConfig::request_deadline`];
//! - a write timeout, so a client that stops reading a response loses its worker too;
//! - request text in the log escaped and capped (`log.rs`).
//!
//! `Connection: close`: one request per connection.
use std::collections::VecDeque;
use std::fs::File;
use std::io::{self, Write};
use std::net::{Ipv4Addr, Shutdown, SocketAddr, TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

mod files;
mod log;
mod pool;
mod request;

pub use files::content_type;
use files::{Refusal, resolve_target};
pub use log::{Log, MAX_LOGGED_BYTES, escaped};
use pool::{Pool, Rejected};
pub use request::MAX_HEAD_BYTES;
use request::{RequestError, read_request_head};

/// How the server bounds its threads and the time a client may hold one.
#[derive(Clone, Debug)]
pub struct ServeConfig {
    /// Worker threads: at most this many requests are read or answered at once.
    pub workers: usize,
    /// Connections waiting for a worker; one more is refused with 503.
    pub queue: usize,
    /// Time from a worker taking a connection to the end of its request head.
    pub request_deadline: Duration,
    /// Longest wait for one write of a response to make progress.
    pub write_timeout: Duration,
    /// Where request lines and problems are logged.
    pub log: Log,
}

impl Default for ServeConfig {
    /// A page load is a handful of requests (html, js, wasm, the scene); 8 workers serve them in
    /// parallel, and 64 waiting covers a browser's bursts. A browser sends its request head in
    /// one packet, so 10 s is generous; 30 s without progress is a client that stopped reading.
    fn default() -> Self {
        ServeConfig {
            workers: 8,
            queue: 64,
            request_deadline: Duration::from_secs(10),
            write_timeout: Duration::from_secs(30),
            log: Log::stderr(),
        }
    }
}

/// Connections waiting to be told 503; when the refuser falls behind this far, the rest are
/// closed unanswered (a flood, not a browser).
const REFUSAL_QUEUE: usize = 64;
/// Longest wait for a 503 to be written; it fits an empty socket buffer, so this is rarely spent.
const REFUSAL_WRITE: Duration = Duration::from_millis(50);
/// How long a refused connection is kept open after its 503, unread: closing a socket with
/// unread input resets the connection, and a reset can reach the client before it has read the
/// 503. Kept in a list the refuser prunes at each refusal, never waited on, so a refusal costs
/// no time; at most [`REFUSAL_QUEUE`] are kept.
const REFUSAL_LINGER: Duration = Duration::from_secs(1);

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
    /// Binds `addr` (port 0 picks a free one) and serves `dir` from background threads, with
    /// the default [`ServeConfig`].
    pub fn start(dir: &Path, addr: SocketAddr) -> io::Result<Server> {
        Server::start_with(dir, addr, ServeConfig::default())
    }

    /// [`Server::start`] with other limits or another log.
    pub fn start_with(dir: &Path, addr: SocketAddr, config: ServeConfig) -> io::Result<Server> {
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
        let workers = {
            let (root, config) = (root.clone(), config.clone());
            Pool::start(config.workers, config.queue, move |stream| {
                handle_connection(stream, &root, &config)
            })?
        };
        let refuser = {
            let config = config.clone();
            let lingering = Mutex::new(VecDeque::new());
            Pool::start(1, REFUSAL_QUEUE, move |stream| refuse(stream, &config, &lingering))?
        };
        let accept_thread = {
            let (stopping, log) = (stopping.clone(), config.log.clone());
            std::thread::Builder::new()
                .name("serve-accept".into())
                .spawn(move || accept_loop(listener, &workers, &refuser, &stopping, &log))?
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

    /// Stops accepting connections and waits for the accept thread; requests in flight finish
    /// (each within its deadline and write timeout), then the workers exit.
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

/// Takes connections and queues them, never blocking on a client: a full queue sends the
/// connection to the refuser, a full refuser drops it. Returning drops both pools, which ends
/// their workers once they finish what they hold.
fn accept_loop(listener: TcpListener, workers: &Pool, refuser: &Pool, stopping: &AtomicBool, log: &Log) {
    for stream in listener.incoming() {
        if stopping.load(Ordering::SeqCst) {
            break;
        }
        let stream = match stream {
            Ok(s) => s,
            Err(e) => {
                log.line(&format!("serve: accept failed: {e}"));
                continue;
            }
        };
        match workers.offer(stream) {
            Ok(()) => {}
            Err(Rejected::Full(stream)) => {
                if let Err(Rejected::Full(s) | Rejected::Closed(s)) = refuser.offer(stream) {
                    log.line(&format!(
                        "serve: {}: dropped unanswered, every worker and both queues are full",
                        peer(&s)
                    ));
                }
            }
            Err(Rejected::Closed(_)) => break,
        }
    }
}

fn peer(stream: &TcpStream) -> String {
    stream.peer_addr().map_or_else(|_| "a client".into(), |a| a.to_string())
}

/// Answers a connection the workers have no room for: 503 and `Retry-After`, without reading
/// its request, then keeps it open a while (see [`REFUSAL_LINGER`]) in `lingering`.
fn refuse(stream: TcpStream, config: &ServeConfig, lingering: &Mutex<VecDeque<(TcpStream, Instant)>>) {
    config.log.line(&format!(
        "503 {}: all {} workers busy and {} connections waiting",
        peer(&stream),
        config.workers,
        config.queue
    ));
    let mut out = &stream;
    let _ = stream.set_write_timeout(Some(REFUSAL_WRITE));
    let body = "503 Service Unavailable: the server is busy; try again\n";
    let answer = format!(
        "HTTP/1.1 503 Service Unavailable\r\nContent-Type: text/plain; charset=utf-8\r\nContent-Length: {}\r\n\
         Retry-After: 1\r\nCache-Control: no-cache\r\nConnection: close\r\n\r\n{body}",
        body.len()
    );
    if out.write_all(answer.as_bytes()).is_err() {
        return;
    }
    let _ = stream.shutdown(Shutdown::Write);
    // Only the refuser thread takes this lock; a poisoned one still holds a usable list.
    let mut kept = lingering.lock().unwrap_or_else(|p| p.into_inner());
    let now = Instant::now();
    while kept
        .front()
        .is_some_and(|(_, since)| now.duration_since(*since) > REFUSAL_LINGER || kept.len() >= REFUSAL_QUEUE)
    {
        kept.pop_front();
    }
    kept.push_back((stream, now));
}

fn handle_connection(stream: TcpStream, root: &Path, config: &ServeConfig) {
    if let Err(e) = serve_connection(&stream, root, config) {
        // Clients hanging up mid-response are routine (reloads, cancelled fetches).
        if !matches!(e.kind(), io::ErrorKind::BrokenPipe | io::ErrorKind::ConnectionReset) {
            config.log.line(&format!("serve: {}: {e}", peer(&stream)));
        }
    }
}

fn serve_connection(stream: &TcpStream, root: &Path, config: &ServeConfig) -> io::Result<()> {
    stream.set_write_timeout(Some(config.write_timeout))?;
    let mut out = stream;
    let request = match read_request_head(stream, config.request_deadline) {
        Ok(Some(r)) => r,
        Ok(None) => return Ok(()), // closed before sending anything (e.g. our own wake-up)
        Err(problem) => {
            let (code, reason) = problem.status();
            config.log.line(&format!("{code} {}: {problem}", peer(stream)));
            if let RequestError::Io(_) = problem {
                return Ok(()); // the connection is broken: nobody to answer
            }
            return send_error(&mut out, code, reason, &problem.to_string(), false);
        }
    };
    let logged = |code: u16| {
        config.log.line(&format!(
            "{code} {} {}",
            escaped(&request.method),
            escaped(&request.target)
        ))
    };
    let head_only = match request.method.as_slice() {
        b"GET" => false,
        b"HEAD" => true,
        _ => {
            logged(405);
            return send_error(
                &mut out,
                405,
                "Method Not Allowed",
                "only GET and HEAD are served",
                false,
            );
        }
    };
    let status = match std::str::from_utf8(&request.target) {
        Ok(target) => respond(&mut out, root, target, head_only)?,
        Err(_) => {
            send_error(
                &mut out,
                400,
                "Bad Request",
                "request target is not UTF-8 (percent-encode it)",
                head_only,
            )?;
            400
        }
    };
    logged(status);
    out.flush()?;
    let _ = stream.shutdown(Shutdown::Write);
    Ok(())
}

/// Sends the file `target` names (or an error page) and returns the status code sent.
fn respond(out: &mut &TcpStream, root: &Path, target: &str, head_only: bool) -> io::Result<u16> {
    // Error pages quote the target escaped, like the log: it is whatever the client sent.
    let quoted = || escaped(target.as_bytes());
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
            send_error(
                out,
                404,
                "Not Found",
                &format!("{} does not exist", quoted()),
                head_only,
            )?;
            return Ok(404);
        }
    };
    let mut file = match File::open(&file_path) {
        Ok(f) => f,
        Err(e) => {
            send_error(out, 404, "Not Found", &format!("{}: {e}", quoted()), head_only)?;
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

fn send_error(out: &mut &TcpStream, code: u16, reason: &str, detail: &str, head_only: bool) -> io::Result<()> {
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
