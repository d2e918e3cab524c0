//! The text files of a Stray Scanner capture: `odometry.csv` (a header line, then one pose a
//! frame: `timestamp, frame, x, y, z, qx, qy, qz, qw`, ARKit's camera-to-world in metres with the
//! camera's axes x right, y up, z backward) and `camera_matrix.csv` (the 3x3 K of the video's
//! frames, comma-separated). Every error names the file, and where it is about one value, the
//! line and the value.
use glam::{DMat3, DMat4, DQuat, DVec3};

use super::text::{intrinsics_from_numbers, parse_numbers};
use crate::scene::camera::{Intrinsics, Pose};
use crate::scene::error::{Result, SceneError};

/// One row of `odometry.csv`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct OdometryRow {
    /// The video frame (and depth file) the pose is for.
    pub frame: u32,
    /// Camera-to-world, OpenCV axes.
    pub pose: Pose,
}

/// The columns `odometry.csv` must have, by the names of its header.
const COLUMNS: [&str; 9] = ["timestamp", "frame", "x", "y", "z", "qx", "qy", "qz", "qw"];
/// How far a quaternion's length may stray from 1: ARKit writes unit quaternions rounded to
/// float precision; farther means the columns are not a rotation.
const UNIT_TOLERANCE: f64 = 1e-3;
/// Frame numbers above this are not a phone's recording (days of 60 Hz video).
const MAX_FRAME: u32 = 100_000_000;

/// The rows of `odometry.csv`'s text, in the file's order; blank lines are skipped.
pub(super) fn parse_odometry(text: &str, file: &str) -> Result<Vec<OdometryRow>> {
    let mut lines = text.lines().enumerate().filter(|(_, l)| !l.trim().is_empty());
    let Some((_, header)) = lines.next() else {
        return Err(SceneError::invalid(
            file,
            "empty (expected a header line, then a pose a line)",
        ));
    };
    let names: Vec<String> = header.split(',').map(|w| w.trim().to_ascii_lowercase()).collect();
    let mut column = [0usize; COLUMNS.len()];
    for (slot, want) in column.iter_mut().zip(COLUMNS) {
        *slot = names.iter().position(|n| n == want).ok_or_else(|| {
            SceneError::invalid(
                file,
                format!(
                    "line 1: the header has no column {want:?} (expected `{}`, found `{}`)",
                    COLUMNS.join(", "),
                    header.trim()
                ),
            )
        })?;
    }
    let mut rows = Vec::new();
    let mut seen = std::collections::BTreeMap::new();
    for (i, line) in lines {
        let at = |what: String| SceneError::invalid(file, format!("line {}: {what}", i + 1));
        let words: Vec<&str> = line.split(',').map(str::trim).collect();
        if words.len() != names.len() {
            return Err(at(format!(
                "{} values for the header's {} columns",
                words.len(),
                names.len()
            )));
        }
        let mut v = [0.0f64; COLUMNS.len()];
        for ((value, &c), name) in v.iter_mut().zip(&column).zip(COLUMNS) {
            let word = words[c];
            *value = word
                .parse()
                .map_err(|_| at(format!("cannot read {name} {word:?} as a number")))?;
            if !value.is_finite() {
                return Err(at(format!("{name} = {word} is not a finite number")));
            }
        }
        let frame = v[1];
        if frame < 0.0 || frame.fract() != 0.0 || frame > MAX_FRAME as f64 {
            return Err(at(format!("frame = {} is not a frame number", words[column[1]])));
        }
        let frame = frame as u32;
        if let Some(first) = seen.insert(frame, i + 1) {
            return Err(at(format!(
                "a second pose for frame {frame} (the first is on line {first})"
            )));
        }
        let q = DQuat::from_xyzw(v[5], v[6], v[7], v[8]);
        if (q.length() - 1.0).abs() > UNIT_TOLERANCE {
            return Err(at(format!(
                "the quaternion (qx, qy, qz, qw) = ({}, {}, {}, {}) has length {:.4}, not 1: not a rotation",
                v[5],
                v[6],
                v[7],
                v[8],
                q.length()
            )));
        }
        let arkit = DMat4::from_mat3_translation(DMat3::from_quat(q.normalize()), DVec3::new(v[2], v[3], v[4]));
        let pose = Pose::from_opengl(arkit);
        pose.check().map_err(|p| at(p.to_string()))?;
        rows.push(OdometryRow { frame, pose });
    }
    if rows.is_empty() {
        return Err(SceneError::invalid(
            file,
            format!("no poses (expected one line `{}` a frame)", COLUMNS.join(", ")),
        ));
    }
    Ok(rows)
}

