//! The training step as one list of stages, read by [`Trainer::train`] (all in one compute
//! pass), [`Trainer::profile_step`] (a timed pass each) and [`Trainer::submit_stage`] (a
//! submission each), so the three cannot disagree on the order.
use super::Trainer;

/// One stage of a training step: a group of passes recorded together.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum StepStage {
    Rays,
    Samples,
    Encoding,
    Sh,
    DensityForward,
    FeatureForward,
    GlueAssemble,
    ColorForward,
    SemanticForward,
    Composite,
    SemanticBackward,
    GlueGatherFeature,
    FeatureBackward,
    ColorBackward,
    GlueGatherGeometry,
    DensityBackward,
    EncodingBackward,
    Adam,
}

/// A training step, in order.
pub(super) const TRAINING_STEP: [StepStage; 18] = [
    StepStage::Rays,
    StepStage::Samples,
    StepStage::Encoding,
    StepStage::Sh,
    StepStage::DensityForward,
    StepStage::FeatureForward,
    StepStage::GlueAssemble,
    StepStage::ColorForward,
    StepStage::SemanticForward,
    StepStage::Composite,
    StepStage::SemanticBackward,
    StepStage::GlueGatherFeature,
    StepStage::FeatureBackward,
    StepStage::ColorBackward,
    StepStage::GlueGatherGeometry,
    StepStage::DensityBackward,
    StepStage::EncodingBackward,
    StepStage::Adam,
];

/// The stages from the sampled rays to the heads' outputs: what rendering a tile of rays runs
/// (after its own ray pass).
pub(super) const FIELD_STAGES: &[StepStage] = {
    let (_, after_rays) = TRAINING_STEP.split_at(1);
    after_rays.split_at(8).0
};

impl StepStage {
    /// The stage's name in profiles (both glue gathers are "glue backward").
    pub(super) fn name(self) -> &'static str {
        match self {
            StepStage::Rays => "rays",
            StepStage::Samples => "samples",
            StepStage::Encoding => "encoding",
            StepStage::Sh => "sh",
            StepStage::DensityForward => "density mlp",
            StepStage::FeatureForward => "feature mlp",
            StepStage::GlueAssemble => "glue",
            StepStage::ColorForward => "colour mlp",
            StepStage::SemanticForward => "semantic mlp",
            StepStage::Composite => "composite",
            StepStage::SemanticBackward => "semantic mlp backward",
            StepStage::GlueGatherFeature | StepStage::GlueGatherGeometry => "glue backward",
            StepStage::FeatureBackward => "feature mlp backward",
            StepStage::ColorBackward => "colour mlp backward",
            StepStage::DensityBackward => "density mlp backward",
            StepStage::EncodingBackward => "encoding backward",
            StepStage::Adam => "adam",
        }
    }
}

impl Trainer {
    /// Records one stage's passes.
    pub(super) fn record_stage(&self, stage: StepStage, pass: &mut wgpu::ComputePass<'_>) {
        // Every MLP here was built with gradients, so recording a backward cannot fail.
        let built = "training MLPs are built with gradients";
        match stage {
            StepStage::Rays => self.ray_batch.record(pass),
            StepStage::Samples => self.sample_points.record(pass),
            StepStage::Encoding => self.encode.record(pass),
            StepStage::Sh => self.sh.record(pass),
            StepStage::DensityForward => self.density.record_forward(pass),
            StepStage::FeatureForward => self.feature.record_forward(pass),
            StepStage::GlueAssemble => self.glue.record_assemble(pass),
            StepStage::ColorForward => self.color.record_forward(pass),
            StepStage::SemanticForward => self.semantic.record_forward(pass),
            StepStage::Composite => self.composite.record(pass),
            StepStage::SemanticBackward => self.semantic.record_backward(pass).expect(built),
            StepStage::GlueGatherFeature => self.glue.record_gather_feature(pass),
            StepStage::FeatureBackward => self.feature.record_backward(pass).expect(built),
            StepStage::ColorBackward => self.color.record_backward(pass).expect(built),
            StepStage::GlueGatherGeometry => self.glue.record_gather_geometry(pass),
            StepStage::DensityBackward => self.density.record_backward(pass).expect(built),
            StepStage::EncodingBackward => self.hash_backward.record(pass),
            StepStage::Adam => self.adam.record(pass),
        }
    }

    /// Starts a training step: the next step's uniforms, and an encoder that first zeroes the
    /// gradient buffer (every backward pass adds to it).
    pub(super) fn begin_step(&mut self) -> wgpu::CommandEncoder {
        self.step += 1;
        let uniforms = super::StepUniforms::for_step(&self.cfg, self.step, self.seed, self.learning_rate());
        self.ctx
            .queue
            .write_buffer(&self.step_uniforms, 0, bytemuck::bytes_of(&uniforms));
        let mut encoder = self.ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("training step"),
        });
        encoder.clear_buffer(&self.optimizer.grads, 0, None);
        encoder
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_field_stages_run_from_samples_to_the_semantic_head() {
        assert_eq!(FIELD_STAGES.first(), Some(&StepStage::Samples));
        assert_eq!(FIELD_STAGES.last(), Some(&StepStage::SemanticForward));
        assert_eq!(FIELD_STAGES.len(), 8);
    }
}
