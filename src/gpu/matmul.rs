//! The plain tiled f32 matmul of `shaders/matmul.wgsl` and its CPU twin. It is the yardstick of
//! what a device can do (see `matmul_bench`), not part of the trainer.
use super::buffers::{read_buffer_async, storage_buffer_from, storage_buffer_garbage, uniform_buffer_from};
use super::context::GpuContext;
use super::dispatch::{bind_named, whole};
use super::error::GpuError;
use super::pipeline::{KernelSpec, create_compute_pipeline};
use super::shaders;

/// Side of the square tile of C one workgroup of `matmul.wgsl` computes (its `OUTPUT_TILE`).
pub const OUTPUT_TILE: u32 = 64;
/// Depth of the slices of A and B it stages in workgroup memory (its `K_SLICE`).
const K_SLICE: u32 = 16;

/// C (m x n) = A (m x k) * B (k x n), row-major.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MatmulDims {
    pub m: u32,
    pub n: u32,
    pub k: u32,
}

impl MatmulDims {
    pub fn square(n: u32) -> Self {
        MatmulDims { m: n, n, k: n }
    }

    /// Floating-point operations of one product (a multiply and an add per term).
    pub fn flops(&self) -> f64 {
        2.0 * f64::from(self.m) * f64::from(self.n) * f64::from(self.k)
    }

    fn element_counts(&self) -> (usize, usize, usize) {
        let (m, n, k) = (self.m as usize, self.n as usize, self.k as usize);
        (m * k, k * n, m * n)
    }
}

/// Uniform block matching `Dims` in matmul.wgsl (padded to 16 bytes).
#[repr(C)]
#[derive(Debug, Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct DimsUniform {
    m: u32,
    n: u32,
    k: u32,
    _pad: u32,
}

/// CPU twin of the kernel, accumulating in f64 so it is the more accurate of the two.
pub fn matmul_reference(a: &[f32], b: &[f32], dims: MatmulDims) -> Vec<f32> {
    let (m, n, k) = (dims.m as usize, dims.n as usize, dims.k as usize);
    let mut c = vec![0.0f32; m * n];
    for row in 0..m {
        for col in 0..n {
            let sum: f64 = (0..k)
                .map(|i| f64::from(a[row * k + i]) * f64::from(b[i * n + col]))
                .sum();
            c[row * n + col] = sum as f32;
        }
    }
    c
}

const MATMUL_KERNEL: KernelSpec<'static> = KernelSpec {
    label: "matmul",
    source: shaders::MATMUL,
    entry_point: "matmul",
    layout: None,
    constants: &[],
};

/// The compiled kernel, reusable across products.
pub struct MatmulKernel {
    pipeline: wgpu::ComputePipeline,
    layout: wgpu::BindGroupLayout,
}

/// The buffers of one product, bound and ready to dispatch.
pub struct MatmulJob {
    pub dims: MatmulDims,
    pub c: wgpu::Buffer,
    bind_group: wgpu::BindGroup,
}

impl MatmulKernel {
    pub async fn new(ctx: &GpuContext) -> Result<Self, GpuError> {
        ctx.ensure_workgroup_storage_fits("matmul tiles", 2 * u64::from(OUTPUT_TILE * K_SLICE) * 4)?;
        let pipeline = create_compute_pipeline(ctx, &MATMUL_KERNEL).await?;
        let layout = pipeline.get_bind_group_layout(0);
        Ok(MatmulKernel { pipeline, layout })
    }

    /// Uploads A and B and makes a garbage-filled C (so an element the kernel misses shows up).
    pub fn prepare(&self, ctx: &GpuContext, a: &[f32], b: &[f32], dims: MatmulDims) -> Result<MatmulJob, GpuError> {
        let (a_len, b_len, c_len) = dims.element_counts();
        if dims.m == 0 || dims.n == 0 || dims.k == 0 {
            return Err(GpuError::invalid_argument(
                "matmul",
                format!("dimensions {dims:?} must be positive"),
            ));
        }
        if a.len() != a_len || b.len() != b_len {
            return Err(GpuError::invalid_argument(
                "matmul",
                format!(
                    "{dims:?} needs A of {a_len} and B of {b_len} elements, got {} and {}",
                    a.len(),
                    b.len()
                ),
            ));
        }
        let max_groups = ctx.limits.max_compute_workgroups_per_dimension;
        let groups = dims.m.div_ceil(OUTPUT_TILE).max(dims.n.div_ceil(OUTPUT_TILE));
        if groups > max_groups {
            return Err(GpuError::LimitExceeded {
                what: format!("matmul {dims:?}"),
                limit: "max_compute_workgroups_per_dimension",
                needed: groups.into(),
                allowed: max_groups.into(),
            });
        }
        let a = storage_buffer_from(ctx, "matmul A", a)?;
        let b = storage_buffer_from(ctx, "matmul B", b)?;
        let c = storage_buffer_garbage::<f32>(ctx, "matmul C", c_len)?;
        let uniform = uniform_buffer_from(
            ctx,
            "matmul dims",
            &DimsUniform {
                m: dims.m,
                n: dims.n,
                k: dims.k,
                _pad: 0,
            },
        );
        let bindings = whole(&[("dims", &uniform), ("a", &a), ("b", &b), ("c", &c)]);
        let bind_group = bind_named(ctx, &MATMUL_KERNEL, &self.layout, 0, &bindings)?;
        Ok(MatmulJob { dims, c, bind_group })
    }

    /// Records `repeats` products of `job` into one pass.
    pub fn record(&self, pass: &mut wgpu::ComputePass<'_>, job: &MatmulJob, repeats: u32) {
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, &job.bind_group, &[]);
        for _ in 0..repeats {
            pass.dispatch_workgroups(job.dims.n.div_ceil(OUTPUT_TILE), job.dims.m.div_ceil(OUTPUT_TILE), 1);
            super::pipeline::count_dispatch();
        }
    }

    /// One product, start to finish: C = A * B read back to the CPU.
    pub async fn multiply(
        &self,
        ctx: &GpuContext,
        a: &[f32],
        b: &[f32],
        dims: MatmulDims,
    ) -> Result<Vec<f32>, GpuError> {
        let job = self.prepare(ctx, a, b, dims)?;
        let mut encoder = ctx
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("matmul") });
        {
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("matmul"),
                timestamp_writes: None,
            });
            self.record(&mut pass, &job, 1);
        }
        ctx.queue.submit([encoder.finish()]);
        let mut c: Vec<f32> = read_buffer_async(ctx, &job.c).await?;
        c.truncate(dims.element_counts().2);
        Ok(c)
    }
}
