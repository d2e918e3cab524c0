//! The training step as one list of stages ([`Trainer::visit_training_step`]), read by
//! [`Trainer::train`] (all in one compute pass), [`Trainer::profile_step`] (a timed pass each),
//! [`Trainer::submit_stage`] (a submission each) and [`Trainer::step_shape`] (dispatches and
//! bytes), so they cannot disagree on the order. Each stage is a pass that implements
//! [`Stage`] in its own file; adding one is a line here.
use super::Trainer;
use crate::field::gpu::dense::{MlpPass, RowFormat};
use crate::field::gpu::stage::{HeadRowFormats, Stage, StepShape};

/// Every MLP here was built with gradients, so its backward stage exists.
const BUILT: &str = "training MLPs are built with gradients";

/// One stage of a training step as `bench` reports it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct StageShape {
    /// The stage's name in profiles (`PassTime::name`).
    pub name: &'static str,
    /// Dispatches it records.
    pub dispatches: u64,
    /// Its global-memory traffic ([`Stage::global_bytes`]).
    pub bytes: u64,
}

impl Trainer {
    /// The stages from the sampled rays to the heads' outputs, in order: what rendering a tile
    /// of rays runs after its own ray pass. The heads see the kept samples alone here too.
    pub(super) fn visit_field_stages(&self, visit: &mut dyn FnMut(&dyn Stage)) {
        visit(&self.sample_points);
        visit(&self.encode);
        visit(&self.sh);
        visit(&self.density.forward_stage("density mlp"));
        visit(&self.keep);
        visit(&self.feature.forward_stage("feature mlp"));
        visit(&self.glue.assemble);
        visit(&self.color.forward_stage("colour mlp"));
        visit(&self.semantic.forward_stage("semantic mlp"));
    }

    /// A training step up to, not including, its parameter update, in order.
    pub(super) fn visit_step_before_update(&self, visit: &mut dyn FnMut(&dyn Stage)) {
        visit(&self.ray_batch);
        self.visit_field_stages(visit);
        visit(&self.composite);
        visit(&self.semantic.backward_stage("semantic mlp backward").expect(BUILT));
        visit(&self.glue.gather_feature);
        visit(&self.feature.backward_stage("feature mlp backward").expect(BUILT));
        visit(&self.color.backward_stage("colour mlp backward").expect(BUILT));
        visit(&self.glue.gather_geometry);
        visit(&self.density.backward_stage("density mlp backward").expect(BUILT));
        visit(&self.hash_backward);
    }

    /// A whole training step, in order. Adam zeroes the gradient it consumed, so there is no
    /// separate clear of the gradient buffer before a step.
    pub(super) fn visit_training_step(&self, visit: &mut dyn FnMut(&dyn Stage)) {
        self.visit_step_before_update(visit);
        visit(&self.adam);
    }

    /// Every stage of a training step in order, with its dispatches (counted by recording a step
    /// into a command buffer that is never submitted: nothing runs, the step count stays) and
    /// its global-memory traffic when `samples_to_heads` samples reach the heads (the batch's
    /// samples at most; `bench` passes the mean it measured). The head kernels' dispatches
    /// are indirect: they count as one each whatever they launch.
    pub fn step_shape(&self, samples_to_heads: u64) -> Vec<StageShape> {
        use crate::gpu::pipeline::dispatches_recorded;
        let mut encoder = self.ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("counting a step's dispatches (never submitted)"),
        });
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor::default());
        let step = StepShape::new(&self.cfg, samples_to_heads, self.head_row_formats());
        let mut shapes = Vec::new();
        self.visit_training_step(&mut |stage| {
            let before = dispatches_recorded();
            stage.record(&mut pass);
            shapes.push(StageShape {
                name: stage.name(),
                dispatches: dispatches_recorded() - before,
                bytes: stage.global_bytes(&step),
            });
        });
        shapes
    }

    fn head_row_formats(&self) -> HeadRowFormats {
        let gradient = |mlp: &MlpPass| mlp.input_gradient().map_or(RowFormat::F32, |view| view.format);
        HeadRowFormats {
            feature: self.feature.output().format,
            color_input: self.color.input().format,
            color_gradient: gradient(&self.color),
            feature_gradient: gradient(&self.feature),
            semantic_input: self.semantic.input().format,
            semantic_gradient: gradient(&self.semantic),
        }
    }

    /// Starts a training step: the next step's uniforms and an encoder. The gradient buffer
    /// the backward passes add to is already zero: it starts zeroed and the previous step's
    /// Adam zeroed what it consumed.
    pub(super) fn begin_step(&mut self) -> wgpu::CommandEncoder {
        self.step += 1;
        let uniforms = super::StepUniforms::for_step(&self.cfg, self.step, self.seed, self.learning_rate());
        self.ctx
            .queue
            .write_buffer(&self.step_uniforms, 0, bytemuck::bytes_of(&uniforms));
        self.ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("training step"),
        })
    }
}
