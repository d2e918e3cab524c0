//! Live training in the page. One task (a future on the page's thread) owns the [`Trainer`] and
//! loops: take new labels, render the visible frame when due, submit a batch of steps, wait for
//! the GPU without blocking, adapt the batch to the time it took. The UI talks to it only
//! through [`Shared`]: it posts requests there and reads the reports, so the trainer is never
//! borrowed across an `await` by two parties.
//!
//! The batch is sized so one batch takes about [`TARGET_BATCH_MS`] of GPU time: the UI shares the
//! GPU, and a longer queue of training work would delay every repaint behind it.
//!
//! The visible frame's mask refreshes progressively: when it is out of date (another frame is
//! shown, or new labels have had one batch of training) the frame is first rendered at a
//! fraction of its resolution ([`Refresh`]), shown enlarged, then rendered in full.
use std::cell::RefCell;
use std::future::Future;
use std::pin::Pin;
use std::rc::Rc;
use std::sync::{Arc, Mutex};
use std::task::{Context, Poll, Waker};

use image::GrayImage;

use super::browser::{now_ms, sleep_ms};
use super::training_scene::upscale_mask;
use crate::export::MaskSet;
use crate::field::FieldConfig;
use crate::field::gpu::refine::RefinePass;
use crate::field::gpu::trainer::{DepthGuide, RenderedFrame, StepLosses, Trainer, ViewCamera};
use crate::field::gpu::view::frame_depth_at;
use crate::field::refine::{Guide, RefineOptions};
use crate::gpu::GpuContext;
use crate::labels::LabelSet;
use crate::labels::scale::scale_labels;
use crate::scene::Scene;

/// GPU time one batch of steps should take.
const TARGET_BATCH_MS: f64 = 20.0;
/// Most steps in one batch (a fast GPU would otherwise queue seconds of work on a slow frame).
const MAX_BATCH: u32 = 64;
/// The visible frame is re-rendered at most this often while training (a render costs as much
/// as tens of steps).
const RENDER_INTERVAL_MS: f64 = 1500.0;

/// How the visible frame's mask is refreshed when it is out of date.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Refresh {
    /// The quick first render is this many times smaller on each axis (1: no quick render).
    pub coarse_divisor: u32,
    /// Render the quick one even when the full frame fits one render tile. A tile costs the
    /// same however few of its rays are used, so there the quick render is no quicker; the
    /// default leaves it out.
    pub coarse_always: bool,
}

impl Default for Refresh {
    fn default() -> Self {
        Refresh {
            coarse_divisor: 4,
            coarse_always: false,
        }
    }
}

impl Refresh {
    /// The quick render's size for a `width x height` frame rendered in tiles of `tile` rays,
    /// or `None` when it would not come sooner than the full one.
    pub fn coarse_size(&self, width: u32, height: u32, tile: u32) -> Option<(u32, u32)> {
        if self.coarse_divisor <= 1 {
            return None;
        }
        let size = (
            width.div_ceil(self.coarse_divisor).max(1),
            height.div_ceil(self.coarse_divisor).max(1),
        );
        let tiles = |pixels: u32| pixels.div_ceil(tile.max(1));
        let quicker = tiles(size.0 * size.1) < tiles(width * height);
        let smaller = size.0 * size.1 < width * height;
        (smaller && (quicker || self.coarse_always)).then_some(size)
    }
}

/// How long the latest refresh of the visible mask took, from the request (a frame shown, or
/// labels handed over) to the first mask shown and to the full-resolution one.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RefreshTimes {
    pub first_ms: f64,
    pub full_ms: Option<f64>,
}

/// Where the training stands.
#[derive(Clone, Debug, PartialEq)]
pub enum Phase {
    /// Uploading the scene and building the kernels.
    Starting,
    Running,
    /// Rendering every frame for the download: `done` of `total`.
    Exporting {
        done: u32,
        total: u32,
    },
    /// Stopped for good; the message says why (lost device, out of memory, a bug).
    Failed(String),
}

/// A finished render of one frame.
pub struct Rendered {
    pub frame: u32,
    /// The labels version the field had been trained on when this was rendered.
    pub labels_version: u64,
    pub step: u32,
    pub image: RenderedFrame,
    /// A quick low-resolution render; the full one follows.
    pub coarse: bool,
}

