//! Stray Scanner captures (the iOS app's export, strayrobots/scanner `docs/format.md`): `rgb.mp4`
//! (the colour camera, HEVC), `depth/NNNNNN.png` (256x192 uint16 millimetres from the LiDAR, one
//! per video frame), `confidence/NNNNNN.png` (0-2 per depth reading), `odometry.csv` (ARKit's
//! camera-to-world pose of each frame, `stray_text.rs`) and `camera_matrix.csv` (K of the video's
//! frames). `imu.csv` is not read. Depth shares the colour camera's view at a lower resolution and
//! is resampled onto the colour frames; readings of confidence below 2 are dropped, as
//! ethz-asl/autolabel's converter drops them.
use std::cell::RefCell;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use image::{DynamicImage, GrayImage, RgbImage};

use super::bounds::{FROM_DEPTH_NOTE, from_required_depth};
use super::files::CapturePath;
use super::frames::{
    DEPTH_SCALE, FrameFiles, InvalidDepth, Prepare, Progress, Reading, files_by_stem, load_frames_prepared, scene_of,
    select,
};
use super::images::{decode, load_depth, load_gt};
use super::stray_text::{OdometryRow, parse_camera_matrix, parse_odometry};
use super::text::{read_text, read_text_up_to};
use super::video::{Decoder, VideoInfo, check_keep, probe};
use super::{Background, Built, ImportOptions, Layout, shown};
use crate::scene::DepthImage;
use crate::scene::error::{Result, SceneError};

const VIDEO_FILE: &str = "rgb.mp4";
const ODOMETRY_FILE: &str = "odometry.csv";
const CAMERA_FILE: &str = "camera_matrix.csv";
const DEPTH_DIR: &str = "depth";
const CONFIDENCE_DIR: &str = "confidence";
/// Depth readings below this confidence (0 low, 1 medium, 2 high) are dropped.
const MIN_CONFIDENCE: u8 = 2;
/// An odometry line is about 120 bytes: this holds hours of 60 Hz recording.
const MAX_ODOMETRY_BYTES: u64 = 64 << 20;

/// Whether `dir` is a Stray Scanner capture: its video and its poses.
pub(super) fn looks_like(dir: &Path) -> bool {
    dir.join(VIDEO_FILE).is_capture_file() && dir.join(ODOMETRY_FILE).is_capture_file()
}

