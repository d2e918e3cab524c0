//! Buffers, readback and large 1D dispatches on a real adapter (lavapipe on CPU-only machines).
use scribblefield::gpu::GpuError;
use scribblefield::gpu::buffers::{
    GARBAGE_WORDS, fill_with_garbage, garbage_words, read_buffer_async, read_buffer_blocking, read_elements_async,
    storage_buffer_from, storage_buffer_garbage, storage_buffer_zeroed, uniform_buffer_from,
};
use scribblefield::gpu::dispatch::{bind_named, whole};
use scribblefield::gpu::pipeline::{Dispatch1d, KernelSpec, create_compute_pipeline, run_1d};
use scribblefield::gpu::shaders;
use scribblefield::gpu::test_support::gpu_for_tests;

#[test]
fn f32_buffer_round_trips_exactly() {
    let Some(ctx) = gpu_for_tests("f32_buffer_round_trips_exactly") else {
        return;
    };
    let data: Vec<f32> = (0..1001)
        .map(|i| (i as f32 * 0.37).sin() * 1e3 + f32::EPSILON * i as f32)
        .collect();
    let buffer = storage_buffer_from(&ctx, "round trip", &data).unwrap();
    let back: Vec<f32> = read_buffer_blocking(&ctx, &buffer).unwrap();
    assert_eq!(back.len(), data.len());
    assert!(back.iter().zip(&data).all(|(a, b)| a.to_bits() == b.to_bits()));
}

#[test]
fn unaligned_element_ranges_read_the_right_elements() {
    let Some(ctx) = gpu_for_tests("unaligned_element_ranges_read_the_right_elements") else {
        return;
    };
    // 11 u16s = 22 bytes: padded on the GPU, and 3..8 starts and ends off the 4-byte grid.
    let data: Vec<u16> = (0..11).map(|i| 1000 + i * 7).collect();
    let buffer = storage_buffer_from(&ctx, "u16s", &data).unwrap();
    let middle: Vec<u16> = pollster::block_on(read_elements_async(&ctx, &buffer, 3..8)).unwrap();
    assert_eq!(middle, data[3..8]);
    let last: Vec<u16> = pollster::block_on(read_elements_async(&ctx, &buffer, 10..11)).unwrap();
    assert_eq!(last, [data[10]]);
    let none: Vec<u16> = pollster::block_on(read_elements_async(&ctx, &buffer, 5..5)).unwrap();
    assert!(none.is_empty());
}

#[test]
fn reading_past_the_end_is_an_error_not_a_panic() {
    let Some(ctx) = gpu_for_tests("reading_past_the_end_is_an_error_not_a_panic") else {
        return;
    };
    let buffer = storage_buffer_zeroed::<f32>(&ctx, "small", 4).unwrap();
    let result = pollster::block_on(read_elements_async::<f32>(&ctx, &buffer, 2..9));
    assert!(matches!(result, Err(GpuError::Readback { .. })), "{result:?}");
}

#[test]
fn garbage_and_zeroed_buffers_hold_what_they_promise() {
    let Some(ctx) = gpu_for_tests("garbage_and_zeroed_buffers_hold_what_they_promise") else {
        return;
    };
    let zeroed: Vec<u32> =
        read_buffer_blocking(&ctx, &storage_buffer_zeroed::<u32>(&ctx, "zeros", 37).unwrap()).unwrap();
    assert_eq!(zeroed, vec![0u32; 37]);

    let garbage: Vec<u32> =
        read_buffer_blocking(&ctx, &storage_buffer_garbage::<f32>(&ctx, "garbage", 37).unwrap()).unwrap();
    assert_eq!(garbage, garbage_words(37));
    let as_floats: Vec<f32> = garbage.iter().map(|&w| f32::from_bits(w)).collect();
    assert!(
        as_floats.iter().all(|v| !v.is_finite() || v.abs() > 1e18),
        "{as_floats:?}"
    );

    // Refilling a used buffer restores the pattern.
    let reused = storage_buffer_from(&ctx, "reused", &[1.0f32; 9]).unwrap();
    fill_with_garbage(&ctx, &reused);
    let refilled: Vec<u32> = read_buffer_blocking(&ctx, &reused).unwrap();
    assert_eq!(refilled, garbage_words(9));
    assert_eq!(refilled[..4], GARBAGE_WORDS);
}

