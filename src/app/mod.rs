//! The egui app (web): gets a scene into the page (`loading`, or a file picked or dropped),
//! then annotates it (`annotator`), training the field live on the page's WebGPU device
//! (`training`). The modules below each draw or do one thing; the plain logic they use (undo,
//! share codec, autosave entries and snapshots, brush and view maths) is in `crate::labels`, tested natively.
//!
//! `page_options` and `status` are plain data and build natively too (their tests
//! run with `cargo test --lib`); the rest needs the browser. docs/architecture.md ("The web
//! app") shows how the parts talk.
#[cfg(target_arch = "wasm32")]
pub mod annotator;
#[cfg(target_arch = "wasm32")]
pub mod bench;
#[cfg(target_arch = "wasm32")]
pub mod browser;
#[cfg(target_arch = "wasm32")]
pub mod canvas;
#[cfg(target_arch = "wasm32")]
pub mod frame_strip;
#[cfg(target_arch = "wasm32")]
pub mod frame_view;
#[cfg(target_arch = "wasm32")]
pub mod loading;
#[cfg(target_arch = "wasm32")]
pub mod overlays;
#[cfg(target_arch = "wasm32")]
pub mod packing;
#[cfg(target_arch = "wasm32")]
mod page;
pub mod page_options;
#[cfg(target_arch = "wasm32")]
pub mod page_status;
#[cfg(target_arch = "wasm32")]
pub mod palette;
#[cfg(target_arch = "wasm32")]
pub mod persistence;
#[cfg(target_arch = "wasm32")]
pub mod scene_panel;
#[cfg(target_arch = "wasm32")]
pub mod side_panel;
pub mod status;
#[cfg(target_arch = "wasm32")]
pub mod store;
#[cfg(target_arch = "wasm32")]
pub mod training;

#[cfg(target_arch = "wasm32")]
pub use page::App;

/// How often progress (decoded frames, loading) asks for a repaint, at most
/// (`DeviceProfile::repaint_ms`); a page without a device repaints as often as on a GPU.
pub fn repaint_interval_ms(gpu: Option<&crate::gpu::GpuContext>) -> u64 {
    gpu.map_or(100, |g| g.profile().repaint_ms)
}
