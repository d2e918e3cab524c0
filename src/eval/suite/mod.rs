//! The quality suite: the one way defaults are decided (docs/quality.md, "The quality suite").
//!
//! For every capture of [`captures::CAPTURES`] it draws strokes from ground truth with several
//! scribble sets, trains the budget preset (with feature supervision on baseline codes, as the
//! README recommends) over trainer seeds, with the strokes spread as the defaults say and with
//! the strokes alone, and scores every frame. A capture's ceiling is the same field trained on the
//! true masks of every frame. Runs go to worker threads, each with its own device.
pub mod captures;
pub mod report;
pub mod score;

use std::collections::VecDeque;
use std::path::Path;
use std::sync::Mutex;
use std::time::Instant;

use serde::{Deserialize, Serialize};

use crate::eval::Confusion;
use crate::eval::headless::{render_and_score, train_schedule};
use crate::field::gpu::trainer::Trainer;
use crate::field::{FieldConfig, Preset, finish};
use crate::gpu::{GpuContext, GpuOptions};
use crate::labels::synthetic::{ScribbleOptions, scribble_frames};
use crate::labels::{LabelSet, UNLABELLED, rasterize_frame};
use crate::refine::RefineOptions;
use crate::scene::Guide;
use crate::scene::{GT_VOID, Scene};
use crate::spread::check::{SpreadCheck, check_spread_now};
use crate::spread::propagate::propagate_labels;

pub use captures::{CAPTURES, Capture};
pub use report::{RunResult, SuiteReport};
use score::{SpreadFigures, add_boundary};

/// Refinements every run also scores its renders with, (rounds, votes), on every
/// [`VARIANT_EVERY`]th scored frame; 0 rounds is the field's own map.
pub const REFINE_VARIANTS: [(u32, bool); 7] = [
    (0, false),
    (1, false),
    (3, false),
    (10, false),
    (1, true),
    (3, true),
    (10, true),
];
pub const VARIANT_EVERY: usize = 4;

/// Warm-up steps (colour, depth and features) before the labels join.
pub const WARMUP: u32 = 100;

/// What a run trains on.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Mode {
    /// The strokes, spread as the config says (the defaults unless `--config` changes them).
    Spread,
    /// The strokes alone (`scribble_propagation.enabled: false`).
    StrokesOnly,
    /// The true masks of every frame: what the field can render on this capture.
    Ceiling,
}

impl Mode {
    pub fn name(self) -> &'static str {
        match self {
            Mode::Spread => "spread",
            Mode::StrokesOnly => "strokes only",
            Mode::Ceiling => "ceiling",
        }
    }
}

/// One training run of the suite.
#[derive(Clone, Copy, Debug)]
pub struct RunSpec {
    pub capture: &'static Capture,
    pub mode: Mode,
    /// Scribble seed (`scribble-from-gt --seed`).
    pub set: u64,
    /// Trainer seed.
    pub seed: u32,
}

/// What the suite runs.
#[derive(Clone, Debug)]
pub struct SuiteOptions {
    /// Captures by name (all of [`CAPTURES`] when empty).
    pub captures: Vec<String>,
    /// Runs per capture and mode: run i draws scribble set i and trains with trainer seed i, so
    /// the runs' spread covers both what the strokes and what the seed move.
    pub runs: u32,
    /// Also train each capture on the strokes alone.
    pub strokes_only: bool,
    /// Also measure the ceilings (one run per capture, seed 0).
    pub ceilings: bool,
    /// Replaces fields of the budget config for the runs (not the ceilings), as `--config`.
    pub config: Option<serde_json::Value>,
    /// Worker threads, each with its own device.
    pub jobs: usize,
    /// Where loaded captures are kept between runs (`Capture::load_cached`); None loads afresh.
    pub cache: Option<std::path::PathBuf>,
}

