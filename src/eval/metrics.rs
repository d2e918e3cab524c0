//! Per-class IoU, mean IoU and pixel accuracy from a confusion matrix, ignoring void pixels.
use serde::Serialize;

use crate::scene::GT_VOID;

/// Counts of (ground truth, prediction) pairs over any number of frames.
#[derive(Clone, Debug)]
pub struct Confusion {
    classes: usize,
    /// `counts[gt * classes + pred]`
    counts: Vec<u64>,
    /// Pixels whose prediction is not a known class (counted as wrong).
    out_of_range: Vec<u64>,
}

#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct ClassScore {
    pub class: usize,
    pub name: String,
    /// None when the class appears in neither ground truth nor prediction.
    pub iou: Option<f64>,
    pub gt_pixels: u64,
}

#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct EvalReport {
    pub classes: Vec<ClassScore>,
    /// Mean over classes present in the ground truth.
    pub mean_iou: f64,
    pub pixel_accuracy: f64,
    pub pixels: u64,
    pub frames: usize,
}

impl Confusion {
    pub fn new(classes: usize) -> Self {
        Confusion {
            classes,
            counts: vec![0; classes * classes],
            out_of_range: vec![0; classes],
        }
    }

    /// Adds one frame; `gt` and `pred` are class ids per pixel, `GT_VOID` in `gt` is ignored.
    pub fn add(&mut self, gt: &[u8], pred: &[u8]) {
        assert_eq!(
            gt.len(),
            pred.len(),
            "ground truth and prediction must have the same size"
        );
        for (&g, &p) in gt.iter().zip(pred) {
            let (g, p) = (g as usize, p as usize);
            if g == GT_VOID as usize || g >= self.classes {
                continue;
            }
            if p < self.classes {
                self.counts[g * self.classes + p] += 1;
            } else {
                self.out_of_range[g] += 1;
            }
        }
    }

    pub fn report(&self, names: &[String], frames: usize) -> EvalReport {
        let c = self.classes;
        let gt_total = |k: usize| (0..c).map(|p| self.counts[k * c + p]).sum::<u64>() + self.out_of_range[k];
        let pred_total = |k: usize| (0..c).map(|g| self.counts[g * c + k]).sum::<u64>();
        let mut scores = Vec::with_capacity(c);
        let (mut sum, mut present) = (0.0, 0usize);
        let mut correct = 0u64;
        let mut pixels = 0u64;
        for k in 0..c {
            let tp = self.counts[k * c + k];
            let gt = gt_total(k);
            let union = gt + pred_total(k) - tp;
            let iou = (union > 0).then(|| tp as f64 / union as f64);
            if gt > 0 {
                sum += iou.unwrap_or(0.0);
                present += 1;
            }
            correct += tp;
            pixels += gt;
            let name = names.get(k).cloned().unwrap_or_else(|| format!("class {k}"));
            scores.push(ClassScore {
                class: k,
                name,
                iou,
                gt_pixels: gt,
            });
        }
        EvalReport {
            classes: scores,
            mean_iou: if present > 0 { sum / present as f64 } else { 0.0 },
            pixel_accuracy: if pixels > 0 {
                correct as f64 / pixels as f64
            } else {
                0.0
            },
            pixels,
            frames,
        }
    }
}

impl EvalReport {
    /// The table `scribblefield eval` prints.
    pub fn table(&self) -> String {
        use std::fmt::Write;
        let mut s = String::new();
        let _ = writeln!(s, "{:<24} {:>8} {:>12}", "class", "IoU", "gt pixels");
        for c in &self.classes {
            let iou = c.iou.map(|v| format!("{v:.4}")).unwrap_or_else(|| "-".into());
            let _ = writeln!(
                s,
                "{:<24} {:>8} {:>12}",
                format!("{}:{}", c.class, c.name),
                iou,
                c.gt_pixels
            );
        }
        let _ = writeln!(s, "{:<24} {:>8.4}", "mean IoU", self.mean_iou);
        let _ = writeln!(s, "{:<24} {:>8.4}", "pixel accuracy", self.pixel_accuracy);
        let _ = writeln!(s, "({} frames, {} labelled pixels)", self.frames, self.pixels);
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn iou_by_hand() {
        // gt:   0 0 1 1 255
        // pred: 0 1 1 1 0
        let mut m = Confusion::new(2);
        m.add(&[0, 0, 1, 1, 255], &[0, 1, 1, 1, 0]);
        let r = m.report(&["a".into(), "b".into()], 1);
        assert_eq!(r.classes[0].iou, Some(0.5)); // tp 1, union 2
        assert!((r.classes[1].iou.unwrap() - 2.0 / 3.0).abs() < 1e-12); // tp 2, union 3
        assert!((r.mean_iou - (0.5 + 2.0 / 3.0) / 2.0).abs() < 1e-12);
        assert!((r.pixel_accuracy - 0.75).abs() < 1e-12);
        assert_eq!(r.pixels, 4);
    }

    #[test]
    fn unknown_predictions_count_as_wrong_and_absent_classes_do_not_average() {
        let mut m = Confusion::new(3);
        m.add(&[0, 0], &[0, 9]);
        let r = m.report(&[], 1);
        assert_eq!(r.classes[0].iou, Some(0.5));
        assert_eq!(r.classes[2].iou, None);
        assert!((r.mean_iou - 0.5).abs() < 1e-12);
    }
}
