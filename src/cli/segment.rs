use std::path::PathBuf;

use clap::Args;
use scribblefield::eval::Confusion;
use scribblefield::eval::headless::{render_and_score, train_schedule};
use scribblefield::eval::source_size::{SourceCapture, render_at_source};
use scribblefield::export::{MaskDirWriter, MaskSet};
use scribblefield::field::gpu::scene_buffers::LabelIndex;
use scribblefield::field::gpu::trainer::Trainer;
use scribblefield::field::refine::RefineOptions;
use scribblefield::gpu::{GpuContext, GpuOptions};
use scribblefield::labels::LabelSet;
use scribblefield::scene::import::Background;
use scribblefield::scene::{Scene, read_archive_path};

use super::field_config::{FieldConfigArgs, without_missing_codes};
use super::{CliResult, progress};

#[derive(Args)]
pub struct SegmentArgs {
    /// Scene archive.
    archive: PathBuf,
    /// Annotations (`labels.json`); default: the labels shipped in the archive.
    #[arg(long)]
    labels: Option<PathBuf>,
    /// Output folder for the masks (class-id PNGs, previews, classes.json, labels.json).
    #[arg(short, long)]
    output: PathBuf,
    /// Training steps with labels.
    #[arg(long, default_value_t = 500)]
    steps: u32,
    /// Warm-up steps before labels join (colour, depth and features only).
    #[arg(long, default_value_t = 100)]
    warmup: u32,
    #[command(flatten)]
    field: FieldConfigArgs,
    #[arg(long, default_value_t = 0)]
    seed: u32,
    /// Rounds of edge-aware refinement of each mask with its frame's colour and depth (0: the
    /// field's own argmax); see `field::refine`.
    #[arg(long, default_value_t = RefineOptions::default().iterations)]
    refine_iterations: u32,
    /// The capture folder the archive was packed from (any layout `pack` reads): the masks are
    /// rendered and refined at its images' resolution instead of the archive's. Every archive
    /// frame must be found there by name with the same pose.
    #[arg(long, value_name = "DIR")]
    source: Option<PathBuf>,
}

pub fn run(mut args: SegmentArgs) -> CliResult {
    let mut scene = read_archive_path(&args.archive)?;
    let labels = match &args.labels {
        Some(path) => {
            let text = std::fs::read(path).map_err(|e| format!("{}: {e}", path.display()))?;
            LabelSet::from_json(&text, &path.display().to_string(), scene.frames.len() as u32)?
        }
        None => scene.labels.clone().ok_or_else(|| {
            format!(
                "{}: ships no labels; give --labels (e.g. from `scribble-from-gt`)",
                args.archive.display()
            )
        })?,
    };
    if labels.classes.is_empty() {
        return Err("labels define no classes".into());
    }
    args.field.check()?;
    let refine = RefineOptions {
        iterations: args.refine_iterations,
        ..RefineOptions::default()
    };
    refine.validate()?;
    let archive_name = args.archive.display().to_string();
    let source = match &args.source {
        Some(dir) => {
            let bar = progress::bar("reading");
            let capture = SourceCapture::check(&scene, &archive_name, dir, &mut |done, total| {
                bar.set_length(total as u64);
                bar.set_position(done as u64);
            })?;
            bar.finish_and_clear();
            println!(
                "source: {} ({} layout), all {} frames found with the archive's poses; masks at {} x {} (the archive is {} x {})",
                dir.display(),
                capture.layout.name(),
                scene.frames.len(),
                capture.width,
                capture.height,
                scene.width,
                scene.height
            );
            if capture.background != Background::default() {
                println!(
                    "source: transparent pixels composited on {}, as when the archive was packed",
                    capture.background.name()
                );
            }
            Some(capture)
        }
        None => None,
    };

    let ctx = GpuContext::new_blocking(&GpuOptions::from_env())?;
    eprintln!("training on {}", ctx.describe());
    args.field.settle(&ctx);
    let mut cfg = args
        .field
        .resolve(labels.classes.len() as u32, scene.features.as_ref())?;
    without_missing_codes(&mut cfg, &scene, &args.archive);
    cfg.validate()?;
    scene.labels = None;
    let mut trainer = pollster::block_on(Trainer::new(&ctx, &scene, &cfg, args.seed))?;
    let bar = progress::bar("training");
    bar.set_length(u64::from(args.warmup + args.steps));
    let quiet = bar.is_hidden();
    train_schedule(
        &mut trainer,
        &scene,
        &labels,
        args.warmup,
        args.steps,
        |done, total, loss| {
            bar.set_position(u64::from(done));
            if let Some(loss) = loss {
                bar.set_message(format!("loss {loss:.4}"));
                // Without a terminal the bar is hidden: leave a line in the log now and then.
                if quiet && (done % 100 == 0 || done == total) {
                    eprintln!("step {done}/{total}: loss {loss:.4}{}", progress::left(&bar));
                }
            }
        },
    )?;
    bar.finish_and_clear();
    let drawn = LabelIndex::from_labels(
        Some(&labels),
        scene.frames.len() as u32,
        scene.width,
        scene.height,
        labels.classes.len() as u32,
    )
    .labelled_pixel_count();
    let trained = trainer.labelled_pixels();
    if trained > drawn {
        println!(
            "labels: {drawn} drawn pixels spread to {trained} in {} frames (scribble_propagation; \"enabled\": false in --config turns it off)",
            trainer.labelled_frames()
        );
    }

    let names: Vec<String> = labels.classes.iter().map(|c| c.name.clone()).collect();
    if let Some(capture) = &source {
        return write_at_source(&mut trainer, &scene, capture, &labels, &names, &refine, &args);
    }
    let render = progress::bar("rendering");
    render.set_length(scene.frames.len() as u64);
    let mut masks = Vec::with_capacity(scene.frames.len());
    let mut bad_size = false;
    let frames = 0..scene.frames.len();
    let report = render_and_score(&mut trainer, &scene, &names, frames, &refine, |_, rendered| {
        match image::GrayImage::from_raw(scene.width, scene.height, rendered.classes) {
            Some(mask) => masks.push(mask),
            None => bad_size = true,
        }
        render.inc(1);
    })?;
    render.finish_and_clear();
    if bad_size {
        return Err("rendered class map has the wrong size".into());
    }
    let set = MaskSet {
        classes: labels.classes.clone(),
        masks,
    };
    set.write_dir(&args.output, Some(&labels))?;
    println!(
        "wrote {} masks of {} x {} (the archive's resolution; --source CAPTURE for the capture's) to {}",
        scene.frames.len(),
        scene.width,
        scene.height,
        args.output.display()
    );
    say_refinement(&refine);
    if scene.has_gt() {
        print!("{}", report.table());
    }
    Ok(())
}

