//! The dense-layer kernels and `MlpPass` against `reference::mlp` (in f64) on every MLP of
//! `FieldConfig::small()` and of the default widths, with row views that have a stride and an
//! offset, garbage-filled outputs and a row count that is no multiple of any tile.
//!
//! Tolerance: a GPU value is a sum of K f32 products, whose rounding error is bounded by about
//! K·2⁻²⁴ times the sum of the absolute terms (the "magnitude"; for K ≤ 128 and the tiled order
//! far less in practice). We accept |gpu − f64 reference| ≤ 1e-5 · magnitude + 1e-6, the
//! magnitude coming from the same reference run on absolute values. dW sums over all N rows
//! (K = N = 777 here, in chunks), so it gets 4e-5 · magnitude. Where dW reads dZ through
//! uniform windows the GPU stores dZ as bf16 (`scribblefield::field::bf16`): each stored value
//! must be the reference's dZ within bf16 rounding, and dW the sum of the stored values.
use scribblefield::field::bf16;
use scribblefield::field::gpu::dense::{
    DenseKernels, InputRows, MlpGradients, MlpPass, MlpPassDesc, PackedReads, RowFormat, RowView, UNIFORM_WEIGHT_FLOATS,
};
use scribblefield::field::gpu::keep::{HeadRows, workgroup_counts};
use scribblefield::field::params::{MlpLayout, ParamLayout};
use scribblefield::field::reference::mlp::{MlpTrace, backward, forward};
use scribblefield::field::{Encoding, FieldConfig};
use scribblefield::gpu::GpuContext;
use scribblefield::gpu::KernelFamily;
use scribblefield::gpu::buffers::{
    GARBAGE_WORDS, fill_with_garbage, read_buffer_blocking, storage_buffer_from, storage_buffer_garbage,
    storage_buffer_padded, storage_buffer_zeroed,
};
use scribblefield::gpu::test_support::gpu_for_tests;
use scribblefield::rng::SplitMix64;

const ROWS: usize = 777;
const FORWARD_TOLERANCE: f64 = 1e-5;
const WEIGHT_GRAD_TOLERANCE: f64 = 4e-5;
const ABSOLUTE_TOLERANCE: f64 = 1e-6;
/// A stored bf16 dZ against the f64 reference: half a bf16 step (2⁻⁸ of the value at most), or
/// a whole one where the GPU's f32 value lay within its rounding of a halfway point.
const BF16_TOLERANCE: f64 = 1.0 / 128.0;
/// Initial value of every gradient element: dW must be added to it, and elements outside the
/// MLP's layers must keep it bit for bit.
const GRAD_PRESET: f32 = 0.25;

/// Rows laid out in a wider buffer: `width` values at `offset` of rows of `stride`.
#[derive(Clone, Copy)]
struct ViewLayout {
    width: usize,
    stride: usize,
    offset: usize,
}

impl ViewLayout {
    fn padded(width: usize, before: usize, after: usize) -> ViewLayout {
        ViewLayout {
            width,
            stride: before + width + after,
            offset: before,
        }
    }

    fn len(&self, rows: usize) -> usize {
        rows * self.stride
    }

    fn view(&self, buffer: &wgpu::Buffer) -> RowView {
        RowView::new(buffer, self.stride as u32, self.offset as u32)
    }

    fn row<'a>(&self, data: &'a [f32], n: usize) -> &'a [f32] {
        &data[n * self.stride + self.offset..][..self.width]
    }

    /// Every element outside the view must still hold the garbage pattern.
    fn assert_gaps_untouched(&self, what: &str, data: &[f32], rows: usize) {
        for (index, value) in data.iter().enumerate().take(self.len(rows)) {
            let column = index % self.stride;
            if column < self.offset || column >= self.offset + self.width {
                assert_eq!(
                    value.to_bits(),
                    GARBAGE_WORDS[index % GARBAGE_WORDS.len()],
                    "{what}: element {index} outside the view was written"
                );
            }
        }
    }
}

/// A parameter buffer as the trainer makes it: readable through the uniform bindings of the
/// CPU-device kernels too.
fn trainer_params(ctx: &GpuContext, params: &[f32]) -> wgpu::Buffer {
    storage_buffer_padded(
        ctx,
        "params",
        params,
        UNIFORM_WEIGHT_FLOATS,
        wgpu::BufferUsages::UNIFORM,
    )
    .unwrap()
}

fn random_values(rng: &mut SplitMix64, count: usize, scale: f64) -> Vec<f32> {
    (0..count).map(|_| rng.uniform(-scale, scale) as f32).collect()
}

fn to_f64(values: &[f32]) -> Vec<f64> {
    values.iter().map(|&v| f64::from(v)).collect()
}

fn abs(values: &[f64]) -> Vec<f64> {
    values.iter().map(|v| v.abs()).collect()
}

fn assert_close(what: &str, gpu: &[f32], reference: &[f64], magnitude: &[f64], relative: f64) -> f64 {
    assert_eq!(gpu.len(), reference.len(), "{what}");
    let mut worst = 0.0f64;
    for (i, ((&g, &r), &m)) in gpu.iter().zip(reference).zip(magnitude).enumerate() {
        let error = (f64::from(g) - r).abs();
        let allowed = relative * m + ABSOLUTE_TOLERANCE;
        assert!(
            error <= allowed,
            "{what}[{i}]: GPU {g}, reference {r} (magnitude {m}, allowed {allowed:e})"
        );
        worst = worst.max(error / (m + ABSOLUTE_TOLERANCE));
    }
    worst
}

/// Configs with MLPs of every kind of shape: the small one (width 32), the default widths
/// with a small hash table (the widths are what matters here, the table only pads the buffer),
/// and a deeper density MLP.
fn configs() -> Vec<(&'static str, FieldConfig)> {
    let default_widths = FieldConfig {
        log2_hash_table_size: 12,
        ..FieldConfig::default()
    };
    let freq_only = FieldConfig {
        encoding: Encoding::freq_only_baseline(),
        num_classes: 5,
        ..FieldConfig::small()
    };
    // Five layers: ten packed copies, more than one packing dispatch takes.
    let deep = FieldConfig {
        density_layers: 4,
        ..FieldConfig::small()
    };
    // Widths 16 (the `tiny` preset's): hidden widths within SwiftShader's blocks of 16, so its
    // input gradients run as one chain there too; the semantic head's 64 inputs take 4 blocks.
    let narrow = FieldConfig {
        density_width: 16,
        color_width: 16,
        feature_width: 16,
        semantic_width: 16,
        ..FieldConfig::small()
    };
    vec![
        ("small", FieldConfig::small()),
        ("default widths", default_widths),
        ("freq-only, 5 classes", freq_only),
        ("small, density 4 hidden layers", deep),
        ("widths 16", narrow),
    ]
}

struct MlpCase<'a> {
    ctx: &'a GpuContext,
    pipelines: &'a mut DenseKernels,
    name: String,
    layout: &'a MlpLayout,
    params: &'a [f32],
    rows: usize,
    /// Whether the input gets a gradient (the colour MLP's SH input does not).
    input_grad: bool,
    /// Write the output into a slice of a wider row instead of the pass's own buffer.
    output_view: bool,
    seed: u64,
    /// Run on the first this many rows alone, as the heads run on the kept samples: the row
    /// count read from a buffer and the kernels launched indirectly (the counts written here
    /// as the keep pass writes them).
    kept: Option<usize>,
}

/// Every word of bf16 rows `from..rows` (`row_words` each) must still hold the garbage pattern.
fn assert_bf16_rows_untouched(what: &str, words: &[u32], row_words: usize, from: usize, rows: usize) {
    for index in from * row_words..rows * row_words {
        assert_eq!(
            words[index],
            GARBAGE_WORDS[index % GARBAGE_WORDS.len()],
            "{what}: word {index} past the kept rows was written"
        );
    }
}

