//! COLMAP captures: `images/` and a sparse model in `sparse/0/` (or `sparse/`) as text or binary
//! (`cameras`, `images`, `points3D`), optionally `masks/` of binary foreground per photo. Photos
//! are undistorted onto one pinhole camera, poses converted from world-to-camera, the 3D points
//! each photo observes become its sparse depth, and the points give the bounds.
use std::cell::Cell;
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use glam::{DMat4, DVec3};
use image::{GrayImage, RgbImage};

use self::model::{Image, Lens, Model, Point3D};
use self::undistort::{undistort_nearest, undistort_pixel, undistort_rgb};
use super::bounds::{from_cameras, from_points};
use super::classes::class_infos;
use super::files::CapturePath;
use super::frames::{
    FrameFiles, InvalidDepth, Prepare, Progress, check_resamplable, load_frames_prepared, scene_of, select,
};
use super::images::decode;
use super::resize::resize_nearest;
use super::{Built, ImportOptions, Layout, shown};
use crate::scene::camera::{Bounds, Intrinsics, Pose};
use crate::scene::error::{Result, SceneError};
use crate::scene::{DepthImage, GT_VOID, Scene};

mod binary;
mod model;
mod text;
mod undistort;

/// The model's three files, without extension.
const FILES: [&str; 3] = ["cameras", "images", "points3D"];
const IMAGES_DIR: &str = "images";
const MASKS_DIR: &str = "masks";
/// Model folders tried in order: COLMAP's mapper writes sparse/0, sparse/1, ... (one per model).
const MODEL_DIRS: [&str; 2] = ["sparse/0", "sparse"];
const IMAGE_EXTS: &[&str] = &["jpg", "jpeg", "png"];
/// Largest model file read, checked as it is read: COLMAP models of the captures packed here
/// are tens of MB; with `model::MAX_POINTS` it keeps a model's memory near 1 GB.
const MAX_MODEL_BYTES: u64 = 256 << 20;
/// Folder depth searched for photos that the model does not register.
const MAX_IMAGE_DEPTH: usize = 4;
/// Points trusted for bounds and depth: seen by at least two photos, reprojection error at most
/// this many pixels (COLMAP's own mapper filters at 4 px).
const MIN_TRACK: usize = 2;
const MAX_POINT_ERROR: f64 = 4.0;
/// Fewer trusted points than this and all points are used for the bounds.
const MIN_BOUNDS_POINTS: usize = 8;
/// Points cut at each end of each axis for the bounds, and the padding added around the rest:
/// the cut drops stray points, the padding gives back the object's extremes they cut off.
const BOUNDS_CUT: f64 = 0.02;
const BOUNDS_PAD: f64 = 0.1;
/// Largest depth value stored (of 65535), leaving headroom for rounding.
const MAX_DEPTH_UNITS: f64 = 60_000.0;
/// Mask values at or above this are foreground.
const MASK_THRESHOLD: u8 = 128;

/// The folder holding the model, if `input` has one.
fn model_dir(input: &Path) -> Option<PathBuf> {
    MODEL_DIRS
        .iter()
        .map(|d| input.join(d))
        .find(|d| FILES.iter().all(|f| has_model_file(d, f)))
        .or_else(|| {
            // A folder with only part of a model is still meant as one: say what is missing later.
            MODEL_DIRS
                .iter()
                .map(|d| input.join(d))
                .find(|d| has_model_file(d, FILES[0]))
        })
}

fn has_model_file(dir: &Path, stem: &str) -> bool {
    ["txt", "bin"]
        .iter()
        .any(|ext| dir.join(format!("{stem}.{ext}")).is_capture_file())
}

/// Whether `input` is a COLMAP capture: photos in images/ and a model beside them.
pub(super) fn looks_like(input: &Path) -> bool {
    input.join(IMAGES_DIR).is_capture_dir() && model_dir(input).is_some()
}

