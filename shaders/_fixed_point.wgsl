// The fixed-point code of the hash-table gradient (hash_gradient_scale.wgsl,
// hash_backward_fixed_point.wgsl, adam.wgsl), twin of `field::gpu::fixed_point`: a level's
// values are integers in units of 2^-exponent.

// The bound on any entry's sum is scaled to at most 2^FIXED_POINT_BITS, so rounding (half a
// unit per add) has 2^30 units of room below i32's 2^31.
const FIXED_POINT_BITS: i32 = 30;
// exp2(±126) is a normal f32.
const MAX_EXPONENT: i32 = 126;

// The largest exponent e with bound · 2^e ≤ 2^FIXED_POINT_BITS (0 for a bound of zero, or one
// that is not finite), clamped to ±MAX_EXPONENT.
fn fixed_point_exponent(bound: f32) -> i32 {
    // Not positive (NaN included) or not finite (all exponent bits set): nothing to scale (a
    // zero bound means every add is zero). The bits, not a literal of f32's largest value,
    // which Tint refuses as not representable.
    let finite = (bitcast<u32>(bound) & 0x7f800000u) != 0x7f800000u;
    if !(bound > 0.0 && finite) {
        return 0;
    }
    // bound = m · 2^k with m in [0.5, 1), so bound ≤ 2^k.
    let k = frexp(bound).exp;
    return clamp(FIXED_POINT_BITS - k, -MAX_EXPONENT, MAX_EXPONENT);
}

// round(value · 2^exponent) as i32, ties to even; the clamp only matters for values the bound
// did not cover (never, unless the gradient holds inf or NaN, which become 0 or the clamp).
fn to_fixed_point(value: f32, exponent: i32) -> i32 {
    let scaled = value * exp2(f32(exponent));
    let limit = f32(1 << u32(FIXED_POINT_BITS));
    return i32(round(clamp(scaled, -limit, limit)));
}

fn from_fixed_point(units: i32, exponent: i32) -> f32 {
    return f32(units) * exp2(f32(-exponent));
}
