//! Turning strokes into labelled pixels, and labelled pixel masks into strokes.
use super::format::{FrameLabels, Stroke};

/// Value of an unlabelled pixel in a rasterized label map.
pub const UNLABELLED: u16 = u16::MAX;

/// Rasterizes a frame's strokes into a `width * height` map of class ids (`UNLABELLED` where
/// nothing is drawn). A pixel is covered when its centre lies within the brush radius of the
/// stroke's polyline.
pub fn rasterize_frame(labels: Option<&FrameLabels>, width: u32, height: u32) -> Vec<u16> {
    let mut map = vec![UNLABELLED; width as usize * height as usize];
    if let Some(fl) = labels {
        for s in &fl.strokes {
            paint_stroke(&mut map, width, height, s);
        }
    }
    map
}

fn paint_stroke(map: &mut [u16], width: u32, height: u32, s: &Stroke) {
    let value = s.class.unwrap_or(UNLABELLED);
    let r = s.radius;
    let pts: Vec<[f32; 2]> = if s.points.len() == 1 {
        vec![s.points[0], s.points[0]]
    } else {
        s.points.clone()
    };
    for seg in pts.windows(2) {
        let (a, b) = (seg[0], seg[1]);
        let x0 = (a[0].min(b[0]) - r).floor().max(0.0) as i64;
        let x1 = (a[0].max(b[0]) + r).ceil().min(width as f32) as i64;
        let y0 = (a[1].min(b[1]) - r).floor().max(0.0) as i64;
        let y1 = (a[1].max(b[1]) + r).ceil().min(height as f32) as i64;
        let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
        let len2 = dx * dx + dy * dy;
        for y in y0..y1 {
            for x in x0..x1 {
                let (px, py) = (x as f32 + 0.5, y as f32 + 0.5);
                let t = if len2 > 0.0 {
                    (((px - a[0]) * dx + (py - a[1]) * dy) / len2).clamp(0.0, 1.0)
                } else {
                    0.0
                };
                let (qx, qy) = (a[0] + t * dx - px, a[1] + t * dy - py);
                if qx * qx + qy * qy <= r * r {
                    map[y as usize * width as usize + x as usize] = value;
                }
            }
        }
    }
}

/// Converts a dense label mask (class id per pixel, `is_label` deciding which are labelled) into
/// horizontal strokes of radius 0.5 that rasterize back to exactly the same pixels.
pub fn mask_to_strokes(mask: &[u16], width: u32, height: u32, is_label: impl Fn(u16) -> bool) -> Vec<Stroke> {
    let mut strokes = Vec::new();
    for y in 0..height as usize {
        let row = &mask[y * width as usize..(y + 1) * width as usize];
        let mut x = 0;
        while x < row.len() {
            let c = row[x];
            if !is_label(c) {
                x += 1;
                continue;
            }
            let start = x;
            while x < row.len() && row[x] == c {
                x += 1;
            }
            let yc = y as f32 + 0.5;
            strokes.push(Stroke {
                class: Some(c),
                radius: 0.5,
                points: vec![[start as f32 + 0.5, yc], [(x - 1) as f32 + 0.5, yc]],
            });
        }
    }
    strokes
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mask_round_trips_through_strokes() {
        let (w, h) = (13u32, 7u32);
        let mask: Vec<u16> = (0..w * h)
            .map(|i| {
                if (i * 7919) % 5 < 2 {
                    UNLABELLED
                } else {
                    ((i / 3) % 4) as u16
                }
            })
            .collect();
        let strokes = mask_to_strokes(&mask, w, h, |c| c != UNLABELLED);
        let fl = FrameLabels { frame: 0, strokes };
        assert_eq!(rasterize_frame(Some(&fl), w, h), mask);
    }

    #[test]
    fn eraser_clears_and_brush_is_round() {
        let mut fl = FrameLabels {
            frame: 0,
            strokes: vec![Stroke {
                class: Some(2),
                radius: 3.0,
                points: vec![[10.0, 10.0]],
            }],
        };
        let map = rasterize_frame(Some(&fl), 20, 20);
        let covered = map.iter().filter(|&&v| v == 2).count();
        // 32 pixel centres (8 per quadrant) lie within 3 px of the corner (10, 10).
        assert_eq!(covered, 32);
        assert_eq!(map[10 * 20 + 10], 2);
        assert_eq!(map[10 * 20 + 13], UNLABELLED);
        fl.strokes.push(Stroke {
            class: None,
            radius: 10.0,
            points: vec![[10.0, 10.0]],
        });
        assert!(rasterize_frame(Some(&fl), 20, 20).iter().all(|&v| v == UNLABELLED));
    }
}
