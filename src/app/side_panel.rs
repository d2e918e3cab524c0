//! The panel beside the canvas: how training goes (steps, speed, loss, labelled pixels; pause
//! and restart) and what the field renders for the visible frame (colour and depth).
use egui::{Color32, RichText};

use super::frame_view::show_image;
use super::overlays::RenderedTextures;
use super::training::{Phase, Shared};
use crate::field::FieldConfig;

#[derive(Default)]
pub struct SideActions {
    pub toggle_pause: bool,
    pub restart: bool,
}

pub fn show(
    ui: &mut egui::Ui,
    rendered: Option<&RenderedTextures>,
    frame: u32,
    training: Option<&Shared>,
    config: Option<&FieldConfig>,
    labelled_pixels: u64,
    factor: u32,
) -> SideActions {
    let mut actions = SideActions::default();
    ui.heading("Training");
    let Some(s) = training else {
        ui.label(RichText::new("not running: no GPU device").color(ui.visuals().error_fg_color));
        return actions;
    };
    match &s.phase {
        Phase::Starting => {
            ui.horizontal(|ui| {
                ui.spinner();
                ui.label("uploading the scene, building kernels");
            });
        }
        Phase::Running | Phase::Exporting { .. } => {
            let label = if s.paused { "resume (space)" } else { "pause (space)" };
            if ui.button(label).clicked() {
                actions.toggle_pause = true;
            }
        }
        Phase::Failed(message) => {
            ui.label(RichText::new(format!("stopped: {message}")).color(ui.visuals().error_fg_color));
            ui.label("The annotations are kept (and saved in this browser).");
            if ui.button("restart training").clicked() {
                actions.restart = true;
            }
        }
    }
    egui::Grid::new("training facts")
        .num_columns(2)
        .striped(true)
        .show(ui, |ui| {
            let mut row = |name: &str, value: String| {
                ui.label(name);
                ui.label(value);
                ui.end_row();
            };
            row("steps", s.steps.to_string());
            row("steps/s", format!("{:.1}", s.steps_per_second));
            if let (Some(l), Some(cfg)) = (s.losses, config) {
                let per_ray = |v: f64| v / f64::from(cfg.batch_rays);
                row("loss", format!("{:.3e}", per_ray(l.terms.total())));
                row(
                    "  colour / depth",
                    format!("{:.2e} / {:.2e}", per_ray(l.terms.rgb), per_ray(l.terms.depth)),
                );
                row("  semantic", format!("{:.3e}", per_ray(l.terms.semantic)));
            }
            row("labelled px", labelled_pixels.to_string());
            row("steps per batch", s.batch.to_string());
            row("render", format!("{:.0} ms", s.render_ms));
            row(
                "resolution",
                if factor > 1 {
                    format!("1/{factor} (#res=1 for full)")
                } else {
                    "full".into()
                },
            );
            if let Some(cfg) = config {
                row(
                    "model",
                    format!(
                        "{} rays, width {}, {} samples",
                        cfg.batch_rays,
                        cfg.density_width,
                        cfg.samples_per_ray()
                    ),
                );
            }
        });

    ui.add_space(8.0);
    ui.heading("Field's view");
    match rendered.filter(|r| r.frame == frame) {
        Some(r) => {
            ui.label(RichText::new(format!("frame {frame} at step {}", r.step)).small());
            let width = ui.available_width();
            let size = egui::vec2(width, width * r.rgb.size()[1] as f32 / r.rgb.size()[0].max(1) as f32);
            show_image(ui, &r.rgb, None, size);
            ui.label(RichText::new("rendered colour").small());
            show_image(ui, &r.depth, None, size);
            ui.label(RichText::new("rendered depth").small());
        }
        None => {
            ui.label(RichText::new("rendering this frame…").color(Color32::GRAY));
        }
    }
    actions
}
