//! Annotations: strokes of a class drawn on a frame with a round brush, or erasing strokes.
//! The same model serves the CLI, the archive's shipped labels and the app. The annotator's
//! plain logic lives here too, so it is tested natively: undo history, the share-link codec,
//! autosave entries, brush strokes from pointer drags and the canvas's zoom maths
//! (`canvas_zoom`). The labels' data model itself (`LabelSet` and its rasterization) lives in
//! `scene::label_set`, because a scene carries labels; it is re-exported here.
pub mod autosave;
pub mod brush;
pub mod canvas_zoom;
pub mod history;
pub mod scale;
pub mod share;
pub mod snapshots;
pub mod summary;
pub mod synthetic;

// The data model lives in `scene` (a scene holds labels); re-exported so the annotating code
// and the rest of the crate name it as `labels::LabelSet`.
pub use crate::scene::label_set::limits;
pub use crate::scene::label_set::{
    ClassInfo, FrameLabels, LABELS_FORMAT, LABELS_VERSION, LabelSet, Stroke, UNLABELLED, mask_to_strokes,
    rasterize_frame,
};
