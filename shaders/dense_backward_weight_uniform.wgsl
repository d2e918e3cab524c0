// Weight gradient of one dense layer on CPU devices (src/field/gpu/dense/,
// `DenseFamily::UniformWeights`): dW[o][i] = Σ_n dZ[n][o] · X[n][i], dZ = dY ⊙ act'(Y), summed
// deterministically like `dense_backward_weight.wgsl` (per-chunk partial matrices, then its
// `reduce_chunks` in order), but with dZ read through a uniform binding so that a SIMD group of
// lanes (one input column i each) loads each dZ value once instead of once per lane.
//
// `mask_output_gradient` (or, in a layer with an input gradient, that kernel with WRITE_DZ)
// writes dZ as bf16 rows (`_bf16.wgsl`: `padded_to_vec8(out_dim)` values per row, two per word,
// so that the windows are read as whole vec4<u32>s of 8 values; zeros in the padding; rows past
// N stay 0) into `dz_out`; then one `chunk_partial_sums` workgroup per span of SPAN chunks of
// dims.chunk_rows rows reads each chunk's dZ through its 64 KiB uniform window (`dz0` .. `dz7`,
// bound at the chunk's offset) and writes the span's partial matrix.
//
// dense_backward_weight_packed_storage.wgsl is the same sum reading dZ from one storage binding
// (what the page runs on a CPU device, `_dense_uniform.wgsl` says why).
//!include _dense_chunk_sums.wgsl
//!include _dispatch.wgsl

const WORKGROUP: u32 = 64u;

// dY in f32 or bf16 rows (DY_BF16, as in `_dense_backward_input_packed.wgsl`).
@group(0) @binding(1) var<storage, read> dy: array<u32>;
override DY_BF16: bool = false;
@group(0) @binding(6) var<storage, read_write> dz_out: array<u32>;

// dZ[n][o] of the layer, 0 past its outputs.
fn dz_value(n: u32, o: u32) -> f32 {
    if o >= dims.out_dim {
        return 0.0;
    }
    let dy_row = n * dims.dy_stride + dims.dy_offset;
    let dy_value = row_value(dy[row_word(dy_row, o, DY_BF16)], o, DY_BF16);
    return output_gradient(dy_value, n * dims.y_stride + dims.y_offset, o);
}

@compute @workgroup_size(WORKGROUP)
fn mask_output_gradient(
    @builtin(workgroup_id) workgroup_id: vec3<u32>,
    @builtin(num_workgroups) num_workgroups: vec3<u32>,
    @builtin(local_invocation_index) local_index: u32,
) {
    // One word (two values) of a dZ row per invocation.
    let e = linear_item_index(workgroup_id, num_workgroups, local_index, WORKGROUP);
    let row_words = padded_to_vec8(dims.out_dim) >> 1u;
    if e >= active_rows() * row_words {
        return;
    }
    let n = e / row_words;
    let o = 2u * (e - n * row_words);
    dz_out[e] = bf16_pair(dz_value(n, o), dz_value(n, o + 1u));
}

// One dispatch sums up to WINDOWS (8) chunks, each through its own 64 KiB window: lavapipe paid
// about 0.15 ms per dispatch when every chunk had its own (docs/results/bench.md). WGSL cannot
// index bindings or pass a uniform pointer to a function (naga refuses it), hence one small
// function per window.
@group(1) @binding(1) var<uniform> dz0: array<vec4<u32>, 4096>;
@group(1) @binding(2) var<uniform> dz1: array<vec4<u32>, 4096>;
@group(1) @binding(3) var<uniform> dz2: array<vec4<u32>, 4096>;
@group(1) @binding(4) var<uniform> dz3: array<vec4<u32>, 4096>;
@group(1) @binding(5) var<uniform> dz4: array<vec4<u32>, 4096>;
@group(1) @binding(6) var<uniform> dz5: array<vec4<u32>, 4096>;
@group(1) @binding(7) var<uniform> dz6: array<vec4<u32>, 4096>;
@group(1) @binding(8) var<uniform> dz7: array<vec4<u32>, 4096>;

// First vec4<u32> (8 values) of row r of window w's outputs from o0, counted from the window's
// start (where its binding starts).
fn oct_at(w: Window, r: u32) -> u32 {
    return r * w.row_octs + w.o0_oct;
}

