// The input gradient of the packed-weight dense kernels (dense_backward_input_uniform.wgsl,
// dense_backward_input_packed_storage.wgsl): everything but the `weights` binding, which each
// stage declares in its own address space (`_dense_uniform.wgsl` says why there are two).
//!include _dense_uniform.wgsl

override WRITE_DZ: bool = false;

@group(0) @binding(0) var<uniform> dims: DenseDims;
@group(0) @binding(1) var<storage, read> dy: array<f32>;
@group(0) @binding(2) var<storage, read> y: array<f32>;
@group(0) @binding(4) var<storage, read_write> dx: array<f32>;
@group(0) @binding(6) var<storage, read_write> dz_out: array<f32>;

// Where one row's steps read and write (UNROLL).
struct InputRow {
    dy: u32,
    y: u32,
    dz: u32,
    q0: u32,
    writes_dz: bool,
}

// Output o's step of the reduction (UNROLL; `forward_step` in _dense_forward_packed.wgsl says
// why): dZ[n][o], stored where asked, times W[o][i0 .. i0 + BLOCK].
fn input_step(acc: ptr<function, Acc>, row: InputRow, o: u32) {
    if o < REDUCED {
        let g = output_gradient(dy[row.dy + o], row.y + o);
        if row.writes_dz {
            dz_out[row.dz + o] = g;
        }
        accumulate(acc, g, o * ROW_QUADS + row.q0);
    }
}

fn input_steps(acc: ptr<function, Acc>, row: InputRow, first: u32) {
    input_step(acc, row, first);
    input_step(acc, row, first + 1u);
    input_step(acc, row, first + 2u);
    input_step(acc, row, first + 3u);
    input_step(acc, row, first + 4u);
    input_step(acc, row, first + 5u);
    input_step(acc, row, first + 6u);
    input_step(acc, row, first + 7u);
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
    let dz_row = n * padded_to_vec4(dims.out_dim);
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
        let quads = quads_per_row(dims.in_dim);
        for (var o = 0u; o < dims.out_dim; o++) {
            let g = output_gradient(dy[dy_row + o], y_row + o);
            if writes_dz {
                dz_out[dz_row + o] = g;
            }
            // W[o][i0 .. i0 + BLOCK] is the packed row's quads from i0 / 4 (BLOCK is a multiple
            // of 4); quads past the row's end are never written.
            accumulate(&acc, g, o * quads + q0);
        }
    }
    if !live {
        return;
    }
    if writes_dz {
        for (var o = dims.out_dim; o < padded_to_vec4(dims.out_dim); o++) {
            dz_out[dz_row + o] = 0.0;
        }
    }
    let dx_row = n * dims.dx_stride + dims.dx_offset;
    for (var j = 0u; j < BLOCK; j++) {
        let i = i0 + j;
        if i < dims.in_dim {
            dx[dx_row + i] = acc_value(&acc, j);
        }
    }
}
