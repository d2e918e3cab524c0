//! Showing one frame: its colour image with an optional class overlay, and its depth as grey.
//! Textures are made for the visible frame only and replaced when the frame changes, so GPU
//! memory does not grow with the number of frames.
use egui::{Color32, ColorImage, Rect, Sense, TextureHandle, TextureOptions, Vec2, pos2};
use image::GrayImage;

use crate::labels::ClassInfo;
use crate::scene::GT_VOID;
use crate::scene::{DepthImage, Scene};

/// Depth shown for pixels without a reading.
const NO_DEPTH: Color32 = Color32::from_rgb(60, 0, 40);

/// The textures of the frame on screen.
pub struct FrameTextures {
    pub frame: usize,
    pub rgb: TextureHandle,
    pub depth: Option<TextureHandle>,
    pub ground_truth: Option<TextureHandle>,
}

impl FrameTextures {
    pub fn new(ctx: &egui::Context, scene: &Scene, frame: usize) -> Option<FrameTextures> {
        let f = scene.frames.get(frame)?;
        let size = [f.rgb.width() as usize, f.rgb.height() as usize];
        let rgb = ctx.load_texture(
            format!("rgb {frame}"),
            ColorImage::from_rgb(size, f.rgb.as_raw()),
            TextureOptions::LINEAR,
        );
        let depth = f
            .depth
            .as_ref()
            .map(|d| ctx.load_texture(format!("depth {frame}"), depth_to_grey(d), TextureOptions::LINEAR));
        // NEAREST keeps class boundaries crisp when the frame is magnified.
        let ground_truth = f.gt.as_ref().map(|g| {
            ctx.load_texture(
                format!("gt {frame}"),
                class_overlay(g, &scene.classes),
                TextureOptions::NEAREST,
            )
        });
        Some(FrameTextures {
            frame,
            rgb,
            depth,
            ground_truth,
        })
    }
}

/// Near is dark, far is bright, scaled to this frame's own depth range; no reading is purple so
/// it cannot be mistaken for a depth.
pub fn depth_to_grey(depth: &DepthImage) -> ColorImage {
    let valid = depth.as_raw().iter().copied().filter(|&d| d != 0);
    let (lo, hi) = valid.fold((u16::MAX, 0u16), |(lo, hi), d| (lo.min(d), hi.max(d)));
    let span = hi.saturating_sub(lo).max(1) as f32;
    let pixels = depth
        .as_raw()
        .iter()
        .map(|&d| {
            if d == 0 {
                NO_DEPTH
            } else {
                Color32::from_gray((40.0 + 215.0 * (d.saturating_sub(lo)) as f32 / span) as u8)
            }
        })
        .collect();
    ColorImage::new([depth.width() as usize, depth.height() as usize], pixels)
}

/// Class ids as opaque class colours, void transparent; the caller sets the opacity.
pub fn class_overlay(ids: &GrayImage, classes: &[ClassInfo]) -> ColorImage {
    let pixels = ids
        .as_raw()
        .iter()
        .map(|&id| {
            if id == GT_VOID {
                Color32::TRANSPARENT
            } else {
                class_color(classes, id as usize)
            }
        })
        .collect();
    ColorImage::new([ids.width() as usize, ids.height() as usize], pixels)
}

/// A class's display colour; ids the scene does not name get a colour from a fixed palette.
pub fn class_color(classes: &[ClassInfo], id: usize) -> Color32 {
    if let Some(c) = classes.get(id) {
        return Color32::from_rgb(c.color[0], c.color[1], c.color[2]);
    }
    let [r, g, b] = crate::colors::distinct_color(id);
    Color32::from_rgb(r, g, b)
}

/// Draws `texture` as large as fits in `max` keeping its aspect ratio, with `overlay` (a
/// texture of the same frame and its opacity) on top. Returns the image's response so callers
/// can map pointer positions to pixels.
pub fn show_image(
    ui: &mut egui::Ui,
    texture: &TextureHandle,
    overlay: Option<(&TextureHandle, f32)>,
    max: Vec2,
) -> egui::Response {
    let size = fit(texture.size_vec2(), max);
    let (rect, response) = ui.allocate_exact_size(size, Sense::hover());
    let uv = Rect::from_min_max(pos2(0.0, 0.0), pos2(1.0, 1.0));
    let painter = ui.painter_at(rect);
    painter.image(texture.id(), rect, uv, Color32::WHITE);
    if let Some((overlay, opacity)) = overlay {
        painter.image(
            overlay.id(),
            rect,
            uv,
            Color32::WHITE.gamma_multiply(opacity.clamp(0.0, 1.0)),
        );
    }
    response
}

/// The largest size with `image`'s aspect ratio inside `max`.
fn fit(image: Vec2, max: Vec2) -> Vec2 {
    if image.x <= 0.0 || image.y <= 0.0 {
        return Vec2::ZERO;
    }
    let scale = (max.x / image.x).min(max.y / image.y).max(0.0);
    image * scale
}
