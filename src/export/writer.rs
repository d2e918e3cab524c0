//! The files of an export, frame by frame: what the folder writer (`segment`, `export`) and the
//! page's zip both write, so the two cannot drift apart. Per frame: the class-id PNG by index
//! and by the frame's capture name, its colour preview, and the formats asked for; at the end,
//! the class manifest, the annotations and the formats' files that cover every frame.
use image::{DynamicImage, GrayImage, ImageFormat};

use super::animation::{self, Animation};
use super::coco::{self, CocoBuilder};
use super::error::ExportError;
use super::manifest::{MASKS_FORMAT, MASKS_VERSION, MasksManifest};
use super::names::frame_names;
use super::options::ExportOptions;
use super::ply::{self, PointCloud};
use super::{objects, voc};
use crate::labels::{ClassInfo, LabelSet};
use crate::scene::Scene;

pub const MANIFEST: &str = "classes.json";
pub const BY_NAME_DIR: &str = "by-name";

/// A file of the export: its path inside the folder or zip (`/`-separated) and its bytes.
pub type File = (String, Vec<u8>);

pub fn mask_name(i: usize) -> String {
    format!("{i:05}.png")
}

pub fn png(img: DynamicImage) -> Vec<u8> {
    let mut out = std::io::Cursor::new(Vec::new());
    img.write_to(&mut out, ImageFormat::Png)
        .expect("PNG encoding into memory cannot fail");
    out.into_inner()
}

/// The colour preview of `mask`: class colours, black for unknown ids.
pub fn preview_of(mask: &GrayImage, classes: &[ClassInfo]) -> image::RgbImage {
    image::RgbImage::from_fn(mask.width(), mask.height(), |x, y| {
        let c = mask.get_pixel(x, y).0[0] as usize;
        image::Rgb(classes.get(c).map(|k| k.color).unwrap_or([0, 0, 0]))
    })
}

/// Makes the files of an export as its masks come.
pub struct ExportWriter<'a> {
    classes: Vec<ClassInfo>,
    options: ExportOptions,
    /// The scene the masks are of: names the frames, and gives the point cloud its depth.
    scene: Option<&'a Scene>,
    /// The frames' names (`super::names`); empty without a scene.
    names: Vec<String>,
    size: Option<(u32, u32)>,
    frames: usize,
    coco: Option<CocoBuilder>,
    points: Option<PointCloud<'a>>,
    animation: Option<Animation>,
}

impl<'a> ExportWriter<'a> {
    /// Checks `options` against `classes` and `scene` before any mask is rendered.
    pub fn new(classes: Vec<ClassInfo>, options: ExportOptions, scene: Option<&'a Scene>) -> Result<Self, ExportError> {
        if options.ply && scene.is_none() {
            return Err(ExportError::NoScene);
        }
        if options.animation && scene.is_none() {
            return Err(ExportError::NoFrames);
        }
        options.check(&classes, scene.is_some_and(Scene::has_depth))?;
        let names = scene.map_or_else(Vec::new, |s| {
            let sources: Vec<Option<&str>> = s.frames.iter().map(|f| f.source.as_deref()).collect();
            frame_names(&sources)
        });
        let coco = options.coco.then(|| {
            let of = scene
                .map(|s| s.provenance.source.as_str())
                .filter(|s| !s.is_empty())
                .map_or(String::new(), |s| format!(" of {s}"));
            CocoBuilder::new(&classes, format!("segmentation masks{of}, made with scribblefield"))
        });
        let points = if options.ply { scene.map(PointCloud::new) } else { None };
        let animation = options.animation.then(Animation::new);
        Ok(ExportWriter {
            classes,
            options,
            scene,
            names,
            size: None,
            frames: 0,
            coco,
            points,
            animation,
        })
    }

