//! Reading and writing `*.scene.zip`. Reading trusts nothing: every size is checked before it is
//! allocated, every referenced entry must exist, and every error names the entry.
use std::io::{Cursor, Read, Seek};
use std::path::Path;

use half::f16;
use image::{ColorType, DynamicImage, GrayImage, ImageDecoder, RgbImage};
use zip::ZipArchive;

use super::camera::{Pose, f32_finite};
use super::decoded::{DepthImage, FeatureCodes, Frame, GT_VOID, Scene};
use super::error::{Result, SceneError};

mod content_id;
mod write;
use super::label_set::LabelSet;
use super::manifest::{FeatureEntry, MANIFEST_FILE, Manifest, SCENE_FORMAT, SCENE_VERSION};
pub use write::{manifest_of, write_archive, write_archive_bytes, write_archive_path};

/// Limits that keep a hostile or corrupt archive from exhausting memory. docs/limits.md lists
/// them with their reasons; every refusal names the entry and the limit it broke.
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
    /// Bytes a whole decoded scene may take: colour (3 per pixel), depth (2), ground truth (1)
    /// and feature codes (2 per value). Worked out from scene.json before anything is decoded.
    /// Natively it keeps a hostile archive's peak memory under 1.5 GiB; a larger capture packs
    /// with `pack --max-size` or fewer frames.
    #[cfg(not(target_arch = "wasm32"))]
    pub const MAX_DECODED_BYTES: u64 = 5 << 28;
    /// The page's budget is lower: a wasm32 memory holds at most 4 GiB, and the trainer, the
    /// label masks and the browser's own copies of the images need room beside the scene.
    #[cfg(target_arch = "wasm32")]
    pub const MAX_DECODED_BYTES: u64 = 1 << 30;
    /// Largest ratio of an entry's size to its compressed size. Deflate's own maximum is about
    /// 1032:1 and real images and depth stay far below it, so only a crafted entry (a run of
    /// zeros that inflates to gigabytes) reaches it. The feature codes are exempt: their exact
    /// size follows from scene.json and is inside the decoded-bytes budget, and near-constant
    /// codes (a featureless synthetic scene) legitimately compress past it.
    pub const MAX_COMPRESSION_RATIO: u64 = 1000;
    /// Entries up to this size are not held to the ratio: a small, repetitive JSON file may
    /// compress very well and cannot exhaust memory.
    pub const RATIO_EXEMPT_BYTES: u64 = 1 << 20;
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
    content_id: String,
}

impl<R: Read + Seek> ArchiveReader<R> {
    /// Opens the zip, checks its entry names and reads and checks `scene.json`.
    pub fn new(source: R, name: &str) -> Result<Self> {
        let mut zip = ZipArchive::new(source).map_err(|source| SceneError::Zip {
            file: name.into(),
            source,
        })?;
        if zip.has_duplicate_names() {
            // The zip reader keeps only the last of several entries with one name; which one
            // a reader sees would then depend on the reader, so such archives are refused.
            let start = zip.central_directory_start();
            let twice = duplicate_entry_name(&mut zip.into_inner(), start);
            return Err(SceneError::invalid(
                name,
                match twice {
                    Some(e) => format!("entry {e:?} appears more than once; each entry name must be unique"),
                    None => "an entry name appears more than once; each entry name must be unique".into(),
                },
            ));
        }
        check_entry_names(&mut zip, name)?;
        let manifest_bytes = read_entry(&mut zip, name, MANIFEST_FILE, limits::MAX_JSON_BYTES)?;
        let at = format!("{name}:{MANIFEST_FILE}");
        let manifest: Manifest = serde_json::from_slice(&manifest_bytes).map_err(|source| SceneError::Json {
            file: at.clone(),
            source,
        })?;
        check_manifest(&manifest, &at)?;
        let content_id = content_id::content_id(&mut zip, name, &manifest_bytes)?;
        let frames = Vec::with_capacity(manifest.frames.len());
        Ok(ArchiveReader {
            zip,
            name: name.into(),
            manifest,
            frames,
            content_id,
        })
    }

    /// The checked manifest (frame count, size, classes...).
    pub fn manifest(&self) -> &Manifest {
        &self.manifest
    }

