use std::io::{Cursor, Read, Write};
use std::path::Path;

use image::{DynamicImage, GrayImage, ImageFormat, RgbImage};
use serde::{Deserialize, Serialize};
use zip::write::SimpleFileOptions;

use crate::labels::{ClassInfo, LabelSet};
use crate::scene::error::{Result, SceneError};

pub const MASKS_FORMAT: &str = "scribblefield-masks";
pub const MASKS_VERSION: u32 = 1;
const MANIFEST: &str = "classes.json";

/// Dense predicted masks of every frame.
#[derive(Clone, Debug, PartialEq)]
pub struct MaskSet {
    pub classes: Vec<ClassInfo>,
    /// Class id per pixel, one image per frame.
    pub masks: Vec<GrayImage>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MasksManifest {
    pub format: String,
    pub version: u32,
    pub frames: u32,
    pub width: u32,
    pub height: u32,
    pub classes: Vec<ClassInfo>,
    /// File of frame i is `files[i]`; previews are under `preview/` with the same names.
    pub files: Vec<String>,
}

fn mask_name(i: usize) -> String {
    format!("{i:05}.png")
}

fn png(img: DynamicImage) -> Vec<u8> {
    let mut out = Cursor::new(Vec::new());
    img.write_to(&mut out, ImageFormat::Png)
        .expect("PNG encoding into memory cannot fail");
    out.into_inner()
}

impl MaskSet {
    fn manifest(&self) -> MasksManifest {
        let (width, height) = self.masks.first().map(|m| m.dimensions()).unwrap_or((0, 0));
        MasksManifest {
            format: MASKS_FORMAT.into(),
            version: MASKS_VERSION,
            frames: self.masks.len() as u32,
            width,
            height,
            classes: self.classes.clone(),
            files: (0..self.masks.len()).map(mask_name).collect(),
        }
    }

    /// The colour preview of frame `i`: class colours, black for unknown ids.
    pub fn preview(&self, i: usize) -> RgbImage {
        preview_of(&self.masks[i], &self.classes)
    }

    /// Every file of the export as (relative path, bytes).
    pub fn files(&self, labels: Option<&LabelSet>) -> Vec<(String, Vec<u8>)> {
        let manifest = self.manifest();
        let mut out = vec![(
            MANIFEST.to_string(),
            serde_json::to_vec_pretty(&manifest).expect("manifest serializes"),
        )];
        for (i, m) in self.masks.iter().enumerate() {
            out.push((manifest.files[i].clone(), png(DynamicImage::ImageLuma8(m.clone()))));
            out.push((
                format!("preview/{}", manifest.files[i]),
                png(DynamicImage::ImageRgb8(self.preview(i))),
            ));
        }
        if let Some(l) = labels {
            out.push(("labels.json".into(), l.to_json().into_bytes()));
        }
        out
    }

    /// The export as a zip in memory (what the browser downloads).
    pub fn to_zip(&self, labels: Option<&LabelSet>) -> Vec<u8> {
        let mut zip = zip::ZipWriter::new(Cursor::new(Vec::new()));
        let stored = SimpleFileOptions::default().compression_method(zip::CompressionMethod::Stored);
        for (name, bytes) in self.files(labels) {
            zip.start_file(name, stored)
                .expect("writing a zip into memory cannot fail");
            zip.write_all(&bytes).expect("writing a zip into memory cannot fail");
        }
        zip.finish()
            .expect("writing a zip into memory cannot fail")
            .into_inner()
    }

