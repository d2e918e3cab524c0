//! Edge-aware refinement of a rendered class map, guided by the frame's own colour and depth.
//!
//! The field's class boundaries are as soft as its features: codes come from image windows a few
//! pixels wide and a grid cell per code, so a rendered object carries a ring of its class a pixel
//! or two into the table around it, and small unlabelled patches (a shadow, a shaded edge) can
//! flip to a wrong class. The frame image has those boundaries sharp. A few rounds of a joint
//! bilateral filter on the class probabilities (each pixel takes the average of its neighbours'
//! probabilities, weighted by how close they are in the image, in colour and in depth) let a
//! region agree with itself and stop at edges, so the halo goes to the table it looks like.
//!
//! Depth is in the weights because colour alone lets objects of the same colour (the demo's red
//! ball and red box) leak into each other where they touch in the image. Cost: one pass over
//! 7 x 7 taps per round (`tests::bench` times it); docs/results/measurements.md has the gains
//! and timings measured. The page runs the GPU twin (`refine::gpu`,
//! `shaders/refine.wgsl`); the CLI runs this one.
pub mod gpu;

use crate::scene::{Guide, Scene};
use serde::{Deserialize, Serialize};

/// How the class probabilities are refined. `iterations: 0` turns refinement off.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RefineOptions {
    /// Rounds of filtering; each spreads agreement about one window further.
    pub iterations: u32,
    /// Colour distance (sRGB in [0, 1], Euclidean over the three channels) at which a
    /// neighbour's weight falls to e^-1/2.
    pub colour_sigma: f32,
    /// Relative depth difference, |ln(d / d')|, at which the weight falls to e^-1/2; pixels
    /// without depth skip this term.
    pub depth_sigma: f32,
    /// Spatial reach as a fraction of the image diagonal (2 pixels at 80 x 60), so the same
    /// setting suits every resolution: the field's blur scales with the image.
    pub spatial_sigma: f32,
    /// Filter each pixel's vote (1 for its most likely class, 0 for the others) instead of its
    /// probabilities, so every pixel counts alike however confident the field is there: where
    /// one class comes out confident and another barely above its rivals (a plain backdrop
    /// behind an object), averaging probabilities lets the confident class flood the other.
    /// On by default: the quality suite's paired comparison on identical fields
    /// (docs/quality.md, "Refinement").
    pub votes: bool,
}

impl Default for RefineOptions {
    fn default() -> Self {
        RefineOptions::DEFAULT
    }
}

impl RefineOptions {
    pub const DEFAULT: RefineOptions = RefineOptions {
        iterations: 3,
        colour_sigma: 0.1,
        depth_sigma: 0.05,
        spatial_sigma: 0.02,
        votes: true,
    };
    /// Rounds on a capture without dense depth (`for_scene`).
    pub const ROUNDS_WITHOUT_DENSE_DEPTH: u32 = 10;

    /// The defaults for `scene`: [`RefineOptions::DEFAULT`]'s 3 rounds where most frames have
    /// dense depth, [`RefineOptions::ROUNDS_WITHOUT_DENSE_DEPTH`] where they do not (a photo
    /// capture: no depth, or a reconstruction's sparse points). Without depth to train on, the
    /// field's silhouettes are soft and its class runs several pixels past an object's outline;
    /// more rounds pull that ring back to the colour edge. With dense depth the ring is thin,
    /// and more rounds only let regions of one colour leak into each other (docs/results/quality-log.md,
    /// "Refinement rounds without dense depth").
    pub fn for_scene(scene: &Scene) -> RefineOptions {
        let iterations = if scene.lacks_dense_depth() {
            RefineOptions::ROUNDS_WITHOUT_DENSE_DEPTH
        } else {
            RefineOptions::DEFAULT.iterations
        };
        RefineOptions {
            iterations,
            ..RefineOptions::DEFAULT
        }
    }

