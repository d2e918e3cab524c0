//! ARKitScenes raw scenes (Apple's dataset, as ethz-asl/autolabel's converter reads them):
//! `lowres_wide/<video_id>_<timestamp>.png` colour, `lowres_depth/` of the same names (uint16
//! millimetres, 0 = no reading), `lowres_wide_intrinsics/<video_id>_<timestamp>.pincam`
//! (`width height fx fy cx cy`) and `lowres_wide.traj` (`timestamp rx ry rz tx ty tz`,
//! world-to-camera, `arkit_text.rs`). Frames find their pose and camera by the timestamp in
//! their names.
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use super::arkit_text::{Pincam, frame_time, parse_pincam, parse_traj};
use super::bounds::{FROM_DEPTH_NOTE, from_required_depth};
use super::files::CapturePath;
use super::frames::{DEPTH_SCALE, FrameFiles, InvalidDepth, Progress, frames_in, load_frames, scene_of, select};
use super::resize::same_aspect;
use super::text::{read_text, read_text_up_to};
use super::{Built, ImportOptions, Layout, shown};
use crate::scene::camera::Intrinsics;
use crate::scene::error::{Result, SceneError};

const WIDE_DIR: &str = "lowres_wide";
const DEPTH_DIR: &str = "lowres_depth";
const INTRINSICS_DIR: &str = "lowres_wide_intrinsics";
const TRAJ_FILE: &str = "lowres_wide.traj";
const COLOR_EXTS: &[&str] = &["png", "jpg", "jpeg"];
/// What the folders are, for a missing one's message.
const LAYOUT: &str = "an ARKitScenes scene (lowres_wide/, lowres_depth/, lowres_wide_intrinsics/, lowres_wide.traj)";
/// A frame takes the trajectory's pose nearest its timestamp when it is this close (seconds):
/// ARKitScenes' own loader (`tenFpsDataLoader.py`) accepts a pose within 5 ms of a frame's
/// name. Farther means tracking had not started or had stopped: the frame has no pose.
const POSE_TOLERANCE_S: f64 = 0.005;
/// A frame's `.pincam` is the one of its name, else of the nearest timestamp this close: names
/// are rounded to milliseconds, and ARKitScenes' loader looks 1 ms either side.
const PINCAM_TOLERANCE_S: f64 = 0.0015;
/// A trajectory has a line (about 70 bytes) per pose: this holds hours of 60 Hz tracking and
/// refuses a file that is something else.
const MAX_TRAJ_BYTES: u64 = 64 << 20;
/// How far a frame's camera may stray from the first kept frame's before it is another camera:
/// a share of the focal length, and of the image side for the principal point. The scene has
/// one camera; ARKit reports one per frame, which wanders by less than this as the lens settles.
const CAMERA_TOLERANCE: f64 = 0.02;

/// Whether `dir` is an ARKitScenes raw scene: its wide camera's frames.
pub(super) fn looks_like(dir: &Path) -> bool {
    dir.join(WIDE_DIR).is_capture_dir()
}

