//! What every dense kernel shares, below the kernels and the choice between them: a layer's
//! shape and weights, the uniform block the kernels read, binding part of a flat buffer, the
//! rows a layer runs over, and the arithmetic of padded rows.
use std::num::NonZeroU64;
use std::ops::Range;

use super::{RowFormat, RowView};
use crate::field::gpu::keep::HeadRows;
use crate::gpu::buffers::storage_buffer_from;
use crate::gpu::dispatch::IndirectArgs;
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

/// Words one row of `width` values takes in `format` (bf16: pairs, what the traffic counts).
pub(super) fn row_words(format: RowFormat, width: u32) -> u64 {
    RowView::words(format, 1, width)
}

/// `n` rounded up to a multiple of 4 (`padded_to_vec4` in `shaders/_dense_tile.wgsl`).
pub(super) fn padded_to_vec4(n: u32) -> u32 {
    n.div_ceil(4) * 4
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dims_uniform_is_sixteen_words() {
        assert_eq!(size_of::<DenseDims>(), 64);
    }
}
