//! `composite.wgsl` against the CPU reference: from random head outputs, the whole per-ray chain
//! (activations, rendering, the four losses, and every per-sample gradient) on lavapipe.
//!
//! Run in release: `cargo test --release --test gpu_field_composite`.
use std::time::Instant;

use scribblefield::field::gpu::composite::{
    CompositeInputs, CompositeKernel, CompositeLayout, CompositePass, CompositeUniforms, RowView,
};
use scribblefield::field::gpu::keep::NOT_KEPT;
use scribblefield::field::gpu::rays::{
    NO_LABEL, RAY_HAS_CODE, RAY_HITS_BOX, StepUniforms, TARGET_DEPTH, TARGET_FLAGS, TARGET_HEADER_WORDS, TARGET_LABEL,
    TARGET_RGB,
};
use scribblefield::field::gpu::stage::Stage;
use scribblefield::field::reference::loss::{RayTarget, add_opacity, opacity_loss, ray_loss};
use scribblefield::field::reference::{Channels, activations, render};
use scribblefield::field::{FieldConfig, bf16};
use scribblefield::gpu::buffers::{fill_with_garbage, read_buffer_blocking, storage_buffer_from, uniform_buffer_from};
use scribblefield::gpu::test_support::gpu_for_tests;
use scribblefield::gpu::{GpuContext, KernelFamily};
use scribblefield::rng::SplitMix64;

/// Stride of the density MLP's output rows in these tests ([h₀, geometry feature]).
const DENSITY_STRIDE: u32 = 16;

/// Random inputs of the pass, laid out as the GPU reads them.
struct Batch {
    cfg: FieldConfig,
    /// B·S rows of DENSITY_STRIDE (h₀ in column 0, noise after it).
    density: Vec<f32>,
    /// B·S rows of 3.
    color: Vec<f32>,
    /// B·S rows of [logits (C), feature (D), 1 spare]: one buffer bound twice.
    logits_and_feature: Vec<f32>,
    /// B·S (δ, z).
    intervals: Vec<[f32; 2]>,
    /// B rows of TARGET_HEADER_WORDS + D.
    targets: Vec<u32>,
    /// Per sample, its packed row in the head outputs, or NOT_KEPT (about a fifth dropped, as
    /// the keep pass drops samples of low weight).
    slot: Vec<u32>,
    /// The class of what lies beyond the box, for the opacity term (`CompositePass::set_far_class`).
    far_class: Option<u32>,
}

impl Batch {
    fn samples(&self) -> usize {
        self.cfg.samples_per_ray()
    }

    fn heads_stride(&self) -> usize {
        (self.cfg.num_classes + self.cfg.feature_dim + 1) as usize
    }

    fn target_stride(&self) -> usize {
        TARGET_HEADER_WORDS + self.cfg.feature_dim as usize
    }

    /// `values` (`width` per sample) moved to the kept samples' packed rows, garbage after.
    fn packed(&self, values: &[f32], width: usize) -> Vec<f32> {
        let mut out = vec![f32::NAN; values.len()];
        for (n, &p) in self.slot.iter().enumerate() {
            if p != NOT_KEPT {
                let p = p as usize;
                out[p * width..(p + 1) * width].copy_from_slice(&values[n * width..(n + 1) * width]);
            }
        }
        out
    }

    /// As [`Batch::random`] with densities low enough that light reaches the last of many samples
    /// (σ ≤ e⁻¹): there, what one sample's gradient owes to the samples behind it is not near 0.
    fn random_thin(cfg: FieldConfig, seed: u64) -> Batch {
        let mut batch = Batch::random(cfg, seed);
        let mut rng = SplitMix64::new(seed ^ 0x7417);
        for row in batch.density.chunks_mut(DENSITY_STRIDE as usize) {
            row[0] = rng.uniform(-6.0, -1.0) as f32;
        }
        batch
    }

