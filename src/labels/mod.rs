//! Annotations: strokes of a class drawn on a frame with a round brush, or erasing strokes.
//! The same model serves the CLI, the archive's shipped labels and the app.
mod format;
mod raster;

pub use format::{ClassInfo, FrameLabels, LabelSet, Stroke, LABELS_FORMAT, LABELS_VERSION};
pub use raster::{mask_to_strokes, rasterize_frame, UNLABELLED};
