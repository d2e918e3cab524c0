//! The part every importer shares once it knows which files make up each frame: choosing the
//! frames to keep, decoding them, checking their sizes agree, and downscaling consistently.
use std::collections::BTreeMap;
use std::future::Future;
use std::path::{Path, PathBuf};
use std::pin::Pin;

use image::{GrayImage, RgbImage};

use super::files::CapturePath;
use super::images::{dimensions, load_depth, load_gt, load_rgb};
use super::resize::{resize_nearest, resize_rgb, same_aspect, target_size};
use super::{Background, ImportOptions};
use crate::pause::Pause;
use crate::scene::archive::limits;
use crate::scene::camera::{Bounds, Intrinsics, Pose};
use crate::scene::error::{Result, SceneError};
use crate::scene::{DepthImage, Frame, Scene};

/// The files and pose of one frame of a capture.
pub(super) struct FrameFiles {
    /// How the capture names the frame (a file stem), kept as `Frame::source`.
    pub name: String,
    pub rgb: PathBuf,
    pub depth: Option<PathBuf>,
    pub gt: Option<PathBuf>,
    /// Camera-to-world, OpenCV axes.
    pub pose: Pose,
}

/// [`files_by_stem`] of the folder `dir/sub`; a missing folder is named as part of `layout`
/// (what the capture's folders are, for the message).
pub(super) fn frames_in(dir: &Path, sub: &str, exts: &[&str], layout: &str) -> Result<BTreeMap<String, PathBuf>> {
    let folder = dir.join(sub);
    if !folder.is_capture_dir() {
        return Err(SceneError::missing(
            super::shown(&folder),
            format!("the {sub}/ folder of {layout}"),
        ));
    }
    files_by_stem(&folder, exts, "")
}

/// The files directly in `dir` whose extension is one of `exts` (lower case; matched ignoring
/// case), keyed by the rest of the name. Two files for the same frame are an error.
pub(super) fn files_by_stem(dir: &Path, exts: &[&str], suffix: &str) -> Result<BTreeMap<String, PathBuf>> {
    let entries = super::files::read_dir(dir).map_err(|e| SceneError::io(dir, e))?;
    let mut out = BTreeMap::new();
    for path in entries {
        let Some(file_name) = path.file_name().and_then(|n| n.to_str()) else {
            continue;
        };
        let Some((stem, ext)) = file_name.rsplit_once('.') else {
            continue;
        };
        let Some(stem) = stem.strip_suffix(suffix) else {
            continue;
        };
        if stem.is_empty() || !exts.contains(&ext.to_ascii_lowercase().as_str()) || !path.is_capture_file() {
            continue;
        }
        if let Some(other) = out.insert(stem.to_string(), path.clone()) {
            return Err(SceneError::invalid(
                path.display().to_string(),
                format!("two files for frame {stem:?} (also {}); remove one", other.display()),
            ));
        }
    }
    Ok(out)
}

/// Frame names in capture order: numerically when all names are numbers (so frame 10 follows
/// frame 9 even without zero padding), otherwise alphabetically.
pub(super) fn frame_order<'a>(names: impl IntoIterator<Item = &'a String>) -> Vec<String> {
    let mut names: Vec<String> = names.into_iter().cloned().collect();
    if names.iter().all(|n| n.parse::<u64>().is_ok()) {
        names.sort_by_key(|n| (n.parse::<u64>().unwrap_or(u64::MAX), n.clone()));
    } else {
        names.sort();
    }
    names
}

/// Where an import reports its frames and gives its thread back between them (`crate::pause`):
/// the page packs a capture on the thread that also draws, and one frame's decoding is the unit
/// of work it can stop after.
pub(super) struct Progress<'a> {
    pub report: &'a mut dyn FnMut(usize, usize),
    pub pause: &'a mut dyn PauseBoxed,
}

