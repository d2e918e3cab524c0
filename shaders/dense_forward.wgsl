// Forward of one bias-free dense layer over N rows (src/field/gpu/dense/):
// Y[n][o] = act(Σ_i X[n][i] · W[o][i]), act ReLU or none, X and Y row views (stride, offset),
// W the layer's row-major [out][in] matrix at dims.weight_offset of the bound params.
// Workgroups: x, y spread the row tiles (Dispatch1d), z the output-column tiles.
//!include _dense_tile.wgsl
//!include _dispatch.wgsl

@group(0) @binding(0) var<uniform> dims: DenseDims;
@group(0) @binding(1) var<storage, read> x: array<f32>;
@group(0) @binding(2) var<storage, read> weights: array<f32>;
@group(0) @binding(3) var<storage, read_write> y: array<f32>;

// Writes the 4 outputs of one block row (columns col .. col + 3) that lie inside Y, activated.
fn store_row(row: u32, col: u32, values: vec4<f32>) {
    if row >= active_rows() {
        return;
    }
    for (var c = 0u; c < RN; c++) {
        let o = col + c;
        if o < dims.out_dim {
            var value = values[c];
            if dims.relu != 0u {
                value = max(value, 0.0);
            }
            y[row * dims.y_stride + dims.y_offset + o] = value;
        }
    }
}

@compute @workgroup_size(TX, TY)
fn forward(
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
    // Uniform per workgroup, so returning before the barriers is allowed.
    if row0 >= rows {
        return;
    }
    let col0 = workgroup_id.z * tn;
    let threads = TX * TY;
    var block: Block;
    for (var k0 = 0u; k0 < dims.in_dim; k0 += KC) {
        // A = X rows: consecutive invocations read consecutive inputs of a row.
        for (var e = local_index; e < tm * KC; e += threads) {
            let k = e % KC;
            let m = e / KC;
            let row = row0 + m;
            let i = k0 + k;
            var value = 0.0;
            if row < rows && i < dims.in_dim {
                value = x[row * dims.x_stride + dims.x_offset + i];
            }
            stage_a(k, m, value);
        }
        // B[k][o] = W[o][k]: consecutive invocations read along a weight row.
        for (var e = local_index; e < tn * KC; e += threads) {
            let k = e % KC;
            let n = e / KC;
            let o = col0 + n;
            let i = k0 + k;
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
