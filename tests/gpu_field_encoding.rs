//! The GPU encodings (`field::gpu::encoding`) against the CPU reference (`reference::hash_grid`,
//! `frequency`, `sh`), on outputs filled with garbage first and sample counts that are not
//! multiples of the workgroup size. Throughput: `cargo test --release --test gpu_field_encoding
//! -- --ignored --nocapture`.
use scribblefield::field::gpu::dense::RowFormat;
use scribblefield::field::gpu::encoding::{
    AtomicAdd, BackwardStrategy, HashGridBackwardBuffers, HashGridBackwardPass, PositionEncodeBuffers,
    PositionEncodePass, WORKGROUP_SIZE,
};
use scribblefield::field::gpu::sh_encode::{ShEncodeBuffers, ShEncodePass, ShOutputLayout};
use scribblefield::field::gpu::stage::Stage;
use scribblefield::field::reference::hash_grid::{self, HashGrid};
use scribblefield::field::reference::{frequency, sh};
use scribblefield::field::{Encoding, FieldConfig, bf16};
use scribblefield::gpu::GpuContext;
use scribblefield::gpu::buffers::{GARBAGE_WORDS, read_buffer_blocking, storage_buffer_from, storage_buffer_garbage};
use scribblefield::gpu::test_support::gpu_for_tests;
use scribblefield::gpu::timing::{PassTimer, Stopwatch};
use scribblefield::rng::SplitMix64;

/// Where the tests put the table in the flat buffer: not at 0, to prove the offset is honoured.
const TABLE_OFFSET: usize = 37;
/// Values after the table, to prove nothing is written past it.
const TAIL: usize = 11;

/// Samples of `rays` rays: `samples_per_ray` sorted points on a segment of `length` through the
/// unit cube, like the rays pass produces (adjacent samples of a ray often share coarse cells).
/// A few points sit exactly on the faces and slightly outside, to exercise the clamp.
fn ray_positions(rng: &mut SplitMix64, rays: usize, samples_per_ray: usize, length: f64) -> Vec<[f32; 4]> {
    let mut out = Vec::with_capacity(rays * samples_per_ray);
    for ray in 0..rays {
        let origin: [f64; 3] = std::array::from_fn(|_| rng.uniform(0.05, 0.95));
        let z = rng.uniform(-1.0, 1.0);
        let phi = rng.uniform(0.0, std::f64::consts::TAU);
        let r = (1.0 - z * z).sqrt();
        let dir = [r * phi.cos(), r * phi.sin(), z];
        let mut ts: Vec<f64> = (0..samples_per_ray).map(|_| rng.uniform(0.0, length)).collect();
        ts.sort_by(f64::total_cmp);
        for t in ts {
            out.push(std::array::from_fn(|a| {
                if a < 3 { (origin[a] + t * dir[a]) as f32 } else { 0.0 }
            }));
        }
        if ray == 0 && samples_per_ray >= 4 {
            let base = out.len() - samples_per_ray;
            out[base] = [0.0, 1.0, 0.5, 0.0];
            out[base + 1] = [1.0, 1.0, 1.0, 0.0];
            out[base + 2] = [-0.02, 1.03, 0.25, 0.0];
            out[base + 3] = [0.5, 0.25, 0.125, 0.0];
        }
    }
    out
}

fn random_values(rng: &mut SplitMix64, n: usize) -> Vec<f32> {
    (0..n).map(|_| rng.uniform(-1.0, 1.0) as f32).collect()
}

/// A flat buffer [garbage | table | garbage] as the trainer's params buffer would hold it.
fn flat_with_table(table: &[f32]) -> Vec<f32> {
    let garbage = |n: usize| {
        GARBAGE_WORDS
            .iter()
            .cycle()
            .take(n)
            .map(|&w| f32::from_bits(w))
            .collect::<Vec<_>>()
    };
    let mut flat = garbage(TABLE_OFFSET);
    flat.extend_from_slice(table);
    flat.extend(garbage(TAIL));
    flat
}

fn xyz(p: &[f32; 4]) -> [f32; 3] {
    [p[0], p[1], p[2]]
}

