//! The uniform-weight dense kernels (`shaders/dense_*_uniform.wgsl`), used on CPU devices: one
//! invocation per row with a packed copy of the layer's weights in a uniform binding, and the
//! weight gradient read through 64 KiB uniform windows of dZ, one per chunk of rows, up to
//! [`WINDOWS_PER_DISPATCH`] chunks per dispatch.
use std::num::NonZeroU64;

use super::pipelines::bound;
use super::pipelines::{DenseKernel, DenseKernels, ProductKind};
use super::spec::{DenseLayerSpec, padded_to_vec4, range_binding};
use super::uniform_shape::{
    PackedReads, UNIFORM_WEIGHT_FLOATS, UNIFORM_WORKGROUP, packed_window_alignment, uniform_block,
};
use super::{RowView, bf16_rows};
use crate::field::bf16;
use crate::gpu::KernelFamily;
use crate::gpu::buffers::uniform_buffer_from;
use crate::gpu::dispatch::{Dispatch, IndirectArgs, bind_named};
use crate::gpu::pipeline::{Dispatch1d, KernelSpec, create_compute_pipeline};
use crate::gpu::{GpuContext, GpuError};

/// Chunks of rows one weight-gradient dispatch sums, each through its own 64 KiB window
/// (`dz0` .. `dz7` in `shaders/dense_backward_weight_uniform.wgsl`). With the layer's `dims` and
/// the chunk slot that is 10 uniform bindings, within WebGPU's default 12 per stage.
pub(super) const WINDOWS_PER_DISPATCH: u32 = 8;

/// Workgroups a full weight-gradient dispatch keeps at least, where summing several chunks per
/// workgroup would leave fewer: a CPU device runs a workgroup on one thread, so fewer would idle
/// its cores.
const MIN_WORKGROUPS_PER_DISPATCH: u32 = 4;

/// How the uniform-window weight gradient of a layer splits its work: lanes (input columns) per
/// workgroup, outputs per workgroup, the workgroup counts over columns and outputs, and how
/// many consecutive chunks one workgroup sums into one partial matrix (SPAN in
/// `shaders/_dense_chunk_sums.wgsl`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) struct WeightGradientShape {
    pub columns: u32,
    pub block: u32,
    pub workgroups: [u32; 2],
    pub span: u32,
}

impl WeightGradientShape {
    /// Every partial matrix is written once and read once by the reduction, so a workgroup
    /// sums as many chunks as it can (up to the [`WINDOWS_PER_DISPATCH`] a dispatch binds)
    /// while a full dispatch keeps [`MIN_WORKGROUPS_PER_DISPATCH`] workgroups.
    pub(super) fn new(spec: &DenseLayerSpec, block_limit: u32) -> WeightGradientShape {
        let block = weight_gradient_block(spec.out_dim, block_limit);
        let columns = spec.in_dim.next_power_of_two().clamp(8, UNIFORM_WORKGROUP);
        let workgroups = [spec.in_dim.div_ceil(columns), spec.out_dim.div_ceil(block)];
        let per_slot = workgroups[0] * workgroups[1];
        let mut span = WINDOWS_PER_DISPATCH;
        while span > 1 && WINDOWS_PER_DISPATCH / span * per_slot < MIN_WORKGROUPS_PER_DISPATCH {
            span /= 2;
        }
        WeightGradientShape {
            columns,
            block,
            workgroups,
            span,
        }
    }

    /// Partial matrices the reduction sums for `chunks` chunks.
    pub(super) fn partials(&self, chunks: u32) -> u32 {
        chunks.div_ceil(self.span)
    }
}

/// Mirrors `ChunkInfo` in `shaders/dense_backward_weight_uniform.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct ChunkInfo {
    first: u32,
    _pad: [u32; 3],
}

