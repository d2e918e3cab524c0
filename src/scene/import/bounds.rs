//! Scene bounds for captures that do not state them: from back-projected depth where there is
//! depth, from the cameras' positions and view directions where there is none.
use glam::{DMat3, DVec3};

use crate::scene::Frame;
use crate::scene::camera::{Bounds, Intrinsics, Pose};

/// Depth pixels back-projected over all frames together, at most (enough for stable
/// percentiles, few enough to take well under a second).
const DEPTH_SAMPLE_BUDGET: usize = 400_000;
/// Fraction of points cut off at each end per axis, so a few flying pixels or far walls seen
/// through a window do not blow up the box.
const OUTLIER_FRACTION: f64 = 0.01;
/// Padding added on each side, as a fraction of the box's size.
const PAD: f64 = 0.05;
/// det(A / n) below this means the cameras' optical axes are (nearly) parallel, so there is no
/// point they all look at (a forward-facing capture); about 2 degrees of spread.
const MIN_AXIS_SPREAD: f64 = 1e-3;

/// What [`from_depth`] did, as the note an importer keeps in the archive's provenance.
pub(super) const FROM_DEPTH_NOTE: &str =
    "bounds: central 98 % of back-projected depth and all camera centres, padded by 5 %";

/// [`from_depth`] for a capture whose frames all come with depth: without any reading, an error
/// that names `depth_source` (the depth folder or the capture).
pub(super) fn from_required_depth(
    frames: &[Frame],
    k: &Intrinsics,
    depth_scale: f64,
    depth_source: &std::path::Path,
) -> crate::scene::error::Result<Bounds> {
    from_depth(frames, k, depth_scale).ok_or_else(|| {
        crate::scene::error::SceneError::invalid(
            super::shown(depth_source),
            "no valid depth in any imported frame, so the scene's bounds cannot be found",
        )
    })
}

/// The box holding the central 98 % of back-projected depth on each axis, together with every
/// camera centre (rays start there), padded by 5 %. None when no frame has a depth reading.
pub(super) fn from_depth(frames: &[Frame], k: &Intrinsics, depth_scale: f64) -> Option<Bounds> {
    let pixels: usize = frames.iter().filter_map(|f| f.depth.as_ref()).map(|d| d.len()).sum();
    if pixels == 0 {
        return None;
    }
    let stride = ((pixels as f64 / DEPTH_SAMPLE_BUDGET as f64).sqrt().ceil() as u32).max(1);
    let mut axes: [Vec<f64>; 3] = [Vec::new(), Vec::new(), Vec::new()];
    for f in frames {
        let Some(depth) = &f.depth else { continue };
        for y in (stride / 2..depth.height()).step_by(stride as usize) {
            for x in (stride / 2..depth.width()).step_by(stride as usize) {
                let d = depth.get_pixel(x, y).0[0];
                if d == 0 {
                    continue;
                }
                let p = f
                    .pose
                    .transform_point(k.ray_dir(x as f64, y as f64) * (d as f64 * depth_scale));
                for (axis, v) in axes.iter_mut().zip(p.to_array()) {
                    axis.push(v);
                }
            }
        }
    }
    let corners = central_box(axes, OUTLIER_FRACTION)?;
    Bounds::around(corners.into_iter().chain(frames.iter().map(|f| f.pose.position())), PAD)
}

/// Corners of the box holding all but `cut` of the values at each end of each axis (x, y and z
/// values listed separately); None when there are none.
fn central_box(mut axes: [Vec<f64>; 3], cut: f64) -> Option<[DVec3; 2]> {
    if axes.iter().any(Vec::is_empty) {
        return None;
    }
    let mut lo = [0.0; 3];
    let mut hi = [0.0; 3];
    for (i, values) in axes.iter_mut().enumerate() {
        lo[i] = percentile(values, cut);
        hi[i] = percentile(values, 1.0 - cut);
    }
    Some([DVec3::from_array(lo), DVec3::from_array(hi)])
}

/// The box holding all but `cut` of the points at each end of each axis, padded by `pad` of its
/// size on each side (for sparse reconstructions, whose stray points would blow up a full box).
pub(super) fn from_points(points: impl IntoIterator<Item = DVec3>, cut: f64, pad: f64) -> Option<Bounds> {
    let mut axes: [Vec<f64>; 3] = [Vec::new(), Vec::new(), Vec::new()];
    for p in points {
        for (axis, v) in axes.iter_mut().zip(p.to_array()) {
            axis.push(v);
        }
    }
    Bounds::around(central_box(axes, cut)?, pad)
}

fn percentile(values: &mut [f64], q: f64) -> f64 {
    let i = ((values.len() - 1) as f64 * q).round() as usize;
    *values.select_nth_unstable_by(i, f64::total_cmp).1
}

