//! Annotations: strokes of a class drawn on a frame with a round brush, or erasing strokes.
//! The same model serves the CLI, the archive's shipped labels and the app.
mod format;
mod raster;
pub mod synthetic;

pub use format::{ClassInfo, FrameLabels, LABELS_FORMAT, LABELS_VERSION, LabelSet, Stroke};
pub use raster::{UNLABELLED, mask_to_strokes, rasterize_frame};