impl Progress<'_> {
    /// Says how far the import is, without pausing.
    pub fn show(&mut self, done: usize, total: usize) {
        (self.report)(done, total)
    }

    /// Says a frame is done, then lets the caller's pause decide whether to give the thread back.
    pub async fn frame_done(&mut self, done: usize, total: usize) {
        (self.report)(done, total);
        self.pause.pause_boxed().await
    }
}

/// [`Pause`] behind a pointer: the importers take one pause of any kind without each becoming
/// generic over it (a boxed future per frame costs nothing next to decoding the frame).
pub(super) trait PauseBoxed {
    fn pause_boxed(&mut self) -> Pin<Box<dyn Future<Output = ()> + '_>>;
}

impl<P: Pause> PauseBoxed for P {
    fn pause_boxed(&mut self) -> Pin<Box<dyn Future<Output = ()> + '_>> {
        Box::pin(self.pause())
    }
}

/// How a layout marks missing depth besides 0.
#[derive(Clone, Copy, PartialEq, Eq)]
pub(super) enum InvalidDepth {
    /// Only 0 means "no reading".
    ZeroOnly,
    /// 65535 also means "no reading" (7-Scenes); it is stored as 0.
    ZeroAndMax,
}

/// Every importer stores depth in millimetres.
pub(super) const DEPTH_SCALE: f64 = 0.001;

/// An imported scene of `frames` (of `size`) with no classes, labels or features yet.
pub(super) fn scene_of(frames: Vec<Frame>, size: (u32, u32), intrinsics: Intrinsics, bounds: Bounds) -> Scene {
    Scene {
        width: size.0,
        height: size.1,
        intrinsics,
        depth_scale: DEPTH_SCALE,
        bounds,
        frames,
        classes: vec![],
        features: None,
        labels: None,
        provenance: Default::default(),
    }
}

pub(super) struct Loaded {
    pub frames: Vec<Frame>,
    /// Size of the capture's colour images.
    pub native: (u32, u32),
    /// Size of the imported frames.
    pub size: (u32, u32),
    pub notes: Vec<String>,
    /// Lines for the user (`Imported::report`): what transparent pixels were composited on.
    pub report: Vec<String>,
}

/// The indices of frames to keep out of the capture's frames, named `names` in capture order:
/// those `only` names (all when it is `None`), then every `every`-th, then at most `max_frames`.
/// Returns notes describing what was dropped. A name in `only` that the capture lacks is an
/// error naming it.
pub(super) fn select(names: &[String], opts: &ImportOptions) -> Result<(Vec<usize>, Vec<String>)> {
    if opts.every == 0 {
        return Err(SceneError::invalid("options", "--every must be at least 1"));
    }
    if opts.max_frames == Some(0) {
        return Err(SceneError::invalid("options", "--max-frames must be at least 1"));
    }
    if opts.max_size == Some(0) {
        return Err(SceneError::invalid("options", "--max-size must be at least 1"));
    }
    let count = names.len();
    let candidates: Vec<usize> = match &opts.only {
        Some(only) => {
            let index: BTreeMap<&str, usize> = names.iter().enumerate().map(|(i, n)| (n.as_str(), i)).collect();
            if let Some(absent) = only.iter().find(|n| !index.contains_key(n.as_str())) {
                return Err(SceneError::invalid(
                    "capture",
                    format!("has no frame named {absent:?} ({})", listed(names)),
                ));
            }
            let mut kept: Vec<usize> = only.iter().map(|n| index[n.as_str()]).collect();
            kept.sort_unstable();
            kept
        }
        None => (0..count).collect(),
    };
    let selected = candidates.len();
    let mut keep: Vec<usize> = candidates.into_iter().step_by(opts.every as usize).collect();
    let mut notes = Vec::new();
    if opts.every > 1 {
        notes.push(format!(
            "kept one frame in {} ({} of {}, --every)",
            opts.every,
            keep.len(),
            selected
        ));
    }
    if let Some(m) = opts.max_frames
        && keep.len() > m as usize
    {
        notes.push(format!(
            "kept the first {m} of {} selected frames (--max-frames)",
            keep.len()
        ));
        keep.truncate(m as usize);
    }
    if keep.len() > limits::MAX_FRAMES as usize {
        return Err(SceneError::invalid(
            "options",
            format!(
                "{} frames exceed the archive limit of {}; use --every or --max-frames",
                keep.len(),
                limits::MAX_FRAMES
            ),
        ));
    }
    Ok((keep, notes))
}

