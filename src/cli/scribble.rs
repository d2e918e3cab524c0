use std::path::PathBuf;

use clap::Args;
use scribblefield::labels::LabelSet;
use scribblefield::labels::synthetic::{ScribbleOptions, scribble_frame};
use scribblefield::scene::read_archive_path;

use super::CliResult;

#[derive(Args)]
pub struct ScribbleArgs {
    /// Scene archive with ground truth.
    archive: PathBuf,
    /// Frames to scribble on, e.g. `0,12`.
    #[arg(long, value_delimiter = ',', required = true)]
    frames: Vec<u32>,
    /// Output labels file.
    #[arg(short, long)]
    output: PathBuf,
    /// Strokes per class per frame.
    #[arg(long, default_value_t = 2)]
    strokes: u32,
    /// Brush radius in pixels (default: 1.2 % of the image diagonal).
    #[arg(long)]
    radius: Option<f32>,
    #[arg(long, default_value_t = 0)]
    seed: u64,
}

pub fn run(args: ScribbleArgs) -> CliResult {
    let scene = read_archive_path(&args.archive)?;
    if scene.classes.is_empty() || !scene.has_gt() {
        return Err(format!("{}: has no ground truth to scribble from", args.archive.display()).into());
    }
    let mut labels = LabelSet::new(scene.classes.clone());
    let opts = ScribbleOptions {
        strokes_per_class: args.strokes,
        radius: args.radius,
        seed: args.seed,
        ..Default::default()
    };
    for &f in &args.frames {
        let frame = scene.frames.get(f as usize).ok_or_else(|| {
            format!(
                "--frames: frame {f} does not exist ({} has {} frames)",
                args.archive.display(),
                scene.frames.len()
            )
        })?;
        let gt = frame
            .gt
            .as_ref()
            .ok_or_else(|| format!("--frames: frame {f} has no ground truth"))?;
        scribble_frame(&mut labels, f, gt, &opts);
    }
    std::fs::write(&args.output, labels.to_json()).map_err(|e| format!("{}: {e}", args.output.display()))?;
    let strokes: usize = labels.frames.iter().map(|f| f.strokes.len()).sum();
    println!(
        "wrote {strokes} strokes on {} frames to {}",
        labels.frames.len(),
        args.output.display()
    );
    Ok(())
}
