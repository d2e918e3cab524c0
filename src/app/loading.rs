//! Getting a scene into the page: which URL (the page's `#scene=` fragment or the demo next to
//! the page), a streamed fetch that reports progress, or a file the user picked or dropped;
//! then decoding.
//!
//! Decoding runs on the page's only thread, a slice at a time: frames are decoded for about
//! [`DECODE_SLICE_MS`], then the task yields to the browser (which paints the progress bar and
//! answers input) before the next slice. Feature codes and labels are read in one piece at the
//! end.
use std::cell::RefCell;
use std::rc::Rc;

use wasm_bindgen::JsCast;
use wasm_bindgen::prelude::*;
use wasm_bindgen_futures::JsFuture;

use super::browser::{js_error_text, now_ms, sleep_ms};
use super::page_options::PageOptions;
use crate::scene::archive::ArchiveReader;
use crate::scene::{Scene, SceneError};

/// Loaded when the page names no scene.
pub const DEFAULT_SCENE_URL: &str = "demo.scene.zip";

/// Largest archive the page will download. wasm32 memory ends at 4 GiB and the decoded scene
/// takes several times the archive's size, so more than this cannot be opened anyway.
pub const MAX_ARCHIVE_BYTES: u64 = 1 << 30;

/// Decoding works this long between yields to the browser (a frame at 30 fps is 33 ms).
pub const DECODE_SLICE_MS: f64 = 25.0;

/// The scene to load: the page's `#scene=<url>` option, else [`DEFAULT_SCENE_URL`]. A
/// relative URL is relative to the page.
pub fn scene_url(options: &PageOptions) -> String {
    options.scene.clone().unwrap_or_else(|| DEFAULT_SCENE_URL.to_string())
}

/// Why a scene could not be loaded; each message names the URL.
#[derive(Debug, thiserror::Error)]
pub enum LoadError {
    #[error(
        "{url}: cannot fetch ({detail}). The server may be unreachable, or it does not allow \
         this page to read the file (CORS)"
    )]
    Network { url: String, detail: String },
    #[error("{url}: the server answered HTTP {status} {status_text}")]
    Http {
        url: String,
        status: u16,
        status_text: String,
    },
    #[error("{url}: the server sent an HTML page, not a scene archive (is the URL right?)")]
    Html { url: String },
    #[error("{url}: {bytes} bytes is more than this page can hold ({MAX_ARCHIVE_BYTES} bytes at most)")]
    TooLarge { url: String, bytes: u64 },
    #[error("{url}: the download broke off after {received} bytes: {detail}")]
    Interrupted { url: String, received: u64, detail: String },
    #[error(transparent)]
    Scene(#[from] SceneError),
}

/// A decoded scene and its archive's content id (what its saved annotations are keyed by).
#[derive(Debug)]
pub struct Loaded {
    pub scene: Box<Scene>,
    pub content_id: String,
}

/// Where a load stands; the UI draws it.
#[derive(Debug)]
pub enum LoadPhase {
    Connecting,
    /// `total` is the Content-Length when the server sent one (compressed size if encoded).
    Downloading {
        received: u64,
        total: Option<u64>,
    },
    /// `frames` is 0 until the manifest has been read.
    Decoding {
        bytes: u64,
        done: usize,
        frames: usize,
    },
    Finished(Result<Loaded, LoadError>),
    /// The result has been handed to the app.
    Taken,
}

/// A scene load running in the background of the page.
pub struct SceneLoad {
    url: String,
    phase: Rc<RefCell<LoadPhase>>,
}

impl SceneLoad {
    /// Starts fetching `url`; `ctx` is asked to repaint whenever there is progress to show.
    /// Progress asks for a repaint at most every `repaint_ms`.
    pub fn start(url: String, ctx: egui::Context, repaint_ms: u64) -> SceneLoad {
        let phase = Rc::new(RefCell::new(LoadPhase::Connecting));
        let task_phase = phase.clone();
        let task_url = url.clone();
        wasm_bindgen_futures::spawn_local(async move {
            let result = load(&task_url, &task_phase, &ctx, repaint_ms).await;
            *task_phase.borrow_mut() = LoadPhase::Finished(result);
            ctx.request_repaint();
        });
        SceneLoad { url, phase }
    }

    /// Decodes a scene archive the user picked or dropped (`name` is the file name).
    pub fn from_bytes(name: String, bytes: Vec<u8>, ctx: egui::Context, repaint_ms: u64) -> SceneLoad {
        let phase = Rc::new(RefCell::new(LoadPhase::Decoding {
            bytes: bytes.len() as u64,
            done: 0,
            frames: 0,
        }));
        let task_phase = phase.clone();
        let task_name = name.clone();
        wasm_bindgen_futures::spawn_local(async move {
            let result = if bytes.len() as u64 > MAX_ARCHIVE_BYTES {
                Err(LoadError::TooLarge {
                    url: task_name,
                    bytes: bytes.len() as u64,
                })
            } else {
                decode(bytes, &task_name, &task_phase, &ctx, repaint_ms).await
            };
            *task_phase.borrow_mut() = LoadPhase::Finished(result);
            ctx.request_repaint();
        });
        SceneLoad { url: name, phase }
    }

    /// The URL, or the file name of a local archive.
    pub fn url(&self) -> &str {
        &self.url
    }

