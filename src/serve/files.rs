//! Which file a request target names: inside the served folder only, and with the content type
//! browsers insist on.
use std::path::{Path, PathBuf};

/// Why a request target does not map to a file that may be served.
#[derive(Debug, PartialEq)]
pub enum Refusal {
    BadPath(String),
    Outside,
    NotFound,
}

/// Maps a request target to a file under `root`. `..` segments are refused outright rather than
/// normalized, and the final path is canonicalized so a symlink cannot lead out of `root` either.
pub fn resolve_target(root: &Path, target: &str) -> Result<PathBuf, Refusal> {
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
