//! Reading and writing `*.scene.zip`. Reading trusts nothing: every size is checked before it is
//! allocated, every referenced entry must exist, and every error names the entry.
use std::io::{Cursor, Read, Seek, Write};
use std::path::Path;

use half::f16;
use image::{DynamicImage, GrayImage, ImageFormat, RgbImage};
use zip::write::SimpleFileOptions;
use zip::{CompressionMethod, ZipArchive, ZipWriter};

use super::camera::Pose;
use super::error::{Result, SceneError};
use super::manifest::{FeatureEntry, FrameEntry, MANIFEST_FILE, Manifest, SCENE_FORMAT, SCENE_VERSION};
use super::scene::{DepthImage, FeatureCodes, Frame, Scene};
use crate::labels::LabelSet;

/// Limits that keep a hostile or corrupt archive from exhausting memory.
pub mod limits {
    pub const MAX_FRAMES: u32 = 20_000;
    pub const MAX_SIDE: u32 = 8192;
    /// Pixels over all frames together (about 4 GiB of decoded RGB + depth).
    pub const MAX_TOTAL_PIXELS: u64 = 1 << 29;
    pub const MAX_FEATURE_DIM: u32 = 1024;
    /// Bytes of `features.f16`.
    pub const MAX_FEATURE_BYTES: u64 = 2 << 30;
    pub const MAX_JSON_BYTES: u64 = 64 << 20;
    pub const MAX_ENTRIES: usize = 200_000;
    pub const MAX_CLASSES: usize = 255;
}

/// Reads a scene archive held in memory; `name` is used in error messages (file name or URL).
pub fn read_archive(bytes: &[u8], name: &str) -> Result<Scene> {
    let mut reader = ArchiveReader::new(Cursor::new(bytes), name)?;
    while reader.decode_next_frame()? {}
    reader.finish()
}

/// Reads an archive a piece at a time, for callers that must not stop for the whole decode
/// (the web page decodes between animation frames): [`ArchiveReader::new`] checks the zip and
/// the manifest, each [`ArchiveReader::decode_next_frame`] decodes one frame's images, and
/// [`ArchiveReader::finish`] reads the feature codes and labels and returns the scene.
/// [`read_archive`] is these three in a row; both check exactly the same things.
pub struct ArchiveReader<R: Read + Seek> {
    zip: ZipArchive<R>,
    name: String,
    manifest: Manifest,
    frames: Vec<Frame>,
}

impl<R: Read + Seek> ArchiveReader<R> {
    /// Opens the zip, checks its entry names and reads and checks `scene.json`.
    pub fn new(source: R, name: &str) -> Result<Self> {
        let mut zip = ZipArchive::new(source).map_err(|source| SceneError::Zip {
            file: name.into(),
            source,
        })?;
        check_entry_names(&mut zip, name)?;
        let manifest_bytes = read_entry(&mut zip, name, MANIFEST_FILE, limits::MAX_JSON_BYTES)?;
        let at = format!("{name}:{MANIFEST_FILE}");
        let manifest: Manifest = serde_json::from_slice(&manifest_bytes).map_err(|source| SceneError::Json {
            file: at.clone(),
            source,
        })?;
        check_manifest(&manifest, &at)?;
        let frames = Vec::with_capacity(manifest.frames.len());
        Ok(ArchiveReader {
            zip,
            name: name.into(),
            manifest,
            frames,
        })
    }

    /// The checked manifest (frame count, size, classes...).
    pub fn manifest(&self) -> &Manifest {
        &self.manifest
    }

    /// Frames decoded so far.
    pub fn frames_done(&self) -> usize {
        self.frames.len()
    }

    pub fn frame_count(&self) -> usize {
        self.manifest.frames.len()
    }

