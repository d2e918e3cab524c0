// The input gradient of the packed-weight dense kernels (dense_backward_input_uniform.wgsl,
// dense_backward_input_packed_storage.wgsl): everything but the `weights` binding, which each
// stage declares in its own address space (`_dense_uniform.wgsl` says why there are two).
//!include _dense_uniform.wgsl
//!include _bf16.wgsl
//!include _dense_output_gradient.wgsl
//!include _dense_relu_mask.wgsl

// Whether block 0 also stores dZ for the layer's uniform-window weight gradient, as bf16 rows
// (`_bf16.wgsl`).
override WRITE_DZ: bool = false;
override Y_BF16: bool = false;
override DY_BF16: bool = false;
override DX_BF16: bool = false;
// Whether dX is stored masked by the ReLU of X (0 where X ≤ 0): X is the previous layer's
// output, so what is stored is that layer's dZ, written straight into its weight gradient's
// windows; that layer then reads it as a dY needing no mask (dims.relu off) and writes no dZ of
// its own (`dense::MlpPass`, docs/architecture.md). Which X are positive comes from the bits the
// previous layer's forward wrote (`_dense_relu_mask.wgsl`, in blocks of MASK_BLOCK), 1/16 of the
// bf16 row.
override MASK_DX: bool = false;
override MASK_BLOCK: u32 = 64u;
// The columns of dX the caller reads ([DX_FIRST, DX_END), DX_FIRST even where dX is bf16): the
// others are not written (the SH part of the colour input, the frequency part of the encoding).
override DX_FIRST: u32 = 0u;
override DX_END: u32 = 0xffffffffu;

@group(0) @binding(0) var<uniform> dims: DenseDims;
// dY and dX in f32 or bf16 rows (DY_BF16, DX_BF16: the input gradients between hidden layers
// of an MLP whose kernels all read bf16 rows).
@group(0) @binding(1) var<storage, read> dy: array<u32>;
// Y in f32 or bf16 rows (Y_BF16: a hidden layer of an MLP whose kernels all read bf16 rows).
@group(0) @binding(2) var<storage, read> y: array<u32>;
@group(0) @binding(4) var<storage, read_write> dx: array<u32>;
@group(0) @binding(5) var<storage, read> relu_mask: array<u32>;
@group(0) @binding(6) var<storage, read_write> dz_out: array<u32>;

// Where one row's steps read and write (UNROLL); `dz` is the row's first word.
struct InputRow {
    dy: u32,
    y: u32,
    dz: u32,
    q0: u32,
    writes_dz: bool,
}

// dZ[n][o] of the row, 0 past the layer's outputs.
fn row_gradient(row: InputRow, o: u32) -> f32 {
    if o >= dims.out_dim {
        return 0.0;
    }
    return output_gradient(dy_value(row.dy, o), row.y, o);
}

fn dy_value(row: u32, j: u32) -> f32 {
    return row_value(dy[row_word(row, j, DY_BF16)], j, DY_BF16);
}

fn y_value(row: u32, j: u32) -> f32 {
    return row_value(y[row_word(row, j, Y_BF16)], j, Y_BF16);
}

// dX[n][i] as stored: masked by X's ReLU where MASK_DX (0 at 0, as `output_gradient`).
fn stored_input_gradient(value: f32, n: u32, i: u32) -> f32 {
    if MASK_DX {
        let word = relu_mask[relu_mask_word(n, dims.in_dim, MASK_BLOCK, i)];
        if ((word >> relu_mask_bit(MASK_BLOCK, i)) & 1u) == 0u {
            return 0.0;
        }
    }
    return value;
}

// Outputs o and o + 1 (o even) of the reduction (UNROLL; `forward_step` in
// _dense_forward_packed.wgsl says why): dZ[n][o], dZ[n][o + 1], stored as one word where asked,
// each times W[·][i0 .. i0 + BLOCK], o first.
fn input_pair(acc: ptr<function, Acc>, row: InputRow, o: u32) {
    if o < REDUCED {
        let g = output_gradient(dy_value(row.dy, o), row.y, o);
        var h = 0.0;
        if o + 1u < REDUCED {
            h = output_gradient(dy_value(row.dy, o + 1u), row.y, o + 1u);
        }
        if row.writes_dz {
            dz_out[row.dz + (o >> 1u)] = bf16_pair(g, h);
        }
        accumulate(acc, g, o * ROW_QUADS + row.q0);
        if o + 1u < REDUCED {
            accumulate(acc, h, (o + 1u) * ROW_QUADS + row.q0);
        }
    }
}

