//! Where a frame lies on screen while annotating: fitted into the canvas, then zoomed and
//! panned by the user. Maps pointer positions to frame pixels (where a brush stroke lands) and
//! back (where to draw a stroke). Plain numbers, no UI types, so it is tested natively.

/// Zoom relative to "fit", the range the user can reach.
pub const MIN_ZOOM: f32 = 0.5;
pub const MAX_ZOOM: f32 = 32.0;

/// An axis-aligned rectangle on screen: top-left corner and size, in points.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ScreenRect {
    pub min: [f32; 2],
    pub size: [f32; 2],
}

impl ScreenRect {
    pub fn center(&self) -> [f32; 2] {
        [self.min[0] + self.size[0] / 2.0, self.min[1] + self.size[1] / 2.0]
    }

    pub fn contains(&self, p: [f32; 2]) -> bool {
        (0..2).all(|a| p[a] >= self.min[a] && p[a] <= self.min[a] + self.size[a])
    }
}

/// Zoom and pan of one frame in a viewport. The same view is kept when the user steps to
/// another frame of the scene (all frames have one size), so a region can be compared.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ViewTransform {
    /// Frame size in pixels.
    pub image: [f32; 2],
    /// 1 = the whole frame fits the viewport.
    pub zoom: f32,
    /// Offset of the frame's centre from the viewport's centre, in screen points.
    pub pan: [f32; 2],
}

impl ViewTransform {
    pub fn new(width: u32, height: u32) -> ViewTransform {
        ViewTransform {
            image: [width as f32, height as f32],
            zoom: 1.0,
            pan: [0.0, 0.0],
        }
    }

    /// Back to the whole frame, fitted.
    pub fn reset(&mut self) {
        self.zoom = 1.0;
        self.pan = [0.0, 0.0];
    }

    /// Screen points per frame pixel in `viewport`.
    pub fn scale(&self, viewport: &ScreenRect) -> f32 {
        if self.image[0] <= 0.0 || self.image[1] <= 0.0 {
            return 1.0;
        }
        let fit = (viewport.size[0] / self.image[0]).min(viewport.size[1] / self.image[1]);
        fit.max(1e-6) * self.zoom
    }

    /// Where the frame's pixel coordinate `p` appears on screen.
    pub fn to_screen(&self, viewport: &ScreenRect, p: [f32; 2]) -> [f32; 2] {
        let (c, s) = (viewport.center(), self.scale(viewport));
        [0, 1].map(|a| c[a] + self.pan[a] + (p[a] - self.image[a] / 2.0) * s)
    }

    /// The frame pixel coordinate under screen point `q` ((0.5, 0.5) is the centre of the
    /// top-left pixel, as in strokes).
    pub fn to_image(&self, viewport: &ScreenRect, q: [f32; 2]) -> [f32; 2] {
        let (c, s) = (viewport.center(), self.scale(viewport));
        [0, 1].map(|a| (q[a] - c[a] - self.pan[a]) / s + self.image[a] / 2.0)
    }

    /// The frame's rectangle on screen.
    pub fn image_rect(&self, viewport: &ScreenRect) -> ScreenRect {
        let min = self.to_screen(viewport, [0.0, 0.0]);
        let s = self.scale(viewport);
        ScreenRect {
            min,
            size: [self.image[0] * s, self.image[1] * s],
        }
    }

    /// Whether screen point `q` is on the frame.
    pub fn hits_image(&self, viewport: &ScreenRect, q: [f32; 2]) -> bool {
        let p = self.to_image(viewport, q);
        (0..2).all(|a| p[a] >= 0.0 && p[a] < self.image[a])
    }

    /// Zooms by `factor`, keeping the frame point under screen point `anchor` where it is (the
    /// mouse wheel zooms into what the pointer is on).
    pub fn zoom_about(&mut self, viewport: &ScreenRect, anchor: [f32; 2], factor: f32) {
        if !(factor.is_finite() && factor > 0.0) {
            return;
        }
        let old = self.scale(viewport);
        self.zoom = (self.zoom * factor).clamp(MIN_ZOOM, MAX_ZOOM);
        let ratio = self.scale(viewport) / old;
        let c = viewport.center();
        self.pan = [0, 1].map(|a| anchor[a] - c[a] - (anchor[a] - c[a] - self.pan[a]) * ratio);
        self.keep_in_view(viewport);
    }

    /// Moves the frame by `delta` screen points.
    pub fn pan_by(&mut self, viewport: &ScreenRect, delta: [f32; 2]) {
        self.pan = [self.pan[0] + delta[0], self.pan[1] + delta[1]];
        self.keep_in_view(viewport);
    }

    /// Keeps at least part of the frame on screen, so the user cannot lose it off the edge.
    fn keep_in_view(&mut self, viewport: &ScreenRect) {
        let s = self.scale(viewport);
        for a in 0..2 {
            let half = (self.image[a] * s + viewport.size[a]) / 2.0 - 32.0_f32.min(viewport.size[a] / 4.0);
            let limit = half.max(0.0);
            self.pan[a] = self.pan[a].clamp(-limit, limit);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const VIEW: ScreenRect = ScreenRect {
        min: [100.0, 50.0],
        size: [800.0, 400.0],
    };

    fn close(a: [f32; 2], b: [f32; 2]) -> bool {
        (a[0] - b[0]).abs() < 1e-3 && (a[1] - b[1]).abs() < 1e-3
    }

    #[test]
    fn fitted_frame_is_centred_and_maps_both_ways() {
        let v = ViewTransform::new(160, 120);
        // 400 / 120 limits: 3.333 points per pixel, 533 wide, centred horizontally.
        assert!((v.scale(&VIEW) - 400.0 / 120.0).abs() < 1e-5);
        let r = v.image_rect(&VIEW);
        assert!(close(r.min, [500.0 - 160.0 * 400.0 / 240.0, 50.0]), "{r:?}");
        for p in [[0.0, 0.0], [0.5, 0.5], [159.5, 119.5], [80.0, 60.0]] {
            assert!(close(v.to_image(&VIEW, v.to_screen(&VIEW, p)), p));
        }
        assert!(v.hits_image(&VIEW, VIEW.center()));
        assert!(!v.hits_image(&VIEW, [110.0, 60.0]));
    }

    #[test]
    fn zoom_keeps_the_point_under_the_pointer() {
        let mut v = ViewTransform::new(160, 120);
        let anchor = [420.0, 300.0];
        let before = v.to_image(&VIEW, anchor);
        v.zoom_about(&VIEW, anchor, 4.0);
        assert_eq!(v.zoom, 4.0);
        assert!(close(v.to_image(&VIEW, anchor), before));
        v.zoom_about(&VIEW, anchor, 1000.0);
        assert_eq!(v.zoom, MAX_ZOOM);
        assert!(close(v.to_image(&VIEW, anchor), before));
        v.zoom_about(&VIEW, anchor, f32::NAN);
        assert_eq!(v.zoom, MAX_ZOOM);
        v.reset();
        assert_eq!(v, ViewTransform::new(160, 120));
    }

    #[test]
    fn panning_cannot_lose_the_frame() {
        let mut v = ViewTransform::new(160, 120);
        v.pan_by(&VIEW, [10.0, -5.0]);
        assert_eq!(v.pan, [10.0, -5.0]);
        v.pan_by(&VIEW, [1e6, 1e6]);
        let r = v.image_rect(&VIEW);
        // Still overlapping the viewport.
        assert!(r.min[0] < VIEW.min[0] + VIEW.size[0] && r.min[1] < VIEW.min[1] + VIEW.size[1]);
    }
}
