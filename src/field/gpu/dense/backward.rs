//! The backward of one dense layer bound to its buffers: dX from dZ, and dW as per-chunk partial
//! sums reduced in a second pass (tiled or uniform-weight kernels per product, as the forward).
use std::ops::Range;

use super::pipelines::{DenseKernel, DenseKernels, ProductKind, ProductWeights};
use super::pipelines::{bound, bound_product};
use super::relu_mask::ReluMask;
use super::spec::{
    DenseDims, DenseLayerSpec, WORD, check_binding, kept_dispatch, padded_to_vec4, range_binding, row_count, row_words,
};
use super::tiled::{REDUCE_SHAPE, REDUCE_WORKGROUP, TileShape, weight_chunks};
use super::uniform::{
    UniformWeightPartials, WeightGradientShape, WindowedLayer, dz_windows_buffer, uniform_weight_chunks,
};
use super::{RowFormat, RowView, bf16_rows};
use crate::field::gpu::keep::HeadRows;
use crate::gpu::KernelFamily;
use crate::gpu::buffers::{storage_buffer_zeroed, uniform_buffer_from};
use crate::gpu::dispatch::Dispatch;
use crate::gpu::pipeline::Dispatch1d;
use crate::gpu::{GpuContext, GpuError};
/// Where a layer's backward gets dZ, the gradient of its output before the activation.
#[derive(Debug, Clone, Copy)]
pub enum OutputGradient<'a> {
    /// dL/dY rows (`out_dim` values per row), masked here by the activation's derivative.
    Rows(&'a RowView),
    /// dZ itself, written into this layer's weight-gradient windows
    /// ([`DenseBackward::dz_rows`]) by a kernel recorded before this layer's: the MLP's
    /// input-gradient chain (`chain.rs`; the layer then records its weight gradient alone) or
    /// the next layer's input gradient ([`DenseGradients::input_mask`]). Only the
    /// uniform-window weight gradient has windows.
    InWindows,
}

/// Buffers of one layer's backward.
#[derive(Debug, Clone)]
pub struct DenseGradients<'a> {
    /// The flat gradient buffer (same layout as the parameters); dW is added at `spec.weights`.
    pub grads: &'a wgpu::Buffer,
    pub output_grad: OutputGradient<'a>,
    /// Where dL/dX goes (`in_dim` values per row, overwritten); `None` skips it.
    pub input_grad: Option<&'a RowView>,
    /// Store dX masked by the ReLU of X (the previous layer's output), whose bits its forward
    /// stored ([`DenseForward::relu_mask`]): that layer's dZ, where `input_grad` is that layer's
    /// windows and it reads them as [`OutputGradient::InWindows`].
    pub input_mask: Option<&'a ReluMask>,
    /// As the forward's `kept`: the rows present are the kept samples (see [`HeadRows`]).
    pub kept: Option<&'a HeadRows>,
    /// The columns of dX the caller reads (`None`: all); the uniform-weight input gradient
    /// writes no others (`DX_FIRST`, `DX_END`), the tiled one writes them all.
    pub input_grad_columns: Option<Range<u32>>,
}

/// The backward of one layer, bound to its buffers; owns the per-chunk partial sums of dW.
pub struct DenseBackward {
    spec: DenseLayerSpec,
    /// dX, and whether it reads a packed copy of the weights (uniform-weight kernels).
    input_grad: Option<(bool, Vec<Dispatch>)>,
    partial_sums: WeightPartials,
    reduce: Dispatch,
    /// Partial matrices of dW the reduction sums.
    partials: u32,
    /// The padded dZ rows the uniform-window weight gradient reads (`None`: tiled).
    dz: Option<wgpu::Buffer>,
    /// The row-count word its kernels read.
    row_count: wgpu::Buffer,
    /// How X, Y, dY and dX are stored.
    formats: [RowFormat; 4],
    /// dY arrives as dZ, written by an earlier kernel ([`OutputGradient::InWindows`]).
    dz_given: bool,
    /// Words per row of the mask bits dX is stored masked by ([`DenseGradients::input_mask`]).
    input_mask_words: Option<u32>,
    /// The columns of dX written.
    input_grad_columns: Range<u32>,
}

