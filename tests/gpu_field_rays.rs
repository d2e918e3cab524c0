//! `ray_batch.wgsl` and `sample_points.wgsl` against their CPU twins (exact picks and jitter) and
//! against `reference::sampling` on a small demo scene, on lavapipe.
//!
//! Run in release: `cargo test --release --test gpu_field_rays`.
use std::time::Instant;

use half::f16;
use scribblefield::field::gpu::rays::{
    NO_LABEL, RAY_HAS_CODE, RAY_HITS_BOX, RayBatchPass, RayGeometry, SamplePlanUniforms, SamplePointsPass,
    StepUniforms, TARGET_DEPTH, TARGET_FLAGS, TARGET_HEADER_WORDS, TARGET_LABEL, TARGET_PIXEL, TARGET_RGB, pick_pixel,
    sample_jitter,
};
use scribblefield::field::gpu::scene_buffers::{LabelIndex, SceneBuffers, SceneUniforms};
use scribblefield::field::gpu::stage::Stage;
use scribblefield::field::reference::sampling::{self, SamplePlan};
use scribblefield::field::{FieldConfig, LastSample};
use scribblefield::gpu::buffers::{fill_with_garbage, read_buffer_blocking, uniform_buffer_from};
use scribblefield::gpu::test_support::gpu_for_tests;
use scribblefield::gpu::{GpuContext, GpuError};
use scribblefield::labels::{LabelSet, mask_to_strokes, rasterize_frame};
use scribblefield::scene::demo::{DemoOptions, demo_classes, demo_scene};
use scribblefield::scene::{FeatureCodes, Pca, Scene};

const FEATURE_DIM: u32 = 8;
/// Frames whose ground truth becomes labels.
const LABELLED_FRAMES: [u32; 2] = [0, 3];

/// A 5-frame 40 x 30 demo scene with made-up feature codes on a 7 x 9 grid (so the nearest-cell
/// lookup is non-trivial) and dense labels from the ground truth of two frames, for all classes
/// but the last (so one class is absent and must never be drawn).
fn test_scene() -> Scene {
    let mut scene = demo_scene(&DemoOptions {
        seed: 3,
        width: 40,
        height: 30,
        frames: 5,
    })
    .unwrap();
    let (fh, fw) = (7u32, 9u32);
    let count = scene.frames.len() * (fh * fw * FEATURE_DIM) as usize;
    scene.features = Some(FeatureCodes {
        height: fh,
        width: fw,
        dim: FEATURE_DIM,
        extractor: "test pattern".into(),
        data: (0..count)
            .map(|i| f16::from_f32(((i * 37 % 101) as f32 - 50.0) / 16.0))
            .collect(),
        pca: Pca {
            mean: vec![0.0; FEATURE_DIM as usize],
            components: Default::default(),
            lo: [0.0; 3],
            hi: [1.0; 3],
        },
    });
    let classes = demo_classes();
    let skipped_class = classes.len() as u16 - 1;
    let mut labels = LabelSet::new(classes);
    for frame in LABELLED_FRAMES {
        let gt = scene.frames[frame as usize].gt.as_ref().unwrap();
        let mask: Vec<u16> = gt.pixels().map(|p| u16::from(p.0[0])).collect();
        for stroke in mask_to_strokes(&mask, scene.width, scene.height, |c| c < skipped_class) {
            labels.push_stroke(frame, stroke);
        }
    }
    scene.labels = Some(labels);
    scene
}

fn test_config(batch: u32) -> FieldConfig {
    FieldConfig {
        num_classes: demo_classes().len() as u32,
        feature_dim: FEATURE_DIM,
        batch_rays: batch,
        ..FieldConfig::small()
    }
}

struct Passes {
    step: wgpu::Buffer,
    scene: SceneBuffers,
    rays: RayBatchPass,
    samples: SamplePointsPass,
}

fn passes(ctx: &GpuContext, scene: &Scene, cfg: &FieldConfig) -> Passes {
    let step = uniform_buffer_from(ctx, "step", &StepUniforms::for_step(cfg, 1, 0, 1e-3));
    let scene_buffers = SceneBuffers::upload(ctx, scene, cfg).unwrap();
    let rays = pollster::block_on(RayBatchPass::new(ctx, cfg, &scene_buffers, &step)).unwrap();
    let samples = pollster::block_on(SamplePointsPass::new(ctx, cfg, &scene.bounds, &step, &rays.rays)).unwrap();
    Passes {
        step,
        scene: scene_buffers,
        rays,
        samples,
    }
}

