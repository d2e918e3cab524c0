// Shared by the dense kernels that read a packed copy of the weights whose index is the same in
// every lane (src/field/gpu/dense/, `DenseFamily::UniformWeights`): the kernels CPU devices
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
// padding, a 64 KiB window. Every weight is read as part of a whole vec4 at an index the same in
// every lane: indexing a vector's component by a runtime value made Tint (the browser's
// compiler) load a whole vec4 per weight and pick the component per lane, which ran the page's
// MLPs about 3x slower than natively on the same device (docs/results/bench.md).
//
// Stages declare `weights: array<vec4<f32>, UNIFORM_WEIGHT_VEC4S>` in one of two address spaces
// (`PackedReads` in src/field/gpu/dense/uniform_shape.rs): `uniform` for naga (native), `storage,
// read` for Tint (the page). Tint lowers every uniform access to a byte offset and back,
// `(index · 16) / 16`, a division per vec4 that SwiftShader's compiler runs lane by lane; in the
// page that made these kernels about 1.3x slower than natively, and reading the same copy from
// storage (where SwiftShader loads an index equal in all lanes once) removes it
// (docs/results/bench.md, "Tint divides per uniform access").
//!include _dense_tile.wgsl
//!include _dispatch.wgsl
//!include _dense_acc.wgsl
//!include _dense_accumulate.wgsl

// Outputs (forward) or inputs (backward) per invocation: a multiple of 4 up to 64 (uniform.rs
// splits the layer into equal blocks, so a 3-wide output does not compute 16).
override BLOCK: u32 = 16u;
const WORKGROUP: u32 = 64u;
// 64 KiB: WebGPU's default maxUniformBufferBindingSize.
const UNIFORM_WEIGHT_VEC4S: u32 = 4096u;

// Straight-line reductions (`Unrolled` in src/field/gpu/dense/uniform.rs). lavapipe loads a
// uniform value once for all lanes only where its index is made of constants and no lane has
// left the kernel before the load; any other index (a loop counter, a workgroup id, a value read
// from a buffer) has each lane gather it, one scalar load per lane, which made the weight loads
// most of these kernels' time there (docs/results/bench.md). With UNROLL the reduction is
// written out step by step (`*_steps`, 8 per call, up to MAX_UNROLLED) with REDUCED steps and
// ROW_QUADS quads per packed row as constants, and invocations past the last row compute on a
// valid row and skip their stores instead of returning. The sums add in the loop's order.
override UNROLL: bool = false;
// The reduction's length (the forward's inputs, the input gradient's outputs) and the vec4s per
// packed weight row, when UNROLL.
override REDUCED: u32 = 1u;
override ROW_QUADS: u32 = 1u;
const MAX_UNROLLED: u32 = 128u;

// The row invocation `item` reads: itself, or with UNROLL past the last row, the last row (row
// 0 when there are none: its reads are bounds-checked and nothing is stored).
fn row_read(item: u32, rows: u32) -> u32 {
    return min(item, max(rows, 1u) - 1u);
}

// Which block of the layer a workgroup computes: its z, or FIXED_BLOCK where each block is a
// pipeline of its own (UNROLL with several blocks: the workgroup id in a weight index would have
// every lane gather the weights, and the written-out reduction then ran slower than the loop).
const ANY_BLOCK: u32 = 0xffffffffu;
override FIXED_BLOCK: u32 = ANY_BLOCK;

fn block_index(z: u32) -> u32 {
    if FIXED_BLOCK != ANY_BLOCK {
        return FIXED_BLOCK;
    }
    return z;
}

// The first packed quad of block b: 0 when the block holds every column of an unrolled layer,
// so that the weight indices stay constants.
fn block_quad(b: u32) -> u32 {
    if UNROLL && ROW_QUADS * 4u <= BLOCK {
        return 0u;
    }
    return (b * BLOCK) >> 2u;
}