/// What the uniform-window weight gradient of one layer reads and writes.
pub(super) struct WindowedLayer<'a> {
    pub label: &'a str,
    pub spec: &'a DenseLayerSpec,
    /// The layer's `DenseDims` uniform buffer.
    pub dims: &'a wgpu::Buffer,
    /// X, the activated Y and dY of the forward.
    pub input: &'a RowView,
    pub output: &'a RowView,
    pub output_grad: &'a RowView,
    /// Where each span of chunks' partial dW goes.
    pub partials: &'a wgpu::Buffer,
    pub shape: WeightGradientShape,
    /// dZ in padded rows (from [`dz_windows_buffer`]), and whether the input gradient's kernel
    /// writes it (then this layer records no masking kernel).
    pub dz: wgpu::Buffer,
    pub dz_written: bool,
    /// From [`uniform_weight_chunks`].
    pub chunk_rows: u32,
    pub chunks: u32,
    /// The word holding the rows present (`row_count` in `_dense_tile.wgsl`).
    pub row_count: &'a wgpu::Buffer,
    /// The masking kernel's workgroup counts when the rows are the kept ones.
    pub mask_dispatch: Option<IndirectArgs>,
}

pub(super) struct UniformWeightPartials {
    /// Forms dZ where dX's kernel does not.
    mask: Option<Dispatch>,
    pipeline: wgpu::ComputePipeline,
    common: wgpu::BindGroup,
    /// One bind group per dispatch: its first chunk's slot and its chunks' dZ windows, with the
    /// number of partial matrices it writes (its workgroups' z).
    windows: Vec<(wgpu::BindGroup, u32)>,
    workgroups: [u32; 2],
    /// Owned so the bind groups' buffers live as long as the pass.
    _buffers: [wgpu::Buffer; 2],
}

impl UniformWeightPartials {
    pub(super) async fn new(
        ctx: &GpuContext,
        pipelines: &mut DenseKernels,
        layer: WindowedLayer<'_>,
    ) -> Result<Self, GpuError> {
        let WindowedLayer {
            label,
            spec,
            dims,
            input,
            output,
            output_grad,
            partials,
            shape,
            dz,
            dz_written,
            chunk_rows,
            chunks,
            row_count,
            mask_dispatch,
        } = layer;
        let span = shape.span;
        let window_words = chunk_rows as usize * bf16::row_words(spec.out_dim) as usize;
        let reads = pipelines.packed_reads();
        let info_stride = ctx.limits.min_uniform_buffer_offset_alignment.max(16);
        // Windows bind one chunk each; from storage one dispatch sums as many spans of chunks
        // as its z dimension allows. Either way a dispatch starts at a whole span.
        let per_dispatch = match reads {
            PackedReads::Uniform => WINDOWS_PER_DISPATCH,
            PackedReads::Storage => ctx.limits.max_compute_workgroups_per_dimension.max(1) * span,
        };
        let dispatches = chunks.div_ceil(per_dispatch);
        let mut infos = vec![0u8; dispatches as usize * info_stride as usize];
        for d in 0..dispatches {
            let info = ChunkInfo {
                first: d * per_dispatch,
                _pad: [0; 3],
            };
            let at = (d * info_stride) as usize;
            infos[at..at + size_of::<ChunkInfo>()].copy_from_slice(bytemuck::bytes_of(&info));
        }
        let info = wgpu::util::DeviceExt::create_buffer_init(
            &ctx.device,
            &wgpu::util::BufferInitDescriptor {
                label: Some(&format!("{label} chunk slots")),
                contents: &infos,
                usage: wgpu::BufferUsages::UNIFORM,
            },
        );

        let mask = if dz_written {
            None
        } else {
            let mask_pipeline = pipelines
                .compile(
                    ctx,
                    DenseKernel::MaskOutputGradient,
                    &[bf16_rows("Y_BF16", output), bf16_rows("DY_BF16", output_grad)],
                )
                .await?;
            let groups = Dispatch1d::for_device(
                ctx,
                u64::from(spec.rows) * u64::from(bf16::row_words(spec.out_dim)),
                UNIFORM_WORKGROUP,
            )?;
            let mask = bound(
                ctx,
                (mask_pipeline, DenseKernel::MaskOutputGradient),
                &[
                    ("dims", dims.as_entire_binding()),
                    ("dy", output_grad.buffer.as_entire_binding()),
                    ("y", output.buffer.as_entire_binding()),
                    ("dz_out", dz.as_entire_binding()),
                    ("row_count", row_count.as_entire_binding()),
                ],
                groups,
            )?
            .with_indirect(mask_dispatch);
            Some(mask)
        };

        let (pipeline, layouts) = pipelines.chunk_sums_pipeline(ctx, &shape, (input, output)).await?;
        let sums = pipelines.chunk_sums_kernel().spec();
        let common = bind_named(
            ctx,
            &sums,
            &layouts[0],
            0,
            &[
                ("dims", dims.as_entire_binding()),
                ("x", input.buffer.as_entire_binding()),
                ("partials", partials.as_entire_binding()),
                ("row_count", row_count.as_entire_binding()),
            ],
        )?;
        let window_bytes = (window_words * 4) as u64;
        let window_names = ["dz0", "dz1", "dz2", "dz3", "dz4", "dz5", "dz6", "dz7"];
        let mut windows = Vec::with_capacity(dispatches as usize);
        for d in 0..dispatches {
            let first = d * per_dispatch;
            let count = (chunks - first).min(per_dispatch);
            let mut entries = vec![(
                "chunk",
                wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                    buffer: &info,
                    offset: u64::from(d * info_stride),
                    size: NonZeroU64::new(size_of::<ChunkInfo>() as u64),
                }),
            )];
            if reads == PackedReads::Storage {
                entries.push(("dz", dz.as_entire_binding()));
                windows.push((bind_named(ctx, &sums, &layouts[1], 1, &entries)?, count.div_ceil(span)));
                continue;
            }
            // Slots past the last chunk are never read; they bind the first chunk's window.
            for (slot, name) in window_names.iter().enumerate() {
                let c = if (slot as u32) < count {
                    first + slot as u32
                } else {
                    first
                };
                entries.push((
                    name,
                    wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                        buffer: &dz,
                        offset: u64::from(c) * window_bytes,
                        size: NonZeroU64::new(UNIFORM_WEIGHT_FLOATS as u64 * 4),
                    }),
                ));
            }
            windows.push((bind_named(ctx, &sums, &layouts[1], 1, &entries)?, count.div_ceil(span)));
        }
        Ok(UniformWeightPartials {
            mask,
            pipeline,
            common,
            windows,
            workgroups: shape.workgroups,
            _buffers: [dz, info],
        })
    }

    /// Whether this layer forms dZ with its own masking kernel (dX's kernel does otherwise).
    pub(super) fn masks(&self) -> bool {
        self.mask.is_some()
    }

    pub(super) fn record(&self, pass: &mut wgpu::ComputePass<'_>) {
        if let Some(mask) = &self.mask {
            mask.record(pass);
        }
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, &self.common, &[]);
        for (windows, count) in &self.windows {
            pass.set_bind_group(1, windows, &[]);
            pass.dispatch_workgroups(self.workgroups[0], self.workgroups[1], *count);
            crate::gpu::pipeline::count_dispatch();
        }
    }
}

