use std::io::{Cursor, Read, Write};
use std::path::{Path, PathBuf};

use image::{DynamicImage, GrayImage, RgbImage};
use zip::write::SimpleFileOptions;

use super::error::ExportError;
use super::options::ExportOptions;
use super::writer::{ExportWriter, File, mask_name, preview_of};
use crate::labels::{ClassInfo, LabelSet};
use crate::scene::Scene;
use crate::scene::error::{Result, SceneError};

/// Dense predicted masks of every frame.
#[derive(Clone, Debug, PartialEq)]
pub struct MaskSet {
    pub classes: Vec<ClassInfo>,
    /// Class id per pixel, one image per frame.
    pub masks: Vec<GrayImage>,
}

impl MaskSet {
    /// The colour preview of frame `i`: class colours, black for unknown ids.
    pub fn preview(&self, i: usize) -> RgbImage {
        preview_of(&self.masks[i], &self.classes)
    }

    /// Every file of the export as (relative path, bytes): the frames' files in frame order,
    /// then the manifest, the annotations and the files of the formats in `options`. `scene`
    /// (the scene the masks are of, at any resolution) names the frames and gives the point
    /// cloud its depth.
    pub fn files(
        &self,
        labels: Option<&LabelSet>,
        options: &ExportOptions,
        scene: Option<&Scene>,
    ) -> Result<Vec<File>, ExportError> {
        let mut writer = ExportWriter::new(self.classes.clone(), options.clone(), scene)?;
        let mut out = Vec::new();
        for m in &self.masks {
            out.extend(writer.frame(&mut m.clone())?);
        }
        out.extend(writer.finish(labels)?);
        Ok(out)
    }

    /// The export as a zip in memory (what the browser downloads).
    pub fn to_zip(
        &self,
        labels: Option<&LabelSet>,
        options: &ExportOptions,
        scene: Option<&Scene>,
    ) -> Result<Vec<u8>, ExportError> {
        Ok(zip_files(self.files(labels, options, scene)?))
    }

    /// Writes the export into a folder, creating it (and the folders inside) as needed.
    pub fn write_dir(
        &self,
        dir: &Path,
        labels: Option<&LabelSet>,
        options: &ExportOptions,
        scene: Option<&Scene>,
    ) -> Result<(), ExportError> {
        write_files(dir, self.files(labels, options, scene)?)
    }
}

/// `files` as a zip in memory, in their order.
pub fn zip_files(files: Vec<File>) -> Vec<u8> {
    let mut zip = zip::ZipWriter::new(Cursor::new(Vec::new()));
    let stored = SimpleFileOptions::default().compression_method(zip::CompressionMethod::Stored);
    let deflated = SimpleFileOptions::default().compression_method(zip::CompressionMethod::Deflated);
    for (name, bytes) in files {
        // PNGs are compressed already; JSON, text and point clouds are not.
        let how = if name.ends_with(".png") { stored } else { deflated };
        zip.start_file(name, how)
            .expect("writing a zip into memory cannot fail");
        zip.write_all(&bytes).expect("writing a zip into memory cannot fail");
    }
    zip.finish()
        .expect("writing a zip into memory cannot fail")
        .into_inner()
}

/// Writes `files` under `dir`, creating the folders they need.
fn write_files(dir: &Path, files: Vec<File>) -> Result<(), ExportError> {
    for (name, bytes) in files {
        let path = dir.join(&name);
        if let Some(parent) = path.parent() {
            std::fs::create_dir_all(parent).map_err(|e| SceneError::io(parent, e))?;
        }
        std::fs::write(&path, bytes).map_err(|e| SceneError::io(path, e))?;
    }
    Ok(())
}

/// Writes the same folder as [`MaskSet::write_dir`] one frame at a time, so that large masks
/// (`segment --source` at a capture's full resolution) need not all be held: `frame` writes
/// frame i's files as it comes, `finish` the manifest, the annotations and the files that
/// cover every frame.
pub struct MaskDirWriter<'a> {
    dir: PathBuf,
    writer: ExportWriter<'a>,
}

