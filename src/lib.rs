//! scribblefield: scribbles on a few RGB-D frames, propagated to dense masks by a neural field.
pub mod adam;
pub mod app;
pub mod bounded_read;
pub mod colors;
pub mod dense;
pub mod eval;
pub mod export;
pub mod features;
pub mod field;
#[cfg(not(target_arch = "wasm32"))]
#[doc(hidden)]
pub mod fuzzing;
pub mod gpu;
pub mod labels;
#[cfg(test)]
mod module_layers;
pub mod pause;
pub mod percent;
pub mod refine;
pub mod rng;
// Weights files and trainer checkpoints: native only (the page reads neither).
#[cfg(not(target_arch = "wasm32"))]
pub mod safetensors;
#[cfg(not(target_arch = "wasm32"))]
pub mod saved_field;
pub mod scene;
#[cfg(not(target_arch = "wasm32"))]
pub mod serve;
pub mod spread;
#[cfg(target_arch = "wasm32")]
mod web;
