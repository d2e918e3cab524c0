// The weight gradient of dense_backward_weight_uniform.wgsl (`chunk_partial_sums`) with dZ read
// from one storage binding instead of 64 KiB uniform windows: what the page runs on a CPU device
// (`_dense_uniform.wgsl` says why). dZ is the same buffer, in the same padded rows, so one
// dispatch sums every chunk (workgroup z = chunk, `chunk.first` = 0) and each chunk adds its rows
// in the same order as the windowed kernel: the partial matrices are the same, bit for bit.
//!include _dense_chunk_sums.wgsl
//!include _dense_accumulate.wgsl

// dZ in padded rows. Named `weights` because `accumulate` (`_dense_accumulate.wgsl`) reads the
// binding of that name: its BLOCK tests skip the quads past BLOCK, whose loads SwiftShader's
// compiler would otherwise make although their values go unused.
@group(1) @binding(1) var<storage, read> weights: array<vec4<f32>>;

@compute @workgroup_size(COLUMNS)
fn chunk_partial_sums(
    @builtin(workgroup_id) workgroup_id: vec3<u32>,
    @builtin(local_invocation_index) local_index: u32,
) {
    let i = workgroup_id.x * COLUMNS + local_index;
    let o0 = workgroup_id.y * BLOCK;
    let index = chunk.first + workgroup_id.z;
    let w = chunk_window(index, i, o0);
    var acc: Acc;
    for (var r = 0u; r < w.count; r++) {
        accumulate(&acc, x_at(w, r), (w.first_row + r) * w.row_quads + w.q0);
    }
    store_partials(&acc, index, i, o0);
}
