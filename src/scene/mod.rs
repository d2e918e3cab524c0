//! Scenes: the in-memory scene (`decoded`) with the labels it carries (`label_set`), the
//! `*.scene.zip` archive that carries it, and the importers
//! that build one from captures in other layouts.
pub mod archive;
pub mod camera;
pub mod decoded;
pub mod demo;
pub mod error;
pub mod guide;
pub mod import;
pub mod label_set;
pub mod manifest;
pub mod pca;
pub mod private_paths;
pub mod resample;

pub use archive::{read_archive, read_archive_path, write_archive, write_archive_path};
pub use camera::{Bounds, Intrinsics, Pose};
pub use decoded::{DepthImage, FeatureCodes, Frame, GT_VOID, Scene};
pub use error::{Result, SceneError};
pub use guide::Guide;
pub use manifest::{Pca, Provenance};
