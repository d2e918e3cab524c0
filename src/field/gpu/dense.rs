//! Bias-free dense layers and whole MLPs on the GPU, the twin of `reference::mlp`.
//!
//! One layer over N rows computes `Y[n][o] = act(Σ_i X[n][i]·W[o][i])` (act ReLU or none), with
//! X and Y [`RowView`]s (a row stride and a column offset each, so a layer can read a slice of a
//! concatenation row and write into a slice of a wider row) and W the layer's row-major
//! `[out][in]` range of the flat parameter buffer. Its backward, given dY:
//! - `dZ = dY ⊙ act'(Y)` (ReLU: `Y > 0`, 0 at 0 as the reference), formed while staging tiles;
//! - `dX = dZ·W`, OVERWRITING the input-gradient view (skipped when there is none, e.g. the
//!   colour MLP's SH input);
//! - `dW = dZᵀ·X`, ADDED to the gradient buffer at the layer's range and nowhere else (the
//!   trainer zeroes the gradient buffer before a step; the hash-table part is another pass's).
//!   The sum over N is deterministic: every chunk of rows writes its own partial matrix, then a
//!   second kernel sums the chunks in order, so a step gives the same bits every run.
//!
//! The three kernels (`shaders/dense_*.wgsl`) share one register-tiled product
//! (`shaders/_dense_tile.wgsl`): each invocation accumulates 4×4 outputs from tiles staged in
//! workgroup memory; the invocation grid and chunk depth are override constants picked per
//! layer shape by [`TileShape`], so 128-wide layers use 64×64 tiles and 1-, 3- or C-wide outputs
//! tall thin ones. Pipelines are compiled once per (kernel, shape) in [`DensePipelines`] and
//! shared by every layer of every MLP.
//!
//! On CPU devices (lavapipe, SwiftShader) the forward and the input gradient use a second
//! family of kernels, [`DenseFamily::UniformWeights`] (`shaders/dense_*_uniform.wgsl`): one
//! invocation per row, the layer's weights read through a uniform binding, which those devices
//! load once per SIMD group instead of once per lane (see the shader for the measurement). It
//! needs the parameter buffer made with UNIFORM usage and [`UNIFORM_WEIGHT_FLOATS`] of padding
//! after the last layer, and a layer of at most that many weights; other layers, and every
//! weight gradient, use the tiled kernels.
//!
//! X and Y (and dY and dX) of one layer must be different buffers: WebGPU forbids binding one
//! buffer both read-only and writable in a dispatch.
use std::collections::HashMap;
use std::num::NonZeroU64;
use std::ops::Range;

use crate::field::params::MlpLayout;
use crate::gpu::buffers::{storage_buffer_zeroed, uniform_buffer_from};
use crate::gpu::pipeline::{Dispatch1d, KernelSpec, create_compute_pipeline};
use crate::gpu::{GpuContext, GpuError, shaders};

/// Outputs per invocation along the rows and columns of a tile (`RM`, `RN` in the shader).
const PER_INVOCATION: u32 = 4;
/// Capacities in f32 of the two staging arrays (`A_TILE_CAP`, `B_TILE_CAP` in the shader).
const A_TILE_CAP: u32 = 2048;
const B_TILE_CAP: u32 = 1024;
/// Workgroup size of `reduce_chunks`.
const REDUCE_WORKGROUP: u32 = 256;
/// `reduce_chunks` uses no tile constants; its pipeline is built with the shader's defaults.
const REDUCE_SHAPE: TileShape = TileShape { tx: 16, ty: 16, kc: 16 };
/// Enough workgroups for the weight gradient to keep a GPU (or lavapipe's threads) busy; more
/// only lengthens the second reduction.
const WEIGHT_GRADIENT_TARGET_WORKGROUPS: u64 = 1024;
/// Fewest rows a weight-gradient chunk sums, so small batches do not make many tiny partials.
const MIN_CHUNK_ROWS: u32 = 256;

/// f32 in the uniform binding of the uniform-weight kernels (64 KiB, WebGPU's default limit).
pub const UNIFORM_WEIGHT_FLOATS: usize = 16384;
/// Invocations per workgroup of the uniform-weight kernels (`WORKGROUP` in the shader).
const UNIFORM_WORKGROUP: u32 = 64;

/// Which kernels compute the forward and input gradient of a layer.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum DenseFamily {
    /// Workgroup-tiled products (GPUs).
    Tiled,
    /// Row-per-invocation loops over weights in a uniform binding (CPU devices), where a layer
    /// and the parameter buffer allow it; tiled otherwise.
    UniformWeights,
}

impl DenseFamily {
    /// The family that is faster on `ctx`'s kind of device.
    pub fn for_device(ctx: &GpuContext) -> DenseFamily {
        if ctx.is_software() {
            DenseFamily::UniformWeights
        } else {
            DenseFamily::Tiled
        }
    }
}

/// The layer's nonlinearity, applied to the product (there is no bias).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Activation {
    Relu,
    None,
}

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
    fn check(&self, what: &str, rows: u32, width: u32) -> Result<(), GpuError> {
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

/// Invocation grid and chunk depth of one kernel instance: the workgroup is `tx × ty`
/// invocations and computes a `4·ty × 4·tx` tile of its product, staging `kc` deep chunks.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct TileShape {
    pub tx: u32,
    pub ty: u32,
    pub kc: u32,
}