/// The outputs one workgroup of the uniform-window weight gradient sums: as
/// [`uniform_block`], but where the layer takes more than one block each is a multiple of 8, so
/// that every block starts at a whole vec4<u32> of the bf16 dZ rows (a device limit of 4 then
/// gets 8).
pub(super) fn weight_gradient_block(out_dim: u32, limit: u32) -> u32 {
    let block = uniform_block(out_dim, limit);
    if block >= out_dim {
        return block;
    }
    let blocks = out_dim.div_ceil(limit.max(8) / 8 * 8);
    bf16::padded_to_vec8(out_dim.div_ceil(blocks))
}

/// The buffer the uniform-window weight gradient reads dZ from: `chunks` windows of
/// `chunk_rows` bf16 rows (`crate::field::bf16`), the last one UNIFORM_WEIGHT_FLOATS words long
/// from its start like every other.
pub(super) fn dz_windows_buffer(
    ctx: &GpuContext,
    label: &str,
    spec: &DenseLayerSpec,
    chunk_rows: u32,
    chunks: u32,
) -> Result<wgpu::Buffer, GpuError> {
    let window_words = chunk_rows as usize * bf16::row_words(spec.out_dim) as usize;
    let dz_words = (chunks as usize - 1) * window_words + UNIFORM_WEIGHT_FLOATS;
    ctx.ensure_storage_binding_fits(label, dz_words as u64 * 4)?;
    Ok(ctx.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(&format!("{label} dZ")),
        size: dz_words as u64 * 4,
        // COPY_DST, COPY_SRC: tests fill it with garbage and read back what was stored.
        usage: wgpu::BufferUsages::STORAGE
            | wgpu::BufferUsages::UNIFORM
            | wgpu::BufferUsages::COPY_DST
            | wgpu::BufferUsages::COPY_SRC,
        mapped_at_creation: false,
    }))
}

