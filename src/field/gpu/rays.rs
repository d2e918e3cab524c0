//! The batch's rays on the GPU: the per-step uniforms, picking B rays (`shaders/ray_batch.wgsl`)
//! and placing S samples on each (`shaders/sample_points.wgsl`), with CPU twins of every random
//! choice so tests can compare picks and jitter exactly.
//!
//! Random numbers are hashes of (seed, step, ray, stream) — PCG's output permutation used as a
//! hash, identical in WGSL and here — so a step's batch depends on nothing but the uniforms and
//! the labels, and no RNG state lives on the GPU.
//!
//! Picking: rays `[0, B − labelled_rays)` are uniform over every pixel of every frame; the last
//! `labelled_rays` draw a class uniformly among the classes with labelled pixels, then one of its
//! pixels, and carry that label (all rays are uniform while nothing is labelled). Only the
//! labelled draws carry a label, so the semantic term is the loss over labelled rays divided by
//! B, as `reference::loss` states.
//!
//! Outputs per ray: a [`RayGeometry`] (origin, unit direction, z per t, [near, far] clipped to
//! the box as `reference::sampling::clip_to_bounds`, measured depth) and a target row of
//! [`TARGET_HEADER_WORDS`] + D u32 words (colour, depth, label, flags, pixel, then the code of
//! the pixel's nearest feature cell; floats stored as bits). Per sample `n = ray·S + s`: the
//! normalized position (xyz in [0,1]³, w = t) and (δ, z-depth).
use crate::field::config::FieldConfig;
use crate::gpu::buffers::{storage_buffer_zeroed, uniform_buffer_from};
use crate::gpu::dispatch::{Dispatch, bind_named, whole};
use crate::gpu::pipeline::{Dispatch1d, KernelSpec, create_compute_pipeline};
use crate::gpu::{GpuContext, GpuError, shaders};
use crate::scene::Bounds;

use super::scene_buffers::{LabelIndex, SceneBuffers};
use super::stage::{Stage, StepShape, WORD};

/// Invocations per workgroup of the ray kernels (one invocation per ray).
pub const RAY_WORKGROUP_SIZE: u32 = 64;
/// The label word of a ray drawn without a label.
pub const NO_LABEL: u32 = u32::MAX;
/// Bits of [`RayGeometry::flags`] and of the target row's flags word.
pub const RAY_HITS_BOX: u32 = 1;
pub const RAY_HAS_CODE: u32 = 2;
/// Target row words before the D code values: r, g, b, depth (0 = none), label, flags, pixel, 0.
pub const TARGET_HEADER_WORDS: usize = 8;
pub const TARGET_RGB: usize = 0;
pub const TARGET_DEPTH: usize = 3;
pub const TARGET_LABEL: usize = 4;
pub const TARGET_FLAGS: usize = 5;
pub const TARGET_PIXEL: usize = 6;

/// Random streams of one ray (`shaders/_ray_random.wgsl`).
pub mod stream {
    pub const PIXEL: u32 = 0;
    pub const CLASS: u32 = 1;
    pub const ENTRY: u32 = 2;
    /// Jitter of sample j is stream `JITTER + j`.
    pub const JITTER: u32 = 16;
}

/// The per-step uniform block (`shaders/_step.wgsl`), written by the trainer before each submit.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct StepUniforms {
    /// Adam step t (1-based); also the RNG counter.
    pub step: u32,
    pub seed: u32,
    pub batch_rays: u32,
    pub samples_per_ray: u32,
    pub lr: f32,
    /// 1/(1 − β₁^t) and 1/(1 − β₂^t), computed in f64 and rounded (`reference::adam`).
    pub adam_c1: f32,
    pub adam_c2: f32,
    /// How many rays at the end of the batch draw from labelled pixels.
    pub labelled_rays: u32,
}

impl StepUniforms {
    /// The uniforms of Adam step `step` (≥ 1) for `cfg`, half the batch drawn from labels.
    pub fn for_step(cfg: &FieldConfig, step: u32, seed: u32, lr: f32) -> Self {
        let t = step.max(1) as i32;
        let c1 = 1.0 / (1.0 - f64::from(cfg.adam.beta1).powi(t));
        let c2 = 1.0 / (1.0 - f64::from(cfg.adam.beta2).powi(t));
        StepUniforms {
            step,
            seed,
            batch_rays: cfg.batch_rays,
            samples_per_ray: cfg.samples_per_ray() as u32,
            lr,
            adam_c1: c1 as f32,
            adam_c2: c2 as f32,
            labelled_rays: cfg.batch_rays / 2,
        }
    }
}

