//! Propagation checks itself against the user's own strokes: part of the strokes is held back,
//! the rest is spread as training would spread it, and the spread's labels are compared with the
//! held-back strokes. No ground truth is needed, so the page runs the same check.
//!
//! Two kinds of fold:
//! - **across views** (a capture whose strokes travel between frames, and at least two drawn
//!   frames): each drawn frame's strokes are held back in turn, and the others' spread must label
//!   them as drawn. This is the spread a user cannot see: labels carried to frames nobody drew on.
//! - **within frames**: every other stroke of each class (or the second half of a class's only
//!   stroke) is held back on every drawn frame at once.
//! - **a class left out**: on a frame drawn with three or more classes, each class's strokes are
//!   held back in turn and the others walk; what they claim of the held-back strokes' pixels is
//!   how readily the walk crosses an object's edges there. Held-back strokes of a class still
//!   drawn lie inside regions the walk fills anyway, so the first two folds miss a walk that
//!   leaks out of a small object (docs/quality.md, "The self-check").
use crate::labels::{FrameLabels, LabelSet, Stroke, UNLABELLED, rasterize_frame};
use crate::pause::{NoPause, Pause, run_to_end};
use crate::scene::{Guide, Intrinsics, Scene};
use crate::spread::propagate::{LeftOutMemo, walk_frame};
use crate::spread::{PropagationCache, PropagationOptions};

/// How well a spread from part of the strokes predicts the rest.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FoldAgreement {
    /// Held-back stroke pixels (not also under a kept stroke).
    pub held: u64,
    /// Of those, the pixels the spread labelled...
    pub labelled: u64,
    /// ...and the pixels it labelled with the class drawn there.
    pub agreeing: u64,
}

impl FoldAgreement {
    /// Share of the labelled held-back pixels that agree (1 when none was labelled).
    pub fn agreement(&self) -> f64 {
        if self.labelled == 0 {
            1.0
        } else {
            self.agreeing as f64 / self.labelled as f64
        }
    }

    fn add(&mut self, other: FoldAgreement) {
        self.held += other.held;
        self.labelled += other.labelled;
        self.agreeing += other.agreeing;
    }
}

/// How far the other classes' spread reaches into an object whose strokes were held back.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct LeftOut {
    /// Pixels of the held-back class's strokes (not also under another class's stroke).
    pub held: u64,
    /// Of those, the pixels the spread gave another class.
    pub claimed: u64,
}

impl LeftOut {
    /// Share of the held-back class's pixels that no other class claimed (1 when none held).
    pub fn unclaimed(&self) -> f64 {
        if self.held == 0 {
            1.0
        } else {
            1.0 - self.claimed as f64 / self.held as f64
        }
    }
}

/// What the check found, per kind of fold (None: no fold of that kind was possible).
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SpreadCheck {
    pub across_views: Option<FoldAgreement>,
    pub within_frames: Option<FoldAgreement>,
    /// Each class of a frame drawn with three or more, held back in turn (`LeftOut`).
    #[serde(default)]
    pub class_left_out: Option<LeftOut>,
}

impl SpreadCheck {
    /// `options` as the check leaves them: across views off where the across-view folds agree
    /// on less than `min_agreement`, spreading off where the within-frame fold does or where
    /// the other classes claim more than `1 - min_agreement` of the classes left out.
    pub fn apply(&self, options: &PropagationOptions) -> PropagationOptions {
        let min = f64::from(options.min_agreement);
        let fails = |f: Option<FoldAgreement>| f.is_some_and(|f| f.agreement() < min);
        let leaks = self.class_left_out.is_some_and(|l| l.unclaimed() < min);
        let mut checked = *options;
        if fails(self.within_frames) || leaks {
            checked.enabled = false;
        } else if fails(self.across_views) {
            checked.across_views = false;
        }
        checked
    }