fn configs() -> Vec<(&'static str, FieldConfig)> {
    vec![
        ("small hash+freq", FieldConfig::small()),
        ("default widths hash+freq", FieldConfig::default()),
        (
            "freq only L=10",
            FieldConfig {
                encoding: Encoding::freq_only_baseline(),
                ..FieldConfig::small()
            },
        ),
        (
            "hash only",
            FieldConfig {
                encoding: Encoding::HashOnly,
                ..FieldConfig::small()
            },
        ),
        (
            // Dense levels of 4³ and 7³ entries, one of exactly the table's 2^12 (16³, still
            // dense), then hashed levels: each level at its own offset in the shrunken table.
            "dense and hashed levels",
            FieldConfig {
                hash_levels: 6,
                hash_base_resolution: 3,
                hash_level_scale: 2.25,
                log2_hash_table_size: 12,
                ..FieldConfig::small()
            },
        ),
        (
            // Non-power-of-two resolutions and 3 features: cells from a rounded p·res.
            "odd grid",
            FieldConfig {
                hash_base_resolution: 5,
                hash_level_scale: 1.5,
                hash_features_per_level: 3,
                ..FieldConfig::small()
            },
        ),
    ]
}

/// The "dense and hashed levels" config really has levels of both kinds, one dense level
/// exactly the table's size, and a table shorter than one full table per level.
#[test]
fn dense_levels_are_sized_to_their_vertices() {
    let (_, cfg) = configs()
        .into_iter()
        .find(|(name, _)| *name == "dense and hashed levels")
        .unwrap();
    let grid = HashGrid::from_config(&cfg);
    assert_eq!(grid.resolutions, vec![3, 6, 15, 34, 76, 172]);
    let entries: Vec<usize> = (0..grid.levels).map(|l| grid.level_entries(l)).collect();
    assert_eq!(entries, vec![64, 343, 4096, 4096, 4096, 4096]);
    assert!(grid.is_dense(2) && !grid.is_dense(3));
    assert!(grid.param_count() < grid.levels * grid.table_size * grid.features);
}

/// Runs the forward of `cfg` on `positions` into a garbage-filled buffer and reads it back.
fn gpu_encode(ctx: &GpuContext, cfg: &FieldConfig, table: &[f32], positions: &[[f32; 4]]) -> Vec<f32> {
    let n = positions.len();
    let positions_buffer = storage_buffer_from(ctx, "positions", positions).unwrap();
    let params = storage_buffer_from(ctx, "params", &flat_with_table(table)).unwrap();
    let encoding = storage_buffer_garbage::<f32>(ctx, "encoding", n * cfg.encoding_dim()).unwrap();
    let buffers = PositionEncodeBuffers {
        positions: &positions_buffer,
        params: &params,
        table_offset: TABLE_OFFSET,
        encoding: &encoding,
    };
    let pass = pollster::block_on(PositionEncodePass::new(ctx, cfg, n, buffers)).unwrap();
    let mut encoder = ctx.device.create_command_encoder(&Default::default());
    pass.record(&mut encoder.begin_compute_pass(&Default::default()));
    ctx.queue.submit([encoder.finish()]);
    let mut out: Vec<f32> = read_buffer_blocking(ctx, &encoding).unwrap();
    out.truncate(n * cfg.encoding_dim());
    out
}

/// The forward writes every value of every row; hash values agree with the f32 reference to
/// the rounding of 8 products summed in the same order (FMA contraction may differ: < 1e-6 for
/// table values in ±1, whose blend is itself in ±1); frequency values agree with the exact (f64)
/// reference to 2e-6, as the kernel reduces the phase exactly before sin/cos (the f32 reference,
/// which rounds 2^k·π·p, is itself off by up to 2^-24·2^k·π: 1e-4 at L = 10).
#[test]
fn position_encoding_matches_reference() {
    let Some(ctx) = gpu_for_tests("position_encoding_matches_reference") else {
        return;
    };
    for (name, cfg) in configs() {
        let mut rng = SplitMix64::new(11);
        let grid = HashGrid::from_config(&cfg);
        let table = random_values(&mut rng, grid.param_count());
        // 37 · 13 = 481 samples: not a multiple of the workgroup size.
        let positions = ray_positions(&mut rng, 37, 13, 0.3);
        let gpu = gpu_encode(&ctx, &cfg, &table, &positions);

        let dim = cfg.encoding_dim();
        let hash_dim = grid.output_dim();
        let octaves = cfg.encoding.frequencies() as usize;
        let (mut hash_error, mut freq_error) = (0.0f64, 0.0f64);
        let mut expect = vec![0.0f32; hash_dim];
        let mut expect_freq = vec![0.0f64; frequency::output_dim(octaves)];
        for (n, p) in positions.iter().enumerate() {
            let row = &gpu[n * dim..(n + 1) * dim];
            hash_grid::encode(&grid, &table, xyz(p), &mut expect);
            let p64 = xyz(p).map(f64::from);
            frequency::encode(octaves, p64, &mut expect_freq);
            for (c, (&g, &e)) in row[..hash_dim].iter().zip(&expect).enumerate() {
                let error = f64::from((g - e).abs());
                assert!(
                    error <= 1e-6,
                    "{name}: sample {n} ({p:?}) hash column {c}: GPU {g}, reference {e}"
                );
                hash_error = hash_error.max(error);
            }
            for (c, (&g, &e)) in row[hash_dim..].iter().zip(&expect_freq).enumerate() {
                let error = (f64::from(g) - e).abs();
                assert!(
                    error <= 2e-6,
                    "{name}: sample {n} ({p:?}) frequency column {c}: GPU {g}, reference {e}"
                );
                freq_error = freq_error.max(error);
            }
        }
        eprintln!("{name}: max |GPU − reference|: hash {hash_error:.2e}, frequency {freq_error:.2e}");
    }
}

