use super::{WeightGradientShape, uniform_block, weight_gradient_block};
use crate::field::gpu::dense::DenseLayerSpec;

#[test]
fn weight_gradient_spans_keep_four_workgroups_per_dispatch() {
    // (in, out, block limit) -> workgroups over columns and outputs, span.
    for (in_dim, out_dim, limit, workgroups, span) in [
        (128, 128, 64, [2, 2], 8),
        (44, 128, 64, [1, 2], 4),
        (64, 64, 64, [1, 1], 2),
        (15, 64, 64, [1, 1], 2),
        (64, 64, 16, [1, 4], 8),
        (128, 3, 64, [2, 1], 4),
    ] {
        let spec = DenseLayerSpec {
            label: "layer".into(),
            rows: 1000,
            in_dim,
            out_dim,
            relu: true,
            weights: 0..(in_dim * out_dim) as usize,
        };
        let shape = WeightGradientShape::new(&spec, limit);
        assert_eq!(
            (shape.workgroups, shape.span),
            (workgroups, span),
            "{in_dim} x {out_dim}, limit {limit}"
        );
        let per_slot = workgroups[0] * workgroups[1];
        assert!(8 / span * per_slot >= 4 || span == 1);
        assert_eq!(shape.partials(17), 17u32.div_ceil(span));
    }
}

#[test]
fn blocks_split_a_layer_evenly_in_multiples_of_four() {
    for (width, limit, block) in [
        (79, 64, 40),
        (128, 64, 64),
        (64, 64, 64),
        (32, 64, 32),
        (28, 64, 28),
        (6, 64, 8),
        (3, 64, 4),
        (79, 16, 16),
        (64, 16, 16),
        (15, 16, 16),
        (6, 4, 4),
    ] {
        assert_eq!(uniform_block(width, limit), block, "width {width}, limit {limit}");
        assert!(block % 4 == 0 && block <= limit.max(4));
    }
}

#[test]
fn weight_gradient_blocks_start_at_whole_bf16_vec4s() {
    for (width, limit, block) in [
        (79, 64, 40),
        (128, 64, 64),
        (100, 64, 56),
        (16, 64, 16),
        (3, 64, 4),
        (79, 16, 16),
        (20, 16, 16),
        (16, 4, 8),
        (3, 4, 4),
    ] {
        assert_eq!(
            weight_gradient_block(width, limit),
            block,
            "width {width}, limit {limit}"
        );
        // One block covering the row, or blocks of whole 8-value vec4<u32>s.
        assert!(block >= width || block % 8 == 0);
    }
}