/// Every element of rows `from..rows` of `view` must still hold the garbage pattern.
fn assert_rows_untouched(what: &str, view: ViewLayout, data: &[f32], from: usize, rows: usize) {
    for n in from..rows {
        for j in 0..view.width {
            let index = n * view.stride + view.offset + j;
            assert_eq!(
                data[index].to_bits(),
                GARBAGE_WORDS[index % GARBAGE_WORDS.len()],
                "{what}: row {n} past the kept rows was written"
            );
        }
    }
}

/// Checks one MLP's forward and backward against the reference; returns the bits of every layer's
/// output, the input gradient and the gradient buffer, for comparing two kernel choices.
fn check_mlp(case: MlpCase<'_>) -> Vec<u32> {
    let MlpCase {
        ctx,
        pipelines,
        name,
        layout,
        params,
        rows,
        input_grad,
        output_view,
        seed,
        kept,
    } = case;
    let active = kept.unwrap_or(rows);
    let head_rows = kept.map(|_| HeadRows::new(ctx, rows as u32).unwrap());
    let dims = &layout.dims;
    let (in_dim, out_dim) = (layout.input_dim(), layout.output_dim());
    let mut rng = SplitMix64::new(seed);
    let input_layout = ViewLayout::padded(in_dim, 3, 2);
    let output_layout = ViewLayout::padded(out_dim, 5, 1);
    let output_grad_layout = ViewLayout::padded(out_dim, 1, 4);
    let input_grad_layout = ViewLayout::padded(in_dim, 2, 3);

    let input = random_values(&mut rng, input_layout.len(rows), 1.0);
    let output_grad = random_values(&mut rng, output_grad_layout.len(rows), 1.0);
    let mut grads = vec![GRAD_PRESET; params.len()];
    // Neighbours of the MLP's range get a different value so an overrun is visible either way.
    grads[..layout.range().start].fill(-1.5);
    grads[layout.range().end..].fill(-1.5);

    let params_buffer = trainer_params(ctx, params);
    let grads_buffer = storage_buffer_from(ctx, "grads", &grads).unwrap();
    let input_buffer = storage_buffer_from(ctx, "input", &input).unwrap();
    let output_grad_buffer = storage_buffer_from(ctx, "output grad", &output_grad).unwrap();
    let input_grad_buffer = storage_buffer_garbage::<f32>(ctx, "input grad", input_grad_layout.len(rows)).unwrap();
    let output_buffer = storage_buffer_garbage::<f32>(ctx, "output", output_layout.len(rows)).unwrap();

    let desc = MlpPassDesc {
        label: &name,
        layout,
        rows: rows as u32,
        params: &params_buffer,
        input: InputRows::Given(input_layout.view(&input_buffer)),
        output: output_view.then(|| output_layout.view(&output_buffer)),
        gradients: Some(MlpGradients {
            grads: grads_buffer.clone(),
            output_grad: output_grad_layout.view(&output_grad_buffer),
            input_grad: input_grad.then(|| InputRows::Given(input_grad_layout.view(&input_grad_buffer))),
            input_grad_columns: None,
        }),
        kept: head_rows.as_ref(),
    };
    let mlp = pollster::block_on(MlpPass::new(ctx, pipelines, desc)).unwrap();
    if let Some(head_rows) = &head_rows {
        let most = ctx.limits.max_compute_workgroups_per_dimension;
        let counts: Vec<u32> = head_rows
            .shapes()
            .into_iter()
            .flat_map(|shape| workgroup_counts(shape, active as u32, most))
            .collect();
        ctx.queue
            .write_buffer(&head_rows.dispatch_args, 0, bytemuck::cast_slice(&counts));
        ctx.queue
            .write_buffer(&head_rows.row_count, 0, bytemuck::bytes_of(&(active as u32)));
    }
    let families: Vec<KernelFamily> = mlp.layer_families().collect();
    let windows = mlp.weight_gradient_windows();
    if pipelines.family() == KernelFamily::Tiled {
        assert!(families.iter().all(|f| *f == KernelFamily::Tiled));
        assert!(windows.iter().all(|w| !w));
    } else {
        assert!(windows.iter().all(|w| *w), "{name}: every dW here fits uniform windows");
    }
    let layers = layout.layers.len();
    for k in 0..layers {
        fill_with_garbage(ctx, &mlp.layer_output(k).unwrap().buffer);
        if let Some(mask) = mlp.layer_relu_mask(k) {
            fill_with_garbage(ctx, &mask.buffer);
        }
        if let Some(buffer) = mlp.hidden_gradient(k) {
            fill_with_garbage(ctx, buffer);
        }
        if let Some(buffer) = mlp.layer_dz(k) {
            fill_with_garbage(ctx, buffer);
        }
    }
    if mlp.chains_input_gradients() {
        assert!(
            (1..layers).all(|k| mlp.hidden_gradient(k).is_none()),
            "{name}: a chain keeps dX in registers"
        );
    }
    assert!(mlp.hidden_gradient(0).is_none() && mlp.hidden_gradient(layers).is_none());

    let mut encoder = ctx.device.create_command_encoder(&Default::default());
    {
        let mut pass = encoder.begin_compute_pass(&Default::default());
        mlp.record_forward(&mut pass);
        mlp.record_backward(&mut pass).unwrap();
    }
    ctx.queue.submit([encoder.finish()]);

    // Every layer's output, as the GPU stored it (bf16 rows decoded into packed f32 rows).
    let mut gpu_outputs: Vec<Vec<f32>> = Vec::new();
    let mut formats = Vec::new();
    for k in 0..layers {
        let view = mlp.layer_output(k).unwrap();
        let words: Vec<u32> = read_buffer_blocking(ctx, &view.buffer).unwrap();
        formats.push(view.format);
        gpu_outputs.push(match view.format {
            RowFormat::F32 => words.iter().map(|&w| f32::from_bits(w)).collect(),
            RowFormat::Bf16 => {
                let width = dims[k + 1];
                let row_words = view.stride as usize / 2;
                if k + 1 == layers {
                    panic!("{name}: the MLP's output is stored as bf16");
                }
                assert_bf16_rows_untouched(&format!("{name} layer {k} output"), &words, row_words, active, rows);
                (0..rows)
                    .flat_map(|n| (0..width).map(move |o| (n, o)))
                    .map(|(n, o)| bf16::row_value(&words[n * row_words..(n + 1) * row_words], o))
                    .collect()
            }
        });
    }
    // Where a hidden layer stores its ReLU's bits, each is whether its output as stored is
    // positive.
    for k in 0..layers {
        let Some(mask) = mlp.layer_relu_mask(k) else {
            continue;
        };
        assert!(k + 1 < layers, "{name}: the output layer stores a ReLU mask");
        let words: Vec<u32> = read_buffer_blocking(ctx, &mask.buffer).unwrap();
        let width = dims[k + 1];
        for n in 0..active {
            for o in 0..width {
                let positive = gpu_outputs[k][n * width + o] > 0.0;
                assert_eq!(
                    mask.is_set(&words, n, o as u32),
                    positive,
                    "{name} row {n} layer {k} ReLU mask bit {o}"
                );
            }
        }
    }
    let bf16_hidden = formats[..layers - 1].iter().all(|f| *f == RowFormat::Bf16);
    assert!(
        bf16_hidden || formats.iter().all(|f| *f == RowFormat::F32),
        "{name}: hidden layers in different formats {formats:?}"
    );
    let output_views: Vec<ViewLayout> = (0..layers)
        .map(|k| match (k + 1 == layers, output_view) {
            (true, true) => output_layout,
            _ => ViewLayout {
                width: dims[k + 1],
                stride: dims[k + 1],
                offset: 0,
            },
        })
        .collect();
    if output_view {
        output_layout.assert_gaps_untouched(&format!("{name} output"), &gpu_outputs[layers - 1], rows);
    }
    for k in (0..layers).filter(|&k| formats[k] == RowFormat::F32) {
        let what = format!("{name} layer {k} output");
        assert_rows_untouched(&what, output_views[k], &gpu_outputs[k], active, rows);
    }

    let weights = to_f64(&params[layout.range()]);
    let abs_weights = abs(&weights);
    // The dZ the uniform-window weight gradients sum, as they stored it (bf16 rows).
    let gpu_dz: Vec<Option<Vec<u32>>> = (0..layers)
        .map(|k| mlp.layer_dz(k).map(|buffer| read_buffer_blocking(ctx, buffer).unwrap()))
        .collect();
    let mut worst_dz = 0.0f64;
    let mut worst_forward = 0.0f64;
    let mut weight_grad = vec![0.0f64; weights.len()];
    let mut weight_grad_magnitude = vec![0.0f64; weights.len()];
    let gpu_input_grad: Vec<f32> = if input_grad {
        read_buffer_blocking(ctx, &input_grad_buffer).unwrap()
    } else {
        Vec::new()
    };
    let mut worst_input_grad = 0.0f64;
    let mut worst_hidden_grad = 0.0f64;
    // Each hidden layer's dX as the GPU stored it, decoded into packed f32 rows: in its own
    // rows, or fused (bf16 hidden rows without a chain), masked by the ReLU of its input as the
    // layer below's dZ.
    let hidden_grads_bf16 = mlp.hidden_gradient_rows() == RowFormat::Bf16;
    let fused = hidden_grads_bf16 && (1..layers).all(|k| mlp.hidden_gradient(k).is_none());
    if fused {
        assert!(!mlp.chains_input_gradients() && gpu_dz.iter().all(Option::is_some));
    }
    let gpu_hidden_grads: Vec<Option<Vec<f32>>> = (0..layers)
        .map(|k| {
            if fused && k > 0 {
                let words = gpu_dz[k - 1].as_ref()?;
                let row_words = bf16::row_words(dims[k] as u32) as usize;
                return Some(
                    (0..active)
                        .flat_map(|n| (0..dims[k]).map(move |i| (n, i)))
                        .map(|(n, i)| bf16::row_value(&words[n * row_words..(n + 1) * row_words], i))
                        .collect(),
                );
            }
            let buffer = mlp.hidden_gradient(k)?;
            let words: Vec<u32> = read_buffer_blocking(ctx, buffer).unwrap();
            let width = dims[k];
            Some(if hidden_grads_bf16 {
                let row_words = width.div_ceil(2);
                (0..active)
                    .flat_map(|n| (0..width).map(move |i| (n, i)))
                    .map(|(n, i)| bf16::row_value(&words[n * row_words..(n + 1) * row_words], i))
                    .collect()
            } else {
                words[..active * width].iter().map(|&w| f32::from_bits(w)).collect()
            })
        })
        .collect();
    for n in 0..active {
        let x = to_f64(input_layout.row(&input, n));
        // Each layer is checked on its input as the GPU stored it, so the reference takes the
        // same ReLU branches even where a pre-activation is within rounding of 0, and a bf16
        // layer's rounding is checked where it happens.
        let mut activations = vec![x.clone()];
        activations.extend((0..layers).map(|k| to_f64(output_views[k].row(&gpu_outputs[k], n))));
        let mut offset = 0;
        for k in 0..layers {
            let (n_in, n_out) = (dims[k], dims[k + 1]);
            let layer_weights = &weights[offset..offset + n_in * n_out];
            offset += n_in * n_out;
            let hidden = k + 1 < layers;
            let relu = |v: f64| if hidden { v.max(0.0) } else { v };
            let reference: Vec<f64> = forward(&[n_in, n_out], layer_weights, &activations[k])
                .output()
                .iter()
                .map(|&v| relu(v))
                .collect();
            let magnitude = forward(
                &[n_in, n_out],
                &abs_weights[offset - n_in * n_out..offset],
                &abs(&activations[k]),
            );
            let rounding = if formats[k] == RowFormat::Bf16 {
                BF16_TOLERANCE
            } else {
                0.0
            };
            let allowed: Vec<f64> = reference
                .iter()
                .zip(magnitude.output())
                .map(|(r, m)| m + rounding / FORWARD_TOLERANCE * r.abs())
                .collect();
            let gpu = output_views[k].row(&gpu_outputs[k], n);
            let what = format!("{name} row {n} layer {k} output");
            let worst = assert_close(&what, gpu, &reference, &allowed, FORWARD_TOLERANCE);
            worst_forward = worst_forward.max(worst);
        }
        let trace = MlpTrace { activations };
        let abs_trace = MlpTrace {
            activations: trace.activations.iter().map(|a| abs(a)).collect(),
        };
        let dy = to_f64(output_grad_layout.row(&output_grad, n));
        // Layer by layer from the last: dZ_k is dY for the last layer, below it the dX of the
        // layer above as the GPU stored it (where it stores it; f32 registers in a chain: the
        // reference's) masked by the ReLU; each layer's dX is checked against W_kᵀ·dZ_k.
        let mut dz = vec![Vec::new(); layers];
        let mut dz_magnitude = vec![Vec::new(); layers];
        let (mut upstream, mut upstream_magnitude) = (dy.clone(), abs(&dy));
        let mut offset = weights.len();
        for k in (0..layers).rev() {
            let (n_in, n_out) = (dims[k], dims[k + 1]);
            offset -= n_in * n_out;
            let w = &weights[offset..offset + n_in * n_out];
            let abs_w = &abs_weights[offset..offset + n_in * n_out];
            let mask = |g: &[f64]| -> Vec<f64> {
                if k + 1 == layers {
                    return g.to_vec();
                }
                g.iter()
                    .zip(&trace.activations[k + 1])
                    .map(|(g, y)| if *y > 0.0 { *g } else { 0.0 })
                    .collect()
            };
            dz[k] = mask(&upstream);
            dz_magnitude[k] = mask(&upstream_magnitude);
            let single = |w: &[f64], x: &[f64], g: &[f64]| {
                let trace = MlpTrace {
                    activations: vec![x.to_vec(), vec![0.0; n_out]],
                };
                let mut unused = vec![0.0f64; w.len()];
                backward(&[n_in, n_out], w, &trace, g, &mut unused)
            };
            let dx = single(w, &trace.activations[k], &dz[k]);
            let dx_magnitude = single(abs_w, &abs_trace.activations[k], &dz_magnitude[k]);
            if k == 0 {
                if input_grad {
                    let what = format!("{name} row {n} input gradient");
                    let gpu = input_grad_layout.row(&gpu_input_grad, n);
                    let worst = assert_close(&what, gpu, &dx, &dx_magnitude, FORWARD_TOLERANCE);
                    worst_input_grad = worst_input_grad.max(worst);
                }
                break;
            }
            upstream = match &gpu_hidden_grads[k] {
                None => dx,
                Some(stored) => {
                    let gpu = &stored[n * n_in..(n + 1) * n_in];
                    // Fused, what is stored is dX masked by the ReLU of this layer's input.
                    let dx: Vec<f64> = if fused {
                        dx.iter()
                            .zip(&trace.activations[k])
                            .map(|(g, x)| if *x > 0.0 { *g } else { 0.0 })
                            .collect()
                    } else {
                        dx
                    };
                    let rounding = if hidden_grads_bf16 { BF16_TOLERANCE } else { 0.0 };
                    let allowed: Vec<f64> = dx
                        .iter()
                        .zip(&dx_magnitude)
                        .map(|(r, m)| m + rounding / FORWARD_TOLERANCE * r.abs())
                        .collect();
                    let what = format!("{name} row {n} layer {k} input gradient");
                    let worst = assert_close(&what, gpu, &dx, &allowed, FORWARD_TOLERANCE);
                    worst_hidden_grad = worst_hidden_grad.max(worst);
                    to_f64(gpu)
                }
            };
            upstream_magnitude = dx_magnitude;
        }
        // dW from each layer's dZ: the one above, or where the GPU stored it as bf16, the
        // stored values (checked here to be it within bf16 rounding).
        let mut offset = 0;
        for k in 0..layers {
            let summed: Vec<f64> = match &gpu_dz[k] {
                None => dz[k].clone(),
                Some(words) => {
                    let row_words = bf16::row_words(dims[k + 1] as u32) as usize;
                    let row = &words[n * row_words..(n + 1) * row_words];
                    let stored: Vec<f64> = (0..dims[k + 1]).map(|o| f64::from(bf16::row_value(row, o))).collect();
                    for (o, ((s, r), m)) in stored.iter().zip(&dz[k]).zip(&dz_magnitude[k]).enumerate() {
                        let error = (s - r).abs();
                        assert!(
                            error <= BF16_TOLERANCE * r.abs() + FORWARD_TOLERANCE * m + ABSOLUTE_TOLERANCE,
                            "{name} row {n} layer {k} stored dZ[{o}]: {s}, reference {r} (magnitude {m})"
                        );
                        worst_dz = worst_dz.max(error / (r.abs() + m).max(f64::MIN_POSITIVE));
                    }
                    stored
                }
            };
            let x = &trace.activations[k];
            let width = x.len();
            for (o, g) in summed.iter().enumerate() {
                for (i, xi) in x.iter().enumerate() {
                    weight_grad[offset + o * width + i] += g * xi;
                    weight_grad_magnitude[offset + o * width + i] += (g * xi).abs();
                }
            }
            offset += width * summed.len();
        }
    }
    if input_grad {
        input_grad_layout.assert_gaps_untouched(&format!("{name} input gradient"), &gpu_input_grad, rows);
        let what = format!("{name} input gradient");
        assert_rows_untouched(&what, input_grad_layout, &gpu_input_grad, active, rows);
        for (k, &width) in dims.iter().enumerate().take(layers).skip(1) {
            let Some(hidden) = mlp.hidden_gradient(k) else {
                continue;
            };
            let what = format!("{name} layer {k} input gradient");
            if hidden_grads_bf16 {
                let words: Vec<u32> = read_buffer_blocking(ctx, hidden).unwrap();
                assert_bf16_rows_untouched(&what, &words, width.div_ceil(2), active, rows);
            } else {
                let hidden: Vec<f32> = read_buffer_blocking(ctx, hidden).unwrap();
                assert_rows_untouched(&what, ViewLayout::padded(width, 0, 0), &hidden, active, rows);
            }
        }
    } else {
        let untouched: Vec<f32> = read_buffer_blocking(ctx, &input_grad_buffer).unwrap();
        assert!(
            untouched
                .iter()
                .enumerate()
                .all(|(i, v)| v.to_bits() == GARBAGE_WORDS[i % GARBAGE_WORDS.len()]),
            "{name}: input gradient written although none was asked for"
        );
    }

    let gpu_grads: Vec<f32> = read_buffer_blocking(ctx, &grads_buffer).unwrap();
    let range = layout.range();
    for (i, (g, preset)) in gpu_grads.iter().zip(&grads).enumerate() {
        if !range.contains(&i) {
            assert_eq!(
                g.to_bits(),
                preset.to_bits(),
                "{name}: gradient element {i} outside the MLP was written"
            );
        }
    }
    let expected: Vec<f64> = weight_grad.iter().map(|g| g + f64::from(GRAD_PRESET)).collect();
    let magnitude: Vec<f64> = weight_grad_magnitude
        .iter()
        .map(|m| m + f64::from(GRAD_PRESET))
        .collect();
    let worst_weight = assert_close(
        &format!("{name} weight gradient"),
        &gpu_grads[range],
        &expected,
        &magnitude,
        WEIGHT_GRAD_TOLERANCE,
    );
    let chained = mlp.chains_input_gradients();
    eprintln!(
        "{name} {dims:?} × {active} of {rows} rows, kernels {families:?}, hidden rows {formats:?}, input gradients chained {chained}: worst error / \
         magnitude: forward {worst_forward:.2e}, input gradient {worst_input_grad:.2e}, hidden input gradients {worst_hidden_grad:.2e}, stored dZ {worst_dz:.2e}, weight gradient {worst_weight:.2e}"
    );
    gpu_outputs
        .iter()
        .flatten()
        .chain(&gpu_input_grad)
        .chain(&gpu_grads)
        .map(|v| v.to_bits())
        .collect()
}

