// The ray batch's per-ray records, shared by ray_batch, sample_points, composite and whoever
// reads the view direction. Mirrors `field::gpu::rays::RayGeometry` (48 bytes) and the target
// word layout of `field::gpu::rays` (TARGET_* constants).
struct RayGeometry {
    origin: vec3<f32>,
    // z-depth per unit of t (cosine between the direction and the optical axis).
    z_per_t: f32,
    // Unit direction in world space.
    dir: vec3<f32>,
    // [near, far]: the ray clipped to the scene box; both 0 when it misses.
    near: f32,
    far: f32,
    // Measured z-depth in metres; 0 where the depth image has no reading.
    depth: f32,
    // Global pixel index: frame * width * height + y * width + x.
    pixel: u32,
    // RAY_HITS_BOX | RAY_HAS_CODE.
    flags: u32,
}

const RAY_HITS_BOX: u32 = 1u;
const RAY_HAS_CODE: u32 = 2u;
const NO_LABEL: u32 = 0xffffffffu;

// Targets: one row of TARGET_HEADER_WORDS + feature_dim u32 words per ray; floats as bits.
const TARGET_RGB: u32 = 0u;
const TARGET_DEPTH: u32 = 3u;
const TARGET_LABEL: u32 = 4u;
const TARGET_FLAGS: u32 = 5u;
const TARGET_PIXEL: u32 = 6u;
const TARGET_HEADER_WORDS: u32 = 8u;
