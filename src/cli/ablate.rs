use std::path::PathBuf;

use clap::Args;
use scribblefield::eval::ablation::{self, scene_name};
use scribblefield::eval::curves::MethodCurve;
use scribblefield::gpu::{GpuContext, GpuOptions};

use super::CliResult;
use super::simulate::{SimArgs, base_config, read_scene, run_one, settings};

#[derive(Args)]
pub struct AblateArgs {
    /// Scene archives with ground truth.
    #[arg(required = true)]
    scenes: Vec<PathBuf>,
    /// Output folder: ablation.csv, table.md, plot-<scene>.svg, and a simulated-user run
    /// per scene and method in <scene>/<method>/ (each resumable).
    #[arg(short, long)]
    output: PathBuf,
    /// Run only the methods whose names contain one of these, e.g. `hash+freq,freq-only`.
    #[arg(long, value_delimiter = ',')]
    only: Option<Vec<String>>,
    #[command(flatten)]
    sim: SimArgs,
}

pub fn run(mut args: AblateArgs) -> CliResult {
    // Read every scene first, so a bad archive fails before hours of training.
    let mut scenes = Vec::new();
    for path in &args.scenes {
        let (scene, id) = read_scene(path)?;
        let name = scene_name(path);
        if scenes.iter().any(|(n, ..): &(String, _, _, _)| *n == name) {
            return Err(format!("{}: two scenes are named {name:?}; rename one", path.display()).into());
        }
        scenes.push((name, path.clone(), scene, id));
    }
    // The preset may depend on the adapter: open it before the settings are made (seconds,
    // against the hours of training a bad setting would waste).
    args.sim.field.check()?;
    let ctx = GpuContext::new_blocking(&GpuOptions::from_env())?;
    eprintln!("training on {}", ctx.describe());
    args.sim.field.settle(&ctx);
    // Every (scene, method) with its settings, checked before any training.
    let mut runs = Vec::new();
    let mut notes = Vec::new();
    for (name, path, scene, id) in &scenes {
        let base = base_config(&args.sim, scene, path).map_err(|e| format!("{}: {e}", path.display()))?;
        let extractor = scene.features.as_ref().map(|f| f.extractor.as_str());
        let (methods, note) = ablation::methods(&base, extractor);
        if let Some(note) = note {
            let line = format!("{name}: {note}");
            println!("note: {line}");
            notes.push(line);
        }
        let methods: Vec<_> = match &args.only {
            Some(only) => methods
                .into_iter()
                .filter(|m| only.iter().any(|o| m.name.contains(o.as_str())))
                .collect(),
            None => methods,
        };
        if methods.is_empty() {
            return Err(format!(
                "--only {}: matches no method for {}",
                args.only.as_deref().unwrap_or_default().join(","),
                path.display()
            )
            .into());
        }
        for method in methods {
            let s = settings(&args.sim, scene, id.clone(), method.config)
                .map_err(|e| format!("{}: {}: {e}", path.display(), method.name))?;
            runs.push((name.clone(), scene, method.name, s));
        }
    }
    std::fs::create_dir_all(&args.output).map_err(|e| format!("{}: {e}", args.output.display()))?;
    let mut curves = Vec::new();
    for (name, scene, method, settings) in runs {
        let out = args.output.join(&name).join(&method);
        eprintln!("== {name}: {method} -> {}", out.display());
        let state = run_one(&ctx, scene, &settings, &args.sim, &out)?;
        curves.push(MethodCurve {
            scene: name,
            method,
            points: state.curve,
        });
    }
    let header = format!(
        "Simulated user: {} clicks per round, {} steps per round after {} warm-up steps, budget {} clicks, preset {}, seed {}.\n{}\n",
        args.sim.clicks_per_round,
        args.sim.steps_per_round,
        args.sim.warmup,
        args.sim.budget,
        args.sim.field.describe(),
        args.sim.seed,
        notes.iter().map(|n| format!("\nNote: {n}\n")).collect::<String>(),
    );
    let written = ablation::write_outputs(&args.output, &curves, &header)
        .map_err(|e| format!("{}: {e}", args.output.display()))?;
    for path in written {
        println!("wrote {}", path.display());
    }
    Ok(())
}
