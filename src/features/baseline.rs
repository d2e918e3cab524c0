//! A feature extractor that needs no weights, so packing works with nothing downloaded:
//! colour and gradient statistics of windows of several sizes around each cell.
//!
//! Per scale (window half-size r): mean and standard deviation of CIE L*a*b* (6), mean gradient
//! magnitude of L* (1) and its split into four unsigned orientation bins (4). Windows of a few
//! sizes let a cell see both its own texture and its surroundings, which is what makes pixels of
//! one object resemble each other more than their raw colour does. Box sums come from integral
//! images, so the cost is a few passes over the image whatever the window size.
use image::RgbImage;

use super::{Extractor, FeatureError, FeatureMap};

/// Quantities summed per window: L, a, b, L², a², b², |∇L|, four orientation bins.
const CHANNELS: usize = 11;
const FEATURES_PER_SCALE: usize = 11;

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
            "baseline colour+gradient statistics, windows of half-size {} px, stride {}",
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
                    for c in 6..CHANNELS {
                        f[c] = (sums[c] / n) as f32;
                    }
                }
            }
        }
        Ok(out)
    }
}

/// L*a*b* scaled to roughly unit range (L/100, a/100, b/100), their squares, and the Sobel
/// gradient of L split by orientation.
fn per_pixel_channels(rgb: &RgbImage) -> Vec<[f64; CHANNELS]> {
    let (w, h) = (rgb.width() as usize, rgb.height() as usize);
    let lab: Vec<[f64; 3]> = rgb.pixels().map(|p| srgb_to_lab(p.0)).collect();
    let l = |x: usize, y: usize| lab[y * w + x][0];
    let mut out = vec![[0.0; CHANNELS]; w * h];
    for y in 0..h {
        let (ym, yp) = (y.saturating_sub(1), (y + 1).min(h - 1));
        for x in 0..w {
            let (xm, xp) = (x.saturating_sub(1), (x + 1).min(w - 1));
            let gx = (l(xp, ym) + 2.0 * l(xp, y) + l(xp, yp)) - (l(xm, ym) + 2.0 * l(xm, y) + l(xm, yp));
            let gy = (l(xm, yp) + 2.0 * l(x, yp) + l(xp, yp)) - (l(xm, ym) + 2.0 * l(x, ym) + l(xp, ym));
            let (gx, gy) = (gx / 8.0, gy / 8.0);
            let mag = (gx * gx + gy * gy).sqrt();
            let [lv, a, b] = lab[y * w + x];
            let o = &mut out[y * w + x];
            *o = [lv, a, b, lv * lv, a * a, b * b, mag, 0.0, 0.0, 0.0, 0.0];
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

fn srgb_to_lab(p: [u8; 3]) -> [f64; 3] {
    let lin = |c: u8| {
        let c = c as f64 / 255.0;
        if c <= 0.04045 {
            c / 12.92
        } else {
            ((c + 0.055) / 1.055).powf(2.4)
        }
    };
    let (r, g, b) = (lin(p[0]), lin(p[1]), lin(p[2]));
    // D65 white.
    let x = (0.4124 * r + 0.3576 * g + 0.1805 * b) / 0.95047;
    let y = 0.2126 * r + 0.7152 * g + 0.0722 * b;
    let z = (0.0193 * r + 0.1192 * g + 0.9505 * b) / 1.08883;
    let f = |t: f64| {
        if t > 216.0 / 24389.0 {
            t.cbrt()
        } else {
            (24389.0 / 27.0 * t + 16.0) / 116.0
        }
    };
    let (fx, fy, fz) = (f(x), f(y), f(z));
    [(116.0 * fy - 16.0) / 100.0, 5.0 * (fx - fy), 2.0 * (fy - fz)]
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
    fn a_flat_image_has_its_colour_as_mean_and_no_spread_or_gradient() {
        let img = RgbImage::from_pixel(40, 24, Rgb([200, 30, 30]));
        let map = Baseline::default().extract(&img).unwrap();
        assert_eq!((map.width, map.height, map.dim), (5, 3, 33));
        let lab = srgb_to_lab([200, 30, 30]);
        for cell in map.data.chunks(33) {
            for s in 0..3 {
                let f = &cell[s * 11..(s + 1) * 11];
                for c in 0..3 {
                    assert!((f[c] as f64 - lab[c]).abs() < 1e-5, "{f:?}");
                    assert!(f[c + 3].abs() < 1e-3, "{f:?}");
                }
                assert!(f[6..].iter().all(|v| v.abs() < 1e-9), "{f:?}");
            }
        }
    }

    #[test]
    fn vertical_edges_land_in_the_horizontal_gradient_bin_and_only_near_the_edge() {
        let img = RgbImage::from_fn(
            64,
            16,
            |x, _| if x < 32 { Rgb([0, 0, 0]) } else { Rgb([255, 255, 255]) },
        );
        let ex = Baseline {
            stride: 8,
            radii: vec![4],
        };
        let map = ex.extract(&img).unwrap();
        let near = map.cell(3, 1); // centre x = 28: the window [24, 33) covers the edge
        let far = map.cell(0, 1);
        assert!(near[6] > 0.01 && (near[7] - near[6]).abs() < 1e-6, "{near:?}");
        assert!(near[8..].iter().all(|v| v.abs() < 1e-9));
        assert!(far[6].abs() < 1e-9);
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
