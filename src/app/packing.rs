//! Packing a capture in the page: the files of a folder the user picked or dropped (or of a zip
//! of one) are read into memory, then packed exactly as `scribblefield pack` would
//! (`features::pack`: the same importers and their errors, the weight-free baseline features and
//! their autoencoder, the same archive writer). The archive is then opened like any other.
//!
//! It all runs on the page's one thread, so the packing future pauses after every frame, every
//! frame's features and every autoencoder step, and gives the thread back once it has held it
//! for [`SLICE_MS`] (the training task's rule, `training/task.rs`): the page keeps painting the
//! progress and answering the Cancel button. Cancelling drops the future at its next pause.
use std::cell::{Cell, RefCell};
use std::future::{Future, poll_fn};
use std::pin::pin;
use std::rc::Rc;
use std::task::Poll;

use wasm_bindgen_futures::JsFuture;

use super::browser::{js_error_text, now_ms, sleep_ms};
use super::page_options::PageOptions;
use crate::features::BakeProgress;
use crate::features::pack::{
    BaselineFeatures, PackError, PackEstimate, PackOptions, PackProgress, PackSeconds, Packed, is_capture_file,
    pack_files,
};
use crate::pause::Pause;
use crate::scene::import::{ImportOptions, MAX_CAPTURE_BYTES, MemoryFiles};

mod setup;
pub use setup::{PackSetup, PackStart, SetupOutcome, estimate_json, set_body_attribute};

/// Packing holds the thread this long before giving it back.
const SLICE_MS: f64 = 12.0;

/// The page's packing defaults (`#pack-size=` and the other `pack-` options change them).
/// Longest side 640: the page trains at most at about 640 x 480 on a GPU, and less on a CPU
/// rasterizer, so larger frames would only make the archive and the decoding slower.
pub const DEFAULT_MAX_SIZE: u32 = 640;
/// A feature cell per 8 x 8 pixels, as `pack --features baseline` (its `--feature-stride`).
pub const DEFAULT_FEATURE_STRIDE: u32 = 8;
/// Fewer steps than the command line's 3000: the page fits on one core, without SIMD kernels.
pub const DEFAULT_AUTOENCODER_STEPS: u32 = 1000;

/// Photo captures without depth (COLMAP, transforms.json) pack at longest side 200 with a feature
/// cell per 2 x 2 pixels (100 x 100 cells), as the quality runs pack them: the shared photo
/// capture's masks were better at 200 than at 400 (mean IoU 0.919 against 0.902 over three
/// scribble sets, docs/quality.md), and a frame of 200 x 200 renders its live mask about 8x
/// faster than one of 640 x 480.
pub const PHOTO_CAPTURE_MAX_SIZE: u32 = 200;
pub const PHOTO_CAPTURE_FEATURE_STRIDE: u32 = 2;

/// What the `pack-` page options ask for, with the page's defaults for a capture with depth
/// images (`dense_depth`) or without.
pub fn pack_options(options: &PageOptions, dense_depth: bool) -> PackOptions {
    let (max_size, stride) = if dense_depth {
        (DEFAULT_MAX_SIZE, DEFAULT_FEATURE_STRIDE)
    } else {
        (PHOTO_CAPTURE_MAX_SIZE, PHOTO_CAPTURE_FEATURE_STRIDE)
    };
    let stride = options.pack_stride.unwrap_or(stride);
    PackOptions {
        import: ImportOptions {
            max_size: Some(options.pack_size.unwrap_or(max_size)),
            every: options.pack_every.unwrap_or(1),
            max_frames: options.pack_frames,
            ..ImportOptions::default()
        },
        features: (stride > 0).then_some(BaselineFeatures {
            stride,
            autoencoder_steps: options.pack_steps.unwrap_or(DEFAULT_AUTOENCODER_STEPS),
        }),
    }
}

/// Where a pack stands; the page draws it.
pub enum PackPhase {
    /// Copying the chosen files into the page (`bytes` so far).
    Reading {
        done: usize,
        total: usize,
        bytes: u64,
    },
    Packing(PackProgress),
    Finished(Result<Packed, PackError>),
    Cancelled,
    /// The result has been handed to the page.
    Taken,
}

