//! Annotating a loaded scene: the labels and their undo history, the tool, the visible frame,
//! and the live training that turns the scribbles into masks. Panels and the canvas are drawn
//! by their own modules; this one keeps the state and turns what they report into edits.
use std::cell::RefCell;
use std::rc::Rc;

use egui::{Key, KeyboardShortcut, Modifiers, RichText};

use super::browser;
use super::canvas::{self, Brush, Layer, Tool};
use super::frame_strip::FrameStrip;
use super::frame_view::{FrameTextures, class_overlay};
use super::model_size::ModelSize;
use super::overlays::{self, RenderedTextures};
use super::palette::{Palette, PaletteAction, color_of};
use super::persistence::{self, Origin};
use super::training::{Phase, Refresh, Training, TrainingOptions};
use super::training_scene::{auto_factor, downscale};
use super::{page_status, scene_panel, side_panel};
use crate::gpu::GpuContext;
use crate::labels::LabelSet;
use crate::labels::autosave::SceneSource;
use crate::labels::brush::{MAX_RADIUS, MIN_RADIUS, StrokeBuilder};
use crate::labels::canvas_zoom::ViewTransform;
use crate::labels::history::{Edit, History};
use crate::labels::summary::{classes_used, labelled_pixels_per_frame};
use crate::scene::Scene;

const UNDO: KeyboardShortcut = KeyboardShortcut::new(Modifiers::COMMAND, Key::Z);
const REDO: KeyboardShortcut = KeyboardShortcut::new(Modifiers::COMMAND.plus(Modifiers::SHIFT), Key::Z);
const REDO_Y: KeyboardShortcut = KeyboardShortcut::new(Modifiers::COMMAND, Key::Y);

/// A message shown under the title bar for a while.
struct Notice {
    text: String,
    error: bool,
    until_ms: f64,
}

/// What has been annotated, recomputed when the labels change.
#[derive(Default)]
struct Summary {
    version: u64,
    strokes: usize,
    labelled_pixels: u64,
    labelled_frames: Vec<bool>,
    classes_used: Vec<bool>,
}

/// Things an async task (file picker) hands back to the next frame.
type Inbox = Rc<RefCell<Vec<InboxItem>>>;

enum InboxItem {
    ImportedLabels(String, Vec<u8>),
    Error(String),
}

pub struct Annotator {
    scene: Rc<Scene>,
    source: SceneSource,
    labels: LabelSet,
    /// Bumped by every edit: textures, summary, autosave and trainer follow it.
    version: u64,
    history: History,
    class: u16,
    tool: Tool,
    radius: f32,
    frame: usize,
    view: ViewTransform,
    drawing: Option<StrokeBuilder>,
    frame_textures: Option<FrameTextures>,
    scribbles: Option<(usize, u64, egui::TextureHandle)>,
    rendered: Option<RenderedTextures>,
    show_mask: bool,
    mask_opacity: f32,
    show_confidence: bool,
    show_gt: bool,
    show_scribbles: bool,
    gpu: Option<GpuContext>,
    model: ModelSize,
    training: Option<Training>,
    palette: Palette,
    strip: FrameStrip,
    notices: Vec<Notice>,
    share_link: Option<String>,
    summary: Summary,
    autosaved_version: Option<u64>,
    autosave_error: Option<String>,
    /// An autosave that a shared link replaced, which the user may want back.
    displaced: bool,
    export_started_ms: Option<f64>,
    last_export_ms: Option<f64>,
    inbox: Inbox,
    restart_pending: bool,
    /// The scene the field trains on and its downscale factor (kept for restarts).
    /// The scene at training resolution, for (downscale factor, whether it keeps the codes).
    train_scene: Option<((u32, bool), Rc<Scene>)>,
    arrow_key_widgets: Vec<egui::Id>,
    image_rect: egui::Rect,
    /// Where the side panel drew the rendered features (for the page status).
    features_rect: Option<egui::Rect>,
}

