// One round of edge-aware refinement of a rendered class map (src/field/gpu/refine.rs; CPU twin
// `field::refine::refine_probabilities` with one iteration): each pixel's class probabilities
// become the mean of its 7 x 7 taps' probabilities, weighted by distance, colour difference and
// log-depth difference. One invocation per pixel; it owns its `classes` output values.
//!include _dispatch.wgsl

// Mirrors `RefineUniforms` in src/field/gpu/refine.rs (32 bytes).
struct RefineUniforms {
    width: u32,
    height: u32,
    classes: u32,
    // Pixels between taps.
    step: u32,
    // 1 / (2 sigma^2) of each term.
    spatial_scale: f32,
    colour_scale: f32,
    depth_scale: f32,
    _pad: u32,
}

// Taps on each side of the centre (`HALF_TAPS` in src/field/refine.rs).
const HALF_TAPS: i32 = 3;
// Log depth at or below this marks a pixel without depth (NaN is not portable in WGSL).
const NO_DEPTH: f32 = -1.0e30;
const WORKGROUP: u32 = 64u;

@group(0) @binding(0) var<uniform> u: RefineUniforms;
// sRGB colour, one RGBA8 word per pixel (r in the low byte), as `pack4x8unorm` writes it.
@group(0) @binding(1) var<storage, read> colour: array<u32>;
@group(0) @binding(2) var<storage, read> log_depth: array<f32>;
@group(0) @binding(3) var<storage, read> probabilities_in: array<f32>;
@group(0) @binding(4) var<storage, read_write> probabilities_out: array<f32>;

@compute @workgroup_size(WORKGROUP)
fn refine(
    @builtin(workgroup_id) workgroup_id: vec3<u32>,
    @builtin(num_workgroups) num_workgroups: vec3<u32>,
    @builtin(local_invocation_index) local_index: u32,
) {
    let pixel = linear_item_index(workgroup_id, num_workgroups, local_index, WORKGROUP);
    if pixel >= u.width * u.height {
        return;
    }
    let x = i32(pixel % u.width);
    let y = i32(pixel / u.width);
    let step = i32(u.step);
    let c0 = unpack4x8unorm(colour[pixel]).rgb;
    let d0 = log_depth[pixel];
    let out_base = pixel * u.classes;
    for (var c = 0u; c < u.classes; c++) {
        probabilities_out[out_base + c] = 0.0;
    }
    var total = 0.0;
    for (var ty = -HALF_TAPS; ty <= HALF_TAPS; ty++) {
        let sy = y + ty * step;
        if sy < 0 || sy >= i32(u.height) {
            continue;
        }
        for (var tx = -HALF_TAPS; tx <= HALF_TAPS; tx++) {
            let sx = x + tx * step;
            if sx < 0 || sx >= i32(u.width) {
                continue;
            }
            let other = u32(sy) * u.width + u32(sx);
            let dc = c0 - unpack4x8unorm(colour[other]).rgb;
            let d1 = log_depth[other];
            var depth2 = 0.0;
            if d0 > NO_DEPTH && d1 > NO_DEPTH {
                depth2 = (d0 - d1) * (d0 - d1);
            }
            let offset2 = f32((ty * ty + tx * tx) * step * step);
            let w = exp(-(offset2 * u.spatial_scale + dot(dc, dc) * u.colour_scale + depth2 * u.depth_scale));
            total += w;
            let in_base = other * u.classes;
            for (var c = 0u; c < u.classes; c++) {
                probabilities_out[out_base + c] += w * probabilities_in[in_base + c];
            }
        }
    }
    // The centre tap has weight 1, so total >= 1.
    for (var c = 0u; c < u.classes; c++) {
        probabilities_out[out_base + c] /= total;
    }
}