/// A model file's bytes; a missing one is named as part of the model.
fn read_model_file(path: &Path) -> Result<Vec<u8>> {
    let meta = super::files::metadata(path).map_err(|e| match e.kind() {
        std::io::ErrorKind::NotFound => SceneError::missing(shown(path), "part of the COLMAP model"),
        _ => SceneError::io(path, e),
    })?;
    if meta.len() > MAX_MODEL_BYTES {
        return Err(SceneError::invalid(
            shown(path),
            format!("{} bytes is too large for a COLMAP model file", meta.len()),
        ));
    }
    super::files::read(path, MAX_MODEL_BYTES).map_err(|e| SceneError::io(path, e))
}

/// Reads the model in `dir`: binary when cameras.bin is there (as COLMAP itself prefers), text
/// otherwise.
fn read_model(dir: &Path, notes: &mut Vec<String>) -> Result<Model> {
    let binary = dir.join("cameras.bin").is_capture_file();
    if binary && dir.join("cameras.txt").is_capture_file() {
        notes.push(format!(
            "{}: both .bin and .txt model files; read the .bin ones",
            shown(dir)
        ));
    }
    let model = if binary { binary::read(dir)? } else { text::read(dir)? };
    model.check()?;
    Ok(model)
}

pub(super) async fn import(input: &Path, opts: &ImportOptions, progress: &mut Progress<'_>) -> Result<Built> {
    let dir = model_dir(input).ok_or_else(|| {
        SceneError::missing(
            shown(&input.join(MODEL_DIRS[0])),
            "the COLMAP sparse model (cameras, images, points3D)",
        )
    })?;
    let mut notes = vec![format!("model: {}", shown(&dir))];
    let mut warnings = Vec::new();
    if dir.ends_with(MODEL_DIRS[0]) && input.join("sparse/1").is_capture_dir() {
        warnings.push("sparse/ holds several models; imported sparse/0 only".into());
    }
    let model = read_model(&dir, &mut notes)?;
    let images_dir = input.join(IMAGES_DIR);

    // Registered photos in name order; photos the model does not register are not posed.
    let mut registered: Vec<&Image> = model.images.iter().collect();
    registered.sort_by(|a, b| a.name.cmp(&b.name));
    let names: BTreeSet<&str> = registered.iter().map(|i| i.name.as_str()).collect();
    let unregistered = photos_under(&images_dir)?
        .iter()
        .filter(|p| !names.contains(p.as_str()))
        .count();
    if unregistered > 0 {
        warnings.push(format!(
            "{}: skipped {unregistered} photos that the model does not register (no pose)",
            shown(&images_dir)
        ));
    }
    // Image names come from the model's file; each must name a file inside images/ (the mask
    // folder is then searched with the same, confined, names).
    let mut image_paths = BTreeMap::new();
    for image in &registered {
        let field = format!("image {} name", image.id);
        let path = super::capture_path(&images_dir, &image.name, &field, &model.files[1], opts)?;
        image_paths.insert(image.name.as_str(), path);
    }
    let (present, missing): (Vec<&Image>, Vec<&Image>) = registered
        .into_iter()
        .partition(|i| image_paths[i.name.as_str()].is_capture_file());
    if let Some(first) = missing.first() {
        warnings.push(format!(
            "{}: {} registered photos are missing (first: {}, image {}); skipped",
            shown(&images_dir),
            missing.len(),
            first.name,
            first.id
        ));
    }
    if present.is_empty() {
        return Err(SceneError::invalid(
            shown(&images_dir),
            format!("none of the {} photos the model registers is here", model.images.len()),
        ));
    }

    let present_names: Vec<String> = present.iter().map(|i| i.name.clone()).collect();
    let (keep, selection) = select(&present_names, opts)?;
    notes.extend(selection);
    let kept: Vec<&Image> = keep.iter().map(|&i| present[i]).collect();
    let masks = find_masks(input, opts, &kept, &mut warnings)?;
    let (out, size, lenses) = output_camera(&model, &kept)?;

    let mut files = Vec::with_capacity(kept.len());
    for (i, image) in kept.iter().enumerate() {
        files.push(FrameFiles {
            name: image.name.clone(),
            rgb: image_paths[image.name.as_str()].clone(),
            depth: None,
            gt: masks.as_ref().map(|m| m[i].clone()),
            pose: camera_to_world(image, &model.files[1])?,
        });
    }
    let prepare = Undistort {
        lenses: lenses.clone(),
        out,
        size,
        names: kept.iter().map(|i| i.name.clone()).collect(),
        outside: Cell::new(0),
    };
    let loaded = load_frames_prepared(files, opts, InvalidDepth::ZeroOnly, &prepare, progress).await?;
    notes.extend(loaded.notes);
    let report = loaded.report;
    notes.push(undistortion_note(&model, &kept, &prepare));

    // The scene measures pixels from the top-left pixel's centre, COLMAP from its corner.
    let native = Intrinsics {
        fx: out.fx,
        fy: out.fy,
        cx: out.cx - 0.5,
        cy: out.cy - 0.5,
    };
    let intrinsics = native.scaled(loaded.native, loaded.size);
    let (bounds, bounds_note) = match points_bounds(&model) {
        Some(b) => b,
        None => {
            warnings.push(format!(
                "{}: no 3D points; bounds estimated from the cameras",
                model.files[2]
            ));
            let poses: Vec<Pose> = loaded.frames.iter().map(|f| f.pose).collect();
            let b = from_cameras(&poses, &intrinsics, loaded.size)
                .ok_or_else(|| SceneError::invalid(shown(input), "no cameras to estimate the bounds from"))?;
            (
                b,
                "bounds: from camera positions and view frustums (no 3D points)".into(),
            )
        }
    };
    notes.push(bounds_note);

    let mut scene = scene_of(loaded.frames, loaded.size, intrinsics, bounds);
    let readings: Vec<Vec<(u32, f64)>> = kept
        .iter()
        .zip(&lenses)
        .map(|(image, lens)| sparse_depth(image, lens, &model, &intrinsics, loaded.size))
        .collect();
    notes.extend(store_depth(&mut scene, readings));
    if masks.is_some() {
        scene.classes = class_infos(opts.mask_classes.iter().cloned());
        notes.push(format!(
            "ground truth from binary masks: < {MASK_THRESHOLD} = {}, >= {MASK_THRESHOLD} = {}; void where undistortion leaves the photo",
            opts.mask_classes[0], opts.mask_classes[1]
        ));
    }
    Ok(Built {
        scene,
        layout: Layout::Colmap,
        warnings,
        notes,
        report,
    })
}