pub(super) async fn import(dir: &Path, opts: &ImportOptions, progress: &mut Progress<'_>) -> Result<Built> {
    let odometry_path = dir.join(ODOMETRY_FILE);
    let mut rows = parse_odometry(
        &read_text_up_to(&odometry_path, MAX_ODOMETRY_BYTES)?,
        &shown(&odometry_path),
    )?;
    rows.sort_by_key(|r| r.frame);
    let camera_path = dir.join(CAMERA_FILE);
    if !camera_path.is_capture_file() {
        return Err(SceneError::missing(
            shown(&camera_path),
            "the camera matrix of a Stray Scanner capture (K of the video's frames, 3 rows of 3 numbers)",
        ));
    }
    let k = parse_camera_matrix(&read_text(&camera_path)?, &shown(&camera_path))?;
    let depth = numbered(dir, DEPTH_DIR)?.ok_or_else(|| {
        SceneError::missing(
            shown(&dir.join(DEPTH_DIR)),
            "the depth/ folder of a Stray Scanner capture (NNNNNN.png a frame)",
        )
    })?;
    let confidence = numbered(dir, CONFIDENCE_DIR)?;
    let mut warnings = Vec::new();
    check_depth_files(dir, &rows, &depth, &mut warnings)?;

    let names: Vec<String> = rows.iter().map(|r| frame_name(r.frame)).collect();
    let (keep, mut notes) = select(&names, opts)?;
    let kept: Vec<OdometryRow> = keep.iter().map(|&i| rows[i]).collect();

    let video_path = dir.join(VIDEO_FILE);
    let info = probe(&video_path)?;
    check_camera(&camera_path, k, info)?;
    let frames: Vec<u32> = kept.iter().map(|r| r.frame).collect();
    check_keep(&video_path, info, &frames)?;
    let mut confidences = Vec::with_capacity(kept.len());
    for r in &kept {
        let file = match &confidence {
            Some(c) => Some(c.get(&r.frame).cloned().ok_or_else(|| {
                SceneError::missing(
                    shown(&dir.join(CONFIDENCE_DIR).join(format!("{}.png", frame_name(r.frame)))),
                    format!(
                        "the confidence of frame {} (confidence/ holds the other frames')",
                        r.frame
                    ),
                )
            })?),
            None => None,
        };
        confidences.push(file);
    }
    let files: Vec<FrameFiles> = kept
        .iter()
        .map(|r| FrameFiles {
            name: frame_name(r.frame),
            rgb: video_path.clone(),
            depth: Some(depth[&r.frame].clone()),
            gt: None,
            pose: r.pose,
        })
        .collect();
    let source = FromVideo {
        decoder: RefCell::new(Some(Decoder::start(&video_path, info, &frames)?)),
        info,
        confidence: confidences,
    };
    let loaded = load_frames_prepared(files, opts, InvalidDepth::ZeroOnly, &source, progress).await?;
    notes.extend(loaded.notes);
    let report = loaded.report;
    let intrinsics = k.scaled(loaded.native, loaded.size);
    notes.push(format!(
        "colour: {VIDEO_FILE} ({} frames of {}x{}, decoded by ffmpeg); poses: {ODOMETRY_FILE} (ARKit camera-to-world, \
         axes turned to OpenCV's); intrinsics: {CAMERA_FILE}",
        info.frames, info.size.0, info.size.1
    ));
    notes.push(match confidence {
        Some(_) => format!("depth readings of confidence below {MIN_CONFIDENCE} (confidence/) dropped"),
        None => {
            let note = format!("{}: no confidence/ folder: every depth reading kept", shown(dir));
            warnings.push(note.clone());
            note
        }
    });
    let bounds = from_required_depth(&loaded.frames, &intrinsics, DEPTH_SCALE, &dir.join(DEPTH_DIR))?;
    notes.push(FROM_DEPTH_NOTE.into());
    let scene = scene_of(loaded.frames, loaded.size, intrinsics, bounds);
    Ok(Built {
        scene,
        layout: Layout::StrayScanner,
        warnings,
        notes,
        report,
    })
}

/// How the app names a frame's files: its number in six digits.
fn frame_name(frame: u32) -> String {
    format!("{frame:06}")
}

/// The PNG files of `dir/sub` by frame number; `None` when there is no such folder. A name that
/// is not a number is skipped; two files for one number (`7.png` and `000007.png`) are an error.
fn numbered(dir: &Path, sub: &str) -> Result<Option<BTreeMap<u32, PathBuf>>> {
    let folder = dir.join(sub);
    if !folder.is_capture_dir() {
        return Ok(None);
    }
    let mut out = BTreeMap::new();
    for (stem, path) in files_by_stem(&folder, &["png"], "")? {
        let Ok(frame) = stem.parse::<u32>() else { continue };
        if let Some(other) = out.insert(frame, path.clone()) {
            return Err(SceneError::invalid(
                shown(&path),
                format!("a second file for frame {frame} (also {}); remove one", shown(&other)),
            ));
        }
    }
    Ok(Some(out))
}