pub(super) async fn import(dir: &Path, opts: &ImportOptions, progress: &mut Progress<'_>) -> Result<Built> {
    let color = frames_in(dir, WIDE_DIR, COLOR_EXTS, LAYOUT)?;
    let timed = timed_frames(&color)?;
    if timed.is_empty() {
        return Err(SceneError::invalid(
            shown(&dir.join(WIDE_DIR)),
            "no colour frames (<video_id>_<timestamp>.png): no frames",
        ));
    }
    let depth = frames_in(dir, DEPTH_DIR, &["png"], LAYOUT)?;
    check_matched(dir, &color, &depth)?;
    let traj_path = dir.join(TRAJ_FILE);
    if !traj_path.is_capture_file() {
        return Err(SceneError::missing(
            shown(&traj_path),
            "the poses of an ARKitScenes scene (`timestamp rx ry rz tx ty tz` a line)",
        ));
    }
    let mut traj = parse_traj(&read_text_up_to(&traj_path, MAX_TRAJ_BYTES)?, &shown(&traj_path))?;
    traj.sort_by(|a, b| a.time.total_cmp(&b.time));

    // Poses first (one text file): frames outside the tracked stretch are dropped before
    // --every and --max-frames pick among the rest.
    let mut warnings = Vec::new();
    let mut posed = Vec::with_capacity(timed.len());
    let mut lost = Vec::new();
    for (time, stem) in &timed {
        match nearest(&traj, *time, |p| p.time).filter(|p| (p.time - time).abs() <= POSE_TOLERANCE_S) {
            Some(p) => posed.push((stem, *time, p.pose)),
            None => lost.push(stem),
        }
    }
    let (first, last) = (traj[0].time, traj[traj.len() - 1].time);
    if posed.is_empty() {
        return Err(SceneError::invalid(
            shown(&traj_path),
            format!(
                "no pose within {} ms of any of the {} frames' timestamps (the poses span {first} to {last} s, the frames {} to {} s): \
                 not this scene's trajectory",
                POSE_TOLERANCE_S * 1e3,
                timed.len(),
                timed[0].0,
                timed[timed.len() - 1].0
            ),
        ));
    }
    if let Some(stem) = lost.first() {
        warnings.push(format!(
            "{}: skipped {} of {} frames with no pose within {} ms of their timestamp (the poses span {first} to {last} s; first: {})",
            shown(&traj_path),
            lost.len(),
            timed.len(),
            POSE_TOLERANCE_S * 1e3,
            shown(&color[*stem])
        ));
    }

    let names: Vec<String> = posed.iter().map(|(stem, _, _)| (*stem).clone()).collect();
    let (keep, mut notes) = select(&names, opts)?;
    let pincams = Pincams::in_dir(dir)?;
    let mut camera: Option<(Pincam, PathBuf)> = None;
    let mut files = Vec::with_capacity(keep.len());
    for &i in &keep {
        let (stem, time, pose) = posed[i];
        let path = pincams.of(dir, stem, time)?;
        let pincam = parse_pincam(&read_text(&path)?, &shown(&path))?;
        match &camera {
            None => camera = Some((pincam, path)),
            Some((first, first_path)) => check_same_camera(first, first_path, &pincam, &path)?,
        }
        files.push(FrameFiles {
            name: stem.clone(),
            rgb: color[stem].clone(),
            depth: Some(depth[stem].clone()),
            gt: None,
            pose,
        });
    }
    let (pincam, pincam_path) = camera.ok_or_else(|| SceneError::invalid(shown(dir), "no frames to import"))?;

    let loaded = load_frames(files, opts, InvalidDepth::ZeroOnly, progress).await?;
    notes.extend(loaded.notes);
    let report = loaded.report;
    let k = native_intrinsics(&pincam, &pincam_path, loaded.native)?;
    let intrinsics = k.scaled(loaded.native, loaded.size);
    notes.push(format!(
        "poses: {TRAJ_FILE} (angle-axis world-to-camera, inverted), each frame the pose nearest its timestamp \
         within {} ms; intrinsics: {INTRINSICS_DIR}/ of the first kept frame",
        POSE_TOLERANCE_S * 1e3
    ));
    let bounds = from_required_depth(&loaded.frames, &intrinsics, DEPTH_SCALE, &dir.join(DEPTH_DIR))?;
    notes.push(FROM_DEPTH_NOTE.into());

    let scene = scene_of(loaded.frames, loaded.size, intrinsics, bounds);
    Ok(Built {
        scene,
        layout: Layout::ArkitScenes,
        warnings,
        notes,
        report,
    })
}

/// The colour frames by timestamp (then name); a name without one is an error naming the file.
fn timed_frames(color: &BTreeMap<String, PathBuf>) -> Result<Vec<(f64, String)>> {
    let mut timed = Vec::with_capacity(color.len());
    for (stem, path) in color {
        let time = frame_time(stem).ok_or_else(|| {
            SceneError::invalid(
                shown(path),
                "not named <video_id>_<timestamp>.png as ARKitScenes names frames; the timestamp finds the frame's pose",
            )
        })?;
        timed.push((time, stem.clone()));
    }
    timed.sort_by(|a, b| a.0.total_cmp(&b.0).then_with(|| a.1.cmp(&b.1)));
    Ok(timed)
}

/// Every colour frame needs its depth image and the reverse.
fn check_matched(dir: &Path, color: &BTreeMap<String, PathBuf>, depth: &BTreeMap<String, PathBuf>) -> Result<()> {
    let counts = format!("{} colour frames, {} in {DEPTH_DIR}/", color.len(), depth.len());
    if let Some(stem) = color.keys().find(|s| !depth.contains_key(*s)) {
        return Err(SceneError::missing(
            shown(&dir.join(DEPTH_DIR).join(format!("{stem}.png"))),
            format!("the depth of frame {stem} ({counts})"),
        ));
    }
    if let Some((stem, path)) = depth.iter().find(|(s, _)| !color.contains_key(*s)) {
        return Err(SceneError::invalid(
            shown(path),
            format!("no colour image {WIDE_DIR}/{stem}.png for this depth image ({counts})"),
        ));
    }
    Ok(())
}

/// The element of `sorted` (by `time`) whose time is nearest `t`.
fn nearest<T>(sorted: &[T], t: f64, time: impl Fn(&T) -> f64) -> Option<&T> {
    let i = sorted.partition_point(|x| time(x) < t);
    let before = i.checked_sub(1).and_then(|j| sorted.get(j));
    match (before, sorted.get(i)) {
        (Some(a), Some(b)) => Some(if t - time(a) <= time(b) - t { a } else { b }),
        (a, b) => a.or(b),
    }
}

/// The `.pincam` files, by name and by timestamp.
struct Pincams {
    by_stem: BTreeMap<String, PathBuf>,
    by_time: Vec<(f64, PathBuf)>,
}

