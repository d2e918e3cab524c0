//! autolabel scene directories: `rgb/NNNNN.{png,jpg}`, `depth/NNNNN.png` (uint16 mm),
//! `pose/NNNNN.txt` (4x4 world-to-camera, OpenCV axes), `intrinsics.txt` (3x3 K), `bbox.txt`,
//! optional `semantic/NNNNN.png` scribbles (0 unlabelled, v = class v-1) that become shipped
//! labels, and optional `gt/NNNNN.png` (8-bit class ids, 255 void) with `classes.txt`.
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use super::bounds::from_depth;
use super::classes::{class_infos, numbered};
use super::files::CapturePath;
use super::frames::{
    DEPTH_SCALE, FrameFiles, InvalidDepth, Progress, files_by_stem, frame_order, load_frames, scene_of, select,
};
use super::images::load_mask;
use super::resize::{resize_nearest, same_aspect};
use super::text::{read_bbox, read_class_names, read_intrinsics, read_pose};
use super::{Built, ImportOptions, Layout, shown};
use crate::scene::archive::limits;
use crate::scene::camera::Pose;
use crate::scene::error::{Result, SceneError};
use crate::scene::label_set::{ClassInfo, FrameLabels, LabelSet, UNLABELLED, mask_to_strokes};
use crate::scene::{Frame, GT_VOID, Scene};

pub(super) const RGB_DIR: &str = "rgb";
const DEPTH_DIR: &str = "depth";
const POSE_DIR: &str = "pose";
const SEMANTIC_DIR: &str = "semantic";
const GT_DIR: &str = "gt";
const INTRINSICS_FILE: &str = "intrinsics.txt";
const BBOX_FILE: &str = "bbox.txt";
const CLASSES_FILE: &str = "classes.txt";
const IMAGE_EXTS: &[&str] = &["png", "jpg", "jpeg"];

/// Whether `dir` has autolabel's camera files (poses or intrinsics) beside its rgb/ folder.
pub(super) fn has_camera_files(dir: &Path) -> bool {
    dir.join(POSE_DIR).is_capture_dir() || dir.join(INTRINSICS_FILE).is_capture_file()
}

