// Backward of the hash grid (field::gpu::encoding::HashGridBackwardPass) on a device with
// float atomics (wgpu's SHADER_FLOAT32_ATOMIC, native only: Vulkan's
// VK_EXT_shader_atomic_float, lavapipe included): one atomicAdd per add instead of
// hash_backward.wgsl's load and compare-exchange loop. The work itself is in
// _hash_backward.wgsl.
//!requires float32-atomics

//!include _hash_backward.wgsl

@group(0) @binding(3) var<storage, read_write> gradient: array<atomic<f32>>;

// gradient[index] += value, safe against concurrent adds to the same element.
fn add_to_gradient(index: u32, value: f32, level: u32) {
    // x + 0 = x: skipping saves an atomic for corners with zero weight or zero gradient.
    if value == 0.0 {
        return;
    }
    atomicAdd(&gradient[index], value);
}
