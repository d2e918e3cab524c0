//! `masks.apng`: the masks over their frames as one animated PNG, to look through a scene's
//! masks in any browser or image viewer without unpacking anything. Each frame is the frame's
//! colour with its mask's class colours blended over it, at most [`MAX_SIDE`] pixels on the long
//! side, shown for [`FRAME_DELAY_MS`]. APNG rather than a video: the `png` crate the archive
//! already uses writes it, and every browser plays it.
use image::{GrayImage, RgbImage};

use crate::labels::ClassInfo;

pub const FILE: &str = "masks.apng";
/// Longest side of the animation's frames: a preview, not the masks themselves.
pub const MAX_SIDE: u32 = 320;
/// How long each frame is shown.
pub const FRAME_DELAY_MS: u16 = 200;
/// Weight of the class colour over the frame's own colour.
const MASK_WEIGHT: f32 = 0.5;

/// The frames of the animation, collected as the masks come.
pub struct Animation {
    frames: Vec<RgbImage>,
    size: Option<(u32, u32)>,
}

impl Animation {
    pub fn new() -> Animation {
        Animation {
            frames: Vec::new(),
            size: None,
        }
    }

    /// Adds `mask` over `rgb` (resampled onto the mask's size when they differ: masks written at
    /// the capture's resolution).
    pub fn add_frame(&mut self, rgb: &RgbImage, mask: &GrayImage, classes: &[ClassInfo]) {
        let size = *self
            .size
            .get_or_insert_with(|| crate::scene::import::target_size(mask.dimensions(), Some(MAX_SIDE)));
        let filter = image::imageops::FilterType::Triangle;
        let rgb = image::imageops::resize(rgb, size.0, size.1, filter);
        let mask = image::imageops::resize(mask, size.0, size.1, image::imageops::FilterType::Nearest);
        let blended = RgbImage::from_fn(size.0, size.1, |x, y| {
            let p = rgb.get_pixel(x, y).0;
            let c = classes
                .get(mask.get_pixel(x, y).0[0] as usize)
                .map_or([0, 0, 0], |k| k.color);
            image::Rgb(std::array::from_fn(|i| {
                (p[i] as f32 * (1.0 - MASK_WEIGHT) + c[i] as f32 * MASK_WEIGHT).round() as u8
            }))
        });
        self.frames.push(blended);
    }

    /// The animated PNG, looping forever; `None` without frames.
    pub fn to_apng(&self) -> Option<Vec<u8>> {
        let (w, h) = self.size?;
        let mut out = Vec::new();
        let mut encoder = png::Encoder::new(&mut out, w, h);
        encoder.set_color(png::ColorType::Rgb);
        encoder.set_depth(png::BitDepth::Eight);
        encoder
            .set_animated(self.frames.len() as u32, 0)
            .expect("an animation of at least one frame");
        encoder
            .set_frame_delay(FRAME_DELAY_MS, 1000)
            .expect("a delay of whole milliseconds");
        let mut writer = encoder.write_header().expect("PNG encoding into memory cannot fail");
        for frame in &self.frames {
            writer
                .write_image_data(frame.as_raw())
                .expect("PNG encoding into memory cannot fail");
        }
        writer.finish().expect("PNG encoding into memory cannot fail");
        Some(out)
    }
}

impl Default for Animation {
    fn default() -> Self {
        Animation::new()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn classes() -> Vec<ClassInfo> {
        vec![
            ClassInfo {
                name: "background".into(),
                color: [0, 0, 255],
            },
            ClassInfo {
                name: "cup".into(),
                color: [255, 0, 0],
            },
        ]
    }

    #[test]
    fn frames_come_back_with_their_masks_over_them() {
        let mut a = Animation::new();
        assert!(a.to_apng().is_none());
        for i in 0..3u32 {
            let rgb = RgbImage::from_pixel(640, 480, image::Rgb([100, 100, 100]));
            let mask = GrayImage::from_fn(640, 480, |x, _| image::Luma([u8::from(x < 200 * (i + 1))]));
            a.add_frame(&rgb, &mask, &classes());
        }
        let apng = a.to_apng().unwrap();
        let mut reader = png::Decoder::new(std::io::Cursor::new(apng)).read_info().unwrap();
        let info = reader.info();
        assert_eq!((info.width, info.height), (320, 240));
        assert_eq!(
            info.animation_control.map(|c| (c.num_frames, c.num_plays)),
            Some((3, 0))
        );
        let mut buf = vec![0; reader.output_buffer_size().unwrap()];
        for i in 0..3u32 {
            reader.next_frame(&mut buf).unwrap();
            // Left of the frame's edge the cup's red over grey, right of it background blue.
            let at = |x: usize| &buf[(120 * 320 + x) * 3..(120 * 320 + x) * 3 + 3];
            assert_eq!(at(10), [178, 50, 50], "frame {i}");
            let edge = (100 * (i + 1)) as usize;
            if edge < 320 {
                assert_eq!(at(edge + 2), [50, 50, 178], "frame {i}");
            }
        }
    }
}
