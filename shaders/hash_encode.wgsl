// Forward of the position encoding (field::gpu::encoding::PositionEncodePass): for N samples,
// row n of `encoding` = [hash-grid level 0 features, …, level L−1 features, frequency values],
// exactly `FieldModel::encode_position` (reference::hash_grid::encode then
// reference::frequency::encode).
//
// One invocation per (slot, sample), slot-major: slots 0..L−1 are the hash levels, slot L the
// frequency encoding. Neighbouring invocations share a level (uniform control flow) and take
// neighbouring samples of a ray, which tend to read the same table entries.

//!include _dispatch.wgsl
//!include _hash_grid.wgsl

const WORKGROUP_SIZE: u32 = 64u;
const PI: f32 = 3.14159265358979323846;

@group(0) @binding(0) var<uniform> grid: HashGridUniforms;
@group(0) @binding(1) var<storage, read> positions: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> params: array<f32>;
@group(0) @binding(3) var<storage, read_write> encoding: array<f32>;

@compute @workgroup_size(WORKGROUP_SIZE)
fn hash_encode(
    @builtin(workgroup_id) workgroup_id: vec3<u32>,
    @builtin(num_workgroups) num_workgroups: vec3<u32>,
    @builtin(local_invocation_index) local_index: u32,
) {
    let item = linear_item_index(workgroup_id, num_workgroups, local_index, WORKGROUP_SIZE);
    let slot = item / grid.sample_count;
    let sample = item - slot * grid.sample_count;
    if slot < grid.levels {
        encode_level(sample, slot);
    } else if slot == grid.levels && grid.frequencies > 0u {
        encode_frequencies(sample);
    }
}

fn encode_level(sample: u32, level: u32) {
    let geometry = grid.level_geometry[level];
    let located = locate_cell(positions[sample].xyz, geometry.x);
    var weights: array<f32, 8>;
    var first_value: array<u32, 8>;
    for (var corner = 0u; corner < 8u; corner++) {
        weights[corner] = corner_weight(located.frac, corner);
        let entry = corner_entry(located.cell, corner, geometry.y, grid.table_size);
        first_value[corner] = table_index(grid.table_offset, grid.features, geometry.z, entry);
    }
    let first_column = sample * grid.row_stride + level * grid.features;
    for (var f = 0u; f < grid.features; f++) {
        // Summed in corner order, as the reference.
        var sum = 0.0;
        for (var corner = 0u; corner < 8u; corner++) {
            sum += weights[corner] * params[first_value[corner] + f];
        }
        encoding[first_column + f] = sum;
    }
}

// out[a·2L + 2k] = sin(2^k·π·p_a), out[a·2L + 2k + 1] = cos(2^k·π·p_a). The phase is reduced
// exactly first (t = 2^k·p is exact, and so is t − 2·round(t/2) ∈ [−1, 1]), so sin and cos
// only see [−π, π], where WGSL bounds their error, and high octaves lose nothing.
fn encode_frequencies(sample: u32) {
    let p = positions[sample].xyz;
    let octaves = grid.frequencies;
    let first_column = sample * grid.row_stride + grid.frequency_column;
    for (var axis = 0u; axis < 3u; axis++) {
        for (var k = 0u; k < octaves; k++) {
            let t = p[axis] * f32(1u << k);
            let phase = PI * (t - 2.0 * round(0.5 * t));
            let column = first_column + axis * 2u * octaves + 2u * k;
            encoding[column] = sin(phase);
            encoding[column + 1u] = cos(phase);
        }
    }
}
