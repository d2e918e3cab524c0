//! Live training in the page. One task (a future on the page's thread, [`task`]) owns the
//! [`Trainer`](crate::field::gpu::trainer::Trainer); the page holds a [`Training`] handle. They
//! talk only through two channels: [`TrainCommand`]s to the task, [`TrainEvent`]s back
//! ([`messages`]), so the trainer is never borrowed across an `await` by two parties.
//!
//! The visible frame's mask refreshes progressively: when it is out of date (another frame is
//! shown, or new labels have had one batch of training) the frame is first rendered at a
//! fraction of its resolution ([`Refresh`]), shown enlarged, then rendered in full.
pub mod batches;
pub mod device;
pub mod messages;
pub mod scene;
mod task;

use std::rc::Rc;

use futures_channel::mpsc::{UnboundedReceiver, UnboundedSender, unbounded};

pub use self::messages::{Phase, Progress, RefreshTimes, Rendered, Spread, TrainCommand, TrainError, TrainEvent};
use super::browser::now_ms;
use crate::export::ExportOptions;
use crate::field::FieldConfig;
use crate::gpu::GpuContext;
use crate::labels::LabelSet;
use crate::labels::scale::scale_labels;
use crate::refine::RefineOptions;
use crate::scene::Scene;

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
    /// Measure where a step's time goes before training (`#profile`).
    pub profile: bool,
    /// Edge-aware refinement of the full renders and the export with each frame's colour and
    /// depth (`RefineOptions::for_scene` unless `#refine=N` rounds, 0: the field's own class
    /// map); the quick coarse render stays unrefined.
    pub refine: RefineOptions,
}

/// What to train: the scene at training resolution and the field.
pub struct TrainingSetup {
    /// The loaded scene downscaled by `factor` (see [`scene`]).
    pub scene: Rc<Scene>,
    /// The field trains on frames this many times smaller than the scene's; labels are scaled
    /// on the way in.
    pub factor: u32,
    /// The loaded scene's frame size, which the masks download has.
    pub full_size: (u32, u32),
    pub config: FieldConfig,
    pub options: TrainingOptions,
}

/// What the task has reported so far (the latest of each).
#[derive(Debug)]
pub struct Reports {
    pub phase: Phase,
    pub progress: Progress,
    pub render_ms: f64,
    pub refresh: Option<RefreshTimes>,
    /// The latest labels are being spread over the frames ([`TrainEvent::Spreading`]).
    pub spreading: bool,
    /// The labels the field trains on, once any were given.
    pub spread: Option<Spread>,
}

/// What [`Training::poll`] hands the page to act on.
#[derive(Default)]
pub struct Delivered {
    pub rendered: Option<Box<Rendered>>,
    pub exported: Option<Result<Vec<u8>, TrainError>>,
}

/// Handle to the training task of one scene. Dropping it stops the task (its command channel
/// closes), which drops the trainer's GPU buffers.
pub struct Training {
    commands: UnboundedSender<TrainCommand>,
    events: UnboundedReceiver<TrainEvent>,
    reports: Reports,
    paused: bool,
    visible_frame: u32,
    pub config: FieldConfig,
    pub factor: u32,
}

impl Training {
    /// Starts training on `ctx` (eframe's device) with `labels` (may be empty, drawn on the
    /// full-resolution frames), showing `visible_frame` first.
    pub fn start(
        ctx: GpuContext,
        setup: TrainingSetup,
        labels: &LabelSet,
        visible_frame: u32,
        egui_ctx: egui::Context,
    ) -> Training {
        let (commands, command_rx) = unbounded();
        let (event_tx, events) = unbounded();
        let training = Training {
            commands,
            events,
            reports: Reports {
                phase: Phase::Starting,
                progress: Progress {
                    batch: 1,
                    ..Progress::default()
                },
                render_ms: 0.0,
                refresh: None,
                spreading: false,
                spread: None,
            },
            paused: false,
            visible_frame,
            config: setup.config.clone(),
            factor: setup.factor,
        };
        // The scene carries no labels (see `scene::downscale`): they are handed over like any
        // later edit.
        training.set_labels(0, labels);
        let task = task::TrainingTask::new(ctx, setup, visible_frame, command_rx, event_tx, egui_ctx);
        wasm_bindgen_futures::spawn_local(task.run());
        training
    }

    fn send(&self, command: TrainCommand) {
        // Fails only when the task has ended (after a failure); then nobody listens.
        let _ = self.commands.unbounded_send(command);
    }

    /// Takes the task's events: the numbers go to [`Training::reports`], a render and an
    /// export's zip are handed back.
    pub fn poll(&mut self) -> Delivered {
        let mut delivered = Delivered::default();
        while let Ok(event) = self.events.try_recv() {
            match event {
                TrainEvent::Phase(phase) => self.reports.phase = phase,
                TrainEvent::Progress(p) => self.reports.progress = p,
                TrainEvent::Rendered(r) => delivered.rendered = Some(r),
                TrainEvent::RenderTime(ms) => self.reports.render_ms = ms,
                TrainEvent::Refresh(r) => self.reports.refresh = Some(r),
                TrainEvent::Spreading(on) => self.reports.spreading = on,
                TrainEvent::Spread(spread) => self.reports.spread = Some(spread),
                TrainEvent::Exported(zip) => delivered.exported = Some(zip),
                TrainEvent::Profile(text) => {
                    web_sys::console::log_1(&format!("scribblefield profile: {text}").into());
                    super::page_status::set_profile(&text);
                }
            }
        }
        if delivered.rendered.is_some() {
            self.send(TrainCommand::RenderTaken);
        }
        delivered
    }

    pub fn reports(&self) -> &Reports {
        &self.reports
    }

    pub fn paused(&self) -> bool {
        self.paused
    }

    pub fn toggle_pause(&mut self) {
        self.paused = !self.paused;
        self.send(TrainCommand::SetPaused(self.paused));
    }

    /// Hands the task labels to train on from now on.
    pub fn set_labels(&self, version: u64, labels: &LabelSet) {
        // No render now: the field has not learnt anything from them yet; the task refreshes
        // the mask after a batch of training with them.
        self.send(TrainCommand::SetLabels {
            version,
            labels: scale_labels(labels, self.factor as f32),
            requested_ms: now_ms(),
        });
    }

    /// The user is drawing or pressing keys: hold the GPU for the UI a moment.
    pub fn user_active(&self, for_ms: f64) {
        self.send(TrainCommand::UserActive {
            until_ms: now_ms() + for_ms,
        });
    }

    pub fn show_frame(&mut self, frame: u32) {
        if self.visible_frame != frame {
            self.visible_frame = frame;
            self.send(TrainCommand::ShowFrame {
                frame,
                requested_ms: now_ms(),
            });
        }
    }

    /// Asks for the masks of every frame; the zip comes back from [`Training::poll`].
    pub fn export(&self, labels: &LabelSet, options: &ExportOptions) {
        // The download carries the labels as drawn (full resolution); the task only needs their
        // classes.
        self.send(TrainCommand::Export(labels.clone(), options.clone()));
    }
}
