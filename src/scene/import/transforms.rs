//! NeRF / instant-ngp / nerfstudio `transforms.json`: shared pinhole intrinsics (`fl_x`, `fl_y`,
//! `cx`, `cy`, `w`, `h`, or `camera_angle_x` [+ `camera_angle_y`]), and per frame an image
//! `file_path` (relative to the json, extension optional) and a camera-to-world
//! `transform_matrix` in OpenGL camera axes. Optional nerfstudio `depth_file_path` (uint16 mm).
use std::path::{Path, PathBuf};

use serde::Deserialize;

use super::alpha::{AlphaGt, alpha_gt_report};
use super::bounds::{FROM_DEPTH_NOTE, from_cameras, from_depth};
use super::classes::class_infos;
use super::files::CapturePath;
use super::frames::{
    DEPTH_SCALE, FrameFiles, InvalidDepth, Progress, load_frames, load_frames_prepared, scene_of, select,
};
use super::images::dimensions;
use super::text::pose_from_numbers;
use super::{Built, ImportOptions, Layout, capture_path, shown};
use crate::scene::archive::limits;
use crate::scene::camera::{Intrinsics, Pose};
use crate::scene::error::{Result, SceneError};

pub(super) const FILE: &str = "transforms.json";
/// Extensions tried, in order, for a `file_path` given without one (NeRF synthetic scenes).
const IMAGE_EXTS: &[&str] = &["png", "jpg", "jpeg", "PNG", "JPG", "JPEG"];
/// Relative difference under which two per-frame intrinsics values count as the same.
const SAME_VALUE: f64 = 1e-6;
/// Missing images listed by name in the warning; the rest are counted.
const LISTED_MISSING: usize = 5;

/// Camera fields, which nerfstudio allows both at the top level and per frame.
#[derive(Deserialize, Default, Clone, Copy, Debug)]
pub(super) struct Camera {
    fl_x: Option<f64>,
    fl_y: Option<f64>,
    cx: Option<f64>,
    cy: Option<f64>,
    w: Option<f64>,
    h: Option<f64>,
    camera_angle_x: Option<f64>,
    camera_angle_y: Option<f64>,
}

#[derive(Deserialize, Default, Debug)]
struct Distortion {
    camera_model: Option<String>,
    k1: Option<f64>,
    k2: Option<f64>,
    k3: Option<f64>,
    k4: Option<f64>,
    p1: Option<f64>,
    p2: Option<f64>,
}

#[derive(Deserialize, Debug)]
struct TransformsFile {
    #[serde(flatten)]
    camera: Camera,
    #[serde(flatten)]
    distortion: Distortion,
    frames: Vec<FrameEntry>,
}

#[derive(Deserialize, Debug)]
struct FrameEntry {
    file_path: String,
    transform_matrix: Vec<Vec<f64>>,
    depth_file_path: Option<String>,
    #[serde(flatten)]
    camera: Camera,
}

/// One frame a transforms file lists whose image is there; its pose is read when it is kept.
pub(super) struct Entry {
    /// `file: frames[i] (file_path)`, for messages.
    at: String,
    /// The `file_path`, kept as the frame's source.
    name: String,
    rgb: PathBuf,
    depth: Option<PathBuf>,
    /// `transform_matrix`, row-major.
    matrix: Vec<f64>,
}

/// What a transforms file says, with its images found.
pub(super) struct Listing {
    /// The file, shown.
    pub file: String,
    pub camera: Camera,
    pub entries: Vec<Entry>,
    pub warnings: Vec<String>,
}

pub(super) async fn import(input: &Path, opts: &ImportOptions, progress: &mut Progress<'_>) -> Result<Built> {
    let json_path = if input.is_capture_dir() {
        input.join(FILE)
    } else {
        input.to_path_buf()
    };
    build(list(&json_path, opts)?, opts, Layout::Transforms, progress).await
}

