//! Undistortion onto a pinhole camera: images by inverse mapping (each output pixel's ray is pushed
//! through the lens model to the photo, which is sampled there), keypoints by inverting the lens
//! model numerically. Coordinates are COLMAP pixels (the top-left pixel's centre at (0.5, 0.5)).
use glam::DVec2;
use image::{GrayImage, Luma, Rgb, RgbImage};

use super::model::Lens;

/// Newton steps and the residual (in normalised coordinates) that counts as converged: far below
/// a thousandth of a pixel for any real focal length.
const NEWTON_STEPS: usize = 50;
const NEWTON_TOLERANCE: f64 = 1e-12;
/// Step for the numerical Jacobian of the lens model.
const JACOBIAN_STEP: f64 = 1e-7;

/// The OPENCV model's distortion of normalised coordinates (COLMAP's `OpenCVCameraModel`).
pub(super) fn distort(lens: &Lens, p: DVec2) -> DVec2 {
    let (x, y) = (p.x, p.y);
    let (x2, y2, xy) = (x * x, y * y, x * y);
    let r2 = x2 + y2;
    let radial = lens.k1 * r2 + lens.k2 * r2 * r2;
    DVec2::new(
        x + x * radial + 2.0 * lens.p1 * xy + lens.p2 * (r2 + 2.0 * x2),
        y + y * radial + 2.0 * lens.p2 * xy + lens.p1 * (r2 + 2.0 * y2),
    )
}

/// Normalised (pinhole) coordinates of a pixel of the photo, or None where the lens model cannot
/// be inverted there (far outside the calibrated field, for strong distortion).
pub(super) fn undistort_pixel(lens: &Lens, pixel: DVec2) -> Option<DVec2> {
    let target = DVec2::new((pixel.x - lens.cx) / lens.fx, (pixel.y - lens.cy) / lens.fy);
    if lens.is_pinhole() {
        return Some(target);
    }
    let mut p = target;
    for _ in 0..NEWTON_STEPS {
        let residual = distort(lens, p) - target;
        if residual.length() < NEWTON_TOLERANCE {
            return Some(p);
        }
        let h = JACOBIAN_STEP;
        let dx = (distort(lens, p + DVec2::new(h, 0.0)) - distort(lens, p - DVec2::new(h, 0.0))) / (2.0 * h);
        let dy = (distort(lens, p + DVec2::new(0.0, h)) - distort(lens, p - DVec2::new(0.0, h))) / (2.0 * h);
        let det = dx.x * dy.y - dy.x * dx.y;
        if det.abs() < 1e-12 || !det.is_finite() {
            return None;
        }
        // Solve [dx dy] step = residual.
        let step = DVec2::new(
            (dy.y * residual.x - dy.x * residual.y) / det,
            (dx.x * residual.y - dx.y * residual.x) / det,
        );
        p -= step;
    }
    ((distort(lens, p) - target).length() < 1e-9).then_some(p)
}

/// Where in the photo (COLMAP pixels) each pixel of the `size` pinhole image with lens `out`
/// comes from, row by row.
fn source_map(src: Lens, out: Lens, size: (u32, u32)) -> impl Iterator<Item = DVec2> {
    (0..size.1).flat_map(move |y| {
        (0..size.0).map(move |x| {
            let n = DVec2::new((x as f64 + 0.5 - out.cx) / out.fx, (y as f64 + 0.5 - out.cy) / out.fy);
            let d = distort(&src, n);
            DVec2::new(src.fx * d.x + src.cx, src.fy * d.y + src.cy)
        })
    })
}

/// Whether resampling is needed at all: an undistorted photo of the output camera is copied as is.
pub(super) fn is_identity(src: &Lens, out: &Lens) -> bool {
    src.is_pinhole() && src == out
}

