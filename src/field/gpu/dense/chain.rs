//! The input gradients of a whole MLP in one dispatch on CPU devices
//! (`shaders/dense_backward_chain_uniform.wgsl`): each invocation walks its row from the last
//! layer to the first with every hidden layer's dX in registers, and writes each layer's dZ
//! where its uniform-window weight gradient reads it. Each layer's [`super::DenseBackward`]
//! then records its weight gradient alone.
//!
//! An MLP qualifies when it runs the uniform-weight family, has 2 or 3 layers (the kernel's
//! storage bindings: dY, two hidden outputs, three dZ, dX and the row count are WebGPU's default
//! 8), every hidden width fits the device's widest uniform block (one invocation holds a whole
//! hidden dX), the output is at most `MAX_UNROLLED` wide (the kernel reads dY written out quad
//! by quad), every layer's weight gradient reads dZ through uniform windows, and the packed
//! copies the walk multiplies by lie in one 64 KiB window. Otherwise each layer keeps its own
//! input-gradient kernel.
use super::pipelines::bound;
use super::pipelines::{DenseKernel, DenseKernels, ProductKind};
use super::spec::{DenseDims, DenseLayerSpec, padded_to_vec4};
use super::uniform::{MlpPacking, uniform_weight_chunks};
use super::uniform_shape::{MAX_UNROLLED, UNIFORM_WORKGROUP, uniform_block, uniform_dispatch};
use super::{RowFormat, RowView, bf16_rows};
use crate::field::gpu::keep::HeadRows;
use crate::gpu::KernelFamily;
use crate::gpu::buffers::{storage_buffer_zeroed, uniform_buffer_from};
use crate::gpu::dispatch::Dispatch;
use crate::gpu::{GpuContext, GpuError};

/// Mirrors `ChainDims` in `shaders/dense_backward_chain_uniform.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, bytemuck::Pod, bytemuck::Zeroable)]
struct ChainDims {
    y0_stride: u32,
    y0_offset: u32,
    y1_stride: u32,
    y1_offset: u32,
}

/// Storage buffers the chain kernel binds.
const CHAIN_STORAGE_BINDINGS: u32 = 8;

/// Whether the MLP of `specs` (with the packed copies of `packing`) can run its input gradients
/// as one chain on `ctx`: the block one invocation computes, or `None`.
pub(super) fn chain_block(
    ctx: &GpuContext,
    pipelines: &DenseKernels,
    specs: &[DenseLayerSpec],
    packing: &MlpPacking,
    input_grad: bool,
) -> Option<u32> {
    if pipelines.family != KernelFamily::UniformWeights
        || !pipelines.input_gradient_chain(ctx)
        || !(2..=3).contains(&specs.len())
        || ctx.limits.max_storage_buffers_per_shader_stage < CHAIN_STORAGE_BINDINGS
    {
        return None;
    }
    let limit = pipelines.uniform_block_limit(ctx);
    let hidden = specs[1..].iter().map(|s| padded_to_vec4(s.in_dim)).max()?;
    let last = specs[specs.len() - 1].out_dim;
    if hidden > limit || last > MAX_UNROLLED || specs.iter().any(|s| uniform_weight_chunks(ctx, s).is_none()) {
        return None;
    }
    chain_weights(packing, specs.len(), input_grad)?;
    Some(hidden.max(uniform_block(specs[0].in_dim, limit)))
}

/// The window of packed copies the walk multiplies by (layer 0's only when the input wants its
/// gradient) and each layer's copy in it as a vec4 index; `None` unless all lie in one window.
fn chain_weights(packing: &MlpPacking, layers: usize, input_grad: bool) -> Option<(usize, [u32; 3])> {
    let first = usize::from(!input_grad);
    let mut base = [0u32; 3];
    for (k, slot) in base.iter_mut().enumerate().take(layers).skip(first) {
        *slot = packing.vec4_index_from(first, k, ProductKind::BackwardInput)?;
    }
    Some((first, base))
}

