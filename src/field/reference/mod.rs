//! The CPU reference of the training step: the spec the GPU kernels are tested against.
//!
//! One module per stage, each with a forward function and, where the stage has parameters or
//! sits between parameters and the loss, a vector-Jacobian backward. Every function is
//! generic over [`Real`] (`f32` to compare with the GPU, `f64` for finite-difference checks)
//! and works on one position, sample or ray, so a GPU twin can be tested stage by stage.
pub mod activations;
pub mod adam;
pub mod frequency;
pub mod hash_grid;
pub mod loss;
pub mod mlp;
pub mod model;
pub mod real;
pub mod render;
pub mod sampling;
pub mod sh;

#[cfg(test)]
mod gradcheck;
#[cfg(test)]
mod model_tests;

pub use adam::Adam;
pub use loss::{LossTerms, RayTarget};
pub use model::{FieldModel, FieldRows, SampledRay, TrainingRay};
pub use real::Real;
pub use render::Channels;
pub use sampling::Ray;