/// A capture being packed in the background of the page.
pub struct ScenePack {
    /// The capture's name (its folder, or the zip's name).
    name: String,
    phase: Rc<RefCell<PackPhase>>,
    cancel: Rc<Cell<bool>>,
    /// When each stage began (`now_ms`), the last entry being the end: the measured time per
    /// stage, to compare with the estimate.
    stages: Rc<RefCell<Vec<(&'static str, f64)>>>,
    /// What the settings form estimated, when it did.
    estimate: Option<PackEstimate>,
    /// The page's wasm memory when packing started (it only ever grows).
    memory_before: u64,
}

/// Where the capture's files come from.
pub enum CaptureInput {
    /// Files the browser handed over (a folder picked or dropped), with their paths relative to
    /// the folder's parent (`capture/images/0001.jpg`).
    Files(Vec<(String, web_sys::File)>),
    /// A zip of a capture, already in memory.
    Zip { name: String, bytes: Vec<u8> },
}

impl ScenePack {
    pub fn start(
        name: String,
        input: CaptureInput,
        opts: PackOptions,
        estimate: Option<PackEstimate>,
        ctx: egui::Context,
        repaint_ms: u64,
    ) -> ScenePack {
        let phase = Rc::new(RefCell::new(PackPhase::Reading {
            done: 0,
            total: 0,
            bytes: 0,
        }));
        let cancel = Rc::new(Cell::new(false));
        let stages = Rc::new(RefCell::new(vec![("reading", now_ms())]));
        let (task_phase, task_cancel, task_stages) = (phase.clone(), cancel.clone(), stages.clone());
        wasm_bindgen_futures::spawn_local(async move {
            let work = pack(input, &opts, &task_phase, &task_stages, &ctx, repaint_ms);
            let outcome = until_cancelled(work, &task_cancel).await;
            task_stages.borrow_mut().push(("end", now_ms()));
            *task_phase.borrow_mut() = match outcome {
                Some(result) => PackPhase::Finished(result),
                None => PackPhase::Cancelled,
            };
            ctx.request_repaint();
        });
        ScenePack {
            name,
            phase,
            cancel,
            stages,
            estimate,
            memory_before: wasm_memory_bytes(),
        }
    }

    /// How much the page's wasm memory grew while packing: what packing needed beyond what the
    /// page had (memory freed before is used again first, so this is at most the peak).
    pub fn memory_growth(&self) -> u64 {
        wasm_memory_bytes().saturating_sub(self.memory_before)
    }

    pub fn estimate(&self) -> Option<&PackEstimate> {
        self.estimate.as_ref()
    }

    /// Seconds spent in each stage so far (the autoencoder's includes encoding the codes).
    pub fn measured(&self) -> PackSeconds {
        let mut s = PackSeconds::default();
        for pair in self.stages.borrow().windows(2) {
            let ((stage, from), (_, to)) = (pair[0], pair[1]);
            let secs = (to - from) / 1e3;
            match stage {
                "reading" => s.reading += secs,
                "frames" => s.frames += secs,
                "features" => s.features += secs,
                "autoencoder" | "encoding" => s.autoencoder += secs,
                _ => s.writing += secs,
            }
        }
        s
    }

    pub fn name(&self) -> &str {
        &self.name
    }

    /// Stops packing at its next pause (within one frame's work).
    pub fn cancel(&self) {
        self.cancel.set(true);
    }

    pub fn cancelling(&self) -> bool {
        self.cancel.get()
    }

    pub fn with_phase<R>(&self, f: impl FnOnce(&PackPhase) -> R) -> R {
        f(&self.phase.borrow())
    }

