//! The whole training step on the GPU: every pass of `field::gpu`, recorded into one command
//! buffer per step with no CPU readback; losses are read back now and then, asynchronously.
//!
//! Order of one step (sample-major buffers, see the module docs of `field::gpu`):
//! ```text
//! rays → samples → encoding, SH → density MLP → keep (which samples reach the heads, packed)
//!   → feature MLP → glue (colour/semantic inputs)
//!   → colour MLP, semantic MLP → composite + losses + their backward
//!   → semantic⁻¹ → glue (df) → feature⁻¹ → colour⁻¹ → glue (dg) → density⁻¹ → hash grid⁻¹ → Adam
//! ```
//! That order is written once, as `steps::Trainer::visit_training_step`.
//! The same code runs natively and in the browser: nothing here blocks.
use crate::field::config::FieldConfig;
use crate::field::params::ParamLayout;
use crate::field::reference::LossTerms;
use crate::gpu::buffers::{
    PendingRead, read_buffer_async, read_elements_async, storage_buffer_from, storage_buffer_zeroed,
};
use crate::gpu::timing::{PassTime, PassTimer, total_by_name};
use crate::gpu::{GpuContext, GpuError};
use crate::scene::{Bounds, Pca, Scene};
use crate::spread::check::SpreadCheck;
use crate::spread::propagate::PropagationCache;

use super::adam::{AdamBuffers, AdamPass};
use super::composite::{CompositeInputs, CompositeLayout, CompositePass, LOSS_WORDS};
use super::dense::{DenseKernels, InputRows, MlpGradients, MlpPass, MlpPassDesc, RowFormat, RowView, mlp_row_format};
use super::encoding::{
    AtomicAdd, HashGridBackwardBuffers, HashGridBackwardPass, PositionEncodeBuffers, PositionEncodePass,
};
use super::head_glue::{GlueBuffers, GlueDims, GlueRows, HeadGluePass};
use super::keep::{HeadRows, KeepBuffers, KeepPass, KeepShape};
use super::rays::{FrameTilePass, RayBatchPass, SamplePointsPass, StepUniforms};
use super::rays::{NO_LABEL, RayGeometry, TARGET_FLAGS, TARGET_HEADER_WORDS, TARGET_LABEL, TARGET_PIXEL};
use super::scene_buffers::SceneBuffers;
use super::sh_encode::{DirectionLayout, ShEncodeBuffers, ShEncodePass, ShOutputLayout};
use super::view::view_rays;
pub use super::view::{DepthGuide, FrameAssembler, RenderedFrame, ViewCamera};
use crate::field::reference::mlp::{Rounding, StoredRows};
pub use steps::StageShape;

mod labels;
mod render;
mod state;
mod steps;
pub use state::TrainerState;

const SH: u32 = 16;

/// Losses of one step, as read back.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StepLosses {
    pub step: u32,
    pub terms: LossTerms,
}

/// The per-sample buffers between passes, owned here so passes can share them. From
/// `density_packed` on they hold the kept samples' packed rows (`super::keep`), sized for all.
struct SampleBuffers {
    encoding: wgpu::Buffer,
    encoding_grad: wgpu::Buffer,
    density_out: wgpu::Buffer,
    density_out_grad: wgpu::Buffer,
    density_packed: wgpu::Buffer,
}

impl SampleBuffers {
    fn new(ctx: &GpuContext, cfg: &FieldConfig) -> Result<Self, GpuError> {
        let n = cfg.batch_rays as usize * cfg.samples_per_ray();
        let (e, g) = (cfg.encoding_dim(), cfg.geometry_dim as usize);
        let make = |label: &str, width: usize| {
            ctx.ensure_storage_binding_fits(label, (n * width * 4) as u64)?;
            storage_buffer_zeroed::<f32>(ctx, label, n * width)
        };
        Ok(SampleBuffers {
            encoding: make("encoding", e)?,
            encoding_grad: make("encoding gradient", e)?,
            density_out: make("density output", 1 + g)?,
            density_out_grad: make("density output gradient", 1 + g)?,
            density_packed: make("kept density output", 1 + g)?,
        })
    }
}

