// Each hash level's fixed-point exponent for this step (field::gpu::encoding, FixedPoint adds):
// one workgroup per level sums |∂L/∂encoding| over the level's columns of every sample. Every
// table entry's gradient is a sum of (trilinear weight ≤ 1) · (one of those values), so that sum
// bounds every entry of the level, whatever the order or the merging of the adds; the exponent
// scales it to 2^FIXED_POINT_BITS (_fixed_point.wgsl). Rewritten every step, so nothing needs
// clearing and a resumed run scales exactly as an uninterrupted one.

//!include _hash_grid.wgsl
//!include _fixed_point.wgsl

const WORKGROUP: u32 = 256u;

@group(0) @binding(0) var<uniform> grid: HashGridUniforms;
@group(0) @binding(1) var<storage, read> encoding_grad: array<f32>;
@group(0) @binding(2) var<storage, read_write> exponents: array<i32>;

var<workgroup> partial: array<f32, WORKGROUP>;

@compute @workgroup_size(WORKGROUP)
fn hash_gradient_scale(
    @builtin(workgroup_id) workgroup_id: vec3<u32>,
    @builtin(local_invocation_index) local_index: u32,
) {
    let level = workgroup_id.x;
    // Workgroup-uniform, so leaving before the barriers is allowed.
    if level >= grid.levels {
        return;
    }
    var sum = 0.0;
    for (var sample = local_index; sample < grid.sample_count; sample += WORKGROUP) {
        let row = sample * grid.row_stride + level * grid.features;
        for (var f = 0u; f < grid.features; f++) {
            sum += abs(encoding_grad[row + f]);
        }
    }
    partial[local_index] = sum;
    workgroupBarrier();
    for (var stride = WORKGROUP / 2u; stride > 0u; stride /= 2u) {
        if local_index < stride {
            partial[local_index] += partial[local_index + stride];
        }
        workgroupBarrier();
    }
    if local_index == 0u {
        // f32 sums round down by at most a few ulps of the total; the half a binary digit
        // of room below 2^31 (FIXED_POINT_BITS) covers that many times over.
        exponents[level] = fixed_point_exponent(partial[0]);
    }
}
