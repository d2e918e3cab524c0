//! Annotating a loaded scene, in three parts: the [`Document`] (labels, undo history, saving),
//! the [`View`] (frame shown, zoom, layers, tool) and the [`TrainingControl`] (the handle to
//! the live training that turns the scribbles into masks). This module joins them: it turns
//! what the panels, keys and canvas report into edits and lets everything that follows the
//! labels know. The panels are drawn in `panels`, keys read in `keys`, the page status put
//! together in `status`.
mod document;
mod keys;
mod panels;
mod saving;
mod status;
mod training;
mod view;

use std::cell::RefCell;
use std::rc::Rc;

use egui::RichText;

use self::document::Document;
use self::training::TrainingControl;
use self::view::View;
use super::browser;
use super::frame_strip::FrameStrip;
use super::overlays::RenderedTextures;
use super::page_options::{PageOptionError, PageOptions};
use super::page_status;
use super::palette::Palette;
use super::persistence::{self, Origin};
use super::side_panel;
use super::store::Opened;
use crate::export::ExportOptions;
use crate::field::{Preset, Runner};
use crate::gpu::GpuContext;
use crate::labels::LabelSet;
use crate::labels::autosave::SceneSource;
use crate::labels::history::Edit;
use crate::labels::snapshots::Reason;
use crate::scene::Scene;
use crate::scene::archive::limits::MAX_JSON_BYTES;

/// A message shown under the title bar for a while.
struct Notice {
    text: String,
    error: bool,
    until_ms: f64,
}

/// Things an async task (file picker) hands back to the next frame.
type Inbox = Rc<RefCell<Vec<InboxItem>>>;

enum InboxItem {
    ImportedLabels(String, Vec<u8>),
    Error(String),
}

/// What the save machinery has told the user, so each change is told once.
#[derive(Default)]
struct SaveNews {
    /// The failure last told, if saving is failing.
    failure: Option<String>,
    read_only: bool,
}

/// What an annotator starts from besides its scene.
pub struct AnnotatorSetup {
    pub source: SceneSource,
    /// eframe's device, shared with the trainer; `None` without WebGPU.
    pub gpu: Option<GpuContext>,
    pub model: Preset,
    /// The page's options; `labels` only for the first scene of the page.
    pub options: PageOptions,
    /// Values in the address that could not be used: told to the user.
    pub option_errors: Vec<PageOptionError>,
}

pub struct Annotator {
    doc: Document,
    view: View,
    training: TrainingControl,
    palette: Palette,
    strip: FrameStrip,
    notices: Vec<Notice>,
    share_link: Option<String>,
    inbox: Inbox,
    /// The snapshots window is open.
    snapshots_open: bool,
    save_news: SaveNews,
    /// What the masks download holds beyond the class-id PNGs.
    export_options: ExportOptions,
}

impl Annotator {
    pub fn new(ctx: &egui::Context, scene: Box<Scene>, opened: Opened, setup: AnnotatorSetup) -> Annotator {
        let scene: Rc<Scene> = Rc::from(scene);
        let AnnotatorSetup {
            source,
            gpu,
            model,
            mut options,
            option_errors,
        } = setup;
        let restored = persistence::initial_labels(&scene, &source, options.labels.take().as_deref(), opened.newest);
        let doc = Document::new(scene, source, restored.labels, opened.store);
        let export_options = options.export.clone();
        let mut a = Annotator {
            view: View::new(&doc),
            doc,
            training: TrainingControl::new(gpu, model, options),
            palette: Palette::default(),
            strip: FrameStrip::default(),
            notices: Vec::new(),
            share_link: None,
            inbox: Inbox::default(),
            snapshots_open: false,
            save_news: SaveNews::default(),
            export_options,
        };
        for w in opened.warnings {
            a.notify(&w, true);
        }
        for i in opened.infos {
            a.notify(&i, false);
        }
        match restored.origin {
            Origin::SharedLink if a.doc.store.writable() => {
                // Saved at once, as a snapshot of its own: what it displaces stays listed.
                a.doc.save(Reason::Link);
                a.notify(
                    "Opened the annotations from the link; what was saved before stays in the snapshots.",
                    false,
                );
            }
            Origin::SharedLink => a.notify(
                "Opened the annotations from the link, NOT saved: another tab saves this scene. Export them to keep them.",
                true,
            ),
            Origin::Snapshot => a.notify("Restored the annotations saved in this browser.", false),
            Origin::Archive => a.notify("Started from the annotations shipped with the scene.", false),
            Origin::Empty => {}
        }
        for w in restored.warnings {
            a.notify(&w, true);
        }
        for e in option_errors {
            a.notify(&e.to_string(), true);
        }
        a.start_training(ctx);
        a
    }

    pub fn source(&self) -> &SceneSource {
        &self.doc.source
    }

    fn notify(&mut self, text: &str, error: bool) {
        let seconds = if error { 20.0 } else { 6.0 };
        self.notices.push(Notice {
            text: text.to_string(),
            error,
            until_ms: browser::now_ms() + seconds * 1000.0,
        });
    }

