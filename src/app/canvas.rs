//! The frame canvas: the frame with its overlays, zoomed and panned, and the pointer turned into
//! brush strokes. Left button draws (or erases), right or middle button pans, the wheel zooms
//! about the pointer.
//!
//! Pointer events are read in order from the frame's event list rather than as one position per
//! repaint: on a slow device one repaint can cover many moves, and a stroke should follow all of
//! them.
use egui::{Color32, Event, PointerButton, Pos2, Rect, Sense, Stroke as Line, TextureHandle, pos2, vec2};

use crate::labels::Stroke;
use crate::labels::brush::StrokeBuilder;
use crate::labels::canvas_zoom::{ScreenRect, ViewTransform};

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Tool {
    Brush,
    Eraser,
}

/// What the left button does now.
pub struct Brush {
    pub tool: Tool,
    pub class: u16,
    pub color: Color32,
    /// Radius in frame pixels.
    pub radius: f32,
}

/// An image drawn over the frame, with its opacity.
pub struct Layer<'a> {
    pub texture: &'a TextureHandle,
    pub opacity: f32,
}

pub struct CanvasOutput {
    /// A stroke the user just finished.
    pub finished: Option<Stroke>,
    /// Where the frame is on screen.
    pub image_rect: Rect,
}

fn screen_rect(r: Rect) -> ScreenRect {
    ScreenRect {
        min: [r.min.x, r.min.y],
        size: [r.width(), r.height()],
    }
}

fn to_pos(p: [f32; 2]) -> Pos2 {
    pos2(p[0], p[1])
}

/// Shows the canvas filling the space left in `ui`.
pub fn show(
    ui: &mut egui::Ui,
    view: &mut ViewTransform,
    frame: &TextureHandle,
    layers: &[Layer<'_>],
    brush: &Brush,
    drawing: &mut Option<StrokeBuilder>,
) -> CanvasOutput {
    let (rect, response) = ui.allocate_exact_size(ui.available_size(), Sense::click_and_drag());
    let viewport = screen_rect(rect);
    let (width, height) = (view.image[0] as u32, view.image[1] as u32);
    let mut finished = None;

    // Pan with the right or middle button.
    if response.dragged_by(PointerButton::Secondary) || response.dragged_by(PointerButton::Middle) {
        let d = response.drag_delta();
        view.pan_by(&viewport, [d.x, d.y]);
    }
    // Zoom with the wheel (or pinch / ctrl+wheel) about the pointer.
    if let Some(hover) = response.hover_pos() {
        let (scroll, zoom) = ui.input(|i| (i.smooth_scroll_delta.y, i.zoom_delta()));
        let factor = (scroll * 0.003).exp() * zoom;
        if (factor - 1.0).abs() > 1e-4 {
            view.zoom_about(&viewport, [hover.x, hover.y], factor);
        }
    }

    // Draw with the left button: every press, move and release of this frame, in order.
    let events = ui.input(|i| i.events.clone());
    let class = (brush.tool == Tool::Brush).then_some(brush.class);
    // Not where a window or popup (a colour picker) lies over the canvas. Asked of the layers
    // rather than of `response.hovered()`: on a slow page a whole press-move-release can arrive
    // in one pass, and the hover state then depends on the previous pass's layout.
    let on_canvas =
        |pos: Pos2| rect.contains(pos) && ui.ctx().layer_id_at(pos).is_none_or(|layer| layer == ui.layer_id());
    for event in events {
        match event {
            Event::PointerButton {
                pos,
                button: PointerButton::Primary,
                pressed: true,
                ..
            } if drawing.is_none() && on_canvas(pos) && view.hits_image(&viewport, [pos.x, pos.y]) => {
                let at = view.to_image(&viewport, [pos.x, pos.y]);
                *drawing = Some(StrokeBuilder::new(class, brush.radius, width, height, at));
            }
            Event::PointerMoved(pos) => {
                if let Some(b) = drawing.as_mut() {
                    b.extend(view.to_image(&viewport, [pos.x, pos.y]));
                }
            }
            Event::PointerButton {
                pos,
                button: PointerButton::Primary,
                pressed: false,
                ..
            } => {
                if let Some(mut b) = drawing.take() {
                    b.extend(view.to_image(&viewport, [pos.x, pos.y]));
                    finished = Some(b.finish());
                }
            }
            // The pointer left the page with the button down: keep what was drawn.
            Event::PointerGone => {
                if let Some(b) = drawing.take() {
                    finished = Some(b.finish());
                }
            }
            _ => {}
        }
    }

    let painter = ui.painter_at(rect);
    let image = view.image_rect(&viewport);
    let image_rect = Rect::from_min_size(to_pos(image.min), vec2(image.size[0], image.size[1]));
    let uv = Rect::from_min_max(pos2(0.0, 0.0), pos2(1.0, 1.0));
    painter.rect_filled(rect, 0.0, Color32::from_gray(24));
    painter.image(frame.id(), image_rect, uv, Color32::WHITE);
    for layer in layers {
        painter.image(
            layer.texture.id(),
            image_rect,
            uv,
            Color32::WHITE.gamma_multiply(layer.opacity.clamp(0.0, 1.0)),
        );
    }
    let scale = view.scale(&viewport);
    if let Some(b) = drawing.as_ref() {
        draw_stroke(&painter, view, &viewport, b.stroke(), stroke_color(brush), scale);
    }
    if let Some(stroke) = finished.as_ref() {
        // Drawn once more this frame so the stroke does not flicker before its texture exists.
        draw_stroke(&painter, view, &viewport, stroke, stroke_color(brush), scale);
    }
    // The brush outline where the pointer is.
    if let Some(hover) = response.hover_pos() {
        let ring = if brush.tool == Tool::Eraser {
            Color32::WHITE
        } else {
            brush.color
        };
        painter.circle_stroke(hover, brush.radius * scale, Line::new(1.5, ring));
        painter.circle_stroke(hover, brush.radius * scale + 1.5, Line::new(1.0, Color32::BLACK));
    }
    CanvasOutput { finished, image_rect }
}

fn stroke_color(brush: &Brush) -> Color32 {
    match brush.tool {
        Tool::Brush => brush.color.gamma_multiply(0.85),
        Tool::Eraser => Color32::from_white_alpha(90),
    }
}

fn draw_stroke(
    painter: &egui::Painter,
    view: &ViewTransform,
    viewport: &ScreenRect,
    stroke: &Stroke,
    color: Color32,
    scale: f32,
) {
    let r = stroke.radius * scale;
    let points: Vec<Pos2> = stroke
        .points
        .iter()
        .map(|&p| to_pos(view.to_screen(viewport, p)))
        .collect();
    for p in &points {
        painter.circle_filled(*p, r, color);
    }
    for w in points.windows(2) {
        painter.line_segment([w[0], w[1]], Line::new(2.0 * r, color));
    }
}