#[test]
fn every_mlp_matches_the_reference() {
    let Some(ctx) = gpu_for_tests("every_mlp_matches_the_reference") else {
        return;
    };
    check_every_mlp(&ctx, DenseKernels::new());
}

/// The kernels CPU devices run: every layer that fits a uniform binding uses them (the default
/// widths' 128 × 128 layers do not and run tiled, so the two families also meet in one MLP).
#[test]
fn every_mlp_matches_the_reference_with_uniform_weights() {
    let Some(ctx) = gpu_for_tests("every_mlp_matches_the_reference_with_uniform_weights") else {
        return;
    };
    // With and without the input-gradient chain (the device decides by default).
    for chain in [true, false] {
        let uniform = DenseKernels::with_family(KernelFamily::UniformWeights).with_input_gradient_chain(chain);
        check_every_mlp(&ctx, uniform.with_uniform_block_limit(64));
        // The narrower blocks other CPU devices get (SwiftShader: 16).
        for limit in [16, 4] {
            check_every_mlp(
                &ctx,
                DenseKernels::with_family(KernelFamily::UniformWeights)
                    .with_uniform_block_limit(limit)
                    .with_input_gradient_chain(chain),
            );
        }
    }
    // And they are used: a small MLP runs every layer on them.
    let cfg = FieldConfig::small();
    let layout = ParamLayout::new(&cfg);
    let params = trainer_params(&ctx, &layout.init(1));
    let rows = 64u32;
    let input = storage_buffer_zeroed::<f32>(&ctx, "input", rows as usize * layout.density.input_dim()).unwrap();
    let desc = MlpPassDesc {
        label: "density",
        layout: &layout.density,
        rows,
        params: &params,
        input: InputRows::Given(RowView::packed(&input, layout.density.input_dim() as u32)),
        output: None,
        gradients: None,
        kept: None,
    };
    let mut pipelines = DenseKernels::with_family(KernelFamily::UniformWeights);
    let mlp = pollster::block_on(MlpPass::new(&ctx, &mut pipelines, desc)).unwrap();
    assert!(mlp.layer_families().all(|f| f == KernelFamily::UniformWeights));
}

