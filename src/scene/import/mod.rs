//! Importers: build a Scene from captures in other layouts (autolabel scene directories,
//! 7-Scenes folders, NeRF-style `transforms.json` and NeRF-synthetic split folders, COLMAP sparse
//! models, ScanNet SensReader exports, ARKitScenes raw scenes, Stray Scanner phone captures). Each layout has its own module; they share decoding,
//! resizing, frame selection and bounds estimation.
use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::rc::Rc;

use crate::pause::{NoPause, Pause, run_to_end};
use crate::scene::Scene;
use crate::scene::error::{Result, SceneError};
use crate::scene::manifest::Provenance;
use files::CapturePath;

mod alpha;
mod arkit_text;
mod arkitscenes;
mod autolabel;
mod bounds;
mod classes;
mod colmap;
mod files;
mod frames;
mod images;
mod mp4;
mod nerf_splits;
mod options;
mod register;
mod resize;
pub use resize::target_size;
mod scannet;
mod seven_scenes;
mod stray;
mod stray_text;
mod text;
mod transforms;
mod video;

use crate::scene::private_paths::{folder_name, scrub};
pub use files::{CaptureFiles, MAX_CAPTURE_BYTES, MemoryFiles, reading_from};
use frames::Progress;
pub use options::{Background, Split};

/// What to keep of a capture.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ImportOptions {
    /// Longest image side in pixels; larger captures are downscaled (never upscaled) and their
    /// intrinsics scaled with `Intrinsics::scaled`.
    pub max_size: Option<u32>,
    /// Keep every k-th frame (k >= 1).
    pub every: u32,
    /// Keep at most this many frames (after `every`).
    pub max_frames: Option<u32>,
    /// Folder of binary foreground masks (COLMAP captures only; a `masks/` folder beside
    /// `images/` is used without asking).
    pub masks: Option<PathBuf>,
    /// Class names of mask values below and at or above 128.
    pub mask_classes: [String; 2],
    /// Accept file paths written in a capture's text files (`transforms.json` `file_path`,
    /// COLMAP image names) that are absolute or leave the capture folder with `..`. Off by
    /// default: a capture downloaded from elsewhere must not pack files from anywhere on disk.
    pub allow_outside_paths: bool,
    /// NeRF split folders: the splits to pack, in this order; empty packs every split present.
    pub splits: Vec<Split>,
    /// What transparent pixels of RGBA images are composited on.
    pub background: Background,
    /// NeRF captures: alpha becomes 2-class ground truth (`mask_classes`; 0 < alpha < 255 void).
    pub alpha_gt: bool,
    /// Keep only the frames of these names (`Frame::source`), before `every` and `max_frames`;
    /// a name the capture lacks is an error. `segment --source` re-imports an archive's frames
    /// at full size with it.
    pub only: Option<BTreeSet<String>>,
}

