//! The page's app: loading a scene, then annotating it, or saying why it cannot.
use std::cell::RefCell;
use std::rc::Rc;

use egui::RichText;

use super::annotator::{Annotator, AnnotatorSetup};
use super::browser::FolderFiles;
use super::loading::{self, LoadPhase, Loaded, SceneLoad};
use super::packing::{self, CaptureInput, PackSetup, PackStart, ScenePack, SetupOutcome};
use super::page_options::{PageOptionError, PageOptions};
use super::status::PageStatus;
use super::store::{self, Opened};
use super::{browser, page_status, repaint_interval_ms};
use crate::field::{Preset, Runner};
use crate::gpu::GpuContext;
use crate::labels::autosave::SceneSource;
use crate::labels::snapshots::SceneShape;
use crate::scene::Scene;
use crate::scene::archive::limits::MAX_JSON_BYTES;

pub struct App {
    stage: Stage,
    /// Adapter and backend, for the scene panel (and for bug reports).
    gpu_name: String,
    /// eframe's device, shared with the trainer; `None` without WebGPU.
    gpu: Option<GpuContext>,
    model: Preset,
    /// The page's options, read once at the start.
    options: PageOptions,
    /// Values in the address that could not be used, for the first annotator to show.
    option_errors: Vec<PageOptionError>,
    /// Files read by async tasks (picker, drop), handled at the next frame.
    inbox: Rc<RefCell<Vec<Incoming>>>,
    /// The archive of the capture packed in this page, while its scene is the one open: *save
    /// scene archive* downloads it.
    packed: Option<PackedArchive>,
    /// The pack settings of a capture picked or dropped, shown over the page until the user
    /// starts packing or cancels.
    setup: Option<PackSetup>,
}

/// What the user handed the page.
enum Incoming {
    /// A file picked or dropped (an archive, a zip of a capture, or annotations).
    File {
        name: String,
        bytes: Result<Vec<u8>, String>,
    },
    /// A capture folder picked or dropped.
    Folder(Result<FolderFiles, String>),
}

struct PackedArchive {
    /// The file name to save it under (`<capture>.scene.zip`).
    file_name: String,
    bytes: Vec<u8>,
    /// What `pack` would have printed: warnings, choices, the features and the scene summary.
    report: String,
}

enum Stage {
    Loading {
        load: SceneLoad,
        source: SceneSource,
    },
    /// Decoded; its saved annotations are being read (`opened` is filled in when done).
    Opening {
        scene: Option<Box<Scene>>,
        source: SceneSource,
        opened: Rc<RefCell<Option<Opened>>>,
    },
    /// A capture being packed into an archive, which then opens like any other.
    Packing(ScenePack),
    Annotating(Box<Annotator>),
    Failed {
        /// What could not be done, naming the scene or capture.
        title: String,
        message: String,
    },
    /// Packing was cancelled; nothing is open.
    Cancelled {
        name: String,
    },
}

impl App {
    pub fn new(cc: &eframe::CreationContext<'_>, options: PageOptions, option_errors: Vec<PageOptionError>) -> App {
        let (gpu_name, gpu, default_model) = match &cc.wgpu_render_state {
            Some(rs) => {
                let info = rs.adapter.get_info();
                let name = format!(
                    "{} ({:?})",
                    if info.name.is_empty() {
                        "unnamed adapter"
                    } else {
                        &info.name
                    },
                    info.backend
                );
                let ctx = GpuContext::from_device(rs.device.clone(), rs.queue.clone());
                (name, Some(ctx), Preset::for_adapter(&info, Runner::Page).0)
            }
            None => ("none".into(), None, Preset::Small),
        };
        for e in &option_errors {
            web_sys::console::warn_1(&e.to_string().into());
        }
        let model = options.model.unwrap_or(default_model);
        let scene_url = loading::scene_url(&options);
        let source = SceneSource::Url(browser::absolute_url(&scene_url));
        let load = SceneLoad::start(scene_url, cc.egui_ctx.clone(), repaint_interval_ms(gpu.as_ref()));
        let inbox: Rc<RefCell<Vec<Incoming>>> = Rc::default();
        let (folder_inbox, ctx) = (inbox.clone(), cc.egui_ctx.clone());
        let installed = browser::on_capture_folder(move |files| {
            folder_inbox.borrow_mut().push(Incoming::Folder(files));
            ctx.request_repaint();
        });
        // Without the input (a page other than index.html) capture folders cannot be picked;
        // archives and capture zips still open.
        if let Err(e) = installed {
            web_sys::console::warn_1(&e.to_string().into());
        }
        App {
            stage: Stage::Loading { load, source },
            gpu_name,
            gpu,
            model,
            options,
            option_errors,
            inbox,
            packed: None,
            setup: None,
        }
    }