/// The ∂L/∂encoding rows `check_backward` draws: uniform in [-1, 1], or their magnitudes.
#[derive(Clone, Copy)]
struct Gradients {
    seed: u64,
    same_sign: bool,
}

/// The table gradient of the GPU backward (after clearing a garbage-filled gradient buffer) and
/// the reference's, summed in f64, over positions and ∂L/∂encoding rows. Also checks that values
/// outside the table range keep their garbage and that the frequency columns of the gradient
/// rows (garbage here) are never read.
fn check_backward(
    ctx: &GpuContext,
    name: &str,
    cfg: &FieldConfig,
    positions: &[[f32; 4]],
    strategy: BackwardStrategy,
    atomics: AtomicAdd,
    gradients: Gradients,
) -> f64 {
    let n = positions.len();
    let grid = HashGrid::from_config(cfg);
    let dim = cfg.encoding_dim();
    let hash_dim = grid.output_dim();
    let mut rng = SplitMix64::new(gradients.seed);
    let mut encoding_grad: Vec<f32> = GARBAGE_WORDS
        .iter()
        .cycle()
        .take(n * dim)
        .map(|&w| f32::from_bits(w))
        .collect();
    for row in encoding_grad.chunks_exact_mut(dim) {
        for g in &mut row[..hash_dim] {
            *g = rng.uniform(-1.0, 1.0) as f32;
            if gradients.same_sign {
                *g = g.abs();
            }
        }
    }

    let positions_buffer = storage_buffer_from(ctx, "positions", positions).unwrap();
    let grad_buffer = storage_buffer_from(ctx, "encoding grad", &encoding_grad).unwrap();
    let table_len = grid.param_count();
    let gradient = storage_buffer_garbage::<f32>(ctx, "gradient", TABLE_OFFSET + table_len + TAIL).unwrap();
    let buffers = HashGridBackwardBuffers {
        positions: &positions_buffer,
        encoding_grad: &grad_buffer,
        gradient: &gradient,
        table_offset: TABLE_OFFSET,
    };
    let pass = pollster::block_on(HashGridBackwardPass::with_atomics(
        ctx, cfg, n, buffers, strategy, atomics,
    ))
    .unwrap();
    let mut encoder = ctx.device.create_command_encoder(&Default::default());
    pass.record_clear(&mut encoder);
    pass.record(&mut encoder.begin_compute_pass(&Default::default()));
    ctx.queue.submit([encoder.finish()]);
    let words: Vec<u32> = read_buffer_blocking(ctx, &gradient).unwrap();
    let exponents = pass.read_exponents(ctx).map(|read| pollster::block_on(read).unwrap());
    assert_eq!(
        exponents.is_some(),
        atomics == AtomicAdd::FixedPoint && grid.levels > 0,
        "{name}"
    );
    let mut decoded: Vec<f32> = words.iter().map(|&w| f32::from_bits(w)).collect();
    pollster::block_on(pass.decode_fixed_point(&mut decoded, pass.read_exponents(ctx))).unwrap();

    let garbage_at = |i: usize| GARBAGE_WORDS[i % GARBAGE_WORDS.len()];
    for i in (0..TABLE_OFFSET).chain(TABLE_OFFSET + table_len..TABLE_OFFSET + table_len + TAIL) {
        assert_eq!(
            words[i],
            garbage_at(i),
            "{name}: gradient element {i} outside the table was written"
        );
    }

    // The reference's f32 corners (the cells and weights the f32 kernel must pick), summed in
    // f64, with the sum of |terms| beside it: a scale for the summation error that cancellation
    // cannot shrink.
    let mut expect = vec![0.0f64; table_len];
    let mut magnitude = vec![0.0f64; table_len];
    let mut terms = vec![0u32; table_len];
    let mut bounds = vec![0.0f64; grid.levels];
    for (p, row) in positions.iter().zip(encoding_grad.chunks_exact(dim)) {
        for level in 0..grid.levels {
            for f in 0..grid.features {
                bounds[level] += f64::from(row[level * grid.features + f].abs());
            }
            for corner in grid.corners::<f32>(level, xyz(p)) {
                for f in 0..grid.features {
                    let term = f64::from(corner.weight) * f64::from(row[level * grid.features + f]);
                    expect[corner.offset + f] += term;
                    magnitude[corner.offset + f] += term.abs();
                    terms[corner.offset + f] += 1;
                }
            }
        }
    }
    // Fixed point: each level's exponent scales the bound on its sums (Σ|∂L/∂encoding| of the
    // level, summed here in f64, on the GPU in f32) to at most 2^30, and by no less than half.
    if let Some(exponents) = &exponents {
        for (level, &bound) in bounds.iter().enumerate() {
            let scaled = bound * 2f64.powi(exponents[level]);
            assert!(
                scaled <= f64::from(1u32 << 30) * (1.0 + 1e-5) && scaled > f64::from(1u32 << 28),
                "{name}: level {level}: bound {bound} scaled by 2^{} to {scaled}",
                exponents[level]
            );
        }
    }
    let mut worst = 0.0f64;
    for (i, (&e, &m)) in expect.iter().zip(&magnitude).enumerate() {
        let level = grid.level_of_value(i);
        let g = f64::from(decoded[TABLE_OFFSET + i]);
        // f32 sums of K terms in an arbitrary order: error ≲ √K·2^-24·Σ|terms| in practice,
        // bounded by K·2^-24·Σ|terms|. 2e-5 covers K up to ~10^5 random-order terms with
        // margin; the measured worst case is printed. Fixed point adds up to half a unit
        // (2^-exponent) per add, and no add of fewer terms than samples: K half units at most.
        let rounding = exponents
            .as_ref()
            .map_or(0.0, |x| 0.5 * f64::from(terms[i]) * 2f64.powi(-x[level]));
        let relative = if m > 0.0 {
            ((g - e).abs() - rounding).max(0.0) / m
        } else {
            (g - e).abs() - rounding
        };
        assert!(
            relative <= 2e-5,
            "{name}: table gradient {i} (level {level}): GPU {g}, reference {e}, Σ|terms| {m}, rounding {rounding:e}",
        );
        worst = worst.max(relative);
    }
    worst
}

