//! Reading one request head (request line and headers) from a client, whole, before a
//! deadline. The deadline is for the whole head, not for each read: a client that sends a byte
//! every few seconds (slow loris) would otherwise hold its worker for as long as it likes.
use std::io::{self, BufRead, BufReader, Read};
use std::net::TcpStream;
use std::time::{Duration, Instant};

use thiserror::Error;

use super::log::escaped;

/// Longest request head (request line + headers) accepted; real browsers send a few hundred bytes.
pub const MAX_HEAD_BYTES: usize = 16 * 1024;

/// What a request asks for, once its head is read. Method and target are raw bytes: they are
/// only ever printed through [`escaped`].
#[derive(Debug)]
pub struct Request {
    pub method: Vec<u8>,
    pub target: Vec<u8>,
}

/// Why no request could be read.
#[derive(Debug, Error)]
pub enum RequestError {
    #[error("request head not complete within {0:?}")]
    Deadline(Duration),
    #[error("request head longer than {MAX_HEAD_BYTES} bytes")]
    TooLong,
    #[error("malformed request line \"{}\"", escaped(.0))]
    Malformed(Vec<u8>),
    #[error("cannot read the request: {0}")]
    Io(#[source] io::Error),
}

impl RequestError {
    /// The status code answered, and its reason phrase.
    pub fn status(&self) -> (u16, &'static str) {
        match self {
            RequestError::Deadline(_) => (408, "Request Timeout"),
            RequestError::TooLong => (431, "Request Header Fields Too Large"),
            RequestError::Malformed(_) | RequestError::Io(_) => (400, "Bad Request"),
        }
    }
}

/// A socket whose every read waits at most until one instant: each read's timeout is the time
/// left, and a read after the instant fails at once.
struct DeadlineReader<'a> {
    stream: &'a TcpStream,
    deadline: Instant,
}

impl Read for DeadlineReader<'_> {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        let left = self.deadline.saturating_duration_since(Instant::now());
        if left.is_zero() {
            return Err(io::ErrorKind::TimedOut.into());
        }
        self.stream.set_read_timeout(Some(left))?;
        self.stream.read(buf)
    }
}

/// Reads the request line and skips the headers, all within `limit` of now. `Ok(None)`: the
/// client closed without sending anything (our own wake-up connection, a browser's spare one).
pub fn read_request_head(stream: &TcpStream, limit: Duration) -> Result<Option<Request>, RequestError> {
    let deadline = Instant::now() + limit;
    let mut reader = BufReader::new(DeadlineReader { stream, deadline });
    let timed_out = |e: io::Error| match e.kind() {
        // A socket read timeout shows as WouldBlock on Unix and TimedOut on Windows.
        io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut => RequestError::Deadline(limit),
        _ => RequestError::Io(e),
    };
    let mut total = 0usize;
    let mut request_line = Vec::new();
    if read_limited_line(&mut reader, &mut request_line, &mut total).map_err(|e| e.map_io(timed_out))? == 0 {
        return Ok(None);
    }
    loop {
        let mut header = Vec::new();
        let n = read_limited_line(&mut reader, &mut header, &mut total).map_err(|e| e.map_io(timed_out))?;
        if n == 0 || header.trim_ascii().is_empty() {
            break;
        }
    }
    parse_request_line(&request_line).map(Some)
}

impl RequestError {
    fn map_io(self, f: impl Fn(io::Error) -> RequestError) -> RequestError {
        match self {
            RequestError::Io(e) => f(e),
            other => other,
        }
    }
}

/// `METHOD TARGET HTTP/1.x`.
fn parse_request_line(line: &[u8]) -> Result<Request, RequestError> {
    let mut parts = line.split(u8::is_ascii_whitespace).filter(|p| !p.is_empty());
    match (parts.next(), parts.next(), parts.next(), parts.next()) {
        (Some(method), Some(target), Some(version), None) if version.starts_with(b"HTTP/1.") => Ok(Request {
            method: method.to_vec(),
            target: target.to_vec(),
        }),
        _ => Err(RequestError::Malformed(line.trim_ascii_end().to_vec())),
    }
}

/// One line (to `\n`) into `line`, counting against [`MAX_HEAD_BYTES`] over the whole head.
fn read_limited_line(reader: &mut impl BufRead, line: &mut Vec<u8>, total: &mut usize) -> Result<usize, RequestError> {
    let budget = MAX_HEAD_BYTES.saturating_sub(*total) as u64 + 1;
    let n = reader.take(budget).read_until(b'\n', line).map_err(RequestError::Io)?;
    *total += n;
    if *total > MAX_HEAD_BYTES {
        return Err(RequestError::TooLong);
    }
    Ok(n)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn request_lines() {
        let r = parse_request_line(b"GET /a%20b HTTP/1.1\r\n").unwrap();
        assert_eq!(
            (r.method.as_slice(), r.target.as_slice()),
            (&b"GET"[..], &b"/a%20b"[..])
        );
        assert!(matches!(
            parse_request_line(b"NONSENSE\r\n"),
            Err(RequestError::Malformed(_))
        ));
        assert!(matches!(
            parse_request_line(b"GET / HTTP/2\r\n"),
            Err(RequestError::Malformed(_))
        ));
        assert!(matches!(
            parse_request_line(b"GET / x HTTP/1.1\r\n"),
            Err(RequestError::Malformed(_))
        ));
        let e = parse_request_line(b"\x1b[2J HTTP/1.1").unwrap_err().to_string();
        assert!(e.contains("\\x1b[2J") && !e.contains('\x1b'), "{e}");
    }
}
