//! Turning a pointer drag into a stroke: points snapped to the share codec's grid (so links
//! carry exactly what was drawn), spaced so a slow drag does not record thousands of points.
use super::Stroke;
use super::share::snap;

/// Smallest brush radius in pixels (the rasterizer's pixel-centre test needs half a pixel to
/// cover anything on a single click).
pub const MIN_RADIUS: f32 = 0.5;
/// Largest brush radius in pixels: the limit every label set is checked against.
pub const MAX_RADIUS: f32 = crate::scene::label_set::limits::MAX_RADIUS;

/// A stroke being drawn.
#[derive(Clone, Debug, PartialEq)]
pub struct StrokeBuilder {
    stroke: Stroke,
    /// The frame's size: points are kept within a radius of it.
    bounds: [f32; 2],
}

impl StrokeBuilder {
    /// Starts a stroke of `class` (`None` erases) with brush `radius` on a `width x height`
    /// frame, at `start` (frame pixel coordinates).
    pub fn new(class: Option<u16>, radius: f32, width: u32, height: u32, start: [f32; 2]) -> StrokeBuilder {
        let mut b = StrokeBuilder {
            stroke: Stroke {
                class,
                radius: snap(radius.clamp(MIN_RADIUS, MAX_RADIUS)),
                points: Vec::new(),
            },
            bounds: [width as f32, height as f32],
        };
        b.extend(start);
        b
    }

    fn clamp(&self, p: [f32; 2]) -> [f32; 2] {
        let r = self.stroke.radius;
        [0, 1].map(|a| snap(p[a].clamp(-r, self.bounds[a] + r)))
    }

    /// Adds the pointer's next position, unless it is within a fraction of the brush of the
    /// last point (the stroke would look the same without it). Returns whether it was added.
    pub fn extend(&mut self, p: [f32; 2]) -> bool {
        if !(p[0].is_finite() && p[1].is_finite()) {
            return false;
        }
        let p = self.clamp(p);
        let spacing = (self.stroke.radius * 0.3).max(0.5);
        if let Some(last) = self.stroke.points.last()
            && (p[0] - last[0]).hypot(p[1] - last[1]) < spacing
        {
            return false;
        }
        self.stroke.points.push(p);
        true
    }

    /// The stroke so far (for drawing it while the button is still down).
    pub fn stroke(&self) -> &Stroke {
        &self.stroke
    }

    pub fn finish(self) -> Stroke {
        self.stroke
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::labels::share::{decode_labels, encode_labels};
    use crate::labels::{LabelSet, UNLABELLED, rasterize_frame};

    #[test]
    fn drags_become_spaced_snapped_points() {
        let mut b = StrokeBuilder::new(Some(1), 4.03, 160, 120, [10.01, 10.0]);
        assert!(!b.extend([10.3, 10.2]), "closer than the spacing");
        assert!(b.extend([20.0, 10.0]));
        assert!(!b.extend([f32::NAN, 1.0]));
        b.extend([1e9, -1e9]);
        let s = b.finish();
        assert_eq!(s.radius, 4.0);
        assert_eq!(s.points, vec![[10.0, 10.0], [20.0, 10.0], [164.0, -4.0]]);
    }

    #[test]
    fn drawn_strokes_survive_a_share_link_pixel_for_pixel() {
        let mut labels = LabelSet::new(vec![]);
        let mut b = StrokeBuilder::new(Some(0), 3.3, 160, 120, [12.34, 56.78]);
        for i in 0..50 {
            b.extend([12.34 + i as f32 * 1.37, 56.78 + (i as f32 * 0.3).sin() * 9.1]);
        }
        labels.push_stroke(5, b.finish());
        let back = decode_labels(&encode_labels(&labels)).unwrap();
        assert_eq!(back, labels);
        let map = rasterize_frame(back.frame(5), 160, 120);
        assert!(map.iter().filter(|&&v| v != UNLABELLED).count() > 300);
    }
}
