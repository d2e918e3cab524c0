//! Counting what has been annotated, for the status line and the frame strip.
use std::collections::HashMap;

use super::{FrameLabels, LabelSet};
use super::{UNLABELLED, rasterize_frame};

/// Labelled pixels of each annotated frame, as (frame, pixels), after erasing.
pub fn labelled_pixels_per_frame(labels: &LabelSet, width: u32, height: u32) -> Vec<(u32, u64)> {
    labels
        .frames
        .iter()
        .filter(|f| !f.strokes.is_empty())
        .map(|f| {
            let map = rasterize_frame(Some(f), width, height);
            (f.frame, map.iter().filter(|&&v| v != UNLABELLED).count() as u64)
        })
        .collect()
}

/// Whether each class has at least one labelled pixel somewhere (index = class id).
pub fn classes_used(labels: &LabelSet, width: u32, height: u32) -> Vec<bool> {
    let mut used = vec![false; labels.classes.len()];
    for f in &labels.frames {
        for v in rasterize_frame(Some(f), width, height) {
            if let Some(u) = used.get_mut(v as usize) {
                *u = true;
            }
        }
    }
    used
}

/// What one frame's strokes cover, kept with the strokes it was counted from.
struct FrameCount {
    labels: FrameLabels,
    pixels: u64,
    /// Class ids with at least one pixel.
    classes: Vec<u16>,
}

/// The two counts above, kept per frame so that an edit rasterizes only the frames whose
/// strokes changed (a stroke on one frame used to re-rasterize every annotated frame twice).
#[derive(Default)]
pub struct SummaryCache {
    frames: HashMap<u32, FrameCount>,
}

impl SummaryCache {
    /// Brings the counts up to `labels`; returns how many frames were rasterized.
    pub fn update(&mut self, labels: &LabelSet, width: u32, height: u32) -> usize {
        let mut rasterized = 0;
        self.frames
            .retain(|frame, _| labels.frames.iter().any(|f| f.frame == *frame && !f.strokes.is_empty()));
        for f in labels.frames.iter().filter(|f| !f.strokes.is_empty()) {
            if self.frames.get(&f.frame).is_some_and(|c| c.labels == *f) {
                continue;
            }
            rasterized += 1;
            let map = rasterize_frame(Some(f), width, height);
            let mut classes: Vec<u16> = Vec::new();
            let mut pixels = 0;
            for &v in &map {
                if v != UNLABELLED {
                    pixels += 1;
                    if !classes.contains(&v) {
                        classes.push(v);
                    }
                }
            }
            self.frames.insert(
                f.frame,
                FrameCount {
                    labels: f.clone(),
                    pixels,
                    classes,
                },
            );
        }
        rasterized
    }

    /// As [`labelled_pixels_per_frame`], in frame order.
    pub fn labelled_pixels_per_frame(&self) -> Vec<(u32, u64)> {
        let mut out: Vec<(u32, u64)> = self.frames.iter().map(|(&f, c)| (f, c.pixels)).collect();
        out.sort_unstable();
        out
    }

    /// As [`classes_used`], for `classes` classes.
    pub fn classes_used(&self, classes: usize) -> Vec<bool> {
        let mut used = vec![false; classes];
        for id in self.frames.values().flat_map(|c| &c.classes) {
            if let Some(u) = used.get_mut(*id as usize) {
                *u = true;
            }
        }
        used
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::labels::{ClassInfo, Stroke};

    fn two_classes() -> LabelSet {
        let c = |n: &str| ClassInfo {
            name: n.into(),
            color: [0, 0, 0],
        };
        LabelSet::new(vec![c("a"), c("b")])
    }

    fn dot(class: Option<u16>, x: f32, radius: f32) -> Stroke {
        Stroke {
            class,
            radius,
            points: vec![[x, 10.0]],
        }
    }

    #[test]
    fn the_cache_counts_alike_and_redoes_only_changed_frames() {
        let mut l = two_classes();
        l.push_stroke(2, dot(Some(1), 10.0, 3.0));
        l.push_stroke(4, dot(Some(0), 10.0, 3.0));
        let mut cache = SummaryCache::default();
        assert_eq!(cache.update(&l, 20, 20), 2);
        assert_eq!(cache.labelled_pixels_per_frame(), labelled_pixels_per_frame(&l, 20, 20));
        l.push_stroke(4, dot(None, 10.0, 10.0));
        assert_eq!(cache.update(&l, 20, 20), 1);
        assert_eq!(cache.labelled_pixels_per_frame(), labelled_pixels_per_frame(&l, 20, 20));
        assert_eq!(cache.classes_used(2), classes_used(&l, 20, 20));
        l.frames.retain(|f| f.frame != 2);
        assert_eq!(cache.update(&l, 20, 20), 0);
        assert_eq!(cache.classes_used(3), vec![false, false, false]);
    }

    #[test]
    fn counts_follow_erasing() {
        let mut l = two_classes();
        l.push_stroke(2, dot(Some(1), 10.0, 3.0));
        l.push_stroke(4, dot(Some(1), 10.0, 3.0));
        l.push_stroke(4, dot(None, 10.0, 10.0));
        assert_eq!(labelled_pixels_per_frame(&l, 20, 20), vec![(2, 32), (4, 0)]);
        assert_eq!(classes_used(&l, 20, 20), vec![false, true]);
    }
}
