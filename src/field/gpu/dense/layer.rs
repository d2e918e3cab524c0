//! One dense layer: its spec, the uniform block every dense kernel reads, and its forward bound
//! to its buffers (picking the tiled or uniform-weight kernels per product); the backward is
//! `backward.rs`.
use std::num::NonZeroU64;
use std::ops::Range;

use super::pipelines::{DenseKernel, DensePipelines, ProductKind, ProductWeights};
use super::relu_mask::ReluMask;
use super::uniform::padded_to_vec4;
use super::{RowFormat, RowView, bf16_rows};
use crate::field::gpu::keep::HeadRows;
use crate::gpu::KernelFamily;
use crate::gpu::buffers::{storage_buffer_from, storage_buffer_zeroed, uniform_buffer_from};
use crate::gpu::dispatch::{Dispatch, IndirectArgs, bind_named};
use crate::gpu::{GpuContext, GpuError};

/// Bytes per `f32` element.
pub(super) const WORD: u64 = 4;

/// Uniform block of every dense kernel; mirrors `DenseDims` in `shaders/_dense_tile.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct DenseDims {
    pub rows: u32,
    pub in_dim: u32,
    pub out_dim: u32,
    pub relu: u32,
    pub x_stride: u32,
    pub x_offset: u32,
    pub y_stride: u32,
    pub y_offset: u32,
    pub dy_stride: u32,
    pub dy_offset: u32,
    pub dx_stride: u32,
    pub dx_offset: u32,
    pub weight_offset: u32,
    pub chunk_rows: u32,
    pub chunks: u32,
    pub _pad: u32,
}

/// One layer's shape and weights.
#[derive(Debug, Clone)]
pub struct DenseLayerSpec {
    pub label: String,
    pub rows: u32,
    pub in_dim: u32,
    pub out_dim: u32,
    /// A ReLU on the product (there is no bias); the last layer of an MLP has none.
    pub relu: bool,
    /// The `[out][in]` matrix's range of the flat parameter (and gradient) buffer.
    pub weights: Range<usize>,
}

impl DenseLayerSpec {
    pub(super) fn check(&self) -> Result<(), GpuError> {
        if self.rows == 0 || self.in_dim == 0 || self.out_dim == 0 {
            return Err(GpuError::invalid_argument(
                &self.label,
                format!(
                    "rows {}, in {} and out {} must be positive",
                    self.rows, self.in_dim, self.out_dim
                ),
            ));
        }
        let expected = self.in_dim as usize * self.out_dim as usize;
        if self.weights.len() != expected {
            return Err(GpuError::invalid_argument(
                &self.label,
                format!(
                    "weight range {:?} holds {} values, not {expected}",
                    self.weights,
                    self.weights.len()
                ),
            ));
        }
        Ok(())
    }

    pub(super) fn base_dims(&self) -> DenseDims {
        DenseDims {
            rows: self.rows,
            in_dim: self.in_dim,
            out_dim: self.out_dim,
            relu: u32::from(self.relu),
            ..DenseDims::default()
        }
    }
}

