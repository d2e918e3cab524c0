//! Small text files of captures: matrices (intrinsics, poses), boxes and class-name lists. Every
//! error names the file, and where it is about one value, the line and the value.
use std::path::Path;

use crate::scene::camera::{Bounds, Intrinsics, Pose};
use crate::scene::error::{Result, SceneError};

/// Largest text file read as a matrix or list; anything bigger is not what we are looking for.
pub(super) const MAX_TEXT_BYTES: u64 = 1 << 20;

/// How far the last row of K may stray from (0 0 1) before the file is not a camera matrix.
const K_TOLERANCE: f64 = 1e-6;

pub(super) fn read_text(path: &Path) -> Result<String> {
    read_text_up_to(path, MAX_TEXT_BYTES)
}

/// [`read_text`] of a file that may be larger than a matrix (a trajectory of every frame).
pub(super) fn read_text_up_to(path: &Path, cap: u64) -> Result<String> {
    let meta = super::files::metadata(path).map_err(|e| SceneError::io(path, e))?;
    if meta.len() > cap {
        return Err(SceneError::invalid(
            path.display().to_string(),
            format!("{} bytes is far too large for this text file", meta.len()),
        ));
    }
    let bytes = super::files::read(path, cap).map_err(|e| SceneError::io(path, e))?;
    String::from_utf8(bytes).map_err(|_| SceneError::invalid(path.display().to_string(), "not a text file (not UTF-8)"))
}

/// All numbers of a whitespace- or comma-separated text, skipping blank lines and `#` comments.
pub(super) fn parse_numbers(text: &str, file: &str) -> Result<Vec<f64>> {
    let mut out = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let line = line.split('#').next().unwrap_or("");
        for word in line
            .split(|c: char| c.is_whitespace() || c == ',')
            .filter(|w| !w.is_empty())
        {
            let v: f64 = word
                .parse()
                .map_err(|_| SceneError::invalid(file, format!("line {}: cannot read {word:?} as a number", i + 1)))?;
            out.push(v);
        }
    }
    Ok(out)
}

fn read_numbers(path: &Path) -> Result<(Vec<f64>, String)> {
    let file = path.display().to_string();
    let text = read_text(path)?;
    Ok((parse_numbers(&text, &file)?, file))
}

/// A 3x3 camera matrix K, or a 4x4 one with K in its top-left corner (as ScanNet writes them).
/// Returns the intrinsics and a warning when K has a skew term, which a pinhole model ignores.
pub(super) fn read_intrinsics(path: &Path) -> Result<(Intrinsics, Option<String>)> {
    let (v, file) = read_numbers(path)?;
    intrinsics_from_numbers(&v, &file)
}

/// [`read_intrinsics`] on numbers already read (the fuzz targets feed text without files).
pub(super) fn intrinsics_from_numbers(v: &[f64], file: &str) -> Result<(Intrinsics, Option<String>)> {
    let k: [f64; 9] = match v.len() {
        9 => [v[0], v[1], v[2], v[3], v[4], v[5], v[6], v[7], v[8]],
        16 => [v[0], v[1], v[2], v[4], v[5], v[6], v[8], v[9], v[10]],
        n => {
            return Err(SceneError::invalid(
                file,
                format!("expected a 3x3 camera matrix K (9 numbers, or 16 for a 4x4), found {n} numbers"),
            ));
        }
    };
    parse_k(&k, file)
}

/// Checks a row-major 3x3 K and turns it into intrinsics.
pub(super) fn parse_k(k: &[f64; 9], file: &str) -> Result<(Intrinsics, Option<String>)> {
    if k.iter().any(|x| !x.is_finite()) {
        return Err(SceneError::invalid(
            file,
            format!("camera matrix has non-finite values: {k:?}"),
        ));
    }
    let lower = [k[3], k[6], k[7]];
    if lower.iter().any(|x| x.abs() > K_TOLERANCE) || (k[8] - 1.0).abs() > K_TOLERANCE {
        return Err(SceneError::invalid(
            file,
            format!(
                "not a camera matrix K: expected rows `fx 0 cx`, `0 fy cy`, `0 0 1`, got last rows `{} {} {}`, `{} {} {}`",
                k[3], k[4], k[5], k[6], k[7], k[8]
            ),
        ));
    }
    let intrinsics = Intrinsics {
        fx: k[0],
        fy: k[4],
        cx: k[2],
        cy: k[5],
    };
    intrinsics.check().map_err(|p| SceneError::invalid(file, p))?;
    let warning = (k[1].abs() > K_TOLERANCE).then(|| format!("{file}: skew {} ignored (pinhole model)", k[1]));
    Ok((intrinsics, warning))
}

