//! Nearest-pixel resampling, the one convention of the crate: output pixel `x` (centre
//! `x + 0.5`) takes the source pixel under source coordinate `(x + 0.5) · from / to`, the
//! mapping `Intrinsics::scaled` assumes. Depth and class ids are resampled this way, never
//! interpolated (interpolating depth would invent surfaces between foreground and background,
//! interpolating class ids would invent classes).
use image::{ImageBuffer, Pixel};

/// The source pixel (along one axis of `from` pixels) whose area holds the centre of output
/// pixel `dst` (of `to`): `floor((dst + 0.5) · from / to)`, in exact integer arithmetic.
pub fn nearest_source(dst: u32, from: u32, to: u32) -> u32 {
    let s = (2 * u64::from(dst) + 1) * u64::from(from) / (2 * u64::from(to.max(1)));
    (s as u32).min(from.saturating_sub(1))
}

/// `img` resampled to `to` (width, height) at the nearest pixel centre.
pub fn resize_nearest<P: Pixel>(
    img: &ImageBuffer<P, Vec<P::Subpixel>>,
    to: (u32, u32),
) -> ImageBuffer<P, Vec<P::Subpixel>> {
    let (w, h) = img.dimensions();
    if (w, h) == to {
        return img.clone();
    }
    let xs: Vec<u32> = (0..to.0).map(|x| nearest_source(x, w, to.0)).collect();
    let ys: Vec<u32> = (0..to.1).map(|y| nearest_source(y, h, to.1)).collect();
    ImageBuffer::from_fn(to.0, to.1, |x, y| *img.get_pixel(xs[x as usize], ys[y as usize]))
}

#[cfg(test)]
mod tests {
    use super::*;
    use image::{GrayImage, Luma};

    #[test]
    fn output_centres_fall_on_the_source_pixel_under_them() {
        // Halving: output pixel 0 covers source pixels 0..2, its centre (1.0) is on pixel 1.
        assert_eq!(
            (0..4).map(|x| nearest_source(x, 8, 4)).collect::<Vec<_>>(),
            [1, 3, 5, 7]
        );
        // Doubling: each source pixel twice.
        assert_eq!(
            (0..6).map(|x| nearest_source(x, 3, 6)).collect::<Vec<_>>(),
            [0, 0, 1, 1, 2, 2]
        );
        // A ratio that is not whole: 5 -> 3 samples at 0.83, 2.5, 4.17.
        assert_eq!((0..3).map(|x| nearest_source(x, 5, 3)).collect::<Vec<_>>(), [0, 2, 4]);
        assert_eq!(nearest_source(0, 1, 100), 0);
    }

    #[test]
    fn resizing_never_mixes_values() {
        let img = GrayImage::from_fn(4, 4, |x, y| Luma([if (x + y) % 2 == 0 { 200 } else { 0 }]));
        let half = resize_nearest(&img, (2, 2));
        assert_eq!(half.get_pixel(0, 0), img.get_pixel(1, 1));
        let up = resize_nearest(&img, (8, 6));
        assert!(up.pixels().all(|p| p.0[0] == 200 || p.0[0] == 0));
        assert_eq!(up.get_pixel(7, 5), img.get_pixel(3, 3));
        assert_eq!(resize_nearest(&img, (4, 4)), img);
    }
}