impl TileShape {
    /// The shape for a product with `columns` output columns and `rows` output rows (`None`:
    /// as many as wanted, i.e. the N rows of a batch).
    pub fn for_product(columns: u32, rows: Option<u32>) -> TileShape {
        let tx = columns.div_ceil(PER_INVOCATION).next_power_of_two().min(16);
        let tall = (256 / tx).min(64);
        let ty = match rows {
            None => tall,
            Some(rows) => rows.div_ceil(PER_INVOCATION).next_power_of_two().min(tall),
        };
        let kc = (A_TILE_CAP / (ty * PER_INVOCATION))
            .min(B_TILE_CAP / (tx * PER_INVOCATION))
            .min(32);
        // Both caps and tile sides are powers of two, so kc is one too (cheap % and / in WGSL).
        TileShape { tx, ty, kc }
    }

    /// Rows and columns of the product one workgroup computes.
    pub fn tile_rows(&self) -> u32 {
        self.ty * PER_INVOCATION
    }

    pub fn tile_columns(&self) -> u32 {
        self.tx * PER_INVOCATION
    }

    fn workgroup_storage_bytes(&self) -> u64 {
        4 * u64::from(self.tile_rows() * self.kc + self.tile_columns() * self.kc)
    }
}

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

#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
enum DenseKernel {
    Forward,
    BackwardInput,
    PartialSums,
    ReduceChunks,
    ForwardUniform,
    BackwardInputUniform,
    MaskOutputGradient,
    ChunkPartialSums,
}

/// The override constants a pipeline is compiled with.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
enum KernelVariant {
    Tiled(TileShape),
    /// Outputs (or inputs) per invocation of a uniform-weight kernel.
    Block(u32),
    /// Outputs per invocation and invocations per workgroup of the uniform-window dW kernel.
    Columns(u32, u32),
}

impl DenseKernel {
    fn source(self) -> (&'static str, &'static str, &'static str) {
        match self {
            DenseKernel::Forward => ("dense forward", shaders::DENSE_FORWARD, "forward"),
            DenseKernel::BackwardInput => ("dense backward input", shaders::DENSE_BACKWARD_INPUT, "backward_input"),
            DenseKernel::PartialSums => (
                "dense weight partial sums",
                shaders::DENSE_BACKWARD_WEIGHT,
                "partial_sums",
            ),
            DenseKernel::ReduceChunks => ("dense weight reduce", shaders::DENSE_BACKWARD_WEIGHT, "reduce_chunks"),
            DenseKernel::ForwardUniform => (
                "dense forward (uniform weights)",
                shaders::DENSE_FORWARD_UNIFORM,
                "forward",
            ),
            DenseKernel::BackwardInputUniform => (
                "dense backward input (uniform weights)",
                shaders::DENSE_BACKWARD_INPUT_UNIFORM,
                "backward_input",
            ),
            DenseKernel::MaskOutputGradient => (
                "dense output gradient mask",
                shaders::DENSE_BACKWARD_WEIGHT_UNIFORM,
                "mask_output_gradient",
            ),
            DenseKernel::ChunkPartialSums => (
                "dense weight partial sums (uniform windows)",
                shaders::DENSE_BACKWARD_WEIGHT_UNIFORM,
                "chunk_partial_sums",
            ),
        }
    }
}

/// The compiled dense kernels, one per (kernel, variant) met so far; shared by all layers.
pub struct DensePipelines {
    family: DenseFamily,
    compiled: HashMap<(DenseKernel, KernelVariant), wgpu::ComputePipeline>,
}

impl Default for DensePipelines {
    fn default() -> Self {
        DensePipelines::with_family(DenseFamily::Tiled)
    }
}

impl DensePipelines {
    /// Tiled kernels everywhere.
    pub fn new() -> DensePipelines {
        DensePipelines::default()
    }

    pub fn with_family(family: DenseFamily) -> DensePipelines {
        DensePipelines {
            family,
            compiled: HashMap::new(),
        }
    }

    pub fn family(&self) -> DenseFamily {
        self.family
    }

    async fn get(
        &mut self,
        ctx: &GpuContext,
        kernel: DenseKernel,
        shape: TileShape,
    ) -> Result<wgpu::ComputePipeline, GpuError> {
        ctx.ensure_workgroup_storage_fits(kernel.source().0, shape.workgroup_storage_bytes())?;
        let constants = [
            ("TX", f64::from(shape.tx)),
            ("TY", f64::from(shape.ty)),
            ("KC", f64::from(shape.kc)),
        ];
        self.compile(ctx, kernel, KernelVariant::Tiled(shape), &constants).await
    }

    async fn get_uniform(
        &mut self,
        ctx: &GpuContext,
        kernel: DenseKernel,
        block: u32,
    ) -> Result<wgpu::ComputePipeline, GpuError> {
        self.compile(ctx, kernel, KernelVariant::Block(block), &[("BLOCK", f64::from(block))])
            .await
    }

    async fn compile(
        &mut self,
        ctx: &GpuContext,
        kernel: DenseKernel,
        variant: KernelVariant,
        constants: &[(&str, f64)],
    ) -> Result<wgpu::ComputePipeline, GpuError> {
        if let Some(pipeline) = self.compiled.get(&(kernel, variant)) {
            return Ok(pipeline.clone());
        }
        let (label, source, entry_point) = kernel.source();
        let spec = KernelSpec {
            label,
            source,
            entry_point,
            layout: None,
            constants,
        };
        let pipeline = create_compute_pipeline(ctx, &spec).await?;
        self.compiled.insert((kernel, variant), pipeline.clone());
        Ok(pipeline)
    }

