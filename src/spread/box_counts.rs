//! How many of a set of pixels lie in each square window of an image, by a summed-area table:
//! the outline of a view's points and the margins along label footprints ask it per pixel.

pub struct BoxCounts {
    width: usize,
    height: usize,
    /// `(width + 1) x (height + 1)`: the count over the rectangle above and left of each corner.
    table: Vec<u32>,
}

impl BoxCounts {
    /// Counts of `pixels` (row-major indices into `width` x `height`; repeats count again).
    pub fn new(pixels: &[u32], width: usize, height: usize) -> BoxCounts {
        let stride = width + 1;
        let mut table = vec![0u32; stride * (height + 1)];
        for &pixel in pixels {
            let (x, y) = (pixel as usize % width, pixel as usize / width);
            table[(y + 1) * stride + x + 1] += 1;
        }
        for y in 1..=height {
            for x in 1..=width {
                table[y * stride + x] +=
                    table[(y - 1) * stride + x] + table[y * stride + x - 1] - table[(y - 1) * stride + x - 1];
            }
        }
        BoxCounts { width, height, table }
    }

    /// The pixels within `radius` of (x, y) along both axes, the window clipped to the image.
    pub fn around(&self, x: usize, y: usize, radius: usize) -> u32 {
        let stride = self.width + 1;
        let (x0, y0) = (x.saturating_sub(radius), y.saturating_sub(radius));
        let (x1, y1) = ((x + radius + 1).min(self.width), (y + radius + 1).min(self.height));
        self.table[y1 * stride + x1] + self.table[y0 * stride + x0]
            - self.table[y0 * stride + x1]
            - self.table[y1 * stride + x0]
    }
}
