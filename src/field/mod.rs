//! The neural field: config, parameter layout, CPU reference, GPU trainer, renderer.
//!
//! `reference` is the plain-Rust spec of every stage of the training step (forward and
//! backward); the GPU kernels are tested against it, and it is proved by finite differences.
//!
//! Size of the default model (`FieldConfig::default()`, C classes): hash table
//! (17³ + 33³ + 65³ + 13 × 2^19) × 2 = 14,262,438 values (the three coarse levels are dense,
//! sized to their vertices) + MLPs 24,064 (density) + 20,736 (colour) + 9,152 (feature) +
//! 5,056 + 64·C (semantic), i.e. 14,321,574 f32 (≈ 55 MiB) for C = 2. The trainer keeps four
//! buffers of that length (parameters, gradient, Adam m and v).
pub mod bf16;
pub mod config;
pub mod params;
pub mod presets;
pub mod reference;
pub mod run_config;

pub use config::{AdamConfig, ConfigError, Encoding, FieldConfig, LastSample, LossWeights, SemanticInput};
pub use params::{MlpLayout, ParamLayout};
pub use presets::{Preset, Runner};
pub use run_config::{Finished, finish};
pub mod gpu;
