//! Exporting masks as a folder (CLI) or a zip made in memory (browser download), both with the
//! same layout: one class-id PNG per frame by index and by the frame's name in its capture,
//! colour previews, the class manifest and the annotations, and on request the CVAT / PASCAL
//! VOC layout, COCO JSON with RLE, a labelled point cloud, the masks over their frames as an
//! animated PNG, and autolabel's object-count cleanup. `read_masks` reads either back for
//! evaluation.
pub mod animation;
pub mod coco;
mod error;
mod manifest;
mod masks;
pub mod names;
pub mod objects;
mod options;
pub mod ply;
pub mod rle;
pub mod voc;
mod writer;

pub use error::ExportError;
pub use manifest::MasksManifest;
pub use masks::{MaskDirWriter, MaskSet, read_masks, read_masks_zip, zip_files};
pub use options::{ExportOptions, Format};
pub use writer::{BY_NAME_DIR, ExportWriter, MANIFEST};

#[cfg(test)]
mod formats_tests;
#[cfg(test)]
mod zip_contents_tests;