    /// The per-chunk weight-gradient kernel, whose dZ window and chunk slot are bound with
    /// dynamic offsets (so an explicit layout), and its two bind group layouts.
    async fn chunk_sums_pipeline(
        &mut self,
        ctx: &GpuContext,
        block: u32,
        columns: u32,
    ) -> Result<(wgpu::ComputePipeline, [wgpu::BindGroupLayout; 2]), GpuError> {
        let entry = |binding, ty, dynamic: bool, min: Option<u64>| wgpu::BindGroupLayoutEntry {
            binding,
            visibility: wgpu::ShaderStages::COMPUTE,
            ty: wgpu::BindingType::Buffer {
                ty,
                has_dynamic_offset: dynamic,
                min_binding_size: min.and_then(NonZeroU64::new),
            },
            count: None,
        };
        let storage = |read_only| wgpu::BufferBindingType::Storage { read_only };
        let common = ctx.device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("dense chunk sums common"),
            entries: &[
                entry(0, wgpu::BufferBindingType::Uniform, false, None),
                entry(3, storage(true), false, None),
                entry(4, storage(false), false, None),
            ],
        });
        let windows = ctx.device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("dense chunk sums windows"),
            entries: &[
                entry(
                    0,
                    wgpu::BufferBindingType::Uniform,
                    true,
                    Some(UNIFORM_WEIGHT_FLOATS as u64 * 4),
                ),
                entry(1, wgpu::BufferBindingType::Uniform, true, Some(16)),
            ],
        });
        let layout = ctx.device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("dense chunk sums"),
            bind_group_layouts: &[Some(&common), Some(&windows)],
            immediate_size: 0,
        });
        let key = (DenseKernel::ChunkPartialSums, KernelVariant::Columns(block, columns));
        let pipeline = match self.compiled.get(&key) {
            Some(p) => p.clone(),
            None => {
                let (label, source, entry_point) = DenseKernel::ChunkPartialSums.source();
                let spec = KernelSpec {
                    label,
                    source,
                    entry_point,
                    layout: Some(&layout),
                    constants: &[("BLOCK", f64::from(block)), ("COLUMNS", f64::from(columns))],
                };
                let pipeline = create_compute_pipeline(ctx, &spec).await?;
                self.compiled.insert(key, pipeline.clone());
                pipeline
            }
        };
        // A pipeline with an explicit layout accepts bind groups of layouts equal to it.
        Ok((pipeline, [common, windows]))
    }

    /// The uniform binding of `range` of `params` and where the range starts in it, when this
    /// family wants uniform-weight kernels and the layer and buffer allow them.
    fn uniform_weights<'a>(
        &self,
        ctx: &GpuContext,
        params: &'a wgpu::Buffer,
        range: &Range<usize>,
    ) -> Option<(wgpu::BindingResource<'a>, u32)> {
        if self.family != DenseFamily::UniformWeights
            || !params.usage().contains(wgpu::BufferUsages::UNIFORM)
            || (ctx.limits.max_uniform_buffer_binding_size as usize) < UNIFORM_WEIGHT_FLOATS * 4
        {
            return None;
        }
        let align = (ctx.limits.min_uniform_buffer_offset_alignment.max(4) / 4) as usize;
        let start = range.start / align * align;
        let local = range.start - start;
        if local + range.len() > UNIFORM_WEIGHT_FLOATS || (start + UNIFORM_WEIGHT_FLOATS) as u64 * 4 > params.size() {
            return None;
        }
        let binding = wgpu::BindingResource::Buffer(wgpu::BufferBinding {
            buffer: params,
            offset: start as u64 * 4,
            size: NonZeroU64::new(UNIFORM_WEIGHT_FLOATS as u64 * 4),
        });
        Some((binding, local as u32))
    }
}

/// The two products that multiply by a layer's weights.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum ProductKind {
    /// Y = act(X Wᵀ): `out_dim` columns.
    Forward,
    /// dX = dZ W: `in_dim` columns.
    BackwardInput,
}

/// A pipeline, the weights' binding (and where the layer starts in it), the workgroup counts and
/// the family actually used.
type ProductKernel<'a> = (
    wgpu::ComputePipeline,
    (wgpu::BindingResource<'a>, u32),
    [u32; 3],
    DenseFamily,
);

impl DensePipelines {
    /// The kernel for one of a layer's weight products: uniform weights where the family wants
    /// them and the layer fits, tiled otherwise.
    async fn product_kernel<'a>(
        &mut self,
        ctx: &GpuContext,
        label: &str,
        params: &'a wgpu::Buffer,
        spec: &DenseLayerSpec,
        kind: ProductKind,
    ) -> Result<ProductKernel<'a>, GpuError> {
        let (columns, uniform_kernel, tiled_kernel) = match kind {
            ProductKind::Forward => (spec.out_dim, DenseKernel::ForwardUniform, DenseKernel::Forward),
            ProductKind::BackwardInput => (
                spec.in_dim,
                DenseKernel::BackwardInputUniform,
                DenseKernel::BackwardInput,
            ),
        };
        if let Some(binding) = self.uniform_weights(ctx, params, &spec.weights) {
            let pipeline = self.get_uniform(ctx, uniform_kernel, uniform_block(columns)).await?;
            let workgroups = uniform_dispatch(ctx, spec.rows, columns)?;
            return Ok((pipeline, binding, workgroups, DenseFamily::UniformWeights));
        }
        let shape = TileShape::for_product(columns, None);
        let pipeline = self.get(ctx, tiled_kernel, shape).await?;
        let binding = range_binding(ctx, label, params, &spec.weights)?;
        let workgroups = row_tile_dispatch(ctx, spec.rows, shape, columns.div_ceil(shape.tile_columns()))?;
        Ok((pipeline, binding, workgroups, DenseFamily::Tiled))
    }
}