/// Rows per chunk and chunk count for the uniform-window weight gradient: as many bf16 dZ rows
/// as fit a 64 KiB window, each window starting at an offset the device accepts for uniform
/// bindings; `None` when the partial matrices would not fit one storage binding (then: tiled).
pub(super) fn uniform_weight_chunks(ctx: &GpuContext, spec: &DenseLayerSpec) -> Option<(u32, u32)> {
    if (ctx.limits.max_uniform_buffer_binding_size as usize) < UNIFORM_WEIGHT_FLOATS * 4 {
        return None;
    }
    // Words per dZ row: bf16 pairs, whole vec4<u32>s.
    let out = bf16::row_words(spec.out_dim) as usize;
    if out > UNIFORM_WEIGHT_FLOATS {
        return None;
    }
    let align = (ctx.limits.min_uniform_buffer_offset_alignment.max(4) / 4) as usize;
    // chunk_rows · out must be a multiple of `align` words.
    let step = align / gcd(out, align);
    let chunk_rows = (UNIFORM_WEIGHT_FLOATS / out) / step * step;
    if chunk_rows == 0 {
        return None;
    }
    let chunks = (spec.rows as usize).div_ceil(chunk_rows);
    let partial_bytes = chunks as u64 * u64::from(spec.out_dim) * u64::from(spec.in_dim) * 4;
    let dz_bytes = ((chunks - 1) * chunk_rows * out + UNIFORM_WEIGHT_FLOATS) as u64 * 4;
    let limit = ctx
        .limits
        .max_storage_buffer_binding_size
        .min(ctx.limits.max_buffer_size);
    (partial_bytes <= limit && dz_bytes <= limit).then_some((chunk_rows as u32, chunks as u32))
}

fn gcd(a: usize, b: usize) -> usize {
    if b == 0 { a } else { gcd(b, a % b) }
}

impl DenseKernels {
    /// The per-chunk weight-gradient kernel, with an explicit layout (its dZ windows are bound
    /// as 64 KiB ranges of a larger buffer, or dZ whole from storage), and its two bind group
    /// layouts.
    pub(super) async fn chunk_sums_pipeline(
        &self,
        ctx: &GpuContext,
        shape: &WeightGradientShape,
        (x, y): (&RowView, &RowView),
    ) -> Result<(wgpu::ComputePipeline, [wgpu::BindGroupLayout; 2]), GpuError> {
        let entry = |binding, ty, min: Option<u64>| wgpu::BindGroupLayoutEntry {
            binding,
            visibility: wgpu::ShaderStages::COMPUTE,
            ty: wgpu::BindingType::Buffer {
                ty,
                has_dynamic_offset: false,
                min_binding_size: min.and_then(NonZeroU64::new),
            },
            count: None,
        };
        let storage = |read_only| wgpu::BufferBindingType::Storage { read_only };
        let common = [
            entry(0, wgpu::BufferBindingType::Uniform, None),
            entry(3, storage(true), None),
            entry(4, storage(false), None),
            entry(7, storage(true), None),
        ];
        let slot = std::iter::once(entry(0, wgpu::BufferBindingType::Uniform, Some(16)));
        let windows: Vec<wgpu::BindGroupLayoutEntry> = match self.packed_reads() {
            PackedReads::Uniform => slot
                .chain((1..=WINDOWS_PER_DISPATCH).map(|binding| {
                    entry(
                        binding,
                        wgpu::BufferBindingType::Uniform,
                        Some(UNIFORM_WEIGHT_FLOATS as u64 * 4),
                    )
                }))
                .collect(),
            PackedReads::Storage => slot.chain(std::iter::once(entry(1, storage(true), Some(16)))).collect(),
        };
        let (label, source, entry_point) = self.chunk_sums_kernel().source();
        let spec = KernelSpec {
            label,
            source,
            entry_point,
            layout: Some(&[&common, &windows]),
            constants: &[
                ("BLOCK", f64::from(shape.block)),
                ("COLUMNS", f64::from(shape.columns)),
                ("SPAN", f64::from(shape.span)),
                bf16_rows("X_BF16", x),
                bf16_rows("Y_BF16", y),
            ],
        };
        let pipeline = create_compute_pipeline(ctx, &spec).await?;
        // The context hands out the very layouts the pipeline was built with.
        let common = ctx.bind_group_layout("dense chunk sums common", &common);
        let windows = ctx.bind_group_layout("dense chunk sums windows", &windows);
        Ok((pipeline, [common, windows]))
    }

