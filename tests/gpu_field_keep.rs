//! `keep.wgsl` against its CPU twin (`reference::render::kept_samples`, then packing in sample
//! order): which samples reach the heads, their packed rows, each sample's slot, the head
//! kernels' workgroup counts, the gathered head inputs and the tally, all over garbage-filled
//! outputs. The batch holds a ray where nothing is kept, one where everything is, rays that
//! miss the box, and random ones.
//!
//! Run in release: `cargo test --release --test gpu_field_keep`.
use scribblefield::field::gpu::dense::{RowFormat, RowView};
use scribblefield::field::gpu::keep::{HeadRows, KeepBuffers, KeepPass, KeepShape, NOT_KEPT, workgroup_counts};
use scribblefield::field::gpu::rays::{RAY_HITS_BOX, StepUniforms, TARGET_FLAGS, TARGET_HEADER_WORDS};
use scribblefield::field::gpu::stage::Stage;
use scribblefield::field::reference::render::{self, kept_samples};
use scribblefield::field::{FieldConfig, bf16};
use scribblefield::gpu::GpuContext;
use scribblefield::gpu::buffers::{
    GARBAGE_WORDS, fill_with_garbage, read_buffer_blocking, storage_buffer_from, storage_buffer_garbage,
    uniform_buffer_from,
};
use scribblefield::gpu::test_support::gpu_for_tests;
use scribblefield::rng::SplitMix64;

const GEOMETRY: usize = 5;
const SH: usize = 16;
const FEATURE: usize = 3;

struct Batch {
    cfg: FieldConfig,
    /// [h₀ | g] per sample.
    density: Vec<f32>,
    /// (δ, z) per sample.
    intervals: Vec<[f32; 2]>,
    targets: Vec<u32>,
    sh: Vec<f32>,
}

impl Batch {
    fn samples(&self) -> usize {
        self.cfg.samples_per_ray()
    }

    fn random(rays: u32, threshold: f32, seed: u64) -> Batch {
        let cfg = FieldConfig {
            samples_coarse: 5,
            samples_fine: 7,
            batch_rays: rays,
            feature_dim: FEATURE as u32,
            geometry_dim: GEOMETRY as u32,
            head_weight_threshold: threshold,
            ..FieldConfig::small()
        };
        let mut rng = SplitMix64::new(seed);
        let s = cfg.samples_per_ray();
        let n = rays as usize * s;
        let mut density = Vec::with_capacity(n * (1 + GEOMETRY));
        let mut intervals = Vec::with_capacity(n);
        for i in 0..n {
            let (ray, _) = (i / s, i % s);
            let h0 = match ray {
                // Empty space all along: every weight about exp(-15)·δ, nothing kept but the
                // opaque last sample.
                0 => -40.0,
                // Thin fog: every sample keeps a weight of about 0.03.
                1 => 0.0,
                _ => rng.uniform(-6.0, 4.0),
            };
            density.push(h0 as f32);
            density.extend((0..GEOMETRY).map(|_| rng.uniform(-3.0, 3.0) as f32));
            // Rays 0 and 2 end in an opaque sample (`LastSample::Opaque`): ray 0
            // keeps only that one.
            let delta = if (ray == 0 || ray == 2) && i % s == s - 1 {
                f64::from(render::OPAQUE_INTERVAL)
            } else if ray == 1 {
                0.03
            } else {
                rng.uniform(0.0, 0.3)
            };
            intervals.push([delta as f32, rng.uniform(0.1, 3.0) as f32]);
        }
        let stride = TARGET_HEADER_WORDS + FEATURE;
        let mut targets = vec![0u32; rays as usize * stride];
        for ray in 0..rays as usize {
            let misses = ray > 1 && rng.next_f64() < 0.15;
            targets[ray * stride + TARGET_FLAGS] = if misses { 0 } else { RAY_HITS_BOX };
        }
        let sh = (0..n * SH).map(|_| rng.uniform(-1.0, 1.0) as f32).collect();
        Batch {
            cfg,
            density,
            intervals,
            targets,
            sh,
        }
    }

