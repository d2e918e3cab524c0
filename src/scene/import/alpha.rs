//! `--alpha-gt`: a NeRF capture's alpha channel as 2-class ground truth. NeRF-synthetic renders
//! an object on a transparent background, so alpha is an exact object mask; pixels partly
//! covered (0 < alpha < 255, the antialiased boundary) belong to neither class and are void.
use std::path::Path;

use image::{GrayImage, RgbImage};

use super::frames::Prepare;
use super::images::decode;
use crate::scene::error::{Result, SceneError};
use crate::scene::{GT_VOID, Scene};

/// Class ids of fully transparent and fully opaque pixels.
const BACKGROUND: u8 = 0;
const OBJECT: u8 = 1;

/// Reads each frame's ground truth from the alpha of its own colour image (the frame's `gt`
/// path is the colour image).
pub(super) struct AlphaGt;

impl Prepare for AlphaGt {
    fn rgb(&self, _frame: usize, rgb: RgbImage) -> Result<RgbImage> {
        Ok(rgb)
    }

    fn gt(&self, _frame: usize, path: &Path, _native: (u32, u32)) -> Result<GrayImage> {
        let img = decode(path)?;
        if !img.color().has_alpha() {
            return Err(SceneError::invalid(
                path.display().to_string(),
                format!(
                    "--alpha-gt reads ground truth from alpha, but this image has no alpha channel ({:?})",
                    img.color()
                ),
            ));
        }
        Ok(classes_of_alpha(&img.into_rgba8()))
    }
}

/// Background where alpha is 0, object where it is 255, void between.
fn classes_of_alpha(rgba: &image::RgbaImage) -> GrayImage {
    GrayImage::from_fn(rgba.width(), rgba.height(), |x, y| {
        image::Luma([match rgba.get_pixel(x, y).0[3] {
            0 => BACKGROUND,
            255 => OBJECT,
            _ => GT_VOID,
        }])
    })
}

/// What `--alpha-gt` made of the scene, for the user: classes, and how much is void.
pub(super) fn alpha_gt_report(scene: &Scene, names: &[String; 2]) -> String {
    let mut counts = [0usize; 3];
    for gt in scene.frames.iter().filter_map(|f| f.gt.as_ref()) {
        for p in gt.pixels() {
            counts[match p.0[0] {
                BACKGROUND => 0,
                OBJECT => 1,
                _ => 2,
            }] += 1;
        }
    }
    let total = counts.iter().sum::<usize>().max(1) as f64;
    let pct = |n: usize| 100.0 * n as f64 / total;
    format!(
        "ground truth from alpha (--alpha-gt): alpha 0 = {} ({:.1} %), 255 = {} ({:.1} %), between = void ({:.1} %)",
        names[0],
        pct(counts[0]),
        names[1],
        pct(counts[1]),
        pct(counts[2])
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn partial_alpha_is_void() {
        let rgba = image::RgbaImage::from_fn(3, 1, |x, _| image::Rgba([9, 9, 9, [0, 128, 255][x as usize]]));
        let gt = classes_of_alpha(&rgba);
        assert_eq!(gt.as_raw(), &vec![BACKGROUND, GT_VOID, OBJECT]);
    }
}