/// What the bit-for-bit comparisons of two ways of running the uniform-weight kernels run:
/// every config at the usual rows, `small` over many weight-gradient chunks, and on kept rows
/// (name, config, rows, rows kept).
fn bit_comparison_cases() -> Vec<(String, FieldConfig, usize, Option<usize>)> {
    let mut cases: Vec<(String, FieldConfig, usize, Option<usize>)> = configs()
        .into_iter()
        .map(|(name, cfg)| (name.to_string(), cfg, ROWS, None))
        .collect();
    cases.push(("small, 5003 rows".into(), FieldConfig::small(), 5003, None));
    cases.push((
        "small, 1500 of 3000 rows kept".into(),
        FieldConfig::small(),
        3000,
        Some(1500),
    ));
    cases
}

/// The page's uniform-weight kernels read the packed copies and dZ from storage (`PackedReads`):
/// the same sums in the same order as from uniform bindings, so every output and gradient is the
/// same bits, and both match the reference; at every config's widths, in blocks of 64 and of 16
/// (the page's), with many weight-gradient chunks (the storage kernel sums them all in one
/// dispatch) and on kept rows.
#[test]
fn packed_reads_from_storage_give_the_bits_of_uniform_reads() {
    let Some(ctx) = gpu_for_tests("packed_reads_from_storage_give_the_bits_of_uniform_reads") else {
        return;
    };
    let pipelines = |reads, limit| {
        DenseKernels::with_family(KernelFamily::UniformWeights)
            .with_uniform_block_limit(limit)
            .with_input_gradient_chain(false)
            .with_packed_reads(reads)
    };
    let cases = bit_comparison_cases();
    for limit in [64, 16] {
        for (config_name, cfg, rows, kept) in &cases {
            let layout = ParamLayout::new(cfg);
            let params = layout.init(23);
            for (index, (mlp_name, mlp)) in layout.mlps().into_iter().enumerate() {
                let run = |reads| {
                    let mut pipelines = pipelines(reads, limit);
                    check_mlp(MlpCase {
                        ctx: &ctx,
                        pipelines: &mut pipelines,
                        name: format!("{config_name} {mlp_name} ({reads:?} reads, blocks of {limit})"),
                        layout: mlp,
                        params: &params,
                        rows: *rows,
                        input_grad: mlp_name != "color",
                        output_view: index % 2 == 0,
                        seed: 300 + index as u64,
                        kept: *kept,
                    })
                };
                let uniform = run(PackedReads::Uniform);
                let storage = run(PackedReads::Storage);
                assert!(
                    uniform == storage,
                    "{config_name} {mlp_name}, blocks of {limit}: storage reads differ from uniform reads"
                );
            }
        }
    }
}

