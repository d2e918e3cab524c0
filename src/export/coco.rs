//! The masks as a COCO annotations file: one image per frame, one category per class, and one
//! annotation per class present in a frame, its pixels as pycocotools' compressed RLE
//! (`{"size": [height, width], "counts": "..."}`, see [`super::rle`]), with `iscrowd` 0 as
//! COCO-Stuff writes its per-class masks. Category ids are class ids + 1: COCO keeps 0 for
//! "no category".
use image::GrayImage;
use serde::{Deserialize, Serialize};

use super::rle;
use crate::labels::ClassInfo;

pub const FILE: &str = "coco.json";

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Coco {
    pub info: Info,
    pub licenses: Vec<serde_json::Value>,
    pub images: Vec<Image>,
    pub annotations: Vec<Annotation>,
    pub categories: Vec<Category>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Info {
    pub description: String,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Image {
    /// The frame's index + 1.
    pub id: u64,
    /// The frame's name in its capture (`source` in scene.json), else its index mask's name.
    pub file_name: String,
    pub width: u32,
    pub height: u32,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Annotation {
    pub id: u64,
    pub image_id: u64,
    pub category_id: u64,
    pub segmentation: Rle,
    pub area: u64,
    /// `[x, y, width, height]` of the class's pixels.
    pub bbox: [u32; 4],
    pub iscrowd: u8,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Rle {
    /// `[height, width]`.
    pub size: [u32; 2],
    pub counts: String,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Category {
    pub id: u64,
    pub name: String,
    pub supercategory: String,
}

/// Builds the file frame by frame, so that masks need not all be held.
pub struct CocoBuilder {
    coco: Coco,
}

impl CocoBuilder {
    pub fn new(classes: &[ClassInfo], description: String) -> CocoBuilder {
        let categories = classes
            .iter()
            .enumerate()
            .map(|(i, c)| Category {
                id: i as u64 + 1,
                name: c.name.clone(),
                supercategory: String::new(),
            })
            .collect();
        CocoBuilder {
            coco: Coco {
                info: Info { description },
                licenses: Vec::new(),
                images: Vec::new(),
                annotations: Vec::new(),
                categories,
            },
        }
    }

    /// Adds frame `index`, named `file_name`, with its class-id `mask`.
    pub fn frame(&mut self, index: usize, file_name: String, mask: &GrayImage) {
        let (w, h) = mask.dimensions();
        let image_id = index as u64 + 1;
        self.coco.images.push(Image {
            id: image_id,
            file_name,
            width: w,
            height: h,
        });
        let mut area = [0u64; 256];
        for p in mask.pixels() {
            area[p.0[0] as usize] += 1;
        }
        let classes = self.coco.categories.len();
        for (class, &area) in area.iter().enumerate().take(classes) {
            if area == 0 {
                continue;
            }
            let is_class = |x: u32, y: u32| mask.get_pixel(x, y).0[0] as usize == class;
            let counts = rle::runs(w, h, is_class);
            self.coco.annotations.push(Annotation {
                id: self.coco.annotations.len() as u64 + 1,
                image_id,
                category_id: class as u64 + 1,
                segmentation: Rle {
                    size: [h, w],
                    counts: rle::to_string(&counts),
                },
                area,
                bbox: rle::bbox(w, h, is_class),
                iscrowd: 0,
            });
        }
    }

    pub fn to_json(&self) -> Vec<u8> {
        serde_json::to_vec(&self.coco).expect("COCO annotations serialize")
    }
}
