// Backward of the hash grid (field::gpu::encoding::HashGridBackwardPass) in fixed point, for
// devices without float atomics (every browser): each add is one atomicAdd of an i32, the value
// times 2^exponents[level], rounded to the nearest integer. hash_gradient_scale.wgsl picked each
// level's exponent for this step from a bound on every entry's sum, so no sum can overflow
// (docs/architecture.md, "Fixed-point hash gradients"), and Adam turns the integers back into
// floats (adam.wgsl, FixedPointTable). Integer adds also make the sum independent of the order
// the adds land in. The work itself is in _hash_backward.wgsl.

//!include _hash_backward.wgsl
//!include _fixed_point.wgsl

@group(0) @binding(3) var<storage, read_write> gradient: array<atomic<i32>>;
@group(0) @binding(4) var<storage, read> exponents: array<i32>;

// gradient[index] += round(value · 2^exponent of the level).
fn add_to_gradient(index: u32, value: f32, level: u32) {
    // x + 0 = x: skipping saves an atomic for corners with zero weight or zero gradient.
    if value == 0.0 {
        return;
    }
    atomicAdd(&gradient[index], to_fixed_point(value, exponents[level]));
}