/// Requests from the UI and reports from the task.
pub struct Shared {
    // Requests.
    pub paused: bool,
    /// Until then (page clock, ms) the user is interacting: training waits so that the UI's
    /// frames are not queued behind training work (on a slow GPU one step outlasts a frame).
    pub busy_until_ms: f64,
    pub visible_frame: u32,
    /// New labels to train on (the UI bumps the version with every edit).
    pending_labels: Option<(u64, LabelSet)>,
    /// Render the visible frame as soon as possible (it changed).
    render_soon: bool,
    /// When the latest refresh was asked for (page clock, ms): a frame shown or labels given.
    refresh_requested_ms: f64,
    export: Option<LabelSet>,
    stop: bool,
    // Reports.
    pub phase: Phase,
    pub steps: u32,
    pub steps_per_second: f64,
    pub losses: Option<StepLosses>,
    pub rendered: Option<Rendered>,
    /// The masks zip, once an export is done (taken by the UI).
    pub exported: Option<Result<Vec<u8>, String>>,
    /// Steps per batch as adapted.
    pub batch: u32,
    pub render_ms: f64,
    pub labels_version: u64,
    pub refresh: Option<RefreshTimes>,
    /// Per step of the latest batch: recording and submitting, then waiting for the GPU.
    pub step_submit_ms: f64,
    pub step_wait_ms: f64,
    /// The wall-clock profile (`#profile` in the address), once measured.
    pub profile: Option<String>,
}

/// Handle to the training task of one scene.
pub struct Training {
    shared: Rc<RefCell<Shared>>,
    pub config: FieldConfig,
    pub device: String,
    /// The field trains on frames this many times smaller than the scene's (see
    /// `training_scene`); labels are scaled on the way in.
    pub factor: u32,
}

impl Training {
    /// Starts training on `ctx` (eframe's device) with `labels` (may be empty, drawn on the
    /// full-resolution frames). `scene` is what the field trains on: the loaded scene downscaled
    /// by `factor`; `full_size` is the loaded scene's frame size, which the masks download has.
    #[allow(clippy::too_many_arguments)]
    pub fn start(
        ctx: GpuContext,
        scene: Rc<Scene>,
        factor: u32,
        full_size: (u32, u32),
        config: FieldConfig,
        labels: &LabelSet,
        visible_frame: u32,
        options: TrainingOptions,
        egui_ctx: egui::Context,
    ) -> Training {
        let shared = Rc::new(RefCell::new(Shared {
            paused: false,
            busy_until_ms: 0.0,
            visible_frame,
            pending_labels: Some((0, scale_labels(labels, factor as f32))),
            render_soon: true,
            refresh_requested_ms: now_ms(),
            export: None,
            stop: false,
            phase: Phase::Starting,
            steps: 0,
            steps_per_second: 0.0,
            losses: None,
            rendered: None,
            exported: None,
            batch: 1,
            render_ms: 0.0,
            labels_version: 0,
            refresh: None,
            step_submit_ms: 0.0,
            step_wait_ms: 0.0,
            profile: None,
        }));
        let device = ctx.describe();
        let faults = GpuFaults::watch(&ctx.device, &egui_ctx);
        let task = TrainingTask {
            ctx,
            scene,
            config: config.clone(),
            shared: shared.clone(),
            egui_ctx,
            faults,
            full_size,
            options,
            refine_pass: None,
        };
        wasm_bindgen_futures::spawn_local(task.run());
        Training {
            shared,
            config,
            device,
            factor,
        }
    }

    pub fn shared(&self) -> std::cell::Ref<'_, Shared> {
        self.shared.borrow()
    }

    pub fn shared_mut(&self) -> std::cell::RefMut<'_, Shared> {
        self.shared.borrow_mut()
    }

    /// Hands the task labels to train on from now on.
    pub fn set_labels(&self, version: u64, labels: &LabelSet) {
        // No render now: the field has not learnt anything from them yet; the task refreshes
        // the mask after a batch of training with them.
        let mut s = self.shared.borrow_mut();
        s.pending_labels = Some((version, scale_labels(labels, self.factor as f32)));
        s.refresh_requested_ms = now_ms();
    }

    /// The user is drawing or pressing keys: hold the GPU for the UI a moment.
    pub fn user_active(&self, for_ms: f64) {
        let mut s = self.shared.borrow_mut();
        s.busy_until_ms = s.busy_until_ms.max(now_ms() + for_ms);
    }

    pub fn show_frame(&self, frame: u32) {
        let mut s = self.shared.borrow_mut();
        if s.visible_frame != frame {
            s.visible_frame = frame;
            s.render_soon = true;
            s.refresh_requested_ms = now_ms();
        }
    }

    /// Asks for the masks of every frame; the zip arrives in `Shared::exported`.
    pub fn export(&self, labels: &LabelSet) {
        // The download carries the labels as drawn (full resolution); the task only needs their
        // classes.
        self.shared.borrow_mut().export = Some(labels.clone());
    }
}

