//! Realistic synthetic scribbles drawn from ground truth, so quality can be measured without a
//! person: a few short, wobbly strokes per class, kept away from class boundaries the way a
//! careful annotator keeps the brush inside an object.
use image::GrayImage;

use super::{LabelSet, Stroke};
use crate::rng::SplitMix64;
use crate::scene::GT_VOID;

#[derive(Clone, Debug)]
pub struct ScribbleOptions {
    pub strokes_per_class: u32,
    /// Brush radius in pixels; None: 1.2 % of the image diagonal (at least 1.5 px).
    pub radius: Option<f32>,
    /// Stroke length as a fraction of the image's shorter side.
    pub length: f32,
    pub seed: u64,
}

impl Default for ScribbleOptions {
    fn default() -> Self {
        ScribbleOptions {
            strokes_per_class: 2,
            radius: None,
            length: 0.15,
            seed: 0,
        }
    }
}

/// Chamfer distance (in pixels, 3-4 weights / 3) from each pixel to the nearest pixel of another
/// class, void, or outside the image.
fn distance_to_boundary(gt: &GrayImage) -> Vec<f32> {
    let (w, h) = (gt.width() as i64, gt.height() as i64);
    let at = |x: i64, y: i64| gt.get_pixel(x as u32, y as u32).0[0];
    let inf = f32::MAX / 4.0;
    let mut d = vec![inf; (w * h) as usize];
    for y in 0..h {
        for x in 0..w {
            let c = at(x, y);
            let edge = x == 0 || y == 0 || x == w - 1 || y == h - 1;
            let differs = [(1, 0), (-1, 0), (0, 1), (0, -1)]
                .iter()
                .any(|(dx, dy)| (0..w).contains(&(x + dx)) && (0..h).contains(&(y + dy)) && at(x + dx, y + dy) != c);
            if c == GT_VOID || edge || differs {
                d[(y * w + x) as usize] = 0.0;
            }
        }
    }
    let mut relax = |x: i64, y: i64, nbrs: &[(i64, i64, f32)]| {
        let i = (y * w + x) as usize;
        for &(dx, dy, cost) in nbrs {
            let (nx, ny) = (x + dx, y + dy);
            if (0..w).contains(&nx) && (0..h).contains(&ny) {
                let v = d[(ny * w + nx) as usize] + cost;
                if v < d[i] {
                    d[i] = v;
                }
            }
        }
    };
    let fwd = [(-1, 0, 1.0), (0, -1, 1.0), (-1, -1, 4.0 / 3.0), (1, -1, 4.0 / 3.0)];
    let bwd = [(1, 0, 1.0), (0, 1, 1.0), (1, 1, 4.0 / 3.0), (-1, 1, 4.0 / 3.0)];
    for y in 0..h {
        for x in 0..w {
            relax(x, y, &fwd);
        }
    }
    for y in (0..h).rev() {
        for x in (0..w).rev() {
            relax(x, y, &bwd);
        }
    }
    d
}

