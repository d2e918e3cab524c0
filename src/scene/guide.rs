//! One frame as the edge-aware steps see it (label spreading, refinement of rendered classes).
use image::RgbImage;

use crate::scene::{DepthImage, Scene};

/// What edge-aware filters and walks follow: a frame's image and its measured depth, at the
/// resolution of the map they filter.
#[derive(Clone, Copy, Debug)]
pub struct Guide<'a> {
    pub rgb: &'a RgbImage,
    /// Raw depth values (any unit; only ratios are used), 0 = no reading.
    pub depth: Option<&'a DepthImage>,
}

impl<'a> Guide<'a> {
    /// Frame `frame` of `scene`: its image and measured depth.
    pub fn of_frame(scene: &'a Scene, frame: usize) -> Option<Guide<'a>> {
        let f = scene.frames.get(frame)?;
        Some(Guide {
            rgb: &f.rgb,
            depth: f.depth.as_ref(),
        })
    }
}
