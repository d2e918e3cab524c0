//! The position encoding on the GPU (hash grid + frequencies) and its hash-table gradient. The
//! GPU twins of `reference::{hash_grid, frequency}`; tested against them in
//! `tests/gpu_field_encoding.rs`. The view direction's encoding is `sh_encode`.
//!
//! - [`PositionEncodePass`] (`shaders/hash_encode.wgsl`): N positions (`vec4<f32>`, xyz in
//!   [0,1]³) → N rows of `cfg.encoding_dim()` values, `[hash levels… | frequencies]`, exactly
//!   `FieldModel::encode_position`.
//! - [`HashGridBackwardPass`] (`shaders/hash_backward*.wgsl`): N rows of ∂L/∂encoding → adds
//!   ∂L/∂table into the table range of the flat gradient buffer with atomics: float atomics,
//!   fixed point or an f32 compare-exchange loop, by device ([`AtomicAdd`];
//!   docs/architecture.md, "Fixed-point hash gradients"). The table range must be zero first:
//!   [`HashGridBackwardPass::record_clear`] does that (in the trainer, the previous step's Adam).
//!
//! Passes are built once with their buffers and only record dispatches, so a training step can
//! record all of them into one encoder. The sample count is fixed at creation.
use std::ops::Range;

use crate::field::config::FieldConfig;
use crate::field::gpu::fixed_point::decode_table;
use crate::field::gpu::stage::{Stage, StepShape};
use crate::field::reference::hash_grid::HashGrid;
use crate::gpu::buffers::{PendingRead, read_buffer_async, storage_buffer_zeroed, uniform_buffer_from};
use crate::gpu::dispatch::{Dispatch, whole};
use crate::gpu::pipeline::{Dispatch1d, KernelSpec};
use crate::gpu::{GpuContext, GpuError, KernelFamily, shaders};

/// Invocations per workgroup of the three kernels (their `WORKGROUP_SIZE`).
pub const WORKGROUP_SIZE: u32 = 64;
/// Levels per workgroup of `hash_backward_per_level.wgsl` (its `LEVELS_PER_GROUP`).
const LEVELS_PER_GROUP: u32 = 4;
/// Loop iterations one invocation of `hash_backward_per_level.wgsl` may run in one dispatch.
/// lavapipe's shader compiler (gallivm) ends every loop of an invocation once all of them
/// together have run 65,535 iterations: in one dispatch the kernel's sums came out short there
/// from 10,240 samples on (8,192 were right), with 2 features. Each sample costs an iteration
/// of its own and two loops over the features, each F + 1 iterations with the one that exits.
const PER_LEVEL_LOOP_BUDGET: u64 = 60_000;

/// Mirrors `SampleRange` in `hash_backward_per_level.wgsl`: the samples one dispatch walks.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, bytemuck::Pod, bytemuck::Zeroable)]
struct SampleRange {
    first: u32,
    end: u32,
    _pad0: u32,
    _pad1: u32,
}

/// Samples per dispatch of `hash_backward_per_level.wgsl` ([`PER_LEVEL_LOOP_BUDGET`]).
fn per_level_chunk(features: u32) -> u64 {
    PER_LEVEL_LOOP_BUDGET / (3 + 2 * u64::from(features))
}
/// Levels the uniform block has room for (`MAX_HASH_LEVELS` in `_hash_grid.wgsl`); the config
/// allows at most this many.
pub const MAX_HASH_LEVELS: usize = 32;
/// Features per level the backward's workgroup memory has room for (`MAX_FEATURES`).
pub const MAX_HASH_FEATURES: usize = 8;

/// Bytes per position or direction: a `vec4<f32>`.
pub(super) const VEC4_BYTES: u64 = 16;
pub(super) const F32_BYTES: u64 = 4;

