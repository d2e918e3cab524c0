//! The egui app (web). For now it loads a scene and lets the user look through its frames:
//! colour, depth and ground truth. The annotator grows from here: `loading` gets the scene into
//! the page, `frame_view` draws a frame, `scene_panel` describes the scene.
pub mod frame_view;
pub mod loading;
pub mod page_status;
pub mod scene_panel;

use egui::{Key, RichText};

use self::frame_view::FrameTextures;
use self::loading::{LoadPhase, SceneLoad};
use crate::scene::Scene;

pub struct App {
    stage: Stage,
    /// Adapter and backend, for the scene panel (and for bug reports).
    gpu: String,
}

enum Stage {
    Loading(SceneLoad),
    Viewing(Box<Viewer>),
    Failed { url: String, message: String },
}

impl App {
    pub fn new(cc: &eframe::CreationContext<'_>, scene_url: String) -> App {
        let gpu = match &cc.wgpu_render_state {
            Some(rs) => {
                let info = rs.adapter.get_info();
                format!(
                    "{} ({:?})",
                    if info.name.is_empty() {
                        "unnamed adapter"
                    } else {
                        &info.name
                    },
                    info.backend
                )
            }
            None => "none".into(),
        };
        let load = SceneLoad::start(scene_url, cc.egui_ctx.clone());
        App {
            stage: Stage::Loading(load),
            gpu,
        }
    }
}

impl eframe::App for App {
    fn ui(&mut self, ui: &mut egui::Ui, _frame: &mut eframe::Frame) {
        if let Stage::Loading(load) = &self.stage
            && let Some(result) = load.take_result()
        {
            let url = load.url().to_string();
            self.stage = match result {
                Ok(scene) => Stage::Viewing(Box::new(Viewer::new(scene, url))),
                Err(e) => Stage::Failed {
                    url,
                    message: e.to_string(),
                },
            };
        }

        egui::Panel::top("title").show(ui, |ui| {
            ui.horizontal(|ui| {
                ui.strong("scribblefield");
                ui.separator();
                ui.label("scene viewer");
            });
        });
        match &mut self.stage {
            Stage::Loading(load) => show_loading(ui, load),
            Stage::Viewing(viewer) => viewer.show(ui, &self.gpu),
            Stage::Failed { url, message } => show_failure(ui, url, message),
        }
    }
}

fn show_loading(ui: &mut egui::Ui, load: &SceneLoad) {
    let (status, text, fraction) = load.with_phase(|phase| match *phase {
        LoadPhase::Connecting => ("loading", format!("Connecting to {}", load.url()), None),
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
                "loading",
                text,
                total.filter(|&t| t > 0).map(|t| (received as f32 / t as f32).min(1.0)),
            )
        }
        LoadPhase::Decoding { bytes } => (
            "decoding",
            format!("Decoding {} ({})", load.url(), megabytes(bytes)),
            Some(1.0),
        ),
        LoadPhase::Finished(_) | LoadPhase::Taken => ("loading", "Opening the scene".into(), Some(1.0)),
    });
    page_status::set(status);
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
        });
    });
}

fn show_failure(ui: &mut egui::Ui, url: &str, message: &str) {
    page_status::set(&format!("error: {message}"));
    egui::CentralPanel::default().show(ui, |ui| {
        ui.vertical_centered(|ui| {
            ui.add_space(ui.available_height() * 0.3);
            ui.label(
                RichText::new(format!("Cannot open the scene {url}"))
                    .size(18.0)
                    .strong(),
            );
            ui.add_space(8.0);
            ui.label(RichText::new(message).color(ui.visuals().error_fg_color).monospace());
            ui.add_space(12.0);
            ui.label("Open the page with #scene=<url of a .scene.zip> in the address to load another scene,");
            ui.label("or without it for the demo scene. `scribblefield pack` makes an archive from a capture.");
        });
    });
}

/// A clicked button or checkbox keeps keyboard focus, and egui then spends the arrow keys on
/// moving focus between widgets; after a click the arrows should step through frames again.
fn release_focus_after_click(responses: &[egui::Response]) {
    for response in responses.iter().filter(|r| r.clicked()) {
        response.surrender_focus();
    }
}

fn megabytes(bytes: u64) -> String {
    format!("{:.1} MB", bytes as f64 / 1e6)
}

/// Looking through a loaded scene.
struct Viewer {
    scene: Box<Scene>,
    url: String,
    frame: usize,
    textures: Option<FrameTextures>,
    show_ground_truth: bool,
    overlay_opacity: f32,
    show_depth: bool,
    /// Widgets that use the arrow keys themselves while focused (from the last frame drawn).
    arrow_key_widgets: Vec<egui::Id>,
}

