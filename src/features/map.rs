//! A dense feature map: `height x width` cells of `dim` values, row-major, channels last.

#[derive(Clone, Debug, PartialEq)]
pub struct FeatureMap {
    pub height: u32,
    pub width: u32,
    pub dim: u32,
    /// `data[(y * width + x) * dim + c]`.
    pub data: Vec<f32>,
}

impl FeatureMap {
    pub fn zeros(height: u32, width: u32, dim: u32) -> Self {
        FeatureMap {
            height,
            width,
            dim,
            data: vec![0.0; height as usize * width as usize * dim as usize],
        }
    }

    pub fn cell(&self, x: u32, y: u32) -> &[f32] {
        let d = self.dim as usize;
        let i = (y as usize * self.width as usize + x as usize) * d;
        &self.data[i..i + d]
    }

    /// Bilinear resampling to `height x width` with pixel centres aligned (what one does to bring
    /// maps of different strides onto one grid).
    pub fn resized(&self, height: u32, width: u32) -> FeatureMap {
        let d = self.dim as usize;
        let mut out = FeatureMap::zeros(height, width, self.dim);
        let sx = self.width as f32 / width as f32;
        let sy = self.height as f32 / height as f32;
        for y in 0..height {
            let fy = ((y as f32 + 0.5) * sy - 0.5).clamp(0.0, (self.height - 1) as f32);
            let y0 = fy.floor() as u32;
            let y1 = (y0 + 1).min(self.height - 1);
            let wy = fy - y0 as f32;
            for x in 0..width {
                let fx = ((x as f32 + 0.5) * sx - 0.5).clamp(0.0, (self.width - 1) as f32);
                let x0 = fx.floor() as u32;
                let x1 = (x0 + 1).min(self.width - 1);
                let wx = fx - x0 as f32;
                let o = (y as usize * width as usize + x as usize) * d;
                let (a, b) = (self.cell(x0, y0), self.cell(x1, y0));
                let (c, e) = (self.cell(x0, y1), self.cell(x1, y1));
                for k in 0..d {
                    let top = a[k] + (b[k] - a[k]) * wx;
                    let bottom = c[k] + (e[k] - c[k]) * wx;
                    out.data[o + k] = top + (bottom - top) * wy;
                }
            }
        }
        out
    }

    /// Channels of `maps` side by side; all must share the grid.
    pub fn concat(maps: &[FeatureMap]) -> FeatureMap {
        let (h, w) = (maps[0].height, maps[0].width);
        assert!(maps.iter().all(|m| m.height == h && m.width == w), "grids differ");
        let dim: u32 = maps.iter().map(|m| m.dim).sum();
        let mut out = FeatureMap::zeros(h, w, dim);
        let cells = h as usize * w as usize;
        let mut o = 0;
        for cell in 0..cells {
            for m in maps {
                let d = m.dim as usize;
                out.data[o..o + d].copy_from_slice(&m.data[cell * d..(cell + 1) * d]);
                o += d;
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn resizing_to_the_same_grid_is_the_identity_and_upsampling_is_bilinear() {
        let m = FeatureMap {
            height: 1,
            width: 2,
            dim: 1,
            data: vec![0.0, 1.0],
        };
        assert_eq!(m.resized(1, 2), m);
        let up = m.resized(1, 4);
        assert_eq!(up.data, vec![0.0, 0.25, 0.75, 1.0]);
    }

    #[test]
    fn concat_interleaves_channels_per_cell() {
        let a = FeatureMap {
            height: 1,
            width: 2,
            dim: 1,
            data: vec![1.0, 2.0],
        };
        let b = FeatureMap {
            height: 1,
            width: 2,
            dim: 2,
            data: vec![3.0, 4.0, 5.0, 6.0],
        };
        let c = FeatureMap::concat(&[a, b]);
        assert_eq!(c.data, vec![1.0, 3.0, 4.0, 2.0, 5.0, 6.0]);
    }
}
