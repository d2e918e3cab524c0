// Weight gradient of one dense layer on CPU devices (src/field/gpu/dense/,
// `DenseFamily::UniformWeights`): dW[o][i] = Σ_n dZ[n][o] · X[n][i], dZ = dY ⊙ act'(Y), summed
// deterministically like `dense_backward_weight.wgsl` (per-chunk partial matrices, then its
// `reduce_chunks` in order), but with dZ read through a uniform binding so that a SIMD group of
// lanes (one input column i each) loads each dZ value once instead of once per lane.
//
// `mask_output_gradient` (or, in a layer with an input gradient, that kernel with WRITE_DZ)
// writes dZ packed ([n][o], rows of `padded_to_vec4(out_dim)` so that the windows are read as
// whole vec4s, zeros in the padding; rows past N stay 0) into `dz_out`; then one
// `chunk_partial_sums` workgroup slot per chunk of dims.chunk_rows rows reads that chunk's dZ
// through a 64 KiB uniform window (`dz0` .. `dz7`, bound at the chunk's offset) and writes
// partials[chunk].
//
// dense_backward_weight_packed_storage.wgsl is the same sum reading dZ from one storage binding
// (what the page runs on a CPU device, `_dense_uniform.wgsl` says why).
//!include _dense_chunk_sums.wgsl
//!include _dispatch.wgsl

const WORKGROUP: u32 = 64u;

@group(0) @binding(1) var<storage, read> dy: array<f32>;
@group(0) @binding(6) var<storage, read_write> dz_out: array<f32>;

@compute @workgroup_size(WORKGROUP)
fn mask_output_gradient(
    @builtin(workgroup_id) workgroup_id: vec3<u32>,
    @builtin(num_workgroups) num_workgroups: vec3<u32>,
    @builtin(local_invocation_index) local_index: u32,
) {
    let e = linear_item_index(workgroup_id, num_workgroups, local_index, WORKGROUP);
    let out_padded = padded_to_vec4(dims.out_dim);
    if e >= active_rows() * out_padded {
        return;
    }
    let n = e / out_padded;
    let o = e - n * out_padded;
    var value = 0.0;
    if o < dims.out_dim {
        value = output_gradient(dy[n * dims.dy_stride + dims.dy_offset + o], n * dims.y_stride + dims.y_offset + o);
    }
    dz_out[e] = value;
}

// One dispatch sums up to WINDOWS (8) chunks, each through its own 64 KiB window: lavapipe paid
// about 0.15 ms per dispatch when every chunk had its own (docs/results/bench.md). WGSL cannot
// index bindings or pass a uniform pointer to a function (naga refuses it), hence one small
// function per window.
@group(1) @binding(1) var<uniform> dz0: array<vec4<f32>, 4096>;
@group(1) @binding(2) var<uniform> dz1: array<vec4<f32>, 4096>;
@group(1) @binding(3) var<uniform> dz2: array<vec4<f32>, 4096>;
@group(1) @binding(4) var<uniform> dz3: array<vec4<f32>, 4096>;
@group(1) @binding(5) var<uniform> dz4: array<vec4<f32>, 4096>;
@group(1) @binding(6) var<uniform> dz5: array<vec4<f32>, 4096>;
@group(1) @binding(7) var<uniform> dz6: array<vec4<f32>, 4096>;
@group(1) @binding(8) var<uniform> dz7: array<vec4<f32>, 4096>;

// Quad of row r of window w's outputs from q0, counted from the window's start (where its
// binding starts).
fn quad_at(w: Window, r: u32) -> u32 {
    return r * w.row_quads + w.q0;
}

