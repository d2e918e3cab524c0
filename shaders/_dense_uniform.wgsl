// Shared by the dense kernels that read the weights from a UNIFORM binding (src/field/gpu/dense/, `DenseFamily::UniformWeights`): the kernels CPU devices
// (lavapipe, SwiftShader) run instead of the workgroup-tiled ones.
//
// Why: those devices run a SIMD group of invocations in lock-step lanes, and every storage or
// workgroup load becomes a per-lane gather; a uniform-buffer load with an index that is the same
// in every lane is one scalar load. Each invocation owns one row n and a block of BLOCK outputs,
// so per step of the reduction it gathers one value of its own row and reads the BLOCK weights
// it multiplies with as uniform scalars, which on those devices is several times faster than
// reading the weights from storage or the tiled kernels (docs/results/measurements.md).
//
// Same uniform block and bindings as the tiled kernels (`_dense_tile.wgsl`), except `weights`:
// the layer's matrix copied by `dense_pack_weights.wgsl` into rows padded to whole vec4s (the
// forward reads it transposed, [in][out], the input gradient as [out][in]), zeros in the
// padding, bound as a 64 KiB uniform. Every weight is read as part of a whole vec4 at an index
// the same in every lane: indexing a vector's component by a runtime value made Tint (the
// browser's compiler) load a whole vec4 per weight and pick the component per lane, which ran
// the page's MLPs about 3x slower than natively on the same device (docs/results/bench.md).
// Stages declare `weights: array<vec4<f32>, UNIFORM_WEIGHT_VEC4S>`.
//!include _dense_tile.wgsl
//!include _dispatch.wgsl
//!include _dense_acc.wgsl

// Outputs (forward) or inputs (backward) per invocation: 4, 8, 16, 32 or 64 (uniform.rs picks
// the least that covers the layer, so a 3-wide output does not compute 16).
override BLOCK: u32 = 16u;
const WORKGROUP: u32 = 64u;
// 64 KiB: WebGPU's default maxUniformBufferBindingSize.
const UNIFORM_WEIGHT_VEC4S: u32 = 4096u;

// acc += value · (BLOCK weights: the packed row's quads from `w`). Quads past BLOCK are never
// used, so specialisation drops their loads.
fn accumulate(acc: ptr<function, Acc>, value: f32, w: u32) {
    add_scaled(acc, value, Acc(weights[w + 0u], weights[w + 1u], weights[w + 2u], weights[w + 3u], weights[w + 4u], weights[w + 5u], weights[w + 6u], weights[w + 7u], weights[w + 8u], weights[w + 9u], weights[w + 10u], weights[w + 11u], weights[w + 12u], weights[w + 13u], weights[w + 14u], weights[w + 15u]));
}
