//! The dense kernels by name, the override constants each is compiled with, and the choice of
//! kernel family for one product. Compiled pipelines are kept by the context's pipeline cache,
//! so every layer of every MLP (and every later trainer on the device) shares them.

use super::RowFormat;
use super::spec::{DenseLayerSpec, kept_dispatch, padded_to_vec4, range_binding};
use super::tiled::{TileShape, row_tile_dispatch};
use super::uniform_shape::{MAX_UNROLLED, PackedReads, uniform_block, uniform_dispatch};
use crate::field::gpu::keep::HeadRows;
use crate::gpu::KernelFamily;
use crate::gpu::dispatch::{Dispatch, bind_named};
use crate::gpu::pipeline::{KernelSpec, create_compute_pipeline};
use crate::gpu::{GpuContext, GpuError, shaders};

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum DenseKernel {
    Forward,
    BackwardInput,
    PartialSums,
    ReduceChunks,
    ForwardUniform,
    BackwardInputUniform,
    BackwardChainUniform,
    MaskOutputGradient,
    ChunkPartialSums,
    ForwardPackedStorage,
    BackwardInputPackedStorage,
    ChunkPartialSumsStorage,
    PackWeights,
}

impl DenseKernel {
    /// The kernel's shader and entry point (no override constants): what its bindings are
    /// named by (`gpu::dispatch::bind_named`).
    pub(super) fn spec(self) -> KernelSpec<'static> {
        let (label, source, entry_point) = self.source();
        KernelSpec::new(label, source, entry_point)
    }

    pub(super) fn source(self) -> (&'static str, &'static str, &'static str) {
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
            DenseKernel::BackwardChainUniform => (
                "dense backward chain (uniform weights)",
                shaders::DENSE_BACKWARD_CHAIN_UNIFORM,
                "backward_chain",
            ),
            DenseKernel::MaskOutputGradient => (
                "dense output gradient mask",
                shaders::DENSE_BACKWARD_WEIGHT_UNIFORM,
                "mask_output_gradient",
            ),
            DenseKernel::PackWeights => (
                "dense weights packed for uniform reads",
                shaders::DENSE_PACK_WEIGHTS,
                "pack_weights",
            ),
            DenseKernel::ChunkPartialSums => (
                "dense weight partial sums (uniform windows)",
                shaders::DENSE_BACKWARD_WEIGHT_UNIFORM,
                "chunk_partial_sums",
            ),
            DenseKernel::ForwardPackedStorage => (
                "dense forward (packed weights in storage)",
                shaders::DENSE_FORWARD_PACKED_STORAGE,
                "forward",
            ),
            DenseKernel::BackwardInputPackedStorage => (
                "dense backward input (packed weights in storage)",
                shaders::DENSE_BACKWARD_INPUT_PACKED_STORAGE,
                "backward_input",
            ),
            DenseKernel::ChunkPartialSumsStorage => (
                "dense weight partial sums (dZ in storage)",
                shaders::DENSE_BACKWARD_WEIGHT_PACKED_STORAGE,
                "chunk_partial_sums",
            ),
        }
    }
}

/// The choice of dense kernels: which family layers use and how its products are shaped, from
/// the device's profile unless a test forces them. It holds no pipelines: it compiles (or
/// fetches from the context's cache) the pipeline for one kernel and its override constants.
pub struct DenseKernels {
    pub(super) family: KernelFamily,
    /// The widest block of outputs one uniform-weight invocation computes; `None`: the device's
    /// (`DeviceProfile::widest_uniform_block`).
    uniform_block_limit: Option<u32>,
    /// Whether MLPs that qualify run their input gradients as one chain (`chain.rs`); `None`:
    /// where the device is faster with it (`DeviceProfile::chains`).
    input_gradient_chain: Option<bool>,
    /// Where the uniform-weight family reads; `None`: [`PackedReads::for_this_build`].
    packed_reads: Option<PackedReads>,
    /// Whether the uniform-weight products write their reductions out step by step; `None`:
    /// where the device is faster with it (`DeviceProfile::unrolled_reductions`).
    unrolled_reductions: Option<bool>,
    /// How MLPs whose kernels all run this family store their hidden outputs.
    hidden_rows: RowFormat,
}

