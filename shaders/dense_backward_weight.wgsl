// Weight gradient of one dense layer (src/field/gpu/dense/): dW[o][i] = Σ_n dZ[n][o] · X[n][i],
// dZ = dY ⊙ act'(Y). A reduction over all N rows done deterministically in two steps:
// `partial_sums` gives every chunk of dims.chunk_rows rows its own [out][in] partial matrix
// (workgroups: x the input-column tiles, y the output-row tiles, z the chunk), then
// `reduce_chunks` sums the chunks in order per weight and ADDS the total to the gradient buffer
// (the trainer zeroes it before a step), touching only the layer's [out][in] range.
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
@group(0) @binding(3) var<storage, read> x: array<f32>;
// [chunk][out][in]
@group(0) @binding(4) var<storage, read_write> partials: array<f32>;
@group(0) @binding(5) var<storage, read_write> grads: array<f32>;

// Writes the 4 partial sums of one block row (output unit o, inputs i .. i + 3) of a chunk.
fn store_row(chunk: u32, o: u32, i: u32, values: vec4<f32>) {
    if o >= dims.out_dim {
        return;
    }
    let base = (chunk * dims.out_dim + o) * dims.in_dim;
    for (var c = 0u; c < RN; c++) {
        let column = i + c;
        if column < dims.in_dim {
            partials[base + column] = values[c];
        }
    }
}

// Writes this invocation's block (output units o .. o + 3, inputs i .. i + 3) of a chunk.
fn store_block(chunk: u32, o: u32, i: u32, block: Block) {
    store_row(chunk, o, i, block.r0);
    store_row(chunk, o + 1u, i, block.r1);
    store_row(chunk, o + 2u, i, block.r2);
    store_row(chunk, o + 3u, i, block.r3);
}

@compute @workgroup_size(TX, TY)
fn partial_sums(
    @builtin(workgroup_id) workgroup_id: vec3<u32>,
    @builtin(local_invocation_id) local_id: vec3<u32>,
    @builtin(local_invocation_index) local_index: u32,
) {
    let tm = tile_m();
    let tn = tile_n();
    let o0 = workgroup_id.y * tm;
    let i0 = workgroup_id.x * tn;
    let chunk = workgroup_id.z;
    let first_row = chunk * dims.chunk_rows;
    let rows = active_rows();
    var block: Block;
    // A chunk past the rows present sums nothing: its partial is zero (reduce_chunks adds
    // every chunk). Uniform per workgroup, so returning before the barriers is allowed.
    if first_row >= rows {
        store_block(chunk, o0 + local_id.y * RM, i0 + local_id.x * RN, block);
        return;
    }
    let end_row = min(first_row + dims.chunk_rows, rows);
    let threads = TX * TY;
    for (var k0 = 0u; k0 < dims.chunk_rows; k0 += KC) {
        // A[m][k] = dZ[row k][output m]: consecutive invocations read along a row of dY.
        for (var e = local_index; e < tm * KC; e += threads) {
            let m = e % tm;
            let k = e / tm;
            let row = first_row + k0 + k;
            let o = o0 + m;
            var value = 0.0;
            if row < end_row && o < dims.out_dim {
                let g = dy[row * dims.dy_stride + dims.dy_offset + o];
                value = output_gradient(g, row * dims.y_stride + dims.y_offset, o);
            }
            stage_a(k, m, value);
        }
        // B[k][n] = X[row k][input n]: read along a row of X.
        for (var e = local_index; e < tn * KC; e += threads) {
            let n = e % tn;
            let k = e / tn;
            let row = first_row + k0 + k;
            let i = i0 + n;
            var value = 0.0;
            if row < end_row && i < dims.in_dim {
                value = x[row * dims.x_stride + dims.x_offset + i];
            }
            stage_b(k, n, value);
        }
        workgroupBarrier();
        multiply_staged(&block, local_id.x, local_id.y);
        workgroupBarrier();
    }
    store_block(chunk, o0 + local_id.y * RM, i0 + local_id.x * RN, block);
}

const REDUCE_WORKGROUP: u32 = 256u;

@compute @workgroup_size(REDUCE_WORKGROUP)
fn reduce_chunks(
    @builtin(workgroup_id) workgroup_id: vec3<u32>,
    @builtin(num_workgroups) num_workgroups: vec3<u32>,
    @builtin(local_invocation_index) local_index: u32,
) {
    let matrix = dims.out_dim * dims.in_dim;
    let e = linear_item_index(workgroup_id, num_workgroups, local_index, REDUCE_WORKGROUP);
    if e >= matrix {
        return;
    }
    var sum = 0.0;
    for (var chunk = 0u; chunk < dims.chunks; chunk++) {
        sum += partials[chunk * matrix + e];
    }
    grads[dims.weight_offset + e] += sum;
}