/// "its N frames are named a, b, ... z", for a message about a frame that is not there.
fn listed(names: &[String]) -> String {
    match names {
        [] => "it has no frames".into(),
        [one] => format!("its one frame is named {one:?}"),
        [a, b] => format!("its 2 frames are named {a:?} and {b:?}"),
        [first, .., last] => format!("its {} frames are named {first:?} ... {last:?}", names.len()),
    }
}

/// Decodes the frames, downscaling to at most `max_size` on the longest side. Depth and ground
/// truth of a different size than the colour image are resampled onto it (nearest) when the
/// aspect ratios agree, since some RGB-D sensors record depth at a lower resolution of the same
/// field of view; a different aspect ratio means the images do not cover the same view: error.
pub(super) async fn load_frames(
    files: Vec<FrameFiles>,
    opts: &ImportOptions,
    invalid: InvalidDepth,
    progress: &mut Progress<'_>,
) -> Result<Loaded> {
    load_frames_prepared(files, opts, invalid, &AsStored, progress).await
}

/// A frame's image being read (see [`Prepare::read_rgb`]).
pub(super) type Reading<'a, T> = Pin<Box<dyn Future<Output = Result<T>> + 'a>>;

/// How an importer reads a frame's images and what it does to them at their native size, before
/// they are downscaled: the COLMAP importer undistorts them there, since resampling twice would
/// blur twice; a video capture takes its colour from the video and drops depth readings of low
/// confidence. The reading methods read the files by default.
pub(super) trait Prepare {
    /// The colour image of the `frame`-th file.
    fn rgb(&self, frame: usize, rgb: RgbImage) -> Result<RgbImage>;
    /// The ground truth of the `frame`-th file, read from `path`, at `native` size or another
    /// size of the same aspect ratio (it is resampled to the frame size afterwards).
    fn gt(&self, frame: usize, path: &Path, native: (u32, u32)) -> Result<GrayImage>;
    /// The size of the first frame's colour image (`path`), without decoding it.
    fn colour_size(&self, path: &Path) -> Result<(u32, u32)> {
        dimensions(path)
    }
    /// The `frame`-th colour image as stored at `path`, and whether it had an alpha channel
    /// (composited on `background`). A future: the page decodes a video's frames with the
    /// browser, which answers later.
    fn read_rgb<'a>(&'a self, _frame: usize, path: &'a Path, background: Background) -> Reading<'a, (RgbImage, bool)> {
        Box::pin(async move { load_rgb(path, background) })
    }
    /// The `frame`-th depth image as stored at `path` (millimetres, 0 = no reading).
    fn read_depth(&self, _frame: usize, path: &Path) -> Result<DepthImage> {
        load_depth(path)
    }
}

/// Images as the capture stores them.
struct AsStored;

impl Prepare for AsStored {
    fn rgb(&self, _frame: usize, rgb: RgbImage) -> Result<RgbImage> {
        Ok(rgb)
    }

    fn gt(&self, _frame: usize, path: &Path, native: (u32, u32)) -> Result<GrayImage> {
        let g = load_gt(path)?;
        if g.dimensions() != native {
            check_resamplable(g.dimensions(), native, &path.display().to_string(), "ground truth")?;
        }
        Ok(g)
    }
}

