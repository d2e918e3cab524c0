//! NeRF-synthetic folders (lego, chair, ...): one transforms file per split,
//! `transforms_train.json`, `transforms_val.json`, `transforms_test.json`, each in the format
//! `transforms.rs` reads (`camera_angle_x`, frames with `file_path` such as `./train/r_0`
//! without extension, OpenGL camera-to-world `transform_matrix`), images RGBA PNGs. The splits
//! are one capture of one camera, so they pack into one scene, in the order train, val, test.
use std::path::Path;

use super::files::CapturePath;
use super::frames::Progress;
use super::options::Split;
use super::transforms::{Listing, build, camera_difference, list};
use super::{Built, ImportOptions, Layout, shown};
use crate::scene::error::{Result, SceneError};

/// Whether `dir` holds at least one split file.
pub(super) fn looks_like(dir: &Path) -> bool {
    Split::ALL.iter().any(|s| dir.join(s.file_name()).is_capture_file())
}

pub(super) async fn import(dir: &Path, opts: &ImportOptions, progress: &mut Progress<'_>) -> Result<Built> {
    let splits = chosen_splits(dir, &opts.splits)?;
    if splits.is_empty() {
        // Detection saw a split file; it is gone now.
        return Err(SceneError::missing(
            shown(&dir.join(Split::Train.file_name())),
            "the split files of a NeRF-synthetic folder (transforms_train.json, ...)",
        ));
    }
    let mut listings: Vec<(Split, Listing)> = Vec::with_capacity(splits.len());
    for split in splits {
        let listing = list(&dir.join(split.file_name()), opts)?;
        if let Some((first_split, first)) = listings.first() {
            check_same_camera(first, *first_split, &listing, split)?;
        }
        listings.push((split, listing));
    }
    let counts = listings
        .iter()
        .map(|(s, l)| format!("{} ({} frames)", s.name(), l.entries.len()))
        .collect::<Vec<_>>()
        .join(", ");
    let skipped: Vec<&str> = Split::ALL
        .iter()
        .filter(|s| !listings.iter().any(|(t, _)| t == *s))
        .map(|s| s.name())
        .collect();
    let mut line = format!("splits packed: {counts}");
    if !skipped.is_empty() {
        line.push_str(&format!("; not packed: {}", skipped.join(", ")));
    }
    if opts.every > 1 || opts.max_frames.is_some() {
        line.push_str(" (before --every / --max-frames)");
    }

    // One listing of every chosen split's frames, in split order, under the first split's camera
    // (all agree, checked above).
    let mut merged = Listing {
        file: listings[0].1.file.clone(),
        camera: listings[0].1.camera,
        entries: Vec::new(),
        warnings: Vec::new(),
    };
    for (_, l) in listings {
        merged.warnings.extend(l.warnings);
        merged.entries.extend(l.entries);
    }
    let mut built = build(merged, opts, Layout::NerfSplits, progress).await?;
    built.report.insert(0, line);
    Ok(built)
}

/// The splits to pack: those asked for (each file must exist), or every one present.
fn chosen_splits(dir: &Path, asked: &[Split]) -> Result<Vec<Split>> {
    if asked.is_empty() {
        return Ok(Split::ALL
            .into_iter()
            .filter(|s| dir.join(s.file_name()).is_capture_file())
            .collect());
    }
    let mut splits = asked.to_vec();
    splits.sort();
    splits.dedup();
    for s in &splits {
        let path = dir.join(s.file_name());
        if !path.is_capture_file() {
            return Err(SceneError::missing(
                shown(&path),
                format!("the {} split asked for with --split", s.name()),
            ));
        }
    }
    Ok(splits)
}

/// All splits must describe the same camera: one scene has one set of intrinsics.
fn check_same_camera(first: &Listing, first_split: Split, other: &Listing, split: Split) -> Result<()> {
    let Some((field, a, b)) = camera_difference(&first.camera, &other.camera) else {
        return Ok(());
    };
    let value = |v: Option<f64>| v.map_or("absent".to_string(), |v| v.to_string());
    Err(SceneError::invalid(
        &other.file,
        format!(
            "{field} = {} in the {} split, but {} in the {} split ({}): the splits must share one camera \
             (pack them one by one, or choose with --split)",
            value(b),
            split.name(),
            value(a),
            first_split.name(),
            first.file
        ),
    ))
}