    /// One line for the CLI and the page, e.g. "agrees with held-back strokes: across views
    /// 99.8 % (1156 px), within frames 100.0 % (576 px), classes left out 100.0 % unclaimed
    /// (429 px)".
    pub fn describe(&self) -> String {
        let part = |name: &str, f: Option<FoldAgreement>| {
            f.map(|f| format!("{name} {:.1} % ({} px)", 100.0 * f.agreement(), f.labelled))
        };
        let left_out = self.class_left_out.map(|l| {
            format!(
                "classes left out {:.1} % unclaimed ({} px)",
                100.0 * l.unclaimed(),
                l.held
            )
        });
        let parts: Vec<String> = [
            part("across views", self.across_views),
            part("within frames", self.within_frames),
            left_out,
        ]
        .into_iter()
        .flatten()
        .collect();
        if parts.is_empty() {
            "no strokes to hold back".into()
        } else {
            format!("agrees with held-back strokes: {}", parts.join(", "))
        }
    }
}

/// Runs the check's folds for `labels` on `scene` with `options` (spreading enabled), reusing
/// `cache` (the trainer's: the points' graph is built once).
pub async fn check_spread(
    cache: &mut PropagationCache,
    scene: &Scene,
    labels: &LabelSet,
    classes: usize,
    options: &PropagationOptions,
    pause: &mut impl Pause,
) -> SpreadCheck {
    let mut check = SpreadCheck::default();
    if !options.enabled {
        return check;
    }
    let drawn: Vec<u32> = labels
        .frames
        .iter()
        .filter(|f| {
            f.strokes
                .iter()
                .any(|s| s.class.is_some_and(|c| (c as usize) < classes))
        })
        .map(|f| f.frame)
        .filter(|&f| (f as usize) < scene.frames.len())
        .collect();
    if options.across_views && scene.has_sparse_depth() && drawn.len() >= 2 {
        let mut total = FoldAgreement::default();
        for &frame in &drawn {
            let kept = LabelSet {
                frames: labels.frames.iter().filter(|f| f.frame != frame).cloned().collect(),
                ..labels.clone()
            };
            let maps = cache.maps_pausing(scene, &kept, classes, options, pause).await;
            let full = rasterize_frame(labels.frame(frame), scene.width, scene.height);
            let none = vec![UNLABELLED; full.len()];
            let spread = maps.iter().find(|(f, _)| *f == frame).map(|(_, m)| m.as_slice());
            total.add(compare(&full, &none, spread.unwrap_or(&none), classes));
        }
        check.across_views = Some(total);
    }
    let kept = LabelSet {
        frames: labels.frames.iter().map(every_other_stroke).collect(),
        ..labels.clone()
    };
    if kept != *labels {
        let maps = cache.maps_pausing(scene, &kept, classes, options, pause).await;
        let mut total = FoldAgreement::default();
        for &frame in &drawn {
            let full = rasterize_frame(labels.frame(frame), scene.width, scene.height);
            let kept_map = rasterize_frame(kept.frame(frame), scene.width, scene.height);
            let none = vec![UNLABELLED; full.len()];
            let spread = maps.iter().find(|(f, _)| *f == frame).map(|(_, m)| m.as_slice());
            total.add(compare(&full, &kept_map, spread.unwrap_or(&none), classes));
        }
        check.within_frames = Some(total);
    }
    check.class_left_out = class_left_out(cache, scene, labels, &drawn, classes, options, pause).await;
    check
}

/// Each class of each drawn frame with strokes of three or more classes held back in turn, the
/// others walked inside the frame: how much of the held-back object they claim. A walk that
/// crosses the edges of an object nobody stroked leaks out of the objects that were stroked just
/// the same, and a small object's class then covers its surroundings in every view.
async fn class_left_out(
    cache: &mut PropagationCache,
    scene: &Scene,
    labels: &LabelSet,
    drawn: &[u32],
    classes: usize,
    options: &PropagationOptions,
    pause: &mut impl Pause,
) -> Option<LeftOut> {
    let mut total: Option<LeftOut> = None;
    cache.left_out.retain(|frame, _| drawn.contains(frame));
    for &frame in drawn {
        let Some(guide) = Guide::of_frame(scene, frame as usize) else {
            continue;
        };
        let full = rasterize_frame(labels.frame(frame), scene.width, scene.height);
        // The fold walks each frame once per class: only a frame whose strokes changed since
        // the last check walks again.
        let memo = cache
            .left_out
            .get(&frame)
            .filter(|m| m.strokes == full && m.classes == classes && m.options == *options);
        let held_claimed = match memo {
            Some(memo) => memo.held_claimed,
            None => {
                let found = left_out_in_frame(&full, classes, guide, Some(&scene.intrinsics), options, pause).await;
                let held_claimed = found.map(|f| (f.held, f.claimed));
                let memo = LeftOutMemo {
                    strokes: full,
                    classes,
                    options: *options,
                    held_claimed,
                };
                cache.left_out.insert(frame, memo);
                held_claimed
            }
        };
        if let Some((held, claimed)) = held_claimed {
            let sum = total.get_or_insert_with(LeftOut::default);
            sum.held += held;
            sum.claimed += claimed;
        }
    }
    total
}