/// Reads the transforms file at `json_path`: its camera, and its frames whose image exists
/// (frames whose image is missing are skipped with a warning, since exports often list frames
/// that were culled; none at all is an error).
pub(super) fn list(json_path: &Path, opts: &ImportOptions) -> Result<Listing> {
    let file = shown(json_path);
    let base = json_path.parent().unwrap_or(Path::new("."));
    let meta = super::files::metadata(json_path).map_err(|e| match e.kind() {
        std::io::ErrorKind::NotFound => SceneError::missing(&file, "the transforms file"),
        _ => SceneError::io(json_path, e),
    })?;
    if meta.len() > limits::MAX_JSON_BYTES {
        return Err(SceneError::invalid(
            &file,
            format!("{} bytes is too large for a transforms file", meta.len()),
        ));
    }
    let bytes = super::files::read(json_path, limits::MAX_JSON_BYTES).map_err(|e| SceneError::io(json_path, e))?;
    let (parsed, camera, mut warnings) = parse(&bytes, &file)?;

    let mut entries = Vec::new();
    let mut missing = Vec::new();
    for (i, f) in parsed.frames.into_iter().enumerate() {
        // Every frame's paths are checked, kept or not: a refused path is a problem of the file.
        let depth = match &f.depth_file_path {
            Some(d) => Some(capture_path(
                base,
                d,
                &format!("frames[{i}].depth_file_path"),
                &file,
                opts,
            )?),
            None => None,
        };
        let image = capture_path(base, &f.file_path, &format!("frames[{i}].file_path"), &file, opts)?;
        match resolve_image(image) {
            Some(rgb) => entries.push(Entry {
                at: format!("{file}: frames[{i}] ({})", f.file_path),
                matrix: f.transform_matrix.iter().flatten().copied().collect(),
                name: f.file_path,
                rgb,
                depth,
            }),
            None => missing.push(f.file_path),
        }
    }
    if !missing.is_empty() {
        let mut listed = missing
            .iter()
            .take(LISTED_MISSING)
            .cloned()
            .collect::<Vec<_>>()
            .join(", ");
        if missing.len() > LISTED_MISSING {
            listed.push_str(&format!(" and {} more", missing.len() - LISTED_MISSING));
        }
        warnings.push(format!(
            "{file}: skipped {} frames whose image is missing: {listed}",
            missing.len()
        ));
    }
    if entries.is_empty() {
        return Err(SceneError::invalid(
            &file,
            format!(
                "none of the {} frames' images exist (file_path is relative to {})",
                missing.len(),
                shown(base)
            ),
        ));
    }
    Ok(Listing {
        file,
        camera,
        entries,
        warnings,
    })
}

/// The scene of a listing (one transforms file, or several sharing one camera, whose `file`
/// names where the camera was read), with `--every`, `--max-frames`, `--alpha-gt` applied.
pub(super) async fn build(
    listing: Listing,
    opts: &ImportOptions,
    layout: Layout,
    progress: &mut Progress<'_>,
) -> Result<Built> {
    let Listing {
        file,
        camera,
        entries,
        warnings,
    } = listing;
    let (file, camera) = (file.as_str(), &camera);
    let first_image = &entries
        .first()
        .ok_or_else(|| SceneError::invalid(file, "no frame's image exists"))?
        .rgb;
    let image_size = dimensions(first_image)?;
    let native = match (camera.w, camera.h) {
        (Some(w), Some(h)) => {
            let stated = (pixels(w, "w", file)?, pixels(h, "h", file)?);
            if stated != image_size {
                return Err(SceneError::invalid(
                    shown(first_image),
                    format!(
                        "image is {}x{}, but {file} says w = {}, h = {}",
                        image_size.0, image_size.1, stated.0, stated.1
                    ),
                ));
            }
            stated
        }
        _ => image_size,
    };
    let k = intrinsics(camera, native, file)?;

    let names: Vec<String> = entries.iter().map(|e| e.name.clone()).collect();
    let (keep, mut notes) = select(&names, opts)?;
    let mut files = Vec::with_capacity(keep.len());
    for &j in &keep {
        let entry = &entries[j];
        let gl = pose_from_numbers(&entry.matrix, &format!("{}: transform_matrix", entry.at))?;
        if let Some(p) = &entry.depth
            && !p.is_capture_file()
        {
            return Err(SceneError::missing(shown(p), format!("depth of {}", entry.at)));
        }
        files.push(FrameFiles {
            name: entry.name.clone(),
            rgb: entry.rgb.clone(),
            depth: entry.depth.clone(),
            // Read from the image's own alpha by `AlphaGt`.
            gt: opts.alpha_gt.then(|| entry.rgb.clone()),
            // OpenGL camera axes (y up, z backward) to the scene's OpenCV axes.
            pose: Pose::from_opengl(gl.0),
        });
    }

    let loaded = if opts.alpha_gt {
        load_frames_prepared(files, opts, InvalidDepth::ZeroOnly, &AlphaGt, progress).await?
    } else {
        load_frames(files, opts, InvalidDepth::ZeroOnly, progress).await?
    };
    notes.extend(loaded.notes);
    let mut report = loaded.report;
    let intrinsics = k.scaled(loaded.native, loaded.size);
    let bounds = match from_depth(&loaded.frames, &intrinsics, DEPTH_SCALE) {
        Some(b) => {
            notes.push(FROM_DEPTH_NOTE.into());
            b
        }
        None => {
            let poses: Vec<Pose> = loaded.frames.iter().map(|f| f.pose).collect();
            notes.push(
                "bounds: estimated from camera positions and view frustums (no depth; the capture's scale is unknown)"
                    .into(),
            );
            from_cameras(&poses, &intrinsics, loaded.size)
                .ok_or_else(|| SceneError::invalid(file, "no cameras to estimate the scene's bounds from"))?
        }
    };

    let mut scene = scene_of(loaded.frames, loaded.size, intrinsics, bounds);
    if opts.alpha_gt {
        scene.classes = class_infos(opts.mask_classes.iter().cloned());
        report.push(alpha_gt_report(&scene, &opts.mask_classes));
    }
    Ok(Built {
        scene,
        layout,
        warnings,
        notes,
        report,
    })
}