    /// The field's own class map.
    pub const OFF: RefineOptions = RefineOptions {
        iterations: 0,
        ..RefineOptions::DEFAULT
    };

    pub fn is_off(&self) -> bool {
        self.iterations == 0
    }

    /// A value that cannot work, named by its field.
    pub fn validate(&self) -> Result<(), String> {
        for (name, v) in [
            ("colour_sigma", self.colour_sigma),
            ("depth_sigma", self.depth_sigma),
            ("spatial_sigma", self.spatial_sigma),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(format!("refine: `{name}` = {v}: must be a positive number"));
            }
        }
        if self.iterations > MAX_ITERATIONS {
            return Err(format!(
                "refine: `iterations` = {}: at most {MAX_ITERATIONS}",
                self.iterations
            ));
        }
        Ok(())
    }
}

const MAX_ITERATIONS: u32 = 64;

/// Taps on each side of the centre: a 7 x 7 window whatever the resolution; larger reaches
/// space the taps out instead of adding more.
pub(crate) const HALF_TAPS: i64 = 3;

/// Refines per-pixel class probabilities (`classes` values per pixel, row-major, each pixel's
/// summing to 1) in place on the CPU (`refine::gpu` is the GPU twin). Errors name a size that
/// does not match the guide, or a bad option.
pub fn refine_probabilities(
    probabilities: &mut Vec<f32>,
    classes: usize,
    guide: Guide<'_>,
    options: &RefineOptions,
) -> Result<(), String> {
    check_inputs(probabilities.len(), classes, guide, options)?;
    if options.is_off() || probabilities.is_empty() {
        return Ok(());
    }
    if options.votes {
        to_votes(probabilities, classes);
    }
    let taps = TapWeights::new(guide, options);
    let mut next = vec![0f32; probabilities.len()];
    for _ in 0..options.iterations {
        taps.filter(probabilities, &mut next, classes);
        std::mem::swap(probabilities, &mut next);
    }
    Ok(())
}

/// Replaces each pixel's `classes` probabilities with its vote: 1 for the most likely class (the
/// first of equals), 0 for the others (`RefineOptions::votes`; the GPU twin filters the same).
pub(crate) fn to_votes(probabilities: &mut [f32], classes: usize) {
    for pixel in probabilities.chunks_mut(classes.max(1)) {
        let best = pixel
            .iter()
            .enumerate()
            .fold(
                (0, f32::NEG_INFINITY),
                |(b, bv), (i, &v)| if v > bv { (i, v) } else { (b, bv) },
            )
            .0;
        for (i, p) in pixel.iter_mut().enumerate() {
            *p = if i == best { 1.0 } else { 0.0 };
        }
    }
}

/// Checks that `values` probabilities of `classes` classes fit `guide`, and the options.
pub(crate) fn check_inputs(
    values: usize,
    classes: usize,
    guide: Guide<'_>,
    options: &RefineOptions,
) -> Result<(), String> {
    options.validate()?;
    let (width, height) = guide.rgb.dimensions();
    let pixels = width as usize * height as usize;
    if classes == 0 || values != pixels * classes {
        return Err(format!(
            "refine: {values} probabilities for {classes} classes do not fit a {width} x {height} guide"
        ));
    }
    if let Some(depth) = guide.depth
        && depth.dimensions() != (width, height)
    {
        return Err(format!(
            "refine: the depth guide is {} x {}, the colour guide {width} x {height}",
            depth.width(),
            depth.height()
        ));
    }
    Ok(())
}

/// Log depth at or below this marks a pixel without depth (`NO_DEPTH` in shaders/refine.wgsl).
pub(crate) const NO_DEPTH: f32 = -1.0e30;

/// The guide's log depth per pixel, [`NO_DEPTH`] where there is no reading.
pub(crate) fn log_depth(guide: Guide<'_>) -> Vec<f32> {
    match guide.depth {
        Some(depth) => depth
            .pixels()
            .map(|d| if d.0[0] == 0 { NO_DEPTH } else { f32::from(d.0[0]).ln() })
            .collect(),
        None => vec![NO_DEPTH; guide.rgb.width() as usize * guide.rgb.height() as usize],
    }
}

