// Adam with bias correction over a segment of the flat parameter buffer (src/field/gpu/adam.rs),
// exactly `field::reference::adam`:
//   m ← β₁ m + (1 − β₁) g;  v ← β₂ v + (1 − β₂) g²;  p ← p − lr · (m · c₁) / (√(v · c₂) + ε)
// β₁, β₂, ε and the segment length are fixed per pass; lr, c₁, c₂ change every step and come
// from the trainer's shared StepUniforms (fields lr, adam_c1, adam_c2).
//
// The step also zeroes the gradient it consumed, so the buffer starts the next step cleared
// (every backward pass adds to it) without a separate clear.
//
// Entry point `adam_fixed_point_table` is the same step for a gradient buffer whose hash-table
// range holds the fixed-point integers of hash_backward_fixed_point.wgsl: it decodes them with
// their level's exponent first.
//!include _dispatch.wgsl
//!include _step.wgsl
//!include _hash_grid.wgsl
//!include _fixed_point.wgsl

// Mirrors `AdamConstants` in src/field/gpu/adam.rs.
struct AdamConstants {
    beta1: f32,
    beta2: f32,
    epsilon: f32,
    count: u32,
    // Index of this segment's first element in the whole flat buffer.
    first: u32,
    // The fixed-point table's elements in the whole flat buffer (adam_fixed_point_table only).
    table_start: u32,
    table_end: u32,
    _pad0: u32,
}

@group(0) @binding(0) var<uniform> constants: AdamConstants;
@group(0) @binding(1) var<uniform> step_info: StepUniforms;
@group(0) @binding(2) var<storage, read_write> params: array<f32>;
@group(0) @binding(3) var<storage, read_write> grads: array<f32>;
@group(0) @binding(4) var<storage, read_write> first_moment: array<f32>;
@group(0) @binding(5) var<storage, read_write> second_moment: array<f32>;
@group(0) @binding(6) var<uniform> grid: HashGridUniforms;
@group(0) @binding(7) var<storage, read> exponents: array<i32>;

const WORKGROUP: u32 = 256u;

fn update(i: u32, g: f32) {
    // Same operation order as the reference so f32 rounding matches.
    let m = constants.beta1 * first_moment[i] + (1.0 - constants.beta1) * g;
    let v = constants.beta2 * second_moment[i] + (1.0 - constants.beta2) * g * g;
    first_moment[i] = m;
    second_moment[i] = v;
    params[i] -= step_info.lr * (m * step_info.adam_c1) / (sqrt(v * step_info.adam_c2) + constants.epsilon);
}

@compute @workgroup_size(WORKGROUP)
fn adam(
    @builtin(workgroup_id) workgroup_id: vec3<u32>,
    @builtin(num_workgroups) num_workgroups: vec3<u32>,
    @builtin(local_invocation_index) local_index: u32,
) {
    let i = linear_item_index(workgroup_id, num_workgroups, local_index, WORKGROUP);
    if i >= constants.count {
        return;
    }
    let g = grads[i];
    grads[i] = 0.0;
    update(i, g);
}

@compute @workgroup_size(WORKGROUP)
fn adam_fixed_point_table(
    @builtin(workgroup_id) workgroup_id: vec3<u32>,
    @builtin(num_workgroups) num_workgroups: vec3<u32>,
    @builtin(local_invocation_index) local_index: u32,
) {
    let i = linear_item_index(workgroup_id, num_workgroups, local_index, WORKGROUP);
    if i >= constants.count {
        return;
    }
    var g = grads[i];
    // Zero bits are 0 as f32 and as i32 alike.
    grads[i] = 0.0;
    let element = constants.first + i;
    if element >= constants.table_start && element < constants.table_end {
        let entry = (element - constants.table_start) / grid.features;
        var level = 0u;
        for (var l = 1u; l < grid.levels; l++) {
            if entry >= grid.level_geometry[l].z {
                level = l;
            }
        }
        g = from_fixed_point(bitcast<i32>(g), exponents[level]);
    }
    update(i, g);
}
