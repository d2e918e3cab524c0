//! The glue between the density MLP and the heads (`shaders/head_glue.wgsl`): builds the colour
//! and semantic inputs from the geometry feature and f, and routes the heads' input gradients
//! back to f and to the density output, exactly as `reference::model` does per sample. The
//! heads' rows are the kept samples, packed (`super::keep`): the forward glue and the feature
//! gather run on those rows (indirect dispatches), the geometry gather on every sample.
use bytemuck::{Pod, Zeroable};

use super::row_view::{RowFormat, RowView};
use super::stage::{Stage, StepShape, WORD};
use crate::gpu::buffers::uniform_buffer_from;
use crate::gpu::dispatch::{Dispatch, IndirectArgs, whole};
use crate::gpu::pipeline::{Dispatch1d, KernelSpec};
use crate::gpu::{GpuContext, GpuError, shaders};

/// Invocations per workgroup of the glue's kernels.
pub const WORKGROUP_SIZE: u32 = 128;

/// Mirrors `GlueDims` in shaders/head_glue.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct GlueDims {
    pub samples: u32,
    pub geometry: u32,
    pub feature: u32,
    pub sh: u32,
    /// Layout of the composite's gradient rows (`CompositeLayout`).
    pub grad_stride: u32,
    pub grad_h0: u32,
    pub grad_feature: u32,
    /// `FieldConfig::semantic_trunk_gradient`: scales the semantic input's gradient on its way
    /// back into f and g.
    pub semantic_trunk_scale: f32,
    /// Columns of g in the semantic input (`FieldConfig::semantic_geometry_dim`: geometry or 0).
    pub semantic_geometry: u32,
    /// Row strides, in values, of the semantic input and its gradient (set by
    /// [`HeadGluePass::new`] from their views).
    pub semantic_in_stride: u32,
    pub semantic_grad_stride: u32,
    /// Row stride, in values, of f (set by [`HeadGluePass::new`]).
    pub feature_stride: u32,
    /// Row strides, in values, of the colour input and its gradient (set by
    /// [`HeadGluePass::new`]).
    pub color_in_stride: u32,
    pub color_grad_stride: u32,
    /// Row stride, in values, of the feature MLP's input gradient (set by
    /// [`HeadGluePass::new`]).
    pub feature_grad_stride: u32,
    pub _pad: u32,
}

/// The buffers the glue reads and writes (row strides in `GlueDims` terms); all but
/// `density_out_grad`, `grad_h0_source` and `slot` hold packed rows.
pub struct GlueBuffers<'a> {
    /// [h0 | g], stride 1 + geometry (the packed copy `keep.wgsl` gathers).
    pub density_out: &'a wgpu::Buffer,
    /// f per packed row, f32 or bf16: the feature MLP's output rows.
    pub feature_out: &'a RowView,
    /// [SH | g] per row, f32 or bf16: the colour MLP's input rows.
    pub color_in: &'a RowView,
    /// [relu(f) | g] per row, f32 or bf16: the semantic MLP's input rows.
    pub semantic_in: &'a RowView,
    /// Their gradient, as the semantic MLP writes it.
    pub semantic_in_grad: &'a RowView,
    /// The composite's packed head-gradient rows; `gather_feature` adds the semantic path into
    /// dL/df.
    pub grad_heads: &'a wgpu::Buffer,
    /// The composite's per-sample gradient rows, read for dL/dh0.
    pub grad_h0_source: &'a wgpu::Buffer,
    /// [dL/dh0 | dL/dg], stride 1 + geometry: written whole by `gather_geometry`.
    pub density_out_grad: &'a wgpu::Buffer,
    /// Their gradient, as the colour MLP writes it.
    pub color_in_grad: &'a RowView,
    /// The feature MLP's input gradient, f32 or bf16, as the feature MLP writes it.
    pub feature_in_grad: &'a RowView,
}

/// The kept rows the glue works on (from `super::keep::HeadRows`).
pub struct GlueRows<'a> {
    /// One word: the packed rows present.
    pub row_count: &'a wgpu::Buffer,
    /// Per sample, its packed row or `keep::NOT_KEPT`.
    pub slot: &'a wgpu::Buffer,
    /// Workgroup counts of a pass over the packed rows (1 item per row, [`WORKGROUP_SIZE`] per
    /// workgroup); `None` launches for all `samples` rows.
    pub dispatch: Option<IndirectArgs>,
}

