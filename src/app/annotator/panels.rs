//! The tools panel left of the canvas: classes, brush, undo, view layers, results (downloads,
//! share link) and the scene's facts.
use egui::RichText;

use super::super::canvas::Tool;
use super::super::palette::PaletteAction;
use super::super::scene_panel;
use super::super::training::Phase;
use super::Annotator;
use crate::export::Format;
use crate::labels::brush::{MAX_RADIUS, MIN_RADIUS};
use crate::labels::history::Edit;

impl Annotator {
    pub(super) fn tools_panel(&mut self, ui: &mut egui::Ui, gpu_name: &str) {
        ui.heading("Classes");
        let used = self.doc.summary.classes_used.clone();
        let classes = self.doc.labels.classes.clone();
        for action in self.palette.show(ui, &classes, self.view.class, &used) {
            match action {
                PaletteAction::Select(c) => self.view.select_class(c),
                PaletteAction::Change { index, after } => {
                    let before = self.doc.labels.classes[index].clone();
                    self.edit(Edit::ChangeClass { index, before, after }, true);
                }
                PaletteAction::Add(class) => {
                    self.edit(Edit::AddClass(class), false);
                    self.view
                        .select_class(self.doc.labels.classes.len().saturating_sub(1) as u16);
                }
            }
        }

        ui.add_space(8.0);
        ui.heading("Brush");
        ui.horizontal(|ui| {
            let brush = ui
                .selectable_value(&mut self.view.tool, Tool::Brush, "brush")
                .on_hover_text("B");
            let eraser = ui
                .selectable_value(&mut self.view.tool, Tool::Eraser, "eraser")
                .on_hover_text("E");
            brush.surrender_focus();
            eraser.surrender_focus();
        });
        let size = ui
            .add(
                egui::Slider::new(
                    &mut self.view.radius,
                    MIN_RADIUS..=MAX_RADIUS.min(self.doc.scene.width as f32 / 4.0),
                )
                .logarithmic(true)
                .text("radius px"),
            )
            .on_hover_text("[ and ] change the size");
        self.view.arrow_key_widgets.push(size.id);
        ui.horizontal(|ui| {
            let undo = ui.add_enabled(self.doc.history.can_undo(), egui::Button::new("↶ undo"));
            let redo = ui.add_enabled(self.doc.history.can_redo(), egui::Button::new("↷ redo"));
            if undo.on_hover_text("Ctrl+Z").clicked() {
                self.undo();
            }
            if redo.on_hover_text("Ctrl+Shift+Z").clicked() {
                self.redo();
            }
        });
        let frame = self.view.frame as u32;
        let has_strokes = self.doc.labels.frame(frame).is_some_and(|f| !f.strokes.is_empty());
        if ui
            .add_enabled(has_strokes, egui::Button::new("clear this frame"))
            .clicked()
            && let Some(f) = self.doc.labels.frame(frame)
        {
            let strokes = f.strokes.clone();
            self.edit(Edit::ClearFrame { frame, strokes }, false);
        }

        ui.add_space(8.0);
        ui.heading("View");
        let mask = ui.add_enabled(
            self.training.handle.is_some(),
            egui::Checkbox::new(&mut self.view.layers.mask, "mask (M)"),
        );
        let confidence = ui
            .checkbox(&mut self.view.layers.confidence, "uncertainty (C)")
            .on_hover_text("magenta where the field is unsure: scribble there next");
        let scribbles = ui.checkbox(&mut self.view.layers.scribbles, "scribbles (S)");
        let gt = ui.add_enabled(
            self.doc.scene.has_gt(),
            egui::Checkbox::new(&mut self.view.layers.ground_truth, "ground truth (G)"),
        );
        for r in [mask, confidence, scribbles, gt] {
            r.surrender_focus();
        }
        let opacity = ui.add(egui::Slider::new(&mut self.view.layers.mask_opacity, 0.0..=1.0).text("opacity"));
        self.view.arrow_key_widgets.push(opacity.id);
        ui.horizontal(|ui| {
            ui.label(format!("zoom {:.1}x", self.view.zoom.zoom));
            if ui.button("fit (0)").clicked() {
                self.view.zoom.reset();
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
            scene_panel::show(ui, &self.doc.scene, self.doc.source.describe(), gpu_name)
        });
    }

    /// What the masks download holds beyond the class-id PNGs: the formats, and autolabel's
    /// object-count cleanup.
    fn export_options_section(&mut self, ui: &mut egui::Ui, enabled: bool) {
        let has_depth = self.doc.scene.has_depth();
        ui.collapsing("download also holds", |ui| {
            ui.add_enabled_ui(enabled, |ui| {
                let options = &mut self.export_options;
                for format in Format::ALL {
                    let possible = format != Format::Ply || has_depth;
                    let mut on = options.has(format) && possible;
                    let response = ui
                        .add_enabled(possible, egui::Checkbox::new(&mut on, format.describe()))
                        .on_disabled_hover_text("this scene has no depth");
                    if response.changed() {
                        options.set(format, on);
                    }
                }
                ui.horizontal(|ui| {
                    let mut limit = options.objects.is_some();
                    let mut n = options.objects.unwrap_or(1);
                    ui.checkbox(&mut limit, "keep the largest").on_hover_text(
                        "of each class but the first, only this many regions per frame are kept; the others \
                             become the first class (autolabel's --objects)",
                    );
                    ui.add_enabled(limit, egui::DragValue::new(&mut n).range(1..=255));
                    ui.label("per class");
                    options.objects = limit.then_some(n);
                });
            });
        });
    }

    fn results_section(&mut self, ui: &mut egui::Ui) {
        let exporting = match self.training.phase() {
            Some(Phase::Exporting { done, total }) => Some((*done, *total)),
            _ => None,
        };
        let running = matches!(self.training.phase(), Some(Phase::Running));
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
                    .on_hover_text(format!(
                        "a zip with a class-id PNG per frame at the archive's {} x {}, by index and (by-name/) by \
                         the frame's name in its capture, colour previews, the annotations and the formats ticked \
                         below; `scribblefield segment --source CAPTURE` makes them at the capture's resolution",
                        self.doc.scene.width, self.doc.scene.height
                    ))
                    .clicked()
                {
                    self.download_masks();
                }
            }
        }
        self.export_options_section(ui, exporting.is_none());
        if let Some(ms) = self.training.last_export_ms {
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
        ui.add_space(4.0);
        self.save_section(ui);
    }
}
