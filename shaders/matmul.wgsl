// C (m x n) = A (m x k) * B (k x n), all row-major f32: the plain workgroup-memory tiled kernel
// the bench uses as the yardstick of what the device can do (src/gpu/matmul_bench.rs).
//
// A 16x16 workgroup computes a 64x64 tile of C; each invocation keeps a 4x4 block of it in
// registers (rows local_id.y + 16 r, columns local_id.x + 16 q, so neighbouring invocations touch
// neighbouring addresses). The k dimension advances in slices of 16: each slice of A (64x16) and
// B (16x64) is staged in workgroup memory (8 KiB) by all 256 invocations, then read 4+4 values
// per 16 multiply-adds. Register blocking made it 4x faster than one-output-per-invocation 16x16
// tiling on lavapipe; it is the usual shape of a plain (no subgroups, no vector types) GPU GEMM.

const OUTPUT_TILE: u32 = 64u;
const K_SLICE: u32 = 16u;
const THREADS_PER_SIDE: u32 = 16u;
const BLOCK: u32 = 4u; // OUTPUT_TILE / THREADS_PER_SIDE
const INVOCATIONS: u32 = 256u; // THREADS_PER_SIDE squared
const LOADS_PER_INVOCATION: u32 = 4u; // OUTPUT_TILE * K_SLICE / INVOCATIONS

struct Dims {
    m: u32,
    n: u32,
    k: u32,
    _pad: u32,
}

@group(0) @binding(0) var<uniform> dims: Dims;
@group(0) @binding(1) var<storage, read> a: array<f32>;
@group(0) @binding(2) var<storage, read> b: array<f32>;
@group(0) @binding(3) var<storage, read_write> c: array<f32>;

var<workgroup> slice_a: array<array<f32, K_SLICE>, OUTPUT_TILE>;
var<workgroup> slice_b: array<array<f32, OUTPUT_TILE>, K_SLICE>;

@compute @workgroup_size(THREADS_PER_SIDE, THREADS_PER_SIDE)
fn matmul(
    @builtin(workgroup_id) workgroup_id: vec3<u32>,
    @builtin(local_invocation_id) local_id: vec3<u32>,
    @builtin(local_invocation_index) local_index: u32,
) {
    let tile_row = workgroup_id.y * OUTPUT_TILE;
    let tile_col = workgroup_id.x * OUTPUT_TILE;
    var sums: array<array<f32, BLOCK>, BLOCK>;
    let slice_count = (dims.k + K_SLICE - 1u) / K_SLICE;
    for (var s = 0u; s < slice_count; s++) {
        // Out-of-range loads become zeros so edge tiles need no special case in the inner loop.
        for (var l = 0u; l < LOADS_PER_INVOCATION; l++) {
            let element = local_index + l * INVOCATIONS;
            let a_row = element / K_SLICE;
            let a_col = element % K_SLICE;
            let a_global_row = tile_row + a_row;
            let a_global_col = s * K_SLICE + a_col;
            var a_value = 0.0;
            if a_global_row < dims.m && a_global_col < dims.k {
                a_value = a[a_global_row * dims.k + a_global_col];
            }
            slice_a[a_row][a_col] = a_value;

            let b_row = element / OUTPUT_TILE;
            let b_col = element % OUTPUT_TILE;
            let b_global_row = s * K_SLICE + b_row;
            let b_global_col = tile_col + b_col;
            var b_value = 0.0;
            if b_global_row < dims.k && b_global_col < dims.n {
                b_value = b[b_global_row * dims.n + b_global_col];
            }
            slice_b[b_row][b_col] = b_value;
        }
        workgroupBarrier();
        for (var i = 0u; i < K_SLICE; i++) {
            var a_column: array<f32, BLOCK>;
            var b_row: array<f32, BLOCK>;
            for (var r = 0u; r < BLOCK; r++) {
                a_column[r] = slice_a[local_id.y + THREADS_PER_SIDE * r][i];
                b_row[r] = slice_b[i][local_id.x + THREADS_PER_SIDE * r];
            }
            for (var r = 0u; r < BLOCK; r++) {
                for (var q = 0u; q < BLOCK; q++) {
                    sums[r][q] += a_column[r] * b_row[q];
                }
            }
        }
        workgroupBarrier();
    }
    for (var r = 0u; r < BLOCK; r++) {
        for (var q = 0u; q < BLOCK; q++) {
            let row = tile_row + local_id.y + THREADS_PER_SIDE * r;
            let col = tile_col + local_id.x + THREADS_PER_SIDE * q;
            if row < dims.m && col < dims.n {
                c[row * dims.n + col] = sums[r][q];
            }
        }
    }
}