/// `load_frames` with `prepare` applied to each frame's colour and ground truth.
pub(super) async fn load_frames_prepared(
    files: Vec<FrameFiles>,
    opts: &ImportOptions,
    invalid: InvalidDepth,
    prepare: &dyn Prepare,
    progress: &mut Progress<'_>,
) -> Result<Loaded> {
    let total = files.len();
    progress.show(0, total);
    if let Some(first) = files.first() {
        // From the first image's header, before any frame is decoded: every frame must have its
        // size, and the frames the scene would hold must fit the archive's budget.
        let name = first.rgb.display().to_string();
        let size = target_size(prepare.colour_size(&first.rgb)?, opts.max_size);
        check_pixel_budget(size, total, &name)?;
        check_decoded_budget(size, &files, &name)?;
    }
    let mut frames = Vec::with_capacity(total);
    let mut sizes: Option<((u32, u32), (u32, u32))> = None;
    let mut notes = Vec::new();
    let mut resampled_depth = false;
    let mut with_alpha = 0;
    let max_size = opts.max_size;
    for (i, f) in files.into_iter().enumerate() {
        let (rgb, alpha) = prepare.read_rgb(i, &f.rgb, opts.background).await?;
        with_alpha += usize::from(alpha);
        let (native, size) = match sizes {
            Some(s) => s,
            None => {
                let native = rgb.dimensions();
                let size = target_size(native, max_size);
                check_pixel_budget(size, total, &f.rgb.display().to_string())?;
                if size != native {
                    notes.push(format!(
                        "resized from {}x{} to {}x{} (longest side {}); intrinsics scaled to match",
                        native.0,
                        native.1,
                        size.0,
                        size.1,
                        size.0.max(size.1)
                    ));
                }
                sizes = Some((native, size));
                (native, size)
            }
        };
        if rgb.dimensions() != native {
            return Err(SceneError::invalid(
                f.rgb.display().to_string(),
                format!(
                    "image is {}x{}, but the capture's first image is {}x{} (all colour images must have the same size)",
                    rgb.width(),
                    rgb.height(),
                    native.0,
                    native.1
                ),
            ));
        }
        let rgb = resize_rgb(&prepare.rgb(i, rgb)?, size);
        let depth = match &f.depth {
            Some(path) => {
                let mut d = prepare.read_depth(i, path)?;
                if d.dimensions() != native {
                    check_resamplable(d.dimensions(), native, &path.display().to_string(), "depth")?;
                    resampled_depth = true;
                }
                if invalid == InvalidDepth::ZeroAndMax {
                    d.pixels_mut().filter(|p| p.0[0] == u16::MAX).for_each(|p| p.0[0] = 0);
                }
                Some(resize_nearest(&d, size))
            }
            None => None,
        };
        let gt = match &f.gt {
            Some(path) => Some(resize_nearest(&prepare.gt(i, path, native)?, size)),
            None => None,
        };
        frames.push(Frame {
            pose: f.pose,
            rgb,
            depth,
            gt,
            source: Some(f.name),
        });
        progress.frame_done(i + 1, total).await;
    }
    let (native, size) = sizes.ok_or_else(|| SceneError::invalid("capture", "no frames to import"))?;
    if resampled_depth {
        notes.push("depth recorded at a different resolution was resampled (nearest) onto the colour images".into());
    }
    let report = background_report(with_alpha, total, opts.background);
    Ok(Loaded {
        frames,
        native,
        size,
        notes,
        report,
    })
}

/// Says what transparent pixels became, when any image had them: the default (white) is a choice
/// a user of black-background renders must know to change.
fn background_report(with_alpha: usize, total: usize, background: Background) -> Vec<String> {
    if with_alpha == 0 {
        return Vec::new();
    }
    let other = Background::ALL
        .into_iter()
        .find(|b| *b != background)
        .unwrap_or(background);
    vec![format!(
        "{with_alpha} of {total} images have an alpha channel: composited on {}{} (--background {} for {})",
        background.name(),
        if background == Background::default() {
            ", the default"
        } else {
            ""
        },
        other.name(),
        other.name()
    )]
}

