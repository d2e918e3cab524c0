//! Bias-free dense layers and whole MLPs on the GPU, the twin of `reference::mlp`.
//!
//! One layer over N rows computes `Y[n][o] = act(Σ_i X[n][i]·W[o][i])` (act ReLU or none), with
//! X and Y [`RowView`]s (a row stride and a column offset each, so a layer can read a slice of a
//! concatenation row and write into a slice of a wider row) and W the layer's row-major
//! `[out][in]` range of the flat parameter buffer. Its backward, given dY:
//! - `dZ = dY ⊙ act'(Y)` (ReLU: `Y > 0`, 0 at 0 as the reference), formed while staging tiles;
//! - `dX = dZ·W`, OVERWRITING the input-gradient view (skipped when there is none, e.g. the
//!   colour MLP's SH input);
//! - `dW = dZᵀ·X`, ADDED to the gradient buffer at the layer's range and nowhere else (the
//!   trainer zeroes the gradient buffer before a step; the hash-table part is another pass's).
//!   The sum over N is deterministic: every chunk of rows writes its own partial matrix, then a
//!   second kernel sums the chunks in order, so a step gives the same bits every run.
//!
//! The three kernels (`shaders/dense_*.wgsl`) share one register-tiled product
//! (`shaders/_dense_tile.wgsl`): each invocation accumulates a contiguous 4×4 block of outputs
//! from tiles staged in workgroup memory as vec4s (one load of A and one of B per 16
//! multiply-adds); the invocation grid and chunk depth are override constants picked per
//! layer shape by [`TileShape`], so 128-wide layers use 64×64 tiles and 1-, 3- or C-wide outputs
//! tall thin ones. Pipelines are compiled once per (kernel, shape) and device (through
//! [`DenseKernels`] into the context's pipeline cache) and shared by every layer of every MLP.
//!
//! On CPU devices (lavapipe, SwiftShader) the forward and the input gradient use a second
//! family of kernels, [`KernelFamily::UniformWeights`] (`shaders/dense_*_uniform.wgsl`): one
//! invocation per row, the layer's weights read through a uniform binding, which those devices
//! load once per SIMD group instead of once per lane (see the shader for the measurement). Each
//! such product reads a copy of the layer's weights in rows padded to whole vec4s (all of one
//! MLP's copies refreshed by one dispatch before its forward: `shaders/dense_pack_weights.wgsl`,
//! `uniform::MlpPacking`), and the weight gradient reads dZ in rows padded the same way, so
//! every uniform read is a whole vec4 at an index every lane shares. A layer qualifies when its padded matrix holds at most [`UNIFORM_WEIGHT_FLOATS`]
//! values; other layers use the tiled kernels.
//!
//! X and Y (and dY and dX) of one layer must be different buffers: WebGPU forbids binding one
//! buffer both read-only and writable in a dispatch.
//!
//! Where the family reads its packed copies and dZ is [`PackedReads`]: uniform bindings natively,
//! storage bindings in the page, whose compiler (Tint) divides on every uniform access
//! (`shaders/_dense_uniform.wgsl`).
//!
//! Where every product of an MLP runs this family, its hidden layers' outputs are stored as
//! bf16 rows ([`RowFormat::Bf16`], two values per word; `shaders/_bf16.wgsl`), which halves
//! what the forward writes and every later pass reads of them (docs/architecture.md, "Hidden
//! activations in bf16"). The MLP's input and output stay f32, and so does everything the
//! tiled kernels touch.
//!
//! On lavapipe an MLP of 2 or 3 such layers whose hidden widths fit one invocation runs all its
//! input gradients as one kernel ([`chain`]), each hidden layer's dX kept in registers. Other
//! such MLPs store each hidden layer's dX masked by the ReLU, as the layer below's dZ, straight
//! into that layer's weight-gradient windows, with the mask from bits its forward stored
//! ([`relu_mask`]).
//!
//! Where things live, from the bottom up (each file imports only those above it in this list):
//! [`spec`] (a layer's spec, the kernels' uniform block, bindings and rows), [`tiled`] (tile
//! shapes and the tiled weight-gradient chunking), [`uniform_shape`] (the uniform-weight
//! family's blocks and reads), [`pipelines`] (the pipeline cache, the choice of kernel per
//! product and binding one), [`uniform`] (the uniform-weight kernels), [`relu_mask`] (the ReLU's
//! bits between layers), [`layer`] (one layer's forward), [`chain`] (the input-gradient chain),
//! [`backward`] (one layer's backward) and [`mlp`] (whole MLPs). Everything a caller needs is
//! re-exported here.
mod backward;
mod chain;
mod layer;
mod mlp;
mod pipelines;
mod relu_mask;
mod spec;
mod tiled;
mod uniform;
mod uniform_shape;

pub use backward::{DenseBackward, DenseGradients};
pub use layer::DenseForward;
pub use mlp::{InputRows, MlpGradients, MlpPass, MlpPassDesc, MlpStage, mlp_row_format};
pub use pipelines::DenseKernels;
pub use relu_mask::ReluMask;
pub use spec::{DenseDims, DenseLayerSpec};
pub use tiled::TileShape;
pub use uniform_shape::{PackedReads, UNIFORM_WEIGHT_FLOATS};

pub use crate::field::gpu::row_view::{RowFormat, RowView};

/// The override constant `name` (`X_BF16`, `Y_BF16`) that makes a packed-weight kernel read or
/// write `view`'s rows in its format.
pub(super) fn bf16_rows(name: &'static str, view: &RowView) -> (&'static str, f64) {
    (name, f64::from(u8::from(view.is_bf16())))
}
