//! Exporting masks: one class-id PNG per frame, colour previews, the class manifest and the
//! annotations, as a folder (CLI) or a zip made in memory (browser download). Both have the same
//! layout, and `read_masks` reads either back for evaluation. The formats others load (the
//! CVAT / PASCAL VOC layout, COCO with RLE, a labelled point cloud) and autolabel's
//! object-count cleanup are in modules of their own.
pub mod coco;
mod error;
mod masks;
pub mod names;
pub mod objects;
mod options;
pub mod ply;
pub mod rle;
pub mod voc;

pub use error::ExportError;
pub use masks::{MaskDirWriter, MaskSet, MasksManifest, read_masks, read_masks_zip};
pub use options::{ExportOptions, Format};

#[cfg(test)]
mod zip_contents_tests;
