//! `scribblefield bench`: throughput of the training step on whatever adapter is found, next to
//! a plain tiled matmul on the same adapter in the same run, and where a step's time goes.
use clap::Args;
use scribblefield::eval::bench::{bench_scene, mean_kept, mlp_gflop_per_step, step_report};
use scribblefield::field::gpu::trainer::Trainer;
use scribblefield::gpu::matmul_bench::matmul_bench;
use scribblefield::gpu::timing::Stopwatch;
use scribblefield::gpu::{GpuContext, GpuOptions};

use super::CliResult;
use super::field_config::FieldConfigArgs;

#[derive(Args)]
pub struct BenchArgs {
    /// Rays per batch (overrides the config's).
    #[arg(long)]
    rays: Option<u32>,
    #[command(flatten)]
    field: FieldConfigArgs,
    /// Timed training steps.
    #[arg(long, default_value_t = 5)]
    steps: u32,
    /// Untimed steps first (pipeline compilation, first touches of the buffers).
    #[arg(long, default_value_t = 2)]
    warmup: u32,
    /// Size n of the n x n x n reference matmul.
    #[arg(long, default_value_t = 512)]
    matmul: u32,
    /// Print one JSON object (docs/results/bench.md lists its fields) instead of the report.
    #[arg(long)]
    json: bool,
}

/// Milliseconds of GPU time per stage name, where the adapter has timestamp queries.
type StageTimes = Option<Vec<(String, f64)>>;

pub fn run(mut args: BenchArgs) -> CliResult {
    args.field.check()?;
    let ctx = GpuContext::new_blocking(&GpuOptions::from_env())?;
    if !args.json {
        println!("adapter:          {}", ctx.describe());
    }
    args.field.settle(&ctx);
    let mut cfg = args.field.resolve()?;
    if let Some(r) = args.rays {
        cfg.batch_rays = r;
    }
    // The demo scene has labels (synthetic scribbles) but no feature codes.
    let scene = bench_scene(&mut cfg)?;

    // Building the trainer uploads the scene and compiles every kernel of the step (the page
    // shows "building kernels" meanwhile).
    let build_clock = Stopwatch::start();
    let mut trainer = pollster::block_on(Trainer::new(&ctx, &scene, &cfg, 0))?;
    ctx.wait_idle()?;
    let build_seconds = build_clock.elapsed_seconds();
    let kernels_compiled = ctx.pipeline_cache_stats().compiled;
    trainer.train(args.warmup);
    ctx.wait_idle()?;
    let tally_before = pollster::block_on(trainer.kept_tally())?;
    let clock = Stopwatch::start();
    trainer.train(args.steps);
    ctx.wait_idle()?;
    let elapsed = clock.elapsed_seconds();
    let samples_to_heads = mean_kept(&tally_before, &pollster::block_on(trainer.kept_tally())?);
    let seconds = elapsed / f64::from(args.steps.max(1));
    let rays = f64::from(cfg.batch_rays);
    let samples = rays * cfg.samples_per_ray() as f64;
    let gflop = mlp_gflop_per_step(&trainer, samples_to_heads.unwrap_or(samples));
    let matmul = pollster::block_on(matmul_bench(&ctx, args.matmul, 3))?;
    let times: StageTimes = pollster::block_on(trainer.profile_step())?
        .map(|times| times.into_iter().map(|t| (t.name, t.seconds * 1e3)).collect());
    let shape = trainer.step_shape(samples_to_heads.unwrap_or(samples).round() as u64);
    if args.json {
        let mut report = step_report(
            &ctx,
            &trainer,
            args.steps,
            elapsed,
            Some(&matmul),
            times.as_deref(),
            samples_to_heads,
        );
        report.insert("config".into(), args.field.describe().into());
        report.insert("build_s".into(), build_seconds.into());
        report.insert("kernels_compiled".into(), kernels_compiled.into());
        let report = serde_json::Value::Object(report);
        println!("{report}");
        return Ok(());
    }
    println!(
        "config:           {}: {} rays x {} samples, {} hash levels, table 2^{}, widths {}/{}/{}/{}",
        args.field.describe(),
        cfg.batch_rays,
        cfg.samples_per_ray(),
        cfg.hash_levels,
        cfg.log2_hash_table_size,
        cfg.density_width,
        cfg.color_width,
        cfg.feature_width,
        cfg.semantic_width
    );
    println!("built:            {build_seconds:.2} s  (scene uploaded, {kernels_compiled} kernels compiled)");
    println!("step:             {:.4} s  ({:.2} steps/s)", seconds, 1.0 / seconds);
    println!("rays/s:           {:.0}", rays / seconds);
    println!("samples/s:        {:.0}", samples / seconds);
    println!(
        "to the heads:     {:.0} samples per step (of {samples:.0})",
        samples_to_heads.unwrap_or(samples)
    );
    println!(
        "MLP GFLOP/s:      {:.3}  ({gflop:.3} GFLOP of MLP products per step)",
        gflop / seconds
    );
    println!(
        "matmul GFLOP/s:   {:.3}  (n = {}, timed by {:?})",
        matmul.gflops, matmul.n, matmul.timed_by
    );
    println!(
        "ratio:            {:.2}  (trainer's MLP throughput / plain matmul)",
        gflop / seconds / matmul.gflops
    );
    let bytes: u64 = shape.iter().map(|s| s.bytes).sum::<u64>();
    let dispatches: u64 = shape.iter().map(|s| s.dispatches).sum();
    println!(
        "per step:         {:.3} GB through global memory (estimate), {dispatches} dispatches and a gradient clear",
        bytes as f64 / 1e9
    );
    match times {
        Some(times) => {
            let total: f64 = times.iter().map(|t| t.1).sum();
            println!("\nGPU time per stage of one step (timestamp queries):");
            for (name, ms) in &times {
                println!("  {:<24} {:>10.3} ms  {:>5.1} %", name, ms, 100.0 * ms / total);
            }
            println!("  {:<24} {:>10.3} ms", "total", total);
        }
        None => println!("\n(no timestamp queries on this adapter: no per-stage times)"),
    }
    Ok(())
}