impl Annotator {
    pub fn new(
        ctx: &egui::Context,
        scene: Box<Scene>,
        source: SceneSource,
        gpu: Option<GpuContext>,
        model: ModelSize,
    ) -> Annotator {
        let scene: Rc<Scene> = Rc::from(scene);
        let restored = persistence::initial_labels(&scene, &source);
        let mut a = Annotator {
            view: ViewTransform::new(scene.width, scene.height),
            labels: restored.labels,
            source,
            version: 1,
            history: History::new(),
            class: 0,
            tool: Tool::Brush,
            radius: (scene.width.min(scene.height) as f32 * 0.03).clamp(2.0, 24.0).round(),
            frame: 0,
            drawing: None,
            frame_textures: None,
            scribbles: None,
            rendered: None,
            show_mask: true,
            mask_opacity: 0.45,
            show_confidence: false,
            show_gt: false,
            show_scribbles: true,
            gpu,
            model,
            training: None,
            palette: Palette::default(),
            strip: FrameStrip::default(),
            notices: Vec::new(),
            share_link: None,
            summary: Summary::default(),
            autosaved_version: None,
            autosave_error: None,
            displaced: restored.displaced,
            export_started_ms: None,
            last_export_ms: None,
            inbox: Inbox::default(),
            restart_pending: false,
            train_scene: None,
            arrow_key_widgets: Vec::new(),
            image_rect: egui::Rect::NOTHING,
            features_rect: None,
            scene,
        };
        match restored.origin {
            Origin::SharedLink => a.notify("Opened the annotations from the link.", false),
            Origin::Autosave => a.notify("Restored the annotations saved in this browser.", false),
            Origin::Archive => a.notify("Started from the annotations shipped with the scene.", false),
            Origin::Empty => {}
        }
        for w in restored.warnings {
            a.notify(&w, true);
        }
        // The first frame with scribbles is the natural place to continue.
        if let Some(f) = a.labels.frames.iter().find(|f| !f.strokes.is_empty()) {
            a.frame = (f.frame as usize).min(a.scene.frames.len().saturating_sub(1));
        }
        a.start_training(ctx);
        a
    }

    pub fn source(&self) -> &SceneSource {
        &self.source
    }

    fn notify(&mut self, text: &str, error: bool) {
        let seconds = if error { 20.0 } else { 6.0 };
        self.notices.push(Notice {
            text: text.to_string(),
            error,
            until_ms: browser::now_ms() + seconds * 1000.0,
        });
    }

    /// (Re)starts training from scratch: on load, after a failure, or when the classes outgrow
    /// the field's semantic head.
    fn start_training(&mut self, ctx: &egui::Context) {
        self.training = None;
        self.rendered = None;
        let Some(gpu) = self.gpu.clone() else {
            self.notify("No GPU device: the field cannot be trained in this page.", true);
            return;
        };
        let factor = crate::labels::share::fragment_value(&browser::page_fragment(), "res")
            .and_then(|v| v.parse::<u32>().ok())
            .filter(|f| (1..=16).contains(f))
            .unwrap_or_else(|| auto_factor(self.scene.width, self.scene.height, self.model == ModelSize::Tiny));
        let key = (factor, self.model.trains_on_feature_codes());
        let train_scene = match &self.train_scene {
            Some((k, s)) if *k == key => s.clone(),
            _ => {
                let s = Rc::new(downscale(&self.scene, factor, key.1));
                self.train_scene = Some((key, s.clone()));
                s
            }
        };
        let mut config = self.model.config(&train_scene, self.labels.classes.len());
        // `#rays=N` in the address: rays per training batch (and per render tile).
        if let Some(rays) =
            crate::labels::share::fragment_value(&browser::page_fragment(), "rays").and_then(|v| v.parse::<u32>().ok())
        {
            config.batch_rays = rays;
        }
        if let Err(e) = config.validate() {
            self.notify(&format!("cannot train: {e}"), true);
            return;
        }
        let fragment = browser::page_fragment();
        let option = |key: &str| crate::labels::share::fragment_value(&fragment, key);
        let software = gpu.is_software();
        let mut options = TrainingOptions {
            profile: option("profile").is_some_and(|v| v != "0"),
            // Training numbers: on a CPU rasterizer every repaint delays training by about a
            // second, so there the panel is updated every few seconds.
            repaint_ms: if software { 3000 } else { 250 },
            split_steps: option("split").is_some_and(|v| v != "0"),
            ..TrainingOptions::default()
        };
        // `#refine=N`: rounds of edge-aware refinement of the shown and exported masks.
        if let Some(n) = option("refine").and_then(|v| v.parse::<u32>().ok()) {
            options.refine.iterations = n.min(16);
        }
        // `#coarse=N`: the quick first render of a stale mask at 1/N, even where it is not
        // quicker than the full one (1: none).
        if let Some(n) = option("coarse").and_then(|v| v.parse::<u32>().ok()) {
            options.refresh = Refresh {
                coarse_divisor: n.clamp(1, 64),
                coarse_always: true,
            };
        }
        // `#kernels=tiled|uniform`: the dense kernels of a GPU or of a CPU rasterizer, whatever
        // the adapter is (to compare them on one device).
        let gpu = match option("kernels").as_deref() {
            Some("tiled") => gpu.treated_as_software(false),
            Some("uniform") => gpu.treated_as_software(true),
            _ => gpu,
        };
        self.training = Some(Training::start(
            gpu,
            train_scene,
            factor,
            (self.scene.width, self.scene.height),
            config,
            &self.labels,
            self.frame as u32,
            options,
            ctx.clone(),
        ));
        if let Some(t) = &self.training {
            t.set_labels(self.version, &self.labels);
        }
    }

