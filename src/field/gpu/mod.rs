//! The GPU twin of `reference`: one WGSL kernel per stage, each wrapped by a pass that owns its
//! pipeline and bind groups, and tested against the CPU reference on lavapipe.
//!
//! Buffers shared between passes are sample-major: with B rays of S samples, sample `n = ray·S + s`
//! owns row `n` of every per-sample buffer (positions, encodings, the density MLP's activations
//! and gradients), except the heads' buffers: those hold the samples `keep` kept, packed in
//! sample order (`keep::HeadRows`: `rows` maps a packed row to its sample, `slot` a sample to its
//! packed row). Parameters, gradients and Adam moments are the flat layout of
//! `field::params::ParamLayout`, bound whole; a pass is told the offset of its range.
pub mod adam;
pub mod composite;
pub mod dense;
pub mod encoding;
pub mod fixed_point;
pub mod head_glue;
pub mod keep;
pub mod rays;
pub mod row_view;
pub mod scene_buffers;
pub mod sh_encode;
pub mod stage;
pub mod trainer;
pub mod view;