    /// The next frame's mask: cleaned in place (`ExportOptions::objects`), so the caller can
    /// score what is written; returns the frame's files.
    pub fn frame(&mut self, mask: &mut GrayImage) -> Result<Vec<File>, ExportError> {
        let i = self.frames;
        let index_name = mask_name(i);
        let (width, height) = *self.size.get_or_insert(mask.dimensions());
        if mask.dimensions() != (width, height) {
            return Err(ExportError::MaskSize {
                file: index_name,
                got_width: mask.width(),
                got_height: mask.height(),
                width,
                height,
            });
        }
        if let Some(scene) = self.scene
            && i >= scene.frames.len()
        {
            return Err(ExportError::FrameCount {
                count: i + 1,
                frames: scene.frames.len(),
            });
        }
        if self.options.voc || self.options.coco || self.options.ply {
            self.check_ids(i, mask)?;
        }
        if let Some(keep) = self.options.objects {
            objects::keep_largest(mask, keep);
        }
        let ids = png(DynamicImage::ImageLuma8(mask.clone()));
        let mut files = vec![
            (index_name.clone(), ids.clone()),
            (
                format!("preview/{index_name}"),
                png(DynamicImage::ImageRgb8(preview_of(mask, &self.classes))),
            ),
        ];
        let name = self.names.get(i).cloned();
        if let Some(name) = &name {
            files.push((format!("{BY_NAME_DIR}/{name}.png"), ids));
        }
        let item = name.unwrap_or_else(|| format!("{i:05}"));
        if self.options.voc {
            files.push((
                format!("{}/{}/{item}.png", voc::DIR, voc::CLASS_DIR),
                voc::palette_png(mask, &self.classes),
            ));
        }
        if let Some(coco) = &mut self.coco {
            let file_name = self
                .scene
                .and_then(|s| s.frames[i].source.clone())
                .unwrap_or_else(|| index_name.clone());
            coco.frame(i, file_name, mask);
        }
        if let Some(points) = &mut self.points {
            points.add_frame(i, mask);
        }
        if let (Some(animation), Some(scene)) = (&mut self.animation, self.scene) {
            animation.add_frame(&scene.frames[i].rgb, mask, &self.classes);
        }
        self.frames += 1;
        Ok(files)
    }

    /// Frames written so far.
    pub fn frames(&self) -> usize {
        self.frames
    }

    fn check_ids(&self, frame: usize, mask: &GrayImage) -> Result<(), ExportError> {
        let classes = self.classes.len();
        match mask.enumerate_pixels().find(|(_, _, p)| p.0[0] as usize >= classes) {
            Some((x, y, p)) => Err(ExportError::UnknownClass {
                frame,
                id: p.0[0],
                x,
                y,
                classes,
            }),
            None => Ok(()),
        }
    }

    /// The files that cover every frame: `classes.json`, `labels` as `labels.json`, and the
    /// formats' manifests, annotation file and point cloud.
    pub fn finish(self, labels: Option<&LabelSet>) -> Result<Vec<File>, ExportError> {
        if let Some(scene) = self.scene
            && self.frames != scene.frames.len()
        {
            return Err(ExportError::FrameCount {
                count: self.frames,
                frames: scene.frames.len(),
            });
        }
        let (width, height) = self.size.unwrap_or((0, 0));
        let by_name = self.names.iter().map(|n| format!("{BY_NAME_DIR}/{n}.png")).collect();
        let manifest = MasksManifest {
            format: MASKS_FORMAT.into(),
            version: MASKS_VERSION,
            frames: self.frames as u32,
            width,
            height,
            classes: self.classes.clone(),
            files: (0..self.frames).map(mask_name).collect(),
            by_name,
            objects: self.options.objects,
        };
        let mut files = vec![(
            MANIFEST.to_string(),
            serde_json::to_vec_pretty(&manifest).expect("manifest serializes"),
        )];
        if let Some(l) = labels {
            files.push(("labels.json".into(), l.to_json().into_bytes()));
        }
        if self.options.voc {
            files.push((
                format!("{}/{}", voc::DIR, voc::LABELMAP),
                voc::labelmap(&self.classes).into_bytes(),
            ));
            let mut list = String::new();
            for i in 0..self.frames {
                list.push_str(&self.names.get(i).cloned().unwrap_or_else(|| format!("{i:05}")));
                list.push('\n');
            }
            files.push((format!("{}/{}", voc::DIR, voc::SUBSET_LIST), list.into_bytes()));
        }
        if let Some(coco) = &self.coco {
            files.push((coco::FILE.into(), coco.to_json()));
        }
        if let Some(points) = &self.points {
            files.push((ply::FILE.into(), points.to_ply(&self.classes)));
        }
        if let Some(apng) = self.animation.as_ref().and_then(Animation::to_apng) {
            files.push((animation::FILE.into(), apng));
        }
        Ok(files)
    }
}
