// Forward of one bias-free dense layer, weights from a uniform binding (`_dense_uniform.wgsl`):
// Y[n][o] = act(Σ_i X[n][i] · W[o][i]). Invocation: row n (x, y spread the rows, Dispatch1d),
// outputs o0 .. o0 + BLOCK with o0 = BLOCK · workgroup_id.z.
//
// This stage reads the packed weights from a uniform binding; dense_forward_packed_storage.wgsl
// is the same kernel reading them from storage.
//!include _dense_forward_packed.wgsl

@group(0) @binding(2) var<uniform> weights: array<vec4<f32>, UNIFORM_WEIGHT_VEC4S>;
