//! Throughput of the plain tiled matmul on the current device: the reference the `bench` command
//! divides the trainer's throughput by, so figures from different devices compare as ratios.
use super::buffers::read_elements_async;
use super::context::GpuContext;
use super::error::GpuError;
use super::matmul::{MatmulDims, MatmulJob, MatmulKernel};
use super::timing::{PassTimer, Stopwatch};

/// How the time of a benchmark was taken.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TimingSource {
    /// Timestamp queries around the timed pass: GPU time only.
    GpuTimestamps,
    /// Wall clock around submit and a one-element readback: includes submission and sync latency.
    WallClock,
}

#[derive(Debug, Clone, PartialEq)]
pub struct MatmulBenchReport {
    pub n: u32,
    pub iterations: u32,
    pub seconds: f64,
    pub gflops: f64,
    pub timed_by: TimingSource,
}

/// GFLOP/s of `iterations` n x n x n products (see [`matmul_bench`]).
pub async fn matmul_gflops(ctx: &GpuContext, n: u32, iterations: u32) -> Result<f64, GpuError> {
    Ok(matmul_bench(ctx, n, iterations).await?.gflops)
}

/// Times `iterations` n x n x n products recorded back to back in one pass, after one untimed
/// warm-up product (pipeline compilation and first-touch costs stay out of the figure).
pub async fn matmul_bench(ctx: &GpuContext, n: u32, iterations: u32) -> Result<MatmulBenchReport, GpuError> {
    if n == 0 || iterations == 0 {
        return Err(GpuError::invalid_argument(
            "matmul bench",
            format!("n = {n} and iterations = {iterations} must be positive"),
        ));
    }
    let dims = MatmulDims::square(n);
    let kernel = MatmulKernel::new(ctx).await?;
    let a = pseudo_random_matrix(n as usize * n as usize, 1);
    let b = pseudo_random_matrix(n as usize * n as usize, 2);
    let job = kernel.prepare(ctx, &a, &b, dims)?;

    run_products(ctx, &kernel, &job, 1, None);
    read_elements_async::<f32>(ctx, &job.c, 0..1).await?;

    let mut timer = PassTimer::new(ctx, 1);
    let stopwatch = Stopwatch::start();
    run_products(ctx, &kernel, &job, iterations, timer.as_mut());
    read_elements_async::<f32>(ctx, &job.c, 0..1).await?;
    let wall_seconds = stopwatch.elapsed_seconds();

    let (seconds, timed_by) = match timer.as_mut() {
        Some(timer) => {
            let times = timer.read(ctx).times().await?;
            match times.first() {
                Some(time) if time.seconds > 0.0 => (time.seconds, TimingSource::GpuTimestamps),
                _ => (wall_seconds, TimingSource::WallClock),
            }
        }
        None => (wall_seconds, TimingSource::WallClock),
    };
    let gflops = dims.flops() * f64::from(iterations) / seconds / 1e9;
    Ok(MatmulBenchReport {
        n,
        iterations,
        seconds,
        gflops,
        timed_by,
    })
}

fn run_products(ctx: &GpuContext, kernel: &MatmulKernel, job: &MatmulJob, repeats: u32, timer: Option<&mut PassTimer>) {
    let mut timer = timer;
    let mut encoder = ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
        label: Some("matmul bench"),
    });
    {
        let timestamp_writes = timer.as_mut().and_then(|timer| timer.timestamp_writes("matmul"));
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("matmul bench"),
            timestamp_writes,
        });
        kernel.record(&mut pass, job, repeats);
    }
    if let Some(timer) = timer {
        timer.resolve(&mut encoder);
    }
    ctx.queue.submit([encoder.finish()]);
}

/// Values in [-1, 1) from a fixed linear congruential sequence: reproducible without a
/// random-number dependency.
fn pseudo_random_matrix(len: usize, seed: u64) -> Vec<f32> {
    let mut state = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
    (0..len)
        .map(|_| {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            ((state >> 40) as f32 / (1u64 << 24) as f32) * 2.0 - 1.0
        })
        .collect()
}