/// Tap spacing and the 1 / (2 sigma^2) of each weight term, for a guide of `width x height`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct TapScales {
    pub step: u32,
    pub spatial: f32,
    pub colour: f32,
    pub depth: f32,
}

impl TapScales {
    pub(crate) fn new(width: u32, height: u32, options: &RefineOptions) -> TapScales {
        let diagonal = (f64::from(width).powi(2) + f64::from(height).powi(2)).sqrt() as f32;
        let sigma_px = (options.spatial_sigma * diagonal).max(0.5);
        TapScales {
            step: ((sigma_px / 2.0).round() as u32).max(1),
            spatial: 1.0 / (2.0 * sigma_px * sigma_px),
            colour: 1.0 / (2.0 * options.colour_sigma * options.colour_sigma),
            depth: 1.0 / (2.0 * options.depth_sigma * options.depth_sigma),
        }
    }
}

/// The guide in the form the weights need: colour in [0, 1] and log depth.
struct TapWeights {
    width: i64,
    height: i64,
    colour: Vec<[f32; 3]>,
    log_depth: Vec<f32>,
    scales: TapScales,
}

impl TapWeights {
    fn new(guide: Guide<'_>, options: &RefineOptions) -> TapWeights {
        let (width, height) = guide.rgb.dimensions();
        TapWeights {
            width: i64::from(width),
            height: i64::from(height),
            colour: guide.rgb.pixels().map(|p| p.0.map(|c| f32::from(c) / 255.0)).collect(),
            log_depth: log_depth(guide),
            scales: TapScales::new(width, height, options),
        }
    }

    fn weight(&self, centre: usize, other: usize, offset2: f32) -> f32 {
        let (a, b) = (self.colour[centre], self.colour[other]);
        let colour2 = (a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2);
        let (d0, d1) = (self.log_depth[centre], self.log_depth[other]);
        let depth2 = if d0 > NO_DEPTH && d1 > NO_DEPTH {
            (d0 - d1) * (d0 - d1)
        } else {
            0.0
        };
        let s = &self.scales;
        (-(offset2 * s.spatial + colour2 * s.colour + depth2 * s.depth)).exp()
    }

    /// One round: `out` = the weighted mean of `input` over each pixel's in-image taps.
    fn filter(&self, input: &[f32], out: &mut [f32], classes: usize) {
        let step = i64::from(self.scales.step);
        for y in 0..self.height {
            for x in 0..self.width {
                let centre = (y * self.width + x) as usize;
                let acc = &mut out[centre * classes..(centre + 1) * classes];
                acc.fill(0.0);
                let mut total = 0.0;
                for ty in -HALF_TAPS..=HALF_TAPS {
                    let sy = y + ty * step;
                    if sy < 0 || sy >= self.height {
                        continue;
                    }
                    for tx in -HALF_TAPS..=HALF_TAPS {
                        let sx = x + tx * step;
                        if sx < 0 || sx >= self.width {
                            continue;
                        }
                        let other = (sy * self.width + sx) as usize;
                        let offset2 = ((ty * ty + tx * tx) * step * step) as f32;
                        let w = self.weight(centre, other, offset2);
                        total += w;
                        for (a, &p) in acc.iter_mut().zip(&input[other * classes..(other + 1) * classes]) {
                            *a += w * p;
                        }
                    }
                }
                // The centre tap has weight 1, so `total` >= 1.
                acc.iter_mut().for_each(|a| *a /= total);
            }
        }
    }
}