/// The field's parameters and optimizer state on the GPU.
struct Optimizer {
    params: wgpu::Buffer,
    grads: wgpu::Buffer,
    first_moment: wgpu::Buffer,
    second_moment: wgpu::Buffer,
}

pub struct Trainer {
    ctx: GpuContext,
    cfg: FieldConfig,
    layout: ParamLayout,
    scene: SceneBuffers,
    step_uniforms: wgpu::Buffer,
    optimizer: Optimizer,
    /// Bound into the passes; kept here so their lifetime is plain.
    _samples: SampleBuffers,
    ray_batch: RayBatchPass,
    frame_tile: FrameTilePass,
    frame_count: u32,
    pixels_per_frame: u32,
    bounds: Bounds,
    /// The scene's PCA of its feature codes, to show rendered features in the same colours.
    display_pca: Option<Pca>,
    sample_points: SamplePointsPass,
    encode: PositionEncodePass,
    sh: ShEncodePass,
    density: MlpPass,
    feature: MlpPass,
    color: MlpPass,
    semantic: MlpPass,
    glue: HeadGluePass,
    keep: KeepPass,
    head_rows: HeadRows,
    composite: CompositePass,
    hash_backward: HashGridBackwardPass,
    adam: AdamPass,
    step: u32,
    seed: u32,
    /// Pixels training draws labels from (the strokes, spread by propagation).
    labelled_pixels: usize,
    /// Frames with at least one of those pixels.
    labelled_frames: usize,
    /// The label maps of `labelled_pixels`, by frame.
    label_maps: Vec<(u32, Vec<u16>)>,
    /// What the spread's self-check found for the current labels.
    spread_check: Option<SpreadCheck>,
    propagation: PropagationCache,
    pending_losses: Option<(u32, PendingRead<f32>)>,
    last_losses: Option<StepLosses>,
}

