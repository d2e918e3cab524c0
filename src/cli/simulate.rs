use std::path::{Path, PathBuf};

use clap::Args;
use scribblefield::eval::simulate::{self, FrameSplit, RunOptions, SceneId, SimEvent, SimulateSettings};
use scribblefield::field::FieldConfig;
use scribblefield::gpu::GpuContext;
use scribblefield::scene::Scene;

use super::field_config::FieldConfigArgs;
use super::{CliResult, progress};

/// The simulated user's schedule, shared by `simulate` and `ablate`.
#[derive(Args, Clone, Debug)]
pub struct SimArgs {
    #[command(flatten)]
    pub field: FieldConfigArgs,
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
    /// Output folder: curve.csv, labels.json, simulate.json (resume state), trainer.safetensors.
    #[arg(short, long)]
    output: PathBuf,
    #[command(flatten)]
    sim: SimArgs,
}

pub fn run(mut args: SimulateArgs) -> CliResult {
    let (scene, id) = read_scene(&args.archive)?;
    args.sim.field.check()?;
    let ctx = GpuContext::new_blocking(&scribblefield::gpu::GpuOptions::from_env())?;
    eprintln!("training on {}", ctx.describe());
    args.sim.field.settle(&ctx);
    let cfg = base_config(&args.sim, &scene, &args.archive)?;
    let settings = settings(&args.sim, &scene, id, cfg).map_err(|e| format!("{}: {e}", args.archive.display()))?;
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

/// The preset with `--config` applied, finished for the scene (from `archive`).
pub fn base_config(sim: &SimArgs, scene: &Scene, archive: &Path) -> Result<FieldConfig, Box<dyn std::error::Error>> {
    let cfg = sim.field.resolve_for(scene, scene.classes.len(), archive)?;
    cfg.validate()?;
    Ok(cfg)
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
    // The whole run's time left, from the clicks labelled in this run so far (the bar's own
    // estimate only covers the current round's training).
    let started = std::time::Instant::now();
    let mut clicks_before = 0u32;
    let mut events = |event: SimEvent<'_>| match event {
        SimEvent::Resumed { rounds, clicks } => {
            clicks_before = clicks;
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
            let left = progress::estimate(
                f64::from(p.clicks.saturating_sub(clicks_before)),
                f64::from(sim.budget.saturating_sub(p.clicks)),
                started.elapsed(),
            )
            .filter(|s| *s > 0.0)
            .map_or(String::new(), |s| {
                format!(", ~{} left to {} clicks", progress::duration(s), sim.budget)
            });
            eprintln!(
                "round {:>3}  clicks {:>4}  steps {:>6}  mean IoU {:.4}  pixel acc {:.4}{}",
                p.round, p.clicks, p.steps, p.mean_iou, p.pixel_acc, left
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
