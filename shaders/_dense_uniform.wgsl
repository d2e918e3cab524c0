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

// Outputs (forward) or inputs (backward) per invocation: 4, 8 or 16 (dense.rs picks the least
// that covers a narrow layer, so a 3-wide output does not compute 16).
override BLOCK: u32 = 16u;
const WORKGROUP: u32 = 64u;
// 64 KiB: WebGPU's default maxUniformBufferBindingSize.
const UNIFORM_WEIGHT_VEC4S: u32 = 4096u;

struct Acc {
    a0: vec4<f32>,
    a1: vec4<f32>,
    a2: vec4<f32>,
    a3: vec4<f32>,
}

// acc += value · (BLOCK weights: the packed row's quads from `w`).
fn accumulate(acc: ptr<function, Acc>, value: f32, w: u32) {
    (*acc).a0 += value * weights[w];
    if BLOCK > 4u {
        (*acc).a1 += value * weights[w + 1u];
    }
    if BLOCK > 8u {
        (*acc).a2 += value * weights[w + 2u];
        (*acc).a3 += value * weights[w + 3u];
    }
}

fn acc_value(acc: ptr<function, Acc>, j: u32) -> f32 {
    let q = j >> 2u;
    var v = (*acc).a0;
    if q == 1u {
        v = (*acc).a1;
    } else if q == 2u {
        v = (*acc).a2;
    } else if q == 3u {
        v = (*acc).a3;
    }
    return v[j & 3u];
}