/// One ray of the batch (`RayGeometry` in `shaders/_ray_layout.wgsl`, 48 bytes).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct RayGeometry {
    pub origin: [f32; 3],
    pub z_per_t: f32,
    pub dir: [f32; 3],
    /// Clipped to the scene box; both 0 when the ray misses it.
    pub near: f32,
    pub far: f32,
    /// Measured z-depth in metres, 0 where there is none.
    pub depth: f32,
    /// Global pixel index `frame · width · height + y · width + x`.
    pub pixel: u32,
    pub flags: u32,
}

/// PCG-RXS-M-XS used as a 32-bit hash (the WGSL `pcg_hash`).
pub fn pcg_hash(v: u32) -> u32 {
    let state = v.wrapping_mul(747_796_405).wrapping_add(2_891_336_453);
    let word = ((state >> ((state >> 28) + 4)) ^ state).wrapping_mul(277_803_737);
    (word >> 22) ^ word
}

/// The hash all of one ray's random numbers in one step derive from.
pub fn ray_stream_base(seed: u32, step: u32, ray: u32) -> u32 {
    pcg_hash(pcg_hash(pcg_hash(seed) ^ step) ^ ray)
}

pub fn ray_random(base: u32, stream: u32) -> u32 {
    pcg_hash(base ^ stream)
}

/// Uniform in [0, n) by multiply-shift.
pub fn random_below(r: u32, n: u32) -> u32 {
    ((u64::from(r) * u64::from(n)) >> 32) as u32
}

/// Uniform in [0, 1) with 24 bits.
pub fn random_unit(r: u32) -> f32 {
    (r >> 8) as f32 * (1.0 / 16_777_216.0)
}

/// A ray's pixel and, for labelled draws, its class.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PickedPixel {
    pub pixel: u32,
    pub label: Option<u32>,
}

/// CPU twin of the picking in `ray_batch.wgsl`: the pixel ray `ray` of the step gets.
pub fn pick_pixel(step: &StepUniforms, ray: u32, total_pixels: u32, labels: &LabelIndex) -> PickedPixel {
    let base = ray_stream_base(step.seed, step.step, ray);
    let uniform = PickedPixel {
        pixel: random_below(ray_random(base, stream::PIXEL), total_pixels),
        label: None,
    };
    let present = labels.present_classes();
    let first_labelled = step.batch_rays - step.labelled_rays.min(step.batch_rays);
    if ray < first_labelled || present.is_empty() {
        return uniform;
    }
    let class = present[random_below(ray_random(base, stream::CLASS), present.len() as u32) as usize];
    let pixels = &labels.pixels_by_class[class as usize];
    let entry = random_below(ray_random(base, stream::ENTRY), pixels.len() as u32);
    PickedPixel {
        pixel: pixels[entry as usize],
        label: Some(class),
    }
}

/// CPU twin of the jitter in `sample_points.wgsl`: the `samples` values in [0,1) that
/// `reference::sampling::place_samples` takes for ray `ray` of the step.
pub fn sample_jitter(step: &StepUniforms, ray: u32, samples: usize) -> Vec<f32> {
    let base = ray_stream_base(step.seed, step.step, ray);
    (0..samples as u32)
        .map(|j| random_unit(ray_random(base, stream::JITTER + j)))
        .collect()
}

fn check_batch(cfg: &FieldConfig, what: &str) -> Result<(), GpuError> {
    cfg.validate()
        .map_err(|error| GpuError::invalid_argument(what, error.to_string()))
}

const RAY_BATCH_KERNEL: KernelSpec<'static> = KernelSpec {
    label: "ray batch",
    source: shaders::RAY_BATCH,
    entry_point: "ray_batch",
    layout: None,
    constants: &[],
};

/// Picks the batch's rays and writes their geometry and targets.
pub struct RayBatchPass {
    dispatch: Dispatch,
    step_uniforms: wgpu::Buffer,
    labels_generation: u64,
    /// `cfg.batch_rays` [`RayGeometry`] records.
    pub rays: wgpu::Buffer,
    /// `cfg.batch_rays` rows of [`RayBatchPass::target_stride`] u32 words.
    pub targets: wgpu::Buffer,
    pub target_stride: u32,
}