/// The argmax class and its probability for each pixel.
pub fn argmax_and_confidence(probabilities: &[f32], classes: usize) -> (Vec<u8>, Vec<f32>) {
    probabilities
        .chunks_exact(classes.max(1))
        .map(|p| {
            let (best, top) =
                p.iter().enumerate().fold(
                    (0usize, f32::NEG_INFINITY),
                    |(bi, bv), (i, &x)| if x > bv { (i, x) } else { (bi, bv) },
                );
            (best as u8, top)
        })
        .unzip()
}

#[cfg(test)]
mod tests {
    use super::*;
    use image::RgbImage;

    #[test]
    fn votes_count_every_pixel_alike() {
        // A barely-right pixel (0.55) beside a confident wrong one (0.95 for class 1): averaged
        // probabilities side with the confident one, votes are even and keep each as it was.
        let mut p = vec![0.55, 0.45, 0.05, 0.95];
        to_votes(&mut p, 2);
        assert_eq!(p, vec![1.0, 0.0, 0.0, 1.0]);
        let mut tie = vec![0.5, 0.5];
        to_votes(&mut tie, 2);
        assert_eq!(tie, vec![1.0, 0.0], "the first of equals");
    }
    use image::{ImageBuffer, Luma};

    fn one_hot(classes: &[u8], count: usize, softness: f32) -> Vec<f32> {
        classes
            .iter()
            .flat_map(|&c| {
                (0..count).map(move |k| {
                    if k == c as usize {
                        1.0 - softness
                    } else {
                        softness / (count - 1) as f32
                    }
                })
            })
            .collect()
    }

    /// The default rounds and sigmas with a reach of about 2.3 pixels on these 20 x 12 images (the
    /// default, 2 % of the diagonal, is under half a pixel here), filtering probabilities.
    fn options() -> RefineOptions {
        RefineOptions {
            spatial_sigma: 0.1,
            votes: false,
            ..RefineOptions::default()
        }
    }

    /// A 20 x 12 image: left half dark red, right half light grey, the boundary at x = 10.
    fn two_region_guide() -> RgbImage {
        RgbImage::from_fn(20, 12, |x, _| {
            if x < 10 {
                image::Rgb([120, 20, 20])
            } else {
                image::Rgb([200, 200, 200])
            }
        })
    }

    #[test]
    fn a_halo_across_an_image_edge_goes_back_to_the_side_it_looks_like() {
        let rgb = two_region_guide();
        // The field's map: class 1 reaches a pixel past the edge, and the grey side has a stray
        // pixel of class 1 too.
        let mut map: Vec<u8> = (0..12 * 20).map(|i| u8::from(i % 20 < 11)).collect();
        map[5 * 20 + 16] = 1;
        let mut p = one_hot(&map, 2, 0.3);
        refine_probabilities(&mut p, 2, Guide::colour_only(&rgb), &options()).unwrap();
        let (classes, confidence) = argmax_and_confidence(&p, 2);
        let want: Vec<u8> = (0..12 * 20).map(|i| u8::from(i % 20 < 10)).collect();
        assert_eq!(classes, want);
        assert!(confidence.iter().all(|&c| (0.5..=1.0).contains(&c)));
        let sums = p.chunks_exact(2).map(|q| q[0] + q[1]);
        assert!(sums.into_iter().all(|s| (s - 1.0).abs() < 1e-5));
    }

    #[test]
    fn depth_separates_regions_of_the_same_colour() {
        // One colour everywhere; the left half is 1 m away, the right half 2 m.
        let rgb = RgbImage::from_pixel(20, 12, image::Rgb([150, 40, 40]));
        let depth = ImageBuffer::from_fn(20, 12, |x, _| Luma([if x < 10 { 1000u16 } else { 2000 }]));
        let map: Vec<u8> = (0..12 * 20).map(|i| u8::from(i % 20 < 11)).collect();
        let refined = |depth| {
            let mut p = one_hot(&map, 2, 0.3);
            refine_probabilities(
                &mut p,
                2,
                Guide {
                    rgb: &rgb,
                    depth,
                    codes: None,
                },
                &options(),
            )
            .unwrap();
            argmax_and_confidence(&p, 2).0
        };
        let want: Vec<u8> = (0..12 * 20).map(|i| u8::from(i % 20 < 10)).collect();
        assert_eq!(refined(Some(&depth)), want);
        // Without depth nothing in the guide marks the edge: the halo stays.
        assert_ne!(refined(None), want);
    }