/// One dispatch per pipeline of a product ([`super::pipelines::ProductKernel`]), each bound to
/// the same resources and launched over the kept rows where there are some.
pub(super) fn bound_product(
    ctx: &GpuContext,
    (pipelines, kernel): (Vec<wgpu::ComputePipeline>, DenseKernel),
    resources: &[(&str, wgpu::BindingResource<'_>)],
    workgroups: [u32; 3],
    (kept, rows_per_workgroup): (Option<&HeadRows>, u32),
) -> Result<Vec<Dispatch>, GpuError> {
    pipelines
        .into_iter()
        .map(|pipeline| {
            let indirect = kept_dispatch(kept, 1, rows_per_workgroup, workgroups[2])?;
            Ok(bound(ctx, (pipeline, kernel), resources, workgroups)?.with_indirect(indirect))
        })
        .collect()
}

/// One dense kernel's dispatch, its group 0 bound by the WGSL names of `kernel`'s bindings.
pub(super) fn bound(
    ctx: &GpuContext,
    (pipeline, kernel): (wgpu::ComputePipeline, DenseKernel),
    resources: &[(&str, wgpu::BindingResource<'_>)],
    workgroups: impl Into<[u32; 3]>,
) -> Result<Dispatch, GpuError> {
    let bind_group = bind_named(ctx, &kernel.spec(), &pipeline.get_bind_group_layout(0), 0, resources)?;
    Ok(Dispatch::new(pipeline, bind_group, workgroups))
}

/// The part of a flat buffer holding `range` (in f32), bound from an offset the device accepts,
/// so only the layer's weights count against the binding-size limit (the hash table in front
/// of them may be larger than one binding); returns the binding and where `range` starts in it.
pub(super) fn range_binding<'a>(
    ctx: &GpuContext,
    what: &str,
    buffer: &'a wgpu::Buffer,
    range: &Range<usize>,
) -> Result<(wgpu::BindingResource<'a>, u32), GpuError> {
    let end = range.end as u64 * 4;
    if end > buffer.size() {
        return Err(GpuError::invalid_argument(
            what,
            format!("range {range:?} ends past the buffer's {} f32", buffer.size() / 4),
        ));
    }
    let align = u64::from(ctx.limits.min_storage_buffer_offset_alignment.max(4));
    let start = range.start as u64 * 4 / align * align;
    let size = end - start;
    ctx.ensure_storage_binding_fits(what, size)?;
    let size =
        NonZeroU64::new(size).ok_or_else(|| GpuError::invalid_argument(what, format!("range {range:?} is empty")))?;
    let local = (range.start as u64 - start / 4) as u32;
    Ok((
        wgpu::BindingResource::Buffer(wgpu::BufferBinding {
            buffer,
            offset: start,
            size: Some(size),
        }),
        local,
    ))
}

pub(super) fn check_binding(ctx: &GpuContext, what: &str, buffer: &wgpu::Buffer) -> Result<(), GpuError> {
    ctx.ensure_storage_binding_fits(what, buffer.size())
}

/// The word the kernels read the rows present from (`row_count` in `_dense_tile.wgsl`): the
/// kept rows' count, or a word holding all of `spec.rows`.
pub(super) fn row_count(
    ctx: &GpuContext,
    spec: &DenseLayerSpec,
    kept: Option<&HeadRows>,
) -> Result<wgpu::Buffer, GpuError> {
    match kept {
        Some(kept) if kept.capacity < spec.rows => Err(GpuError::invalid_argument(
            &spec.label,
            format!("{} rows, but the kept rows hold at most {}", spec.rows, kept.capacity),
        )),
        Some(kept) => Ok(kept.row_count.clone()),
        None => storage_buffer_from(ctx, &format!("{} rows", spec.label), &[spec.rows]),
    }
}

/// The indirect workgroup counts of a row-parallel kernel over the kept rows (`None`: a fixed
/// batch, launched as recorded).
pub(super) fn kept_dispatch(
    kept: Option<&HeadRows>,
    items_per_row: u32,
    per_workgroup: u32,
    z: u32,
) -> Result<Option<IndirectArgs>, GpuError> {
    kept.map(|kept| kept.dispatch(items_per_row, per_workgroup, z))
        .transpose()
}

/// The forward of one layer, bound to its buffers.
pub struct DenseForward {
    spec: DenseLayerSpec,
    /// Whether the kernel reads a packed copy of the weights (uniform-weight kernels).
    packed: bool,
    /// One per block where each block is its own pipeline, otherwise one.
    dispatches: Vec<Dispatch>,
    family: KernelFamily,
    /// How X and Y are stored.
    formats: (RowFormat, RowFormat),
    /// The bits of Y > 0 it also stores, where asked.
    relu_mask: Option<ReluMask>,
}

impl DenseForward {
    /// `input` must hold `spec.rows` rows of `in_dim` values, `output` of `out_dim`; the output
    /// is overwritten. With `kept`, only the first kept rows are computed (see [`HeadRows`]).
    /// `packed`: the window of the MLP's packed weights for this layer's forward (then the
    /// uniform-weight kernel runs; the MLP refreshes the copy), or `None` (tiled).
    /// `relu_mask`: also store which outputs are positive ([`DenseForward::relu_mask`]; a ReLU
    /// layer on the uniform-weight kernel only).
    #[allow(clippy::too_many_arguments)]
    pub(super) async fn new(
        ctx: &GpuContext,
        pipelines: &mut DensePipelines,
        spec: &DenseLayerSpec,
        params: &wgpu::Buffer,
        (input, output): (&RowView, &RowView),
        kept: Option<&HeadRows>,
        packed: Option<wgpu::BindingResource<'_>>,
        relu_mask: bool,
    ) -> Result<DenseForward, GpuError> {
        spec.check()?;
        let label = format!("{} forward", spec.label);
        if relu_mask && (packed.is_none() || !spec.relu) {
            return Err(GpuError::invalid_argument(
                &label,
                "only a ReLU layer on the uniform-weight kernel stores its mask bits",
            ));
        }
        input.check(&format!("{label} input"), spec.rows, spec.in_dim)?;
        output.check(&format!("{label} output"), spec.rows, spec.out_dim)?;
        check_binding(ctx, &label, &input.buffer)?;
        check_binding(ctx, &label, &output.buffer)?;
        let (kernel, product_weights, workgroups, family, rows_per_workgroup) = pipelines
            .product_kernel(
                ctx,
                &label,
                (params, packed),
                spec,
                ProductKind::Forward,
                &[
                    bf16_rows("X_BF16", input),
                    bf16_rows("Y_BF16", output),
                    ("WRITE_MASK", f64::from(u8::from(relu_mask))),
                ],
            )
            .await?;
        let packed = matches!(product_weights, ProductWeights::Packed(_));
        let (weights, weight_offset) = product_weights.binding();
        let rows = row_count(ctx, spec, kept)?;
        let dims = DenseDims {
            x_stride: input.stride,
            x_offset: input.offset,
            y_stride: output.stride,
            y_offset: output.offset,
            weight_offset,
            ..spec.base_dims()
        };
        let uniform = uniform_buffer_from(ctx, &label, &dims);
        let mut resources = vec![
            ("dims", uniform.as_entire_binding()),
            ("x", input.buffer.as_entire_binding()),
            ("weights", weights),
            ("y", output.buffer.as_entire_binding()),
            ("row_count", rows.as_entire_binding()),
        ];
        // The uniform-weight kernel always names `relu_mask`; without WRITE_MASK any buffer does.
        let mask = match (relu_mask, family) {
            (true, KernelFamily::UniformWeights) => Some(ReluMask::zeroed(
                ctx,
                &format!("{label} ReLU mask"),
                spec.rows,
                spec.out_dim,
                pipelines.uniform_product_block(ctx, spec.out_dim),
            )?),
            (true, KernelFamily::Tiled) => {
                return Err(GpuError::invalid_argument(
                    &label,
                    "the tiled forward stores no mask bits",
                ));
            }
            (false, _) => None,
        };
        let unused;
        if family == KernelFamily::UniformWeights {
            let target = match &mask {
                Some(mask) => &mask.buffer,
                None => {
                    unused = storage_buffer_zeroed::<u32>(ctx, &format!("{label} (no mask)"), 4)?;
                    &unused
                }
            };
            resources.push(("relu_mask", target.as_entire_binding()));
        }
        let dispatches = bound_product(ctx, kernel, &resources, workgroups, (kept, rows_per_workgroup))?;
        Ok(DenseForward {
            spec: spec.clone(),
            packed,
            dispatches,
            family,
            formats: (input.format, output.format),
            relu_mask: mask,
        })
    }

    /// The bits of which outputs are positive, where it stores them.
    pub fn relu_mask(&self) -> Option<&ReluMask> {
        self.relu_mask.as_ref()
    }

    pub fn spec(&self) -> &DenseLayerSpec {
        &self.spec
    }

    /// Bytes its dispatch moves through global memory over `rows` rows (every element read or
    /// written counted once, bf16 rows as their words): X read, Y (and its mask bits) written,
    /// the weights (or their packed copy) read. The MLP counts the packing.
    pub fn global_bytes(&self, rows: u64) -> u64 {
        let (i, o) = (u64::from(self.spec.in_dim), u64::from(self.spec.out_dim));
        let weights = if self.packed {
            i * u64::from(padded_to_vec4(self.spec.out_dim))
        } else {
            i * o
        };
        let (x, y) = self.formats;
        let mask = self.relu_mask.as_ref().map_or(0, |mask| u64::from(mask.row_words()));
        WORD * (rows * (row_words(x, self.spec.in_dim) + row_words(y, self.spec.out_dim) + mask) + weights)
    }

    /// The kernels this layer's forward runs (uniform weights only where the layer fits).
    pub fn family(&self) -> KernelFamily {
        self.family
    }

    pub fn record(&self, pass: &mut wgpu::ComputePass<'_>) {
        for dispatch in &self.dispatches {
            dispatch.record(pass);
        }
    }
}

/// Words one row of `width` values takes in `format` (bf16: pairs, what the traffic counts).
pub(super) fn row_words(format: RowFormat, width: u32) -> u64 {
    RowView::words(format, 1, width)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dims_uniform_is_sixteen_words() {
        assert_eq!(size_of::<DenseDims>(), 64);
    }
}
