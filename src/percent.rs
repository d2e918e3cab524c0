//! Percent-encoding (`%XX`, RFC 3986) for the page's URL fragment and the file server's request
//! paths: one escape decoder, with the two policies its callers need.

/// Percent-encodes everything but unreserved characters and `/ : ? @ ! $ ' ( ) * + , ;`, which
/// keeps URLs readable while `&`, `=`, `#` and `%` cannot break the fragment apart.
pub fn encode(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for b in s.bytes() {
        if b.is_ascii_alphanumeric() || b"-._~/:?@!$'()*+,;".contains(&b) {
            out.push(b as char);
        } else {
            out.push_str(&format!("%{b:02X}"));
        }
    }
    out
}

/// Decodes `%XX` escapes; `None` at a malformed escape (a `%` not followed by two hex digits)
/// or when the result is not UTF-8. For request paths, where anything odd is refused.
pub fn decode_strict(s: &str) -> Option<String> {
    String::from_utf8(decode_bytes(s, true)?).ok()
}

/// Decodes `%XX` escapes; malformed escapes and invalid UTF-8 are kept as written, so a bad URL
/// in the page's fragment reaches the loader (which says what is wrong with it) rather than
/// vanishing.
pub fn decode_lenient(s: &str) -> String {
    let bytes = decode_bytes(s, false).unwrap_or_default();
    String::from_utf8(bytes).unwrap_or_else(|_| s.to_string())
}

/// The bytes `s` stands for; with `strict`, `None` at a malformed escape, else the escape is
/// kept as written.
fn decode_bytes(s: &str, strict: bool) -> Option<Vec<u8>> {
    let bytes = s.as_bytes();
    let hex = |i: usize| bytes.get(i).and_then(|&b| (b as char).to_digit(16));
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        if bytes[i] == b'%' {
            if let (Some(h), Some(l)) = (hex(i + 1), hex(i + 2)) {
                out.push((h * 16 + l) as u8);
                i += 3;
                continue;
            }
            if strict {
                return None;
            }
        }
        out.push(bytes[i]);
        i += 1;
    }
    Some(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_two_policies_agree_on_good_input_and_differ_on_bad() {
        for s in ["/a%20b/c%2Fd", "/plain", "%E2%98%95", ""] {
            assert_eq!(decode_strict(s), Some(decode_lenient(s)), "{s}");
        }
        for bad in ["/bad%2", "/bad%zz", "/notutf8%ff", "%+F"] {
            assert_eq!(decode_strict(bad), None, "{bad}");
        }
        assert_eq!(decode_lenient("%E2%98%95%zz"), "☕%zz");
        assert_eq!(decode_lenient("/notutf8%ff"), "/notutf8%ff");
    }

    #[test]
    fn encoding_round_trips_and_keeps_urls_readable() {
        let url = "https://example.org/a b/scene.zip?x=1&y=☕#top";
        let encoded = encode(url);
        assert_eq!(
            encoded,
            "https://example.org/a%20b/scene.zip?x%3D1%26y%3D%E2%98%95%23top"
        );
        assert_eq!(decode_strict(&encoded).as_deref(), Some(url));
    }
}