/// Uniform block of `hash_encode.wgsl` and `hash_backward.wgsl` (`HashGridUniforms` in
/// `_hash_grid.wgsl`, field by field).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct HashGridUniforms {
    pub sample_count: u32,
    /// Hash-grid levels; 0 for the frequency-only encoding.
    pub levels: u32,
    pub features: u32,
    pub table_size: u32,
    /// Index of the table's first value in the flat params / gradient buffer.
    pub table_offset: u32,
    /// Values per encoding row (`cfg.encoding_dim()`).
    pub row_stride: u32,
    /// Column of the first frequency value (`cfg.hash_encoding_dim()`).
    pub frequency_column: u32,
    pub frequencies: u32,
    /// Backward: workgroups covering the samples of one level.
    pub groups_per_level: u32,
    pub _pad: [u32; 3],
    /// Per level: [cells per axis, vertices per axis if indexed densely else 0, the level's first
    /// entry in the table (`HashGrid::level_offsets`), 0].
    pub level_geometry: [[u32; 4]; MAX_HASH_LEVELS],
}

impl HashGridUniforms {
    /// The uniforms for `samples` positions encoded with `cfg`, the table starting at
    /// `table_offset` in the flat buffer.
    pub fn new(cfg: &FieldConfig, samples: usize, table_offset: usize) -> Result<Self, GpuError> {
        cfg.validate()
            .map_err(|error| GpuError::invalid_argument("hash grid config", error.to_string()))?;
        let grid = HashGrid::from_config(cfg);
        if grid.levels > MAX_HASH_LEVELS || grid.features > MAX_HASH_FEATURES {
            return Err(GpuError::invalid_argument(
                "hash grid config",
                format!(
                    "{} levels of {} features exceed the kernels' {MAX_HASH_LEVELS} levels of {MAX_HASH_FEATURES}",
                    grid.levels, grid.features
                ),
            ));
        }
        let mut level_geometry = [[0u32; 4]; MAX_HASH_LEVELS];
        for (level, geometry) in level_geometry.iter_mut().enumerate().take(grid.levels) {
            let resolution = grid.resolutions[level];
            let dense_side = if grid.is_dense(level) { resolution + 1 } else { 0 };
            let first_entry = index_u32("hash level offset", grid.level_offsets[level])?;
            *geometry = [resolution, dense_side, first_entry, 0];
        }
        let groups_per_level = samples.div_ceil(WORKGROUP_SIZE as usize);
        Ok(HashGridUniforms {
            sample_count: index_u32("sample count", samples)?,
            levels: grid.levels as u32,
            features: grid.features as u32,
            table_size: index_u32("hash table size", grid.table_size)?,
            table_offset: index_u32("hash table offset", table_offset)?,
            row_stride: index_u32("encoding width", cfg.encoding_dim())?,
            frequency_column: index_u32("hash encoding width", cfg.hash_encoding_dim())?,
            frequencies: cfg.encoding.frequencies(),
            groups_per_level: index_u32("workgroups per level", groups_per_level)?,
            _pad: [0; 3],
            level_geometry,
        })
    }
}

/// The buffers of [`PositionEncodePass`].
#[derive(Debug, Clone, Copy)]
pub struct PositionEncodeBuffers<'a> {
    /// N sample positions as `vec4<f32>` (xyz normalized to [0,1]³, w unused).
    pub positions: &'a wgpu::Buffer,
    /// The flat parameter buffer holding the hash table (bound read-only).
    pub params: &'a wgpu::Buffer,
    /// Index of the table's first value in `params` (`ParamLayout::hash_table.start`).
    pub table_offset: usize,
    /// Output: N rows of `cfg.encoding_dim()` f32.
    pub encoding: &'a wgpu::Buffer,
}

/// Forward of the position encoding (see the module docs).
#[derive(Debug)]
pub struct PositionEncodePass {
    dispatch: Dispatch,
    /// Kept with the pass that reads it.
    _uniforms: wgpu::Buffer,
}

