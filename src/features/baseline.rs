//! A feature extractor that needs no weights, so packing works with nothing downloaded:
//! illumination-invariant colour and texture statistics of windows of several sizes around each
//! cell.
//!
//! Per scale (window half-size r): mean and standard deviation of the chromaticity (linear RGB
//! divided by its sum; 6) and the orientation histogram of log-intensity gradients (four unsigned
//! bins) divided by the window's mean gradient magnitude (4). None of these change when a surface
//! is lit more or less: a shadow on a table, or the side of the table away from the light, keeps
//! the table's values. With brightness in the features instead (CIE L\*a\*b\* means and gradient
//! energies, this extractor's first version), the trained field gave every dark unlabelled region
//! the class of whichever scribbled object had dark pixels, and the masks were worse
//! (docs/results/measurements.md, docs/features.md). Where brightness itself tells classes
//! apart (a white box on a grey desk) they give up some of it. Windows of a few sizes let a cell
//! see both its own texture and its surroundings. Box sums come from integral images, so the cost
//! is a few passes over the image whatever the window size.
use image::RgbImage;

use super::{Extractor, FeatureError, FeatureMap};

/// Quantities summed per window: chromaticity r, g, b, their squares, |∇ log I|, four
/// orientation bins of ∇ log I.
const CHANNELS: usize = 11;
const FEATURES_PER_SCALE: usize = 10;
/// Added to the linear intensity before its logarithm and to the gradient magnitude before
/// dividing by it, so black pixels and flat windows give zeros rather than noise.
const INTENSITY_FLOOR: f64 = 1e-3;
const MAGNITUDE_FLOOR: f64 = 1e-3;

#[derive(Clone, Debug, PartialEq)]
pub struct Baseline {
    /// Pixels per feature cell along each axis.
    pub stride: u32,
    /// Window half-sizes in pixels, one group of statistics each.
    pub radii: Vec<u32>,
}

impl Default for Baseline {
    fn default() -> Self {
        Baseline::with_stride(8)
    }
}

impl Baseline {
    /// Windows of half a cell, one and a half cells and four cells around each cell: the cell
    /// itself, its neighbours, and its surroundings.
    pub fn with_stride(stride: u32) -> Baseline {
        let stride = stride.max(1);
        Baseline {
            stride,
            radii: vec![stride.div_ceil(2), (3 * stride).div_ceil(2), 4 * stride],
        }
    }

    pub fn dim(&self) -> u32 {
        (self.radii.len() * FEATURES_PER_SCALE) as u32
    }
}

impl Extractor for Baseline {
    fn describe(&self) -> String {
        let radii: Vec<String> = self.radii.iter().map(|r| r.to_string()).collect();
        format!(
            "baseline chromaticity+gradient-orientation statistics, windows of half-size {} px, stride {}",
            radii.join(","),
            self.stride
        )
    }

    fn extract(&self, rgb: &RgbImage) -> Result<FeatureMap, FeatureError> {
        let (w, h) = rgb.dimensions();
        if w < 2 || h < 2 || self.stride == 0 || self.radii.is_empty() {
            return Err(FeatureError::invalid(
                "baseline extractor",
                format!(
                    "needs an image of at least 2x2, a stride > 0 and a window (got {w}x{h}, stride {}, {} windows)",
                    self.stride,
                    self.radii.len()
                ),
            ));
        }
        let integral = Integral::of(&per_pixel_channels(rgb), w as usize, h as usize);
        let gw = w.div_ceil(self.stride);
        let gh = h.div_ceil(self.stride);
        let mut out = FeatureMap::zeros(gh, gw, self.dim());
        let mut sums = [0.0f64; CHANNELS];
        for gy in 0..gh {
            let cy = (gy * self.stride + self.stride / 2).min(h - 1) as i64;
            for gx in 0..gw {
                let cx = (gx * self.stride + self.stride / 2).min(w - 1) as i64;
                let o = ((gy * gw + gx) * self.dim()) as usize;
                for (s, &r) in self.radii.iter().enumerate() {
                    let r = r as i64;
                    let n = integral.window(cx - r, cy - r, cx + r + 1, cy + r + 1, &mut sums);
                    let f = &mut out.data[o + s * FEATURES_PER_SCALE..o + (s + 1) * FEATURES_PER_SCALE];
                    for c in 0..3 {
                        let mean = sums[c] / n;
                        let var = (sums[c + 3] / n - mean * mean).max(0.0);
                        f[c] = mean as f32;
                        f[c + 3] = var.sqrt() as f32;
                    }
                    let magnitude = sums[6] / n + MAGNITUDE_FLOOR;
                    for b in 0..4 {
                        f[6 + b] = (sums[7 + b] / n / magnitude) as f32;
                    }
                }
            }
        }
        Ok(out)
    }
}