struct StepOutput {
    rays: Vec<RayGeometry>,
    targets: Vec<u32>,
    positions: Vec<[f32; 4]>,
    intervals: Vec<[f32; 2]>,
}

/// Runs both passes for `step` into garbage-filled outputs and reads everything back.
fn run_step(ctx: &GpuContext, p: &Passes, step: &StepUniforms) -> StepOutput {
    ctx.queue.write_buffer(&p.step, 0, bytemuck::bytes_of(step));
    for buffer in [
        &p.rays.rays,
        &p.rays.targets,
        &p.samples.positions,
        &p.samples.intervals,
    ] {
        fill_with_garbage(ctx, buffer);
    }
    let mut encoder = ctx.device.create_command_encoder(&Default::default());
    {
        let mut compute = encoder.begin_compute_pass(&Default::default());
        p.rays.record(&mut compute);
        p.samples.record(&mut compute);
    }
    ctx.queue.submit([encoder.finish()]);
    StepOutput {
        rays: read_buffer_blocking(ctx, &p.rays.rays).unwrap(),
        targets: read_buffer_blocking(ctx, &p.rays.targets).unwrap(),
        positions: read_buffer_blocking(ctx, &p.samples.positions).unwrap(),
        intervals: read_buffer_blocking(ctx, &p.samples.intervals).unwrap(),
    }
}

fn label_index(scene: &Scene, cfg: &FieldConfig) -> LabelIndex {
    LabelIndex::from_labels(
        scene.labels.as_ref(),
        scene.frames.len() as u32,
        scene.width,
        scene.height,
        cfg.num_classes,
    )
}

fn close(a: f32, b: f32, tolerance: f32) -> bool {
    (a - b).abs() <= tolerance * (1.0 + b.abs())
}

#[test]
fn uniform_blocks_match_wgsl_sizes() {
    assert_eq!(size_of::<StepUniforms>(), 32);
    assert_eq!(size_of::<RayGeometry>(), 48);
    assert_eq!(size_of::<SceneUniforms>(), 80);
    assert_eq!(size_of::<SamplePlanUniforms>(), 48);
}

#[test]
fn label_index_groups_rasterized_pixels_by_class() {
    let scene = test_scene();
    let cfg = test_config(64);
    let index = label_index(&scene, &cfg);
    let last = cfg.num_classes - 1;
    assert!(index.pixels_by_class[last as usize].is_empty());
    assert!(index.present_classes().len() >= 3, "{:?}", index.present_classes());
    let ppf = scene.width * scene.height;
    for (class, pixels) in index.pixels_by_class.iter().enumerate() {
        for &pixel in pixels {
            let frame = pixel / ppf;
            let map = rasterize_frame(scene.labels.as_ref().unwrap().frame(frame), scene.width, scene.height);
            assert_eq!(u32::from(map[(pixel % ppf) as usize]), class as u32);
        }
    }
    let words = index.to_words();
    let k = words[0] as usize;
    assert_eq!(k, index.present_classes().len());
    assert_eq!(words.len(), 1 + 3 * k + index.labelled_pixel_count());
    for slot in 0..k {
        let (class, start, count) = (
            words[1 + 3 * slot],
            words[2 + 3 * slot] as usize,
            words[3 + 3 * slot] as usize,
        );
        assert_eq!(&words[start..start + count], &index.pixels_by_class[class as usize][..]);
    }
}

/// Every ray's pixel and label equal the CPU twin's, bit for bit, over several steps and seeds,
/// with labels and without; its geometry and targets match `reference::sampling` and the scene.
#[test]
fn ray_batch_matches_cpu_twin_and_reference() {
    let Some(ctx) = gpu_for_tests("ray_batch_matches_cpu_twin_and_reference") else {
        return;
    };
    let labelled = test_scene();
    let mut unlabelled = labelled.clone();
    unlabelled.labels = None;
    // 1000 rays: not a multiple of the 64-ray workgroup.
    let cfg = test_config(1000);
    for scene in [&labelled, &unlabelled] {
        let p = passes(&ctx, scene, &cfg);
        let index = label_index(scene, &cfg);
        let total_pixels = scene.frames.len() as u32 * scene.width * scene.height;
        let mut labelled_draws = 0;
        for (seed, step) in [(0u32, 1u32), (0, 2), (77, 1), (77, 9000)] {
            let uniforms = StepUniforms::for_step(&cfg, step, seed, 1e-3);
            let out = run_step(&ctx, &p, &uniforms);
            for ray in 0..cfg.batch_rays {
                let twin = pick_pixel(&uniforms, ray, total_pixels, &index);
                let geometry = out.rays[ray as usize];
                let target =
                    &out.targets[ray as usize * p.rays.target_stride as usize..][..p.rays.target_stride as usize];
                assert_eq!(geometry.pixel, twin.pixel, "seed {seed} step {step} ray {ray}");
                assert_eq!(target[TARGET_PIXEL], twin.pixel);
                assert_eq!(
                    target[TARGET_LABEL],
                    twin.label.unwrap_or(NO_LABEL),
                    "seed {seed} step {step} ray {ray}"
                );
                labelled_draws += usize::from(twin.label.is_some());
                check_ray_against_scene(scene, &geometry, target);
            }
        }
        if scene.labels.is_some() {
            assert_eq!(labelled_draws, 4 * (cfg.batch_rays / 2) as usize);
        } else {
            assert_eq!(labelled_draws, 0);
        }
    }
}