impl Viewer {
    fn new(scene: Box<Scene>, url: String) -> Viewer {
        Viewer {
            scene,
            url,
            frame: 0,
            textures: None,
            show_ground_truth: false,
            overlay_opacity: 0.5,
            show_depth: true,
            arrow_key_widgets: Vec::new(),
        }
    }

    fn show(&mut self, ui: &mut egui::Ui, gpu: &str) {
        let frame_count = self.scene.frames.len();
        self.handle_keys(ui.ctx());
        self.arrow_key_widgets.clear();

        egui::Panel::left("scene").default_size(260.0).show(ui, |ui| {
            egui::ScrollArea::vertical().show(ui, |ui| {
                scene_panel::show(ui, &self.scene, &self.url, gpu);
                ui.add_space(8.0);
                ui.heading("View");
                let depth = ui.checkbox(&mut self.show_depth, "depth");
                let ground_truth = ui.add_enabled(
                    self.scene.has_gt(),
                    egui::Checkbox::new(&mut self.show_ground_truth, "ground truth"),
                );
                release_focus_after_click(&[depth, ground_truth]);
                let opacity = ui.add_enabled(
                    self.scene.has_gt() && self.show_ground_truth,
                    egui::Slider::new(&mut self.overlay_opacity, 0.0..=1.0).text("opacity"),
                );
                self.arrow_key_widgets.push(opacity.id);
            });
        });
        egui::Panel::bottom("frames").show(ui, |ui| {
            ui.add_space(4.0);
            ui.horizontal(|ui| {
                let back = ui.button("◀").on_hover_text("previous frame (←)");
                let forward = ui.button("▶").on_hover_text("next frame (→)");
                if back.clicked() {
                    self.step(-1);
                }
                if forward.clicked() {
                    self.step(1);
                }
                release_focus_after_click(&[back, forward]);
                let last = frame_count.saturating_sub(1);
                ui.spacing_mut().slider_width = (ui.available_width() - 160.0).max(100.0);
                let slider = ui.add(egui::Slider::new(&mut self.frame, 0..=last).text(format!("of {frame_count}")));
                self.arrow_key_widgets.push(slider.id);
            });
            ui.add_space(4.0);
        });
        egui::CentralPanel::default().show(ui, |ui| self.show_frame(ui));
        page_status::set(&format!(
            "ready frames={frame_count} size={}x{} frame={}",
            self.scene.width, self.scene.height, self.frame
        ));
    }

    fn show_frame(&mut self, ui: &mut egui::Ui) {
        if self.textures.as_ref().is_none_or(|t| t.frame != self.frame) {
            self.textures = FrameTextures::new(ui.ctx(), &self.scene, self.frame);
        }
        let Some(textures) = &self.textures else {
            ui.label("This scene has no frames.");
            return;
        };
        let source = self.scene.frames[self.frame].source.as_deref().unwrap_or("");
        ui.label(format!("frame {} of {}  {source}", self.frame, self.scene.frames.len()));
        let overlay = textures
            .ground_truth
            .as_ref()
            .filter(|_| self.show_ground_truth)
            .map(|t| (t, self.overlay_opacity));
        let depth = textures.depth.as_ref().filter(|_| self.show_depth);
        let available = ui.available_size();
        match depth {
            // Side by side on a wide screen, stacked on a tall one.
            Some(depth) if available.x >= available.y => {
                let half = egui::vec2((available.x - ui.spacing().item_spacing.x) / 2.0, available.y);
                ui.horizontal_top(|ui| {
                    frame_view::show_image(ui, &textures.rgb, overlay, half);
                    frame_view::show_image(ui, depth, None, half);
                });
            }
            Some(depth) => {
                let half = egui::vec2(available.x, (available.y - ui.spacing().item_spacing.y) / 2.0);
                frame_view::show_image(ui, &textures.rgb, overlay, half);
                frame_view::show_image(ui, depth, None, half);
            }
            None => {
                frame_view::show_image(ui, &textures.rgb, overlay, available);
            }
        }
    }

    /// Arrow keys step through frames, unless a text field or a slider has keyboard focus:
    /// those use the arrows themselves.
    fn handle_keys(&mut self, ctx: &egui::Context) {
        let focused = ctx.memory(|m| m.focused());
        if ctx.egui_wants_keyboard_input() || focused.is_some_and(|id| self.arrow_key_widgets.contains(&id)) {
            return;
        }
        // Count presses: on a slow device several can arrive between two frames.
        let (back, forward) = ctx.input(|i| (i.num_presses(Key::ArrowLeft), i.num_presses(Key::ArrowRight)));
        self.step(forward as isize - back as isize);
    }

    fn step(&mut self, delta: isize) {
        let last = self.scene.frames.len().saturating_sub(1);
        self.frame = self.frame.saturating_add_signed(delta).min(last);
    }
}
