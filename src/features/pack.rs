//! Packing a capture held in memory into a scene archive, as `pack` does on the command line:
//! the same importers (reading the files given instead of the disk), the weight-free baseline
//! features and their autoencoder, the same archive writer. The page runs this on its one thread
//! with a pause that gives the thread back ([`crate::pause`]): after every frame imported, every
//! frame's features and every autoencoder step.
use std::rc::Rc;

use super::bake::{BakeOptions, BakeProgress, bake_pausing};
use super::{Baseline, Extractor, FeatureError};
use crate::pause::Pause;
use crate::scene::SceneError;
use crate::scene::archive::write_archive_bytes;
use crate::scene::import::{ImportOptions, Layout, MemoryFiles, import_files};

/// What to pack, besides the capture's own files.
#[derive(Clone, Debug, PartialEq)]
pub struct PackOptions {
    /// Which frames, at what size (`pack --max-size`, `--every`, `--max-frames`, ...).
    pub import: ImportOptions,
    /// Baseline feature codes (`pack --features baseline`), or none.
    pub features: Option<BaselineFeatures>,
}

/// `pack --features baseline --feature-stride S --autoencoder-steps N`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BaselineFeatures {
    pub stride: u32,
    pub autoencoder_steps: u32,
}

/// Where packing is, for a progress bar.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum PackProgress {
    /// Frames decoded (ScanNet counts colour and depth separately: `total` is twice its frames).
    Importing {
        done: usize,
        total: usize,
    },
    Features(BakeProgress),
    Writing,
}

/// A packed capture.
pub struct Packed {
    /// The `.scene.zip`'s bytes, as `pack -o` would write them.
    pub archive: Vec<u8>,
    pub layout: Layout,
    /// What the importer guessed, ignored or skipped (`pack` prints them as warnings).
    pub warnings: Vec<String>,
    /// What the user should see without asking (`pack` prints these lines).
    pub report: Vec<String>,
    /// The scene's summary (`pack` and `info` print it).
    pub summary: String,
    /// The features line `pack` prints, when there are features.
    pub features: Option<String>,
}

