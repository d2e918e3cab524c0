//! Seeds for every frame of a capture with sparse depth, from its labelled points
//! (docs/quality.md, "Labels in every view").
//!
//! The points a walk over the reconstruction labels (`field::point_walk`) reach every frame that
//! sees them, but they reach it only where the reconstruction has points. A photo capture's
//! model is dense on the object a user photographs from all sides and nearly empty elsewhere: an
//! out-of-focus or textureless room behind it gives the matcher nothing to track. So a frame's
//! pixels that are far from every projected point show what the reconstruction missed, and on
//! the frames the user drew on, the strokes say which class that is. Each frame then starts its
//! own walk from its projected point labels and from its far pixels in that class.
use glam::{DMat4, DVec3};

use crate::labels::UNLABELLED;
use crate::scene::Scene;

/// A pixel is far from the points when no projected point lies within this share of the image
/// diagonal.
pub const FAR_FROM_POINTS: f64 = 0.03;
/// The class the strokes give a region (pixels far from every point, a support plane) must hold
/// at least this share of the region's stroked pixels to be trusted with all of it...
const REGION_SHARE: f64 = 0.75;
/// ...and be drawn on at least this many of its pixels.
const REGION_PIXELS: usize = 20;

/// A camera's view of the points: where each lands in one frame.
pub struct View {
    width: usize,
    height: usize,
    /// (pixel, depth along the optical axis, point) for each point in front of the camera and
    /// inside the image.
    hits: Vec<(u32, f64, u32)>,
}

impl View {
    /// The points `xyz` (world) seen from frame `frame` of `scene`.
    pub fn of_frame(scene: &Scene, frame: usize, xyz: &[DVec3]) -> View {
        let (width, height) = (scene.width as usize, scene.height as usize);
        let world_to_camera: DMat4 = scene.frames[frame].pose.0.inverse();
        let k = &scene.intrinsics;
        let hits = xyz
            .iter()
            .enumerate()
            .filter_map(|(i, p)| {
                let c = world_to_camera.transform_point3(*p);
                if c.z <= 1e-9 {
                    return None;
                }
                let u = (c.x / c.z * k.fx + k.cx).round();
                let v = (c.y / c.z * k.fy + k.cy).round();
                let inside = u >= 0.0 && v >= 0.0 && (u as usize) < width && (v as usize) < height;
                inside.then(|| ((v as usize * width + u as usize) as u32, c.z, i as u32))
            })
            .collect();
        View { width, height, hits }
    }

    /// Each pixel's label from the nearest labelled point that lands on it (`labels` per point,
    /// `UNLABELLED` for a point without one).
    pub fn labels(&self, labels: &[u16]) -> Vec<u16> {
        let mut nearest = vec![f64::INFINITY; self.width * self.height];
        let mut map = vec![UNLABELLED; self.width * self.height];
        for &(pixel, z, point) in &self.hits {
            let label = labels[point as usize];
            if label != UNLABELLED && z < nearest[pixel as usize] {
                nearest[pixel as usize] = z;
                map[pixel as usize] = label;
            }
        }
        map
    }

    /// True for each pixel with no point within [`FAR_FROM_POINTS`] of the image diagonal.
    pub fn far_from_points(&self) -> Vec<bool> {
        let mut occupied = vec![false; self.width * self.height];
        for &(pixel, _, _) in &self.hits {
            occupied[pixel as usize] = true;
        }
        let radius = FAR_FROM_POINTS * ((self.width * self.width + self.height * self.height) as f64).sqrt();
        distance_to_nearest(&occupied, self.width, self.height)
            .into_iter()
            .map(|d| d > radius)
            .collect()
    }
}

/// The class the strokes give a region of pixels, when one class clearly holds it: `strokes`
/// are frames' rasterized strokes, each with its region (the pixels far from every point,
/// [`View::far_from_points`]; a frame's support plane, `field::support_plane`).
pub fn region_class(strokes: &[(&[u16], &[bool])], classes: usize) -> Option<u16> {
    let mut counts = vec![0usize; classes];
    for (map, region) in strokes {
        for (&c, &inside) in map.iter().zip(region.iter()) {
            if inside && (c as usize) < classes {
                counts[c as usize] += 1;
            }
        }
    }
    let total: usize = counts.iter().sum();
    let (best, &count) = counts.iter().enumerate().max_by_key(|(_, n)| **n)?;
    (count >= REGION_PIXELS && count as f64 >= REGION_SHARE * total as f64).then_some(best as u16)
}

