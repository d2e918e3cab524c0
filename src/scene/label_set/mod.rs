//! The labels a scene carries: the versioned `labels.json` data model (classes, frames,
//! strokes, the limits on input from outside) and its rasterization into per-pixel class ids.
//! It lives in `scene` because a scene (and its archive, and the importers that turn
//! ground-truth masks into scribbles) holds labels; `labels` builds the annotating logic on it
//! and re-exports these names.
mod format;
mod raster;

pub(crate) use format::check_stroke;
pub use format::limits;
pub use format::{ClassInfo, FrameLabels, LABELS_FORMAT, LABELS_VERSION, LabelSet, Stroke};
pub use raster::{UNLABELLED, mask_to_strokes, rasterize_frame};
