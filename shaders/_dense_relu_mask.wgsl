// Where a hidden layer's forward stores which of its outputs are positive, one bit each, and
// where the next layer's input gradient reads them (_dense_forward_packed.wgsl WRITE_MASK,
// _dense_backward_input_packed.wgsl MASK_DX; src/field/gpu/dense/relu_mask.rs is the CPU twin).
// Each block of `block` outputs one forward invocation computes owns whole words, so no two
// invocations write one word: a row is ceil(width / block) blocks of ceil(block / 32) words,
// output o at bit (o mod block) mod 32 of word (o mod block) / 32 of block o / block.

fn relu_mask_block_words(block: u32) -> u32 {
    return (block + 31u) >> 5u;
}

fn relu_mask_row_words(width: u32, block: u32) -> u32 {
    return (width + block - 1u) / block * relu_mask_block_words(block);
}

// The word holding output o of row n (o0 = the block's first output: its first word).
fn relu_mask_word(n: u32, width: u32, block: u32, o: u32) -> u32 {
    let b = o / block;
    return n * relu_mask_row_words(width, block) + b * relu_mask_block_words(block) + ((o - b * block) >> 5u);
}

// Output o's bit in its word.
fn relu_mask_bit(block: u32, o: u32) -> u32 {
    return (o % block) & 31u;
}