/// lavapipe's uniform-weight products write their reductions out step by step (UNROLL in
/// `shaders/_dense_uniform.wgsl`): the same sums in the same order as the loops, so every output
/// and gradient is the same bits, and both match the reference; at every config's widths, in
/// blocks of 64 and of 16 (a layer of one or two blocks is written out, two as a pipeline per
/// block, `FIXED_BLOCK`; one of more blocks keeps the loop), with many rows and on kept rows
/// (rows past the last compute and store nothing), with and without the input-gradient chain
/// (which is always written out, one dispatch per block of its first layer's dX).
#[test]
fn unrolled_reductions_give_the_bits_of_loops() {
    let Some(ctx) = gpu_for_tests("unrolled_reductions_give_the_bits_of_loops") else {
        return;
    };
    let cases = bit_comparison_cases();
    for (limit, chain) in [(64, false), (16, false), (64, true)] {
        for (config_name, cfg, rows, kept) in &cases {
            let layout = ParamLayout::new(cfg);
            let params = layout.init(29);
            for (index, (mlp_name, mlp)) in layout.mlps().into_iter().enumerate() {
                let run = |unrolled| {
                    let mut pipelines = DenseKernels::with_family(KernelFamily::UniformWeights)
                        .with_uniform_block_limit(limit)
                        .with_input_gradient_chain(chain)
                        .with_unrolled_reductions(unrolled);
                    check_mlp(MlpCase {
                        ctx: &ctx,
                        pipelines: &mut pipelines,
                        name: format!(
                            "{config_name} {mlp_name} (unrolled {unrolled}, blocks of {limit}, chain {chain})"
                        ),
                        layout: mlp,
                        params: &params,
                        rows: *rows,
                        input_grad: mlp_name != "color",
                        output_view: index % 2 == 1,
                        seed: 500 + index as u64,
                        kept: *kept,
                    })
                };
                let unrolled = run(true);
                let looped = run(false);
                assert!(
                    unrolled == looped,
                    "{config_name} {mlp_name}, blocks of {limit}, chain {chain}: unrolled reductions differ from loops"
                );
            }
        }
    }
}

/// Which MLPs run their input gradients as one chain: those of 2 or 3 layers on the uniform
/// family whose hidden widths fit one block (the checks above run both kinds).
#[test]
fn uniform_mlps_chain_their_input_gradients_where_they_fit() {
    let Some(ctx) = gpu_for_tests("uniform_mlps_chain_their_input_gradients_where_they_fit") else {
        return;
    };
    let configs = configs();
    let config = |name: &str| configs.iter().find(|(n, _)| *n == name).unwrap().1.clone();
    let uniform = || DenseKernels::with_family(KernelFamily::UniformWeights).with_input_gradient_chain(true);
    let cases = [
        (
            "small",
            uniform().with_uniform_block_limit(64),
            [true, true, true, true],
        ),
        ("small", uniform().with_uniform_block_limit(16), [false; 4]),
        ("small", DenseKernels::new(), [false; 4]),
        ("widths 16", uniform().with_uniform_block_limit(16), [true; 4]),
        // 128-wide density and colour layers; the feature MLP's copies span more than one
        // window; the semantic head's one hidden layer of 64 fits.
        (
            "default widths",
            uniform().with_uniform_block_limit(64),
            [false, false, false, true],
        ),
        (
            "small, density 4 hidden layers",
            uniform().with_uniform_block_limit(64),
            [false, true, true, true],
        ),
        (
            "small",
            uniform().with_uniform_block_limit(64).with_input_gradient_chain(false),
            [false; 4],
        ),
    ];
    let mut fused_mlps = 0;
    for (name, mut pipelines, expected) in cases {
        let layout = ParamLayout::new(&config(name));
        let params = trainer_params(&ctx, &layout.init(3));
        let rows = 100u32;
        for ((mlp_name, mlp), chains) in layout.mlps().into_iter().zip(expected) {
            let (in_dim, out_dim) = (mlp.input_dim() as u32, mlp.output_dim() as u32);
            let buffer = |width: u32| storage_buffer_zeroed::<f32>(&ctx, "rows", (rows * width) as usize).unwrap();
            let (input, output_grad, input_grad) = (buffer(in_dim), buffer(out_dim), buffer(in_dim));
            let desc = MlpPassDesc {
                label: mlp_name,
                layout: mlp,
                rows,
                params: &params,
                input: InputRows::Given(RowView::packed(&input, in_dim)),
                output: None,
                gradients: Some(MlpGradients {
                    grads: storage_buffer_zeroed::<f32>(&ctx, "grads", layout.total).unwrap(),
                    output_grad: RowView::packed(&output_grad, out_dim),
                    input_grad: (mlp_name != "color").then(|| InputRows::Given(RowView::packed(&input_grad, in_dim))),
                    input_grad_columns: None,
                }),
                kept: None,
            };
            let pass = pollster::block_on(MlpPass::new(&ctx, &mut pipelines, desc)).unwrap();
            assert_eq!(pass.chains_input_gradients(), chains, "{name} {mlp_name}");
            // Unchained with bf16 hidden rows, each input gradient stores the layer below's dZ
            // in its windows: no rows of its own.
            let layers = pass.layers().count();
            let fused = !chains && pass.hidden_rows() == RowFormat::Bf16;
            assert_eq!(
                (1..layers).all(|k| pass.hidden_gradient(k).is_none()),
                chains || fused,
                "{name} {mlp_name}: hidden gradient rows"
            );
            if fused {
                fused_mlps += 1;
                assert!((0..layers).all(|k| pass.layer_dz(k).is_some()), "{name} {mlp_name}");
                assert!(
                    (0..layers).all(|k| pass.layer_relu_mask(k).is_some() == (k + 1 < layers)),
                    "{name} {mlp_name}: the hidden layers store their ReLU's bits"
                );
                assert_eq!(pass.hidden_gradient_rows(), RowFormat::Bf16, "{name} {mlp_name}");
            }
        }
    }
    assert!(fused_mlps >= 4, "only {fused_mlps} MLPs fused");
}

