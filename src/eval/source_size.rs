//! Masks at the capture's resolution (`segment --source DIR`): a field renders any resolution,
//! so the archive's frames are found again in the capture they were packed from, re-imported
//! there at full size (no `--max-size`), checked against the archive (every frame present by its
//! `source` name, the same pose, the same field of view), and rendered and refined at that size
//! with the capture's own image and depth as the guide.
//!
//! Full-size frames are not all held at once: the capture is read in chunks of
//! [`CHUNK_FRAMES`] frames, once to check it before any training and once more to render, and
//! each frame is rendered in bands of rows (`Trainer::render_probabilities`).
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use image::GrayImage;

use crate::field::gpu::trainer::Trainer;
use crate::field::gpu::view::ViewCamera;
use crate::refine::{RefineOptions, argmax_and_confidence, refine_probabilities};
use crate::scene::Guide;
use crate::scene::Scene;
use crate::scene::camera::Pose;
use crate::scene::import::{Background, ImportOptions, Layout, import};

/// Frames re-imported at a time.
pub const CHUNK_FRAMES: usize = 8;

/// Largest rotation between an archive frame's pose and its capture frame's, in radians
/// (0.06 degrees): a re-import gives the same pose to the digit; another capture does not.
pub const POSE_ANGLE_TOLERANCE: f64 = 1e-3;
/// Largest distance between the two camera centres, as a fraction of the archive bounds'
/// diagonal.
pub const POSE_SHIFT_TOLERANCE: f64 = 1e-3;
/// Largest relative difference of focal lengths, and of the principal point as a fraction of
/// the image side, between the archive's intrinsics scaled to the capture's size and the
/// capture's.
pub const INTRINSICS_TOLERANCE: f64 = 0.02;

/// A capture the archive's frames were found in, at its own resolution.
#[derive(Debug)]
pub struct SourceCapture {
    pub dir: PathBuf,
    pub layout: Layout,
    /// The capture's image size: the size of the masks.
    pub width: u32,
    pub height: u32,
    /// What transparent pixels are composited on, as when the archive was packed.
    pub background: Background,
    /// Source name of each archive frame.
    names: Vec<String>,
}

impl SourceCapture {
    /// Finds every frame of `archive` (read from `archive_name`) in the capture at `dir` and
    /// checks it: present by name, same size for all, the archive's aspect ratio and
    /// intrinsics, the same pose. `progress(done, total)` counts frames read. Errors name the
    /// frame, the file and the difference.
    pub fn check(
        archive: &Scene,
        archive_name: &str,
        dir: &Path,
        progress: &mut dyn FnMut(usize, usize),
    ) -> Result<SourceCapture, String> {
        let names = source_names(archive, archive_name)?;
        let background = packed_background(archive);
        let mut capture: Option<SourceCapture> = None;
        let total = names.len();
        progress(0, total);
        for first in (0..total).step_by(CHUNK_FRAMES) {
            let frames: Vec<usize> = (first..(first + CHUNK_FRAMES).min(total)).collect();
            let (layout, scene) = import_chunk(dir, &names, &frames, background, archive_name)?;
            let (width, height) = (scene.width, scene.height);
            let known = capture.get_or_insert_with(|| SourceCapture {
                dir: dir.to_path_buf(),
                layout,
                background,
                width,
                height,
                names: names.clone(),
            });
            if (width, height) != (known.width, known.height) {
                return Err(format!(
                    "--source {}: frame {:?} is {width} x {height}, but frame {:?} is {} x {}",
                    dir.display(),
                    names[first],
                    names[0],
                    known.width,
                    known.height
                ));
            }
            if first == 0 {
                check_camera(archive, archive_name, &scene, dir)?;
            }
            for (k, &i) in frames.iter().enumerate() {
                check_pose(archive, archive_name, i, &names[i], &scene.frames[k].pose, dir)?;
            }
            progress(first + frames.len(), total);
        }
        capture.ok_or_else(|| format!("{archive_name}: has no frames"))
    }

    /// The archive frames of chunk `chunk` (consecutive, at most [`CHUNK_FRAMES`]).
    pub fn chunks(&self) -> impl Iterator<Item = std::ops::Range<usize>> + use<> {
        let total = self.names.len();
        (0..total)
            .step_by(CHUNK_FRAMES)
            .map(move |first| first..(first + CHUNK_FRAMES).min(total))
    }

