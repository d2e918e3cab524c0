// C (m x n) = A (m x k) * B (k x n), all row-major f32: the plain workgroup-memory tiled kernel
// the bench uses as the yardstick of what the device can do (src/gpu/matmul_bench.rs).
// One invocation computes one element of C; a 16x16 workgroup stages 16x16 tiles of A and B.

const TILE: u32 = 16u;

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

var<workgroup> tile_a: array<array<f32, TILE>, TILE>;
var<workgroup> tile_b: array<array<f32, TILE>, TILE>;

@compute @workgroup_size(TILE, TILE)
fn matmul(@builtin(workgroup_id) workgroup_id: vec3<u32>, @builtin(local_invocation_id) local_id: vec3<u32>) {
    let row = workgroup_id.y * TILE + local_id.y;
    let col = workgroup_id.x * TILE + local_id.x;
    var sum = 0.0;
    let tile_count = (dims.k + TILE - 1u) / TILE;
    for (var t = 0u; t < tile_count; t++) {
        // Out-of-range loads become zeros so edge tiles need no special case in the inner loop.
        let a_col = t * TILE + local_id.x;
        var a_value = 0.0;
        if row < dims.m && a_col < dims.k {
            a_value = a[row * dims.k + a_col];
        }
        tile_a[local_id.y][local_id.x] = a_value;
        let b_row = t * TILE + local_id.y;
        var b_value = 0.0;
        if b_row < dims.k && col < dims.n {
            b_value = b[b_row * dims.n + col];
        }
        tile_b[local_id.y][local_id.x] = b_value;
        workgroupBarrier();
        for (var i = 0u; i < TILE; i++) {
            sum += tile_a[local_id.y][i] * tile_b[i][local_id.x];
        }
        workgroupBarrier();
    }
    if row < dims.m && col < dims.n {
        c[row * dims.n + col] = sum;
    }
}