/// The runs `options` asks for, the slowest captures first so workers finish together.
pub fn plan(options: &SuiteOptions) -> Result<Vec<RunSpec>, String> {
    let chosen: Vec<&'static Capture> = if options.captures.is_empty() {
        CAPTURES.iter().collect()
    } else {
        options
            .captures
            .iter()
            .map(|name| {
                captures::capture(name).ok_or_else(|| {
                    let names: Vec<&str> = CAPTURES.iter().map(|c| c.name).collect();
                    format!("unknown capture {name:?}: one of {}", names.join(", "))
                })
            })
            .collect::<Result<_, _>>()?
    };
    let mut runs = Vec::new();
    for capture in chosen.iter().rev() {
        for i in 0..options.runs {
            let mut modes = vec![Mode::Spread];
            if options.strokes_only {
                modes.push(Mode::StrokesOnly);
            }
            for mode in modes {
                runs.push(RunSpec {
                    capture,
                    mode,
                    set: u64::from(i),
                    seed: i,
                });
            }
        }
        if options.ceilings {
            runs.push(RunSpec {
                capture,
                mode: Mode::Ceiling,
                set: 0,
                seed: 0,
            });
        }
    }
    Ok(runs)
}

/// The config a run of `capture` trains with: the budget preset with feature supervision, the
/// `overrides` on top (not for the ceiling), propagation off for the strokes alone, finished for
/// the scene.
pub fn run_config(scene: &Scene, mode: Mode, overrides: Option<&serde_json::Value>) -> Result<FieldConfig, String> {
    let mut cfg = FieldConfig {
        feature_supervision: true,
        ..Preset::Budget.config()
    };
    if let (Some(overrides), false) = (overrides, mode == Mode::Ceiling) {
        cfg = cfg.with_changes(overrides).map_err(|e| format!("--config: {e}"))?;
    }
    if mode != Mode::Spread {
        cfg.scribble_propagation.enabled = false;
    }
    let cfg = finish(cfg, scene, scene.classes.len()).config;
    cfg.validate().map_err(|e| e.to_string())?;
    Ok(cfg)
}

/// Runs `runs` on the captures' scenes (loaded from `data`), `options.jobs` at a time;
/// `progress` hears of every finished run. Captures whose data is absent are left out and named
/// in the report.
pub fn run(
    runs: Vec<RunSpec>,
    data: &Path,
    options: &SuiteOptions,
    mut progress: impl FnMut(&RunResult, usize, usize),
) -> Result<SuiteReport, String> {
    let mut wanted: Vec<&'static Capture> = Vec::new();
    for r in &runs {
        if !wanted.iter().any(|c| c.name == r.capture.name) {
            wanted.push(r.capture);
        }
    }
    let (scenes, skipped) = load(&wanted, data, options)?;
    let runs: Vec<RunSpec> = runs
        .into_iter()
        .filter(|r| scenes.iter().any(|(c, _)| c.name == r.capture.name))
        .collect();
    let total = runs.len();
    let queue = Mutex::new(runs.into_iter().collect::<VecDeque<_>>());
    let (send, receive) = std::sync::mpsc::channel::<Result<RunResult, String>>();
    let mut results = Vec::with_capacity(total);
    let mut device = String::new();
    std::thread::scope(|scope| -> Result<(), String> {
        for _ in 0..options.jobs.max(1).min(total.max(1)) {
            let (send, queue, scenes) = (send.clone(), &queue, &scenes);
            scope.spawn(move || {
                let ctx = match GpuContext::new_blocking(&GpuOptions::from_env()) {
                    Ok(ctx) => ctx,
                    Err(e) => {
                        let _ = send.send(Err(format!("no GPU device: {e}")));
                        return;
                    }
                };
                loop {
                    let Some(spec) = queue.lock().ok().and_then(|mut q| q.pop_front()) else {
                        return;
                    };
                    let scene = scenes.iter().find(|(c, _)| c.name == spec.capture.name).map(|(_, s)| s);
                    let result = match scene {
                        Some(scene) => run_one(&ctx, scene, &spec, options.config.as_ref()),
                        None => continue,
                    };
                    let failed = result.is_err();
                    if send.send(result).is_err() || failed {
                        return;
                    }
                }
            });
        }
        drop(send);
        for result in receive {
            let result = result?;
            if device.is_empty() {
                device = result.device.clone();
            }
            results.push(result);
            progress(results.last().expect("just pushed"), results.len(), total);
        }
        Ok(())
    })?;
    if results.len() < total {
        return Err(format!("only {} of {total} runs finished", results.len()));
    }
    Ok(SuiteReport::new(results, skipped, options, device))
}

