// The input gradients of a whole MLP of 2 or 3 layers in one kernel, weights from a uniform
// binding (`_dense_uniform.wgsl`; src/field/gpu/dense/chain.rs): CPU devices only, where every
// storage load and store is a loop over the SIMD lanes. One invocation per row n walks the
// layers from the last to the first:
//   dZ of the last (linear) layer = dY;
//   dX of layer k = Σ_o dZ_k[o] · W_k[o][·], kept in registers (`Acc`), not written;
//   dZ of layer k - 1 = that dX ⊙ ReLU'(Y_{k-1}) (0 at 0, as the reference);
// and writes every layer's dZ in the bf16 rows its uniform-window weight gradient reads
// (`dense_backward_weight_uniform.wgsl`, `_bf16.wgsl`; a row's quads past its width, where
// `padded_to_vec8` adds one, are left as they are: the weight gradient never stores the outputs
// they feed) and dX of the first layer. Per layer boundary that saves the store of dX and its
// load as the next layer's dY, and a dispatch. Every sum adds in the order of
// `dense_backward_input_uniform.wgsl`, o = 0, 1, ...
//
// BLOCK covers every hidden width (uniform.rs keeps hidden widths within the device's widest
// block), so a hidden layer's dX is one invocation's accumulators; the first layer's dX is
// split into blocks of BLOCK, one pipeline and dispatch each (FIXED_BLOCK), and the invocations of
// the later blocks redo the walk without writing dZ again.
//!include _dense_uniform.wgsl
//!include _bf16.wgsl

// Layers (2 or 3) and widths: D0 in, D1 .. the hidden and output widths (D3 unused with 2).
override LAYERS: u32 = 3u;
override D0: u32 = 16u;
override D1: u32 = 32u;
override D2: u32 = 32u;
override D3: u32 = 16u;
// Whether the MLP's input wants its gradient; without, the walk stops at dZ of layer 0.
override WRITE_DX: bool = true;
// Each layer's packed [out][in] copy in `weights` (vec4 index). Constants, like every other part
// of a weight's index here, so that lavapipe loads each weight once for all lanes (UNROLL in
// `_dense_uniform.wgsl` says why; this kernel is always written out).
override W0: u32 = 0u;
override W1: u32 = 0u;
override W2: u32 = 0u;
// FIXED_BLOCK (`_dense_uniform.wgsl`) is the block of the first layer's dX this pipeline
// computes (one dispatch per block, so that its first input is a constant too); block 0 also
// writes every layer's dZ.

// Mirrors `ChainDims` in src/field/gpu/dense/chain.rs: where the hidden outputs Y_0 and Y_1
// are.
struct ChainDims {
    y0_stride: u32,
    y0_offset: u32,
    y1_stride: u32,
    y1_offset: u32,
}

// dims: rows, dy and dx views (the MLP's output gradient and input gradient).
@group(0) @binding(0) var<uniform> dims: DenseDims;
@group(0) @binding(1) var<storage, read> dy: array<f32>;
// Y_0, the first hidden layer's output; the hidden outputs are f32 or bf16 rows (Y_BF16).
@group(0) @binding(2) var<storage, read> y: array<u32>;
@group(0) @binding(3) var<uniform> weights: array<vec4<f32>, UNIFORM_WEIGHT_VEC4S>;
// The MLP's input gradient, f32 or bf16 rows (DX_BF16: an MLP's own input rows, `InputRows`).
@group(0) @binding(4) var<storage, read_write> dx: array<u32>;
override DX_BF16: bool = false;
// Y_1 (3 layers).
@group(0) @binding(5) var<storage, read> y_upper: array<u32>;
override Y_BF16: bool = false;
@group(0) @binding(8) var<uniform> chain: ChainDims;
// dZ of each layer, bf16 rows of padded_to_vec8(its output width) values, a quad per vec2<u32>.
@group(0) @binding(9) var<storage, read_write> dz0: array<vec2<u32>>;
@group(0) @binding(10) var<storage, read_write> dz1: array<vec2<u32>>;
@group(0) @binding(11) var<storage, read_write> dz2: array<vec2<u32>>;

// Width j of the MLP: D0 (its input) .. D_LAYERS (its output).
fn width(j: u32) -> u32 {
    switch j {
        case 0u: {
            return D0;
        }
        case 1u: {
            return D1;
        }
        case 2u: {
            return D2;
        }
        default: {
            return D3;
        }
    }
}

fn weight_base(k: u32) -> u32 {
    switch k {
        case 0u: {
            return W0;
        }
        case 1u: {
            return W1;
        }
        default: {
            return W2;
        }
    }
}

