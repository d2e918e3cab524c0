use std::path::PathBuf;

use clap::Args;
use scribblefield::eval::Confusion;
use scribblefield::export::read_masks;
use scribblefield::scene::read_archive_path;

use super::CliResult;

#[derive(Args)]
pub struct EvalArgs {
    /// Scene archive with ground truth.
    archive: PathBuf,
    /// Masks folder (or zip) written by `segment` or downloaded from the web app.
    masks: PathBuf,
    /// Only these frames, e.g. `1,2,3` (default: all frames with ground truth).
    #[arg(long, value_delimiter = ',')]
    frames: Vec<u32>,
    /// Print JSON instead of a table.
    #[arg(long)]
    json: bool,
}

pub fn run(args: EvalArgs) -> CliResult {
    let scene = read_archive_path(&args.archive)?;
    if !scene.has_gt() {
        return Err(format!("{}: has no ground truth to evaluate against", args.archive.display()).into());
    }
    if let Some(bad) = args.frames.iter().find(|&&f| f as usize >= scene.frames.len()) {
        return Err(format!(
            "--frames: frame {bad} does not exist (the scene has {} frames)",
            scene.frames.len()
        )
        .into());
    }
    let masks = read_masks(&args.masks, scene.frames.len(), scene.width, scene.height)?;
    let mut confusion = Confusion::new(scene.classes.len().max(1));
    let mut frames = 0;
    for (i, (frame, mask)) in scene.frames.iter().zip(&masks).enumerate() {
        if !args.frames.is_empty() && !args.frames.contains(&(i as u32)) {
            continue;
        }
        if let Some(gt) = &frame.gt {
            confusion.add(gt.as_raw(), mask.as_raw());
            frames += 1;
        }
    }
    let names: Vec<String> = scene.classes.iter().map(|c| c.name.clone()).collect();
    let report = confusion.report(&names, frames);
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print!("{}", report.table());
    }
    Ok(())
}