impl PositionEncodePass {
    /// A pass encoding `samples` positions with `cfg`'s encoding.
    pub async fn new(
        ctx: &GpuContext,
        cfg: &FieldConfig,
        samples: usize,
        buffers: PositionEncodeBuffers<'_>,
    ) -> Result<Self, GpuError> {
        const WHAT: &str = "position encoding";
        let uniforms = HashGridUniforms::new(cfg, samples, buffers.table_offset)?;
        check_samples(WHAT, samples)?;
        let table_len = HashGrid::from_config(cfg).param_count();
        check_buffer(ctx, WHAT, "positions", buffers.positions, samples as u64 * VEC4_BYTES)?;
        check_buffer(
            ctx,
            WHAT,
            "params",
            buffers.params,
            (buffers.table_offset + table_len) as u64 * F32_BYTES,
        )?;
        let encoding_values = samples as u64 * cfg.encoding_dim() as u64;
        check_buffer(ctx, WHAT, "encoding", buffers.encoding, encoding_values * F32_BYTES)?;
        check_index_range(WHAT, encoding_values)?;
        check_index_range(WHAT, (buffers.table_offset + table_len) as u64)?;

        // Slots: one per hash level, plus one for the frequency encoding when there is one.
        let slots = uniforms.levels + u32::from(uniforms.frequencies > 0);
        let items = u64::from(slots) * samples as u64;
        check_index_range(WHAT, items + u64::from(WORKGROUP_SIZE) * u64::from(u16::MAX))?;
        let groups = Dispatch1d::for_device(ctx, items, WORKGROUP_SIZE)?;

        let spec = KernelSpec::new(WHAT, shaders::HASH_ENCODE, "hash_encode");
        let uniform_buffer = uniform_buffer_from(ctx, "position encoding uniforms", &uniforms);
        let bindings = whole(&[
            ("grid", &uniform_buffer),
            ("positions", buffers.positions),
            ("params", buffers.params),
            ("encoding", buffers.encoding),
        ]);
        let dispatch = Dispatch::build(ctx, &spec, &bindings, groups).await?;
        Ok(PositionEncodePass {
            dispatch,
            _uniforms: uniform_buffer,
        })
    }
}

impl Stage for PositionEncodePass {
    fn name(&self) -> &'static str {
        "encoding"
    }

    fn record(&self, pass: &mut wgpu::ComputePass<'_>) {
        if !self.dispatch.is_empty() {
            self.dispatch.record(pass);
        }
    }

    /// Reads N positions and the 8 corners × levels × features of the hash table a sample
    /// touches; writes N·E.
    fn global_bytes(&self, step: &StepShape) -> u64 {
        let n = step.samples();
        n * VEC4_BYTES + n * step.hash_corners() * F32_BYTES + n * step.cfg.encoding_dim() as u64 * F32_BYTES
    }
}

/// How the hash-grid backward cuts down its atomic adds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum BackwardStrategy {
    /// Runs of consecutive samples in the same cell (common on coarse levels, as samples of a
    /// ray are adjacent) are summed in registers and added once. The default.
    #[default]
    MergeRuns,
    /// Every sample adds its own 8 corners: the plain baseline, kept for measurements (with
    /// float atomics on lavapipe it is no faster: docs/results/bench.md, "Float atomics, fixed
    /// point").
    PerSample,
}

/// How the hash-grid backward adds a float into the gradient buffer.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AtomicAdd {
    /// An atomic load, then a compare-exchange loop on the f32's bits (`hash_backward.wgsl`):
    /// the one f32 add core WebGPU allows. [`AtomicAdd::best_for`] picks it for no device (it
    /// retries under contention: fixed point replaced it on GPUs, one invocation per level on
    /// CPU devices); it stays the portable f32 add the encoding tests run beside the others on
    /// every device.
    CompareExchange,
    /// One float `atomicAdd` (`hash_backward_float_atomics.wgsl`): native devices with
    /// `SHADER_FLOAT32_ATOMIC` (Vulkan's VK_EXT_shader_atomic_float, Metal 3).
    Float,
    /// One i32 `atomicAdd` of the value in fixed point (`hash_backward_fixed_point.wgsl`), at a
    /// per-level scale `hash_gradient_scale.wgsl` picks each step so that no sum can overflow;
    /// Adam decodes the table's integers (`field::gpu::fixed_point`). Core WebGPU.
    FixedPoint,
    /// No atomic at all (`hash_backward_per_level.wgsl`): one invocation per level adds its
    /// samples in order, with plain loads and stores, into the level's own part of the table.
    /// Always merges runs ([`BackwardStrategy`] does not apply). Core WebGPU; for CPU devices
    /// without float atomics (SwiftShader), whose compare-exchange loops are slow.
    PerLevel,
}