    fn random(cfg: FieldConfig, seed: u64) -> Batch {
        let mut rng = SplitMix64::new(seed);
        let (b, s) = (cfg.batch_rays as usize, cfg.samples_per_ray());
        let (c, d) = (cfg.num_classes as usize, cfg.feature_dim as usize);
        let n = b * s;
        let density = (0..n * DENSITY_STRIDE as usize)
            .map(|i| {
                let r = rng.next_f64();
                // Mostly moderate densities; a few far outside the clamp on both sides.
                let h0 = if r < 0.02 {
                    40.0
                } else if r < 0.04 {
                    -40.0
                } else {
                    rng.uniform(-4.0, 5.0)
                };
                if i % DENSITY_STRIDE as usize == 0 {
                    h0 as f32
                } else {
                    rng.uniform(-9.0, 9.0) as f32
                }
            })
            .collect();
        let color = (0..n * 3).map(|_| rng.uniform(-4.0, 4.0) as f32).collect();
        let logits_and_feature = (0..n * (c + d + 1)).map(|_| rng.uniform(-2.0, 2.0) as f32).collect();
        let intervals = (0..n)
            .map(|i| {
                // Every other ray ends in an opaque sample (`LastSample::Opaque`).
                let delta = if i % s == s - 1 && (i / s) % 2 == 0 {
                    f64::from(render::OPAQUE_INTERVAL)
                } else if rng.next_f64() < 0.05 {
                    0.0
                } else {
                    rng.uniform(0.0, 0.25)
                };
                [delta as f32, rng.uniform(0.3, 3.0) as f32]
            })
            .collect();
        let mut targets = Vec::with_capacity(b * (TARGET_HEADER_WORDS + d));
        for _ in 0..b {
            let rgb: [f32; 3] = std::array::from_fn(|_| rng.next_f32());
            let depth = if rng.next_f64() < 0.6 {
                rng.uniform(0.3, 3.0) as f32
            } else {
                0.0
            };
            let label = match rng.below(4) {
                0 => NO_LABEL,
                // Out of range: treated as unlabelled, as in the reference.
                1 => c as u32 + 2,
                _ => rng.below(c as u64) as u32,
            };
            let hits = rng.next_f64() < 0.9;
            let has_code = rng.next_f64() < 0.8;
            let flags = if hits { RAY_HITS_BOX } else { 0 } | if has_code { RAY_HAS_CODE } else { 0 };
            let mut header = [0u32; TARGET_HEADER_WORDS];
            header[TARGET_RGB..TARGET_RGB + 3].copy_from_slice(&rgb.map(f32::to_bits));
            header[TARGET_DEPTH] = depth.to_bits();
            header[TARGET_LABEL] = label;
            header[TARGET_FLAGS] = flags;
            targets.extend_from_slice(&header);
            targets.extend((0..d).map(|_| if has_code { rng.uniform(-1.5, 1.5) as f32 } else { 0.0 }.to_bits()));
        }
        let mut kept = 0u32;
        let slot = (0..n)
            .map(|_| {
                if rng.next_f64() < 0.2 {
                    NOT_KEPT
                } else {
                    kept += 1;
                    kept - 1
                }
            })
            .collect();
        Batch {
            cfg,
            density,
            color,
            logits_and_feature,
            intervals,
            targets,
            slot,
            far_class: None,
        }
    }
}

/// The reference's answer for one ray: (loss terms, rendered, dL/drendered, grad rows).
struct Expected {
    losses: [f64; 4],
    rendered: Vec<f64>,
    grad_rendered: Vec<f64>,
    grad_heads: Vec<f64>,
}

