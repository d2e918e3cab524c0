//! The side panel describing the loaded scene: what the archive holds and its classes.
use egui::RichText;

use super::frame_view::class_color;
use crate::scene::Scene;

pub fn show(ui: &mut egui::Ui, scene: &Scene, scene_url: &str, gpu: &str) {
    ui.heading("Scene");
    ui.label(RichText::new(scene_url).monospace())
        .on_hover_text("set another with #scene=<url> in the address");
    ui.add_space(4.0);
    egui::Grid::new("scene facts")
        .num_columns(2)
        .striped(true)
        .show(ui, |ui| {
            let mut row = |name: &str, value: String| {
                ui.label(name);
                ui.label(value);
                ui.end_row();
            };
            row("frames", scene.frames.len().to_string());
            row("image size", format!("{} x {}", scene.width, scene.height));
            let k = &scene.intrinsics;
            row("focal length", format!("{:.1}, {:.1} px", k.fx, k.fy));
            let depth_frames = scene.frames.iter().filter(|f| f.depth.is_some()).count();
            row("depth", format!("{depth_frames} of {} frames", scene.frames.len()));
            let gt_frames = scene.frames.iter().filter(|f| f.gt.is_some()).count();
            row(
                "ground truth",
                if gt_frames > 0 {
                    format!("{gt_frames} frames")
                } else {
                    "no".into()
                },
            );
            row(
                "features",
                match &scene.features {
                    Some(f) => format!("{} x {} x {}", f.width, f.height, f.dim),
                    None => "no".into(),
                },
            );
            let strokes = scene
                .labels
                .as_ref()
                .map(|l| l.frames.iter().map(|f| f.strokes.len()).sum::<usize>());
            row(
                "labels",
                strokes.map_or_else(|| "no".into(), |n| format!("{n} strokes")),
            );
            let b = &scene.bounds;
            let extent = [b.max[0] - b.min[0], b.max[1] - b.min[1], b.max[2] - b.min[2]];
            row(
                "bounds",
                format!("{:.2} x {:.2} x {:.2} m", extent[0], extent[1], extent[2]),
            );
            row("GPU", gpu.to_string());
        });
    ui.add_space(8.0);
    ui.heading("Classes");
    if scene.classes.is_empty() {
        ui.label("not named in this scene");
    }
    for (id, class) in scene.classes.iter().enumerate() {
        ui.horizontal(|ui| {
            let (rect, _) = ui.allocate_exact_size(egui::vec2(14.0, 14.0), egui::Sense::hover());
            ui.painter().rect_filled(rect, 2.0, class_color(&scene.classes, id));
            ui.label(format!("{id}: {}", class.name));
        });
    }
}