impl Pincams {
    fn in_dir(dir: &Path) -> Result<Pincams> {
        let by_stem = frames_in(dir, INTRINSICS_DIR, &["pincam"], LAYOUT)?;
        let mut by_time: Vec<(f64, PathBuf)> = by_stem
            .iter()
            .filter_map(|(stem, path)| frame_time(stem).map(|t| (t, path.clone())))
            .collect();
        by_time.sort_by(|a, b| a.0.total_cmp(&b.0));
        Ok(Pincams { by_stem, by_time })
    }

    /// The camera file of the frame named `stem`, taken at `time`.
    fn of(&self, dir: &Path, stem: &str, time: f64) -> Result<PathBuf> {
        if let Some(path) = self.by_stem.get(stem) {
            return Ok(path.clone());
        }
        nearest(&self.by_time, time, |p| p.0)
            .filter(|p| (p.0 - time).abs() <= PINCAM_TOLERANCE_S)
            .map(|p| p.1.clone())
            .ok_or_else(|| {
                SceneError::missing(
                    shown(&dir.join(INTRINSICS_DIR).join(format!("{stem}.pincam"))),
                    format!(
                        "the camera of frame {stem} (`width height fx fy cx cy`; none within {} ms of its timestamp either)",
                        PINCAM_TOLERANCE_S * 1e3
                    ),
                )
            })
    }
}

/// A kept frame's camera must be the first's: the scene has one.
fn check_same_camera(first: &Pincam, first_path: &Path, other: &Pincam, path: &Path) -> Result<()> {
    let (a, b) = (first.k, other.k);
    let (w, h) = (first.size.0 as f64, first.size.1 as f64);
    let off = other.size != first.size
        || (a.fx - b.fx).abs() > CAMERA_TOLERANCE * a.fx
        || (a.fy - b.fy).abs() > CAMERA_TOLERANCE * a.fy
        || (a.cx - b.cx).abs() > CAMERA_TOLERANCE * w
        || (a.cy - b.cy).abs() > CAMERA_TOLERANCE * h;
    if !off {
        return Ok(());
    }
    let describe = |p: &Pincam| {
        format!(
            "{}x{}, fx {} fy {} cx {} cy {}",
            p.size.0, p.size.1, p.k.fx, p.k.fy, p.k.cx, p.k.cy
        )
    };
    Err(SceneError::invalid(
        shown(path),
        format!(
            "another camera ({}) than the first frame's {} ({}); a scene has one camera (a focal length may differ by {} %)",
            describe(other),
            shown(first_path),
            describe(first),
            CAMERA_TOLERANCE * 100.0
        ),
    ))
}

/// The camera for the colour images as stored (`native`): the `.pincam`'s, scaled when it was
/// written for another size of the same aspect ratio.
fn native_intrinsics(pincam: &Pincam, path: &Path, native: (u32, u32)) -> Result<Intrinsics> {
    if pincam.size == native {
        return Ok(pincam.k);
    }
    if same_aspect(pincam.size, native) {
        return Ok(pincam.k.scaled(pincam.size, native));
    }
    Err(SceneError::invalid(
        shown(path),
        format!(
            "is for {}x{} images, but the colour images are {}x{} (not even their aspect ratio): not these images' camera",
            pincam.size.0, pincam.size.1, native.0, native.1
        ),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nearest_picks_the_closest_either_side() {
        let times = [1.0, 2.0, 4.0];
        let at = |t: f64| *nearest(&times, t, |x| *x).unwrap();
        assert_eq!((at(0.0), at(1.4), at(1.6), at(3.2), at(9.0)), (1.0, 1.0, 2.0, 4.0, 4.0));
        assert!(nearest(&[] as &[f64], 1.0, |x| *x).is_none());
    }

    #[test]
    fn another_camera_is_named_with_both_files() {
        let k = |fx| Pincam {
            size: (256, 192),
            k: Intrinsics {
                fx,
                fy: 211.0,
                cx: 128.0,
                cy: 96.0,
            },
        };
        let (a, b) = (Path::new("s/i/v_1.000.pincam"), Path::new("s/i/v_2.000.pincam"));
        assert!(check_same_camera(&k(211.0), a, &k(212.0), b).is_ok());
        let e = check_same_camera(&k(211.0), a, &k(250.0), b).unwrap_err().to_string();
        assert!(
            e.starts_with("s/i/v_2.000.pincam") && e.contains("fx 250") && e.contains("v_1.000"),
            "{e}"
        );
        let e = native_intrinsics(&k(211.0), a, (300, 100)).unwrap_err().to_string();
        assert!(e.contains("256x192") && e.contains("300x100"), "{e}");
        let doubled = native_intrinsics(&k(211.0), a, (512, 384)).unwrap();
        assert!((doubled.fx - 422.0).abs() < 1e-9);
    }
}