    /// The outcome, once (`None` while packing, and after): `Some(None)` when cancelled.
    pub fn take_result(&self) -> Option<Option<Result<Packed, PackError>>> {
        let mut phase = self.phase.borrow_mut();
        if !matches!(*phase, PackPhase::Finished(_) | PackPhase::Cancelled) {
            return None;
        }
        match std::mem::replace(&mut *phase, PackPhase::Taken) {
            PackPhase::Finished(result) => Some(Some(result)),
            _ => Some(None),
        }
    }
}

/// Runs `work` until it ends or `cancel` is set; a cancelled `work` is dropped where it paused.
async fn until_cancelled<T>(work: impl Future<Output = T>, cancel: &Cell<bool>) -> Option<T> {
    let mut work = pin!(work);
    poll_fn(|cx| {
        if cancel.get() {
            return Poll::Ready(None);
        }
        work.as_mut().poll(cx).map(Some)
    })
    .await
}

/// Gives the thread back once a slice of time is used up.
struct Slices {
    since_ms: f64,
}

impl Pause for Slices {
    async fn pause(&mut self) {
        if now_ms() - self.since_ms < SLICE_MS {
            return;
        }
        sleep_ms(0).await;
        self.since_ms = now_ms();
    }
}

async fn pack(
    input: CaptureInput,
    opts: &PackOptions,
    phase: &RefCell<PackPhase>,
    stages: &RefCell<Vec<(&'static str, f64)>>,
    ctx: &egui::Context,
    repaint_ms: u64,
) -> Result<Packed, PackError> {
    let show = |p: PackPhase| {
        let (key, _, _) = stage(&p);
        let key = match p {
            PackPhase::Packing(PackProgress::Features(BakeProgress::Encoding)) => "encoding",
            _ => key,
        };
        let mut stages = stages.borrow_mut();
        if stages.last().is_none_or(|&(last, _)| last != key) {
            stages.push((key, now_ms()));
        }
        drop(stages);
        *phase.borrow_mut() = p;
        // A repaint per frame would cost more than the frame on a CPU rasterizer.
        ctx.request_repaint_after(std::time::Duration::from_millis(repaint_ms));
    };
    let files = match input {
        CaptureInput::Files(list) => read_files(list, &show).await?,
        CaptureInput::Zip { name, bytes } => MemoryFiles::from_zip(&name, &bytes)?,
    };
    show(PackPhase::Packing(PackProgress::Importing { done: 0, total: 0 }));
    let mut slices = Slices { since_ms: now_ms() };
    // Let the page paint "packing" first.
    sleep_ms(0).await;
    pack_files(Rc::new(files), opts, |p| show(PackPhase::Packing(p)), &mut slices).await
}

/// Copies the capture's files into memory, one at a time so the bar moves, skipping files no
/// importer reads.
async fn read_files(list: Vec<(String, web_sys::File)>, show: &impl Fn(PackPhase)) -> Result<MemoryFiles, PackError> {
    let wanted: Vec<(String, web_sys::File)> = list.into_iter().filter(|(path, _)| is_capture_file(path)).collect();
    let declared: f64 = wanted.iter().map(|(_, f)| f.size()).sum();
    if declared > MAX_CAPTURE_BYTES as f64 {
        let root = wanted
            .first()
            .map_or("the folder", |(p, _)| p.split('/').next().unwrap_or(p));
        return Err(crate::scene::SceneError::invalid(
            root,
            format!(
                "its images and model files are {} bytes, more than this page packs ({MAX_CAPTURE_BYTES} bytes at most); \
                 pack it with the command line (`scribblefield pack`), or pick fewer frames",
                declared as u64
            ),
        )
        .into());
    }
    let total = wanted.len();
    let mut files = MemoryFiles::new();
    for (done, (path, file)) in wanted.into_iter().enumerate() {
        let buffer = JsFuture::from(file.array_buffer())
            .await
            .map_err(|e| crate::scene::SceneError::invalid(&path, format!("cannot read: {}", js_error_text(&e))))?;
        files.add(&path, js_sys::Uint8Array::new(&buffer).to_vec())?;
        show(PackPhase::Reading {
            done: done + 1,
            total,
            bytes: files.bytes(),
        });
    }
    Ok(files)
}

/// Whether a zip holds a scene archive (`scene.json` at its top) rather than a capture.
pub fn is_scene_archive(bytes: &[u8]) -> bool {
    zip::ZipArchive::new(std::io::Cursor::new(bytes))
        .is_ok_and(|z| z.index_for_name(crate::scene::manifest::MANIFEST_FILE).is_some())
}

/// The stage for `data-status` (`reading`, `frames`, `features`, `autoencoder`, `writing`),
/// with its progress (`done` of `total`).
pub fn stage(phase: &PackPhase) -> (&'static str, usize, usize) {
    match *phase {
        PackPhase::Reading { done, total, .. } => ("reading", done, total),
        PackPhase::Packing(PackProgress::Importing { done, total }) => ("frames", done, total),
        PackPhase::Packing(PackProgress::Features(BakeProgress::Extracting { done, total })) => {
            ("features", done, total)
        }
        PackPhase::Packing(PackProgress::Features(BakeProgress::Fitting { step, steps, .. })) => {
            ("autoencoder", step as usize, steps as usize)
        }
        PackPhase::Packing(PackProgress::Features(BakeProgress::Encoding)) => ("features", 0, 0),
        PackPhase::Packing(PackProgress::Writing) => ("writing", 0, 0),
        PackPhase::Finished(_) | PackPhase::Cancelled | PackPhase::Taken => ("writing", 0, 0),
    }
}

/// One line for the progress bar, and the fraction done when known.
pub fn describe(name: &str, phase: &PackPhase) -> (String, Option<f32>) {
    let frac = |done: usize, total: usize| (total > 0).then(|| done as f32 / total as f32);
    match *phase {
        PackPhase::Reading { done, total, bytes } => (
            format!("Reading {name}: file {done} of {total} ({:.1} MB)", bytes as f64 / 1e6),
            frac(done, total),
        ),
        PackPhase::Packing(PackProgress::Importing { done, total }) => {
            (format!("Packing {name}: frame {done} of {total}"), frac(done, total))
        }
        PackPhase::Packing(PackProgress::Features(BakeProgress::Extracting { done, total })) => (
            format!("Packing {name}: features of frame {done} of {total}"),
            frac(done, total),
        ),
        PackPhase::Packing(PackProgress::Features(BakeProgress::Fitting { step, steps, loss })) => (
            format!("Packing {name}: feature autoencoder, step {step} of {steps} (loss {loss:.3})"),
            frac(step as usize, steps as usize),
        ),
        PackPhase::Packing(PackProgress::Features(BakeProgress::Encoding)) => {
            (format!("Packing {name}: encoding the features"), Some(1.0))
        }
        PackPhase::Packing(PackProgress::Writing) => (format!("Packing {name}: writing the archive"), Some(1.0)),
        PackPhase::Finished(_) | PackPhase::Cancelled | PackPhase::Taken => (format!("Packed {name}"), Some(1.0)),
    }
}

/// Bytes of the page's wasm memory.
pub fn wasm_memory_bytes() -> u64 {
    let buffer = js_sys::Reflect::get(&wasm_bindgen::memory(), &"buffer".into()).unwrap_or_default();
    js_sys::Reflect::get(&buffer, &"byteLength".into())
        .ok()
        .and_then(|n| n.as_f64())
        .unwrap_or(0.0) as u64
}
