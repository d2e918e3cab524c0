// out[i] = i for i < count: the simplest 1D kernel, used to prove 2D-spread dispatches reach
// every item exactly once.
//!include _dispatch.wgsl

const WORKGROUP_SIZE: u32 = 64u;

struct Params {
    count: u32,
}

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read_write> out: array<u32>;

@compute @workgroup_size(WORKGROUP_SIZE)
fn iota(
    @builtin(workgroup_id) workgroup_id: vec3<u32>,
    @builtin(num_workgroups) num_workgroups: vec3<u32>,
    @builtin(local_invocation_index) local_index: u32,
) {
    let i = linear_item_index(workgroup_id, num_workgroups, local_index, WORKGROUP_SIZE);
    if i >= params.count {
        return;
    }
    out[i] = i;
}