/// Loaded captures with their scenes, and the names of those whose data is absent.
pub type Loaded = (Vec<(&'static Capture, Scene)>, Vec<String>);

/// The scenes of `captures` (through the cache when `options` has one), and the names of those
/// whose data is absent.
pub fn load(captures: &[&'static Capture], data: &Path, options: &SuiteOptions) -> Result<Loaded, String> {
    let loaded = in_parallel(captures.to_vec(), options.jobs, |capture| {
        let scene = match &options.cache {
            Some(cache) => capture.load_cached(data, cache),
            None => capture.load(data),
        };
        (capture, scene)
    });
    let (mut scenes, mut skipped) = (Vec::new(), Vec::new());
    for (capture, scene) in loaded {
        match scene? {
            Some(scene) => scenes.push((capture, scene)),
            None => skipped.push(capture.name.to_string()),
        }
    }
    Ok((scenes, skipped))
}

/// The strokes of scribble set `set` on `capture`'s drawn frames.
pub fn strokes(capture: &Capture, scene: &Scene, set: u64) -> LabelSet {
    scribble_frames(
        scene,
        capture.drawn,
        &ScribbleOptions {
            seed: set,
            ..Default::default()
        },
    )
}

/// Where the strokes of scribble set `set` spread on `scene` with the spreading options of
/// `cfg`, measured against the ground truth without training (seconds: the spreading's time).
pub fn spread_alone(
    capture: &Capture,
    scene: &Scene,
    set: u64,
    cfg: &FieldConfig,
) -> (SpreadFigures, SpreadCheck, f64) {
    let labels = strokes(capture, scene, set);
    let started = Instant::now();
    let maps = propagate_labels(scene, &labels, cfg.num_classes as usize, &cfg.scribble_propagation);
    let seconds = started.elapsed().as_secs_f64();
    let check = check_spread_now(scene, &labels, cfg.num_classes as usize, &cfg.scribble_propagation);
    (measure_spread(scene, &labels, &maps), check, seconds)
}

fn measure_spread(scene: &Scene, labels: &LabelSet, maps: &[(u32, Vec<u16>)]) -> SpreadFigures {
    let drawn: Vec<(u32, Vec<u16>)> = labels
        .frames
        .iter()
        .map(|f| {
            (
                f.frame,
                rasterize_frame(labels.frame(f.frame), scene.width, scene.height),
            )
        })
        .collect();
    SpreadFigures::measure(maps, &drawn, |f| {
        scene.frames.get(f as usize).and_then(|f| f.gt.as_ref())
    })
}

/// `f` over `items` on up to `jobs` threads, in the items' order.
pub fn in_parallel<T: Send, R: Send>(items: Vec<T>, jobs: usize, f: impl Fn(T) -> R + Sync) -> Vec<R> {
    let queue = Mutex::new(items.into_iter().enumerate().collect::<VecDeque<_>>());
    let out = Mutex::new(Vec::new());
    std::thread::scope(|scope| {
        for _ in 0..jobs.max(1) {
            scope.spawn(|| {
                while let Some((i, item)) = queue.lock().ok().and_then(|mut q| q.pop_front()) {
                    let r = f(item);
                    if let Ok(mut out) = out.lock() {
                        out.push((i, r));
                    }
                }
            });
        }
    });
    let mut out = out.into_inner().unwrap_or_default();
    out.sort_by_key(|(i, _)| *i);
    out.into_iter().map(|(_, r)| r).collect()
}

/// Trains and scores one run.
pub fn run_one(
    ctx: &GpuContext,
    scene: &Scene,
    spec: &RunSpec,
    overrides: Option<&serde_json::Value>,
) -> Result<RunResult, String> {
    let started = Instant::now();
    let capture = spec.capture;
    let cfg = run_config(scene, spec.mode, overrides)?;
    let mut trainer = pollster::block_on(Trainer::new(ctx, scene, &cfg, spec.seed)).map_err(|e| e.to_string())?;
    let labels = strokes(capture, scene, spec.set);
    let gpu = |e: crate::gpu::GpuError| format!("{}: {e}", capture.name);
    if spec.mode == Mode::Ceiling {
        train_schedule(&mut trainer, scene, &labels, WARMUP, 0, |_, _, _| {}).map_err(gpu)?;
        trainer.set_label_maps(true_maps(scene), scene).map_err(gpu)?;
        for _ in 0..capture.steps / 10 {
            trainer.train(10);
        }
        trainer.losses_blocking().map_err(gpu)?;
    } else {
        // `segment`'s schedule: the labels join after the warm-up.
        train_schedule(&mut trainer, scene, &labels, WARMUP, capture.steps, |_, _, _| {}).map_err(gpu)?;
    }
    let spread = measure_spread(scene, &labels, trainer.label_maps());
    let trained = started.elapsed().as_secs_f64();
    let names: Vec<String> = scene.classes.iter().map(|c| c.name.clone()).collect();
    let refine = RefineOptions::for_scene(scene);
    let mut refined = Confusion::new(names.len());
    let mut boundary = Confusion::new(names.len());
    // The same renders refined otherwise, on every `VARIANT_EVERY`th scored frame: refinement's
    // defaults are decided on identical fields, at no extra training.
    let mut variants: Vec<(String, RefineOptions, Confusion)> = REFINE_VARIANTS
        .iter()
        .map(|&(rounds, votes)| {
            let name = format!("{} {rounds}", if votes { "votes" } else { "probabilities" });
            let options = RefineOptions {
                iterations: rounds,
                votes,
                ..refine
            };
            (name, options, Confusion::new(names.len()))
        })
        .collect();
    let scored = capture.scored(scene.frames.len());
    let field = render_and_score(
        &mut trainer,
        scene,
        &names,
        scored,
        &RefineOptions::OFF,
        |i, rendered| {
            let (Some(guide), Some(gt)) = (Guide::of_frame(scene, i), scene.frames[i].gt.as_ref()) else {
                return;
            };
            if (i - capture.first_scored).is_multiple_of(VARIANT_EVERY) {
                for (_, options, confusion) in &mut variants {
                    let mut other = rendered.clone();
                    if other.refine(guide, options).is_ok() {
                        confusion.add(gt.as_raw(), &other.classes);
                    }
                }
            }
            let mut rendered = rendered;
            if rendered.refine(guide, &refine).is_ok() {
                refined.add(gt.as_raw(), &rendered.classes);
                add_boundary(&mut boundary, gt, &rendered.classes);
            }
        },
    )
    .map_err(gpu)?;
    let refined = refined.report(&names, field.frames);
    let boundary = boundary.report(&names, field.frames);
    let refine_variants = variants
        .iter()
        .map(|(name, _, c)| (name.clone(), c.report(&names, field.frames).mean_iou))
        .collect();
    Ok(RunResult {
        capture: capture.name.to_string(),
        mode: spec.mode,
        set: spec.set,
        seed: spec.seed,
        mean_iou: refined.mean_iou,
        field_mean_iou: field.mean_iou,
        class_iou: refined.classes.iter().map(|c| c.iou).collect(),
        boundary_iou: boundary.mean_iou,
        pixel_accuracy: refined.pixel_accuracy,
        spread: (spec.mode == Mode::Spread).then_some(spread),
        check: trainer.spread_check(),
        withheld: trainer.spread_withheld(),
        opacity_far_class: trainer.opacity_far_class(),
        seconds: started.elapsed().as_secs_f64(),
        train_seconds: trained,
        refine_rounds: refine.iterations,
        refine_variants,
        device: ctx.describe(),
    })
}

/// The ground truth of every frame as label maps (void pixels unlabelled).
fn true_maps(scene: &Scene) -> Vec<(u32, Vec<u16>)> {
    scene
        .frames
        .iter()
        .enumerate()
        .filter_map(|(i, f)| {
            let gt = f.gt.as_ref()?;
            let map = gt
                .as_raw()
                .iter()
                .map(|&g| if g == GT_VOID { UNLABELLED } else { u16::from(g) })
                .collect();
            Some((i as u32, map))
        })
        .collect()
}