/// The first half of dW: every chunk of rows' partial matrix.
enum WeightPartials {
    /// One dispatch of the tiled kernel over all chunks.
    Tiled(Dispatch),
    /// dZ masked into a packed buffer (by dX's kernel where the layer has one), then up to 8
    /// chunks per dispatch reading it as uniform windows.
    Uniform(UniformWeightPartials),
}

impl WeightPartials {
    fn record(&self, pass: &mut wgpu::ComputePass<'_>) {
        match self {
            WeightPartials::Tiled(dispatch) => dispatch.record(pass),
            WeightPartials::Uniform(partials) => partials.record(pass),
        }
    }
}

impl DenseBackward {
    /// `input` and `output` are the forward's views (X and the activated Y); `packed` as for
    /// [`DenseForward::new`], the window of the copy dX reads.
    pub(super) async fn new(
        ctx: &GpuContext,
        pipelines: &mut DenseKernels,
        spec: &DenseLayerSpec,
        params: &wgpu::Buffer,
        (input, output): (&RowView, &RowView),
        gradients: &DenseGradients<'_>,
        packed: Option<wgpu::BindingResource<'_>>,
    ) -> Result<DenseBackward, GpuError> {
        let kept = gradients.kept;
        spec.check()?;
        let label = format!("{} backward", spec.label);
        input.check(&format!("{label} input"), spec.rows, spec.in_dim)?;
        output.check(&format!("{label} output"), spec.rows, spec.out_dim)?;
        let rows = row_count(ctx, spec, kept)?;

        let label_dw = format!("{label} weight gradient");
        let uniform_plan = match pipelines.family {
            KernelFamily::UniformWeights => uniform_weight_chunks(ctx, spec),
            KernelFamily::Tiled => None,
        };
        // The uniform-window weight gradient reads dZ from its own buffer, in padded rows.
        let dz = uniform_plan
            .map(|(chunk_rows, chunks)| dz_windows_buffer(ctx, &label_dw, spec, chunk_rows, chunks))
            .transpose()?;
        // dZ written by an earlier kernel is dY needing no mask, read from the windows.
        let dz_given = matches!(gradients.output_grad, OutputGradient::InWindows);
        let output_grad = match (gradients.output_grad, &dz) {
            (OutputGradient::Rows(view), _) => view.clone(),
            (OutputGradient::InWindows, Some(dz)) => dz_rows(dz, spec.out_dim),
            (OutputGradient::InWindows, None) => {
                return Err(GpuError::invalid_argument(
                    &label,
                    "dZ can be written for this layer only into a uniform-window weight gradient's windows",
                ));
            }
        };
        let output_grad = &output_grad;
        output_grad.check(&format!("{label} output gradient"), spec.rows, spec.out_dim)?;
        for buffer in [&input.buffer, &output.buffer, &output_grad.buffer] {
            check_binding(ctx, &label, buffer)?;
        }
        let base = DenseDims {
            x_stride: input.stride,
            x_offset: input.offset,
            y_stride: output.stride,
            y_offset: output.offset,
            dy_stride: output_grad.stride,
            dy_offset: output_grad.offset,
            relu: if dz_given { 0 } else { spec.base_dims().relu },
            ..spec.base_dims()
        };

        let mut dz_written = dz_given;
        let input_grad = match gradients.input_grad {
            None => None,
            Some(input_grad) => {
                let label = format!("{label} input gradient");
                input_grad.check(&label, spec.rows, spec.in_dim)?;
                check_binding(ctx, &label, &input_grad.buffer)?;
                let columns = gradients.input_grad_columns.clone().unwrap_or(0..spec.in_dim);
                if columns.is_empty()
                    || columns.end > spec.in_dim
                    || input_grad.is_bf16() && !columns.start.is_multiple_of(2)
                {
                    return Err(GpuError::invalid_argument(
                        &label,
                        format!(
                            "input gradient columns {columns:?} of {} inputs: a non-empty range inside them, starting at an even column where dX is bf16",
                            spec.in_dim
                        ),
                    ));
                }
                let writes_dz = dz.is_some() && !dz_given;
                let constants = [
                    ("WRITE_DZ", f64::from(u8::from(writes_dz))),
                    bf16_rows("Y_BF16", output),
                    bf16_rows("DY_BF16", output_grad),
                    bf16_rows("DX_BF16", input_grad),
                    ("MASK_DX", f64::from(u8::from(gradients.input_mask.is_some()))),
                    (
                        "MASK_BLOCK",
                        f64::from(gradients.input_mask.map_or(1, |mask| mask.block)),
                    ),
                    ("DX_FIRST", f64::from(columns.start)),
                    ("DX_END", f64::from(columns.end)),
                ];
                if let Some(mask) = gradients.input_mask
                    && mask.width != spec.in_dim
                {
                    return Err(GpuError::invalid_argument(
                        &label,
                        format!("a ReLU mask of {} outputs for {} inputs", mask.width, spec.in_dim),
                    ));
                }
                let (kernel, product_weights, workgroups, family, rows_per_workgroup) = pipelines
                    .product_kernel(
                        ctx,
                        &label,
                        (params, packed),
                        spec,
                        ProductKind::BackwardInput,
                        &constants,
                    )
                    .await?;
                let (weights, weight_offset) = product_weights.binding();
                let dims = DenseDims {
                    dx_stride: input_grad.stride,
                    dx_offset: input_grad.offset,
                    weight_offset,
                    ..base
                };
                let uniform = uniform_buffer_from(ctx, &label, &dims);
                let mut resources = vec![
                    ("dims", uniform.as_entire_binding()),
                    ("dy", output_grad.buffer.as_entire_binding()),
                    ("y", output.buffer.as_entire_binding()),
                    ("weights", weights),
                    ("dx", input_grad.buffer.as_entire_binding()),
                    ("row_count", rows.as_entire_binding()),
                ];
                // The uniform-weight kernel always names `dz_out`; without windows to fill (or
                // with windows an earlier kernel filled, which it reads as dY) it writes nothing
                // there (WRITE_DZ off), so any other buffer does.
                let (unused, unused_mask);
                if family == KernelFamily::UniformWeights {
                    let target = match &dz {
                        Some(dz) if writes_dz => dz,
                        _ => {
                            unused = storage_buffer_zeroed::<f32>(ctx, &format!("{label} (no dZ)"), 4)?;
                            &unused
                        }
                    };
                    resources.push(("dz_out", target.as_entire_binding()));
                    let mask = match gradients.input_mask {
                        Some(mask) => &mask.buffer,
                        None => {
                            unused_mask = storage_buffer_zeroed::<u32>(ctx, &format!("{label} (no mask)"), 4)?;
                            &unused_mask
                        }
                    };
                    resources.push(("relu_mask", mask.as_entire_binding()));
                    dz_written = dz.is_some();
                } else if gradients.input_mask.is_some() {
                    return Err(GpuError::invalid_argument(
                        &label,
                        "only the uniform-weight input gradient stores dX masked by X's ReLU",
                    ));
                }
                let dispatches = bound_product(ctx, kernel, &resources, workgroups, (kept, rows_per_workgroup))?;
                Some((matches!(product_weights, ProductWeights::Packed(_)), dispatches))
            }
        };

        let label = label_dw;
        let shape = TileShape::for_product(spec.in_dim, Some(spec.out_dim));
        let (chunk_rows, chunks) = match uniform_plan {
            Some(plan) => plan,
            None => weight_chunks(ctx, spec, shape)?,
        };
        // Uniform windows: each workgroup sums a span of chunks into one partial matrix.
        let windowed = WeightGradientShape::new(spec, pipelines.uniform_block_limit(ctx));
        let partial_count = match uniform_plan {
            Some(_) => windowed.partials(chunks),
            None => chunks,
        };
        let matrix = spec.in_dim as usize * spec.out_dim as usize;
        let partials =
            storage_buffer_zeroed::<f32>(ctx, &format!("{label} partials"), partial_count as usize * matrix)?;
        let (grads, grad_offset) = range_binding(ctx, &label, gradients.grads, &spec.weights)?;
        let dims = DenseDims {
            chunk_rows,
            chunks: partial_count,
            weight_offset: grad_offset,
            ..base
        };
        let uniform = uniform_buffer_from(ctx, &label, &dims);

        let dz_kept = dz.clone();
        let partial_sums = match dz {
            Some(dz) => WeightPartials::Uniform(
                UniformWeightPartials::new(
                    ctx,
                    pipelines,
                    WindowedLayer {
                        label: &label,
                        spec,
                        dims: &uniform,
                        input,
                        output,
                        output_grad,
                        partials: &partials,
                        shape: windowed,
                        dz,
                        dz_written,
                        chunk_rows,
                        chunks,
                        row_count: &rows,
                        mask_dispatch: kept_dispatch(
                            kept,
                            crate::field::bf16::row_words(spec.out_dim),
                            super::uniform_shape::UNIFORM_WORKGROUP,
                            1,
                        )?,
                    },
                )
                .await?,
            ),
            None => {
                if input.is_bf16() || output.is_bf16() || output_grad.is_bf16() {
                    return Err(GpuError::invalid_argument(
                        &label,
                        "the tiled weight gradient reads f32 rows: bf16 rows need uniform windows",
                    ));
                }
                let pipeline = pipelines.get(ctx, DenseKernel::PartialSums, shape).await?;
                let workgroups = [
                    spec.in_dim.div_ceil(shape.tile_columns()),
                    spec.out_dim.div_ceil(shape.tile_rows()),
                    chunks,
                ];
                WeightPartials::Tiled(bound(
                    ctx,
                    (pipeline, DenseKernel::PartialSums),
                    &[
                        ("dims", uniform.as_entire_binding()),
                        ("dy", output_grad.buffer.as_entire_binding()),
                        ("y", output.buffer.as_entire_binding()),
                        ("x", input.buffer.as_entire_binding()),
                        ("partials", partials.as_entire_binding()),
                        ("row_count", rows.as_entire_binding()),
                    ],
                    workgroups,
                )?)
            }
        };

        let pipeline = pipelines.get(ctx, DenseKernel::ReduceChunks, REDUCE_SHAPE).await?;
        let reduce_groups = Dispatch1d::for_device(ctx, matrix as u64, REDUCE_WORKGROUP)?;
        let reduce = bound(
            ctx,
            (pipeline, DenseKernel::ReduceChunks),
            &[
                ("dims", uniform.as_entire_binding()),
                ("partials", partials.as_entire_binding()),
                ("grads", grads),
            ],
            reduce_groups,
        )?;
        let input_grad_columns = match (&input_grad, &gradients.input_grad_columns) {
            (Some((true, _)), Some(columns)) => columns.clone(),
            _ => 0..spec.in_dim,
        };
        Ok(DenseBackward {
            spec: spec.clone(),
            input_grad,
            partial_sums,
            reduce,
            partials: partial_count,
            dz: dz_kept,
            row_count: rows,
            formats: [
                input.format,
                output.format,
                output_grad.format,
                gradients.input_grad.map_or(RowFormat::F32, |view| view.format),
            ],
            dz_given,
            input_mask_words: gradients.input_mask.map(ReluMask::row_words),
            input_grad_columns,
        })
    }

