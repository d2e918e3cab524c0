//! The shapes of the uniform-weight family that the choice of kernel needs before any kernel
//! is built: where its packed copies are read from, the block one invocation computes, how far
//! a reduction is written out and how its rows are dispatched (the kernels are `uniform.rs`).
use super::spec::padded_to_vec4;
use crate::gpu::pipeline::Dispatch1d;
use crate::gpu::{GpuContext, GpuError};

/// Where the uniform-weight kernels read a layer's packed weights and the weight gradient reads
/// dZ (`shaders/_dense_uniform.wgsl`). The same kernels either way, summing in the same order,
/// so the results are the same bits.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum PackedReads {
    /// 64 KiB uniform bindings (`dense_*_uniform.wgsl`): a load every lane shares is one scalar
    /// load on CPU devices, as naga's SPIR-V runs natively.
    Uniform,
    /// Storage bindings (`dense_*_packed_storage.wgsl`): Tint, the browser's compiler, turns
    /// every uniform access into a byte offset divided back by 16, which SwiftShader runs lane by
    /// lane; from storage it loads a shared index once (docs/results/bench.md, "Tint divides per
    /// uniform access").
    Storage,
}

impl PackedReads {
    /// The faster for the compiler this build hands its WGSL to: Tint in the browser (measured
    /// in Chromium), naga natively.
    pub fn for_this_build() -> PackedReads {
        if cfg!(target_arch = "wasm32") {
            PackedReads::Storage
        } else {
            PackedReads::Uniform
        }
    }
}

/// Offset alignment of a window of the packed copies, bound as a uniform or a storage range.
pub(super) fn packed_window_alignment(ctx: &GpuContext) -> u32 {
    ctx.limits
        .min_uniform_buffer_offset_alignment
        .max(ctx.limits.min_storage_buffer_offset_alignment)
        .max(16)
}

/// f32 in the uniform binding of the uniform-weight kernels (64 KiB, WebGPU's default limit).
pub const UNIFORM_WEIGHT_FLOATS: usize = 16384;
/// Invocations per workgroup of the uniform-weight kernels (`WORKGROUP` in the shader).
pub(super) const UNIFORM_WORKGROUP: u32 = 64;

/// Outputs (or inputs) per invocation of a uniform-weight kernel (`shaders/_dense_acc.wgsl`):
/// `width` split into as few blocks of at most `limit` (a multiple of 4, at most 64) as
/// possible, of equal size rounded up to a multiple of 4, so a 79-wide layer runs two blocks
/// of 40 rather than 64 and 15 wasted.
pub(super) fn uniform_block(width: u32, limit: u32) -> u32 {
    let blocks = width.max(1).div_ceil(limit);
    padded_to_vec4(width.max(1).div_ceil(blocks))
}

/// The longest reduction the uniform-weight kernels write out step by step (`MAX_UNROLLED` in
/// `shaders/_dense_uniform.wgsl`).
pub(super) const MAX_UNROLLED: u32 = 128;

pub(super) fn uniform_dispatch(ctx: &GpuContext, rows: u32, width: u32, block: u32) -> Result<[u32; 3], GpuError> {
    let groups = Dispatch1d::for_device(ctx, u64::from(rows), UNIFORM_WORKGROUP)?;
    Ok([groups.x, groups.y, width.div_ceil(block)])
}
