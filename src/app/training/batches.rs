//! Training batches as the page runs them, for the training task and the page's bench mode
//! (`app::bench`) alike: record and submit a batch of steps, yield to the browser, and adapt the
//! batch to the GPU time it took.
//!
//! On a GPU two batches are in flight, to bring the page near native speed: the next batch is
//! recorded and submitted while the previous one runs, and only then does the task wait, for the
//! older one.
//! So the GPU does not idle while the page's thread records, and the wait for a batch's end
//! overlaps the next batch's work. The steps are submitted in the same order either way, so
//! training is the same; only when the page's thread waits changes. On a CPU rasterizer one: a
//! step there takes seconds, against about a millisecond of recording and yielding, so a second
//! batch gains nothing measurable (Chromium on SwiftShader even reports both done together, when
//! the second ends), while every render and repaint the user waits for would queue behind
//! seconds more of training (docs/results/bench.md, "The page against native").
//!
//! The batch is sized so one batch takes about [`TARGET_BATCH_MS`] of GPU time: the UI shares the
//! GPU, and a longer queue of training work would delay every repaint behind it.
use std::collections::VecDeque;

use super::super::browser::{now_ms, sleep_ms};
use super::device::{GpuDone, RateMeter, gpu_done, gpu_done_at};
use crate::field::gpu::trainer::Trainer;
use crate::gpu::GpuContext;
use crate::gpu::profile::GPU_BATCHES_IN_FLIGHT;

/// GPU time one batch of steps should take.
pub const TARGET_BATCH_MS: f64 = 20.0;
/// Most steps in one batch (a fast GPU would otherwise queue seconds of work on a slow frame).
pub const MAX_BATCH: u32 = 64;

/// A batch submitted, not yet seen done.
struct Submitted {
    steps: u32,
    /// When its recording began (page clock, ms).
    start_ms: f64,
    done: GpuDone,
}

/// A batch the GPU has finished.
#[derive(Clone, Copy, Debug, Default)]
pub struct Finished {
    pub steps: u32,
    /// Its share of the GPU's time: from when it was submitted, or the batch before it ended
    /// (whichever was later), to its end.
    pub gpu_ms: f64,
    /// When it ended (page clock, ms).
    pub done_ms: f64,
}

/// What one call of [`Batches::run`] did.
#[derive(Clone, Copy, Debug, Default)]
pub struct BatchTimes {
    /// Steps recorded and submitted.
    pub steps: u32,
    /// Recording and submitting them, ms.
    pub record_ms: f64,
    /// Waiting for the GPU afterwards, ms.
    pub wait_ms: f64,
    /// The oldest batch in flight, when it finished during this call.
    pub finished: Option<Finished>,
}

/// The page's way of training: batches adapted to the GPU's time, up to
/// [`GPU_BATCHES_IN_FLIGHT`] of them queued.
pub struct Batches {
    /// Steps in the next batch, adapted to [`TARGET_BATCH_MS`].
    pub size: u32,
    /// Batches kept in flight: [`GPU_BATCHES_IN_FLIGHT`], or 1 to wait for each batch before
    /// recording the next ([`Batches::for_device`] chooses).
    pub depth: usize,
    /// Submit every stage of a step as its own command buffer (`#split=1`).
    pub split_steps: bool,
    in_flight: VecDeque<Submitted>,
    /// When the latest batch seen done ended.
    last_done_ms: f64,
    /// GPU time per step of the latest batch the size was adapted to.
    step_ms: Option<f64>,
    /// The latest batch was not believed (see [`Batches::finish_oldest`]).
    doubted: bool,
    pub rate: RateMeter,
}

impl Batches {
    /// Batches kept in flight on `ctx` (`DeviceProfile::batches_in_flight`: one on a CPU
    /// rasterizer, [`GPU_BATCHES_IN_FLIGHT`] on a GPU; see the module's notes).
    pub fn for_device(ctx: &GpuContext, split_steps: bool) -> Batches {
        let mut batches = Batches::new(split_steps);
        batches.depth = ctx.profile().batches_in_flight();
        batches
    }