fn check_ray_against_scene(scene: &Scene, geometry: &RayGeometry, target: &[u32]) {
    let ppf = scene.width * scene.height;
    let (frame, local) = (geometry.pixel / ppf, geometry.pixel % ppf);
    let (x, y) = (local % scene.width, local / scene.width);
    let pose = &scene.frames[frame as usize].pose;
    let reference = sampling::ray_through_pixel(&scene.intrinsics, pose, f64::from(x), f64::from(y));
    let what = format!("frame {frame} pixel ({x}, {y})");
    // f32 arithmetic on the GPU against f64 rounded to f32: a few ulps.
    for a in 0..3 {
        assert!(
            close(geometry.origin[a], reference.origin[a], 1e-6),
            "{what}: origin {geometry:?} vs {reference:?}"
        );
        assert!(
            close(geometry.dir[a], reference.dir[a], 1e-5),
            "{what}: dir {geometry:?} vs {reference:?}"
        );
    }
    assert!(close(geometry.z_per_t, reference.z_per_t, 1e-6), "{what}");
    match sampling::clip_to_bounds(&reference, &scene.bounds) {
        Some((near, far)) => {
            assert_eq!(geometry.flags & RAY_HITS_BOX, RAY_HITS_BOX, "{what}");
            assert!(
                close(geometry.near, near, 1e-4) && close(geometry.far, far, 1e-4),
                "{what}: {geometry:?} vs {near} {far}"
            );
        }
        None => assert_eq!(
            (geometry.flags & RAY_HITS_BOX, geometry.near, geometry.far),
            (0, 0.0, 0.0),
            "{what}"
        ),
    }
    let f = |w: usize| f32::from_bits(target[w]);
    let rgb = scene.frames[frame as usize].rgb.get_pixel(x, y).0;
    for (c, value) in rgb.iter().enumerate() {
        assert!(
            (f(TARGET_RGB + c) - f32::from(*value) / 255.0).abs() < 1e-6,
            "{what}: colour"
        );
    }
    let depth = scene.depth_m(frame as usize, x, y).map_or(0.0, |d| d as f32);
    assert!(
        close(f(TARGET_DEPTH), depth, 1e-6) && close(geometry.depth, depth, 1e-6),
        "{what}: depth"
    );
    assert_eq!(target[TARGET_FLAGS], geometry.flags);
    let codes = scene.features.as_ref().unwrap();
    assert_eq!(geometry.flags & RAY_HAS_CODE, RAY_HAS_CODE);
    // The nearest cell by the archive's rule: cell (i, j) covers [j·W/w, (j+1)·W/w) x [i·H/h, …).
    let (row, col) = (y * codes.height / scene.height, x * codes.width / scene.width);
    let start = ((row * codes.width + col) * codes.dim) as usize;
    let expected = &codes.frame(frame as usize)[start..start + codes.dim as usize];
    for (d, value) in expected.iter().enumerate() {
        assert_eq!(f(TARGET_HEADER_WORDS + d), value.to_f32(), "{what}: code {d}");
    }
}