/// Linear RGB, which scales with the light falling on a surface (sRGB does not).
fn linear_rgb(p: [u8; 3]) -> [f64; 3] {
    p.map(|c| {
        let c = c as f64 / 255.0;
        if c <= 0.04045 {
            c / 12.92
        } else {
            ((c + 0.055) / 1.055).powf(2.4)
        }
    })
}

/// Chromaticity, its square, and the central-difference gradient of log intensity (zero on the
/// image border) as its magnitude and split into four unsigned orientation bins.
fn per_pixel_channels(rgb: &RgbImage) -> Vec<[f64; CHANNELS]> {
    let (w, h) = (rgb.width() as usize, rgb.height() as usize);
    let linear: Vec<[f64; 3]> = rgb.pixels().map(|p| linear_rgb(p.0)).collect();
    let log_intensity: Vec<f64> = linear
        .iter()
        .map(|c| (c[0] + c[1] + c[2] + INTENSITY_FLOOR).ln())
        .collect();
    let l = |x: usize, y: usize| log_intensity[y * w + x];
    let mut out = vec![[0.0; CHANNELS]; w * h];
    for y in 0..h {
        for x in 0..w {
            let gx = if x == 0 || x + 1 == w {
                0.0
            } else {
                (l(x + 1, y) - l(x - 1, y)) / 2.0
            };
            let gy = if y == 0 || y + 1 == h {
                0.0
            } else {
                (l(x, y + 1) - l(x, y - 1)) / 2.0
            };
            let mag = (gx * gx + gy * gy).sqrt();
            let [r, g, b] = linear[y * w + x];
            let sum = r + g + b + INTENSITY_FLOOR;
            let (r, g, b) = (r / sum, g / sum, b / sum);
            let o = &mut out[y * w + x];
            *o = [r, g, b, r * r, g * g, b * b, mag, 0.0, 0.0, 0.0, 0.0];
            if mag > 0.0 {
                // Unsigned orientation in [0, π), soft-assigned to the two nearest of four bins.
                let theta = gy.atan2(gx).rem_euclid(std::f64::consts::PI);
                let pos = theta / (std::f64::consts::PI / 4.0);
                let bin = pos.floor() as usize % 4;
                let t = pos - pos.floor();
                o[7 + bin] += mag * (1.0 - t);
                o[7 + (bin + 1) % 4] += mag * t;
            }
        }
    }
    out
}

/// Summed-area tables of every channel, `(w + 1) x (h + 1)`.
struct Integral {
    w: usize,
    h: usize,
    table: Vec<[f64; CHANNELS]>,
}

impl Integral {
    fn of(values: &[[f64; CHANNELS]], w: usize, h: usize) -> Integral {
        let stride = w + 1;
        let mut table = vec![[0.0; CHANNELS]; stride * (h + 1)];
        for y in 0..h {
            let mut row = [0.0; CHANNELS];
            for x in 0..w {
                let v = &values[y * w + x];
                for c in 0..CHANNELS {
                    row[c] += v[c];
                    table[(y + 1) * stride + x + 1][c] = table[y * stride + x + 1][c] + row[c];
                }
            }
        }
        Integral { w, h, table }
    }

