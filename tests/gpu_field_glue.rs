//! The head glue against the per-sample arithmetic of `reference::model`, on the packed rows of
//! the samples kept for the heads (a third of them dropped): the forward and the feature gather
//! on the packed rows alone, the geometry gather on every sample; f, the semantic input and its
//! gradient as f32 rows and as bf16 rows (the feature and semantic MLPs' rows on CPU devices).
use scribblefield::field::bf16;
use scribblefield::field::gpu::dense::{RowFormat, RowView};
use scribblefield::field::gpu::head_glue::{GlueBuffers, GlueDims, GlueRows, HeadGluePass, WORKGROUP_SIZE};
use scribblefield::field::gpu::keep::{HeadRows, NOT_KEPT, workgroup_counts};
use scribblefield::field::gpu::stage::Stage;
use scribblefield::gpu::buffers::{read_buffer_blocking, storage_buffer_from, storage_buffer_garbage};
use scribblefield::gpu::test_support::gpu_for_tests;

fn values(len: usize, salt: f32) -> Vec<f32> {
    (0..len)
        .map(|i| ((i as f32 * 0.618 + salt).fract() - 0.5) * 3.0)
        .collect()
}

#[test]
fn glue_matches_reference_arithmetic() {
    check_glue("glue_matches_reference_arithmetic", true, RowFormat::F32);
}

/// `SemanticInput::Feature`: the semantic input is relu(f) alone, and no semantic
/// gradient reaches g.
#[test]
fn glue_without_geometry_in_the_semantic_input() {
    check_glue("glue_without_geometry_in_the_semantic_input", false, RowFormat::F32);
}

/// bf16 rows of f and of the semantic input: an odd semantic width (8 + 15), so every row ends
/// in a padding value, and an even one.
#[test]
fn glue_with_bf16_semantic_rows() {
    check_glue("glue_with_bf16_semantic_rows", true, RowFormat::Bf16);
    check_glue("glue_with_bf16_semantic_rows", false, RowFormat::Bf16);
}

/// Rows of `width` values in `format`: their words, and the values as stored.
fn stored_rows(values: &[f32], width: usize, format: RowFormat) -> (Vec<u32>, Vec<f32>) {
    match format {
        RowFormat::F32 => (values.iter().map(|v| v.to_bits()).collect(), values.to_vec()),
        RowFormat::Bf16 => {
            let stride = width.next_multiple_of(2);
            let mut words = Vec::new();
            let mut stored = Vec::new();
            for row in values.chunks(width) {
                let padded: Vec<f32> = (0..stride).map(|j| row.get(j).copied().unwrap_or(0.0)).collect();
                words.extend(padded.chunks(2).map(|p| bf16::pair(p[0], p[1])));
                stored.extend(row.iter().map(|&v| bf16::round(v)));
            }
            (words, stored)
        }
    }
}

/// Value `j` of row `p` of `width`-value rows held in `words`.
fn row_value(words: &[u32], p: usize, j: usize, width: usize, format: RowFormat) -> f32 {
    match format {
        RowFormat::F32 => f32::from_bits(words[p * width + j]),
        RowFormat::Bf16 => {
            let stride = width.next_multiple_of(2);
            bf16::row_value(&words[p * stride / 2..], j)
        }
    }
}

/// Row `p` of bf16 rows of an odd `width` ends in a padding value: it must be 0.
fn assert_padding_is_zero(words: &[u32], p: usize, width: usize, format: RowFormat) {
    if format == RowFormat::Bf16 && width % 2 == 1 {
        assert_eq!(row_value(words, p, width, width, format), 0.0, "padding of row {p}");
    }
}