impl<'a> MaskDirWriter<'a> {
    /// Creates `dir` as needed; `options` and `scene` as for [`MaskSet::files`].
    pub fn new(
        dir: &Path,
        classes: Vec<ClassInfo>,
        options: &ExportOptions,
        scene: Option<&'a Scene>,
    ) -> Result<Self, ExportError> {
        let writer = ExportWriter::new(classes, options.clone(), scene)?;
        std::fs::create_dir_all(dir).map_err(|e| SceneError::io(dir, e))?;
        Ok(MaskDirWriter {
            dir: dir.to_path_buf(),
            writer,
        })
    }

    /// Writes the next frame's mask (every mask must have the first one's size), cleaned in
    /// place first when the options ask for it.
    pub fn frame(&mut self, mask: &mut GrayImage) -> Result<(), ExportError> {
        let files = self.writer.frame(mask).map_err(|e| match e {
            // Name the file as it is on disk.
            ExportError::MaskSize {
                file,
                got_width,
                got_height,
                width,
                height,
            } => ExportError::MaskSize {
                file: self.dir.join(file).display().to_string(),
                got_width,
                got_height,
                width,
                height,
            },
            e => e,
        })?;
        write_files(&self.dir, files)
    }

    /// Writes `classes.json`, `labels.json` and the formats' files covering every frame;
    /// returns the number of frames written.
    pub fn finish(self, labels: Option<&LabelSet>) -> Result<usize, ExportError> {
        let frames = self.writer.frames();
        write_files(&self.dir, self.writer.finish(labels)?)?;
        Ok(frames)
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
        let none = ExportOptions::default();
        let zip = s.to_zip(Some(&LabelSet::new(s.classes.clone())), &none, None).unwrap();
        assert_eq!(read_masks_zip(&zip, "m.zip", 3, 5, 4).unwrap(), s.masks);
        let dir = std::env::temp_dir().join(format!("sf-masks-{}", std::process::id()));
        s.write_dir(&dir, None, &none, None).unwrap();
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
        let scene = crate::scene::demo::demo_scene(&crate::scene::demo::DemoOptions {
            seed: 1,
            width: 24,
            height: 18,
            frames: 24,
        })
        .unwrap();
        let s = MaskSet {
            classes: scene.classes.clone(),
            masks: scene.frames.iter().map(|f| f.gt.clone().unwrap()).collect(),
        };
        let all = ExportOptions::with(&crate::export::Format::ALL, Some(2));
        let labels = LabelSet::new(s.classes.clone());
        let base = std::env::temp_dir().join(format!("sf-mask-writer-{}", std::process::id()));
        let (whole, streamed) = (base.join("whole"), base.join("streamed"));
        s.write_dir(&whole, Some(&labels), &all, Some(&scene)).unwrap();
        let mut w = MaskDirWriter::new(&streamed, s.classes.clone(), &all, Some(&scene)).unwrap();
        for m in &s.masks {
            w.frame(&mut m.clone()).unwrap();
        }
        let err = w.frame(&mut GrayImage::new(3, 3)).unwrap_err().to_string();
        assert!(
            err.contains("00024.png") && err.contains("3 x 3") && err.contains("24 x 18"),
            "{err}"
        );
        assert_eq!(w.finish(Some(&labels)).unwrap(), 24);
        let files = s.files(Some(&labels), &all, Some(&scene)).unwrap();
        assert!(files.iter().any(|(n, _)| n == "points.ply"));
        for (name, bytes) in files {
            assert_eq!(std::fs::read(streamed.join(&name)).unwrap(), bytes, "{name}");
            assert_eq!(std::fs::read(whole.join(&name)).unwrap(), bytes, "{name}");
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