fn reference_ray(batch: &Batch, ray: usize) -> Expected {
    let cfg = &batch.cfg;
    let s_count = batch.samples();
    let channels = Channels {
        classes: cfg.num_classes as usize,
        feature_dim: cfg.feature_dim as usize,
    };
    let (c, d, k) = (channels.classes, channels.feature_dim, channels.count());
    let row = &batch.targets[ray * batch.target_stride()..(ray + 1) * batch.target_stride()];
    if row[TARGET_FLAGS] & RAY_HITS_BOX == 0 {
        return Expected {
            losses: [0.0; 4],
            rendered: vec![0.0; k],
            grad_rendered: vec![0.0; k],
            grad_heads: vec![0.0; s_count * k],
        };
    }
    let hs = batch.heads_stride();
    let mut sigmas = Vec::new();
    let mut deltas = Vec::new();
    let mut values = Vec::new();
    let mut h0s = Vec::new();
    let mut colours = Vec::new();
    for s in 0..s_count {
        let n = ray * s_count + s;
        let h0 = f64::from(batch.density[n * DENSITY_STRIDE as usize]);
        h0s.push(h0);
        sigmas.push(activations::density(h0));
        deltas.push(f64::from(batch.intervals[n][0]));
        // A sample kept from the heads renders 0 for colour, logits and feature.
        let kept = batch.slot[n] != NOT_KEPT;
        let rgb: [f64; 3] = std::array::from_fn(|i| {
            if kept {
                activations::sigmoid(f64::from(batch.color[n * 3 + i]))
            } else {
                0.0
            }
        });
        colours.push(rgb);
        values.extend_from_slice(&rgb);
        values.push(f64::from(batch.intervals[n][1]));
        values.extend(
            batch.logits_and_feature[n * hs..n * hs + c + d]
                .iter()
                .map(|v| if kept { f64::from(*v) } else { 0.0 }),
        );
    }
    let forward = render::composite(&sigmas, &deltas, &values, k);
    let f = |w: usize| f32::from_bits(row[w]);
    let depth = f(TARGET_DEPTH);
    let target = RayTarget {
        rgb: [f(TARGET_RGB), f(TARGET_RGB + 1), f(TARGET_RGB + 2)],
        depth: (depth > 0.0).then_some(depth),
        label: (row[TARGET_LABEL] != NO_LABEL).then_some(row[TARGET_LABEL]),
        code: (row[TARGET_FLAGS] & RAY_HAS_CODE != 0).then(|| (0..d).map(|i| f(TARGET_HEADER_WORDS + i)).collect()),
    };
    let (mut terms, grad_rendered) = ray_loss(
        &cfg.loss,
        cfg.feature_supervision,
        &channels,
        &forward.output,
        &target,
        cfg.batch_rays as usize,
    );
    let opacity = opacity_loss(
        &cfg.loss,
        render::left_for_opaque_sample(&forward, &deltas),
        target.label,
        batch.far_class,
        c,
        cfg.batch_rays as usize,
    );
    let grad_left = add_opacity(&mut terms, opacity);
    let (grad_sigma, grad_values) =
        render::composite_backward(&forward, &deltas, &values, k, &grad_rendered, grad_left);
    let mut grad_heads = Vec::with_capacity(s_count * k);
    for s in 0..s_count {
        let gv = &grad_values[s * k..(s + 1) * k];
        grad_heads.push(activations::density_backward(h0s[s], grad_sigma[s]));
        for i in 0..3 {
            grad_heads.push(activations::sigmoid_backward(colours[s][i], gv[Channels::RGB + i]));
        }
        grad_heads.extend_from_slice(&gv[Channels::SEMANTIC..]);
    }
    Expected {
        losses: [terms.rgb, terms.depth, terms.semantic, terms.feature],
        rendered: forward.output,
        grad_rendered,
        grad_heads,
    }
}

struct GpuRun {
    grad_heads: Vec<f32>,
    head_grads: Vec<f32>,
    ray_outputs: Vec<f32>,
}

fn run_on_gpu(ctx: &GpuContext, batch: &Batch) -> GpuRun {
    run_entry(ctx, batch, false)
}

/// Runs the training entry point, or with `render` the forward alone, on garbage-filled outputs.
fn run_entry(ctx: &GpuContext, batch: &Batch, render: bool) -> GpuRun {
    run_with_features(ctx, batch, render, false)
}