/// Outputs per invocation of a uniform-weight kernel: the fewest of 4, 8, 16 covering `width`.
fn uniform_block(width: u32) -> u32 {
    match width {
        0..=4 => 4,
        5..=8 => 8,
        _ => 16,
    }
}

fn uniform_dispatch(ctx: &GpuContext, rows: u32, width: u32) -> Result<[u32; 3], GpuError> {
    let groups = Dispatch1d::for_device(ctx, u64::from(rows), UNIFORM_WORKGROUP)?;
    Ok([groups.x, groups.y, width.div_ceil(uniform_block(width))])
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
    fn check(&self) -> Result<(), GpuError> {
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

    fn base_dims(&self) -> DenseDims {
        DenseDims {
            rows: self.rows,
            in_dim: self.in_dim,
            out_dim: self.out_dim,
            relu: u32::from(self.activation == Activation::Relu),
            ..DenseDims::default()
        }
    }
}

/// A pipeline, its bind group and workgroup counts: one recorded dispatch.
struct BoundDispatch {
    pipeline: wgpu::ComputePipeline,
    bind_group: wgpu::BindGroup,
    workgroups: [u32; 3],
}

impl BoundDispatch {
    fn record(&self, pass: &mut wgpu::ComputePass<'_>) {
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, &self.bind_group, &[]);
        let [x, y, z] = self.workgroups;
        pass.dispatch_workgroups(x, y, z);
    }
}

fn bind_group(
    ctx: &GpuContext,
    label: &str,
    pipeline: &wgpu::ComputePipeline,
    resources: &[(u32, wgpu::BindingResource<'_>)],
) -> wgpu::BindGroup {
    let entries: Vec<wgpu::BindGroupEntry<'_>> = resources
        .iter()
        .map(|(binding, resource)| wgpu::BindGroupEntry {
            binding: *binding,
            resource: resource.clone(),
        })
        .collect();
    ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some(label),
        layout: &pipeline.get_bind_group_layout(0),
        entries: &entries,
    })
}

/// The part of a flat buffer holding `range` (in f32), bound from an offset the device accepts,
/// so only the layer's weights count against the binding-size limit (the hash table in front
/// of them may be larger than one binding); returns the binding and where `range` starts in it.
fn range_binding<'a>(
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

fn row_tile_dispatch(ctx: &GpuContext, rows: u32, shape: TileShape, column_tiles: u32) -> Result<[u32; 3], GpuError> {
    let tiles = Dispatch1d::for_device(ctx, u64::from(rows.div_ceil(shape.tile_rows())), 1)?;
    Ok([tiles.x, tiles.y, column_tiles])
}

/// The forward of one layer, bound to its buffers.
pub struct DenseForward {
    spec: DenseLayerSpec,
    dispatch: BoundDispatch,
    family: DenseFamily,
}

impl DenseForward {
    /// `input` must hold `spec.rows` rows of `in_dim` values, `output` of `out_dim`; the output
    /// is overwritten.
    pub async fn new(
        ctx: &GpuContext,
        pipelines: &mut DensePipelines,
        spec: &DenseLayerSpec,
        params: &wgpu::Buffer,
        input: &RowView,
        output: &RowView,
    ) -> Result<DenseForward, GpuError> {
        spec.check()?;
        let label = format!("{} forward", spec.label);
        input.check(&format!("{label} input"), spec.rows, spec.in_dim)?;
        output.check(&format!("{label} output"), spec.rows, spec.out_dim)?;
        check_binding(ctx, &label, &input.buffer)?;
        check_binding(ctx, &label, &output.buffer)?;
        let (pipeline, (weights, weight_offset), workgroups, family) = pipelines
            .product_kernel(ctx, &label, params, spec, ProductKind::Forward)
            .await?;
        let dims = DenseDims {
            x_stride: input.stride,
            x_offset: input.offset,
            y_stride: output.stride,
            y_offset: output.offset,
            weight_offset,
            ..spec.base_dims()
        };
        let uniform = uniform_buffer_from(ctx, &label, &dims);
        let bind_group = bind_group(
            ctx,
            &label,
            &pipeline,
            &[
                (0, uniform.as_entire_binding()),
                (1, input.buffer.as_entire_binding()),
                (2, weights),
                (3, output.buffer.as_entire_binding()),
            ],
        );
        Ok(DenseForward {
            spec: spec.clone(),
            dispatch: BoundDispatch {
                pipeline,
                bind_group,
                workgroups,
            },
            family,
        })
    }

    pub fn spec(&self) -> &DenseLayerSpec {
        &self.spec
    }

    /// The kernels this layer's forward runs (uniform weights only where the layer fits).
    pub fn family(&self) -> DenseFamily {
        self.family
    }

    pub fn record(&self, pass: &mut wgpu::ComputePass<'_>) {
        self.dispatch.record(pass);
    }
}

/// Buffers of one layer's backward.
#[derive(Debug, Clone)]
pub struct DenseGradients<'a> {
    /// The flat gradient buffer (same layout as the parameters); dW is added at `spec.weights`.
    pub grads: &'a wgpu::Buffer,
    /// dL/dY, `out_dim` values per row.
    pub output_grad: &'a RowView,
    /// Where dL/dX goes (`in_dim` values per row, overwritten); `None` skips it.
    pub input_grad: Option<&'a RowView>,
}

