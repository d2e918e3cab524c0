//! How the document is looked at: the frame shown, zoom and pan, the layers over the frame,
//! the tool and brush, and the textures they are drawn from. Nothing here changes the labels:
//! the canvas hands a finished stroke back to the annotator.
use super::super::canvas::{self, Brush, Layer, Tool};
use super::super::frame_view::{FrameTextures, class_overlay};
use super::super::overlays::{self, RenderedTextures};
use super::super::palette::color_of;
use super::document::Document;
use crate::labels::Stroke;
use crate::labels::brush::{MAX_RADIUS, MIN_RADIUS, StrokeBuilder};
use crate::labels::canvas_zoom::ViewTransform;

/// What is drawn over the frame.
pub struct Layers {
    pub mask: bool,
    pub mask_opacity: f32,
    pub confidence: bool,
    pub ground_truth: bool,
    pub scribbles: bool,
}

pub struct View {
    /// The frame shown.
    pub frame: usize,
    pub zoom: ViewTransform,
    pub layers: Layers,
    pub tool: Tool,
    /// The class the brush paints.
    pub class: u16,
    /// Brush radius, frame pixels.
    pub radius: f32,
    drawing: Option<StrokeBuilder>,
    frame_textures: Option<FrameTextures>,
    /// The scribbles of (frame, labels version).
    scribbles: Option<(usize, u64, egui::TextureHandle)>,
    /// The field's latest render (of whichever frame it was).
    pub rendered: Option<RenderedTextures>,
    /// Where the frame was drawn (for the page status).
    pub image_rect: egui::Rect,
    /// Where the side panel drew the rendered features (for the page status).
    pub features_rect: Option<egui::Rect>,
    /// Widgets that use the arrow keys themselves while focused (sliders, the frame strip).
    pub arrow_key_widgets: Vec<egui::Id>,
}

impl View {
    pub fn new(doc: &Document) -> View {
        let scene = &doc.scene;
        // The first frame with scribbles is the natural place to continue.
        let frame = doc
            .labels
            .frames
            .iter()
            .find(|f| !f.strokes.is_empty())
            .map_or(0, |f| (f.frame as usize).min(doc.frame_count().saturating_sub(1)));
        View {
            frame,
            zoom: ViewTransform::new(scene.width, scene.height),
            layers: Layers {
                mask: true,
                mask_opacity: 0.45,
                confidence: false,
                ground_truth: false,
                scribbles: true,
            },
            tool: Tool::Brush,
            class: 0,
            radius: (scene.width.min(scene.height) as f32 * 0.03).clamp(2.0, 24.0).round(),
            drawing: None,
            frame_textures: None,
            scribbles: None,
            rendered: None,
            image_rect: egui::Rect::NOTHING,
            features_rect: None,
            arrow_key_widgets: Vec::new(),
        }
    }

    /// Shows `frame` (clamped to the scene).
    pub fn go_to(&mut self, frame: usize, frames: usize) {
        self.frame = frame.min(frames.saturating_sub(1));
    }

    /// Steps `by` frames (negative: back), within the scene.
    pub fn step(&mut self, by: isize, frames: usize) {
        self.frame = self.frame.saturating_add_signed(by).min(frames.saturating_sub(1));
    }

    /// Paints class `class` with the brush.
    pub fn select_class(&mut self, class: u16) {
        self.class = class;
        self.tool = Tool::Brush;
    }

    pub fn smaller_brush(&mut self) {
        self.radius = (self.radius / 1.25).max(MIN_RADIUS);
    }

    pub fn larger_brush(&mut self) {
        self.radius = (self.radius * 1.25).min(MAX_RADIUS);
    }

    /// The field's render of the frame shown, if there is one.
    pub fn rendered_here(&self) -> Option<&RenderedTextures> {
        self.rendered.as_ref().filter(|r| r.frame as usize == self.frame)
    }

    /// Draws the frame with its layers and returns a stroke the user has just finished.
    pub fn canvas(&mut self, ui: &mut egui::Ui, doc: &Document) -> Option<Stroke> {
        let scene = &doc.scene;
        if self.frame_textures.as_ref().is_none_or(|t| t.frame != self.frame) {
            self.frame_textures = FrameTextures::new(ui.ctx(), scene, self.frame);
        }
        let (w, h) = (scene.width, scene.height);
        if self
            .scribbles
            .as_ref()
            .is_none_or(|(f, v, _)| *f != self.frame || *v != doc.version)
        {
            let image = overlays::scribbles(doc.labels.frame(self.frame as u32), w, h, &doc.labels.classes);
            let texture = ui.ctx().load_texture("scribbles", image, egui::TextureOptions::NEAREST);
            self.scribbles = Some((self.frame, doc.version, texture));
        }
        let Some(frame_textures) = &self.frame_textures else {
            ui.label("This scene has no frames.");
            return None;
        };
        let opacity = self.layers.mask_opacity;
        let mut layers = Vec::new();
        let gt_texture;
        if self.layers.ground_truth
            && let Some(gt) = scene.frames[self.frame].gt.as_ref()
        {
            gt_texture = frame_textures.ground_truth.clone().unwrap_or_else(|| {
                ui.ctx()
                    .load_texture("gt", class_overlay(gt, &scene.classes), egui::TextureOptions::NEAREST)
            });
            layers.push(Layer {
                texture: &gt_texture,
                opacity,
            });
        }
        // Before the field has learnt classes from a stroke its mask is the semantic head's
        // random start: nothing to show over the frame.
        if let Some(r) = self
            .rendered
            .as_ref()
            .filter(|r| r.frame as usize == self.frame && r.labelled)
        {
            if self.layers.mask {
                layers.push(Layer {
                    texture: &r.mask,
                    opacity,
                });
            }
            if self.layers.confidence {
                layers.push(Layer {
                    texture: &r.confidence,
                    opacity: 1.0,
                });
            }
        }
        if self.layers.scribbles
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
            color: color_of(&doc.labels.classes, self.class),
            radius: self.radius,
        };
        let out = canvas::show(
            ui,
            &mut self.zoom,
            &frame_textures.rgb,
            &layers,
            &brush,
            &mut self.drawing,
        );
        self.image_rect = out.image_rect;
        out.finished
    }
}
