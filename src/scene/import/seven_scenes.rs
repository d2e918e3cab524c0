//! 7-Scenes (and TUM-like exports of it): one folder of `frame-NNNNNN.color.{jpg,png}`,
//! `frame-NNNNNN.depth.png` (uint16 mm; 0 and 65535 invalid), `frame-NNNNNN.pose.txt` (4x4
//! camera-to-world, OpenCV axes) and optionally `camera-intrinsics.txt` (3x3 K).
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use super::bounds::{FROM_DEPTH_NOTE, from_required_depth};
use super::files::CapturePath;
use super::frames::{
    DEPTH_SCALE, FrameFiles, InvalidDepth, Progress, files_by_stem, frame_order, load_frames, scene_of, select,
};
use super::text::{read_intrinsics, read_pose};
use super::{Built, ImportOptions, Layout, shown};
use crate::scene::camera::Intrinsics;
use crate::scene::error::{Result, SceneError};

const INTRINSICS_FILE: &str = "camera-intrinsics.txt";
const COLOR: &str = ".color";
const DEPTH: &str = ".depth";
const POSE: &str = ".pose";
/// The Kinect calibration 7-Scenes documents, for its 640x480 images; the dataset ships no
/// intrinsics file, so a missing one means these.
const DEFAULT_INTRINSICS: Intrinsics = Intrinsics {
    fx: 585.0,
    fy: 585.0,
    cx: 320.0,
    cy: 240.0,
};
const DEFAULT_SIZE: (u32, u32) = (640, 480);

/// Whether `dir` holds 7-Scenes colour frames.
pub(super) fn looks_like(dir: &Path) -> Result<bool> {
    Ok(!files_by_stem(dir, &["jpg", "jpeg", "png"], COLOR)?.is_empty())
}

pub(super) async fn import(dir: &Path, opts: &ImportOptions, progress: &mut Progress<'_>) -> Result<Built> {
    let mut warnings = Vec::new();
    let color = files_by_stem(dir, &["jpg", "jpeg", "png"], COLOR)?;
    let depth = files_by_stem(dir, &["png"], DEPTH)?;
    let pose = files_by_stem(dir, &["txt"], POSE)?;
    let names = frame_order(color.keys());
    if names.is_empty() {
        return Err(SceneError::invalid(
            shown(dir),
            "no colour frames (frame-000000.color.jpg, ...): no frames",
        ));
    }
    check_matched(dir, &color, &depth, DEPTH, "png")?;
    check_matched(dir, &color, &pose, POSE, "txt")?;

    let (keep, mut notes) = select(&names, opts)?;
    let mut files = Vec::with_capacity(keep.len());
    for &i in &keep {
        let name = &names[i];
        let file = |map: &BTreeMap<String, PathBuf>, suffix: &str| {
            map.get(name)
                .cloned()
                .ok_or_else(|| SceneError::missing(shown(&dir.join(name)), format!("{suffix} file")))
        };
        files.push(FrameFiles {
            name: name.clone(),
            rgb: file(&color, COLOR)?,
            depth: Some(file(&depth, DEPTH)?),
            gt: None,
            pose: read_pose(&file(&pose, POSE)?)?,
        });
    }

    let intrinsics_path = dir.join(INTRINSICS_FILE);
    let k = if intrinsics_path.is_capture_file() {
        let (k, skew) = read_intrinsics(&intrinsics_path)?;
        warnings.extend(skew);
        Some(k)
    } else {
        None
    };

    let loaded = load_frames(files, opts, InvalidDepth::ZeroAndMax, progress).await?;
    notes.extend(loaded.notes);
    let report = loaded.report;
    let k = match k {
        Some(k) => k,
        None if loaded.native == DEFAULT_SIZE => {
            warnings.push(format!(
                "{}: missing; assumed the 7-Scenes Kinect intrinsics fx = fy = 585, cx = 320, cy = 240",
                shown(&intrinsics_path)
            ));
            DEFAULT_INTRINSICS
        }
        None => {
            return Err(SceneError::missing(
                shown(&intrinsics_path),
                format!(
                    "the 3x3 camera matrix K; the 7-Scenes defaults only fit 640x480 images, these are {}x{}",
                    loaded.native.0, loaded.native.1
                ),
            ));
        }
    };
    let intrinsics = k.scaled(loaded.native, loaded.size);
    let bounds = from_required_depth(&loaded.frames, &intrinsics, DEPTH_SCALE, dir)?;
    notes.push(FROM_DEPTH_NOTE.into());

    let scene = scene_of(loaded.frames, loaded.size, intrinsics, bounds);
    Ok(Built {
        scene,
        layout: Layout::SevenScenes,
        warnings,
        notes,
        report,
    })
}

/// Every colour frame needs its depth and pose and vice versa, or frames would go missing.
fn check_matched(
    dir: &Path,
    color: &BTreeMap<String, PathBuf>,
    other: &BTreeMap<String, PathBuf>,
    suffix: &str,
    ext: &str,
) -> Result<()> {
    let counts = format!("{} colour frames, {} {suffix}.{ext} files", color.len(), other.len());
    if let Some(name) = frame_order(color.keys()).into_iter().find(|n| !other.contains_key(n)) {
        let expected = dir.join(format!("{name}{suffix}.{ext}"));
        return Err(SceneError::missing(
            shown(&expected),
            format!("the {} of {name} ({counts})", &suffix[1..]),
        ));
    }
    if let Some((name, path)) = other.iter().find(|(n, _)| !color.contains_key(*n)) {
        return Err(SceneError::invalid(
            shown(path),
            format!("no colour image {name}{COLOR}.jpg for this frame ({counts})"),
        ));
    }
    Ok(())
}
