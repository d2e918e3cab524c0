// Counter-based random numbers for ray picking and sample jitter: every value is a hash of
// (seed, step, ray, stream), so no state is stored and the CPU twin in
// `field::gpu::rays` (pcg_hash, ray_stream_base, ray_random, random_below, random_unit)
// reproduces every pick and every jitter exactly.

// Streams of one ray (the CPU twin's `rays::stream`).
const STREAM_PIXEL: u32 = 0u;
const STREAM_CLASS: u32 = 1u;
const STREAM_ENTRY: u32 = 2u;
const STREAM_JITTER: u32 = 16u;

// PCG-RXS-M-XS as a hash (Jarzynski & Olano, "Hash Functions for GPU Rendering", 2020).
fn pcg_hash(v: u32) -> u32 {
    let state = v * 747796405u + 2891336453u;
    let word = ((state >> ((state >> 28u) + 4u)) ^ state) * 277803737u;
    return (word >> 22u) ^ word;
}

fn ray_stream_base(seed: u32, step: u32, ray: u32) -> u32 {
    return pcg_hash(pcg_hash(pcg_hash(seed) ^ step) ^ ray);
}

fn ray_random(base: u32, stream: u32) -> u32 {
    return pcg_hash(base ^ stream);
}

// High 32 bits of the 64-bit product a * b (WGSL has no u64).
fn mul_hi_u32(a: u32, b: u32) -> u32 {
    let a_lo = a & 0xffffu;
    let a_hi = a >> 16u;
    let b_lo = b & 0xffffu;
    let b_hi = b >> 16u;
    let lo_lo = a_lo * b_lo;
    let hi_lo = a_hi * b_lo;
    let lo_hi = a_lo * b_hi;
    let hi_hi = a_hi * b_hi;
    // (2^16 - 1) + (2^16 - 1) + (2^16 - 1)^2 = 2^32 - 1: the sum cannot overflow.
    let cross = (lo_lo >> 16u) + (hi_lo & 0xffffu) + lo_hi;
    return hi_hi + (hi_lo >> 16u) + (cross >> 16u);
}

// Uniform in [0, n) by multiply-shift (bias < n / 2^32, unlike `r % n`).
fn random_below(r: u32, n: u32) -> u32 {
    return mul_hi_u32(r, n);
}

// Uniform in [0, 1) with 24 bits, exactly representable, never 1.
fn random_unit(r: u32) -> f32 {
    return f32(r >> 8u) * (1.0 / 16777216.0);
}