#[test]
fn try_take_delivers_once_without_blocking() {
    let Some(ctx) = gpu_for_tests("try_take_delivers_once_without_blocking") else {
        return;
    };
    let buffer = storage_buffer_from(&ctx, "loss", &[0.25f32, 0.5]).unwrap();
    let mut pending = read_elements_async::<f32>(&ctx, &buffer, 1..2);
    let started = std::time::Instant::now();
    let value = loop {
        if let Some(result) = pending.try_take() {
            break result.unwrap();
        }
        assert!(started.elapsed().as_secs() < 60, "readback never arrived");
        std::thread::sleep(std::time::Duration::from_millis(1));
    };
    assert_eq!(value, [0.5]);
    assert!(matches!(pending.try_take(), Some(Err(GpuError::Readback { .. }))));
}

#[test]
fn async_read_sees_work_submitted_before_it() {
    let Some(ctx) = gpu_for_tests("async_read_sees_work_submitted_before_it") else {
        return;
    };
    let buffer = storage_buffer_from(&ctx, "overwritten", &[1u32, 2, 3]).unwrap();
    ctx.queue.write_buffer(&buffer, 4, bytemuck::cast_slice(&[20u32]));
    let uniform = uniform_buffer_from(&ctx, "unused uniform", &[7u32, 0, 0, 0]);
    assert_eq!(uniform.size(), 16);
    let back: Vec<u32> = pollster::block_on(read_buffer_async(&ctx, &buffer)).unwrap();
    assert_eq!(back, [1, 20, 3]);
}

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct IotaParams {
    count: u32,
    _pad: [u32; 3],
}

#[test]
fn dispatch_beyond_65535_workgroups_reaches_every_item_once() {
    let Some(ctx) = gpu_for_tests("dispatch_beyond_65535_workgroups_reaches_every_item_once") else {
        return;
    };
    const WORKGROUP_SIZE: u32 = 64; // iota.wgsl's WORKGROUP_SIZE
    let max = ctx.limits.max_compute_workgroups_per_dimension;
    let count = u64::from(max) * u64::from(WORKGROUP_SIZE) + 12_345;
    let dispatch = Dispatch1d::for_device(&ctx, count, WORKGROUP_SIZE).unwrap();
    assert!(dispatch.y > 1, "{dispatch:?} should need a second dimension");

    let iota = KernelSpec::new("iota", shaders::IOTA, "iota");
    let pipeline = pollster::block_on(create_compute_pipeline(&ctx, &iota)).unwrap();
    // Room past the end: items the overshooting workgroups must not touch.
    let slack = 1000;
    let out = storage_buffer_garbage::<u32>(&ctx, "iota out", count as usize + slack).unwrap();
    let params = uniform_buffer_from(
        &ctx,
        "iota params",
        &IotaParams {
            count: count as u32,
            _pad: [0; 3],
        },
    );
    let bindings = whole(&[("params", &params), ("out", &out)]);
    let bind_group = bind_named(&ctx, &iota, &pipeline.get_bind_group_layout(0), 0, &bindings).unwrap();
    run_1d(&ctx, "iota", &pipeline, &bind_group, dispatch);

    let values: Vec<u32> = read_buffer_blocking(&ctx, &out).unwrap();
    let wrong = (0..count as usize).find(|&i| values[i] != i as u32);
    assert_eq!(wrong, None, "first wrong item (value {:?})", wrong.map(|i| values[i]));
    assert_eq!(
        values[count as usize..],
        garbage_words(count as usize + slack)[count as usize..]
    );
}

#[test]
fn bindings_are_given_by_their_wgsl_names_and_checked() {
    let Some(ctx) = gpu_for_tests("bindings_are_given_by_their_wgsl_names_and_checked") else {
        return;
    };
    let iota = KernelSpec::new("iota", shaders::IOTA, "iota");
    let pipeline = pollster::block_on(create_compute_pipeline(&ctx, &iota)).unwrap();
    let layout = pipeline.get_bind_group_layout(0);
    let out = storage_buffer_garbage::<u32>(&ctx, "iota out", 4).unwrap();
    let params = uniform_buffer_from(&ctx, "iota params", &IotaParams { count: 4, _pad: [0; 3] });
    let bind = |bindings: &[(&str, &wgpu::Buffer)]| bind_named(&ctx, &iota, &layout, 0, &whole(bindings));
    assert!(bind(&[("out", &out), ("params", &params)]).is_ok(), "any order");
    let e = bind(&[("params", &params), ("output", &out)]).unwrap_err().to_string();
    assert!(
        e.contains("`output` is not a binding it uses") && e.contains("\"out\""),
        "{e}"
    );
    let e = bind(&[("params", &params)]).unwrap_err().to_string();
    assert!(e.contains("`out` (@binding(1)) is not given"), "{e}");
    let e = bind(&[("params", &params), ("out", &out), ("out", &out)])
        .unwrap_err()
        .to_string();
    assert!(e.contains("`out` is given twice"), "{e}");
}
