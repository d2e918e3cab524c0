//! What an export holds beyond the class-id PNGs by index and by frame name, their previews,
//! `classes.json` and `labels.json` (always written): the formats asked for, and the
//! object-count cleanup applied to every mask before any of it is written.
use super::error::ExportError;

/// The formats an export may add.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Format {
    /// CVAT / PASCAL VOC segmentation layout under `voc/`.
    Voc,
    /// `coco.json`: compressed RLE per class per frame.
    Coco,
    /// `points.ply`: the labelled point cloud from the frames' depth.
    Ply,
    /// `masks.apng`: the masks over their frames as an animated PNG.
    Animation,
}

impl Format {
    pub const ALL: [Format; 4] = [Format::Voc, Format::Coco, Format::Ply, Format::Animation];

    /// The name the command line and the page's options use.
    pub fn name(self) -> &'static str {
        match self {
            Format::Voc => "voc",
            Format::Coco => "coco",
            Format::Ply => "ply",
            Format::Animation => "apng",
        }
    }

    /// What it is, for people.
    pub fn describe(self) -> &'static str {
        match self {
            Format::Voc => "CVAT / PASCAL VOC (palette PNGs + labelmap.txt)",
            Format::Coco => "COCO JSON (RLE per class per frame)",
            Format::Ply => "labelled point cloud (.ply, from depth)",
            Format::Animation => "the masks over the frames, animated (.apng)",
        }
    }
}

#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct ExportOptions {
    pub voc: bool,
    pub coco: bool,
    pub ply: bool,
    pub animation: bool,
    /// Keep only this many largest regions of each class but the first (autolabel's
    /// `--objects`; `super::objects`).
    pub objects: Option<u32>,
}

impl ExportOptions {
    pub fn with(formats: &[Format], objects: Option<u32>) -> ExportOptions {
        let mut o = ExportOptions {
            objects,
            ..ExportOptions::default()
        };
        for &f in formats {
            o.set(f, true);
        }
        o
    }

    pub fn has(&self, f: Format) -> bool {
        match f {
            Format::Voc => self.voc,
            Format::Coco => self.coco,
            Format::Ply => self.ply,
            Format::Animation => self.animation,
        }
    }

    pub fn set(&mut self, f: Format, on: bool) {
        match f {
            Format::Voc => self.voc = on,
            Format::Coco => self.coco = on,
            Format::Ply => self.ply = on,
            Format::Animation => self.animation = on,
        }
    }

    /// Refuses what cannot be written, before any mask is rendered: no objects at all, VOC
    /// with classes it cannot tell apart or name, a point cloud of a scene without depth.
    pub fn check(&self, classes: &[crate::labels::ClassInfo], has_depth: bool) -> Result<(), ExportError> {
        if self.objects == Some(0) {
            return Err(ExportError::NoObjects(0));
        }
        if self.voc {
            super::voc::check_classes(classes)?;
        }
        if self.ply && !has_depth {
            return Err(ExportError::NoDepth);
        }
        Ok(())
    }
}