impl AtomicAdd {
    /// Float atomics where the device has them (lavapipe: as fast as one invocation per level
    /// at `small` and `budget`, faster at `full`); otherwise one invocation per level on a CPU
    /// device, whose atomics and workgroup barriers are slow, and fixed point on a GPU, where a
    /// compare-exchange loop retries under contention (docs/results/bench.md, "Float atomics,
    /// fixed point" and "The hash backward without atomics on CPU devices").
    pub fn best_for(ctx: &GpuContext) -> AtomicAdd {
        if ctx.features.contains(wgpu::Features::SHADER_FLOAT32_ATOMIC) {
            AtomicAdd::Float
        } else if ctx.profile().kernels == KernelFamily::UniformWeights {
            AtomicAdd::PerLevel
        } else {
            AtomicAdd::FixedPoint
        }
    }
}

/// Where a fixed-point table gradient's scales are, for the pass that decodes it (Adam).
#[derive(Debug, Clone)]
pub struct FixedPointTable<'a> {
    /// The backward's `HashGridUniforms` (`shaders/_hash_grid.wgsl`): the levels' first entries.
    pub grid: &'a wgpu::Buffer,
    /// One i32 exponent per level (`MAX_HASH_LEVELS`): level l's values are in units of 2^-e.
    pub exponents: &'a wgpu::Buffer,
    /// The table's elements in the flat gradient buffer.
    pub table: Range<usize>,
}

/// The buffers of [`HashGridBackwardPass`].
#[derive(Debug, Clone, Copy)]
pub struct HashGridBackwardBuffers<'a> {
    /// The N positions the forward encoded.
    pub positions: &'a wgpu::Buffer,
    /// ∂L/∂encoding: N rows of `cfg.encoding_dim()` f32 (only the hash columns are read).
    pub encoding_grad: &'a wgpu::Buffer,
    /// The flat gradient buffer, bound as `array<atomic<u32>>`, `array<atomic<f32>>` or
    /// `array<atomic<i32>>` ([`AtomicAdd`]).
    pub gradient: &'a wgpu::Buffer,
    /// Index of the table's first value in `gradient` (`ParamLayout::hash_table.start`).
    pub table_offset: usize,
}

/// Backward of the hash grid (see the module docs). For the frequency-only encoding there is
/// nothing to do and recording is a no-op.
#[derive(Debug)]
pub struct HashGridBackwardPass {
    kernel: Option<BoundKernel>,
    gradient: wgpu::Buffer,
    /// Bytes of the table's range in the gradient buffer.
    table_bytes: Range<u64>,
    atomics: AtomicAdd,
}

#[derive(Debug)]
struct BoundKernel {
    /// Fixed point only: the levels' exponents for this step, before the adds.
    scale: Option<Dispatch>,
    /// One, or one per range of samples (one invocation per level: [`PER_LEVEL_LOOP_BUDGET`]).
    dispatches: Vec<Dispatch>,
    uniforms: wgpu::Buffer,
    /// The ranges' uniforms, kept alive with their bind groups.
    _ranges: Vec<wgpu::Buffer>,
    /// Fixed point only: `MAX_HASH_LEVELS` i32, written by `scale`.
    exponents: Option<wgpu::Buffer>,
    /// Each level's first entry in the table, and the values per entry (for decoding).
    level_starts: Vec<u32>,
    features: usize,
}

impl HashGridBackwardPass {
    /// A pass for `samples` samples with the default [`BackwardStrategy`] and the atomic add
    /// that suits the device ([`AtomicAdd::best_for`]).
    pub async fn new(
        ctx: &GpuContext,
        cfg: &FieldConfig,
        samples: usize,
        buffers: HashGridBackwardBuffers<'_>,
    ) -> Result<Self, GpuError> {
        Self::with_strategy(ctx, cfg, samples, buffers, BackwardStrategy::default()).await
    }