/// Every posed frame needs its depth image; depth images with no pose are skipped with a warning
/// (tracking had not started).
fn check_depth_files(
    dir: &Path,
    rows: &[OdometryRow],
    depth: &BTreeMap<u32, PathBuf>,
    warnings: &mut Vec<String>,
) -> Result<()> {
    if let Some(r) = rows.iter().find(|r| !depth.contains_key(&r.frame)) {
        return Err(SceneError::missing(
            shown(&dir.join(DEPTH_DIR).join(format!("{}.png", frame_name(r.frame)))),
            format!(
                "the depth of frame {} ({ODOMETRY_FILE} has {} poses, {DEPTH_DIR}/ {} images)",
                r.frame,
                rows.len(),
                depth.len()
            ),
        ));
    }
    let posed: std::collections::BTreeSet<u32> = rows.iter().map(|r| r.frame).collect();
    let unposed = depth.keys().filter(|f| !posed.contains(f)).count();
    if unposed > 0 {
        warnings.push(format!(
            "{}: skipped {unposed} depth images with no pose in {ODOMETRY_FILE}",
            shown(&dir.join(DEPTH_DIR))
        ));
    }
    Ok(())
}

/// K must be for the video's frames as stored: its principal point inside them. A K for frames
/// turned upright, or for another resolution, puts it outside or far from the middle.
fn check_camera(path: &Path, k: crate::scene::camera::Intrinsics, info: VideoInfo) -> Result<()> {
    let (w, h) = (info.size.0 as f64, info.size.1 as f64);
    if !(k.cx > 0.0 && k.cx < w && k.cy > 0.0 && k.cy < h) {
        return Err(SceneError::invalid(
            shown(path),
            format!(
                "the principal point ({}, {}) lies outside the video's {}x{} frames: not the camera matrix of {VIDEO_FILE}'s frames",
                k.cx, k.cy, info.size.0, info.size.1
            ),
        ));
    }
    Ok(())
}

/// Colour from the video, in the order the frames are loaded; depth with its low-confidence
/// readings dropped.
struct FromVideo {
    decoder: RefCell<Option<Decoder>>,
    info: VideoInfo,
    /// The confidence image of each kept frame, when the capture has them.
    confidence: Vec<Option<PathBuf>>,
}

impl Prepare for FromVideo {
    fn rgb(&self, _frame: usize, rgb: RgbImage) -> Result<RgbImage> {
        Ok(rgb)
    }

    fn gt(&self, _frame: usize, path: &Path, _native: (u32, u32)) -> Result<GrayImage> {
        load_gt(path)
    }

    fn colour_size(&self, _path: &Path) -> Result<(u32, u32)> {
        Ok(self.info.size)
    }

    fn read_rgb<'a>(&'a self, _frame: usize, path: &'a Path, _background: Background) -> Reading<'a, (RgbImage, bool)> {
        Box::pin(async move {
            // Out of its cell while it decodes, so no borrow is held across the wait.
            let mut decoder = self
                .decoder
                .take()
                .ok_or_else(|| SceneError::invalid(shown(path), "frames read out of order"))?;
            let frame = decoder.next().await;
            self.decoder.replace(Some(decoder));
            Ok((frame?, false))
        })
    }

    fn read_depth(&self, frame: usize, path: &Path) -> Result<DepthImage> {
        let mut depth = load_depth(path)?;
        let Some(Some(confidence_path)) = self.confidence.get(frame) else {
            return Ok(depth);
        };
        let confidence = match decode(confidence_path)? {
            DynamicImage::ImageLuma8(c) => c,
            other => {
                return Err(SceneError::invalid(
                    shown(confidence_path),
                    format!(
                        "a confidence map must be an 8-bit single-channel PNG (0, 1 or 2 a pixel), got {:?}",
                        other.color()
                    ),
                ));
            }
        };
        if confidence.dimensions() != depth.dimensions() {
            return Err(SceneError::invalid(
                shown(confidence_path),
                format!(
                    "the confidence map is {}x{}, its depth image {}x{}: one value a depth reading",
                    confidence.width(),
                    confidence.height(),
                    depth.width(),
                    depth.height()
                ),
            ));
        }
        for (d, c) in depth.pixels_mut().zip(confidence.pixels()) {
            if c.0[0] < MIN_CONFIDENCE {
                d.0[0] = 0;
            }
        }
        Ok(depth)
    }
}