pub(super) async fn import(dir: &Path, opts: &ImportOptions, progress: &mut Progress<'_>) -> Result<Built> {
    let mut warnings = Vec::new();
    let rgb = files_by_stem(&dir.join(RGB_DIR), IMAGE_EXTS, "")?;
    let depth = files_by_stem(
        &required_dir(dir, DEPTH_DIR, "depth images (uint16 millimetres)")?,
        &["png"],
        "",
    )?;
    let pose = files_by_stem(
        &required_dir(dir, POSE_DIR, "4x4 world-to-camera pose files")?,
        &["txt"],
        "",
    )?;
    let gt = optional_files(dir, GT_DIR)?;
    let semantic = optional_files(dir, SEMANTIC_DIR)?;
    let intrinsics_path = dir.join(INTRINSICS_FILE);
    if !intrinsics_path.is_capture_file() {
        return Err(SceneError::missing(shown(&intrinsics_path), "the 3x3 camera matrix K"));
    }

    let names = frame_order(rgb.keys());
    if names.is_empty() {
        return Err(SceneError::invalid(
            shown(&dir.join(RGB_DIR)),
            "no colour images (expected rgb/00000.png or .jpg, ...): the scene has no frames",
        ));
    }
    check_matched(dir, &rgb, &depth, DEPTH_DIR, "png")?;
    check_matched(dir, &rgb, &pose, POSE_DIR, "txt")?;
    for (what, files) in [(GT_DIR, &gt), (SEMANTIC_DIR, &semantic)] {
        let orphans = files.keys().filter(|k| !rgb.contains_key(*k)).count();
        if orphans > 0 {
            warnings.push(format!("{what}/: {orphans} images without a colour image were ignored"));
        }
    }

    let (keep, mut notes) = select(&names, opts)?;
    let dropped_scribbles = names
        .iter()
        .enumerate()
        .filter(|(i, n)| semantic.contains_key(*n) && keep.binary_search(i).is_err())
        .count();
    if dropped_scribbles > 0 {
        warnings.push(format!(
            "scribbles of {dropped_scribbles} frames in semantic/ were dropped with their frames (--every / --max-frames)"
        ));
    }

    let mut files = Vec::with_capacity(keep.len());
    for &i in &keep {
        let name = &names[i];
        let file = |map: &BTreeMap<String, PathBuf>, sub: &str| {
            map.get(name)
                .cloned()
                .ok_or_else(|| SceneError::missing(shown(&dir.join(sub).join(name)), "file of this frame"))
        };
        // autolabel stores world-to-camera; the scene stores camera-to-world. The full inverse
        // (not the rigid shortcut) so that the two multiply to the identity even though text
        // files hold rotations orthonormal only to their printed digits.
        let pose_file = file(&pose, POSE_DIR)?;
        let pose = Pose(read_pose(&pose_file)?.0.inverse());
        pose.check()
            .map_err(|p| SceneError::invalid(shown(&pose_file), format!("inverted: {p}")))?;
        files.push(FrameFiles {
            name: name.clone(),
            rgb: file(&rgb, RGB_DIR)?,
            depth: Some(file(&depth, DEPTH_DIR)?),
            gt: gt.get(name).cloned(),
            pose,
        });
    }
    let (k, skew) = read_intrinsics(&intrinsics_path)?;
    warnings.extend(skew);

    let loaded = load_frames(files, opts, InvalidDepth::ZeroOnly, progress).await?;
    notes.extend(loaded.notes);
    let report = loaded.report;
    let intrinsics = k.scaled(loaded.native, loaded.size);

    let masks = load_scribbles(&names, &keep, &semantic, loaded.native, loaded.size)?;
    let class_names = class_names(dir, &loaded.frames, &masks, &mut warnings)?;
    check_gt_ids(&loaded.frames, &keep, &names, &gt, class_names.len())?;
    let classes = class_infos(class_names);
    let labels = scribble_labels(&masks, loaded.size, &classes, keep.len(), dir)?;

    let bbox_path = dir.join(BBOX_FILE);
    let bounds = if bbox_path.is_capture_file() {
        read_bbox(&bbox_path)?
    } else {
        warnings.push(format!(
            "{}: missing; bounds estimated from the depth",
            shown(&bbox_path)
        ));
        from_depth(&loaded.frames, &intrinsics, DEPTH_SCALE).ok_or_else(|| {
            SceneError::invalid(
                shown(&dir.join(DEPTH_DIR)),
                "no valid depth in any frame, and no bbox.txt for bounds",
            )
        })?
    };

    let scene = Scene {
        classes: classes.clone(),
        labels,
        ..scene_of(loaded.frames, loaded.size, intrinsics, bounds)
    };
    Ok(Built {
        scene,
        layout: Layout::Autolabel,
        warnings,
        notes,
        report,
    })
}

fn required_dir(dir: &Path, name: &str, what: &str) -> Result<PathBuf> {
    let path = dir.join(name);
    if path.is_capture_dir() {
        Ok(path)
    } else {
        Err(SceneError::missing(format!("{}/", shown(&path)), what))
    }
}

fn optional_files(dir: &Path, name: &str) -> Result<BTreeMap<String, PathBuf>> {
    let path = dir.join(name);
    if path.is_capture_dir() {
        files_by_stem(&path, &["png"], "")
    } else {
        Ok(BTreeMap::new())
    }
}

/// Every colour image needs its depth and pose, and every depth and pose its colour image:
/// otherwise frames would silently pair up wrongly or vanish.
fn check_matched(
    dir: &Path,
    rgb: &BTreeMap<String, PathBuf>,
    other: &BTreeMap<String, PathBuf>,
    sub: &str,
    ext: &str,
) -> Result<()> {
    let counts = format!("{RGB_DIR}/ has {} images, {sub}/ has {} files", rgb.len(), other.len());
    if let Some(name) = frame_order(rgb.keys()).into_iter().find(|n| !other.contains_key(n)) {
        let expected = dir.join(sub).join(format!("{name}.{ext}"));
        return Err(SceneError::missing(
            shown(&expected),
            format!("{sub} of frame {name} ({counts})"),
        ));
    }
    if let Some((name, path)) = other.iter().find(|(n, _)| !rgb.contains_key(*n)) {
        return Err(SceneError::invalid(
            shown(path),
            format!("no colour image {RGB_DIR}/{name}.png or .jpg for this frame ({counts})"),
        ));
    }
    Ok(())
}