/// Everything [`import`] decides from a text model alone, without photos: the three files
/// parse and agree, image names stay inside images/, every pose is rigid, the bounds and one
/// shared output camera follow, and each photo's sparse depth can be computed. The fuzz target
/// and its corpus replay (`scribblefield::fuzzing`) run this. Returns the number of images.
pub(super) fn check_text_model(texts: [&str; 3]) -> Result<usize> {
    check_model(text::parse(texts, FILES.map(|f| format!("{f}.txt")))?)
}

/// [`check_text_model`] for a binary model (`cameras.bin`, `images.bin`, `points3D.bin`).
pub(super) fn check_binary_model(bytes: [&[u8]; 3]) -> Result<usize> {
    check_model(binary::parse(bytes, FILES.map(|f| format!("{f}.bin")))?)
}

fn check_model(model: Model) -> Result<usize> {
    model.check()?;
    let mut images: Vec<&Image> = model.images.iter().collect();
    images.sort_by(|a, b| a.name.cmp(&b.name));
    let opts = ImportOptions::default();
    for image in &images {
        let field = format!("image {} name", image.id);
        super::capture_path(Path::new(IMAGES_DIR), &image.name, &field, &model.files[1], &opts)?;
        camera_to_world(image, &model.files[1])?;
    }
    let _ = points_bounds(&model);
    if images.is_empty() {
        return Ok(0);
    }
    let (out, size, lenses) = output_camera(&model, &images)?;
    let k = Intrinsics {
        fx: out.fx,
        fy: out.fy,
        cx: out.cx - 0.5,
        cy: out.cy - 0.5,
    };
    for (image, lens) in images.iter().zip(&lenses) {
        sparse_depth(image, lens, &model, &k, size);
    }
    Ok(images.len())
}

