// The weight gradient of dense_backward_weight_uniform.wgsl (`chunk_partial_sums`) with dZ read
// from one storage binding instead of 64 KiB uniform windows: what the page runs on a CPU device
// (`_dense_uniform.wgsl` says why). dZ is the same buffer, in the same padded rows, so one
// dispatch sums every chunk (workgroup z = chunk, `chunk.first` = 0) and each chunk adds its rows
// in the same order as the windowed kernel: the partial matrices are the same, bit for bit.
//!include _dense_chunk_sums.wgsl

@group(1) @binding(1) var<storage, read> dz: array<vec4<f32>>;

// dZ[row][o0 .. o0 + 64] as quads from quad `b` (quads past the row's end give outputs that are
// never written; those past BLOCK are dropped by specialisation).
fn quads(b: u32) -> Acc {
    return Acc(dz[b + 0u], dz[b + 1u], dz[b + 2u], dz[b + 3u], dz[b + 4u], dz[b + 5u], dz[b + 6u], dz[b + 7u], dz[b + 8u], dz[b + 9u], dz[b + 10u], dz[b + 11u], dz[b + 12u], dz[b + 13u], dz[b + 14u], dz[b + 15u]);
}

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
        add_scaled(&acc, x_at(w, r), quads((w.first_row + r) * w.row_quads + w.q0));
    }
    store_partials(&acc, index, i, o0);
}
