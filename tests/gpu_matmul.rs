//! The tiled matmul against its CPU twin, pass timing, and the throughput bench.
use scribblefield::gpu::matmul::{MatmulDims, MatmulKernel, matmul_reference};
use scribblefield::gpu::matmul_bench::{TimingSource, matmul_bench};
use scribblefield::gpu::test_support::gpu_for_tests;
use scribblefield::gpu::timing::PassTimer;

fn test_matrix(len: usize, salt: f32) -> Vec<f32> {
    (0..len)
        .map(|i| ((i as f32 * 0.618 + salt).fract() - 0.5) * 4.0)
        .collect()
}

/// The GPU sums in f32 in tile order, the twin in f64: they agree to f32 rounding of k terms.
fn assert_close(gpu: &[f32], cpu: &[f32], dims: MatmulDims) {
    assert_eq!(gpu.len(), cpu.len(), "{dims:?}");
    let tolerance = 1e-5 * dims.k as f32 * 4.0;
    for (index, (g, c)) in gpu.iter().zip(cpu).enumerate() {
        assert!(
            (g - c).abs() <= tolerance * c.abs().max(1.0),
            "{dims:?}: C[{}][{}] is {g} on the GPU, {c} on the CPU",
            index / dims.n as usize,
            index % dims.n as usize
        );
    }
}

#[test]
fn matmul_matches_cpu_twin_on_odd_sizes() {
    let Some(ctx) = gpu_for_tests("matmul_matches_cpu_twin_on_odd_sizes") else {
        return;
    };
    let kernel = pollster::block_on(MatmulKernel::new(&ctx)).unwrap();
    let sizes = [
        MatmulDims { m: 37, n: 29, k: 53 },
        MatmulDims { m: 1, n: 1, k: 1 },
        MatmulDims { m: 16, n: 16, k: 16 },
        MatmulDims { m: 17, n: 33, k: 1 },
        MatmulDims { m: 5, n: 70, k: 300 },
        MatmulDims { m: 130, n: 67, k: 33 },
    ];
    for dims in sizes {
        let a = test_matrix((dims.m * dims.k) as usize, 0.1);
        let b = test_matrix((dims.k * dims.n) as usize, 0.7);
        // `multiply` writes into a garbage-filled C, so a missed element fails the comparison.
        let gpu = pollster::block_on(kernel.multiply(&ctx, &a, &b, dims)).unwrap();
        assert_close(&gpu, &matmul_reference(&a, &b, dims), dims);
    }
}

#[test]
fn matmul_rejects_mismatched_inputs() {
    let Some(ctx) = gpu_for_tests("matmul_rejects_mismatched_inputs") else {
        return;
    };
    let kernel = pollster::block_on(MatmulKernel::new(&ctx)).unwrap();
    let dims = MatmulDims { m: 3, n: 4, k: 5 };
    assert!(kernel.prepare(&ctx, &[0.0; 15], &[0.0; 19], dims).is_err());
    assert!(kernel.prepare(&ctx, &[], &[], MatmulDims { m: 0, n: 4, k: 0 }).is_err());
}

#[test]
fn pass_timer_measures_a_pass_when_timestamps_exist() {
    let Some(ctx) = gpu_for_tests("pass_timer_measures_a_pass_when_timestamps_exist") else {
        return;
    };
    let Some(mut timer) = PassTimer::new(&ctx, 2) else {
        assert!(!ctx.has_timestamps);
        eprintln!(
            "{}: no timestamp queries; PassTimer is None as it should be",
            ctx.describe()
        );
        return;
    };
    let kernel = pollster::block_on(MatmulKernel::new(&ctx)).unwrap();
    let dims = MatmulDims::square(64);
    let job = kernel
        .prepare(&ctx, &test_matrix(64 * 64, 0.2), &test_matrix(64 * 64, 0.3), dims)
        .unwrap();
    let mut encoder = ctx.device.create_command_encoder(&Default::default());
    for name in ["first", "second", "beyond capacity"] {
        let timestamp_writes = timer.timestamp_writes(name);
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: None,
            timestamp_writes,
        });
        kernel.record(&mut pass, &job, 3);
    }
    assert_eq!(timer.untimed_passes(), 1);
    timer.resolve(&mut encoder);
    ctx.queue.submit([encoder.finish()]);
    let times = pollster::block_on(timer.read(&ctx).times()).unwrap();
    let names: Vec<&str> = times.iter().map(|t| t.name.as_str()).collect();
    assert_eq!(names, ["first", "second"]);
    for time in &times {
        assert!(time.seconds > 0.0 && time.seconds < 60.0, "{time:?}");
    }
}

#[test]
fn matmul_bench_reports_a_plausible_rate() {
    let Some(ctx) = gpu_for_tests("matmul_bench_reports_a_plausible_rate") else {
        return;
    };
    let report = pollster::block_on(matmul_bench(&ctx, 64, 2)).unwrap();
    assert!(report.gflops.is_finite() && report.gflops > 0.0, "{report:?}");
    assert_eq!(
        report.timed_by == TimingSource::GpuTimestamps,
        ctx.has_timestamps,
        "{report:?}"
    );
}

/// Measurement, not a check: `cargo test --release --test gpu_matmul -- --ignored --nocapture`.
#[test]
#[ignore = "measurement; run explicitly in release mode"]
fn matmul_throughput_report() {
    let Some(ctx) = gpu_for_tests("matmul_throughput_report") else {
        return;
    };
    let limits = &ctx.limits;
    println!("adapter: {}", ctx.describe());
    println!(
        "limits: max_storage_buffer_binding_size {} B, max_buffer_size {} B, workgroup storage {} B, \
         storage buffers per stage {}, invocations per workgroup {}, workgroups per dimension {}, timestamps {}",
        limits.max_storage_buffer_binding_size,
        limits.max_buffer_size,
        limits.max_compute_workgroup_storage_size,
        limits.max_storage_buffers_per_shader_stage,
        limits.max_compute_invocations_per_workgroup,
        limits.max_compute_workgroups_per_dimension,
        ctx.has_timestamps
    );
    for shortfall in ctx.compute_limit_shortfalls() {
        println!("below WebGPU default: {shortfall}");
    }
    for (n, iterations) in [(256, 10), (512, 4), (1024, 2)] {
        let report = pollster::block_on(matmul_bench(&ctx, n, iterations)).unwrap();
        println!(
            "matmul n={n}: {:.2} GFLOP/s ({} products in {:.4} s, {:?})",
            report.gflops, report.iterations, report.seconds, report.timed_by
        );
    }
}