/// Adds synthetic scribbles for `frame` (whose ground truth is `gt`) to `labels`. Classes are
/// the ground truth's ids; `labels.classes` must already list them.
pub fn scribble_frame(labels: &mut LabelSet, frame: u32, gt: &GrayImage, opts: &ScribbleOptions) {
    let (w, h) = gt.dimensions();
    let diag = ((w * w + h * h) as f32).sqrt();
    let radius = opts.radius.unwrap_or((0.012 * diag).max(1.5));
    let dist = distance_to_boundary(gt);
    let mut rng = SplitMix64::new(opts.seed ^ (frame as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15));
    let classes = labels.classes.len();
    for class in 0..classes {
        let pixels: Vec<usize> = (0..dist.len()).filter(|&i| gt.as_raw()[i] as usize == class).collect();
        if pixels.is_empty() {
            continue;
        }
        // Keep the whole brush inside the class; small objects get a brush-sized margin at
        // their deepest point instead of none at all.
        let deepest = pixels.iter().map(|&i| dist[i]).fold(0.0f32, f32::max);
        let margin = (radius + 1.0).min(deepest);
        let inside = |x: f32, y: f32| {
            let (xi, yi) = (x.floor() as i64, y.floor() as i64);
            if xi < 0 || yi < 0 || xi >= w as i64 || yi >= h as i64 {
                return false;
            }
            let i = (yi as u32 * w + xi as u32) as usize;
            gt.as_raw()[i] as usize == class && dist[i] >= margin
        };
        let candidates: Vec<usize> = pixels.into_iter().filter(|&i| dist[i] >= margin).collect();
        let brush = radius.min(margin.max(0.75));
        for _ in 0..opts.strokes_per_class {
            let start = candidates[rng.below(candidates.len() as u64) as usize];
            let (mut x, mut y) = ((start as u32 % w) as f32 + 0.5, (start as u32 / w) as f32 + 0.5);
            let mut angle = rng.uniform(0.0, std::f64::consts::TAU) as f32;
            let mut points = vec![[x, y]];
            let target = opts.length * w.min(h) as f32;
            let step = 1.5f32;
            let mut travelled = 0.0;
            while travelled < target {
                angle += rng.uniform(-0.35, 0.35) as f32;
                let (nx, ny) = (x + step * angle.cos(), y + step * angle.sin());
                if !inside(nx, ny) {
                    // Turn around once rather than cross a boundary; a stroke may end early.
                    angle += std::f32::consts::PI;
                    let (bx, by) = (x + step * angle.cos(), y + step * angle.sin());
                    if !inside(bx, by) || points.len() > 1 && travelled > target * 0.5 {
                        break;
                    }
                    continue;
                }
                (x, y) = (nx, ny);
                points.push([x, y]);
                travelled += step;
            }
            labels.push_stroke(
                frame,
                Stroke {
                    class: Some(class as u16),
                    radius: brush,
                    points,
                },
            );
        }
    }
}

/// Synthetic scribbles on each of `frames` of `scene`, over the scene's classes. Frames
/// without ground truth are skipped; an index past the scene is the caller's to check.
pub fn scribble_frames(scene: &crate::scene::Scene, frames: &[u32], opts: &ScribbleOptions) -> LabelSet {
    let mut labels = LabelSet::new(scene.classes.clone());
    for &f in frames {
        if let Some(gt) = scene.frames.get(f as usize).and_then(|frame| frame.gt.as_ref()) {
            scribble_frame(&mut labels, f, gt, opts);
        }
    }
    labels
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::labels::{ClassInfo, UNLABELLED, rasterize_frame};

    #[test]
    fn strokes_stay_inside_their_class_and_every_class_gets_some() {
        // Three classes: left half 0, right half 1, a 6x6 square of 2 in the middle.
        let gt = GrayImage::from_fn(80, 60, |x, y| {
            image::Luma([if (37..43).contains(&x) && (27..33).contains(&y) {
                2
            } else {
                (x >= 40) as u8
            }])
        });
        let classes = (0..3)
            .map(|i| ClassInfo {
                name: format!("c{i}"),
                color: [i as u8; 3],
            })
            .collect();
        let mut labels = LabelSet::new(classes);
        scribble_frame(
            &mut labels,
            0,
            &gt,
            &ScribbleOptions {
                seed: 7,
                ..Default::default()
            },
        );
        let map = rasterize_frame(labels.frame(0), 80, 60);
        let mut seen = [0usize; 3];
        for (i, &v) in map.iter().enumerate() {
            if v != UNLABELLED {
                assert_eq!(v as u8, gt.as_raw()[i], "scribble pixel {i} crosses into another class");
                seen[v as usize] += 1;
            }
        }
        assert!(seen.iter().all(|&n| n > 0), "every class is scribbled: {seen:?}");
        // Scribbles are sparse: well under a tenth of the image.
        assert!(seen.iter().sum::<usize>() < 80 * 60 / 10, "{seen:?}");
    }
}