impl Drop for Training {
    fn drop(&mut self) {
        // The task sees this at its next turn and ends, dropping the trainer's GPU buffers.
        self.shared.borrow_mut().stop = true;
    }
}

/// Device loss and uncaptured GPU errors, as the device reports them (from browser callbacks,
/// hence the mutex: wgpu asks for `Send` handlers).
#[derive(Clone)]
struct GpuFaults(Arc<Mutex<Option<String>>>);

impl GpuFaults {
    fn watch(device: &wgpu::Device, egui_ctx: &egui::Context) -> GpuFaults {
        let faults = GpuFaults(Arc::new(Mutex::new(None)));
        let lost = faults.clone();
        let repaint = egui_ctx.clone();
        device.set_device_lost_callback(move |reason, message| {
            let text = format!("the GPU device was lost ({reason:?}): {message}");
            // Dropping a trainer destroys its buffers, not the device: anything arriving here
            // means the page's (shared) device is gone.
            super::page_status::set_gpu_lost(&text);
            lost.record(text);
            repaint.request_repaint();
        });
        let errors = faults.clone();
        let repaint = egui_ctx.clone();
        device.on_uncaptured_error(Arc::new(move |error| {
            let text = match &error {
                wgpu::Error::OutOfMemory { .. } => {
                    "the GPU ran out of memory; a smaller scene or a GPU with more memory is needed".to_string()
                }
                other => format!("GPU error: {other}"),
            };
            errors.record(text);
            repaint.request_repaint();
        }));
        faults
    }

    fn record(&self, message: String) {
        if let Ok(mut slot) = self.0.lock() {
            slot.get_or_insert(message);
        }
    }

    fn take(&self) -> Option<String> {
        self.0.lock().ok().and_then(|mut slot| slot.take())
    }
}

/// Choices from the page's address and the device.
#[derive(Clone, Copy, Debug, Default)]
pub struct TrainingOptions {
    pub refresh: Refresh,
    /// Asks for a repaint (new numbers in the panel) at most this often while training. On a
    /// CPU rasterizer a repaint of the page takes about a second of the same device, and every
    /// wait for training work waits behind it (see docs/web-app.md), so there it is rare.
    pub repaint_ms: u64,
    /// Submit every stage of a step as its own command buffer instead of one per step
    /// (`#split=1`; measured on SwiftShader: slower, see docs/web-app.md).
    pub split_steps: bool,
    /// Measure where a step's time goes before training (`#profile`), see [`TrainingTask::profile`].
    pub profile: bool,
    /// Edge-aware refinement of the full renders and the export with each frame's colour and
    /// depth (`#refine=N` rounds, 0: the field's own class map); the quick coarse render stays
    /// unrefined.
    pub refine: RefineOptions,
}

struct TrainingTask {
    options: TrainingOptions,
    ctx: GpuContext,
    scene: Rc<Scene>,
    config: FieldConfig,
    shared: Rc<RefCell<Shared>>,
    egui_ctx: egui::Context,
    faults: GpuFaults,
    full_size: (u32, u32),
    /// The refinement kernel, built when training starts (refinement runs on the GPU here so a
    /// large frame's filter does not hold up the page's thread).
    refine_pass: Option<RefinePass>,
}

