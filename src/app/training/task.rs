//! The training task: owns the [`Trainer`] and, each turn, applies the page's commands, then
//! does one thing ([`Action`]): wait, export, refresh the visible mask, render it again, or
//! train a batch of steps. It waits for the GPU without blocking and adapts the batch to the
//! time it took ([`Batches`]: on a GPU the next batch is submitted before the previous one is
//! waited for).
use std::rc::Rc;

use futures_channel::mpsc::{TryRecvError, UnboundedReceiver, UnboundedSender};
use image::GrayImage;

use super::super::browser::{now_ms, sleep_ms};
use super::batches::{Batches, MAX_BATCH, stage_wall_ms, train_split};
use super::device::{GpuFaults, gpu_done};
use super::messages::{Phase, Progress, RefreshTimes, Rendered, Spread, TrainCommand, TrainError, TrainEvent};
use super::scene::upscale_mask;
use super::{TrainingOptions, TrainingSetup};
use crate::export::{ExportOptions, ExportWriter, zip_files};
use crate::field::FieldConfig;
use crate::field::gpu::trainer::{DepthGuide, RenderedFrame, Trainer, ViewCamera};
use crate::field::gpu::view::frame_depth_at;
use crate::gpu::GpuContext;
use crate::labels::LabelSet;
use crate::pause::Pause;
use crate::refine::gpu::RefinePass;
use crate::scene::Guide;
use crate::scene::Scene;

/// The visible frame is re-rendered at most this often while training (a render costs as much
/// as tens of steps).
const RENDER_INTERVAL_MS: f64 = 1500.0;

/// Work on the page's thread between two gives back (it also draws the page and takes strokes).
const SLICE_MS: f64 = 12.0;

/// Pauses a long computation on the page's thread ([`crate::pause`]) once it has held the
/// thread for [`SLICE_MS`], and tells the page the first time, so it can say what is going on.
struct Slices<'a> {
    task: &'a TrainingTask,
    since_ms: f64,
    reported: bool,
}

impl<'a> Slices<'a> {
    fn new(task: &'a TrainingTask) -> Slices<'a> {
        Slices {
            task,
            since_ms: now_ms(),
            reported: false,
        }
    }
}

impl Pause for Slices<'_> {
    async fn pause(&mut self) {
        if now_ms() - self.since_ms < SLICE_MS {
            return;
        }
        if !self.reported {
            self.reported = true;
            self.task.report(TrainEvent::Spreading(true));
        }
        sleep_ms(0).await;
        self.since_ms = now_ms();
    }
}

/// What the page has asked for, as of the latest commands.
struct Requests {
    paused: bool,
    busy_until_ms: f64,
    visible_frame: u32,
    /// New labels to train on, with their version.
    labels: Option<(u64, LabelSet)>,
    /// Render the visible frame as soon as possible (it changed).
    render_soon: bool,
    /// When the latest refresh was asked for (page clock, ms): a frame shown or labels given.
    refresh_requested_ms: f64,
    export: Option<(LabelSet, ExportOptions)>,
    /// The page has not taken the latest render yet.
    render_untaken: bool,
}

/// What the task does next.
enum Action {
    /// The user is at work: give the page the device for a moment.
    Wait,
    /// Paused: look again in a while.
    Paused,
    Export(LabelSet, ExportOptions),
    /// The mask shown is out of date: quick render first (when quicker), then the full one.
    RefreshStale,
    /// The full render after a quick one, asked for at `requested_ms`.
    FinishRefresh {
        requested_ms: f64,
    },
    /// The periodic render while training.
    RenderAgain,
    TrainBatch,
}

