//! Volume rendering, the four losses and the backward of both on the GPU
//! (`shaders/composite*.wgsl`), in one of two kernels ([`CompositeKernel`]) that compute the
//! same values in the same order.
//!
//! Reads per sample the density pre-activation h₀ and, at the sample's packed row
//! (`slot`, see [`super::keep`]), the raw head outputs (colour pre-sigmoid (3), semantic
//! logits (C), feature (D)) from buffers other passes own, each at `row · stride + offset`,
//! plus the sample's (δ, z-depth) and the ray's targets from [`super::rays`]. A sample the
//! keep pass dropped renders 0 for colour, logits and feature. Writes:
//! - `grad_heads`, per sample `n = ray·S + s` a row of [`CompositeLayout::grad_stride`] values
//!   whose first is ∂L/∂h₀ (σ = exp(clamp(h₀)) undone here, as `reference::activations`); the
//!   rest of the row is scratch;
//! - `head_grads`, per kept sample at its packed row, a row of the same stride
//!   `[unused, ∂L/∂colour pre-sigmoid (3), ∂L/∂logits (C), ∂L/∂feature (D)]`: what the heads'
//!   backward passes start from (the sigmoid undone here);
//! - `ray_outputs`, three blocks of B rows: the losses `[rgb, depth, semantic, feature]` per ray
//!   (the semantic word holds the opacity term too, as `reference::loss` counts it)
//!   ([`CompositeLayout::losses`]), the rendered channels (k per ray,
//!   [`CompositeLayout::rendered`]) and ∂L/∂rendered (k per ray,
//!   [`CompositeLayout::grad_rendered`]), channels in `reference::render::Channels` order
//!   (k = 4 + C + D). The loss terms are weighted and divided by the batch size B, so their sum
//!   over rays is the batch loss. Blocks rather than one row per ray, so that the trainer's loss
//!   read-back copies the losses alone and a render copies the rendered channels alone.
//!
//! [`CompositePass::record_render`] runs the forward alone (entry point `composite_render`): the
//! rendered block and nothing else, for frames that are shown and not trained on.
//!
//! A ray that misses the scene box contributes nothing (zero loss and gradients).
use crate::field::config::FieldConfig;
use crate::field::reference::Channels;
use crate::gpu::buffers::{storage_buffer_zeroed, uniform_buffer_from};
use crate::gpu::dispatch::{Dispatch, whole};
use crate::gpu::pipeline::{Dispatch1d, KernelSpec};
use crate::gpu::{GpuContext, GpuError, KernelFamily, shaders};

use super::rays::{RAY_WORKGROUP_SIZE, TARGET_HEADER_WORDS, target_bytes};
pub use super::row_view::RowView;
use super::stage::{Stage, StepShape, WORD};

/// Loss words at the start of a ray's output row: rgb, depth, semantic, feature.
pub const LOSS_WORDS: usize = 4;

/// Uniform block mirrored by `CompositeUniforms` in `shaders/_composite.wgsl` (80 bytes).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct CompositeUniforms {
    pub classes: u32,
    pub feature_dim: u32,
    pub supervise_features: u32,
    pub target_stride: u32,
    pub h0_stride: u32,
    pub h0_offset: u32,
    pub color_stride: u32,
    pub color_offset: u32,
    pub logits_stride: u32,
    pub logits_offset: u32,
    pub feature_stride: u32,
    pub feature_offset: u32,
    pub weight_rgb: f32,
    pub weight_depth: f32,
    pub weight_semantic: f32,
    pub weight_feature: f32,
    pub weight_opacity: f32,
    /// The class of what lies beyond the scene box ([`CompositePass::set_far_class`]), or
    /// [`NO_FAR_CLASS`].
    pub far_class: u32,
    pub _pad0: u32,
    pub _pad1: u32,
}

/// `CompositeUniforms::far_class` when the labels name none: no opacity term.
pub const NO_FAR_CLASS: u32 = u32::MAX;

