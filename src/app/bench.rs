//! The page's bench (`#bench=PRESET[&bench-steps=N][&bench-inflight=N][&rays=N][&kernels=...]`,
//! figures in docs/results/bench.md): instead of the annotator, trains a preset on the built-in
//! demo scene with synthetic scribbles (the scene and labels of `scribblefield bench`,
//! `eval::bench`) on the page's own WebGPU device, in batches as the page trains while the user
//! annotates (`training::batches`: the same batch sizing, up to two batches in flight, a yield to
//! the browser and a repaint at the page's interval between batches), and reports the figures of
//! `bench --json` that apply on `<body data-bench="...">` (JSON): while it runs
//! `{"state":"running","stage":...}`, then `{"state":"done",...}` with the report, or
//! `{"state":"error","message":...}`. Browsers offer no timestamp queries by default, so the
//! stages' `gpu_ms` are `null` here; `page` says how the page's thread spent the timed steps.
use std::cell::RefCell;
use std::rc::Rc;

use egui::RichText;
use serde_json::{Map, Value, json};

use super::browser::{self, now_ms};
use super::page_options::PageOptions;
use super::page_status;
use super::status::PageStatus;
use super::training::batches::{Batches, MAX_BATCH, stage_wall_ms};
use super::training::device::gpu_done;
use crate::eval::bench::{bench_scene, mean_kept, step_report};
use crate::field::Preset;
use crate::field::gpu::trainer::Trainer;
use crate::gpu::matmul_bench::matmul_bench;
use crate::gpu::{GpuContext, KernelFamily};

/// Untimed steps first, as `bench`'s default `--warmup` (pipeline compilation, first touches).
const WARMUP_STEPS: u32 = 2;
/// Timed steps without `bench-steps=`, as `bench`'s default `--steps`.
const DEFAULT_STEPS: u32 = 5;
/// Size of the plain matmul, as `bench`'s default `--matmul`.
const MATMUL_N: u32 = 512;
/// The longest wait for the page to paint a new stage.
const PAINT_WAIT_MS: f64 = 2000.0;

/// What the bench runs: from the page's options.
#[derive(Clone, Copy, Debug)]
struct BenchPlan {
    preset: Preset,
    steps: u32,
    /// Batches in flight; by default as the page's training task keeps them on this device.
    in_flight: Option<usize>,
    rays: Option<u32>,
    kernels: Option<KernelFamily>,
}

/// What the page shows and the bench task updates.
#[derive(Default)]
struct Shown {
    stage: String,
    steps: u32,
    report: Option<String>,
    error: Option<String>,
    /// Frames painted since the page opened.
    painted: u32,
    /// Frames painted and the page thread's time in them while the timed steps ran.
    frames: u32,
    paint_ms: f64,
    timing: bool,
}

pub struct BenchApp {
    shown: Rc<RefCell<Shown>>,
}

impl BenchApp {
    /// Starts the bench of `preset` (the page's `bench=`) on eframe's device.
    pub fn new(cc: &eframe::CreationContext<'_>, preset: Preset, options: &PageOptions) -> BenchApp {
        let plan = BenchPlan {
            preset,
            steps: options.bench_steps.unwrap_or(DEFAULT_STEPS),
            in_flight: options.bench_inflight.map(|n| n as usize),
            rays: options.rays,
            kernels: options.kernels,
        };
        let shown: Rc<RefCell<Shown>> = Rc::default();
        let gpu = cc
            .wgpu_render_state
            .as_ref()
            .map(|rs| GpuContext::from_device(rs.device.clone(), rs.queue.clone()));
        let egui_ctx = cc.egui_ctx.clone();
        let task_shown = shown.clone();
        wasm_bindgen_futures::spawn_local(async move {
            let result = match gpu {
                Some(gpu) => run(gpu, plan, &egui_ctx, &task_shown).await,
                None => Err("no WebGPU device: nothing to bench".to_string()),
            };
            let mut shown = task_shown.borrow_mut();
            match result {
                Ok(report) => {
                    let text = Value::Object(report).to_string();
                    web_sys::console::log_1(&format!("scribblefield bench: {text}").into());
                    page_status::set_bench(&text);
                    shown.report = Some(text);
                }
                Err(message) => {
                    page_status::set_bench(&json!({"state": "error", "message": message}).to_string());
                    page_status::set(&PageStatus::Error {
                        message: format!("bench: {message}"),
                    });
                    shown.error = Some(message);
                }
            }
            egui_ctx.request_repaint();
        });
        BenchApp { shown }
    }
}

