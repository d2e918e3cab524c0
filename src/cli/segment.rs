use std::error::Error;
use std::path::{Path, PathBuf};

use clap::Args;
use scribblefield::eval::Confusion;
use scribblefield::eval::headless::{render_and_score, train_schedule};
use scribblefield::eval::source_size::{SourceCapture, render_at_source};
use scribblefield::export::{ExportOptions, Format, MaskDirWriter};
use scribblefield::field::gpu::scene_buffers::LabelIndex;
use scribblefield::field::gpu::trainer::Trainer;
use scribblefield::gpu::{GpuContext, GpuOptions};
use scribblefield::labels::{ClassInfo, LabelSet};
use scribblefield::refine::RefineOptions;
use scribblefield::saved_field::TrainedOn;
use scribblefield::scene::import::Background;
use scribblefield::scene::{Scene, read_archive_path};

use super::field_config::FieldConfigArgs;
use super::{CliResult, progress};

#[derive(Args)]
pub struct SegmentArgs {
    /// Scene archive.
    archive: PathBuf,
    /// Annotations (`labels.json`); default: the labels shipped in the archive.
    #[arg(long)]
    labels: Option<PathBuf>,
    #[command(flatten)]
    masks: MaskArgs,
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
    /// Also write the trained field to FILE (`.safetensors`, with the archive and labels it was
    /// trained on), so `scribblefield export FILE ARCHIVE -o DIR` writes these masks again (at
    /// another resolution, with other refinement) without training.
    #[arg(long, value_name = "FILE")]
    save_checkpoint: Option<PathBuf>,
}

/// Where and how `segment` and `export` write the masks.
#[derive(Args)]
pub(super) struct MaskArgs {
    /// Output folder for the masks (class-id PNGs by index and, under by-name/, by the frames'
    /// names in their capture; previews, classes.json, labels.json).
    #[arg(short, long)]
    output: PathBuf,
    /// Also write these formats (comma-separated): voc (the CVAT / PASCAL VOC segmentation
    /// layout under voc/: palette PNGs, labelmap.txt), coco (coco.json: compressed RLE per
    /// class per frame), ply (points.ply: a labelled point cloud from the frames' depth), apng
    /// (masks.apng: the masks over the frames, animated).
    #[arg(long = "format", value_name = "FORMATS", value_enum, value_delimiter = ',')]
    formats: Vec<FormatArg>,
    /// Keep only the N largest 8-connected regions of each class but the first (class 0) in
    /// every mask; the pixels of the others become class 0 (autolabel's `--objects`). Every
    /// file written, and the scores printed, are of the cleaned masks.
    #[arg(long, value_name = "N")]
    objects: Option<u32>,
    /// Rounds of edge-aware refinement of each mask with its frame's colour and depth (0: the
    /// field's own argmax); default: 3 where the frames have dense depth, 10 where they do not
    /// (photo captures); see `refine`.
    #[arg(long)]
    refine_iterations: Option<u32>,
    /// The capture folder the archive was packed from (any layout `pack` reads): the masks are
    /// rendered and refined at its images' resolution instead of the archive's. Every archive
    /// frame must be found there by name with the same pose.
    #[arg(long, value_name = "DIR")]
    source: Option<PathBuf>,
}

pub fn run(mut args: SegmentArgs) -> CliResult {
    let mut scene = read_archive_path(&args.archive)?;
    let labels = read_labels(args.labels.as_deref(), &scene, &args.archive)?;
    args.field.check()?;
    if let Some(file) = &args.save_checkpoint {
        check_checkpoint_path(file)?;
    }
    let masks = args.masks.check(&scene, &args.archive, &labels.classes)?;

    let ctx = GpuContext::new_blocking(&GpuOptions::from_env())?;
    eprintln!("training on {}", ctx.describe());
    args.field.settle(&ctx);
    let cfg = args.field.resolve_for(&scene, labels.classes.len(), &args.archive)?;
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
    if let Some(check) = trainer.spread_check() {
        let verdict = if trainer.spread_withheld() {
            " (below min_agreement: trained with less spreading, see docs/quality.md)"
        } else {
            ""
        };
        println!("labels: spread {}{verdict}", check.describe());
    }
    if let Some(class) = trainer.opacity_far_class() {
        let name = labels.classes.get(class as usize).map_or("?", |c| c.name.as_str());
        println!(
            "opacity: rays labelled {name:?} (far from every point) pass through the scene box, rays of the other classes stop in it (loss.opacity; 0 in --config turns it off)"
        );
    }

    if let Some(file) = &args.save_checkpoint {
        save_checkpoint(&trainer, file, &args.archive, &scene, args.seed, &labels)?;
    }
    write_masks(&mut trainer, &scene, &labels, &masks)
}

