// Input gradient of one dense layer (src/field/gpu/dense/):
// dX[n][i] = Σ_o dZ[n][o] · W[o][i] with dZ = dY ⊙ act'(Y) formed while staging (ReLU: Y > 0).
// dX is overwritten (not accumulated). Workgroups: x, y spread the row tiles, z the input-column
// tiles.
//!include _dense_tile.wgsl
//!include _dense_output_gradient.wgsl
//!include _dispatch.wgsl

@group(0) @binding(0) var<uniform> dims: DenseDims;
@group(0) @binding(1) var<storage, read> dy: array<f32>;
@group(0) @binding(2) var<storage, read> y: array<f32>;

// Y in f32 rows: the tiled kernels never see bf16 rows (src/field/gpu/dense/mlp.rs).
fn y_value(row: u32, j: u32) -> f32 {
    return y[row + j];
}
@group(0) @binding(3) var<storage, read> weights: array<f32>;
@group(0) @binding(4) var<storage, read_write> dx: array<f32>;

// Writes the 4 values of one block row (columns col .. col + 3) that lie inside dX.
fn store_row(row: u32, col: u32, values: vec4<f32>) {
    if row >= active_rows() {
        return;
    }
    for (var c = 0u; c < RN; c++) {
        let i = col + c;
        if i < dims.in_dim {
            dx[row * dims.dx_stride + dims.dx_offset + i] = values[c];
        }
    }
}

@compute @workgroup_size(TX, TY)
fn backward_input(
    @builtin(workgroup_id) workgroup_id: vec3<u32>,
    @builtin(num_workgroups) num_workgroups: vec3<u32>,
    @builtin(local_invocation_id) local_id: vec3<u32>,
    @builtin(local_invocation_index) local_index: u32,
) {
    let tm = tile_m();
    let tn = tile_n();
    let row_tile = linear_item_index(workgroup_id, num_workgroups, 0u, 1u);
    let row0 = row_tile * tm;
    let rows = active_rows();
    if row0 >= rows {
        return;
    }
    let col0 = workgroup_id.z * tn;
    let threads = TX * TY;
    var block: Block;
    for (var k0 = 0u; k0 < dims.out_dim; k0 += KC) {
        // A = dZ rows (k = output unit), read along a row.
        for (var e = local_index; e < tm * KC; e += threads) {
            let k = e % KC;
            let m = e / KC;
            let row = row0 + m;
            let o = k0 + k;
            var value = 0.0;
            if row < rows && o < dims.out_dim {
                let g = dy[row * dims.dy_stride + dims.dy_offset + o];
                value = output_gradient(g, row * dims.y_stride + dims.y_offset, o);
            }
            stage_a(k, m, value);
        }
        // B[k][i] = W[k0 + k][i]: read along a weight row.
        for (var e = local_index; e < tn * KC; e += threads) {
            let n = e % tn;
            let k = e / tn;
            let o = k0 + k;
            let i = col0 + n;
            var value = 0.0;
            if o < dims.out_dim && i < dims.in_dim {
                value = weights[dims.weight_offset + o * dims.in_dim + i];
            }
            stage_b(k, n, value);
        }
        workgroupBarrier();
        multiply_staged(&block, local_id.x, local_id.y);
        workgroupBarrier();
    }
    let row = row0 + local_id.y * RM;
    let col = col0 + local_id.x * RN;
    store_row(row, col, block.r0);
    store_row(row + 1u, col, block.r1);
    store_row(row + 2u, col, block.r2);
    store_row(row + 3u, col, block.r3);
}
