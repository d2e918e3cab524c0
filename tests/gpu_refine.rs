//! `shaders/refine.wgsl` against its CPU twin `refine::refine_probabilities` on lavapipe:
//! one round into an output buffer filled with garbage, and the whole refinement through
//! `RefinePass::refine` and `RenderedFrame::refine_on_gpu`.
//!
//! Tolerance: the kernel does the twin's arithmetic, but a Vulkan device's `exp` is not correctly
//! rounded and it may fuse multiply-adds; probabilities in [0, 1] agree within 1e-5 after a round
//! and 1e-4 after several.
use image::{ImageBuffer, Luma, Rgb, RgbImage};
use scribblefield::field::gpu::view::FrameAssembler;
use scribblefield::gpu::GpuContext;
use scribblefield::gpu::buffers::{read_buffer_blocking, storage_buffer_from, storage_buffer_garbage};
use scribblefield::gpu::test_support::gpu_for_tests;
use scribblefield::refine::gpu::{GuideBuffers, RefinePass, RefineUniforms};
use scribblefield::refine::{RefineOptions, refine_probabilities};
use scribblefield::rng::SplitMix64;
use scribblefield::scene::DepthImage;
use scribblefield::scene::Guide;

const CLASSES: usize = 5;

/// A 37 x 23 guide of coloured blocks with noise, depth in steps with holes (0 = no reading),
/// and random probabilities (each pixel's summing to 1).
fn inputs() -> (RgbImage, DepthImage, Vec<f32>) {
    let mut rng = SplitMix64::new(7);
    let (w, h) = (37u32, 23u32);
    let rgb = RgbImage::from_fn(w, h, |x, y| {
        let block = ((x / 6) * 3 + y / 5) as u8;
        let noise = (x * 13 + y * 7) % 9;
        Rgb([
            block.wrapping_mul(40).wrapping_add(noise as u8),
            90 + (x % 3) as u8 * 20,
            200 - block * 5,
        ])
    });
    let depth = ImageBuffer::from_fn(w, h, |x, y| {
        Luma([if (x * 5 + y * 3) % 11 == 0 {
            0
        } else {
            800 + (x / 9) as u16 * 300 + y as u16
        }])
    });
    let mut probabilities = Vec::with_capacity((w * h) as usize * CLASSES);
    for _ in 0..w * h {
        let raw: Vec<f32> = (0..CLASSES).map(|_| rng.uniform(0.01, 1.0) as f32).collect();
        let sum: f32 = raw.iter().sum();
        probabilities.extend(raw.iter().map(|v| v / sum));
    }
    (rgb, depth, probabilities)
}

fn assert_close(what: &str, gpu: &[f32], cpu: &[f32], tolerance: f32) {
    assert_eq!(gpu.len(), cpu.len(), "{what}");
    for (i, (g, c)) in gpu.iter().zip(cpu).enumerate() {
        assert!((g - c).abs() <= tolerance, "{what}[{i}]: GPU {g}, CPU {c}");
    }
}

/// A reach of a few pixels on this small guide, so taps are spaced (step 2) and clipped at the
/// borders.
fn options(iterations: u32) -> RefineOptions {
    RefineOptions {
        iterations,
        spatial_sigma: 0.09,
        votes: false,
        ..RefineOptions::default()
    }
}

#[test]
fn one_round_matches_the_cpu_twin() {
    let Some(ctx) = gpu_for_tests("one_round_matches_the_cpu_twin") else {
        return;
    };
    let (rgb, depth, probabilities) = inputs();
    let guide = Guide {
        rgb: &rgb,
        depth: Some(&depth),
        codes: None,
    };
    let uniforms = RefineUniforms::new(rgb.width(), rgb.height(), CLASSES as u32, &options(1));
    assert_eq!(uniforms.step, 2, "the test should exercise spaced taps");
    let pass = pollster::block_on(RefinePass::new(&ctx)).unwrap();
    let guide_buffers = GuideBuffers::new(&ctx, guide, CLASSES, &options(1)).unwrap();
    let input = storage_buffer_from(&ctx, "input", &probabilities).unwrap();
    let output = storage_buffer_garbage::<f32>(&ctx, "output", probabilities.len()).unwrap();
    let mut encoder = ctx.device.create_command_encoder(&Default::default());
    pass.record(&ctx, &mut encoder, &guide_buffers, &input, &output)
        .unwrap();
    ctx.queue.submit([encoder.finish()]);
    let gpu = read_buffer_blocking::<f32>(&ctx, &output).unwrap();

    let mut cpu = probabilities.clone();
    refine_probabilities(&mut cpu, CLASSES, guide, &options(1)).unwrap();
    assert_ne!(cpu, probabilities, "the round should change the probabilities");
    assert_close("one round", &gpu, &cpu, 1e-5);
}

