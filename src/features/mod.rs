//! Dense image features for the archive (DESIGN §4): an extractor turns each frame into a
//! feature map, the autoencoder compresses all frames' maps to 64-d codes, and a PCA of the
//! codes is kept for display. Everything here runs on the CPU in the native packer.
pub mod dino;
pub mod efficientnet;
mod error;
mod map;
pub mod ops;
pub mod safetensors;

pub use efficientnet::{EfficientNetConfig, EfficientNetExtractor, EfficientNetLite0};
pub use error::FeatureError;
pub use map::FeatureMap;

use image::RgbImage;

/// Something that turns one RGB frame into a dense feature map.
pub trait Extractor {
    /// A short description for the archive's provenance, e.g. `efficientnet-lite0 groups 2,3,4`.
    fn describe(&self) -> String;
    /// Features of one frame on a grid coarser than (or equal to) the image.
    fn extract(&self, rgb: &RgbImage) -> Result<FeatureMap, FeatureError>;
}