/// Many samples per cell: short ray segments (adjacent samples share cells up to fine levels),
/// and rays whose samples all sit on one point (thousands of adds to the same 8 entries).
fn contended_positions(rng: &mut SplitMix64) -> Vec<[f32; 4]> {
    let mut positions = ray_positions(rng, 53, 29, 0.05);
    let hot = [0.4321f32, 0.6543, 0.2109, 0.0];
    positions.extend(std::iter::repeat_n(hot, 3001));
    positions.extend(ray_positions(rng, 17, 61, 0.8));
    positions
}

/// Every way of adding the device runs: the portable compare-exchange loop, fixed point and one
/// invocation per level always, float atomics where the device has them (lavapipe does;
/// SwiftShader and browsers do not).
fn atomic_adds(ctx: &GpuContext) -> Vec<AtomicAdd> {
    let mut adds = vec![AtomicAdd::CompareExchange, AtomicAdd::FixedPoint, AtomicAdd::PerLevel];
    if ctx.features.contains(wgpu::Features::SHADER_FLOAT32_ATOMIC) {
        adds.push(AtomicAdd::Float);
    } else {
        eprintln!(
            "{}: no float atomics, only the portable adds are tested",
            ctx.describe()
        );
    }
    adds
}

/// The fixed-point sums' worst case: every sample on one vertex of every level (all its weight
/// on one entry) with gradients of one sign, so that entry's sum is the whole bound the scale
/// was picked for, plus every add's rounding. It must not wrap.
#[test]
fn fixed_point_sums_reach_their_bound_without_overflowing() {
    let Some(ctx) = gpu_for_tests("fixed_point_sums_reach_their_bound_without_overflowing") else {
        return;
    };
    let cfg = FieldConfig::small();
    // 0.5 lies on a vertex of every level (resolutions are even): weight 1 on one corner.
    let positions = vec![[0.5f32, 0.5, 0.5, 0.0]; 5000];
    for strategy in [BackwardStrategy::MergeRuns, BackwardStrategy::PerSample] {
        let worst = check_backward(
            &ctx,
            "one vertex",
            &cfg,
            &positions,
            strategy,
            AtomicAdd::FixedPoint,
            Gradients {
                seed: 9,
                same_sign: true,
            },
        );
        eprintln!("one vertex {strategy:?}: max |GPU − ref| / Σ|terms| = {worst:.2e}");
    }
}

