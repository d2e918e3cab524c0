// Weight gradient of one dense layer on CPU devices (src/field/gpu/dense/,
// `DenseFamily::UniformWeights`): dW[o][i] = Σ_n dZ[n][o] · X[n][i], dZ = dY ⊙ act'(Y), summed
// deterministically like `dense_backward_weight.wgsl` (per-chunk partial matrices, then its
// `reduce_chunks` in order), but with dZ read through a uniform binding so that a SIMD group of
// lanes (one input column i each) loads each dZ value once instead of once per lane.
//
// `mask_output_gradient` writes dZ packed ([n][o], rows of `padded_to_vec4(out_dim)` so that
// the windows are read as whole vec4s, zeros in the padding; rows past N stay 0) into `dz_out`; then one
// `chunk_partial_sums` dispatch per chunk of dims.chunk_rows rows reads that chunk's dZ through
// the 64 KiB uniform window `dz` (bound at the chunk's offset) and writes partials[chunk].
//!include _dense_tile.wgsl
//!include _dispatch.wgsl

const WORKGROUP: u32 = 64u;
override BLOCK: u32 = 16u;
// Lanes (input columns) per workgroup of `chunk_partial_sums`: dense.rs picks the smallest of
// 8..64 covering the layer's inputs, so a 15- or 32-input layer leaves few lanes idle.
override COLUMNS: u32 = 64u;

@group(0) @binding(0) var<uniform> dims: DenseDims;
@group(0) @binding(1) var<storage, read> dy: array<f32>;
@group(0) @binding(2) var<storage, read> y: array<f32>;
@group(0) @binding(3) var<storage, read> x: array<f32>;
// [chunk][out][in]
@group(0) @binding(4) var<storage, read_write> partials: array<f32>;
@group(0) @binding(6) var<storage, read_write> dz_out: array<f32>;

@compute @workgroup_size(WORKGROUP)
fn mask_output_gradient(
    @builtin(workgroup_id) workgroup_id: vec3<u32>,
    @builtin(num_workgroups) num_workgroups: vec3<u32>,
    @builtin(local_invocation_index) local_index: u32,
) {
    let e = linear_item_index(workgroup_id, num_workgroups, local_index, WORKGROUP);
    let out_padded = padded_to_vec4(dims.out_dim);
    if e >= active_rows() * out_padded {
        return;
    }
    let n = e / out_padded;
    let o = e - n * out_padded;
    var value = 0.0;
    if o < dims.out_dim {
        value = output_gradient(dy[n * dims.dy_stride + dims.dy_offset + o], n * dims.y_stride + dims.y_offset + o);
    }
    dz_out[e] = value;
}

// Mirrors `ChunkInfo` in dense.rs: one 256-byte slot per chunk, bound with a dynamic offset.
struct ChunkInfo {
    index: u32,
}

@group(1) @binding(0) var<uniform> dz: array<vec4<f32>, 4096>;
@group(1) @binding(1) var<uniform> chunk: ChunkInfo;

@compute @workgroup_size(COLUMNS)
fn chunk_partial_sums(
    @builtin(workgroup_id) workgroup_id: vec3<u32>,
    @builtin(local_invocation_index) local_index: u32,
) {
    let i = workgroup_id.x * COLUMNS + local_index;
    let o0 = workgroup_id.y * BLOCK;
    let first_row = chunk.index * dims.chunk_rows;
    let rows = active_rows();
    var count = 0u;
    if first_row < rows {
        count = min(dims.chunk_rows, rows - first_row);
    }
    // Lanes past the last column read a valid column and discard the result.
    let column = dims.x_offset + min(i, dims.in_dim - 1u);
    var a0 = vec4<f32>();
    var a1 = vec4<f32>();
    var a2 = vec4<f32>();
    var a3 = vec4<f32>();
    let row_quads = quads_per_row(dims.out_dim);
    for (var r = 0u; r < count; r++) {
        let xv = x[(first_row + r) * dims.x_stride + column];
        // dZ[r][o0 .. o0 + BLOCK] as whole vec4s (o0 is a multiple of 4); quads past the row's
        // end give outputs that are never written.
        let base = r * row_quads + (o0 >> 2u);
        a0 += xv * dz[base];
        if BLOCK > 4u {
            a1 += xv * dz[base + 1u];
        }
        if BLOCK > 8u {
            a2 += xv * dz[base + 2u];
            a3 += xv * dz[base + 3u];
        }
    }
    if i >= dims.in_dim {
        return;
    }
    let matrix = dims.out_dim * dims.in_dim;
    for (var j = 0u; j < BLOCK; j++) {
        let o = o0 + j;
        if o < dims.out_dim {
            let q = j >> 2u;
            var v = a0;
            if q == 1u {
                v = a1;
            } else if q == 2u {
                v = a2;
            } else if q == 3u {
                v = a3;
            }
            partials[chunk.index * matrix + o * dims.in_dim + i] = v[j & 3u];
        }
    }
}
