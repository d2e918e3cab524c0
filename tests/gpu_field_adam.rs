//! `AdamPass` against `reference::adam` over several steps, with the step values coming from the
//! trainer's `StepUniforms` buffer rewritten between submits, also when the buffers are split
//! into segments; every step leaves the gradient buffer zeroed.
//!
//! Tolerance: the kernel does the reference's f32 operations in the same order, but a Vulkan
//! device may fuse a multiply-add and its `sqrt` and division are not correctly rounded (a few
//! ulp). Those differences are relative to the quantity computed, so after a few steps the
//! moments agree within 1e-6 relative, and a parameter within 1e-6 of max(|p|, the total step
//! length lr·steps) (a step's error is relative to the step, not to a p near zero).
use scribblefield::field::FieldConfig;
use scribblefield::field::gpu::stage::Stage;
use std::ops::Range;

use scribblefield::field::gpu::adam::{AdamBuffers, AdamPass};
use scribblefield::field::gpu::encoding::{FixedPointTable, HashGridUniforms};
use scribblefield::field::gpu::fixed_point::{from_fixed, to_fixed};
use scribblefield::field::gpu::rays::StepUniforms;
use scribblefield::field::reference::Adam;
use scribblefield::gpu::GpuContext;
use scribblefield::gpu::buffers::{
    read_buffer_blocking, storage_buffer_from, storage_buffer_zeroed, uniform_buffer_from,
};
use scribblefield::gpu::test_support::gpu_for_tests;
use scribblefield::rng::SplitMix64;

const STEPS: u32 = 5;
const RELATIVE_TOLERANCE: f32 = 1e-6;

/// `scale[i]` is the size the error of element i is relative to: the value itself, or for a sum
/// whose terms can cancel, the sum of the terms' sizes.
fn assert_close(what: &str, gpu: &[f32], reference: &[f32], scale: &[f32], floor: f32) {
    assert_eq!(gpu.len(), reference.len(), "{what}");
    for (i, (&g, &r)) in gpu.iter().zip(reference).enumerate() {
        let allowed = RELATIVE_TOLERANCE * scale[i].abs().max(floor);
        assert!(
            (g - r).abs() <= allowed,
            "{what}[{i}]: GPU {g}, reference {r}, allowed {allowed:e}"
        );
    }
}

