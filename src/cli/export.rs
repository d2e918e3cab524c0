//! `export CHECKPOINT ARCHIVE -o DIR`: the masks `segment` wrote, again, from the field it saved
//! with `--save-checkpoint`, without training: at the archive's resolution or, with `--source`,
//! at the capture's, with the refinement asked for. The checkpoint's metadata
//! (`saved_field::TrainedOn`) says which archive, seed and labels the field was trained
//! with; an archive other than that one is refused before the GPU opens.
use std::path::PathBuf;

use clap::Args;
use scribblefield::field::gpu::trainer::Trainer;
use scribblefield::gpu::{GpuContext, GpuOptions};
use scribblefield::saved_field::{Checkpoint, TrainedOn};
use scribblefield::scene::read_archive_path;

use super::CliResult;
use super::segment::{MaskArgs, read_labels, write_masks};

#[derive(Args)]
pub struct ExportArgs {
    /// A trained field, written by `segment --save-checkpoint FILE`.
    checkpoint: PathBuf,
    /// The scene archive it was trained on.
    archive: PathBuf,
    // As `segment`'s: the output folder, formats, object cleanup, refinement and `--source`.
    #[command(flatten)]
    masks: MaskArgs,
    /// Annotations written as the masks' `labels.json` (and naming the classes: the same class
    /// names as those the field was trained with); default: the labels kept in the checkpoint.
    #[arg(long)]
    labels: Option<PathBuf>,
}

pub fn run(args: ExportArgs) -> CliResult {
    let file = args.checkpoint.display().to_string();
    let checkpoint = Checkpoint::read_file(&args.checkpoint)
        .map_err(|e| format!("{e} (write one with `segment --save-checkpoint FILE`)"))?;
    let trained_on = TrainedOn::from_checkpoint(&file, &checkpoint)?;
    let mut scene = read_archive_path(&args.archive)?;
    let archive_name = args.archive.display().to_string();
    trained_on.check_scene(&file, &checkpoint.config, &archive_name, &scene)?;
    let labels = match &args.labels {
        Some(path) => {
            let labels = read_labels(Some(path), &scene, &args.archive)?;
            trained_on.check_labels(&file, &labels, &path.display().to_string())?;
            labels
        }
        None => trained_on.labels.clone(),
    };
    let masks = args.masks.check(&scene, &args.archive, &labels.classes)?;

    let ctx = GpuContext::new_blocking(&GpuOptions::from_env())?;
    eprintln!("rendering on {}", ctx.describe());
    scene.labels = None;
    let mut trainer = pollster::block_on(Trainer::new(&ctx, &scene, &checkpoint.config, trained_on.seed))?;
    trainer.restore_checkpoint(&file, &checkpoint)?;
    println!(
        "field: {file}, trained {} steps on {} (seed {}), {} classes",
        checkpoint.state.step,
        trained_on.archive,
        trained_on.seed,
        labels.classes.len()
    );
    write_masks(&mut trainer, &scene, &labels, &masks)
}
