//! Headless training and scoring (native only): the schedule `segment`, the quality tests and
//! the ablations share, so they measure the same thing.
//!
//! Schedule: `warmup` steps without labels (colour, depth and features only), then the labels
//! join and `steps` more steps train with them.
use crate::field::gpu::trainer::{RenderedFrame, Trainer};
use crate::gpu::GpuError;
use crate::labels::LabelSet;
use crate::refine::RefineOptions;
use crate::scene::Guide;
use crate::scene::Scene;

use super::metrics::{Confusion, EvalReport};

/// Steps trained between loss read-backs (each read waits for the GPU).
const CHUNK: u32 = 10;

/// Runs the warm-up-then-labels schedule. `progress(done, total, loss)` is called after every
/// chunk of steps (loss: the latest total loss read back, read every 50 steps).
pub fn train_schedule(
    trainer: &mut Trainer,
    scene: &Scene,
    labels: &LabelSet,
    warmup: u32,
    steps: u32,
    mut progress: impl FnMut(u32, u32, Option<f64>),
) -> Result<(), GpuError> {
    let total = warmup + steps;
    let mut done = 0;
    let mut loss = None;
    while done < total {
        if done == warmup {
            trainer.set_labels(Some(labels), scene)?;
        }
        let until = if done < warmup { warmup } else { total };
        let n = CHUNK.min(until - done);
        trainer.train(n);
        done += n;
        if done % 50 < CHUNK || done == total {
            loss = Some(trainer.losses_blocking()?.terms.total());
        }
        progress(done, total, loss);
    }
    Ok(())
}

/// Renders frame `frame` of `scene` at its resolution and refines its class map with the
/// frame's image and depth as the guide (`refine` off: the field's own argmax).
pub fn render_scene_frame(
    trainer: &mut Trainer,
    scene: &Scene,
    frame: usize,
    refine: &RefineOptions,
) -> Result<RenderedFrame, GpuError> {
    let mut rendered = pollster::block_on(trainer.render_frame(frame as u32, scene.width, scene.height))?;
    if let Some(guide) = Guide::of_frame(scene, frame) {
        rendered
            .refine(guide, refine)
            .map_err(|e| GpuError::invalid_argument("refine", e))?;
    }
    Ok(rendered)
}

/// Renders `frames` (refined as `render_scene_frame` does) and scores their class maps against
/// the scene's ground truth (frames without ground truth are rendered but not scored).
/// `each(frame, rendered)` sees every render.
pub fn render_and_score(
    trainer: &mut Trainer,
    scene: &Scene,
    class_names: &[String],
    frames: impl IntoIterator<Item = usize>,
    refine: &RefineOptions,
    mut each: impl FnMut(usize, RenderedFrame),
) -> Result<EvalReport, GpuError> {
    let mut confusion = Confusion::new(class_names.len());
    let mut scored = 0;
    for i in frames {
        let rendered = render_scene_frame(trainer, scene, i, refine)?;
        if let Some(gt) = scene.frames.get(i).and_then(|f| f.gt.as_ref()) {
            confusion.add(gt.as_raw(), &rendered.classes);
            scored += 1;
        }
        each(i, rendered);
    }
    Ok(confusion.report(class_names, scored))
}
