//! What the suite measures of one run besides `Confusion`'s figures: IoU in the band along the
//! ground truth's edges, and how many labels the strokes spread to and how many of those are right.
use image::GrayImage;
use serde::{Deserialize, Serialize};

use crate::eval::Confusion;
use crate::labels::UNLABELLED;
use crate::scene::GT_VOID;

/// Pixels within this many pixels (in both axes) of a ground-truth edge form the boundary band.
pub const BOUNDARY_BAND: i64 = 2;

/// Marks the pixels of `gt` within `BOUNDARY_BAND` pixels of an edge between two classes: a
/// pixel whose 4-neighbour has another class is on the edge (both sides of it are); void pixels
/// make no edge.
pub fn boundary_band(gt: &GrayImage) -> Vec<bool> {
    let (w, h) = (gt.width() as i64, gt.height() as i64);
    let at = |x: i64, y: i64| gt.as_raw()[(y * w + x) as usize];
    let on_edge = |x: i64, y: i64| {
        let c = at(x, y);
        c != GT_VOID
            && [(1, 0), (-1, 0), (0, 1), (0, -1)].iter().any(|&(dx, dy)| {
                let (nx, ny) = (x + dx, y + dy);
                (0..w).contains(&nx) && (0..h).contains(&ny) && at(nx, ny) != c && at(nx, ny) != GT_VOID
            })
    };
    let mut band = vec![false; (w * h) as usize];
    for y in 0..h {
        for x in 0..w {
            if !on_edge(x, y) {
                continue;
            }
            for ny in (y - BOUNDARY_BAND).max(0)..=(y + BOUNDARY_BAND).min(h - 1) {
                for nx in (x - BOUNDARY_BAND).max(0)..=(x + BOUNDARY_BAND).min(w - 1) {
                    band[(ny * w + nx) as usize] = true;
                }
            }
        }
    }
    band
}

/// Adds the pixels of one frame inside its boundary band to `confusion`.
pub fn add_boundary(confusion: &mut Confusion, gt: &GrayImage, pred: &[u8]) {
    let band = boundary_band(gt);
    let gt_in: Vec<u8> = gt
        .as_raw()
        .iter()
        .zip(&band)
        .map(|(&g, &on)| if on { g } else { GT_VOID })
        .collect();
    confusion.add(&gt_in, pred);
}

/// How far the strokes spread and how good the spread labels are, against the ground truth.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct SpreadFigures {
    /// Pixels the strokes cover.
    pub drawn: u64,
    /// Labels training draws from beyond the strokes.
    pub written: u64,
    /// Frames holding labels (drawn or spread).
    pub frames: u64,
    /// Share of the spread labels (on pixels with ground truth) that name the true class.
    pub right: f64,
    /// The same share over the frames with strokes alone (what the walk inside a drawn frame
    /// gives); 1 where they have no spread label.
    #[serde(default)]
    pub right_on_drawn_frames: f64,
    /// The class whose spread labels are least often right (of those given at least
    /// [`MIN_CLASS_LABELS`] scored labels), and that share: a small object the walk leaks out of
    /// hides in `right` behind the large classes around it.
    #[serde(default)]
    pub worst_class: Option<u16>,
    #[serde(default = "one")]
    pub worst_class_right: f64,
}

fn one() -> f64 {
    1.0
}

/// Scored spread labels a class needs before its share right counts towards
/// [`SpreadFigures::worst_class`].
pub const MIN_CLASS_LABELS: u64 = 20;

