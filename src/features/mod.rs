//! Dense image features for the archive (docs/features.md): an extractor turns each frame into a
//! feature map, the autoencoder compresses all frames' maps to 64-d codes, and a PCA of the
//! codes is kept for display. Everything here runs on the CPU: in the native packer, and in the
//! page, which packs captures with the weight-free baseline only (`pack.rs`); the networks and
//! their weight files are native only (their dense layers use native kernels, and their weights
//! are far too large to download into a page).
mod autoencoder;
mod bake;
mod baseline;
#[cfg(not(target_arch = "wasm32"))]
pub mod checkpoint;
#[cfg(not(target_arch = "wasm32"))]
pub mod dino;
#[cfg(test)]
mod dino_vectors;
#[cfg(not(target_arch = "wasm32"))]
pub mod efficientnet;
mod error;
mod map;
#[cfg(not(target_arch = "wasm32"))]
mod npy;
#[cfg(not(target_arch = "wasm32"))]
pub mod ops;
pub mod pack;
#[cfg(not(target_arch = "wasm32"))]
mod pickle;
#[cfg(not(target_arch = "wasm32"))]
pub mod pth;
#[cfg(test)]
mod pth_writer;
#[cfg(not(target_arch = "wasm32"))]
pub mod softmax;
#[cfg(not(target_arch = "wasm32"))]
mod upscale;
#[cfg(not(target_arch = "wasm32"))]
pub mod vit;
#[cfg(not(target_arch = "wasm32"))]
mod weights;

pub use autoencoder::{Autoencoder, AutoencoderConfig, FitReport};
pub use bake::{BakeOptions, BakeProgress, Baked, bake, bake_pausing};
pub use baseline::Baseline;
#[cfg(not(target_arch = "wasm32"))]
pub use efficientnet::{EfficientNetConfig, EfficientNetExtractor, EfficientNetLite0};
pub use error::FeatureError;
pub use map::FeatureMap;
#[cfg(not(target_arch = "wasm32"))]
pub use npy::{NpyLayout, npy_path_of_frame, parse_npy_map, read_npy_map, write_npy_f32};
#[cfg(not(target_arch = "wasm32"))]
pub use upscale::{Upscaled, upscale_factor};

use image::RgbImage;

/// Something that turns one RGB frame into a dense feature map.
pub trait Extractor {
    /// A short description for the archive's provenance, e.g. `efficientnet-lite0 groups 2,3,4`.
    fn describe(&self) -> String;
    /// Features of one frame on a grid coarser than (or equal to) the image.
    fn extract(&self, rgb: &RgbImage) -> Result<FeatureMap, FeatureError>;
}