    /// Decodes the next frame (colour, depth, ground truth); `false` once every frame is done.
    pub fn decode_next_frame(&mut self) -> Result<bool> {
        let i = self.frames.len();
        let Some(fe) = self.manifest.frames.get(i) else {
            return Ok(false);
        };
        let name = self.name.as_str();
        let zip = &mut self.zip;
        let at = |entry: &str| format!("{name}:{entry}");
        let (w, h) = (self.manifest.width, self.manifest.height);
        let pose = Pose::from_row_major(&fe.pose);
        pose.check()
            .map_err(|p| SceneError::invalid(at(MANIFEST_FILE), format!("frame {i}: {p}")))?;
        let image_limit = w as u64 * h as u64 * 8 + (1 << 20);
        let rgb_bytes = read_entry(zip, name, &fe.rgb, image_limit)?;
        let rgb = decode_rgb(&rgb_bytes, &at(&fe.rgb), w, h)?;
        let depth = match &fe.depth {
            Some(d) => Some(decode_depth(&read_entry(zip, name, d, image_limit)?, &at(d), w, h)?),
            None => None,
        };
        let gt = match &fe.gt {
            Some(g) => Some(decode_gt(&read_entry(zip, name, g, image_limit)?, &at(g), w, h)?),
            None => None,
        };
        self.frames.push(Frame {
            pose,
            rgb,
            depth,
            gt,
            source: fe.source.clone(),
        });
        Ok(true)
    }

    /// Decodes the frames not yet decoded, then the feature codes and labels: the scene.
    pub fn finish(mut self) -> Result<Scene> {
        while self.decode_next_frame()? {}
        let name = self.name.as_str();
        let manifest = self.manifest;
        let features = match &manifest.features {
            Some(fe) => Some(read_features(&mut self.zip, name, fe, manifest.frame_count)?),
            None => None,
        };
        let labels = match &manifest.labels {
            Some(l) => {
                let text = read_entry(&mut self.zip, name, l, limits::MAX_JSON_BYTES)?;
                Some(LabelSet::from_json(
                    &text,
                    &format!("{name}:{l}"),
                    manifest.frame_count,
                )?)
            }
            None => None,
        };
        Ok(Scene {
            width: manifest.width,
            height: manifest.height,
            intrinsics: manifest.intrinsics,
            depth_scale: manifest.depth_scale,
            bounds: manifest.bounds,
            frames: self.frames,
            classes: manifest.classes,
            features,
            labels,
            provenance: manifest.provenance,
        })
    }
}

/// Reads a scene archive from a file.
pub fn read_archive_path(path: &Path) -> Result<Scene> {
    let bytes = std::fs::read(path).map_err(|e| SceneError::io(path, e))?;
    read_archive(&bytes, &path.display().to_string())
}

fn check_entry_names<R: Read + Seek>(zip: &mut ZipArchive<R>, name: &str) -> Result<()> {
    if zip.len() > limits::MAX_ENTRIES {
        return Err(SceneError::invalid(
            name,
            format!("{} entries is more than any scene needs", zip.len()),
        ));
    }
    for i in 0..zip.len() {
        let entry = zip.by_index_raw(i).map_err(|source| SceneError::Zip {
            file: name.into(),
            source,
        })?;
        let raw = entry
            .name()
            .map_err(|source| SceneError::Zip {
                file: name.into(),
                source,
            })?
            .to_string();
        let absolute = raw.starts_with('/') || raw.starts_with('\\') || raw.get(1..2) == Some(":");
        let climbs = raw.split(['/', '\\']).any(|part| part == "..");
        if absolute || climbs || entry.enclosed_name().is_none() {
            return Err(SceneError::invalid(
                name,
                format!("entry name {raw:?} is absolute or leaves the archive ('..'); refusing to read it"),
            ));
        }
    }
    Ok(())
}

/// Reads one entry whole, refusing more than `limit` bytes whatever the header claims.
fn read_entry<R: Read + Seek>(zip: &mut ZipArchive<R>, archive: &str, entry: &str, limit: u64) -> Result<Vec<u8>> {
    let at = format!("{archive}:{entry}");
    let file = match zip.by_name(entry) {
        Ok(f) => f,
        Err(zip::result::ZipError::FileNotFound) => {
            return Err(SceneError::missing(at, "named in scene.json but not in the archive"));
        }
        Err(source) => return Err(SceneError::Zip { file: at, source }),
    };
    if file.size() > limit {
        return Err(SceneError::invalid(
            at,
            format!("{} bytes is more than the {limit} allowed here", file.size()),
        ));
    }
    let mut buf = Vec::with_capacity(file.size() as usize);
    file.take(limit + 1)
        .read_to_end(&mut buf)
        .map_err(|e| SceneError::invalid(&at, format!("cannot read entry (truncated or corrupt archive): {e}")))?;
    if buf.len() as u64 > limit {
        return Err(SceneError::invalid(
            at,
            format!("more than the {limit} bytes allowed here"),
        ));
    }
    Ok(buf)
}