/// The file parsed, with the camera its frames share and the warnings about it.
fn parse(bytes: &[u8], file: &str) -> Result<(TransformsFile, Camera, Vec<String>)> {
    let parsed: TransformsFile = serde_json::from_slice(bytes).map_err(|source| SceneError::Json {
        file: file.to_string(),
        source,
    })?;
    if parsed.frames.is_empty() {
        return Err(SceneError::invalid(
            file,
            "\"frames\" is empty: the scene has no frames",
        ));
    }
    let warnings = distortion_warning(&parsed.distortion, file)?.into_iter().collect();
    let camera = shared_camera(&parsed, file)?;
    Ok((parsed, camera, warnings))
}

/// Everything [`import`] decides from the file alone, without reading images: the file parses,
/// its camera is consistent, every path stays in `base` (unless allowed), every
/// `transform_matrix` is a rigid pose and, when the size is stated, the intrinsics are valid.
/// The fuzz target and its corpus replay (`scribblefield::fuzzing`) run this. Returns the
/// number of frames.
pub(super) fn check_text(bytes: &[u8], base: &Path, opts: &ImportOptions) -> Result<usize> {
    let file = FILE;
    if bytes.len() as u64 > limits::MAX_JSON_BYTES {
        return Err(SceneError::invalid(
            file,
            format!("{} bytes is too large for a transforms file", bytes.len()),
        ));
    }
    let (parsed, camera, _) = parse(bytes, file)?;
    for (i, f) in parsed.frames.iter().enumerate() {
        if let Some(d) = &f.depth_file_path {
            capture_path(base, d, &format!("frames[{i}].depth_file_path"), file, opts)?;
        }
        capture_path(base, &f.file_path, &format!("frames[{i}].file_path"), file, opts)?;
        let numbers: Vec<f64> = f.transform_matrix.iter().flatten().copied().collect();
        pose_from_numbers(&numbers, &format!("{file}: frames[{i}]: transform_matrix"))?;
    }
    if let (Some(w), Some(h)) = (camera.w, camera.h) {
        let size = (pixels(w, "w", file)?, pixels(h, "h", file)?);
        intrinsics(&camera, size, file)?;
    }
    Ok(parsed.frames.len())
}

/// The image a `file_path` names (already joined to the capture folder): as given, or with an
/// image extension appended.
fn resolve_image(direct: PathBuf) -> Option<PathBuf> {
    if direct.is_capture_file() {
        return Some(direct);
    }
    IMAGE_EXTS
        .iter()
        .map(|ext| {
            let mut p = direct.clone().into_os_string();
            p.push(".");
            p.push(ext);
            PathBuf::from(p)
        })
        .find(|p| p.is_capture_file())
}

type CameraField = fn(&mut Camera) -> &mut Option<f64>;
const CAMERA_FIELDS: [(&str, CameraField); 8] = [
    ("fl_x", |c| &mut c.fl_x),
    ("fl_y", |c| &mut c.fl_y),
    ("cx", |c| &mut c.cx),
    ("cy", |c| &mut c.cy),
    ("w", |c| &mut c.w),
    ("h", |c| &mut c.h),
    ("camera_angle_x", |c| &mut c.camera_angle_x),
    ("camera_angle_y", |c| &mut c.camera_angle_y),
];

fn same_value(a: f64, b: f64) -> bool {
    (a - b).abs() <= SAME_VALUE * a.abs().max(1.0)
}