/// The backward of one layer, bound to its buffers; owns the per-chunk partial sums of dW.
pub struct DenseBackward {
    input_grad: Option<BoundDispatch>,
    partial_sums: WeightPartials,
    reduce: BoundDispatch,
    chunks: u32,
}

/// The first half of dW: every chunk of rows' partial matrix.
enum WeightPartials {
    /// One dispatch of the tiled kernel over all chunks.
    Tiled(BoundDispatch),
    /// dZ masked into a packed buffer, then one dispatch per chunk reading it as uniform.
    Uniform(UniformWeightPartials),
}

/// Mirrors `ChunkInfo` in `shaders/dense_backward_weight_uniform.wgsl`.
#[repr(C)]
#[derive(Debug, Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct ChunkInfo {
    index: u32,
    _pad: [u32; 3],
}

struct UniformWeightPartials {
    mask: BoundDispatch,
    pipeline: wgpu::ComputePipeline,
    common: wgpu::BindGroup,
    windows: wgpu::BindGroup,
    /// Bytes between consecutive chunks' dZ windows, and between their `ChunkInfo` slots.
    window_stride: u32,
    info_stride: u32,
    chunks: u32,
    workgroups: [u32; 2],
    /// Owned so the bind groups' buffers live as long as the pass.
    _buffers: [wgpu::Buffer; 2],
}

impl UniformWeightPartials {
    #[allow(clippy::too_many_arguments)]
    async fn new(
        ctx: &GpuContext,
        pipelines: &mut DensePipelines,
        label: &str,
        spec: &DenseLayerSpec,
        dims: &wgpu::Buffer,
        (input, output, output_grad): (&RowView, &RowView, &RowView),
        partials: &wgpu::Buffer,
        (chunk_rows, chunks): (u32, u32),
    ) -> Result<Self, GpuError> {
        let window_floats = chunk_rows as usize * spec.out_dim as usize;
        // Every chunk's window is UNIFORM_WEIGHT_FLOATS long from its start, the last included.
        let dz_floats = (chunks as usize - 1) * window_floats + UNIFORM_WEIGHT_FLOATS;
        ctx.ensure_storage_binding_fits(label, dz_floats as u64 * 4)?;
        let dz = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(&format!("{label} dZ")),
            size: dz_floats as u64 * 4,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::UNIFORM,
            mapped_at_creation: false,
        });
        let info_stride = ctx.limits.min_uniform_buffer_offset_alignment.max(16);
        let mut infos = vec![0u8; chunks as usize * info_stride as usize];
        for c in 0..chunks {
            let info = ChunkInfo { index: c, _pad: [0; 3] };
            let at = (c * info_stride) as usize;
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

        let mask_pipeline = pipelines
            .compile(ctx, DenseKernel::MaskOutputGradient, KernelVariant::Block(0), &[])
            .await?;
        let mask_bind = bind_group(
            ctx,
            label,
            &mask_pipeline,
            &[
                (0, dims.as_entire_binding()),
                (1, output_grad.buffer.as_entire_binding()),
                (2, output.buffer.as_entire_binding()),
                (6, dz.as_entire_binding()),
            ],
        );
        let groups = Dispatch1d::for_device(ctx, u64::from(spec.rows) * u64::from(spec.out_dim), UNIFORM_WORKGROUP)?;
        let mask = BoundDispatch {
            pipeline: mask_pipeline,
            bind_group: mask_bind,
            workgroups: [groups.x, groups.y, 1],
        };

        let block = uniform_block(spec.out_dim);
        let columns = spec.in_dim.next_power_of_two().clamp(8, UNIFORM_WORKGROUP);
        let (pipeline, layouts) = pipelines.chunk_sums_pipeline(ctx, block, columns).await?;
        let common = ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some(label),
            layout: &layouts[0],
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: dims.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 3,
                    resource: input.buffer.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 4,
                    resource: partials.as_entire_binding(),
                },
            ],
        });
        let windows = ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some(label),
            layout: &layouts[1],
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                        buffer: &dz,
                        offset: 0,
                        size: NonZeroU64::new(UNIFORM_WEIGHT_FLOATS as u64 * 4),
                    }),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                        buffer: &info,
                        offset: 0,
                        size: NonZeroU64::new(size_of::<ChunkInfo>() as u64),
                    }),
                },
            ],
        });
        Ok(UniformWeightPartials {
            mask,
            pipeline,
            common,
            windows,
            window_stride: (window_floats * 4) as u32,
            info_stride,
            chunks,
            workgroups: [spec.in_dim.div_ceil(columns), spec.out_dim.div_ceil(block)],
            _buffers: [dz, info],
        })
    }

    fn record(&self, pass: &mut wgpu::ComputePass<'_>) {
        self.mask.record(pass);
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, &self.common, &[]);
        for c in 0..self.chunks {
            pass.set_bind_group(1, &self.windows, &[c * self.window_stride, c * self.info_stride]);
            pass.dispatch_workgroups(self.workgroups[0], self.workgroups[1], 1);
        }
    }
}

impl WeightPartials {
    fn record(&self, pass: &mut wgpu::ComputePass<'_>) {
        match self {
            WeightPartials::Tiled(dispatch) => dispatch.record(pass),
            WeightPartials::Uniform(partials) => partials.record(pass),
        }
    }
}