/// Euclidean distance from each pixel to the nearest `true` pixel (infinite when there is
/// none), by the exact two-pass transform of Felzenszwalb and Huttenlocher (2012).
fn distance_to_nearest(occupied: &[bool], width: usize, height: usize) -> Vec<f64> {
    const FAR: f64 = 1e20;
    let mut squared: Vec<f64> = occupied.iter().map(|&o| if o { 0.0 } else { FAR }).collect();
    let mut line = Vec::new();
    for x in 0..width {
        line.clear();
        line.extend((0..height).map(|y| squared[y * width + x]));
        for (y, d) in lower_envelope(&line).into_iter().enumerate() {
            squared[y * width + x] = d;
        }
    }
    for y in 0..height {
        let row = &mut squared[y * width..(y + 1) * width];
        let transformed = lower_envelope(row);
        row.copy_from_slice(&transformed);
    }
    squared
        .into_iter()
        .map(|d| if d >= FAR { f64::INFINITY } else { d.sqrt() })
        .collect()
}

/// One dimension of the squared distance transform: min over q of (p - q)² + f(q).
fn lower_envelope(f: &[f64]) -> Vec<f64> {
    let n = f.len();
    if n == 0 {
        return Vec::new();
    }
    let mut vertices = vec![0usize; n];
    let mut bounds = vec![0f64; n + 1];
    let mut k = 0;
    bounds[0] = f64::NEG_INFINITY;
    bounds[1] = f64::INFINITY;
    let intersect =
        |q: usize, v: usize| ((f[q] + (q * q) as f64) - (f[v] + (v * v) as f64)) / (2.0 * q as f64 - 2.0 * v as f64);
    for q in 1..n {
        let mut s = intersect(q, vertices[k]);
        while s <= bounds[k] {
            k -= 1;
            s = intersect(q, vertices[k]);
        }
        k += 1;
        vertices[k] = q;
        bounds[k] = s;
        bounds[k + 1] = f64::INFINITY;
    }
    let mut out = vec![0f64; n];
    k = 0;
    for (p, out) in out.iter_mut().enumerate() {
        while bounds[k + 1] < p as f64 {
            k += 1;
        }
        let v = vertices[k];
        *out = (p as f64 - v as f64).powi(2) + f[v];
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_distance_transform_matches_brute_force() {
        let (width, height) = (23, 17);
        let occupied: Vec<bool> = (0..width * height).map(|i| (i * 7919) % 97 == 3).collect();
        let fast = distance_to_nearest(&occupied, width, height);
        for y in 0..height {
            for x in 0..width {
                let brute = (0..width * height)
                    .filter(|&j| occupied[j])
                    .map(|j| {
                        let (dx, dy) = ((j % width) as f64 - x as f64, (j / width) as f64 - y as f64);
                        (dx * dx + dy * dy).sqrt()
                    })
                    .fold(f64::INFINITY, f64::min);
                assert!(
                    (fast[y * width + x] - brute).abs() < 1e-9,
                    "({x}, {y}): {} against {brute}",
                    fast[y * width + x]
                );
            }
        }
        assert!(distance_to_nearest(&[false; 6], 3, 2).iter().all(|d| d.is_infinite()));
    }

    #[test]
    fn far_pixels_take_a_class_only_when_the_strokes_agree_on_it() {
        let map = [0u16, 0, 0, 1, 1, UNLABELLED];
        let far = [true, true, true, true, false, true];
        // 3 of 4 far stroke pixels are class 0: not the 75 % asked for at 20 pixels...
        assert_eq!(region_class(&[(&map, &far)], 2), None);
        // ...but 30 of 31 are.
        let map: Vec<u16> = std::iter::repeat_n(0, 30).chain([1]).collect();
        let far = vec![true; 31];
        assert_eq!(region_class(&[(&map, &far)], 2), Some(0));
        // A class the model does not have is not counted.
        assert_eq!(region_class(&[(&map, &far)], 0), None);
    }
}