/// Image files below `dir` (a few levels deep), as paths relative to it with `/` separators, the
/// way COLMAP names them.
fn photos_under(dir: &Path) -> Result<Vec<String>> {
    let mut out = Vec::new();
    let mut stack = vec![(dir.to_path_buf(), String::new(), 0)];
    while let Some((folder, prefix, depth)) = stack.pop() {
        let entries = super::files::read_dir(&folder).map_err(|e| SceneError::io(&folder, e))?;
        for path in entries {
            let Some(name) = path.file_name().and_then(|n| n.to_str()) else {
                continue;
            };
            let rel = format!("{prefix}{name}");
            // A link to a folder is not walked: `images/a -> .` would list every photo again
            // under each name, and a few such links multiply the walk past any bound.
            let folder = super::files::metadata(&path).is_ok_and(|m| m.is_dir && !m.is_link);
            if folder && depth < MAX_IMAGE_DEPTH {
                stack.push((path.clone(), format!("{rel}/"), depth + 1));
            } else if is_photo(name) {
                out.push(rel);
            }
        }
    }
    Ok(out)
}

fn is_photo(name: &str) -> bool {
    name.rsplit_once('.')
        .is_some_and(|(_, ext)| IMAGE_EXTS.contains(&ext.to_ascii_lowercase().as_str()))
}

/// Each kept photo's mask: `<stem>.png` or COLMAP's own `<name>.png`, in --masks or masks/.
/// None when there is no mask folder, or when it has no mask for any kept photo; some but not
/// all missing is an error, since the ground truth would silently cover only part of the scene.
fn find_masks(
    input: &Path,
    opts: &ImportOptions,
    kept: &[&Image],
    warnings: &mut Vec<String>,
) -> Result<Option<Vec<PathBuf>>> {
    let dir = match &opts.masks {
        Some(d) if d.is_capture_dir() => d.clone(),
        Some(d) => return Err(SceneError::missing(shown(d), "the mask folder given with --masks")),
        None if input.join(MASKS_DIR).is_capture_dir() => input.join(MASKS_DIR),
        None => return Ok(None),
    };
    let found: Vec<Option<PathBuf>> = kept
        .iter()
        .map(|image| {
            let stem = Path::new(&image.name).with_extension("png");
            [dir.join(stem), dir.join(format!("{}.png", image.name))]
                .into_iter()
                .find(|p| p.is_capture_file())
        })
        .collect();
    let missing: Vec<&Image> = kept
        .iter()
        .zip(&found)
        .filter(|(_, f)| f.is_none())
        .map(|(i, _)| *i)
        .collect();
    if missing.len() == kept.len() {
        warnings.push(format!(
            "{}: no mask for any imported photo (expected e.g. {}); no ground truth",
            shown(&dir),
            shown(&dir.join(Path::new(&kept[0].name).with_extension("png")))
        ));
        return Ok(None);
    }
    if let Some(first) = missing.first() {
        return Err(SceneError::missing(
            shown(&dir.join(Path::new(&first.name).with_extension("png"))),
            format!(
                "the mask of photo {} (image {}); {} of {} imported photos have no mask",
                first.name,
                first.id,
                missing.len(),
                kept.len()
            ),
        ));
    }
    Ok(Some(found.into_iter().flatten().collect()))
}

