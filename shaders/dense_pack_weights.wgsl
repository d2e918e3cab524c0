// Copies the [out][in] weights of every layer of one MLP into the layouts the uniform-weight
// kernels read as whole vec4s (`_dense_uniform.wgsl`), zeros in the padding: [in][out padded to
// a multiple of 4] for a forward (transposed), [out][in padded] for an input gradient. One
// dispatch per MLP (src/field/gpu/dense/uniform.rs, `MlpPacking`), recorded before its forward:
// the parameters change every step, and not between an MLP's forward and its backward.
// Invocation: one packed element of job workgroup_id.z.
//!include _dispatch.wgsl

const PACK_WORKGROUP: u32 = 64u;

// Mirrors `PackJob` in uniform.rs: one packed matrix. `src` is where the layer's [out][in]
// matrix starts in `params`; the packed matrix has `rows` rows of `columns` values padded to a
// multiple of 4 and starts at `dst` in `packed`.
struct PackJob {
    src: u32,
    rows: u32,
    columns: u32,
    transposed: u32,
    dst: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

// Up to 8 jobs per dispatch, in a uniform so that each workgroup reads its job's fields as
// scalars (a storage read on a CPU device is a loop over the lanes).
const MAX_PACK_JOBS: u32 = 8u;
@group(0) @binding(0) var<uniform> jobs: array<PackJob, MAX_PACK_JOBS>;
@group(0) @binding(1) var<storage, read> params: array<f32>;
@group(0) @binding(2) var<storage, read_write> packed: array<f32>;

@compute @workgroup_size(PACK_WORKGROUP)
fn pack_weights(
    @builtin(workgroup_id) workgroup_id: vec3<u32>,
    @builtin(num_workgroups) num_workgroups: vec3<u32>,
    @builtin(local_invocation_index) local_index: u32,
) {
    let job = jobs[workgroup_id.z];
    let local = linear_item_index(vec3<u32>(workgroup_id.xy, 0u), num_workgroups, local_index, PACK_WORKGROUP);
    let row_length = (job.columns + 3u) & ~3u;
    if local >= job.rows * row_length {
        return;
    }
    let r = local / row_length;
    let c = local - r * row_length;
    var value = 0.0;
    if c < job.columns {
        // [out][in]: the forward's packed row r is input r, the input gradient's is output r.
        if job.transposed != 0u {
            value = params[job.src + c * job.rows + r];
        } else {
            value = params[job.src + r * job.columns + c];
        }
    }
    packed[job.dst + local] = value;
}