/// Says what the bench is doing, on `data-bench` and in the page.
fn stage(shown: &RefCell<Shown>, egui_ctx: &egui::Context, name: &str) {
    page_status::set_bench(&json!({"state": "running", "stage": name}).to_string());
    shown.borrow_mut().stage = name.to_string();
    egui_ctx.request_repaint();
}

/// Waits until the page has painted (at most [`PAINT_WAIT_MS`]) and the GPU has finished the
/// paint: on a CPU device one paint holds the device for tens of milliseconds, and the one
/// showing a new stage must not land in that stage's first timed step. The page's own repaints
/// while training stay in the timings (`frames_painted`).
async fn settle_paint(gpu: &GpuContext, shown: &RefCell<Shown>) {
    // egui may paint twice (a second pass), and the browser composites each painted frame after
    // it, on SwiftShader on the same cores: wait for a paint, then for two frames without one.
    let before = shown.borrow().painted;
    let start = now_ms();
    loop {
        let painted = shown.borrow().painted;
        browser::next_animation_frame().await;
        browser::next_animation_frame().await;
        let now = shown.borrow().painted;
        if (now == painted && now != before) || now_ms() - start > PAINT_WAIT_MS {
            break;
        }
    }
    gpu_done(&gpu.queue).await;
}

async fn run(
    gpu: GpuContext,
    plan: BenchPlan,
    egui_ctx: &egui::Context,
    shown: &RefCell<Shown>,
) -> Result<Map<String, Value>, String> {
    let gpu = match plan.kernels {
        Some(kernels) => gpu.with_kernels(kernels),
        None => gpu,
    };
    // As the annotator asks while training: on a CPU rasterizer a repaint costs about a second
    // of the device the steps run on.
    let repaint = std::time::Duration::from_millis(gpu.profile().training_repaint_ms);
    stage(shown, egui_ctx, "scene");
    // Let the page show it before the scene's rendering holds the thread.
    browser::sleep_ms(20).await;
    let mut cfg = plan.preset.config();
    if let Some(rays) = plan.rays {
        cfg.batch_rays = rays;
    }
    let scene = bench_scene(&mut cfg).map_err(|e| format!("the bench scene: {e}"))?;
    stage(shown, egui_ctx, "kernels");
    let mut trainer = Trainer::new(&gpu, &scene, &cfg, 0)
        .await
        .map_err(|e| format!("cannot start training: {e}"))?;

    let mut batches = Batches::for_device(&gpu, false);
    if let Some(depth) = plan.in_flight {
        batches.depth = depth;
    }
    stage(shown, egui_ctx, "warm-up");
    let mut warm = 0;
    while warm < WARMUP_STEPS {
        warm += batches.run(&gpu, &mut trainer, WARMUP_STEPS - warm).await.steps;
    }
    batches.drain().await;
    batches.rate.reset();
    let tally_before = trainer.kept_tally().await.ok();

    stage(shown, egui_ctx, "timed");
    settle_paint(&gpu, shown).await;
    {
        let mut s = shown.borrow_mut();
        s.timing = true;
        s.frames = 0;
        s.paint_ms = 0.0;
    }
    let start = now_ms();
    let (mut done, mut count, mut record_ms, mut wait_ms, mut yield_ms) = (0, 0u32, 0.0, 0.0, 0.0);
    let mut largest = 0;
    // Per batch: steps, recording ms, waiting ms, and for the batch that finished meanwhile its
    // steps, GPU share and end (ms from the start).
    let mut log = Vec::new();
    while done < plan.steps {
        let times = batches
            .run(&gpu, &mut trainer, (plan.steps - done).min(MAX_BATCH))
            .await;
        log.push(json!([
            times.steps,
            round2(times.record_ms),
            round2(times.wait_ms),
            times
                .finished
                .map(|f| json!([f.steps, round2(f.gpu_ms), round2(f.done_ms - start)]))
        ]));
        done += times.steps;
        count += 1;
        largest = largest.max(times.steps);
        record_ms += times.record_ms;
        wait_ms += times.wait_ms;
        shown.borrow_mut().steps = done;
        egui_ctx.request_repaint_after(repaint);
        let before = now_ms();
        batches.yield_to_page().await;
        yield_ms += now_ms() - before;
    }
    let before = now_ms();
    let end = batches.drain().await.map_or_else(now_ms, |f| f.done_ms);
    wait_ms += now_ms() - before;
    let seconds = (end - start).max(0.001) / 1000.0;
    let (frames, paint_ms) = {
        let mut s = shown.borrow_mut();
        s.timing = false;
        (s.frames, s.paint_ms)
    };
    let losses = trainer.poll_losses().map_err(|e| format!("reading the losses: {e}"))?;
    let tally_after = trainer.kept_tally().await.ok();
    let samples_to_heads = tally_before
        .zip(tally_after)
        .and_then(|(before, after)| mean_kept(&before, &after));

    // Where a step's time goes, by the wall clock: one step alone, then each stage alone.
    stage(shown, egui_ctx, "stages");
    settle_paint(&gpu, shown).await;
    let before = now_ms();
    trainer.train(1);
    gpu_done(&gpu.queue).await;
    let single_step_ms = now_ms() - before;
    let walls = stage_wall_ms(&gpu, &mut trainer, 1).await;

    stage(shown, egui_ctx, "matmul");
    let matmul = matmul_bench(&gpu, MATMUL_N, 3)
        .await
        .map_err(|e| format!("the plain matmul: {e}"))?;
    let mut report = step_report(
        &gpu,
        &trainer,
        plan.steps,
        seconds,
        Some(&matmul),
        None,
        samples_to_heads,
    );
    // Each stage's wall-clock time alone (summed where a name repeats), beside its `gpu_ms`.
    if let Some(Value::Array(stages)) = report.get_mut("stages") {
        for entry in stages.iter_mut() {
            let name = entry["name"].as_str().unwrap_or_default().to_string();
            let ms: f64 = walls.iter().filter(|w| w.0 == name).map(|w| w.1).sum();
            entry["wall_ms"] = json!(round2(ms));
        }
    }
    let per_step = |ms: f64| ms / f64::from(plan.steps);
    report.insert("state".into(), "done".into());
    report.insert("config".into(), plan.preset.name().into());
    report.insert(
        "loss_per_ray".into(),
        losses.map_or(Value::Null, |l| json!(l.terms.total() / f64::from(cfg.batch_rays))),
    );
    report.insert(
        "page".into(),
        json!({
            "in_flight": batches.depth,
            "single_step_ms": round2(single_step_ms),
            "stages_wall_ms": round2(walls.iter().map(|w| w.1).sum()),
            "batches": count,
            "largest_batch": largest,
            "record_ms_per_step": per_step(record_ms),
            "wait_ms_per_step": per_step(wait_ms),
            "yield_ms_per_step": per_step(yield_ms),
            "frames_painted": frames,
            "paint_cpu_ms_per_step": per_step(paint_ms),
            "log": log,
        }),
    );
    Ok(report)
}

impl eframe::App for BenchApp {
    fn ui(&mut self, ui: &mut egui::Ui, _frame: &mut eframe::Frame) {
        let start = now_ms();
        egui::CentralPanel::default().show(ui, |ui| {
            let shown = self.shown.borrow();
            ui.heading("scribblefield bench");
            ui.label("Training the demo scene as the page does; the report goes on <body data-bench>.");
            ui.separator();
            if let Some(error) = &shown.error {
                ui.colored_label(egui::Color32::LIGHT_RED, error);
            } else if let Some(report) = &shown.report {
                ui.label(RichText::new(report).monospace().small());
            } else {
                ui.label(format!("{}: {} steps", shown.stage, shown.steps));
            }
        });
        let mut shown = self.shown.borrow_mut();
        shown.painted += 1;
        if shown.timing {
            shown.frames += 1;
            shown.paint_ms += now_ms() - start;
        }
    }
}

fn round2(x: f64) -> f64 {
    (x * 100.0).round() / 100.0
}
