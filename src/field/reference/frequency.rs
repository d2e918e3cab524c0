//! Sin/cos frequency encoding of a position (NeRF's positional encoding, tiny-cuda-nn order).
//!
//! For each axis a and octave k < L: `out[a·2L + 2k] = sin(2^k·π·p_a)` and
//! `out[a·2L + 2k + 1] = cos(2^k·π·p_a)`, so 6·L values (12 for the default L = 2, 60 for the
//! frequency-only baseline L = 10). The position itself is not appended: with p ∈ [0,1] the
//! k = 0 sine/cosine pair already determines p, and leaving it out keeps the paper's 44-value
//! input. There are no parameters and positions are data, so there is no backward pass.
use super::real::Real;

pub fn output_dim(frequencies: usize) -> usize {
    6 * frequencies
}

/// `pos`: normalized position; `out`: `output_dim(frequencies)` values.
pub fn encode<R: Real>(frequencies: usize, pos: [R; 3], out: &mut [R]) {
    for (axis, &p) in pos.iter().enumerate() {
        for k in 0..frequencies {
            let phase = p * R::of(std::f64::consts::PI * (1u64 << k) as f64);
            out[axis * 2 * frequencies + 2 * k] = phase.sin();
            out[axis * 2 * frequencies + 2 * k + 1] = phase.cos();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn layout_is_axis_then_octave_then_sin_cos() {
        let mut out = [0.0f64; 12];
        encode(2, [0.25, 0.5, 0.0], &mut out);
        let h = std::f64::consts::FRAC_1_SQRT_2;
        let expect = [h, h, 1.0, 0.0, 1.0, 0.0, 0.0, -1.0, 0.0, 1.0, 0.0, 1.0];
        for (o, e) in out.iter().zip(expect) {
            assert!((o - e).abs() < 1e-12, "{out:?}");
        }
    }
}