impl SpreadFigures {
    /// Compares the label maps training drew from (`maps`, by frame) with the strokes
    /// (`drawn`, by frame) and the ground truth (`gt_of(frame)`).
    pub fn measure<'a>(
        maps: &[(u32, Vec<u16>)],
        drawn: &[(u32, Vec<u16>)],
        gt_of: impl Fn(u32) -> Option<&'a GrayImage>,
    ) -> SpreadFigures {
        let mut figures = SpreadFigures::default();
        let (mut scored, mut right) = (0u64, 0u64);
        let (mut scored_drawn, mut right_drawn) = (0u64, 0u64);
        // Scored and right labels per class given.
        let mut by_class: std::collections::BTreeMap<u16, (u64, u64)> = Default::default();
        for (frame, map) in maps {
            let strokes = drawn.iter().find(|(f, _)| f == frame).map(|(_, s)| s.as_slice());
            let gt = gt_of(*frame).map(|g| g.as_raw().as_slice());
            let mut any = false;
            for (i, &label) in map.iter().enumerate() {
                if label == UNLABELLED {
                    continue;
                }
                any = true;
                if strokes.and_then(|s| s.get(i)).is_some_and(|&d| d != UNLABELLED) {
                    figures.drawn += 1;
                    continue;
                }
                figures.written += 1;
                if let Some(&g) = gt.and_then(|g| g.get(i))
                    && g != GT_VOID
                {
                    let is_right = u64::from(u16::from(g) == label);
                    scored += 1;
                    right += is_right;
                    let class = by_class.entry(label).or_default();
                    class.0 += 1;
                    class.1 += is_right;
                    if strokes.is_some() {
                        scored_drawn += 1;
                        right_drawn += is_right;
                    }
                }
            }
            figures.frames += u64::from(any);
        }
        let share = |right: u64, scored: u64| if scored > 0 { right as f64 / scored as f64 } else { 1.0 };
        figures.right = share(right, scored);
        figures.right_on_drawn_frames = share(right_drawn, scored_drawn);
        figures.worst_class_right = 1.0;
        for (&class, &(scored, right)) in by_class.iter().filter(|(_, (scored, _))| *scored >= MIN_CLASS_LABELS) {
            let right = share(right, scored);
            if right < figures.worst_class_right {
                figures.worst_class = Some(class);
                figures.worst_class_right = right;
            }
        }
        figures
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_band_covers_two_pixels_on_each_side_of_an_edge() {
        // Class 0 left of x = 5, class 1 from it on; a void column at x = 9 makes no edge.
        let gt = GrayImage::from_fn(12, 3, |x, _| {
            image::Luma([if x == 9 { GT_VOID } else { u8::from(x >= 5) }])
        });
        let band = boundary_band(&gt);
        let row: Vec<bool> = band[..12].to_vec();
        let expected: Vec<bool> = (0..12).map(|x| (2..=6 + 1).contains(&x)).collect();
        assert_eq!(row, expected);
    }

    #[test]
    fn spread_figures_count_drawn_written_and_right() {
        let gt = GrayImage::from_raw(4, 1, vec![0, 0, 1, GT_VOID]).unwrap();
        let drawn = vec![(3, vec![0, UNLABELLED, UNLABELLED, UNLABELLED])];
        let maps = vec![(3, vec![0, 0, 0, 1]), (4, vec![UNLABELLED; 4]), (5, vec![1, 1, 1, 1])];
        let f = SpreadFigures::measure(&maps, &drawn, |frame| (frame != 4).then_some(&gt));
        assert_eq!((f.drawn, f.written, f.frames), (1, 7, 2));
        // On the drawn frame one of two spread labels on scored pixels is right (the void one is
        // not scored); on frame 5, nobody drew, one of three.
        assert!((f.right_on_drawn_frames - 0.5).abs() < 1e-12);
        assert!((f.right - 2.0 / 5.0).abs() < 1e-12);
        // Too few labels per class to name a worst one.
        assert_eq!((f.worst_class, f.worst_class_right), (None, 1.0));
    }

    #[test]
    fn the_worst_class_is_the_least_right_of_those_with_enough_labels() {
        // Frame 0 is class 0 everywhere: 25 labels of class 0 (all right) and 10 of class 1
        // (all wrong, but too few to count). Frame 1 is class 2 on its first 6 pixels and class
        // 3 after: 24 labels of class 2, 6 of them right.
        let n = 40;
        let gt0 = GrayImage::from_raw(n, 1, vec![0; n as usize]).unwrap();
        let gt1 = GrayImage::from_raw(
            n,
            1,
            (0..n).map(|i| u8::from(i >= 6) * 3 + 2 * u8::from(i < 6)).collect(),
        )
        .unwrap();
        let mut map0 = vec![UNLABELLED; n as usize];
        map0[..25].fill(0);
        map0[25..35].fill(1);
        let mut map1 = vec![UNLABELLED; n as usize];
        map1[..24].fill(2);
        let maps = vec![(0, map0), (1, map1)];
        let f = SpreadFigures::measure(&maps, &[], |frame| Some(if frame == 0 { &gt0 } else { &gt1 }));
        assert_eq!(f.worst_class, Some(2));
        assert!((f.worst_class_right - 6.0 / 24.0).abs() < 1e-12);
    }
}