    /// The buffer of bf16 dZ rows (`crate::field::bf16`) its weight gradient reads, where it
    /// reads one.
    pub fn dz_buffer(&self) -> Option<&wgpu::Buffer> {
        self.dz.as_ref()
    }

    /// Those rows as a view, for the kernel that writes them ([`OutputGradient::InWindows`]).
    pub fn dz_rows(&self) -> Option<RowView> {
        self.dz.as_ref().map(|dz| dz_rows(dz, self.spec.out_dim))
    }

    /// The row-count word its kernels read.
    pub(super) fn row_count(&self) -> &wgpu::Buffer {
        &self.row_count
    }

    /// Bytes its dispatches move through global memory over `rows` rows (every element a
    /// dispatch reads or writes counted once, bf16 rows as their words; dZ = dY masked by the
    /// ReLU reads Y as well, unless dY arrives as dZ):
    /// - dX: dY (and Y) and the weights (or their packed copy) read, dX written (and X's ReLU
    ///   mask bits read where it is stored as the previous layer's dZ), and dZ in padded rows
    ///   where the
    ///   uniform-window weight gradient reads it and no earlier kernel wrote it;
    /// - uniform weight gradient: dZ formed by its own kernel where dX's does not, then X and dZ
    ///   read and every chunk's partial matrix written;
    /// - tiled weight gradient: dY (and Y) and X read, the partial matrices written;
    /// - the reduction: the partial matrices read, the gradient read and written.
    pub fn global_bytes(&self, rows: u64) -> u64 {
        let (i, o) = (u64::from(self.spec.in_dim), u64::from(self.spec.out_dim));
        let relu = u64::from(self.spec.relu && !self.dz_given);
        // dZ's bf16 rows, in words.
        let dz_row = u64::from(crate::field::bf16::row_words(self.spec.out_dim));
        let [x_row, y_row, dy_row, dx_row] = [
            (self.formats[0], self.spec.in_dim),
            (self.formats[1], self.spec.out_dim),
            (self.formats[2], self.spec.out_dim),
            (self.formats[3], self.input_grad_columns.len() as u32),
        ]
        .map(|(format, width)| row_words(format, width));
        let dz_from_dy = rows * (dy_row + relu * y_row);
        // dX's kernel forms the dZ the uniform windows read unless the layer masks it itself
        // or an earlier kernel wrote it.
        let dz_written = matches!(&self.partial_sums, WeightPartials::Uniform(p) if !p.masks());
        let dz_by_input_grad = dz_written && !self.dz_given;
        let mask_reads = rows * u64::from(self.input_mask_words.unwrap_or(0));
        let input_grad = match &self.input_grad {
            None => 0,
            Some((packed, _)) => {
                let weights = if *packed {
                    o * u64::from(padded_to_vec4(self.spec.in_dim))
                } else {
                    i * o
                };
                let dz = if dz_by_input_grad { rows * dz_row } else { 0 };
                dz_from_dy + weights + rows * dx_row + mask_reads + dz
            }
        };
        let partials = u64::from(self.partials) * i * o;
        let weight_grad = match &self.partial_sums {
            WeightPartials::Uniform(_) => {
                let mask = if dz_written { 0 } else { dz_from_dy + rows * dz_row };
                mask + rows * (x_row + dz_row) + partials
            }
            WeightPartials::Tiled(_) => dz_from_dy + rows * x_row + partials,
        };
        WORD * (input_grad + weight_grad + partials + 2 * i * o)
    }