/// Everything the pass reads. Each head's outputs are a [`RowView`]: sample n's values start at
/// `n · stride + offset`.
#[derive(Clone, Debug)]
pub struct CompositeInputs<'a> {
    pub step_uniforms: &'a wgpu::Buffer,
    /// h₀: 1 value per sample (column 0 of the density MLP's output rows).
    pub h0: RowView,
    /// Colour before the sigmoid: 3 values.
    pub color: RowView,
    /// Semantic logits: C values.
    pub logits: RowView,
    /// Feature f: D values, f32 or bf16 rows.
    pub feature: RowView,
    /// `SamplePointsPass::intervals`.
    pub intervals: &'a wgpu::Buffer,
    /// `RayBatchPass::targets`.
    pub targets: &'a wgpu::Buffer,
    /// Per sample, its packed row in the head outputs (`keep::HeadRows::slot`), or
    /// `keep::NOT_KEPT`.
    pub slot: &'a wgpu::Buffer,
}

/// Shapes of the pass's outputs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CompositeLayout {
    pub channels: Channels,
    /// Rays per batch, B.
    pub batch: usize,
}

impl CompositeLayout {
    pub fn new(cfg: &FieldConfig) -> Self {
        CompositeLayout {
            channels: Channels {
                classes: cfg.num_classes as usize,
                feature_dim: cfg.feature_dim as usize,
            },
            batch: cfg.batch_rays as usize,
        }
    }

    /// Values per sample in `grad_heads` (equal to the channel count k: h₀ takes depth's place).
    pub fn grad_stride(&self) -> usize {
        self.channels.count()
    }

    /// Values in `ray_outputs`: B·(4 + 2k).
    pub fn ray_output_words(&self) -> usize {
        self.batch * (LOSS_WORDS + 2 * self.channels.count())
    }

    /// Where the losses of rays `rays` lie in `ray_outputs`: [`LOSS_WORDS`] per ray.
    pub fn losses(&self, rays: std::ops::Range<usize>) -> std::ops::Range<usize> {
        rays.start * LOSS_WORDS..rays.end * LOSS_WORDS
    }

    /// Where the rendered channels of rays `rays` lie in `ray_outputs`: k per ray.
    pub fn rendered(&self, rays: std::ops::Range<usize>) -> std::ops::Range<usize> {
        let (base, k) = (self.batch * LOSS_WORDS, self.channels.count());
        base + rays.start * k..base + rays.end * k
    }

    /// Where ∂L/∂rendered of rays `rays` lies in `ray_outputs`: k per ray.
    pub fn grad_rendered(&self, rays: std::ops::Range<usize>) -> std::ops::Range<usize> {
        let (base, k) = (self.batch * (LOSS_WORDS + self.channels.count()), self.channels.count());
        base + rays.start * k..base + rays.end * k
    }

    /// Offsets in a `grad_heads` row.
    pub const GRAD_H0: usize = 0;
    pub const GRAD_COLOR: usize = 1;
    pub fn grad_logits_offset(&self) -> usize {
        4
    }
    pub fn grad_feature_offset(&self) -> usize {
        4 + self.channels.classes
    }
}

/// How the composite spreads a batch over invocations.
///
/// A batch has a few thousand rays: as one invocation each, too few to fill a GPU, and each ray's
/// serial loops (S samples times k channels, three times) made the composite the longest stage
/// of a step on an NVIDIA H200 (docs/results/bench.md). On a CPU device the opposite holds: its
/// SIMD lanes run neighbouring invocations, so one ray each keeps them all busy, while a
/// workgroup per ray waits at barriers with one lane walking the ray (3.6x slower on lavapipe).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CompositeKernel {
    /// `composite.wgsl`: one invocation per ray, looping over its samples and channels.
    InvocationPerRay,
    /// `composite_lanes.wgsl`: one workgroup of 64 invocations per ray, splitting its channels
    /// and samples; the two walks along the ray run on one lane over values staged in
    /// workgroup memory, so every sum adds in the same order as the other kernel's.
    WorkgroupPerRay,
}