#[derive(Debug, thiserror::Error)]
pub enum PackError {
    #[error(transparent)]
    Scene(#[from] SceneError),
    #[error("features: {0}")]
    Features(#[from] FeatureError),
}

/// Packs the capture in `files` (its root folder; see [`MemoryFiles::root`]).
pub async fn pack_files<P: Pause>(
    files: Rc<MemoryFiles>,
    opts: &PackOptions,
    mut progress: impl FnMut(PackProgress),
    pause: &mut P,
) -> Result<Packed, PackError> {
    let imported = import_files(
        files,
        &opts.import,
        &mut |done, total| progress(PackProgress::Importing { done, total }),
        pause,
    )
    .await?;
    let mut scene = imported.scene;
    let mut features = None;
    if let Some(f) = opts.features {
        let extractor = Baseline::with_stride(f.stride);
        let mut bake = BakeOptions::default();
        bake.autoencoder.steps = f.autoencoder_steps.max(1);
        let frames = &scene.frames;
        let baked = bake_pausing(
            frames.len(),
            |i| extractor.extract(&frames[i].rgb).map_err(|e| e.at_frame(i)),
            &extractor.describe(),
            &bake,
            |p| progress(PackProgress::Features(p)),
            pause,
        )
        .await?;
        features = Some(format!(
            "features: {} -> {} dims on a {} x {} grid; autoencoder reconstruction MSE {:.3} (mean predictor: {:.3}), \
             code sparsity {:.2}",
            baked.input_dim,
            baked.codes.dim,
            baked.codes.width,
            baked.codes.height,
            baked.fit.reconstruction_mse,
            baked.fit.baseline_mse,
            baked.fit.code_sparsity
        ));
        scene.features = Some(baked.codes);
    }
    progress(PackProgress::Writing);
    pause.pause().await;
    let archive = write_archive_bytes(&scene)?;
    Ok(Packed {
        archive,
        layout: imported.layout,
        warnings: imported.warnings,
        report: imported.report,
        summary: scene.summary(),
        features,
    })
}

/// Extensions of the files a capture is read from (a Stray Scanner capture's video and CSV files
/// among them); anything else in the folder (COLMAP's `database.db`, meshes) is never read into
/// the page's memory.
pub const CAPTURE_EXTENSIONS: &[&str] = &[
    "jpg", "jpeg", "png", "txt", "json", "bin", "traj", "pincam", "csv", "mp4",
];

/// Whether the importers may read `path` (by its extension, [`CAPTURE_EXTENSIONS`]).
pub fn is_capture_file(path: &str) -> bool {
    path.rsplit_once('.')
        .is_some_and(|(_, ext)| CAPTURE_EXTENSIONS.contains(&ext.to_ascii_lowercase().as_str()))
}

/// What a capture's list of files says before any is read: how many colour images it has, so
/// the page can estimate what packing will cost before it starts. A guess from names alone: the
/// importer decides (a COLMAP model may register fewer photos than `images/` holds, a
/// `transforms.json` may list fewer frames than its folder has images).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct CaptureSurvey {
    /// Colour images found (for a video capture: its frames, one depth image each).
    pub images: usize,
    /// Index (in the list surveyed) of the first colour image by path: its header gives the
    /// frames' size.
    pub first_image: Option<usize>,
    /// Index of a video capture's video (Stray Scanner's `rgb.mp4`), whose MP4 index gives the
    /// frames' size; the frames are counted by their depth images.
    pub video: Option<usize>,
    /// Bytes of the files the page reads (images and model files, [`is_capture_file`]).
    pub capture_bytes: u64,
    /// Of those, the bytes of files that are not images (camera, pose and model files), which
    /// the importer parses whatever frames it keeps.
    pub model_bytes: u64,
    /// Where the images were found, for the estimate's caption (`images/`, `color/`, ...).
    pub found_in: String,
    /// The capture has depth images (a depth folder, `*.depth.png`), packed beside each frame.
    pub dense_depth: bool,
}

const IMAGE_EXTENSIONS: &[&str] = &["jpg", "jpeg", "png"];
/// Folders whose images are not the frames' colour.
const NOT_COLOUR_DIRS: &[&str] = &[
    "depth",
    "masks",
    "mask",
    "gt",
    "semantic",
    "sparse",
    "normals",
    "pose",
    "intrinsic",
    "confidence",
];

/// Surveys a capture from its files' paths (`/`-separated, any prefix) and sizes.
pub fn survey_capture<'a>(files: impl IntoIterator<Item = (&'a str, u64)>) -> CaptureSurvey {
    let files: Vec<(&str, u64)> = files.into_iter().collect();
    let capture_bytes = files.iter().filter(|(p, _)| is_capture_file(p)).map(|&(_, b)| b).sum();
    let is_image = |path: &str| {
        path.rsplit_once('.')
            .is_some_and(|(_, e)| IMAGE_EXTENSIONS.contains(&e.to_ascii_lowercase().as_str()))
    };
    let model_bytes = files
        .iter()
        .filter(|(p, _)| is_capture_file(p) && !is_image(p))
        .map(|&(_, b)| b)
        .sum();
    let dirs = |path: &str| -> Vec<String> {
        let mut parts: Vec<String> = path.split('/').map(|c| c.to_ascii_lowercase()).collect();
        parts.pop();
        parts
    };
    let name = |path: &str| path.rsplit('/').next().unwrap_or(path).to_ascii_lowercase();
    let images: Vec<usize> = (0..files.len())
        .filter(|&i| {
            let n = name(files[i].0);
            n.rsplit_once('.').is_some_and(|(_, e)| IMAGE_EXTENSIONS.contains(&e)) && !n.starts_with('.')
        })
        .collect();
    let dense_depth = images.iter().any(|&i| {
        dirs(files[i].0).iter().any(|d| d == "depth" || d == "lowres_depth") || name(files[i].0).contains(".depth.")
    });
    // A Stray Scanner capture: its colour is a video, one depth image a frame.
    let video = (0..files.len()).find(|&i| {
        name(files[i].0) == "rgb.mp4" && {
            let folder = &files[i].0[..files[i].0.len() - "rgb.mp4".len()];
            files.iter().any(|(p, _)| {
                p.strip_prefix(folder)
                    .is_some_and(|r| r.eq_ignore_ascii_case("odometry.csv"))
            })
        }
    });
    if let Some(v) = video {
        let folder = &files[v].0[..files[v].0.len() - "rgb.mp4".len()];
        let frames = images
            .iter()
            .filter(|&&i| {
                files[i]
                    .0
                    .strip_prefix(folder)
                    .is_some_and(|r| r.to_ascii_lowercase().starts_with("depth/"))
            })
            .count();
        return CaptureSurvey {
            images: frames,
            first_image: None,
            video: Some(v),
            capture_bytes,
            model_bytes,
            found_in: "rgb.mp4".into(),
            dense_depth: true,
        };
    }
    // The colour folder of each layout, most specific first (ScanNet, autolabel, COLMAP and most
    // transforms.json captures, ARKitScenes, 7-Scenes); else every image that is not depth, a mask or ground truth.
    let in_dir = |i: usize, dir: &str| dirs(files[i].0).iter().any(|d| d == dir);
    let mut found = None;
    for (label, dir) in [
        ("color/", "color"),
        ("rgb/", "rgb"),
        ("images/", "images"),
        ("lowres_wide/", "lowres_wide"),
    ] {
        let chosen: Vec<usize> = images.iter().copied().filter(|&i| in_dir(i, dir)).collect();
        if !chosen.is_empty() {
            found = Some((label.to_string(), chosen));
            break;
        }
    }
    let seven_scenes: Vec<usize> = images
        .iter()
        .copied()
        .filter(|&i| name(files[i].0).contains(".color."))
        .collect();
    let (found_in, mut chosen) = match found {
        Some(f) => f,
        None if !seven_scenes.is_empty() => ("*.color.*".to_string(), seven_scenes),
        None => {
            let colour = images
                .iter()
                .copied()
                .filter(|&i| {
                    let n = name(files[i].0);
                    !dirs(files[i].0).iter().any(|d| NOT_COLOUR_DIRS.contains(&d.as_str()))
                        && !["depth", "normal", "mask", "alpha"].iter().any(|w| n.contains(w))
                })
                .collect();
            ("the folder".to_string(), colour)
        }
    };
    chosen.sort_by_key(|&i| files[i].0);
    CaptureSurvey {
        images: chosen.len(),
        first_image: chosen.first().copied(),
        video: None,
        capture_bytes,
        model_bytes,
        found_in,
        dense_depth,
    }
}

