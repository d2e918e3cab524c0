//! COLMAP's binary model (`cameras.bin`, `images.bin`, `points3D.bin`): little-endian, each file
//! a u64 record count followed by the records. Counts are checked against the bytes left before
//! anything is allocated, so a damaged or hostile file cannot ask for gigabytes.
use std::collections::{BTreeMap, HashMap};
use std::path::Path;

use glam::{DVec2, DVec3};

use super::model::{
    At, Camera, Image, MAX_POINTS, MODELS, Model, Point3D, SUPPORTED, camera, duplicate, param_count, rotation,
    too_many_points,
};
use super::read_model_file;
use crate::scene::error::{Result, SceneError};

/// Longest image name accepted (COLMAP writes it NUL-terminated, with no length).
const MAX_NAME_BYTES: usize = 4096;
/// Bytes of one keypoint (x, y, point3D_id) and one track element (image_id, point2D_idx).
const KEYPOINT_BYTES: usize = 24;
const TRACK_BYTES: usize = 8;
/// COLMAP writes "no 3D point" as the largest u64 (-1 as a signed id).
const NO_POINT: u64 = u64::MAX;

pub(super) fn read(dir: &Path) -> Result<Model> {
    let paths = super::FILES.map(|f| dir.join(format!("{f}.bin")));
    let files = paths.clone().map(|p| p.display().to_string());
    Ok(Model {
        cameras: read_cameras(&mut Reader::new(&read_model_file(&paths[0])?, &files[0]))?,
        images: read_images(&mut Reader::new(&read_model_file(&paths[1])?, &files[1]))?,
        points: read_points(&mut Reader::new(&read_model_file(&paths[2])?, &files[2]))?,
        files,
    })
}

/// The model in the three files' bytes (cameras, images, points3D), named `files` in messages.
pub(super) fn parse(bytes: [&[u8]; 3], files: [String; 3]) -> Result<Model> {
    Ok(Model {
        cameras: read_cameras(&mut Reader::new(bytes[0], &files[0]))?,
        images: read_images(&mut Reader::new(bytes[1], &files[1]))?,
        points: read_points(&mut Reader::new(bytes[2], &files[2]))?,
        files,
    })
}

/// A cursor over one file's bytes that knows which record it is in, for messages.
struct Reader<'a> {
    bytes: &'a [u8],
    pos: usize,
    file: &'a str,
    at: At,
}

impl<'a> Reader<'a> {
    fn new(bytes: &'a [u8], file: &'a str) -> Self {
        Reader {
            bytes,
            pos: 0,
            file,
            at: At::Record(0),
        }
    }

    fn left(&self) -> usize {
        self.bytes.len() - self.pos
    }

    fn err(&self, problem: String) -> SceneError {
        match self.at {
            At::Record(0) => SceneError::invalid(self.file, problem),
            at => SceneError::invalid(self.file, format!("{at}: {problem}")),
        }
    }

    fn take(&mut self, n: usize, field: &str) -> Result<&'a [u8]> {
        if self.left() < n {
            return Err(self.err(format!(
                "truncated: {field} needs {n} bytes at byte {}, but the file ends after {}",
                self.pos,
                self.left()
            )));
        }
        let out = &self.bytes[self.pos..self.pos + n];
        self.pos += n;
        Ok(out)
    }

    fn array<const N: usize>(&mut self, field: &str) -> Result<[u8; N]> {
        let mut out = [0; N];
        out.copy_from_slice(self.take(N, field)?);
        Ok(out)
    }

    fn u32(&mut self, field: &str) -> Result<u32> {
        Ok(u32::from_le_bytes(self.array(field)?))
    }

    fn u64(&mut self, field: &str) -> Result<u64> {
        Ok(u64::from_le_bytes(self.array(field)?))
    }

    /// Consecutive numbers named `fields`, each named `{prefix}{field}` in messages.
    fn reals<const N: usize>(&mut self, prefix: &str, fields: [&str; N]) -> Result<[f64; N]> {
        let mut out = [0.0; N];
        for (v, field) in out.iter_mut().zip(fields) {
            *v = self.real(&format!("{prefix}{field}"))?;
        }
        Ok(out)
    }

    fn real(&mut self, field: &str) -> Result<f64> {
        let v = f64::from_le_bytes(self.array(field)?);
        if v.is_finite() {
            Ok(v)
        } else {
            Err(self.err(format!("{field} is {v}, not a finite number")))
        }
    }

    /// A record count, checked against the bytes left given each record's smallest size.
    fn count(&mut self, what: &str, min_bytes: usize) -> Result<usize> {
        let n = self.u64(&format!("the number of {what}"))?;
        let fits = (self.left() / min_bytes.max(1)) as u64;
        if n > fits {
            return Err(self.err(format!(
                "truncated or wrong count: {n} {what} need at least {} bytes, but only {} are left",
                n.saturating_mul(min_bytes as u64),
                self.left()
            )));
        }
        Ok(n as usize)
    }

    fn name(&mut self) -> Result<String> {
        let rest = &self.bytes[self.pos..];
        let Some(len) = rest.iter().take(MAX_NAME_BYTES + 1).position(|&b| b == 0) else {
            return Err(self.err(if rest.len() <= MAX_NAME_BYTES {
                "truncated: the file ends inside NAME (no terminating NUL)".to_string()
            } else {
                format!("NAME is longer than {MAX_NAME_BYTES} bytes (no terminating NUL)")
            }));
        };
        let name = std::str::from_utf8(&rest[..len])
            .map_err(|_| self.err("NAME is not UTF-8".into()))?
            .to_string();
        self.pos += len + 1;
        if name.is_empty() {
            return Err(self.err("NAME is empty".into()));
        }
        Ok(name)
    }

    /// Trailing bytes mean the count at the start was wrong (or the file is something else).
    fn finish(&self, records: usize, what: &str) -> Result<()> {
        if self.left() == 0 {
            return Ok(());
        }
        Err(SceneError::invalid(
            self.file,
            format!(
                "wrong count: {} bytes follow the {records} {what} the file announces",
                self.left()
            ),
        ))
    }
}