/// The pinhole camera all frames are resampled onto (the first kept photo's camera without its
/// distortion), its image size, and each kept photo's own lens. Photos of other cameras must have
/// its size.
fn output_camera(model: &Model, kept: &[&Image]) -> Result<(Lens, (u32, u32), Vec<Lens>)> {
    let camera = |image: &Image| &model.cameras[&image.camera_id];
    let first = camera(kept[0]);
    for image in kept {
        let c = camera(image);
        if (c.width, c.height) != (first.width, first.height) {
            return Err(SceneError::invalid(
                &model.files[0],
                format!(
                    "camera {} ({}x{}, image {} {}) and camera {} ({}x{}, image {} {}) differ in size; \
                     a scene holds one image size",
                    kept[0].camera_id,
                    first.width,
                    first.height,
                    kept[0].id,
                    kept[0].name,
                    image.camera_id,
                    c.width,
                    c.height,
                    image.id,
                    image.name
                ),
            ));
        }
    }
    let out = Lens {
        k1: 0.0,
        k2: 0.0,
        p1: 0.0,
        p2: 0.0,
        ..first.lens
    };
    let lenses = kept.iter().map(|i| camera(i).lens).collect();
    Ok((out, (first.width, first.height), lenses))
}

fn undistortion_note(model: &Model, kept: &[&Image], prepare: &Undistort) -> String {
    let used: BTreeMap<u32, &str> = kept
        .iter()
        .map(|i| (i.camera_id, model.cameras[&i.camera_id].model.as_str()))
        .collect();
    let list = used
        .iter()
        .map(|(id, m)| format!("{id} {m}"))
        .collect::<Vec<_>>()
        .join(", ");
    format!(
        "cameras ({list}) resampled onto one pinhole camera where they differ from it (bilinear); {} pixels over all frames fell outside their photo (black, void)",
        prepare.outside.get()
    )
}

/// COLMAP stores x_cam = R x_world + t in OpenCV axes; the scene stores the inverse.
fn camera_to_world(image: &Image, file: &str) -> Result<Pose> {
    let r = image.rotation.transpose();
    let c = -(r * image.translation);
    let pose = Pose(DMat4::from_cols(
        r.x_axis.extend(0.0),
        r.y_axis.extend(0.0),
        r.z_axis.extend(0.0),
        c.extend(1.0),
    ));
    pose.check()
        .map_err(|p| SceneError::invalid(file, format!("{}: image {} ({}): {p}", image.at, image.id, image.name)))?;
    Ok(pose)
}

/// Undistorts each frame's photo and mask at full size, before any downscaling.
struct Undistort {
    lenses: Vec<Lens>,
    out: Lens,
    size: (u32, u32),
    names: Vec<String>,
    outside: Cell<usize>,
}

impl Prepare for Undistort {
    fn rgb(&self, frame: usize, rgb: RgbImage) -> Result<RgbImage> {
        if rgb.dimensions() != self.size {
            return Err(SceneError::invalid(
                format!("{IMAGES_DIR}/{}", self.names[frame]),
                format!(
                    "photo is {}x{}, but its camera in the model is {}x{}",
                    rgb.width(),
                    rgb.height(),
                    self.size.0,
                    self.size.1
                ),
            ));
        }
        let (img, outside) = undistort_rgb(&rgb, &self.lenses[frame], &self.out);
        self.outside.set(self.outside.get() + outside);
        Ok(img)
    }

    fn gt(&self, frame: usize, path: &Path, native: (u32, u32)) -> Result<GrayImage> {
        // Any colour type: 16-bit and colour masks are converted to 8-bit grey first.
        let mask = decode(path)?.into_luma8();
        if mask.dimensions() != native {
            check_resamplable(mask.dimensions(), native, &shown(path), "mask")?;
        }
        let mut classes = resize_nearest(&mask, native);
        classes
            .pixels_mut()
            .for_each(|p| p.0[0] = u8::from(p.0[0] >= MASK_THRESHOLD));
        Ok(undistort_nearest(&classes, &self.lenses[frame], &self.out, GT_VOID))
    }
}

