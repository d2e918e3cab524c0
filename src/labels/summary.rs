//! Counting what has been annotated, for the status line and the frame strip.
use super::LabelSet;
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::labels::{ClassInfo, Stroke};

    #[test]
    fn counts_follow_erasing() {
        let c = |n: &str| ClassInfo {
            name: n.into(),
            color: [0, 0, 0],
        };
        let mut l = LabelSet::new(vec![c("a"), c("b")]);
        let dot = |class, x: f32, r| Stroke {
            class,
            radius: r,
            points: vec![[x, 10.0]],
        };
        l.push_stroke(2, dot(Some(1), 10.0, 3.0));
        l.push_stroke(4, dot(Some(1), 10.0, 3.0));
        l.push_stroke(4, dot(None, 10.0, 10.0));
        assert_eq!(labelled_pixels_per_frame(&l, 20, 20), vec![(2, 32), (4, 0)]);
        assert_eq!(classes_used(&l, 20, 20), vec![false, true]);
    }
}
