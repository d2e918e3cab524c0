//! Exporting masks: one class-id PNG per frame, colour previews, the class manifest and the
//! annotations, as a folder (CLI) or a zip made in memory (browser download). Both have the same
//! layout, and `read_masks` reads either back for evaluation.
mod masks;

pub use masks::{MaskDirWriter, MaskSet, MasksManifest, read_masks, read_masks_zip};

#[cfg(test)]
mod zip_contents_tests;
