//! One dense layer's forward, bound to its buffers (picking the tiled or uniform-weight kernels
//! per product); its spec is `spec.rs`, its backward `backward.rs`.
use super::pipelines::{DenseKernels, ProductKind, ProductWeights, bound_product};
use super::relu_mask::ReluMask;
use super::spec::{DenseDims, DenseLayerSpec, WORD, check_binding, padded_to_vec4, row_count, row_words};
use super::{RowFormat, RowView, bf16_rows};
use crate::field::gpu::keep::HeadRows;
use crate::gpu::KernelFamily;
use crate::gpu::buffers::{storage_buffer_zeroed, uniform_buffer_from};
use crate::gpu::dispatch::Dispatch;
use crate::gpu::{GpuContext, GpuError};

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
        pipelines: &mut DenseKernels,
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