fn check_manifest(m: &Manifest, at: &str) -> Result<()> {
    let bad = |p: String| Err(SceneError::invalid(at, p));
    if m.format != SCENE_FORMAT {
        return bad(format!("format is {:?}, expected {SCENE_FORMAT:?}", m.format));
    }
    if m.version != SCENE_VERSION {
        return bad(format!(
            "unknown format version {} (this build reads version {SCENE_VERSION}; a newer scribblefield may read it)",
            m.version
        ));
    }
    if m.frame_count == 0 || m.frames.is_empty() {
        return bad("the scene has no frames".into());
    }
    if m.frame_count as usize != m.frames.len() {
        return bad(format!(
            "frame_count is {} but {} frames are listed",
            m.frame_count,
            m.frames.len()
        ));
    }
    if m.frame_count > limits::MAX_FRAMES {
        return bad(format!(
            "frame_count {} exceeds the limit of {}",
            m.frame_count,
            limits::MAX_FRAMES
        ));
    }
    if m.width == 0 || m.height == 0 || m.width > limits::MAX_SIDE || m.height > limits::MAX_SIDE {
        return bad(format!(
            "image size {} x {} is not within 1..={} per side",
            m.width,
            m.height,
            limits::MAX_SIDE
        ));
    }
    let total = m.width as u64 * m.height as u64 * m.frame_count as u64;
    if total > limits::MAX_TOTAL_PIXELS {
        return bad(format!(
            "{total} pixels over all frames exceeds the limit of {}",
            limits::MAX_TOTAL_PIXELS
        ));
    }
    m.intrinsics.check().or_else(bad)?;
    m.bounds.check().or_else(bad)?;
    if !(m.depth_scale.is_finite() && m.depth_scale > 0.0) {
        return bad(format!("depth_scale must be a positive number, got {}", m.depth_scale));
    }
    if m.classes.len() > limits::MAX_CLASSES {
        return bad(format!(
            "{} classes exceeds the limit of {}",
            m.classes.len(),
            limits::MAX_CLASSES
        ));
    }
    if let Some(f) = &m.features {
        if f.dim == 0 || f.dim > limits::MAX_FEATURE_DIM || f.width == 0 || f.height == 0 {
            return bad(format!(
                "features: dim {} and grid {} x {} must be positive (dim <= {})",
                f.dim,
                f.width,
                f.height,
                limits::MAX_FEATURE_DIM
            ));
        }
        if f.width > m.width || f.height > m.height {
            return bad(format!(
                "features: grid {} x {} is larger than the images",
                f.width, f.height
            ));
        }
        let d = f.dim as usize;
        if f.pca.mean.len() != d || f.pca.components.iter().any(|c| c.len() != d) {
            return bad(format!("features: PCA mean and components must have {d} values each"));
        }
        if f.pca
            .mean
            .iter()
            .chain(f.pca.components.iter().flatten())
            .chain(&f.pca.lo)
            .chain(&f.pca.hi)
            .any(|v| !v.is_finite())
        {
            return bad("features: PCA has non-finite values".into());
        }
    }
    Ok(())
}

fn decode(bytes: &[u8], at: &str, w: u32, h: u32) -> Result<DynamicImage> {
    let mut reader = image::ImageReader::new(Cursor::new(bytes))
        .with_guessed_format()
        .map_err(|e| SceneError::invalid(at, format!("cannot read image: {e}")))?;
    let mut lim = image::Limits::default();
    lim.max_image_width = Some(limits::MAX_SIDE);
    lim.max_image_height = Some(limits::MAX_SIDE);
    lim.max_alloc = Some(w as u64 * h as u64 * 8 + (1 << 20));
    reader.limits(lim);
    let img = reader.decode().map_err(|source| SceneError::Image {
        file: at.into(),
        source,
    })?;
    if img.width() != w || img.height() != h {
        return Err(SceneError::invalid(
            at,
            format!(
                "image is {} x {}, but the scene's frames are {w} x {h}",
                img.width(),
                img.height()
            ),
        ));
    }
    Ok(img)
}

pub(crate) fn decode_rgb(bytes: &[u8], at: &str, w: u32, h: u32) -> Result<RgbImage> {
    Ok(decode(bytes, at, w, h)?.into_rgb8())
}