#[test]
fn float_atomics_are_refused_on_a_device_without_them() {
    let Some(ctx) = gpu_for_tests("float_atomics_are_refused_on_a_device_without_them") else {
        return;
    };
    let cfg = FieldConfig::default();
    let layout = scribblefield::field::ParamLayout::new(&cfg);
    let positions = storage_buffer_garbage::<[f32; 4]>(&ctx, "positions", 64).unwrap();
    let encoding_grad = storage_buffer_garbage::<f32>(&ctx, "encoding grad", 64 * cfg.encoding_dim()).unwrap();
    let gradient = storage_buffer_garbage::<f32>(&ctx, "gradient", layout.total).unwrap();
    let buffers = HashGridBackwardBuffers {
        positions: &positions,
        encoding_grad: &encoding_grad,
        gradient: &gradient,
        table_offset: layout.hash_table.start,
    };
    let made = pollster::block_on(HashGridBackwardPass::with_atomics(
        &ctx,
        &cfg,
        64,
        buffers,
        BackwardStrategy::MergeRuns,
        AtomicAdd::Float,
    ));
    let has_them = ctx.features.contains(wgpu::Features::SHADER_FLOAT32_ATOMIC);
    match made {
        Ok(_) => assert!(has_them, "float atomics were built on a device without them"),
        Err(error) => {
            assert!(!has_them, "{error}");
            assert!(error.to_string().contains("SHADER_FLOAT32_ATOMIC"), "{error}");
        }
    }
}

#[test]
fn hash_backward_matches_reference_sum() {
    let Some(ctx) = gpu_for_tests("hash_backward_matches_reference_sum") else {
        return;
    };
    for (name, cfg) in configs() {
        let mut rng = SplitMix64::new(21);
        let positions = contended_positions(&mut rng);
        assert_ne!(positions.len() % WORKGROUP_SIZE as usize, 0);
        for strategy in [BackwardStrategy::MergeRuns, BackwardStrategy::PerSample] {
            for atomics in atomic_adds(&ctx) {
                let worst = check_backward(
                    &ctx,
                    name,
                    &cfg,
                    &positions,
                    strategy,
                    atomics,
                    Gradients {
                        seed: 5,
                        same_sign: false,
                    },
                );
                eprintln!(
                    "{name} {strategy:?} {atomics:?}: {} samples, max |GPU − ref| / Σ|terms| = {worst:.2e}",
                    positions.len()
                );
            }
        }
    }
}

/// The default model at the bench size (4096 rays × 64 samples): the backward launches
/// 16 · 4096 = 65536 workgroups and the forward 17 · 4096, both beyond one dispatch dimension.
#[test]
fn default_size_batch_spans_more_than_65535_workgroups() {
    let Some(ctx) = gpu_for_tests("default_size_batch_spans_more_than_65535_workgroups") else {
        return;
    };
    let cfg = FieldConfig::default();
    let mut rng = SplitMix64::new(31);
    let positions = ray_positions(&mut rng, 4096, 64, 0.6);
    let n = positions.len();
    assert!(16 * n.div_ceil(WORKGROUP_SIZE as usize) > 65535);

    let grid = HashGrid::from_config(&cfg);
    let table = random_values(&mut rng, grid.param_count());
    let gpu = gpu_encode(&ctx, &cfg, &table, &positions);
    let dim = cfg.encoding_dim();
    let mut expect = vec![0.0f32; dim];
    let mut worst = 0.0f32;
    for (n, p) in positions.iter().enumerate() {
        hash_grid::encode(&grid, &table, xyz(p), &mut expect[..grid.output_dim()]);
        frequency::encode(2, xyz(p), &mut expect[grid.output_dim()..]);
        for (c, (&g, &e)) in gpu[n * dim..(n + 1) * dim].iter().zip(&expect).enumerate() {
            // Frequencies against the f32 reference: its rounded phase costs up to 2^-24·2π.
            assert!((g - e).abs() <= 2e-6, "sample {n} column {c}: GPU {g}, reference {e}");
            worst = worst.max((g - e).abs());
        }
    }
    // The device's own add, and one invocation per level whatever the device: at this size its
    // samples take several dispatches (lavapipe's loop limit, `PER_LEVEL_LOOP_BUDGET`).
    let mut adds = vec![AtomicAdd::best_for(&ctx)];
    if !adds.contains(&AtomicAdd::PerLevel) {
        adds.push(AtomicAdd::PerLevel);
    }
    let mut backward = 0.0f64;
    for atomics in adds {
        backward = backward.max(check_backward(
            &ctx,
            "default",
            &cfg,
            &positions,
            BackwardStrategy::MergeRuns,
            atomics,
            Gradients {
                seed: 7,
                same_sign: false,
            },
        ));
    }
    eprintln!("default config, {n} samples: forward max error {worst:.2e}, backward {backward:.2e}");
}