    fn repaint_ms(&self) -> u64 {
        repaint_interval_ms(self.gpu.as_ref())
    }

    /// Asks for a scene archive and opens it.
    fn pick_scene(&self, ctx: &egui::Context) {
        let inbox = self.inbox.clone();
        let ctx = ctx.clone();
        wasm_bindgen_futures::spawn_local(async move {
            let opened = match browser::pick_file(".zip,application/zip", loading::MAX_ARCHIVE_BYTES).await {
                Ok(Some((name, bytes))) => Incoming::File { name, bytes: Ok(bytes) },
                Ok(None) => return,
                Err(e) => Incoming::File {
                    name: "the chosen file".into(),
                    bytes: Err(e.to_string()),
                },
            };
            inbox.borrow_mut().push(opened);
            ctx.request_repaint();
        });
    }

    /// Reads files dropped on the page (browsers only hand them over asynchronously).
    fn take_dropped_files(&self, ctx: &egui::Context) {
        let dropped = ctx.input(|i| i.raw.dropped_files.clone());
        for file in dropped {
            let inbox = self.inbox.clone();
            let ctx = ctx.clone();
            wasm_bindgen_futures::spawn_local(async move {
                let name = file
                    .path()
                    .file_name()
                    .map(|n| n.to_string_lossy().into_owned())
                    .unwrap_or_else(|| "dropped file".into());
                // Checked before the browser copies the file into the page's memory.
                let limit = if name.to_ascii_lowercase().ends_with(".json") {
                    MAX_JSON_BYTES
                } else {
                    loading::MAX_ARCHIVE_BYTES
                };
                let too_large = file.web_file().and_then(|f| browser::check_file_size(f, limit).err());
                let bytes = match too_large {
                    Some(e) => Err(e.to_string()),
                    None => file.bytes_async().await,
                };
                inbox.borrow_mut().push(Incoming::File { name, bytes });
                ctx.request_repaint();
            });
        }
    }

    /// A picked or dropped file: annotations go to the annotator, a zip of a capture is packed,
    /// anything else is opened as a scene archive (which says clearly when it is not one). A
    /// picked or dropped folder is packed.
    fn open_files(&mut self, ctx: &egui::Context) {
        let incoming: Vec<Incoming> = self.inbox.borrow_mut().drain(..).collect();
        for item in incoming {
            let (name, bytes) = match item {
                Incoming::Folder(Ok(files)) => {
                    let name = files
                        .first()
                        .and_then(|(path, _)| path.split('/').next())
                        .unwrap_or("the folder")
                        .to_string();
                    self.offer_pack(name, CaptureInput::Files(files), ctx);
                    continue;
                }
                Incoming::Folder(Err(e)) => {
                    self.stage = Stage::Failed {
                        title: "Cannot read the dropped folder".into(),
                        message: e,
                    };
                    continue;
                }
                Incoming::File { name, bytes: Ok(b) } => (name, b),
                Incoming::File { name, bytes: Err(e) } => {
                    self.stage = Stage::Failed {
                        title: format!("Cannot open the scene {name}"),
                        message: format!("cannot read the file: {e}"),
                    };
                    continue;
                }
            };
            let is_labels = name.to_ascii_lowercase().ends_with(".json");
            if let (true, Stage::Annotating(a)) = (is_labels, &mut self.stage) {
                a.import_labels_bytes(&name, &bytes);
                continue;
            }
            // A zip without a scene.json at its top is a capture: pack it (a zip that is neither
            // is refused by the packer, which says what layouts it knows).
            if !is_labels && zip_magic(&bytes) && !packing::is_scene_archive(&bytes) {
                let capture = name.trim_end_matches(".zip").trim_end_matches(".ZIP").to_string();
                self.offer_pack(capture, CaptureInput::Zip { name, bytes }, ctx);
                continue;
            }
            let source = SceneSource::File {
                name: name.clone(),
                bytes: bytes.len() as u64,
            };
            self.packed = None;
            // The old scene's training stops when its annotator is dropped here.
            self.stage = Stage::Loading {
                load: SceneLoad::from_bytes(name, bytes, ctx.clone(), self.repaint_ms()),
                source,
            };
        }
    }