impl Trainer {
    /// Uploads `scene` and builds every pass for `cfg` (whose `num_classes` must cover the
    /// labels' classes). Parameters start from `ParamLayout::init(seed)`.
    pub async fn new(ctx: &GpuContext, scene: &Scene, cfg: &FieldConfig, seed: u32) -> Result<Self, GpuError> {
        let cfg = &cfg.for_scene(scene);
        cfg.validate()
            .map_err(|e| GpuError::invalid_argument("field config", e.to_string()))?;
        let layout = ParamLayout::new(cfg);
        let initial = layout.init(u64::from(seed));
        let total = initial.len();
        for what in ["parameters", "gradients", "Adam moments"] {
            ctx.ensure_storage_binding_fits(what, (total * 4) as u64)?;
        }
        let optimizer = Optimizer {
            params: storage_buffer_from(ctx, "field parameters", &initial)?,
            grads: storage_buffer_zeroed::<f32>(ctx, "field gradients", total)?,
            first_moment: storage_buffer_zeroed::<f32>(ctx, "Adam first moment", total)?,
            second_moment: storage_buffer_zeroed::<f32>(ctx, "Adam second moment", total)?,
        };
        let scene_buffers = SceneBuffers::upload(ctx, scene, cfg)?;
        let step_uniforms = crate::gpu::buffers::uniform_buffer_from(
            ctx,
            "step uniforms",
            &StepUniforms::for_step(cfg, 1, seed, cfg.adam.lr_warmup),
        );
        let samples = SampleBuffers::new(ctx, cfg)?;
        let n = cfg.batch_rays * cfg.samples_per_ray() as u32;
        let (g, d, c) = (cfg.geometry_dim, cfg.feature_dim, cfg.num_classes);
        let sg = cfg.semantic_geometry_dim() as u32;

        let ray_batch = RayBatchPass::new(ctx, cfg, &scene_buffers, &step_uniforms).await?;
        let frame_tile = FrameTilePass::new(ctx, cfg, &scene_buffers, &step_uniforms, &ray_batch).await?;
        let sample_points = SamplePointsPass::new(ctx, cfg, &scene.bounds, &step_uniforms, &ray_batch.rays).await?;
        let encode = PositionEncodePass::new(
            ctx,
            cfg,
            n as usize,
            PositionEncodeBuffers {
                positions: &sample_points.positions,
                params: &optimizer.params,
                table_offset: layout.hash_table.start,
                encoding: &samples.encoding,
            },
        )
        .await?;
        let mut pipelines = DenseKernels::with_family(ctx.profile().kernels);
        // The SH in the colour MLP's row format: it owns its input rows, and the keep pass
        // copies the SH into them.
        let sh_format = mlp_row_format(ctx, &pipelines, &layout.color, n, true, true)?;
        let sh_rows = RowView::zeroed(ctx, "view SH", sh_format, n, SH)?;
        let sh = ShEncodePass::with_directions(
            ctx,
            n as usize,
            ShOutputLayout {
                samples_per_ray: cfg.samples_per_ray(),
                row_stride: SH as usize,
                column_offset: 0,
                format: sh_format,
            },
            DirectionLayout::RAY_GEOMETRY,
            ShEncodeBuffers {
                directions: &ray_batch.rays,
                output: &sh_rows.buffer,
            },
        )
        .await?;

        // The composite's gradient rows exist only once it is built, but the MLPs' backward
        // passes read them: build the forward-facing pieces first, then the composite, then the
        // MLPs with their gradients.
        let head_rows = HeadRows::new(ctx, n)?;
        let composite_layout = CompositeLayout::new(cfg);
        let grad_stride = composite_layout.grad_stride() as u32;
        // f, in the feature MLP's row format: its last layer writes it, the composite and the
        // glue read it.
        let format = mlp_row_format(ctx, &pipelines, &layout.feature, n, true, true)?;
        let feature_out = RowView::zeroed(ctx, "feature output", format, n, d)?;
        let color_out = storage_buffer_zeroed::<f32>(ctx, "colour output", n as usize * 3)?;
        let logits = storage_buffer_zeroed::<f32>(ctx, "semantic logits", n as usize * c as usize)?;
        let composite = CompositePass::new(
            ctx,
            cfg,
            &CompositeInputs {
                step_uniforms: &step_uniforms,
                h0: RowView::new(&samples.density_out, 1 + g, 0),
                color: RowView::new(&color_out, 3, 0),
                logits: RowView::new(&logits, c, 0),
                feature: feature_out.clone(),
                intervals: &sample_points.intervals,
                targets: &ray_batch.targets,
                slot: &head_rows.slot,
            },
        )
        .await?;
        let grad_view = |offset: usize| RowView::new(&composite.head_grads, grad_stride, offset as u32);
        let grads = &optimizer.grads;
        let density = MlpPass::new(
            ctx,
            &mut pipelines,
            MlpPassDesc {
                label: "density",
                layout: &layout.density,
                rows: n,
                params: &optimizer.params,
                input: InputRows::Given(RowView::packed(&samples.encoding, cfg.encoding_dim() as u32)),
                output: Some(RowView::packed(&samples.density_out, 1 + g)),
                gradients: Some(MlpGradients {
                    grads: grads.clone(),
                    output_grad: RowView::packed(&samples.density_out_grad, 1 + g),
                    input_grad: cfg
                        .encoding
                        .uses_hash_grid()
                        .then(|| InputRows::Given(RowView::packed(&samples.encoding_grad, cfg.encoding_dim() as u32))),
                    // The hash grid's part: the frequency encoding has no parameters.
                    input_grad_columns: Some(0..cfg.hash_encoding_dim() as u32),
                }),
                kept: None,
            },
        )
        .await?;
        let feature = MlpPass::new(
            ctx,
            &mut pipelines,
            MlpPassDesc {
                label: "feature",
                layout: &layout.feature,
                rows: n,
                params: &optimizer.params,
                input: InputRows::Given(RowView::new(&samples.density_packed, 1 + g, 1)),
                output: Some(feature_out.clone()),
                gradients: Some(MlpGradients {
                    grads: grads.clone(),
                    output_grad: grad_view(composite_layout.grad_feature_offset()),
                    input_grad: Some(InputRows::Owned),
                    input_grad_columns: None,
                }),
                kept: Some(&head_rows),
            },
        )
        .await?;
        let color = MlpPass::new(
            ctx,
            &mut pipelines,
            MlpPassDesc {
                label: "colour",
                layout: &layout.color,
                rows: n,
                params: &optimizer.params,
                // Its own rows, bf16 where it stores its hidden rows so: the keep pass and the
                // glue write them.
                input: InputRows::Owned,
                output: Some(RowView::packed(&color_out, 3)),
                gradients: Some(MlpGradients {
                    grads: grads.clone(),
                    output_grad: grad_view(CompositeLayout::GRAD_COLOR),
                    input_grad: Some(InputRows::Owned),
                    // g's part: the SH are the view direction's, with no parameters.
                    input_grad_columns: Some(SH..SH + g),
                }),
                kept: Some(&head_rows),
            },
        )
        .await?;
        let semantic = MlpPass::new(
            ctx,
            &mut pipelines,
            MlpPassDesc {
                label: "semantic",
                layout: &layout.semantic,
                rows: n,
                params: &optimizer.params,
                // Its own rows, bf16 where it stores its hidden rows so: the glue writes them.
                input: InputRows::Owned,
                output: Some(RowView::packed(&logits, c)),
                gradients: Some(MlpGradients {
                    grads: grads.clone(),
                    output_grad: grad_view(composite_layout.grad_logits_offset()),
                    input_grad: Some(InputRows::Owned),
                    input_grad_columns: None,
                }),
                kept: Some(&head_rows),
            },
        )
        .await?;
        let glue = HeadGluePass::new(
            ctx,
            GlueDims {
                samples: n,
                geometry: g,
                feature: d,
                sh: SH,
                grad_stride,
                grad_h0: CompositeLayout::GRAD_H0 as u32,
                grad_feature: composite_layout.grad_feature_offset() as u32,
                semantic_trunk_scale: cfg.semantic_trunk_gradient,
                semantic_geometry: sg,
                // The row strides: from the views.
                ..bytemuck::Zeroable::zeroed()
            },
            &GlueBuffers {
                density_out: &samples.density_packed,
                feature_out: &feature_out,
                color_in: color.input(),
                semantic_in: semantic.input(),
                semantic_in_grad: semantic
                    .input_gradient()
                    .ok_or_else(|| GpuError::invalid_argument("semantic", "no input gradient"))?,
                grad_heads: &composite.head_grads,
                grad_h0_source: &composite.grad_heads,
                density_out_grad: &samples.density_out_grad,
                color_in_grad: color
                    .input_gradient()
                    .ok_or_else(|| GpuError::invalid_argument("colour", "no input gradient"))?,
                feature_in_grad: feature
                    .input_gradient()
                    .ok_or_else(|| GpuError::invalid_argument("feature", "no input gradient"))?,
            },
            &GlueRows {
                row_count: &head_rows.row_count,
                slot: &head_rows.slot,
                dispatch: Some(head_rows.dispatch(1, super::head_glue::WORKGROUP_SIZE, 1)?),
            },
        )
        .await?;
        // Last of the head passes' builders: it writes the workgroup counts all of them asked for.
        let keep = KeepPass::new(
            ctx,
            KeepShape {
                batch_rays: cfg.batch_rays,
                samples_per_ray: cfg.samples_per_ray() as u32,
                threshold: cfg.head_weight_threshold,
                density_stride: 1 + g,
                sh_width: SH,
                target_stride: TARGET_HEADER_WORDS as u32 + d,
            },
            &head_rows,
            &KeepBuffers {
                step_uniforms: &step_uniforms,
                density_out: &samples.density_out,
                intervals: &sample_points.intervals,
                targets: &ray_batch.targets,
                sh_rows: &sh_rows.buffer,
                density_packed: &samples.density_packed,
                color_packed: color.input(),
            },
        )
        .await?;
        let hash_backward = HashGridBackwardPass::new(
            ctx,
            cfg,
            n as usize,
            HashGridBackwardBuffers {
                positions: &sample_points.positions,
                encoding_grad: &samples.encoding_grad,
                gradient: grads,
                table_offset: layout.hash_table.start,
            },
        )
        .await?;
        let adam = AdamPass::new(
            ctx,
            &cfg.adam,
            total,
            AdamBuffers {
                params: &optimizer.params,
                grads,
                first_moment: &optimizer.first_moment,
                second_moment: &optimizer.second_moment,
                fixed_point_table: hash_backward.fixed_point_table(),
            },
            &step_uniforms,
        )
        .await?;

        let mut trainer = Trainer {
            ctx: ctx.clone(),
            cfg: cfg.clone(),
            layout,
            scene: scene_buffers,
            step_uniforms,
            optimizer,
            _samples: samples,
            ray_batch,
            frame_tile,
            frame_count: scene.frames.len() as u32,
            pixels_per_frame: scene.width * scene.height,
            bounds: scene.bounds,
            display_pca: scene.features.as_ref().map(|f| f.pca.clone()),
            sample_points,
            encode,
            sh,
            density,
            feature,
            color,
            semantic,
            glue,
            keep,
            head_rows,
            composite,
            hash_backward,
            adam,
            step: 0,
            seed,
            labelled_pixels: 0,
            labelled_frames: 0,
            label_maps: Vec::new(),
            spread_check: None,
            propagation: PropagationCache::default(),
            pending_losses: None,
            last_losses: None,
        };
        trainer.set_labels(scene.labels.as_ref(), scene)?;
        Ok(trainer)
    }