/// The photo `rgb` (lens `src`) seen through the pinhole camera `out`, bilinear; pixels whose
/// ray leaves the photo are black. Returns the image and the number of such pixels.
pub(super) fn undistort_rgb(rgb: &RgbImage, src: &Lens, out: &Lens) -> (RgbImage, usize) {
    if is_identity(src, out) {
        return (rgb.clone(), 0);
    }
    let (w, h) = rgb.dimensions();
    let mut outside = 0;
    let mut pixels = Vec::with_capacity(w as usize * h as usize * 3);
    for s in source_map(*src, *out, (w, h)) {
        // Image coordinates with integer pixel centres.
        let (u, v) = (s.x - 0.5, s.y - 0.5);
        if !(u >= -0.5 && v >= -0.5 && u <= w as f64 - 0.5 && v <= h as f64 - 0.5) {
            outside += 1;
            pixels.extend([0, 0, 0]);
            continue;
        }
        let (x0, y0) = (u.floor(), v.floor());
        let (fx, fy) = (u - x0, v - y0);
        let clamp = |c: f64, n: u32| c.clamp(0.0, (n - 1) as f64) as u32;
        let (xa, xb) = (clamp(x0, w), clamp(x0 + 1.0, w));
        let (ya, yb) = (clamp(y0, h), clamp(y0 + 1.0, h));
        let at = |x, y| rgb.get_pixel(x, y).0.map(f64::from);
        let (a, b, c, d) = (at(xa, ya), at(xb, ya), at(xa, yb), at(xb, yb));
        for k in 0..3 {
            let top = a[k] + (b[k] - a[k]) * fx;
            let bottom = c[k] + (d[k] - c[k]) * fx;
            pixels.push((top + (bottom - top) * fy).round().clamp(0.0, 255.0) as u8);
        }
    }
    let img = RgbImage::from_raw(w, h, pixels).unwrap_or_else(|| RgbImage::from_pixel(w, h, Rgb([0, 0, 0])));
    (img, outside)
}

/// A mask or class map seen through the pinhole camera `out`, nearest (values must not mix);
/// pixels whose ray leaves the photo get `outside`.
pub(super) fn undistort_nearest(mask: &GrayImage, src: &Lens, out: &Lens, outside: u8) -> GrayImage {
    if is_identity(src, out) {
        return mask.clone();
    }
    let (w, h) = mask.dimensions();
    let values = source_map(*src, *out, (w, h))
        .map(|s| {
            // Pixel k covers COLMAP coordinates [k, k + 1).
            let (x, y) = (s.x.floor(), s.y.floor());
            if x >= 0.0 && y >= 0.0 && x < w as f64 && y < h as f64 {
                mask.get_pixel(x as u32, y as u32).0[0]
            } else {
                outside
            }
        })
        .collect();
    GrayImage::from_raw(w, h, values).unwrap_or_else(|| GrayImage::from_pixel(w, h, Luma([outside])))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lens(k1: f64, k2: f64, p1: f64, p2: f64) -> Lens {
        Lens {
            fx: 100.0,
            fy: 110.0,
            cx: 50.0,
            cy: 40.0,
            k1,
            k2,
            p1,
            p2,
        }
    }

    #[test]
    fn undistorting_a_pixel_inverts_the_lens() {
        let l = lens(-0.2, 0.05, 0.001, -0.002);
        for p in [DVec2::new(0.3, -0.2), DVec2::new(-0.45, 0.35), DVec2::ZERO] {
            let d = distort(&l, p);
            let pixel = DVec2::new(l.fx * d.x + l.cx, l.fy * d.y + l.cy);
            let back = undistort_pixel(&l, pixel).unwrap();
            assert!((back - p).length() < 1e-10, "{p} -> {back}");
        }
    }

    #[test]
    fn pinhole_images_are_copied_exactly() {
        let img = RgbImage::from_fn(8, 6, |x, y| Rgb([x as u8 * 30, y as u8 * 40, 7]));
        let l = lens(0.0, 0.0, 0.0, 0.0);
        assert_eq!(undistort_rgb(&img, &l, &l), (img.clone(), 0));
        // Sampling exactly at pixel centres reproduces the image even without the shortcut.
        let shifted = Lens { k1: 1e-300, ..l };
        assert_eq!(undistort_rgb(&img, &shifted, &l).0, img);
    }
}
