// The forward of the packed-weight dense kernels (dense_forward_uniform.wgsl,
// dense_forward_packed_storage.wgsl): everything but the `weights` binding, which each stage
// declares in its own address space (`_dense_uniform.wgsl` says why there are two).
//!include _dense_uniform.wgsl
//!include _bf16.wgsl
//!include _dense_relu_mask.wgsl

@group(0) @binding(0) var<uniform> dims: DenseDims;
// X and Y in f32 or bf16 rows (X_BF16, Y_BF16: hidden layers of an MLP whose kernels all read
// bf16 rows, `_bf16.wgsl`); bf16 rows start at even values.
@group(0) @binding(1) var<storage, read> x: array<u32>;
@group(0) @binding(3) var<storage, read_write> y: array<u32>;
override X_BF16: bool = false;
override Y_BF16: bool = false;
// Whether a hidden layer also writes which of its stored outputs are positive, one bit each
// (`_dense_relu_mask.wgsl`), for the next layer's input gradient to mask with in place of
// reading Y back (`dense::MlpPass`, docs/architecture.md).
override WRITE_MASK: bool = false;
@group(0) @binding(5) var<storage, read_write> relu_mask: array<u32>;

fn x_value(row: u32, i: u32) -> f32 {
    return row_value(x[row_word(row, i, X_BF16)], i, X_BF16);
}

// Whether Y[n][o] as stored is positive (a bf16 row's value rounds to 0 only from 0 itself or
// below bf16's range).
fn stored_positive(value: f32) -> bool {
    if Y_BF16 {
        return value > 0.0 && bf16_bits(value) != 0u;
    }
    return value > 0.0;
}

// Y[n][o] after the activation, 0 past the layer's outputs.
fn output_value(acc: ptr<function, Acc>, j: u32, o: u32) -> f32 {
    if o >= dims.out_dim {
        return 0.0;
    }
    let value = acc_value(acc, j);
    if dims.relu != 0u {
        return max(value, 0.0);
    }
    return value;
}

// Input i's step of the reduction (UNROLL): i and the weight index are constants once the
// pipeline is specialised and the calls inlined (q0 too, where the block holds the whole row);
// steps past REDUCED fold away.
fn forward_step(acc: ptr<function, Acc>, x_row: u32, q0: u32, i: u32) {
    if i < REDUCED {
        accumulate(acc, x_value(x_row, i), i * ROW_QUADS + q0);
    }
}

fn forward_steps(acc: ptr<function, Acc>, x_row: u32, q0: u32, first: u32) {
    forward_step(acc, x_row, q0, first);
    forward_step(acc, x_row, q0, first + 1u);
    forward_step(acc, x_row, q0, first + 2u);
    forward_step(acc, x_row, q0, first + 3u);
    forward_step(acc, x_row, q0, first + 4u);
    forward_step(acc, x_row, q0, first + 5u);
    forward_step(acc, x_row, q0, first + 6u);
    forward_step(acc, x_row, q0, first + 7u);
}

@compute @workgroup_size(WORKGROUP)
fn forward(
    @builtin(workgroup_id) workgroup_id: vec3<u32>,
    @builtin(num_workgroups) num_workgroups: vec3<u32>,
    @builtin(local_invocation_index) local_index: u32,
) {
    let item = linear_item_index(vec3<u32>(workgroup_id.xy, 0u), num_workgroups, local_index, WORKGROUP);
    let rows = active_rows();
    if !UNROLL && item >= rows {
        return;
    }
    let n = row_read(item, rows);
    let block = block_index(workgroup_id.z);
    let o0 = block * BLOCK;
    let x_row = n * dims.x_stride + dims.x_offset;
    let q0 = block_quad(block);
    var acc: Acc;
    if UNROLL {
        forward_steps(&acc, x_row, q0, 0u);
        forward_steps(&acc, x_row, q0, 8u);
        forward_steps(&acc, x_row, q0, 16u);
        forward_steps(&acc, x_row, q0, 24u);
        forward_steps(&acc, x_row, q0, 32u);
        forward_steps(&acc, x_row, q0, 40u);
        forward_steps(&acc, x_row, q0, 48u);
        forward_steps(&acc, x_row, q0, 56u);
        forward_steps(&acc, x_row, q0, 64u);
        forward_steps(&acc, x_row, q0, 72u);
        forward_steps(&acc, x_row, q0, 80u);
        forward_steps(&acc, x_row, q0, 88u);
        forward_steps(&acc, x_row, q0, 96u);
        forward_steps(&acc, x_row, q0, 104u);
        forward_steps(&acc, x_row, q0, 112u);
        forward_steps(&acc, x_row, q0, 120u);
    } else {
        // Input i's packed row holds W[0 .. out][i]; outputs o0 .. o0 + BLOCK are its quads from
        // o0 / 4 (BLOCK is a multiple of 4). Quads past the row's end give outputs never written.
        let quads = quads_per_row(dims.out_dim);
        for (var i = 0u; i < dims.in_dim; i++) {
            accumulate(&acc, x_value(x_row, i), i * quads + q0);
        }
    }
    if item >= rows {
        return;
    }
    let y_row = n * dims.y_stride + dims.y_offset;
    // The block's mask words (BLOCK is at most 64), bits set as the pairs are stored.
    var mask = vec2<u32>(0u, 0u);
    // Pairs of outputs (BLOCK and o0 are multiples of 4): a bf16 pair is one word, the second
    // 0 past an odd width (the row's padding).
    for (var j = 0u; j < BLOCK; j += 2u) {
        let o = o0 + j;
        if o < dims.out_dim {
            let first = output_value(&acc, j, o);
            let second = output_value(&acc, j + 1u, o + 1u);
            if Y_BF16 {
                y[row_word(y_row, o, true)] = bf16_pair(first, second);
            } else {
                y[y_row + o] = bitcast<u32>(first);
                if o + 1u < dims.out_dim {
                    y[y_row + o + 1u] = bitcast<u32>(second);
                }
            }
            if WRITE_MASK {
                let bits = u32(stored_positive(first)) | (u32(stored_positive(second)) << 1u);
                mask[j >> 5u] |= bits << (j & 31u);
            }
        }
    }
    if WRITE_MASK {
        let first_word = relu_mask_word(n, dims.out_dim, BLOCK, o0);
        relu_mask[first_word] = mask.x;
        if relu_mask_block_words(BLOCK) > 1u {
            relu_mask[first_word + 1u] = mask.y;
        }
    }
}
