//! Adam over the whole flat parameter buffer on the GPU (`shaders/adam.wgsl`), the twin of
//! `reference::adam`: one element-wise kernel over params, gradient and the two moments. It
//! zeroes each gradient it reads, so the gradient buffer is clear for the next step's backward
//! passes (which add to it) without a separate clear.
//!
//! β₁, β₂ and ε are fixed when the pass is built; the learning rate and the bias corrections
//! c₁, c₂ change every step and are read from the trainer's shared `StepUniforms` buffer
//! (`shaders/_step.wgsl`: fields `lr`, `adam_c1`, `adam_c2`, with c₁, c₂ from
//! `reference::adam::Adam::bias_corrections`), so a step records no CPU work.
//!
//! Buffers longer than one storage binding are updated in segments, each bound at an aligned
//! offset; the kernel itself only ever sees one segment.
use crate::field::config::AdamConfig;
use crate::field::gpu::encoding::FixedPointTable;
use crate::field::gpu::stage::{Stage, StepShape, WORD};
use crate::field::params::ParamLayout;
use crate::gpu::buffers::uniform_buffer_from;
use crate::gpu::dispatch::{Dispatch, bind_named};
use crate::gpu::pipeline::{Dispatch1d, KernelSpec, create_compute_pipeline};
use crate::gpu::{GpuContext, GpuError, shaders};

/// Workgroup size of `adam.wgsl`.
const WORKGROUP: u32 = 256;

/// The fixed hyper-parameters and segment length; mirrors `AdamConstants` in `shaders/adam.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct AdamConstants {
    pub beta1: f32,
    pub beta2: f32,
    pub epsilon: f32,
    pub count: u32,
    /// The segment's first element in the whole flat buffer.
    pub first: u32,
    /// The fixed-point table's elements in the whole flat buffer (0..0 without one).
    pub table_start: u32,
    pub table_end: u32,
    pub _pad0: u32,
}

/// The four flat buffers Adam walks (all of `count` f32, ParamLayout order).
#[derive(Debug, Clone)]
pub struct AdamBuffers<'a> {
    pub params: &'a wgpu::Buffer,
    pub grads: &'a wgpu::Buffer,
    pub first_moment: &'a wgpu::Buffer,
    pub second_moment: &'a wgpu::Buffer,
    /// Where `grads` holds the hash table's gradient in fixed point (the backward's
    /// [`HashGridBackwardPass::fixed_point_table`](crate::field::gpu::encoding::HashGridBackwardPass::fixed_point_table)),
    /// to be decoded before the update; `None` when all of it is f32.
    pub fixed_point_table: Option<FixedPointTable<'a>>,
}

/// One Adam step over `count` parameters: one dispatch per segment of the buffers.
pub struct AdamPass {
    segments: Vec<Dispatch>,
}

impl AdamPass {
    /// `step` is the trainer's `StepUniforms` uniform buffer (`shaders/_step.wgsl`), rewritten
    /// before every submit.
    pub async fn new(
        ctx: &GpuContext,
        config: &AdamConfig,
        count: usize,
        buffers: AdamBuffers<'_>,
        step: &wgpu::Buffer,
    ) -> Result<AdamPass, GpuError> {
        Self::with_segment_length(ctx, config, count, buffers, step, segment_length(ctx)).await
    }

