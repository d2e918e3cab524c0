//! Native only: the device GPU tests run on. Without any adapter the tests skip loudly, so
//! `cargo test` passes on a machine without Vulkan; set `SCRIBBLEFIELD_REQUIRE_GPU=1` (CI, any
//! machine with lavapipe) to turn that skip into a failure.
use super::context::{GpuContext, GpuOptions};
use super::error::GpuError;

/// Environment variable that makes a missing adapter fail the tests instead of skipping them.
pub const REQUIRE_GPU_ENV: &str = "SCRIBBLEFIELD_REQUIRE_GPU";

/// The adapter chosen by [`GpuOptions::from_env`], or `None` (after a loud message) when the
/// machine has none. Panics when the adapter exists but will not open, or when
/// `SCRIBBLEFIELD_REQUIRE_GPU` is set and there is no adapter: both are real failures.
pub fn gpu_for_tests(test: &str) -> Option<GpuContext> {
    match GpuContext::new_blocking(&GpuOptions::from_env()) {
        Ok(ctx) => {
            eprintln!("{test}: running on {}", ctx.describe());
            Some(ctx)
        }
        Err(error @ GpuError::NoAdapter { .. }) => {
            let required = std::env::var(REQUIRE_GPU_ENV).is_ok_and(|value| !value.is_empty() && value != "0");
            assert!(!required, "{test}: {REQUIRE_GPU_ENV} is set but {error}");
            eprintln!("\n!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!");
            eprintln!("!!! SKIPPING GPU TEST {test}: {error}");
            eprintln!("!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!!\n");
            None
        }
        Err(error) => panic!("{test}: {error}"),
    }
}
