//! Rows inside a buffer: how every per-sample GPU pass names the slice of a wider row it reads
//! or writes (an MLP layer's input, a head's output inside the composite's rows).
use crate::gpu::buffers::storage_buffer_zeroed;
use crate::gpu::{GpuContext, GpuError};

/// How a row's values are stored.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum RowFormat {
    /// One f32 per word.
    #[default]
    F32,
    /// bf16, two values per word, value 2p low in word p (`crate::field::bf16`): the hidden
    /// layers of an MLP whose kernels all read such rows (`dense::MlpPass`).
    Bf16,
}

/// Rows inside a buffer: value `j` of row `n` is value `n·stride + offset + j` (f32 rows: that
/// word; bf16 rows: half of word `(n·stride + offset + j) / 2`, with stride and offset even).
#[derive(Debug, Clone)]
pub struct RowView {
    pub buffer: wgpu::Buffer,
    pub stride: u32,
    pub offset: u32,
    pub format: RowFormat,
}

impl RowView {
    /// Rows of exactly `width` f32 values, back to back from the start of `buffer`.
    pub fn packed(buffer: &wgpu::Buffer, width: u32) -> RowView {
        RowView::new(buffer, width, 0)
    }

    /// f32 rows of `stride` values, the view's first value at `offset` of each.
    pub fn new(buffer: &wgpu::Buffer, stride: u32, offset: u32) -> RowView {
        RowView {
            buffer: buffer.clone(),
            stride,
            offset,
            format: RowFormat::F32,
        }
    }

    /// bf16 rows of `width` values back to back from the start of `buffer`, each padded to an
    /// even length so that every row starts a word.
    pub fn packed_bf16(buffer: &wgpu::Buffer, width: u32) -> RowView {
        RowView {
            buffer: buffer.clone(),
            stride: width.next_multiple_of(2),
            offset: 0,
            format: RowFormat::Bf16,
        }
    }

    /// `rows` rows of `width` values in `format`, back to back in a zeroed buffer of their own.
    pub fn zeroed(
        ctx: &GpuContext,
        label: &str,
        format: RowFormat,
        rows: u32,
        width: u32,
    ) -> Result<RowView, GpuError> {
        let words = RowView::words(format, rows, width);
        ctx.ensure_storage_binding_fits(label, words * 4)?;
        let buffer = storage_buffer_zeroed::<f32>(ctx, label, words as usize)?;
        Ok(RowView::packed_as(&buffer, width, format))
    }

    /// Rows of `width` values in `format`, back to back from the start of `buffer`
    /// ([`RowView::packed`] or [`RowView::packed_bf16`]).
    pub fn packed_as(buffer: &wgpu::Buffer, width: u32, format: RowFormat) -> RowView {
        match format {
            RowFormat::F32 => RowView::packed(buffer, width),
            RowFormat::Bf16 => RowView::packed_bf16(buffer, width),
        }
    }

    /// Words a buffer needs for `rows` such rows of `width` values, and their format.
    pub fn words(format: RowFormat, rows: u32, width: u32) -> u64 {
        match format {
            RowFormat::F32 => u64::from(rows) * u64::from(width),
            RowFormat::Bf16 => u64::from(rows) * u64::from(width.div_ceil(2)),
        }
    }

    pub fn is_bf16(&self) -> bool {
        self.format == RowFormat::Bf16
    }

    /// Checks that `rows` rows of `width` values fit in the view's buffer without overlapping
    /// (and that bf16 rows start at whole words).
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
        if self.is_bf16() && (!self.stride.is_multiple_of(2) || !self.offset.is_multiple_of(2)) {
            return Err(GpuError::invalid_argument(
                what,
                format!(
                    "bf16 rows need an even stride and offset, not {} and {}",
                    self.stride, self.offset
                ),
            ));
        }
        let values =
            u64::from(rows).saturating_sub(1) * u64::from(self.stride) + u64::from(self.offset) + u64::from(width);
        let (needed, unit) = match self.format {
            RowFormat::F32 => (values, "f32"),
            RowFormat::Bf16 => (values.div_ceil(2), "words of bf16 pairs"),
        };
        let available = self.buffer.size() / 4;
        if needed > available {
            return Err(GpuError::invalid_argument(
                what,
                format!(
                    "{rows} rows of stride {} need {needed} {unit} but the buffer holds {available}",
                    self.stride
                ),
            ));
        }
        // Index arithmetic in the shaders is u32.
        if values > u64::from(u32::MAX) {
            return Err(GpuError::invalid_argument(
                what,
                format!("{values} values exceed u32 indexing"),
            ));
        }
        Ok(())
    }
}
