//! Cameras on an orbit around the table and the per-pixel ray tracing of one frame.
use glam::{DMat4, DVec3};
use image::{GrayImage, Luma, Rgb, RgbImage};

use super::layout::{DemoWorld, WorldHit};
use crate::rng::SplitMix64;
use crate::scene::camera::{Intrinsics, Pose};
use crate::scene::{DepthImage, GT_VOID};

/// Horizontal field of view of the demo camera.
pub const HORIZONTAL_FOV_DEGREES: f64 = 60.0;
/// Millimetres: the stored depth unit.
pub const DEPTH_SCALE: f64 = 0.001;

/// Square pixels, the given horizontal field of view, principal point at the image centre
/// (integer pixel coordinates are pixel centres, as `Intrinsics::ray_dir` expects).
pub fn demo_intrinsics(width: u32, height: u32) -> Intrinsics {
    let f = width as f64 * 0.5 / (HORIZONTAL_FOV_DEGREES.to_radians() * 0.5).tan();
    Intrinsics {
        fx: f,
        fy: f,
        cx: (width as f64 - 1.0) * 0.5,
        cy: (height as f64 - 1.0) * 0.5,
    }
}

/// A camera at `eye` looking at `target` with no roll (world z up), in OpenCV axes.
pub fn look_at(eye: DVec3, target: DVec3) -> Pose {
    let forward = (target - eye).normalize();
    let right = forward.cross(DVec3::Z).normalize();
    let down = forward.cross(right);
    Pose(DMat4::from_cols(
        right.extend(0.0),
        down.extend(0.0),
        forward.extend(0.0),
        eye.extend(1.0),
    ))
}

/// One loop around the target; elevation and distance swing gently so views differ in more
/// than their azimuth.
#[derive(Clone, Copy, Debug)]
pub struct Orbit {
    target: DVec3,
    start_azimuth: f64,
    distance: f64,
    elevation_degrees: f64,
    swing_degrees: f64,
    swing_phase: f64,
}

impl Orbit {
    pub fn new(target: DVec3, rng: &mut SplitMix64) -> Orbit {
        Orbit {
            target,
            start_azimuth: rng.uniform(0.0, std::f64::consts::TAU),
            distance: rng.uniform(0.95, 1.05),
            elevation_degrees: rng.uniform(26.0, 30.0),
            swing_degrees: 9.0,
            swing_phase: rng.uniform(0.0, std::f64::consts::TAU),
        }
    }

    /// Camera-to-world pose of view `i` of `n`, evenly spaced in azimuth.
    pub fn pose(&self, i: u32, n: u32) -> Pose {
        let turn = i as f64 / n.max(1) as f64 * std::f64::consts::TAU;
        let azimuth = self.start_azimuth + turn;
        let elevation =
            (self.elevation_degrees + self.swing_degrees * (2.0 * turn + self.swing_phase).sin()).to_radians();
        let distance = self.distance * (1.0 + 0.06 * (3.0 * turn).cos());
        let offset = DVec3::new(
            azimuth.cos() * elevation.cos(),
            azimuth.sin() * elevation.cos(),
            elevation.sin(),
        );
        look_at(self.target + offset * distance, self.target)
    }
}

/// The images of one view.
pub struct RenderedFrame {
    pub rgb: RgbImage,
    pub depth: DepthImage,
    pub gt: GrayImage,
}

/// Sub-pixel offsets used to smooth colour along silhouettes (a rotated 2x2 grid).
const EDGE_SAMPLES: [(f64, f64); 4] = [(-0.125, -0.375), (0.375, -0.125), (0.125, 0.375), (-0.375, 0.125)];

/// Traces one ray through each pixel centre for depth, class and colour; pixels on a
/// silhouette get their colour from four sub-pixel rays instead, as a camera would blur them.
/// Depth and class always come from the centre ray, so they match the geometry exactly.
/// A ray that meets nothing (only possible in a world without its room,
/// `DemoWorld::without_room`) shows `backdrop` and has no depth and no class.
pub fn render_frame(
    world: &DemoWorld,
    k: &Intrinsics,
    pose: &Pose,
    (width, height): (u32, u32),
    backdrop: DVec3,
) -> RenderedFrame {
    let rotation = pose.rotation();
    let eye = pose.position();
    let cast = |u: f64, v: f64| world.cast(eye, rotation * k.ray_dir(u, v));
    let hits: Vec<Option<WorldHit>> = (0..height)
        .flat_map(|y| (0..width).map(move |x| (x, y)))
        .map(|(x, y)| cast(x as f64, y as f64))
        .collect();

    let part_at = |x: u32, y: u32| hits[(y * width + x) as usize].map(|h| h.part);
    let on_edge = |x: u32, y: u32| {
        let here = part_at(x, y);
        let neighbours = [(x.wrapping_sub(1), y), (x + 1, y), (x, y.wrapping_sub(1)), (x, y + 1)];
        neighbours
            .iter()
            .any(|&(nx, ny)| nx < width && ny < height && part_at(nx, ny) != here)
    };
    let colour_of = |hit: Option<WorldHit>| hit.map_or(backdrop, |h| world.shade(&h));

    let mut rgb = RgbImage::new(width, height);
    let mut depth = DepthImage::new(width, height);
    let mut gt = GrayImage::new(width, height);
    for y in 0..height {
        for x in 0..width {
            let hit = hits[(y * width + x) as usize];
            let colour = if on_edge(x, y) {
                let sum: DVec3 = EDGE_SAMPLES
                    .iter()
                    .map(|&(dx, dy)| colour_of(cast(x as f64 + dx, y as f64 + dy)))
                    .sum();
                sum / EDGE_SAMPLES.len() as f64
            } else {
                colour_of(hit)
            };
            rgb.put_pixel(x, y, Rgb(colour.to_array().map(to_byte)));
            depth.put_pixel(x, y, Luma([hit.map_or(0, |h| depth_units(h.t))]));
            gt.put_pixel(x, y, Luma([hit.map_or(GT_VOID, |h| h.class)]));
        }
    }
    RenderedFrame { rgb, depth, gt }
}