    fn start_training(&mut self, ctx: &egui::Context) {
        self.view.rendered = None;
        if let Err(e) = self.training.start(ctx, &self.doc, self.view.frame as u32) {
            self.notify(&e, true);
        }
    }

    /// Applies an edit made by the user and lets everything that follows the labels know.
    fn edit(&mut self, edit: Edit, merge: bool) {
        self.edit_for(edit, merge, Reason::Edits);
    }

    /// As [`Annotator::edit`], saving with `reason` (a restore or an import starts a snapshot).
    fn edit_for(&mut self, edit: Edit, merge: bool, reason: Reason) {
        if !self.may_edit() {
            return;
        }
        match self.doc.apply(edit, merge) {
            Ok(()) => self.labels_changed(reason),
            Err(e) => self.notify(&format!("cannot apply that edit: {e}"), true),
        }
    }

    /// A follower tab refuses edits: they could not be saved, and the writer's next save
    /// would replace them.
    fn may_edit(&mut self) -> bool {
        if self.doc.store.writable() {
            return true;
        }
        self.notify(
            "Read-only: this scene is being edited in another tab. Close that tab (this one then takes over) or edit there.",
            true,
        );
        false
    }

    fn undo(&mut self) {
        if !self.may_edit() {
            return;
        }
        match self.doc.undo() {
            Ok(Some(frame)) => {
                self.labels_changed(Reason::Edits);
                self.go_to_edited_frame(frame);
            }
            Ok(None) => {}
            Err(e) => self.notify(&format!("cannot undo: {e}"), true),
        }
    }

    fn redo(&mut self) {
        if !self.may_edit() {
            return;
        }
        match self.doc.redo() {
            Ok(Some(frame)) => {
                self.labels_changed(Reason::Edits);
                self.go_to_edited_frame(frame);
            }
            Ok(None) => {}
            Err(e) => self.notify(&format!("cannot redo: {e}"), true),
        }
    }

    /// Undoing a stroke on another frame shows that frame, so the user sees what changed.
    fn go_to_edited_frame(&mut self, frame: Option<u32>) {
        if let Some(f) = frame {
            self.view.go_to(f as usize, self.doc.frame_count());
        }
    }

    /// After every change of the labels by this tab (the document's version has moved on).
    fn labels_changed(&mut self, reason: Reason) {
        self.labels_followed();
        self.doc.save(reason);
    }

    /// After every change of the labels, this tab's or the writer's it follows.
    fn labels_followed(&mut self) {
        self.share_link = None;
        self.view.class = self
            .view
            .class
            .min(self.doc.labels.classes.len().saturating_sub(1) as u16);
        if self.training.labels_changed(&self.doc) {
            // Restarted from `show`, where the egui context is at hand.
            self.notify("A new class needs a larger field: training restarts.", false);
        }
    }

    pub fn show(&mut self, ui: &mut egui::Ui, gpu_name: &str) {
        let ctx = ui.ctx().clone();
        if self.training.restart_pending() {
            self.start_training(&ctx);
        }
        self.take_inbox();
        self.take_store_news();
        // Any key, or the pointer pressed or moving with a button down: the user is at work.
        let active = ctx.input(|i| {
            i.events.iter().any(|e| {
                matches!(e, egui::Event::Key { .. } | egui::Event::PointerButton { .. })
                    || (matches!(e, egui::Event::PointerMoved(_)) && i.pointer.any_down())
            })
        });
        if active && let Some(t) = &self.training.handle {
            t.user_active(400.0);
        }
        self.take_training_reports(&ctx);
        self.doc.refresh_summary();
        self.handle_keys(&ctx);
        self.view.arrow_key_widgets.clear();
        let now = browser::now_ms();
        self.notices.retain(|n| n.until_ms > now);

        egui::Panel::left("tools").default_size(270.0).show(ui, |ui| {
            egui::ScrollArea::vertical().show(ui, |ui| self.tools_panel(ui, gpu_name));
        });
        let mut actions = side_panel::SideActions::default();
        egui::Panel::right("field").default_size(240.0).show(ui, |ui| {
            egui::ScrollArea::vertical().show(ui, |ui| {
                let t = &self.training;
                actions = side_panel::show(
                    ui,
                    self.view.rendered.as_ref(),
                    t.handle.as_ref(),
                    &side_panel::SideFacts {
                        frame: self.view.frame as u32,
                        labelled_pixels: self.doc.summary.labelled_pixels,
                        factor: t.factor(),
                        has_codes: self.doc.scene.features.is_some() && Runner::Page.trains_on_codes(t.model),
                        animate: !t.software(),
                    },
                );
            })
        });
        if actions.toggle_pause {
            self.training.toggle_pause();
        }
        self.view.features_rect = actions.features_rect;
        if actions.restart {
            self.start_training(&ctx);
        }
        egui::Panel::bottom("frames").show(ui, |ui| {
            let out = self
                .strip
                .show(ui, &self.doc.scene, self.view.frame, &self.doc.summary.labelled_frames);
            self.view.frame = out.frame;
            self.view.arrow_key_widgets.extend(out.arrow_key_widgets);
        });
        let banner = self.save_banner();
        if !self.notices.is_empty() || banner.is_some() {
            egui::Panel::top("notices").show(ui, |ui| {
                if let Some((text, error)) = &banner {
                    let color = if *error {
                        ui.visuals().error_fg_color
                    } else {
                        ui.visuals().warn_fg_color
                    };
                    ui.label(RichText::new(text).color(color).strong());
                }
                for n in &self.notices {
                    let color = if n.error {
                        ui.visuals().error_fg_color
                    } else {
                        ui.visuals().strong_text_color()
                    };
                    ui.label(RichText::new(&n.text).color(color));
                }
            });
        }
        egui::CentralPanel::default().show(ui, |ui| {
            if let Some(stroke) = self.view.canvas(ui, &self.doc) {
                // People draw several strokes in a row: keep the GPU for the UI a little longer
                // than after other input, so a slow training step does not land between strokes.
                if let Some(t) = &self.training.handle {
                    t.user_active(1500.0);
                }
                let frame = self.view.frame as u32;
                self.edit(Edit::AddStroke { frame, stroke }, false);
            }
        });
        self.snapshots_window(&ctx);
        if let Some(t) = &mut self.training.handle {
            t.show_frame(self.view.frame as u32);
        }
        page_status::set(&self.status());
        if !self.notices.is_empty() {
            ctx.request_repaint_after(std::time::Duration::from_millis(500));
        }
    }