    pub fn config(&self) -> &FieldConfig {
        &self.cfg
    }

    pub fn layout(&self) -> &ParamLayout {
        &self.layout
    }

    pub fn steps_done(&self) -> u32 {
        self.step
    }

    pub fn has_labels(&self) -> bool {
        self.labelled_pixels > 0
    }

    /// Which MLPs store their hidden outputs as bf16, and which layers' weight gradients sum
    /// dZ stored as bf16 (those reading it through uniform windows), for the reference to round
    /// the same way.
    pub fn stored_rows(&self) -> crate::field::reference::FieldRows {
        let bf16 = |yes: bool| if yes { Rounding::Bf16 } else { Rounding::Exact };
        let rows = |mlp: &MlpPass| StoredRows {
            dz: mlp.weight_gradient_windows().into_iter().map(bf16).collect(),
            hidden: bf16(mlp.hidden_rows() == RowFormat::Bf16),
            hidden_gradients: bf16(mlp.hidden_gradient_rows() == RowFormat::Bf16),
            input: bf16(mlp.input().is_bf16()),
            input_gradient: bf16(mlp.input_gradient().is_some_and(RowView::is_bf16)),
            output: bf16(mlp.output().is_bf16()),
        };
        crate::field::reference::FieldRows {
            density: rows(&self.density),
            color: rows(&self.color),
            feature: rows(&self.feature),
            semantic: rows(&self.semantic),
        }
    }