fn say_refinement(refine: &RefineOptions) {
    if refine.is_off() {
        println!("masks: the field's own class maps (--refine-iterations 0)");
    } else {
        println!(
            "masks: refined with each frame's colour and depth ({} rounds; --refine-iterations 0 for the field's own)",
            refine.iterations
        );
    }
}

/// Renders every frame at the capture's size (chunk by chunk, as `SourceCapture` reads it),
/// refines it with the capture's image and depth, writes each mask as it comes, and scores the
/// masks against the capture's ground truth where it has some.
fn write_at_source(
    trainer: &mut Trainer,
    scene: &Scene,
    capture: &SourceCapture,
    labels: &LabelSet,
    names: &[String],
    refine: &RefineOptions,
    args: &SegmentArgs,
) -> CliResult {
    let archive_name = args.archive.display().to_string();
    let render = progress::bar("rendering");
    render.set_length(scene.frames.len() as u64);
    let quiet = render.is_hidden();
    let mut writer = MaskDirWriter::new(&args.output, labels.classes.clone())?;
    let mut confusion = Confusion::new(names.len());
    let mut scored = 0;
    let started = std::time::Instant::now();
    for frames in capture.chunks() {
        let source = capture.load(frames.clone(), &archive_name)?;
        for (k, i) in frames.enumerate() {
            let mask = render_at_source(trainer, scene, i, &source, k, refine)?;
            if let Some(gt) = &source.frames[k].gt {
                confusion.add(gt.as_raw(), mask.as_raw());
                scored += 1;
            }
            writer.frame(&mask)?;
            render.inc(1);
            if quiet {
                eprintln!(
                    "frame {}/{} at {} x {}{}",
                    i + 1,
                    scene.frames.len(),
                    capture.width,
                    capture.height,
                    progress::left(&render)
                );
            }
        }
    }
    render.finish_and_clear();
    let written = writer.finish(Some(labels))?;
    println!(
        "wrote {written} masks of {} x {} (the capture's resolution, from {}; the archive is {} x {}) to {} in {:.1} s",
        capture.width,
        capture.height,
        capture.dir.display(),
        scene.width,
        scene.height,
        args.output.display(),
        started.elapsed().as_secs_f64()
    );
    say_refinement(refine);
    if scored > 0 {
        println!(
            "scored against the capture's ground truth at {} x {}:",
            capture.width, capture.height
        );
        print!("{}", confusion.report(names, scored).table());
    }
    Ok(())
}
