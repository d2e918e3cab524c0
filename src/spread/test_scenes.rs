//! What the spreading tests share: a small demo scene and strokes of one dot each.
use crate::labels::{ClassInfo, LabelSet, Stroke};
use crate::scene::Scene;
use crate::scene::demo::{DemoOptions, demo_scene};

/// The demo at 32 x 24 with `frames` frames (dense depth).
pub fn small_demo(frames: u32) -> Scene {
    demo_scene(&DemoOptions {
        width: 32,
        height: 24,
        frames,
        ..DemoOptions::default()
    })
    .expect("the demo scene builds")
}

/// A label set with one class per name, unnamed colours, and no strokes.
pub fn classes(names: &[&str]) -> LabelSet {
    LabelSet::new(
        names
            .iter()
            .map(|name| ClassInfo {
                name: (*name).into(),
                color: [0, 0, 0],
            })
            .collect(),
    )
}

/// A stroke of class `class` that is one dot of radius 1 at (`x`, `y`).
pub fn dot(class: u16, x: f32, y: f32) -> Stroke {
    Stroke {
        class: Some(class),
        radius: 1.0,
        points: vec![[x, y]],
    }
}