/// The annotations: `--labels FILE` (`path`), else those shipped in `archive`.
pub(super) fn read_labels(path: Option<&Path>, scene: &Scene, archive: &Path) -> Result<LabelSet, Box<dyn Error>> {
    let labels = match path {
        Some(path) => {
            let text = std::fs::read(path).map_err(|e| format!("{}: {e}", path.display()))?;
            LabelSet::from_json(&text, &path.display().to_string(), scene.frames.len() as u32)?
        }
        None => scene.labels.clone().ok_or_else(|| {
            format!(
                "{}: ships no labels; give --labels (e.g. from `scribble-from-gt`)",
                archive.display()
            )
        })?,
    };
    if labels.classes.is_empty() {
        return Err("labels define no classes".into());
    }
    Ok(labels)
}

/// `--format`'s values.
#[derive(Clone, Copy, clap::ValueEnum)]
enum FormatArg {
    Voc,
    Coco,
    Ply,
    Apng,
}

impl From<FormatArg> for Format {
    fn from(f: FormatArg) -> Format {
        match f {
            FormatArg::Voc => Format::Voc,
            FormatArg::Coco => Format::Coco,
            FormatArg::Ply => Format::Ply,
            FormatArg::Apng => Format::Animation,
        }
    }
}

impl MaskArgs {
    /// Checks the refinement and the formats (for `classes`), and finds the `--source`
    /// capture's frames for `scene` (read from `archive`): before any GPU work, and before the
    /// output folder is created.
    pub(super) fn check<'a>(
        &'a self,
        scene: &Scene,
        archive: &'a Path,
        classes: &[ClassInfo],
    ) -> Result<Masks<'a>, Box<dyn Error>> {
        let formats: Vec<Format> = self.formats.iter().map(|&f| f.into()).collect();
        let export = ExportOptions::with(&formats, self.objects);
        export.check(classes, scene.has_depth())?;
        let defaults = RefineOptions::for_scene(scene);
        let refine = RefineOptions {
            iterations: self.refine_iterations.unwrap_or(defaults.iterations),
            ..defaults
        };
        refine.validate()?;
        let source = match &self.source {
            Some(dir) => Some(check_source(scene, archive, dir)?),
            None => None,
        };
        Ok(Masks {
            archive,
            output: &self.output,
            refine,
            source,
            export,
        })
    }
}

