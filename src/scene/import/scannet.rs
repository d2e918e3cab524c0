//! ScanNet scenes as ScanNet's SensReader exports them: `color/N.jpg`, `depth/N.png` (uint16
//! millimetres, 0 = no reading), `pose/N.txt` (4x4 camera-to-world, OpenCV axes; `-inf` rows
//! where tracking was lost), `intrinsic/intrinsic_color.txt` and `intrinsic/intrinsic_depth.txt`
//! (4x4, K top-left). Colour and depth come at different sizes and intrinsics (1296x968 and
//! 640x480), so depth is registered to the colour camera (`register.rs`).
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use super::bounds::{FROM_DEPTH_NOTE, from_required_depth};
use super::files::CapturePath;
use super::frames::{
    DEPTH_SCALE, FrameFiles, InvalidDepth, Progress, frame_order, frames_in, load_frames, scene_of, select,
};
use super::images::load_depth;
use super::register::register_depth;
use super::text::{parse_numbers, pose_from_numbers, read_intrinsics, read_text};
use super::{Built, ImportOptions, Layout, shown};
use crate::scene::camera::{Intrinsics, Pose};
use crate::scene::error::{Result, SceneError};

const COLOR_DIR: &str = "color";
const DEPTH_DIR: &str = "depth";
const POSE_DIR: &str = "pose";
const INTRINSIC_DIR: &str = "intrinsic";
const COLOR_INTRINSICS: &str = "intrinsic/intrinsic_color.txt";
const DEPTH_INTRINSICS: &str = "intrinsic/intrinsic_depth.txt";
const COLOR_EXTS: &[&str] = &["jpg", "jpeg", "png"];
/// What the folders are, for a missing one's message.
const LAYOUT: &str = "a ScanNet export (color/, depth/, pose/, intrinsic/)";

/// Whether `dir` is a SensReader export: colour frames and the intrinsics folder.
pub(super) fn looks_like(dir: &Path) -> bool {
    dir.join(COLOR_DIR).is_capture_dir() && dir.join(INTRINSIC_DIR).is_capture_dir()
}

pub(super) async fn import(dir: &Path, opts: &ImportOptions, progress: &mut Progress<'_>) -> Result<Built> {
    let color = frames_in(dir, COLOR_DIR, COLOR_EXTS, LAYOUT)?;
    let depth = frames_in(dir, DEPTH_DIR, &["png"], LAYOUT)?;
    let pose = frames_in(dir, POSE_DIR, &["txt"], LAYOUT)?;
    let names = frame_order(color.keys());
    if names.is_empty() {
        return Err(SceneError::invalid(
            shown(&dir.join(COLOR_DIR)),
            "no colour frames (0.jpg, 1.jpg, ...): no frames",
        ));
    }
    check_matched(dir, &color, &depth, DEPTH_DIR, "png")?;
    check_matched(dir, &color, &pose, POSE_DIR, "txt")?;
    let (kc, mut warnings) = intrinsics(dir, COLOR_INTRINSICS, "the colour camera's intrinsics")?;
    let (kd, skew) = intrinsics(dir, DEPTH_INTRINSICS, "the depth camera's intrinsics")?;
    warnings.extend(skew);

    // Poses first (small text files): frames whose tracking was lost are dropped before
    // --every and --max-frames pick among the rest.
    let mut posed = Vec::with_capacity(names.len());
    let mut lost = Vec::new();
    for name in &names {
        match read_scannet_pose(&pose[name])? {
            Some(p) => posed.push((name, p)),
            None => lost.push(name),
        }
    }
    if let Some(first) = lost.first() {
        warnings.push(format!(
            "{}: skipped {} of {} frames whose pose is invalid (non-finite, as ScanNet writes where tracking was lost; first: {})",
            shown(&dir.join(POSE_DIR)),
            lost.len(),
            names.len(),
            shown(&pose[*first])
        ));
    }
    if posed.is_empty() {
        return Err(SceneError::invalid(
            shown(&dir.join(POSE_DIR)),
            format!(
                "all {} poses are invalid (non-finite): no frame can be placed",
                names.len()
            ),
        ));
    }

    // Frames are named by their colour file, as `Frame::source` keeps them.
    let source_names: Vec<String> = posed
        .iter()
        .map(|(name, _)| format!("{COLOR_DIR}/{}", file_name(&color[*name])))
        .collect();
    let (keep, mut notes) = select(&source_names, opts)?;
    let files: Vec<FrameFiles> = keep
        .iter()
        .map(|&i| {
            let (name, pose) = posed[i];
            FrameFiles {
                name: source_names[i].clone(),
                rgb: color[name].clone(),
                // Registered below: depth is not a resampling of the colour view.
                depth: None,
                gt: None,
                pose,
            }
        })
        .collect();
    let count = files.len();
    // Colour first, then depth: the bar covers both passes.
    let report = &mut progress.report;
    let mut colour = Progress {
        report: &mut |done, total| report(done, 2 * total),
        pause: &mut *progress.pause,
    };
    let mut loaded = load_frames(files, opts, InvalidDepth::ZeroOnly, &mut colour).await?;
    notes.extend(loaded.notes);
    let report = loaded.report;
    let intrinsics = kc.scaled(loaded.native, loaded.size);
    check_principal_point(&kc, loaded.native, &dir.join(COLOR_INTRINSICS))?;

    let mut depth_size = None;
    for (j, &i) in keep.iter().enumerate() {
        let path = &depth[posed[i].0];
        let d = load_depth(path)?;
        match depth_size {
            None => {
                check_principal_point(&kd, d.dimensions(), &dir.join(DEPTH_INTRINSICS))?;
                depth_size = Some(d.dimensions());
            }
            Some(size) if size != d.dimensions() => {
                return Err(SceneError::invalid(
                    shown(path),
                    format!(
                        "depth is {}x{}, but the first depth image is {}x{} (all depth images must have one size)",
                        d.width(),
                        d.height(),
                        size.0,
                        size.1
                    ),
                ));
            }
            Some(_) => {}
        }
        loaded.frames[j].depth = Some(register_depth(&d, &kd, &intrinsics, loaded.size));
        progress.frame_done(count + j + 1, 2 * count).await;
    }
    if let Some((w, h)) = depth_size {
        notes.push(format!(
            "depth ({w}x{h}, {DEPTH_INTRINSICS}) registered to the colour camera ({}x{} as packed, {COLOR_INTRINSICS}): \
             each depth pixel carried through both intrinsics, the nearest where several land on one pixel",
            loaded.size.0, loaded.size.1
        ));
    }
    let bounds = from_required_depth(&loaded.frames, &intrinsics, DEPTH_SCALE, &dir.join(DEPTH_DIR))?;
    notes.push(FROM_DEPTH_NOTE.into());

    let scene = scene_of(loaded.frames, loaded.size, intrinsics, bounds);
    Ok(Built {
        scene,
        layout: Layout::ScanNet,
        warnings,
        notes,
        report,
    })
}

