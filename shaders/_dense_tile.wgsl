// Shared by the dense-layer kernels (src/field/gpu/dense.rs): the uniform describing one layer
// and the register-tiled product C += A·B of a TM x KC tile of A and a KC x TN tile of B staged
// in workgroup memory. Each invocation owns RM x RN elements of the TM x TN tile of C, strided by
// the invocation grid (row ty + r·TY, column tx + c·TX) so neighbouring invocations read
// neighbouring workgroup words.
//
// The grid (TX, TY) and the chunk depth KC are override constants chosen per layer shape by
// `dense::TileShape` (wide layers 16x16 invocations over 64x64 tiles, narrow outputs tall thin
// tiles); the staging arrays are sized for the largest shape: 12 KiB, under WebGPU's 16 KiB.

// Mirrors `DenseDims` in src/field/gpu/dense.rs (16 u32, 64 bytes). Offsets and strides count
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
    // Backward weight only: rows summed by one workgroup, and how many such chunks.
    chunk_rows: u32,
    chunks: u32,
    _pad: u32,
}

override TX: u32 = 16u;
override TY: u32 = 16u;
override KC: u32 = 16u;
const RM: u32 = 4u;
const RN: u32 = 4u;
// Capacities in f32 of the staging arrays; TileShape keeps TY·RM·KC and TX·RN·KC within them.
const A_TILE_CAP: u32 = 2048u;
const B_TILE_CAP: u32 = 1024u;

// a_tile[k · TM + m], b_tile[k · TN + n]: k-major so the inner loop reads RM (RN) words of one row.
var<workgroup> a_tile: array<f32, A_TILE_CAP>;
var<workgroup> b_tile: array<f32, B_TILE_CAP>;

fn tile_m() -> u32 {
    return TY * RM;
}

fn tile_n() -> u32 {
    return TX * RN;
}

// acc[r][c] += Σ_k a_tile[k][ty + r·TY] · b_tile[k][tx + c·TX] over the staged chunk.
fn multiply_staged(acc: ptr<function, array<array<f32, RN>, RM>>, tx: u32, ty: u32) {
    let tm = tile_m();
    let tn = tile_n();
    for (var k = 0u; k < KC; k++) {
        var a: array<f32, RM>;
        var b: array<f32, RN>;
        for (var r = 0u; r < RM; r++) {
            a[r] = a_tile[k * tm + ty + r * TY];
        }
        for (var c = 0u; c < RN; c++) {
            b[c] = b_tile[k * tn + tx + c * TX];
        }
        for (var r = 0u; r < RM; r++) {
            for (var c = 0u; c < RN; c++) {
                (*acc)[r][c] += a[r] * b[c];
            }
        }
    }
}

// dL/dZ of one element: dY, masked by the ReLU's derivative (taken as 0 at 0, as the reference).
fn output_gradient(dy: f32, y: f32) -> f32 {
    if dims.relu != 0u && !(y > 0.0) {
        return 0.0;
    }
    return dy;
}
