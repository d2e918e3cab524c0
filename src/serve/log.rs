//! The server's log: where lines go, and how request text is made safe to print. A request
//! target is whatever bytes a client sent; printed raw, ANSI escapes could rewrite the
//! developer's terminal and newlines could forge log lines.
use std::fmt;
use std::sync::Arc;

/// Longest piece of request text (target, method) printed; the rest is counted, not shown.
pub const MAX_LOGGED_BYTES: usize = 200;

/// Where the server's log lines go: stderr by default, anything else in tests.
#[derive(Clone)]
pub struct Log(Arc<dyn Fn(&str) + Send + Sync>);

impl Log {
    /// Each line to stderr, as a development server on a terminal should.
    pub fn stderr() -> Log {
        Log(Arc::new(|line| eprintln!("{line}")))
    }

    /// Each line to `sink` (a test collects them).
    pub fn to(sink: impl Fn(&str) + Send + Sync + 'static) -> Log {
        Log(Arc::new(sink))
    }

    pub fn line(&self, line: &str) {
        (self.0)(line)
    }
}

impl Default for Log {
    fn default() -> Self {
        Log::stderr()
    }
}

impl fmt::Debug for Log {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("Log")
    }
}

/// `bytes` as printable ASCII: bytes outside `0x20..=0x7e` (control characters, ESC, DEL and
/// every byte of a non-ASCII character, so no bidi override slips through either) become `\xHH`,
/// a backslash `\\`; at most [`MAX_LOGGED_BYTES`] input bytes are shown, then how many were left
/// out.
pub fn escaped(bytes: &[u8]) -> String {
    let shown = &bytes[..bytes.len().min(MAX_LOGGED_BYTES)];
    let mut out = String::with_capacity(shown.len() + 16);
    for &b in shown {
        match b {
            b'\\' => out.push_str("\\\\"),
            0x20..=0x7e => out.push(b as char),
            _ => out.push_str(&format!("\\x{b:02x}")),
        }
    }
    if bytes.len() > shown.len() {
        out.push_str(&format!("...({} more bytes)", bytes.len() - shown.len()));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn control_characters_and_non_ascii_are_escaped() {
        assert_eq!(escaped(b"/index.html?v=2"), "/index.html?v=2");
        assert_eq!(escaped(b"/\x1b[31mred\r\nX"), "/\\x1b[31mred\\x0d\\x0aX");
        assert_eq!(escaped("/é".as_bytes()), "/\\xc3\\xa9");
        assert_eq!(
            escaped(b"/a\\x1b"),
            "/a\\\\x1b",
            "a literal backslash cannot pass for an escape"
        );
        assert_eq!(escaped(b"\x7f\x00"), "\\x7f\\x00");
    }

    #[test]
    fn long_text_is_capped() {
        let long = vec![b'a'; MAX_LOGGED_BYTES + 50];
        let line = escaped(&long);
        assert!(line.starts_with(&"a".repeat(MAX_LOGGED_BYTES)));
        assert!(line.ends_with("...(50 more bytes)"), "{line}");
    }
}
