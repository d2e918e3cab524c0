//! A stage of the training step: what the trainer records, names in profiles and counts in
//! `bench`. Each pass implements [`Stage`] in its own file, beside its kernel's bindings, so a
//! new stage touches its own files and the one line of the step that lists it
//! (`trainer::steps`). An MLP is two stages (its forward and its backward) and the head glue
//! three (assembling the heads' inputs, gathering each gradient back).
use crate::field::config::FieldConfig;
use crate::field::gpu::dense::RowFormat;
use crate::field::gpu::row_view::RowView;

/// Bytes per `f32`/`u32` element.
pub const WORD: u64 = 4;

/// One stage of a training step.
pub trait Stage {
    /// The stage's name in profiles and `bench` (both glue gathers are "glue backward").
    fn name(&self) -> &'static str;
    /// Records the stage's dispatches into `pass`.
    fn record(&self, pass: &mut wgpu::ComputePass<'_>);
    /// Bytes the stage moves through global memory in one step of `step`, estimated from the
    /// kernels' shapes: every element a dispatch reads or writes counted once (caches,
    /// workgroup memory and re-reads of a tile by several workgroups ignored, so it is a lower
    /// bound of what a kernel without reuse moves).
    fn global_bytes(&self, step: &StepShape) -> u64;
}

/// How the rows between the heads are stored (f32 or bf16), for the traffic of the keep pass,
/// the composite and the glue: f as the feature MLP writes it, the colour and semantic MLPs'
/// own input rows and their gradients (`dense::MlpPass::input`).
#[derive(Clone, Copy, Debug, Default)]
pub struct HeadRowFormats {
    pub feature: RowFormat,
    pub color_input: RowFormat,
    pub color_gradient: RowFormat,
    pub feature_gradient: RowFormat,
    pub semantic_input: RowFormat,
    pub semantic_gradient: RowFormat,
}

/// What the stages' traffic models read of a step: the config (R rays of S samples, N = R·S,
/// encoding width E, geometry g, feature f, classes C, P parameters), the samples that reach
/// the heads (K, at most N: what the keep stage kept, e.g. measured by `bench`) and how the
/// heads' rows are stored.
#[derive(Clone, Copy, Debug)]
pub struct StepShape<'a> {
    pub cfg: &'a FieldConfig,
    kept: u64,
    pub heads: HeadRowFormats,
}

impl<'a> StepShape<'a> {
    /// A step of `cfg` in which `kept` samples reach the heads (clamped to the batch's).
    pub fn new(cfg: &'a FieldConfig, kept: u64, heads: HeadRowFormats) -> Self {
        let mut shape = StepShape { cfg, kept: 0, heads };
        shape.kept = kept.min(shape.samples());
        shape
    }

    /// R: the batch's rays.
    pub fn rays(&self) -> u64 {
        u64::from(self.cfg.batch_rays)
    }

    /// N: the batch's samples.
    pub fn samples(&self) -> u64 {
        self.rays() * self.cfg.samples_per_ray() as u64
    }

    /// K: the samples that reach the heads.
    pub fn kept(&self) -> u64 {
        self.kept
    }

    /// g and f.
    pub fn geometry_and_feature(&self) -> (u64, u64) {
        (u64::from(self.cfg.geometry_dim), u64::from(self.cfg.feature_dim))
    }

    /// Words of one row of `width` values stored as `format`.
    pub fn words(format: RowFormat, width: u64) -> u64 {
        RowView::words(format, 1, width as u32)
    }

    /// Hash-grid corners a sample touches: 8 × levels × features, 0 without a hash grid.
    pub fn hash_corners(&self) -> u64 {
        if self.cfg.encoding.uses_hash_grid() {
            8 * u64::from(self.cfg.hash_levels) * u64::from(self.cfg.hash_features_per_level)
        } else {
            0
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_step_keeps_at_most_its_samples_and_bf16_rows_take_half_the_words() {
        let cfg = FieldConfig::default();
        let step = StepShape::new(&cfg, u64::MAX, HeadRowFormats::default());
        assert_eq!(step.samples(), u64::from(cfg.batch_rays) * cfg.samples_per_ray() as u64);
        assert_eq!(step.kept(), step.samples());
        assert_eq!(StepShape::new(&cfg, 10, HeadRowFormats::default()).kept(), 10);
        assert_eq!(StepShape::words(RowFormat::F32, 16), 16);
        assert_eq!(StepShape::words(RowFormat::Bf16, 16), 8);
        assert_eq!(
            step.hash_corners(),
            8 * u64::from(cfg.hash_levels) * u64::from(cfg.hash_features_per_level)
        );
    }
}
