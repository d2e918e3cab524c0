//! The surface a scene's objects stand on, found in a frame's dense depth, with the class the
//! strokes give it (docs/results/quality-log.md, "The surface the objects stand on").
//!
//! The walk inside a frame fades with distance, so on a real capture much of the floor or desk
//! under the objects is reached by no stroke and stays unlabelled; the field then fills it from
//! its features, which on the YCB clip paint the brown carpet with the red box's class. Yet the
//! depth says plainly that the carpet is one plane, and the plane is the largest flat surface in
//! view. Where the user's strokes on that plane agree on one class, every pixel on the plane
//! starts the frame's walk in that class; objects standing on it rise above it and are left out.
use crate::rng::SplitMix64;
use crate::scene::{DepthImage, Intrinsics};

/// Planes tried (three readings each).
const TRIALS: usize = 400;
/// A reading is on the plane within this share of its distance from the camera (depth sensors'
/// noise grows with distance).
const TOLERANCE: f64 = 0.01;
/// ...and where its surface normal is known, within this angle of the plane's (cosine).
const MIN_NORMAL_COSINE: f32 = 0.9;
/// The plane must hold at least this share of the frame's readings.
const MIN_SHARE: f64 = 0.15;
/// Readings sampled for the search (every k-th in both directions); the plane is then applied
/// to every pixel.
const SAMPLE_STEP: usize = 3;

/// A plane in camera coordinates: `normal · p = offset`, `normal` of unit length.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Plane {
    normal: [f64; 3],
    offset: f64,
}

impl Plane {
    fn through(a: [f64; 3], b: [f64; 3], c: [f64; 3]) -> Option<Plane> {
        let u = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
        let v = [c[0] - a[0], c[1] - a[1], c[2] - a[2]];
        let n = [
            u[1] * v[2] - u[2] * v[1],
            u[2] * v[0] - u[0] * v[2],
            u[0] * v[1] - u[1] * v[0],
        ];
        let length = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
        if length <= 1e-12 {
            return None;
        }
        let normal = n.map(|x| x / length);
        Some(Plane {
            normal,
            offset: normal[0] * a[0] + normal[1] * a[1] + normal[2] * a[2],
        })
    }

    fn holds(&self, p: [f64; 3], normal: Option<[f32; 3]>) -> bool {
        let distance = (self.normal[0] * p[0] + self.normal[1] * p[1] + self.normal[2] * p[2] - self.offset).abs();
        let range = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
        let facing = normal.is_none_or(|n| {
            let cos = n[0] * self.normal[0] as f32 + n[1] * self.normal[1] as f32 + n[2] * self.normal[2] as f32;
            cos.abs() >= MIN_NORMAL_COSINE
        });
        distance <= TOLERANCE * range && facing
    }
}

/// The pixels of the largest plane in `depth` (raw readings, 0 = none) seen by `camera`, with
/// `normals` per pixel (`spread::normals`); `None` when no plane holds [`MIN_SHARE`] of the
/// readings. Deterministic: the search draws from a fixed seed.
pub fn largest_plane(depth: &DepthImage, camera: &Intrinsics, normals: &[Option<[f32; 3]>]) -> Option<Vec<bool>> {
    let (w, h) = (depth.width() as usize, depth.height() as usize);
    let point = |i: usize| -> Option<[f64; 3]> {
        let d = f64::from(depth.as_raw()[i]);
        (d > 0.0).then(|| {
            let r = camera.ray_dir((i % w) as f64, (i / w) as f64) * d;
            [r.x, r.y, r.z]
        })
    };
    let normal = |i: usize| normals.get(i).copied().flatten();
    let sample: Vec<(usize, [f64; 3])> = (0..h)
        .step_by(SAMPLE_STEP)
        .flat_map(|y| (0..w).step_by(SAMPLE_STEP).map(move |x| y * w + x))
        .filter_map(|i| point(i).map(|p| (i, p)))
        .collect();
    if sample.len() < 3 {
        return None;
    }
    let mut rng = SplitMix64::new(0x5eed_9a1e);
    let mut best: Option<(usize, Plane)> = None;
    for _ in 0..TRIALS {
        let pick = |rng: &mut SplitMix64| sample[rng.below(sample.len() as u64) as usize].1;
        let Some(plane) = Plane::through(pick(&mut rng), pick(&mut rng), pick(&mut rng)) else {
            continue;
        };
        let support = sample.iter().filter(|(i, p)| plane.holds(*p, normal(*i))).count();
        if best.is_none_or(|(n, _)| support > n) {
            best = Some((support, plane));
        }
    }
    let (support, plane) = best?;
    if (support as f64) < MIN_SHARE * sample.len() as f64 {
        return None;
    }
    Some(
        (0..w * h)
            .map(|i| point(i).is_some_and(|p| plane.holds(p, normal(i))))
            .collect(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use image::Luma;

    fn camera() -> Intrinsics {
        Intrinsics {
            fx: 60.0,
            fy: 60.0,
            cx: 40.0,
            cy: 30.0,
        }
    }

    /// A floor seen from above at an angle, with a box standing on it in the middle.
    fn floor_with_box() -> DepthImage {
        let k = camera();
        DepthImage::from_fn(80, 60, |x, y| {
            // Floor: the plane y_cam * 0.8 + z_cam * 0.6 = 1.2 (metres), in millimetres.
            let ray = k.ray_dir(f64::from(x), f64::from(y));
            let on_floor = 1.2 / (0.8 * ray.y + 0.6 * ray.z);
            let z = if (30..50).contains(&x) && (20..35).contains(&y) {
                on_floor * 0.9 // the box's top, nearer the camera than the floor behind it
            } else {
                on_floor
            };
            Luma([(z * 1000.0).round() as u16])
        })
    }

    #[test]
    fn the_floor_is_found_and_the_box_on_it_is_not() {
        let depth = floor_with_box();
        let normals = crate::spread::normals::depth_normals(&depth, &camera());
        let plane = largest_plane(&depth, &camera(), &normals).expect("a floor");
        let at = |x: usize, y: usize| plane[y * 80 + x];
        assert!(at(5, 5) && at(70, 55) && at(10, 45), "floor pixels");
        assert!(!at(40, 27) && !at(35, 22), "box pixels");
        let share = plane.iter().filter(|&&p| p).count() as f64 / plane.len() as f64;
        assert!(share > 0.8, "{share}");
    }

    #[test]
    fn no_plane_in_a_bumpy_surface_or_without_depth() {
        let k = camera();
        let bumpy = DepthImage::from_fn(80, 60, |x, y| {
            Luma([(1000.0 + 150.0 * ((f64::from(x) * 0.7).sin() + (f64::from(y) * 0.9).cos())) as u16])
        });
        let normals = crate::spread::normals::depth_normals(&bumpy, &k);
        assert_eq!(largest_plane(&bumpy, &k, &normals), None);
        let empty = DepthImage::new(80, 60);
        assert_eq!(largest_plane(&empty, &k, &[]), None);
    }
}
