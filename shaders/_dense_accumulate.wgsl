// One step of the packed-weight kernels' reduction (`_dense_uniform.wgsl`, and the weight
// gradient reading dZ from storage, dense_backward_weight_packed_storage.wgsl): BLOCK
// accumulators take `value` times BLOCK values of the includer's `weights` binding (vec4s).
// Includers declare `weights` and `override BLOCK`.
//!include _dense_acc.wgsl

// acc += value · (BLOCK weights: the packed row's quads from `w`). Each quad's load sits behind
// its own BLOCK test: SwiftShader's compiler does not drop loads whose values go unused.
fn accumulate(acc: ptr<function, Acc>, value: f32, w: u32) {
    if BLOCK > 0u {
        (*acc).a0 += value * weights[w + 0u];
    }
    if BLOCK > 4u {
        (*acc).a1 += value * weights[w + 1u];
    }
    if BLOCK > 8u {
        (*acc).a2 += value * weights[w + 2u];
    }
    if BLOCK > 12u {
        (*acc).a3 += value * weights[w + 3u];
    }
    if BLOCK > 16u {
        (*acc).a4 += value * weights[w + 4u];
    }
    if BLOCK > 20u {
        (*acc).a5 += value * weights[w + 5u];
    }
    if BLOCK > 24u {
        (*acc).a6 += value * weights[w + 6u];
    }
    if BLOCK > 28u {
        (*acc).a7 += value * weights[w + 7u];
    }
    if BLOCK > 32u {
        (*acc).a8 += value * weights[w + 8u];
    }
    if BLOCK > 36u {
        (*acc).a9 += value * weights[w + 9u];
    }
    if BLOCK > 40u {
        (*acc).a10 += value * weights[w + 10u];
    }
    if BLOCK > 44u {
        (*acc).a11 += value * weights[w + 11u];
    }
    if BLOCK > 48u {
        (*acc).a12 += value * weights[w + 12u];
    }
    if BLOCK > 52u {
        (*acc).a13 += value * weights[w + 13u];
    }
    if BLOCK > 56u {
        (*acc).a14 += value * weights[w + 14u];
    }
    if BLOCK > 60u {
        (*acc).a15 += value * weights[w + 15u];
    }
}
