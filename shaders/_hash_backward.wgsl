// The body of the hash grid's backward (hash_backward.wgsl, hash_backward_float_atomics.wgsl):
// adds ∂L/∂table = Σ_samples weight · ∂L/∂encoding into the flat gradient buffer, as
// reference::hash_grid::backward summed over all samples. The frequency encoding has no
// parameters, so only the first levels · F columns of each gradient row are read. The including
// stage declares the `gradient` binding (@binding(3)) and `add_to_gradient(index, value, level)`.
//
// To cut the number of atomics (and the contention on coarse cells), a workgroup takes 64
// consecutive samples of ONE level; consecutive samples of a ray often fall in the same cell on
// coarse levels, so each run of samples sharing a cell is summed in registers by its first
// invocation, which then issues one atomic add per corner and feature for the whole run. With
// MERGE_RUNS = false every sample adds its own corners (kept to measure the difference).
//
// The gradient buffer must be zeroed before this pass (HashGridBackwardPass::record_clear, or
// the previous step's Adam).

//!include _dispatch.wgsl
//!include _hash_grid.wgsl

const WORKGROUP_SIZE: u32 = 64u;
const MAX_FEATURES: u32 = 8u;

override MERGE_RUNS: bool = true;

@group(0) @binding(0) var<uniform> grid: HashGridUniforms;
@group(0) @binding(1) var<storage, read> positions: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> encoding_grad: array<f32>;

// Per invocation: its cell (w = 1 for a real sample, 0 past the end so it matches nothing),
// trilinear fractions and ∂L/∂features of its level.
var<workgroup> cells: array<vec4<u32>, WORKGROUP_SIZE>;
var<workgroup> fracs: array<vec4<f32>, WORKGROUP_SIZE>;
var<workgroup> grads: array<f32, WORKGROUP_SIZE * MAX_FEATURES>;

@compute @workgroup_size(WORKGROUP_SIZE)
fn hash_backward(
    @builtin(workgroup_id) workgroup_id: vec3<u32>,
    @builtin(num_workgroups) num_workgroups: vec3<u32>,
    @builtin(local_invocation_index) local_index: u32,
) {
    let group = linear_item_index(workgroup_id, num_workgroups, 0u, 1u);
    let level = group / grid.groups_per_level;
    // Workgroup-uniform, so leaving before the barrier is allowed.
    if level >= grid.levels {
        return;
    }
    let sample = (group - level * grid.groups_per_level) * WORKGROUP_SIZE + local_index;
    let geometry = grid.level_geometry[level];
    var key = vec4<u32>(0u);
    if sample < grid.sample_count {
        let located = locate_cell(positions[sample].xyz, geometry.x);
        key = vec4(located.cell, 1u);
        fracs[local_index] = vec4(located.frac, 0.0);
        let row = sample * grid.row_stride + level * grid.features;
        for (var f = 0u; f < grid.features; f++) {
            grads[local_index * MAX_FEATURES + f] = encoding_grad[row + f];
        }
    }
    cells[local_index] = key;
    workgroupBarrier();

    let starts_run = local_index == 0u || any(cells[local_index - 1u] != key);
    if key.w == 0u || (MERGE_RUNS && !starts_run) {
        return;
    }
    var end = local_index + 1u;
    if MERGE_RUNS {
        while end < WORKGROUP_SIZE && all(cells[end] == key) {
            end++;
        }
    }

    var first_value: array<u32, 8>;
    for (var corner = 0u; corner < 8u; corner++) {
        let entry = corner_entry(key.xyz, corner, geometry.y, grid.table_size);
        first_value[corner] = table_index(grid.table_offset, grid.features, geometry.z, entry);
    }
    for (var f = 0u; f < grid.features; f++) {
        var sums: array<f32, 8>;
        for (var member = local_index; member < end; member++) {
            let g = grads[member * MAX_FEATURES + f];
            let frac = fracs[member].xyz;
            for (var corner = 0u; corner < 8u; corner++) {
                sums[corner] += corner_weight(frac, corner) * g;
            }
        }
        for (var corner = 0u; corner < 8u; corner++) {
            add_to_gradient(first_value[corner] + f, sums[corner], level);
        }
    }
}