    /// Applies an edit made by the user and lets everything that follows the labels know.
    fn edit(&mut self, edit: Edit, merge: bool) {
        let result = if merge {
            self.history.apply_merging(&mut self.labels, edit)
        } else {
            self.history.apply(&mut self.labels, edit)
        };
        match result {
            Ok(()) => self.labels_changed(),
            Err(e) => self.notify(&format!("cannot apply that edit: {e}"), true),
        }
    }

    fn undo(&mut self) {
        match self.history.undo(&mut self.labels) {
            Ok(Some(edit)) => {
                let frame = edit.frame();
                self.labels_changed();
                self.go_to_edited_frame(frame);
            }
            Ok(None) => {}
            Err(e) => self.notify(&format!("cannot undo: {e}"), true),
        }
    }

    fn redo(&mut self) {
        match self.history.redo(&mut self.labels) {
            Ok(Some(edit)) => {
                let frame = edit.frame();
                self.labels_changed();
                self.go_to_edited_frame(frame);
            }
            Ok(None) => {}
            Err(e) => self.notify(&format!("cannot redo: {e}"), true),
        }
    }

    /// Undoing a stroke on another frame shows that frame, so the user sees what changed.
    fn go_to_edited_frame(&mut self, frame: Option<u32>) {
        if let Some(f) = frame {
            self.frame = (f as usize).min(self.scene.frames.len().saturating_sub(1));
        }
    }

    fn labels_changed(&mut self) {
        self.version += 1;
        self.share_link = None;
        self.class = self.class.min(self.labels.classes.len().saturating_sub(1) as u16);
        let needs_restart = self
            .training
            .as_ref()
            .is_some_and(|t| (t.config.num_classes as usize) < self.labels.classes.len());
        if needs_restart {
            self.notify("A new class needs a larger field: training restarts.", false);
            // Restarted from `show`, where the egui context is at hand.
            self.training = None;
            self.restart_pending = true;
        } else if let Some(t) = &self.training {
            t.set_labels(self.version, &self.labels);
        }
        self.save();
    }

    /// Writes the autosave (each edit is one small write: strokes are whole, not per move).
    fn save(&mut self) {
        match persistence::autosave(&self.scene, &self.source, &self.labels) {
            Ok(()) => {
                self.autosaved_version = Some(self.version);
                self.autosave_error = None;
            }
            Err(e) => {
                if self.autosave_error.is_none() {
                    self.notify(
                        &format!("Cannot autosave the annotations ({e}); export them to keep them."),
                        true,
                    );
                }
                self.autosave_error = Some(e.to_string());
            }
        }
    }

    fn refresh_summary(&mut self) {
        if self.summary.version == self.version {
            return;
        }
        let (w, h) = (self.scene.width, self.scene.height);
        let per_frame = labelled_pixels_per_frame(&self.labels, w, h);
        let mut labelled_frames = vec![false; self.scene.frames.len()];
        for &(f, n) in &per_frame {
            if let Some(slot) = labelled_frames.get_mut(f as usize) {
                *slot = n > 0;
            }
        }
        self.summary = Summary {
            version: self.version,
            strokes: self.labels.frames.iter().map(|f| f.strokes.len()).sum(),
            labelled_pixels: per_frame.iter().map(|p| p.1).sum(),
            labelled_frames,
            classes_used: classes_used(&self.labels, w, h),
        };
    }