/// [`run_entry`], with the feature head's rows in bf16 rows of their own where `bf16_features`.
fn run_with_features(ctx: &GpuContext, batch: &Batch, render: bool, bf16_features: bool) -> GpuRun {
    let cfg = &batch.cfg;
    let step = uniform_buffer_from(ctx, "step", &StepUniforms::for_step(cfg, 1, 0, 1e-3));
    let density = storage_buffer_from(ctx, "density out", &batch.density).unwrap();
    let color = storage_buffer_from(ctx, "colour out", &batch.packed(&batch.color, 3)).unwrap();
    let heads = storage_buffer_from(
        ctx,
        "logits and feature",
        &batch.packed(&batch.logits_and_feature, batch.heads_stride()),
    )
    .unwrap();
    let intervals = storage_buffer_from(ctx, "intervals", &batch.intervals).unwrap();
    let targets = storage_buffer_from(ctx, "targets", &batch.targets).unwrap();
    let slot = storage_buffer_from(ctx, "slot", &batch.slot).unwrap();
    let hs = batch.heads_stride() as u32;
    let (c, d) = (cfg.num_classes as usize, cfg.feature_dim as usize);
    let feature = if bf16_features {
        // Each packed row's D values as bf16 pairs, rows padded to an even length.
        let packed = batch.packed(&batch.logits_and_feature, hs as usize);
        let words: Vec<u32> = packed
            .chunks(hs as usize)
            .flat_map(|row| {
                let mut f = row[c..c + d].to_vec();
                f.resize(d.next_multiple_of(2), 0.0);
                f.chunks(2).map(|p| bf16::pair(p[0], p[1])).collect::<Vec<_>>()
            })
            .collect();
        RowView::packed_bf16(&storage_buffer_from(ctx, "bf16 features", &words).unwrap(), d as u32)
    } else {
        RowView::new(&heads, hs, cfg.num_classes)
    };
    let inputs = CompositeInputs {
        step_uniforms: &step,
        h0: RowView::new(&density, DENSITY_STRIDE, 0),
        color: RowView::new(&color, 3, 0),
        logits: RowView::new(&heads, hs, 0),
        feature,
        intervals: &intervals,
        targets: &targets,
        slot: &slot,
    };
    let mut pass = pollster::block_on(CompositePass::new(ctx, cfg, &inputs)).unwrap();
    pass.set_far_class(ctx, batch.far_class);
    assert_eq!(pass.far_class(), batch.far_class);
    assert_eq!(pass.kernel, CompositeKernel::for_device(ctx));
    fill_with_garbage(ctx, &pass.grad_heads);
    fill_with_garbage(ctx, &pass.head_grads);
    fill_with_garbage(ctx, &pass.ray_outputs);
    let mut encoder = ctx.device.create_command_encoder(&Default::default());
    {
        let mut compute = encoder.begin_compute_pass(&Default::default());
        if render {
            pass.record_render(&mut compute);
        } else {
            pass.record(&mut compute);
        }
    }
    ctx.queue.submit([encoder.finish()]);
    GpuRun {
        grad_heads: read_buffer_blocking(ctx, &pass.grad_heads).unwrap(),
        head_grads: read_buffer_blocking(ctx, &pass.head_grads).unwrap(),
        ray_outputs: read_buffer_blocking(ctx, &pass.ray_outputs).unwrap(),
    }
}

/// f32 on the GPU against the f64 reference. Each group of values (one ray's rendered channels,
/// gradients, one ray's per-sample gradients of one kind) is compared relative to its largest
/// magnitude: the GPU sums S terms in f32, so errors are a few ulps of the largest term, and a
/// value that cancels to near zero (a gradient behind an opaque surface) can only be judged
/// against the scale of its neighbours. 2e-4 is ~1000 ulps, far below any real mistake (a
/// missing term or a wrong weight changes values by O(1) of that scale).
fn assert_group_close(what: &str, gpu: &[f32], expected: &[f64]) {
    assert_eq!(gpu.len(), expected.len(), "{what}");
    let scale = expected.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    for (i, (g, e)) in gpu.iter().zip(expected).enumerate() {
        let g = f64::from(*g);
        assert!(g.is_finite(), "{what}[{i}]: GPU wrote {g} (expected {e})");
        let tolerance = 2e-4 * scale + 1e-6 * e.abs() + 1e-12;
        assert!(
            (g - e).abs() <= tolerance,
            "{what}[{i}]: GPU {g}, reference {e} (group scale {scale:e})"
        );
    }
}

