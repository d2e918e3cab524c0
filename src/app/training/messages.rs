//! What the page and its training task say to each other: [`TrainCommand`]s go to the task,
//! [`TrainEvent`]s come back, each over its own channel. Neither side holds the other's state.
use crate::export::{ExportError, ExportOptions};
use crate::field::gpu::trainer::{RenderedFrame, StepLosses};
use crate::gpu::GpuError;
use crate::labels::LabelSet;

/// From the page to the training task. The task applies every queued command at the top of
/// each turn, before it decides what to do next; dropping the sender stops the task.
pub enum TrainCommand {
    /// Train on these labels from now on (`version` is bumped by every edit; the labels are
    /// already scaled to the training resolution). `requested_ms` is when (page clock).
    SetLabels {
        version: u64,
        labels: LabelSet,
        requested_ms: f64,
    },
    /// The visible frame changed: render it as soon as possible.
    ShowFrame {
        frame: u32,
        requested_ms: f64,
    },
    /// The user is at work until then (page clock, ms): training waits so that the UI's frames
    /// are not queued behind training work (on a slow GPU one step outlasts a frame).
    UserActive {
        until_ms: f64,
    },
    SetPaused(bool),
    /// Render every frame into a masks zip with these labels (as drawn, full resolution) and
    /// these formats.
    Export(LabelSet, ExportOptions),
    /// The page has taken the latest [`TrainEvent::Rendered`]: the next periodic render may
    /// follow. A hidden tab draws no frames, so renders would otherwise pile up in the queue.
    RenderTaken,
}

/// From the training task to the page.
pub enum TrainEvent {
    Phase(Phase),
    /// After every batch of steps.
    Progress(Progress),
    Rendered(Box<Rendered>),
    /// How long the latest full render took, ms.
    RenderTime(f64),
    /// The latest refresh of the visible mask, as it goes.
    Refresh(RefreshTimes),
    /// The masks zip, once an export is done.
    Exported(Result<Vec<u8>, TrainError>),
    /// The strokes are being spread over the frames (`true`), or that is done (`false`): on a
    /// large capture with sparse depth it takes seconds, in slices that leave the page drawing,
    /// and the field does not train meanwhile. Sent only when spreading outlasts one slice.
    Spreading(bool),
    /// What the field now trains on: labelled pixels (strokes and where they spread) and the
    /// frames holding them, after every change of labels.
    Spread(Spread),
    /// The wall-clock profile (`#profile` in the address), once measured.
    Profile(String),
}

/// Where the training stands.
#[derive(Debug)]
pub enum Phase {
    /// Uploading the scene and building the kernels.
    Starting,
    Running,
    /// Rendering every frame for the download: `done` of `total`.
    Exporting {
        done: u32,
        total: u32,
    },
    /// Stopped for good: lost device, out of memory, a bug.
    Failed(TrainError),
}

/// The labels the field trains on ([`TrainEvent::Spread`]).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Spread {
    pub pixels: usize,
    pub frames: usize,
    /// What the spread's self-check found (`spread::check`), and whether it withheld
    /// spreading.
    pub check: Option<crate::spread::check::SpreadCheck>,
    pub withheld: bool,
}

/// Numbers from the latest batch of steps.
#[derive(Clone, Copy, Debug, Default)]
pub struct Progress {
    pub steps: u32,
    pub steps_per_second: f64,
    pub losses: Option<StepLosses>,
    /// Steps per batch as adapted.
    pub batch: u32,
    /// Per step of the batch: recording and submitting, then waiting for the GPU.
    pub step_submit_ms: f64,
    pub step_wait_ms: f64,
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
    /// Whether the field had any labelled pixel to train its classes on: before the first
    /// stroke the semantic head's classes are its random start, not a mask to show.
    pub labelled: bool,
}

/// How long the latest refresh of the visible mask took, from the request (a frame shown, or
/// labels handed over) to the first mask shown and to the full-resolution one.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RefreshTimes {
    pub first_ms: f64,
    pub full_ms: Option<f64>,
}

/// Why training stopped, or an export failed.
#[derive(Debug, thiserror::Error)]
pub enum TrainError {
    #[error("cannot start training: {0}")]
    Start(#[source] GpuError),
    #[error("cannot build the mask refinement: {0}")]
    RefineKernel(#[source] GpuError),
    #[error("profiling failed: {0}")]
    Profile(#[source] Box<TrainError>),
    #[error("cannot upload the labels: {0}")]
    Labels(#[source] GpuError),
    #[error("frame {0} is not in the scene")]
    NoSuchFrame(u32),
    #[error("rendering frame {frame} failed: {source}")]
    Render { frame: u32, source: GpuError },
    #[error("refining frame {frame} failed: {source}")]
    Refine { frame: u32, source: GpuError },
    #[error("reading the losses failed: {0}")]
    Losses(#[source] GpuError),
    #[error("frame {0}: the rendered class map has the wrong size")]
    MaskSize(u32),
    /// The device reported a loss or an uncaptured error (the message says which).
    #[error("{0}")]
    Device(String),
    /// The export's options or masks cannot be written (the message says which and why).
    #[error("{0}")]
    Export(#[source] ExportError),
    /// The page went away during an export.
    #[error("stopped")]
    Stopped,
}