    /// Partial matrices of dW the second kernel sums (one per chunk of rows, or on the
    /// uniform-window path one per span of chunks).
    pub fn partials(&self) -> u32 {
        self.partials
    }

    /// Records dX (if wanted; on the uniform-window path it also writes the dZ that dW reads),
    /// then the dW partial sums and their reduction into the gradient.
    pub fn record(&self, pass: &mut wgpu::ComputePass<'_>) {
        for dispatch in self.input_grad.iter().flat_map(|(_, dispatches)| dispatches) {
            dispatch.record(pass);
        }
        self.partial_sums.record(pass);
        self.reduce.record(pass);
    }

    /// Whether dW reads dZ through uniform windows (the CPU-device kernels).
    pub fn uses_uniform_windows(&self) -> bool {
        matches!(self.partial_sums, WeightPartials::Uniform(_))
    }
}

/// The uniform-window weight gradient's dZ rows of `width` values in `dz` (bf16, each padded to
/// whole vec4<u32>s of 8 values: `dz_windows_buffer`).
fn dz_rows(dz: &wgpu::Buffer, width: u32) -> RowView {
    RowView {
        buffer: dz.clone(),
        stride: 2 * crate::field::bf16::row_words(width),
        offset: 0,
        format: RowFormat::Bf16,
    }
}
