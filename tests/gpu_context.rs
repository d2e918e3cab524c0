//! Device creation: the adapter's own limits, wrapping an existing device, clear errors.
use scribblefield::gpu::pipeline::Dispatch1d;
use scribblefield::gpu::test_support::gpu_for_tests;
use scribblefield::gpu::{GpuContext, GpuError, GpuOptions};

#[test]
fn device_gets_the_adapters_own_limits() {
    let Some(ctx) = gpu_for_tests("device_gets_the_adapters_own_limits") else {
        return;
    };
    let instance = wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
    let adapters = pollster::block_on(instance.enumerate_adapters(wgpu::Backends::all()));
    let adapter = adapters
        .iter()
        .find(|a| a.get_info().name == ctx.adapter_info.name)
        .unwrap();
    let offered = adapter.limits();
    assert_eq!(
        ctx.limits.max_storage_buffer_binding_size,
        offered.max_storage_buffer_binding_size
    );
    assert_eq!(
        ctx.limits.max_storage_buffers_per_shader_stage,
        offered.max_storage_buffers_per_shader_stage
    );
    assert_eq!(
        ctx.limits.max_compute_workgroup_storage_size,
        offered.max_compute_workgroup_storage_size
    );
    assert_eq!(
        ctx.has_timestamps,
        adapter.features().contains(wgpu::Features::TIMESTAMP_QUERY)
    );
    eprintln!("shortfalls below WebGPU defaults: {:?}", ctx.compute_limit_shortfalls());
}

#[test]
fn wrapping_an_existing_device_sees_the_same_device() {
    let Some(ctx) = gpu_for_tests("wrapping_an_existing_device_sees_the_same_device") else {
        return;
    };
    let wrapped = GpuContext::from_device(ctx.device.clone(), ctx.queue.clone());
    assert_eq!(wrapped.adapter_info.name, ctx.adapter_info.name);
    assert_eq!(wrapped.limits, ctx.limits);
    assert_eq!(wrapped.features, ctx.features);
    assert_eq!(wrapped.has_timestamps, ctx.has_timestamps);
}

#[test]
fn limit_checks_name_the_limit() {
    let Some(ctx) = gpu_for_tests("limit_checks_name_the_limit") else {
        return;
    };
    let too_big = ctx.limits.max_storage_buffer_binding_size + 4;
    let error = ctx.ensure_storage_binding_fits("hash table", too_big).unwrap_err();
    assert!(matches!(
        error,
        GpuError::LimitExceeded {
            limit: "max_storage_buffer_binding_size",
            ..
        }
    ));
    assert!(error.to_string().contains("hash table"), "{error}");
    ctx.ensure_storage_binding_fits("small", 1024).unwrap();
    assert!(ctx.ensure_workgroup_storage_fits("tiles", u64::from(u32::MAX)).is_err());
    // A real GPU's limit can be any size (NVIDIA's Vulkan driver: past 1000); test one over it.
    let storage_buffers = ctx.limits.max_storage_buffers_per_shader_stage;
    if let Some(over) = storage_buffers.checked_add(1) {
        let error = ctx.ensure_storage_buffer_count_fits("kernel", over).unwrap_err();
        assert!(
            error.to_string().contains("max_storage_buffers_per_shader_stage"),
            "{error}"
        );
    }
    ctx.ensure_storage_buffer_count_fits("kernel", storage_buffers).unwrap();
    ctx.ensure_storage_buffer_count_fits("kernel", 4).unwrap();
}

#[test]
fn a_missing_adapter_is_a_clear_error() {
    let options = GpuOptions {
        adapter_name: Some("no adapter is called this".into()),
        ..GpuOptions::default()
    };
    let error = GpuContext::new_blocking(&options).unwrap_err();
    assert!(matches!(error, GpuError::NoAdapter { .. }), "{error}");
    if cfg!(target_os = "linux") {
        assert!(error.to_string().contains("mesa-vulkan-drivers"), "{error}");
    }
}

#[test]
fn dispatch_1d_spreads_over_two_dimensions_only_when_needed() {
    assert_eq!(Dispatch1d::new(0, 64, 65535).unwrap(), Dispatch1d { x: 0, y: 1 });
    assert_eq!(Dispatch1d::new(1, 64, 65535).unwrap(), Dispatch1d { x: 1, y: 1 });
    assert_eq!(
        Dispatch1d::new(64 * 65535, 64, 65535).unwrap(),
        Dispatch1d { x: 65535, y: 1 }
    );
    let split = Dispatch1d::new(64 * 65535 + 1, 64, 65535).unwrap();
    assert_eq!(split.y, 2);
    assert!(split.workgroups() >= 65536 && split.workgroups() - 65536 < u64::from(split.y));
    // Overshoot stays under one row for awkward sizes too.
    for items in [1_000_003u64, 77_777_777, 4_000_000_000] {
        let d = Dispatch1d::new(items, 256, 65535).unwrap();
        let needed = items.div_ceil(256);
        assert!(d.x <= 65535 && d.y <= 65535 && d.workgroups() >= needed && d.workgroups() - needed < u64::from(d.y));
    }
    assert!(Dispatch1d::new(u64::MAX / 2, 1, 65535).is_err());
    assert!(Dispatch1d::new(10, 0, 65535).is_err());
}

#[test]
fn pipelines_are_compiled_once_per_device() {
    use scribblefield::gpu::pipeline::{KernelSpec, create_compute_pipeline};
    use scribblefield::gpu::shaders;
    let Some(ctx) = gpu_for_tests("pipelines_are_compiled_once_per_device") else {
        return;
    };
    let spec = KernelSpec::new("iota", shaders::IOTA, "iota");
    let first = pollster::block_on(create_compute_pipeline(&ctx, &spec)).unwrap();
    // A clone of the context (what a second trainer gets) shares the cache.
    let again = pollster::block_on(create_compute_pipeline(&ctx.clone(), &spec)).unwrap();
    assert_eq!(first, again);
    let stats = ctx.pipeline_cache_stats();
    assert_eq!((stats.compiled, stats.reused), (1, 1), "{stats:?}");
    // Another context, even on the same device, has a cache of its own.
    let other = GpuContext::from_device(ctx.device.clone(), ctx.queue.clone());
    pollster::block_on(create_compute_pipeline(&other, &spec)).unwrap();
    assert_eq!(other.pipeline_cache_stats().compiled, 1);
    assert_eq!(ctx.pipeline_cache_stats().compiled, 1);
}