    /// Shows the pack settings of a capture (the `pack-` page options first) with an estimate;
    /// nothing changes until the user starts packing.
    fn offer_pack(&mut self, name: String, input: CaptureInput, ctx: &egui::Context) {
        self.setup = Some(PackSetup::new(name, input, &self.options, ctx));
    }

    /// The pack settings, while shown: *Start* packs, *Cancel* leaves the page as it was.
    fn show_setup(&mut self, ctx: &egui::Context) {
        let Some(setup) = &mut self.setup else {
            return;
        };
        match setup.show(ctx) {
            SetupOutcome::Open => return,
            SetupOutcome::Start(start) => {
                // The scene open until now closes (its training stops with its annotator).
                self.packed = None;
                let PackStart {
                    name,
                    input,
                    opts,
                    estimate,
                } = *start;
                let pack = ScenePack::start(name, input, opts, estimate, ctx.clone(), self.repaint_ms());
                self.stage = Stage::Packing(pack);
            }
            SetupOutcome::Cancel => {}
        }
        self.setup = None;
        packing::set_body_attribute("data-pack-setup", None);
    }
}

impl App {
    /// Moves on when a stage is done: a decoded scene has its saved annotations read, and
    /// then it is annotated.
    fn advance(&mut self, ctx: &egui::Context) {
        if let Stage::Packing(pack) = &self.stage
            && let Some(outcome) = pack.take_result()
        {
            let name = pack.name().to_string();
            let (measured, estimate, memory) = (pack.measured(), pack.estimate().cloned(), pack.memory_growth());
            self.stage = match outcome {
                None => Stage::Cancelled { name },
                Some(Err(e)) => Stage::Failed {
                    title: format!("Cannot pack the capture {name}"),
                    message: e.to_string(),
                },
                Some(Ok(packed)) => {
                    let file_name = format!("{name}.scene.zip");
                    let mut report: Vec<String> = packed.warnings.iter().map(|w| format!("warning: {w}")).collect();
                    report.extend(packed.report.iter().cloned());
                    report.extend(packed.features.iter().cloned());
                    report.push(format!("packed {name} ({:?} layout)", packed.layout));
                    report.push(packed.summary.trim_end().to_string());
                    report.push(format!(
                        "packed in {:.1} s (reading {:.1} s, frames {:.1} s, features {:.1} s, autoencoder {:.1} s, \
                         writing {:.1} s), archive {} bytes, the page's memory grew by {} bytes",
                        measured.total(),
                        measured.reading,
                        measured.frames,
                        measured.features,
                        measured.autoencoder,
                        measured.writing,
                        packed.archive.len(),
                        memory
                    ));
                    if let Some(e) = &estimate {
                        report.push(format!(
                            "estimated: {} frames, {:.1} s, archive {} bytes, memory {} bytes",
                            e.frames,
                            e.seconds.total(),
                            e.archive_bytes,
                            e.memory_bytes
                        ));
                    }
                    publish_pack_result(&measured, packed.archive.len(), memory, estimate.as_ref());
                    let report = report.join("\n");
                    web_sys::console::log_1(&report.clone().into());
                    let source = SceneSource::File {
                        name: file_name.clone(),
                        bytes: packed.archive.len() as u64,
                    };
                    // Opened exactly as if the user had opened the archive; the bytes stay for
                    // *save scene archive*.
                    let load = SceneLoad::from_bytes(
                        file_name.clone(),
                        packed.archive.clone(),
                        ctx.clone(),
                        self.repaint_ms(),
                    );
                    self.packed = Some(PackedArchive {
                        file_name,
                        bytes: packed.archive,
                        report,
                    });
                    Stage::Loading { load, source }
                }
            };
        }
        if let Stage::Loading { load, source } = &self.stage
            && let Some(result) = load.take_result()
        {
            self.stage = match result {
                Ok(Loaded { scene, content_id }) => {
                    let opened: Rc<RefCell<Option<Opened>>> = Rc::default();
                    let shape = SceneShape {
                        frames: scene.frames.len() as u32,
                        width: scene.width,
                        height: scene.height,
                    };
                    let (slot, source_for_task, ctx) = (opened.clone(), source.clone(), ctx.clone());
                    wasm_bindgen_futures::spawn_local(async move {
                        let o = store::open_scene(&content_id, &source_for_task, shape).await;
                        *slot.borrow_mut() = Some(o);
                        ctx.request_repaint();
                    });
                    Stage::Opening {
                        scene: Some(scene),
                        source: source.clone(),
                        opened,
                    }
                }
                Err(e) => Stage::Failed {
                    title: format!("Cannot open the scene {}", load.url()),
                    message: e.to_string(),
                },
            };
        }
        let taken = match &mut self.stage {
            Stage::Opening { scene, source, opened } => {
                let o = opened.borrow_mut().take();
                o.and_then(|o| Some((o, scene.take()?, source.clone())))
            }
            _ => None,
        };
        if let Some((o, scene, source)) = taken {
            let annotator = Annotator::new(
                ctx,
                scene,
                o,
                AnnotatorSetup {
                    source,
                    gpu: self.gpu.clone(),
                    model: self.model,
                    // A share link's labels are for the first scene the page opens.
                    options: PageOptions {
                        labels: self.options.labels.take(),
                        ..self.options.clone()
                    },
                    option_errors: std::mem::take(&mut self.option_errors),
                },
            );
            self.stage = Stage::Annotating(Box::new(annotator));
        }
    }
}