/// The first camera field two files disagree on (one giving it and the other not counts), with
/// both values.
pub(super) fn camera_difference(a: &Camera, b: &Camera) -> Option<(&'static str, Option<f64>, Option<f64>)> {
    let (mut a, mut b) = (*a, *b);
    CAMERA_FIELDS.iter().find_map(|(name, field)| {
        let (x, y) = (*field(&mut a), *field(&mut b));
        let same = match (x, y) {
            (Some(x), Some(y)) => same_value(x, y),
            (None, None) => true,
            _ => false,
        };
        (!same).then_some((*name, x, y))
    })
}

/// The one camera all frames share: top-level values, filled in from the first frame that has
/// them. Frames may repeat a value but not change it (a single pinhole camera is assumed).
fn shared_camera(t: &TransformsFile, file: &str) -> Result<Camera> {
    let mut cam = t.camera;
    for (i, f) in t.frames.iter().enumerate() {
        let mut frame_cam = f.camera;
        for (name, field) in &CAMERA_FIELDS {
            let Some(v) = *field(&mut frame_cam) else { continue };
            let shared = field(&mut cam);
            match *shared {
                None => *shared = Some(v),
                Some(s) if same_value(s, v) => {}
                Some(s) => {
                    return Err(SceneError::invalid(
                        file,
                        format!(
                            "frames[{i}] ({}) has {name} = {v}, but another value is {s}: per-frame intrinsics are not supported (all frames must share one camera)",
                            f.file_path
                        ),
                    ));
                }
            }
        }
    }
    Ok(cam)
}

fn pixels(v: f64, name: &str, file: &str) -> Result<u32> {
    if v.is_finite() && v >= 1.0 && v.fract() == 0.0 && v <= limits::MAX_SIDE as f64 {
        Ok(v as u32)
    } else {
        Err(SceneError::invalid(
            file,
            format!("{name} = {v} is not an image size in pixels (1..={})", limits::MAX_SIDE),
        ))
    }
}

/// Pinhole intrinsics in the scene's convention. transforms.json measures the principal point
/// with pixel centres at +0.5 (instant-ngp and nerfstudio cast rays through `x + 0.5`), the scene
/// at integer coordinates, hence the half-pixel shift; a missing one is the image centre.
fn intrinsics(c: &Camera, (w, h): (u32, u32), file: &str) -> Result<Intrinsics> {
    let from_angle = |angle: f64, side: u32, name: &str| {
        if angle.is_finite() && angle > 0.0 && angle < std::f64::consts::PI {
            Ok(0.5 * side as f64 / (0.5 * angle).tan())
        } else {
            Err(SceneError::invalid(
                file,
                format!("{name} = {angle} is not a field of view in radians (0..pi)"),
            ))
        }
    };
    let fx = match (c.fl_x, c.camera_angle_x) {
        (Some(f), _) => f,
        (None, Some(a)) => from_angle(a, w, "camera_angle_x")?,
        (None, None) => {
            return Err(SceneError::invalid(
                file,
                "no focal length: expected fl_x (pixels) or camera_angle_x (radians)",
            ));
        }
    };
    let fy = match (c.fl_y, c.camera_angle_y, c.fl_x) {
        (Some(f), _, _) => f,
        (None, Some(a), _) => from_angle(a, h, "camera_angle_y")?,
        // Square pixels unless stated otherwise.
        (None, None, _) => fx,
    };
    let k = Intrinsics {
        fx,
        fy,
        cx: c.cx.unwrap_or(w as f64 / 2.0) - 0.5,
        cy: c.cy.unwrap_or(h as f64 / 2.0) - 0.5,
    };
    k.check().map_err(|p| SceneError::invalid(file, p))?;
    Ok(k)
}

/// Lens distortion cannot be represented by the scene's pinhole model: say it is ignored.
fn distortion_warning(d: &Distortion, file: &str) -> Result<Option<String>> {
    let model = d.camera_model.as_deref().unwrap_or("PINHOLE");
    if model.eq_ignore_ascii_case("EQUIRECTANGULAR") {
        return Err(SceneError::invalid(
            file,
            "camera_model EQUIRECTANGULAR is not a pinhole camera; not supported",
        ));
    }
    let coefficients = [d.k1, d.k2, d.k3, d.k4, d.p1, d.p2];
    let distorted = coefficients.iter().flatten().any(|v| *v != 0.0);
    let fisheye = model.to_ascii_uppercase().contains("FISHEYE");
    Ok((distorted || fisheye).then(|| {
        format!("{file}: camera_model {model} with lens distortion; distortion is ignored (images are used as pinhole)")
    }))
}
