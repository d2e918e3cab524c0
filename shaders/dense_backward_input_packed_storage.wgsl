// The input gradient of dense_backward_input_uniform.wgsl with the packed weights read from a
// storage binding instead of a uniform one: what the page runs on a CPU device
// (`_dense_uniform.wgsl` says why).
//!include _dense_backward_input_packed.wgsl

@group(0) @binding(3) var<storage, read> weights: array<vec4<f32>, UNIFORM_WEIGHT_VEC4S>;