    /// The CPU twin: each sample's slot and the packed rows' samples.
    fn expected(&self) -> (Vec<u32>, Vec<u32>) {
        let s = self.samples();
        let stride = TARGET_HEADER_WORDS + FEATURE;
        let threshold = self.cfg.head_weight_threshold;
        let mut slot = Vec::new();
        let mut rows = Vec::new();
        for ray in 0..self.cfg.batch_rays as usize {
            let hits = self.targets[ray * stride + TARGET_FLAGS] & RAY_HITS_BOX != 0;
            let h0: Vec<f32> = (0..s).map(|i| self.density[(ray * s + i) * (1 + GEOMETRY)]).collect();
            let deltas: Vec<f32> = (0..s).map(|i| self.intervals[ray * s + i][0]).collect();
            let kept = if threshold > 0.0 && !hits {
                vec![false; s]
            } else {
                kept_samples(&h0, &deltas, threshold)
            };
            for (i, kept) in kept.into_iter().enumerate() {
                if kept {
                    slot.push(rows.len() as u32);
                    rows.push((ray * s + i) as u32);
                } else {
                    slot.push(NOT_KEPT);
                }
            }
        }
        (slot, rows)
    }
}

fn is_garbage(index: usize, value: u32) -> bool {
    value == GARBAGE_WORDS[index % GARBAGE_WORDS.len()]
}

fn check_batch(ctx: &GpuContext, batch: &Batch) -> usize {
    check_batch_with(ctx, batch, RowFormat::F32)
}

/// [`check_batch`] with the colour input's rows in `color` (bf16: the colour MLP's own rows on
/// CPU devices).
fn check_batch_with(ctx: &GpuContext, batch: &Batch, color: RowFormat) -> usize {
    let cfg = &batch.cfg;
    let s = batch.samples();
    let n = cfg.batch_rays as usize * s;
    let step = uniform_buffer_from(ctx, "step", &StepUniforms::for_step(cfg, 1, 0, 1e-3));
    let density = storage_buffer_from(ctx, "density", &batch.density).unwrap();
    let intervals = storage_buffer_from(ctx, "intervals", &batch.intervals).unwrap();
    let targets = storage_buffer_from(ctx, "targets", &batch.targets).unwrap();
    // The SH rows come in the colour rows' format.
    let sh_words: Vec<u32> = match color {
        RowFormat::F32 => batch.sh.iter().map(|v| v.to_bits()).collect(),
        RowFormat::Bf16 => batch.sh.chunks(2).map(|q| bf16::pair(q[0], q[1])).collect(),
    };
    let sh = storage_buffer_from(ctx, "sh", &sh_words).unwrap();
    let density_packed = storage_buffer_garbage::<f32>(ctx, "density packed", n * (1 + GEOMETRY)).unwrap();
    let color_words = RowView::words(color, n as u32, (SH + GEOMETRY) as u32) as usize;
    let color_buffer = storage_buffer_garbage::<u32>(ctx, "colour packed", color_words).unwrap();
    let color_packed = RowView::packed_as(&color_buffer, (SH + GEOMETRY) as u32, color);
    let rows = HeadRows::new(ctx, n as u32).unwrap();
    // Shapes the head kernels would ask for: a tiled layer's row tiles, a uniform layer's rows,
    // a mask over rows × outputs (one asked twice shares its slot).
    let shapes_asked = [[1, 64, 3], [1, 64, 1], [7, 64, 1], [1, 64, 3]];
    let args: Vec<_> = shapes_asked
        .iter()
        .map(|&[a, b, c]| rows.dispatch(a, b, c).unwrap())
        .collect();
    assert_eq!(args[0].offset, args[3].offset);
    let pass = pollster::block_on(KeepPass::new(
        ctx,
        KeepShape {
            batch_rays: cfg.batch_rays,
            samples_per_ray: s as u32,
            threshold: cfg.head_weight_threshold,
            density_stride: 1 + GEOMETRY as u32,
            sh_width: SH as u32,
            target_stride: (TARGET_HEADER_WORDS + FEATURE) as u32,
        },
        &rows,
        &KeepBuffers {
            step_uniforms: &step,
            density_out: &density,
            intervals: &intervals,
            targets: &targets,
            sh_rows: &sh,
            density_packed: &density_packed,
            color_packed: &color_packed,
        },
    ))
    .unwrap();
    for buffer in [&rows.row_count, &rows.rows, &rows.slot, &rows.dispatch_args] {
        fill_with_garbage(ctx, buffer);
    }
    ctx.queue
        .write_buffer(&rows.kept_tally, 0, bytemuck::cast_slice(&[5u32, 2]));
    let mut encoder = ctx.device.create_command_encoder(&Default::default());
    {
        let mut compute = encoder.begin_compute_pass(&Default::default());
        pass.record(&mut compute);
    }
    ctx.queue.submit([encoder.finish()]);

    let (slot, packed_rows) = batch.expected();
    let kept = packed_rows.len();
    let read = |b: &wgpu::Buffer| read_buffer_blocking::<u32>(ctx, b).unwrap();
    assert_eq!(read(&rows.row_count), [kept as u32]);
    assert_eq!(read(&rows.kept_tally), [5 + kept as u32, 3], "the tally adds the batch");
    assert_eq!(read(&rows.slot), slot);
    let gpu_rows = read(&rows.rows);
    assert_eq!(&gpu_rows[..kept], &packed_rows[..]);
    assert!(gpu_rows.iter().enumerate().skip(kept).all(|(i, v)| is_garbage(i, *v)));

    let shapes = rows.shapes();
    assert_eq!(shapes.len(), 3, "three shapes asked for; the gather's is the second's");
    let most = ctx.limits.max_compute_workgroups_per_dimension;
    let expected_args: Vec<u32> = shapes
        .iter()
        .flat_map(|&shape| workgroup_counts(shape, kept as u32, most))
        .collect();
    let gpu_args = read(&rows.dispatch_args);
    assert_eq!(&gpu_args[..expected_args.len()], &expected_args[..]);
    assert_eq!(
        workgroup_counts([7, 64, 1, 0], kept as u32, most)[0],
        (kept as u32 * 7).div_ceil(64)
    );

    // The gathered inputs: [h₀ | g] and the SH columns at each packed row; the rest untouched.
    let d = read_buffer_blocking::<f32>(ctx, &density_packed).unwrap();
    let c = read_buffer_blocking::<u32>(ctx, &color_buffer).unwrap();
    let dw = 1 + GEOMETRY;
    // Words per colour row, and the words of its SH part.
    let (cw, sh_words) = match color {
        RowFormat::F32 => (SH + GEOMETRY, SH),
        RowFormat::Bf16 => ((SH + GEOMETRY).div_ceil(2), SH / 2),
    };
    for (p, &sample) in packed_rows.iter().enumerate() {
        let sample = sample as usize;
        assert_eq!(&d[p * dw..(p + 1) * dw], &batch.density[sample * dw..(sample + 1) * dw]);
        let sh = &batch.sh[sample * SH..(sample + 1) * SH];
        let want: Vec<u32> = match color {
            RowFormat::F32 => sh.iter().map(|v| v.to_bits()).collect(),
            RowFormat::Bf16 => sh.chunks(2).map(|q| bf16::pair(q[0], q[1])).collect(),
        };
        assert_eq!(&c[p * cw..p * cw + sh_words], &want[..], "SH of packed row {p}");
        for j in sh_words..cw {
            assert!(is_garbage(p * cw + j, c[p * cw + j]), "g columns are the glue's");
        }
    }
    for (i, v) in d.iter().enumerate().take(n * dw).skip(kept * dw) {
        assert!(is_garbage(i, v.to_bits()), "density row past the kept ones written");
    }
    kept
}

