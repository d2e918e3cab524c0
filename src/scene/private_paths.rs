//! What an archive may say about where its capture came from: the capture folder's own name,
//! never a path of the machine that packed it. Archives are shared by link, and an absolute path
//! tells everyone the packer's folder layout and often their user name.
use std::path::Path;

/// The last component of `path`, for provenance: `/home/ana/scans/kitchen` -> `kitchen`. `.`
/// and `..` are resolved first (to name the folder, not to be stored); a path with no name at
/// all (`/`) is `capture`.
pub fn folder_name(path: &Path) -> String {
    let named = |p: &Path| p.file_name().map(|n| n.to_string_lossy().into_owned());
    named(path)
        .or_else(|| std::fs::canonicalize(path).ok().as_deref().and_then(named))
        .unwrap_or_else(|| "capture".into())
}

/// `text` with `folder` (a capture's path as it was given) replaced by `name`, then every
/// absolute path left (`/a/b/c`, `C:\a\b`, `\\server\share`) cut to `.../c`: notes name the
/// files they are about, under whatever path the capture was given.
pub fn scrub(text: &str, folder: Option<(&str, &str)>) -> String {
    let text = match folder {
        Some((path, name)) if !path.is_empty() && path != name => text.replace(path, name),
        _ => text.to_string(),
    };
    let mut out = String::with_capacity(text.len());
    let mut rest = text.as_str();
    while let Some(start) = absolute_start(rest) {
        out.push_str(&rest[..start]);
        let tail = &rest[start..];
        let end = tail
            .find(|c: char| c.is_whitespace() || matches!(c, ')' | '"' | '\'' | ',' | ';' | '`'))
            .unwrap_or(tail.len());
        let path = &tail[..end];
        let last = path
            .trim_end_matches(['/', '\\'])
            .rsplit(['/', '\\'])
            .next()
            .unwrap_or("");
        out.push_str(".../");
        out.push_str(last);
        rest = &tail[end..];
    }
    out.push_str(rest);
    out
}

/// Where the first absolute path of `text` starts: a `/` or `\` (or `X:\`, `X:/`) at the start
/// of a word, followed by a name and a second separator, so that "1/2" or "a / b" are left be.
fn absolute_start(text: &str) -> Option<usize> {
    let bytes = text.as_bytes();
    let word_start =
        |i: usize| i == 0 || matches!(bytes[i - 1], b' ' | b'\t' | b'\n' | b'(' | b'"' | b'\'' | b'`' | b'=');
    let sep = |b: u8| b == b'/' || b == b'\\';
    for i in 0..bytes.len() {
        if !word_start(i) {
            continue;
        }
        let body = if sep(bytes[i]) {
            i + 1
        } else if bytes[i].is_ascii_alphabetic()
            && bytes.get(i + 1) == Some(&b':')
            && bytes.get(i + 2).is_some_and(|&b| sep(b))
        {
            i + 3
        } else {
            continue;
        };
        let word_end = bytes[body..]
            .iter()
            .position(|&b| b.is_ascii_whitespace())
            .map_or(bytes.len(), |n| body + n);
        let word = &bytes[body..word_end];
        // A name, then another separator: a path of at least two levels.
        if word.first().is_some_and(|&b| !sep(b) || bytes[i] == b'\\') && word.iter().skip(1).any(|&b| sep(b)) {
            return Some(i);
        }
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn absolute_paths_are_cut_to_their_last_name() {
        assert_eq!(folder_name(Path::new("/home/ana/scans/kitchen")), "kitchen");
        assert_eq!(folder_name(Path::new("kitchen/")), "kitchen");
        assert_eq!(folder_name(Path::new("/")), "capture");
        assert_eq!(
            scrub(
                "skipped 2 frames (first: /home/ana/scans/kitchen/pose/12.txt)",
                Some(("/home/ana/scans/kitchen", "kitchen"))
            ),
            "skipped 2 frames (first: kitchen/pose/12.txt)"
        );
        assert_eq!(
            scrub("imported from /home/ana/npy, masks C:\\Users\\ana\\m.png", None),
            "imported from .../npy, masks .../m.png"
        );
        assert_eq!(scrub("ratio 1/2 and a / b, /x", None), "ratio 1/2 and a / b, /x");
    }
}