    pub fn new(split_steps: bool) -> Batches {
        Batches {
            size: 1,
            depth: GPU_BATCHES_IN_FLIGHT,
            split_steps,
            in_flight: VecDeque::new(),
            last_done_ms: f64::NEG_INFINITY,
            step_ms: None,
            doubted: false,
            rate: RateMeter::default(),
        }
    }

    /// Records and submits one batch of at most `most` steps (and a read of its losses), then
    /// waits for the oldest batch in flight once [`Batches::depth`] are, and adapts the batch
    /// size to it.
    pub async fn run(&mut self, ctx: &GpuContext, trainer: &mut Trainer, most: u32) -> BatchTimes {
        let steps = self.size.min(most.max(1));
        let start_ms = now_ms();
        if self.split_steps {
            train_split(trainer, steps);
        } else {
            trainer.train(steps);
        }
        trainer.request_losses();
        let submitted = now_ms();
        self.in_flight.push_back(Submitted {
            steps,
            start_ms,
            done: gpu_done_at(&ctx.queue),
        });
        let finished = if self.in_flight.len() >= self.depth.max(1) {
            self.finish_oldest().await
        } else {
            None
        };
        BatchTimes {
            steps,
            record_ms: submitted - start_ms,
            wait_ms: now_ms() - submitted,
            finished,
        }
    }

    /// Waits for every batch in flight; the last one's end, if any were.
    pub async fn drain(&mut self) -> Option<Finished> {
        let mut last = None;
        while !self.in_flight.is_empty() {
            last = self.finish_oldest().await.or(last);
        }
        last
    }

    /// Waits for the oldest batch in flight, counts it and adapts the batch size to it.
    async fn finish_oldest(&mut self) -> Option<Finished> {
        let batch = self.in_flight.pop_front()?;
        // A device gone drops the callback: count the batch as ending now.
        let done_ms = batch.done.await.unwrap_or_else(now_ms);
        let gpu_ms = (done_ms - batch.start_ms.max(self.last_done_ms)).max(0.1);
        self.last_done_ms = done_ms;
        self.rate.add_at(done_ms, batch.steps, gpu_ms);
        // Aim the next batch at the target time, changing by at most 2x at a time so one
        // slow frame (a tab switch, a render in between) does not swing it wildly. Chromium on
        // SwiftShader reports two batches in flight done together, when the second ends: the
        // first is charged for both and the second looks nearly free. A batch more than 4x
        // quicker per step than the one before is therefore not believed, once.
        let steps = f64::from(batch.steps);
        let per_step = gpu_ms / steps;
        let implausible = !self.doubted && self.step_ms.is_some_and(|last| per_step < last / 4.0);
        self.doubted = implausible;
        if !implausible {
            self.step_ms = Some(per_step);
            let wanted = steps * TARGET_BATCH_MS / gpu_ms;
            self.size = (wanted.clamp(steps / 2.0, steps * 2.0).round() as u32).clamp(1, MAX_BATCH);
        }
        Some(Finished {
            steps: batch.steps,
            gpu_ms,
            done_ms,
        })
    }

    /// Lets the browser run the UI's frame before the next batch.
    pub async fn yield_to_page(&self) {
        sleep_ms(0).await;
    }
}

/// Trains `steps` steps submitting each stage on its own (see
/// [`super::TrainingOptions::split_steps`]).
pub fn train_split(trainer: &mut Trainer, steps: u32) {
    let stages = trainer.stage_count();
    for _ in 0..steps {
        for i in 0..stages {
            trainer.submit_stage(i);
        }
    }
}

/// Wall-clock milliseconds of each stage of a training step submitted alone, from submission
/// until the GPU reports it done, best of `rounds` (each round trains one whole step, stage by
/// stage); by stage name, in step order. Where timestamp queries are missing (browsers).
pub async fn stage_wall_ms(ctx: &GpuContext, trainer: &mut Trainer, rounds: u32) -> Vec<(String, f64)> {
    let mut best = vec![(String::new(), f64::MAX); trainer.stage_count()];
    for _ in 0..rounds.max(1) {
        for (i, slot) in best.iter_mut().enumerate() {
            let start = now_ms();
            let name = trainer.submit_stage(i).unwrap_or("?");
            gpu_done(&ctx.queue).await;
            slot.0 = name.to_string();
            slot.1 = slot.1.min(now_ms() - start);
        }
    }
    best
}
