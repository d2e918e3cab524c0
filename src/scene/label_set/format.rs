//! The versioned `labels.json` format.
use serde::{Deserialize, Serialize};

use crate::scene::error::{Result, SceneError};

pub const LABELS_FORMAT: &str = "scribblefield-labels";
pub const LABELS_VERSION: u32 = 1;

/// Limits on labels from outside (labels.json, an archive, a share link, an autosave), all
/// enforced by [`LabelSet::check`]. Rasterizing a stroke costs about its points times the
/// brush's square, and the page rasterizes labels on every load and edit: these keep a hostile
/// file or link from freezing it. docs/limits.md lists them.
pub mod limits {
    /// Largest brush radius in pixels; the annotator's brush (`labels::brush::MAX_RADIUS`) is
    /// this, so anything it draws passes.
    pub const MAX_RADIUS: f32 = 200.0;
    /// Points in one stroke. The annotator records a point per few pixels of drag, so a stroke
    /// across an 8192-pixel frame and back stays far below this.
    pub const MAX_POINTS_PER_STROKE: usize = 65_536;
    /// Points over all strokes of all frames (8 MiB of coordinates). Scribble masks imported as
    /// strokes use two points per run of pixels in a row, so sparse scribbles on hundreds of
    /// frames fit.
    pub const MAX_TOTAL_POINTS: usize = 1 << 20;
}
use limits::{MAX_POINTS_PER_STROKE, MAX_RADIUS, MAX_TOTAL_POINTS};

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

/// Checks stroke `index` of `frame` against the class count (when given) and the limits, adding its points
/// to `total_points`; the problem, naming frame and stroke, otherwise. Shared with the share-link
/// decoder, which checks as it decodes so a hostile link is refused before it is built whole.
pub(crate) fn check_stroke(
    s: &Stroke,
    frame: u32,
    index: usize,
    classes: Option<usize>,
    total_points: &mut usize,
) -> std::result::Result<(), String> {
    let at = format!("frame {frame} stroke {index}");
    if let (Some(c), Some(classes)) = (s.class, classes)
        && c as usize >= classes
    {
        return Err(format!("{at}: class {c} but only {classes} classes are defined"));
    }
    if !(s.radius.is_finite() && s.radius > 0.0 && s.radius <= MAX_RADIUS) {
        return Err(format!(
            "{at}: brush radius {} is not in (0, {MAX_RADIUS}] (the brush's largest)",
            s.radius
        ));
    }
    if s.points.is_empty() {
        return Err(format!("{at}: has no points"));
    }
    if s.points.len() > MAX_POINTS_PER_STROKE {
        return Err(format!(
            "{at}: {} points, more than the limit of {MAX_POINTS_PER_STROKE} per stroke",
            s.points.len()
        ));
    }
    *total_points += s.points.len();
    if *total_points > MAX_TOTAL_POINTS {
        return Err(format!(
            "{at}: brings the points of all strokes past the limit of {MAX_TOTAL_POINTS}"
        ));
    }
    if s.points.iter().flatten().any(|v| !v.is_finite()) {
        return Err(format!("{at}: has non-finite coordinates"));
    }
    Ok(())
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
        let mut seen = std::collections::HashSet::new();
        let mut total_points = 0usize;
        for fl in &self.frames {
            if fl.frame >= frame_count {
                return Err(SceneError::invalid(
                    file,
                    format!("labels for frame {} but the scene has {frame_count} frames", fl.frame),
                ));
            }
            // Two entries for one frame would be merged by some readers and not others.
            if !seen.insert(fl.frame) {
                return Err(SceneError::invalid(
                    file,
                    format!(
                        "frame {} has more than one entry; each frame's strokes must be in one entry",
                        fl.frame
                    ),
                ));
            }
            for (i, s) in fl.strokes.iter().enumerate() {
                check_stroke(s, fl.frame, i, Some(self.classes.len()), &mut total_points)
                    .map_err(|p| SceneError::invalid(file, p))?;
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
