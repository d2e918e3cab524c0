//! Quality of the propagated masks, trained headless on the GPU (lavapipe in CI) with fixed
//! seeds: synthetic scribbles from ground truth, the warm-up-then-labels schedule of `segment`,
//! every frame rendered and scored. The thresholds sit a little under what these runs measured
//! (the figures are in the comments); they guard against regressions, they are not the goals.
//!
//! `cargo test --release --test quality -- --ignored --nocapture` also runs the encoding
//! ablation (hash grid + frequency vs frequency only vs hash grid only at the same budget).
use scribblefield::eval::headless::{render_and_score, train_schedule};
use scribblefield::eval::{Confusion, EvalReport};
use scribblefield::field::gpu::trainer::Trainer;
use scribblefield::field::refine::{Guide, RefineOptions};
use scribblefield::field::{Encoding, FieldConfig};
use scribblefield::gpu::GpuContext;
use scribblefield::gpu::test_support::gpu_for_tests;
use scribblefield::labels::LabelSet;
use scribblefield::labels::synthetic::{ScribbleOptions, scribble_frames};
use scribblefield::scene::Scene;
use scribblefield::scene::demo::{DemoOptions, demo_scene};

/// The budget of these tests: `headless::budget_config` (small widths, 256 rays of 4 + 12
/// samples), 100 warm-up steps and `DEMO_STEPS` with labels. About 6 minutes on lavapipe on 2 cores.
fn budget_config(classes: usize) -> FieldConfig {
    scribblefield::eval::headless::budget_config(classes as u32)
}

const WARMUP: u32 = 100;
const DEMO_STEPS: u32 = 800;

fn demo() -> Scene {
    demo_scene(&DemoOptions {
        width: 80,
        height: 60,
        frames: 36,
        ..Default::default()
    })
    .unwrap()
}

/// The demo scene with weight-free baseline features baked in as `pack --features baseline
/// --feature-stride 2` does it: a 40 x 30 grid on 80 x 60 frames. Coarser grids hurt here
/// (stride 4: mean IoU 0.47, below the 0.58 without features), see issue 5's note.
fn demo_with_features() -> Scene {
    with_baseline_features(demo())
}

/// `scene` with baseline features on a stride-2 grid baked in (as `pack --features baseline
/// --feature-stride 2`).
fn with_baseline_features(mut scene: Scene) -> Scene {
    use scribblefield::features::{BakeOptions, Baseline, Extractor, bake};
    let ex = Baseline::with_stride(2);
    let baked = bake(
        scene.frames.len(),
        |i| ex.extract(&scene.frames[i].rgb),
        &ex.describe(),
        &BakeOptions::default(),
        |_| {},
    )
    .unwrap();
    scene.features = Some(baked.codes);
    scene
}

/// What one training run scored: the field's own class maps, and the same renders refined with
/// each frame's colour and depth (`field::refine`, what `segment` writes and the app shows).
struct Scores {
    field: EvalReport,
    refined: EvalReport,
    /// `Trainer::opacity_far_class` after training.
    opacity_far_class: Option<u32>,
}

impl Scores {
    fn assert_above(&self, field_floor: f64, refined_floor: f64, frames: &str) {
        for (what, report, floor) in [
            ("field", &self.field, field_floor),
            ("refined", &self.refined, refined_floor),
        ] {
            assert!(
                report.mean_iou > floor,
                "{what}: mean IoU {:.3} on {frames}, floor {floor}",
                report.mean_iou
            );
        }
    }
}