// Y_k[n][j] (k = 0 or 1: only hidden layers are masked).
fn hidden_output(k: u32, n: u32, j: u32) -> f32 {
    if k == 0u {
        let row = n * chain.y0_stride + chain.y0_offset;
        return row_value(y[row_word(row, j, Y_BF16)], j, Y_BF16);
    }
    let row = n * chain.y1_stride + chain.y1_offset;
    return row_value(y_upper[row_word(row, j, Y_BF16)], j, Y_BF16);
}

// Quad q of row n of layer k's dZ, as bf16.
fn store_dz(k: u32, n: u32, q: u32, value: vec4<f32>) {
    let index = n * (padded_to_vec8(width(k + 1u)) >> 2u) + q;
    let packed = bf16_quad(value);
    switch k {
        case 0u: {
            dz0[index] = packed;
        }
        case 1u: {
            dz1[index] = packed;
        }
        default: {
            dz2[index] = packed;
        }
    }
}

// 1 where Y_k[n][o0 + c] > 0 and o0 + c is inside the width, else 0.
fn relu_mask(k: u32, n: u32, o0: u32, w: u32) -> vec4<f32> {
    var mask = vec4<f32>(0.0);
    if hidden_output(k, n, o0) > 0.0 {
        mask.x = 1.0;
    }
    if o0 + 1u < w && hidden_output(k, n, o0 + 1u) > 0.0 {
        mask.y = 1.0;
    }
    if o0 + 2u < w && hidden_output(k, n, o0 + 2u) > 0.0 {
        mask.z = 1.0;
    }
    if o0 + 3u < w && hidden_output(k, n, o0 + 3u) > 0.0 {
        mask.w = 1.0;
    }
    return mask;
}

// dX of layer k (into `to`, inputs from packed quad `i0_quad`) gains dZ_k[o0 .. o0 + 4] = g,
// output by output in order, those inside the layer's width.
fn feed_quad(to: ptr<function, Acc>, k: u32, g: vec4<f32>, o0: u32, i0_quad: u32) {
    let w = width(k + 1u);
    let quads = quads_per_row(width(k));
    let base = weight_base(k) + o0 * quads + i0_quad;
    accumulate(to, g.x, base);
    if o0 + 1u < w {
        accumulate(to, g.y, base + quads);
    }
    if o0 + 2u < w {
        accumulate(to, g.z, base + 2u * quads);
    }
    if o0 + 3u < w {
        accumulate(to, g.w, base + 3u * quads);
    }
}

// Quad q of layer k's dZ from quad q of `upstream` (dX of layer k + 1): masked, stored (first
// block only), and, if `feeds`, added into `to` (dX of layer k, quads from `i0_quad` of each
// packed row).
fn back_quad(k: u32, n: u32, q: u32, upstream: vec4<f32>, to: ptr<function, Acc>, stores: bool, feeds: bool, i0_quad: u32) {
    let w = width(k + 1u);
    let o0 = 4u * q;
    if o0 >= w {
        return;
    }
    // A select, not a product: an infinite upstream value where Y is 0 gives 0, as the
    // reference's mask does.
    let g = select(vec4<f32>(0.0), upstream, relu_mask(k, n, o0, w) > vec4<f32>(0.0));
    if stores {
        store_dz(k, n, q, g);
    }
    if !feeds {
        return;
    }
    feed_quad(to, k, g, o0, i0_quad);
}

// Layer k's dZ from `upstream` (dX of layer k + 1, quad by quad in order), and dX of layer k into
// `to`. The quads past BLOCK are dropped when the pipeline is specialised.
fn back_through(k: u32, n: u32, upstream: ptr<function, Acc>, to: ptr<function, Acc>, stores: bool, feeds: bool, i0_quad: u32) {
    back_quad(k, n, 0u, (*upstream).a0, to, stores, feeds, i0_quad);
    if BLOCK > 4u {
        back_quad(k, n, 1u, (*upstream).a1, to, stores, feeds, i0_quad);
    }
    if BLOCK > 8u {
        back_quad(k, n, 2u, (*upstream).a2, to, stores, feeds, i0_quad);
    }
    if BLOCK > 12u {
        back_quad(k, n, 3u, (*upstream).a3, to, stores, feeds, i0_quad);
    }
    if BLOCK > 16u {
        back_quad(k, n, 4u, (*upstream).a4, to, stores, feeds, i0_quad);
    }
    if BLOCK > 20u {
        back_quad(k, n, 5u, (*upstream).a5, to, stores, feeds, i0_quad);
    }
    if BLOCK > 24u {
        back_quad(k, n, 6u, (*upstream).a6, to, stores, feeds, i0_quad);
    }
    if BLOCK > 28u {
        back_quad(k, n, 7u, (*upstream).a7, to, stores, feeds, i0_quad);
    }
    if BLOCK > 32u {
        back_quad(k, n, 8u, (*upstream).a8, to, stores, feeds, i0_quad);
    }
    if BLOCK > 36u {
        back_quad(k, n, 9u, (*upstream).a9, to, stores, feeds, i0_quad);
    }
    if BLOCK > 40u {
        back_quad(k, n, 10u, (*upstream).a10, to, stores, feeds, i0_quad);
    }
    if BLOCK > 44u {
        back_quad(k, n, 11u, (*upstream).a11, to, stores, feeds, i0_quad);
    }
    if BLOCK > 48u {
        back_quad(k, n, 12u, (*upstream).a12, to, stores, feeds, i0_quad);
    }
    if BLOCK > 52u {
        back_quad(k, n, 13u, (*upstream).a13, to, stores, feeds, i0_quad);
    }
    if BLOCK > 56u {
        back_quad(k, n, 14u, (*upstream).a14, to, stores, feeds, i0_quad);
    }
    if BLOCK > 60u {
        back_quad(k, n, 15u, (*upstream).a15, to, stores, feeds, i0_quad);
    }
}