/// Runs `STEPS` Adam steps of `count` parameters on the GPU (segments of `segment_len` when
/// given) and on the reference, with learning rates changing every step. With `fixed_table`,
/// those elements of the gradient are fixed-point integers of three hash levels (the
/// backward's `AtomicAdd::FixedPoint`), each at its own exponent, which Adam decodes.
fn check_adam(ctx: &GpuContext, count: usize, segment_len: Option<u64>, fixed_table: Option<Range<usize>>) {
    let cfg = FieldConfig::small();
    let mut rng = SplitMix64::new(count as u64);
    let mut params: Vec<f32> = (0..count).map(|_| rng.uniform(-1.0, 1.0) as f32).collect();
    // Gradients of mixed scales, including exact zeros (an untouched hash entry).
    let gradient = |rng: &mut SplitMix64| -> Vec<f32> {
        (0..count)
            .map(|i| {
                if i % 7 == 0 {
                    0.0
                } else {
                    (rng.uniform(-1.0, 1.0) * 10f64.powi((i % 5) as i32 - 3)) as f32
                }
            })
            .collect()
    };
    let params_buffer = storage_buffer_from(ctx, "params", &params).unwrap();
    let grads_buffer = storage_buffer_zeroed::<f32>(ctx, "grads", count).unwrap();
    let m_buffer = storage_buffer_zeroed::<f32>(ctx, "m", count).unwrap();
    let v_buffer = storage_buffer_zeroed::<f32>(ctx, "v", count).unwrap();
    let step_buffer = uniform_buffer_from(ctx, "step", &StepUniforms::for_step(&cfg, 1, 0, 0.0));
    // Three levels of 2 values per entry, starting at entries 0, 40 and 1000 of the table, with
    // exponents far apart (a level of tiny gradients, one of large ones).
    let exponents = [40i32, 12, -3];
    let mut grid: HashGridUniforms = bytemuck::Zeroable::zeroed();
    grid.levels = 3;
    grid.features = 2;
    for (geometry, start) in grid.level_geometry.iter_mut().zip([0, 40, 1000]) {
        geometry[2] = start;
    }
    let grid_buffer = uniform_buffer_from(ctx, "grid", &grid);
    let exponents_buffer = storage_buffer_from(ctx, "exponents", &exponents).unwrap();
    let level_of = |i: usize| -> Option<usize> {
        let table = fixed_table.as_ref()?;
        let entry = (i.checked_sub(table.start)? / 2) as u32;
        table
            .contains(&i)
            .then(|| grid.level_geometry[..3].iter().rposition(|g| entry >= g[2]).unwrap())
    };
    let buffers = AdamBuffers {
        params: &params_buffer,
        grads: &grads_buffer,
        first_moment: &m_buffer,
        second_moment: &v_buffer,
        fixed_point_table: fixed_table.clone().map(|table| FixedPointTable {
            grid: &grid_buffer,
            exponents: &exponents_buffer,
            table,
        }),
    };
    let adam_pass = match segment_len {
        None => pollster::block_on(AdamPass::new(ctx, &cfg.adam, count, buffers, &step_buffer)),
        Some(len) => pollster::block_on(AdamPass::with_segment_length(
            ctx,
            &cfg.adam,
            count,
            buffers,
            &step_buffer,
            len,
        )),
    }
    .unwrap();
    if let Some(len) = segment_len {
        assert_eq!(adam_pass.segment_count(), count.div_ceil(len as usize));
    }

    let mut reference = Adam::new(cfg.adam, count);
    let mut total_lr = 0.0f32;
    // The first moment is a sum of gradients of both signs: where they nearly cancel, m is tiny
    // and a rounding the GPU may do differently (WGSL allows fused multiply-adds; NVIDIA's
    // Vulkan driver contracts) is large against it. Its error is bounded by the terms' sizes.
    let mut m_scale = vec![0.0f32; count];
    for t in 1..=STEPS {
        let lr = 1e-2 / t as f32;
        total_lr += lr;
        let mut grads = gradient(&mut rng);
        // What the GPU reads: the table's values as integers at their level's exponent; what the
        // reference gets: those integers decoded, exactly as the kernel decodes them.
        let mut written = grads.clone();
        for i in 0..count {
            if let Some(level) = level_of(i) {
                let units = to_fixed(grads[i] * 2f32.powi(-exponents[level] / 2), exponents[level]);
                written[i] = f32::from_bits(units as u32);
                grads[i] = from_fixed(units, exponents[level]);
            }
        }
        let uniforms = StepUniforms::for_step(&cfg, t, 7, lr);
        assert_eq!((uniforms.adam_c1, uniforms.adam_c2), reference.bias_corrections(t));
        ctx.queue.write_buffer(&step_buffer, 0, bytemuck::bytes_of(&uniforms));
        ctx.queue.write_buffer(&grads_buffer, 0, bytemuck::cast_slice(&written));
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        {
            let mut pass = encoder.begin_compute_pass(&Default::default());
            adam_pass.record(&mut pass);
        }
        ctx.queue.submit([encoder.finish()]);
        reference.update(&mut params, &grads, lr);
        let beta1 = cfg.adam.beta1;
        for (scale, g) in m_scale.iter_mut().zip(&grads) {
            *scale = beta1 * *scale + (1.0 - beta1) * g.abs();
        }
    }
    let what = format!("{count} parameters, segments {segment_len:?}, fixed-point table {fixed_table:?}");
    let gpu_params: Vec<f32> = read_buffer_blocking(ctx, &params_buffer).unwrap();
    let gpu_m: Vec<f32> = read_buffer_blocking(ctx, &m_buffer).unwrap();
    let gpu_v: Vec<f32> = read_buffer_blocking(ctx, &v_buffer).unwrap();
    // Adam zeroes the gradient it consumed (the trainer needs no clear before a step).
    let gpu_grads: Vec<f32> = read_buffer_blocking(ctx, &grads_buffer).unwrap();
    assert!(
        gpu_grads.iter().all(|&g| g.to_bits() == 0),
        "{what}: gradient left after the step"
    );
    assert_close(&format!("{what}: m"), &gpu_m[..count], &reference.m, &m_scale, 0.0);
    assert_close(&format!("{what}: v"), &gpu_v[..count], &reference.v, &reference.v, 0.0);
    assert_close(
        &format!("{what}: params"),
        &gpu_params[..count],
        &params,
        &params,
        total_lr,
    );
    let moved = gpu_params.iter().zip(&params).filter(|(g, p)| g != p).count();
    eprintln!("{what}: {moved} of {count} parameters differ in some bit from the reference");
}

