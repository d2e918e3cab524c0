//! Measuring masks against ground truth, and (natively) training headless to measure a config.
#[cfg(not(target_arch = "wasm32"))]
pub mod headless;
pub mod metrics;

pub use metrics::{Confusion, EvalReport};
