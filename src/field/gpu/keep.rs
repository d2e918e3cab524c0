//! Which samples reach the heads (`shaders/keep.wgsl`), the GPU twin of
//! `reference::render::kept_samples`: after the density MLP, samples whose compositing weight
//! is below `FieldConfig::head_weight_threshold` are dropped, and the rest are packed, in sample
//! order, into the first rows of the heads' buffers.
//!
//! [`HeadRows`] is what the head passes share: the packed row count (a storage word their
//! kernels stop at), `rows` (packed row → sample), `slot` (sample → packed row or
//! [`NOT_KEPT`]) and the workgroup counts of every head kernel, which the keep pass writes on
//! the GPU so that the head kernels launch through `dispatch_workgroups_indirect` for the kept
//! rows alone. Each head kernel shape asks [`HeadRows::dispatch`] for its slot of those counts
//! while the passes are built; [`KeepPass`], built after them, writes all the slots asked for.
use std::sync::Mutex;

use bytemuck::{Pod, Zeroable};

use super::row_view::RowView;
use super::stage::{Stage, StepShape, WORD};
use crate::gpu::buffers::{STORAGE_USAGE, storage_buffer_from, storage_buffer_zeroed, uniform_buffer_from};
use crate::gpu::dispatch::{Dispatch, IndirectArgs, bindings_used, whole};
use crate::gpu::pipeline::{Dispatch1d, KernelSpec};
use crate::gpu::{GpuContext, GpuError, shaders};

/// `slot` of a sample that does not reach the heads.
pub const NOT_KEPT: u32 = u32::MAX;
/// Invocations per workgroup of the per-ray and per-row kernels (`WORKGROUP_SIZE`).
const WORKGROUP_SIZE: u32 = 64;
/// Head kernel shapes one set of rows can serve: every MLP layer's forward and input gradient,
/// the weight gradients' masks and the glue take a few each.
const MAX_DISPATCH_SLOTS: usize = 128;
/// Bytes of one slot of workgroup counts.
const SLOT_BYTES: u64 = 12;

/// Mirrors `KeepUniforms` in `shaders/keep.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct KeepUniforms {
    pub threshold: f32,
    pub density_stride: u32,
    pub sh_width: u32,
    pub color_stride: u32,
    pub arg_count: u32,
    pub max_groups_per_dimension: u32,
    pub target_stride: u32,
    pub _pad: u32,
}

/// The packed rows of the samples that reach the heads, shared by the keep pass (which writes
/// them) and the head passes (which read their row count and workgroup counts from them).
#[derive(Debug)]
pub struct HeadRows {
    /// Most rows: every sample of a batch.
    pub capacity: u32,
    /// One u32: the kept rows.
    pub row_count: wgpu::Buffer,
    /// `capacity` u32: the sample of each packed row (the first `row_count`).
    pub rows: wgpu::Buffer,
    /// `capacity` u32: each sample's packed row, or [`NOT_KEPT`].
    pub slot: wgpu::Buffer,
    /// Three u32 workgroup counts per shape asked for (INDIRECT usage).
    pub dispatch_args: wgpu::Buffer,
    /// Two u32, wrapping: kept rows summed over every decision, and the decisions.
    pub kept_tally: wgpu::Buffer,
    /// (items per row, items per workgroup, z workgroups, 0) of each slot, in slot order.
    shapes: Mutex<Vec<[u32; 4]>>,
}