impl RayBatchPass {
    pub async fn new(
        ctx: &GpuContext,
        cfg: &FieldConfig,
        scene: &SceneBuffers,
        step_uniforms: &wgpu::Buffer,
    ) -> Result<Self, GpuError> {
        check_batch(cfg, "ray batch pass")?;
        let batch = cfg.batch_rays as usize;
        let target_stride = TARGET_HEADER_WORDS as u32 + cfg.feature_dim;
        let rays = storage_buffer_zeroed::<RayGeometry>(ctx, "ray geometry", batch)?;
        let targets = storage_buffer_zeroed::<u32>(ctx, "ray targets", batch * target_stride as usize)?;
        let pipeline = create_compute_pipeline(ctx, &RAY_BATCH_KERNEL).await?;
        let groups = Dispatch1d::for_device(ctx, batch as u64, RAY_WORKGROUP_SIZE)?;
        let bind_group = Self::bind(ctx, &pipeline, scene, step_uniforms, &rays, &targets)?;
        Ok(RayBatchPass {
            dispatch: Dispatch::new(pipeline, bind_group, groups),
            step_uniforms: step_uniforms.clone(),
            labels_generation: scene.labels_generation(),
            rays,
            targets,
            target_stride,
        })
    }

    fn bind(
        ctx: &GpuContext,
        pipeline: &wgpu::ComputePipeline,
        scene: &SceneBuffers,
        step_uniforms: &wgpu::Buffer,
        rays: &wgpu::Buffer,
        targets: &wgpu::Buffer,
    ) -> Result<wgpu::BindGroup, GpuError> {
        let bindings = whole(&[
            ("step_info", step_uniforms),
            ("scene", &scene.uniforms),
            ("rgb", &scene.rgb),
            ("depth", &scene.depth),
            ("poses", &scene.poses),
            ("features", &scene.features),
            ("labels", &scene.labels),
            ("rays", rays),
            ("targets", targets),
        ]);
        bind_named(ctx, &RAY_BATCH_KERNEL, &pipeline.get_bind_group_layout(0), 0, &bindings)
    }

    /// Rebinds after [`SceneBuffers::upload_labels`] replaced the labels buffer (a no-op
    /// otherwise). Call between steps, before recording.
    pub fn follow_labels(&mut self, ctx: &GpuContext, scene: &SceneBuffers) {
        if scene.labels_generation() != self.labels_generation {
            self.dispatch.bind_group = Self::bind(
                ctx,
                &self.dispatch.pipeline,
                scene,
                &self.step_uniforms,
                &self.rays,
                &self.targets,
            )
            .expect("the same bindings by the same names were accepted when the pass was made");
            self.labels_generation = scene.labels_generation();
        }
    }
}

/// Bytes of the batch's targets in `step`: R·(header + f) words.
pub(super) fn target_bytes(step: &StepShape) -> u64 {
    step.rays() * WORD * (TARGET_HEADER_WORDS as u64 + u64::from(step.cfg.feature_dim))
}

/// Bytes of one [`RayGeometry`].
pub(super) const RAY_GEOMETRY_BYTES: u64 = std::mem::size_of::<RayGeometry>() as u64;

impl Stage for RayBatchPass {
    fn name(&self) -> &'static str {
        "rays"
    }

    fn record(&self, pass: &mut wgpu::ComputePass<'_>) {
        self.dispatch.record(pass);
    }

    /// Reads the pixels' targets, R·(8 + f) words; writes R ray geometries and targets.
    fn global_bytes(&self, step: &StepShape) -> u64 {
        2 * target_bytes(step) + step.rays() * RAY_GEOMETRY_BYTES
    }
}

/// Uniform block mirrored by `TileUniforms` in `shaders/ray_batch.wgsl` (16 bytes).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct TileUniforms {
    pub first_pixel: u32,
    pub count: u32,
    pub _pad0: u32,
    pub _pad1: u32,
}

/// Rays through consecutive pixels of a frame, in pixel order (rendering): fills the same
/// `rays` and `targets` buffers as [`RayBatchPass`], so every later pass works unchanged.
/// Rays past the tile's pixel count miss the scene.
pub struct FrameTilePass {
    dispatch: Dispatch,
    tile: wgpu::Buffer,
}

impl FrameTilePass {
    pub async fn new(
        ctx: &GpuContext,
        cfg: &FieldConfig,
        scene: &SceneBuffers,
        step_uniforms: &wgpu::Buffer,
        batch: &RayBatchPass,
    ) -> Result<Self, GpuError> {
        check_batch(cfg, "frame tile pass")?;
        let tile = uniform_buffer_from(
            ctx,
            "frame tile",
            &TileUniforms {
                first_pixel: 0,
                count: 0,
                _pad0: 0,
                _pad1: 0,
            },
        );
        let spec = KernelSpec::new("frame tile", shaders::RAY_BATCH, "frame_tile");
        let groups = Dispatch1d::for_device(ctx, u64::from(cfg.batch_rays), RAY_WORKGROUP_SIZE)?;
        let bindings = whole(&[
            ("step_info", step_uniforms),
            ("scene", &scene.uniforms),
            ("rgb", &scene.rgb),
            ("depth", &scene.depth),
            ("poses", &scene.poses),
            ("features", &scene.features),
            ("rays", &batch.rays),
            ("targets", &batch.targets),
            ("tile", &tile),
        ]);
        let dispatch = Dispatch::build(ctx, &spec, &bindings, groups).await?;
        Ok(FrameTilePass { dispatch, tile })
    }

