// bf16 rows: two values per u32, value 2p of a row in the low half of word p, so a row of
// `padded_to_vec8(width)` values is whole vec4<u32>s of 8 values each (twin:
// src/field/gpu/bf16.rs). bf16 is the top half of an f32: f32's range, 8 bits of mantissa, and
// plain integer operations to convert, so every WebGPU device runs it (no `shader-f16`). The
// uniform-window weight gradient reads dZ stored this way (docs/architecture.md, "dZ in bf16").

// `n` rounded up to a multiple of 8: a bf16 row's length, whole vec4<u32>s.
fn padded_to_vec8(n: u32) -> u32 {
    return (n + 7u) & ~7u;
}

// vec4<u32>s (8 values each) per bf16 row of `width` values.
fn bf16_row_octs(width: u32) -> u32 {
    return padded_to_vec8(width) >> 3u;
}

// The bf16 nearest `v` (ties to even), as the low 16 bits. Finite values only: dZ is finite
// wherever training is.
fn bf16_bits(v: f32) -> u32 {
    let u = bitcast<u32>(v);
    return (u + 0x7fffu + ((u >> 16u) & 1u)) >> 16u;
}

// One word of a bf16 row: `first` (the even value) low, `second` high.
fn bf16_pair(first: f32, second: f32) -> u32 {
    return bf16_bits(first) | (bf16_bits(second) << 16u);
}

// A quad of values as two words.
fn bf16_quad(q: vec4<f32>) -> vec2<u32> {
    return vec2<u32>(bf16_pair(q.x, q.y), bf16_pair(q.z, q.w));
}

// Values 0..3 and 4..7 of the 8 in `w`.
fn bf16_first_quad(w: vec4<u32>) -> vec4<f32> {
    return bitcast<vec4<f32>>(vec4<u32>(w.x << 16u, w.x & 0xffff0000u, w.y << 16u, w.y & 0xffff0000u));
}

fn bf16_second_quad(w: vec4<u32>) -> vec4<f32> {
    return bitcast<vec4<f32>>(vec4<u32>(w.z << 16u, w.z & 0xffff0000u, w.w << 16u, w.w & 0xffff0000u));
}

// Value `index` of a bf16 row from its word (`index` even: the low half).
fn bf16_at(word: u32, index: u32) -> f32 {
    return bitcast<f32>(select(word << 16u, word & 0xffff0000u, (index & 1u) != 0u));
}

// Rows a stage reads or writes as f32 or as bf16 (an override constant per binding, `bf16`),
// bound as array<u32>: value j of the row starting at value `row` (even for bf16 rows, so the
// word and half of a constant j are constants).
fn row_word(row: u32, j: u32, bf16: bool) -> u32 {
    if bf16 {
        return (row >> 1u) + (j >> 1u);
    }
    return row + j;
}

fn row_value(word: u32, j: u32, bf16: bool) -> f32 {
    if bf16 {
        return bf16_at(word, j);
    }
    return bitcast<f32>(word);
}