pub struct TrainingTask {
    options: TrainingOptions,
    ctx: GpuContext,
    scene: Rc<Scene>,
    config: FieldConfig,
    full_size: (u32, u32),
    commands: UnboundedReceiver<TrainCommand>,
    events: UnboundedSender<TrainEvent>,
    egui_ctx: egui::Context,
    faults: GpuFaults,
    /// The refinement kernel, built when training starts (refinement runs on the GPU here so a
    /// large frame's filter does not hold up the page's thread).
    refine_pass: Option<RefinePass>,
    requests: Requests,
    /// The batches of steps: their size, the ones in flight, the rate.
    batches: Batches,
    /// The labels version the trainer has.
    trained_version: u64,
    last_render_end: f64,
    render_ms: f64,
    /// New labels wait for one batch of training before the mask is refreshed for them.
    labels_refresh: bool,
    trained_since_labels: bool,
    /// A coarse render of this frame is shown; the full one is next. With the request time.
    full_pending: Option<(u32, f64)>,
    refresh: Option<RefreshTimes>,
}

impl TrainingTask {
    pub fn new(
        ctx: GpuContext,
        setup: TrainingSetup,
        visible_frame: u32,
        commands: UnboundedReceiver<TrainCommand>,
        events: UnboundedSender<TrainEvent>,
        egui_ctx: egui::Context,
    ) -> TrainingTask {
        let faults = GpuFaults::watch(&ctx.device, &egui_ctx);
        let batches = Batches::for_device(&ctx, setup.options.split_steps);
        TrainingTask {
            options: setup.options,
            ctx,
            scene: setup.scene,
            config: setup.config,
            full_size: setup.full_size,
            commands,
            events,
            egui_ctx,
            faults,
            refine_pass: None,
            requests: Requests {
                paused: false,
                busy_until_ms: 0.0,
                visible_frame,
                labels: None,
                render_soon: true,
                refresh_requested_ms: now_ms(),
                export: None,
                render_untaken: false,
            },
            batches,
            trained_version: 0,
            last_render_end: f64::NEG_INFINITY,
            render_ms: 0.0,
            labels_refresh: false,
            trained_since_labels: false,
            full_pending: None,
            refresh: None,
        }
    }

    pub async fn run(mut self) {
        let mut trainer = match self.prepare().await {
            Ok(t) => t,
            Err(e) => return self.report(TrainEvent::Phase(Phase::Failed(e))),
        };
        self.report(TrainEvent::Phase(Phase::Running));
        if let Err(e) = self.train(&mut trainer).await {
            self.report(TrainEvent::Phase(Phase::Failed(e)));
        }
    }

    /// Sends an event and asks the page to repaint for it. A closed channel means the page has
    /// dropped its handle; the task sees that at its next turn.
    fn report(&self, event: TrainEvent) {
        let _ = self.events.unbounded_send(event);
        self.egui_ctx.request_repaint();
    }

    /// Builds the trainer and the refinement kernel, and profiles a step when asked to.
    async fn prepare(&mut self) -> Result<Trainer, TrainError> {
        let mut trainer = Trainer::new(&self.ctx, &self.scene, &self.config, 0)
            .await
            .map_err(TrainError::Start)?;
        if !self.options.refine.is_off() {
            self.refine_pass = Some(RefinePass::new(&self.ctx).await.map_err(TrainError::RefineKernel)?);
        }
        if self.options.profile {
            let text = self
                .profile(&mut trainer)
                .await
                .map_err(|e| TrainError::Profile(Box::new(e)))?;
            let _ = self.events.unbounded_send(TrainEvent::Profile(text));
        }
        Ok(trainer)
    }

    /// Applies every queued command. `false` once the page has dropped its handle.
    fn take_commands(&mut self) -> bool {
        loop {
            let command = match self.commands.try_recv() {
                Ok(c) => c,
                Err(TryRecvError::Empty) => return true,
                Err(TryRecvError::Closed) => return false,
            };
            let r = &mut self.requests;
            match command {
                TrainCommand::SetLabels {
                    version,
                    labels,
                    requested_ms,
                } => {
                    r.labels = Some((version, labels));
                    r.refresh_requested_ms = requested_ms;
                }
                TrainCommand::ShowFrame { frame, requested_ms } => {
                    if r.visible_frame != frame {
                        r.visible_frame = frame;
                        r.render_soon = true;
                        r.refresh_requested_ms = requested_ms;
                    }
                }
                TrainCommand::UserActive { until_ms } => r.busy_until_ms = r.busy_until_ms.max(until_ms),
                TrainCommand::SetPaused(paused) => r.paused = paused,
                TrainCommand::Export(labels, options) => r.export = Some((labels, options)),
                TrainCommand::RenderTaken => r.render_untaken = false,
            }
        }
    }

