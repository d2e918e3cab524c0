//! One frame as the edge-aware steps see it (label spreading, refinement of rendered classes).
use half::f16;
use image::RgbImage;

use crate::scene::{DepthImage, Scene};

/// What edge-aware filters and walks follow: a frame's image and its measured depth, at the
/// resolution of the map they filter.
#[derive(Clone, Copy, Debug)]
pub struct Guide<'a> {
    pub rgb: &'a RgbImage,
    /// Raw depth values (any unit; only ratios are used), 0 = no reading.
    pub depth: Option<&'a DepthImage>,
    /// The frame's image feature codes, on their own (coarser) grid, where the archive has them.
    pub codes: Option<FrameCodes<'a>>,
}

/// One frame's feature codes: `height` x `width` cells of `dim` values, row-major.
#[derive(Clone, Copy, Debug)]
pub struct FrameCodes<'a> {
    pub width: usize,
    pub height: usize,
    pub dim: usize,
    pub values: &'a [f16],
}

impl FrameCodes<'_> {
    /// The codes at every pixel of a `width` x `height` image, interpolated bilinearly between
    /// cell centres (pixel-major, `dim` values per pixel).
    pub fn upsampled(&self, width: usize, height: usize) -> Vec<f32> {
        let (cw, ch, dim) = (self.width, self.height, self.dim);
        let mut out = vec![0f32; width * height * dim];
        if cw == 0 || ch == 0 || dim == 0 || self.values.len() != cw * ch * dim {
            return out;
        }
        let axis = |p: usize, pixels: usize, cells: usize| {
            let c = ((p as f32 + 0.5) * cells as f32 / pixels as f32 - 0.5).clamp(0.0, (cells - 1) as f32);
            let lo = c.floor() as usize;
            (lo, (lo + 1).min(cells - 1), c - lo as f32)
        };
        for y in 0..height {
            let (y0, y1, ty) = axis(y, height, ch);
            for x in 0..width {
                let (x0, x1, tx) = axis(x, width, cw);
                let at = |cx: usize, cy: usize, k: usize| f32::from(self.values[(cy * cw + cx) * dim + k]);
                for k in 0..dim {
                    let top = at(x0, y0, k) * (1.0 - tx) + at(x1, y0, k) * tx;
                    let bottom = at(x0, y1, k) * (1.0 - tx) + at(x1, y1, k) * tx;
                    out[(y * width + x) * dim + k] = top * (1.0 - ty) + bottom * ty;
                }
            }
        }
        out
    }
}

impl<'a> Guide<'a> {
    /// A frame seen by its colours alone: no depth, no feature codes.
    pub fn colour_only(rgb: &'a RgbImage) -> Guide<'a> {
        Guide {
            rgb,
            depth: None,
            codes: None,
        }
    }

    /// Frame `frame` of `scene`: its image and measured depth.
    pub fn of_frame(scene: &'a Scene, frame: usize) -> Option<Guide<'a>> {
        let f = scene.frames.get(frame)?;
        let codes = scene
            .features
            .as_ref()
            .filter(|c| frame < c.data.len() / c.values_per_frame().max(1))
            .map(|c| FrameCodes {
                width: c.width as usize,
                height: c.height as usize,
                dim: c.dim as usize,
                values: c.frame(frame),
            });
        Some(Guide {
            rgb: &f.rgb,
            depth: f.depth.as_ref(),
            codes,
        })
    }
}
