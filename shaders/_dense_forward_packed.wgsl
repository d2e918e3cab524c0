// The forward of the packed-weight dense kernels (dense_forward_uniform.wgsl,
// dense_forward_packed_storage.wgsl): everything but the `weights` binding, which each stage
// declares in its own address space (`_dense_uniform.wgsl` says why there are two).
//!include _dense_uniform.wgsl

@group(0) @binding(0) var<uniform> dims: DenseDims;
@group(0) @binding(1) var<storage, read> x: array<f32>;
@group(0) @binding(3) var<storage, read_write> y: array<f32>;

@compute @workgroup_size(WORKGROUP)
fn forward(
    @builtin(workgroup_id) workgroup_id: vec3<u32>,
    @builtin(num_workgroups) num_workgroups: vec3<u32>,
    @builtin(local_invocation_index) local_index: u32,
) {
    let n = linear_item_index(vec3<u32>(workgroup_id.xy, 0u), num_workgroups, local_index, WORKGROUP);
    if n >= active_rows() {
        return;
    }
    let o0 = workgroup_id.z * BLOCK;
    let x_row = n * dims.x_stride + dims.x_offset;
    // Input i's packed row holds W[0 .. out][i]; outputs o0 .. o0 + BLOCK are its quads from
    // o0 / 4 (BLOCK is a multiple of 4). Quads past the row's end give outputs never written.
    let quads = quads_per_row(dims.out_dim);
    let q0 = o0 >> 2u;
    var acc: Acc;
    for (var i = 0u; i < dims.in_dim; i++) {
        let value = x[x_row + i];
        let w = i * quads + q0;
        accumulate(&acc, value, w);
    }
    let y_row = n * dims.y_stride + dims.y_offset;
    for (var j = 0u; j < BLOCK; j++) {
        let o = o0 + j;
        if o < dims.out_dim {
            var value = acc_value(&acc, j);
            if dims.relu != 0u {
                value = max(value, 0.0);
            }
            y[y_row + o] = value;
        }
    }
}