    /// As [`HashGridBackwardPass::new`] with the given strategy, and the best atomic add the
    /// device has ([`AtomicAdd::best_for`]).
    pub async fn with_strategy(
        ctx: &GpuContext,
        cfg: &FieldConfig,
        samples: usize,
        buffers: HashGridBackwardBuffers<'_>,
        strategy: BackwardStrategy,
    ) -> Result<Self, GpuError> {
        Self::with_atomics(ctx, cfg, samples, buffers, strategy, AtomicAdd::best_for(ctx)).await
    }

    /// As [`HashGridBackwardPass::with_strategy`] with the given atomic add; [`AtomicAdd::Float`]
    /// on a device without float atomics is an error.
    pub async fn with_atomics(
        ctx: &GpuContext,
        cfg: &FieldConfig,
        samples: usize,
        buffers: HashGridBackwardBuffers<'_>,
        strategy: BackwardStrategy,
        atomics: AtomicAdd,
    ) -> Result<Self, GpuError> {
        const WHAT: &str = "hash grid backward";
        if atomics == AtomicAdd::Float && !ctx.features.contains(wgpu::Features::SHADER_FLOAT32_ATOMIC) {
            return Err(GpuError::invalid_argument(
                WHAT,
                format!(
                    "float atomics asked for, but {} has no SHADER_FLOAT32_ATOMIC",
                    ctx.describe()
                ),
            ));
        }
        let uniforms = HashGridUniforms::new(cfg, samples, buffers.table_offset)?;
        check_samples(WHAT, samples)?;
        let table_len = HashGrid::from_config(cfg).param_count();
        let table_end = (buffers.table_offset + table_len) as u64;
        check_buffer(ctx, WHAT, "positions", buffers.positions, samples as u64 * VEC4_BYTES)?;
        let grad_values = samples as u64 * cfg.encoding_dim() as u64;
        check_buffer(
            ctx,
            WHAT,
            "encoding gradient",
            buffers.encoding_grad,
            grad_values * F32_BYTES,
        )?;
        check_buffer(ctx, WHAT, "gradient", buffers.gradient, table_end * F32_BYTES)?;
        check_index_range(WHAT, grad_values)?;
        check_index_range(WHAT, table_end)?;
        let table_bytes = buffers.table_offset as u64 * F32_BYTES..table_end * F32_BYTES;
        if uniforms.levels == 0 || samples == 0 {
            return Ok(HashGridBackwardPass {
                kernel: None,
                gradient: buffers.gradient.clone(),
                table_bytes,
                atomics,
            });
        }

        let uniform_buffer = uniform_buffer_from(ctx, "hash grid backward uniforms", &uniforms);
        let merge_runs = [(
            "MERGE_RUNS",
            f64::from(u8::from(strategy == BackwardStrategy::MergeRuns)),
        )];
        // One workgroup per (level, WORKGROUP_SIZE consecutive samples), adding atomically.
        let per_sample = |source| -> Result<(KernelSpec<'_>, [u32; 3], Vec<SampleRange>), GpuError> {
            let workgroups = u64::from(uniforms.levels) * u64::from(uniforms.groups_per_level);
            check_index_range(WHAT, workgroups + u64::from(u16::MAX))?;
            let workgroup_bytes = u64::from(WORKGROUP_SIZE) * (16 + 16 + MAX_HASH_FEATURES as u64 * F32_BYTES);
            ctx.ensure_workgroup_storage_fits("hash grid backward run merging", workgroup_bytes)?;
            let groups = Dispatch1d::for_device(ctx, workgroups * u64::from(WORKGROUP_SIZE), WORKGROUP_SIZE)?;
            let spec = KernelSpec {
                constants: &merge_runs,
                ..KernelSpec::new(WHAT, source, "hash_backward")
            };
            Ok((spec, groups.into(), Vec::new()))
        };
        // The kernel, its workgroups and the sample ranges it is dispatched over, one dispatch
        // each (none: one dispatch over every sample).
        let (spec, groups, sample_ranges) = match atomics {
            // One invocation per level, LEVELS_PER_GROUP to a workgroup, over ranges that keep
            // each invocation's loops under the driver's limit (`PER_LEVEL_LOOP_BUDGET`).
            AtomicAdd::PerLevel => {
                let chunk = per_level_chunk(uniforms.features);
                let ranges = (0..samples as u64)
                    .step_by(chunk as usize)
                    .map(|first| SampleRange {
                        first: first as u32,
                        end: (first + chunk).min(samples as u64) as u32,
                        _pad0: 0,
                        _pad1: 0,
                    })
                    .collect();
                (
                    KernelSpec::new(WHAT, shaders::HASH_BACKWARD_PER_LEVEL, "hash_backward"),
                    [uniforms.levels.div_ceil(LEVELS_PER_GROUP), 1, 1],
                    ranges,
                )
            }
            AtomicAdd::Float => per_sample(shaders::HASH_BACKWARD_FLOAT_ATOMICS)?,
            AtomicAdd::FixedPoint => per_sample(shaders::HASH_BACKWARD_FIXED_POINT)?,
            AtomicAdd::CompareExchange => per_sample(shaders::HASH_BACKWARD)?,
        };
        let exponents = (atomics == AtomicAdd::FixedPoint)
            .then(|| storage_buffer_zeroed::<i32>(ctx, "hash gradient exponents", MAX_HASH_LEVELS))
            .transpose()?;
        let scale = match &exponents {
            Some(exponents) => {
                let spec = KernelSpec::new(
                    "hash gradient scale",
                    shaders::HASH_GRADIENT_SCALE,
                    "hash_gradient_scale",
                );
                let bindings = whole(&[
                    ("grid", &uniform_buffer),
                    ("encoding_grad", buffers.encoding_grad),
                    ("exponents", exponents),
                ]);
                Some(Dispatch::build(ctx, &spec, &bindings, [uniforms.levels, 1, 1]).await?)
            }
            None => None,
        };
        let mut named = vec![
            ("grid", &uniform_buffer),
            ("positions", buffers.positions),
            ("encoding_grad", buffers.encoding_grad),
            ("gradient", buffers.gradient),
        ];
        if let Some(exponents) = &exponents {
            named.push(("exponents", exponents));
        }
        let ranges: Vec<wgpu::Buffer> = sample_ranges
            .iter()
            .map(|range| uniform_buffer_from(ctx, "hash grid backward sample range", range))
            .collect();
        let mut dispatches = Vec::new();
        if ranges.is_empty() {
            dispatches.push(Dispatch::build(ctx, &spec, &whole(&named), groups).await?);
        }
        for range in &ranges {
            let mut with_range = named.clone();
            with_range.push(("range", range));
            dispatches.push(Dispatch::build(ctx, &spec, &whole(&with_range), groups).await?);
        }
        Ok(HashGridBackwardPass {
            kernel: Some(BoundKernel {
                scale,
                dispatches,
                uniforms: uniform_buffer,
                _ranges: ranges,
                exponents,
                level_starts: uniforms.level_geometry[..uniforms.levels as usize]
                    .iter()
                    .map(|g| g[2])
                    .collect(),
                features: uniforms.features as usize,
            }),
            gradient: buffers.gradient.clone(),
            table_bytes,
            atomics,
        })
    }