impl Default for DenseKernels {
    fn default() -> Self {
        DenseKernels::with_family(KernelFamily::Tiled)
    }
}

impl DenseKernels {
    /// Tiled kernels everywhere.
    pub fn new() -> DenseKernels {
        DenseKernels::default()
    }

    pub fn with_family(family: KernelFamily) -> DenseKernels {
        DenseKernels {
            family,
            uniform_block_limit: None,
            input_gradient_chain: None,
            packed_reads: None,
            unrolled_reductions: None,
            hidden_rows: RowFormat::Bf16,
        }
    }

    /// The same with the hidden outputs of MLPs that run the uniform-weight family stored as
    /// `format` (bf16 by default), so tests and benchmarks can compare both.
    pub fn with_hidden_rows(self, format: RowFormat) -> DenseKernels {
        DenseKernels {
            hidden_rows: format,
            ..self
        }
    }

    pub(super) fn hidden_rows(&self) -> RowFormat {
        self.hidden_rows
    }

    /// The same with the uniform-weight family reading its packed copies and dZ as `reads` says
    /// whatever the build, so tests can run both on one device.
    pub fn with_packed_reads(self, reads: PackedReads) -> DenseKernels {
        DenseKernels {
            packed_reads: Some(reads),
            ..self
        }
    }

    pub fn packed_reads(&self) -> PackedReads {
        self.packed_reads.unwrap_or_else(PackedReads::for_this_build)
    }

    /// The uniform-weight family's kernels of a forward, an input gradient and a weight gradient,
    /// as they read ([`DenseKernels::packed_reads`]).
    fn packed_kernel(&self, kind: ProductKind) -> DenseKernel {
        match (kind, self.packed_reads()) {
            (ProductKind::Forward, PackedReads::Uniform) => DenseKernel::ForwardUniform,
            (ProductKind::Forward, PackedReads::Storage) => DenseKernel::ForwardPackedStorage,
            (ProductKind::BackwardInput, PackedReads::Uniform) => DenseKernel::BackwardInputUniform,
            (ProductKind::BackwardInput, PackedReads::Storage) => DenseKernel::BackwardInputPackedStorage,
        }
    }

    pub(super) fn chunk_sums_kernel(&self) -> DenseKernel {
        match self.packed_reads() {
            PackedReads::Uniform => DenseKernel::ChunkPartialSums,
            PackedReads::Storage => DenseKernel::ChunkPartialSumsStorage,
        }
    }

    /// The same with the input-gradient chain on or off whatever the device, so tests can run
    /// it on one device at every block width.
    pub fn with_input_gradient_chain(self, chain: bool) -> DenseKernels {
        DenseKernels {
            input_gradient_chain: Some(chain),
            ..self
        }
    }

    pub(super) fn input_gradient_chain(&self, ctx: &GpuContext) -> bool {
        self.input_gradient_chain.unwrap_or(ctx.profile().chains)
    }

    /// The same with the uniform-weight products' reductions written out step by step, or kept
    /// as loops, whatever the device, so tests can run both on one device.
    pub fn with_unrolled_reductions(self, unrolled: bool) -> DenseKernels {
        DenseKernels {
            unrolled_reductions: Some(unrolled),
            ..self
        }
    }

