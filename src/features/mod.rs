//! Dense image features for the archive (docs/features.md): an extractor turns each frame into a
//! feature map, the autoencoder compresses all frames' maps to 64-d codes, and a PCA of the
//! codes is kept for display. Everything here runs on the CPU in the native packer.
mod autoencoder;
mod bake;
mod baseline;
pub mod checkpoint;
pub mod dino;
#[cfg(test)]
mod dino_vectors;
pub mod efficientnet;
mod error;
mod map;
mod npy;
pub mod ops;
mod pickle;
pub mod pth;
#[cfg(test)]
mod pth_writer;
pub mod safetensors;
pub mod softmax;
mod upscale;
pub mod vit;
mod weights;

pub use autoencoder::{Autoencoder, AutoencoderConfig, FitReport};
pub use bake::{BakeOptions, BakeProgress, Baked, bake};
pub use baseline::Baseline;
pub use efficientnet::{EfficientNetConfig, EfficientNetExtractor, EfficientNetLite0};
pub use error::FeatureError;
pub use map::FeatureMap;
pub use npy::{NpyLayout, npy_path_of_frame, parse_npy_map, read_npy_map, write_npy_f32};
pub use upscale::{Upscaled, upscale_factor};

use image::RgbImage;

/// Something that turns one RGB frame into a dense feature map.
pub trait Extractor {
    /// A short description for the archive's provenance, e.g. `efficientnet-lite0 groups 2,3,4`.
    fn describe(&self) -> String;
    /// Features of one frame on a grid coarser than (or equal to) the image.
    fn extract(&self, rgb: &RgbImage) -> Result<FeatureMap, FeatureError>;
}