/// `camera_matrix.csv`'s text: K, three rows of three comma-separated numbers.
pub(super) fn parse_camera_matrix(text: &str, file: &str) -> Result<Intrinsics> {
    let v = parse_numbers(text, file)?;
    if v.len() != 9 {
        return Err(SceneError::invalid(
            file,
            format!(
                "expected the 3x3 camera matrix K (9 numbers), found {} numbers",
                v.len()
            ),
        ));
    }
    Ok(intrinsics_from_numbers(&v, file)?.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    const HEADER: &str = "timestamp, frame, x, y, z, qx, qy, qz, qw\n";

    fn err(r: Result<impl std::fmt::Debug>) -> String {
        r.unwrap_err().to_string()
    }

    #[test]
    fn rows_are_arkit_camera_to_world_turned_to_opencv_axes() {
        // A camera at (1, 2, 3) turned a quarter about the world's y axis (qy = sin 45°).
        let h = std::f64::consts::FRAC_1_SQRT_2;
        let text = format!("{HEADER}12.5, 0, 1, 2, 3, 0, {h}, 0, {h}\n\n12.6, 1, 0, 0, 0, 0, 0, 0, 1\n");
        let rows = parse_odometry(&text, "s/odometry.csv").unwrap();
        assert_eq!(rows.len(), 2);
        assert_eq!((rows[0].frame, rows[1].frame), (0, 1));
        assert!(rows[0].pose.position().abs_diff_eq(DVec3::new(1.0, 2.0, 3.0), 1e-12));
        // ARKit's camera looks along its -z: with no rotation, OpenCV's forward (+z) is the
        // world's -z, and its down (+y) the world's -y.
        let still = rows[1].pose;
        assert!(still.transform_vector(DVec3::Z).abs_diff_eq(-DVec3::Z, 1e-12));
        assert!(still.transform_vector(DVec3::Y).abs_diff_eq(-DVec3::Y, 1e-12));
        assert!(still.transform_vector(DVec3::X).abs_diff_eq(DVec3::X, 1e-12));
        // Turned a quarter about y, the camera looks along the world's -x.
        assert!(rows[0].pose.transform_vector(DVec3::Z).abs_diff_eq(-DVec3::X, 1e-12));
    }

    #[test]
    fn columns_are_found_by_their_names() {
        let text = "frame,qw,qx,qy,qz,x,y,z,timestamp\n7,1,0,0,0,4,5,6,0.1\n";
        let rows = parse_odometry(text, "o.csv").unwrap();
        assert_eq!(rows[0].frame, 7);
        assert!(rows[0].pose.position().abs_diff_eq(DVec3::new(4.0, 5.0, 6.0), 1e-12));
    }

    #[test]
    fn bad_odometry_names_the_file_line_and_value() {
        let f = "s/odometry.csv";
        let cases = [
            ("", "empty"),
            ("timestamp, frame, x, y, z\n", "no column \"qx\""),
            (&format!("{HEADER}0, 0, 1, 2, 3, 0, 0, 0\n") as &str, "line 2: 8 values"),
            (
                &format!("{HEADER}0, 0, 1, 2, nan, 0, 0, 0, 1\n"),
                "line 2: z = nan is not a finite",
            ),
            (
                &format!("{HEADER}0, 0, 1, 2, 1e400, 0, 0, 0, 1\n"),
                "z = 1e400 is not a finite",
            ),
            (
                &format!("{HEADER}0, 1.5, 1, 2, 3, 0, 0, 0, 1\n"),
                "frame = 1.5 is not a frame number",
            ),
            (&format!("{HEADER}0, -1, 1, 2, 3, 0, 0, 0, 1\n"), "frame = -1"),
            (
                &format!("{HEADER}0, 0, 1, 2, 3, 0, 0, 0, 2\n"),
                "has length 2.0000, not 1",
            ),
            (&format!("{HEADER}0, 0, 1, 2, 3, 0, 0, 0, 0\n"), "has length 0.0000"),
            (
                &format!("{HEADER}0, 3, 1, 2, 3, 0, 0, 0, 1\n0, 3, 1, 2, 3, 0, 0, 0, 1\n"),
                "line 3: a second pose for frame 3 (the first is on line 2)",
            ),
            (&format!("{HEADER}0, 0, x, 2, 3, 0, 0, 0, 1\n"), "cannot read x \"x\""),
            (HEADER, "no poses"),
            (&format!("{HEADER}0, 0, 1e39, 2, 3, 0, 0, 0, 1\n"), "line 2: pose"),
        ];
        for (text, want) in cases {
            let e = err(parse_odometry(text, f));
            assert!(e.contains(f) && e.contains(want), "{text:?}: {e}");
        }
    }

    #[test]
    fn camera_matrices_are_read_and_checked() {
        let k = parse_camera_matrix("1590.5,0.0,959.2\n0.0,1590.5,719.8\n0.0,0.0,1.0\n", "c.csv").unwrap();
        assert_eq!((k.fx, k.fy, k.cx, k.cy), (1590.5, 1590.5, 959.2, 719.8));
        let e = err(parse_camera_matrix("1,0,1\n0,1,1\n", "s/camera_matrix.csv"));
        assert!(
            e.contains("s/camera_matrix.csv") && e.contains("found 6 numbers"),
            "{e}"
        );
        let e = err(parse_camera_matrix("1,0,1\n0,1,1\n1,0,1\n", "s/camera_matrix.csv"));
        assert!(e.contains("not a camera matrix"), "{e}");
    }
}