#[test]
fn adam_matches_the_reference_over_several_steps() {
    let Some(ctx) = gpu_for_tests("adam_matches_the_reference_over_several_steps") else {
        return;
    };
    // Not a multiple of the workgroup size; then one long enough to need a 2D dispatch when the
    // device allows only 65535 workgroups per dimension (> 65535 · 256).
    check_adam(&ctx, 100_003, None, None);
    check_adam(&ctx, 17_000_001, None, None);
}

#[test]
fn adam_in_segments_matches_the_reference() {
    let Some(ctx) = gpu_for_tests("adam_in_segments_matches_the_reference") else {
        return;
    };
    let align = u64::from(ctx.limits.min_storage_buffer_offset_alignment.max(4)) / 4;
    check_adam(&ctx, 10_001, Some(align * 13), None);
}

#[test]
fn adam_decodes_a_fixed_point_table_level_by_level() {
    let Some(ctx) = gpu_for_tests("adam_decodes_a_fixed_point_table_level_by_level") else {
        return;
    };
    // The table neither at the start nor at the end, and split across segments.
    let align = u64::from(ctx.limits.min_storage_buffer_offset_alignment.max(4)) / 4;
    check_adam(&ctx, 10_001, None, Some(37..4_037));
    check_adam(&ctx, 10_001, Some(align * 13), Some(37..4_037));
}

#[test]
fn adam_rejects_short_buffers_and_bad_segments() {
    let Some(ctx) = gpu_for_tests("adam_rejects_short_buffers_and_bad_segments") else {
        return;
    };
    let cfg = FieldConfig::small();
    let long = storage_buffer_zeroed::<f32>(&ctx, "long", 100).unwrap();
    let short = storage_buffer_zeroed::<f32>(&ctx, "short", 99).unwrap();
    let step = uniform_buffer_from(&ctx, "step", &StepUniforms::for_step(&cfg, 1, 0, 0.1));
    let buffers = AdamBuffers {
        params: &long,
        grads: &long,
        first_moment: &long,
        second_moment: &short,
        fixed_point_table: None,
    };
    assert!(pollster::block_on(AdamPass::new(&ctx, &cfg.adam, 100, buffers, &step)).is_err());
    let buffers = AdamBuffers {
        params: &long,
        grads: &short,
        first_moment: &long,
        second_moment: &long,
        fixed_point_table: None,
    };
    assert!(
        pollster::block_on(AdamPass::with_segment_length(
            &ctx,
            &cfg.adam,
            99,
            buffers.clone(),
            &step,
            0
        ))
        .is_err()
    );
    assert!(pollster::block_on(AdamPass::new(&ctx, &cfg.adam, 0, buffers, &step)).is_err());
}
