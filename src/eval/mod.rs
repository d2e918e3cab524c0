//! Measuring masks against ground truth.
pub mod metrics;

pub use metrics::{Confusion, EvalReport};