fn check_refine(ctx: &GpuContext, with_depth: bool) {
    let (rgb, depth, probabilities) = inputs();
    let guide = Guide {
        rgb: &rgb,
        depth: with_depth.then_some(&depth),
        codes: None,
    };
    let pass = pollster::block_on(RefinePass::new(ctx)).unwrap();
    for (iterations, votes) in [(0, false), (1, false), (3, false), (3, true)] {
        let options = RefineOptions {
            votes,
            ..options(iterations)
        };
        let mut gpu = probabilities.clone();
        pollster::block_on(pass.refine(ctx, &mut gpu, CLASSES, guide, &options)).unwrap();
        let mut cpu = probabilities.clone();
        refine_probabilities(&mut cpu, CLASSES, guide, &options).unwrap();
        assert_close(
            &format!("{iterations} rounds, votes {votes}, depth {with_depth}"),
            &gpu,
            &cpu,
            1e-4,
        );
    }
    // Sizes that do not fit are refused before any GPU work, naming them.
    let mut short = probabilities[..10].to_vec();
    let err = pollster::block_on(pass.refine(ctx, &mut short, CLASSES, guide, &options(3))).unwrap_err();
    assert!(err.to_string().contains("37 x 23"), "{err}");
}

#[test]
fn whole_refinement_matches_the_cpu_twin_with_and_without_depth() {
    let Some(ctx) = gpu_for_tests("whole_refinement_matches_the_cpu_twin_with_and_without_depth") else {
        return;
    };
    check_refine(&ctx, true);
    check_refine(&ctx, false);
}

#[test]
fn a_rendered_frame_refined_on_the_gpu_matches_one_refined_on_the_cpu() {
    let Some(ctx) = gpu_for_tests("a_rendered_frame_refined_on_the_gpu_matches_one_refined_on_the_cpu") else {
        return;
    };
    let (rgb, depth, probabilities) = inputs();
    let guide = Guide {
        rgb: &rgb,
        depth: Some(&depth),
        codes: None,
    };
    // Rendered rows: rgb, depth, the logits (log probabilities), no features.
    let mut assembler = FrameAssembler::new(rgb.width(), rgb.height(), CLASSES, 0);
    for p in probabilities.chunks_exact(CLASSES) {
        let mut row = vec![0.5, 0.5, 0.5, 1.0];
        row.extend(p.iter().map(|v| v.ln()));
        assembler.push(&row);
    }
    let rendered = assembler.finish(None);
    let mut on_cpu = rendered.clone();
    on_cpu.refine(guide, &options(3)).unwrap();
    let mut on_gpu = rendered.clone();
    let pass = pollster::block_on(RefinePass::new(&ctx)).unwrap();
    pollster::block_on(on_gpu.refine_on_gpu(&ctx, &pass, guide, &options(3))).unwrap();
    assert!(on_gpu.refined && on_cpu.refined);
    assert_ne!(on_cpu.classes, rendered.classes, "refining should change some classes");
    assert_close("probabilities", &on_gpu.probabilities, &on_cpu.probabilities, 1e-4);
    // Ties aside, the class maps agree.
    let differing = on_gpu
        .classes
        .iter()
        .zip(&on_cpu.classes)
        .filter(|(a, b)| a != b)
        .count();
    assert!(differing <= 2, "{differing} pixels differ");
    let wrong = RgbImage::new(4, 4);
    let err =
        pollster::block_on(on_gpu.refine_on_gpu(&ctx, &pass, Guide::colour_only(&wrong), &options(3))).unwrap_err();
    assert!(err.to_string().contains("4 x 4"), "{err}");
}

/// `cargo test --release --test gpu_refine -- --ignored --nocapture`: time per frame on this
/// adapter, upload and read-back included.
#[test]
#[ignore = "benchmark: prints the time per frame"]
fn bench() {
    let Some(ctx) = gpu_for_tests("bench") else {
        return;
    };
    let pass = pollster::block_on(RefinePass::new(&ctx)).unwrap();
    for (w, h) in [(160u32, 120u32), (640, 480)] {
        let rgb = RgbImage::from_fn(w, h, |x, y| Rgb([(x * 7 % 256) as u8, (y * 5 % 256) as u8, 90]));
        let depth = ImageBuffer::from_fn(w, h, |x, y| Luma([1000 + (x + y) as u16]));
        let guide = Guide {
            rgb: &rgb,
            depth: Some(&depth),
            codes: None,
        };
        let classes = 6;
        let base = vec![1.0 / classes as f32; (w * h) as usize * classes];
        let mut p = base.clone();
        pollster::block_on(pass.refine(&ctx, &mut p, classes, guide, &RefineOptions::default())).unwrap();
        let runs = 3;
        let clock = std::time::Instant::now();
        for _ in 0..runs {
            p.copy_from_slice(&base);
            pollster::block_on(pass.refine(&ctx, &mut p, classes, guide, &RefineOptions::default())).unwrap();
        }
        let ms = clock.elapsed().as_secs_f64() * 1e3 / f64::from(runs);
        println!(
            "GPU refine {w} x {h}, {classes} classes, 3 rounds on {}: {ms:.1} ms per frame",
            ctx.describe()
        );
    }
}