fn file_name(path: &Path) -> String {
    path.file_name()
        .map_or_else(String::new, |n| n.to_string_lossy().into_owned())
}

/// Every colour frame needs its depth and pose, and every depth or pose its colour frame.
fn check_matched(
    dir: &Path,
    color: &BTreeMap<String, PathBuf>,
    other: &BTreeMap<String, PathBuf>,
    sub: &str,
    ext: &str,
) -> Result<()> {
    let counts = format!("{} colour frames, {} in {sub}/", color.len(), other.len());
    if let Some(name) = frame_order(color.keys()).into_iter().find(|n| !other.contains_key(n)) {
        return Err(SceneError::missing(
            shown(&dir.join(sub).join(format!("{name}.{ext}"))),
            format!("the {sub} of frame {name} ({counts})"),
        ));
    }
    if let Some((name, path)) = other.iter().find(|(n, _)| !color.contains_key(*n)) {
        return Err(SceneError::invalid(
            shown(path),
            format!("no colour image {COLOR_DIR}/{name}.jpg for this frame ({counts})"),
        ));
    }
    Ok(())
}

/// One of the two intrinsics files, which must be there.
fn intrinsics(dir: &Path, file: &str, what: &str) -> Result<(Intrinsics, Vec<String>)> {
    let path = dir.join(file);
    if !path.is_capture_file() {
        return Err(SceneError::missing(shown(&path), format!("{what} (a 4x4 or 3x3 K)")));
    }
    let (k, skew) = read_intrinsics(&path)?;
    Ok((k, skew.into_iter().collect()))
}

/// A pose file: None when it holds non-finite values (ScanNet's mark of a lost frame); an
/// error when it is not a pose at all.
fn read_scannet_pose(path: &Path) -> Result<Option<Pose>> {
    pose_from_text(&read_text(path)?, &shown(path))
}

/// [`read_scannet_pose`] of the text of `file`.
pub(super) fn pose_from_text(text: &str, file: &str) -> Result<Option<Pose>> {
    let numbers = parse_numbers(text, file)?;
    if numbers.iter().any(|v| !v.is_finite()) {
        return Ok(None);
    }
    pose_from_numbers(&numbers, file).map(Some)
}

/// A principal point outside its image means the intrinsics are not this camera's (say, the
/// colour and depth files swapped, or K of another resolution).
pub(super) fn check_principal_point(k: &Intrinsics, (w, h): (u32, u32), path: &Path) -> Result<()> {
    if (0.0..w as f64).contains(&k.cx) && (0.0..h as f64).contains(&k.cy) {
        return Ok(());
    }
    Err(SceneError::invalid(
        shown(path),
        format!(
            "principal point cx = {}, cy = {} lies outside the {w}x{h} images it is for: not these images' intrinsics",
            k.cx, k.cy
        ),
    ))
}
