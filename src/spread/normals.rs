//! Surface normals of a depth map: where two surfaces meet at a crease (a box's face and the
//! table under it) colour and depth may both change smoothly, but the normal turns. Whether a
//! crease folds inward (concave: where an object stands on a table) or outward (convex: a box's
//! own edge) tells the two apart: objects meet their support at concave creases (docs/results/quality-log.md,
//! "Only inward creases stop the walk").
use crate::scene::{DepthImage, Intrinsics};

/// The camera-space point (x, y, depth) of each pixel of `depth` with a reading, in the depth's
/// unit, seen by `camera`.
pub fn depth_points(depth: &DepthImage, camera: &Intrinsics) -> Vec<Option<[f32; 3]>> {
    let w = depth.width() as usize;
    let (fx, fy, cx, cy) = (camera.fx as f32, camera.fy as f32, camera.cx as f32, camera.cy as f32);
    depth
        .pixels()
        .enumerate()
        .map(|(i, p)| {
            let d = f32::from(p.0[0]);
            let (x, y) = ((i % w) as f32, (i / w) as f32);
            (d > 0.0).then(|| [(x - cx) / fx * d, (y - cy) / fy * d, d])
        })
        .collect()
}

/// True where the surface through points `p` and `q`, with normals `n` and `m` as
/// [`depth_normals`] gives them (pointing away from the camera, into the surface), folds
/// outward between them (a convex edge, as a box's own corner). With normals pointing out of
/// the surface a convex fold has (n - m)·(p - q) > 0; these point in, so the sign flips.
pub fn folds_outward(p: [f32; 3], n: [f32; 3], q: [f32; 3], m: [f32; 3]) -> bool {
    (0..3).map(|k| (n[k] - m[k]) * (p[k] - q[k])).sum::<f32>() < 0.0
}

/// The unit normal at each pixel of `depth` (raw readings, any unit; 0 = no reading) seen by
/// `camera`, from central differences of the back-projected points; `None` where the pixel or
/// one of its four neighbours has no reading, and on the border.
pub fn depth_normals(depth: &DepthImage, camera: &Intrinsics) -> Vec<Option<[f32; 3]>> {
    normals_of_points(&depth_points(depth, camera), depth.width() as usize)
}

/// [`depth_normals`] from the points [`depth_points`] gives, `width` to a row.
pub fn normals_of_points(points: &[Option<[f32; 3]>], width: usize) -> Vec<Option<[f32; 3]>> {
    let (w, h) = (width, points.len() / width.max(1));
    let mut normals = vec![None; w * h];
    for y in 1..h.saturating_sub(1) {
        for x in 1..w.saturating_sub(1) {
            let i = y * w + x;
            let (Some(l), Some(r), Some(u), Some(d), Some(_)) =
                (points[i - 1], points[i + 1], points[i - w], points[i + w], points[i])
            else {
                continue;
            };
            let sub = |a: [f32; 3], b: [f32; 3]| [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
            let gx = sub(r, l);
            let gy = sub(d, u);
            let n = [
                gx[1] * gy[2] - gx[2] * gy[1],
                gx[2] * gy[0] - gx[0] * gy[2],
                gx[0] * gy[1] - gx[1] * gy[0],
            ];
            let length = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
            if length > 0.0 && length.is_finite() {
                normals[i] = Some([n[0] / length, n[1] / length, n[2] / length]);
            }
        }
    }
    normals
}

#[cfg(test)]
mod tests {
    use super::*;
    use image::{ImageBuffer, Luma};

    fn camera() -> Intrinsics {
        Intrinsics {
            fx: 50.0,
            fy: 50.0,
            cx: 15.5,
            cy: 11.5,
        }
    }

    fn dot(a: [f32; 3], b: [f32; 3]) -> f32 {
        a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
    }

    #[test]
    fn a_plane_facing_the_camera_has_one_normal_along_the_axis() {
        let depth = ImageBuffer::from_pixel(32, 24, Luma([1000u16]));
        let normals = depth_normals(&depth, &camera());
        let inner: Vec<[f32; 3]> = normals.iter().flatten().copied().collect();
        assert_eq!(inner.len(), 30 * 22);
        for n in inner {
            assert!(dot(n, [0.0, 0.0, 1.0]).abs() > 0.999, "{n:?}");
        }
    }

    #[test]
    fn a_crease_turns_the_normal_and_holes_have_none() {
        // Two planes meeting at x = 16: depth falls with x on the left, rises on the right.
        let mut depth = ImageBuffer::from_fn(32, 24, |x, _| Luma([(1000 + 20 * (x as i32 - 16).abs()) as u16]));
        depth.put_pixel(5, 5, Luma([0]));
        let normals = depth_normals(&depth, &camera());
        let at = |x: usize, y: usize| normals[y * 32 + x];
        let (left, right) = (at(8, 12).unwrap(), at(24, 12).unwrap());
        assert!(dot(left, right) < 0.9, "{left:?} {right:?}");
        assert!(dot(left, at(10, 3).unwrap()) > 0.999);
        assert!(at(5, 5).is_none() && at(6, 5).is_none() && at(5, 4).is_none());
        assert!(at(0, 12).is_none() && at(31, 12).is_none());
    }

    #[test]
    fn a_ridge_towards_the_camera_folds_outward_and_a_valley_inward() {
        // Depth rises away from x = 16 (a ridge nearest the camera: a box's corner) or falls
        // away from it (a valley: where a box stands on a table).
        for (sign, outward) in [(1i32, true), (-1, false)] {
            let depth = ImageBuffer::from_fn(32, 24, |x, _| Luma([(1000 + sign * 20 * (x as i32 - 16).abs()) as u16]));
            let normals = depth_normals(&depth, &camera());
            let points = depth_points(&depth, &camera());
            let at = |x: usize| (points[12 * 32 + x].unwrap(), normals[12 * 32 + x].unwrap());
            let ((p, n), (q, m)) = (at(12), at(20));
            assert_eq!(folds_outward(p, n, q, m), outward, "sign {sign}");
            assert_eq!(folds_outward(q, m, p, n), outward, "sign {sign}, swapped");
        }
    }
}