// What a row's walk reads and whether it stores: its row, where its dY starts, and whether it
// writes dZ (block 0 of a live row).
struct ChainRow {
    n: u32,
    dy: u32,
    stores: bool,
}

// Quad q of the last (linear) layer's dZ, which is dY read as the per-layer kernel reads it:
// stored, and added output by output into `upper` (dX of the last layer).
fn last_quad(upper: ptr<function, Acc>, row: ChainRow, q: u32) {
    let w = width(LAYERS);
    let o0 = 4u * q;
    if o0 >= w {
        return;
    }
    var g = vec4<f32>(dy[row.dy + o0], 0.0, 0.0, 0.0);
    if o0 + 1u < w {
        g.y = dy[row.dy + o0 + 1u];
    }
    if o0 + 2u < w {
        g.z = dy[row.dy + o0 + 2u];
    }
    if o0 + 3u < w {
        g.w = dy[row.dy + o0 + 3u];
    }
    if row.stores {
        store_dz(LAYERS - 1u, row.n, q, g);
    }
    feed_quad(upper, LAYERS - 1u, g, o0, 0u);
}

// Quads first .. first + 8 of the last layer (past its width they fold away).
fn last_quads(upper: ptr<function, Acc>, row: ChainRow, first: u32) {
    last_quad(upper, row, first);
    last_quad(upper, row, first + 1u);
    last_quad(upper, row, first + 2u);
    last_quad(upper, row, first + 3u);
    last_quad(upper, row, first + 4u);
    last_quad(upper, row, first + 5u);
    last_quad(upper, row, first + 6u);
    last_quad(upper, row, first + 7u);
}

@compute @workgroup_size(WORKGROUP)
fn backward_chain(
    @builtin(workgroup_id) workgroup_id: vec3<u32>,
    @builtin(num_workgroups) num_workgroups: vec3<u32>,
    @builtin(local_invocation_index) local_index: u32,
) {
    // No invocation returns before the walk (rows past the last compute on a valid one and
    // store nothing): see W0.
    let item = linear_item_index(vec3<u32>(workgroup_id.xy, 0u), num_workgroups, local_index, WORKGROUP);
    let rows = active_rows();
    let live = item < rows;
    let n = row_read(item, rows);
    let block = block_index(workgroup_id.z);
    let i0 = block * BLOCK;
    let stores = live && block == 0u;
    let row = ChainRow(n, n * dims.dy_stride + dims.dy_offset, stores);
    var upper: Acc;
    last_quads(&upper, row, 0u);
    last_quads(&upper, row, 8u);
    last_quads(&upper, row, 16u);
    last_quads(&upper, row, 24u);
    var lower: Acc;
    var first: Acc;
    if LAYERS == 3u {
        back_through(1u, n, &upper, &lower, stores, true, 0u);
        back_through(0u, n, &lower, &first, stores, WRITE_DX, i0 >> 2u);
    } else {
        back_through(0u, n, &upper, &first, stores, WRITE_DX, i0 >> 2u);
    }
    if !WRITE_DX || !live {
        return;
    }
    let dx_row = n * dims.dx_stride + dims.dx_offset;
    if DX_BF16 {
        // Pairs from an even column (BLOCK is a multiple of 4); past D0, the row's padding.
        for (var j = 0u; j < BLOCK; j += 2u) {
            let i = i0 + j;
            if i < D0 {
                let second = select(0.0, acc_value(&first, j + 1u), i + 1u < D0);
                dx[(dx_row + i) >> 1u] = bf16_pair(acc_value(&first, j), second);
            }
        }
    } else {
        for (var j = 0u; j < BLOCK; j++) {
            let i = i0 + j;
            if i < D0 {
                dx[dx_row + i] = bitcast<u32>(acc_value(&first, j));
            }
        }
    }
}
