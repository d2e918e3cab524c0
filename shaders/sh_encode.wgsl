// Degree-4 real spherical harmonics of each ray's view direction, written for every SAMPLE of
// the ray into columns [column_offset, column_offset + 16) of a strided per-sample buffer (the
// colour MLP's input row is [SH 16 | geometry]). Exactly reference::sh::encode: same constants
// (tiny-cuda-nn's), same products. Other columns of the rows are left untouched.
// Rust side: field::gpu::encoding::DirectionShPass.

//!include _dispatch.wgsl
//!include _bf16.wgsl

const WORKGROUP_SIZE: u32 = 64u;

// Mirrors `field::gpu::encoding::ShUniforms`.
struct ShUniforms {
    sample_count: u32,
    samples_per_ray: u32,
    row_stride: u32,
    column_offset: u32,
    // Ray r's direction is directions[r * direction_stride + direction_offset] (in vec4s), so
    // the pass can read the `dir` field of the ray batch's `RayGeometry` records in place.
    direction_stride: u32,
    direction_offset: u32,
    _pad0: u32,
    _pad1: u32,
}

@group(0) @binding(0) var<uniform> sh_layout: ShUniforms;
// Unit directions (xyz; w unused), see direction_stride.
@group(0) @binding(1) var<storage, read> directions: array<vec4<f32>>;
// f32 or bf16 rows (SH_BF16: where the colour MLP's input rows are bf16, which the SH reach
// unchanged, so rounding here loses nothing).
@group(0) @binding(2) var<storage, read_write> sh_out: array<u32>;
override SH_BF16: bool = false;

@compute @workgroup_size(WORKGROUP_SIZE)
fn sh_encode(
    @builtin(workgroup_id) workgroup_id: vec3<u32>,
    @builtin(num_workgroups) num_workgroups: vec3<u32>,
    @builtin(local_invocation_index) local_index: u32,
) {
    let sample = linear_item_index(workgroup_id, num_workgroups, local_index, WORKGROUP_SIZE);
    if sample >= sh_layout.sample_count {
        return;
    }
    let ray = sample / sh_layout.samples_per_ray;
    let d = directions[ray * sh_layout.direction_stride + sh_layout.direction_offset].xyz;
    let x = d.x;
    let y = d.y;
    let z = d.z;
    let xy = x * y;
    let xz = x * z;
    let yz = y * z;
    let x2 = x * x;
    let y2 = y * y;
    let z2 = z * z;
    let o = sample * sh_layout.row_stride + sh_layout.column_offset;
    var v: array<f32, 16>;
    v[0] = 0.28209479177387814;
    v[1] = -0.48860251190291987 * y;
    v[2] = 0.48860251190291987 * z;
    v[3] = -0.48860251190291987 * x;
    v[4] = 1.0925484305920792 * xy;
    v[5] = -1.0925484305920792 * yz;
    v[6] = 0.94617469575755997 * z2 - 0.31539156525251999;
    v[7] = -1.0925484305920792 * xz;
    v[8] = 0.54627421529603959 * x2 - 0.54627421529603959 * y2;
    v[9] = 0.59004358992664352 * y * (-3.0 * x2 + y2);
    v[10] = 2.8906114426405538 * xy * z;
    v[11] = 0.45704579946446572 * y * (1.0 - 5.0 * z2);
    v[12] = 0.3731763325901154 * z * (5.0 * z2 - 3.0);
    v[13] = 0.45704579946446572 * x * (1.0 - 5.0 * z2);
    v[14] = 1.4453057213202769 * z * (x2 - y2);
    v[15] = 0.59004358992664352 * x * (-x2 + 3.0 * y2);
    if SH_BF16 {
        // column_offset and row_stride are even: whole words.
        for (var k = 0u; k < 16u; k += 2u) {
            sh_out[(o + k) >> 1u] = bf16_pair(v[k], v[k + 1u]);
        }
    } else {
        for (var k = 0u; k < 16u; k++) {
            sh_out[o + k] = bitcast<u32>(v[k]);
        }
    }
}