impl HeadRows {
    pub fn new(ctx: &GpuContext, capacity: u32) -> Result<HeadRows, GpuError> {
        let dispatch_args = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("head kernels' workgroup counts"),
            size: MAX_DISPATCH_SLOTS as u64 * SLOT_BYTES,
            usage: STORAGE_USAGE | wgpu::BufferUsages::INDIRECT,
            mapped_at_creation: false,
        });
        Ok(HeadRows {
            capacity,
            row_count: storage_buffer_from(ctx, "kept row count", &[capacity])?,
            rows: storage_buffer_zeroed::<u32>(ctx, "kept rows", capacity as usize)?,
            slot: storage_buffer_zeroed::<u32>(ctx, "kept slot of each sample", capacity as usize)?,
            dispatch_args,
            kept_tally: storage_buffer_zeroed::<u32>(ctx, "kept rows tally", 2)?,
            shapes: Mutex::new(Vec::new()),
        })
    }

    /// Where the workgroup counts of a head kernel will be: a 1D job of `items_per_row` items
    /// per kept row in workgroups of `per_workgroup` items (spread over x and y as
    /// [`Dispatch1d`]), times `z` along z. Shapes asked for twice share a slot.
    pub fn dispatch(&self, items_per_row: u32, per_workgroup: u32, z: u32) -> Result<IndirectArgs, GpuError> {
        if items_per_row == 0 || per_workgroup == 0 || z == 0 {
            return Err(GpuError::invalid_argument(
                "head kernel dispatch",
                format!("{items_per_row} items per row in workgroups of {per_workgroup}, {z} deep"),
            ));
        }
        let shape = [items_per_row, per_workgroup, z, 0];
        let mut shapes = self.shapes.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
        let index = match shapes.iter().position(|s| *s == shape) {
            Some(index) => index,
            None if shapes.len() < MAX_DISPATCH_SLOTS => {
                shapes.push(shape);
                shapes.len() - 1
            }
            None => {
                return Err(GpuError::LimitExceeded {
                    what: "head kernel shapes".into(),
                    limit: "MAX_DISPATCH_SLOTS",
                    needed: shapes.len() as u64 + 1,
                    allowed: MAX_DISPATCH_SLOTS as u64,
                });
            }
        };
        Ok(IndirectArgs {
            buffer: self.dispatch_args.clone(),
            offset: index as u64 * SLOT_BYTES,
        })
    }

    /// The shapes asked for so far, in slot order.
    pub fn shapes(&self) -> Vec<[u32; 4]> {
        self.shapes
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner())
            .clone()
    }
}

/// The workgroup counts `scan_kept` writes for one shape of [`HeadRows::shapes`] when `rows`
/// rows are kept: its CPU twin (tests write them without running the keep pass).
pub fn workgroup_counts(shape: [u32; 4], rows: u32, max_per_dimension: u32) -> [u32; 3] {
    let [items_per_row, per_workgroup, z, _] = shape;
    let groups = (rows * items_per_row).div_ceil(per_workgroup);
    let x = groups.min(max_per_dimension);
    let y = if x > 0 { groups.div_ceil(x) } else { 1 };
    [x, y, z]
}

/// What the keep pass decides from, and where the packed head inputs go.
pub struct KeepBuffers<'a> {
    pub step_uniforms: &'a wgpu::Buffer,
    /// The density MLP's output rows [h₀ | g], `density_stride` values per sample.
    pub density_out: &'a wgpu::Buffer,
    /// `SamplePointsPass::intervals`.
    pub intervals: &'a wgpu::Buffer,
    /// `RayBatchPass::targets` (the flags say which rays hit the box).
    pub targets: &'a wgpu::Buffer,
    /// The view's SH coefficients, `sh_width` per sample, in the colour rows' format.
    pub sh_rows: &'a wgpu::Buffer,
    /// Packed [h₀ | g] rows: what the feature MLP and the glue read.
    pub density_packed: &'a wgpu::Buffer,
    /// Packed colour-input rows [SH | g], f32 or bf16 (the colour MLP's own input rows): the SH
    /// part is written here.
    pub color_packed: &'a RowView,
}

/// The shapes of the rows the keep pass reads and writes.
#[derive(Clone, Copy, Debug)]
pub struct KeepShape {
    pub batch_rays: u32,
    pub samples_per_ray: u32,
    pub threshold: f32,
    pub density_stride: u32,
    pub sh_width: u32,
    pub target_stride: u32,
}

