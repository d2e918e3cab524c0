//! The versioned `labels.json` format.
use serde::{Deserialize, Serialize};

use crate::scene::error::{Result, SceneError};

pub const LABELS_FORMAT: &str = "scribblefield-labels";
pub const LABELS_VERSION: u32 = 1;

/// Largest brush radius accepted from a file, in pixels; more is surely a corrupt value.
const MAX_RADIUS: f32 = 4096.0;

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ClassInfo {
    pub name: String,
    /// sRGB display colour.
    pub color: [u8; 3],
}

/// A polyline swept by a round brush. `class: None` erases.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Stroke {
    pub class: Option<u16>,
    /// Brush radius in pixels of the frame at full resolution.
    pub radius: f32,
    /// Pixel coordinates (x, y); (0.5, 0.5) is the centre of the top-left pixel.
    pub points: Vec<[f32; 2]>,
}

#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct FrameLabels {
    pub frame: u32,
    /// Applied in order: later strokes paint over (or erase) earlier ones.
    pub strokes: Vec<Stroke>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LabelSet {
    pub format: String,
    pub version: u32,
    pub classes: Vec<ClassInfo>,
    pub frames: Vec<FrameLabels>,
}

impl Default for LabelSet {
    fn default() -> Self {
        LabelSet {
            format: LABELS_FORMAT.into(),
            version: LABELS_VERSION,
            classes: vec![],
            frames: vec![],
        }
    }
}

impl LabelSet {
    pub fn new(classes: Vec<ClassInfo>) -> Self {
        LabelSet {
            classes,
            ..Default::default()
        }
    }

    pub fn to_json(&self) -> String {
        serde_json::to_string_pretty(self).expect("labels always serialize")
    }

    /// Parses and checks a labels file against a scene with `frame_count` frames; `file` names
    /// the source in errors.
    pub fn from_json(text: &[u8], file: &str, frame_count: u32) -> Result<LabelSet> {
        let set: LabelSet = serde_json::from_slice(text).map_err(|source| SceneError::Json {
            file: file.into(),
            source,
        })?;
        set.check(file, frame_count)?;
        Ok(set)
    }

    pub fn check(&self, file: &str, frame_count: u32) -> Result<()> {
        if self.format != LABELS_FORMAT {
            return Err(SceneError::invalid(
                file,
                format!("format is {:?}, expected {LABELS_FORMAT:?}", self.format),
            ));
        }
        if self.version != LABELS_VERSION {
            return Err(SceneError::invalid(
                file,
                format!(
                    "unsupported labels version {} (this build reads version {LABELS_VERSION})",
                    self.version
                ),
            ));
        }
        if self.classes.len() > u16::MAX as usize {
            return Err(SceneError::invalid(
                file,
                format!("{} classes is too many", self.classes.len()),
            ));
        }
        for fl in &self.frames {
            if fl.frame >= frame_count {
                return Err(SceneError::invalid(
                    file,
                    format!("labels for frame {} but the scene has {frame_count} frames", fl.frame),
                ));
            }
            for (i, s) in fl.strokes.iter().enumerate() {
                let at = format!("frame {} stroke {i}", fl.frame);
                if let Some(c) = s.class
                    && c as usize >= self.classes.len()
                {
                    return Err(SceneError::invalid(
                        file,
                        format!("{at}: class {c} but only {} classes are defined", self.classes.len()),
                    ));
                }
                if !(s.radius.is_finite() && s.radius > 0.0 && s.radius <= MAX_RADIUS) {
                    return Err(SceneError::invalid(
                        file,
                        format!("{at}: brush radius {} is not in (0, {MAX_RADIUS}]", s.radius),
                    ));
                }
                if s.points.is_empty() {
                    return Err(SceneError::invalid(file, format!("{at}: has no points")));
                }
                if s.points.iter().flatten().any(|v| !v.is_finite()) {
                    return Err(SceneError::invalid(file, format!("{at}: has non-finite coordinates")));
                }
            }
        }
        Ok(())
    }

    /// Strokes of one frame, if any.
    pub fn frame(&self, frame: u32) -> Option<&FrameLabels> {
        self.frames.iter().find(|f| f.frame == frame)
    }

    /// Appends a stroke to a frame, creating its entry if needed.
    pub fn push_stroke(&mut self, frame: u32, stroke: Stroke) {
        match self.frames.iter_mut().find(|f| f.frame == frame) {
            Some(f) => f.strokes.push(stroke),
            None => {
                self.frames.push(FrameLabels {
                    frame,
                    strokes: vec![stroke],
                });
                self.frames.sort_by_key(|f| f.frame);
            }
        }
    }
}