/// Bounds for a capture without depth, whose scale is unknown (NeRF poses are often normalised,
/// and instant-ngp's `aabb_scale` is a rendering hint, not a size). The rule:
/// 1. the look-at point is the point closest (least squares) to all cameras' optical axes; the
///    look distance is the median distance from the cameras to it. If the axes are nearly
///    parallel (forward-facing captures) or the point lies behind the cameras, the look distance
///    is the diagonal of the cameras' box, or 1 unit if that is smaller (a single camera).
/// 2. the box holds every camera centre and every camera's view frustum (image corners and
///    centre) out to the look distance, padded by 5 %.
///
/// For an orbit around an object this covers the object and the orbit; for forward-facing
/// captures it is a guess that covers what the cameras see up to a plausible depth.
pub(super) fn from_cameras(poses: &[Pose], k: &Intrinsics, size: (u32, u32)) -> Option<Bounds> {
    if poses.is_empty() {
        return None;
    }
    let centres: Vec<DVec3> = poses.iter().map(Pose::position).collect();
    let camera_box = Bounds::around(centres.iter().copied(), 0.0)?;
    let fallback = (camera_box.max_vec() - camera_box.min_vec()).length().max(1.0);
    let distance = look_at_point(poses)
        .map(|f| median(centres.iter().map(|c| (*c - f).length()).collect()))
        .filter(|d| d.is_finite() && *d > 0.0)
        .unwrap_or(fallback);
    let (w, h) = (size.0 as f64 - 0.5, size.1 as f64 - 0.5);
    let image_points = [(-0.5, -0.5), (w, -0.5), (-0.5, h), (w, h), (k.cx, k.cy)];
    let frustum = poses.iter().flat_map(|p| {
        image_points.iter().map(move |&(u, v)| {
            let dir = k.ray_dir(u, v);
            // Out to the look distance along the optical axis, so corner rays reach the same plane.
            p.transform_point(dir * distance)
        })
    });
    Bounds::around(centres.iter().copied().chain(frustum), PAD)
}

/// The point nearest to all optical axes, if the axes converge in front of the cameras.
fn look_at_point(poses: &[Pose]) -> Option<DVec3> {
    let mut a = DMat3::ZERO;
    let mut b = DVec3::ZERO;
    for p in poses {
        let d = p.transform_vector(DVec3::Z).normalize();
        let proj = DMat3::IDENTITY - DMat3::from_cols(d * d.x, d * d.y, d * d.z);
        a += proj;
        b += proj * p.position();
    }
    if (a * (1.0 / poses.len() as f64)).determinant() < MIN_AXIS_SPREAD {
        return None;
    }
    let f = a.inverse() * b;
    let depths: Vec<f64> = poses.iter().map(|p| p.inverse().transform_point(f).z).collect();
    (median(depths) > 0.0).then_some(f)
}

fn median(mut values: Vec<f64>) -> f64 {
    let mid = values.len() / 2;
    *values.select_nth_unstable_by(mid, f64::total_cmp).1
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DMat4;

    fn look_at(eye: DVec3, target: DVec3) -> Pose {
        // OpenCV axes: z forward, y down.
        let z = (target - eye).normalize();
        let x = z.cross(DVec3::NEG_Y).normalize();
        let y = z.cross(x);
        Pose(DMat4::from_cols(
            x.extend(0.0),
            y.extend(0.0),
            z.extend(0.0),
            eye.extend(1.0),
        ))
    }

    #[test]
    fn orbit_bounds_hold_cameras_and_target() {
        let target = DVec3::new(1.0, 2.0, 0.5);
        let poses: Vec<Pose> = (0..12)
            .map(|i| {
                let a = i as f64 * std::f64::consts::TAU / 12.0;
                look_at(target + DVec3::new(3.0 * a.cos(), -1.0, 3.0 * a.sin()), target)
            })
            .collect();
        for p in &poses {
            assert!(p.check().is_ok());
        }
        let f = look_at_point(&poses).unwrap();
        assert!((f - target).length() < 1e-6, "{f}");
        let k = Intrinsics {
            fx: 100.0,
            fy: 100.0,
            cx: 49.5,
            cy: 49.5,
        };
        let b = from_cameras(&poses, &k, (100, 100)).unwrap();
        for p in poses.iter().map(Pose::position).chain([target]) {
            assert!((0..3).all(|i| b.min[i] < p[i] && p[i] < b.max[i]));
        }
        // Not absurdly large: within a few orbit radii.
        assert!((0..3).all(|i| b.max[i] - b.min[i] < 20.0));
    }

    #[test]
    fn parallel_cameras_fall_back_to_spread() {
        let poses: Vec<Pose> = (0..3)
            .map(|i| Pose(DMat4::from_translation(DVec3::new(i as f64, 0.0, 0.0))))
            .collect();
        assert!(look_at_point(&poses).is_none());
        let k = Intrinsics {
            fx: 100.0,
            fy: 100.0,
            cx: 49.5,
            cy: 49.5,
        };
        let b = from_cameras(&poses, &k, (100, 100)).unwrap();
        // Look distance = the cameras' box diagonal (2), so the box reaches z = 2 in front.
        assert!(b.max[2] > 2.0 && b.max[2] < 2.5 && b.min[2] < 0.0);
    }
}
