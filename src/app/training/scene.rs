//! The scene the field trains on: the loaded one, or a copy at a fraction of its resolution.
//! Training cost does not depend on resolution (a batch is a fixed number of rays), but every
//! render of the live mask and the masks download render every pixel: on a CPU rasterizer a
//! full 160 x 120 frame takes tens of seconds, a quarter-size one a few. Masks come back at
//! the training resolution and are enlarged (nearest pixel centre, `scene::resample`) for display and download.
use image::imageops::{self, FilterType};

use crate::scene::resample::resize_nearest;
use crate::scene::{Frame, Scene};

/// Pixels per frame the field renders on a software rasterizer, at most, when the page picks
/// the resolution itself.
const SOFTWARE_PIXEL_BUDGET: u32 = 2000;
/// On a GPU: full resolution up to about 640 x 480.
const GPU_PIXEL_BUDGET: u32 = 320_000;

/// The downscale factor (1 = full resolution) for a `width x height` scene.
pub fn auto_factor(width: u32, height: u32, software: bool) -> u32 {
    let budget = if software {
        SOFTWARE_PIXEL_BUDGET
    } else {
        GPU_PIXEL_BUDGET
    };
    let mut factor = 1;
    while (width / factor) * (height / factor) > budget && width / (factor * 2) >= 16 && height / (factor * 2) >= 16 {
        factor *= 2;
    }
    factor
}

/// `scene` with frames `factor` times smaller on each axis (at least 1 x 1). Colour is
/// averaged; depth and ground truth take the nearest pixel, since averaging depth across an
/// edge or class ids makes values that exist nowhere. The feature codes stay (they are looked
/// up by position in the frame, whatever its size) unless `keep_codes` is false.
pub fn downscale(scene: &Scene, factor: u32, keep_codes: bool) -> Scene {
    if factor <= 1 {
        let mut s = scene.clone();
        s.labels = None;
        return s;
    }
    let (w, h) = ((scene.width / factor).max(1), (scene.height / factor).max(1));
    Scene {
        width: w,
        height: h,
        intrinsics: scene.intrinsics.scaled((scene.width, scene.height), (w, h)),
        frames: scene
            .frames
            .iter()
            .map(|f| Frame {
                pose: f.pose,
                rgb: imageops::resize(&f.rgb, w, h, FilterType::Triangle),
                depth: f.depth.as_ref().map(|d| resize_nearest(d, (w, h))),
                gt: f.gt.as_ref().map(|g| resize_nearest(g, (w, h))),
                source: f.source.clone(),
            })
            .collect(),
        depth_scale: scene.depth_scale,
        bounds: scene.bounds,
        classes: scene.classes.clone(),
        features: if keep_codes { scene.features.clone() } else { None },
        labels: None,
        provenance: scene.provenance.clone(),
    }
}

/// A class map at training resolution, enlarged to `width x height` (nearest).
pub fn upscale_mask(mask: image::GrayImage, width: u32, height: u32) -> image::GrayImage {
    if mask.dimensions() == (width, height) {
        mask
    } else {
        resize_nearest(&mask, (width, height))
    }
}