fn train_and_score(
    ctx: &GpuContext,
    scene: &Scene,
    labels: &LabelSet,
    cfg: &FieldConfig,
    steps: u32,
    frames: impl IntoIterator<Item = usize>,
) -> Scores {
    let mut trainer = pollster::block_on(Trainer::new(ctx, scene, cfg, 0)).unwrap();
    let clock = std::time::Instant::now();
    train_schedule(&mut trainer, scene, labels, WARMUP, steps, |_, _, _| {}).unwrap();
    let trained = clock.elapsed().as_secs_f64();
    // Samples that reached the heads (FieldConfig::head_weight_threshold), per step over the
    // whole run: what the keep stage saves at this quality.
    let tally = pollster::block_on(trainer.kept_tally()).unwrap();
    let samples = cfg.batch_rays as usize * cfg.samples_per_ray();
    eprintln!(
        "samples to the heads: {:.0} of {samples} per step, mean over {} steps (threshold {})",
        f64::from(tally[0]) / f64::from(tally[1].max(1)),
        tally[1],
        cfg.head_weight_threshold
    );
    let names: Vec<String> = labels.classes.iter().map(|c| c.name.clone()).collect();
    let mut refined = Confusion::new(names.len());
    let mut refine_seconds = 0.0;
    let field = render_and_score(
        &mut trainer,
        scene,
        &names,
        frames,
        &RefineOptions::OFF,
        |i, mut rendered| {
            let clock = std::time::Instant::now();
            rendered
                .refine(Guide::of_frame(scene, i).unwrap(), &RefineOptions::for_scene(scene))
                .unwrap();
            refine_seconds += clock.elapsed().as_secs_f64();
            refined.add(scene.frames[i].gt.as_ref().unwrap().as_raw(), &rendered.classes);
        },
    )
    .unwrap();
    let refined = refined.report(&names, field.frames);
    eprintln!(
        "{:?}: {} + {steps} steps in {trained:.0} s; field: mean IoU {:.3}, pixel accuracy {:.3}; \
         refined (in {refine_seconds:.2} s): mean IoU {:.3}, pixel accuracy {:.3}\n{}",
        cfg.encoding,
        WARMUP,
        field.mean_iou,
        field.pixel_accuracy,
        refined.mean_iou,
        refined.pixel_accuracy,
        refined.table()
    );
    Scores {
        field,
        refined,
        opacity_far_class: trainer.opacity_far_class(),
    }
}

#[test]
fn demo_scribbles_on_two_frames_propagate_to_every_frame() {
    let Some(ctx) = gpu_for_tests("demo_scribbles_on_two_frames_propagate_to_every_frame") else {
        return;
    };
    let scene = demo_with_features();
    let labels = scribble_frames(&scene, &[0, 12], &ScribbleOptions::default());
    let cfg = supervised_budget(&scene);
    let scores = train_and_score(&ctx, &scene, &labels, &cfg, DEMO_STEPS, 0..scene.frames.len());
    scores.assert_above(MEASURED_DEMO_FIELD_FLOOR, MEASURED_DEMO_REFINED_FLOOR, "all frames");
}

/// Floors under what this test measures (docs/quality.md, "What tests/quality.rs measures"): the
/// test bakes its own feature codes, so a change to the feature fit or to the rounding of a sum
/// moves the field a few hundredths; the floors leave room for that.
const MEASURED_DEMO_FIELD_FLOOR: f64 = 0.82;
/// The refined maps (`segment`'s output); issue 17's target is 0.90.
const MEASURED_DEMO_REFINED_FLOOR: f64 = 0.90;

#[test]
#[ignore = "measurement (about 6 minutes on lavapipe): the encodings at the same budget"]
fn encoding_ablation_on_the_demo_scene() {
    let Some(ctx) = gpu_for_tests("encoding_ablation_on_the_demo_scene") else {
        return;
    };
    let scene = demo_with_features();
    let labels = scribble_frames(&scene, &[0, 12], &ScribbleOptions::default());
    let mut rows = Vec::new();
    for encoding in [Encoding::default(), Encoding::freq_only_baseline(), Encoding::HashOnly] {
        let cfg = FieldConfig {
            encoding,
            feature_supervision: true,
            ..budget_config(scene.classes.len())
        };
        let scores = train_and_score(&ctx, &scene, &labels, &cfg, DEMO_STEPS, 0..scene.frames.len());
        rows.push((encoding, scores));
    }
    println!("| encoding | field mean IoU | refined mean IoU | refined pixel accuracy |\n|---|---|---|---|");
    for (encoding, s) in rows {
        println!(
            "| {encoding:?} | {:.3} | {:.3} | {:.3} |",
            s.field.mean_iou, s.refined.mean_iou, s.refined.pixel_accuracy
        );
    }
}

