//! Annotations: strokes of a class drawn on a frame with a round brush, or erasing strokes.
//! The same model serves the CLI, the archive's shipped labels and the app. The annotator's
//! plain logic lives here too, so it is tested natively: undo history, the share-link codec,
//! autosave entries, brush strokes from pointer drags and the canvas's view maths.
pub mod autosave;
pub mod brush;
mod format;
pub mod history;
mod raster;
pub mod scale;
pub mod share;
pub mod summary;
pub mod synthetic;
pub mod view;

pub use format::limits;
pub use format::{ClassInfo, FrameLabels, LABELS_FORMAT, LABELS_VERSION, LabelSet, Stroke};
pub use raster::{UNLABELLED, mask_to_strokes, rasterize_frame};