    /// The override constants that write a reduction of `reduced` steps over packed rows of
    /// `row_columns` columns in blocks of `block` out step by step, where this device does so,
    /// the weights are read from uniform bindings (what the unrolling is for; unrolled storage
    /// reads compiled for minutes on lavapipe), it is short enough, and the row takes at most
    /// [`MAX_FIXED_BLOCKS`] blocks, each then its own pipeline ([`DenseKernels::fixed_blocks`]).
    pub(super) fn unrolled_constants(
        &self,
        ctx: &GpuContext,
        reduced: u32,
        row_columns: u32,
        block: u32,
    ) -> (bool, [(&'static str, f64); 3]) {
        let unrolled = self.unrolls(ctx, reduced, row_columns, block);
        let constants = [
            ("UNROLL", f64::from(u8::from(unrolled))),
            ("REDUCED", f64::from(reduced)),
            ("ROW_QUADS", f64::from(padded_to_vec4(row_columns) / 4)),
        ];
        (unrolled, constants)
    }

    fn unrolls(&self, ctx: &GpuContext, reduced: u32, row_columns: u32, block: u32) -> bool {
        self.unrolled_reductions.unwrap_or(ctx.profile().unrolled_reductions)
            && self.packed_reads() == PackedReads::Uniform
            && reduced <= MAX_UNROLLED
            && row_columns.div_ceil(block) <= MAX_FIXED_BLOCKS
    }

    /// The `FIXED_BLOCK` of each pipeline a product of `columns` columns in blocks of `block`
    /// runs: one per block where its reduction is written out (`unrolled`) and there are several (the
    /// block's first weight is then a constant: from the workgroup id, every lane gathered it
    /// and the written-out reduction ran slower than the loop), otherwise one pipeline whose
    /// workgroups' z picks the block (`ANY_BLOCK` in `shaders/_dense_uniform.wgsl`). Every
    /// block's pipeline compiles the written-out reduction again, hence [`MAX_FIXED_BLOCKS`].
    fn fixed_blocks(unrolled: bool, columns: u32, block: u32) -> Vec<u32> {
        let blocks = columns.div_ceil(block);
        if blocks > 1 && unrolled {
            (0..blocks).collect()
        } else {
            vec![ANY_BLOCK]
        }
    }

    /// The same with the uniform-weight kernels' blocks at most `limit` (a multiple of 4 up to 64)
    /// outputs wide whatever the device, so tests can run every width on one device.
    pub fn with_uniform_block_limit(self, limit: u32) -> DenseKernels {
        DenseKernels {
            uniform_block_limit: Some(limit),
            ..self
        }
    }

    pub(super) fn uniform_block_limit(&self, ctx: &GpuContext) -> u32 {
        self.uniform_block_limit.unwrap_or(ctx.profile().widest_uniform_block)
    }

    /// The columns one invocation of a uniform-weight product of `columns` columns computes
    /// (`BLOCK`): a forward's outputs, an input gradient's inputs.
    pub(super) fn uniform_product_block(&self, ctx: &GpuContext, columns: u32) -> u32 {
        uniform_block(columns, self.uniform_block_limit(ctx))
    }

    pub fn family(&self) -> KernelFamily {
        self.family
    }

    pub(super) async fn get(
        &self,
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
        self.compile(ctx, kernel, &constants).await
    }

    pub(super) async fn compile(
        &self,
        ctx: &GpuContext,
        kernel: DenseKernel,
        constants: &[(&str, f64)],
    ) -> Result<wgpu::ComputePipeline, GpuError> {
        let (label, source, entry_point) = kernel.source();
        let spec = KernelSpec {
            label,
            source,
            entry_point,
            layout: None,
            constants,
        };
        create_compute_pipeline(ctx, &spec).await
    }
}

/// The two products that multiply by a layer's weights.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum ProductKind {
    /// Y = act(X Wᵀ): `out_dim` columns.
    Forward,
    /// dX = dZ W: `in_dim` columns.
    BackwardInput,
}

/// Where a product kernel reads the layer's weights.
pub(super) enum ProductWeights<'a> {
    /// The parameter buffer's range, and where the layer starts in it (tiled kernels).
    Range(wgpu::BindingResource<'a>, u32),
    /// The 64 KiB window of the MLP's packed copies holding this product's (uniform-weight
    /// kernels; `MlpPacking` refreshes them).
    Packed(wgpu::BindingResource<'a>),
}

impl ProductWeights<'_> {
    /// The binding and the `weight_offset` the kernel's uniform block holds.
    pub(super) fn binding(&self) -> (wgpu::BindingResource<'_>, u32) {
        match self {
            ProductWeights::Range(binding, offset) => (binding.clone(), *offset),
            ProductWeights::Packed(window) => (window.clone(), 0),
        }
    }
}

/// The pipelines a product runs (one dispatch each, with the same bindings) and their kernel,
/// where it reads the weights, the workgroup counts of each dispatch, the family actually used
/// and the rows one workgroup covers.
pub(super) type ProductKernel<'a> = (
    (Vec<wgpu::ComputePipeline>, DenseKernel),
    ProductWeights<'a>,
    [u32; 3],
    KernelFamily,
    u32,
);