/// The real YCB-Video clip (../shared/data), packed at 160 x 120: scribbles on frame 0 only,
/// scored on frames 1-9. The camera barely moves over the clip, so this measures propagation
/// from sparse scribbles to whole objects on real colour and depth within nearly one view.
#[test]
fn ycb_scribbles_on_frame_0_propagate_to_frames_1_to_9() {
    let Some((ctx, scene)) = real_capture(
        "ycb_scribbles_on_frame_0_propagate_to_frames_1_to_9",
        "ycb-video-0000",
        160,
    ) else {
        return;
    };
    let labels = scribble_frames(&scene, &[0], &ScribbleOptions::default());
    let cfg = supervised_budget(&scene);
    let scores = train_and_score(&ctx, &scene, &labels, &cfg, YCB_STEPS, 1..scene.frames.len());
    scores.assert_above(MEASURED_YCB_FIELD_FLOOR, MEASURED_YCB_REFINED_FLOOR, "frames 1-9");
    // Dense depth: no opaque last sample, no far class, no opacity term.
    assert_eq!(scores.opacity_far_class, None);
}

/// A capture of ../shared/data imported at a longest side of `max_size` with baseline features
/// baked in, and the device to train it on; None (the test checks nothing) without the data or a
/// GPU.
fn real_capture(test: &str, folder: &str, max_size: u32) -> Option<(GpuContext, Scene)> {
    use scribblefield::scene::import::{ImportOptions, import};
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/data")
        .join(folder);
    if !dir.is_dir() {
        eprintln!(
            "\n!!! SKIPPING: real data {} is absent; this test checks nothing here !!!\n",
            dir.display()
        );
        return None;
    }
    let ctx = gpu_for_tests(test)?;
    let options = ImportOptions {
        max_size: Some(max_size),
        ..Default::default()
    };
    let scene = with_baseline_features(import(&dir, &options, &mut |_, _| {}).unwrap().scene);
    Some((ctx, scene))
}

/// The budget config with feature supervision, for `scene`'s classes.
fn supervised_budget(scene: &Scene) -> FieldConfig {
    FieldConfig {
        feature_supervision: true,
        ..budget_config(scene.classes.len())
    }
}

const YCB_STEPS: u32 = 500;
/// Floors under what this test measures on frames 1-9 (docs/quality.md, "What tests/quality.rs
/// measures"); the field's and the refined maps'.
const MEASURED_YCB_FIELD_FLOOR: f64 = 0.80;
const MEASURED_YCB_REFINED_FLOOR: f64 = 0.85;

/// The real photo capture with a COLMAP model (../shared/data/alexander-colmap), packed at 200 x
/// 200: no depth but the model's points, scribbles on photos 0 and 26, all 52 photos scored
/// against their masks. Its rays end in an opaque sample (`LastSample::Auto` on a capture
/// without dense depth), the opacity term applies to its labelled rays, and its masks are refined
/// with 10 rounds (`RefineOptions::for_scene`).
#[test]
fn colmap_scribbles_on_two_photos_propagate_to_every_photo() {
    let Some((ctx, scene)) = real_capture(
        "colmap_scribbles_on_two_photos_propagate_to_every_photo",
        "alexander-colmap",
        200,
    ) else {
        return;
    };
    let labels = scribble_frames(&scene, &[0, 26], &ScribbleOptions::default());
    let cfg = supervised_budget(&scene);
    let scores = train_and_score(&ctx, &scene, &labels, &cfg, COLMAP_STEPS, 0..scene.frames.len());
    scores.assert_above(
        MEASURED_COLMAP_FIELD_FLOOR,
        MEASURED_COLMAP_REFINED_FLOOR,
        "all 52 photos",
    );
    // The room (the masks' background, class 0) lies beyond the box: the opacity term pulls
    // its rays through it (docs/quality.md, "The labels say what is empty").
    assert_eq!(scores.opacity_far_class, Some(0));
}

const COLMAP_STEPS: u32 = 800;
/// Floors under what this test measures on the 52 photos (docs/quality.md, "What
/// tests/quality.rs measures"); the field's and the refined maps'.
const MEASURED_COLMAP_FIELD_FLOOR: f64 = 0.85;
const MEASURED_COLMAP_REFINED_FLOOR: f64 = 0.90;
