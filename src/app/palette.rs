//! The class palette: pick the class to draw (or press its number), rename and recolour it, add
//! a class. Returns what the user asked for; the annotator turns it into undoable edits.
use egui::{Color32, RichText};

use super::frame_view::class_color;
use crate::labels::ClassInfo;

pub enum PaletteAction {
    Select(u16),
    Change { index: usize, after: ClassInfo },
    Add(ClassInfo),
}

/// Per-palette UI state: the name being typed.
#[derive(Default)]
pub struct Palette {
    renaming: Option<(usize, String)>,
}

impl Palette {
    /// `used[i]`: class i has labelled pixels (shown, so the user sees what is missing).
    pub fn show(
        &mut self,
        ui: &mut egui::Ui,
        classes: &[ClassInfo],
        selected: u16,
        used: &[bool],
    ) -> Vec<PaletteAction> {
        let mut actions = Vec::new();
        for (i, class) in classes.iter().enumerate() {
            ui.horizontal(|ui| {
                let mut rgb = class.color;
                if ui.color_edit_button_srgb(&mut rgb).changed() {
                    actions.push(PaletteAction::Change {
                        index: i,
                        after: ClassInfo {
                            name: class.name.clone(),
                            color: rgb,
                        },
                    });
                }
                match &mut self.renaming {
                    Some((index, text)) if *index == i => {
                        let edit = ui.add(egui::TextEdit::singleline(text).desired_width(110.0));
                        if !edit.has_focus() && !edit.gained_focus() {
                            edit.request_focus();
                        }
                        let done = ui.input(|inp| inp.key_pressed(egui::Key::Enter)) || edit.lost_focus();
                        let cancel = ui.input(|inp| inp.key_pressed(egui::Key::Escape));
                        if cancel {
                            self.renaming = None;
                        } else if done {
                            let name = text.trim().to_string();
                            if !name.is_empty() && name != class.name {
                                actions.push(PaletteAction::Change {
                                    index: i,
                                    after: ClassInfo {
                                        name,
                                        color: class.color,
                                    },
                                });
                            }
                            self.renaming = None;
                        }
                    }
                    _ => {
                        let key = if i < 9 { format!("{} ", i + 1) } else { "  ".into() };
                        let mut text = RichText::new(format!("{key}{}", class.name));
                        if !used.get(i).copied().unwrap_or(false) {
                            text = text.italics();
                        }
                        let pick = ui
                            .selectable_label(selected as usize == i, text)
                            .on_hover_text("draw this class (number key); double-click to rename");
                        if pick.double_clicked() {
                            self.renaming = Some((i, class.name.clone()));
                        } else if pick.clicked() {
                            actions.push(PaletteAction::Select(i as u16));
                        }
                        pick.surrender_focus();
                    }
                }
            });
        }
        if used.iter().any(|u| !u) {
            ui.label(
                RichText::new("classes in italics have no scribbles yet")
                    .small()
                    .color(Color32::GRAY),
            );
        }
        if classes.len() < usize::from(u8::MAX) && ui.button("+ class").clicked() {
            let n = classes.len();
            let taken: Vec<[u8; 3]> = classes.iter().map(|k| k.color).collect();
            let colour = crate::colors::unused_color(&taken);
            actions.push(PaletteAction::Add(ClassInfo {
                name: format!("class {}", n + 1),
                color: colour,
            }));
        }
        actions
    }
}

/// The colour class `id` is drawn in.
pub fn color_of(classes: &[ClassInfo], id: u16) -> Color32 {
    class_color(classes, id as usize)
}
