//! `scene.json`: the archive's manifest, as stored. See docs/scene-archive.md.
use serde::{Deserialize, Serialize};

use super::camera::{Bounds, Intrinsics};
use super::label_set::ClassInfo;

pub const SCENE_FORMAT: &str = "scribblefield-scene";
pub const SCENE_VERSION: u32 = 1;
pub const MANIFEST_FILE: &str = "scene.json";

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Manifest {
    pub format: String,
    pub version: u32,
    pub frame_count: u32,
    pub width: u32,
    pub height: u32,
    pub intrinsics: Intrinsics,
    /// Metres per unit of the stored depth PNGs (0.001: millimetres).
    pub depth_scale: f64,
    pub bounds: Bounds,
    pub frames: Vec<FrameEntry>,
    #[serde(default)]
    pub features: Option<FeatureEntry>,
    /// Class names and colours, when known (from ground truth or shipped labels).
    #[serde(default)]
    pub classes: Vec<ClassInfo>,
    /// Archive path of shipped annotations, if any.
    #[serde(default)]
    pub labels: Option<String>,
    #[serde(default)]
    pub provenance: Provenance,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FrameEntry {
    pub rgb: String,
    #[serde(default)]
    pub depth: Option<String>,
    #[serde(default)]
    pub gt: Option<String>,
    /// Camera-to-world, OpenCV camera axes, row-major.
    pub pose: [f64; 16],
    /// Name of the frame in the capture it came from.
    #[serde(default)]
    pub source: Option<String>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FeatureEntry {
    pub file: String,
    pub height: u32,
    pub width: u32,
    pub dim: u32,
    /// What produced the features (extractor and autoencoder), for people.
    #[serde(default)]
    pub extractor: String,
    pub pca: Pca,
}

/// A 3-component projection of the feature codes for display:
/// `rgb_k = (dot(code - mean, components[k]) - lo[k]) / (hi[k] - lo[k])`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Pca {
    pub mean: Vec<f32>,
    pub components: [Vec<f32>; 3],
    pub lo: [f32; 3],
    pub hi: [f32; 3],
}

#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Provenance {
    /// Where the capture came from (a path or a name).
    #[serde(default)]
    pub source: String,
    /// Which importer (or generator) made the archive.
    #[serde(default)]
    pub importer: String,
    /// The tool and version that wrote the archive.
    #[serde(default)]
    pub tool: String,
    /// Anything a user should know (skipped frames, resizing, ...).
    #[serde(default)]
    pub notes: Vec<String>,
}
