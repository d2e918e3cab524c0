//! Labels drawn on full-resolution frames, carried to a field trained on smaller frames (the
//! page trains at a fraction of the resolution on slow devices, where rendering every pixel of
//! every frame would take minutes).
use super::LabelSet;
use super::brush::MIN_RADIUS;

/// `labels` for frames `factor` times smaller on each axis: coordinates in the same pixel
/// convention ((0.5, 0.5) the centre of the top-left pixel), radii shrunk but never below half a
/// pixel, so a thin stroke still labels the pixel it crosses.
pub fn scale_labels(labels: &LabelSet, factor: f32) -> LabelSet {
    if factor == 1.0 || !(factor.is_finite() && factor > 0.0) {
        return labels.clone();
    }
    let mut out = labels.clone();
    for stroke in out.frames.iter_mut().flat_map(|f| f.strokes.iter_mut()) {
        stroke.radius = (stroke.radius / factor).max(MIN_RADIUS);
        for p in &mut stroke.points {
            *p = p.map(|v| v / factor);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::labels::{ClassInfo, Stroke, UNLABELLED, rasterize_frame};

    #[test]
    fn quarter_size_labels_cover_the_same_region() {
        let mut labels = LabelSet::new(vec![ClassInfo {
            name: "a".into(),
            color: [0, 0, 0],
        }]);
        labels.push_stroke(
            0,
            Stroke {
                class: Some(0),
                radius: 8.0,
                points: vec![[40.0, 40.0], [120.0, 40.0]],
            },
        );
        labels.push_stroke(
            0,
            Stroke {
                class: Some(0),
                radius: 1.0,
                points: vec![[10.0, 100.0]],
            },
        );
        let small = scale_labels(&labels, 4.0);
        assert_eq!(small.frames[0].strokes[0].points, vec![[10.0, 10.0], [30.0, 10.0]]);
        assert_eq!(small.frames[0].strokes[0].radius, 2.0);
        assert_eq!(small.frames[0].strokes[1].radius, MIN_RADIUS);
        let full = rasterize_frame(labels.frame(0), 160, 120);
        let low = rasterize_frame(small.frame(0), 40, 30);
        // Every labelled low-resolution pixel's block is partly labelled at full resolution (the
        // thin dot, inflated to half a low-resolution pixel, covers 2 of its block's 16).
        for (i, &v) in low.iter().enumerate() {
            if v == UNLABELLED {
                continue;
            }
            let (bx, by) = (i % 40 * 4, i / 40 * 4);
            let covered = (0..16)
                .filter(|k| full[(by + k / 4) * 160 + bx + k % 4] != UNLABELLED)
                .count();
            assert!(covered >= 2, "low pixel {i} labelled, its block has {covered} of 16");
        }
        assert!(low.iter().filter(|&&v| v != UNLABELLED).count() > 30);
        assert_eq!(scale_labels(&labels, 1.0), labels);
    }
}
