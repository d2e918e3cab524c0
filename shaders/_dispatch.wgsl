// 1D work spread over a 2D grid of workgroups (src/gpu/pipeline.rs `Dispatch1d`): a dispatch
// dimension is capped (65535 by default), so long 1D jobs use y as well. Workgroups past the end
// of the job exist; kernels must return early when the index is >= their item count.
fn linear_item_index(workgroup_id: vec3<u32>, num_workgroups: vec3<u32>, local_index: u32, workgroup_size: u32) -> u32 {
    return (workgroup_id.y * num_workgroups.x + workgroup_id.x) * workgroup_size + local_index;
}
