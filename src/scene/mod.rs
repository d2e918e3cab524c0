//! Scenes: the in-memory scene, the `*.scene.zip` archive that carries it, and the importers
//! that build one from captures in other layouts.
pub mod archive;
pub mod camera;
pub mod demo;
pub mod error;
pub mod import;
pub mod manifest;
pub mod pca;
// `scene::scene` reads oddly, but it is where the decoded Scene lives; everything else
// re-exports it as `scene::Scene`.
#[allow(clippy::module_inception)]
pub mod scene;

pub use archive::{read_archive, read_archive_path, write_archive, write_archive_path};
pub use camera::{Bounds, Intrinsics, Pose};
pub use error::{Result, SceneError};
pub use manifest::{Pca, Provenance};
pub use scene::{DepthImage, FeatureCodes, Frame, Scene};