fn input_steps(acc: ptr<function, Acc>, row: InputRow, first: u32) {
    input_pair(acc, row, first);
    input_pair(acc, row, first + 2u);
    input_pair(acc, row, first + 4u);
    input_pair(acc, row, first + 6u);
}

@compute @workgroup_size(WORKGROUP)
fn backward_input(
    @builtin(workgroup_id) workgroup_id: vec3<u32>,
    @builtin(num_workgroups) num_workgroups: vec3<u32>,
    @builtin(local_invocation_index) local_index: u32,
) {
    let item = linear_item_index(vec3<u32>(workgroup_id.xy, 0u), num_workgroups, local_index, WORKGROUP);
    let rows = active_rows();
    if !UNROLL && item >= rows {
        return;
    }
    let live = item < rows;
    let n = row_read(item, rows);
    let block = block_index(workgroup_id.z);
    let i0 = block * BLOCK;
    let q0 = block_quad(block);
    let dy_row = n * dims.dy_stride + dims.dy_offset;
    let y_row = n * dims.y_stride + dims.y_offset;
    // Block 0 writes dZ (q0 is 0 for it alone, and a constant where it is the only block).
    let writes_dz = WRITE_DZ && live && q0 == 0u;
    let dz_row = n * (padded_to_vec8(dims.out_dim) >> 1u);
    var acc: Acc;
    if UNROLL {
        let row = InputRow(dy_row, y_row, dz_row, q0, writes_dz);
        input_steps(&acc, row, 0u);
        input_steps(&acc, row, 8u);
        input_steps(&acc, row, 16u);
        input_steps(&acc, row, 24u);
        input_steps(&acc, row, 32u);
        input_steps(&acc, row, 40u);
        input_steps(&acc, row, 48u);
        input_steps(&acc, row, 56u);
        input_steps(&acc, row, 64u);
        input_steps(&acc, row, 72u);
        input_steps(&acc, row, 80u);
        input_steps(&acc, row, 88u);
        input_steps(&acc, row, 96u);
        input_steps(&acc, row, 104u);
        input_steps(&acc, row, 112u);
        input_steps(&acc, row, 120u);
    } else {
        let row = InputRow(dy_row, y_row, dz_row, q0, writes_dz);
        let quads = quads_per_row(dims.in_dim);
        for (var o = 0u; o < dims.out_dim; o += 2u) {
            let g = row_gradient(row, o);
            let h = row_gradient(row, o + 1u);
            if writes_dz {
                dz_out[dz_row + (o >> 1u)] = bf16_pair(g, h);
            }
            // W[o][i0 .. i0 + BLOCK] is the packed row's quads from i0 / 4 (BLOCK is a multiple
            // of 4); quads past the row's end are never written.
            accumulate(&acc, g, o * quads + q0);
            if o + 1u < dims.out_dim {
                accumulate(&acc, h, (o + 1u) * quads + q0);
            }
        }
    }
    if !live {
        return;
    }
    if writes_dz {
        for (var p = (dims.out_dim + 1u) >> 1u; p < (padded_to_vec8(dims.out_dim) >> 1u); p++) {
            dz_out[dz_row + p] = 0u;
        }
    }
    let dx_row = n * dims.dx_stride + dims.dx_offset;
    // Pairs of inputs (BLOCK and i0 are multiples of 4): a bf16 pair is one word, the second 0
    // past an odd width (the row's padding).
    for (var j = 0u; j < BLOCK; j += 2u) {
        let i = i0 + j;
        if i < min(dims.in_dim, DX_END) && i + 1u >= DX_FIRST {
            let first = stored_input_gradient(acc_value(&acc, j), n, i);
            var second = 0.0;
            if i + 1u < dims.in_dim {
                second = stored_input_gradient(acc_value(&acc, j + 1u), n, i + 1u);
            }
            if DX_BF16 {
                dx[row_word(dx_row, i, true)] = bf16_pair(first, second);
            } else {
                if i >= DX_FIRST {
                    dx[dx_row + i] = bitcast<u32>(first);
                }
                if i + 1u < min(dims.in_dim, DX_END) {
                    dx[dx_row + i + 1u] = bitcast<u32>(second);
                }
            }
        }
    }
}