impl Default for ImportOptions {
    fn default() -> Self {
        ImportOptions {
            max_size: None,
            every: 1,
            max_frames: None,
            masks: None,
            mask_classes: ["background".into(), "object".into()],
            allow_outside_paths: false,
            splits: Vec::new(),
            background: Background::White,
            alpha_gt: false,
            only: None,
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Layout {
    /// autolabel scene directory: rgb/ depth/ pose/ intrinsics.txt bbox.txt [semantic/ gt/].
    Autolabel,
    /// 7-Scenes folder: frame-NNNNNN.color.jpg / .depth.png / .pose.txt.
    SevenScenes,
    /// NeRF / instant-ngp / nerfstudio transforms.json.
    Transforms,
    /// COLMAP sparse model: images/ and sparse/0/ (or sparse/) with cameras, images, points3D.
    Colmap,
    /// NeRF-synthetic split folder: transforms_train.json, transforms_val.json, transforms_test.json.
    NerfSplits,
    /// ScanNet SensReader export: color/ depth/ pose/ intrinsic/.
    ScanNet,
    /// ARKitScenes raw scene: lowres_wide/ lowres_depth/ lowres_wide_intrinsics/ lowres_wide.traj.
    ArkitScenes,
    /// Stray Scanner (iOS) capture: rgb.mp4 depth/ confidence/ odometry.csv camera_matrix.csv.
    StrayScanner,
}

impl Layout {
    pub fn name(self) -> &'static str {
        match self {
            Layout::Autolabel => "autolabel",
            Layout::SevenScenes => "7-scenes",
            Layout::Transforms => "transforms.json",
            Layout::Colmap => "colmap",
            Layout::NerfSplits => "nerf-splits",
            Layout::ScanNet => "scannet",
            Layout::ArkitScenes => "arkitscenes",
            Layout::StrayScanner => "stray-scanner",
        }
    }
}

/// A scene built from a capture, with what the user should know about how.
#[derive(Debug)]
pub struct Imported {
    pub scene: Scene,
    pub layout: Layout,
    /// Things that were guessed, ignored or skipped (also recorded in the provenance notes).
    pub warnings: Vec<String>,
    /// Choices the user should see without asking (which splits were packed, what transparent
    /// pixels were composited on); also in the provenance notes.
    pub report: Vec<String>,
}

/// Names the capture layout at `input` (a folder, or a `.json` file for transforms).
pub fn detect_layout(input: &Path) -> Result<Layout> {
    let meta = files::metadata(input).map_err(|e| match e.kind() {
        std::io::ErrorKind::NotFound => SceneError::missing(input.display().to_string(), "the capture to import"),
        _ => SceneError::io(input, e),
    })?;
    if meta.is_file() {
        if input.extension().is_some_and(|e| e.eq_ignore_ascii_case("json")) {
            return Ok(Layout::Transforms);
        }
        return Err(SceneError::invalid(
            input.display().to_string(),
            "is a file; expected a capture folder or a transforms.json",
        ));
    }
    let has_rgb_dir = input.join(autolabel::RGB_DIR).is_capture_dir();
    // A full autolabel scene wins over a transforms.json exported next to it, since only the
    // autolabel files carry depth; a bare rgb/ folder next to a transforms.json is just images.
    if has_rgb_dir && autolabel::has_camera_files(input) {
        return Ok(Layout::Autolabel);
    }
    // COLMAP before transforms.json: only the sparse model carries points (depth and bounds).
    if colmap::looks_like(input) {
        return Ok(Layout::Colmap);
    }
    if scannet::looks_like(input) {
        return Ok(Layout::ScanNet);
    }
    if arkitscenes::looks_like(input) {
        return Ok(Layout::ArkitScenes);
    }
    if stray::looks_like(input) {
        return Ok(Layout::StrayScanner);
    }
    if input.join(transforms::FILE).is_capture_file() {
        return Ok(Layout::Transforms);
    }
    if nerf_splits::looks_like(input) {
        return Ok(Layout::NerfSplits);
    }
    if has_rgb_dir {
        return Ok(Layout::Autolabel);
    }
    if seven_scenes::looks_like(input)? {
        return Ok(Layout::SevenScenes);
    }
    Err(SceneError::invalid(
        input.display().to_string(),
        "not a capture layout scribblefield knows; expected one of: an autolabel scene folder \
         (rgb/, depth/, pose/, intrinsics.txt, bbox.txt), a 7-Scenes folder (frame-000000.color.jpg, \
         frame-000000.depth.png, frame-000000.pose.txt, ...), a folder with a transforms.json, a NeRF-synthetic \
         folder (transforms_train.json, transforms_val.json, transforms_test.json), a COLMAP folder (images/ and \
         sparse/0/ with cameras, images and points3D .txt or .bin), a ScanNet export (color/, depth/, pose/, \
         intrinsic/intrinsic_color.txt), an ARKitScenes scene (lowres_wide/, lowres_depth/, \
         lowres_wide_intrinsics/, lowres_wide.traj), or a Stray Scanner capture (rgb.mp4, depth/, \
         odometry.csv, camera_matrix.csv)",
    ))
}

/// Imports the capture at `input`, calling `progress(done, total)` as frames load.
pub fn import(input: &Path, opts: &ImportOptions, progress: &mut dyn FnMut(usize, usize)) -> Result<Imported> {
    run_to_end(import_pausing(input, opts, progress, &mut NoPause))
}

/// [`import`] that calls `pause` after each frame, so a caller on a thread that must stay
/// responsive (the page) can give it back; where the files are read from is set by
/// [`reading_from`] (the disk otherwise).
pub async fn import_pausing<P: Pause>(
    input: &Path,
    opts: &ImportOptions,
    progress: &mut dyn FnMut(usize, usize),
    pause: &mut P,
) -> Result<Imported> {
    let layout = detect_layout(input)?;
    options::check_for_layout(opts, layout, input)?;
    let progress = &mut Progress {
        report: progress,
        pause,
    };
    let built = match layout {
        Layout::Autolabel => autolabel::import(input, opts, progress).await?,
        Layout::SevenScenes => seven_scenes::import(input, opts, progress).await?,
        Layout::Transforms => transforms::import(input, opts, progress).await?,
        Layout::Colmap => colmap::import(input, opts, progress).await?,
        Layout::NerfSplits => nerf_splits::import(input, opts, progress).await?,
        Layout::ScanNet => scannet::import(input, opts, progress).await?,
        Layout::ArkitScenes => arkitscenes::import(input, opts, progress).await?,
        Layout::StrayScanner => stray::import(input, opts, progress).await?,
    };
    check_scene(&built.scene, input)?;
    Ok(built.finish(input))
}

/// Imports a capture held in memory (a folder the page was handed, or a zip of one): the same
/// importers, reading `files` instead of the disk, from its root folder.
pub async fn import_files<P: Pause>(
    files: Rc<MemoryFiles>,
    opts: &ImportOptions,
    progress: &mut dyn FnMut(usize, usize),
    pause: &mut P,
) -> Result<Imported> {
    let root = files.root().ok_or_else(|| {
        SceneError::invalid(
            "the files given",
            if files.is_empty() {
                "no files (an empty folder?)"
            } else {
                "not one capture folder: the files lie in several folders"
            },
        )
    })?;
    reading_from(files, import_pausing(&root, opts, progress, pause)).await
}

/// What every importer returns before provenance is filled in.
struct Built {
    scene: Scene,
    layout: Layout,
    warnings: Vec<String>,
    notes: Vec<String>,
    /// Lines for the user (see `Imported::report`).
    report: Vec<String>,
}

impl Built {
    /// Records where the scene came from and how it was changed on the way.
    fn finish(mut self, input: &Path) -> Imported {
        let mut notes = self.notes;
        notes.extend(self.report.iter().cloned());
        notes.extend(self.warnings.iter().cloned());
        // The capture by its folder's name: an archive is shared, the packer's paths are not.
        let name = folder_name(input);
        let given = input.display().to_string();
        let notes = notes
            .iter()
            .map(|n| scrub(n, Some((given.as_str(), name.as_str()))))
            .collect();
        self.scene.provenance = Provenance {
            source: name,
            importer: self.layout.name().into(),
            tool: format!("scribblefield {}", env!("CARGO_PKG_VERSION")),
            notes,
        };
        Imported {
            scene: self.scene,
            layout: self.layout,
            warnings: self.warnings,
            report: self.report,
        }
    }
}

/// Final checks shared by all layouts, so a scene that imports also archives.
fn check_scene(scene: &Scene, input: &Path) -> Result<()> {
    let at = input.display().to_string();
    if scene.frames.is_empty() {
        return Err(SceneError::invalid(at, "the capture has no frames"));
    }
    scene
        .intrinsics
        .check()
        .map_err(|p| SceneError::invalid(&at, format!("intrinsics: {p}")))?;
    scene
        .bounds
        .check()
        .map_err(|p| SceneError::invalid(&at, format!("bounds: {p}")))?;
    if let Some(labels) = &scene.labels {
        labels.check(&format!("{at}: imported labels"), scene.frames.len() as u32)?;
    }
    Ok(())
}

/// `relative` (the value of `field` in `file`, a path written in a capture's own files) joined
/// to `base`, the capture folder. An absolute path, or one that climbs above `base` with `..`, is
/// refused unless the user allowed outside paths: the capture's text decides which files get
/// packed, and it must not reach files the user never pointed at. The check is on the path's
/// components, not the file system, so folders the user linked into the capture still work.
fn capture_path(base: &Path, relative: &str, field: &str, file: &str, opts: &ImportOptions) -> Result<PathBuf> {
    use std::path::Component;
    if opts.allow_outside_paths {
        return Ok(base.join(relative));
    }
    let outside = |why: &str| {
        SceneError::invalid(
            file,
            format!(
                "{field} {relative:?} {why}, outside the capture folder {}; paths in a capture must stay inside \
                 it (pack --allow-outside-paths accepts them)",
                shown(base)
            ),
        )
    };
    let path = Path::new(relative);
    let mut depth: usize = 0;
    for part in path.components() {
        match part {
            Component::Prefix(_) | Component::RootDir => return Err(outside("is absolute")),
            Component::ParentDir => depth = depth.checked_sub(1).ok_or_else(|| outside("climbs out with .."))?,
            Component::Normal(_) => depth += 1,
            Component::CurDir => {}
        }
    }
    // On Unix a Windows-style absolute path (C:\x, \\server\x) is one normal component; it
    // names no file inside the capture either.
    let bytes = relative.as_bytes();
    let drive = bytes.len() >= 2
        && bytes[0].is_ascii_alphabetic()
        && bytes[1] == b':'
        && matches!(bytes.get(2), None | Some(b'/' | b'\\'));
    if relative.starts_with('\\') || drive {
        return Err(outside("is absolute"));
    }
    Ok(base.join(path))
}

/// The importers' parsers of a capture's own text files (and of a video's MP4 index), run on
/// bytes in memory (no file is read, no image decoded): everything each importer decides from
/// them alone. The fuzz targets (`fuzz/`) and their corpus replay (`tests/fuzz_corpus.rs`) call
/// these, through `scribblefield::fuzzing`, and the tests compare them with other tools.
pub mod text_checks {
    use std::path::Path;

    use super::{ImportOptions, colmap, mp4, scannet, stray_text, text, transforms};
    use crate::scene::camera::{Intrinsics, Pose};
    use crate::scene::error::{Result, SceneError};

    /// A `transforms.json` in a capture folder `capture/`; returns its frame count.
    pub fn transforms_json(bytes: &[u8]) -> Result<usize> {
        transforms::check_text(bytes, Path::new("capture"), &ImportOptions::default())
    }

    /// A COLMAP text model (`cameras.txt`, `images.txt`, `points3D.txt`); returns its image count.
    pub fn colmap_text(cameras: &str, images: &str, points: &str) -> Result<usize> {
        colmap::check_text_model([cameras, images, points])
    }

    /// A COLMAP binary model (`cameras.bin`, `images.bin`, `points3D.bin`); returns its image count.
    pub fn colmap_binary(cameras: &[u8], images: &[u8], points: &[u8]) -> Result<usize> {
        colmap::check_binary_model([cameras, images, points])
    }

    /// A Stray Scanner `odometry.csv`: its frame numbers and camera-to-world poses (OpenCV axes).
    pub fn stray_odometry(bytes: &[u8]) -> Result<Vec<(u32, Pose)>> {
        let file = "odometry.csv";
        Ok(stray_text::parse_odometry(text_of(bytes, file)?, file)?
            .into_iter()
            .map(|r| (r.frame, r.pose))
            .collect())
    }

    /// A Stray Scanner `camera_matrix.csv`.
    pub fn stray_camera_matrix(bytes: &[u8]) -> Result<Intrinsics> {
        let file = "camera_matrix.csv";
        stray_text::parse_camera_matrix(text_of(bytes, file)?, file)
    }

    /// An MP4's video track as the page seeks in it: the frame size and, in presentation order,
    /// the second at which each frame starts.
    pub fn mp4_video(bytes: &[u8]) -> Result<((u32, u32), Vec<f64>)> {
        let v = mp4::parse(bytes, "rgb.mp4")?;
        Ok((v.size, v.frame_times))
    }

    /// [`mp4_video`] refusing a track of over `max_frames` frames (the fuzzer's low cap).
    pub fn mp4_video_capped(bytes: &[u8], max_frames: u64) -> Result<((u32, u32), Vec<f64>)> {
        let v = mp4::parse_capped(bytes, "rgb.mp4", max_frames)?;
        Ok((v.size, v.frame_times))
    }

    /// A ScanNet pose file (`pose/N.txt`): `None` where it marks a lost frame (non-finite).
    pub fn scannet_pose(bytes: &[u8]) -> Result<Option<Pose>> {
        let file = "pose/0.txt";
        scannet::pose_from_text(text_of(bytes, file)?, file)
    }

    /// ScanNet intrinsics (`intrinsic/intrinsic_color.txt`) for colour images of `size`.
    pub fn scannet_intrinsics(bytes: &[u8], size: (u32, u32)) -> Result<Intrinsics> {
        let file = "intrinsic/intrinsic_color.txt";
        let (k, _skew) = text::intrinsics_from_numbers(&text::parse_numbers(text_of(bytes, file)?, file)?, file)?;
        scannet::check_principal_point(&k, size, Path::new(file))?;
        Ok(k)
    }

    /// A 7-Scenes `frame-NNNNNN.pose.txt`: a 4x4 (or 3x4) camera-to-world matrix.
    pub fn pose_text(bytes: &[u8]) -> Result<Pose> {
        let file = "frame-000000.pose.txt";
        text::pose_from_numbers(&text::parse_numbers(text_of(bytes, file)?, file)?, file)
    }

    /// A 7-Scenes `camera-intrinsics.txt` (or autolabel `intrinsics.txt`): a 3x3 or 4x4 K.
    pub fn intrinsics_text(bytes: &[u8]) -> Result<Intrinsics> {
        let file = "camera-intrinsics.txt";
        let (k, _skew) = text::intrinsics_from_numbers(&text::parse_numbers(text_of(bytes, file)?, file)?, file)?;
        Ok(k)
    }

    /// The checks `text::read_text` makes on a file's bytes.
    fn text_of<'a>(bytes: &'a [u8], file: &str) -> Result<&'a str> {
        if bytes.len() as u64 > text::MAX_TEXT_BYTES {
            return Err(SceneError::invalid(
                file,
                format!("{} bytes is far too large for this text file", bytes.len()),
            ));
        }
        std::str::from_utf8(bytes).map_err(|_| SceneError::invalid(file, "not a text file (not UTF-8)"))
    }
}

/// Display name of a path for messages.
fn shown(path: &Path) -> String {
    path.display().to_string()
}