    /// Runs `f` on the current phase (the phase stays shared with the loading task).
    pub fn with_phase<R>(&self, f: impl FnOnce(&LoadPhase) -> R) -> R {
        f(&self.phase.borrow())
    }

    /// The outcome, once: later calls return `None`.
    pub fn take_result(&self) -> Option<Result<Loaded, LoadError>> {
        let mut phase = self.phase.borrow_mut();
        if !matches!(*phase, LoadPhase::Finished(_)) {
            return None;
        }
        match std::mem::replace(&mut *phase, LoadPhase::Taken) {
            LoadPhase::Finished(result) => Some(result),
            _ => None,
        }
    }
}

async fn load(
    url: &str,
    phase: &RefCell<LoadPhase>,
    ctx: &egui::Context,
    repaint_ms: u64,
) -> Result<Loaded, LoadError> {
    let bytes = download(url, phase, ctx, repaint_ms).await?;
    let name = url.rsplit('/').next().filter(|n| !n.is_empty()).unwrap_or(url);
    decode(bytes, name, phase, ctx, repaint_ms).await
}

/// Decodes an archive a slice of frames at a time, yielding to the browser between slices so
/// the page keeps painting (the progress bar moves) and answering input.
async fn decode(
    bytes: Vec<u8>,
    name: &str,
    phase: &RefCell<LoadPhase>,
    ctx: &egui::Context,
    repaint_ms: u64,
) -> Result<Loaded, LoadError> {
    let total = bytes.len() as u64;
    let show = |done: usize, frames: usize| {
        *phase.borrow_mut() = LoadPhase::Decoding {
            bytes: total,
            done,
            frames,
        };
        // A repaint per slice would cost more than the slice on a CPU rasterizer.
        ctx.request_repaint_after(std::time::Duration::from_millis(repaint_ms));
    };
    show(0, 0);
    ctx.request_repaint();
    // Let the page paint "decoding" first.
    sleep_ms(0).await;
    let mut reader = ArchiveReader::new(std::io::Cursor::new(bytes), name)?;
    let content_id = reader.content_id().to_string();
    let frames = reader.frame_count();
    loop {
        let slice_start = now_ms();
        let mut more = true;
        while more && now_ms() - slice_start < DECODE_SLICE_MS {
            more = reader.decode_next_frame()?;
        }
        show(reader.frames_done(), frames);
        if !more {
            break;
        }
        sleep_ms(0).await;
    }
    let scene = reader.finish()?;
    Ok(Loaded {
        scene: Box::new(scene),
        content_id,
    })
}

async fn download(
    url: &str,
    phase: &RefCell<LoadPhase>,
    ctx: &egui::Context,
    repaint_ms: u64,
) -> Result<Vec<u8>, LoadError> {
    let network = |e: JsValue| LoadError::Network {
        url: url.into(),
        detail: js_error_text(&e),
    };
    let window = web_sys::window().ok_or_else(|| network(JsValue::from_str("no window")))?;
    let response: web_sys::Response = JsFuture::from(window.fetch_with_str(url))
        .await
        .map_err(network)?
        .unchecked_into();
    if !response.ok() {
        return Err(LoadError::Http {
            url: url.into(),
            status: response.status(),
            status_text: response.status_text(),
        });
    }
    let headers = response.headers();
    let content_type = headers.get("content-type").ok().flatten().unwrap_or_default();
    if content_type.to_ascii_lowercase().starts_with("text/html") {
        return Err(LoadError::Html { url: url.into() });
    }
    let total = headers
        .get("content-length")
        .ok()
        .flatten()
        .and_then(|v| v.trim().parse::<u64>().ok());
    if let Some(bytes) = total.filter(|&t| t > MAX_ARCHIVE_BYTES) {
        return Err(LoadError::TooLarge { url: url.into(), bytes });
    }
    *phase.borrow_mut() = LoadPhase::Downloading { received: 0, total };
    ctx.request_repaint();

    let mut bytes = Vec::with_capacity(total.unwrap_or(0) as usize);
    let Some(body) = response.body() else { return Ok(bytes) };
    let reader = web_sys::ReadableStreamDefaultReader::new(&body).map_err(network)?;
    let interrupted = |received: usize, e: JsValue| LoadError::Interrupted {
        url: url.into(),
        received: received as u64,
        detail: js_error_text(&e),
    };
    loop {
        let chunk: web_sys::ReadableStreamReadResult = JsFuture::from(reader.read())
            .await
            .map_err(|e| interrupted(bytes.len(), e))?
            .unchecked_into();
        if chunk.get_done().unwrap_or(false) {
            break;
        }
        let data: js_sys::Uint8Array = chunk.get_value().unchecked_into();
        let received = bytes.len() as u64 + data.length() as u64;
        if received > MAX_ARCHIVE_BYTES {
            let _ = reader.cancel();
            return Err(LoadError::TooLarge {
                url: url.into(),
                bytes: received,
            });
        }
        let start = bytes.len();
        bytes.resize(start + data.length() as usize, 0);
        data.copy_to(&mut bytes[start..]);
        *phase.borrow_mut() = LoadPhase::Downloading { received, total };
        ctx.request_repaint_after(std::time::Duration::from_millis(repaint_ms));
    }
    Ok(bytes)
}
