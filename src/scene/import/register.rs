//! Depth registered to a colour camera of other intrinsics and size (ScanNet records 640x480
//! depth beside 1296x968 colour, with its own focal length and principal point): every depth
//! pixel is carried through the depth camera's intrinsics and the colour camera's onto the
//! colour pixels its footprint overlaps, and where several land on one pixel the nearest wins (a
//! farther surface is hidden behind it; averaging would invent a surface between them). The two cameras share a centre and axes, as in
//! ScanNet's exports.
use crate::scene::DepthImage;
use crate::scene::camera::Intrinsics;

/// `depth`, seen by camera `kd`, as a `size` image of camera `kc` (both with integer pixel
/// centres); 0 where no depth pixel lands or it had no reading.
pub(super) fn register_depth(depth: &DepthImage, kd: &Intrinsics, kc: &Intrinsics, size: (u32, u32)) -> DepthImage {
    let mut out = DepthImage::new(size.0, size.1);
    // Each axis maps on its own: x_c = fx_c (u - cx_d) / fx_d + cx_c (the ray through a pixel
    // does not depend on its depth when the centres coincide).
    let cols = spans(depth.width(), kd.fx, kd.cx, kc.fx, kc.cx, size.0);
    let rows = spans(depth.height(), kd.fy, kd.cy, kc.fy, kc.cy, size.1);
    for (u, v, p) in depth.enumerate_pixels() {
        let d = p.0[0];
        if d == 0 {
            continue;
        }
        let ((x0, x1), (y0, y1)) = (cols[u as usize], rows[v as usize]);
        for y in y0..y1 {
            for x in x0..x1 {
                let o = out.get_pixel_mut(x, y);
                if o.0[0] == 0 || d < o.0[0] {
                    o.0[0] = d;
                }
            }
        }
    }
    out
}

/// For each of `n` depth pixels along one axis, the colour pixels `lo..hi` (of `m`) whose
/// footprints overlap its own `[i - 0.5, i + 0.5]` carried to the colour camera: all of them, so
/// a finer colour camera has no holes and a coarser one takes the nearest of the depth pixels it
/// covers.
fn spans(n: u32, fd: f64, cd: f64, fc: f64, cc: f64, m: u32) -> Vec<(u32, u32)> {
    // Footprints that only touch do not overlap; rounding must not make them.
    const TOUCH: f64 = 1e-9;
    let to_colour = |u: f64| fc * (u - cd) / fd + cc;
    (0..n)
        .map(|i| {
            let (a, b) = (to_colour(i as f64 - 0.5) + TOUCH, to_colour(i as f64 + 0.5) - TOUCH);
            // Colour pixel x spans [x - 0.5, x + 0.5]: it overlaps [a, b] when a - 0.5 < x < b + 0.5.
            let lo = ((a - 0.5).floor() + 1.0).clamp(0.0, m as f64);
            let hi = (b + 0.5).ceil().clamp(0.0, m as f64);
            (lo as u32, hi.max(lo) as u32)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use image::Luma;

    fn k(f: f64, cx: f64, cy: f64) -> Intrinsics {
        Intrinsics { fx: f, fy: f, cx, cy }
    }

    #[test]
    fn same_camera_is_unchanged() {
        let d = DepthImage::from_fn(4, 3, |x, y| Luma([(x + 10 * y) as u16]));
        assert_eq!(register_depth(&d, &k(5.0, 1.5, 1.0), &k(5.0, 1.5, 1.0), (4, 3)), d);
    }

    #[test]
    fn a_finer_colour_camera_gets_every_pixel_covered() {
        // Twice the focal length and twice the size: each depth pixel covers 2x2 colour pixels.
        let d = DepthImage::from_fn(4, 3, |x, y| Luma([1 + (x + 10 * y) as u16]));
        let kd = k(5.0, 1.5, 1.0);
        let kc = kd.scaled((4, 3), (8, 6));
        let r = register_depth(&d, &kd, &kc, (8, 6));
        assert!(r.pixels().all(|p| p.0[0] != 0));
        assert_eq!(r.get_pixel(5, 3), d.get_pixel(2, 1));
        assert_eq!(r.get_pixel(4, 2), d.get_pixel(2, 1));
    }

    #[test]
    fn principal_points_shift_and_nearest_wins() {
        // Colour camera with the principal point one pixel to the right: everything moves right.
        let d = DepthImage::from_fn(4, 1, |x, _| Luma([100 + x as u16]));
        let r = register_depth(&d, &k(5.0, 1.5, 0.0), &k(5.0, 2.5, 0.0), (4, 1));
        assert_eq!(r.as_raw(), &vec![0, 100, 101, 102]);
        // A coarser colour camera: two depth pixels per colour pixel; the nearer is kept.
        let d = DepthImage::from_raw(4, 1, vec![900, 300, 0, 500]).unwrap();
        let r = register_depth(&d, &k(4.0, 1.5, 0.0), &k(2.0, 0.5, 0.0), (2, 1));
        // Colour pixel 0 covers depth pixels 0 and 1, colour pixel 1 covers 2 (no reading) and 3.
        assert_eq!(r.as_raw(), &vec![300, 500]);
    }
}