fn check_every_mlp(ctx: &GpuContext, mut pipelines: DenseKernels) {
    let ctx = ctx.clone();
    for (config_name, cfg) in configs() {
        cfg.validate().unwrap();
        let layout = ParamLayout::new(&cfg);
        let params = layout.init(17);
        for (index, (mlp_name, mlp)) in layout.mlps().into_iter().enumerate() {
            check_mlp(MlpCase {
                ctx: &ctx,
                pipelines: &mut pipelines,
                name: format!("{config_name} {mlp_name}"),
                layout: mlp,
                params: &params,
                rows: ROWS,
                // Colour input is [SH | geometry]: SH needs no gradient.
                input_grad: mlp_name != "color",
                output_view: index % 2 == 1,
                seed: 100 + index as u64,
                kept: None,
            });
        }
    }
}

#[test]
fn tiny_and_multi_chunk_row_counts_match_the_reference() {
    let Some(ctx) = gpu_for_tests("tiny_and_multi_chunk_row_counts_match_the_reference") else {
        return;
    };
    let cfg = FieldConfig::small();
    let layout = ParamLayout::new(&cfg);
    let params = layout.init(5);
    for family in [KernelFamily::Tiled, KernelFamily::UniformWeights] {
        let mut pipelines = DenseKernels::with_family(family);
        // 1 row; fewer rows than a tile; many weight-gradient chunks with a ragged last one.
        for (rows, seed) in [(1, 1), (61, 2), (5003, 3)] {
            check_mlp(MlpCase {
                ctx: &ctx,
                pipelines: &mut pipelines,
                name: format!("small density ({family:?}), {rows} rows"),
                layout: &layout.density,
                params: &params,
                rows,
                input_grad: true,
                output_view: rows > 1,
                seed,
                kept: None,
            });
        }
    }
}

/// The heads' case: the rows present are fewer than the buffers hold, their count read from a
/// buffer and every row-parallel kernel launched indirectly. Rows past the count keep their
/// garbage, and the weight gradient sums the rows present alone; none, one, and all of them.
#[test]
fn kept_row_counts_match_the_reference() {
    let Some(ctx) = gpu_for_tests("kept_row_counts_match_the_reference") else {
        return;
    };
    let cfg = FieldConfig::small();
    let layout = ParamLayout::new(&cfg);
    let params = layout.init(7);
    for family in [KernelFamily::Tiled, KernelFamily::UniformWeights] {
        let mut pipelines = DenseKernels::with_family(family).with_input_gradient_chain(true);
        for (kept, seed) in [(0, 11), (1, 12), (1500, 13), (3000, 14)] {
            for (mlp_name, mlp, input_grad) in [("colour", &layout.color, false), ("semantic", &layout.semantic, true)]
            {
                check_mlp(MlpCase {
                    ctx: &ctx,
                    pipelines: &mut pipelines,
                    name: format!("small {mlp_name} ({family:?}), {kept} of 3000 rows kept"),
                    layout: mlp,
                    params: &params,
                    rows: 3000,
                    input_grad,
                    output_view: true,
                    seed,
                    kept: Some(kept),
                });
            }
        }
    }
}

#[test]
fn forward_only_pass_refuses_backward_and_bad_views_are_errors() {
    let Some(ctx) = gpu_for_tests("forward_only_pass_refuses_backward_and_bad_views_are_errors") else {
        return;
    };
    let mut pipelines = DenseKernels::new();
    let layout = ParamLayout::new(&FieldConfig::small());
    let params = storage_buffer_from(&ctx, "params", &layout.init(1)).unwrap();
    let rows = 10;
    let input = storage_buffer_garbage::<f32>(&ctx, "input", rows * layout.density.input_dim()).unwrap();
    let desc = |input: RowView| MlpPassDesc {
        label: "density",
        layout: &layout.density,
        rows: rows as u32,
        params: &params,
        input: InputRows::Given(input),
        output: None,
        gradients: None,
        kept: None,
    };
    let width = layout.density.input_dim() as u32;
    let mlp = pollster::block_on(MlpPass::new(&ctx, &mut pipelines, desc(RowView::packed(&input, width)))).unwrap();
    let mut encoder = ctx.device.create_command_encoder(&Default::default());
    let mut pass = encoder.begin_compute_pass(&Default::default());
    mlp.record_forward(&mut pass);
    assert!(mlp.record_backward(&mut pass).is_err());
    drop(pass);
    // One row too many for the buffer, and columns spilling past the stride.
    let too_long = RowView::new(&input, width + 1, 0);
    assert!(pollster::block_on(MlpPass::new(&ctx, &mut pipelines, desc(too_long))).is_err());
    let spilling = RowView::new(&input, width, 1);
    assert!(pollster::block_on(MlpPass::new(&ctx, &mut pipelines, desc(spilling))).is_err());
    // bf16 rows: an odd offset is refused, and so is any bf16 row for the tiled kernels.
    let odd = RowView {
        offset: 1,
        stride: width + 2,
        ..RowView::packed_bf16(&input, width)
    };
    let error = pollster::block_on(MlpPass::new(&ctx, &mut pipelines, desc(odd)))
        .err()
        .unwrap();
    assert!(error.to_string().contains("even stride and offset"), "{error}");
    let bf16_input = RowView::packed_bf16(&input, width);
    let error = pollster::block_on(MlpPass::new(&ctx, &mut pipelines, desc(bf16_input.clone())))
        .err()
        .unwrap();
    assert!(
        error.to_string().contains("bf16 rows need the packed-weight kernels"),
        "{error}"
    );
    // The packed-weight kernels take it, and store the hidden outputs as bf16 unless told not to.
    let mut uniform = DenseKernels::with_family(KernelFamily::UniformWeights);
    let mlp = pollster::block_on(MlpPass::new(&ctx, &mut uniform, desc(bf16_input))).unwrap();
    assert_eq!(mlp.hidden_rows(), RowFormat::Bf16);
    let mut f32_rows = DenseKernels::with_family(KernelFamily::UniformWeights).with_hidden_rows(RowFormat::F32);
    let mlp = pollster::block_on(MlpPass::new(&ctx, &mut f32_rows, desc(RowView::packed(&input, width)))).unwrap();
    assert_eq!(mlp.hidden_rows(), RowFormat::F32);
}

/// An MLP that owns its input rows (`InputRows::Owned`) stores them as its hidden rows, and its
/// input gradient too (written by a chain or a kernel per layer); the caller reaches both
/// through `input` and `input_gradient`.
#[test]
fn owned_input_rows_take_the_hidden_rows_format() {
    let Some(ctx) = gpu_for_tests("owned_input_rows_take_the_hidden_rows_format") else {
        return;
    };
    let layout = ParamLayout::new(&FieldConfig::small());
    let params = storage_buffer_from(&ctx, "params", &layout.init(1)).unwrap();
    let grads = storage_buffer_zeroed::<f32>(&ctx, "grads", layout.total).unwrap();
    let rows = 300u32;
    let mlp = &layout.semantic;
    let (in_dim, out_dim) = (mlp.input_dim() as u32, mlp.output_dim() as u32);
    let output_grad = storage_buffer_garbage::<f32>(&ctx, "output grad", (rows * out_dim) as usize).unwrap();
    let build = |pipelines: &mut DenseKernels| {
        let desc = MlpPassDesc {
            label: "semantic",
            layout: mlp,
            rows,
            params: &params,
            input: InputRows::Owned,
            output: None,
            gradients: Some(MlpGradients {
                grads: grads.clone(),
                output_grad: RowView::packed(&output_grad, out_dim),
                input_grad: Some(InputRows::Owned),
                input_grad_columns: None,
            }),
            kept: None,
        };
        pollster::block_on(MlpPass::new(&ctx, pipelines, desc)).unwrap()
    };
    let check = |pass: &MlpPass, input: RowFormat, gradient: RowFormat| {
        assert_eq!(pass.input().format, input);
        pass.input().check("input", rows, in_dim).unwrap();
        let grad = pass.input_gradient().expect("an input gradient");
        assert_eq!(grad.format, gradient);
        grad.check("input gradient", rows, in_dim).unwrap();
    };
    let uniform = build(&mut DenseKernels::with_family(KernelFamily::UniformWeights));
    check(&uniform, RowFormat::Bf16, RowFormat::Bf16);
    let f32_rows = build(&mut DenseKernels::with_family(KernelFamily::UniformWeights).with_hidden_rows(RowFormat::F32));
    check(&f32_rows, RowFormat::F32, RowFormat::F32);
    let tiled = build(&mut DenseKernels::with_family(KernelFamily::Tiled));
    check(&tiled, RowFormat::F32, RowFormat::F32);
}