fn check_batch(ctx: &GpuContext, batch: &Batch) {
    let cfg = &batch.cfg;
    let layout = CompositeLayout::new(cfg);
    let gpu = run_on_gpu(ctx, batch);
    let (s_count, k) = (batch.samples(), layout.grad_stride());
    assert_eq!(gpu.grad_heads.len(), cfg.batch_rays as usize * s_count * k);
    assert_eq!(gpu.ray_outputs.len(), layout.ray_output_words());
    let mut totals = [0.0f64; 4];
    let mut gpu_totals = [0.0f64; 4];
    let mut labelled_rays = 0;
    for ray in 0..cfg.batch_rays as usize {
        let expected = reference_ray(batch, ray);
        let out = &gpu.ray_outputs[layout.losses(ray..ray + 1)];
        let loss_scale = expected.losses.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        for term in 0..4 {
            let (g, e) = (f64::from(out[term]), expected.losses[term]);
            assert!(
                (g - e).abs() <= 1e-4 * loss_scale + 1e-12,
                "ray {ray} loss term {term}: GPU {g}, reference {e}"
            );
            totals[term] += e;
            gpu_totals[term] += g;
        }
        labelled_rays += usize::from(expected.losses[2] > 0.0);
        let rendered = &gpu.ray_outputs[layout.rendered(ray..ray + 1)];
        assert_group_close(&format!("ray {ray} rendered"), rendered, &expected.rendered);
        let grad_rendered = &gpu.ray_outputs[layout.grad_rendered(ray..ray + 1)];
        assert_group_close(
            &format!("ray {ray} dL/drendered"),
            grad_rendered,
            &expected.grad_rendered,
        );
        // Per kind of gradient over the ray's samples: h₀ (every sample, in its own row), then
        // colour, logits and feature (the kept samples, at their packed rows).
        let first = ray * s_count;
        let dh0: Vec<f32> = (0..s_count).map(|s| gpu.grad_heads[(first + s) * k]).collect();
        let expected_dh0: Vec<f64> = (0..s_count).map(|s| expected.grad_heads[s * k]).collect();
        assert_group_close(&format!("ray {ray} dh0"), &dh0, &expected_dh0);
        let kept: Vec<(usize, usize)> = (0..s_count)
            .filter(|&s| batch.slot[first + s] != NOT_KEPT)
            .map(|s| (s, batch.slot[first + s] as usize))
            .collect();
        let kinds = [
            ("dcolour", 1..4),
            ("dlogits", layout.grad_logits_offset()..layout.grad_feature_offset()),
            ("dfeature", layout.grad_feature_offset()..k),
        ];
        for (name, columns) in kinds {
            let want: Vec<f64> = kept
                .iter()
                .flat_map(|&(s, _)| expected.grad_heads[s * k + columns.start..s * k + columns.end].to_vec())
                .collect();
            let gpu_values: Vec<f32> = kept
                .iter()
                .flat_map(|&(_, p)| gpu.head_grads[p * k + columns.start..p * k + columns.end].to_vec())
                .collect();
            assert_group_close(&format!("ray {ray} {name}"), &gpu_values, &want);
        }
    }
    // The inputs exercise every term (a case where one is silently zero proves nothing).
    assert!(
        totals
            .iter()
            .enumerate()
            .all(|(i, t)| *t > 0.0 || (i == 3 && !cfg.feature_supervision)),
        "{totals:?}"
    );
    assert!(labelled_rays > 0);
    eprintln!("batch loss terms: reference {totals:?}, GPU {gpu_totals:?}");
}

