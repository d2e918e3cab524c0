// Backward of the hash grid (field::gpu::encoding::HashGridBackwardPass), portable: WebGPU
// has no float atomics, so each add is a compare-exchange loop on the f32's bits. Devices with
// float atomics run hash_backward_float_atomics.wgsl instead. The work itself is in
// _hash_backward.wgsl.

//!include _hash_backward.wgsl

@group(0) @binding(3) var<storage, read_write> gradient: array<atomic<u32>>;

// gradient[index] += value, as f32, safe against concurrent adds to the same element.
fn add_to_gradient(index: u32, value: f32, level: u32) {
    // x + 0 = x: skipping saves an atomic for corners with zero weight or zero gradient.
    if value == 0.0 {
        return;
    }
    var old = atomicLoad(&gradient[index]);
    loop {
        let result = atomicCompareExchangeWeak(&gradient[index], old, bitcast<u32>(bitcast<f32>(old) + value));
        if result.exchanged {
            return;
        }
        old = result.old_value;
    }
}