    /// Starts reading the levels' exponents back when the adds are fixed point.
    pub fn read_exponents(&self, ctx: &GpuContext) -> Option<PendingRead<i32>> {
        let kernel = self.kernel.as_ref()?;
        Some(read_buffer_async::<i32>(ctx, kernel.exponents.as_ref()?))
    }

    /// Decodes the table's range of `flat` (the whole gradient buffer read back as f32) with the
    /// exponents [`HashGridBackwardPass::read_exponents`] read; nothing to do without them.
    pub async fn decode_fixed_point(
        &self,
        flat: &mut [f32],
        exponents: Option<PendingRead<i32>>,
    ) -> Result<(), GpuError> {
        let (Some(kernel), Some(exponents)) = (&self.kernel, exponents) else {
            return Ok(());
        };
        let exponents = exponents.await?;
        let range = (self.table_bytes.start / F32_BYTES) as usize..(self.table_bytes.end / F32_BYTES) as usize;
        let Some(table) = flat.get_mut(range.clone()) else {
            return Err(GpuError::invalid_argument(
                "hash grid backward",
                format!("{} values read back, the table spans {range:?}", flat.len()),
            ));
        };
        decode_table(table, &exponents, &kernel.level_starts, kernel.features);
        Ok(())
    }

    /// How this pass adds into the gradient buffer.
    pub fn atomics(&self) -> AtomicAdd {
        self.atomics
    }