/// [`class_left_out`] on one frame's rasterized strokes (`None` with fewer than three classes).
async fn left_out_in_frame(
    full: &[u16],
    classes: usize,
    guide: Guide<'_>,
    camera: Option<&Intrinsics>,
    options: &PropagationOptions,
    pause: &mut impl Pause,
) -> Option<LeftOut> {
    let present: Vec<u16> = (0..classes as u16).filter(|c| full.contains(c)).collect();
    if present.len() < 3 {
        return None;
    }
    let mut sum = LeftOut::default();
    for &class in &present {
        let kept: Vec<u16> = full.iter().map(|&c| if c == class { UNLABELLED } else { c }).collect();
        let spread = walk_frame(&kept, classes, guide, camera, options, pause).await;
        for (&drawn, &spread) in full.iter().zip(&spread) {
            if drawn == class {
                sum.held += 1;
                sum.claimed += u64::from(spread != UNLABELLED);
            }
        }
    }
    Some(sum)
}

/// [`check_spread`] run to the end with a cache of its own.
pub fn check_spread_now(scene: &Scene, labels: &LabelSet, classes: usize, options: &PropagationOptions) -> SpreadCheck {
    let mut cache = PropagationCache::default();
    run_to_end(check_spread(&mut cache, scene, labels, classes, options, &mut NoPause))
}

/// The held-back pixels of a frame (under a stroke in `full`, not in `kept`) against `spread`.
fn compare(full: &[u16], kept: &[u16], spread: &[u16], classes: usize) -> FoldAgreement {
    let mut fold = FoldAgreement::default();
    for ((&drawn, &kept), &spread) in full.iter().zip(kept).zip(spread) {
        if drawn == UNLABELLED || (drawn as usize) >= classes || kept != UNLABELLED {
            continue;
        }
        fold.held += 1;
        if spread != UNLABELLED {
            fold.labelled += 1;
            fold.agreeing += u64::from(spread == drawn);
        }
    }
    fold
}