/// The default model's C, D and S (16 + 48) over `batch` rays.
fn default_widths(batch: u32, features: bool) -> FieldConfig {
    let d = FieldConfig::default();
    config(
        d.num_classes,
        d.feature_dim,
        d.samples_coarse,
        d.samples_fine,
        batch,
        features,
    )
}

fn config(classes: u32, feature_dim: u32, coarse: u32, fine: u32, batch: u32, features: bool) -> FieldConfig {
    FieldConfig {
        num_classes: classes,
        feature_dim,
        samples_coarse: coarse,
        samples_fine: fine,
        batch_rays: batch,
        feature_supervision: features,
        ..FieldConfig::small()
    }
}

/// The render entry point (forward alone) writes the rendered block exactly as the training
/// entry point does, bit for bit, over garbage: misses included (zero), and a render is what a
/// frame shows. It writes no loss and no gradient.
fn check_render_matches_training(ctx: &GpuContext, batch: &Batch) {
    let layout = CompositeLayout::new(&batch.cfg);
    let trained = run_on_gpu(ctx, batch);
    let rendered = run_entry(ctx, batch, true);
    let all = 0..batch.cfg.batch_rays as usize;
    let (a, b) = (
        &trained.ray_outputs[layout.rendered(all.clone())],
        &rendered.ray_outputs[layout.rendered(all.clone())],
    );
    for (i, (x, y)) in a.iter().zip(b).enumerate() {
        assert_eq!(x.to_bits(), y.to_bits(), "rendered word {i}: training {x}, render {y}");
    }
    let misses = (0..batch.cfg.batch_rays as usize)
        .filter(|&r| batch.targets[r * batch.target_stride() + TARGET_FLAGS] & RAY_HITS_BOX == 0)
        .count();
    assert!(misses > 0, "the batch should hold rays that miss the box");
    // The losses and gradients are left as they were (garbage): the render computes none.
    let garbage = |v: &[f32]| v.iter().filter(|x| !x.is_finite() || x.abs() > 1e6).count();
    assert!(garbage(&rendered.ray_outputs[layout.losses(all.clone())]) > 0);
    assert!(garbage(&rendered.ray_outputs[layout.grad_rendered(all)]) > 0);
}

/// The device as it is chosen for a CPU device and for a GPU: each composite kernel in turn,
/// whatever the adapter.
fn with_each_kernel(ctx: &GpuContext) -> [GpuContext; 2] {
    let kernels = [
        ctx.clone().with_kernels(KernelFamily::UniformWeights),
        ctx.clone().with_kernels(KernelFamily::Tiled),
    ];
    assert_eq!(
        CompositeKernel::for_device(&kernels[0]),
        CompositeKernel::InvocationPerRay
    );
    assert_eq!(
        CompositeKernel::for_device(&kernels[1]),
        CompositeKernel::WorkgroupPerRay
    );
    kernels
}

/// Feature rows in bf16 (as the feature MLP stores them on CPU devices) composite exactly as f32
/// rows holding the same rounded values, in training and in the render, with each kernel.
#[test]
fn bf16_feature_rows_composite_as_their_rounded_values() {
    let Some(ctx) = gpu_for_tests("bf16_feature_rows_composite_as_their_rounded_values") else {
        return;
    };
    for ctx in with_each_kernel(&ctx) {
        // An odd feature width: every bf16 row ends in a padding value.
        let mut batch = Batch::random(config(3, 5, 5, 7, 300, true), 21);
        let (c, d, hs) = (3, 5, batch.heads_stride());
        for row in batch.logits_and_feature.chunks_mut(hs) {
            for v in &mut row[c..c + d] {
                *v = bf16::round(*v);
            }
        }
        let layout = CompositeLayout::new(&batch.cfg);
        let rendered = layout.rendered(0..batch.cfg.batch_rays as usize);
        let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        for render in [false, true] {
            let f32_rows = run_with_features(&ctx, &batch, render, false);
            let bf16_rows = run_with_features(&ctx, &batch, render, true);
            assert_eq!(
                bits(&f32_rows.ray_outputs[rendered.clone()]),
                bits(&bf16_rows.ray_outputs[rendered.clone()]),
                "render {render}"
            );
            if !render {
                assert_eq!(bits(&f32_rows.ray_outputs), bits(&bf16_rows.ray_outputs));
                assert_eq!(bits(&f32_rows.head_grads), bits(&bf16_rows.head_grads));
            }
        }
    }
}