    /// As [`AdamPass::new`], splitting the buffers into segments of at most `segment_len`
    /// elements (a multiple of the device's storage offset alignment, in f32, and at most one
    /// binding); `new` uses the largest allowed. Exposed so the splitting can be tested.
    pub async fn with_segment_length(
        ctx: &GpuContext,
        config: &AdamConfig,
        count: usize,
        buffers: AdamBuffers<'_>,
        step: &wgpu::Buffer,
        segment_len: u64,
    ) -> Result<AdamPass, GpuError> {
        let align = u64::from(ctx.limits.min_storage_buffer_offset_alignment.max(4)) / 4;
        if segment_len == 0 || !segment_len.is_multiple_of(align) || segment_len > segment_length(ctx) {
            return Err(GpuError::invalid_argument(
                "adam",
                format!(
                    "segment length {segment_len} must be a positive multiple of {align} and at most {}",
                    segment_length(ctx)
                ),
            ));
        }
        let bytes = count as u64 * 4;
        if count == 0 {
            return Err(GpuError::invalid_argument("adam", "no parameters to update"));
        }
        let named = [
            ("params", buffers.params),
            ("gradient", buffers.grads),
            ("first moment", buffers.first_moment),
            ("second moment", buffers.second_moment),
        ];
        for (name, buffer) in named {
            if buffer.size() < bytes {
                return Err(GpuError::invalid_argument(
                    format!("adam {name}"),
                    format!("buffer of {} bytes is shorter than {count} f32", buffer.size()),
                ));
            }
        }
        let table = buffers.fixed_point_table.as_ref().map(|t| t.table.clone());
        if let Some(table) = &table
            && (table.start > table.end || table.end > count)
        {
            return Err(GpuError::invalid_argument(
                "adam",
                format!("fixed-point table {table:?} is not inside the {count} parameters"),
            ));
        }
        let entry = if table.is_some() {
            "adam_fixed_point_table"
        } else {
            "adam"
        };
        let spec = KernelSpec::new("adam", shaders::ADAM, entry);
        let pipeline = create_compute_pipeline(ctx, &spec).await?;
        let layout = pipeline.get_bind_group_layout(0);

        let mut segments = Vec::new();
        let mut start = 0u64;
        while start < count as u64 {
            let len = (count as u64 - start).min(segment_len);
            let table = table.clone().unwrap_or(0..0);
            let constants = AdamConstants {
                beta1: config.beta1,
                beta2: config.beta2,
                epsilon: config.epsilon,
                count: len as u32,
                first: start as u32,
                table_start: table.start as u32,
                table_end: table.end as u32,
                _pad0: 0,
            };
            let uniform = uniform_buffer_from(ctx, "adam constants", &constants);
            let size = std::num::NonZeroU64::new(len * 4)
                .ok_or_else(|| GpuError::invalid_argument("adam", "empty segment"))?;
            let slice = |buffer| {
                wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                    buffer,
                    offset: start * 4,
                    size: Some(size),
                })
            };
            let mut bindings = vec![
                ("constants", uniform.as_entire_binding()),
                ("step_info", step.as_entire_binding()),
                ("params", slice(buffers.params)),
                ("grads", slice(buffers.grads)),
                ("first_moment", slice(buffers.first_moment)),
                ("second_moment", slice(buffers.second_moment)),
            ];
            if let Some(fixed) = &buffers.fixed_point_table {
                bindings.push(("grid", fixed.grid.as_entire_binding()));
                bindings.push(("exponents", fixed.exponents.as_entire_binding()));
            }
            let bind_group = bind_named(ctx, &spec, &layout, 0, &bindings)?;
            let groups = Dispatch1d::for_device(ctx, len, WORKGROUP)?;
            segments.push(Dispatch::new(pipeline.clone(), bind_group, groups));
            start += len;
        }
        Ok(AdamPass { segments })
    }

    /// Segments the buffers were split into (1 unless they exceed one storage binding).
    pub fn segment_count(&self) -> usize {
        self.segments.len()
    }
}

impl Stage for AdamPass {
    fn name(&self) -> &'static str {
        "adam"
    }

    fn record(&self, pass: &mut wgpu::ComputePass<'_>) {
        for segment in &self.segments {
            segment.record(pass);
        }
    }

    /// Reads parameters, gradients and both moments (4·P); writes the same, the gradients
    /// zeroed.
    fn global_bytes(&self, step: &StepShape) -> u64 {
        8 * ParamLayout::new(step.cfg).total as u64 * WORD
    }
}

/// Elements per segment: the largest binding the device allows, in whole alignment units so
/// every segment starts at an offset the device accepts.
fn segment_length(ctx: &GpuContext) -> u64 {
    let align = u64::from(ctx.limits.min_storage_buffer_offset_alignment.max(4));
    let max_binding = ctx
        .limits
        .max_storage_buffer_binding_size
        .min(ctx.limits.max_buffer_size);
    (max_binding / align * align / 4).max(align / 4)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn uniforms_match_the_wgsl_layout() {
        assert_eq!(size_of::<AdamConstants>(), 32);
    }
}