fn read_cameras(r: &mut Reader) -> Result<BTreeMap<u32, Camera>> {
    // camera_id u32, model_id i32, width u64, height u64, then the model's f64 parameters.
    let n = r.count("cameras", 24)?;
    let mut cameras = BTreeMap::new();
    for i in 0..n {
        r.at = At::Record(i + 1);
        let id = r.u32("CAMERA_ID")?;
        let model_id = r.u32("MODEL_ID")?;
        let Some(&(model, _)) = MODELS.get(model_id as usize) else {
            return Err(r.err(format!(
                "camera {id} has unknown model id {} (supported: {SUPPORTED})",
                model_id as i32
            )));
        };
        let count = param_count(model, id, r.file, r.at)?;
        let mut size = [0; 2];
        for (v, field) in size.iter_mut().zip(["WIDTH", "HEIGHT"]) {
            let s = r.u64(field)?;
            *v = u32::try_from(s).map_err(|_| r.err(format!("camera {id}: {field} = {s} is not an image size")))?;
        }
        let mut params = Vec::with_capacity(count);
        for p in 0..count {
            params.push(r.real(&format!("camera {id}: PARAMS[{p}] of {model}"))?);
        }
        let cam = camera(model, id, (size[0], size[1]), &params, r.file, r.at)?;
        if cameras.insert(id, cam).is_some() {
            return Err(duplicate("camera", id, r.file, r.at));
        }
    }
    r.finish(n, "cameras")?;
    Ok(cameras)
}

fn read_images(r: &mut Reader) -> Result<Vec<Image>> {
    // image_id u32, q 4 x f64, t 3 x f64, camera_id u32, name + NUL, count u64, keypoints.
    let n = r.count("images", 4 + 56 + 4 + 2 + 8)?;
    let mut images = Vec::with_capacity(n);
    for i in 0..n {
        r.at = At::Record(i + 1);
        let id = r.u32("IMAGE_ID")?;
        let q = r.reals(&format!("image {id}: "), ["QW", "QX", "QY", "QZ"])?;
        let t = r.reals(&format!("image {id}: "), ["TX", "TY", "TZ"])?;
        let camera_id = r.u32("CAMERA_ID")?;
        let name = r.name()?;
        let keypoints = r.count(&format!("keypoints of image {id} ({name})"), KEYPOINT_BYTES)?;
        let mut points2d = Vec::with_capacity(keypoints);
        for k in 0..keypoints {
            let x = r.real(&format!("image {id}: POINTS2D[{k}] X"))?;
            let y = r.real(&format!("image {id}: POINTS2D[{k}] Y"))?;
            let p = r.u64(&format!("image {id}: POINTS2D[{k}] POINT3D_ID"))?;
            points2d.push((DVec2::new(x, y), (p != NO_POINT).then_some(p)));
        }
        images.push(Image {
            id,
            rotation: rotation(q, r.file, r.at, id)?,
            translation: DVec3::from_array(t),
            camera_id,
            name,
            points2d,
            at: r.at,
        });
    }
    r.finish(n, "images")?;
    Ok(images)
}

fn read_points(r: &mut Reader) -> Result<HashMap<u64, Point3D>> {
    // point3D_id u64, xyz 3 x f64, rgb 3 x u8, error f64, track length u64, track elements.
    let n = r.count("3D points", 8 + 24 + 3 + 8 + 8)?;
    if n > MAX_POINTS {
        return Err(too_many_points(n, r.file));
    }
    let mut points = HashMap::with_capacity(n);
    for i in 0..n {
        r.at = At::Record(i + 1);
        let id = r.u64("POINT3D_ID")?;
        let xyz = r.reals(&format!("point {id}: "), ["X", "Y", "Z"])?;
        r.take(3, "RGB")?;
        let error = r.real(&format!("point {id}: ERROR"))?;
        let len = r.count(&format!("track elements of point {id}"), TRACK_BYTES)?;
        let mut track = Vec::with_capacity(len);
        for _ in 0..len {
            track.push((r.u32("TRACK IMAGE_ID")?, r.u32("TRACK POINT2D_IDX")?));
        }
        let point = Point3D {
            xyz: DVec3::from_array(xyz),
            error,
            track,
            at: r.at,
        };
        if points.insert(id, point).is_some() {
            return Err(duplicate("3D point", id, r.file, r.at));
        }
    }
    r.finish(n, "3D points")?;
    Ok(points)
}
