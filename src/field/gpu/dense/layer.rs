//! One dense layer: its spec, the uniform block every dense kernel reads, and its forward and
//! backward bound to their buffers (picking the tiled or uniform-weight kernels per product).
use std::num::NonZeroU64;
use std::ops::Range;

use super::pipelines::{DenseKernel, DensePipelines, ProductKind, ProductWeights};
use super::relu_mask::ReluMask;
use super::tiled::{REDUCE_SHAPE, REDUCE_WORKGROUP, TileShape, weight_chunks};
use super::uniform::{
    UniformWeightPartials, WeightGradientShape, WindowedLayer, dz_windows_buffer, padded_to_vec4, uniform_weight_chunks,
};
use super::{Activation, DenseFamily, RowFormat, RowView, bf16_rows};
use crate::field::gpu::keep::HeadRows;
use crate::gpu::buffers::{storage_buffer_from, storage_buffer_zeroed, uniform_buffer_from};
use crate::gpu::dispatch::{Dispatch, IndirectArgs, bind_named};
use crate::gpu::pipeline::Dispatch1d;
use crate::gpu::{GpuContext, GpuError};

/// Bytes per `f32` element.
const WORD: u64 = 4;

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
    pub activation: Activation,
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
            relu: u32::from(self.activation == Activation::Relu),
            ..DenseDims::default()
        }
    }
}

/// One dispatch per pipeline of a product ([`super::pipelines::ProductKernel`]), each bound to
/// the same resources and launched over the kept rows where there are some.
fn bound_product(
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

fn check_binding(ctx: &GpuContext, what: &str, buffer: &wgpu::Buffer) -> Result<(), GpuError> {
    ctx.ensure_storage_binding_fits(what, buffer.size())
}

/// The word the kernels read the rows present from (`row_count` in `_dense_tile.wgsl`): the
/// kept rows' count, or a word holding all of `spec.rows`.
fn row_count(ctx: &GpuContext, spec: &DenseLayerSpec, kept: Option<&HeadRows>) -> Result<wgpu::Buffer, GpuError> {
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
fn kept_dispatch(
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
    family: DenseFamily,
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
        if relu_mask && (packed.is_none() || spec.activation != Activation::Relu) {
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
            (true, DenseFamily::UniformWeights) => Some(ReluMask::zeroed(
                ctx,
                &format!("{label} ReLU mask"),
                spec.rows,
                spec.out_dim,
                pipelines.uniform_product_block(ctx, spec.out_dim),
            )?),
            (true, DenseFamily::Tiled) => {
                return Err(GpuError::invalid_argument(
                    &label,
                    "the tiled forward stores no mask bits",
                ));
            }
            (false, _) => None,
        };
        let unused;
        if family == DenseFamily::UniformWeights {
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
    pub fn family(&self) -> DenseFamily {
        self.family
    }

    pub fn record(&self, pass: &mut wgpu::ComputePass<'_>) {
        for dispatch in &self.dispatches {
            dispatch.record(pass);
        }
    }
}

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
        pipelines: &mut DensePipelines,
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
            DenseFamily::UniformWeights => uniform_weight_chunks(ctx, spec),
            DenseFamily::Tiled => None,
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
                if family == DenseFamily::UniformWeights {
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
                            super::uniform::UNIFORM_WORKGROUP,
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
        let relu = u64::from(self.spec.activation == Activation::Relu && !self.dz_given);
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