#[test]
fn direction_sh_matches_reference_and_leaves_other_columns() {
    let Some(ctx) = gpu_for_tests("direction_sh_matches_reference_and_leaves_other_columns") else {
        return;
    };
    let mut rng = SplitMix64::new(41);
    let cases = [
        (37, 13, 31, 0, RowFormat::F32),
        (5, 64, 40, 7, RowFormat::F32),
        (300, 1, 16, 0, RowFormat::F32),
        // bf16 rows, as for the colour MLP's own input rows on CPU devices.
        (37, 13, 32, 0, RowFormat::Bf16),
        (5, 64, 40, 8, RowFormat::Bf16),
    ];
    for (rays, samples_per_ray, row_stride, column_offset, format) in cases {
        let directions: Vec<[f32; 4]> = (0..rays)
            .map(|_| {
                let z = rng.uniform(-1.0, 1.0);
                let phi = rng.uniform(0.0, std::f64::consts::TAU);
                let r = (1.0 - z * z).sqrt();
                [(r * phi.cos()) as f32, (r * phi.sin()) as f32, z as f32, 0.0]
            })
            .collect();
        let n = rays * samples_per_ray;
        let layout = ShOutputLayout {
            samples_per_ray,
            row_stride,
            column_offset,
            format,
        };
        let bf16_rows = format == RowFormat::Bf16;
        // Values per word.
        let per_word = if bf16_rows { 2 } else { 1 };
        let directions_buffer = storage_buffer_from(&ctx, "directions", &directions).unwrap();
        let output = storage_buffer_garbage::<f32>(&ctx, "sh output", n * row_stride / per_word).unwrap();
        let buffers = ShEncodeBuffers {
            directions: &directions_buffer,
            output: &output,
        };
        let pass = pollster::block_on(ShEncodePass::new(&ctx, n, layout, buffers)).unwrap();
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        pass.record(&mut encoder.begin_compute_pass(&Default::default()));
        ctx.queue.submit([encoder.finish()]);
        let words: Vec<u32> = read_buffer_blocking(&ctx, &output).unwrap();

        let mut expect = [0.0f32; sh::SH_COEFFS];
        let mut worst = 0.0f32;
        for sample in 0..n {
            let d = directions[sample / samples_per_ray];
            sh::encode([d[0], d[1], d[2]], &mut expect);
            let row = sample * row_stride / per_word;
            for column in 0..row_stride {
                let i = row + column / per_word;
                if (column_offset..column_offset + sh::SH_COEFFS).contains(&column) {
                    let e = expect[column - column_offset];
                    let (g, bound) = if bf16_rows {
                        // The GPU's f32 rounded to bf16: half a bf16 step of e, and the f32 slack.
                        (bf16::row_value(&words[row..], column), e.abs() * 2f32.powi(-8) + 1e-6)
                    } else {
                        // Same products in the same order; FMA contraction may move the last bits.
                        (f32::from_bits(words[i]), 1e-6)
                    };
                    assert!(
                        (g - e).abs() <= bound,
                        "{layout:?}: sample {sample} column {column}: GPU {g}, reference {e}"
                    );
                    worst = worst.max((g - e).abs());
                } else {
                    assert_eq!(
                        words[i],
                        GARBAGE_WORDS[i % 4],
                        "{layout:?}: sample {sample} column {column} was written"
                    );
                }
            }
        }
        eprintln!("SH {layout:?}: max |GPU − reference| {worst:.2e}");
    }
}

