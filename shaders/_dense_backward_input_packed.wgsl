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

@compute @workgroup_size(WORKGROUP)
fn backward_input(
    @builtin(workgroup_id) workgroup_id: vec3<u32>,
    @builtin(num_workgroups) num_workgroups: vec3<u32>,
    @builtin(local_invocation_index) local_index: u32,
) {
    let n = linear_item_index(vec3<u32>(workgroup_id.xy, 0u), num_workgroups, local_index, WORKGROUP);
    if n >= active_rows() {
        return;
    }
    let i0 = workgroup_id.z * BLOCK;
    let dy_row = n * dims.dy_stride + dims.dy_offset;
    let y_row = n * dims.y_stride + dims.y_offset;
    let quads = quads_per_row(dims.in_dim);
    let writes_dz = WRITE_DZ && workgroup_id.z == 0u;
    let dz_row = n * padded_to_vec4(dims.out_dim);
    var acc: Acc;
    for (var o = 0u; o < dims.out_dim; o++) {
        let g = output_gradient(dy[dy_row + o], y_row + o);
        if writes_dz {
            dz_out[dz_row + o] = g;
        }
        // W[o][i0 .. i0 + BLOCK] is the packed row's quads from i0 / 4 (BLOCK is a multiple of 4);
        // quads past the row's end are never written.
        let w = o * quads + (i0 >> 2u);
        accumulate(&acc, g, w);
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