impl CompositeKernel {
    /// The kernel that is faster on `ctx`'s kind of device.
    pub fn for_device(ctx: &GpuContext) -> CompositeKernel {
        match ctx.profile().kernels {
            KernelFamily::UniformWeights => CompositeKernel::InvocationPerRay,
            KernelFamily::Tiled => CompositeKernel::WorkgroupPerRay,
        }
    }
}

/// Compositing, losses and their backward for a batch of `cfg.batch_rays` rays.
pub struct CompositePass {
    pub kernel: CompositeKernel,
    dispatch: Dispatch,
    /// The forward alone (`composite_render`).
    render: Dispatch,
    pub layout: CompositeLayout,
    /// B·S rows of [`CompositeLayout::grad_stride`] f32: ∂L/∂h₀ first.
    pub grad_heads: wgpu::Buffer,
    /// B·S rows of [`CompositeLayout::grad_stride`] f32, the heads' gradients at packed rows.
    pub head_grads: wgpu::Buffer,
    /// [`CompositeLayout::ray_output_words`] f32 in three blocks (see the module docs).
    pub ray_outputs: wgpu::Buffer,
    uniforms: CompositeUniforms,
    uniform: wgpu::Buffer,
}

impl CompositePass {
    pub async fn new(ctx: &GpuContext, cfg: &FieldConfig, inputs: &CompositeInputs<'_>) -> Result<Self, GpuError> {
        cfg.validate()
            .map_err(|error| GpuError::invalid_argument("composite pass", error.to_string()))?;
        let layout = CompositeLayout::new(cfg);
        let batch = cfg.batch_rays as usize;
        let samples = batch * cfg.samples_per_ray();
        let heads = [
            ("h0", &inputs.h0, 1),
            ("colour", &inputs.color, 3),
            ("logits", &inputs.logits, cfg.num_classes),
            ("feature", &inputs.feature, cfg.feature_dim),
        ];
        for (name, source, width) in heads {
            // Only the feature head's rows may be bf16.
            if source.is_bf16() && name != "feature" {
                return Err(GpuError::invalid_argument(
                    "composite pass",
                    format!("the {name} head's rows must be f32"),
                ));
            }
            source.check(&format!("composite pass: {name} head source"), samples as u32, width)?;
        }
        let uniforms = CompositeUniforms {
            classes: cfg.num_classes,
            feature_dim: cfg.feature_dim,
            supervise_features: u32::from(cfg.feature_supervision),
            target_stride: TARGET_HEADER_WORDS as u32 + cfg.feature_dim,
            h0_stride: inputs.h0.stride,
            h0_offset: inputs.h0.offset,
            color_stride: inputs.color.stride,
            color_offset: inputs.color.offset,
            logits_stride: inputs.logits.stride,
            logits_offset: inputs.logits.offset,
            feature_stride: inputs.feature.stride,
            feature_offset: inputs.feature.offset,
            weight_rgb: cfg.loss.rgb,
            weight_depth: cfg.loss.depth,
            weight_semantic: cfg.loss.semantic,
            weight_feature: cfg.loss.feature,
            weight_opacity: cfg.loss.opacity,
            far_class: NO_FAR_CLASS,
            _pad0: 0,
            _pad1: 0,
        };
        let grad_heads = storage_buffer_zeroed::<f32>(ctx, "density gradients", samples * layout.grad_stride())?;
        let head_grads = storage_buffer_zeroed::<f32>(ctx, "head gradients", samples * layout.grad_stride())?;
        let ray_outputs = storage_buffer_zeroed::<f32>(ctx, "ray losses and renders", layout.ray_output_words())?;
        let uniform = uniform_buffer_from(ctx, "composite uniforms", &uniforms);
        let kernel = CompositeKernel::for_device(ctx);
        let (source, groups) = match kernel {
            CompositeKernel::InvocationPerRay => (
                shaders::COMPOSITE,
                Dispatch1d::for_device(ctx, batch as u64, RAY_WORKGROUP_SIZE)?,
            ),
            CompositeKernel::WorkgroupPerRay => {
                (shaders::COMPOSITE_LANES, Dispatch1d::for_device(ctx, batch as u64, 1)?)
            }
        };
        let constants = [("FEATURE_BF16", f64::from(u8::from(inputs.feature.is_bf16())))];
        let spec = KernelSpec {
            constants: &constants,
            ..KernelSpec::new("composite", source, "composite")
        };
        let bindings = whole(&[
            ("step_info", inputs.step_uniforms),
            ("params", &uniform),
            ("h0_source", &inputs.h0.buffer),
            ("color_source", &inputs.color.buffer),
            ("logits_source", &inputs.logits.buffer),
            ("feature_source", &inputs.feature.buffer),
            ("intervals", inputs.intervals),
            ("targets", inputs.targets),
            ("grad_heads", &grad_heads),
            ("ray_outputs", &ray_outputs),
            ("slot", inputs.slot),
            ("head_grads", &head_grads),
        ]);
        let dispatch = Dispatch::build(ctx, &spec, &bindings, groups).await?;
        let render_spec = KernelSpec {
            constants: &constants,
            ..KernelSpec::new("composite (render)", source, "composite_render")
        };
        let render_bindings: Vec<_> = bindings
            .iter()
            .filter(|(name, _)| *name != "head_grads")
            .cloned()
            .collect();
        let render = Dispatch::build(ctx, &render_spec, &render_bindings, groups).await?;
        Ok(CompositePass {
            kernel,
            dispatch,
            render,
            layout,
            grad_heads,
            head_grads,
            ray_outputs,
            uniforms,
            uniform,
        })
    }