impl eframe::App for App {
    fn ui(&mut self, ui: &mut egui::Ui, _frame: &mut eframe::Frame) {
        let ctx = ui.ctx().clone();
        self.take_dropped_files(&ctx);
        self.open_files(&ctx);
        self.advance(&ctx);

        let mut pick = false;
        let mut pick_folder = false;
        let mut save_archive = false;
        egui::Panel::top("title").show(ui, |ui| {
            ui.horizontal(|ui| {
                ui.strong("scribblefield");
                ui.separator();
                pick = ui
                    .button("open scene…")
                    .on_hover_text(
                        "a .scene.zip archive, or a zip of a capture folder to pack; or drop one (or a labels.json) \
                         on the page",
                    )
                    .clicked();
                pick_folder = ui
                    .button("pack capture folder…")
                    .on_hover_text(
                        "a capture folder (COLMAP, transforms.json, NeRF splits, ScanNet, ARKitScenes, 7-Scenes, \
                         autolabel, Stray Scanner), packed here into a scene archive as `scribblefield pack` would; or drop the \
                         folder on the page",
                    )
                    .clicked();
                if let Stage::Annotating(a) = &self.stage {
                    ui.separator();
                    ui.label(RichText::new(a.source().describe()).monospace().small());
                    if let Some(p) = &self.packed {
                        save_archive = ui
                            .button("save scene archive")
                            .on_hover_text(format!(
                                "download {} ({:.1} MB), the archive packed from the capture, to host and share \
                                 (open it with #scene=<its url>); key A\n\n{}",
                                p.file_name,
                                p.bytes.len() as f64 / 1e6,
                                p.report
                            ))
                            .clicked();
                    }
                }
                ui.with_layout(egui::Layout::right_to_left(egui::Align::Center), |ui| {
                    ui.label(RichText::new(format!("model: {}", self.model.name())).small())
                        .on_hover_text("#model=tiny|small|budget|full in the address picks another");
                });
            });
        });
        // The page's own keys (the annotator reads its own, and none of these): Escape cancels
        // packing, A saves the packed archive; not while a text field has the keyboard.
        let (escape, save_key) = if ctx.egui_wants_keyboard_input() {
            (false, false)
        } else {
            ctx.input(|i| {
                let plain = !i.modifiers.command && !i.modifiers.alt;
                (i.key_pressed(egui::Key::Escape), plain && i.key_pressed(egui::Key::A))
            })
        };
        // With the pack settings open, Escape closes them (and leaves packing alone).
        if let (true, None, Stage::Packing(pack)) = (escape, &self.setup, &self.stage) {
            pack.cancel();
        }
        let save_archive = save_archive || (save_key && matches!(self.stage, Stage::Annotating(_)));
        if pick {
            self.pick_scene(&ctx);
        }
        if pick_folder && let Err(e) = browser::pick_capture_folder() {
            self.stage = Stage::Failed {
                title: "Cannot pick a capture folder".into(),
                message: e.to_string(),
            };
        }
        if save_archive
            && let Some(p) = &self.packed
            && let Err(e) = browser::download(&p.bytes, &p.file_name, "application/zip")
        {
            web_sys::console::error_1(&e.to_string().into());
        }
        match &mut self.stage {
            Stage::Loading { load, .. } => show_loading(ui, load),
            Stage::Packing(pack) => show_packing(ui, pack),
            Stage::Opening { .. } => show_opening(ui),
            Stage::Annotating(a) => a.show(ui, &self.gpu_name),
            Stage::Failed { title, message } => show_failure(ui, title, message),
            Stage::Cancelled { name } => show_cancelled(ui, name),
        }
        self.show_setup(&ctx);
        show_drop_hint(&ctx);
    }
}

