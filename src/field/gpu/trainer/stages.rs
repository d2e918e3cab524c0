//! The training step as one list of stages, read by [`Trainer::train`] (all in one compute
//! pass), [`Trainer::profile_step`] (a timed pass each) and [`Trainer::submit_stage`] (a
//! submission each), so the three cannot disagree on the order.
use super::Trainer;
use crate::field::config::FieldConfig;
use crate::field::gpu::composite::CompositeLayout;
use crate::field::gpu::dense::{MlpPass, RowFormat, RowView};
use crate::field::gpu::encoding::AtomicAdd;
use crate::field::gpu::rays::TARGET_HEADER_WORDS;
use crate::field::params::ParamLayout;

/// One stage of a training step: a group of passes recorded together.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum StepStage {
    Rays,
    Samples,
    Encoding,
    Sh,
    DensityForward,
    Keep,
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
pub(super) const TRAINING_STEP: [StepStage; 19] = [
    StepStage::Rays,
    StepStage::Samples,
    StepStage::Encoding,
    StepStage::Sh,
    StepStage::DensityForward,
    StepStage::Keep,
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
/// (after its own ray pass). The heads see the kept samples alone here too.
pub(super) const FIELD_STAGES: &[StepStage] = {
    let (_, after_rays) = TRAINING_STEP.split_at(1);
    after_rays.split_at(9).0
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
            StepStage::Keep => "keep",
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

/// Bytes per `f32`/`u32` element.
const WORD: u64 = 4;

/// How the rows between the heads are stored (f32 or bf16), for the traffic of the keep pass,
/// the composite and the glue: f as the feature MLP writes it, the colour and semantic MLPs'
/// own input rows and their gradients (`dense::MlpPass::input`).
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct HeadRowFormats {
    pub feature: RowFormat,
    pub color_input: RowFormat,
    pub color_gradient: RowFormat,
    pub feature_gradient: RowFormat,
    pub semantic_input: RowFormat,
    pub semantic_gradient: RowFormat,
}

/// Bytes of one `RayGeometry` (origin, z per t, direction, near, far, depth, pixel, flags).
const RAY_GEOMETRY_BYTES: u64 = 48;
/// Bytes of one sample's position (vec4) and interval (vec2).
const SAMPLE_BYTES: u64 = 16 + 8;

impl StepStage {
    /// Bytes the stage moves through global memory in one step, estimated from the kernels'
    /// shapes: every element a dispatch reads or writes counted once (caches, workgroup
    /// memory and re-reads of a tile by several workgroups ignored, so it is a lower bound of
    /// what a kernel without reuse moves). With R rays of S samples (N = R·S) of which K reach
    /// the heads (`kept`, at most N: what the keep stage kept, e.g. measured by `bench`),
    /// encoding width E, geometry g, feature f, classes C, heads' row h = 4 + C + f and P
    /// parameters:
    ///
    /// | stage | reads | writes |
    /// |---|---|---|
    /// | rays | the pixel's targets, R·(8 + f) words | R ray geometries (48 B) and targets |
    /// | samples | R ray geometries | N positions and intervals (24 B) |
    /// | encoding | N positions, 8 corners × levels × features of the hash table per sample | N·E |
    /// | sh | R ray geometries | N·16 (in the colour input's format) |
    /// | density mlp, the heads' MLPs (N rows, K rows) | see `DenseForward::global_bytes` | |
    /// | keep | N h₀ and intervals twice, R flags and counts, K·(1 + g + 16) gathered | R counts, N slots, K rows, K·(1 + g + 16) (the SH in the colour input's format) |
    /// | glue | density (K·(1+g)) and feature (K·f, in its format) rows | colour input's g, semantic input (K·(f + sg)), each in its format |
    /// | composite | N h₀, intervals and slots, K head values (f in its format), R targets | N·3 (∂L/∂h₀ and scratch), K head gradients, R ray outputs |
    /// | an MLP backward (K rows for the heads, N for density) | see `DenseBackward::global_bytes` | |
    /// | glue backward (feature) | K·f semantic-input (in its format) and K·f feature-loss gradients | K·f |
    /// | glue backward (geometry) | N slots and ∂L/∂h₀, K·g of the feature input's, K·g of the colour input's and K·sg of the semantic input's gradients (each in its format) | N·(1 + g) |
    /// | encoding backward | N hash-grid gradients and positions (fixed point: the gradients twice; one invocation per level: the positions once per level; `Trainer::stage_bytes`) | an atomic add (read and write) per corner, level and feature (fixed point: and an exponent per level) |
    /// | adam | parameters, gradients, both moments: 4·P | parameters, gradients (zeroed), both moments: 4·P |
    ///
    /// The MLPs' stages are `None`: their passes know which kernels they record, and count
    /// them (`Trainer::stage_bytes`). Adam zeroes the gradient it consumed, so there is no
    /// separate clear of the gradient buffer before a step.
    pub(super) fn global_bytes(self, cfg: &FieldConfig, kept: u64, heads: HeadRowFormats) -> Option<u64> {
        let layout = ParamLayout::new(cfg);
        let r = u64::from(cfg.batch_rays);
        let n = r * cfg.samples_per_ray() as u64;
        let k = kept.min(n);
        let (g, f) = (u64::from(cfg.geometry_dim), u64::from(cfg.feature_dim));
        let sg = cfg.semantic_geometry_dim() as u64;
        let targets = r * WORD * (TARGET_HEADER_WORDS as u64 + f);
        let hash = cfg.encoding.uses_hash_grid();
        let corners = if hash {
            8 * u64::from(cfg.hash_levels) * u64::from(cfg.hash_features_per_level)
        } else {
            0
        };
        // Words of `width` semantic-input (gradient) values stored as `format`.
        let words = |format, width: u64| RowView::words(format, 1, width as u32);
        let composite = CompositeLayout::new(cfg);
        let heads_row = composite.grad_stride() as u64;
        let bytes = match self {
            StepStage::Rays => 2 * targets + r * RAY_GEOMETRY_BYTES,
            StepStage::Samples => r * RAY_GEOMETRY_BYTES + n * SAMPLE_BYTES,
            StepStage::Encoding => n * 16 + n * corners * WORD + n * cfg.encoding_dim() as u64 * WORD,
            StepStage::Sh => r * RAY_GEOMETRY_BYTES + n * words(heads.color_input, 16) * WORD,
            StepStage::Keep => {
                WORD * (2 * 3 * n + 3 * r + n + k + 2 * k * (1 + g) + 2 * k * words(heads.color_input, 16))
            }
            StepStage::GlueAssemble => {
                let color_g = words(heads.color_input, 16 + g) - words(heads.color_input, 16);
                WORD * k * ((1 + g) + words(heads.feature, f) + color_g + words(heads.semantic_input, f + sg))
            }
            StepStage::Composite => {
                n * (2 * WORD + 8)
                    + k * (heads_row - 1 - f + words(heads.feature, f)) * WORD
                    + targets
                    + n * 3 * WORD
                    + k * heads_row * WORD
                    + composite.ray_output_words() as u64 * WORD
            }
            StepStage::GlueGatherFeature => {
                WORD * k * (words(heads.feature, f) + f + words(heads.semantic_gradient, f))
            }
            StepStage::GlueGatherGeometry => {
                let color_g = words(heads.color_gradient, 16 + g) - words(heads.color_gradient, 16);
                let feature_g = words(heads.feature_gradient, g);
                WORD * (2 * n + k * (color_g + feature_g + words(heads.semantic_gradient, sg)) + n * (1 + g))
            }
            StepStage::EncodingBackward if hash => {
                n * 16 + n * cfg.hash_encoding_dim() as u64 * WORD + 2 * n * corners * WORD
            }
            StepStage::EncodingBackward => 0,
            StepStage::Adam => 8 * layout.total as u64 * WORD,
            StepStage::DensityForward
            | StepStage::FeatureForward
            | StepStage::ColorForward
            | StepStage::SemanticForward
            | StepStage::SemanticBackward
            | StepStage::FeatureBackward
            | StepStage::ColorBackward
            | StepStage::DensityBackward => return None,
        };
        Some(bytes)
    }
}

/// One stage of a training step as `bench` reports it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct StageShape {
    /// The stage's name in profiles (`PassTime::name`).
    pub name: &'static str,
    /// Dispatches it records.
    pub dispatches: u64,
    /// Its global-memory traffic (the estimate of `StepStage::global_bytes`).
    pub bytes: u64,
}

impl Trainer {
    /// Every stage of a training step in order, with its dispatches (counted by recording a step
    /// into a command buffer that is never submitted: nothing runs, the step count stays) and
    /// its global-memory traffic when `samples_to_heads` samples reach the heads (the batch's
    /// samples at most; `bench` passes the mean it measured). The head kernels' dispatches
    /// are indirect: they count as one each whatever they launch.
    pub fn step_shape(&self, samples_to_heads: u64) -> Vec<StageShape> {
        use crate::gpu::dispatch::dispatches_recorded;
        let mut encoder = self.ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("counting a step's dispatches (never submitted)"),
        });
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor::default());
        TRAINING_STEP
            .iter()
            .map(|&stage| {
                let before = dispatches_recorded();
                self.record_stage(stage, &mut pass);
                StageShape {
                    name: stage.name(),
                    dispatches: dispatches_recorded() - before,
                    bytes: self.stage_bytes(stage, samples_to_heads),
                }
            })
            .collect()
    }

    /// Bytes `stage` moves through global memory in one step when `samples_to_heads` samples
    /// reach the heads ([`StepStage::global_bytes`]; the MLPs' passes count their own).
    fn stage_bytes(&self, stage: StepStage, samples_to_heads: u64) -> u64 {
        let n = u64::from(self.cfg.batch_rays) * self.cfg.samples_per_ray() as u64;
        let k = samples_to_heads.min(n);
        match stage {
            StepStage::DensityForward => self.density.forward_bytes(n),
            StepStage::FeatureForward => self.feature.forward_bytes(k),
            StepStage::ColorForward => self.color.forward_bytes(k),
            StepStage::SemanticForward => self.semantic.forward_bytes(k),
            StepStage::SemanticBackward => self.semantic.backward_bytes(k),
            StepStage::FeatureBackward => self.feature.backward_bytes(k),
            StepStage::ColorBackward => self.color.backward_bytes(k),
            StepStage::DensityBackward => self.density.backward_bytes(n),
            StepStage::EncodingBackward => {
                let adds = stage
                    .global_bytes(&self.cfg, samples_to_heads, self.head_row_formats())
                    .unwrap_or(0);
                // Fixed point first bounds each level's sums: one more read of the hash
                // columns of every gradient row, one exponent written per level.
                let scale = match self.hash_backward.fixed_point_table() {
                    Some(_) => n * self.cfg.hash_encoding_dim() as u64 * WORD + u64::from(self.cfg.hash_levels) * WORD,
                    None => 0,
                };
                // One invocation per level reads every position once per level.
                let positions_again = match self.hash_backward.atomics() {
                    AtomicAdd::PerLevel => n * 16 * u64::from(self.cfg.hash_levels.saturating_sub(1)),
                    _ => 0,
                };
                adds + scale + positions_again
            }
            _ => stage
                .global_bytes(&self.cfg, samples_to_heads, self.head_row_formats())
                .unwrap_or(0),
        }
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
            StepStage::Keep => self.keep.record(pass),
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_field_stages_run_from_samples_to_the_semantic_head() {
        assert_eq!(FIELD_STAGES.first(), Some(&StepStage::Samples));
        assert_eq!(FIELD_STAGES.last(), Some(&StepStage::SemanticForward));
        assert_eq!(FIELD_STAGES.len(), 9);
    }

    #[test]
    fn every_stage_but_the_mlps_has_a_traffic_model_and_a_smaller_batch_moves_less() {
        // The MLPs' passes count their own traffic (tests/gpu_trainer.rs checks the whole step).
        let cfg = FieldConfig::default();
        let all = u64::from(cfg.batch_rays) * cfg.samples_per_ray() as u64;
        let f32_rows = HeadRowFormats::default();
        for stage in TRAINING_STEP {
            let is_mlp = stage.name().contains("mlp");
            match stage.global_bytes(&cfg, all, f32_rows) {
                Some(bytes) => assert!(!is_mlp && bytes > 0, "{}: {bytes}", stage.name()),
                None => assert!(is_mlp, "{} has no model", stage.name()),
            }
        }
        let half = FieldConfig {
            batch_rays: 2048,
            ..cfg.clone()
        };
        assert!(
            StepStage::Encoding.global_bytes(&half, all, f32_rows)
                < StepStage::Encoding.global_bytes(&cfg, all, f32_rows)
        );
        // Fewer samples at the heads: the glue moves less, the encoding the same.
        assert!(
            StepStage::GlueAssemble.global_bytes(&cfg, all / 10, f32_rows)
                < StepStage::GlueAssemble.global_bytes(&cfg, all, f32_rows)
        );
        assert_eq!(
            StepStage::Encoding.global_bytes(&cfg, all / 10, f32_rows),
            StepStage::Encoding.global_bytes(&cfg, all, f32_rows)
        );
    }
}
