//! Seeds for every frame of a capture with sparse depth, from its labelled points
//! (docs/results/quality-log.md, "Labels in every view").
//!
//! The points a walk over the reconstruction labels (`spread::point_walk`) reach every frame that
//! sees them, but they reach it only where the reconstruction has points. A photo capture's
//! model is dense on the object a user photographs from all sides and nearly empty elsewhere: an
//! out-of-focus or textureless room behind it gives the matcher nothing to track. So a frame's
//! pixels that are far from every projected point show what the reconstruction missed, and on
//! the frames the user drew on, the strokes say which class that is. Each frame then starts its
//! own walk from its projected point labels and from its far pixels in that class.
use glam::{DMat4, DVec3};

use crate::labels::UNLABELLED;
use crate::scene::Scene;
use crate::spread::box_counts::BoxCounts;

/// A pixel is far from the points when no projected point lies within this share of the image
/// diagonal.
pub const FAR_FROM_POINTS: f64 = 0.03;
/// A point counts towards an outline ([`View::outline_of_points_not_in`]) only when more than this
/// many points land within the far radius of it, itself included: a lone point is more often a
/// wrong match than an object's edge.
const OUTLINE_NEIGHBOURS: u32 = 10;
/// A pixel is near a point ([`View::near_points_not_in`]) within this share of the far radius.
const NEAR_SHARE_OF_FAR: f64 = 0.5;
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

    /// True for each pixel inside the outline of the points not labelled `class` (`labels` per
    /// point, unlabelled points included): the convex hull of where they land, without the lone
    /// ones. A photographed object's reconstruction has holes where its surface is smooth or
    /// seen from few photos, but its outline still encloses them, so a pixel far from every
    /// point inside it is more likely such a hole than the room behind the object.
    pub fn outline_of_points_not_in(&self, labels: &[u16], class: u16) -> Vec<bool> {
        let landed: Vec<u32> = self
            .hits
            .iter()
            .filter(|&&(_, _, point)| labels[point as usize] != class)
            .map(|&(pixel, _, _)| pixel)
            .collect();
        let neighbours = BoxCounts::new(&landed, self.width, self.height);
        let radius = self.far_radius() as usize;
        let mut corners: Vec<(i64, i64)> = landed
            .iter()
            .map(|&pixel| (pixel as usize % self.width, pixel as usize / self.width))
            .filter(|&(x, y)| neighbours.around(x, y, radius) > OUTLINE_NEIGHBOURS)
            .map(|(x, y)| (x as i64, y as i64))
            .collect();
        let hull = convex_hull(&mut corners);
        if hull.len() < 3 {
            return vec![false; self.width * self.height];
        }
        (0..self.width * self.height)
            .map(|i| {
                let (x, y) = ((i % self.width) as i64, (i / self.width) as i64);
                let edges = hull.iter().zip(hull.iter().cycle().skip(1));
                edges
                    .into_iter()
                    .all(|(a, b)| (b.0 - a.0) * (y - a.1) - (b.1 - a.1) * (x - a.0) >= 0)
            })
            .collect()
    }

    /// True for each pixel within half the far radius of a point not labelled `class` (`labels`
    /// per point, unlabelled points included). Next to the object's points, the far pixels'
    /// class only arrives through the frame's walk, which crosses a faint edge as easily as none;
    /// the points the walk over the points left unlabelled are mostly the object's.
    pub fn near_points_not_in(&self, labels: &[u16], class: u16) -> Vec<bool> {
        let mut occupied = vec![false; self.width * self.height];
        for &(pixel, _, point) in &self.hits {
            if labels[point as usize] != class {
                occupied[pixel as usize] = true;
            }
        }
        let radius = NEAR_SHARE_OF_FAR * self.far_radius();
        distance_to_nearest(&occupied, self.width, self.height)
            .into_iter()
            .map(|d| d <= radius)
            .collect()
    }

    fn far_radius(&self) -> f64 {
        FAR_FROM_POINTS * ((self.width * self.width + self.height * self.height) as f64).sqrt()
    }

    /// True for each pixel with no point within [`FAR_FROM_POINTS`] of the image diagonal.
    pub fn far_from_points(&self) -> Vec<bool> {
        let mut occupied = vec![false; self.width * self.height];
        for &(pixel, _, _) in &self.hits {
            occupied[pixel as usize] = true;
        }
        let radius = self.far_radius();
        distance_to_nearest(&occupied, self.width, self.height)
            .into_iter()
            .map(|d| d > radius)
            .collect()
    }
}