    /// The class [`CompositePass::set_far_class`] gave last.
    pub fn far_class(&self) -> Option<u32> {
        (self.uniforms.far_class != NO_FAR_CLASS).then_some(self.uniforms.far_class)
    }

    /// The class of what lies beyond the scene box, for the opacity term
    /// (`reference::loss::opacity_loss`; `None`: no term). It applies only to rays that end in
    /// an opaque sample. Takes effect with the next recorded pass.
    pub fn set_far_class(&mut self, ctx: &GpuContext, class: Option<u32>) {
        let far_class = class.unwrap_or(NO_FAR_CLASS);
        if far_class != self.uniforms.far_class {
            self.uniforms.far_class = far_class;
            ctx.queue
                .write_buffer(&self.uniform, 0, bytemuck::bytes_of(&self.uniforms));
        }
    }

    /// Records the forward alone: the rendered block of `ray_outputs` (the same values
    /// the whole pass writes there) and, as scratch, the first two words of each
    /// sample's `grad_heads` row. No loss, no gradient: for frames shown, not trained on.
    pub fn record_render(&self, pass: &mut wgpu::ComputePass<'_>) {
        self.render.record(pass);
    }
}

impl Stage for CompositePass {
    fn name(&self) -> &'static str {
        "composite"
    }

    /// Records the whole pass: rendering, losses and their backward.
    fn record(&self, pass: &mut wgpu::ComputePass<'_>) {
        self.dispatch.record(pass);
    }

    /// Reads N h₀, intervals and slots, K head values (f in its format) and R targets; writes
    /// N·3 (∂L/∂h₀ and scratch), K head gradients and R ray outputs.
    fn global_bytes(&self, step: &StepShape) -> u64 {
        let (n, k) = (step.samples(), step.kept());
        let (_, f) = step.geometry_and_feature();
        let heads_row = self.layout.grad_stride() as u64;
        let feature = StepShape::words(step.heads.feature, f);
        n * (2 * WORD + 8)
            + k * (heads_row - 1 - f + feature) * WORD
            + target_bytes(step)
            + n * 3 * WORD
            + k * heads_row * WORD
            + self.layout.ray_output_words() as u64 * WORD
    }
}