/// What the chain reads and writes, beside the layers' specs.
pub(super) struct ChainDesc<'a> {
    pub label: &'a str,
    pub specs: &'a [DenseLayerSpec],
    pub block: u32,
    /// Each layer's output (the hidden ones are masked by).
    pub outputs: &'a [RowView],
    pub output_grad: &'a RowView,
    pub input_grad: Option<&'a RowView>,
    /// Each layer's dZ buffer (the one its weight gradient reads through uniform windows).
    pub dz: Vec<wgpu::Buffer>,
    pub row_count: &'a wgpu::Buffer,
    pub kept: Option<&'a HeadRows>,
}

/// One MLP's input gradients as one dispatch.
pub(super) struct BackwardChain {
    /// One per block of the first layer's dX.
    dispatches: Vec<Dispatch>,
    widths: Vec<u32>,
    /// How it stores the MLP's input gradient, where it writes one.
    input_grad: Option<RowFormat>,
    blocks: u32,
    /// How the hidden outputs it masks with are stored.
    hidden: RowFormat,
}

impl BackwardChain {
    pub(super) async fn new(
        ctx: &GpuContext,
        pipelines: &DenseKernels,
        packing: &MlpPacking,
        desc: ChainDesc<'_>,
    ) -> Result<BackwardChain, GpuError> {
        let ChainDesc {
            label,
            specs,
            block,
            outputs,
            output_grad,
            input_grad,
            dz,
            row_count,
            kept,
        } = desc;
        let layers = specs.len();
        let label = format!("{label} input gradients");
        let (first, base) = chain_weights(packing, layers, input_grad.is_some())
            .ok_or_else(|| GpuError::invalid_argument(&label, "the packed weights are not in one window"))?;
        let window = packing
            .window(first, ProductKind::BackwardInput)
            .ok_or_else(|| GpuError::invalid_argument(&label, "no packed weights"))?;
        if dz.len() != layers || outputs.len() != layers {
            return Err(GpuError::invalid_argument(
                &label,
                format!(
                    "{} dZ buffers and {} outputs for {layers} layers",
                    dz.len(),
                    outputs.len()
                ),
            ));
        }
        let mut widths: Vec<u32> = specs.iter().map(|s| s.in_dim).collect();
        widths.push(specs[layers - 1].out_dim);
        let rows = specs[0].rows;
        // A binding the specialised kernel never touches still needs a buffer, one of its own:
        // one buffer bound both read-only and writable is a validation error.
        let unused = |what: &str| storage_buffer_zeroed::<f32>(ctx, &format!("{label} (no {what})"), 4);
        let (no_dx, no_y_upper, no_dz2) = (unused("dX")?, unused("Y_1")?, unused("dZ_2")?);
        let view = |k: usize| outputs.get(k).filter(|_| k + 1 < layers);
        let hidden0 = view(0).ok_or_else(|| GpuError::invalid_argument(&label, "no hidden layer"))?;
        if view(1).is_some_and(|upper| upper.format != hidden0.format) {
            return Err(GpuError::invalid_argument(
                &label,
                "the hidden outputs differ in format",
            ));
        }
        let y0 = (hidden0.stride, hidden0.offset);
        let y1 = view(1).map_or((0, 0), |v| (v.stride, v.offset));
        let dims = DenseDims {
            rows,
            in_dim: widths[0],
            out_dim: widths[layers],
            dy_stride: output_grad.stride,
            dy_offset: output_grad.offset,
            dx_stride: input_grad.map_or(0, |v| v.stride),
            dx_offset: input_grad.map_or(0, |v| v.offset),
            ..DenseDims::default()
        };
        let chain = ChainDims {
            y0_stride: y0.0,
            y0_offset: y0.1,
            y1_stride: y1.0,
            y1_offset: y1.1,
        };
        let width = |j: usize| f64::from(widths.get(j).copied().unwrap_or(0));
        let blocks = if input_grad.is_some() {
            widths[0].div_ceil(block)
        } else {
            1
        };
        let workgroups = uniform_dispatch(ctx, rows, block, block)?;
        let dims = uniform_buffer_from(ctx, &label, &dims);
        let chain = uniform_buffer_from(ctx, &format!("{label} layers"), &chain);
        fn or<'a>(buffer: Option<&'a wgpu::Buffer>, unused: &'a wgpu::Buffer) -> wgpu::BindingResource<'a> {
            buffer.unwrap_or(unused).as_entire_binding()
        }
        let mut dispatches = Vec::with_capacity(blocks as usize);
        for dx_block in 0..blocks {
            let constants = [
                ("BLOCK", f64::from(block)),
                ("LAYERS", layers as f64),
                ("D0", width(0)),
                ("D1", width(1)),
                ("D2", width(2)),
                ("D3", width(3)),
                ("WRITE_DX", f64::from(u8::from(input_grad.is_some()))),
                ("W0", f64::from(base[0])),
                ("W1", f64::from(base[1])),
                ("W2", f64::from(base[2])),
                ("FIXED_BLOCK", f64::from(dx_block)),
                bf16_rows("Y_BF16", hidden0),
                ("DX_BF16", f64::from(u8::from(input_grad.is_some_and(RowView::is_bf16)))),
            ];
            let pipeline = pipelines
                .compile(ctx, DenseKernel::BackwardChainUniform, &constants)
                .await?;
            let dispatch = bound(
                ctx,
                (pipeline, DenseKernel::BackwardChainUniform),
                &[
                    ("dims", dims.as_entire_binding()),
                    ("dy", output_grad.buffer.as_entire_binding()),
                    ("y", hidden0.buffer.as_entire_binding()),
                    ("weights", window.clone()),
                    ("dx", or(input_grad.map(|v| &v.buffer), &no_dx)),
                    ("y_upper", or(view(1).map(|v| &v.buffer), &no_y_upper)),
                    ("chain", chain.as_entire_binding()),
                    ("dz0", dz[0].as_entire_binding()),
                    ("dz1", dz[1].as_entire_binding()),
                    ("dz2", or(dz.get(2), &no_dz2)),
                    ("row_count", row_count.as_entire_binding()),
                ],
                workgroups,
            )?
            .with_indirect(kept.map(|kept| kept.dispatch(1, UNIFORM_WORKGROUP, 1)).transpose()?);
            dispatches.push(dispatch);
        }
        Ok(BackwardChain {
            dispatches,
            widths,
            input_grad: input_grad.map(|view| view.format),
            blocks,
            hidden: hidden0.format,
        })
    }

