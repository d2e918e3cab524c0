use std::path::{Path, PathBuf};

use clap::{Args, ValueEnum};
use scribblefield::eval::simulate::{self, FrameSplit, RunOptions, SceneId, SimEvent, SimulateSettings};
use scribblefield::field::FieldConfig;
use scribblefield::gpu::GpuContext;
use scribblefield::scene::Scene;

use super::{CliResult, progress};

/// The base field config, before `--config` changes fields of it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum Preset {
    /// DESIGN §5 (hash table 2^19, widths 128, 4096 rays): for a real GPU.
    Default,
    /// 8 levels, 2^14 table, widths 32, 1024 rays.
    Small,
    /// The quality tests' CPU budget: `small` with 256 rays of 4 + 12 samples, no feature
    /// supervision, annotating lr 5e-3 (about 0.2-0.5 s a step on lavapipe).
    Budget,
}

/// The simulated user's schedule, shared by `simulate` and `ablate`.
#[derive(Args, Clone, Debug)]
pub struct SimArgs {
    /// Base field config; `--config` overrides fields of it.
    #[arg(long, value_enum, default_value_t = Preset::Default)]
    pub preset: Preset,
    /// Field config as JSON: fields given replace the preset's (`adam` and `loss` field by field,
    /// `encoding` as a whole); see `FieldConfig`.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Stop once this many clicks are labelled (a rerun with a larger budget continues).
    #[arg(long, default_value_t = 100)]
    pub budget: u32,
    /// Wrongly predicted pixels labelled per round.
    #[arg(long, default_value_t = 5)]
    pub clicks_per_round: u32,
    /// Training steps after each round's clicks.
    #[arg(long, default_value_t = 250)]
    pub steps_per_round: u32,
    /// Steps without labels before the first click (colour, depth and features only).
    #[arg(long, default_value_t = 100)]
    pub warmup: u32,
    /// Score the held-out frames every this many rounds (and after the last).
    #[arg(long, default_value_t = 1)]
    pub eval_every: u32,
    /// Hold out every N-th frame for scoring (frames N-1, 2N-1, ...); the others are clicked on.
    #[arg(long, default_value_t = 3, conflicts_with = "held_out")]
    pub held_out_every: u32,
    /// Hold out exactly these frames instead, e.g. `2,5,8`.
    #[arg(long, value_delimiter = ',')]
    pub held_out: Option<Vec<u32>>,
    /// Brush radius of a click in pixels; 0.5 labels exactly the clicked pixel.
    #[arg(long, default_value_t = 0.5)]
    pub click_radius: f32,
    /// Seed of the trainer and of the clicks.
    #[arg(long, default_value_t = 0)]
    pub seed: u32,
    /// Discard a previous run in the output folder instead of continuing it.
    #[arg(long)]
    pub restart: bool,
}

#[derive(Args)]
pub struct SimulateArgs {
    /// Scene archive with ground truth.
    archive: PathBuf,
    /// Output folder: curve.csv, labels.json, simulate.json (resume state), trainer.bin.
    #[arg(short, long)]
    output: PathBuf,
    #[command(flatten)]
    sim: SimArgs,
}

pub fn run(args: SimulateArgs) -> CliResult {
    let (scene, id) = read_scene(&args.archive)?;
    let mut cfg = base_config(&args.sim, &scene)?;
    if scene.features.is_none() && cfg.feature_supervision {
        eprintln!(
            "note: {} has no feature codes; training without feature supervision",
            args.archive.display()
        );
        cfg.feature_supervision = false;
    }
    let settings = settings(&args.sim, &scene, id, cfg).map_err(|e| format!("{}: {e}", args.archive.display()))?;
    let ctx = GpuContext::new_blocking(&scribblefield::gpu::GpuOptions::from_env())?;
    eprintln!("training on {}", ctx.describe());
    let state = run_one(&ctx, &scene, &settings, &args.sim, &args.output)?;
    if let Some(why) = &state.stopped {
        println!("stopped early: {why}");
    }
    if let Some(p) = state.curve.last() {
        println!(
            "{} clicks in {} rounds: mean IoU {:.4}, pixel accuracy {:.4} (held-out frames {:?})",
            p.clicks, p.round, p.mean_iou, p.pixel_acc, state.settings.frames.held_out
        );
    }
    println!("wrote {}", args.output.join(simulate::CURVE_FILE).display());
    Ok(())
}

/// Reads an archive and its identity for resuming.
pub fn read_scene(archive: &Path) -> Result<(Scene, SceneId), Box<dyn std::error::Error>> {
    let bytes = std::fs::read(archive).map_err(|e| format!("{}: {e}", archive.display()))?;
    let name = archive.display().to_string();
    let scene = scribblefield::scene::read_archive(&bytes, &name)?;
    if !scene.has_gt() || scene.classes.is_empty() {
        return Err(format!(
            "{}: has no ground truth; the simulated user labels its clicks from it (pack a capture with gt/ and classes.txt, or use `demo-scene`)",
            archive.display()
        )
        .into());
    }
    let id = SceneId::new(&bytes, &scene);
    Ok((scene, id))
}

