//! A COLMAP sparse model as read from `cameras`, `images` and `points3D` (text or binary), and
//! the checks that tie the three files together. Values keep COLMAP's conventions here (pixel
//! coordinates with the top-left pixel's centre at (0.5, 0.5), world-to-camera poses); the
//! importer converts to the scene's at the end.
use std::collections::{BTreeMap, HashMap};

use glam::{DMat3, DQuat, DVec2, DVec3};

use crate::scene::error::{Result, SceneError};

/// Camera models, by COLMAP's numeric id (the index here) and name, with their parameter count.
pub(super) const MODELS: [(&str, usize); 12] = [
    ("SIMPLE_PINHOLE", 3),
    ("PINHOLE", 4),
    ("SIMPLE_RADIAL", 4),
    ("RADIAL", 5),
    ("OPENCV", 8),
    ("OPENCV_FISHEYE", 8),
    ("FULL_OPENCV", 12),
    ("FOV", 5),
    ("SIMPLE_RADIAL_FISHEYE", 4),
    ("RADIAL_FISHEYE", 5),
    ("THIN_PRISM_FISHEYE", 12),
    ("RAD_TAN_THIN_PRISM_FISHEYE", 16),
];

/// The models whose distortion the importer can undo (all special cases of OPENCV).
pub(super) const SUPPORTED: &str = "SIMPLE_PINHOLE, PINHOLE, SIMPLE_RADIAL, RADIAL, OPENCV";

/// How far a quaternion's norm may be from 1 before it is taken for garbage (columns in the wrong
/// order, say) rather than rounding; within it, it is normalised as COLMAP does.
const UNIT_TOLERANCE: f64 = 0.01;

/// Where in a model file a record came from, for messages.
#[derive(Clone, Copy, Debug)]
pub(super) enum At {
    Line(usize),
    Record(usize),
}

impl std::fmt::Display for At {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            At::Line(n) => write!(f, "line {n}"),
            At::Record(n) => write!(f, "record {n}"),
        }
    }
}

/// Most 3D points in a model: each costs about 260 bytes once read (its track, the map), so
/// 2 M keep a model's memory near 500 MB. Models of the captures packed here (a few hundred
/// photos) have 10^4 to 10^6.
pub(super) const MAX_POINTS: usize = 2_000_000;

/// The error for a model with more than [`MAX_POINTS`] points.
pub(super) fn too_many_points(n: usize, file: &str) -> SceneError {
    SceneError::invalid(
        file,
        format!(
            "{n} 3D points, more than the {MAX_POINTS} read from a model; filter the model first (COLMAP's \
             point_filtering, or export fewer points)"
        ),
    )
}

/// Largest |k1|, |k2|, |p1|, |p2| accepted: calibrated lenses, fisheye ones included, stay
/// below about 1; far larger terms are a broken calibration, not a lens.
pub(super) const MAX_DISTORTION: f64 = 10.0;

/// The OPENCV lens model, which covers every supported model (the others fix some of its
/// parameters): pixel = (fx x'' + cx, fy y'' + cy), with (x'', y'') the distorted normalised
/// coordinates; cx, cy in COLMAP pixels (corner origin).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Lens {
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
    pub k1: f64,
    pub k2: f64,
    pub p1: f64,
    pub p2: f64,
}

impl Lens {
    /// The lens of a supported model from its parameters, or None for an unsupported model.
    /// `params` has the model's count (the readers check it).
    pub fn of_model(model: &str, p: &[f64]) -> Option<Lens> {
        let pinhole = |fx, fy, cx, cy| Lens {
            fx,
            fy,
            cx,
            cy,
            k1: 0.0,
            k2: 0.0,
            p1: 0.0,
            p2: 0.0,
        };
        Some(match model {
            "SIMPLE_PINHOLE" => pinhole(p[0], p[0], p[1], p[2]),
            "PINHOLE" => pinhole(p[0], p[1], p[2], p[3]),
            "SIMPLE_RADIAL" => Lens {
                k1: p[3],
                ..pinhole(p[0], p[0], p[1], p[2])
            },
            "RADIAL" => Lens {
                k1: p[3],
                k2: p[4],
                ..pinhole(p[0], p[0], p[1], p[2])
            },
            "OPENCV" => Lens {
                k1: p[4],
                k2: p[5],
                p1: p[6],
                p2: p[7],
                ..pinhole(p[0], p[1], p[2], p[3])
            },
            _ => return None,
        })
    }

    pub fn is_pinhole(&self) -> bool {
        [self.k1, self.k2, self.p1, self.p2].iter().all(|&v| v == 0.0)
    }
}

#[derive(Clone, Debug)]
pub(super) struct Camera {
    pub model: String,
    pub width: u32,
    pub height: u32,
    pub lens: Lens,
}

#[derive(Clone, Debug)]
pub(super) struct Image {
    pub id: u32,
    /// World-to-camera rotation (from the normalised quaternion) and translation.
    pub rotation: DMat3,
    pub translation: DVec3,
    pub camera_id: u32,
    pub name: String,
    /// Keypoints in COLMAP pixels and the 3D point each observes, if any.
    pub points2d: Vec<(DVec2, Option<u64>)>,
    pub at: At,
}

#[derive(Clone, Debug)]
pub(super) struct Point3D {
    pub xyz: DVec3,
    /// Mean reprojection error in pixels.
    pub error: f64,
    /// (image id, keypoint index) of each observation.
    pub track: Vec<(u32, u32)>,
    pub at: At,
}

/// The three files' contents; `files` names them for messages (cameras, images, points3D).
pub(super) struct Model {
    pub cameras: BTreeMap<u32, Camera>,
    pub images: Vec<Image>,
    pub points: HashMap<u64, Point3D>,
    pub files: [String; 3],
}

