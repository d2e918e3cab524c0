//! The spherical harmonics of the view direction on the GPU (`shaders/sh_encode.wgsl`): one unit
//! direction per ray → the 16 SH values of every sample of the ray, in given columns of a
//! strided per-sample buffer. The GPU twin of `reference::sh`; tested against it in
//! `tests/gpu_field_encoding.rs`. Built once with its buffers, it only records a dispatch.
use crate::field::gpu::encoding::{
    F32_BYTES, VEC4_BYTES, WORKGROUP_SIZE, check_buffer, check_index_range, check_samples, index_u32,
};
use crate::field::gpu::rays::RAY_GEOMETRY_BYTES;
use crate::field::gpu::row_view::RowFormat;
use crate::field::gpu::stage::{Stage, StepShape};
use crate::field::reference::sh::SH_COEFFS;
use crate::gpu::buffers::uniform_buffer_from;
use crate::gpu::dispatch::{Dispatch, whole};
use crate::gpu::pipeline::{Dispatch1d, KernelSpec};
use crate::gpu::{GpuContext, GpuError, shaders};

/// Uniform block of `sh_encode.wgsl` (`ShUniforms`, field by field).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct ShUniforms {
    pub sample_count: u32,
    pub samples_per_ray: u32,
    pub row_stride: u32,
    pub column_offset: u32,
    pub direction_stride: u32,
    pub direction_offset: u32,
    pub _pad0: u32,
    pub _pad1: u32,
}

/// Where ray r's direction sits in the directions buffer: `vec4` index `r·stride + offset`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DirectionLayout {
    pub stride: usize,
    pub offset: usize,
}

impl DirectionLayout {
    /// One direction per ray, back to back.
    pub const PACKED: DirectionLayout = DirectionLayout { stride: 1, offset: 0 };
    /// The `dir` field of the ray batch's `RayGeometry` records (3 vec4s each, dir second).
    pub const RAY_GEOMETRY: DirectionLayout = DirectionLayout { stride: 3, offset: 1 };
}

/// Where [`ShEncodePass`] writes: 16 columns of a per-sample buffer whose rows also hold
/// other values (the colour MLP's input `[SH 16 | geometry]`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ShOutputLayout {
    /// Samples of one ray: sample n takes the direction of ray n / samples_per_ray.
    pub samples_per_ray: usize,
    /// Values per output row.
    pub row_stride: usize,
    /// Column of the first SH value; columns `column_offset..column_offset + 16` are written.
    pub column_offset: usize,
    /// f32 rows, or bf16 rows (`row_stride` and `column_offset` even).
    pub format: RowFormat,
}

/// The buffers of [`ShEncodePass`].
#[derive(Debug, Clone, Copy)]
pub struct ShEncodeBuffers<'a> {
    /// One unit direction per ray as `vec4<f32>` (xyz; w unused).
    pub directions: &'a wgpu::Buffer,
    /// Output: N rows of `row_stride` values in `ShOutputLayout::format`; only the SH columns
    /// are written.
    pub output: &'a wgpu::Buffer,
}

/// Degree-4 SH of each ray's direction, written for each of its samples (see the module docs).
#[derive(Debug)]
pub struct ShEncodePass {
    dispatch: Dispatch,
    _uniforms: wgpu::Buffer,
}

impl ShEncodePass {
    pub async fn new(
        ctx: &GpuContext,
        samples: usize,
        layout: ShOutputLayout,
        buffers: ShEncodeBuffers<'_>,
    ) -> Result<Self, GpuError> {
        Self::with_directions(ctx, samples, layout, DirectionLayout::PACKED, buffers).await
    }

    /// As [`ShEncodePass::new`] with directions laid out as `directions_at` says.
    pub async fn with_directions(
        ctx: &GpuContext,
        samples: usize,
        layout: ShOutputLayout,
        directions_at: DirectionLayout,
        buffers: ShEncodeBuffers<'_>,
    ) -> Result<Self, GpuError> {
        const WHAT: &str = "view direction SH";
        check_samples(WHAT, samples)?;
        if layout.samples_per_ray == 0 || layout.column_offset + SH_COEFFS > layout.row_stride {
            return Err(GpuError::invalid_argument(
                WHAT,
                format!("{layout:?}: needs samples_per_ray >= 1 and column_offset + {SH_COEFFS} <= row_stride"),
            ));
        }
        let rays = samples.div_ceil(layout.samples_per_ray) as u64;
        if directions_at.stride == 0 || directions_at.offset >= directions_at.stride {
            return Err(GpuError::invalid_argument(
                WHAT,
                format!("{directions_at:?}: offset must be below a positive stride"),
            ));
        }
        let direction_vec4s = (rays - 1) * directions_at.stride as u64 + directions_at.offset as u64 + 1;
        check_buffer(
            ctx,
            WHAT,
            "directions",
            buffers.directions,
            direction_vec4s * VEC4_BYTES,
        )?;
        let bf16 = layout.format == RowFormat::Bf16;
        if bf16 && (!layout.row_stride.is_multiple_of(2) || !layout.column_offset.is_multiple_of(2)) {
            return Err(GpuError::invalid_argument(
                WHAT,
                format!("{layout:?}: bf16 rows need an even row stride and column offset"),
            ));
        }
        let output_values = samples as u64 * layout.row_stride as u64;
        let output_words = if bf16 { output_values / 2 } else { output_values };
        check_buffer(ctx, WHAT, "output", buffers.output, output_words * F32_BYTES)?;
        check_index_range(WHAT, output_values)?;
        check_index_range(WHAT, samples as u64 + u64::from(WORKGROUP_SIZE) * u64::from(u16::MAX))?;
        let uniforms = ShUniforms {
            sample_count: samples as u32,
            samples_per_ray: index_u32("samples per ray", layout.samples_per_ray)?,
            row_stride: index_u32("SH row stride", layout.row_stride)?,
            column_offset: index_u32("SH column offset", layout.column_offset)?,
            direction_stride: index_u32("direction stride", directions_at.stride)?,
            direction_offset: index_u32("direction offset", directions_at.offset)?,
            _pad0: 0,
            _pad1: 0,
        };
        let groups = Dispatch1d::for_device(ctx, samples as u64, WORKGROUP_SIZE)?;
        let constants = [("SH_BF16", f64::from(u8::from(bf16)))];
        let spec = KernelSpec {
            constants: &constants,
            ..KernelSpec::new(WHAT, shaders::SH_ENCODE, "sh_encode")
        };
        let uniform_buffer = uniform_buffer_from(ctx, "view direction SH uniforms", &uniforms);
        let bindings = whole(&[
            ("sh_layout", &uniform_buffer),
            ("directions", buffers.directions),
            ("sh_out", buffers.output),
        ]);
        let dispatch = Dispatch::build(ctx, &spec, &bindings, groups).await?;
        Ok(ShEncodePass {
            dispatch,
            _uniforms: uniform_buffer,
        })
    }
}

impl Stage for ShEncodePass {
    fn name(&self) -> &'static str {
        "sh"
    }

    fn record(&self, pass: &mut wgpu::ComputePass<'_>) {
        if !self.dispatch.is_empty() {
            self.dispatch.record(pass);
        }
    }

    /// Reads R ray geometries; writes N·16 values in the colour input's format.
    fn global_bytes(&self, step: &StepShape) -> u64 {
        let values = StepShape::words(step.heads.color_input, SH_COEFFS as u64);
        step.rays() * RAY_GEOMETRY_BYTES + step.samples() * values * F32_BYTES
    }
}
