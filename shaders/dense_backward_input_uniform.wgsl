// Input gradient of one dense layer, weights from a uniform binding (`_dense_uniform.wgsl`):
// dX[n][i] = Σ_o dZ[n][o] · W[o][i], dZ = dY ⊙ act'(Y) (ReLU: Y > 0, 0 at 0 as the reference).
// dX is overwritten. Invocation: row n, inputs i0 .. i0 + BLOCK with i0 = BLOCK · workgroup_id.z.
//
// With WRITE_DZ the invocations of the first input block also write the dZ they form into
// `dz_out` in the rows the uniform-window weight gradient reads (`padded_to_vec4(out_dim)` per
// row, zeros in the padding; `dense_backward_weight_uniform.wgsl`), so that layer needs no
// masking kernel of its own: one pass over dY and Y instead of two.
//
// This stage reads the packed weights from a uniform binding;
// dense_backward_input_packed_storage.wgsl is the same kernel reading them from storage.
//!include _dense_backward_input_packed.wgsl

@group(0) @binding(3) var<uniform> weights: array<vec4<f32>, UNIFORM_WEIGHT_VEC4S>;