    /// Writes the export into a folder, creating it (and `preview/`) as needed.
    pub fn write_dir(&self, dir: &Path, labels: Option<&LabelSet>) -> Result<()> {
        std::fs::create_dir_all(dir.join("preview")).map_err(|e| SceneError::io(dir, e))?;
        for (name, bytes) in self.files(labels) {
            let path = dir.join(&name);
            std::fs::write(&path, bytes).map_err(|e| SceneError::io(path, e))?;
        }
        Ok(())
    }
}

/// The colour preview of `mask`: class colours, black for unknown ids.
fn preview_of(mask: &GrayImage, classes: &[ClassInfo]) -> RgbImage {
    RgbImage::from_fn(mask.width(), mask.height(), |x, y| {
        let c = mask.get_pixel(x, y).0[0] as usize;
        image::Rgb(classes.get(c).map(|k| k.color).unwrap_or([0, 0, 0]))
    })
}

/// Writes the same folder as [`MaskSet::write_dir`] one frame at a time, so that large masks
/// (`segment --source` at a capture's full resolution) need not all be held: `frame` writes
/// frame i's mask and preview as it comes, `finish` the manifest and the annotations.
pub struct MaskDirWriter {
    dir: std::path::PathBuf,
    classes: Vec<ClassInfo>,
    size: Option<(u32, u32)>,
    frames: usize,
}

impl MaskDirWriter {
    /// Creates `dir` (and `preview/`) as needed.
    pub fn new(dir: &Path, classes: Vec<ClassInfo>) -> Result<Self> {
        std::fs::create_dir_all(dir.join("preview")).map_err(|e| SceneError::io(dir, e))?;
        Ok(MaskDirWriter {
            dir: dir.to_path_buf(),
            classes,
            size: None,
            frames: 0,
        })
    }

    /// Writes the next frame's mask; every mask must have the first one's size.
    pub fn frame(&mut self, mask: &GrayImage) -> Result<()> {
        let name = mask_name(self.frames);
        let size = *self.size.get_or_insert(mask.dimensions());
        if mask.dimensions() != size {
            return Err(SceneError::invalid(
                self.dir.join(&name).display().to_string(),
                format!(
                    "mask is {} x {}, the first was {} x {}",
                    mask.width(),
                    mask.height(),
                    size.0,
                    size.1
                ),
            ));
        }
        for (path, img) in [
            (self.dir.join(&name), DynamicImage::ImageLuma8(mask.clone())),
            (
                self.dir.join("preview").join(&name),
                DynamicImage::ImageRgb8(preview_of(mask, &self.classes)),
            ),
        ] {
            std::fs::write(&path, png(img)).map_err(|e| SceneError::io(path, e))?;
        }
        self.frames += 1;
        Ok(())
    }

