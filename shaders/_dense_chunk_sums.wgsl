// What both weight-gradient kernels of the packed-weight family share
// (dense_backward_weight_uniform.wgsl, dZ through 64 KiB uniform windows;
// dense_backward_weight_packed_storage.wgsl, dZ from one storage binding): the bindings of X and
// of the partial matrices, a chunk's window of rows, and writing a lane's sums. Workgroup x picks
// COLUMNS input columns (one per lane), y a block of BLOCK outputs, z a span of SPAN consecutive
// chunks of dims.chunk_rows rows each, whose partial dW[o][i] = Σ_n dZ[n][o] · X[n][i] (rows in
// order) goes to partials[first chunk / SPAN]: a partial matrix is written and read back once,
// so the fewer the better, while enough workgroups remain to keep a CPU device's threads busy
// (uniform.rs, `WeightGradientShape`).
//!include _dense_tile.wgsl
//!include _dense_acc.wgsl
//!include _bf16.wgsl
//!include _dense_output_gradient.wgsl

override BLOCK: u32 = 16u;
// Lanes (input columns) per workgroup: uniform.rs picks the smallest of 8..64 covering the
// layer's inputs, so a 15- or 32-input layer leaves few lanes idle.
override COLUMNS: u32 = 64u;
// Chunks one workgroup sums into one partial matrix: 1, 2, 4 or 8 (a divisor of the 8 windows
// a dispatch of the windowed kernel binds).
override SPAN: u32 = 1u;

@group(0) @binding(0) var<uniform> dims: DenseDims;
// Y: what `output_gradient` (`_dense_tile.wgsl`) masks with, where the windowed stage forms dZ.
// X and Y in f32 or bf16 rows (X_BF16, Y_BF16: hidden layers of an MLP whose kernels all read
// bf16 rows, `_bf16.wgsl`).
@group(0) @binding(2) var<storage, read> y: array<u32>;
@group(0) @binding(3) var<storage, read> x: array<u32>;
override X_BF16: bool = false;
override Y_BF16: bool = false;
// [chunk][out][in]
@group(0) @binding(4) var<storage, read_write> partials: array<f32>;

// Mirrors `ChunkInfo` in uniform.rs: the first of the chunks one dispatch sums (a multiple of
// SPAN); workgroup z is the span of SPAN of them from slot z · SPAN.
struct ChunkInfo {
    first: u32,
}

@group(1) @binding(0) var<uniform> chunk: ChunkInfo;

// What one chunk's loop reads: its first row, its row count, the lane's column of X, the first
// vec4<u32> of the workgroup's outputs in a dZ row (o0 is a multiple of 8), and the vec4<u32>s
// per dZ row (bf16 rows, `_bf16.wgsl`).
struct Window {
    first_row: u32,
    count: u32,
    column: u32,
    o0_oct: u32,
    row_octs: u32,
}

// Chunk `index`'s rows for the lane of input column i and the outputs from o0. Lanes past the
// last column read a valid column and discard the result.
fn chunk_window(index: u32, i: u32, o0: u32) -> Window {
    let first_row = index * dims.chunk_rows;
    let rows = active_rows();
    var count = 0u;
    if first_row < rows {
        count = min(dims.chunk_rows, rows - first_row);
    }
    let column = dims.x_offset + min(i, dims.in_dim - 1u);
    return Window(first_row, count, column, o0 >> 3u, bf16_row_octs(dims.out_dim));
}

fn x_at(w: Window, r: u32) -> f32 {
    let index = (w.first_row + r) * dims.x_stride + w.column;
    if X_BF16 {
        return bf16_at(x[index >> 1u], index);
    }
    return bitcast<f32>(x[index]);
}

fn y_value(row: u32, j: u32) -> f32 {
    return row_value(y[row_word(row, j, Y_BF16)], j, Y_BF16);
}

// partials[index][o0 + j][i] = the lane's sums, for the outputs and the column inside the layer.
fn store_partials(acc: ptr<function, Acc>, index: u32, i: u32, o0: u32) {
    if i >= dims.in_dim {
        return;
    }
    let matrix = dims.out_dim * dims.in_dim;
    for (var j = 0u; j < BLOCK; j++) {
        let o = o0 + j;
        if o < dims.out_dim {
            partials[index * matrix + o * dims.in_dim + i] = acc_value(acc, j);
        }
    }
}