pub(super) fn check_resamplable(got: (u32, u32), native: (u32, u32), file: &str, what: &str) -> Result<()> {
    if same_aspect(got, native) {
        return Ok(());
    }
    Err(SceneError::invalid(
        file,
        format!(
            "{what} is {}x{}, which does not match the colour image's {}x{} (nor its aspect ratio)",
            got.0, got.1, native.0, native.1
        ),
    ))
}

/// Fails early, before decoding thousands of frames, when the result could not be archived.
fn check_pixel_budget(size: (u32, u32), frames: usize, first: &str) -> Result<()> {
    let total = size.0 as u64 * size.1 as u64 * frames as u64;
    if total > limits::MAX_TOTAL_PIXELS {
        return Err(SceneError::invalid(
            first,
            format!(
                "{frames} frames of {}x{} are {total} pixels, over the archive limit of {}; use --max-size, --every or --max-frames",
                size.0,
                size.1,
                limits::MAX_TOTAL_PIXELS
            ),
        ));
    }
    Ok(())
}

/// The bytes `files` decode to at `size` (colour 3 a pixel, depth 2, ground truth 1) within the
/// archive's decoded budget, which writing the scene would check only after decoding them all.
fn check_decoded_budget(size: (u32, u32), files: &[FrameFiles], first: &str) -> Result<()> {
    let pixels = size.0 as u64 * size.1 as u64;
    let bytes = files
        .iter()
        .map(|f| pixels * (3 + 2 * f.depth.is_some() as u64 + f.gt.is_some() as u64))
        .fold(0u64, u64::saturating_add);
    if bytes > limits::MAX_DECODED_BYTES {
        return Err(SceneError::invalid(
            first,
            format!(
                "{} frames of {}x{} decode to {bytes} bytes, more than the budget of {} bytes for one scene \
                 (checked from the image header, before decoding); use --max-size, --every or --max-frames",
                files.len(),
                size.0,
                size.1,
                limits::MAX_DECODED_BYTES
            ),
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_sort_numerically() {
        let names: Vec<String> = ["10", "9", "011", "2"].iter().map(|s| s.to_string()).collect();
        assert_eq!(frame_order(&names), vec!["2", "9", "10", "011"]);
        let mixed: Vec<String> = ["2", "10", "1a"].iter().map(|s| s.to_string()).collect();
        assert_eq!(frame_order(&mixed), vec!["10", "1a", "2"]);
    }

    #[test]
    fn selection_applies_every_then_max() {
        let opts = ImportOptions {
            every: 3,
            max_frames: Some(2),
            ..Default::default()
        };
        let names = |n: usize| (0..n).map(|i| format!("f{i}")).collect::<Vec<_>>();
        let (keep, notes) = select(&names(10), &opts).unwrap();
        assert_eq!(keep, vec![0, 3]);
        assert_eq!(notes.len(), 2);
        assert_eq!(
            select(&names(5), &ImportOptions::default()).unwrap().0,
            vec![0, 1, 2, 3, 4]
        );
        let zero = ImportOptions {
            every: 0,
            ..Default::default()
        };
        assert!(select(&names(5), &zero).unwrap_err().to_string().contains("--every"));
    }

    #[test]
    fn selection_by_name_keeps_capture_order_and_names_an_absent_frame() {
        let names: Vec<String> = ["a", "b", "c", "d"].iter().map(|s| s.to_string()).collect();
        let only = |list: &[&str]| ImportOptions {
            only: Some(list.iter().map(|s| s.to_string()).collect()),
            ..Default::default()
        };
        assert_eq!(select(&names, &only(&["d", "b"])).unwrap().0, vec![1, 3]);
        let err = select(&names, &only(&["b", "x"])).unwrap_err().to_string();
        assert!(
            err.contains("no frame named \"x\"") && err.contains("4 frames are named \"a\" ... \"d\""),
            "{err}"
        );
    }
}
