// Glue between the density MLP and the three heads (see field/reference/model.rs):
//   colour input   = [SH(d) (written by sh_encode) | g]
//   semantic input = [relu(f) | g], or [relu(f)] alone (FieldConfig::semantic_geometry_dim() = 0)
// and, backwards, the sums that route the heads' input gradients to f and to the density output
// [h0 | g]. One invocation per row. The heads run on the samples the keep pass kept
// (keep.wgsl), packed: `assemble` and `gather_feature` work on the first row_count[0] packed
// rows (density_out is then the packed copy of the density rows), `gather_geometry` on every
// sample, reading the heads' gradients from the sample's packed row (`slot`) and 0 for a
// sample that was not kept. f, the colour and semantic inputs and the heads' input gradients
// are f32 or bf16 rows (FEATURE_BF16, COLOR_IN_BF16, COLOR_GRAD_BF16, FEATURE_GRAD_BF16,
// SEMANTIC_IN_BF16, SEMANTIC_GRAD_BF16: as the MLPs store them, `dense::mlp_row_format`,
// `dense::MlpPass::input`).
//!include _dispatch.wgsl
//!include _bf16.wgsl

const WORKGROUP_SIZE: u32 = 128u;

// Mirrors `GlueDims` in src/field/gpu/head_glue.rs.
struct GlueDims {
    samples: u32,
    geometry: u32,
    feature: u32,
    sh: u32,
    // Layout of the composite pass's per-sample gradient rows (`CompositeLayout`).
    grad_stride: u32,
    grad_h0: u32,
    grad_feature: u32,
    // FieldConfig::semantic_trunk_gradient: share of the semantic gradient passed back into f, g.
    semantic_trunk_scale: f32,
    // Columns of g in the semantic input: geometry, or 0 (FieldConfig::semantic_geometry_dim).
    semantic_geometry: u32,
    // Row strides, in values, of the semantic input and of its gradient.
    semantic_in_stride: u32,
    semantic_grad_stride: u32,
    // Row stride, in values, of f.
    feature_stride: u32,
    // Row strides, in values, of the colour input and of its gradient.
    color_in_stride: u32,
    color_grad_stride: u32,
    // Row stride, in values, of the feature MLP's input gradient.
    feature_grad_stride: u32,
    pad0: u32,
}

override COLOR_IN_BF16: bool = false;
override FEATURE_GRAD_BF16: bool = false;
override COLOR_GRAD_BF16: bool = false;

override FEATURE_BF16: bool = false;
override SEMANTIC_IN_BF16: bool = false;
override SEMANTIC_GRAD_BF16: bool = false;

// Each entry point uses its own subset of these bindings (derived layouts).
@group(0) @binding(0) var<uniform> dims: GlueDims;
// [h0 | g] per sample, row stride 1 + geometry.
@group(0) @binding(1) var<storage, read> density_out: array<f32>;
// f per packed row, row stride feature_stride.
@group(0) @binding(2) var<storage, read> feature_out: array<u32>;
// [SH | g], row stride color_in_stride.
@group(0) @binding(3) var<storage, read_write> color_in: array<u32>;
// [relu(f) | g], row stride semantic_in_stride.
@group(0) @binding(4) var<storage, read_write> semantic_in: array<u32>;
// Its gradient, row stride semantic_grad_stride; the colour input's, as the colour input.
@group(0) @binding(5) var<storage, read> semantic_in_grad: array<u32>;
// The composite's [dL/dh0, dL/dcolour, dL/dlogits, dL/df] rows; gather_feature adds into dL/df.
@group(0) @binding(6) var<storage, read_write> grad_heads: array<f32>;
@group(0) @binding(7) var<storage, read_write> density_out_grad: array<f32>;
@group(0) @binding(8) var<storage, read> color_in_grad: array<u32>;
// The feature MLP's input gradient dL/dg, row stride feature_grad_stride.
@group(0) @binding(9) var<storage, read> feature_in_grad: array<u32>;
// One word: the packed rows present (keep.wgsl).
@group(0) @binding(10) var<storage, read> row_count: array<u32>;
// Per sample: its packed row, or NOT_KEPT.
@group(0) @binding(11) var<storage, read> slot: array<u32>;
// The composite's per-sample rows, for dL/dh0 (grad_heads holds the packed heads' rows).
@group(0) @binding(12) var<storage, read> grad_h0_source: array<f32>;

const NOT_KEPT: u32 = 0xffffffffu;

fn packed_rows() -> u32 {
    return min(dims.samples, row_count[0]);
}

fn sample_index(wid: vec3<u32>, nwg: vec3<u32>, lid: u32) -> u32 {
    return linear_item_index(wid, nwg, lid, WORKGROUP_SIZE);
}