/// While files are dragged over the page, say what dropping them does.
fn show_drop_hint(ctx: &egui::Context) {
    if ctx.input(|i| i.raw.hovered_files.is_empty()) {
        return;
    }
    let screen = ctx.content_rect();
    let painter = ctx.layer_painter(egui::LayerId::new(
        egui::Order::Foreground,
        egui::Id::unique("drop hint"),
    ));
    painter.rect_filled(screen, 0.0, egui::Color32::from_black_alpha(180));
    painter.text(
        screen.center(),
        egui::Align2::CENTER_CENTER,
        "Drop a scene archive (.zip) to open it, a capture folder (or a zip of one) to pack it, \
         or annotations (.json) to import them",
        egui::FontId::proportional(20.0),
        egui::Color32::WHITE,
    );
}

fn show_loading(ui: &mut egui::Ui, load: &SceneLoad) {
    let (status, text, fraction): (PageStatus, String, Option<f32>) = load.with_phase(|phase| match *phase {
        LoadPhase::Connecting => (PageStatus::Loading, format!("Connecting to {}", load.url()), None),
        LoadPhase::Downloading { received, total } => {
            let text = match total {
                Some(t) => format!(
                    "Downloading {}: {} of {}",
                    load.url(),
                    megabytes(received),
                    megabytes(t)
                ),
                None => format!("Downloading {}: {}", load.url(), megabytes(received)),
            };
            (
                PageStatus::Loading,
                text,
                total.filter(|&t| t > 0).map(|t| (received as f32 / t as f32).min(1.0)),
            )
        }
        LoadPhase::Decoding { bytes, done, frames } => (
            PageStatus::Decoding { done, frames },
            if frames > 0 {
                format!(
                    "Decoding {} ({}): frame {done} of {frames}",
                    load.url(),
                    megabytes(bytes)
                )
            } else {
                format!("Decoding {} ({})", load.url(), megabytes(bytes))
            },
            Some(if frames > 0 { done as f32 / frames as f32 } else { 0.0 }),
        ),
        LoadPhase::Finished(_) | LoadPhase::Taken => (PageStatus::Loading, "Opening the scene".into(), Some(1.0)),
    });
    page_status::set(&status);
    progress_panel(ui, text, fraction, |_| {});
}