    /// The capture's frames for archive frames `frames` (one of [`SourceCapture::chunks`]), at
    /// full size, in the same order.
    pub fn load(&self, frames: std::ops::Range<usize>, archive_name: &str) -> Result<Scene, String> {
        let list: Vec<usize> = frames.collect();
        let (_, scene) = import_chunk(&self.dir, &self.names, &list, self.background, archive_name)?;
        if (scene.width, scene.height) != (self.width, self.height) {
            return Err(format!(
                "--source {}: the capture changed while it was read: its frames are now {} x {}, were {} x {}",
                self.dir.display(),
                scene.width,
                scene.height,
                self.width,
                self.height
            ));
        }
        Ok(scene)
    }
}

/// The source name of every archive frame; an archive frame without one, or two frames with the
/// same, cannot be found in a capture.
fn source_names(archive: &Scene, archive_name: &str) -> Result<Vec<String>, String> {
    let mut seen = BTreeMap::new();
    let mut names = Vec::with_capacity(archive.frames.len());
    for (i, f) in archive.frames.iter().enumerate() {
        let Some(name) = f.source.clone() else {
            return Err(format!(
                "{archive_name}: frame {i} does not name the capture frame it was packed from (no `source`), so \
                 --source cannot find it; archives from `pack` name every frame"
            ));
        };
        if let Some(other) = seen.insert(name.clone(), i) {
            return Err(format!(
                "{archive_name}: frames {other} and {i} both name {name:?} as their source; --source cannot tell \
                 them apart"
            ));
        }
        names.push(name);
    }
    Ok(names)
}

/// Imports archive frames `frames` (named `names[i]`) from `dir` at full size; the scene's frames
/// come back in the order of `frames`.
fn import_chunk(
    dir: &Path,
    names: &[String],
    frames: &[usize],
    background: Background,
    archive_name: &str,
) -> Result<(Layout, Scene), String> {
    let opts = ImportOptions {
        only: Some(frames.iter().map(|&i| names[i].clone()).collect()),
        background,
        ..ImportOptions::default()
    };
    let imported = import(dir, &opts, &mut |_, _| {}).map_err(|e| {
        let e = e.to_string();
        // The importer names a frame it lacks; say which archive frame that is.
        match frames
            .iter()
            .find(|&&i| e.contains(&format!("no frame named {:?}", names[i])))
        {
            Some(&i) => format!(
                "--source {}: frame {i} of {archive_name} ({:?}) is not in this capture{}",
                dir.display(),
                names[i],
                // "(its 11 frames are named ...)", from the importer's message.
                e.rfind(" (its ").map_or(String::new(), |at| e[at..].to_string())
            ),
            None => format!("--source {}: {e}", dir.display()),
        }
    })?;
    let mut scene = imported.scene;
    let mut by_name: BTreeMap<String, crate::scene::Frame> = std::mem::take(&mut scene.frames)
        .into_iter()
        .filter_map(|f| Some((f.source.clone()?, f)))
        .collect();
    for &i in frames {
        let frame = by_name.remove(&names[i]).ok_or_else(|| {
            format!(
                "--source {}: frame {i} of {archive_name} ({:?}) is not in this capture",
                dir.display(),
                names[i]
            )
        })?;
        scene.frames.push(frame);
    }
    Ok((imported.layout, scene))
}

/// The background `pack` composited transparent pixels on, from the line it left in the
/// archive's provenance notes ("... composited on black ..."); white, the default, otherwise.
pub fn packed_background(archive: &Scene) -> Background {
    let black = format!("composited on {}", Background::Black.name());
    if archive.provenance.notes.iter().any(|n| n.contains(&black)) {
        Background::Black
    } else {
        Background::White
    }
}

/// The capture must show what the archive shows at another scale: same aspect ratio, and the
/// archive's intrinsics scaled to the capture's size.
fn check_camera(archive: &Scene, archive_name: &str, source: &Scene, dir: &Path) -> Result<(), String> {
    let (w, h) = (archive.width, archive.height);
    let (sw, sh) = (source.width, source.height);
    let implied = f64::from(sw) * f64::from(h) / f64::from(w);
    if (implied - f64::from(sh)).abs() > (f64::from(sh) / f64::from(h)).max(1.0) {
        return Err(format!(
            "--source {}: its images are {sw} x {sh}, which is not {archive_name}'s {w} x {h} at another scale (the \
             aspect ratio differs); was {archive_name} packed from this capture?",
            dir.display()
        ));
    }
    let expected = archive.intrinsics.scaled((w, h), (sw, sh));
    let got = source.intrinsics;
    let fields: [(&str, f64, f64, f64); 4] = [
        ("fx", expected.fx, got.fx, expected.fx),
        ("fy", expected.fy, got.fy, expected.fy),
        ("cx", expected.cx, got.cx, f64::from(sw)),
        ("cy", expected.cy, got.cy, f64::from(sh)),
    ];
    for (field, want, have, scale) in fields {
        if (want - have).abs() > INTRINSICS_TOLERANCE * scale.abs() {
            return Err(format!(
                "--source {}: intrinsics {field} = {have:.2} at {sw} x {sh}, but {archive_name}'s scaled to that \
                 size is {want:.2}; was {archive_name} packed from this capture?",
                dir.display()
            ));
        }
    }
    Ok(())
}

