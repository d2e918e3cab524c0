//! The captures the quality suite decides defaults on: every capture with ground truth in
//! `../shared/data`, and variants of the demo that stand for what those lack (no depth at all;
//! an object on a plain white or black backdrop with no depth, as NeRF-synthetic renders are).
//! Each is loaded as the README says to pack it: baseline feature codes on a stride-2 grid.
use std::path::Path;

use crate::features::{BakeOptions, Baseline, Extractor, bake};
use crate::scene::demo::{DemoOptions, demo_scene, demo_scene_on_backdrop};
use crate::scene::import::{ImportOptions, import};
use crate::scene::{Scene, read_archive_path, write_archive_path};

/// Where a capture's frames come from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Source {
    /// The built-in demo (a table-top in a room, 36 views at 80 x 60); `depth: false` drops its
    /// depth, as a photo capture without a reconstruction would have.
    Demo { depth: bool },
    /// The demo's table and objects with no room, on a plain backdrop colour, no depth.
    Backdrop([u8; 3]),
    /// A folder of the shared data, packed at a longest side of `max_size` pixels.
    Shared { folder: &'static str, max_size: u32 },
}

/// One capture of the suite: how to load it, which frames the simulated user draws on, which
/// frames are scored, and how long the field trains with labels.
#[derive(Clone, Copy, Debug)]
pub struct Capture {
    pub name: &'static str,
    /// One line for the table's legend: what the capture tests.
    pub tests: &'static str,
    pub source: Source,
    /// Frames the strokes are drawn on (from ground truth, `labels::synthetic`).
    pub drawn: &'static [u32],
    /// Scored frames start here (the YCB clip's frame 0 is the drawn one and nearly the same view
    /// as the rest, so it is left out); every frame from `first_scored` on is scored.
    pub first_scored: usize,
    /// Steps with labels after the warm-up.
    pub steps: u32,
    /// Feature cells are this many pixels wide (`pack --feature-stride`).
    pub feature_stride: u32,
}

/// Every capture of the suite, in the order the table lists them.
pub const CAPTURES: &[Capture] = &[
    Capture {
        name: "demo",
        tests: "synthetic table-top, dense depth, 6 classes",
        source: Source::Demo { depth: true },
        drawn: &[0, 12],
        first_scored: 0,
        steps: 800,
        feature_stride: 2,
    },
    Capture {
        name: "demo-no-depth",
        tests: "the demo without depth (a photo capture with no reconstruction)",
        source: Source::Demo { depth: false },
        drawn: &[0, 12],
        first_scored: 0,
        steps: 800,
        feature_stride: 2,
    },
    Capture {
        name: "backdrop-white",
        tests: "objects on a plain white backdrop, no depth (NeRF-synthetic)",
        source: Source::Backdrop([255, 255, 255]),
        drawn: &[0, 18],
        first_scored: 0,
        steps: 800,
        feature_stride: 2,
    },
    Capture {
        name: "backdrop-black",
        tests: "objects on a plain black backdrop, no depth (NeRF-synthetic)",
        source: Source::Backdrop([0, 0, 0]),
        drawn: &[0, 18],
        first_scored: 0,
        steps: 800,
        feature_stride: 2,
    },
    Capture {
        name: "ycb",
        tests: "real RGB-D clip, 4 classes, strokes on frame 0, frames 1-9 scored",
        source: Source::Shared {
            folder: "ycb-video-0000",
            max_size: 160,
        },
        drawn: &[0],
        first_scored: 1,
        steps: 500,
        feature_stride: 2,
    },
    Capture {
        name: "alexander",
        tests: "real photo capture (COLMAP, 52 views), a convex head in a room",
        source: Source::Shared {
            folder: "alexander-colmap",
            max_size: 200,
        },
        drawn: &[0, 26],
        first_scored: 0,
        steps: 800,
        feature_stride: 2,
    },
    Capture {
        name: "moldgoldcape",
        tests: "real photo capture (COLMAP, 119 views), a hollow shell that leaves the frame",
        source: Source::Shared {
            folder: "moldgoldcape-colmap",
            max_size: 200,
        },
        drawn: &[0, 60],
        first_scored: 0,
        steps: 800,
        // 119 frames of codes at stride 2 exceed a storage binding of 128 MiB.
        feature_stride: 3,
    },
];