// dZ[row][o0 .. o0 + 64] of window k as quads from `b` (quads past the row's end give outputs
// that are never written; those past BLOCK are dropped by specialisation), and one window's
// sum: acc += X[row][column] · dZ[row][o0 .. o0 + BLOCK] over its rows.
fn quads_0(b: u32) -> Acc { return Acc(dz0[b + 0u], dz0[b + 1u], dz0[b + 2u], dz0[b + 3u], dz0[b + 4u], dz0[b + 5u], dz0[b + 6u], dz0[b + 7u], dz0[b + 8u], dz0[b + 9u], dz0[b + 10u], dz0[b + 11u], dz0[b + 12u], dz0[b + 13u], dz0[b + 14u], dz0[b + 15u]); }
fn quads_1(b: u32) -> Acc { return Acc(dz1[b + 0u], dz1[b + 1u], dz1[b + 2u], dz1[b + 3u], dz1[b + 4u], dz1[b + 5u], dz1[b + 6u], dz1[b + 7u], dz1[b + 8u], dz1[b + 9u], dz1[b + 10u], dz1[b + 11u], dz1[b + 12u], dz1[b + 13u], dz1[b + 14u], dz1[b + 15u]); }
fn quads_2(b: u32) -> Acc { return Acc(dz2[b + 0u], dz2[b + 1u], dz2[b + 2u], dz2[b + 3u], dz2[b + 4u], dz2[b + 5u], dz2[b + 6u], dz2[b + 7u], dz2[b + 8u], dz2[b + 9u], dz2[b + 10u], dz2[b + 11u], dz2[b + 12u], dz2[b + 13u], dz2[b + 14u], dz2[b + 15u]); }
fn quads_3(b: u32) -> Acc { return Acc(dz3[b + 0u], dz3[b + 1u], dz3[b + 2u], dz3[b + 3u], dz3[b + 4u], dz3[b + 5u], dz3[b + 6u], dz3[b + 7u], dz3[b + 8u], dz3[b + 9u], dz3[b + 10u], dz3[b + 11u], dz3[b + 12u], dz3[b + 13u], dz3[b + 14u], dz3[b + 15u]); }
fn quads_4(b: u32) -> Acc { return Acc(dz4[b + 0u], dz4[b + 1u], dz4[b + 2u], dz4[b + 3u], dz4[b + 4u], dz4[b + 5u], dz4[b + 6u], dz4[b + 7u], dz4[b + 8u], dz4[b + 9u], dz4[b + 10u], dz4[b + 11u], dz4[b + 12u], dz4[b + 13u], dz4[b + 14u], dz4[b + 15u]); }
fn quads_5(b: u32) -> Acc { return Acc(dz5[b + 0u], dz5[b + 1u], dz5[b + 2u], dz5[b + 3u], dz5[b + 4u], dz5[b + 5u], dz5[b + 6u], dz5[b + 7u], dz5[b + 8u], dz5[b + 9u], dz5[b + 10u], dz5[b + 11u], dz5[b + 12u], dz5[b + 13u], dz5[b + 14u], dz5[b + 15u]); }
fn quads_6(b: u32) -> Acc { return Acc(dz6[b + 0u], dz6[b + 1u], dz6[b + 2u], dz6[b + 3u], dz6[b + 4u], dz6[b + 5u], dz6[b + 6u], dz6[b + 7u], dz6[b + 8u], dz6[b + 9u], dz6[b + 10u], dz6[b + 11u], dz6[b + 12u], dz6[b + 13u], dz6[b + 14u], dz6[b + 15u]); }
fn quads_7(b: u32) -> Acc { return Acc(dz7[b + 0u], dz7[b + 1u], dz7[b + 2u], dz7[b + 3u], dz7[b + 4u], dz7[b + 5u], dz7[b + 6u], dz7[b + 7u], dz7[b + 8u], dz7[b + 9u], dz7[b + 10u], dz7[b + 11u], dz7[b + 12u], dz7[b + 13u], dz7[b + 14u], dz7[b + 15u]); }
fn window_0(a: ptr<function, Acc>, w: Window) { for (var r = 0u; r < w.count; r++) { add_scaled(a, x_at(w, r), quads_0(quad_at(w, r))); } }
fn window_1(a: ptr<function, Acc>, w: Window) { for (var r = 0u; r < w.count; r++) { add_scaled(a, x_at(w, r), quads_1(quad_at(w, r))); } }
fn window_2(a: ptr<function, Acc>, w: Window) { for (var r = 0u; r < w.count; r++) { add_scaled(a, x_at(w, r), quads_2(quad_at(w, r))); } }
fn window_3(a: ptr<function, Acc>, w: Window) { for (var r = 0u; r < w.count; r++) { add_scaled(a, x_at(w, r), quads_3(quad_at(w, r))); } }
fn window_4(a: ptr<function, Acc>, w: Window) { for (var r = 0u; r < w.count; r++) { add_scaled(a, x_at(w, r), quads_4(quad_at(w, r))); } }
fn window_5(a: ptr<function, Acc>, w: Window) { for (var r = 0u; r < w.count; r++) { add_scaled(a, x_at(w, r), quads_5(quad_at(w, r))); } }
fn window_6(a: ptr<function, Acc>, w: Window) { for (var r = 0u; r < w.count; r++) { add_scaled(a, x_at(w, r), quads_6(quad_at(w, r))); } }
fn window_7(a: ptr<function, Acc>, w: Window) { for (var r = 0u; r < w.count; r++) { add_scaled(a, x_at(w, r), quads_7(quad_at(w, r))); } }

@compute @workgroup_size(COLUMNS)
fn chunk_partial_sums(
    @builtin(workgroup_id) workgroup_id: vec3<u32>,
    @builtin(local_invocation_index) local_index: u32,
) {
    let i = workgroup_id.x * COLUMNS + local_index;
    let o0 = workgroup_id.y * BLOCK;
    let slot = workgroup_id.z;
    let index = chunk.first + slot;
    let w = chunk_window(index, i, o0);
    var acc: Acc;
    switch slot {
        case 0u: { window_0(&acc, w); }
        case 1u: { window_1(&acc, w); }
        case 2u: { window_2(&acc, w); }
        case 3u: { window_3(&acc, w); }
        case 4u: { window_4(&acc, w); }
        case 5u: { window_5(&acc, w); }
        case 6u: { window_6(&acc, w); }
        default: { window_7(&acc, w); }
    }
    store_partials(&acc, index, i, o0);
}
