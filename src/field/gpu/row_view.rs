//! Rows of f32 inside a buffer: how every per-sample GPU pass names the slice of a wider row
//! it reads or writes (an MLP layer's input, a head's output inside the composite's rows).
use crate::gpu::GpuError;

/// Rows of f32 inside a buffer: element `j` of row `n` is at `n·stride + offset + j` (in f32).
#[derive(Debug, Clone)]
pub struct RowView {
    pub buffer: wgpu::Buffer,
    pub stride: u32,
    pub offset: u32,
}

impl RowView {
    /// Rows of exactly `width` values, back to back from the start of `buffer`.
    pub fn packed(buffer: &wgpu::Buffer, width: u32) -> RowView {
        RowView {
            buffer: buffer.clone(),
            stride: width,
            offset: 0,
        }
    }

    /// Checks that `rows` rows of `width` values fit in the view's buffer without overlapping.
    pub fn check(&self, what: &str, rows: u32, width: u32) -> Result<(), GpuError> {
        if self.offset.checked_add(width).is_none_or(|end| end > self.stride) {
            return Err(GpuError::invalid_argument(
                what,
                format!(
                    "columns {}..{} do not fit in rows of stride {}",
                    self.offset,
                    self.offset + width,
                    self.stride
                ),
            ));
        }
        let needed =
            u64::from(rows).saturating_sub(1) * u64::from(self.stride) + u64::from(self.offset) + u64::from(width);
        let available = self.buffer.size() / 4;
        if needed > available {
            return Err(GpuError::invalid_argument(
                what,
                format!(
                    "{rows} rows of stride {} need {needed} f32 but the buffer holds {available}",
                    self.stride
                ),
            ));
        }
        // Index arithmetic in the shaders is u32.
        if needed > u64::from(u32::MAX) {
            return Err(GpuError::invalid_argument(
                what,
                format!("{needed} f32 exceed u32 indexing"),
            ));
        }
        Ok(())
    }
}