impl TrainingTask {
    async fn run(mut self) {
        // The scene carries no labels (see `training_scene::downscale`): the app decides which
        // to start from and hands them over like any later edit.
        let trainer = Trainer::new(&self.ctx, &self.scene, &self.config, 0).await;
        let mut trainer = match trainer {
            Ok(t) => t,
            Err(e) => return self.fail(format!("cannot start training: {e}")),
        };
        if !self.options.refine.is_off() {
            match RefinePass::new(&self.ctx).await {
                Ok(pass) => self.refine_pass = Some(pass),
                Err(e) => return self.fail(format!("cannot build the mask refinement: {e}")),
            }
        }
        if self.options.profile {
            match self.profile(&mut trainer).await {
                Ok(text) => {
                    web_sys::console::log_1(&format!("scribblefield profile: {text}").into());
                    super::page_status::set_profile(&text);
                    self.shared.borrow_mut().profile = Some(text);
                }
                Err(e) => return self.fail(format!("profiling failed: {e}")),
            }
        }
        self.shared.borrow_mut().phase = Phase::Running;
        self.egui_ctx.request_repaint();
        if let Err(e) = self.train(&mut trainer).await {
            self.fail(e);
        }
    }

    fn fail(&self, message: String) {
        self.shared.borrow_mut().phase = Phase::Failed(message);
        self.egui_ctx.request_repaint();
    }

    fn fault(&self) -> Result<(), String> {
        match self.faults.take() {
            Some(message) => Err(message),
            None => Ok(()),
        }
    }

    async fn train(&self, trainer: &mut Trainer) -> Result<(), String> {
        let scene = &self.scene;
        let (w, h, frames) = (scene.width, scene.height, scene.frames.len() as u32);
        let mut batch = 1u32;
        let mut trained_version = 0u64;
        let mut last_render_end = f64::NEG_INFINITY;
        let mut rate = RateMeter::default();
        // New labels wait for one batch of training before the mask is refreshed for them.
        let mut labels_refresh = false;
        let mut trained_since_labels = false;
        // A coarse render of this frame is shown; the full one is next. With the request time.
        let mut full_pending: Option<(u32, f64)> = None;
        loop {
            self.fault()?;
            let (stop, labels, export, paused, periodic_due, frame, busy, frame_changed, requested) = {
                let mut s = self.shared.borrow_mut();
                let since = now_ms() - last_render_end;
                // At most a quarter of the time goes to renders the user did not ask for.
                let due = since > RENDER_INTERVAL_MS.max(3.0 * s.render_ms);
                (
                    s.stop,
                    s.pending_labels.take(),
                    s.export.take(),
                    s.paused,
                    due,
                    s.visible_frame.min(frames.saturating_sub(1)),
                    now_ms() < s.busy_until_ms,
                    s.render_soon,
                    s.refresh_requested_ms,
                )
            };
            if stop {
                return Ok(());
            }
            if let Some((version, labels)) = labels {
                trainer
                    .set_labels(Some(&labels), scene)
                    .map_err(|e| format!("cannot upload the labels: {e}"))?;
                trained_version = version;
                self.shared.borrow_mut().labels_version = version;
                labels_refresh = true;
                trained_since_labels = false;
            }
            if busy {
                sleep_ms(30).await;
                continue;
            }
            if let Some(labels) = export {
                let zip = self.export(trainer, &labels).await;
                let mut s = self.shared.borrow_mut();
                s.exported = Some(zip);
                s.phase = Phase::Running;
                drop(s);
                self.egui_ctx.request_repaint();
                continue;
            }
            // The mask shown is out of date: quick render first, then the full one. A paused
            // field still renders a frame the user steps to.
            let stale = frame_changed || (labels_refresh && trained_since_labels);
            if stale {
                self.shared.borrow_mut().render_soon = false;
                labels_refresh = false;
                full_pending = None;
                let coarse = self.options.refresh.coarse_size(w, h, trainer.config().batch_rays);
                let image = match coarse {
                    Some((cw, ch)) => {
                        let view = ViewCamera::of_frame(scene, frame as usize, cw, ch)
                            .ok_or_else(|| format!("frame {frame} is not in the scene"))?;
                        let depth = frame_depth_at(scene, frame as usize, cw, ch);
                        trainer
                            .render_view(&view, DepthGuide::Measured(&depth))
                            .await
                            .map_err(|e| format!("rendering frame {frame} failed: {e}"))?
                    }
                    None => self.render_full(trainer, frame).await?,
                };
                last_render_end = now_ms();
                let coarse = coarse.is_some();
                if coarse {
                    full_pending = Some((frame, requested));
                }
                self.publish(frame, trained_version, trainer.steps_done(), image, coarse);
                let mut s = self.shared.borrow_mut();
                s.refresh = Some(RefreshTimes {
                    first_ms: last_render_end - requested,
                    full_ms: (!coarse).then_some(last_render_end - requested),
                });
                continue;
            }
            if let Some((pending, requested)) = full_pending.take()
                && pending == frame
            {
                let image = self.render_full(trainer, frame).await?;
                last_render_end = now_ms();
                self.publish(frame, trained_version, trainer.steps_done(), image, false);
                if let Some(r) = &mut self.shared.borrow_mut().refresh {
                    r.full_ms = Some(last_render_end - requested);
                }
                continue;
            }
            if periodic_due && !paused {
                let image = self.render_full(trainer, frame).await?;
                last_render_end = now_ms();
                self.publish(frame, trained_version, trainer.steps_done(), image, false);
                continue;
            }
            if paused {
                rate.reset();
                sleep_ms(100).await;
                continue;
            }
            let start = now_ms();
            if self.options.split_steps {
                train_split(trainer, batch);
            } else {
                trainer.train(batch);
            }
            trainer.request_losses();
            let submitted = now_ms();
            gpu_done(&self.ctx.queue).await;
            let done = now_ms();
            let elapsed = (done - start).max(0.1);
            rate.add(batch, elapsed);
            trained_since_labels = true;
            // Aim the next batch at the target time, changing by at most 2x at a time so one
            // slow frame (a tab switch, a render in between) does not swing it wildly.
            let steps = f64::from(batch);
            let wanted = steps * TARGET_BATCH_MS / elapsed;
            batch = (wanted.clamp(steps / 2.0, steps * 2.0).round() as u32).clamp(1, MAX_BATCH);
            let losses = trainer
                .poll_losses()
                .map_err(|e| format!("reading the losses failed: {e}"))?;
            {
                let mut s = self.shared.borrow_mut();
                s.steps = trainer.steps_done();
                s.steps_per_second = rate.per_second();
                s.losses = losses;
                s.batch = batch;
                s.step_submit_ms = (submitted - start) / steps;
                s.step_wait_ms = (done - submitted) / steps;
            }
            self.egui_ctx
                .request_repaint_after(std::time::Duration::from_millis(self.options.repaint_ms.max(50)));
            // Let the browser run the UI's frame before the next batch.
            sleep_ms(0).await;
        }
    }