fn trusted(p: &Point3D) -> bool {
    p.track.len() >= MIN_TRACK && p.error <= MAX_POINT_ERROR
}

/// Bounds from the 3D points (trusted ones, or all when too few are), with a note saying how.
fn points_bounds(model: &Model) -> Option<(Bounds, String)> {
    let good: Vec<DVec3> = model.points.values().filter(|p| trusted(p)).map(|p| p.xyz).collect();
    let (points, which) = if good.len() >= MIN_BOUNDS_POINTS {
        (
            good,
            format!("seen by >= {MIN_TRACK} photos with error <= {MAX_POINT_ERROR} px"),
        )
    } else {
        (
            model.points.values().map(|p| p.xyz).collect(),
            "all of them: too few trusted".into(),
        )
    };
    let n = points.len();
    let b = from_points(points, BOUNDS_CUT, BOUNDS_PAD)?;
    let note = format!(
        "bounds: {:.0}-{:.0} percentile per axis of {n} 3D points ({which}), padded by {:.0} %",
        BOUNDS_CUT * 100.0,
        (1.0 - BOUNDS_CUT) * 100.0,
        BOUNDS_PAD * 100.0
    );
    Some((b, note))
}

/// The depth (z in the camera, in model units) of each trusted 3D point `image` observes, at the
/// pixel of the `size` frame nearest to its undistorted keypoint; the nearest point where two land
/// on one pixel (the farther one is hidden behind it). Sorted by pixel index.
fn sparse_depth(image: &Image, lens: &Lens, model: &Model, k: &Intrinsics, size: (u32, u32)) -> Vec<(u32, f64)> {
    let mut readings: Vec<(u32, f64)> = Vec::new();
    for (keypoint, id) in &image.points2d {
        let Some(point) = id.and_then(|id| model.points.get(&id)) else {
            continue;
        };
        if !trusted(point) {
            continue;
        }
        let z = (image.rotation * point.xyz + image.translation).z;
        let Some(n) = undistort_pixel(lens, *keypoint) else {
            continue;
        };
        let (u, v) = ((k.fx * n.x + k.cx).round(), (k.fy * n.y + k.cy).round());
        if z > 0.0 && u >= 0.0 && v >= 0.0 && u < size.0 as f64 && v < size.1 as f64 {
            readings.push((v as u32 * size.0 + u as u32, z));
        }
    }
    readings.sort_by(|a, b| a.0.cmp(&b.0).then(a.1.total_cmp(&b.1)));
    readings.dedup_by_key(|r| r.0);
    readings
}

/// Writes the readings as depth images, in units chosen so the farthest reading fits a u16 (a
/// power of ten, so the stored values read plainly); returns a note on what was stored.
fn store_depth(scene: &mut Scene, readings: Vec<Vec<(u32, f64)>>) -> Option<String> {
    let far = readings.iter().flatten().map(|r| r.1).fold(0.0, f64::max);
    if far <= 0.0 {
        return None;
    }
    let scale = 10f64.powf((far / MAX_DEPTH_UNITS).log10().ceil());
    scene.depth_scale = scale;
    let total: usize = readings.iter().map(Vec::len).sum();
    for (frame, frame_readings) in scene.frames.iter_mut().zip(readings) {
        let mut depth = DepthImage::new(scene.width, scene.height);
        let width = scene.width;
        for (pixel, z) in frame_readings {
            // A reading never rounds to 0, which would mean "none".
            let units = (z / scale).round().clamp(1.0, u16::MAX as f64) as u16;
            depth.put_pixel(pixel % width, pixel / width, image::Luma([units]));
        }
        frame.depth = Some(depth);
    }
    Some(format!(
        "sparse depth: {total} readings from 3D points ({:.0} per frame), depth_scale {scale:e} model units",
        total as f64 / scene.frames.len() as f64
    ))
}
