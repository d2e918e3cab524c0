//! Rays through pixels, clipping to the scene box, depth-guided sample placement and the
//! normalization of world positions to [0,1]³.
//!
//! Sample placement (`place_samples`), with `n_c` coarse and `n_f` fine samples:
//! - ray with a measured depth whose band [t_s − ε, t_s + ε] overlaps [near, far]: `n_c`
//!   stratified samples over [near, far] and `n_f` stratified samples over the band (clipped
//!   to [near, far]), merged in order;
//! - otherwise: `n_c + n_f` stratified samples over [near, far].
//!
//! Stratified: sample j of m over [a, b] is `a + (b − a)(j + u_j)/m` with jitter u_j ∈ [0,1)
//! passed in (so CPU and GPU place identical samples given the same jitter). Every ray has
//! the same sample count, which keeps the GPU's per-ray work uniform. Interval lengths are
//! the gaps to the next sample, the last one reaching `far` (a sample stands for the stretch
//! of ray up to the next one, as in NeRF's quadrature).
use glam::DVec3;

use crate::scene::{Bounds, Intrinsics, Pose};

/// A ray in world space. `t` is metric distance along the unit `dir`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ray {
    pub origin: [f32; 3],
    /// Unit direction (this is what the SH view encoding sees).
    pub dir: [f32; 3],
    /// z-depth per unit of t: the cosine between `dir` and the camera's optical axis. The
    /// z-depth of the point at t is `t · z_per_t`, comparable with the depth image.
    pub z_per_t: f32,
}

impl Ray {
    pub fn at(&self, t: f32) -> [f32; 3] {
        std::array::from_fn(|a| self.origin[a] + t * self.dir[a])
    }
}

/// The ray through pixel (u, v) (integer coordinates are pixel centres) of a camera with
/// intrinsics `k` and camera-to-world `pose` (OpenCV axes).
pub fn ray_through_pixel(k: &Intrinsics, pose: &Pose, u: f64, v: f64) -> Ray {
    // The camera-space direction has z = 1, so its length is 1 / cos(angle to the axis).
    let camera_dir = k.ray_dir(u, v);
    let length = camera_dir.length();
    let world_dir = pose.transform_vector(camera_dir / length);
    Ray {
        origin: pose.position().as_vec3().to_array(),
        dir: world_dir.as_vec3().to_array(),
        z_per_t: (1.0 / length) as f32,
    }
}

/// [near, far] of the part of the ray inside the box (slab method), with near ≥ 0 (nothing
/// behind the camera); None when the ray misses the box or the interval is empty.
pub fn clip_to_bounds(ray: &Ray, bounds: &Bounds) -> Option<(f32, f32)> {
    let mut near = 0.0f64;
    let mut far = f64::INFINITY;
    for a in 0..3 {
        let o = ray.origin[a] as f64;
        let d = ray.dir[a] as f64;
        if d.abs() < 1e-12 {
            if o < bounds.min[a] || o > bounds.max[a] {
                return None;
            }
            continue;
        }
        let t0 = (bounds.min[a] - o) / d;
        let t1 = (bounds.max[a] - o) / d;
        near = near.max(t0.min(t1));
        far = far.min(t0.max(t1));
    }
    (far > near).then_some((near as f32, far as f32))
}

/// Half-width ε of the band around a measured surface: a fraction of the box diagonal.
pub fn surface_band_half_width(bounds: &Bounds, fraction: f32) -> f32 {
    ((bounds.max_vec() - bounds.min_vec()).length() * fraction as f64) as f32
}

/// How many samples go where along a ray.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SamplePlan {
    pub coarse: usize,
    pub fine: usize,
    /// ε in metres of t.
    pub band_half_width: f32,
}

impl SamplePlan {
    pub fn total(&self) -> usize {
        self.coarse + self.fine
    }
}

/// Sample distances t (sorted, `plan.total()` values) on [near, far]. `surface_t`: the
/// measured surface as a distance along the ray (z-depth / z_per_t), if any. `jitter`:
/// `plan.total()` values in [0,1); the first `coarse` jitter the coarse samples, the rest the
/// fine ones (all of them the uniform samples when there is no usable depth).
pub fn place_samples(plan: &SamplePlan, near: f32, far: f32, surface_t: Option<f32>, jitter: &[f32]) -> Vec<f32> {
    debug_assert_eq!(jitter.len(), plan.total());
    let band = surface_t.and_then(|s| {
        let lo = (s - plan.band_half_width).max(near);
        let hi = (s + plan.band_half_width).min(far);
        (hi > lo && plan.fine > 0).then_some((lo, hi))
    });
    match band {
        Some((lo, hi)) => {
            let coarse = stratified(near, far, &jitter[..plan.coarse]);
            let fine = stratified(lo, hi, &jitter[plan.coarse..]);
            merge_sorted(&coarse, &fine)
        }
        None => stratified(near, far, jitter),
    }
}

/// `jitter.len()` stratified samples over [a, b].
pub fn stratified(a: f32, b: f32, jitter: &[f32]) -> Vec<f32> {
    let m = jitter.len() as f32;
    jitter
        .iter()
        .enumerate()
        .map(|(j, u)| a + (b - a) * ((j as f32 + u) / m))
        .collect()
}

/// Merges two sorted lists (a GPU thread does the same two-pointer walk).
pub fn merge_sorted(a: &[f32], b: &[f32]) -> Vec<f32> {
    let mut out = Vec::with_capacity(a.len() + b.len());
    let (mut i, mut j) = (0, 0);
    while i < a.len() || j < b.len() {
        if j >= b.len() || (i < a.len() && a[i] <= b[j]) {
            out.push(a[i]);
            i += 1;
        } else {
            out.push(b[j]);
            j += 1;
        }
    }
    out
}