    /// Whether the uniform-weight kernel of `kind` can run `spec`: the family wants it, the
    /// device binds 64 KiB uniforms, and the packed matrix fits one.
    pub(super) fn packs(&self, ctx: &GpuContext, spec: &DenseLayerSpec, kind: ProductKind) -> bool {
        let (rows, columns) = packed_shape(spec, kind);
        self.family == KernelFamily::UniformWeights
            && (ctx.limits.max_uniform_buffer_binding_size as usize) >= UNIFORM_WEIGHT_FLOATS * 4
            && rows as usize * padded_to_vec4(columns) as usize <= UNIFORM_WEIGHT_FLOATS
    }
}

/// Rows and columns of a layer's packed copy for `kind`: [in][out] for the forward, [out][in]
/// for the input gradient.
fn packed_shape(spec: &DenseLayerSpec, kind: ProductKind) -> (u32, u32) {
    match kind {
        ProductKind::Forward => (spec.in_dim, spec.out_dim),
        ProductKind::BackwardInput => (spec.out_dim, spec.in_dim),
    }
}

/// Mirrors `PackJob` in `shaders/dense_pack_weights.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct PackJob {
    src: u32,
    rows: u32,
    columns: u32,
    transposed: u32,
    dst: u32,
    _pad: [u32; 3],
}

/// Jobs one packing dispatch takes (`MAX_PACK_JOBS` in the shader).
const MAX_PACK_JOBS: usize = 8;

/// Every packed weight copy one MLP's uniform-weight kernels read, in one buffer, and the one
/// dispatch that refreshes them all (`shaders/dense_pack_weights.wgsl`), recorded before the
/// MLP's forward: one dispatch per MLP and step instead of one per product.
pub(super) struct MlpPacking {
    /// (layer, product) → byte offset and size of its packed copy in `buffer`.
    slots: Vec<((usize, ProductKind), u64, u64)>,
    /// What refreshing them moves: every copied weight read, every packed value written.
    bytes: u64,
    buffer: Option<wgpu::Buffer>,
    /// One dispatch per MAX_PACK_JOBS copies (one for MLPs of up to 4 layers).
    packs: Vec<Dispatch>,
}