/// A world-to-camera rotation from COLMAP's (qw, qx, qy, qz), refusing quaternions that are not
/// (nearly) unit length.
pub(super) fn rotation(q: [f64; 4], file: &str, at: At, id: u32) -> Result<DMat3> {
    let norm = q.iter().map(|v| v * v).sum::<f64>().sqrt();
    if !norm.is_finite() || (norm - 1.0).abs() > UNIT_TOLERANCE {
        return Err(SceneError::invalid(
            file,
            format!("{at}: image {id}: quaternion (QW QX QY QZ) = {q:?} has norm {norm}, not a unit rotation"),
        ));
    }
    let [w, x, y, z] = q.map(|v| v / norm);
    Ok(DMat3::from_quat(DQuat::from_xyzw(x, y, z, w)))
}

/// The camera of `model` with `params`: checks the parameter count and that the model is one
/// the importer can undistort.
pub(super) fn camera(model: &str, id: u32, size: (u32, u32), params: &[f64], file: &str, at: At) -> Result<Camera> {
    let Some(lens) = Lens::of_model(model, params) else {
        return Err(SceneError::invalid(
            file,
            format!("{at}: camera {id} has model {model}, which is not supported (supported: {SUPPORTED})"),
        ));
    };
    if !(lens.fx > 0.0 && lens.fy > 0.0) {
        return Err(SceneError::invalid(
            file,
            format!(
                "{at}: camera {id}: focal length must be positive, got fx = {}, fy = {}",
                lens.fx, lens.fy
            ),
        ));
    }
    let terms = [("k1", lens.k1), ("k2", lens.k2), ("p1", lens.p1), ("p2", lens.p2)];
    if let Some((name, v)) = terms.iter().find(|(_, v)| !v.is_finite() || v.abs() > MAX_DISTORTION) {
        return Err(SceneError::invalid(
            file,
            format!(
                "{at}: camera {id}: distortion {name} = {v:e} is outside [-{MAX_DISTORTION}, {MAX_DISTORTION}]; \
                 real lenses stay well inside it, and such a lens would map every pixel outside the photo"
            ),
        ));
    }
    if size.0 == 0 || size.1 == 0 {
        return Err(SceneError::invalid(
            file,
            format!(
                "{at}: camera {id}: WIDTH and HEIGHT must be positive, got {}x{}",
                size.0, size.1
            ),
        ));
    }
    Ok(Camera {
        model: model.to_string(),
        width: size.0,
        height: size.1,
        lens,
    })
}

/// The parameter count of a named model, refusing (before its parameters are read, which an
/// unknown model's count would get wrong) any model the importer cannot undistort.
pub(super) fn param_count(model: &str, id: u32, file: &str, at: At) -> Result<usize> {
    let Some(&(_, count)) = MODELS.iter().find(|(name, _)| *name == model) else {
        return Err(SceneError::invalid(
            file,
            format!("{at}: camera {id} has unknown model {model:?} (supported: {SUPPORTED})"),
        ));
    };
    if Lens::of_model(model, &vec![0.0; count]).is_none() {
        return Err(SceneError::invalid(
            file,
            format!("{at}: camera {id} has model {model}, which is not supported (supported: {SUPPORTED})"),
        ));
    }
    Ok(count)
}

impl Model {
    /// Checks the files agree with each other: ids unique, every camera, image and 3D point that
    /// one file names exists in the other, keypoint indices in range. A model that fails would
    /// place depth at the wrong pixels or poses on the wrong photos.
    pub fn check(&self) -> Result<()> {
        let [cameras, images, points] = &self.files;
        let mut by_id: HashMap<u32, &Image> = HashMap::with_capacity(self.images.len());
        for image in &self.images {
            if let Some(other) = by_id.insert(image.id, image) {
                return Err(SceneError::invalid(
                    images,
                    format!("{}: image id {} is used twice (also {})", image.at, image.id, other.at),
                ));
            }
            if !self.cameras.contains_key(&image.camera_id) {
                return Err(SceneError::invalid(
                    images,
                    format!(
                        "{}: image {} ({}) uses camera {}, which {cameras} does not have",
                        image.at, image.id, image.name, image.camera_id
                    ),
                ));
            }
            if let Some((i, (_, id))) = image
                .points2d
                .iter()
                .enumerate()
                .find(|(_, (_, p))| p.is_some_and(|p| !self.points.contains_key(&p)))
            {
                return Err(SceneError::invalid(
                    images,
                    format!(
                        "{}: image {} ({}): keypoint {i} observes 3D point {}, which {points} does not have",
                        image.at,
                        image.id,
                        image.name,
                        id.unwrap_or_default()
                    ),
                ));
            }
        }
        for (id, point) in &self.points {
            for &(image_id, index) in &point.track {
                let Some(image) = by_id.get(&image_id) else {
                    return Err(SceneError::invalid(
                        points,
                        format!(
                            "{}: point {id}: its track names image {image_id}, which {images} does not have",
                            point.at
                        ),
                    ));
                };
                if index as usize >= image.points2d.len() {
                    return Err(SceneError::invalid(
                        points,
                        format!(
                            "{}: point {id}: its track names keypoint {index} of image {image_id}, which has only {} keypoints",
                            point.at,
                            image.points2d.len()
                        ),
                    ));
                }
            }
        }
        Ok(())
    }
}

/// The error for a second record with an id already used in the same file.
pub(super) fn duplicate(what: &str, id: impl std::fmt::Display, file: &str, at: At) -> SceneError {
    SceneError::invalid(file, format!("{at}: {what} id {id} is used twice"))
}
