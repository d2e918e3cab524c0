//! The names masks get after the frames they are of. An archive keeps the name each frame had
//! in its capture (`source` in scene.json: a photo's file name, a video frame's number), and
//! tools that pair masks with images go by that name. Each name is made a safe relative path
//! without the image's extension; masks by these names sit beside the ones by index.

/// Image extensions dropped from a frame's name (compared ignoring case).
const IMAGE_EXTENSIONS: &[&str] = &["png", "jpg", "jpeg", "tif", "tiff", "bmp", "webp", "exr"];

/// The by-name path (no extension, `/` between folders) of each frame whose capture name is
/// `sources[i]`. File names alone where they are all different (ignoring case, as some file
/// systems do), else the capture's relative paths; a frame without a name, or one whose name
/// is still taken, is named by its index (`00012`, or `name-00012`).
pub fn frame_names(sources: &[Option<&str>]) -> Vec<String> {
    let paths: Vec<Option<Vec<String>>> = sources.iter().map(|s| s.and_then(safe_components)).collect();
    let file_names: Vec<Option<String>> = paths
        .iter()
        .map(|p| p.as_ref().and_then(|c| c.last().cloned()))
        .collect();
    let unique = {
        let mut seen = std::collections::HashSet::new();
        file_names.iter().flatten().all(|n| seen.insert(n.to_lowercase()))
    };
    let chosen: Vec<Option<String>> = if unique {
        file_names
    } else {
        paths.iter().map(|p| p.as_ref().map(|c| c.join("/"))).collect()
    };
    let mut taken = std::collections::HashSet::new();
    // Claim what is free first, so that an index name never takes a capture's name.
    let mut out: Vec<Option<String>> = chosen
        .into_iter()
        .map(|name| name.filter(|n| taken.insert(n.to_lowercase())))
        .collect();
    for (i, name) in out.iter_mut().enumerate() {
        if name.is_none() {
            let base = match sources[i].and_then(safe_components) {
                Some(c) if unique => c.last().cloned().unwrap_or_default(),
                Some(c) => c.join("/"),
                None => String::new(),
            };
            let mut candidate = if base.is_empty() {
                format!("{i:05}")
            } else {
                format!("{base}-{i:05}")
            };
            if taken.contains(&candidate.to_lowercase()) {
                candidate = format!("{candidate}-{i:05}");
            }
            while !taken.insert(candidate.to_lowercase()) {
                candidate.push('_');
            }
            *name = Some(candidate);
        }
    }
    out.into_iter().flatten().collect()
}

/// `source` as relative path components fit for any file system: `.`, `..` and empty
/// components dropped, other characters than letters, digits, `-`, `_` and `.` made `_`,
/// the last component without its image extension. None when nothing is left.
fn safe_components(source: &str) -> Option<Vec<String>> {
    let mut parts: Vec<String> = source
        .split(['/', '\\'])
        .filter(|c| !c.is_empty() && *c != "." && *c != "..")
        .map(|c| {
            c.chars()
                .map(|ch| {
                    if ch.is_alphanumeric() || matches!(ch, '-' | '_' | '.') {
                        ch
                    } else {
                        '_'
                    }
                })
                .collect()
        })
        .collect();
    let last = parts.last_mut()?;
    if let Some((stem, ext)) = last.rsplit_once('.')
        && !stem.is_empty()
        && IMAGE_EXTENSIONS.iter().any(|e| e.eq_ignore_ascii_case(ext))
    {
        *last = stem.to_string();
    }
    // A leading dot would hide the file on most systems.
    for part in parts.iter_mut() {
        if part.starts_with('.') {
            part.replace_range(..1, "_");
        }
    }
    Some(parts)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(sources: &[Option<&str>]) -> Vec<String> {
        frame_names(sources)
    }

    #[test]
    fn photos_lose_their_extension_and_video_frames_keep_their_number() {
        assert_eq!(
            names(&[Some("IMG_0001.JPG"), Some("IMG_0002.jpeg")]),
            ["IMG_0001", "IMG_0002"]
        );
        assert_eq!(
            names(&[Some("000000"), Some("000010"), Some("frame-000020")]),
            ["000000", "000010", "frame-000020"]
        );
        // ScanNet and transforms.json name frames by a path: the file name is enough.
        assert_eq!(names(&[Some("color/0.jpg"), Some("./train/r_1")]), ["0", "r_1"]);
    }

    #[test]
    fn clashing_file_names_keep_their_folders() {
        assert_eq!(
            names(&[Some("cam1/0001.jpg"), Some("cam2/0001.jpg"), Some("cam2/0002.jpg")]),
            ["cam1/0001", "cam2/0001", "cam2/0002"]
        );
        // Differing only in case clashes too.
        assert_eq!(names(&[Some("a/X.png"), Some("b/x.png")]), ["a/X", "b/x"]);
    }

    #[test]
    fn unsafe_or_missing_names_are_made_safe_or_indexed() {
        assert_eq!(
            names(&[Some("../../etc/pass wd.png"), None, Some(".hidden.jpg"), Some("/")]),
            ["pass_wd", "00001", "_hidden", "00003"]
        );
        // A capture name that looks like an index keeps it; the frame without a name moves.
        assert_eq!(names(&[None, Some("00000")]), ["00000-00000", "00000"]);
        // Two names equal once made safe.
        assert_eq!(names(&[Some("a b"), Some("a_b")]), ["a_b", "a_b-00001"]);
        assert_eq!(names(&[Some("photo.tar.gz")]), ["photo.tar.gz"]);
    }
}
