//! The random walk on one frame's pixel grid (Grady 2006): edge weights from colour, depth and
//! surface normals, and the conjugate-gradient solve that gives, per class, the probability that
//! a walk from each pixel reaches that class's strokes first (`spread::propagate` uses it;
//! docs/quality.md explains the weights).
use crate::labels::UNLABELLED;
use crate::pause::Pause;
use crate::scene::Guide;
use crate::scene::Intrinsics;
use crate::spread::PropagationOptions;
use crate::spread::colour::srgb_to_lab;
use crate::spread::normals::{depth_points, folds_outward, normals_of_points};

/// Conjugate-gradient stopping point: residual relative to the right-hand side.
const TOLERANCE: f64 = 1e-4;
/// Smallest step weight: keeps every pixel connected to the strokes, so each system has one
/// solution, while a pixel behind a strong edge still ends up uncertain.
const MIN_WEIGHT: f32 = 1e-6;
/// The pixel grid with a step weight on each 4-neighbour edge.
pub(crate) struct PixelGraph {
    width: usize,
    height: usize,
    /// Weight of the edge from pixel i to i + 1 (0 in the last column).
    right: Vec<f32>,
    /// Weight of the edge from pixel i to i + width (0 in the last row).
    down: Vec<f32>,
    /// Weight of each pixel's edge to a sink that ends the walk (`PropagationOptions::reach`).
    absorption: f64,
}

impl PixelGraph {
    pub(crate) fn new(guide: Guide<'_>, camera: Option<&Intrinsics>, options: &PropagationOptions) -> PixelGraph {
        let (width, height) = (guide.rgb.width() as usize, guide.rgb.height() as usize);
        let lab: Vec<[f32; 3]> = guide.rgb.pixels().map(|p| srgb_to_lab(p.0)).collect();
        let log_depth: Vec<Option<f32>> = match guide.depth {
            Some(d) if d.len() == width * height => d
                .pixels()
                .map(|d| (d.0[0] > 0).then(|| f32::from(d.0[0]).ln()))
                .collect(),
            _ => vec![None; width * height],
        };
        let colour_scale = 0.5 / (options.colour_sigma * options.colour_sigma);
        let depth_scale = 0.5 / (options.depth_sigma * options.depth_sigma);
        let dense_depth = log_depth.iter().filter(|d| d.is_some()).count() * 2 > log_depth.len();
        let points = match (guide.depth, camera) {
            (Some(depth), Some(camera)) if options.normal_sigma > 0.0 && dense_depth => depth_points(depth, camera),
            _ => vec![None; width * height],
        };
        let normals = normals_of_points(&points, width);
        let normal_scale = if options.normal_sigma > 0.0 {
            1.0 / (options.normal_sigma * options.normal_sigma)
        } else {
            0.0
        };
        // Feature differences in units of the frame's root-mean-square neighbour difference, so
        // one sigma means the same on every extractor and code size.
        let dim = guide.codes.map_or(0, |c| c.dim);
        let codes = match guide.codes {
            Some(c) if options.feature_sigma > 0.0 && dim > 0 => c.upsampled(width, height),
            _ => Vec::new(),
        };
        let code_distance = |a: usize, b: usize| -> f32 {
            (0..dim)
                .map(|k| (codes[a * dim + k] - codes[b * dim + k]).powi(2))
                .sum()
        };
        let feature_scale = if codes.is_empty() {
            0.0
        } else {
            let (mut sum, mut n) = (0f64, 0usize);
            for i in 0..width * height {
                if i % width + 1 < width {
                    sum += f64::from(code_distance(i, i + 1));
                    n += 1;
                }
                if i + width < width * height {
                    sum += f64::from(code_distance(i, i + width));
                    n += 1;
                }
            }
            let mean = (sum / n.max(1) as f64) as f32;
            if mean > 0.0 {
                0.5 / (options.feature_sigma * options.feature_sigma * mean)
            } else {
                0.0
            }
        };
        let hole_factor = if dense_depth { options.depth_hole_factor } else { 1.0 };
        let weight = |a: usize, b: usize| {
            let dc: f32 = (0..3).map(|k| (lab[a][k] - lab[b][k]).powi(2)).sum();
            let (dd, factor) = match (log_depth[a], log_depth[b]) {
                (Some(x), Some(y)) => ((x - y).powi(2), 1.0),
                (None, None) => (0.0, 1.0),
                _ => (0.0, hole_factor),
            };
            let turn = match (normals[a], normals[b], points[a], points[b]) {
                (Some(n), Some(m), Some(p), Some(q)) if options.inward_creases_only && folds_outward(p, n, q, m) => 0.0,
                (Some(n), Some(m), _, _) => 1.0 - (n[0] * m[0] + n[1] * m[1] + n[2] * m[2]),
                _ => 0.0,
            };
            let df = if feature_scale > 0.0 {
                code_distance(a, b) * feature_scale
            } else {
                0.0
            };
            ((-(dc * colour_scale + dd * depth_scale + turn * normal_scale + df)).exp() * factor).max(MIN_WEIGHT)
        };
        let mut right = vec![0f32; width * height];
        let mut down = vec![0f32; width * height];
        for y in 0..height {
            for x in 0..width {
                let i = y * width + x;
                if x + 1 < width {
                    right[i] = weight(i, i + 1);
                }
                if y + 1 < height {
                    down[i] = weight(i, i + width);
                }
            }
        }
        // A walk that ends with probability about a/4 per step spreads over about 1/sqrt(a)
        // pixels of a uniform region.
        let reach_pixels = f64::from(options.reach) * ((width * width + height * height) as f64).sqrt();
        PixelGraph {
            width,
            height,
            right,
            down,
            absorption: 1.0 / (reach_pixels * reach_pixels).max(1.0),
        }
    }

