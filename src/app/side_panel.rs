//! The panel beside the canvas: how training goes (steps, speed, loss, labelled pixels; pause
//! and restart) and what the field renders for the visible frame (colour, depth, and its
//! features through a 3-component PCA).
use egui::{Color32, RichText};

use super::frame_view::show_image;
use super::overlays::RenderedTextures;
use super::training::{Phase, Training};

#[derive(Default)]
pub struct SideActions {
    pub toggle_pause: bool,
    pub restart: bool,
    /// Where the features image was drawn (for the page status, so tests can look at it).
    pub features_rect: Option<egui::Rect>,
}

/// Facts about the annotation the panel shows.
pub struct SideFacts {
    pub frame: u32,
    pub labelled_pixels: u64,
    /// The field trains on frames this many times smaller.
    pub factor: u32,
    /// The field trains on the scene's feature codes (and shows them through their PCA); else
    /// the features are shown through a PCA fitted to each render.
    pub has_codes: bool,
    /// Spinners may animate (not on a CPU rasterizer, where every repaint costs the training
    /// about a second).
    pub animate: bool,
}

pub fn show(
    ui: &mut egui::Ui,
    rendered: Option<&RenderedTextures>,
    training: Option<&Training>,
    facts: &SideFacts,
) -> SideActions {
    let SideFacts {
        frame,
        labelled_pixels,
        factor,
        has_codes,
        animate,
    } = *facts;
    let mut actions = SideActions::default();
    ui.heading("Training");
    let Some(t) = training else {
        ui.label(RichText::new("not running: no GPU device").color(ui.visuals().error_fg_color));
        return actions;
    };
    let (reports, cfg) = (t.reports(), &t.config);
    let s = &reports.progress;
    match &reports.phase {
        Phase::Starting => {
            ui.horizontal(|ui| {
                if animate {
                    ui.spinner();
                }
                ui.label("uploading the scene, building kernels…");
            });
        }
        Phase::Running | Phase::Exporting { .. } => {
            let label = if t.paused() { "resume (space)" } else { "pause (space)" };
            if ui.button(label).clicked() {
                actions.toggle_pause = true;
            }
            if reports.spreading {
                ui.horizontal(|ui| {
                    if animate {
                        ui.spinner();
                    }
                    ui.label("spreading the strokes over the frames…")
                        .on_hover_text("training waits until the new strokes have reached every frame they can");
                });
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
            if let Some(spread) = reports.spread {
                row("trains on", format!("{} px in {} frames", spread.pixels, spread.frames));
                if let Some(check) = spread.check {
                    let verdict = if spread.withheld { " (too low: spread less)" } else { "" };
                    row("spread check", format!("{}{verdict}", check.describe()));
                }
            }
            row("steps/s", format!("{:.1}", s.steps_per_second));
            if let Some(l) = s.losses {
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
            row("render", format!("{:.0} ms", reports.render_ms));
            if let Some(r) = reports.refresh {
                let full = r.full_ms.map_or("…".to_string(), |ms| format!("{:.1} s", ms / 1000.0));
                row("mask refresh", format!("{:.1} s, full {full}", r.first_ms / 1000.0));
            }
            if s.step_submit_ms + s.step_wait_ms > 0.0 {
                row(
                    "step (submit+GPU)",
                    format!("{:.0} + {:.0} ms", s.step_submit_ms, s.step_wait_ms),
                );
            }
            row(
                "resolution",
                if factor > 1 {
                    format!("1/{factor} (#res=1 for full)")
                } else {
                    "full".into()
                },
            );
            row(
                "model",
                format!(
                    "{} rays, width {}, {} samples",
                    cfg.batch_rays,
                    cfg.density_width,
                    cfg.samples_per_ray()
                ),
            );
        });

    ui.add_space(8.0);
    ui.heading("Field's view");
    match rendered.filter(|r| r.frame == frame) {
        Some(r) => {
            let [w, h] = r.rgb.size();
            let what = if r.coarse {
                format!(
                    "frame {frame} at step {}: quick {w} x {h} render, full one next",
                    r.step
                )
            } else {
                format!("frame {frame} at step {}", r.step)
            };
            ui.label(RichText::new(what).small());
            if !r.labelled {
                ui.label(RichText::new("Masks appear once the field has trained on a stroke.").small());
            }
            // Two images a row, so all three fit beside the facts above on a small screen.
            let width = ((ui.available_width() - ui.spacing().item_spacing.x) / 2.0).max(16.0);
            let size = egui::vec2(width, width * h as f32 / w.max(1) as f32);
            let captioned = |ui: &mut egui::Ui, texture, caption: &str| {
                ui.vertical(|ui| {
                    let response = show_image(ui, texture, None, size);
                    ui.label(RichText::new(caption).small());
                    response
                })
                .inner
            };
            ui.horizontal_top(|ui| {
                captioned(ui, &r.rgb, "rendered colour");
                captioned(ui, &r.depth, "rendered depth");
            });
            let (caption, why) = if has_codes {
                (
                    "rendered features, PCA of the scene's codes",
                    "The field's rendered feature vectors projected on the first three principal \
                     components of the scene's feature codes, as red, green and blue: the same \
                     colours as the codes themselves.",
                )
            } else {
                (
                    "rendered features, PCA of this view",
                    "The field trains on no feature codes here (the scene has none, or the tiny \
                     model of software rasterizers leaves them out), so the feature branch is \
                     trained only through the semantic head; its rendered vectors are shown through a PCA \
                     fitted to this render (the colours change from render to render).",
                )
            };
            ui.horizontal_top(|ui| {
                let features = captioned(ui, &r.features, "rendered features");
                // Only the part on screen (the panel scrolls).
                let visible = features.rect.intersect(ui.clip_rect());
                if visible.width() > 0.0 && visible.height() > 0.0 {
                    actions.features_rect = Some(visible);
                }
                ui.add(egui::Label::new(RichText::new(caption).small()).wrap())
                    .on_hover_text(why);
            });
        }
        None => {
            ui.label(RichText::new("rendering this frame…").color(Color32::GRAY));
        }
    }
    actions
}