/// What packing a capture will cost, worked out before it starts ([`estimate_pack`]).
#[derive(Clone, Debug, PartialEq)]
pub struct PackEstimate {
    /// Frames packed (of the images found, after `every` and `max_frames`).
    pub frames: usize,
    /// Each frame's size in the archive.
    pub size: (u32, u32),
    /// Feature cells per frame (columns, rows), when features are packed.
    pub grid: Option<(u32, u32)>,
    pub archive_bytes: u64,
    /// The page's memory at the peak of packing (the capture's files, the decoded frames, the
    /// feature maps and codes, the archive and its copy opened for annotation).
    pub memory_bytes: u64,
    /// Seconds of packing, by stage: reading the files, decoding frames, features, the
    /// autoencoder (and encoding the codes), writing the archive.
    pub seconds: PackSeconds,
}

#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PackSeconds {
    pub reading: f64,
    pub frames: f64,
    pub features: f64,
    pub autoencoder: f64,
    pub writing: f64,
}

impl PackSeconds {
    pub fn total(&self) -> f64 {
        self.reading + self.frames + self.features + self.autoencoder + self.writing
    }
}

/// Per-unit costs of packing in the page, and the archive's bytes per pixel: fitted to five
/// packs of the COLMAP capture (52 photos of 800 x 800, 4.3 MB of model text) in headless
/// Chromium on SwiftShader, on a loaded 2-core machine, 2026-12 (6 frames at 64, 96 and 192
/// pixels, 13 at 320, 26 at 96; stride 4 and 8; 100 to 1000 steps), then checked against two
/// more (52 frames at 640, the page's defaults: 62 s packed, 67 s estimated; 18 frames at 256:
/// 20 s and 25 s; docs/web-app.md, "Packing in the page"). They are wall-clock costs of the
/// page, whose every repaint there takes up to a second that packing waits behind, so a fixed
/// part per stage is in them; with a GPU the page packs quicker. Within about a third of what
/// was measured for those packs; the page says the time is an estimate.
pub mod costs {
    /// Copying the chosen files into the page.
    pub const READ_NS_PER_BYTE: f64 = 40.0;
    /// Parsing the capture's model and camera files (COLMAP's `images.txt` and `points3D.txt`:
    /// 0.9 s for 4.3 MB).
    pub const MODEL_NS_PER_BYTE: f64 = 210.0;
    /// Decoding a frame's image, per pixel of the source image (0.2 s a frame of 800 x 800).
    pub const DECODE_NS_PER_SOURCE_PIXEL: f64 = 310.0;
    /// Per pixel of the packed frame: resampling, undistortion, depth, ground truth.
    pub const IMPORT_NS_PER_PIXEL: f64 = 700.0;
    /// Baseline features: a fixed part, and per pixel of the packed frames.
    pub const FEATURES_FIXED_S: f64 = 2.5;
    pub const FEATURES_NS_PER_PIXEL: f64 = 600.0;
    /// One step of the feature autoencoder (256 cells a batch, 30 -> 128 -> 64 -> 128 -> 30):
    /// 3 ms of work, 15 ms of the page's time once the fit is long enough for repaints.
    pub const AUTOENCODER_MS_PER_STEP: f64 = 15.0;
    /// Encoding every cell once the autoencoder is fitted.
    pub const ENCODE_NS_PER_CELL: f64 = 5_000.0;
    /// Writing the archive: a fixed part, and PNG encoding per pixel of the packed frames.
    pub const WRITE_FIXED_S: f64 = 0.1;
    pub const WRITE_NS_PER_PIXEL: f64 = 400.0;
    /// A photo as a PNG, per pixel (the COLMAP capture's photos at 96, 320 and 640 pixels:
    /// 1.6-1.8, 1.3-1.4 and about 1.1; downscaled photos compress little).
    pub const RGB_BYTES_PER_PIXEL: f64 = 1.3;
    /// Dense depth as a 16-bit PNG, per pixel; sparse depth (COLMAP's points) is mostly zeros
    /// (0.1-0.4 with its ground truth masks, by size).
    pub const DENSE_DEPTH_BYTES_PER_PIXEL: f64 = 1.3;
    pub const SPARSE_DEPTH_BYTES_PER_PIXEL: f64 = 0.15;
    /// Dimensions of a feature code, as half floats in the archive.
    pub const CODE_DIM: u64 = 64;
    /// What deflate leaves of the codes (0.62 for the COLMAP capture's).
    pub const CODE_COMPRESSION: f64 = 0.65;
}