fn to_byte(channel: f64) -> u8 {
    (channel.clamp(0.0, 1.0) * 255.0).round() as u8
}

/// Z-depth in metres to stored units, never 0 (which means "no reading") for a real hit.
fn depth_units(z: f64) -> u16 {
    (z / DEPTH_SCALE).round().clamp(1.0, u16::MAX as f64) as u16
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn look_at_points_the_optical_axis_at_the_target_with_image_down_toward_the_floor() {
        let eye = DVec3::new(1.0, -0.5, 1.4);
        let target = DVec3::new(0.0, 0.1, 0.8);
        let pose = look_at(eye, target);
        pose.check().unwrap();
        let forward = pose.transform_vector(DVec3::Z);
        assert!((forward - (target - eye).normalize()).length() < 1e-12);
        assert!(
            pose.transform_vector(DVec3::Y).z < 0.0,
            "camera y (image down) points down in the world"
        );
        assert!(pose.transform_vector(DVec3::X).z.abs() < 1e-12, "no roll");
        assert!(
            pose.inverse().transform_point(target).truncate().length() < 1e-12,
            "target on the axis"
        );
    }

    #[test]
    fn intrinsics_give_the_field_of_view_and_centre_pixels() {
        let k = demo_intrinsics(160, 120);
        assert_eq!((k.cx, k.cy), (79.5, 59.5));
        // The outer edges of the outer pixels are half a pixel beyond their centres.
        let left = k.ray_dir(-0.5, k.cy);
        let right = k.ray_dir(159.5, k.cy);
        let fov = (right.x.atan2(right.z) - left.x.atan2(left.z)).to_degrees();
        assert!((fov - HORIZONTAL_FOV_DEGREES).abs() < 1e-9, "fov {fov}");
        assert_eq!(k.fx, k.fy);
    }

    #[test]
    fn orbit_circles_the_target_and_varies_elevation() {
        let target = DVec3::new(0.0, 0.0, 0.8);
        let orbit = Orbit::new(target, &mut SplitMix64::new(1));
        let n = 36;
        let poses: Vec<Pose> = (0..n).map(|i| orbit.pose(i, n)).collect();
        let heights: Vec<f64> = poses.iter().map(|p| p.position().z).collect();
        let spread =
            heights.iter().cloned().fold(f64::MIN, f64::max) - heights.iter().cloned().fold(f64::MAX, f64::min);
        assert!(spread > 0.2, "camera heights vary by only {spread} m");
        let mut swept = 0.0;
        for w in poses.windows(2) {
            let (a, b) = (
                (w[0].position() - target).truncate(),
                (w[1].position() - target).truncate(),
            );
            swept += a.angle_to(b);
        }
        assert!(
            (swept.to_degrees() - 350.0).abs() < 1e-6,
            "35 steps of 10 degrees, got {}",
            swept.to_degrees()
        );
        for p in &poses {
            p.check().unwrap();
            assert!(p.inverse().transform_point(target).truncate().length() < 1e-9);
        }
    }

    #[test]
    fn depth_is_z_depth_not_ray_length() {
        let world = DemoWorld::generate(0);
        let (w, h) = (64, 48);
        let k = demo_intrinsics(w, h);
        let pose = look_at(DVec3::new(1.2, 0.3, 1.4), world.look_target());
        let frame = render_frame(&world, &k, &pose, (w, h), DVec3::ZERO);
        let to_camera = pose.inverse();
        for (x, y) in [(0, 0), (63, 0), (0, 47), (63, 47), (31, 24), (10, 40)] {
            let hit = world
                .cast(pose.position(), pose.rotation() * k.ray_dir(x as f64, y as f64))
                .unwrap();
            let z = to_camera.transform_point(hit.point).z;
            let stored = frame.depth.get_pixel(x, y).0[0];
            assert_eq!(stored, (z * 1000.0).round() as u16, "pixel ({x}, {y})");
            assert_eq!(frame.gt.get_pixel(x, y).0[0], hit.class);
        }
    }

    #[test]
    fn depth_units_round_and_never_read_as_missing() {
        assert_eq!(depth_units(1.2344), 1234);
        assert_eq!(depth_units(1.2346), 1235);
        assert_eq!(depth_units(0.0001), 1);
        assert_eq!(depth_units(1e6), u16::MAX);
    }
}