    /// Points the next recorded dispatch at pixels `first_pixel .. first_pixel + count`.
    pub fn set_tile(&self, ctx: &GpuContext, first_pixel: u32, count: u32) {
        let tile = TileUniforms {
            first_pixel,
            count,
            _pad0: 0,
            _pad1: 0,
        };
        ctx.queue.write_buffer(&self.tile, 0, bytemuck::bytes_of(&tile));
    }

    pub fn record(&self, pass: &mut wgpu::ComputePass<'_>) {
        self.dispatch.record(pass);
    }
}

/// Uniform block mirrored by `SamplePlanUniforms` in `shaders/sample_points.wgsl` (48 bytes).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct SamplePlanUniforms {
    pub bounds_min: [f32; 3],
    pub band_half_width: f32,
    pub bounds_max: [f32; 3],
    pub fine: u32,
    /// 1: the last sample's interval is `reference::render::OPAQUE_INTERVAL`
    /// (`FieldConfig::opaque_last_sample`: `LastSample::Auto` must be resolved before).
    pub opaque_last: u32,
    pub _pad: [u32; 3],
}

impl SamplePlanUniforms {
    pub fn new(cfg: &FieldConfig, bounds: &Bounds) -> Self {
        SamplePlanUniforms {
            bounds_min: bounds.min.map(|v| v as f32),
            band_half_width: crate::field::reference::sampling::surface_band_half_width(
                bounds,
                cfg.surface_band_fraction,
            ),
            bounds_max: bounds.max.map(|v| v as f32),
            fine: cfg.samples_fine,
            opaque_last: u32::from(cfg.opaque_last_sample()),
            _pad: [0; 3],
        }
    }
}

/// Places `cfg.samples_per_ray()` samples on every ray of a [`RayBatchPass`].
pub struct SamplePointsPass {
    dispatch: Dispatch,
    /// B·S `vec4<f32>`: normalized position (xyz), t (w).
    pub positions: wgpu::Buffer,
    /// B·S `vec2<f32>`: (δ, z-depth of the sample).
    pub intervals: wgpu::Buffer,
}

impl SamplePointsPass {
    /// `rays`: the [`RayBatchPass::rays`] buffer of `cfg.batch_rays` records.
    pub async fn new(
        ctx: &GpuContext,
        cfg: &FieldConfig,
        bounds: &Bounds,
        step_uniforms: &wgpu::Buffer,
        rays: &wgpu::Buffer,
    ) -> Result<Self, GpuError> {
        check_batch(cfg, "sample points pass")?;
        let samples = cfg.batch_rays as usize * cfg.samples_per_ray();
        let positions = storage_buffer_zeroed::<[f32; 4]>(ctx, "sample positions", samples)?;
        let intervals = storage_buffer_zeroed::<[f32; 2]>(ctx, "sample intervals", samples)?;
        let plan = uniform_buffer_from(ctx, "sample plan", &SamplePlanUniforms::new(cfg, bounds));
        let spec = KernelSpec::new("sample points", shaders::SAMPLE_POINTS, "sample_points");
        let groups = Dispatch1d::for_device(ctx, u64::from(cfg.batch_rays), RAY_WORKGROUP_SIZE)?;
        let bindings = whole(&[
            ("step_info", step_uniforms),
            ("plan", &plan),
            ("rays", rays),
            ("positions", &positions),
            ("intervals", &intervals),
        ]);
        let dispatch = Dispatch::build(ctx, &spec, &bindings, groups).await?;
        Ok(SamplePointsPass {
            dispatch,
            positions,
            intervals,
        })
    }
}

/// Bytes of one sample's position (vec4) and interval (vec2).
const SAMPLE_BYTES: u64 = 16 + 8;

impl Stage for SamplePointsPass {
    fn name(&self) -> &'static str {
        "samples"
    }

    fn record(&self, pass: &mut wgpu::ComputePass<'_>) {
        self.dispatch.record(pass);
    }

    /// Reads R ray geometries; writes N positions and intervals.
    fn global_bytes(&self, step: &StepShape) -> u64 {
        step.rays() * RAY_GEOMETRY_BYTES + step.samples() * SAMPLE_BYTES
    }
}
