//! GPU plumbing shared by the trainer, the renderer and the bench: device creation, buffers and
//! readback, pipelines and dispatch, pass timing, and the matmul yardstick. Everything here runs
//! natively (Vulkan/Metal/DX12, lavapipe on CPU-only machines) and in the browser (WebGPU); the
//! few blocking helpers are native-only.
pub mod buffers;
pub mod context;
pub mod dispatch;
pub mod error;
pub mod matmul;
pub mod matmul_bench;
pub mod pipeline;
pub mod pipeline_cache;
pub mod profile;
#[cfg(not(target_arch = "wasm32"))]
pub mod shader_check;
pub mod shaders;
#[cfg(not(target_arch = "wasm32"))]
pub mod test_support;
pub mod timing;
#[cfg(not(target_arch = "wasm32"))]
pub mod uniform_layout;

pub use context::{GpuContext, GpuOptions};
pub use error::GpuError;
pub use profile::{DeviceProfile, KernelFamily};

/// `shader_check` and `uniform_layout` are shared with build.rs, where `naga` is a build-dependency; here it is
/// wgpu's own copy (same version, with the WGSL front end).
#[cfg(not(target_arch = "wasm32"))]
use wgpu::naga;
