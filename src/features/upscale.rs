//! Running an extractor on upscaled frames. Networks trained on ImageNet see objects at about
//! 224 pixels; on small frames (the 80 x 60 demo) their receptive fields cover the whole scene,
//! so the packer enlarges such frames by a whole factor first (a whole factor keeps the feature
//! grid aligned with the frame's pixels).
use image::RgbImage;
use image::imageops::FilterType;

use super::{Extractor, FeatureError, FeatureMap};

/// The whole factor that brings the shorter side of a `width` x `height` frame to at least
/// `min_side` (1 when it already is).
pub fn upscale_factor(width: u32, height: u32, min_side: u32) -> u32 {
    min_side.div_ceil(width.min(height).max(1)).max(1)
}

/// `inner` run on frames enlarged `factor` times (bilinear). Give `inner` a stride `factor`
/// times the wanted one, so the grid per original pixel stays as asked.
pub struct Upscaled<E> {
    pub inner: E,
    pub factor: u32,
}

impl<E: Extractor> Extractor for Upscaled<E> {
    fn describe(&self) -> String {
        match self.factor {
            0 | 1 => self.inner.describe(),
            k => format!("{} on frames upscaled x{k}", self.inner.describe()),
        }
    }

    fn extract(&self, rgb: &RgbImage) -> Result<FeatureMap, FeatureError> {
        if self.factor <= 1 {
            return self.inner.extract(rgb);
        }
        let (w, h) = (rgb.width() * self.factor, rgb.height() * self.factor);
        self.inner
            .extract(&image::imageops::resize(rgb, w, h, FilterType::Triangle))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::features::Baseline;

    #[test]
    fn factor_brings_the_short_side_to_the_minimum() {
        assert_eq!(upscale_factor(80, 60, 224), 4);
        assert_eq!(upscale_factor(160, 120, 224), 2);
        assert_eq!(upscale_factor(640, 480, 224), 1);
        assert_eq!(upscale_factor(0, 0, 224), 224);
    }

    #[test]
    fn upscaled_extractor_keeps_the_grid_per_original_pixel() {
        let rgb = RgbImage::from_fn(20, 10, |x, y| image::Rgb([(x * 12) as u8, (y * 25) as u8, 90]));
        let plain = Baseline::with_stride(2).extract(&rgb).unwrap();
        let up = Upscaled {
            inner: Baseline::with_stride(4),
            factor: 2,
        };
        let big = up.extract(&rgb).unwrap();
        assert_eq!((big.width, big.height, big.dim), (plain.width, plain.height, plain.dim));
        assert!(up.describe().ends_with("on frames upscaled x2"), "{}", up.describe());
    }
}