    /// Writes `classes.json` (and `labels.json`); returns the number of frames written.
    pub fn finish(self, labels: Option<&LabelSet>) -> Result<usize> {
        let (width, height) = self.size.unwrap_or((0, 0));
        let manifest = MasksManifest {
            format: MASKS_FORMAT.into(),
            version: MASKS_VERSION,
            frames: self.frames as u32,
            width,
            height,
            classes: self.classes,
            files: (0..self.frames).map(mask_name).collect(),
        };
        let mut files = vec![(
            MANIFEST.to_string(),
            serde_json::to_vec_pretty(&manifest).expect("manifest serializes"),
        )];
        if let Some(l) = labels {
            files.push(("labels.json".into(), l.to_json().into_bytes()));
        }
        for (name, bytes) in files {
            let path = self.dir.join(name);
            std::fs::write(&path, bytes).map_err(|e| SceneError::io(path, e))?;
        }
        Ok(self.frames)
    }
}

/// Reads masks written by `write_dir`, or a plain folder of `NNNNN.png` class-id images, for a
/// scene of `frames` frames of `width x height`.
pub fn read_masks(dir: &Path, frames: usize, width: u32, height: u32) -> Result<Vec<GrayImage>> {
    if dir.is_file() {
        let bytes = std::fs::read(dir).map_err(|e| SceneError::io(dir, e))?;
        return read_masks_zip(&bytes, &dir.display().to_string(), frames, width, height);
    }
    if !dir.is_dir() {
        return Err(SceneError::missing(
            dir.display().to_string(),
            "a folder (or zip) of masks",
        ));
    }
    (0..frames)
        .map(|i| {
            let path = dir.join(mask_name(i));
            let bytes = std::fs::read(&path)
                .map_err(|_| SceneError::missing(path.display().to_string(), format!("mask of frame {i}")))?;
            decode_mask(&bytes, &path.display().to_string(), width, height)
        })
        .collect()
}

/// Reads the masks out of an export zip.
pub fn read_masks_zip(bytes: &[u8], name: &str, frames: usize, width: u32, height: u32) -> Result<Vec<GrayImage>> {
    let mut zip = zip::ZipArchive::new(Cursor::new(bytes)).map_err(|source| SceneError::Zip {
        file: name.into(),
        source,
    })?;
    (0..frames)
        .map(|i| {
            let entry = mask_name(i);
            let at = format!("{name}:{entry}");
            let mut f = zip
                .by_name(&entry)
                .map_err(|_| SceneError::missing(&at, format!("mask of frame {i}")))?;
            let mut data = Vec::new();
            f.by_ref()
                .take(width as u64 * height as u64 * 4 + (1 << 20))
                .read_to_end(&mut data)
                .map_err(|e| SceneError::invalid(&at, e.to_string()))?;
            decode_mask(&data, &at, width, height)
        })
        .collect()
}

fn decode_mask(bytes: &[u8], at: &str, width: u32, height: u32) -> Result<GrayImage> {
    let img = image::load_from_memory(bytes).map_err(|source| SceneError::Image {
        file: at.into(),
        source,
    })?;
    let DynamicImage::ImageLuma8(m) = img else {
        return Err(SceneError::invalid(
            at,
            format!("mask must be an 8-bit single-channel PNG, got {:?}", img.color()),
        ));
    };
    if m.dimensions() != (width, height) {
        return Err(SceneError::invalid(
            at,
            format!(
                "mask is {} x {} but the scene's frames are {width} x {height}",
                m.width(),
                m.height()
            ),
        ));
    }
    Ok(m)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn set() -> MaskSet {
        MaskSet {
            classes: vec![
                ClassInfo {
                    name: "a".into(),
                    color: [1, 2, 3],
                },
                ClassInfo {
                    name: "b".into(),
                    color: [9, 8, 7],
                },
            ],
            masks: (0..3)
                .map(|i| GrayImage::from_fn(5, 4, |x, y| image::Luma([((x + y + i) % 2) as u8])))
                .collect(),
        }
    }

    #[test]
    fn zip_and_folder_round_trip() {
        let s = set();
        let zip = s.to_zip(Some(&LabelSet::new(s.classes.clone())));
        assert_eq!(read_masks_zip(&zip, "m.zip", 3, 5, 4).unwrap(), s.masks);
        let dir = std::env::temp_dir().join(format!("sf-masks-{}", std::process::id()));
        s.write_dir(&dir, None).unwrap();
        assert_eq!(read_masks(&dir, 3, 5, 4).unwrap(), s.masks);
        assert!(dir.join("preview/00002.png").is_file() && dir.join("classes.json").is_file());
        let err = read_masks(&dir, 4, 5, 4).unwrap_err().to_string();
        assert!(err.contains("00003.png") && err.contains("frame 3"), "{err}");
        let err = read_masks(&dir, 3, 6, 4).unwrap_err().to_string();
        assert!(err.contains("5 x 4"), "{err}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn writing_frame_by_frame_makes_the_same_folder() {
        let s = set();
        let labels = LabelSet::new(s.classes.clone());
        let base = std::env::temp_dir().join(format!("sf-mask-writer-{}", std::process::id()));
        let (whole, streamed) = (base.join("whole"), base.join("streamed"));
        s.write_dir(&whole, Some(&labels)).unwrap();
        let mut w = MaskDirWriter::new(&streamed, s.classes.clone()).unwrap();
        for m in &s.masks {
            w.frame(m).unwrap();
        }
        let err = w.frame(&GrayImage::new(3, 3)).unwrap_err().to_string();
        assert!(
            err.contains("00003.png") && err.contains("3 x 3") && err.contains("5 x 4"),
            "{err}"
        );
        assert_eq!(w.finish(Some(&labels)).unwrap(), 3);
        for (name, bytes) in s.files(Some(&labels)) {
            assert_eq!(std::fs::read(streamed.join(&name)).unwrap(), bytes, "{name}");
        }
        std::fs::remove_dir_all(&base).unwrap();
    }

    #[test]
    fn preview_uses_class_colours() {
        let s = set();
        assert_eq!(s.preview(0).get_pixel(0, 0).0, [1, 2, 3]);
        assert_eq!(s.preview(0).get_pixel(1, 0).0, [9, 8, 7]);
    }
}