/// The class the strokes give a region of pixels, when one class clearly holds it: `strokes`
/// are frames' rasterized strokes, each with its region (the pixels far from every point,
/// [`View::far_from_points`]; a frame's support plane, `spread::support_plane`).
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

/// The convex hull of `points`, counter-clockwise in image coordinates (x right, y down), by
/// Andrew's monotone chain; fewer than three points when they are collinear.
fn convex_hull(points: &mut Vec<(i64, i64)>) -> Vec<(i64, i64)> {
    points.sort_unstable();
    points.dedup();
    if points.len() < 3 {
        return points.clone();
    }
    let cross = |o: (i64, i64), a: (i64, i64), b: (i64, i64)| (a.0 - o.0) * (b.1 - o.1) - (a.1 - o.1) * (b.0 - o.0);
    let mut hull: Vec<(i64, i64)> = Vec::with_capacity(2 * points.len());
    for pass in 0..2 {
        let start = hull.len();
        let ordered: Box<dyn Iterator<Item = &(i64, i64)>> = if pass == 0 {
            Box::new(points.iter())
        } else {
            Box::new(points.iter().rev())
        };
        for &p in ordered {
            while hull.len() >= start + 2 && cross(hull[hull.len() - 2], hull[hull.len() - 1], p) <= 0 {
                hull.pop();
            }
            hull.push(p);
        }
        hull.pop();
    }
    hull
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
    fn the_convex_hull_keeps_the_corners_and_drops_what_is_inside() {
        let mut points = vec![(0, 0), (4, 0), (4, 4), (0, 4), (2, 2), (1, 3), (2, 0), (0, 0)];
        let hull = convex_hull(&mut points);
        assert_eq!(hull.len(), 4, "{hull:?}");
        for corner in [(0, 0), (4, 0), (4, 4), (0, 4)] {
            assert!(hull.contains(&corner), "{corner:?} missing from {hull:?}");
        }
        assert!(convex_hull(&mut vec![(0, 0), (1, 1), (2, 2)]).len() < 3);
    }

    /// Points in a ring, as a reconstruction outlines an object whose middle is smooth, and one
    /// lone point far off: the outline is the ring's, and the lone point does not stretch it.
    #[test]
    fn the_outline_of_the_points_holds_their_hole_and_not_a_lone_point() {
        let (width, height) = (60usize, 60usize);
        let mut hits = Vec::new();
        let mut point = 0u32;
        for y in 10..50usize {
            for x in 10..50usize {
                let ring = !(16..44).contains(&x) || !(16..44).contains(&y);
                if ring && (x + y) % 2 == 0 {
                    hits.push(((y * width + x) as u32, 1.0, point));
                    point += 1;
                }
            }
        }
        hits.push(((2 * width + 58) as u32, 1.0, point));
        let labels = vec![1u16; hits.len()];
        let view = View { width, height, hits };
        let outline = view.outline_of_points_not_in(&labels, 0);
        assert!(outline[30 * width + 30], "the hole inside the ring");
        assert!(outline[12 * width + 12]);
        assert!(!outline[5 * width + 55], "towards the lone point");
        assert!(!outline[55 * width + 30]);
        // Points of the far class itself draw no outline.
        assert!(view.outline_of_points_not_in(&labels, 1).iter().all(|&inside| !inside));
    }

    /// Near means within half the far radius (1.27 px at 60 x 60) of a point not of the class:
    /// points the walk left unlabelled count, points of the class itself do not.
    #[test]
    fn pixels_near_the_points_of_the_other_classes() {
        let (width, height) = (60usize, 60usize);
        let hits = vec![
            ((10 * width + 10) as u32, 1.0, 0),
            ((40 * width + 40) as u32, 1.0, 1),
            ((5 * width + 50) as u32, 1.0, 2),
        ];
        let labels = [1u16, UNLABELLED, 0];
        let view = View { width, height, hits };
        let near = view.near_points_not_in(&labels, 0);
        assert!(near[10 * width + 10] && near[10 * width + 11] && near[11 * width + 10]);
        assert!(!near[11 * width + 11], "a diagonal step (1.41 px) is not near");
        assert!(near[40 * width + 41], "an unlabelled point counts");
        assert!(
            !near[5 * width + 50] && !near[5 * width + 51],
            "a point of the class itself does not"
        );
        assert_eq!(near.iter().filter(|&&n| n).count(), 10);
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