/// Rows per chunk and chunk count for the uniform-window weight gradient: as many rows as fit
/// a 64 KiB window, each window starting at an offset the device accepts for uniform bindings;
/// `None` when the partial matrices would not fit one storage binding (then: tiled).
fn uniform_weight_chunks(ctx: &GpuContext, spec: &DenseLayerSpec) -> Option<(u32, u32)> {
    if (ctx.limits.max_uniform_buffer_binding_size as usize) < UNIFORM_WEIGHT_FLOATS * 4 {
        return None;
    }
    let out = spec.out_dim as usize;
    if out > UNIFORM_WEIGHT_FLOATS {
        return None;
    }
    let align = (ctx.limits.min_uniform_buffer_offset_alignment.max(4) / 4) as usize;
    // chunk_rows · out must be a multiple of `align` floats.
    let step = align / gcd(out, align);
    let chunk_rows = (UNIFORM_WEIGHT_FLOATS / out) / step * step;
    if chunk_rows == 0 {
        return None;
    }
    let chunks = (spec.rows as usize).div_ceil(chunk_rows);
    let partial_bytes = chunks as u64 * out as u64 * u64::from(spec.in_dim) * 4;
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

impl DenseBackward {
    /// `input` and `output` are the forward's views (X and the activated Y).
    pub async fn new(
        ctx: &GpuContext,
        pipelines: &mut DensePipelines,
        spec: &DenseLayerSpec,
        params: &wgpu::Buffer,
        input: &RowView,
        output: &RowView,
        gradients: &DenseGradients<'_>,
    ) -> Result<DenseBackward, GpuError> {
        spec.check()?;
        let label = format!("{} backward", spec.label);
        input.check(&format!("{label} input"), spec.rows, spec.in_dim)?;
        output.check(&format!("{label} output"), spec.rows, spec.out_dim)?;
        let output_grad = gradients.output_grad;
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
            ..spec.base_dims()
        };

        let input_grad = match gradients.input_grad {
            None => None,
            Some(input_grad) => {
                let label = format!("{label} input gradient");
                input_grad.check(&label, spec.rows, spec.in_dim)?;
                check_binding(ctx, &label, &input_grad.buffer)?;
                let (pipeline, (weights, weight_offset), workgroups, _) = pipelines
                    .product_kernel(ctx, &label, params, spec, ProductKind::BackwardInput)
                    .await?;
                let dims = DenseDims {
                    dx_stride: input_grad.stride,
                    dx_offset: input_grad.offset,
                    weight_offset,
                    ..base
                };
                let uniform = uniform_buffer_from(ctx, &label, &dims);
                let bind_group = bind_group(
                    ctx,
                    &label,
                    &pipeline,
                    &[
                        (0, uniform.as_entire_binding()),
                        (1, output_grad.buffer.as_entire_binding()),
                        (2, output.buffer.as_entire_binding()),
                        (3, weights),
                        (4, input_grad.buffer.as_entire_binding()),
                    ],
                );
                Some(BoundDispatch {
                    pipeline,
                    bind_group,
                    workgroups,
                })
            }
        };

        let label = format!("{label} weight gradient");
        let uniform_plan = match pipelines.family {
            DenseFamily::UniformWeights => uniform_weight_chunks(ctx, spec),
            DenseFamily::Tiled => None,
        };
        let shape = TileShape::for_product(spec.in_dim, Some(spec.out_dim));
        let (chunk_rows, chunks) = match uniform_plan {
            Some(plan) => plan,
            None => weight_chunks(ctx, spec, shape)?,
        };
        let matrix = spec.in_dim as usize * spec.out_dim as usize;
        let partials = storage_buffer_zeroed::<f32>(ctx, &format!("{label} partials"), chunks as usize * matrix)?;
        let (grads, grad_offset) = range_binding(ctx, &label, gradients.grads, &spec.weights)?;
        let dims = DenseDims {
            chunk_rows,
            chunks,
            weight_offset: grad_offset,
            ..base
        };
        let uniform = uniform_buffer_from(ctx, &label, &dims);

        let partial_sums = match uniform_plan {
            Some(_) => WeightPartials::Uniform(
                UniformWeightPartials::new(
                    ctx,
                    pipelines,
                    &label,
                    spec,
                    &uniform,
                    (input, output, output_grad),
                    &partials,
                    (chunk_rows, chunks),
                )
                .await?,
            ),
            None => {
                let pipeline = pipelines.get(ctx, DenseKernel::PartialSums, shape).await?;
                let bind = bind_group(
                    ctx,
                    &label,
                    &pipeline,
                    &[
                        (0, uniform.as_entire_binding()),
                        (1, output_grad.buffer.as_entire_binding()),
                        (2, output.buffer.as_entire_binding()),
                        (3, input.buffer.as_entire_binding()),
                        (4, partials.as_entire_binding()),
                    ],
                );
                let workgroups = [
                    spec.in_dim.div_ceil(shape.tile_columns()),
                    spec.out_dim.div_ceil(shape.tile_rows()),
                    chunks,
                ];
                WeightPartials::Tiled(BoundDispatch {
                    pipeline,
                    bind_group: bind,
                    workgroups,
                })
            }
        };

        let pipeline = pipelines.get(ctx, DenseKernel::ReduceChunks, REDUCE_SHAPE).await?;
        let bind = bind_group(
            ctx,
            &label,
            &pipeline,
            &[
                (0, uniform.as_entire_binding()),
                (4, partials.as_entire_binding()),
                (5, grads),
            ],
        );
        let reduce_groups = Dispatch1d::for_device(ctx, matrix as u64, REDUCE_WORKGROUP)?;
        let reduce = BoundDispatch {
            pipeline,
            bind_group: bind,
            workgroups: [reduce_groups.x, reduce_groups.y, 1],
        };
        Ok(DenseBackward {
            input_grad,
            partial_sums,
            reduce,
            chunks,
        })
    }

    /// Chunks of rows whose partial dW are summed by the second kernel.
    pub fn chunks(&self) -> u32 {
        self.chunks
    }

    /// Records dX (if wanted), then the dW partial sums and their reduction into the gradient.
    pub fn record(&self, pass: &mut wgpu::ComputePass<'_>) {
        if let Some(input_grad) = &self.input_grad {
            input_grad.record(pass);
        }
        self.partial_sums.record(pass);
        self.reduce.record(pass);
    }

    /// Whether dW reads dZ through uniform windows (the CPU-device kernels).
    pub fn uses_uniform_windows(&self) -> bool {
        matches!(self.partial_sums, WeightPartials::Uniform(_))
    }
}