/// Estimates what packing `survey`'s capture with `opts` costs, its frames being `source` pixels
/// (the first image's size).
pub fn estimate_pack(survey: &CaptureSurvey, source: (u32, u32), opts: &PackOptions) -> PackEstimate {
    use costs::*;
    let every = opts.import.every.max(1) as usize;
    let mut frames = survey.images.div_ceil(every);
    if let Some(m) = opts.import.max_frames {
        frames = frames.min(m as usize);
    }
    let size = crate::scene::import::target_size(source, opts.import.max_size);
    let pixels = size.0 as f64 * size.1 as f64;
    let source_pixels = source.0 as f64 * source.1 as f64;
    let n = frames as f64;
    let grid = opts
        .features
        .map(|f| (size.0.div_ceil(f.stride.max(1)), size.1.div_ceil(f.stride.max(1))));
    let cells = grid.map_or(0.0, |(w, h)| w as f64 * h as f64 * n);
    let depth_bytes = if survey.dense_depth {
        DENSE_DEPTH_BYTES_PER_PIXEL
    } else {
        SPARSE_DEPTH_BYTES_PER_PIXEL
    };
    let code_bytes = cells * CODE_DIM as f64 * 2.0;
    let archive = n * pixels * (RGB_BYTES_PER_PIXEL + depth_bytes) + code_bytes * CODE_COMPRESSION + 4096.0 + n * 300.0;
    let input_dim = 30.0;
    let memory = survey.capture_bytes as f64
        // One source image decoded and resized at a time.
        + source_pixels * 3.0 * 2.0
        // The frames: colour, depth (f32), ground truth.
        + n * pixels * (3.0 + 4.0 + 1.0)
        // Feature maps and the codes (f32 while encoding).
        + cells * (input_dim * 4.0 + CODE_DIM as f64 * 4.0)
        // The archive, and the scene opened from it (colour, depth, ground truth, codes).
        + archive
        + n * pixels * 6.0
        + code_bytes;
    let seconds = PackSeconds {
        reading: survey.capture_bytes as f64 * READ_NS_PER_BYTE * 1e-9,
        frames: (survey.model_bytes as f64 * MODEL_NS_PER_BYTE
            + n * (source_pixels * DECODE_NS_PER_SOURCE_PIXEL + pixels * IMPORT_NS_PER_PIXEL))
            * 1e-9,
        features: if opts.features.is_some() {
            FEATURES_FIXED_S + n * pixels * FEATURES_NS_PER_PIXEL * 1e-9
        } else {
            0.0
        },
        autoencoder: opts.features.map_or(0.0, |f| {
            f.autoencoder_steps.max(1) as f64 * AUTOENCODER_MS_PER_STEP * 1e-3 + cells * ENCODE_NS_PER_CELL * 1e-9
        }),
        writing: WRITE_FIXED_S + n * pixels * WRITE_NS_PER_PIXEL * 1e-9,
    };
    PackEstimate {
        frames,
        size,
        grid,
        archive_bytes: archive as u64,
        memory_bytes: memory as u64,
        seconds,
    }
}