    #[test]
    fn missing_depth_readings_leave_the_colour_term_in_charge() {
        let rgb = two_region_guide();
        let depth = ImageBuffer::from_fn(20, 12, |x, y| Luma([if (x + y) % 3 == 0 { 0u16 } else { 1500 }]));
        let map: Vec<u8> = (0..12 * 20).map(|i| u8::from(i % 20 < 11)).collect();
        let mut p = one_hot(&map, 2, 0.3);
        refine_probabilities(
            &mut p,
            2,
            Guide {
                rgb: &rgb,
                depth: Some(&depth),
                codes: None,
            },
            &options(),
        )
        .unwrap();
        let want: Vec<u8> = (0..12 * 20).map(|i| u8::from(i % 20 < 10)).collect();
        assert_eq!(argmax_and_confidence(&p, 2).0, want);
        assert!(p.iter().all(|v| v.is_finite()));
    }

    /// `cargo test --release --lib refine::tests::bench -- --ignored --nocapture`
    #[test]
    #[ignore = "benchmark: prints the time per frame"]
    fn bench() {
        for (w, h) in [(80u32, 60u32), (160, 120), (640, 480)] {
            let rgb = RgbImage::from_fn(w, h, |x, y| image::Rgb([(x * 7 % 256) as u8, (y * 5 % 256) as u8, 90]));
            let depth = ImageBuffer::from_fn(w, h, |x, y| Luma([1000 + (x + y) as u16]));
            let classes = 6;
            let base: Vec<f32> = (0..w as usize * h as usize * classes)
                .map(|i| ((i * 2654435761) % 1000) as f32 / 1000.0 + 0.01)
                .collect();
            let mut p = base.clone();
            let guide = Guide {
                rgb: &rgb,
                depth: Some(&depth),
                codes: None,
            };
            let clock = std::time::Instant::now();
            let runs = 3;
            for _ in 0..runs {
                p.copy_from_slice(&base);
                refine_probabilities(&mut p, classes, guide, &RefineOptions::default()).unwrap();
            }
            let ms = clock.elapsed().as_secs_f64() * 1e3 / runs as f64;
            println!("refine {w} x {h}, {classes} classes, 3 rounds of 7 x 7 taps: {ms:.1} ms per frame");
        }
    }

    #[test]
    fn off_changes_nothing_and_bad_input_is_named() {
        let rgb = two_region_guide();
        let map: Vec<u8> = (0..12 * 20).map(|i| u8::from(i % 20 < 12)).collect();
        let before = one_hot(&map, 2, 0.3);
        let mut p = before.clone();
        refine_probabilities(&mut p, 2, Guide::colour_only(&rgb), &RefineOptions::OFF).unwrap();
        assert_eq!(p, before);

        let err = refine_probabilities(&mut p, 3, Guide::colour_only(&rgb), &RefineOptions::default()).unwrap_err();
        assert!(err.contains("3 classes") && err.contains("20 x 12"), "{err}");
        let bad = RefineOptions {
            colour_sigma: 0.0,
            ..RefineOptions::default()
        };
        let err = refine_probabilities(&mut p, 2, Guide::colour_only(&rgb), &bad).unwrap_err();
        assert!(err.contains("colour_sigma"), "{err}");
        let small_depth = ImageBuffer::from_pixel(4, 4, Luma([1000u16]));
        let err = refine_probabilities(
            &mut p,
            2,
            Guide {
                rgb: &rgb,
                depth: Some(&small_depth),
                codes: None,
            },
            &RefineOptions::default(),
        )
        .unwrap_err();
        assert!(err.contains("4 x 4"), "{err}");
    }
}
