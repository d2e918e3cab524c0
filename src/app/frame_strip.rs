//! The frame strip under the canvas: previous/next, a slider, and thumbnails of every frame
//! (annotated ones marked) to jump to. Thumbnails are made the first time they scroll into
//! view, so a long scene does not make hundreds of textures up front.
use std::collections::HashMap;

use egui::{Color32, ColorImage, Sense, Stroke, TextureHandle, TextureOptions, vec2};

use crate::scene::Scene;

const THUMB_HEIGHT: f32 = 54.0;

#[derive(Default)]
pub struct FrameStrip {
    thumbnails: HashMap<usize, TextureHandle>,
    /// The frame the strip last scrolled to, so it follows arrow keys without fighting the user.
    scrolled_to: Option<usize>,
}

pub struct StripOutput {
    /// The frame the user picked (buttons, slider or a thumbnail).
    pub frame: usize,
    /// Widgets that use the arrow keys themselves while focused.
    pub arrow_key_widgets: Vec<egui::Id>,
}

impl FrameStrip {
    /// `labelled[i]`: frame i has scribbles.
    pub fn show(&mut self, ui: &mut egui::Ui, scene: &Scene, frame: usize, labelled: &[bool]) -> StripOutput {
        let count = scene.frames.len();
        let last = count.saturating_sub(1);
        let mut frame = frame.min(last);
        let mut arrow_key_widgets = Vec::new();
        ui.add_space(4.0);
        ui.horizontal(|ui| {
            let back = ui.button("◀").on_hover_text("previous frame (←)");
            let forward = ui.button("▶").on_hover_text("next frame (→)");
            if back.clicked() {
                frame = frame.saturating_sub(1);
            }
            if forward.clicked() {
                frame = (frame + 1).min(last);
            }
            back.surrender_focus();
            forward.surrender_focus();
            ui.spacing_mut().slider_width = (ui.available_width() - 120.0).max(100.0);
            let slider = ui.add(egui::Slider::new(&mut frame, 0..=last).text(format!("of {count}")));
            arrow_key_widgets.push(slider.id);
        });
        egui::ScrollArea::horizontal()
            .id_salt("thumbnails")
            .auto_shrink([false, true])
            .show(ui, |ui| {
                ui.horizontal(|ui| {
                    for i in 0..count {
                        let aspect = scene.width as f32 / scene.height.max(1) as f32;
                        let size = vec2(THUMB_HEIGHT * aspect, THUMB_HEIGHT);
                        let (rect, response) = ui.allocate_exact_size(size, Sense::click());
                        if ui.is_rect_visible(rect) {
                            let texture = self.thumbnail(ui.ctx(), scene, i);
                            let painter = ui.painter();
                            let uv = egui::Rect::from_min_max(egui::pos2(0.0, 0.0), egui::pos2(1.0, 1.0));
                            painter.image(texture.id(), rect, uv, Color32::WHITE);
                            if labelled.get(i).copied().unwrap_or(false) {
                                painter.circle_filled(
                                    rect.right_top() + vec2(-7.0, 7.0),
                                    5.0,
                                    Color32::from_rgb(255, 200, 0),
                                );
                            }
                            let border = if i == frame {
                                Stroke::new(3.0, Color32::WHITE)
                            } else {
                                Stroke::new(1.0, Color32::from_gray(60))
                            };
                            painter.rect_stroke(rect, 2.0, border, egui::StrokeKind::Inside);
                        }
                        if i == frame && self.scrolled_to != Some(frame) {
                            response.scroll_to_me(Some(egui::Align::Center));
                            self.scrolled_to = Some(frame);
                        }
                        if response.on_hover_text(format!("frame {i}")).clicked() {
                            frame = i;
                            self.scrolled_to = Some(i);
                        }
                    }
                });
            });
        ui.add_space(4.0);
        StripOutput {
            frame,
            arrow_key_widgets,
        }
    }

    fn thumbnail(&mut self, ctx: &egui::Context, scene: &Scene, i: usize) -> TextureHandle {
        self.thumbnails
            .entry(i)
            .or_insert_with(|| {
                let rgb = &scene.frames[i].rgb;
                let h = (THUMB_HEIGHT as u32 * 2).min(rgb.height()).max(1);
                let w = (rgb.width() * h / rgb.height().max(1)).max(1);
                let small = image::imageops::thumbnail(rgb, w, h);
                ctx.load_texture(
                    format!("thumbnail {i}"),
                    ColorImage::from_rgb([w as usize, h as usize], small.as_raw()),
                    TextureOptions::LINEAR,
                )
            })
            .clone()
    }
}