/// Sample positions, intervals and z-depths equal `reference::sampling` (`place_samples`,
/// `interval_lengths`, `normalize_position`) fed the CPU twin's jitter and the GPU ray (whose
/// geometry `ray_batch_matches_cpu_twin_and_reference` checks against the reference's own ray).
#[test]
fn sample_points_match_reference_placement() {
    let Some(ctx) = gpu_for_tests("sample_points_match_reference_placement") else {
        return;
    };
    let scene = test_scene();
    for cfg in [
        FieldConfig {
            last_sample: LastSample::Opaque,
            ..test_config(300)
        },
        FieldConfig {
            samples_coarse: 16,
            samples_fine: 48,
            last_sample: LastSample::Clear,
            ..test_config(130)
        },
    ] {
        let p = passes(&ctx, &scene, &cfg);
        let uniforms = StepUniforms::for_step(&cfg, 5, 21, 1e-3);
        let out = run_step(&ctx, &p, &uniforms);
        let s_count = cfg.samples_per_ray();
        let plan = SamplePlan {
            coarse: cfg.samples_coarse as usize,
            fine: cfg.samples_fine as usize,
            band_half_width: sampling::surface_band_half_width(&scene.bounds, cfg.surface_band_fraction),
        };
        let mut banded = 0;
        for ray in 0..cfg.batch_rays as usize {
            let g = out.rays[ray];
            let jitter = sample_jitter(&uniforms, ray as u32, s_count);
            let surface = (g.depth > 0.0).then(|| g.depth / g.z_per_t);
            let ts = sampling::place_samples(&plan, g.near, g.far, surface, &jitter);
            let deltas = sampling::interval_lengths(&ts, g.far, cfg.opaque_last_sample());
            let r = sampling::Ray {
                origin: g.origin,
                dir: g.dir,
                z_per_t: g.z_per_t,
            };
            banded += usize::from(surface.is_some() && g.flags & RAY_HITS_BOX != 0);
            for s in 0..s_count {
                let n = ray * s_count + s;
                let [px, py, pz, t] = out.positions[n];
                let what = format!("ray {ray} sample {s}");
                // Same f32 operations on both sides; 1e-6 allows a fused multiply-add.
                assert!(close(t, ts[s], 1e-6), "{what}: t {t} vs {}", ts[s]);
                let expected = sampling::normalize_position(&scene.bounds, r.at(ts[s]));
                for (a, v) in [px, py, pz].iter().enumerate() {
                    assert!(
                        (v - expected[a]).abs() < 1e-5,
                        "{what}: position {:?} vs {expected:?}",
                        out.positions[n]
                    );
                }
                let [delta, z] = out.intervals[n];
                assert!(
                    (delta - deltas[s]).abs() <= 1e-5 * (1.0 + g.far),
                    "{what}: delta {delta} vs {}",
                    deltas[s]
                );
                assert!(close(z, ts[s] * g.z_per_t, 1e-6), "{what}: z-depth");
            }
        }
        assert!(
            banded > cfg.batch_rays as usize / 2,
            "most demo rays have depth: {banded}"
        );
    }
}

/// Labelled rays draw the class uniformly (not in proportion to its pixel count): a chi-square
/// test over many steps of the GPU picks, and only classes that have labelled pixels appear.
#[test]
fn labelled_half_is_class_balanced() {
    let Some(ctx) = gpu_for_tests("labelled_half_is_class_balanced") else {
        return;
    };
    let scene = test_scene();
    let cfg = test_config(1000);
    let p = passes(&ctx, &scene, &cfg);
    let index = label_index(&scene, &cfg);
    let present = index.present_classes();
    let sizes: Vec<usize> = present
        .iter()
        .map(|c| index.pixels_by_class[*c as usize].len())
        .collect();
    // The classes are very unequal in pixels, so a pixel-uniform draw would fail the test.
    assert!(
        sizes.iter().max().unwrap() > &(4 * sizes.iter().min().unwrap()),
        "{sizes:?}"
    );
    let mut counts = vec![0u64; cfg.num_classes as usize];
    let steps = 30;
    for step in 1..=steps {
        let out = run_step(&ctx, &p, &StepUniforms::for_step(&cfg, step, 4, 1e-3));
        for ray in 0..cfg.batch_rays as usize {
            let label = out.targets[ray * p.rays.target_stride as usize + TARGET_LABEL];
            if label != NO_LABEL {
                counts[label as usize] += 1;
            }
        }
    }
    let total: u64 = counts.iter().sum();
    assert_eq!(total, u64::from(steps * (cfg.batch_rays / 2)));
    for (class, count) in counts.iter().enumerate() {
        assert_eq!(
            *count > 0,
            present.contains(&(class as u32)),
            "class {class}: {counts:?}"
        );
    }
    let expected = total as f64 / present.len() as f64;
    let chi2: f64 = present
        .iter()
        .map(|c| (counts[*c as usize] as f64 - expected).powi(2) / expected)
        .sum();
    // 99.9th percentile of chi-square with up to 5 degrees of freedom is 20.5.
    assert!(chi2 < 20.5, "chi-square {chi2:.1} over {counts:?}");
    eprintln!("labelled draws per class {counts:?}, chi-square {chi2:.2}, pixels per class {sizes:?}");
}