    /// What the archive holds, as 32 hex digits (see `content_id`): the page keys saved
    /// annotations by it.
    pub fn content_id(&self) -> &str {
        &self.content_id
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
            Some(g) => {
                let gt = decode_gt(&read_entry(zip, name, g, image_limit)?, &at(g), w, h)?;
                check_gt_classes(&gt, self.manifest.classes.len(), &at(g), i)?;
                Some(gt)
            }
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

/// Reads a scene archive from a file. The file is read entry by entry, never whole: only what
/// scene.json names is read, each entry within its limits.
pub fn read_archive_path(path: &Path) -> Result<Scene> {
    let file = std::fs::File::open(path).map_err(|e| SceneError::io(path, e))?;
    let mut reader = ArchiveReader::new(std::io::BufReader::new(file), &path.display().to_string())?;
    while reader.decode_next_frame()? {}
    reader.finish()
}

/// The first name that appears twice in the zip's central directory at `start`, read directly
/// (the zip reader keeps one entry per name). `None` when the directory cannot be walked.
fn duplicate_entry_name<R: Read + Seek>(source: &mut R, start: u64) -> Option<String> {
    const CENTRAL_HEADER: [u8; 4] = [0x50, 0x4b, 0x01, 0x02];
    source.seek(std::io::SeekFrom::Start(start)).ok()?;
    let mut seen = std::collections::HashSet::new();
    for _ in 0..=limits::MAX_ENTRIES {
        let mut fixed = [0u8; 46];
        source.read_exact(&mut fixed).ok()?;
        if fixed[..4] != CENTRAL_HEADER {
            return None;
        }
        let len = |at: usize| u16::from_le_bytes([fixed[at], fixed[at + 1]]) as usize;
        let (name_len, extra_len, comment_len) = (len(28), len(30), len(32));
        let mut raw = vec![0u8; name_len];
        source.read_exact(&mut raw).ok()?;
        let entry = String::from_utf8_lossy(&raw).into_owned();
        if !seen.insert(entry.clone()) {
            return Some(entry);
        }
        source
            .seek(std::io::SeekFrom::Current((extra_len + comment_len) as i64))
            .ok()?;
    }
    None
}

/// Every ground-truth value must be a class of the scene or void: an id past the class list
/// would make evaluation score a class that does not exist.
pub(crate) fn check_gt_classes(gt: &GrayImage, classes: usize, at: &str, frame: usize) -> Result<()> {
    let bad = gt
        .enumerate_pixels()
        .find(|(_, _, p)| p.0[0] != GT_VOID && p.0[0] as usize >= classes);
    match bad {
        Some((x, y, p)) => Err(SceneError::invalid(
            at,
            format!(
                "frame {frame}: ground-truth class id {} at pixel ({x}, {y}), but the scene has {classes} classes \
                 (ids 0..{classes}, {GT_VOID} = void)",
                p.0[0]
            ),
        )),
        None => Ok(()),
    }
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

/// Whether an entry is held to `limits::MAX_COMPRESSION_RATIO`.
#[derive(Clone, Copy, PartialEq, Eq)]
enum RatioCap {
    Apply,
    /// For an entry whose exact size scene.json fixes and the decoded-bytes budget covers.
    Exempt,
}

/// Opens one entry for reading, checked against `limit` bytes and (unless exempt) the
/// compression ratio cap before anything is read; the reader stops one byte past what is
/// allowed, so a header that understates the size is caught too.
fn open_entry<'z, R: Read + Seek>(
    zip: &'z mut ZipArchive<R>,
    archive: &str,
    entry: &str,
    limit: u64,
    cap: RatioCap,
) -> Result<OpenEntry<impl Read + 'z>> {
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
    let compressed = file.compressed_size();
    let ratio_cap = match cap {
        RatioCap::Apply => compressed
            .saturating_mul(limits::MAX_COMPRESSION_RATIO)
            .max(limits::RATIO_EXEMPT_BYTES),
        RatioCap::Exempt => u64::MAX,
    };
    if file.size() > ratio_cap {
        return Err(ratio_error(&at, file.size(), compressed));
    }
    let allowed = limit.min(ratio_cap);
    let size = file.size();
    Ok(OpenEntry {
        reader: file.take(allowed + 1),
        allowed,
        compressed,
        size,
    })
}

struct OpenEntry<R> {
    reader: R,
    /// Bytes it may hold: the caller's limit, or less where the ratio cap is lower.
    allowed: u64,
    compressed: u64,
    /// What the header claims (at most `allowed`).
    size: u64,
}

fn ratio_error(at: &str, size: u64, compressed: u64) -> SceneError {
    SceneError::invalid(
        at,
        format!(
            "{size} bytes from {compressed} compressed is a compression ratio of {}:1, over the limit of {}:1 \
             for entries over {} bytes",
            size / compressed.max(1),
            limits::MAX_COMPRESSION_RATIO,
            limits::RATIO_EXEMPT_BYTES
        ),
    )
}

/// The error for an entry that held more than `allowed` bytes when read (its header said less).
fn overlong(at: &str, allowed: u64, limit: u64, compressed: u64) -> SceneError {
    if allowed < limit {
        ratio_error(at, allowed + 1, compressed)
    } else {
        SceneError::invalid(at, format!("more than the {limit} bytes allowed here"))
    }
}

/// Reads one entry whole, refusing more than `limit` bytes whatever the header claims.
fn read_entry<R: Read + Seek>(zip: &mut ZipArchive<R>, archive: &str, entry: &str, limit: u64) -> Result<Vec<u8>> {
    let at = format!("{archive}:{entry}");
    let mut e = open_entry(zip, archive, entry, limit, RatioCap::Apply)?;
    // The header's size is a hint for the allocation, already checked against what is allowed.
    let mut buf = Vec::with_capacity(e.size as usize);
    e.reader
        .read_to_end(&mut buf)
        .map_err(|err| SceneError::invalid(&at, format!("cannot read entry (truncated or corrupt archive): {err}")))?;
    if buf.len() as u64 > e.allowed {
        return Err(overlong(&at, e.allowed, limit, e.compressed));
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
    // Depth is scaled in f32 on the GPU: the scale must not flush to zero or overflow there.
    f32_finite("scene", "depth_scale", m.depth_scale).or_else(bad)?;
    if (m.depth_scale as f32) < f32::MIN_POSITIVE {
        return bad(format!(
            "depth_scale = {:e} is too small for a 32-bit float (at least {:e})",
            m.depth_scale,
            f32::MIN_POSITIVE
        ));
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
    check_entry_users(m).or_else(bad)?;
    let (images, features) = decoded_bytes(m);
    if images + features > limits::MAX_DECODED_BYTES {
        return bad(format!(
            "the scene decodes to {} bytes ({images} of images, {features} of feature codes), more than the \
             budget of {} bytes for one scene (pack it with a smaller --max-size or fewer frames)",
            images + features,
            limits::MAX_DECODED_BYTES
        ));
    }
    Ok(())
}

/// Bytes of decoded images and of feature codes that the manifest `m` (already checked for
/// sizes and counts) describes.
fn decoded_bytes(m: &Manifest) -> (u64, u64) {
    let pixels = m.width as u64 * m.height as u64;
    let images = m
        .frames
        .iter()
        .map(|f| pixels * (3 + 2 * f.depth.is_some() as u64 + f.gt.is_some() as u64))
        .fold(0u64, u64::saturating_add);
    let features = m.features.as_ref().map_or(0, |f| {
        (m.frames.len() as u64)
            .saturating_mul(f.height as u64 * f.width as u64 * f.dim as u64)
            .saturating_mul(2)
    });
    (images, features)
}

/// Each entry backs one image or file: several frames decoding one small, highly compressed
/// image would multiply its memory without growing the archive.
fn check_entry_users(m: &Manifest) -> Result<(), String> {
    let mut users: std::collections::HashMap<String, String> = std::collections::HashMap::new();
    let mut claim = |entry: &str, user: String| -> Result<(), String> {
        if entry == MANIFEST_FILE {
            return Err(format!("{user} is entry {entry:?}, the manifest itself"));
        }
        match users.insert(entry.to_string(), user.clone()) {
            Some(before) => Err(format!(
                "entry {entry:?} is used as both {before} and {user}; each entry may back one image or file only"
            )),
            None => Ok(()),
        }
    };
    for (i, f) in m.frames.iter().enumerate() {
        claim(&f.rgb, format!("the colour of frame {i}"))?;
        if let Some(d) = &f.depth {
            claim(d, format!("the depth of frame {i}"))?;
        }
        if let Some(g) = &f.gt {
            claim(g, format!("the ground truth of frame {i}"))?;
        }
    }
    if let Some(f) = &m.features {
        claim(&f.file, "the feature codes".into())?;
    }
    if let Some(l) = &m.labels {
        claim(l, "the labels".into())?;
    }
    Ok(())
}

/// Decodes one image of the scene. The header is read first: an image whose size (or, with
/// `color`, pixel type) is not what the scene says is refused before its pixels are decoded,
/// so no entry can make the reader allocate more than one frame of the manifest's size.
fn decode(bytes: &[u8], at: &str, w: u32, h: u32, color: Option<(ColorType, &str)>) -> Result<DynamicImage> {
    let mut reader = image::ImageReader::new(Cursor::new(bytes))
        .with_guessed_format()
        .map_err(|e| SceneError::invalid(at, format!("cannot read image: {e}")))?;
    let mut lim = image::Limits::default();
    lim.max_image_width = Some(limits::MAX_SIDE);
    lim.max_image_height = Some(limits::MAX_SIDE);
    lim.max_alloc = Some(w as u64 * h as u64 * 8 + (1 << 20));
    reader.limits(lim);
    let image_err = |source| SceneError::Image {
        file: at.into(),
        source,
    };
    let decoder = reader.into_decoder().map_err(image_err)?;
    let (iw, ih) = decoder.dimensions();
    if iw != w || ih != h {
        return Err(SceneError::invalid(
            at,
            format!("image is {iw} x {ih}, but the scene's frames are {w} x {h}"),
        ));
    }
    if let Some((expected, what)) = color
        && decoder.color_type() != expected
    {
        return Err(SceneError::invalid(
            at,
            format!("{what}, got {:?}", decoder.color_type()),
        ));
    }
    DynamicImage::from_decoder(decoder).map_err(image_err)
}

pub(crate) fn decode_rgb(bytes: &[u8], at: &str, w: u32, h: u32) -> Result<RgbImage> {
    Ok(decode(bytes, at, w, h, None)?.into_rgb8())
}

pub(crate) fn decode_depth(bytes: &[u8], at: &str, w: u32, h: u32) -> Result<DepthImage> {
    let what = "depth must be a 16-bit single-channel PNG";
    match decode(bytes, at, w, h, Some((ColorType::L16, what)))? {
        DynamicImage::ImageLuma16(d) => Ok(d),
        other => Err(SceneError::invalid(at, format!("{what}, got {:?}", other.color()))),
    }
}

pub(crate) fn decode_gt(bytes: &[u8], at: &str, w: u32, h: u32) -> Result<GrayImage> {
    let what = "ground truth must be an 8-bit single-channel PNG of class ids";
    match decode(bytes, at, w, h, Some((ColorType::L8, what)))? {
        DynamicImage::ImageLuma8(g) => Ok(g),
        other => Err(SceneError::invalid(at, format!("{what}, got {:?}", other.color()))),
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
    // Decoded straight into the codes a block at a time: the entry's bytes are never held
    // whole beside them.
    let mut entry = open_entry(zip, name, &fe.file, expected, RatioCap::Exempt)?;
    let mut data: Vec<f16> = Vec::with_capacity((expected / 2) as usize);
    let mut block = vec![0u8; 1 << 16];
    let mut pending = 0usize;
    let mut read_bytes = 0u64;
    loop {
        let n = entry
            .reader
            .read(&mut block[pending..])
            .map_err(|e| SceneError::invalid(&at, format!("cannot read entry (truncated or corrupt archive): {e}")))?;
        if n == 0 {
            break;
        }
        read_bytes += n as u64;
        if read_bytes > entry.allowed {
            return Err(overlong(&at, entry.allowed, expected, entry.compressed));
        }
        let filled = pending + n;
        let whole = filled - filled % 2;
        for c in block[..whole].chunks_exact(2) {
            let v = f16::from_le_bytes([c[0], c[1]]);
            if !v.is_finite() {
                return Err(SceneError::invalid(at, "contains non-finite values"));
            }
            data.push(v);
        }
        // An odd byte left over waits for the next read.
        block.copy_within(whole..filled, 0);
        pending = filled - whole;
    }
    if read_bytes != expected {
        return Err(SceneError::invalid(
            at,
            format!(
                "holds {read_bytes} bytes but {frames} frames x {} x {} x {} f16 values need {expected}",
                fe.height, fe.width, fe.dim
            ),
        ));
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
