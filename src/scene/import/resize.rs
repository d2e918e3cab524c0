//! Downscaling that keeps colour, depth and class ids consistent with each other and with the
//! scaled intrinsics: colour is filtered, depth and class ids are sampled at the nearest pixel
//! centre (interpolating depth would invent surfaces between foreground and background, and
//! interpolating class ids would invent classes).
use image::imageops::FilterType;
use image::{ImageBuffer, Luma, RgbImage};

/// Output size for an image of `size` whose longest side may be at most `max_side`: only ever
/// smaller, aspect ratio kept, at least one pixel per side.
pub fn target_size(size: (u32, u32), max_side: Option<u32>) -> (u32, u32) {
    let (w, h) = size;
    let longest = w.max(h);
    match max_side {
        Some(m) if m > 0 && longest > m => {
            let s = m as f64 / longest as f64;
            let side = |v: u32| ((v as f64 * s).round() as u32).clamp(1, m);
            (side(w), side(h))
        }
        _ => (w, h),
    }
}

pub fn resize_rgb(img: &RgbImage, to: (u32, u32)) -> RgbImage {
    if img.dimensions() == to {
        return img.clone();
    }
    image::imageops::resize(img, to.0, to.1, FilterType::Triangle)
}

/// Nearest-pixel-centre resampling, the one the page and the masks use too.
pub use crate::scene::resample::resize_nearest;

/// Whether two image sizes have the same aspect ratio (to within a pixel of rounding), so one
/// can be resampled onto the other without distorting it.
pub fn same_aspect(a: (u32, u32), b: (u32, u32)) -> bool {
    let (aw, ah, bw, bh) = (a.0 as f64, a.1 as f64, b.0 as f64, b.1 as f64);
    // Compare the heights each width implies; allow one pixel of rounding on the smaller image.
    let implied = aw * bh / bw;
    let tolerance = (ah / bh).max(1.0);
    (implied - ah).abs() <= tolerance
}

/// A 16-bit single-channel label mask.
pub type Mask16 = ImageBuffer<Luma<u16>, Vec<u16>>;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn target_only_shrinks_and_keeps_aspect() {
        assert_eq!(target_size((640, 480), Some(320)), (320, 240));
        assert_eq!(target_size((640, 480), Some(1000)), (640, 480));
        assert_eq!(target_size((480, 640), Some(100)), (75, 100));
        assert_eq!(target_size((640, 480), None), (640, 480));
        assert_eq!(target_size((5000, 1), Some(10)), (10, 1));
    }

    #[test]
    fn nearest_never_mixes_values() {
        let img: Mask16 = ImageBuffer::from_fn(4, 4, |x, y| Luma([if (x + y) % 2 == 0 { 1000 } else { 0 }]));
        let half = resize_nearest(&img, (2, 2));
        assert!(half.pixels().all(|p| p.0[0] == 1000 || p.0[0] == 0));
        // Output pixel 0 covers source pixels 0..2; its centre (1.0) falls on source pixel 1.
        assert_eq!(half.get_pixel(0, 0).0[0], img.get_pixel(1, 1).0[0]);
        let up = resize_nearest(&img, (8, 8));
        assert_eq!(up.get_pixel(7, 7), img.get_pixel(3, 3));
    }

    #[test]
    fn aspect_comparison_allows_rounding() {
        assert!(same_aspect((640, 480), (256, 192)));
        assert!(same_aspect((1920, 1440), (256, 192)));
        assert!(same_aspect((641, 480), (320, 240)));
        assert!(!same_aspect((640, 480), (640, 360)));
    }
}