// 64 bf16 values, 8 per vec4<u32>, as the quads `add_scaled` takes.
fn bf16_acc(w0: vec4<u32>, w1: vec4<u32>, w2: vec4<u32>, w3: vec4<u32>, w4: vec4<u32>, w5: vec4<u32>, w6: vec4<u32>, w7: vec4<u32>) -> Acc {
    return Acc(
        bf16_first_quad(w0), bf16_second_quad(w0), bf16_first_quad(w1), bf16_second_quad(w1),
        bf16_first_quad(w2), bf16_second_quad(w2), bf16_first_quad(w3), bf16_second_quad(w3),
        bf16_first_quad(w4), bf16_second_quad(w4), bf16_first_quad(w5), bf16_second_quad(w5),
        bf16_first_quad(w6), bf16_second_quad(w6), bf16_first_quad(w7), bf16_second_quad(w7),
    );
}
// dZ[row][o0 .. o0 + 64] of window k as quads, from the 8 vec4<u32>s from `b` (those past the
// row's end give outputs that are never written; those past BLOCK are dropped by
// specialisation), and one window's sum: acc += X[row][column] · dZ[row][o0 .. o0 + BLOCK] over
// its rows.
fn quads_0(b: u32) -> Acc { return bf16_acc(dz0[b + 0u], dz0[b + 1u], dz0[b + 2u], dz0[b + 3u], dz0[b + 4u], dz0[b + 5u], dz0[b + 6u], dz0[b + 7u]); }
fn quads_1(b: u32) -> Acc { return bf16_acc(dz1[b + 0u], dz1[b + 1u], dz1[b + 2u], dz1[b + 3u], dz1[b + 4u], dz1[b + 5u], dz1[b + 6u], dz1[b + 7u]); }
fn quads_2(b: u32) -> Acc { return bf16_acc(dz2[b + 0u], dz2[b + 1u], dz2[b + 2u], dz2[b + 3u], dz2[b + 4u], dz2[b + 5u], dz2[b + 6u], dz2[b + 7u]); }
fn quads_3(b: u32) -> Acc { return bf16_acc(dz3[b + 0u], dz3[b + 1u], dz3[b + 2u], dz3[b + 3u], dz3[b + 4u], dz3[b + 5u], dz3[b + 6u], dz3[b + 7u]); }
fn quads_4(b: u32) -> Acc { return bf16_acc(dz4[b + 0u], dz4[b + 1u], dz4[b + 2u], dz4[b + 3u], dz4[b + 4u], dz4[b + 5u], dz4[b + 6u], dz4[b + 7u]); }
fn quads_5(b: u32) -> Acc { return bf16_acc(dz5[b + 0u], dz5[b + 1u], dz5[b + 2u], dz5[b + 3u], dz5[b + 4u], dz5[b + 5u], dz5[b + 6u], dz5[b + 7u]); }
fn quads_6(b: u32) -> Acc { return bf16_acc(dz6[b + 0u], dz6[b + 1u], dz6[b + 2u], dz6[b + 3u], dz6[b + 4u], dz6[b + 5u], dz6[b + 6u], dz6[b + 7u]); }
fn quads_7(b: u32) -> Acc { return bf16_acc(dz7[b + 0u], dz7[b + 1u], dz7[b + 2u], dz7[b + 3u], dz7[b + 4u], dz7[b + 5u], dz7[b + 6u], dz7[b + 7u]); }
fn window_0(a: ptr<function, Acc>, w: Window) { for (var r = 0u; r < w.count; r++) { add_scaled(a, x_at(w, r), quads_0(oct_at(w, r))); } }
fn window_1(a: ptr<function, Acc>, w: Window) { for (var r = 0u; r < w.count; r++) { add_scaled(a, x_at(w, r), quads_1(oct_at(w, r))); } }
fn window_2(a: ptr<function, Acc>, w: Window) { for (var r = 0u; r < w.count; r++) { add_scaled(a, x_at(w, r), quads_2(oct_at(w, r))); } }
fn window_3(a: ptr<function, Acc>, w: Window) { for (var r = 0u; r < w.count; r++) { add_scaled(a, x_at(w, r), quads_3(oct_at(w, r))); } }
fn window_4(a: ptr<function, Acc>, w: Window) { for (var r = 0u; r < w.count; r++) { add_scaled(a, x_at(w, r), quads_4(oct_at(w, r))); } }
fn window_5(a: ptr<function, Acc>, w: Window) { for (var r = 0u; r < w.count; r++) { add_scaled(a, x_at(w, r), quads_5(oct_at(w, r))); } }
fn window_6(a: ptr<function, Acc>, w: Window) { for (var r = 0u; r < w.count; r++) { add_scaled(a, x_at(w, r), quads_6(oct_at(w, r))); } }
fn window_7(a: ptr<function, Acc>, w: Window) { for (var r = 0u; r < w.count; r++) { add_scaled(a, x_at(w, r), quads_7(oct_at(w, r))); } }

@compute @workgroup_size(COLUMNS)
fn chunk_partial_sums(
    @builtin(workgroup_id) workgroup_id: vec3<u32>,
    @builtin(local_invocation_index) local_index: u32,
) {
    let i = workgroup_id.x * COLUMNS + local_index;
    let o0 = workgroup_id.y * BLOCK;
    let first_slot = workgroup_id.z * SPAN;
    let first = chunk.first + first_slot;
    var acc: Acc;
    for (var s = 0u; s < SPAN; s++) {
        let w = chunk_window(first + s, i, o0);
        switch first_slot + s {
            case 0u: { window_0(&acc, w); }
            case 1u: { window_1(&acc, w); }
            case 2u: { window_2(&acc, w); }
            case 3u: { window_3(&acc, w); }
            case 4u: { window_4(&acc, w); }
            case 5u: { window_5(&acc, w); }
            case 6u: { window_6(&acc, w); }
            default: { window_7(&acc, w); }
        }
    }
    store_partials(&acc, first / SPAN, i, o0);
}
