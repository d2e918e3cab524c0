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
// 64 KiB of the parameter buffer bound as uniform from a 256-byte aligned offset, the layer's
// [out][in] matrix at dims.weight_offset inside it (dense.rs checks it fits). Stages declare
// `weights: array<vec4<f32>, UNIFORM_WEIGHT_VEC4S>` at their own binding.
//!include _dense_tile.wgsl
//!include _dispatch.wgsl

// Outputs (forward) or inputs (backward) per invocation: 4, 8 or 16 (dense.rs picks the least
// that covers a narrow layer, so a 3-wide output does not compute 16).
override BLOCK: u32 = 16u;
const WORKGROUP: u32 = 64u;
// 64 KiB: WebGPU's default maxUniformBufferBindingSize.
const UNIFORM_WEIGHT_VEC4S: u32 = 4096u;

fn weight(i: u32) -> f32 {
    return weights[i >> 2u][i & 3u];
}

// Four weights `stride` apart from `first`.
fn weights4(first: u32, stride: u32) -> vec4<f32> {
    return vec4<f32>(weight(first), weight(first + stride), weight(first + 2u * stride), weight(first + 3u * stride));
}

struct Acc {
    a0: vec4<f32>,
    a1: vec4<f32>,
    a2: vec4<f32>,
    a3: vec4<f32>,
}

// acc += value · (4·BLOCK/4 weights: element j at first + j·stride).
fn accumulate(acc: ptr<function, Acc>, value: f32, first: u32, stride: u32) {
    (*acc).a0 += value * weights4(first, stride);
    if BLOCK > 4u {
        (*acc).a1 += value * weights4(first + 4u * stride, stride);
    }
    if BLOCK > 8u {
        (*acc).a2 += value * weights4(first + 8u * stride, stride);
        (*acc).a3 += value * weights4(first + 12u * stride, stride);
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