/// The input gradient an MLP stores in its own bf16 rows is the f32 one rounded, value for value
/// (the padding of the odd-width colour input's rows 0), written by the chain and by the
/// first layer's own kernel: the same MLP run on the same (bf16-exact) input with the caller's
/// f32 rows is the reference.
#[test]
fn owned_bf16_input_gradient_is_the_f32_one_rounded() {
    let Some(ctx) = gpu_for_tests("owned_bf16_input_gradient_is_the_f32_one_rounded") else {
        return;
    };
    let layout = ParamLayout::new(&FieldConfig::small());
    let params = trainer_params(&ctx, &layout.init(3));
    let mlp = &layout.color;
    let (in_dim, out_dim) = (mlp.input_dim(), mlp.output_dim());
    assert_eq!(in_dim % 2, 1, "an odd width, so rows end in padding");
    let rows = 300usize;
    let mut rng = SplitMix64::new(5);
    let input: Vec<f32> = random_values(&mut rng, rows * in_dim, 1.0)
        .into_iter()
        .map(bf16::round)
        .collect();
    let output_grad = storage_buffer_from(&ctx, "output grad", &random_values(&mut rng, rows * out_dim, 1.0)).unwrap();
    let input_buffer = storage_buffer_from(&ctx, "input", &input).unwrap();
    let f32_grad = storage_buffer_garbage::<f32>(&ctx, "input grad", rows * in_dim).unwrap();
    for chain in [true, false] {
        let mut pipelines = DenseKernels::with_family(KernelFamily::UniformWeights).with_input_gradient_chain(chain);
        let build = |pipelines: &mut DenseKernels, input: InputRows, input_grad: InputRows| {
            let grads = storage_buffer_zeroed::<f32>(&ctx, "grads", layout.total).unwrap();
            let desc = MlpPassDesc {
                label: "colour",
                layout: mlp,
                rows: rows as u32,
                params: &params,
                input,
                output: None,
                gradients: Some(MlpGradients {
                    grads,
                    output_grad: RowView::packed(&output_grad, out_dim as u32),
                    input_grad: Some(input_grad),
                    input_grad_columns: None,
                }),
                kept: None,
            };
            pollster::block_on(MlpPass::new(&ctx, pipelines, desc)).unwrap()
        };
        let given = build(
            &mut pipelines,
            InputRows::Given(RowView::packed(&input_buffer, in_dim as u32)),
            InputRows::Given(RowView::packed(&f32_grad, in_dim as u32)),
        );
        let owned = build(&mut pipelines, InputRows::Owned, InputRows::Owned);
        assert_eq!(owned.chains_input_gradients(), chain);
        let stride = owned.input().stride as usize;
        let words: Vec<u32> = input
            .chunks(in_dim)
            .flat_map(|row| {
                let mut padded = row.to_vec();
                padded.resize(stride, 0.0);
                padded.chunks(2).map(|p| bf16::pair(p[0], p[1])).collect::<Vec<_>>()
            })
            .collect();
        ctx.queue
            .write_buffer(&owned.input().buffer, 0, bytemuck::cast_slice(&words));
        let grad_rows = owned.input_gradient().unwrap();
        fill_with_garbage(&ctx, &grad_rows.buffer);
        fill_with_garbage(&ctx, &f32_grad);
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        {
            let mut pass = encoder.begin_compute_pass(&Default::default());
            for mlp in [&given, &owned] {
                mlp.record_forward(&mut pass);
                mlp.record_backward(&mut pass).unwrap();
            }
        }
        ctx.queue.submit([encoder.finish()]);
        let want: Vec<f32> = read_buffer_blocking(&ctx, &f32_grad).unwrap();
        let got: Vec<u32> = read_buffer_blocking(&ctx, &grad_rows.buffer).unwrap();
        for n in 0..rows {
            let row = &got[n * stride / 2..(n + 1) * stride / 2];
            for j in 0..in_dim {
                let expected = bf16::round(want[n * in_dim + j]);
                assert_eq!(bf16::row_value(row, j), expected, "chain {chain}: row {n}, value {j}");
            }
            assert_eq!(bf16::row_value(row, in_dim), 0.0, "chain {chain}: row {n}'s padding");
        }
    }
}

/// An MLP asked for some columns of its input gradient (the trainer's colour MLP: g's, not the
/// SH's) writes those as it writes them when asked for all, bit for bit, and leaves the others
/// as they were; in f32 rows and in bf16 rows (whose range starts at an even column), run per
/// layer as the trainer's 128-wide MLPs are.
#[test]
fn input_gradient_columns_outside_the_range_are_left_alone() {
    let Some(ctx) = gpu_for_tests("input_gradient_columns_outside_the_range_are_left_alone") else {
        return;
    };
    let layout = ParamLayout::new(&FieldConfig::small());
    let params = trainer_params(&ctx, &layout.init(9));
    let mlp = &layout.color;
    let (in_dim, out_dim) = (mlp.input_dim(), mlp.output_dim());
    let rows = 200usize;
    let mut rng = SplitMix64::new(11);
    let input = storage_buffer_from(&ctx, "input", &random_values(&mut rng, rows * in_dim, 1.0)).unwrap();
    let output_grad = storage_buffer_from(&ctx, "output grad", &random_values(&mut rng, rows * out_dim, 1.0)).unwrap();
    let width = in_dim as u32;
    for (format, columns) in [
        (RowFormat::F32, 15..width),
        (RowFormat::Bf16, 16..width),
        (RowFormat::F32, 0..3),
    ] {
        let mut pipelines = DenseKernels::with_family(KernelFamily::UniformWeights).with_input_gradient_chain(false);
        let words = RowView::words(format, rows as u32, width) as usize;
        let mut run = |columns: Option<std::ops::Range<u32>>| -> Vec<u32> {
            let grad = storage_buffer_garbage::<f32>(&ctx, "input grad", words).unwrap();
            let desc = MlpPassDesc {
                label: "colour",
                layout: mlp,
                rows: rows as u32,
                params: &params,
                input: InputRows::Given(RowView::packed(&input, width)),
                output: None,
                gradients: Some(MlpGradients {
                    grads: storage_buffer_zeroed::<f32>(&ctx, "grads", layout.total).unwrap(),
                    output_grad: RowView::packed(&output_grad, out_dim as u32),
                    input_grad: Some(InputRows::Given(RowView::packed_as(&grad, width, format))),
                    input_grad_columns: columns,
                }),
                kept: None,
            };
            let pass = pollster::block_on(MlpPass::new(&ctx, &mut pipelines, desc)).unwrap();
            assert!(!pass.chains_input_gradients());
            let mut encoder = ctx.device.create_command_encoder(&Default::default());
            {
                let mut compute = encoder.begin_compute_pass(&Default::default());
                pass.record_forward(&mut compute);
                pass.record_backward(&mut compute).unwrap();
            }
            ctx.queue.submit([encoder.finish()]);
            read_buffer_blocking(&ctx, &grad).unwrap()
        };
        let all = run(None);
        let some = run(Some(columns.clone()));
        let stride = RowView::packed_as(&input, width, format).stride as usize;
        for n in 0..rows {
            for j in 0..width as usize {
                let (word, shift) = match format {
                    RowFormat::F32 => (n * stride + j, 0),
                    RowFormat::Bf16 => ((n * stride + j) / 2, 16 * (j % 2)),
                };
                let value = |words: &[u32]| match format {
                    RowFormat::F32 => words[word],
                    RowFormat::Bf16 => (words[word] >> shift) & 0xffff,
                };
                if columns.contains(&(j as u32)) {
                    assert_eq!(value(&some), value(&all), "{format:?} {columns:?}: row {n} column {j}");
                } else {
                    let garbage = GARBAGE_WORDS[word % GARBAGE_WORDS.len()];
                    let untouched = match format {
                        RowFormat::F32 => some[word] == garbage,
                        // A bf16 pair is written whole: past an odd range's end its second
                        // value is the column after, which the caller does not read.
                        RowFormat::Bf16 => some[word] == garbage || j as u32 == columns.end,
                    };
                    assert!(untouched, "{format:?} {columns:?}: row {n} column {j} was written");
                }
            }
        }
    }
}