#[test]
fn passes_refuse_buffers_that_are_too_small() {
    let Some(ctx) = gpu_for_tests("passes_refuse_buffers_that_are_too_small") else {
        return;
    };
    let cfg = FieldConfig::small();
    let table_len = HashGrid::from_config(&cfg).param_count();
    let positions = storage_buffer_garbage::<[f32; 4]>(&ctx, "positions", 100).unwrap();
    let params = storage_buffer_garbage::<f32>(&ctx, "params", table_len).unwrap();
    let encoding = storage_buffer_garbage::<f32>(&ctx, "encoding", 100 * cfg.encoding_dim()).unwrap();
    let buffers = PositionEncodeBuffers {
        positions: &positions,
        params: &params,
        table_offset: 0,
        encoding: &encoding,
    };
    assert!(pollster::block_on(PositionEncodePass::new(&ctx, &cfg, 100, buffers)).is_ok());
    assert!(pollster::block_on(PositionEncodePass::new(&ctx, &cfg, 101, buffers)).is_err());
    let shifted = PositionEncodeBuffers {
        table_offset: 1,
        ..buffers
    };
    assert!(pollster::block_on(PositionEncodePass::new(&ctx, &cfg, 100, shifted)).is_err());
    let sh_buffers = ShEncodeBuffers {
        directions: &positions,
        output: &encoding,
    };
    let layout = ShOutputLayout {
        samples_per_ray: 1,
        row_stride: 15,
        column_offset: 0,
        format: RowFormat::F32,
    };
    assert!(pollster::block_on(ShEncodePass::new(&ctx, 100, layout, sh_buffers)).is_err());
}

/// Samples like the trainer's: per ray, 16 stratified over the chord through the unit cube and
/// 48 in a band of ±0.035 (0.02 of the box diagonal) around a surface point, sorted along the ray.
fn trainer_like_positions(rng: &mut SplitMix64, rays: usize) -> Vec<[f32; 4]> {
    let mut out = Vec::with_capacity(rays * 64);
    for _ in 0..rays {
        let origin: [f64; 3] = std::array::from_fn(|_| rng.uniform(0.0, 1.0));
        let z = rng.uniform(-1.0, 1.0);
        let phi = rng.uniform(0.0, std::f64::consts::TAU);
        let r = (1.0 - z * z).sqrt();
        let dir = [r * phi.cos(), r * phi.sin(), z];
        let surface = rng.uniform(0.2, 0.8);
        let mut ts: Vec<f64> = (0..16).map(|j| (j as f64 + rng.next_f64()) / 16.0).collect();
        ts.extend((0..48).map(|j| surface - 0.035 + 0.07 * (j as f64 + rng.next_f64()) / 48.0));
        ts.sort_by(f64::total_cmp);
        for t in ts {
            out.push(std::array::from_fn(|a| {
                if a < 3 {
                    (origin[a] + (t - 0.5) * dir[a]) as f32
                } else {
                    0.0
                }
            }));
        }
    }
    out
}

/// Seconds per run of `record`, by timestamps when the adapter has them, else wall clock.
fn time_runs(ctx: &GpuContext, runs: u32, record: &dyn Fn(&mut wgpu::CommandEncoder, Option<&mut PassTimer>)) -> f64 {
    let mut encoder = ctx.device.create_command_encoder(&Default::default());
    record(&mut encoder, None);
    ctx.queue.submit([encoder.finish()]);
    ctx.wait_idle().unwrap();
    let mut timer = PassTimer::new(ctx, runs);
    let stopwatch = Stopwatch::start();
    let mut encoder = ctx.device.create_command_encoder(&Default::default());
    for _ in 0..runs {
        record(&mut encoder, timer.as_mut());
    }
    if let Some(timer) = &timer {
        timer.resolve(&mut encoder);
    }
    ctx.queue.submit([encoder.finish()]);
    ctx.wait_idle().unwrap();
    let wall = stopwatch.elapsed_seconds() / f64::from(runs);
    match timer.as_mut() {
        Some(timer) => {
            let times = pollster::block_on(timer.read(ctx).times()).unwrap();
            let gpu = times.iter().map(|t| t.seconds).sum::<f64>() / f64::from(runs);
            eprintln!("  (timestamps {gpu:.4} s per run, wall clock {wall:.4} s)");
            gpu
        }
        None => wall,
    }
}