    /// The visible frame, within the scene.
    fn frame(&self) -> u32 {
        self.requests
            .visible_frame
            .min((self.scene.frames.len() as u32).saturating_sub(1))
    }

    /// Decides what to do this turn, in order of urgency.
    fn next_action(&mut self) -> Action {
        let frame = self.frame();
        if now_ms() < self.requests.busy_until_ms {
            return Action::Wait;
        }
        if let Some((labels, options)) = self.requests.export.take() {
            return Action::Export(labels, options);
        }
        // A paused field still renders a frame the user steps to.
        if self.requests.render_soon || (self.labels_refresh && self.trained_since_labels) {
            return Action::RefreshStale;
        }
        if let Some((pending, requested_ms)) = self.full_pending.take()
            && pending == frame
        {
            return Action::FinishRefresh { requested_ms };
        }
        // At most a quarter of the time goes to renders the user did not ask for.
        let due = now_ms() - self.last_render_end > RENDER_INTERVAL_MS.max(3.0 * self.render_ms);
        if self.requests.paused {
            return Action::Paused;
        }
        if due && !self.requests.render_untaken {
            return Action::RenderAgain;
        }
        Action::TrainBatch
    }

    async fn train(&mut self, trainer: &mut Trainer) -> Result<(), TrainError> {
        loop {
            self.faults.check()?;
            if !self.take_commands() {
                return Ok(());
            }
            self.upload_labels(trainer).await?;
            match self.next_action() {
                Action::Wait => sleep_ms(30).await,
                Action::Paused => {
                    self.batches.rate.reset();
                    sleep_ms(100).await;
                }
                Action::Export(labels, options) => {
                    let zip = self.export(trainer, &labels, options).await;
                    let _ = self.events.unbounded_send(TrainEvent::Exported(zip));
                    self.report(TrainEvent::Phase(Phase::Running));
                }
                Action::RefreshStale => self.refresh_stale(trainer).await?,
                Action::FinishRefresh { requested_ms } => self.finish_refresh(trainer, requested_ms).await?,
                Action::RenderAgain => {
                    let image = self.render_full(trainer, self.frame()).await?;
                    self.publish(trainer, image, false);
                }
                Action::TrainBatch => self.train_batch(trainer).await?,
            }
        }
    }

    /// Hands the trainer the latest labels, if any came. Spreading them can take seconds on a
    /// capture with sparse depth: it runs in slices, giving the page's thread back between them.
    async fn upload_labels(&mut self, trainer: &mut Trainer) -> Result<(), TrainError> {
        if let Some((version, labels)) = self.requests.labels.take() {
            let mut slices = Slices::new(self);
            let spread = trainer
                .set_labels_pausing(Some(&labels), &self.scene, &mut slices)
                .await;
            if slices.reported {
                self.report(TrainEvent::Spreading(false));
            }
            spread.map_err(TrainError::Labels)?;
            self.report(TrainEvent::Spread(Spread {
                pixels: trainer.labelled_pixels(),
                frames: trainer.labelled_frames(),
                check: trainer.spread_check(),
                withheld: trainer.spread_withheld(),
            }));
            self.trained_version = version;
            self.labels_refresh = true;
            self.trained_since_labels = false;
        }
        Ok(())
    }