/// New labels are written in place and the very next step draws from them.
#[test]
fn relabelling_changes_the_draws() {
    let Some(ctx) = gpu_for_tests("relabelling_changes_the_draws") else {
        return;
    };
    let scene = test_scene();
    let cfg = test_config(200);
    let mut p = passes(&ctx, &scene, &cfg);
    let mut index = LabelIndex {
        pixels_by_class: vec![Vec::new(); cfg.num_classes as usize],
    };
    index.pixels_by_class[2] = vec![17, 5000, 5999];
    p.scene.upload_labels(&ctx, &index).unwrap();
    p.rays.follow_labels(&ctx, &p.scene);
    let uniforms = StepUniforms::for_step(&cfg, 3, 1, 1e-3);
    let out = run_step(&ctx, &p, &uniforms);
    let total = scene.frames.len() as u32 * scene.width * scene.height;
    for ray in 0..cfg.batch_rays {
        let twin = pick_pixel(&uniforms, ray, total, &index);
        assert_eq!(out.rays[ray as usize].pixel, twin.pixel);
        if ray >= cfg.batch_rays / 2 {
            assert_eq!(twin.label, Some(2));
            assert!([17, 5000, 5999].contains(&twin.pixel));
        }
    }
}

#[test]
fn scene_too_big_for_a_binding_is_a_clear_error() {
    let Some(ctx) = gpu_for_tests("scene_too_big_for_a_binding_is_a_clear_error") else {
        return;
    };
    let mut small = ctx.clone();
    // 6000 pixels of 4 bytes do not fit 16 KiB.
    small.limits.max_storage_buffer_binding_size = 16 << 10;
    let error = SceneBuffers::upload(&small, &test_scene(), &test_config(64))
        .err()
        .expect("must not fit");
    assert!(matches!(error, GpuError::LimitExceeded { .. }), "{error}");
    let message = error.to_string();
    assert!(
        message.contains("scene colour") && message.contains("5 frames of 40 x 30"),
        "{message}"
    );

    let wrong_dim = FieldConfig {
        feature_dim: FEATURE_DIM + 1,
        ..test_config(64)
    };
    let error = SceneBuffers::upload(&ctx, &test_scene(), &wrong_dim)
        .err()
        .expect("feature dims differ");
    assert!(error.to_string().contains("feature_dim"), "{error}");
}

/// Measurement, not a check: `cargo test --release --test gpu_field_rays -- --ignored --nocapture`.
#[test]
#[ignore = "measurement; run explicitly in release mode"]
fn ray_passes_throughput_report() {
    let Some(ctx) = gpu_for_tests("ray_passes_throughput_report") else {
        return;
    };
    let mut scene = demo_scene(&DemoOptions::default()).unwrap();
    scene.labels = test_scene().labels;
    let d = FieldConfig::default();
    let cfg = FieldConfig {
        num_classes: demo_classes().len() as u32,
        feature_dim: d.feature_dim,
        ..d
    };
    let p = passes(&ctx, &scene, &cfg);
    ctx.queue.write_buffer(
        &p.step,
        0,
        bytemuck::bytes_of(&StepUniforms::for_step(&cfg, 1, 0, 1e-3)),
    );
    let time = |record: &dyn Fn(&mut wgpu::ComputePass<'_>), repeats: u32| {
        let run = |n: u32| {
            let mut encoder = ctx.device.create_command_encoder(&Default::default());
            {
                let mut compute = encoder.begin_compute_pass(&Default::default());
                for _ in 0..n {
                    record(&mut compute);
                }
            }
            ctx.queue.submit([encoder.finish()]);
            ctx.wait_idle().unwrap();
        };
        run(1);
        let start = Instant::now();
        run(repeats);
        f64::from(repeats * cfg.batch_rays) / start.elapsed().as_secs_f64()
    };
    let batch_rate = time(&|c| p.rays.record(c), 20);
    let sample_rate = time(&|c| p.samples.record(c), 20);
    println!(
        "on {} with B = {}, S = {}, D = {}: ray_batch {batch_rate:.0} rays/s, sample_points {sample_rate:.0} rays/s \
         ({:.0} samples/s)",
        ctx.describe(),
        cfg.batch_rays,
        cfg.samples_per_ray(),
        cfg.feature_dim,
        sample_rate * cfg.samples_per_ray() as f64
    );
}