pub(crate) fn decode_depth(bytes: &[u8], at: &str, w: u32, h: u32) -> Result<DepthImage> {
    match decode(bytes, at, w, h)? {
        DynamicImage::ImageLuma16(d) => Ok(d),
        other => Err(SceneError::invalid(
            at,
            format!("depth must be a 16-bit single-channel PNG, got {:?}", other.color()),
        )),
    }
}

pub(crate) fn decode_gt(bytes: &[u8], at: &str, w: u32, h: u32) -> Result<GrayImage> {
    match decode(bytes, at, w, h)? {
        DynamicImage::ImageLuma8(g) => Ok(g),
        other => Err(SceneError::invalid(
            at,
            format!(
                "ground truth must be an 8-bit single-channel PNG of class ids, got {:?}",
                other.color()
            ),
        )),
    }
}

fn read_features<R: Read + Seek>(
    zip: &mut ZipArchive<R>,
    name: &str,
    fe: &FeatureEntry,
    frames: u32,
) -> Result<FeatureCodes> {
    let expected = frames as u64 * fe.height as u64 * fe.width as u64 * fe.dim as u64 * 2;
    let at = format!("{name}:{}", fe.file);
    if expected > limits::MAX_FEATURE_BYTES {
        return Err(SceneError::invalid(
            at,
            format!(
                "{expected} bytes of features exceeds the limit of {}",
                limits::MAX_FEATURE_BYTES
            ),
        ));
    }
    let bytes = read_entry(zip, name, &fe.file, expected)?;
    if bytes.len() as u64 != expected {
        return Err(SceneError::invalid(
            at,
            format!(
                "holds {} bytes but {frames} frames x {} x {} x {} f16 values need {expected}",
                bytes.len(),
                fe.height,
                fe.width,
                fe.dim
            ),
        ));
    }
    let data: Vec<f16> = bytes
        .chunks_exact(2)
        .map(|c| f16::from_le_bytes([c[0], c[1]]))
        .collect();
    if data.iter().any(|v| !v.is_finite()) {
        return Err(SceneError::invalid(at, "contains non-finite values"));
    }
    Ok(FeatureCodes {
        height: fe.height,
        width: fe.width,
        dim: fe.dim,
        extractor: fe.extractor.clone(),
        data,
        pca: fe.pca.clone(),
    })
}

/// Entry names used by the writer.
fn frame_entry(dir: &str, i: usize) -> String {
    format!("{dir}/{i:05}.png")
}

/// Builds the manifest that describes `scene` as the writer lays it out.
pub fn manifest_of(scene: &Scene) -> Manifest {
    let frames = scene
        .frames
        .iter()
        .enumerate()
        .map(|(i, f)| FrameEntry {
            rgb: frame_entry("rgb", i),
            depth: f.depth.as_ref().map(|_| frame_entry("depth", i)),
            gt: f.gt.as_ref().map(|_| frame_entry("gt", i)),
            pose: f.pose.to_row_major(),
            source: f.source.clone(),
        })
        .collect();
    Manifest {
        format: SCENE_FORMAT.into(),
        version: SCENE_VERSION,
        frame_count: scene.frames.len() as u32,
        width: scene.width,
        height: scene.height,
        intrinsics: scene.intrinsics,
        depth_scale: scene.depth_scale,
        bounds: scene.bounds,
        frames,
        features: scene.features.as_ref().map(|f| FeatureEntry {
            file: "features.f16".into(),
            height: f.height,
            width: f.width,
            dim: f.dim,
            extractor: f.extractor.clone(),
            pca: f.pca.clone(),
        }),
        classes: scene.classes.clone(),
        labels: scene.labels.as_ref().map(|_| "labels.json".into()),
        provenance: scene.provenance.clone(),
    }
}

fn encode_png(img: &DynamicImage) -> Vec<u8> {
    let mut out = Cursor::new(Vec::new());
    img.write_to(&mut out, ImageFormat::Png)
        .expect("PNG encoding into memory cannot fail");
    out.into_inner()
}