    /// The mask shown is out of date: renders it quickly at low resolution when that comes
    /// sooner (the full render follows, [`Action::FinishRefresh`]), else in full.
    async fn refresh_stale(&mut self, trainer: &mut Trainer) -> Result<(), TrainError> {
        let frame = self.frame();
        let requested = self.requests.refresh_requested_ms;
        self.requests.render_soon = false;
        self.labels_refresh = false;
        self.full_pending = None;
        let (w, h) = (self.scene.width, self.scene.height);
        let coarse = self.options.refresh.coarse_size(w, h, trainer.config().batch_rays);
        let image = match coarse {
            Some((cw, ch)) => {
                let view =
                    ViewCamera::of_frame(&self.scene, frame as usize, cw, ch).ok_or(TrainError::NoSuchFrame(frame))?;
                let depth = frame_depth_at(&self.scene, frame as usize, cw, ch);
                trainer
                    .render_view(&view, DepthGuide::Measured(&depth))
                    .await
                    .map_err(|source| TrainError::Render { frame, source })?
            }
            None => self.render_full(trainer, frame).await?,
        };
        if coarse.is_some() {
            self.full_pending = Some((frame, requested));
        }
        self.publish(trainer, image, coarse.is_some());
        let took = self.last_render_end - requested;
        self.update_refresh(RefreshTimes {
            first_ms: took,
            full_ms: coarse.is_none().then_some(took),
        });
        Ok(())
    }

    /// The full render after a quick one.
    async fn finish_refresh(&mut self, trainer: &mut Trainer, requested_ms: f64) -> Result<(), TrainError> {
        let image = self.render_full(trainer, self.frame()).await?;
        self.publish(trainer, image, false);
        if let Some(mut times) = self.refresh {
            times.full_ms = Some(self.last_render_end - requested_ms);
            self.update_refresh(times);
        }
        Ok(())
    }

    fn update_refresh(&mut self, times: RefreshTimes) {
        self.refresh = Some(times);
        let _ = self.events.unbounded_send(TrainEvent::Refresh(times));
    }

    /// Trains one batch of steps (on a GPU submitted behind the previous one, which is then
    /// waited for) and reports the progress.
    async fn train_batch(&mut self, trainer: &mut Trainer) -> Result<(), TrainError> {
        let times = self.batches.run(&self.ctx, trainer, MAX_BATCH).await;
        self.trained_since_labels = true;
        let losses = trainer.poll_losses().map_err(TrainError::Losses)?;
        let steps = f64::from(times.steps.max(1));
        let _ = self.events.unbounded_send(TrainEvent::Progress(Progress {
            steps: trainer.steps_done(),
            steps_per_second: self.batches.rate.per_second(),
            losses,
            batch: self.batches.size,
            step_submit_ms: times.record_ms / steps,
            step_wait_ms: times.wait_ms / steps,
        }));
        self.egui_ctx
            .request_repaint_after(std::time::Duration::from_millis(self.options.repaint_ms.max(50)));
        self.batches.yield_to_page().await;
        Ok(())
    }

    /// Renders `frame` at the training resolution, noting how long it took.
    async fn render_full(&mut self, trainer: &mut Trainer, frame: u32) -> Result<RenderedFrame, TrainError> {
        let start = now_ms();
        let image = self.render_refined(trainer, frame).await?;
        self.render_ms = now_ms() - start;
        let _ = self.events.unbounded_send(TrainEvent::RenderTime(self.render_ms));
        Ok(image)
    }

    /// Renders `frame` at the training resolution and refines its class map (`options.refine`).
    async fn render_refined(&self, trainer: &mut Trainer, frame: u32) -> Result<RenderedFrame, TrainError> {
        let mut image = trainer
            .render_frame(frame, self.scene.width, self.scene.height)
            .await
            .map_err(|source| TrainError::Render { frame, source })?;
        if let (Some(guide), Some(pass)) = (Guide::of_frame(&self.scene, frame as usize), &self.refine_pass) {
            image
                .refine_on_gpu(&self.ctx, pass, guide, &self.options.refine)
                .await
                .map_err(|source| TrainError::Refine { frame, source })?;
        }
        Ok(image)
    }

    /// Hands a render of the visible frame to the page.
    fn publish(&mut self, trainer: &Trainer, image: RenderedFrame, coarse: bool) {
        self.last_render_end = now_ms();
        self.requests.render_untaken = true;
        self.report(TrainEvent::Rendered(Box::new(Rendered {
            frame: self.frame(),
            labels_version: self.trained_version,
            step: trainer.steps_done(),
            image,
            coarse,
            labelled: trainer.labelled_pixels() > 0,
        })));
    }

