//! The fixed-point code of the hash-table gradient on devices without float atomics (every
//! browser), the CPU twin of `shaders/_fixed_point.wgsl` (docs/architecture.md, "Fixed-point
//! hash gradients"). Each step, `hash_gradient_scale.wgsl` bounds every entry's sum on a level
//! by Σ|∂L/∂encoding| over the level's columns (each add is a trilinear weight ≤ 1 times one of
//! those values) and picks the largest exponent e that scales the bound to at most
//! 2^[`FIXED_POINT_BITS`]; the backward adds round(value · 2^e) as i32, so no sum overflows, and
//! Adam reads the integers back as units of 2^-e.

/// A level's bound is scaled to at most 2^30: rounding adds at most half a unit per add, and
/// i32 holds 2^31.
pub const FIXED_POINT_BITS: i32 = 30;
/// Exponents stay within ±126, where 2^e is a normal f32.
pub const MAX_EXPONENT: i32 = 126;

/// The largest exponent e with `bound` · 2^e ≤ 2^[`FIXED_POINT_BITS`], within ±[`MAX_EXPONENT`];
/// 0 for a bound that is zero, negative or not finite (`fixed_point_exponent` in WGSL).
pub fn exponent_for(bound: f32) -> i32 {
    if !(bound > 0.0 && bound.is_finite()) {
        return 0;
    }
    // bound = m · 2^k with m in [0.5, 1), as WGSL's frexp gives it.
    let k = frexp_exponent(bound);
    (FIXED_POINT_BITS - k).clamp(-MAX_EXPONENT, MAX_EXPONENT)
}

/// k with x = m · 2^k, m in [0.5, 1), for a positive finite x (subnormals included).
fn frexp_exponent(x: f32) -> i32 {
    let bits = x.to_bits();
    let biased = ((bits >> 23) & 0xff) as i32;
    if biased == 0 {
        // Subnormal: the value is mantissa · 2^-149.
        let mantissa = bits & 0x7f_ffff;
        return 32 - mantissa.leading_zeros() as i32 - 149;
    }
    biased - 126
}

/// round(value · 2^exponent) as i32, ties to even, clamped to ±2^[`FIXED_POINT_BITS`]
/// (`to_fixed_point` in WGSL).
pub fn to_fixed(value: f32, exponent: i32) -> i32 {
    let limit = (1i64 << FIXED_POINT_BITS) as f32;
    let scaled = (value * 2f32.powi(exponent)).clamp(-limit, limit);
    if scaled.is_nan() {
        0
    } else {
        scaled.round_ties_even() as i32
    }
}

/// The value of `units` at `exponent` (`from_fixed_point` in WGSL).
pub fn from_fixed(units: i32, exponent: i32) -> f32 {
    units as f32 * 2f32.powi(-exponent)
}

/// Decodes a fixed-point table gradient in place: `values` is the table's range of the flat
/// gradient buffer as read back (i32 bits), `level_starts[l]` the first entry of level l (the
/// backward's `level_geometry` z), `features` values per entry.
pub fn decode_table(values: &mut [f32], exponents: &[i32], level_starts: &[u32], features: usize) {
    for (i, v) in values.iter_mut().enumerate() {
        let entry = (i / features.max(1)) as u32;
        let level = level_starts.iter().rposition(|&start| entry >= start).unwrap_or(0);
        *v = from_fixed(v.to_bits() as i32, exponents.get(level).copied().unwrap_or(0));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_exponent_scales_the_bound_to_at_most_two_to_the_thirty() {
        for bound in [1e-20f32, 3.7e-9, 0.001, 0.5, 1.0, 1.5, 2.0, 1234.5, 3.0e20] {
            let e = exponent_for(bound);
            let scaled = f64::from(bound) * 2f64.powi(e);
            assert!(scaled <= f64::from(1u32 << 30), "{bound}: e {e}, scaled {scaled}");
            assert!(
                scaled * 2.0 > f64::from(1u32 << 29),
                "{bound}: e {e} wastes bits ({scaled})"
            );
        }
        assert_eq!(exponent_for(1.0), 29);
        assert_eq!(exponent_for(0.75), 30);
        for nothing in [0.0, -1.0, f32::INFINITY, f32::NAN] {
            assert_eq!(exponent_for(nothing), 0);
        }
        assert_eq!(exponent_for(f32::from_bits(1)), MAX_EXPONENT);
        assert_eq!(exponent_for(f32::MAX), FIXED_POINT_BITS - 128);
    }

    #[test]
    fn values_round_to_the_nearest_unit_and_decode_back() {
        assert_eq!(to_fixed(1.0, 29), 1 << 29);
        assert_eq!(to_fixed(-0.25, 2), -1);
        // Ties go to even, as WGSL's round.
        assert_eq!(to_fixed(2.5, 0), 2);
        assert_eq!(to_fixed(-3.5, 0), -4);
        assert_eq!(to_fixed(1e30, 0), 1 << 30);
        assert_eq!(to_fixed(f32::NAN, 0), 0);
        let e = exponent_for(3.0);
        let units = to_fixed(0.123_456, e);
        assert!((from_fixed(units, e) - 0.123_456).abs() <= 2f32.powi(-e));
    }

    #[test]
    fn a_table_decodes_level_by_level() {
        // Two levels of 2 and 3 entries, 2 features each.
        let exponents = [4, -1];
        let mut values: Vec<f32> = [16, -8, 32, 1, 3, -2, 5, 7, 0, 1]
            .iter()
            .map(|&u: &i32| f32::from_bits(u as u32))
            .collect();
        decode_table(&mut values, &exponents, &[0, 2], 2);
        assert_eq!(values, [1.0, -0.5, 2.0, 0.0625, 6.0, -4.0, 10.0, 14.0, 0.0, 2.0]);
    }
}