// Value k of packed row n's f.
fn feature_value(n: u32, k: u32) -> f32 {
    let row = n * dims.feature_stride;
    return row_value(feature_out[row_word(row, k, FEATURE_BF16)], k, FEATURE_BF16);
}

// Value j of packed row n's semantic input: relu(f), then g, then 0 (a bf16 row's padding).
fn semantic_value(n: u32, j: u32) -> f32 {
    let d = dims.feature;
    if j < d {
        return max(feature_value(n, j), 0.0);
    }
    if j < d + dims.semantic_geometry {
        return density_out[n * (1u + dims.geometry) + 1u + j - d];
    }
    return 0.0;
}

// Value j of packed row k's semantic input gradient.
fn semantic_gradient(k: u32, j: u32) -> f32 {
    let row = k * dims.semantic_grad_stride;
    return row_value(semantic_in_grad[row_word(row, j, SEMANTIC_GRAD_BF16)], j, SEMANTIC_GRAD_BF16);
}

// Forward: copy g into the colour and semantic inputs, relu(f) into the semantic input.
@compute @workgroup_size(WORKGROUP_SIZE)
fn assemble(
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let n = sample_index(wid, nwg, lid);
    if n >= packed_rows() {
        return;
    }
    let g = dims.geometry;
    let density_row = n * (1u + g) + 1u;
    let color_row = n * dims.color_in_stride + dims.sh;
    if COLOR_IN_BF16 {
        // From the even column sh, a pair per word; past g, the row's padding.
        for (var j = 0u; j < g; j += 2u) {
            let second = select(0.0, density_out[density_row + j + 1u], j + 1u < g);
            color_in[(color_row + j) >> 1u] = bf16_pair(density_out[density_row + j], second);
        }
    } else {
        for (var j = 0u; j < g; j++) {
            color_in[color_row + j] = bitcast<u32>(density_out[density_row + j]);
        }
    }
    let width = dims.feature + dims.semantic_geometry;
    let row = n * dims.semantic_in_stride;
    if SEMANTIC_IN_BF16 {
        // Whole words: the row's padding value too.
        for (var j = 0u; j < width; j += 2u) {
            semantic_in[(row + j) >> 1u] = bf16_pair(semantic_value(n, j), semantic_value(n, j + 1u));
        }
    } else {
        for (var j = 0u; j < width; j++) {
            semantic_in[row + j] = bitcast<u32>(semantic_value(n, j));
        }
    }
}

// Backward, step 1 (after the semantic head's backward): the gradient of f is the composite's
// (in grad_heads) plus the semantic input's relu(f) part.
@compute @workgroup_size(WORKGROUP_SIZE)
fn gather_feature(
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let n = sample_index(wid, nwg, lid);
    if n >= packed_rows() {
        return;
    }
    let d = dims.feature;
    for (var k = 0u; k < d; k++) {
        if feature_value(n, k) > 0.0 {
            let at = n * dims.grad_stride + dims.grad_feature + k;
            grad_heads[at] += dims.semantic_trunk_scale * semantic_gradient(n, k);
        }
    }
}

// Backward, step 2 (after all three heads' backward): dL/dg = colour input grad's g part +
// semantic input grad's g part + feature MLP input grad, written next to the composite's dL/dh0
// as the density MLP's output gradient row [dL/dh0 | dL/dg].
@compute @workgroup_size(WORKGROUP_SIZE)
fn gather_geometry(
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let n = sample_index(wid, nwg, lid);
    if n >= dims.samples {
        return;
    }
    let g = dims.geometry;
    let d = dims.feature;
    let sg = dims.semantic_geometry;
    density_out_grad[n * (1u + g)] = grad_h0_source[n * dims.grad_stride + dims.grad_h0];
    let k = slot[n];
    if k == NOT_KEPT {
        for (var j = 0u; j < g; j++) {
            density_out_grad[n * (1u + g) + 1u + j] = 0.0;
        }
        return;
    }
    for (var j = 0u; j < g; j++) {
        var semantic = 0.0;
        if j < sg {
            semantic = dims.semantic_trunk_scale * semantic_gradient(k, d + j);
        }
        let color_row = k * dims.color_grad_stride;
        let color = row_value(color_in_grad[row_word(color_row, dims.sh + j, COLOR_GRAD_BF16)], dims.sh + j, COLOR_GRAD_BF16);
        let feature_row = k * dims.feature_grad_stride;
        let feature = row_value(feature_in_grad[row_word(feature_row, j, FEATURE_GRAD_BF16)], j, FEATURE_GRAD_BF16);
        density_out_grad[n * (1u + g) + 1u + j] = color + semantic + feature;
    }
}