/// Rows per weight-gradient chunk and the chunk count: enough workgroups to fill the device,
/// chunks a multiple of the staging depth, partials within one binding and the z-dimension limit.
fn weight_chunks(ctx: &GpuContext, spec: &DenseLayerSpec, shape: TileShape) -> Result<(u32, u32), GpuError> {
    let tiles = u64::from(spec.in_dim.div_ceil(shape.tile_columns()) * spec.out_dim.div_ceil(shape.tile_rows()));
    let matrix_bytes = 4 * u64::from(spec.in_dim) * u64::from(spec.out_dim);
    let by_binding = (ctx
        .limits
        .max_storage_buffer_binding_size
        .min(ctx.limits.max_buffer_size)
        / matrix_bytes)
        .max(1);
    let max_chunks = by_binding
        .min(u64::from(ctx.limits.max_compute_workgroups_per_dimension))
        .min(u64::from(spec.rows.div_ceil(MIN_CHUNK_ROWS)))
        .max(1);
    let wanted = WEIGHT_GRADIENT_TARGET_WORKGROUPS.div_ceil(tiles).clamp(1, max_chunks);
    let chunk_rows = (u64::from(spec.rows).div_ceil(wanted) as u32).next_multiple_of(shape.kc);
    let chunks = spec.rows.div_ceil(chunk_rows);
    if u64::from(chunks) > max_chunks {
        return Err(GpuError::LimitExceeded {
            what: format!("{} weight-gradient partial sums", spec.label),
            limit: "max_storage_buffer_binding_size",
            needed: u64::from(chunks) * matrix_bytes,
            allowed: max_chunks * matrix_bytes,
        });
    }
    Ok((chunk_rows, chunks))
}

/// Gradient buffers of an MLP's backward.
#[derive(Debug, Clone)]
pub struct MlpGradients {
    /// The flat gradient buffer; every layer's dW is added at its range.
    pub grads: wgpu::Buffer,
    /// dL/d(output), `output_dim` values per row.
    pub output_grad: RowView,
    /// Where dL/d(input) goes (overwritten); `None` when the input needs no gradient.
    pub input_grad: Option<RowView>,
}

/// What an MLP reads and writes.
#[derive(Debug, Clone)]
pub struct MlpPassDesc<'a> {
    pub label: &'a str,
    pub layout: &'a MlpLayout,
    pub rows: u32,
    pub params: &'a wgpu::Buffer,
    /// `input_dim` values per row.
    pub input: RowView,
    /// Where the last layer writes; `None`: a packed buffer the pass allocates.
    pub output: Option<RowView>,
    /// `None` builds a forward-only pass (rendering).
    pub gradients: Option<MlpGradients>,
}

/// A whole MLP (ReLU after every hidden layer, linear output, as `reference::mlp`): the forward
/// keeps every layer's output in buffers this pass owns (N × width, packed) for the backward.
pub struct MlpPass {
    forward: Vec<DenseForward>,
    backward: Option<Vec<DenseBackward>>,
    /// Output of layer k (the input of layer k + 1; the last is the MLP's output).
    outputs: Vec<RowView>,
    /// dL/d(input of layer k) for k ≥ 1, packed, owned.
    hidden_grads: Vec<wgpu::Buffer>,
}