/// The preset with `--config` applied and `num_classes` from the scene.
pub fn base_config(sim: &SimArgs, scene: &Scene) -> Result<FieldConfig, Box<dyn std::error::Error>> {
    let classes = scene.classes.len() as u32;
    let preset = match sim.preset {
        Preset::Default => FieldConfig::default(),
        Preset::Small => FieldConfig::small(),
        Preset::Budget => scribblefield::eval::headless::budget_config(classes),
    };
    let mut cfg = match &sim.config {
        Some(path) => {
            let text = std::fs::read(path).map_err(|e| format!("--config {}: {e}", path.display()))?;
            let changes: serde_json::Value =
                serde_json::from_slice(&text).map_err(|e| format!("--config {}: {e}", path.display()))?;
            apply_config_changes(&preset, &changes).map_err(|e| format!("--config {}: {e}", path.display()))?
        }
        None => preset,
    };
    cfg.num_classes = classes;
    // The rendered feature f is compared with the archive's codes: their width decides.
    if let Some(codes) = &scene.features {
        cfg.feature_dim = codes.dim;
    }
    cfg.validate()?;
    Ok(cfg)
}

/// `base` with the fields of the JSON object `changes` replaced: nested objects (`adam`, `loss`)
/// field by field, `encoding` (a tagged choice) as a whole. Unknown fields are an error.
pub fn apply_config_changes(base: &FieldConfig, changes: &serde_json::Value) -> Result<FieldConfig, String> {
    use serde_json::Value;
    let Value::Object(changes) = changes else {
        return Err("must be a JSON object of FieldConfig fields".into());
    };
    let mut merged = serde_json::to_value(base).expect("configs serialize");
    let Value::Object(fields) = &mut merged else {
        unreachable!("a config serializes to an object")
    };
    for (key, value) in changes {
        match (fields.get_mut(key), value) {
            (Some(Value::Object(inner)), Value::Object(new)) if key != "encoding" => {
                for (k, v) in new {
                    inner.insert(k.clone(), v.clone());
                }
            }
            _ => {
                fields.insert(key.clone(), value.clone());
            }
        }
    }
    serde_json::from_value(merged).map_err(|e| e.to_string())
}

pub fn settings(sim: &SimArgs, scene: &Scene, id: SceneId, config: FieldConfig) -> Result<SimulateSettings, String> {
    let frames = scene.frames.len() as u32;
    let split = match &sim.held_out {
        Some(list) => FrameSplit::explicit(frames, list).map_err(|e| format!("--held-out: {e}"))?,
        None => FrameSplit::every(frames, sim.held_out_every).map_err(|e| e.to_string())?,
    };
    let s = SimulateSettings {
        scene: id,
        config,
        seed: sim.seed,
        warmup: sim.warmup,
        steps_per_round: sim.steps_per_round,
        clicks_per_round: sim.clicks_per_round,
        click_radius: sim.click_radius,
        eval_every: sim.eval_every,
        frames: split,
    };
    s.check().map_err(|e| e.to_string())?;
    Ok(s)
}

/// Runs one simulated user into `out` with a progress bar, printing each evaluation.
pub fn run_one(
    ctx: &GpuContext,
    scene: &Scene,
    settings: &SimulateSettings,
    sim: &SimArgs,
    out: &Path,
) -> Result<simulate::SimulateState, Box<dyn std::error::Error>> {
    let bar = progress::bar("training");
    let quiet = bar.is_hidden();
    let mut events = |event: SimEvent<'_>| match event {
        SimEvent::Resumed { rounds, clicks } => {
            bar.suspend(|| eprintln!("resuming {}: {rounds} rounds, {clicks} clicks done", out.display()))
        }
        SimEvent::Training { done, total, loss } => {
            bar.set_length(u64::from(total));
            bar.set_position(u64::from(done));
            if let Some(loss) = loss {
                bar.set_message(format!("loss {loss:.4}"));
            }
        }
        SimEvent::Clicked {
            round, frame, clicks, ..
        } => {
            if !quiet {
                bar.set_message(format!("round {round}: {} clicks on frame {frame}", clicks.len()));
            }
        }
        SimEvent::Evaluated(p) => bar.suspend(|| {
            eprintln!(
                "round {:>3}  clicks {:>4}  steps {:>6}  mean IoU {:.4}  pixel acc {:.4}",
                p.round, p.clicks, p.steps, p.mean_iou, p.pixel_acc
            )
        }),
        SimEvent::Note(line) => bar.suspend(|| eprintln!("note: {line}")),
    };
    let options = RunOptions {
        budget: sim.budget,
        restart: sim.restart,
    };
    let state = simulate::run(ctx, scene, settings, options, out, &mut events)?;
    bar.finish_and_clear();
    Ok(state)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn config_changes_replace_fields_of_the_preset() {
        let base = scribblefield::eval::headless::budget_config(6);
        let changes =
            serde_json::json!({"batch_rays": 128, "adam": {"lr_warmup": 1e-2}, "encoding": {"kind": "hash_only"}});
        let c = apply_config_changes(&base, &changes).unwrap();
        assert_eq!(c.batch_rays, 128);
        assert_eq!(c.adam.lr_warmup, 1e-2);
        assert_eq!(c.adam.lr_annotating, base.adam.lr_annotating);
        assert_eq!(c.encoding, scribblefield::field::Encoding::HashOnly);
        assert_eq!(c.samples_fine, base.samples_fine);
        let e = apply_config_changes(&base, &serde_json::json!({"batch_ray": 1})).unwrap_err();
        assert!(e.contains("batch_ray"), "{e}");
        assert!(apply_config_changes(&base, &serde_json::json!([1])).is_err());
    }
}
