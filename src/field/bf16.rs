//! bf16 rows, the CPU twin of `shaders/_bf16.wgsl`: the uniform-window weight gradient stores
//! dZ as bf16 (the top half of an f32), two values per u32 word, value 2p of a row in the low
//! half of word p, rows padded to a multiple of 8 values (docs/architecture.md, "dZ in bf16").
//! The reference rounds dZ the same way where the GPU does (`reference::mlp::StoredRows`).

/// `n` rounded up to a multiple of 8: a bf16 row's length in values (`padded_to_vec8`).
pub fn padded_to_vec8(n: u32) -> u32 {
    n.div_ceil(8) * 8
}

/// u32 words of a bf16 row of `width` values.
pub fn row_words(width: u32) -> u32 {
    padded_to_vec8(width) / 2
}

/// The bf16 nearest `v` (ties to even), as bits (`bf16_bits`). Finite values only, as in WGSL.
pub fn bits(v: f32) -> u16 {
    let u = v.to_bits();
    (u.wrapping_add(0x7fff + ((u >> 16) & 1)) >> 16) as u16
}

/// The f32 a bf16 stands for.
pub fn value(bits: u16) -> f32 {
    f32::from_bits(u32::from(bits) << 16)
}

/// `v` rounded to the nearest bf16 (ties to even), as f32.
pub fn round(v: f32) -> f32 {
    value(bits(v))
}

/// One word of a row: `first` (the even value) low, `second` high (`bf16_pair`).
pub fn pair(first: f32, second: f32) -> u32 {
    u32::from(bits(first)) | (u32::from(bits(second)) << 16)
}

/// Value `j` of a bf16 row held in `words`.
pub fn row_value(words: &[u32], j: usize) -> f32 {
    let word = words[j / 2];
    value((word >> (16 * (j % 2))) as u16)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rounds_to_nearest_with_ties_to_even() {
        // 1 + 2^-8 is halfway between bf16 1.0 and 1 + 2^-7: even mantissa (1.0) wins.
        assert_eq!(round(1.0 + 2f32.powi(-8)), 1.0);
        // 1 + 3·2^-8 is halfway between 1 + 2^-7 (odd) and 1 + 2^-6 (even).
        assert_eq!(round(1.0 + 3.0 * 2f32.powi(-8)), 1.0 + 2f32.powi(-6));
        // Just above halfway rounds up.
        assert_eq!(round(1.0 + 2f32.powi(-8) + 2f32.powi(-20)), 1.0 + 2f32.powi(-7));
        assert_eq!(round(-2.5), -2.5);
        assert_eq!(round(0.0), 0.0);
        assert_eq!(bits(-0.0), 0x8000);
        // A rounding moves a value by at most half a step: 2^-8 of it.
        for k in 0..1000 {
            let v = (k as f32 * 0.7371).sin() * 10f32.powi(k % 30 - 15);
            assert!((round(v) - v).abs() <= v.abs() * 2f32.powi(-8), "{v}");
        }
    }

    #[test]
    fn a_row_packs_two_values_per_word_even_first() {
        let words = [pair(1.5, -2.0), pair(0.25, 0.0)];
        assert_eq!(words[0], 0xc000_3fc0);
        let values: Vec<f32> = (0..4).map(|j| row_value(&words, j)).collect();
        assert_eq!(values, [1.5, -2.0, 0.25, 0.0]);
        assert_eq!((padded_to_vec8(3), padded_to_vec8(8), padded_to_vec8(9)), (8, 8, 16));
        assert_eq!(row_words(79), 40);
    }
}