    /// How the hash grid's backward adds into the gradient buffer on this device.
    pub fn hash_atomics(&self) -> AtomicAdd {
        self.hash_backward.atomics()
    }

    /// The learning rate of the next step: warm-up until labels exist, then the annotating one.
    pub fn learning_rate(&self) -> f32 {
        if self.has_labels() {
            self.cfg.adam.lr_annotating
        } else {
            self.cfg.adam.lr_warmup
        }
    }

    /// Records and submits `steps` training steps (one submission each, since every step
    /// rewrites the step uniforms). Returns at once; the GPU works on.
    pub fn train(&mut self, steps: u32) {
        for _ in 0..steps {
            let mut encoder = self.begin_step();
            {
                let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                    label: Some("training step"),
                    timestamp_writes: None,
                });
                self.visit_training_step(&mut |stage| stage.record(&mut pass));
            }
            self.ctx.queue.submit([encoder.finish()]);
        }
    }

    /// Trains one step with every stage in its own timed compute pass, and returns the GPU time
    /// of each stage (`None` when the adapter has no timestamp queries). For `bench`.
    pub async fn profile_step(&mut self) -> Result<Option<Vec<PassTime>>, GpuError> {
        let Some(mut timer) = PassTimer::new(&self.ctx, 32) else {
            self.train(1);
            return Ok(None);
        };
        let mut encoder = self.begin_step();
        self.visit_training_step(&mut |stage| {
            let name = stage.name();
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some(name),
                timestamp_writes: timer.timestamp_writes(name),
            });
            stage.record(&mut pass);
        });
        timer.resolve(&mut encoder);
        self.ctx.queue.submit([encoder.finish()]);
        Ok(Some(total_by_name(&timer.read(&self.ctx).times().await?)))
    }

    /// Stages in one training step (see [`Trainer::submit_stage`]).
    pub fn stage_count(&self) -> usize {
        let mut count = 0;
        self.visit_training_step(&mut |_| count += 1);
        count
    }

    /// Records stage `index` of a training step alone in its own command buffer and submits it;
    /// stage 0 starts a new step. Submitting every stage in order trains one step exactly as
    /// [`Trainer::train`] does. For wall-clock profiling where timestamp queries are missing
    /// (the caller times each submission until the GPU is done). Returns the stage's name.
    pub fn submit_stage(&mut self, index: usize) -> Option<&'static str> {
        if index >= self.stage_count() {
            return None;
        }
        let mut encoder = if index == 0 {
            self.begin_step()
        } else {
            self.ctx.device.create_command_encoder(&Default::default())
        };
        let mut name = None;
        let mut at = 0;
        self.visit_training_step(&mut |stage| {
            if at == index {
                let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                    label: Some(stage.name()),
                    timestamp_writes: None,
                });
                stage.record(&mut pass);
                name = Some(stage.name());
            }
            at += 1;
        });
        self.ctx.queue.submit([encoder.finish()]);
        name
    }

    /// Starts reading the losses of the latest step, unless a read is already under way.
    pub fn request_losses(&mut self) {
        if self.pending_losses.is_none() && self.step > 0 {
            // The losses are the first block of the ray outputs: copy that block, not the
            // rendered channels and their gradients after it.
            let words = self.composite.layout.losses(0..self.cfg.batch_rays as usize);
            let read = read_elements_async::<f32>(
                &self.ctx,
                &self.composite.ray_outputs,
                words.start as u64..words.end as u64,
            );
            self.pending_losses = Some((self.step, read));
        }
    }

    /// The most recent losses read back, polling a pending read without blocking.
    pub fn poll_losses(&mut self) -> Result<Option<StepLosses>, GpuError> {
        if let Some((step, read)) = &mut self.pending_losses
            && let Some(result) = read.try_take()
        {
            let step = *step;
            self.pending_losses = None;
            let rows = result?;
            let mut terms = LossTerms::default();
            for l in rows.chunks_exact(LOSS_WORDS) {
                terms.add(&LossTerms {
                    rgb: l[0] as f64,
                    depth: l[1] as f64,
                    semantic: l[2] as f64,
                    feature: l[3] as f64,
                });
            }
            self.last_losses = Some(StepLosses { step, terms });
        }
        Ok(self.last_losses)
    }

    /// Native convenience: waits for the GPU and returns the losses of the latest step.
    #[cfg(not(target_arch = "wasm32"))]
    pub fn losses_blocking(&mut self) -> Result<StepLosses, GpuError> {
        self.request_losses();
        loop {
            self.ctx.wait_idle()?;
            if self.pending_losses.is_none() {
                break;
            }
            self.poll_losses()?;
        }
        self.last_losses
            .ok_or_else(|| GpuError::invalid_argument("losses", "no step has been trained yet"))
    }

    /// Reads back two wrapping u32: the samples that reached the heads, summed over every
    /// batch since the trainer was made (training steps and rendered tiles), and the batches.
    /// Two reads around some steps give the mean kept samples per step (`bench`).
    pub fn kept_tally(&self) -> PendingRead<u32> {
        read_buffer_async::<u32>(&self.ctx, &self.head_rows.kept_tally)
    }
}
