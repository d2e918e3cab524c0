// The weight gradient of dense_backward_weight_uniform.wgsl (`chunk_partial_sums`) with dZ read
// from one storage binding instead of 64 KiB uniform windows: what the page runs on a CPU device
// (`_dense_uniform.wgsl` says why). dZ is the same buffer, in the same bf16 rows, so one dispatch
// sums every chunk (workgroup z = span of SPAN chunks, `chunk.first` = 0) and each span adds its
// rows in the same order as the windowed kernel: the partial matrices are the same, bit for bit.
//!include _dense_chunk_sums.wgsl

// dZ in bf16 rows (`_bf16.wgsl`), 8 values per vec4<u32>.
@group(1) @binding(1) var<storage, read> dz: array<vec4<u32>>;

// acc += value · dZ[row][o0 .. o0 + BLOCK] (the row's vec4<u32>s from `w`). Each load sits
// behind its own BLOCK test: SwiftShader's compiler does not drop loads whose values go unused.
fn accumulate_bf16(acc: ptr<function, Acc>, value: f32, w: u32) {
    if BLOCK > 0u {
        let v = dz[w + 0u];
        (*acc).a0 += value * bf16_first_quad(v);
        if BLOCK > 4u {
            (*acc).a1 += value * bf16_second_quad(v);
        }
    }
    if BLOCK > 8u {
        let v = dz[w + 1u];
        (*acc).a2 += value * bf16_first_quad(v);
        if BLOCK > 12u {
            (*acc).a3 += value * bf16_second_quad(v);
        }
    }
    if BLOCK > 16u {
        let v = dz[w + 2u];
        (*acc).a4 += value * bf16_first_quad(v);
        if BLOCK > 20u {
            (*acc).a5 += value * bf16_second_quad(v);
        }
    }
    if BLOCK > 24u {
        let v = dz[w + 3u];
        (*acc).a6 += value * bf16_first_quad(v);
        if BLOCK > 28u {
            (*acc).a7 += value * bf16_second_quad(v);
        }
    }
    if BLOCK > 32u {
        let v = dz[w + 4u];
        (*acc).a8 += value * bf16_first_quad(v);
        if BLOCK > 36u {
            (*acc).a9 += value * bf16_second_quad(v);
        }
    }
    if BLOCK > 40u {
        let v = dz[w + 5u];
        (*acc).a10 += value * bf16_first_quad(v);
        if BLOCK > 44u {
            (*acc).a11 += value * bf16_second_quad(v);
        }
    }
    if BLOCK > 48u {
        let v = dz[w + 6u];
        (*acc).a12 += value * bf16_first_quad(v);
        if BLOCK > 52u {
            (*acc).a13 += value * bf16_second_quad(v);
        }
    }
    if BLOCK > 56u {
        let v = dz[w + 7u];
        (*acc).a14 += value * bf16_first_quad(v);
        if BLOCK > 60u {
            (*acc).a15 += value * bf16_second_quad(v);
        }
    }
}

@compute @workgroup_size(COLUMNS)
fn chunk_partial_sums(
    @builtin(workgroup_id) workgroup_id: vec3<u32>,
    @builtin(local_invocation_index) local_index: u32,
) {
    let i = workgroup_id.x * COLUMNS + local_index;
    let o0 = workgroup_id.y * BLOCK;
    let first = chunk.first + workgroup_id.z * SPAN;
    var acc: Acc;
    for (var s = 0u; s < SPAN; s++) {
        let w = chunk_window(first + s, i, o0);
        for (var r = 0u; r < w.count; r++) {
            accumulate_bf16(&acc, x_at(w, r), (w.first_row + r) * w.row_octs + w.o0_oct);
        }
    }
    store_partials(&acc, first / SPAN, i, o0);
}