    /// Bytes it moves over `rows` rows (every element a dispatch reads or writes counted once
    /// per block of the first layer's dX, since each block redoes the walk): dY and the hidden
    /// outputs (in their format) read, the packed weights read, every layer's dZ written in bf16 rows, dX
    /// written.
    pub(super) fn global_bytes(&self, rows: u64) -> u64 {
        let w: Vec<u64> = self.widths.iter().map(|&d| u64::from(d)).collect();
        let layers = w.len() - 1;
        let hidden: u64 = w[1..layers].iter().sum();
        let first_fed = usize::from(self.input_grad.is_none());
        let weights: u64 = (first_fed..layers)
            .map(|k| w[k + 1] * u64::from(padded_to_vec4(self.widths[k])))
            .sum();
        let hidden = match self.hidden {
            RowFormat::F32 => hidden,
            RowFormat::Bf16 => w[1..layers].iter().map(|d| d.div_ceil(2)).sum(),
        };
        let reads = rows * (w[layers] + hidden) + weights;
        let dz: u64 = w[1..]
            .iter()
            .map(|&d| rows * u64::from(crate::field::bf16::row_words(d as u32)))
            .sum();
        let dx = self
            .input_grad
            .map_or(0, |format| RowView::words(format, rows as u32, self.widths[0]));
        4 * (u64::from(self.blocks) * reads + dz + dx)
    }

    pub(super) fn record(&self, pass: &mut wgpu::ComputePass<'_>) {
        for dispatch in &self.dispatches {
            dispatch.record(pass);
        }
    }
}