/// δ_i = t_{i+1} − t_i, and far − t_last for the last sample, or
/// [`OPAQUE_INTERVAL`](super::render::OPAQUE_INTERVAL) when it is opaque
/// (`FieldConfig::opaque_last_sample()`).
pub fn interval_lengths(ts: &[f32], far: f32, opaque_last: bool) -> Vec<f32> {
    (0..ts.len())
        .map(|i| match ts.get(i + 1) {
            Some(next) => next - ts[i],
            None if opaque_last => super::render::OPAQUE_INTERVAL,
            None => far - ts[i],
        })
        .collect()
}

/// World position to [0,1]³ by the scene box (clamped, so rounding at the box faces cannot
/// leave the unit cube).
pub fn normalize_position(bounds: &Bounds, p: [f32; 3]) -> [f32; 3] {
    std::array::from_fn(|a| (((p[a] as f64 - bounds.min[a]) / (bounds.max[a] - bounds.min[a])) as f32).clamp(0.0, 1.0))
}

/// The camera's optical axis in world space (the z-depth direction).
pub fn camera_forward(pose: &Pose) -> DVec3 {
    pose.transform_vector(DVec3::Z)
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{DMat4, DQuat};

    fn unit_box() -> Bounds {
        Bounds {
            min: [0.0; 3],
            max: [1.0; 3],
        }
    }

    #[test]
    fn ray_t_times_z_per_t_is_z_depth() {
        let k = Intrinsics {
            fx: 100.0,
            fy: 120.0,
            cx: 50.0,
            cy: 40.0,
        };
        let pose = Pose(DMat4::from_rotation_translation(
            DQuat::from_rotation_y(0.4),
            DVec3::new(1.0, 2.0, 3.0),
        ));
        let ray = ray_through_pixel(&k, &pose, 90.0, 5.0);
        let t = 2.5f32;
        let world = DVec3::from_array(ray.at(t).map(f64::from));
        let in_camera = pose.inverse().transform_point(world);
        assert!((in_camera.z - (t * ray.z_per_t) as f64).abs() < 1e-5);
        // And the point projects back to the pixel.
        assert!((k.fx * in_camera.x / in_camera.z + k.cx - 90.0).abs() < 1e-3);
        assert!((DVec3::from_array(ray.dir.map(f64::from)).length() - 1.0).abs() < 1e-6);
        assert!(
            (camera_forward(&pose).dot(DVec3::from_array(ray.dir.map(f64::from))) - ray.z_per_t as f64).abs() < 1e-6
        );
    }

    #[test]
    fn clipping_finds_the_box_and_misses() {
        let ray = Ray {
            origin: [0.5, 0.5, -1.0],
            dir: [0.0, 0.0, 1.0],
            z_per_t: 1.0,
        };
        assert_eq!(clip_to_bounds(&ray, &unit_box()), Some((1.0, 2.0)));
        let inside = Ray {
            origin: [0.5, 0.5, 0.5],
            ..ray
        };
        assert_eq!(clip_to_bounds(&inside, &unit_box()), Some((0.0, 0.5)));
        let miss = Ray {
            origin: [2.0, 0.5, -1.0],
            ..ray
        };
        assert_eq!(clip_to_bounds(&miss, &unit_box()), None);
        let away = Ray {
            dir: [0.0, 0.0, -1.0],
            ..ray
        };
        assert_eq!(clip_to_bounds(&away, &unit_box()), None);
    }

    #[test]
    fn depth_puts_fine_samples_in_the_band() {
        let plan = SamplePlan {
            coarse: 4,
            fine: 12,
            band_half_width: 0.05,
        };
        let jitter: Vec<f32> = (0..16).map(|i| (i as f32 * 0.37) % 1.0).collect();
        let ts = place_samples(&plan, 1.0, 3.0, Some(2.2), &jitter);
        assert_eq!(ts.len(), 16);
        assert!(ts.windows(2).all(|w| w[0] <= w[1]));
        assert!(ts.iter().all(|t| (1.0..3.0).contains(t)));
        let in_band = ts.iter().filter(|t| (**t - 2.2).abs() <= 0.05).count();
        assert!(in_band >= 12, "{ts:?}");
        // Without depth (or with a surface outside the box) everything is uniform.
        let uniform = place_samples(&plan, 1.0, 3.0, None, &jitter);
        assert_eq!(uniform, stratified(1.0, 3.0, &jitter));
        assert_eq!(place_samples(&plan, 1.0, 3.0, Some(7.0), &jitter), uniform);
        let deltas = interval_lengths(&ts, 3.0, false);
        assert!((deltas.iter().sum::<f32>() - (3.0 - ts[0])).abs() < 1e-5);
        assert!(deltas.iter().all(|d| *d >= 0.0));
        let opaque = interval_lengths(&ts, 3.0, true);
        assert_eq!(opaque[..15], deltas[..15]);
        assert_eq!(opaque[15], crate::field::reference::render::OPAQUE_INTERVAL);
    }

    #[test]
    fn normalization_maps_the_box_to_the_unit_cube() {
        let b = Bounds {
            min: [-1.0, 0.0, 2.0],
            max: [1.0, 4.0, 3.0],
        };
        assert_eq!(normalize_position(&b, [0.0, 1.0, 2.5]), [0.5, 0.25, 0.5]);
        assert_eq!(normalize_position(&b, [5.0, -1.0, 3.0]), [1.0, 0.0, 1.0]);
        assert!((surface_band_half_width(&b, 0.1) - 0.1 * 21f32.sqrt()).abs() < 1e-6);
    }
}
