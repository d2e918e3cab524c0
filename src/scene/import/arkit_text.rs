//! The text files of an ARKitScenes raw scene: `lowres_wide.traj` (one pose a line:
//! `timestamp rx ry rz tx ty tz`, an angle-axis rotation in radians and a translation in metres,
//! world-to-camera) and `lowres_wide_intrinsics/*.pincam` (one line: `width height fx fy cx cy`),
//! and the timestamps in the frames' file names (`<video_id>_<timestamp>.png`). Every error
//! names the file, and where it is about one value, the line and the value.
use glam::{DMat3, DMat4, DVec3};

use crate::scene::camera::{Intrinsics, Pose};
use crate::scene::error::{Result, SceneError};

/// One line of `lowres_wide.traj`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct TimedPose {
    /// Seconds, on the clock the frames' names use.
    pub time: f64,
    /// Camera-to-world, OpenCV axes (the inverse of the line's transform).
    pub pose: Pose,
}

/// A `.pincam`: the camera and the image size it is for.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Pincam {
    pub size: (u32, u32),
    pub k: Intrinsics,
}

/// Words of one line as numbers, each finite; `names` says what each is, for messages.
fn finite_words(line: &str, index: usize, file: &str, names: &[&str], form: &str) -> Result<Vec<f64>> {
    let words: Vec<&str> = line.split_whitespace().collect();
    if words.len() != names.len() {
        return Err(SceneError::invalid(
            file,
            format!(
                "line {}: expected {} numbers `{form}`, found {} words",
                index + 1,
                names.len(),
                words.len()
            ),
        ));
    }
    words
        .iter()
        .zip(names)
        .map(|(word, name)| {
            let v: f64 = word.parse().map_err(|_| {
                SceneError::invalid(
                    file,
                    format!("line {}: cannot read {name} {word:?} as a number", index + 1),
                )
            })?;
            if !v.is_finite() {
                return Err(SceneError::invalid(
                    file,
                    format!("line {}: {name} = {word} is not a finite number", index + 1),
                ));
            }
            Ok(v)
        })
        .collect()
}

const TRAJ_FIELDS: [&str; 7] = ["timestamp", "rx", "ry", "rz", "tx", "ty", "tz"];
const TRAJ_FORM: &str = "timestamp rx ry rz tx ty tz";

/// The poses of a `.traj` file's text, in the file's order; blank lines are skipped.
pub(super) fn parse_traj(text: &str, file: &str) -> Result<Vec<TimedPose>> {
    let mut out = Vec::new();
    for (i, line) in text.lines().enumerate() {
        if line.trim().is_empty() {
            continue;
        }
        let v = finite_words(line, i, file, &TRAJ_FIELDS, TRAJ_FORM)?;
        let rotation = rotation_from_angle_axis(DVec3::new(v[1], v[2], v[3]));
        let world_to_camera = DMat4::from_mat3_translation(rotation, DVec3::new(v[4], v[5], v[6]));
        let pose = Pose(world_to_camera).inverse();
        pose.check()
            .map_err(|p| SceneError::invalid(file, format!("line {}: {p}", i + 1)))?;
        out.push(TimedPose { time: v[0], pose });
    }
    if out.is_empty() {
        return Err(SceneError::invalid(
            file,
            format!("no poses (expected one line `{TRAJ_FORM}` per pose)"),
        ));
    }
    Ok(out)
}

/// The rotation of angle |r| about r's direction (Rodrigues' formula, as OpenCV's `Rodrigues`
/// that ARKitScenes' own loader calls).
pub(super) fn rotation_from_angle_axis(r: DVec3) -> DMat3 {
    let angle = r.length();
    if angle < 1e-12 {
        // First order: exact to rounding at such angles, and no division by ~0.
        return DMat3::IDENTITY + cross_matrix(r);
    }
    let k = r / angle;
    let outer = DMat3::from_cols(k * k.x, k * k.y, k * k.z);
    DMat3::IDENTITY * angle.cos() + cross_matrix(k) * angle.sin() + outer * (1.0 - angle.cos())
}

/// The matrix of `v x _`.
fn cross_matrix(v: DVec3) -> DMat3 {
    DMat3::from_cols(
        DVec3::new(0.0, v.z, -v.y),
        DVec3::new(-v.z, 0.0, v.x),
        DVec3::new(v.y, -v.x, 0.0),
    )
}

const PINCAM_FIELDS: [&str; 6] = ["width", "height", "fx", "fy", "cx", "cy"];
const PINCAM_FORM: &str = "width height fx fy cx cy";
/// Far beyond any camera; a size this large is a wrong file, not an image.
const MAX_SIDE: f64 = 1e6;

/// A `.pincam` file's text: one line `width height fx fy cx cy` (blank lines around it skipped).
pub(super) fn parse_pincam(text: &str, file: &str) -> Result<Pincam> {
    let lines: Vec<(usize, &str)> = text.lines().enumerate().filter(|(_, l)| !l.trim().is_empty()).collect();
    let [(i, line)] = lines[..] else {
        return Err(SceneError::invalid(
            file,
            format!("expected one line `{PINCAM_FORM}`, found {} lines", lines.len()),
        ));
    };
    let v = finite_words(line, i, file, &PINCAM_FIELDS, PINCAM_FORM)?;
    for (name, side) in [("width", v[0]), ("height", v[1])] {
        if !(1.0..=MAX_SIDE).contains(&side) || side.fract() != 0.0 {
            return Err(SceneError::invalid(
                file,
                format!("line {}: {name} = {side} is not an image side in pixels", i + 1),
            ));
        }
    }
    let k = Intrinsics {
        fx: v[2],
        fy: v[3],
        cx: v[4],
        cy: v[5],
    };
    k.check()
        .map_err(|p| SceneError::invalid(file, format!("line {}: {p}", i + 1)))?;
    Ok(Pincam {
        size: (v[0] as u32, v[1] as u32),
        k,
    })
}

