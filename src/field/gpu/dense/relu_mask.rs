//! Which outputs of a hidden layer are positive, one bit each, as its forward stores them for
//! the next layer's input gradient (`shaders/_dense_relu_mask.wgsl`, whose layout this mirrors):
//! that kernel stores the layer's dZ masked by the ReLU, and reads these bits instead of the
//! bf16 outputs, 1/16 of the bytes (docs/architecture.md, "Hidden activations in bf16").
//!
//! Each block of `block` outputs, the ones one forward invocation computes, owns whole words, so
//! no two invocations write one word.
use crate::gpu::buffers::storage_buffer_zeroed;
use crate::gpu::{GpuContext, GpuError};

/// A hidden layer's mask bits over its rows, and the block they are laid out in.
#[derive(Debug, Clone)]
pub struct ReluMask {
    pub buffer: wgpu::Buffer,
    /// Outputs per block (the forward's `BLOCK`).
    pub block: u32,
    /// The layer's outputs.
    pub width: u32,
}

impl ReluMask {
    /// A zeroed mask of `rows` rows.
    pub fn zeroed(ctx: &GpuContext, label: &str, rows: u32, width: u32, block: u32) -> Result<ReluMask, GpuError> {
        if block == 0 {
            return Err(GpuError::invalid_argument(label, "a ReLU mask needs a positive block"));
        }
        let words = u64::from(rows) * u64::from(row_words(width, block));
        ctx.ensure_storage_binding_fits(label, words * 4)?;
        Ok(ReluMask {
            buffer: storage_buffer_zeroed::<u32>(ctx, label, words as usize)?,
            block,
            width,
        })
    }

    /// Words per row.
    pub fn row_words(&self) -> u32 {
        row_words(self.width, self.block)
    }

    /// Whether output `o` of row `n` is set in `words` (the buffer read back).
    pub fn is_set(&self, words: &[u32], n: usize, o: u32) -> bool {
        let word = n * self.row_words() as usize + word_in_row(self.block, o) as usize;
        (words[word] >> bit(self.block, o)) & 1 == 1
    }
}

/// Words one block takes.
fn block_words(block: u32) -> u32 {
    block.div_ceil(32)
}

/// Words one row of `width` outputs takes.
pub fn row_words(width: u32, block: u32) -> u32 {
    width.div_ceil(block) * block_words(block)
}

/// The word of its row that holds output `o`.
fn word_in_row(block: u32, o: u32) -> u32 {
    let b = o / block;
    b * block_words(block) + (o - b * block) / 32
}

/// Output `o`'s bit in its word.
fn bit(block: u32, o: u32) -> u32 {
    (o % block) % 32
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_output_has_its_own_bit_and_blocks_own_whole_words() {
        for (width, block) in [(128, 64), (128, 16), (79, 40), (64, 64), (15, 16), (3, 4), (100, 36)] {
            let words = row_words(width, block);
            let mut seen = vec![0u32; words as usize];
            let mut owner = vec![None; words as usize];
            for o in 0..width {
                let (w, b) = (word_in_row(block, o) as usize, bit(block, o));
                assert!(w < words as usize, "{width}/{block}: output {o} past the row");
                assert_eq!(seen[w] & (1 << b), 0, "{width}/{block}: output {o} shares a bit");
                seen[w] |= 1 << b;
                let blk = o / block;
                assert!(
                    owner[w].is_none_or(|x| x == blk),
                    "{width}/{block}: word {w} spans blocks"
                );
                owner[w] = Some(blk);
            }
        }
    }
}