    /// Renders `frame` at the training resolution, noting how long it took.
    async fn render_full(&self, trainer: &mut Trainer, frame: u32) -> Result<RenderedFrame, String> {
        let start = now_ms();
        let image = self.render_refined(trainer, frame).await?;
        self.shared.borrow_mut().render_ms = now_ms() - start;
        Ok(image)
    }

    /// Renders `frame` at the training resolution and refines its class map (`options.refine`).
    async fn render_refined(&self, trainer: &mut Trainer, frame: u32) -> Result<RenderedFrame, String> {
        let mut image = trainer
            .render_frame(frame, self.scene.width, self.scene.height)
            .await
            .map_err(|e| format!("rendering frame {frame} failed: {e}"))?;
        if let (Some(guide), Some(pass)) = (Guide::of_frame(&self.scene, frame as usize), &self.refine_pass) {
            image
                .refine_on_gpu(&self.ctx, pass, guide, &self.options.refine)
                .await
                .map_err(|e| format!("refining frame {frame} failed: {e}"))?;
        }
        Ok(image)
    }

    fn publish(&self, frame: u32, labels_version: u64, step: u32, image: RenderedFrame, coarse: bool) {
        self.shared.borrow_mut().rendered = Some(Rendered {
            frame,
            labels_version,
            step,
            image,
            coarse,
        });
        self.egui_ctx.request_repaint();
    }

    /// Where a step's time goes, by the wall clock (browsers offer no timestamp queries by
    /// default): an empty submission, whole steps, each stage submitted alone, and a render
    /// of frame 0, each timed from submission until the GPU reports it done. One line of
    /// `name=ms` pairs (the stages' best of two).
    async fn profile(&self, trainer: &mut Trainer) -> Result<String, String> {
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
        let stages = trainer.stage_count();
        let mut best = vec![(String::new(), f64::MAX); stages];
        for _ in 0..2 {
            for (i, slot) in best.iter_mut().enumerate() {
                let start = now_ms();
                let name = trainer.submit_stage(i).unwrap_or("?");
                gpu_done(&self.ctx.queue).await;
                let ms = timed(start);
                slot.0 = name.replace(' ', "_");
                slot.1 = slot.1.min(ms);
            }
        }
        let sum: f64 = best.iter().map(|b| b.1).sum();
        out.push(format!("stages_sum={sum:.1}"));
        out.extend(best.iter().map(|(name, ms)| format!("{name}={ms:.1}")));
        let start = now_ms();
        self.render_full(trainer, 0).await?;
        out.push(format!("render_frame={:.1}", timed(start)));
        self.fault()?;
        Ok(out.join(" "))
    }

