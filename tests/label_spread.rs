//! Not checks: prints how far the labels the trainer draws from reach and how right they are,
//! before any training, on the demo scene, the YCB clip and the COLMAP capture, for three sets of
//! synthetic strokes each (`cargo test --release --test label_spread -- --ignored --nocapture`).
//! docs/quality.md reports these figures; `tests/quality.rs` and `tests/import_colmap` hold the
//! checks. With `SCRIBBLEFIELD_LABEL_DUMP=DIR` it also writes every label map as an 8-bit PNG
//! (class id, 255 unlabelled) to `DIR/<capture>-<scribble seed>/<frame>.png`, to look at where
//! the labels go wrong.
use std::path::Path;

use scribblefield::labels::synthetic::{ScribbleOptions, scribble_frames};
use scribblefield::pause::run_to_end;
use scribblefield::scene::Scene;
use scribblefield::scene::demo::{DemoOptions, demo_scene};
use scribblefield::scene::import::{ImportOptions, import};
use scribblefield::spread::PropagationOptions;
use scribblefield::spread::propagate::propagate_labels;

/// Labelled pixels, the share of them that are right, and per class: pixels labelled right over
/// pixels labelled as it or truly it (an unlabelled pixel counts as missed), over the frames the
/// labels reach.
fn spread(name: &str, scene: &Scene, frames: &[u32], options: &PropagationOptions) {
    let classes = scene.classes.len();
    for seed in 0..3 {
        let scribbles = ScribbleOptions {
            seed,
            ..ScribbleOptions::default()
        };
        let labels = scribble_frames(scene, frames, &scribbles);
        let maps = propagate_labels(scene, &labels, classes, options);
        if let Some(dir) = std::env::var_os("SCRIBBLEFIELD_LABEL_DUMP") {
            dump(&Path::new(&dir).join(format!("{name}-{seed}")), scene, &maps);
        }
        let (mut labelled, mut right) = (0usize, 0usize);
        let mut iou = vec![(0usize, 0usize); classes];
        for (frame, map) in &maps {
            let gt = scene.frames[*frame as usize].gt.as_ref().expect("ground truth");
            for (&label, truth) in map.iter().zip(gt.pixels()) {
                let truth = truth.0[0];
                if truth == 255 {
                    continue;
                }
                if label != u16::MAX {
                    labelled += 1;
                    right += usize::from(label == u16::from(truth));
                }
                for (c, (hit, union)) in iou.iter_mut().enumerate() {
                    let (is_label, is_truth) = (label == c as u16, truth as usize == c);
                    *hit += usize::from(is_label && is_truth);
                    *union += usize::from(is_label || is_truth);
                }
            }
        }
        let per_class: Vec<f64> = iou.iter().map(|(h, u)| *h as f64 / (*u).max(1) as f64).collect();
        let mean = per_class.iter().sum::<f64>() / classes as f64;
        let per_class: Vec<String> = per_class.iter().map(|v| format!("{v:.3}")).collect();
        eprintln!(
            "  scribbles {seed}: {} frames, {labelled} labelled pixels, {:.4} right; IoU of the labels {mean:.3} {per_class:?}",
            maps.len(),
            right as f64 / labelled.max(1) as f64
        );
    }
}

fn dump(dir: &Path, scene: &Scene, maps: &[(u32, Vec<u16>)]) {
    std::fs::create_dir_all(dir).expect("label dump folder");
    for (frame, map) in maps {
        let pixels = map
            .iter()
            .map(|&l| if l == u16::MAX { 255 } else { l.min(254) as u8 })
            .collect();
        let image = image::GrayImage::from_raw(scene.width, scene.height, pixels).expect("label map size");
        image.save(dir.join(format!("{frame:05}.png"))).expect("label dump");
    }
}

fn real(name: &str, max_size: u32) -> Option<Scene> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data").join(name);
    if !dir.is_dir() {
        eprintln!("\n!!! SKIPPING {name}: real data {} is absent !!!\n", dir.display());
        return None;
    }
    let options = ImportOptions {
        max_size: Some(max_size),
        ..ImportOptions::default()
    };
    Some(import(&dir, &options, &mut |_, _| {}).unwrap().scene)
}

#[test]
#[ignore]
fn labels_before_training() {
    let options = PropagationOptions::default();
    let demo = demo_scene(&DemoOptions {
        width: 80,
        height: 60,
        frames: 36,
        ..Default::default()
    })
    .unwrap();
    eprintln!("demo, strokes on frames 0 and 12:");
    spread("demo", &demo, &[0, 12], &options);
    if let Some(ycb) = real("ycb-video-0000", 160) {
        eprintln!("YCB, strokes on frame 0:");
        spread("ycb", &ycb, &[0], &options);
    }
    if let Some(colmap) = real("alexander-colmap", 200) {
        eprintln!("COLMAP capture, strokes on photos 0 and 26:");
        spread("colmap", &colmap, &[0, 26], &options);
    }
}

/// Not a check: how long the labels take on the COLMAP capture (52 photos at 200x200) when the
/// page sends them after each edit: the first time (the points' graph is built), again unchanged,
/// and after one more stroke on a drawn photo, and the longest stretch between two pauses (what
/// holds the page's thread at once) (`--ignored --nocapture`; docs/quality.md).
#[test]
#[ignore]
fn time_per_edit_on_a_sparse_capture() {
    use scribblefield::spread::propagate::PropagationCache;
    use std::time::Instant;
    let Some(scene) = real("alexander-colmap", 200) else {
        return;
    };
    let labels = scribble_frames(&scene, &[0, 26], &ScribbleOptions::default());
    let more = scribble_frames(
        &scene,
        &[0, 26],
        &ScribbleOptions {
            strokes_per_class: 3,
            ..ScribbleOptions::default()
        },
    );
    let options = PropagationOptions::default();
    let mut cache = PropagationCache::default();
    for (what, labels) in [("first", &labels), ("unchanged", &labels), ("after an edit", &more)] {
        let clock = Instant::now();
        let mut pause = LongestStretch::new();
        let maps = run_to_end(cache.maps_pausing(&scene, labels, 2, &options, &mut pause));
        eprintln!(
            "{what}: {:.2} s for {} frames, at most {:.3} s between pauses",
            clock.elapsed().as_secs_f64(),
            maps.len(),
            pause.longest.as_secs_f64()
        );
    }
}

/// A pause that never waits and remembers the longest time between two pauses.
struct LongestStretch {
    last: std::time::Instant,
    longest: std::time::Duration,
}

impl LongestStretch {
    fn new() -> LongestStretch {
        LongestStretch {
            last: std::time::Instant::now(),
            longest: std::time::Duration::ZERO,
        }
    }
}

impl scribblefield::pause::Pause for LongestStretch {
    fn pause(&mut self) -> impl std::future::Future<Output = ()> {
        let now = std::time::Instant::now();
        self.longest = self.longest.max(now - self.last);
        self.last = now;
        std::future::ready(())
    }
}