/// Rotation angle (radians) and centre distance between two camera-to-world poses.
pub fn pose_difference(a: &Pose, b: &Pose) -> (f64, f64) {
    let r = a.rotation().transpose() * b.rotation();
    let cos = ((r.x_axis.x + r.y_axis.y + r.z_axis.z - 1.0) / 2.0).clamp(-1.0, 1.0);
    (cos.acos(), a.position().distance(b.position()))
}

fn check_pose(
    archive: &Scene,
    archive_name: &str,
    i: usize,
    name: &str,
    pose: &Pose,
    dir: &Path,
) -> Result<(), String> {
    let diagonal = {
        let b = &archive.bounds;
        (0..3).map(|k| (b.max[k] - b.min[k]).powi(2)).sum::<f64>().sqrt()
    };
    let (angle, shift) = pose_difference(&archive.frames[i].pose, pose);
    if !(angle <= POSE_ANGLE_TOLERANCE && shift <= POSE_SHIFT_TOLERANCE * diagonal) {
        return Err(format!(
            "--source {}: frame {i} of {archive_name} ({name:?}) has another pose in this capture: turned by \
             {:.3} degrees and moved by {shift:.4} (the scene's bounds are {diagonal:.3} across); was \
             {archive_name} packed from this capture?",
            dir.display(),
            angle.to_degrees()
        ));
    }
    Ok(())
}

/// Archive frame `frame`'s class map at the capture's size: the field rendered from the
/// archive's pose through the capture's intrinsics, the capture frame's depth guiding the
/// samples, refined with the capture frame's image and depth (`refine` off: the field's own
/// argmax). `source_frame` is the frame's index in `source` (a chunk from
/// [`SourceCapture::load`]).
pub fn render_at_source(
    trainer: &mut Trainer,
    archive: &Scene,
    frame: usize,
    source: &Scene,
    source_frame: usize,
    refine: &RefineOptions,
) -> Result<GrayImage, String> {
    let f = &source.frames[source_frame];
    let (width, height) = (source.width, source.height);
    let view = ViewCamera {
        intrinsics: source.intrinsics,
        pose: archive.frames[frame].pose,
        width,
        height,
    };
    let depth: Vec<f32> = match &f.depth {
        Some(d) => d
            .pixels()
            .map(|p| (f64::from(p.0[0]) * source.depth_scale) as f32)
            .collect(),
        None => vec![0.0; view.pixels()],
    };
    let mut probabilities =
        pollster::block_on(trainer.render_probabilities(&view, &depth)).map_err(|e| e.to_string())?;
    let classes = trainer.config().num_classes as usize;
    if !refine.is_off() {
        let guide = Guide {
            rgb: &f.rgb,
            depth: f.depth.as_ref(),
            codes: None,
        };
        refine_probabilities(&mut probabilities, classes, guide, refine)?;
    }
    let (ids, _) = argmax_and_confidence(&probabilities, classes);
    GrayImage::from_raw(width, height, ids).ok_or_else(|| "rendered class map has the wrong size".to_string())
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{DMat4, DVec3};

    #[test]
    fn pose_difference_measures_turn_and_shift() {
        let a = Pose::identity();
        let b = Pose(DMat4::from_rotation_translation(
            glam::DQuat::from_rotation_y(0.01),
            DVec3::new(0.0, 0.3, 0.4),
        ));
        let (angle, shift) = pose_difference(&a, &b);
        assert!((angle - 0.01).abs() < 1e-9, "{angle}");
        assert!((shift - 0.5).abs() < 1e-12, "{shift}");
        assert_eq!(pose_difference(&b, &b).1, 0.0);
        assert!(pose_difference(&b, &b).0 < 1e-7);
    }

    #[test]
    fn the_background_packed_on_is_read_from_the_provenance() {
        let mut scene = crate::scene::demo::demo_scene(&crate::scene::demo::DemoOptions {
            width: 16,
            height: 16,
            frames: 1,
            ..Default::default()
        })
        .unwrap();
        assert_eq!(packed_background(&scene), Background::White);
        scene.provenance.notes =
            vec!["3 of 3 images have an alpha channel: composited on black (--background white for white)".into()];
        assert_eq!(packed_background(&scene), Background::Black);
    }
}