impl MlpPacking {
    /// Packs layer k's forward copy where its uniform kernel runs, and its input-gradient copy
    /// too where `input_grads[k]` (the backward computes dX of that layer).
    pub(super) async fn new(
        ctx: &GpuContext,
        pipelines: &DenseKernels,
        label: &str,
        params: &wgpu::Buffer,
        specs: &[DenseLayerSpec],
        input_grads: &[bool],
    ) -> Result<MlpPacking, GpuError> {
        let mut wanted = Vec::new();
        for (k, spec) in specs.iter().enumerate() {
            for kind in [ProductKind::Forward, ProductKind::BackwardInput] {
                let needed = kind == ProductKind::Forward || input_grads.get(k).copied().unwrap_or(false);
                if needed && pipelines.packs(ctx, spec, kind) {
                    wanted.push((k, kind));
                }
            }
        }
        if wanted.is_empty() {
            return Ok(MlpPacking {
                slots: Vec::new(),
                bytes: 0,
                buffer: None,
                packs: Vec::new(),
            });
        }
        let start = specs.iter().map(|s| s.weights.start).min().unwrap_or(0);
        let end = specs.iter().map(|s| s.weights.end).max().unwrap_or(0);
        let (source, local) = range_binding(ctx, label, params, &(start..end))?;
        let align = u64::from(packed_window_alignment(ctx));
        let (mut slots, mut jobs) = (Vec::new(), Vec::new());
        let (mut offset, mut bytes) = (0u64, 0u64);
        for &(k, kind) in &wanted {
            let spec = &specs[k];
            let (rows, columns) = packed_shape(spec, kind);
            let transposed = kind == ProductKind::Forward;
            jobs.push(PackJob {
                src: local + (spec.weights.start - start) as u32,
                rows,
                columns,
                transposed: u32::from(transposed),
                dst: (offset / 4) as u32,
                _pad: [0; 3],
            });
            let floats = rows * padded_to_vec4(columns);
            slots.push(((k, kind), offset, u64::from(floats) * 4));
            bytes += 4 * (u64::from(rows) * u64::from(columns) + u64::from(floats));
            offset = (offset + u64::from(floats) * 4).div_ceil(align) * align;
        }
        // Each kernel binds a whole 64 KiB window from its copy's start, the last one included.
        let last = slots.last().map_or(0, |(_, at, _)| *at);
        let size = last + UNIFORM_WEIGHT_FLOATS as u64 * 4;
        ctx.ensure_storage_binding_fits(label, size)?;
        let buffer = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(&format!("{label} packed weights")),
            size,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::UNIFORM,
            mapped_at_creation: false,
        });
        let pipeline = pipelines.compile(ctx, DenseKernel::PackWeights, &[]).await?;
        let mut packs = Vec::new();
        for batch in jobs.chunks(MAX_PACK_JOBS) {
            let most = batch
                .iter()
                .map(|j| j.rows * padded_to_vec4(j.columns))
                .max()
                .unwrap_or(0);
            let mut table = [<PackJob as bytemuck::Zeroable>::zeroed(); MAX_PACK_JOBS];
            table[..batch.len()].copy_from_slice(batch);
            let table = uniform_buffer_from(ctx, &format!("{label} packing jobs"), &table);
            let groups = Dispatch1d::for_device(ctx, u64::from(most), UNIFORM_WORKGROUP)?;
            packs.push(bound(
                ctx,
                (pipeline.clone(), DenseKernel::PackWeights),
                &[
                    ("jobs", table.as_entire_binding()),
                    ("params", source.clone()),
                    ("packed", buffer.as_entire_binding()),
                ],
                [groups.x, groups.y, batch.len() as u32],
            )?);
        }
        Ok(MlpPacking {
            slots,
            bytes,
            buffer: Some(buffer),
            packs,
        })
    }

    /// The 64 KiB window holding layer `layer`'s packed copy for `kind`, if it has one.
    pub(super) fn window(&self, layer: usize, kind: ProductKind) -> Option<wgpu::BindingResource<'_>> {
        let buffer = self.buffer.as_ref()?;
        let &(_, offset, _) = self.slots.iter().find(|(slot, _, _)| *slot == (layer, kind))?;
        Some(wgpu::BindingResource::Buffer(wgpu::BufferBinding {
            buffer,
            offset,
            size: NonZeroU64::new(UNIFORM_WEIGHT_FLOATS as u64 * 4),
        }))
    }

    /// Where layer `layer`'s packed copy for `kind` starts, in vec4s from the start of the window
    /// of layer `from`'s input-gradient copy; `None` unless both exist and the copy ends inside
    /// that window.
    pub(super) fn vec4_index_from(&self, from: usize, layer: usize, kind: ProductKind) -> Option<u32> {
        let find = |layer, kind| self.slots.iter().find(|(slot, _, _)| *slot == (layer, kind));
        let &(_, start, _) = find(from, ProductKind::BackwardInput)?;
        let &(_, offset, size) = find(layer, kind)?;
        let end = offset.checked_sub(start)? + size;
        (end <= UNIFORM_WEIGHT_FLOATS as u64 * 4).then_some(((offset - start) / 16) as u32)
    }

    /// Bytes one refresh moves: every copied weight read and every packed value written.
    pub(super) fn global_bytes(&self) -> u64 {
        self.bytes
    }

    pub(super) fn record(&self, pass: &mut wgpu::ComputePass<'_>) {
        for pack in &self.packs {
            pack.record(pass);
        }
    }
}

#[cfg(test)]
#[path = "uniform_tests.rs"]
mod tests;