    /// Sums over `[x0, x1) x [y0, y1)` clipped to the image; returns the pixel count.
    fn window(&self, x0: i64, y0: i64, x1: i64, y1: i64, sums: &mut [f64; CHANNELS]) -> f64 {
        let clip = |v: i64, hi: usize| v.clamp(0, hi as i64) as usize;
        let (x0, x1) = (clip(x0, self.w), clip(x1, self.w));
        let (y0, y1) = (clip(y0, self.h), clip(y1, self.h));
        let s = self.w + 1;
        let (a, b, c, d) = (
            &self.table[y0 * s + x0],
            &self.table[y0 * s + x1],
            &self.table[y1 * s + x0],
            &self.table[y1 * s + x1],
        );
        for ch in 0..CHANNELS {
            sums[ch] = d[ch] - b[ch] - c[ch] + a[ch];
        }
        ((x1 - x0) * (y1 - y0)) as f64
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use image::Rgb;

    #[test]
    fn a_flat_image_has_its_chromaticity_as_mean_and_no_spread_or_gradient() {
        let img = RgbImage::from_pixel(40, 24, Rgb([200, 30, 30]));
        let map = Baseline::default().extract(&img).unwrap();
        assert_eq!((map.width, map.height, map.dim), (5, 3, 30));
        let [r, g, b] = linear_rgb([200, 30, 30]);
        let sum = r + g + b + INTENSITY_FLOOR;
        for cell in map.data.chunks(30) {
            for s in 0..3 {
                let f = &cell[s * 10..(s + 1) * 10];
                for (c, want) in [r / sum, g / sum, b / sum].into_iter().enumerate() {
                    assert!((f[c] as f64 - want).abs() < 1e-6, "{f:?}");
                    assert!(f[c + 3].abs() < 1e-3, "{f:?}");
                }
                assert!(f[6..].iter().all(|v| v.abs() < 1e-9), "{f:?}");
            }
        }
    }

    #[test]
    fn vertical_edges_land_in_the_horizontal_gradient_bin_and_only_near_the_edge() {
        let img = RgbImage::from_fn(64, 16, |x, _| {
            if x < 32 {
                Rgb([20, 20, 20])
            } else {
                Rgb([255, 255, 255])
            }
        });
        let ex = Baseline {
            stride: 8,
            radii: vec![4],
        };
        let map = ex.extract(&img).unwrap();
        let near = map.cell(3, 1); // centre x = 28: the window [24, 33) covers the edge
        let far = map.cell(0, 1);
        // The histogram is divided by the mean magnitude: all of it in the first bin.
        assert!(near[6] > 0.9 && near[6] <= 1.0, "{near:?}");
        assert!(near[7..].iter().all(|v| v.abs() < 1e-9), "{near:?}");
        assert!(far[6].abs() < 1e-9);
    }

    /// The point of this extractor: a region in shadow (the same surface under a quarter of the
    /// light) has nearly the features of the lit region.
    #[test]
    fn features_barely_change_when_the_light_dims() {
        let texture = |x: u32, y: u32| {
            let stripe = ((x / 3 + y / 5) % 2) as f64;
            [0.55 + 0.3 * stripe, 0.35 + 0.2 * stripe, 0.2 + 0.1 * stripe]
        };
        let to_srgb = |c: f64| {
            let s = if c <= 0.0031308 {
                12.92 * c
            } else {
                1.055 * c.powf(1.0 / 2.4) - 0.055
            };
            (s * 255.0).round().clamp(0.0, 255.0) as u8
        };
        let lit = RgbImage::from_fn(48, 32, |x, y| Rgb(texture(x, y).map(to_srgb)));
        let shadow = RgbImage::from_fn(48, 32, |x, y| Rgb(texture(x, y).map(|c| to_srgb(0.25 * c))));
        let ex = Baseline::with_stride(4);
        let (a, b) = (ex.extract(&lit).unwrap(), ex.extract(&shadow).unwrap());
        let worst = a
            .data
            .iter()
            .zip(&b.data)
            .map(|(p, q)| (p - q).abs())
            .fold(0.0f32, f32::max);
        assert!(worst < 0.03, "features moved by {worst} when the light dimmed");
    }

    #[test]
    fn the_window_sum_matches_a_direct_sum() {
        let img = RgbImage::from_fn(13, 9, |x, y| {
            Rgb([(x * 19) as u8, (y * 27) as u8, ((x * y) % 255) as u8])
        });
        let values = per_pixel_channels(&img);
        let integral = Integral::of(&values, 13, 9);
        let mut sums = [0.0; CHANNELS];
        let n = integral.window(-3, 2, 7, 20, &mut sums);
        assert_eq!(n, 7.0 * 7.0);
        for c in 0..CHANNELS {
            let direct: f64 = (2..9)
                .flat_map(|y| (0..7).map(move |x| (x, y)))
                .map(|(x, y)| values[y * 13 + x][c])
                .sum();
            assert!((direct - sums[c]).abs() < 1e-9 * (1.0 + direct.abs()));
        }
    }
}
