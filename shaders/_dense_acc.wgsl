// The BLOCK (a multiple of 4 up to 64) accumulators of one invocation of the uniform-weight dense
// kernels (src/field/gpu/dense/uniform.rs), as named vec4s rather than an indexed array: a
// private array indexed in a loop ends up in scratch memory on lavapipe, and every scratch or
// storage access there is a per-lane loop. Quads past BLOCK are dropped when the pipeline is
// specialised (BLOCK is an override constant), so a narrow layer pays for its own width alone.
// One invocation covering a whole row of a 32- or 64-wide layer loads each of its inputs once
// instead of once per block of 16 (docs/results/bench.md).
//
// Stages declare `override BLOCK: u32`.

struct Acc {
    a0: vec4<f32>,
    a1: vec4<f32>,
    a2: vec4<f32>,
    a3: vec4<f32>,
    a4: vec4<f32>,
    a5: vec4<f32>,
    a6: vec4<f32>,
    a7: vec4<f32>,
    a8: vec4<f32>,
    a9: vec4<f32>,
    a10: vec4<f32>,
    a11: vec4<f32>,
    a12: vec4<f32>,
    a13: vec4<f32>,
    a14: vec4<f32>,
    a15: vec4<f32>,
}

// acc += value · q, quad by quad, for the BLOCK / 4 quads in use.
fn add_scaled(acc: ptr<function, Acc>, value: f32, q: Acc) {
    if BLOCK > 0u {
        (*acc).a0 += value * q.a0;
    }
    if BLOCK > 4u {
        (*acc).a1 += value * q.a1;
    }
    if BLOCK > 8u {
        (*acc).a2 += value * q.a2;
    }
    if BLOCK > 12u {
        (*acc).a3 += value * q.a3;
    }
    if BLOCK > 16u {
        (*acc).a4 += value * q.a4;
    }
    if BLOCK > 20u {
        (*acc).a5 += value * q.a5;
    }
    if BLOCK > 24u {
        (*acc).a6 += value * q.a6;
    }
    if BLOCK > 28u {
        (*acc).a7 += value * q.a7;
    }
    if BLOCK > 32u {
        (*acc).a8 += value * q.a8;
    }
    if BLOCK > 36u {
        (*acc).a9 += value * q.a9;
    }
    if BLOCK > 40u {
        (*acc).a10 += value * q.a10;
    }
    if BLOCK > 44u {
        (*acc).a11 += value * q.a11;
    }
    if BLOCK > 48u {
        (*acc).a12 += value * q.a12;
    }
    if BLOCK > 52u {
        (*acc).a13 += value * q.a13;
    }
    if BLOCK > 56u {
        (*acc).a14 += value * q.a14;
    }
    if BLOCK > 60u {
        (*acc).a15 += value * q.a15;
    }
}

// Accumulator j (0 ≤ j < BLOCK).
fn acc_value(acc: ptr<function, Acc>, j: u32) -> f32 {
    let q = j >> 2u;
    var v = (*acc).a0;
    if BLOCK > 4u && q == 1u {
        v = (*acc).a1;
    }
    if BLOCK > 8u && q == 2u {
        v = (*acc).a2;
    }
    if BLOCK > 12u && q == 3u {
        v = (*acc).a3;
    }
    if BLOCK > 16u && q == 4u {
        v = (*acc).a4;
    }
    if BLOCK > 20u && q == 5u {
        v = (*acc).a5;
    }
    if BLOCK > 24u && q == 6u {
        v = (*acc).a6;
    }
    if BLOCK > 28u && q == 7u {
        v = (*acc).a7;
    }
    if BLOCK > 32u && q == 8u {
        v = (*acc).a8;
    }
    if BLOCK > 36u && q == 9u {
        v = (*acc).a9;
    }
    if BLOCK > 40u && q == 10u {
        v = (*acc).a10;
    }
    if BLOCK > 44u && q == 11u {
        v = (*acc).a11;
    }
    if BLOCK > 48u && q == 12u {
        v = (*acc).a12;
    }
    if BLOCK > 52u && q == 13u {
        v = (*acc).a13;
    }
    if BLOCK > 56u && q == 14u {
        v = (*acc).a14;
    }
    if BLOCK > 60u && q == 15u {
        v = (*acc).a15;
    }
    return v[j & 3u];
}