/// `frame` with every other painting stroke of each class held back (the 2nd, 4th, ...), or,
/// for a class drawn with one stroke, the second half of its points; erasing strokes stay.
fn every_other_stroke(frame: &FrameLabels) -> FrameLabels {
    let mut seen: Vec<(u16, usize)> = Vec::new();
    let count = |class: u16| frame.strokes.iter().filter(|s| s.class == Some(class)).count();
    let mut strokes = Vec::with_capacity(frame.strokes.len());
    for stroke in &frame.strokes {
        let Some(class) = stroke.class else {
            strokes.push(stroke.clone());
            continue;
        };
        let index = match seen.iter_mut().find(|(c, _)| *c == class) {
            Some((_, n)) => {
                *n += 1;
                *n - 1
            }
            None => {
                seen.push((class, 1));
                0
            }
        };
        if count(class) == 1 {
            if stroke.points.len() >= 4 {
                strokes.push(Stroke {
                    points: stroke.points[..stroke.points.len() / 2].to_vec(),
                    ..stroke.clone()
                });
            } else {
                strokes.push(stroke.clone());
            }
        } else if index % 2 == 0 {
            strokes.push(stroke.clone());
        }
    }
    FrameLabels {
        frame: frame.frame,
        strokes,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn stroke(class: u16, points: usize) -> Stroke {
        Stroke {
            class: Some(class),
            radius: 1.0,
            points: (0..points).map(|i| [i as f32, 0.0]).collect(),
        }
    }

    #[test]
    fn every_other_stroke_holds_back_the_second_of_each_class_or_half_of_a_lone_stroke() {
        let frame = FrameLabels {
            frame: 3,
            strokes: vec![stroke(0, 6), stroke(1, 2), stroke(0, 3), stroke(0, 2)],
        };
        let kept = every_other_stroke(&frame);
        // Class 0: strokes 1 and 3 of three kept; class 1's only stroke is too short to split.
        assert_eq!(kept.strokes, vec![stroke(0, 6), stroke(1, 2), stroke(0, 2)]);
        let lone = FrameLabels {
            frame: 0,
            strokes: vec![stroke(2, 8)],
        };
        assert_eq!(every_other_stroke(&lone).strokes, vec![stroke(2, 4)]);
    }

    /// A 30 x 8 frame in three bands of 10 columns, a class stroked down the middle of each;
    /// `right` is the colour of the right band (the middle one is grey).
    fn left_out_of_bands(right: [u8; 3]) -> LeftOut {
        let rgb = image::RgbImage::from_fn(30, 8, |x, _| {
            image::Rgb(match x {
                0..10 => [200, 40, 40],
                10..20 => [120, 120, 120],
                _ => right,
            })
        });
        let strokes: Vec<u16> = (0..30 * 8)
            .map(|i| match i % 30 {
                4 | 5 => 0,
                14 | 15 => 1,
                24 | 25 => 2,
                _ => UNLABELLED,
            })
            .collect();
        let guide = Guide::colour_only(&rgb);
        let options = PropagationOptions::default();
        run_to_end(left_out_in_frame(&strokes, 3, guide, None, &options, &mut NoPause)).unwrap()
    }

    #[test]
    fn a_class_left_out_is_claimed_where_no_edge_bounds_it() {
        // The right band as grey as the middle one: left out, it goes to the middle's class.
        let leaky = left_out_of_bands([120, 120, 120]);
        assert_eq!(leaky.held, 3 * 16);
        assert!(leaky.unclaimed() < 0.9, "{leaky:?}");
        // A blue right band: every held-back class keeps its pixels.
        let edged = left_out_of_bands([40, 40, 200]);
        assert_eq!((edged.held, edged.claimed), (3 * 16, 0));
        let check = SpreadCheck {
            class_left_out: Some(leaky),
            ..SpreadCheck::default()
        };
        assert!(!check.apply(&PropagationOptions::default()).enabled);
        let check = SpreadCheck {
            class_left_out: Some(edged),
            ..SpreadCheck::default()
        };
        assert!(check.apply(&PropagationOptions::default()).enabled);
    }

    #[test]
    fn the_fold_that_leaves_a_class_out_walks_again_only_where_strokes_changed() {
        use crate::pause::CountPauses;
        use crate::spread::test_scenes::{classes, dot, small_demo};
        let scene = small_demo(4);
        let mut labels = classes(&["a", "b", "c"]);
        for frame in [0, 2] {
            labels.push_stroke(frame, dot(0, 4.5, 20.5));
            labels.push_stroke(frame, dot(1, 16.5, 4.5));
            labels.push_stroke(frame, dot(2, 28.5, 12.5));
        }
        let options = PropagationOptions::default();
        let mut cache = PropagationCache::default();
        let fold = |cache: &mut PropagationCache, labels: &LabelSet| {
            let mut pauses = CountPauses(0);
            let found = run_to_end(class_left_out(cache, &scene, labels, &[0, 2], 3, &options, &mut pauses));
            (found, pauses.0)
        };
        let (first, walked) = fold(&mut cache, &labels);
        assert!(walked > 0 && first.is_some());
        assert_eq!(fold(&mut cache, &labels), (first, 0), "nothing changed: nothing walks");
        labels.push_stroke(2, dot(0, 8.5, 20.5));
        let (changed, walked_again) = fold(&mut cache, &labels);
        assert!(walked_again > 0 && walked_again < walked, "{walked_again} of {walked}");
        assert_eq!(changed, fold(&mut PropagationCache::default(), &labels).0);
    }

    #[test]
    fn comparison_counts_held_back_pixels_only() {
        let u = UNLABELLED;
        let full = [0, 0, 1, 1, u];
        let kept = [0, u, u, u, u];
        let spread = [0, 0, 0, u, 1];
        let fold = compare(&full, &kept, &spread, 2);
        assert_eq!((fold.held, fold.labelled, fold.agreeing), (3, 2, 1));
        assert!((fold.agreement() - 0.5).abs() < 1e-12);
    }
}