fn check_glue(name: &str, semantic_sees_geometry: bool, format: RowFormat) {
    let Some(ctx) = gpu_for_tests(name) else {
        return;
    };
    let (n, g, d, sh) = (1037usize, 15usize, 8usize, 16usize);
    // Columns of g in the semantic input.
    let sg = if semantic_sees_geometry { g } else { 0 };
    // Composite rows [dh0, dcolour (3), dlogits (C = 2), df (D)].
    let (stride, h0_at, f_at) = (1 + 3 + 2 + d, 0usize, 6usize);
    let density_out = values(n * (1 + g), 0.1);
    // f as the feature MLP stored it, and the values the glue should read.
    let (feature_words, feature_out) = stored_rows(&values(n * d, 0.2), d, format);
    // The gradient as the semantic MLP stored it, and the values the glue should read.
    let (semantic_grad_words, semantic_in_grad) = stored_rows(&values(n * (d + sg), 0.3), d + sg, format);
    let grad_heads0 = values(n * stride, 0.4);
    let grad_h0 = values(n * stride, 0.8);
    // Every third sample dropped; the rest packed in order.
    let mut slot = vec![NOT_KEPT; n];
    let mut kept = 0usize;
    for (s, slot) in slot.iter_mut().enumerate() {
        if s % 3 != 1 {
            *slot = kept as u32;
            kept += 1;
        }
    }
    let (color_grad_words, color_in_grad) = stored_rows(&values(n * (sh + g), 0.5), sh + g, format);
    let (feature_grad_words, feature_in_grad) = stored_rows(&values(n * g, 0.6), g, format);
    let (color_words, _) = stored_rows(&values(n * (sh + g), 0.7), sh + g, format);

    let buf = |label: &str, v: &[f32]| storage_buffer_from(&ctx, label, v).unwrap();
    let density_out_b = buf("density out", &density_out);
    let rows_of = |buffer: &wgpu::Buffer, width: usize| RowView::packed_as(buffer, width as u32, format);
    let feature_out_b = rows_of(&storage_buffer_from(&ctx, "feature out", &feature_words).unwrap(), d);
    let color_in_b = rows_of(&storage_buffer_from(&ctx, "color in", &color_words).unwrap(), sh + g);
    let view = |buffer: &wgpu::Buffer| rows_of(buffer, d + sg);
    let semantic_words = RowView::words(format, n as u32, (d + sg) as u32) as usize;
    let semantic_in_b = view(&storage_buffer_garbage::<u32>(&ctx, "semantic in", semantic_words).unwrap());
    let semantic_in_grad_b = view(&storage_buffer_from(&ctx, "semantic in grad", &semantic_grad_words).unwrap());
    let grad_heads_b = buf("grad heads", &grad_heads0);
    let density_out_grad_b = storage_buffer_garbage::<f32>(&ctx, "density out grad", n * (1 + g)).unwrap();
    let color_in_grad_b = rows_of(
        &storage_buffer_from(&ctx, "color in grad", &color_grad_words).unwrap(),
        sh + g,
    );
    let feature_in_grad_b = rows_of(
        &storage_buffer_from(&ctx, "feature in grad", &feature_grad_words).unwrap(),
        g,
    );
    let grad_h0_b = buf("grad h0", &grad_h0);
    let rows = HeadRows::new(&ctx, n as u32).unwrap();
    let dispatch = rows.dispatch(1, WORKGROUP_SIZE, 1).unwrap();
    let counts = workgroup_counts(
        rows.shapes()[0],
        kept as u32,
        ctx.limits.max_compute_workgroups_per_dimension,
    );
    ctx.queue
        .write_buffer(&rows.dispatch_args, 0, bytemuck::cast_slice(&counts));
    ctx.queue
        .write_buffer(&rows.row_count, 0, bytemuck::bytes_of(&(kept as u32)));
    ctx.queue.write_buffer(&rows.slot, 0, bytemuck::cast_slice(&slot));
    let dims = GlueDims {
        samples: n as u32,
        geometry: g as u32,
        feature: d as u32,
        sh: sh as u32,
        grad_stride: stride as u32,
        grad_h0: h0_at as u32,
        grad_feature: f_at as u32,
        semantic_trunk_scale: 1.0,
        semantic_geometry: sg as u32,
        // The row strides: from the views.
        ..bytemuck::Zeroable::zeroed()
    };
    let buffers = GlueBuffers {
        density_out: &density_out_b,
        feature_out: &feature_out_b,
        color_in: &color_in_b,
        semantic_in: &semantic_in_b,
        semantic_in_grad: &semantic_in_grad_b,
        grad_heads: &grad_heads_b,
        grad_h0_source: &grad_h0_b,
        density_out_grad: &density_out_grad_b,
        color_in_grad: &color_in_grad_b,
        feature_in_grad: &feature_in_grad_b,
    };
    let glue_rows = GlueRows {
        row_count: &rows.row_count,
        slot: &rows.slot,
        dispatch: Some(dispatch),
    };
    let glue = pollster::block_on(HeadGluePass::new(&ctx, dims, &buffers, &glue_rows)).unwrap();
    let mut encoder = ctx.device.create_command_encoder(&Default::default());
    {
        let mut pass = encoder.begin_compute_pass(&Default::default());
        glue.assemble.record(&mut pass);
        glue.gather_feature.record(&mut pass);
        glue.gather_geometry.record(&mut pass);
    }
    ctx.queue.submit([encoder.finish()]);

    let color_in: Vec<u32> = read_buffer_blocking(&ctx, &color_in_b.buffer).unwrap();
    // Words per colour row and of its SH part.
    let (cw, sh_words) = match format {
        RowFormat::F32 => (sh + g, sh),
        RowFormat::Bf16 => ((sh + g).div_ceil(2), sh / 2),
    };
    let semantic_in: Vec<u32> = read_buffer_blocking(&ctx, &semantic_in_b.buffer).unwrap();
    let stored = |v: f32| match format {
        RowFormat::F32 => v,
        RowFormat::Bf16 => bf16::round(v),
    };
    let grad_heads: Vec<f32> = read_buffer_blocking(&ctx, &grad_heads_b).unwrap();
    let density_grad: Vec<f32> = read_buffer_blocking(&ctx, &density_out_grad_b).unwrap();
    for p in 0..n {
        let geo = &density_out[p * (1 + g) + 1..(p + 1) * (1 + g)];
        let f = &feature_out[p * d..(p + 1) * d];
        let row = p * cw;
        assert_eq!(
            &color_in[row..row + sh_words],
            &color_words[row..row + sh_words],
            "SH columns untouched"
        );
        if p >= kept {
            // Past the packed rows nothing is written.
            assert_eq!(&color_in[row..row + cw], &color_words[row..row + cw], "row {p}");
            assert_eq!(
                &grad_heads[p * stride..(p + 1) * stride],
                &grad_heads0[p * stride..(p + 1) * stride]
            );
            continue;
        }
        let got: Vec<f32> = (sh..sh + g)
            .map(|j| row_value(&color_in, p, j, sh + g, format))
            .collect();
        let want: Vec<f32> = geo.iter().copied().map(stored).collect();
        assert_eq!(got, want, "g in the colour input of row {p}");
        assert_padding_is_zero(&color_in, p, sh + g, format);
        let want: Vec<f32> = f
            .iter()
            .map(|v| v.max(0.0))
            .chain(geo[..sg].iter().copied())
            .map(stored)
            .collect();
        let got: Vec<f32> = (0..d + sg)
            .map(|j| row_value(&semantic_in, p, j, d + sg, format))
            .collect();
        assert_eq!(got, want, "semantic input of row {p}");
        assert_padding_is_zero(&semantic_in, p, d + sg, format);
        for k in 0..d {
            let at = p * stride + f_at + k;
            let via_semantic = if f[k] > 0.0 {
                semantic_in_grad[p * (d + sg) + k]
            } else {
                0.0
            };
            assert_eq!(grad_heads[at], grad_heads0[at] + via_semantic);
        }
        assert_eq!(
            &grad_heads[p * stride..p * stride + f_at],
            &grad_heads0[p * stride..p * stride + f_at]
        );
    }
    for (s, &p) in slot.iter().enumerate() {
        assert_eq!(
            density_grad[s * (1 + g)],
            grad_h0[s * stride + h0_at],
            "dL/dh0 copied for every sample"
        );
        for j in 0..g {
            let got = density_grad[s * (1 + g) + 1 + j];
            if p == NOT_KEPT {
                assert_eq!(got, 0.0, "no head gradient for a dropped sample");
                continue;
            }
            let p = p as usize;
            let via_semantic = if j < sg {
                semantic_in_grad[p * (d + sg) + d + j]
            } else {
                0.0
            };
            let color = color_in_grad[p * (sh + g) + sh + j];
            let want = color + via_semantic + feature_in_grad[p * g + j];
            assert!((got - want).abs() <= 1e-6 * want.abs().max(1.0));
        }
    }
}