/// A 4x4 (or 3x4, bottom row implied) row-major matrix, checked to be a rigid transform.
pub(super) fn read_pose(path: &Path) -> Result<Pose> {
    let (v, file) = read_numbers(path)?;
    pose_from_numbers(&v, &file)
}

pub(super) fn pose_from_numbers(v: &[f64], file: &str) -> Result<Pose> {
    let mut m = [0.0; 16];
    match v.len() {
        16 => m.copy_from_slice(v),
        12 => {
            m[..12].copy_from_slice(v);
            m[15] = 1.0;
        }
        n => {
            return Err(SceneError::invalid(
                file,
                format!("expected a 4x4 pose matrix (16 numbers, or 12 for 3x4), found {n} numbers"),
            ));
        }
    }
    let pose = Pose::from_row_major(&m);
    pose.check().map_err(|p| SceneError::invalid(file, p))?;
    Ok(pose)
}

/// `minx miny minz maxx maxy maxz [voxel size]`, as autolabel writes `bbox.txt`.
pub(super) fn read_bbox(path: &Path) -> Result<Bounds> {
    let (v, file) = read_numbers(path)?;
    if v.len() != 6 && v.len() != 7 {
        return Err(SceneError::invalid(
            file,
            format!(
                "expected `minx miny minz maxx maxy maxz [voxel]` (6 or 7 numbers), found {} numbers",
                v.len()
            ),
        ));
    }
    let bounds = Bounds {
        min: [v[0], v[1], v[2]],
        max: [v[3], v[4], v[5]],
    };
    bounds.check().map_err(|p| SceneError::invalid(file, p))?;
    Ok(bounds)
}

/// One class name per non-empty line.
pub(super) fn read_class_names(path: &Path) -> Result<Vec<String>> {
    let text = read_text(path)?;
    let names: Vec<String> = text
        .lines()
        .map(str::trim)
        .filter(|l| !l.is_empty())
        .map(String::from)
        .collect();
    if names.is_empty() {
        return Err(SceneError::invalid(path.display().to_string(), "lists no class names"));
    }
    Ok(names)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_error_names_line_and_word() {
        let err = parse_numbers("1 2 3\n4 five 6\n", "k.txt").unwrap_err().to_string();
        assert!(
            err.contains("k.txt") && err.contains("line 2") && err.contains("\"five\""),
            "{err}"
        );
        assert_eq!(parse_numbers("# c\n1,2\n\n 3e-1 ", "x").unwrap(), vec![1.0, 2.0, 0.3]);
    }

    #[test]
    fn k_must_look_like_a_camera_matrix() {
        let (k, warn) = parse_k(&[500.0, 0.0, 320.0, 0.0, 510.0, 240.0, 0.0, 0.0, 1.0], "k").unwrap();
        assert_eq!((k.fx, k.fy, k.cx, k.cy, warn), (500.0, 510.0, 320.0, 240.0, None));
        let err = parse_k(&[500.0, 0.0, 320.0, 0.0, 510.0, 240.0, 0.0, 0.0, 2.0], "k").unwrap_err();
        assert!(err.to_string().contains("not a camera matrix"));
        let err = parse_k(&[-5.0, 0.0, 320.0, 0.0, 510.0, 240.0, 0.0, 0.0, 1.0], "k").unwrap_err();
        assert!(err.to_string().contains("positive"));
        assert!(
            parse_k(&[500.0, 2.0, 320.0, 0.0, 510.0, 240.0, 0.0, 0.0, 1.0], "k")
                .unwrap()
                .1
                .is_some()
        );
    }

    #[test]
    fn poses_accept_3x4_and_reject_wrong_counts() {
        let p = pose_from_numbers(&[1.0, 0.0, 0.0, 2.0, 0.0, 1.0, 0.0, 3.0, 0.0, 0.0, 1.0, 4.0], "p").unwrap();
        assert_eq!(p.position().to_array(), [2.0, 3.0, 4.0]);
        let err = pose_from_numbers(&[1.0; 15], "p.txt").unwrap_err().to_string();
        assert!(err.contains("p.txt") && err.contains("found 15"), "{err}");
    }
}
