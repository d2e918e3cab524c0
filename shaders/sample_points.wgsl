// Places S samples on every ray of the batch exactly as reference::sampling::place_samples
// (src/field/gpu/rays.rs `SamplePointsPass`): with a measured surface whose band overlaps
// [near, far], S - fine stratified samples over [near, far] merged in order with `fine`
// stratified samples over the band; otherwise S stratified samples over [near, far]. Jitter j of
// a ray is random stream STREAM_JITTER + j (CPU twin `rays::sample_jitter`). One invocation per
// ray; sample n = ray * S + s gets its row n of `positions` and `intervals`.
//!include _dispatch.wgsl
//!include _step.wgsl
//!include _ray_random.wgsl
//!include _ray_layout.wgsl
//!include _density.wgsl

// Mirrors `field::gpu::rays::SamplePlanUniforms` (48 bytes).
struct SamplePlanUniforms {
    bounds_min: vec3<f32>,
    // Half-width of the band around the measured surface, metres of t.
    band_half_width: f32,
    bounds_max: vec3<f32>,
    // Samples in the band; the other S - fine are coarse.
    fine: u32,
    // 1: the last sample is opaque (its interval is OPAQUE_INTERVAL, _density.wgsl).
    opaque_last: u32,
}

const WORKGROUP_SIZE: u32 = 64u;

@group(0) @binding(0) var<uniform> step_info: StepUniforms;
@group(0) @binding(1) var<uniform> plan: SamplePlanUniforms;
@group(0) @binding(2) var<storage, read> rays: array<RayGeometry>;
// xyz: the position normalized to [0,1]^3 by the scene box; w: t.
@group(0) @binding(3) var<storage, read_write> positions: array<vec4<f32>>;
// (delta, z-depth of the sample): what compositing needs.
@group(0) @binding(4) var<storage, read_write> intervals: array<vec2<f32>>;

// Sample j of m over [a, b] (reference::sampling::stratified, same operation order).
fn stratified(a: f32, b: f32, j: u32, jitter: f32, m: u32) -> f32 {
    return a + (b - a) * ((f32(j) + jitter) / f32(m));
}

fn jitter(base: u32, j: u32) -> f32 {
    return random_unit(ray_random(base, STREAM_JITTER + j));
}

@compute @workgroup_size(WORKGROUP_SIZE)
fn sample_points(
    @builtin(workgroup_id) workgroup_id: vec3<u32>,
    @builtin(num_workgroups) num_workgroups: vec3<u32>,
    @builtin(local_invocation_index) local_index: u32,
) {
    let ray = linear_item_index(workgroup_id, num_workgroups, local_index, WORKGROUP_SIZE);
    if ray >= step_info.batch_rays || step_info.samples_per_ray == 0u {
        return;
    }
    let r = rays[ray];
    let samples = step_info.samples_per_ray;
    let fine = min(plan.fine, samples);
    let coarse = samples - fine;
    let base = ray_stream_base(step_info.seed, step_info.step, ray);

    var band_lo = 0.0;
    var band_hi = 0.0;
    var use_band = false;
    if r.depth > 0.0 && fine > 0u {
        let surface_t = r.depth / r.z_per_t;
        band_lo = max(surface_t - plan.band_half_width, r.near);
        band_hi = min(surface_t + plan.band_half_width, r.far);
        use_band = band_hi > band_lo;
    }

    let extent = plan.bounds_max - plan.bounds_min;
    let first = ray * samples;
    // Two-pointer merge of the coarse and band samples (reference::sampling::merge_sorted).
    var i = 0u;
    var j = 0u;
    var next_coarse = stratified(r.near, r.far, 0u, jitter(base, 0u), coarse);
    var next_fine = 0.0;
    if use_band {
        next_fine = stratified(band_lo, band_hi, 0u, jitter(base, coarse), fine);
    }
    var previous_t = 0.0;
    for (var s = 0u; s < samples; s++) {
        var t: f32;
        if !use_band {
            t = stratified(r.near, r.far, s, jitter(base, s), samples);
        } else if j >= fine || (i < coarse && next_coarse <= next_fine) {
            t = next_coarse;
            i++;
            if i < coarse {
                next_coarse = stratified(r.near, r.far, i, jitter(base, i), coarse);
            }
        } else {
            t = next_fine;
            j++;
            if j < fine {
                next_fine = stratified(band_lo, band_hi, j, jitter(base, coarse + j), fine);
            }
        }
        let world = r.origin + t * r.dir;
        let normalized = clamp((world - plan.bounds_min) / extent, vec3<f32>(0.0), vec3<f32>(1.0));
        positions[first + s] = vec4<f32>(normalized, t);
        if s > 0u {
            intervals[first + s - 1u] = vec2<f32>(t - previous_t, previous_t * r.z_per_t);
        }
        previous_t = t;
    }
    var last_interval = r.far - previous_t;
    if plan.opaque_last != 0u {
        last_interval = OPAQUE_INTERVAL;
    }
    intervals[first + samples - 1u] = vec2<f32>(last_interval, previous_t * r.z_per_t);
}