/// Measurement, not a check: `cargo test --release --test gpu_field_encoding -- --ignored --nocapture`.
#[test]
#[ignore = "measurement; run explicitly in release mode"]
fn encoding_throughput_report() {
    let Some(ctx) = gpu_for_tests("encoding_throughput_report") else {
        return;
    };
    let cfg = FieldConfig::default();
    let rays = 4096;
    let mut rng = SplitMix64::new(51);
    let positions = trainer_like_positions(&mut rng, rays);
    let n = positions.len();
    let layout = scribblefield::field::ParamLayout::new(&cfg);
    let params_values = layout.init(1);
    let params = storage_buffer_from(&ctx, "params", &params_values).unwrap();
    let gradient = storage_buffer_garbage::<f32>(&ctx, "gradient", layout.total).unwrap();
    let positions_buffer = storage_buffer_from(&ctx, "positions", &positions).unwrap();
    let encoding = storage_buffer_garbage::<f32>(&ctx, "encoding", n * cfg.encoding_dim()).unwrap();
    let encoding_grad =
        storage_buffer_from(&ctx, "encoding grad", &random_values(&mut rng, n * cfg.encoding_dim())).unwrap();
    let directions = storage_buffer_from(&ctx, "directions", &vec![[0.0f32, 0.6, 0.8, 0.0]; rays]).unwrap();
    let color_in = storage_buffer_garbage::<f32>(&ctx, "colour input", n * 31).unwrap();

    let forward_buffers = PositionEncodeBuffers {
        positions: &positions_buffer,
        params: &params,
        table_offset: layout.hash_table.start,
        encoding: &encoding,
    };
    let forward = pollster::block_on(PositionEncodePass::new(&ctx, &cfg, n, forward_buffers)).unwrap();
    let backward_buffers = HashGridBackwardBuffers {
        positions: &positions_buffer,
        encoding_grad: &encoding_grad,
        gradient: &gradient,
        table_offset: layout.hash_table.start,
    };
    let sh_layout = ShOutputLayout {
        samples_per_ray: 64,
        row_stride: 31,
        column_offset: 0,
        format: RowFormat::F32,
    };
    let sh_buffers = ShEncodeBuffers {
        directions: &directions,
        output: &color_in,
    };
    let sh_pass = pollster::block_on(ShEncodePass::new(&ctx, n, sh_layout, sh_buffers)).unwrap();

    eprintln!("adapter: {}", ctx.describe());
    eprintln!("default config (16 levels × 2^19 × 2, 2 octaves), {rays} rays × 64 samples = {n} samples");
    let runs = 5;
    let seconds = time_runs(&ctx, runs, &|encoder, timer| {
        let timestamp_writes = timer.and_then(|t| t.timestamp_writes("forward"));
        forward.record(&mut encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: None,
            timestamp_writes,
        }));
    });
    eprintln!(
        "position encoding forward: {:.3} ms, {:.2} M samples/s",
        seconds * 1e3,
        n as f64 / seconds / 1e6
    );
    let ways = [BackwardStrategy::MergeRuns, BackwardStrategy::PerSample]
        .into_iter()
        .flat_map(|strategy| atomic_adds(&ctx).into_iter().map(move |atomics| (strategy, atomics)));
    for (strategy, atomics) in ways {
        let backward = pollster::block_on(HashGridBackwardPass::with_atomics(
            &ctx,
            &cfg,
            n,
            backward_buffers,
            strategy,
            atomics,
        ))
        .unwrap();
        let seconds = time_runs(&ctx, runs, &|encoder, timer| {
            backward.record_clear(encoder);
            let timestamp_writes = timer.and_then(|t| t.timestamp_writes("backward"));
            backward.record(&mut encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: None,
                timestamp_writes,
            }));
        });
        eprintln!(
            "hash grid backward {strategy:?} {atomics:?} (incl. clearing 64 MiB only when wall-clock timed): {:.3} ms, {:.2} M samples/s",
            seconds * 1e3,
            n as f64 / seconds / 1e6
        );
    }
    let seconds = time_runs(&ctx, runs, &|encoder, timer| {
        let timestamp_writes = timer.and_then(|t| t.timestamp_writes("sh"));
        sh_pass.record(&mut encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: None,
            timestamp_writes,
        }));
    });
    eprintln!(
        "view direction SH: {:.3} ms, {:.2} M samples/s",
        seconds * 1e3,
        n as f64 / seconds / 1e6
    );
}