    /// With fixed-point adds, where the table's integers and their scales are; the gradient
    /// buffer's table range holds i32 until the pass given this decodes it.
    pub fn fixed_point_table(&self) -> Option<FixedPointTable<'_>> {
        let kernel = self.kernel.as_ref()?;
        let exponents = kernel.exponents.as_ref()?;
        let bytes = &self.table_bytes;
        Some(FixedPointTable {
            grid: &kernel.uniforms,
            exponents,
            table: (bytes.start / F32_BYTES) as usize..(bytes.end / F32_BYTES) as usize,
        })
    }

    /// Records zeroing the table's range of the gradient buffer; record it before the compute
    /// pass holding [`HashGridBackwardPass::record`] (the buffer needs COPY_DST).
    pub fn record_clear(&self, encoder: &mut wgpu::CommandEncoder) {
        let Range { start, end } = self.table_bytes;
        if end > start {
            encoder.clear_buffer(&self.gradient, start, Some(end - start));
        }
    }
}

impl Stage for HashGridBackwardPass {
    fn name(&self) -> &'static str {
        "encoding backward"
    }

    /// Records the accumulation of ∂L/∂table into the (zeroed) gradient buffer.
    fn record(&self, pass: &mut wgpu::ComputePass<'_>) {
        let Some(kernel) = &self.kernel else { return };
        if let Some(scale) = &kernel.scale {
            scale.record(pass);
        }
        for dispatch in &kernel.dispatches {
            dispatch.record(pass);
        }
    }

    /// Reads N hash-grid gradient rows and positions; an atomic add (a read and a write) per
    /// corner, level and feature. Fixed point first bounds each level's sums: one more read of
    /// the gradient rows, an exponent written per level. One invocation per level reads every
    /// position once per level.
    fn global_bytes(&self, step: &StepShape) -> u64 {
        if self.kernel.is_none() {
            return 0;
        }
        let n = step.samples();
        let levels = u64::from(step.cfg.hash_levels);
        let gradient_rows = n * step.cfg.hash_encoding_dim() as u64 * F32_BYTES;
        let adds = n * VEC4_BYTES + gradient_rows + 2 * n * step.hash_corners() * F32_BYTES;
        let scale = match self.fixed_point_table() {
            Some(_) => gradient_rows + levels * F32_BYTES,
            None => 0,
        };
        let positions_again = match self.atomics {
            AtomicAdd::PerLevel => n * VEC4_BYTES * levels.saturating_sub(1),
            _ => 0,
        };
        adds + scale + positions_again
    }
}

pub(super) fn index_u32(what: &str, value: usize) -> Result<u32, GpuError> {
    u32::try_from(value).map_err(|_| GpuError::invalid_argument(what, format!("{value} does not fit the kernels' u32")))
}

/// The kernels index with u32: every element index (and the dispatch's overshoot) must fit.
pub(super) fn check_index_range(what: &str, elements: u64) -> Result<(), GpuError> {
    if elements > u64::from(u32::MAX) {
        return Err(GpuError::invalid_argument(
            what,
            format!("{elements} elements exceed the kernels' u32 indices"),
        ));
    }
    Ok(())
}

pub(super) fn check_samples(what: &str, samples: usize) -> Result<(), GpuError> {
    index_u32(what, samples).map(|_| ())
}

/// The buffer holds at least `needed` bytes and can be bound whole on this device.
pub(super) fn check_buffer(
    ctx: &GpuContext,
    what: &str,
    role: &str,
    buffer: &wgpu::Buffer,
    needed: u64,
) -> Result<(), GpuError> {
    if buffer.size() < needed {
        return Err(GpuError::invalid_argument(
            format!("{what}: {role} buffer"),
            format!("holds {} bytes but {needed} are needed", buffer.size()),
        ));
    }
    ctx.ensure_storage_binding_fits(&format!("{what}: {role} buffer"), buffer.size())
}

#[cfg(test)]
#[path = "encoding_tests.rs"]
mod tests;