/// The timestamp in a frame's file stem `<video_id>_<timestamp>` (`41069025_3054.713`).
pub(super) fn frame_time(stem: &str) -> Option<f64> {
    let (video, time) = stem.rsplit_once('_')?;
    let t: f64 = time.parse().ok()?;
    (!video.is_empty() && t.is_finite() && t >= 0.0).then_some(t)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn err(r: Result<impl std::fmt::Debug>) -> String {
        r.unwrap_err().to_string()
    }

    #[test]
    fn angle_axis_matches_the_closed_form() {
        // A quarter turn about z takes x to y.
        let r = rotation_from_angle_axis(DVec3::new(0.0, 0.0, std::f64::consts::FRAC_PI_2));
        assert!((r * DVec3::X).abs_diff_eq(DVec3::Y, 1e-12), "{r}");
        assert_eq!(rotation_from_angle_axis(DVec3::ZERO), DMat3::IDENTITY);
        // Any axis: orthonormal, and the axis is left where it is.
        let axis = DVec3::new(0.3, -1.2, 0.7);
        let r = rotation_from_angle_axis(axis);
        assert!((r.transpose() * r).abs_diff_eq(DMat3::IDENTITY, 1e-12));
        assert!((r * axis).abs_diff_eq(axis, 1e-12));
        assert!((r.determinant() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn traj_lines_are_world_to_camera() {
        // Camera turned a quarter about z and moved: the line holds world-to-camera, the pose
        // is its inverse, so the world point the line takes to the camera's origin is the centre.
        let text = "3054.713 0 0 1.5707963267948966 1 2 3\n\n3054.813 0 0 0 0 0 0\n";
        let poses = parse_traj(text, "s/lowres_wide.traj").unwrap();
        assert_eq!(poses.len(), 2);
        assert_eq!(poses[0].time, 3054.713);
        let w2c = poses[0].pose.inverse();
        assert!(w2c.translation().abs_diff_eq(DVec3::new(1.0, 2.0, 3.0), 1e-12));
        let centre = poses[0].pose.position();
        assert!(w2c.transform_point(centre).abs_diff_eq(DVec3::ZERO, 1e-12));
        assert!(centre.abs_diff_eq(DVec3::new(-2.0, 1.0, -3.0), 1e-12), "{centre}");
        assert_eq!(poses[1].pose, Pose::identity());
    }

    #[test]
    fn bad_traj_lines_name_the_file_line_and_value() {
        let f = "s/lowres_wide.traj";
        let e = err(parse_traj("1 0 0 0 0 0 0\n2 0 0 0 0 0\n", f));
        assert!(
            e.contains(f) && e.contains("line 2") && e.contains("found 6 words"),
            "{e}"
        );
        let e = err(parse_traj("1 0 0 0 0 0 0\n2 0 0 x 0 0 0\n", f));
        assert!(e.contains("line 2") && e.contains("rz \"x\""), "{e}");
        let e = err(parse_traj("1 0 nan 0 0 0 0\n", f));
        assert!(e.contains("line 1") && e.contains("ry = nan is not a finite"), "{e}");
        let e = err(parse_traj("1 0 0 0 0 inf 0\n", f));
        assert!(e.contains("ty = inf"), "{e}");
        let e = err(parse_traj("1 0 0 0 0 1e300 0\n", f));
        assert!(e.contains("line 1") && e.contains(f), "{e}");
        let e = err(parse_traj("\n  \n", f));
        assert!(e.contains("no poses"), "{e}");
    }

    #[test]
    fn pincam_reads_one_line_and_refuses_bad_values() {
        let f = "s/lowres_wide_intrinsics/41069025_3054.713.pincam";
        let p = parse_pincam("256 192 211.5 211.6 127.9 95.8\n", f).unwrap();
        assert_eq!(p.size, (256, 192));
        assert_eq!((p.k.fx, p.k.fy, p.k.cx, p.k.cy), (211.5, 211.6, 127.9, 95.8));
        let e = err(parse_pincam("256 192 211 211 127\n", f));
        assert!(
            e.contains(f) && e.contains("line 1") && e.contains("found 5 words"),
            "{e}"
        );
        let e = err(parse_pincam("256 192 211 211 127 96\n256 192 211 211 127 96\n", f));
        assert!(e.contains("found 2 lines"), "{e}");
        let e = err(parse_pincam("256 192.5 211 211 127 96", f));
        assert!(e.contains("height = 192.5"), "{e}");
        let e = err(parse_pincam("0 192 211 211 127 96", f));
        assert!(e.contains("width = 0"), "{e}");
        let e = err(parse_pincam("256 192 -211 211 127 96", f));
        assert!(e.contains("line 1"), "{e}");
        let e = err(parse_pincam("256 192 211 211 127 NaN", f));
        assert!(e.contains("cy = NaN is not a finite"), "{e}");
        let e = err(parse_pincam("256 192 fx 211 127 96", f));
        assert!(e.contains("fx \"fx\""), "{e}");
        assert!(err(parse_pincam("", f)).contains("found 0 lines"));
    }

    #[test]
    fn frame_names_carry_their_timestamp() {
        assert_eq!(frame_time("41069025_3054.713"), Some(3054.713));
        assert_eq!(frame_time("a_b_12"), Some(12.0));
        assert_eq!(frame_time("3054.713"), None);
        assert_eq!(frame_time("_3054.713"), None);
        assert_eq!(frame_time("x_inf"), None);
        assert_eq!(frame_time("x_-1"), None);
    }
}