#[test]
fn keep_matches_its_cpu_twin() {
    let Some(ctx) = gpu_for_tests("keep_matches_its_cpu_twin") else {
        return;
    };
    // 300 rays: not a multiple of the 64-ray workgroup, more than the scan's 256 invocations.
    let batch = Batch::random(300, 1e-4, 7);
    let kept = check_batch(&ctx, &batch);
    let (slot, _) = batch.expected();
    let s = batch.samples();
    assert!(
        slot[..s - 1].iter().all(|&p| p == NOT_KEPT) && slot[s - 1] != NOT_KEPT,
        "ray 0 keeps its opaque last sample alone"
    );
    assert!(slot[s..2 * s].iter().all(|&p| p != NOT_KEPT), "ray 1 keeps everything");
    let n = slot.len();
    assert!(kept > n / 10 && kept < n * 9 / 10, "{kept} of {n} kept");

    // A few rays (fewer than the scan's invocations), and many (several per invocation).
    check_batch(&ctx, &Batch::random(3, 1e-3, 8));
    check_batch(&ctx, &Batch::random(1000, 1e-2, 9));
    // The colour input's rows in bf16.
    check_batch_with(&ctx, &Batch::random(300, 1e-4, 7), RowFormat::Bf16);
}

#[test]
fn threshold_zero_keeps_every_sample_in_order() {
    let Some(ctx) = gpu_for_tests("threshold_zero_keeps_every_sample_in_order") else {
        return;
    };
    let batch = Batch::random(130, 0.0, 10);
    let n = batch.cfg.batch_rays as usize * batch.samples();
    assert_eq!(check_batch(&ctx, &batch), n, "misses included");
    let (slot, rows) = batch.expected();
    assert!(slot.iter().enumerate().all(|(i, &p)| p == i as u32));
    assert!(rows.iter().enumerate().all(|(i, &r)| r == i as u32));
}