/// The pack settings as a user types them (the page's form), each checked as the page options
/// of the same name are (`#pack-size=` and the others; docs/web-app.md).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct PackForm {
    /// Longest side in pixels.
    pub max_size: String,
    /// Every N-th frame.
    pub every: String,
    /// At most N frames; empty for all.
    pub max_frames: String,
    /// Bake baseline features.
    pub features: bool,
    /// Pixels per feature cell.
    pub stride: String,
    pub steps: String,
}

/// A setting of the form that cannot be used, and why.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FormError {
    /// `max_size`, `every`, `max_frames`, `stride` or `steps`.
    pub field: &'static str,
    pub message: String,
}

impl PackForm {
    /// The form filled in with `opts`.
    pub fn from_options(opts: &PackOptions) -> PackForm {
        let i = &opts.import;
        PackForm {
            max_size: i.max_size.map_or(String::new(), |s| s.to_string()),
            every: i.every.to_string(),
            max_frames: i.max_frames.map_or(String::new(), |m| m.to_string()),
            features: opts.features.is_some(),
            stride: opts.features.map_or(String::from("8"), |f| f.stride.to_string()),
            steps: opts
                .features
                .map_or(String::from("1000"), |f| f.autoencoder_steps.to_string()),
        }
    }

    /// The options the form asks for, on top of `base` (its other import options), or what is
    /// wrong with it, field by field.
    pub fn options(&self, base: &PackOptions) -> Result<PackOptions, Vec<FormError>> {
        let mut errors = Vec::new();
        let mut number = |field: &'static str, text: &str, range: std::ops::RangeInclusive<u32>, what: &str| {
            let text = text.trim();
            match text.parse::<u32>() {
                Ok(n) if range.contains(&n) => Some(n),
                _ => {
                    errors.push(FormError {
                        field,
                        message: if text.is_empty() {
                            format!("give {what}")
                        } else {
                            format!("{text:?} is not {what}")
                        },
                    });
                    None
                }
            }
        };
        let max_size = number(
            "max_size",
            &self.max_size,
            8..=crate::scene::archive::limits::MAX_SIDE,
            "a longest side from 8 to 8192 pixels",
        );
        let every = number("every", &self.every, 1..=u32::MAX, "a whole number from 1");
        let max_frames = if self.max_frames.trim().is_empty() {
            Some(None)
        } else {
            number(
                "max_frames",
                &self.max_frames,
                1..=u32::MAX,
                "a whole number of frames from 1 (empty: all)",
            )
            .map(Some)
        };
        let features = if self.features {
            let stride = number("stride", &self.stride, 1..=64, "a cell of 1 to 64 pixels");
            let steps = number("steps", &self.steps, 1..=100_000, "a number of steps from 1 to 100000");
            stride.zip(steps).map(|(stride, autoencoder_steps)| {
                Some(BaselineFeatures {
                    stride,
                    autoencoder_steps,
                })
            })
        } else {
            Some(None)
        };
        match (max_size, every, max_frames, features) {
            (Some(max_size), Some(every), Some(max_frames), Some(features)) if errors.is_empty() => Ok(PackOptions {
                import: ImportOptions {
                    max_size: Some(max_size),
                    every,
                    max_frames,
                    ..base.import.clone()
                },
                features,
            }),
            _ => Err(errors),
        }
    }
}

#[cfg(test)]
#[path = "pack_tests.rs"]
mod tests;