/// The glue's three stages: the forward and the two gathers of the backward.
pub struct HeadGluePass {
    pub assemble: GlueAssemble,
    pub gather_feature: GlueGatherFeature,
    pub gather_geometry: GlueGatherGeometry,
}

/// Forward: the colour input's g columns and the whole semantic input.
pub struct GlueAssemble(Dispatch);
/// Backward, after the semantic head: dL/df += relu'(f) · dL/d(semantic input)[f part].
pub struct GlueGatherFeature(Dispatch);
/// Backward, after all heads: dL/dg into columns 1.. of the density output gradient.
pub struct GlueGatherGeometry(Dispatch);

async fn stage(
    ctx: &GpuContext,
    entry: &str,
    groups: Dispatch1d,
    bindings: &[(&str, &wgpu::Buffer)],
    constants: &[(&str, f64)],
) -> Result<Dispatch, GpuError> {
    let spec = KernelSpec {
        constants,
        ..KernelSpec::new(entry, shaders::HEAD_GLUE, entry)
    };
    Dispatch::build(ctx, &spec, &whole(bindings), groups).await
}

impl HeadGluePass {
    pub async fn new(
        ctx: &GpuContext,
        dims: GlueDims,
        b: &GlueBuffers<'_>,
        rows: &GlueRows<'_>,
    ) -> Result<Self, GpuError> {
        let width = dims.feature + dims.semantic_geometry;
        b.feature_out.check("head glue: f", dims.samples, dims.feature)?;
        b.feature_in_grad
            .check("head glue: feature input gradient", dims.samples, dims.geometry)?;
        let color_width = dims.sh + dims.geometry;
        b.color_in.check("head glue: colour input", dims.samples, color_width)?;
        b.color_in_grad
            .check("head glue: colour input gradient", dims.samples, color_width)?;
        if !dims.sh.is_multiple_of(2) && (b.color_in.is_bf16() || b.color_in_grad.is_bf16()) {
            return Err(GpuError::invalid_argument(
                "head glue",
                format!("bf16 colour rows need an even SH width, not {}", dims.sh),
            ));
        }
        b.semantic_in.check("head glue: semantic input", dims.samples, width)?;
        b.semantic_in_grad
            .check("head glue: semantic input gradient", dims.samples, width)?;
        let views = [
            b.feature_out,
            b.color_in,
            b.color_in_grad,
            b.feature_in_grad,
            b.semantic_in,
            b.semantic_in_grad,
        ];
        if views.iter().any(|view| view.offset != 0) {
            return Err(GpuError::invalid_argument(
                "head glue",
                "f, the colour and semantic inputs and the heads' input gradients must start their rows",
            ));
        }
        let dims = GlueDims {
            semantic_in_stride: b.semantic_in.stride,
            semantic_grad_stride: b.semantic_in_grad.stride,
            feature_stride: b.feature_out.stride,
            color_in_stride: b.color_in.stride,
            color_grad_stride: b.color_in_grad.stride,
            feature_grad_stride: b.feature_in_grad.stride,
            ..dims
        };
        let bf16 = |name, view: &RowView| (name, f64::from(u8::from(view.is_bf16())));
        let feature_bf16 = bf16("FEATURE_BF16", b.feature_out);
        let semantic_grad_bf16 = bf16("SEMANTIC_GRAD_BF16", b.semantic_in_grad);
        let input_bf16 = [
            feature_bf16,
            bf16("SEMANTIC_IN_BF16", b.semantic_in),
            bf16("COLOR_IN_BF16", b.color_in),
        ];
        let grad_bf16 = [
            semantic_grad_bf16,
            bf16("COLOR_GRAD_BF16", b.color_in_grad),
            bf16("FEATURE_GRAD_BF16", b.feature_in_grad),
        ];
        let feature_and_grad_bf16 = [feature_bf16, semantic_grad_bf16];
        let uniform = uniform_buffer_from(ctx, "head glue dims", &dims);
        let groups = Dispatch1d::for_device(ctx, dims.samples.into(), WORKGROUP_SIZE)?;
        let assemble = stage(
            ctx,
            "assemble",
            groups,
            &[
                ("dims", &uniform),
                ("density_out", b.density_out),
                ("feature_out", &b.feature_out.buffer),
                ("color_in", &b.color_in.buffer),
                ("semantic_in", &b.semantic_in.buffer),
                ("row_count", rows.row_count),
            ],
            &input_bf16,
        )
        .await?
        .with_indirect(rows.dispatch.clone());
        let gather_feature = stage(
            ctx,
            "gather_feature",
            groups,
            &[
                ("dims", &uniform),
                ("feature_out", &b.feature_out.buffer),
                ("semantic_in_grad", &b.semantic_in_grad.buffer),
                ("grad_heads", b.grad_heads),
                ("row_count", rows.row_count),
            ],
            &feature_and_grad_bf16,
        )
        .await?
        .with_indirect(rows.dispatch.clone());
        let gather_geometry = stage(
            ctx,
            "gather_geometry",
            groups,
            &[
                ("dims", &uniform),
                ("semantic_in_grad", &b.semantic_in_grad.buffer),
                ("grad_h0_source", b.grad_h0_source),
                ("slot", rows.slot),
                ("density_out_grad", b.density_out_grad),
                ("color_in_grad", &b.color_in_grad.buffer),
                ("feature_in_grad", &b.feature_in_grad.buffer),
            ],
            &grad_bf16,
        )
        .await?;
        Ok(HeadGluePass {
            assemble: GlueAssemble(assemble),
            gather_feature: GlueGatherFeature(gather_feature),
            gather_geometry: GlueGatherGeometry(gather_geometry),
        })
    }
}

