// Copies one layer's [out][in] weights into the layout a uniform-weight kernel reads as whole
// vec4s (`_dense_uniform.wgsl`), zeros in the padding: [in][out padded to a multiple of 4] for
// the forward (TRANSPOSED), [out][in padded] for the input gradient. Run before each use, as the
// parameters change every step. Invocation: one packed element.
//!include _dense_tile.wgsl
//!include _dispatch.wgsl

const PACK_WORKGROUP: u32 = 64u;
override TRANSPOSED: bool = false;

@group(0) @binding(0) var<uniform> dims: DenseDims;
@group(0) @binding(1) var<storage, read> params: array<f32>;
@group(0) @binding(2) var<storage, read_write> packed: array<f32>;
// Named by `_dense_tile.wgsl`'s output_gradient, which this stage does not call.
@group(0) @binding(3) var<storage, read> y: array<f32>;

@compute @workgroup_size(PACK_WORKGROUP)
fn pack_weights(
    @builtin(workgroup_id) workgroup_id: vec3<u32>,
    @builtin(num_workgroups) num_workgroups: vec3<u32>,
    @builtin(local_invocation_index) local_index: u32,
) {
    let e = linear_item_index(workgroup_id, num_workgroups, local_index, PACK_WORKGROUP);
    // Packed rows: `rows` of `row_length`, the last `row_length - columns` of each zero.
    var rows = dims.out_dim;
    var columns = dims.in_dim;
    if TRANSPOSED {
        rows = dims.in_dim;
        columns = dims.out_dim;
    }
    let row_length = padded_to_vec4(columns);
    if e >= rows * row_length {
        return;
    }
    let r = e / row_length;
    let c = e - r * row_length;
    var value = 0.0;
    if c < columns {
        var o = r;
        var i = c;
        if TRANSPOSED {
            o = c;
            i = r;
        }
        value = params[dims.weight_offset + o * dims.in_dim + i];
    }
    packed[e] = value;
}