/// Scribble masks of the kept frames as class ids (`UNLABELLED` where none), at the frame size.
type Masks = BTreeMap<usize, Vec<u16>>;

fn load_scribbles(
    names: &[String],
    keep: &[usize],
    semantic: &BTreeMap<String, PathBuf>,
    native: (u32, u32),
    size: (u32, u32),
) -> Result<Masks> {
    let mut masks = Masks::new();
    for (frame, &i) in keep.iter().enumerate() {
        let Some(path) = semantic.get(&names[i]) else { continue };
        let mask = load_mask(path)?;
        if mask.dimensions() != native && !same_aspect(mask.dimensions(), native) {
            return Err(SceneError::invalid(
                shown(path),
                format!(
                    "scribble mask is {}x{}, which does not match the colour image's {}x{}",
                    mask.width(),
                    mask.height(),
                    native.0,
                    native.1
                ),
            ));
        }
        // autolabel writes class c as c + 1 so that 0 can mean "not labelled".
        let ids = resize_nearest(&mask, size)
            .into_raw()
            .into_iter()
            .map(|v| if v == 0 { UNLABELLED } else { v - 1 });
        masks.insert(frame, ids.collect());
    }
    Ok(masks)
}

/// Class names from classes.txt, or numbered placeholders covering every id seen.
fn class_names(dir: &Path, frames: &[Frame], masks: &Masks, warnings: &mut Vec<String>) -> Result<Vec<String>> {
    let path = dir.join(CLASSES_FILE);
    let gt_max = frames
        .iter()
        .filter_map(|f| f.gt.as_ref())
        .flat_map(|g| g.iter())
        .filter(|&&v| v != GT_VOID)
        .max();
    let scribble_max = masks.values().flatten().filter(|&&v| v != UNLABELLED).max();
    let names = if path.is_capture_file() {
        read_class_names(&path)?
    } else {
        let count = gt_max
            .map(|&v| v as usize + 1)
            .max(scribble_max.map(|&v| v as usize + 1))
            .unwrap_or(0);
        if count > 0 {
            warnings.push(format!("{}: missing; classes are named by number", shown(&path)));
        }
        numbered(count)
    };
    if names.len() > limits::MAX_CLASSES {
        return Err(SceneError::invalid(
            shown(&path),
            format!("{} classes exceed the limit of {}", names.len(), limits::MAX_CLASSES),
        ));
    }
    if let Some(&c) = scribble_max
        && c as usize >= names.len()
    {
        return Err(SceneError::invalid(
            shown(&dir.join(SEMANTIC_DIR)),
            format!(
                "scribbles use class {c} (value {}) but {CLASSES_FILE} names only {} classes",
                c + 1,
                names.len()
            ),
        ));
    }
    Ok(names)
}

fn check_gt_ids(
    frames: &[Frame],
    keep: &[usize],
    names: &[String],
    gt: &BTreeMap<String, PathBuf>,
    classes: usize,
) -> Result<()> {
    for (f, &i) in frames.iter().zip(keep) {
        let Some(g) = &f.gt else { continue };
        if let Some(&v) = g.iter().find(|&&v| v != GT_VOID && v as usize >= classes) {
            return Err(SceneError::invalid(
                gt.get(&names[i]).map(|p| shown(p)).unwrap_or_else(|| names[i].clone()),
                format!("class id {v} but {CLASSES_FILE} names only {classes} classes (255 = void)"),
            ));
        }
    }
    Ok(())
}

fn scribble_labels(
    masks: &Masks,
    size: (u32, u32),
    classes: &[ClassInfo],
    frames: usize,
    dir: &Path,
) -> Result<Option<LabelSet>> {
    if masks.is_empty() {
        return Ok(None);
    }
    let mut set = LabelSet::new(classes.to_vec());
    for (&frame, mask) in masks {
        let strokes = mask_to_strokes(mask, size.0, size.1, |c| c != UNLABELLED);
        if !strokes.is_empty() {
            set.frames.push(FrameLabels {
                frame: frame as u32,
                strokes,
            });
        }
    }
    set.check(&shown(&dir.join(SEMANTIC_DIR)), frames as u32)?;
    Ok(Some(set))
}