/// Finds every frame of `scene` (read from `archive`) in the capture at `dir` (`--source`),
/// before any training or rendering, and says what the masks will be.
fn check_source(scene: &Scene, archive: &Path, dir: &Path) -> Result<SourceCapture, Box<dyn Error>> {
    let bar = progress::bar("reading");
    let archive_name = archive.display().to_string();
    let capture = SourceCapture::check(scene, &archive_name, dir, &mut |done, total| {
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
    Ok(capture)
}

/// A checkpoint is written only where it can be, to a `.safetensors` file: checked before
/// training, so that a long run does not end in a refusal.
fn check_checkpoint_path(file: &Path) -> CliResult {
    let shown = file.display();
    if file.extension().and_then(|e| e.to_str()) != Some("safetensors") {
        return Err(format!("--save-checkpoint {shown}: the file must end in .safetensors").into());
    }
    if file.is_dir() {
        return Err(format!("--save-checkpoint {shown}: is a directory").into());
    }
    if let Some(parent) = file.parent().filter(|p| !p.as_os_str().is_empty())
        && !parent.is_dir()
    {
        return Err(format!("--save-checkpoint {shown}: folder {} does not exist", parent.display()).into());
    }
    Ok(())
}

/// Writes the trained field with what `export` needs ([`TrainedOn`]) to `file`, through a
/// temporary file and a rename, so an interrupted write leaves no truncated checkpoint.
fn save_checkpoint(
    trainer: &Trainer,
    file: &Path,
    archive: &Path,
    scene: &Scene,
    seed: u32,
    labels: &LabelSet,
) -> CliResult {
    let trained_on = TrainedOn::of_scene(&archive.display().to_string(), scene, seed, labels);
    let checkpoint = pollster::block_on(trainer.checkpoint(trained_on.to_extra()))?;
    let tmp = file.with_extension("safetensors.tmp");
    std::fs::write(&tmp, checkpoint.to_bytes()).map_err(|e| format!("{}: {e}", tmp.display()))?;
    std::fs::rename(&tmp, file).map_err(|e| format!("{}: {e}", file.display()))?;
    println!(
        "saved the trained field to {} (`scribblefield export {} {} -o DIR` writes masks from it without training)",
        file.display(),
        file.display(),
        archive.display()
    );
    Ok(())
}

/// [`MaskArgs`] checked: what to write, and where.
pub(super) struct Masks<'a> {
    /// The archive, for messages.
    archive: &'a Path,
    output: &'a Path,
    refine: RefineOptions,
    /// Masks at this capture's resolution (`--source`), else the archive's.
    source: Option<SourceCapture>,
    /// The formats asked for and the object-count cleanup.
    export: ExportOptions,
}

/// Renders every frame of `scene` with `trainer`'s field and writes the masks folder (class-id
/// PNGs by index and by name, previews, classes.json, `labels` as labels.json, the formats
/// asked for; the classes are `labels'`), scored against the ground truth where there is
/// some: what `segment` writes after training and `export` from a checkpoint.
pub(super) fn write_masks(trainer: &mut Trainer, scene: &Scene, labels: &LabelSet, masks: &Masks) -> CliResult {
    let names: Vec<String> = labels.classes.iter().map(|c| c.name.clone()).collect();
    if let Some(capture) = &masks.source {
        return write_at_source(trainer, scene, capture, labels, &names, masks);
    }
    let render = progress::bar("rendering");
    render.set_length(scene.frames.len() as u64);
    let mut writer = MaskDirWriter::new(masks.output, labels.classes.clone(), &masks.export, Some(scene))?;
    let mut confusion = Confusion::new(names.len());
    let mut scored = 0;
    let mut failed: Option<Box<dyn Error>> = None;
    let frames = 0..scene.frames.len();
    render_and_score(trainer, scene, &names, frames, &masks.refine, |i, rendered| {
        if failed.is_some() {
            return;
        }
        let Some(mut mask) = image::GrayImage::from_raw(scene.width, scene.height, rendered.classes) else {
            failed = Some(format!("frame {i}: rendered class map has the wrong size").into());
            return;
        };
        // Scored after the cleanup: the scores are of the masks written.
        if let Err(e) = writer.frame(&mut mask) {
            failed = Some(e.into());
            return;
        }
        if let Some(gt) = &scene.frames[i].gt {
            confusion.add(gt.as_raw(), mask.as_raw());
            scored += 1;
        }
        render.inc(1);
    })?;
    render.finish_and_clear();
    if let Some(e) = failed {
        return Err(e);
    }
    writer.finish(Some(labels))?;
    println!(
        "wrote {} masks of {} x {} (the archive's resolution; --source CAPTURE for the capture's) to {}",
        scene.frames.len(),
        scene.width,
        scene.height,
        masks.output.display()
    );
    say_refinement(&masks.refine);
    say_export(&masks.export, masks.output, &labels.classes);
    if scored > 0 {
        print!("{}", confusion.report(&names, scored).table());
    }
    Ok(())
}

/// What the folder holds beyond the masks by index: the masks by name, the formats, the
/// cleanup.
fn say_export(export: &ExportOptions, output: &Path, classes: &[ClassInfo]) {
    let mut extra = vec!["by-name/ (the frames' names in their capture)".to_string()];
    for f in Format::ALL.into_iter().filter(|&f| export.has(f)) {
        extra.push(f.describe().to_string());
    }
    println!("{}: also {}", output.display(), extra.join(", "));
    if let Some(n) = export.objects {
        let first = classes.first().map_or("?", |c| c.name.as_str());
        let regions = if n == 1 { "region" } else { "regions" };
        println!(
            "masks: the {n} largest {regions} of each class but the first kept (--objects), the others made {first:?}"
        );
    }
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
    masks: &Masks,
) -> CliResult {
    let archive_name = masks.archive.display().to_string();
    let render = progress::bar("rendering");
    render.set_length(scene.frames.len() as u64);
    let quiet = render.is_hidden();
    let mut writer = MaskDirWriter::new(masks.output, labels.classes.clone(), &masks.export, Some(scene))?;
    let mut confusion = Confusion::new(names.len());
    let mut scored = 0;
    let started = std::time::Instant::now();
    for frames in capture.chunks() {
        let source = capture.load(frames.clone(), &archive_name)?;
        for (k, i) in frames.enumerate() {
            let mut mask = render_at_source(trainer, scene, i, &source, k, &masks.refine)?;
            // Scored after the cleanup: the scores are of the masks written.
            writer.frame(&mut mask)?;
            if let Some(gt) = &source.frames[k].gt {
                confusion.add(gt.as_raw(), mask.as_raw());
                scored += 1;
            }
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
        masks.output.display(),
        started.elapsed().as_secs_f64()
    );
    say_refinement(&masks.refine);
    say_export(&masks.export, masks.output, &labels.classes);
    if scored > 0 {
        println!(
            "scored against the capture's ground truth at {} x {}:",
            capture.width, capture.height
        );
        print!("{}", confusion.report(names, scored).table());
    }
    Ok(())
}
