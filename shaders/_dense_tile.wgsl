// Shared by the dense-layer kernels (src/field/gpu/dense/): the uniform describing one layer
// and the register-tiled product C += A·B of a TM x KC tile of A and a KC x TN tile of B staged
// in workgroup memory. Each invocation owns a contiguous RM x RN (4 x 4) block of the TM x TN
// tile of C (rows RM·ty + r, columns RN·tx + c), so per step of k it reads its four A values
// and its four B values as one vec4 each: 2 workgroup loads per 16 multiply-adds, neighbouring
// invocations reading neighbouring vec4s of B and the same vec4 of A.
//
// The grid (TX, TY) and the chunk depth KC are override constants chosen per layer shape by
// `dense::TileShape` (wide layers 16x16 invocations over 64x64 tiles, narrow outputs tall thin
// tiles); the staging arrays are sized for the largest shape: 12 KiB, under WebGPU's 16 KiB.

// Mirrors `DenseDims` in src/field/gpu/dense/spec.rs (16 u32, 64 bytes). Offsets and strides count
// f32 elements; a view (stride, offset) addresses element j of row n at n·stride + offset + j.
struct DenseDims {
    rows: u32,
    in_dim: u32,
    out_dim: u32,
    // 1: ReLU after the product (forward), mask by Y > 0 (backward); 0: linear.
    relu: u32,
    x_stride: u32,
    x_offset: u32,
    y_stride: u32,
    y_offset: u32,
    dy_stride: u32,
    dy_offset: u32,
    dx_stride: u32,
    dx_offset: u32,
    // Start of the layer's [out][in] matrix in the bound params (or grads) range.
    weight_offset: u32,
    // Backward weight only: rows of one chunk, and how many partial matrices the reduction
    // sums (one per chunk, or per span of chunks in `_dense_chunk_sums.wgsl`).
    chunk_rows: u32,
    chunks: u32,
    _pad: u32,
}

// One word: the rows actually present (at most dims.rows, the capacity the dispatch and the
// buffers were sized for). The heads run on the samples the keep pass kept (keep.wgsl), whose
// count is only known on the GPU; layers over a fixed batch bind a word holding dims.rows.
@group(0) @binding(7) var<storage, read> row_count: array<u32>;

// Rows to compute; a value read from a read-only binding, so uniform across a workgroup (the
// tiled kernels return on it before their barriers).
fn active_rows() -> u32 {
    return min(dims.rows, row_count[0]);
}

// `n` rounded up to a multiple of 4: the row length of the uniform-weight kernels' packed
// matrices, so that they read whole vec4s (`_dense_uniform.wgsl`).
fn padded_to_vec4(n: u32) -> u32 {
    return (n + 3u) & ~3u;
}

// vec4s per packed row of `columns` values.
fn quads_per_row(columns: u32) -> u32 {
    return padded_to_vec4(columns) >> 2u;
}

override TX: u32 = 16u;
override TY: u32 = 16u;
override KC: u32 = 16u;
const RM: u32 = 4u;
const RN: u32 = 4u;
// Capacities in f32 of the staging arrays; TileShape keeps TY·RM·KC and TX·RN·KC within them.
const A_TILE_CAP: u32 = 2048u;
const B_TILE_CAP: u32 = 1024u;

// Element (k, m) of the A tile is word k · TM + m, (k, n) of the B tile word k · TN + n, held as
// vec4s (TM and TN are multiples of 4): k-major, so an invocation's RM (RN) values of one k are
// one vec4.
var<workgroup> a_tile: array<vec4<f32>, A_TILE_CAP / 4u>;
var<workgroup> b_tile: array<vec4<f32>, B_TILE_CAP / 4u>;

fn stage_a(k: u32, m: u32, value: f32) {
    a_tile[(k * tile_m() + m) >> 2u][m & 3u] = value;
}

fn stage_b(k: u32, n: u32, value: f32) {
    b_tile[(k * tile_n() + n) >> 2u][n & 3u] = value;
}

fn tile_m() -> u32 {
    return TY * RM;
}

fn tile_n() -> u32 {
    return TX * RN;
}

// The RM x RN = 4 x 4 outputs of one invocation: row r of its block in `r<r>`. Four named
// vectors rather than an indexed array, so no compiler has to keep them in memory (a private
// array indexed in a loop that is not unrolled ends up in scratch memory, e.g. on lavapipe).
struct Block {
    r0: vec4<f32>,
    r1: vec4<f32>,
    r2: vec4<f32>,
    r3: vec4<f32>,
}

// block.r[r][c] += Σ_k A[k][RM·ty + r] · B[k][RN·tx + c] over the staged chunk.
fn multiply_staged(block: ptr<function, Block>, tx: u32, ty: u32) {
    var r0 = (*block).r0;
    var r1 = (*block).r1;
    var r2 = (*block).r2;
    var r3 = (*block).r3;
    for (var k = 0u; k < KC; k++) {
        let a = a_tile[k * TY + ty];
        let b = b_tile[k * TX + tx];
        r0 += a.x * b;
        r1 += a.y * b;
        r2 += a.z * b;
        r3 += a.w * b;
    }
    (*block).r0 = r0;
    (*block).r1 = r1;
    (*block).r2 = r2;
    (*block).r3 = r3;
}