impl MlpPass {
    pub async fn new(
        ctx: &GpuContext,
        pipelines: &mut DensePipelines,
        desc: MlpPassDesc<'_>,
    ) -> Result<MlpPass, GpuError> {
        let MlpPassDesc {
            label,
            layout,
            rows,
            params,
            input,
            output,
            gradients,
        } = desc;
        let dims: Vec<u32> = layout
            .dims
            .iter()
            .map(|&d| u32::try_from(d).map_err(|_| GpuError::invalid_argument(label, format!("width {d} exceeds u32"))))
            .collect::<Result<_, _>>()?;
        let layers = layout.layers.len();
        if layers == 0 || dims.len() != layers + 1 {
            return Err(GpuError::invalid_argument(
                label,
                format!("layout {layout:?} has no consistent layers"),
            ));
        }
        let specs: Vec<DenseLayerSpec> = (0..layers)
            .map(|k| DenseLayerSpec {
                label: format!("{label}.{k}"),
                rows,
                in_dim: dims[k],
                out_dim: dims[k + 1],
                activation: if k + 1 < layers {
                    Activation::Relu
                } else {
                    Activation::None
                },
                weights: layout.layers[k].clone(),
            })
            .collect();

        let mut outputs = Vec::with_capacity(layers);
        for (k, spec) in specs.iter().enumerate() {
            let view = match (&output, k + 1 == layers) {
                (Some(view), true) => view.clone(),
                _ => {
                    let count = rows as usize * spec.out_dim as usize;
                    let buffer = storage_buffer_zeroed::<f32>(ctx, &format!("{} output", spec.label), count)?;
                    RowView::packed(&buffer, spec.out_dim)
                }
            };
            outputs.push(view);
        }
        let mut forward = Vec::with_capacity(layers);
        for (k, spec) in specs.iter().enumerate() {
            let layer_input = if k == 0 { &input } else { &outputs[k - 1] };
            forward.push(DenseForward::new(ctx, pipelines, spec, params, layer_input, &outputs[k]).await?);
        }

        let mut hidden_grads = Vec::new();
        let backward = match gradients {
            None => None,
            Some(gradients) => {
                for spec in &specs[1..] {
                    let count = rows as usize * spec.in_dim as usize;
                    hidden_grads.push(storage_buffer_zeroed::<f32>(
                        ctx,
                        &format!("{} input gradient", spec.label),
                        count,
                    )?);
                }
                let hidden_views: Vec<RowView> = hidden_grads
                    .iter()
                    .zip(&specs[1..])
                    .map(|(b, spec)| RowView::packed(b, spec.in_dim))
                    .collect();
                let mut backward = Vec::with_capacity(layers);
                for (k, spec) in specs.iter().enumerate() {
                    let layer_input = if k == 0 { &input } else { &outputs[k - 1] };
                    let output_grad = if k + 1 == layers {
                        &gradients.output_grad
                    } else {
                        &hidden_views[k]
                    };
                    let input_grad = if k == 0 {
                        gradients.input_grad.as_ref()
                    } else {
                        Some(&hidden_views[k - 1])
                    };
                    let layer_gradients = DenseGradients {
                        grads: &gradients.grads,
                        output_grad,
                        input_grad,
                    };
                    backward.push(
                        DenseBackward::new(ctx, pipelines, spec, params, layer_input, &outputs[k], &layer_gradients)
                            .await?,
                    );
                }
                Some(backward)
            }
        };
        Ok(MlpPass {
            forward,
            backward,
            outputs,
            hidden_grads,
        })
    }

    /// Records every layer's forward, in order.
    pub fn record_forward(&self, pass: &mut wgpu::ComputePass<'_>) {
        for layer in &self.forward {
            layer.record(pass);
        }
    }

    /// Records every layer's backward, last layer first. Needs the forward of the same rows
    /// recorded before it (it reads the stored outputs); fails on a forward-only pass.
    pub fn record_backward(&self, pass: &mut wgpu::ComputePass<'_>) -> Result<(), GpuError> {
        let backward = self.backward.as_ref().ok_or_else(|| {
            let label = self.forward.first().map_or("mlp", |layer| layer.spec().label.as_str());
            GpuError::invalid_argument(label, "backward recorded on a pass built without gradients")
        })?;
        for layer in backward.iter().rev() {
            layer.record(pass);
        }
        Ok(())
    }

    /// The MLP's (linear) output.
    pub fn output(&self) -> &RowView {
        &self.outputs[self.outputs.len() - 1]
    }

    /// Output of layer `k` (ReLU-activated for hidden layers).
    pub fn layer_output(&self, k: usize) -> Option<&RowView> {
        self.outputs.get(k)
    }

    /// dL/d(input of layer k) for k ≥ 1, as written by the backward.
    pub fn hidden_gradient(&self, k: usize) -> Option<&wgpu::Buffer> {
        k.checked_sub(1).and_then(|i| self.hidden_grads.get(i))
    }

    pub fn layers(&self) -> impl Iterator<Item = &DenseLayerSpec> {
        self.forward.iter().map(DenseForward::spec)
    }

    /// For each layer's backward: whether dW reads dZ through uniform windows (none: forward only).
    pub fn weight_gradient_windows(&self) -> Vec<bool> {
        self.backward
            .iter()
            .flatten()
            .map(DenseBackward::uses_uniform_windows)
            .collect()
    }

    /// The kernel family each layer's forward (and input gradient) runs.
    pub fn layer_families(&self) -> impl Iterator<Item = DenseFamily> + '_ {
        self.forward.iter().map(DenseForward::family)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dims_uniform_is_sixteen_words() {
        assert_eq!(size_of::<DenseDims>(), 64);
    }

    #[test]
    fn tile_shapes_fit_the_staging_arrays_and_webgpu_limits() {
        for columns in 1..=300 {
            for rows in [None, Some(1), Some(3), Some(16), Some(128), Some(1000)] {
                let s = TileShape::for_product(columns, rows);
                assert!(s.tx * s.ty <= 256 && s.tx >= 1 && s.ty >= 1, "{s:?}");
                assert!(s.kc.is_power_of_two() && s.kc >= 2, "{s:?}");
                assert!(
                    s.tile_rows() * s.kc <= A_TILE_CAP && s.tile_columns() * s.kc <= B_TILE_CAP,
                    "{s:?}"
                );
                assert!(s.workgroup_storage_bytes() <= 16 * 1024);
            }
        }
        assert_eq!(TileShape::for_product(128, None), TileShape { tx: 16, ty: 16, kc: 16 });
        assert_eq!(TileShape::for_product(3, None), TileShape { tx: 1, ty: 64, kc: 8 });
    }
}