#[test]
fn render_entry_point_matches_the_training_render_bit_for_bit() {
    let Some(ctx) = gpu_for_tests("render_entry_point_matches_the_training_render_bit_for_bit") else {
        return;
    };
    for ctx in with_each_kernel(&ctx) {
        check_render_matches_training(&ctx, &Batch::random(config(3, 5, 5, 7, 300, true), 11));
        let widths = default_widths(130, true);
        check_render_matches_training(&ctx, &Batch::random(widths, 12));
    }
}

#[test]
fn uniform_block_matches_wgsl_size() {
    assert_eq!(size_of::<CompositeUniforms>(), 80);
}

#[test]
fn composite_matches_reference_on_small_shapes() {
    let Some(ctx) = gpu_for_tests("composite_matches_reference_on_small_shapes") else {
        return;
    };
    for ctx in with_each_kernel(&ctx) {
        // 300 rays: not a multiple of the 64-ray workgroup; S = 12, C = 3, D = 5.
        check_batch(&ctx, &Batch::random(config(3, 5, 5, 7, 300, true), 11));
    }
}

#[test]
fn composite_matches_reference_with_default_widths() {
    let Some(ctx) = gpu_for_tests("composite_matches_reference_with_default_widths") else {
        return;
    };
    for ctx in with_each_kernel(&ctx) {
        // The default model's C, D and S (16 + 48), feature supervision on and off.
        let on = default_widths(130, true);
        check_batch(&ctx, &Batch::random(on, 12));
        let off = default_widths(70, false);
        check_batch(&ctx, &Batch::random(off, 13));
    }
}

/// Labelled rays that end in an opaque sample are pulled through the box (labelled with the far
/// class) or into it (any other class): the term's loss in the semantic word and its gradient
/// through every sample's density, against the reference, in both kernels.
#[test]
fn composite_matches_reference_with_the_opacity_term() {
    let Some(ctx) = gpu_for_tests("composite_matches_reference_with_the_opacity_term") else {
        return;
    };
    let plain = Batch::random_thin(config(3, 5, 5, 7, 300, true), 16);
    let semantic = |batch: &Batch| -> f64 { (0..300).map(|ray| reference_ray(batch, ray).losses[2]).sum() };
    for far_class in [0, 2] {
        let batch = Batch {
            far_class: Some(far_class),
            ..Batch::random_thin(config(3, 5, 5, 7, 300, true), 16)
        };
        // The term is there: thin rays leave much of their light to the opaque sample.
        assert!(semantic(&batch) > semantic(&plain) * 1.05, "far class {far_class}");
        for ctx in with_each_kernel(&ctx) {
            check_batch(&ctx, &batch);
        }
    }
}

#[test]
fn composite_matches_reference_over_several_chunks_of_samples() {
    let Some(ctx) = gpu_for_tests("composite_matches_reference_over_several_chunks_of_samples") else {
        return;
    };
    // S = 129: the workgroup kernel stages samples 64 at a time, so two full chunks and one of a
    // single sample, each walked back to front in turn, with the light reaching all of them.
    for ctx in with_each_kernel(&ctx) {
        check_batch(&ctx, &Batch::random_thin(config(4, 6, 33, 96, 70, true), 14));
        check_render_matches_training(&ctx, &Batch::random_thin(config(4, 6, 33, 96, 70, true), 15));
    }
}

