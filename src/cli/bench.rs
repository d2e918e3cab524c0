//! `scribblefield bench`: throughput of the training step on whatever adapter is found, next to
//! a plain tiled matmul on the same adapter in the same run, and where a step's time goes.
use clap::Args;
use scribblefield::field::gpu::trainer::Trainer;
use scribblefield::gpu::matmul_bench::matmul_bench;
use scribblefield::gpu::timing::Stopwatch;
use scribblefield::gpu::{GpuContext, GpuOptions};
use scribblefield::labels::synthetic::{ScribbleOptions, scribble_frames};
use scribblefield::scene::demo::{DemoOptions, demo_scene};

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
}

/// Multiply-adds of one sample through every MLP, forward.
fn mlp_macs_per_sample(trainer: &Trainer) -> f64 {
    trainer
        .layout()
        .mlps()
        .iter()
        .flat_map(|(_, mlp)| mlp.layers.iter().map(|r| r.len() as f64))
        .sum()
}

pub fn run(mut args: BenchArgs) -> CliResult {
    args.field.check()?;
    let ctx = GpuContext::new_blocking(&GpuOptions::from_env())?;
    println!("adapter:          {}", ctx.describe());
    args.field.settle(&ctx);
    let mut cfg = args.field.resolve(0, None)?;
    if let Some(r) = args.rays {
        cfg.batch_rays = r;
    }
    // The demo scene has labels (synthetic scribbles) but no feature codes.
    let mut scene = demo_scene(&DemoOptions::default())?;
    scene.labels = Some(scribble_frames(&scene, &[0, 12], &ScribbleOptions::default()));
    cfg.num_classes = scene.classes.len() as u32;
    cfg.feature_supervision = false;
    cfg.validate()?;

    let mut trainer = pollster::block_on(Trainer::new(&ctx, &scene, &cfg, 0))?;
    trainer.train(args.warmup);
    ctx.wait_idle()?;
    let clock = Stopwatch::start();
    trainer.train(args.steps);
    ctx.wait_idle()?;
    let seconds = clock.elapsed_seconds() / f64::from(args.steps.max(1));
    let rays = f64::from(cfg.batch_rays);
    let samples = rays * cfg.samples_per_ray() as f64;
    // Forward, input gradient and weight gradient: three products of the same size.
    let gflop = 3.0 * 2.0 * mlp_macs_per_sample(&trainer) * samples / 1e9;
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
    println!("step:             {:.4} s  ({:.2} steps/s)", seconds, 1.0 / seconds);
    println!("rays/s:           {:.0}", rays / seconds);
    println!("samples/s:        {:.0}", samples / seconds);
    println!(
        "MLP GFLOP/s:      {:.3}  ({gflop:.3} GFLOP of MLP products per step)",
        gflop / seconds
    );
    let matmul = pollster::block_on(matmul_bench(&ctx, args.matmul, 3))?;
    println!(
        "matmul GFLOP/s:   {:.3}  (n = {}, timed by {:?})",
        matmul.gflops, matmul.n, matmul.timed_by
    );
    println!(
        "ratio:            {:.2}  (trainer's MLP throughput / plain matmul)",
        gflop / seconds / matmul.gflops
    );
    match pollster::block_on(trainer.profile_step())? {
        Some(times) => {
            let total: f64 = times.iter().map(|t| t.seconds).sum();
            println!("\nGPU time per stage of one step (timestamp queries):");
            for t in &times {
                println!(
                    "  {:<24} {:>10.3} ms  {:>5.1} %",
                    t.name,
                    t.seconds * 1e3,
                    100.0 * t.seconds / total
                );
            }
            println!("  {:<24} {:>10.3} ms", "total", total * 1e3);
        }
        None => println!("\n(no timestamp queries on this adapter: no per-stage times)"),
    }
    Ok(())
}