    /// Where a step's time goes, by the wall clock (browsers offer no timestamp queries by
    /// default): an empty submission, whole steps, each stage submitted alone, and a render
    /// of frame 0, each timed from submission until the GPU reports it done. One line of
    /// `name=ms` pairs (the stages' best of two).
    async fn profile(&mut self, trainer: &mut Trainer) -> Result<String, TrainError> {
        let timed = |start: f64| now_ms() - start;
        let mut out = Vec::new();
        // Warm up (first use of every pipeline).
        trainer.train(1);
        gpu_done(&self.ctx.queue).await;
        let mut empty = f64::MAX;
        for _ in 0..3 {
            let start = now_ms();
            self.ctx.queue.submit(std::iter::empty::<wgpu::CommandBuffer>());
            gpu_done(&self.ctx.queue).await;
            empty = empty.min(timed(start));
        }
        out.push(format!("empty_submit={empty:.1}"));
        let mut step = f64::MAX;
        let mut step_submit = 0.0;
        for _ in 0..2 {
            let start = now_ms();
            trainer.train(1);
            step_submit = timed(start);
            gpu_done(&self.ctx.queue).await;
            step = step.min(timed(start));
        }
        out.push(format!("step={step:.1} step_submit={step_submit:.1}"));
        let mut split = f64::MAX;
        for _ in 0..2 {
            let start = now_ms();
            train_split(trainer, 1);
            gpu_done(&self.ctx.queue).await;
            split = split.min(timed(start));
        }
        out.push(format!("step_split={split:.1}"));
        let best: Vec<(String, f64)> = stage_wall_ms(&self.ctx, trainer, 2)
            .await
            .into_iter()
            .map(|(name, ms)| (name.replace(' ', "_"), ms))
            .collect();
        let sum: f64 = best.iter().map(|b| b.1).sum();
        out.push(format!("stages_sum={sum:.1}"));
        out.extend(best.iter().map(|(name, ms)| format!("{name}={ms:.1}")));
        let start = now_ms();
        self.render_full(trainer, 0).await?;
        out.push(format!("render_frame={:.1}", timed(start)));
        self.faults.check()?;
        Ok(out.join(" "))
    }

    /// Renders every frame into a masks zip (class ids by index and by name, previews, labels,
    /// class manifest, and the formats in `options`). The options are checked before the first
    /// frame is rendered.
    async fn export(
        &mut self,
        trainer: &mut Trainer,
        labels: &LabelSet,
        options: ExportOptions,
    ) -> Result<Vec<u8>, TrainError> {
        let total = self.scene.frames.len() as u32;
        let scene = Rc::clone(&self.scene);
        // The training scene: the frames' names, and depth for the point cloud at its size
        // (masks come at the full size; `ply` looks up each depth pixel's class in them).
        let mut writer =
            ExportWriter::new(labels.classes.clone(), options, Some(&scene)).map_err(TrainError::Export)?;
        let mut files = Vec::new();
        for frame in 0..total {
            // Later commands wait for the export; a dropped handle ends it.
            if !self.take_commands() {
                return Err(TrainError::Stopped);
            }
            self.report(TrainEvent::Phase(Phase::Exporting { done: frame, total }));
            self.faults.check()?;
            let rendered = self.render_refined(trainer, frame).await?;
            let mask = GrayImage::from_raw(self.scene.width, self.scene.height, rendered.classes)
                .ok_or(TrainError::MaskSize(frame))?;
            let mut mask = upscale_mask(mask, self.full_size.0, self.full_size.1);
            files.extend(writer.frame(&mut mask).map_err(TrainError::Export)?);
        }
        self.report(TrainEvent::Phase(Phase::Exporting { done: total, total }));
        // Let the page show "packing" before the zip takes the thread.
        sleep_ms(20).await;
        files.extend(writer.finish(Some(labels)).map_err(TrainError::Export)?);
        Ok(zip_files(files))
    }
}
