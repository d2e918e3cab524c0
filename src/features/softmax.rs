//! The softmax of attention scores, with an `exp` that vectorizes (on x86-64 also compiled with
//! AVX2+FMA and picked at run time, like the matmul in `ops.rs`).

/// `e^x` to about 2e-7 relative for the softmax (Cephes' `expf`: `x = n ln 2 + r`, a degree-6
/// polynomial in `r`, `2^n` built in the exponent bits). Unlike `f32::exp` (a libm call) it
/// vectorizes, and attention at 4800 tokens evaluates billions of them per frame. Inputs below
/// -87 give about 1e-38 instead of a subnormal or 0, which no softmax sum notices.
#[inline(always)]
pub fn exp_approx(x: f32) -> f32 {
    const LOG2E: f32 = std::f32::consts::LOG2_E;
    // ln 2 split in two so that `n * LN2_HI` is exact.
    const LN2_HI: f32 = 0.693_359_4;
    const LN2_LO: f32 = -2.121_944_4e-4;
    // Adding 1.5 * 2^23 rounds to an integer without a (non-vectorizing) call to `round`.
    const ROUND: f32 = 12_582_912.0;
    let x = x.clamp(-87.0, 88.0);
    let n = (x * LOG2E + ROUND) - ROUND;
    let r = x - n * LN2_HI - n * LN2_LO;
    let p = ((((1.987_569_1e-4 * r + 1.398_199_9e-3) * r + 8.333_452e-3) * r + 4.166_579_6e-2) * r + 1.666_666_5e-1)
        * r
        + 0.5;
    let y = p * r * r + r + 1.0;
    y * f32::from_bits(((n as i32 + 127) as u32) << 23)
}

/// Replaces each row of `rows` (rows of `row_len` values) by its softmax.
pub fn softmax_rows(rows: &mut [f32], row_len: usize) {
    #[cfg(target_arch = "x86_64")]
    if super::ops::has_avx2_fma() {
        // SAFETY: the CPU supports AVX2 and FMA (checked just above).
        unsafe { softmax_rows_avx2(rows, row_len) };
        return;
    }
    softmax_rows_generic(rows, row_len);
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn softmax_rows_avx2(rows: &mut [f32], row_len: usize) {
    softmax_rows_generic(rows, row_len)
}

#[inline(always)]
fn softmax_rows_generic(rows: &mut [f32], row_len: usize) {
    for row in rows.chunks_exact_mut(row_len) {
        let max = row.iter().fold(f32::NEG_INFINITY, |m, &v| m.max(v));
        row.iter_mut().for_each(|v| *v = exp_approx(*v - max));
        // Eight partial sums so that the sum vectorizes (a single f32 accumulator must be summed
        // in order); also a little more accurate.
        let mut parts = [0f32; 8];
        for c in row.chunks(8) {
            for (p, &v) in parts.iter_mut().zip(c) {
                *p += v;
            }
        }
        let inv = 1.0 / parts.iter().sum::<f32>();
        row.iter_mut().for_each(|v| *v *= inv);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_fast_exp_and_softmax_are_as_accurate_as_f32() {
        let mut worst = 0f64;
        for i in -870_000..=880_000 {
            let x = i as f32 * 1e-4;
            let want = (x as f64).exp();
            worst = worst.max((exp_approx(x) as f64 - want).abs() / want);
        }
        assert!(worst < 3e-7, "exp relative error {worst:.2e}");
        assert_eq!(exp_approx(0.0), 1.0);
        assert!(exp_approx(-1000.0) >= 0.0 && exp_approx(-1000.0) < 1e-37);
        // Rows of ragged length (not a multiple of the 8 partial sums), with and without AVX2.
        for len in [1, 7, 13, 100] {
            let x: Vec<f32> = (0..3 * len)
                .map(|i| (i as f32 * 1.7 + len as f32).sin() * 30.0)
                .collect();
            let want: Vec<f64> = x
                .chunks_exact(len)
                .flat_map(|row| {
                    let m = row.iter().fold(f32::MIN, |a, &b| a.max(b)) as f64;
                    let e: Vec<f64> = row.iter().map(|&v| (v as f64 - m).exp()).collect();
                    let s: f64 = e.iter().sum();
                    e.into_iter().map(move |v| v / s)
                })
                .collect();
            let mut got = x.clone();
            softmax_rows(&mut got, len);
            for (g, w) in got.iter().zip(&want) {
                assert!((*g as f64 - w).abs() < 1e-6 * (1.0 + w.abs()), "len {len}: {g} vs {w}");
            }
            let mut got = x.clone();
            softmax_rows_generic(&mut got, len);
            for (g, w) in got.iter().zip(&want) {
                assert!((*g as f64 - w).abs() < 1e-6 * (1.0 + w.abs()), "len {len}: {g} vs {w}");
            }
        }
    }
}