/// Measurement, not a check: GFLOP/s of the default density MLP's forward and backward at
/// N = 262144 rows (4096 rays × 64 samples) next to the plain matmul's, in the same run:
/// `cargo test --release --test gpu_field_dense -- --ignored --nocapture`. `DENSE_BENCH_ROWS`,
/// `DENSE_BENCH_PRESET` and `DENSE_FAMILY=uniform` change the rows, the widths and the kernels;
/// `DENSE_BENCH_MLP` (semantic, feature, colour), `DENSE_BENCH_CLASSES` and
/// `DENSE_BENCH_REPEATS` the MLP, the semantic head's classes and the timed repeats.
#[test]
#[ignore = "measurement; run explicitly in release mode"]
fn density_mlp_throughput_report() {
    use scribblefield::gpu::matmul_bench::matmul_gflops;
    use scribblefield::gpu::timing::{PassTimer, Stopwatch};

    let Some(ctx) = gpu_for_tests("density_mlp_throughput_report") else {
        return;
    };
    let rows: usize = std::env::var("DENSE_BENCH_ROWS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(262_144);
    let iterations: u32 = std::env::var("DENSE_BENCH_REPEATS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(3);
    // DENSE_BENCH_PRESET=small measures the widths the page and the CPU devices train.
    let cfg = match std::env::var("DENSE_BENCH_PRESET") {
        Ok(name) => scribblefield::field::Preset::parse(&name)
            .unwrap_or_else(|| panic!("DENSE_BENCH_PRESET={name}: not a preset"))
            .config(),
        Err(_) => FieldConfig::default(),
    };
    let mut cfg = cfg;
    if let Some(classes) = std::env::var("DENSE_BENCH_CLASSES").ok().and_then(|v| v.parse().ok()) {
        cfg.num_classes = classes;
    }
    let layout = ParamLayout::new(&cfg);
    // DENSE_BENCH_MLP=semantic (feature, colour) measures another of the field's MLPs.
    let mlp_layout = match std::env::var("DENSE_BENCH_MLP").as_deref() {
        Ok("semantic") => &layout.semantic,
        Ok("feature") => &layout.feature,
        Ok("colour") => &layout.color,
        _ => &layout.density,
    };
    let mut rng = SplitMix64::new(9);
    let params = trainer_params(&ctx, &layout.init(1));
    let grads = storage_buffer_from(&ctx, "grads", &vec![0.0f32; layout.total]).unwrap();
    let (in_dim, out_dim) = (mlp_layout.input_dim(), mlp_layout.output_dim());
    let input = storage_buffer_from(&ctx, "input", &random_values(&mut rng, rows * in_dim, 1.0)).unwrap();
    let output_grad = storage_buffer_from(&ctx, "output grad", &random_values(&mut rng, rows * out_dim, 1.0)).unwrap();
    let input_grad = storage_buffer_garbage::<f32>(&ctx, "input grad", rows * in_dim).unwrap();
    // DENSE_FAMILY=uniform measures the CPU-device kernels.
    let family = match std::env::var("DENSE_FAMILY").as_deref() {
        Ok("uniform") => KernelFamily::UniformWeights,
        _ => KernelFamily::Tiled,
    };
    let mut pipelines = DenseKernels::with_family(family);
    let desc = MlpPassDesc {
        label: "density",
        layout: mlp_layout,
        rows: rows as u32,
        params: &params,
        input: InputRows::Given(RowView::packed(&input, in_dim as u32)),
        output: None,
        gradients: Some(MlpGradients {
            grads: grads.clone(),
            output_grad: RowView::packed(&output_grad, out_dim as u32),
            input_grad: Some(InputRows::Given(RowView::packed(&input_grad, in_dim as u32))),
            input_grad_columns: None,
        }),
        kept: None,
    };
    let mlp = pollster::block_on(MlpPass::new(&ctx, &mut pipelines, desc)).unwrap();
    let weights: f64 = mlp_layout.layers.iter().map(|r| r.len() as f64).sum();
    let forward_flops = 2.0 * rows as f64 * weights;
    // dX of every layer (the input needs it: hash-grid gradients) and dW of every layer.
    let backward_flops = 2.0 * forward_flops;

    let run = |backward: bool, repeats: u32| -> f64 {
        let mut timer = PassTimer::new(&ctx, repeats);
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        for _ in 0..repeats {
            let timestamp_writes = timer.as_mut().and_then(|t| t.timestamp_writes("mlp"));
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: None,
                timestamp_writes,
            });
            if backward {
                mlp.record_backward(&mut pass).unwrap();
            } else {
                mlp.record_forward(&mut pass);
            }
        }
        if let Some(timer) = &timer {
            timer.resolve(&mut encoder);
        }
        let stopwatch = Stopwatch::start();
        ctx.queue.submit([encoder.finish()]);
        ctx.wait_idle().unwrap();
        let wall = stopwatch.elapsed_seconds();
        match timer.as_mut() {
            Some(timer) => {
                let times = pollster::block_on(timer.read(&ctx).times()).unwrap();
                let gpu: f64 = times.iter().map(|t| t.seconds).sum();
                if gpu > 0.0 { gpu } else { wall }
            }
            None => wall,
        }
    };
    // Warm-up: first touch of the buffers and lazy compilation stay out of the figures.
    run(false, 1);
    run(true, 1);
    let forward_seconds = run(false, iterations) / f64::from(iterations);
    let backward_seconds = run(true, iterations) / f64::from(iterations);
    let matmul = pollster::block_on(matmul_gflops(&ctx, 512, 5)).unwrap();
    println!("adapter: {} (timestamps: {})", ctx.describe(), ctx.has_timestamps);
    println!(
        "MLP {:?}, N = {rows} rows, kernels {:?}",
        mlp_layout.dims,
        mlp.layer_families().collect::<Vec<_>>()
    );
    println!(
        "forward:  {:.3} s, {:.2} GFLOP/s ({:.2} GFLOP)",
        forward_seconds,
        forward_flops / forward_seconds / 1e9,
        forward_flops / 1e9
    );
    println!(
        "backward: {:.3} s, {:.2} GFLOP/s ({:.2} GFLOP: dX and dW)",
        backward_seconds,
        backward_flops / backward_seconds / 1e9,
        backward_flops / 1e9
    );
    println!("plain matmul n=512: {matmul:.2} GFLOP/s");
}