/// One entry point of `keep.wgsl`, bound to those of `all` it uses.
async fn kernel(
    ctx: &GpuContext,
    entry: &'static str,
    all: &[(&str, wgpu::BindingResource<'_>)],
    groups: [u32; 3],
    constants: &[(&str, f64)],
) -> Result<Dispatch, GpuError> {
    let spec = KernelSpec {
        constants,
        ..KernelSpec::new(entry, shaders::KEEP, entry)
    };
    let used = bindings_used(&spec, 0)?;
    let mine: Vec<_> = all
        .iter()
        .filter(|(name, _)| used.iter().any(|b| b.name == *name))
        .cloned()
        .collect();
    Dispatch::build(ctx, &spec, &mine, groups).await
}

/// Decides which samples reach the heads, packs them and writes the head kernels' workgroup
/// counts; then gathers the packed head inputs.
pub struct KeepPass {
    count: Dispatch,
    scan: Dispatch,
    compact: Dispatch,
    gather: Dispatch,
    /// Owned so the bind groups' buffers live as long as the pass.
    _buffers: [wgpu::Buffer; 3],
}

impl KeepPass {
    /// Build it after every pass that asked `rows` for a dispatch slot: it writes the slots
    /// asked for by then.
    pub async fn new(
        ctx: &GpuContext,
        shape: KeepShape,
        rows: &HeadRows,
        b: &KeepBuffers<'_>,
    ) -> Result<KeepPass, GpuError> {
        let samples = u64::from(shape.batch_rays) * u64::from(shape.samples_per_ray);
        if samples != u64::from(rows.capacity) {
            return Err(GpuError::invalid_argument(
                "keep pass",
                format!("{samples} samples per batch, head rows for {}", rows.capacity),
            ));
        }
        let color = b.color_packed;
        color.check("keep pass: colour input rows", rows.capacity, shape.sh_width)?;
        if color.offset != 0 || (color.is_bf16() && !shape.sh_width.is_multiple_of(2)) {
            return Err(GpuError::invalid_argument(
                "keep pass",
                format!(
                    "the SH part of the colour input rows must start them (offset {}) and fill whole words \
                     of bf16 rows ({} values)",
                    color.offset, shape.sh_width
                ),
            ));
        }
        let gather_args = rows.dispatch(1, WORKGROUP_SIZE, 1)?;
        let shapes = rows.shapes();
        let uniforms = KeepUniforms {
            threshold: shape.threshold,
            density_stride: shape.density_stride,
            sh_width: shape.sh_width,
            color_stride: color.stride,
            arg_count: shapes.len() as u32,
            max_groups_per_dimension: ctx.limits.max_compute_workgroups_per_dimension,
            target_stride: shape.target_stride,
            _pad: 0,
        };
        let uniform = uniform_buffer_from(ctx, "keep uniforms", &uniforms);
        let specs = storage_buffer_from(ctx, "head kernel shapes", &shapes)?;
        let batch = shape.batch_rays as usize;
        let ray_kept = storage_buffer_zeroed::<u32>(ctx, "kept samples per ray", batch)?;
        let ray_first = storage_buffer_zeroed::<u32>(ctx, "first kept row per ray", batch)?;
        let per_ray = Dispatch1d::for_device(ctx, u64::from(shape.batch_rays), WORKGROUP_SIZE)?;
        let most_rows = Dispatch1d::for_device(ctx, u64::from(rows.capacity), WORKGROUP_SIZE)?;
        let bindings = whole(&[
            ("step_info", b.step_uniforms),
            ("keep", &uniform),
            ("density_out", b.density_out),
            ("intervals", b.intervals),
            ("targets", b.targets),
            ("ray_kept", &ray_kept),
            ("ray_first", &ray_first),
            ("row_count", &rows.row_count),
            ("dispatch_args", &rows.dispatch_args),
            ("arg_specs", &specs),
            ("rows", &rows.rows),
            ("slot", &rows.slot),
            ("sh_rows", b.sh_rows),
            ("density_packed", b.density_packed),
            ("color_packed", &color.buffer),
            ("kept_tally", &rows.kept_tally),
        ]);
        let count = kernel(ctx, "count_kept", &bindings, per_ray.into(), &[]).await?;
        let scan = kernel(ctx, "scan_kept", &bindings, [1, 1, 1], &[]).await?;
        let compact = kernel(ctx, "compact_kept", &bindings, per_ray.into(), &[]).await?;
        let color_bf16 = [("COLOR_BF16", f64::from(u8::from(color.is_bf16())))];
        let gather = kernel(ctx, "gather_rows", &bindings, most_rows.into(), &color_bf16)
            .await?
            .with_indirect(Some(gather_args));
        Ok(KeepPass {
            count,
            scan,
            compact,
            gather,
            _buffers: [ray_kept, ray_first, specs],
        })
    }
}

impl Stage for KeepPass {
    fn name(&self) -> &'static str {
        "keep"
    }

    /// Records the decision, the packing and the gather of the packed head inputs.
    fn record(&self, pass: &mut wgpu::ComputePass<'_>) {
        self.count.record(pass);
        self.scan.record(pass);
        self.compact.record(pass);
        self.gather.record(pass);
    }

    /// Reads N density outputs (h₀) and intervals twice, R flags and counts, K·(1 + g + 16)
    /// gathered; writes R counts, N slots, K rows and K·(1 + g + 16) (the SH in the colour
    /// input's format).
    fn global_bytes(&self, step: &StepShape) -> u64 {
        let (n, r, k) = (step.samples(), step.rays(), step.kept());
        let (g, _) = step.geometry_and_feature();
        let sh = StepShape::words(step.heads.color_input, 16);
        WORD * (2 * 3 * n + 3 * r + n + k + 2 * k * (1 + g) + 2 * k * sh)
    }
}