/// A centred line of text over a progress bar (`fraction`, or a moving bar when unknown), then
/// whatever `below` adds.
fn progress_panel(ui: &mut egui::Ui, text: String, fraction: Option<f32>, below: impl FnOnce(&mut egui::Ui)) {
    egui::CentralPanel::default().show(ui, |ui| {
        ui.vertical_centered(|ui| {
            ui.add_space(ui.available_height() * 0.35);
            ui.label(RichText::new(text).size(16.0));
            ui.add_space(8.0);
            let bar = match fraction {
                Some(f) => egui::ProgressBar::new(f).show_percentage(),
                None => egui::ProgressBar::new(0.0).animate(true),
            };
            ui.add(bar.desired_width(ui.available_width().min(480.0)));
            below(ui);
        });
    });
}

fn show_packing(ui: &mut egui::Ui, pack: &ScenePack) {
    let (status, (text, fraction)) =
        pack.with_phase(|phase| (packing::stage(phase), packing::describe(pack.name(), phase)));
    page_status::set(&PageStatus::Packing {
        stage: status.0,
        done: status.1,
        total: status.2,
    });
    let mut cancel = false;
    progress_panel(ui, text, fraction, |ui| {
        ui.add_space(8.0);
        if pack.cancelling() {
            ui.label("cancelling…");
        } else {
            cancel = ui.button("Cancel").on_hover_text("Escape").clicked();
        }
    });
    if cancel {
        pack.cancel();
    }
}

fn show_cancelled(ui: &mut egui::Ui, name: &str) {
    page_status::set(&PageStatus::Cancelled);
    egui::CentralPanel::default().show(ui, |ui| {
        ui.vertical_centered(|ui| {
            ui.add_space(ui.available_height() * 0.35);
            ui.label(RichText::new(format!("Packing {name} was cancelled")).size(16.0));
            ui.add_space(8.0);
            ui.label("Open a scene or pack a capture folder with the buttons above, or drop one on the page.");
        });
    });
}

fn show_opening(ui: &mut egui::Ui) {
    page_status::set(&PageStatus::Loading);
    egui::CentralPanel::default().show(ui, |ui| {
        ui.vertical_centered(|ui| {
            ui.add_space(ui.available_height() * 0.35);
            ui.label(RichText::new("Reading the annotations saved in this browser").size(16.0));
        });
    });
}

fn show_failure(ui: &mut egui::Ui, title: &str, message: &str) {
    page_status::set(&PageStatus::Error {
        message: message.to_string(),
    });
    egui::CentralPanel::default().show(ui, |ui| {
        ui.vertical_centered(|ui| {
            ui.add_space(ui.available_height() * 0.3);
            ui.label(RichText::new(title).size(18.0).strong());
            ui.add_space(8.0);
            ui.label(RichText::new(message).color(ui.visuals().error_fg_color).monospace());
            ui.add_space(12.0);
            ui.label("Open a scene file with the button above or drop one on the page, or open the page");
            ui.label("with #scene=<url of a .scene.zip> in the address (without it: the demo scene).");
            ui.label("A capture folder packs here (pack capture folder…, or drop it), or with `scribblefield pack`.");
        });
    });
}

/// Whether `bytes` start as a zip does (a local file header).
fn zip_magic(bytes: &[u8]) -> bool {
    bytes.starts_with(b"PK\x03\x04")
}

fn megabytes(bytes: u64) -> String {
    format!("{:.1} MB", bytes as f64 / 1e6)
}

/// Puts how long packing took, stage by stage, and what the settings form estimated on
/// `<body data-pack-result="...">` for scripts (docs/web-app.md, "For scripts").
fn publish_pack_result(
    measured: &crate::features::pack::PackSeconds,
    archive_bytes: usize,
    memory_growth: u64,
    estimate: Option<&crate::features::pack::PackEstimate>,
) {
    let value = serde_json::json!({
        "seconds": measured.total(),
        "stages": {
            "reading": measured.reading, "frames": measured.frames, "features": measured.features,
            "autoencoder": measured.autoencoder, "writing": measured.writing,
        },
        "archive_bytes": archive_bytes,
        "memory_growth_bytes": memory_growth,
        "estimate": estimate.map(packing::estimate_json),
    });
    packing::set_body_attribute("data-pack-result", Some(&value.to_string()));
}