    pub fn show(&mut self, ui: &mut egui::Ui, gpu_name: &str) {
        let ctx = ui.ctx().clone();
        // Dropped when a new class outgrew the field (see `labels_changed`).
        if self.training.is_none() && self.gpu.is_some() && self.restart_pending {
            self.restart_pending = false;
            self.start_training(&ctx);
        }
        self.take_inbox();
        // Any key, or the pointer pressed or moving with a button down: the user is at work.
        let active = ctx.input(|i| {
            i.events.iter().any(|e| {
                matches!(e, egui::Event::Key { .. } | egui::Event::PointerButton { .. })
                    || (matches!(e, egui::Event::PointerMoved(_)) && i.pointer.any_down())
            })
        });
        if active && let Some(t) = &self.training {
            t.user_active(400.0);
        }
        self.take_training_reports(&ctx);
        self.refresh_summary();
        self.handle_keys(&ctx);
        self.arrow_key_widgets.clear();
        let now = browser::now_ms();
        self.notices.retain(|n| n.until_ms > now);

        egui::Panel::left("tools").default_size(270.0).show(ui, |ui| {
            egui::ScrollArea::vertical().show(ui, |ui| self.tools_panel(ui, gpu_name));
        });
        let mut actions = side_panel::SideActions::default();
        egui::Panel::right("field").default_size(240.0).show(ui, |ui| {
            egui::ScrollArea::vertical().show(ui, |ui| {
                let training = self.training.as_ref().map(|t| t.shared());
                actions = side_panel::show(
                    ui,
                    self.rendered.as_ref(),
                    training.as_deref(),
                    self.training.as_ref().map(|t| &t.config),
                    &side_panel::SideFacts {
                        frame: self.frame as u32,
                        labelled_pixels: self.summary.labelled_pixels,
                        factor: self.training.as_ref().map_or(1, |t| t.factor),
                        has_codes: self.scene.features.is_some() && self.model.trains_on_feature_codes(),
                        animate: !self.gpu.as_ref().is_some_and(|g| g.is_software()),
                    },
                );
            })
        });
        if actions.toggle_pause
            && let Some(t) = &self.training
        {
            let mut sh = t.shared_mut();
            sh.paused = !sh.paused;
        }
        self.features_rect = actions.features_rect;
        if actions.restart {
            self.start_training(&ctx);
        }
        egui::Panel::bottom("frames").show(ui, |ui| {
            let out = self
                .strip
                .show(ui, &self.scene, self.frame, &self.summary.labelled_frames);
            self.frame = out.frame;
            self.arrow_key_widgets.extend(out.arrow_key_widgets);
        });
        if !self.notices.is_empty() {
            egui::Panel::top("notices").show(ui, |ui| {
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
        egui::CentralPanel::default().show(ui, |ui| self.canvas(ui));
        if let Some(t) = &self.training {
            t.show_frame(self.frame as u32);
        }
        self.publish_status();
        if !self.notices.is_empty() {
            ctx.request_repaint_after(std::time::Duration::from_millis(500));
        }
    }

    fn canvas(&mut self, ui: &mut egui::Ui) {
        if self.frame_textures.as_ref().is_none_or(|t| t.frame != self.frame) {
            self.frame_textures = FrameTextures::new(ui.ctx(), &self.scene, self.frame);
        }
        let (w, h) = (self.scene.width, self.scene.height);
        if self
            .scribbles
            .as_ref()
            .is_none_or(|(f, v, _)| *f != self.frame || *v != self.version)
        {
            let image = overlays::scribbles(self.labels.frame(self.frame as u32), w, h, &self.labels.classes);
            let texture = ui.ctx().load_texture("scribbles", image, egui::TextureOptions::NEAREST);
            self.scribbles = Some((self.frame, self.version, texture));
        }
        let Some(frame_textures) = &self.frame_textures else {
            ui.label("This scene has no frames.");
            return;
        };
        let mut layers = Vec::new();
        let gt_texture;
        if self.show_gt
            && let Some(gt) = self.scene.frames[self.frame].gt.as_ref()
        {
            gt_texture = frame_textures.ground_truth.clone().unwrap_or_else(|| {
                ui.ctx().load_texture(
                    "gt",
                    class_overlay(gt, &self.scene.classes),
                    egui::TextureOptions::NEAREST,
                )
            });
            layers.push(Layer {
                texture: &gt_texture,
                opacity: self.mask_opacity,
            });
        }
        let rendered = self.rendered.as_ref().filter(|r| r.frame as usize == self.frame);
        if let Some(r) = rendered {
            if self.show_mask {
                layers.push(Layer {
                    texture: &r.mask,
                    opacity: self.mask_opacity,
                });
            }
            if self.show_confidence {
                layers.push(Layer {
                    texture: &r.confidence,
                    opacity: 1.0,
                });
            }
        }
        if self.show_scribbles
            && let Some((_, _, t)) = &self.scribbles
        {
            layers.push(Layer {
                texture: t,
                opacity: 1.0,
            });
        }
        let brush = Brush {
            tool: self.tool,
            class: self.class,
            color: color_of(&self.labels.classes, self.class),
            radius: self.radius,
        };
        let out = canvas::show(
            ui,
            &mut self.view,
            &frame_textures.rgb,
            &layers,
            &brush,
            &mut self.drawing,
        );
        self.image_rect = out.image_rect;
        if let Some(stroke) = out.finished {
            // People draw several strokes in a row: keep the GPU for the UI a little longer
            // than after other input, so a slow training step does not land between strokes.
            if let Some(t) = &self.training {
                t.user_active(1500.0);
            }
            let frame = self.frame as u32;
            self.edit(Edit::AddStroke { frame, stroke }, false);
        }
    }

    fn tools_panel(&mut self, ui: &mut egui::Ui, gpu_name: &str) {
        ui.heading("Classes");
        let used = self.summary.classes_used.clone();
        let classes = self.labels.classes.clone();
        for action in self.palette.show(ui, &classes, self.class, &used) {
            match action {
                PaletteAction::Select(c) => {
                    self.class = c;
                    self.tool = Tool::Brush;
                }
                PaletteAction::Change { index, after } => {
                    let before = self.labels.classes[index].clone();
                    self.edit(Edit::ChangeClass { index, before, after }, true);
                }
                PaletteAction::Add(class) => {
                    self.edit(Edit::AddClass(class), false);
                    self.class = self.labels.classes.len().saturating_sub(1) as u16;
                    self.tool = Tool::Brush;
                }
            }
        }

        ui.add_space(8.0);
        ui.heading("Brush");
        ui.horizontal(|ui| {
            let brush = ui
                .selectable_value(&mut self.tool, Tool::Brush, "brush")
                .on_hover_text("B");
            let eraser = ui
                .selectable_value(&mut self.tool, Tool::Eraser, "eraser")
                .on_hover_text("E");
            brush.surrender_focus();
            eraser.surrender_focus();
        });
        let size = ui
            .add(
                egui::Slider::new(
                    &mut self.radius,
                    MIN_RADIUS..=MAX_RADIUS.min(self.scene.width as f32 / 4.0),
                )
                .logarithmic(true)
                .text("radius px"),
            )
            .on_hover_text("[ and ] change the size");
        self.arrow_key_widgets.push(size.id);
        ui.horizontal(|ui| {
            let undo = ui.add_enabled(self.history.can_undo(), egui::Button::new("↶ undo"));
            let redo = ui.add_enabled(self.history.can_redo(), egui::Button::new("↷ redo"));
            if undo.on_hover_text("Ctrl+Z").clicked() {
                self.undo();
            }
            if redo.on_hover_text("Ctrl+Shift+Z").clicked() {
                self.redo();
            }
        });
        let frame = self.frame as u32;
        let has_strokes = self.labels.frame(frame).is_some_and(|f| !f.strokes.is_empty());
        if ui
            .add_enabled(has_strokes, egui::Button::new("clear this frame"))
            .clicked()
            && let Some(f) = self.labels.frame(frame)
        {
            let strokes = f.strokes.clone();
            self.edit(Edit::ClearFrame { frame, strokes }, false);
        }

        ui.add_space(8.0);
        ui.heading("View");
        let mask = ui.add_enabled(
            self.training.is_some(),
            egui::Checkbox::new(&mut self.show_mask, "mask (M)"),
        );
        let confidence = ui
            .checkbox(&mut self.show_confidence, "uncertainty (C)")
            .on_hover_text("magenta where the field is unsure: scribble there next");
        let scribbles = ui.checkbox(&mut self.show_scribbles, "scribbles (S)");
        let gt = ui.add_enabled(
            self.scene.has_gt(),
            egui::Checkbox::new(&mut self.show_gt, "ground truth (G)"),
        );
        for r in [mask, confidence, scribbles, gt] {
            r.surrender_focus();
        }
        let opacity = ui.add(egui::Slider::new(&mut self.mask_opacity, 0.0..=1.0).text("opacity"));
        self.arrow_key_widgets.push(opacity.id);
        ui.horizontal(|ui| {
            ui.label(format!("zoom {:.1}x", self.view.zoom));
            if ui.button("fit (0)").clicked() {
                self.view.reset();
            }
        });
        ui.label(
            RichText::new("wheel zooms, right-drag pans")
                .small()
                .color(egui::Color32::GRAY),
        );

        ui.add_space(8.0);
        ui.heading("Results");
        self.results_section(ui);

        ui.add_space(8.0);
        ui.collapsing("Scene", |ui| {
            scene_panel::show(ui, &self.scene, self.source.describe(), gpu_name)
        });
    }

    fn results_section(&mut self, ui: &mut egui::Ui) {
        let exporting = self.training.as_ref().and_then(|t| match t.shared().phase {
            Phase::Exporting { done, total } => Some((done, total)),
            _ => None,
        });
        let running = self
            .training
            .as_ref()
            .is_some_and(|t| matches!(t.shared().phase, Phase::Running));
        match exporting {
            Some((done, total)) => {
                ui.add(
                    egui::ProgressBar::new(done as f32 / total.max(1) as f32)
                        .text(format!("rendering masks {done} / {total}")),
                );
            }
            None => {
                if ui
                    .add_enabled(running, egui::Button::new("⬇ download masks (D)"))
                    .on_hover_text("a zip with a class-id PNG per frame, colour previews and the annotations")
                    .clicked()
                {
                    self.download_masks();
                }
            }
        }
        if let Some(ms) = self.last_export_ms {
            ui.label(RichText::new(format!("last export took {:.1} s", ms / 1000.0)).small());
        }
        ui.horizontal(|ui| {
            if ui
                .button("export labels")
                .on_hover_text("the annotations alone, as labels.json")
                .clicked()
            {
                self.export_labels();
            }
            if ui.button("import labels").clicked() {
                self.import_labels();
            }
        });
        if ui
            .button("share link (L)")
            .on_hover_text("a link with the scene and the annotations; copied to the clipboard")
            .clicked()
        {
            self.make_share_link(ui.ctx());
        }
        if let Some(link) = &self.share_link {
            let mut shown = link.clone();
            ui.add(
                egui::TextEdit::singleline(&mut shown)
                    .desired_width(f32::INFINITY)
                    .font(egui::TextStyle::Monospace),
            );
            ui.label(RichText::new(format!("{} characters, copied", link.len())).small());
        }
        if self.displaced && ui.button("restore my earlier annotations").clicked() {
            match persistence::take_displaced(&self.scene, &self.source) {
                Ok(Some(labels)) => self.replace_labels(labels, "Restored the annotations from before the link."),
                Ok(None) => self.notify("The earlier annotations are gone.", true),
                Err(e) => self.notify(&e, true),
            }
            self.displaced = false;
        }
    }

    fn replace_labels(&mut self, labels: LabelSet, message: &str) {
        let before = Box::new(self.labels.clone());
        self.edit(
            Edit::Replace {
                before,
                after: Box::new(labels),
            },
            false,
        );
        self.notify(message, false);
    }

    fn download_masks(&mut self) {
        let Some(t) = &self.training else {
            self.notify("No trained field to render masks from.", true);
            return;
        };
        t.export(&self.labels);
        self.export_started_ms = Some(browser::now_ms());
    }

    fn export_labels(&mut self) {
        let name = format!("{}-labels.json", persistence::download_stem(&self.source));
        if let Err(e) = browser::download(self.labels.to_json().as_bytes(), &name, "application/json") {
            self.notify(&e.to_string(), true);
        }
    }

    fn import_labels(&mut self) {
        let inbox = self.inbox.clone();
        wasm_bindgen_futures::spawn_local(async move {
            let item = match browser::pick_file(".json,application/json").await {
                Ok(Some((name, bytes))) => InboxItem::ImportedLabels(name, bytes),
                Ok(None) => return,
                Err(e) => InboxItem::Error(e.to_string()),
            };
            inbox.borrow_mut().push(item);
        });
    }

    /// A dropped or picked `labels.json`.
    pub fn import_labels_bytes(&mut self, name: &str, bytes: &[u8]) {
        match LabelSet::from_json(bytes, name, self.scene.frames.len() as u32) {
            Ok(labels) if labels.classes.is_empty() => {
                self.notify(&format!("{name}: defines no classes"), true);
            }
            Ok(labels) => self.replace_labels(labels, &format!("Imported {name} (undo brings back what was there).")),
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
        match persistence::share_link(&self.source, &self.labels) {
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

    fn take_training_reports(&mut self, ctx: &egui::Context) {
        let Some(t) = &self.training else { return };
        let (rendered, exported) = {
            let mut s = t.shared_mut();
            (s.rendered.take(), s.exported.take())
        };
        if let Some(r) = rendered {
            self.rendered = Some(RenderedTextures::new(
                ctx,
                &r.image,
                (r.frame, r.step, r.coarse),
                &self.labels.classes,
            ));
        }
        if let Some(result) = exported {
            self.last_export_ms = self.export_started_ms.take().map(|s| browser::now_ms() - s);
            match result {
                Ok(zip) => {
                    let name = format!("{}-masks.zip", persistence::download_stem(&self.source));
                    if let Err(e) = browser::download(&zip, &name, "application/zip") {
                        self.notify(&e.to_string(), true);
                    }
                }
                Err(e) => self.notify(&format!("The masks could not be made: {e}"), true),
            }
        }
    }

    /// Keyboard shortcuts, unless a text field has the keyboard.
    fn handle_keys(&mut self, ctx: &egui::Context) {
        if ctx.egui_wants_keyboard_input() {
            return;
        }
        let (undo, redo) = ctx.input_mut(|i| {
            // Check the longer shortcut first: Ctrl+Z would also match Ctrl+Shift+Z.
            let redo = i.consume_shortcut(&REDO) || i.consume_shortcut(&REDO_Y);
            (i.consume_shortcut(&UNDO), redo)
        });
        if redo {
            self.redo();
        } else if undo {
            self.undo();
        }
        let focused = ctx.memory(|m| m.focused());
        let arrows_taken = focused.is_some_and(|id| self.arrow_key_widgets.contains(&id));
        let keys = ctx.input(|i| {
            let plain = !i.modifiers.command && !i.modifiers.alt;
            let pressed = |k| plain && i.key_pressed(k);
            let digit = [
                Key::Num1,
                Key::Num2,
                Key::Num3,
                Key::Num4,
                Key::Num5,
                Key::Num6,
                Key::Num7,
                Key::Num8,
                Key::Num9,
            ]
            .iter()
            .position(|&k| pressed(k));
            (
                digit,
                i.num_presses(Key::ArrowRight) as isize - i.num_presses(Key::ArrowLeft) as isize,
                [
                    Key::B,
                    Key::E,
                    Key::OpenBracket,
                    Key::CloseBracket,
                    Key::M,
                    Key::C,
                    Key::S,
                    Key::G,
                    Key::Num0,
                    Key::Space,
                    Key::D,
                    Key::L,
                ]
                .map(pressed),
            )
        });
        let (digit, step, [b, e, smaller, larger, m, c, s, g, fit, space, d, l]) = keys;
        if let Some(i) = digit.filter(|&i| i < self.labels.classes.len()) {
            self.class = i as u16;
            self.tool = Tool::Brush;
        }
        if !arrows_taken && step != 0 {
            let last = self.scene.frames.len().saturating_sub(1);
            self.frame = self.frame.saturating_add_signed(step).min(last);
        }
        if b {
            self.tool = Tool::Brush;
        }
        if e {
            self.tool = Tool::Eraser;
        }
        if smaller {
            self.radius = (self.radius / 1.25).max(MIN_RADIUS);
        }
        if larger {
            self.radius = (self.radius * 1.25).min(MAX_RADIUS);
        }
        self.show_mask ^= m;
        self.show_confidence ^= c;
        self.show_scribbles ^= s;
        self.show_gt ^= g && self.scene.has_gt();
        if fit {
            self.view.reset();
        }
        if space && let Some(t) = &self.training {
            let mut sh = t.shared_mut();
            sh.paused = !sh.paused;
        }
        if d {
            self.download_masks();
        }
        if l {
            self.make_share_link(ctx);
        }
    }

    /// The one-line status scripts and tests read (see `page_status`).
    fn publish_status(&self) {
        let s = &self.summary;
        let r = self.image_rect;
        let (phase, steps, sps, loss, rendered_step, timing) = match &self.training {
            Some(t) => {
                let sh = t.shared();
                let phase = match &sh.phase {
                    Phase::Starting => "starting".to_string(),
                    Phase::Running if sh.paused => "paused".into(),
                    Phase::Running => "running".into(),
                    Phase::Exporting { done, total } => format!("exporting:{done}/{total}"),
                    Phase::Failed(_) => "failed".into(),
                };
                let loss = sh
                    .losses
                    .map(|l| l.terms.total() / f64::from(t.config.batch_rays))
                    .map_or("-".to_string(), |l| format!("{l:.4}"));
                let rendered = self
                    .rendered
                    .as_ref()
                    .filter(|r| r.frame as usize == self.frame)
                    .map_or(-1, |r| i64::from(r.step));
                let mask = match self.rendered.as_ref().filter(|r| r.frame as usize == self.frame) {
                    None => "none",
                    Some(r) if r.coarse => "coarse",
                    Some(_) => "full",
                };
                let refresh = sh.refresh.map_or("-".to_string(), |r| {
                    format!(
                        "{:.0},{}",
                        r.first_ms,
                        r.full_ms.map_or("-".to_string(), |f| format!("{f:.0}"))
                    )
                });
                let timing = format!(
                    " mask={mask} refresh_ms={refresh} step_ms={:.0}+{:.0} batch={}",
                    sh.step_submit_ms, sh.step_wait_ms, sh.batch
                );
                (phase, sh.steps, sh.steps_per_second, loss, rendered, timing)
            }
            None => ("none".to_string(), 0, 0.0, "-".to_string(), -1, String::new()),
        };
        let features = self
            .features_rect
            .filter(|_| self.rendered.as_ref().is_some_and(|r| r.frame as usize == self.frame))
            .map_or(String::new(), |f| {
                format!(
                    " features={:.0},{:.0},{:.0},{:.0}",
                    f.min.x,
                    f.min.y,
                    f.width(),
                    f.height()
                )
            });
        // Last, since it has spaces: why training stopped.
        let failure = self
            .training
            .as_ref()
            .and_then(|t| match &t.shared().phase {
                Phase::Failed(m) => Some(format!(" failure: {m}")),
                _ => None,
            })
            .unwrap_or_default();
        page_status::set(&format!(
            "ready frames={} size={}x{} frame={} class={} tool={} classes={} strokes={} labelled={} \
             training={phase} steps={steps} sps={sps:.2} loss={loss} rendered={rendered_step} \
             saved={} res={} render_ms={:.0} view={:.0},{:.0},{:.0},{:.0}{timing}{features}{failure}",
            self.scene.frames.len(),
            self.scene.width,
            self.scene.height,
            self.frame,
            self.class,
            match self.tool {
                Tool::Brush => "brush",
                Tool::Eraser => "eraser",
            },
            self.labels.classes.len(),
            s.strokes,
            s.labelled_pixels,
            u8::from(self.autosaved_version == Some(self.version)),
            self.training.as_ref().map_or(1, |t| t.factor),
            self.training.as_ref().map_or(0.0, |t| t.shared().render_ms),
            r.min.x,
            r.min.y,
            r.width(),
            r.height(),
        ));
    }
}
