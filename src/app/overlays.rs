//! Images drawn over and beside the frame: the scribbles, the field's mask and confidence, and
//! the field's rendered colour, depth and features (3-component PCA as RGB). Each becomes a
//! texture of the render's size (drawn stretched over the frame), replaced when what it shows
//! changes.
use egui::{Color32, ColorImage, TextureHandle, TextureOptions};

use super::frame_view::class_color;
use crate::field::gpu::trainer::RenderedFrame;
use crate::labels::{ClassInfo, FrameLabels, UNLABELLED, rasterize_frame};

/// Shown where the field is unsure (the top class has little more than an even share).
const UNSURE: Color32 = Color32::from_rgb(255, 0, 200);

/// The scribbles of one frame, opaque class colours on transparent.
pub fn scribbles(labels: Option<&FrameLabels>, width: u32, height: u32, classes: &[ClassInfo]) -> ColorImage {
    let map = rasterize_frame(labels, width, height);
    let pixels = map
        .iter()
        .map(|&c| {
            if c == UNLABELLED {
                Color32::TRANSPARENT
            } else {
                class_color(classes, c as usize)
            }
        })
        .collect();
    ColorImage::new([width as usize, height as usize], pixels)
}

/// The textures of one render of the visible frame.
pub struct RenderedTextures {
    pub frame: u32,
    pub step: u32,
    /// A quick low-resolution render (the full one follows).
    pub coarse: bool,
    /// Whether the field had learnt classes from labels (`training::Rendered::labelled`): the
    /// mask and its confidence are shown only then.
    pub labelled: bool,
    pub mask: TextureHandle,
    pub confidence: TextureHandle,
    pub rgb: TextureHandle,
    pub depth: TextureHandle,
    /// The rendered features through a 3-component PCA.
    pub features: TextureHandle,
}

impl RenderedTextures {
    pub fn new(
        ctx: &egui::Context,
        r: &RenderedFrame,
        (frame, step, coarse, labelled): (u32, u32, bool, bool),
        classes: &[ClassInfo],
    ) -> Self {
        let size = [r.width as usize, r.height as usize];
        let mask = r.classes.iter().map(|&c| class_color(classes, c as usize)).collect();
        // The top probability runs from 1/C (no idea) to 1 (certain); show the shortfall.
        let floor = 1.0 / classes.len().max(2) as f32;
        let confidence = r
            .confidence
            .iter()
            .map(|&p| {
                let unsure = ((1.0 - p) / (1.0 - floor)).clamp(0.0, 1.0);
                Color32::from_rgba_unmultiplied(UNSURE.r(), UNSURE.g(), UNSURE.b(), (unsure * 230.0) as u8)
            })
            .collect();
        let rgb = r
            .rgb
            .iter()
            .map(|c| {
                let [r, g, b] = c.map(|v| (v.clamp(0.0, 1.0) * 255.0 + 0.5) as u8);
                Color32::from_rgb(r, g, b)
            })
            .collect();
        let finite = r.depth.iter().copied().filter(|d| d.is_finite() && *d > 0.0);
        let (lo, hi) = finite.fold((f32::MAX, 0.0f32), |(lo, hi), d| (lo.min(d), hi.max(d)));
        let span = (hi - lo).max(1e-6);
        let depth = r
            .depth
            .iter()
            .map(|&d| {
                if d.is_finite() && d > 0.0 {
                    Color32::from_gray((40.0 + 215.0 * ((d - lo) / span).clamp(0.0, 1.0)) as u8)
                } else {
                    Color32::from_rgb(60, 0, 40)
                }
            })
            .collect();
        let features = if r.features_pca.len() == r.depth.len() {
            r.features_pca
                .iter()
                .map(|c| {
                    let [r, g, b] = c.map(|v| (v.clamp(0.0, 1.0) * 255.0 + 0.5) as u8);
                    Color32::from_rgb(r, g, b)
                })
                .collect()
        } else {
            vec![Color32::GRAY; r.depth.len()]
        };
        let tex = |name: &str, pixels: Vec<Color32>, options| {
            ctx.load_texture(format!("rendered {name}"), ColorImage::new(size, pixels), options)
        };
        // A coarse render is enlarged a lot: NEAREST shows its pixels for what they are.
        let smooth = if coarse {
            TextureOptions::NEAREST
        } else {
            TextureOptions::LINEAR
        };
        RenderedTextures {
            frame,
            step,
            coarse,
            labelled,
            // NEAREST keeps class boundaries crisp when zoomed in.
            mask: tex("mask", mask, TextureOptions::NEAREST),
            confidence: tex("confidence", confidence, TextureOptions::NEAREST),
            rgb: tex("colour", rgb, smooth),
            depth: tex("depth", depth, smooth),
            features: tex("features", features, smooth),
        }
    }
}