    /// Renders every frame into a masks zip (class ids, previews, labels, class manifest).
    async fn export(&self, trainer: &mut Trainer, labels: &LabelSet) -> Result<Vec<u8>, String> {
        let scene = &self.scene;
        let total = scene.frames.len() as u32;
        let mut masks = Vec::with_capacity(total as usize);
        for frame in 0..total {
            {
                let mut s = self.shared.borrow_mut();
                if s.stop {
                    return Err("stopped".into());
                }
                s.phase = Phase::Exporting { done: frame, total };
            }
            self.egui_ctx.request_repaint();
            self.fault()?;
            let rendered = self.render_refined(trainer, frame).await?;
            let mask = GrayImage::from_raw(scene.width, scene.height, rendered.classes)
                .ok_or_else(|| format!("frame {frame}: the rendered class map has the wrong size"))?;
            masks.push(upscale_mask(mask, self.full_size.0, self.full_size.1));
        }
        self.shared.borrow_mut().phase = Phase::Exporting { done: total, total };
        self.egui_ctx.request_repaint();
        // Let the page show "packing" before the zip takes the thread.
        sleep_ms(20).await;
        let set = MaskSet {
            classes: labels.classes.clone(),
            masks,
        };
        Ok(set.to_zip(Some(labels)))
    }
}

/// Trains `steps` steps submitting each stage on its own (see [`TrainingOptions::split_steps`]).
fn train_split(trainer: &mut Trainer, steps: u32) {
    let stages = trainer.stage_count();
    for _ in 0..steps {
        for i in 0..stages {
            trainer.submit_stage(i);
        }
    }
}

/// Steps per second over the last few seconds of batches.
#[derive(Default)]
struct RateMeter {
    samples: std::collections::VecDeque<(f64, u32, f64)>,
}

impl RateMeter {
    fn add(&mut self, steps: u32, ms: f64) {
        self.samples.push_back((now_ms(), steps, ms));
        while self.samples.len() > 2 && self.samples.front().is_some_and(|s| now_ms() - s.0 > 3000.0) {
            self.samples.pop_front();
        }
    }

    /// Steps per second of wall time, counting the gaps between batches too.
    fn per_second(&self) -> f64 {
        let (Some(first), Some(last)) = (self.samples.front(), self.samples.back()) else {
            return 0.0;
        };
        let steps: u32 = self.samples.iter().map(|s| s.1).sum();
        let span = last.0 - (first.0 - first.2);
        if span <= 0.0 {
            0.0
        } else {
            f64::from(steps) * 1000.0 / span
        }
    }

    fn reset(&mut self) {
        self.samples.clear();
    }
}

/// Resolves once the GPU has finished everything submitted so far. The browser calls back
/// from its event loop; nothing blocks.
fn gpu_done(queue: &wgpu::Queue) -> impl Future<Output = ()> {
    let state = Arc::new(Mutex::new(WorkDone::default()));
    let callback_state = state.clone();
    queue.on_submitted_work_done(move || {
        if let Ok(mut s) = callback_state.lock() {
            s.done = true;
            if let Some(w) = s.waker.take() {
                w.wake();
            }
        }
    });
    WaitWorkDone(state)
}

#[derive(Default)]
struct WorkDone {
    done: bool,
    waker: Option<Waker>,
}

struct WaitWorkDone(Arc<Mutex<WorkDone>>);

impl Future for WaitWorkDone {
    type Output = ();

    fn poll(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<()> {
        let Ok(mut s) = self.0.lock() else {
            // A poisoned lock means the callback panicked: do not wait forever.
            return Poll::Ready(());
        };
        if s.done {
            Poll::Ready(())
        } else {
            s.waker = Some(cx.waker().clone());
            Poll::Pending
        }
    }
}