/// Words of a colour row's g columns after its 16 SH values, stored as `format`.
fn color_geometry_words(format: RowFormat, g: u64) -> u64 {
    StepShape::words(format, 16 + g) - StepShape::words(format, 16)
}

impl Stage for GlueAssemble {
    fn name(&self) -> &'static str {
        "glue"
    }

    fn record(&self, pass: &mut wgpu::ComputePass<'_>) {
        self.0.record(pass);
    }

    /// Reads the density (K·(1 + g)) and feature (K·f, in its format) rows; writes the colour
    /// input's g and the semantic input (K·(f + sg)), each in its format.
    fn global_bytes(&self, step: &StepShape) -> u64 {
        let (g, f) = step.geometry_and_feature();
        let sg = step.cfg.semantic_geometry_dim() as u64;
        let h = step.heads;
        WORD * step.kept()
            * ((1 + g)
                + StepShape::words(h.feature, f)
                + color_geometry_words(h.color_input, g)
                + StepShape::words(h.semantic_input, f + sg))
    }
}

impl Stage for GlueGatherFeature {
    fn name(&self) -> &'static str {
        "glue backward"
    }

    fn record(&self, pass: &mut wgpu::ComputePass<'_>) {
        self.0.record(pass);
    }

    /// Reads K·f of the semantic input's gradients (in its format) and K·f feature rows; writes
    /// K·f.
    fn global_bytes(&self, step: &StepShape) -> u64 {
        let (_, f) = step.geometry_and_feature();
        let h = step.heads;
        WORD * step.kept() * (StepShape::words(h.feature, f) + f + StepShape::words(h.semantic_gradient, f))
    }
}

impl Stage for GlueGatherGeometry {
    fn name(&self) -> &'static str {
        "glue backward"
    }

    fn record(&self, pass: &mut wgpu::ComputePass<'_>) {
        self.0.record(pass);
    }

    /// Reads N slots and ∂L/∂h₀, K·g of the feature input's, K·g of the colour input's and K·sg
    /// of the semantic input's gradients (each in its format); writes N·(1 + g).
    fn global_bytes(&self, step: &StepShape) -> u64 {
        let (g, _) = step.geometry_and_feature();
        let sg = step.cfg.semantic_geometry_dim() as u64;
        let (n, k, h) = (step.samples(), step.kept(), step.heads);
        let gradients = color_geometry_words(h.color_gradient, g)
            + StepShape::words(h.feature_gradient, g)
            + StepShape::words(h.semantic_gradient, sg);
        WORD * (2 * n + k * gradients + n * (1 + g))
    }
}