/// The capture named `name`.
pub fn capture(name: &str) -> Option<&'static Capture> {
    CAPTURES.iter().find(|c| c.name == name)
}

impl Capture {
    /// The capture's scene with baseline codes baked in (`pack --features baseline
    /// --feature-stride 2`). `Ok(None)`: its shared folder is not under `data`.
    pub fn load(&self, data: &Path) -> Result<Option<Scene>, String> {
        let demo = DemoOptions {
            width: 80,
            height: 60,
            frames: 36,
            ..Default::default()
        };
        let scene = match self.source {
            Source::Demo { depth } => {
                let mut scene = demo_scene(&demo).map_err(|e| e.to_string())?;
                if !depth {
                    for frame in &mut scene.frames {
                        frame.depth = None;
                    }
                }
                scene
            }
            Source::Backdrop(colour) => demo_scene_on_backdrop(&demo, colour).map_err(|e| e.to_string())?,
            Source::Shared { folder, max_size } => {
                let dir = data.join(folder);
                if !dir.is_dir() {
                    return Ok(None);
                }
                let options = ImportOptions {
                    max_size: Some(max_size),
                    ..Default::default()
                };
                import(&dir, &options, &mut |_, _| {})
                    .map_err(|e| format!("{}: {e}", dir.display()))?
                    .scene
            }
        };
        with_baseline_codes(scene, self.feature_stride).map(Some)
    }

    /// [`Capture::load`] through a cache folder: the scene is kept there as a scene archive
    /// (`<name>.scene.zip`) and read back on the next run while its recipe (the capture's source,
    /// stride and this build's version, in the provenance notes) is the same.
    pub fn load_cached(&self, data: &Path, cache: &Path) -> Result<Option<Scene>, String> {
        let file = cache.join(format!("{}.scene.zip", self.name));
        let recipe = self.recipe();
        if let Ok(scene) = read_archive_path(&file)
            && scene.provenance.notes.contains(&recipe)
        {
            return Ok(Some(scene));
        }
        let Some(mut scene) = self.load(data)? else {
            return Ok(None);
        };
        scene.provenance.notes.push(recipe);
        std::fs::create_dir_all(cache).map_err(|e| format!("{}: {e}", cache.display()))?;
        // A name of this process's own: two suites may fill one cache at once.
        let tmp = file.with_extension(format!("zip.{}.tmp", std::process::id()));
        write_archive_path(&scene, &tmp).map_err(|e| format!("{}: {e}", tmp.display()))?;
        std::fs::rename(&tmp, &file).map_err(|e| format!("{}: {e}", file.display()))?;
        Ok(Some(scene))
    }

    /// What a cached archive of this capture must have been made from.
    fn recipe(&self) -> String {
        format!(
            "quality suite capture {}: {:?}, feature stride {}, scribblefield {}",
            self.name,
            self.source,
            self.feature_stride,
            env!("CARGO_PKG_VERSION")
        )
    }

    /// Frames scored in a scene of `frames` frames.
    pub fn scored(&self, frames: usize) -> std::ops::Range<usize> {
        self.first_scored.min(frames)..frames
    }
}

/// `scene` with baseline feature codes on a grid of `stride`-pixel cells.
fn with_baseline_codes(mut scene: Scene, stride: u32) -> Result<Scene, String> {
    let extractor = Baseline::with_stride(stride);
    let baked = bake(
        scene.frames.len(),
        |i| extractor.extract(&scene.frames[i].rgb),
        &extractor.describe(),
        &BakeOptions::default(),
        |_| {},
    )
    .map_err(|e| format!("baking baseline codes: {e}"))?;
    scene.features = Some(baked.codes);
    Ok(scene)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_are_unique_and_drawn_frames_exist_in_the_demo_variants() {
        for (i, c) in CAPTURES.iter().enumerate() {
            assert!(CAPTURES[..i].iter().all(|o| o.name != c.name), "{} twice", c.name);
            if !matches!(c.source, Source::Shared { .. }) {
                assert!(c.drawn.iter().all(|&f| f < 36), "{}", c.name);
            }
        }
        assert_eq!(capture("ycb").map(|c| c.first_scored), Some(1));
    }
}