    /// Calls `f(neighbour, weight)` for each 4-neighbour of `i`.
    fn for_neighbours(&self, i: usize, mut f: impl FnMut(usize, f32)) {
        let (x, y) = (i % self.width, i / self.width);
        if x + 1 < self.width {
            f(i + 1, self.right[i]);
        }
        if x > 0 {
            f(i - 1, self.right[i - 1]);
        }
        if y + 1 < self.height {
            f(i + self.width, self.down[i]);
        }
        if y > 0 {
            f(i - self.width, self.down[i - self.width]);
        }
    }

    /// The probability that a walk from each pixel reaches a stroke of `class` before a stroke of
    /// another class and before it ends: strokes are fixed at 1 or 0, and every other pixel solves
    /// `(degree + absorption)·x_i − Σ w_ij·x_j = 0`, here by Jacobi-preconditioned conjugate gradients over the
    /// unlabelled pixels.
    pub(crate) async fn walk(&self, seeds: &[u16], class: u16, pause: &mut impl Pause) -> Vec<f32> {
        let n = seeds.len();
        let free: Vec<usize> = (0..n).filter(|&i| seeds[i] == UNLABELLED).collect();
        let mut slot = vec![u32::MAX; n];
        for (k, &i) in free.iter().enumerate() {
            slot[i] = k as u32;
        }
        // The system over the free pixels in one flat list (each free pixel's free neighbours,
        // by slot), so each iteration reads memory in order.
        let mut degree = vec![self.absorption; free.len()];
        let mut rhs = vec![0f64; free.len()];
        let mut starts = Vec::with_capacity(free.len() + 1);
        let mut links: Vec<(u32, f32)> = Vec::with_capacity(4 * free.len());
        for (k, &i) in free.iter().enumerate() {
            starts.push(links.len() as u32);
            self.for_neighbours(i, |j, w| {
                degree[k] += f64::from(w);
                if seeds[j] == class {
                    rhs[k] += f64::from(w);
                }
                if slot[j] != u32::MAX {
                    links.push((slot[j], w));
                }
            });
        }
        starts.push(links.len() as u32);
        let apply = |x: &[f64], out: &mut [f64]| {
            for (k, out) in out.iter_mut().enumerate() {
                let mut sum = degree[k] * x[k];
                for &(j, w) in &links[starts[k] as usize..starts[k + 1] as usize] {
                    sum -= f64::from(w) * x[j as usize];
                }
                *out = sum;
            }
        };
        let x = conjugate_gradient(apply, &rhs, &degree, 4 * (self.width + self.height) + 200, pause).await;
        let mut p: Vec<f32> = seeds.iter().map(|&s| if s == class { 1.0 } else { 0.0 }).collect();
        for (k, &i) in free.iter().enumerate() {
            p[i] = x[k].clamp(0.0, 1.0) as f32;
        }
        p
    }
}

/// Solves `A x = b` for a symmetric positive definite `A` given as `apply(x, out)`, with the
/// Jacobi preconditioner `diagonal`, from x = 0, for at most `max_iterations` iterations, pausing
/// before each.
pub(crate) async fn conjugate_gradient(
    apply: impl Fn(&[f64], &mut [f64]),
    b: &[f64],
    diagonal: &[f64],
    max_iterations: usize,
    pause: &mut impl Pause,
) -> Vec<f64> {
    let n = b.len();
    let mut x = vec![0f64; n];
    let mut r = b.to_vec();
    let b_norm = b.iter().map(|v| v * v).sum::<f64>().sqrt();
    if b_norm == 0.0 {
        return x;
    }
    let precondition = |r: &[f64], z: &mut [f64]| {
        for ((z, r), d) in z.iter_mut().zip(r).zip(diagonal) {
            *z = r / d.max(1e-30);
        }
    };
    let mut z = vec![0f64; n];
    precondition(&r, &mut z);
    let mut p = z.clone();
    let mut rz: f64 = r.iter().zip(&z).map(|(a, b)| a * b).sum();
    let mut ap = vec![0f64; n];
    for _ in 0..max_iterations {
        pause.pause().await;
        apply(&p, &mut ap);
        let pap: f64 = p.iter().zip(&ap).map(|(a, b)| a * b).sum();
        if pap <= 0.0 {
            break;
        }
        let alpha = rz / pap;
        for k in 0..n {
            x[k] += alpha * p[k];
            r[k] -= alpha * ap[k];
        }
        if r.iter().map(|v| v * v).sum::<f64>().sqrt() <= TOLERANCE * b_norm {
            break;
        }
        precondition(&r, &mut z);
        let rz_next: f64 = r.iter().zip(&z).map(|(a, b)| a * b).sum();
        let beta = rz_next / rz;
        rz = rz_next;
        for k in 0..n {
            p[k] = z[k] + beta * p[k];
        }
    }
    x
}