    /// Replaces the labels as one undoable edit, saved as a new snapshot (`reason`), so
    /// the labels replaced stay in the snapshot before it.
    fn replace_labels(&mut self, labels: LabelSet, message: &str, reason: Reason) {
        if !self.may_edit() {
            return;
        }
        let before = Box::new(self.doc.labels.clone());
        self.edit_for(
            Edit::Replace {
                before,
                after: Box::new(labels),
            },
            false,
            reason,
        );
        self.notify(message, false);
    }

    fn download_masks(&mut self) {
        if let Err(e) = self.training.export(&self.doc.labels, &self.export_options) {
            self.notify(&e, true);
        }
    }

    fn export_labels(&mut self) {
        let (name, bytes) = self.doc.labels_file();
        if let Err(e) = browser::download(&bytes, &name, "application/json") {
            self.notify(&e.to_string(), true);
        }
    }

    fn import_labels(&mut self) {
        let inbox = self.inbox.clone();
        wasm_bindgen_futures::spawn_local(async move {
            let item = match browser::pick_file(".json,application/json", MAX_JSON_BYTES).await {
                Ok(Some((name, bytes))) => InboxItem::ImportedLabels(name, bytes),
                Ok(None) => return,
                Err(e) => InboxItem::Error(e.to_string()),
            };
            inbox.borrow_mut().push(item);
        });
    }

    /// A dropped or picked `labels.json`.
    pub fn import_labels_bytes(&mut self, name: &str, bytes: &[u8]) {
        match LabelSet::from_json(bytes, name, self.doc.frame_count() as u32) {
            Ok(labels) if labels.classes.is_empty() => {
                self.notify(&format!("{name}: defines no classes"), true);
            }
            Ok(labels) => self.replace_labels(
                labels,
                &format!("Imported {name} (undo brings back what was there)."),
                Reason::Imported,
            ),
            Err(e) => self.notify(&e.to_string(), true),
        }
    }

    fn take_inbox(&mut self) {
        let items: Vec<InboxItem> = self.inbox.borrow_mut().drain(..).collect();
        for item in items {
            match item {
                InboxItem::ImportedLabels(name, bytes) => self.import_labels_bytes(&name, &bytes),
                InboxItem::Error(e) => self.notify(&e, true),
            }
        }
    }

    fn make_share_link(&mut self, ctx: &egui::Context) {
        match persistence::share_link(&self.doc.source, &self.doc.labels) {
            Ok(link) => {
                ctx.copy_text(link.clone());
                page_status::set_share_link(&link);
                self.share_link = Some(link);
            }
            Err(e) => {
                self.share_link = None;
                self.notify(&format!("{e}. Downloading the annotations file instead."), true);
                self.export_labels();
            }
        }
    }

    /// Takes what the training task has sent: a render to show, an export's zip to download.
    fn take_training_reports(&mut self, ctx: &egui::Context) {
        let Some(t) = &mut self.training.handle else { return };
        let delivered = t.poll();
        if let Some(r) = delivered.rendered {
            self.view.rendered = Some(RenderedTextures::new(
                ctx,
                &r.image,
                (r.frame, r.step, r.coarse, r.labelled),
                &self.doc.labels.classes,
            ));
        }
        if let Some(result) = delivered.exported {
            self.training.export_done();
            match result {
                Ok(zip) => {
                    let name = format!("{}-masks.zip", persistence::download_stem(&self.doc.source));
                    if let Err(e) = browser::download(&zip, &name, "application/zip") {
                        self.notify(&e.to_string(), true);
                    }
                }
                Err(e) => self.notify(&format!("The masks could not be made: {e}"), true),
            }
        }
    }
}