/// `FIXED_BLOCK` of a pipeline whose workgroups' z picks the block.
const ANY_BLOCK: u32 = u32::MAX;

/// The most blocks a product splits into pipelines of one block each: every layer of the
/// presets in lavapipe's blocks of 64 (the semantic head's 79 inputs, the 128-wide layers).
const MAX_FIXED_BLOCKS: u32 = 2;

impl DenseKernels {
    /// The kernel for one of a layer's weight products, given where the weights are: the
    /// parameters, and the window of the MLP's packed copy for this product if it has one
    /// (`MlpPacking::window`; then the uniform-weight kernel runs, tiled otherwise).
    /// `constants`: the uniform-weight kernel's own (the rows' formats, `X_BF16` and `Y_BF16`,
    /// and for the input gradient `WRITE_DZ`: it also writes dZ for the uniform-window weight
    /// gradient); a tiled product reads and writes f32 rows only, so a bf16 row is an error there.
    pub(super) async fn product_kernel<'a>(
        &self,
        ctx: &GpuContext,
        label: &str,
        (params, packed): (&'a wgpu::Buffer, Option<wgpu::BindingResource<'a>>),
        spec: &DenseLayerSpec,
        kind: ProductKind,
        constants: &[(&'static str, f64)],
    ) -> Result<ProductKernel<'a>, GpuError> {
        // The columns one invocation computes, the reduction's length, and the tiled kernel.
        let (columns, reduced, tiled_kernel) = match kind {
            ProductKind::Forward => (spec.out_dim, spec.in_dim, DenseKernel::Forward),
            ProductKind::BackwardInput => (spec.in_dim, spec.out_dim, DenseKernel::BackwardInput),
        };
        let uniform_kernel = self.packed_kernel(kind);
        if let Some(packed) = packed {
            let block = self.uniform_product_block(ctx, columns);
            let mut workgroups = uniform_dispatch(ctx, spec.rows, columns, block)?;
            let (unrolled, unroll_constants) = self.unrolled_constants(ctx, reduced, columns, block);
            let fixed = DenseKernels::fixed_blocks(unrolled, columns, block);
            if fixed.len() > 1 {
                workgroups[2] = 1;
            }
            let own = constants;
            let mut constants = vec![("BLOCK", f64::from(block))];
            constants.extend(unroll_constants);
            constants.extend_from_slice(own);
            let mut pipelines = Vec::with_capacity(fixed.len());
            for fixed_block in fixed {
                let mut constants = constants.clone();
                constants.push(("FIXED_BLOCK", f64::from(fixed_block)));
                pipelines.push(self.compile(ctx, uniform_kernel, &constants).await?);
            }
            return Ok((
                (pipelines, uniform_kernel),
                ProductWeights::Packed(packed),
                workgroups,
                KernelFamily::UniformWeights,
                super::uniform_shape::UNIFORM_WORKGROUP,
            ));
        }
        if let Some((name, _)) = constants
            .iter()
            .find(|(name, value)| name.ends_with("_BF16") && *value != 0.0)
        {
            return Err(GpuError::invalid_argument(
                label,
                format!("the tiled kernels take no {name}: bf16 rows need the packed-weight kernels"),
            ));
        }
        let shape = TileShape::for_product(columns, None);
        let pipeline = self.get(ctx, tiled_kernel, shape).await?;
        let (binding, offset) = range_binding(ctx, label, params, &spec.weights)?;
        let workgroups = row_tile_dispatch(ctx, spec.rows, shape, columns.div_ceil(shape.tile_columns()))?;
        Ok((
            (vec![pipeline], tiled_kernel),
            ProductWeights::Range(binding, offset),
            workgroups,
            KernelFamily::Tiled,
            shape.tile_rows(),
        ))
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