#[test]
fn composite_rejects_head_sources_too_small() {
    let Some(ctx) = gpu_for_tests("composite_rejects_head_sources_too_small") else {
        return;
    };
    let batch = Batch::random(config(3, 5, 5, 7, 10, true), 1);
    let step = uniform_buffer_from(&ctx, "step", &StepUniforms::for_step(&batch.cfg, 1, 0, 1e-3));
    let small = storage_buffer_from(&ctx, "small", &[0.0f32; 16]).unwrap();
    let inputs = CompositeInputs {
        step_uniforms: &step,
        h0: RowView::new(&small, 1, 0),
        color: RowView::new(&small, 3, 0),
        logits: RowView::new(&small, 3, 0),
        feature: RowView::new(&small, 5, 0),
        intervals: &small,
        targets: &small,
        slot: &small,
    };
    let error = pollster::block_on(CompositePass::new(&ctx, &batch.cfg, &inputs))
        .err()
        .expect("must fail");
    assert!(error.to_string().contains("head source"), "{error}");
}

/// Measurement, not a check: `cargo test --release --test gpu_field_composite -- --ignored --nocapture`.
#[test]
#[ignore = "measurement; run explicitly in release mode"]
fn composite_throughput_report() {
    let Some(ctx) = gpu_for_tests("composite_throughput_report") else {
        return;
    };
    let cfg = default_widths(4096, true);
    let batch = Batch::random(cfg.clone(), 5);
    let step = uniform_buffer_from(&ctx, "step", &StepUniforms::for_step(&cfg, 1, 0, 1e-3));
    let density = storage_buffer_from(&ctx, "density out", &batch.density).unwrap();
    let color = storage_buffer_from(&ctx, "colour out", &batch.color).unwrap();
    let heads = storage_buffer_from(&ctx, "logits and feature", &batch.logits_and_feature).unwrap();
    let intervals = storage_buffer_from(&ctx, "intervals", &batch.intervals).unwrap();
    let targets = storage_buffer_from(&ctx, "targets", &batch.targets).unwrap();
    let slot = storage_buffer_from(&ctx, "slot", &batch.slot).unwrap();
    let hs = batch.heads_stride() as u32;
    let inputs = CompositeInputs {
        step_uniforms: &step,
        h0: RowView::new(&density, DENSITY_STRIDE, 0),
        color: RowView::new(&color, 3, 0),
        logits: RowView::new(&heads, hs, 0),
        feature: RowView::new(&heads, hs, cfg.num_classes),
        intervals: &intervals,
        targets: &targets,
        slot: &slot,
    };
    for ctx in with_each_kernel(&ctx) {
        report_throughput(&ctx, &cfg, &inputs);
    }
}

fn report_throughput(ctx: &GpuContext, cfg: &FieldConfig, inputs: &CompositeInputs<'_>) {
    let pass = pollster::block_on(CompositePass::new(ctx, cfg, inputs)).unwrap();
    // The training entry point and the render one (forward alone), on the same inputs.
    let run = |repeats: u32, render: bool| {
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        {
            let mut compute = encoder.begin_compute_pass(&Default::default());
            for _ in 0..repeats {
                if render {
                    pass.record_render(&mut compute);
                } else {
                    pass.record(&mut compute);
                }
            }
        }
        ctx.queue.submit([encoder.finish()]);
        ctx.wait_idle().unwrap();
    };
    for (name, render) in [("composite", false), ("composite_render", true)] {
        run(1, render);
        let repeats = 10;
        let start = Instant::now();
        run(repeats, render);
        let seconds = start.elapsed().as_secs_f64();
        let rays = f64::from(repeats * cfg.batch_rays);
        println!(
            "{name}, {:?} (B = {}, S = {}, C = {}, D = {}) on {}: {:.0} rays/s, {:.0} samples/s",
            pass.kernel,
            cfg.batch_rays,
            cfg.samples_per_ray(),
            cfg.num_classes,
            cfg.feature_dim,
            ctx.describe(),
            rays / seconds,
            rays * cfg.samples_per_ray() as f64 / seconds
        );
    }
}