/// Writes `scene` as an archive into any seekable writer. The scene is checked first, so a
/// written archive always reads back.
pub fn write_archive<W: Write + Seek>(scene: &Scene, out: W) -> Result<W> {
    let manifest = manifest_of(scene);
    check_manifest(&manifest, "scene to write")?;
    for (i, f) in scene.frames.iter().enumerate() {
        f.pose
            .check()
            .map_err(|p| SceneError::invalid("scene to write", format!("frame {i}: {p}")))?;
        let dims_ok = f.rgb.dimensions() == (scene.width, scene.height)
            && f.depth
                .as_ref()
                .is_none_or(|d| d.dimensions() == (scene.width, scene.height))
            && f.gt
                .as_ref()
                .is_none_or(|g| g.dimensions() == (scene.width, scene.height));
        if !dims_ok {
            return Err(SceneError::invalid(
                "scene to write",
                format!("frame {i}: image sizes differ from the scene's"),
            ));
        }
    }
    if let Some(f) = &scene.features
        && f.data.len() != f.values_per_frame() * scene.frames.len()
    {
        return Err(SceneError::invalid(
            "scene to write",
            "feature codes do not match frames x grid x dim",
        ));
    }
    if let Some(l) = &scene.labels {
        l.check("scene to write: labels", scene.frames.len() as u32)?;
    }

    let zip_err = |source| SceneError::Zip {
        file: "scene to write".into(),
        source,
    };
    let io_err = |e| SceneError::io("scene to write", e);
    let mut zip = ZipWriter::new(out);
    let stored = SimpleFileOptions::default()
        .compression_method(CompressionMethod::Stored)
        .large_file(false);
    let deflated = SimpleFileOptions::default().compression_method(CompressionMethod::Deflated);

    let json = serde_json::to_vec_pretty(&manifest).expect("manifest always serializes");
    zip.start_file(MANIFEST_FILE, deflated).map_err(zip_err)?;
    zip.write_all(&json).map_err(io_err)?;
    for (f, fe) in scene.frames.iter().zip(&manifest.frames) {
        zip.start_file(fe.rgb.as_str(), stored).map_err(zip_err)?;
        zip.write_all(&encode_png(&DynamicImage::ImageRgb8(f.rgb.clone())))
            .map_err(io_err)?;
        if let (Some(d), Some(name)) = (&f.depth, &fe.depth) {
            zip.start_file(name.as_str(), stored).map_err(zip_err)?;
            zip.write_all(&encode_png(&DynamicImage::ImageLuma16(d.clone())))
                .map_err(io_err)?;
        }
        if let (Some(g), Some(name)) = (&f.gt, &fe.gt) {
            zip.start_file(name.as_str(), stored).map_err(zip_err)?;
            zip.write_all(&encode_png(&DynamicImage::ImageLuma8(g.clone())))
                .map_err(io_err)?;
        }
    }
    if let (Some(f), Some(fe)) = (&scene.features, &manifest.features) {
        zip.start_file(
            fe.file.as_str(),
            deflated.large_file(f.data.len() * 2 >= u32::MAX as usize),
        )
        .map_err(zip_err)?;
        let bytes: Vec<u8> = f.data.iter().flat_map(|v| v.to_le_bytes()).collect();
        zip.write_all(&bytes).map_err(io_err)?;
    }
    if let (Some(l), Some(name)) = (&scene.labels, &manifest.labels) {
        zip.start_file(name.as_str(), deflated).map_err(zip_err)?;
        zip.write_all(l.to_json().as_bytes()).map_err(io_err)?;
    }
    zip.finish().map_err(zip_err)
}

/// Writes `scene` to a file, through a temporary sibling so a failed write never leaves a
/// half-written archive where a good one was.
pub fn write_archive_path(scene: &Scene, path: &Path) -> Result<()> {
    let tmp = path.with_extension("zip.partial");
    let file = std::fs::File::create(&tmp).map_err(|e| SceneError::io(&tmp, e))?;
    let result = write_archive(scene, std::io::BufWriter::new(file)).and_then(|w| {
        w.into_inner()
            .map_err(|e| SceneError::io(&tmp, e.into_error()))
            .map(drop)
    });
    if let Err(e) = result {
        let _ = std::fs::remove_file(&tmp);
        return Err(e);
    }
    std::fs::rename(&tmp, path).map_err(|e| SceneError::io(path, e))
}

/// Writes to memory (the browser's download path, and tests).
pub fn write_archive_bytes(scene: &Scene) -> Result<Vec<u8>> {
    Ok(write_archive(scene, Cursor::new(Vec::new()))?.into_inner())
}
