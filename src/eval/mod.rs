//! Measuring masks against ground truth, and (natively) training headless to measure a config:
//! the simulated user, the ablation's curves, tables and plots.
pub mod ablation;
pub mod bench;
pub mod curves;
#[cfg(not(target_arch = "wasm32"))]
pub mod headless;
pub mod metrics;
pub mod plot;
#[cfg(not(target_arch = "wasm32"))]
pub mod simulate;
#[cfg(not(target_arch = "wasm32"))]
pub mod source_size;
#[cfg(not(target_arch = "wasm32"))]
pub mod suite;

pub use metrics::{Confusion, EvalReport};
