//! What `scribblefield bench` and the page's bench mode (`#bench=PRESET`, `app::bench`) share:
//! the scene and labels a bench trains on, and the figures of a report, so the two measure the
//! same thing and name it the same way (docs/results/bench.md lists the fields).
use serde_json::{Map, Value, json};

use crate::field::FieldConfig;
use crate::field::gpu::encoding::AtomicAdd;
use crate::field::gpu::trainer::{StageShape, Trainer};
use crate::gpu::GpuContext;
use crate::gpu::matmul_bench::MatmulBenchReport;
use crate::labels::synthetic::{ScribbleOptions, scribble_frames};
use crate::scene::Scene;
use crate::scene::demo::{DemoOptions, demo_scene};

/// Frames of the demo scene that carry the bench's synthetic scribbles.
pub const SCRIBBLED_FRAMES: [u32; 2] = [0, 12];

/// The demo scene (default options: no feature codes) with synthetic scribbles on
/// [`SCRIBBLED_FRAMES`], and `cfg` finished for it (`field::finish`): its classes, no feature
/// supervision.
pub fn bench_scene(cfg: &mut FieldConfig) -> Result<Scene, Box<dyn std::error::Error>> {
    let mut scene = demo_scene(&DemoOptions::default())?;
    scene.labels = Some(scribble_frames(&scene, &SCRIBBLED_FRAMES, &ScribbleOptions::default()));
    *cfg = crate::field::finish(cfg.clone(), &scene, scene.classes.len()).config;
    cfg.validate()?;
    Ok(scene)
}

/// Multiply-adds of one sample through every MLP, forward.
pub fn mlp_macs_per_sample(trainer: &Trainer) -> f64 {
    trainer
        .layout()
        .mlps()
        .iter()
        .flat_map(|(_, mlp)| mlp.layers.iter().map(|r| r.len() as f64))
        .sum()
}

/// MLP products of one step, GFLOP: forward, input gradient and weight gradient, three products
/// of the same size; the density MLP over every sample, the heads over the
/// `samples_to_heads` that reach them.
pub fn mlp_gflop_per_step(trainer: &Trainer, samples_to_heads: f64) -> f64 {
    let cfg = trainer.config();
    let samples = f64::from(cfg.batch_rays) * cfg.samples_per_ray() as f64;
    let density: f64 = trainer.layout().density.layers.iter().map(|r| r.len() as f64).sum();
    let heads = mlp_macs_per_sample(trainer) - density;
    3.0 * 2.0 * (density * samples + heads * samples_to_heads) / 1e9
}

/// Mean samples that reached the heads per batch between two reads of
/// `Trainer::kept_tally` (`None` when no batch ran between them).
pub fn mean_kept(before: &[u32], after: &[u32]) -> Option<f64> {
    let (sum0, runs0) = (*before.first()?, *before.get(1)?);
    let (sum1, runs1) = (*after.first()?, *after.get(1)?);
    let runs = runs1.wrapping_sub(runs0);
    (runs > 0).then(|| f64::from(sum1.wrapping_sub(sum0)) / f64::from(runs))
}

/// The report's fields for `steps` steps timed over `seconds` (wall clock), in `bench --json`'s
/// names: the batch, the rates, the step's estimated traffic and dispatches, the MLP rate, and,
/// when given, the plain matmul's rate and the ratio to it. `stage_ms` are GPU milliseconds per
/// stage name where timestamp queries measured them. `samples_to_heads`: the mean samples per
/// step that reached the heads over the timed steps ([`mean_kept`]; `None`: all of them), which
/// the traffic and the MLP products are counted for. With the adapter and the dense kernels'
/// family (`uniform` on CPU devices, `tiled` on GPUs) and the hash backward's atomic add
/// (`float`, `fixed_point`, `compare_exchange` or `per_level`: `AtomicAdd::best_for`); the caller adds
/// `config`.
pub fn step_report(
    ctx: &GpuContext,
    trainer: &Trainer,
    steps: u32,
    seconds: f64,
    matmul: Option<&MatmulBenchReport>,
    stage_ms: Option<&[(String, f64)]>,
    samples_to_heads: Option<f64>,
) -> Map<String, Value> {
    let cfg = trainer.config();
    let step_s = seconds / f64::from(steps.max(1));
    let rays = f64::from(cfg.batch_rays);
    let samples = rays * cfg.samples_per_ray() as f64;
    let to_heads = samples_to_heads.unwrap_or(samples).min(samples);
    let gflop = mlp_gflop_per_step(trainer, to_heads);
    let shape = trainer.step_shape(to_heads.round() as u64);
    let stages: Vec<Value> = stage_names(&shape)
        .into_iter()
        .map(|name| {
            let of_name = shape.iter().filter(|s| s.name == name);
            let ms = stage_ms.and_then(|t| t.iter().find(|t| t.0 == name).map(|t| t.1));
            json!({
                "name": name,
                "gpu_ms": ms,
                "dispatches": of_name.clone().map(|s| s.dispatches).sum::<u64>(),
                "bytes": of_name.map(|s| s.bytes).sum::<u64>(),
            })
        })
        .collect();
    let Value::Object(mut fields) = json!({
        "adapter": ctx.describe(),
        "kernels": ctx.profile().kernels.name(),
        "hash_atomics": match trainer.hash_atomics() {
            AtomicAdd::Float => "float",
            AtomicAdd::FixedPoint => "fixed_point",
            AtomicAdd::CompareExchange => "compare_exchange",
            AtomicAdd::PerLevel => "per_level",
        },
        "rays": cfg.batch_rays,
        "samples_per_ray": cfg.samples_per_ray(),
        "steps_timed": steps,
        "step_s": step_s,
        "steps_per_s": 1.0 / step_s,
        "rays_per_s": rays / step_s,
        "samples_per_s": samples / step_s,
        // The mean kept by the keep stage over the timed steps (FieldConfig::head_weight_threshold).
        "samples_to_heads_per_step": to_heads,
        "bytes_per_step": shape.iter().map(|s| s.bytes).sum::<u64>(),
        "dispatches_per_step": shape.iter().map(|s| s.dispatches).sum::<u64>(),
        "mlp_gflop_per_step": gflop,
        "mlp_gflops": gflop / step_s,
    }) else {
        unreachable!("a JSON object literal")
    };
    if let Some(m) = matmul {
        fields.insert("matmul_gflops".into(), json!(m.gflops));
        fields.insert("matmul_n".into(), json!(m.n));
        fields.insert("ratio_to_matmul".into(), json!(gflop / step_s / m.gflops));
    }
    fields.insert("stages".into(), Value::Array(stages));
    fields
}

/// Stage names in step order, each once (both glue gathers are "glue backward").
pub fn stage_names(shape: &[StageShape]) -> Vec<&'static str> {
    let mut names = Vec::new();
    for s in shape {
        if !names.contains(&s.name) {
            names.push(s.name);
        }
    }
    names
}
