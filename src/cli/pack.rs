use std::path::PathBuf;

use clap::Args;
use scribblefield::scene::import::{Background, ImportOptions, Split, import};
use scribblefield::scene::write_archive_path;

use super::{CliResult, check_output, progress};

#[derive(Args)]
pub struct PackArgs {
    /// Capture folder (autolabel scene, 7-Scenes/TUM, COLMAP, ScanNet export, ARKitScenes scene,
    /// Stray Scanner capture, NeRF-synthetic split folder) or a NeRF `transforms.json` (or its
    /// folder).
    input: PathBuf,
    /// Output archive, e.g. `scene.scene.zip`.
    #[arg(short, long)]
    output: PathBuf,
    /// Downscale so the longest image side is at most this many pixels (intrinsics follow).
    #[arg(long)]
    max_size: Option<u32>,
    /// Keep every k-th frame.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..))]
    every: u32,
    /// Keep at most this many frames (after --every).
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..))]
    max_frames: Option<u32>,
    /// COLMAP captures: folder of binary foreground masks, one `<photo stem>.png` per photo
    /// (>= 128 = foreground); a `masks/` folder beside `images/` is used without this.
    #[arg(long)]
    masks: Option<PathBuf>,
    /// Names of the two mask classes (COLMAP masks, --alpha-gt), background first.
    #[arg(long, value_delimiter = ',', num_args = 1, default_value = "background,object")]
    mask_classes: Vec<String>,
    /// Accept image and depth paths in the capture's files (`transforms.json` `file_path`,
    /// COLMAP image names) that are absolute or leave the capture folder with `..`; refused by
    /// default so that a capture from elsewhere cannot pack arbitrary files.
    #[arg(long)]
    allow_outside_paths: bool,
    /// NeRF-synthetic split folders: the splits to pack (train, val, test; repeat the flag or
    /// give a comma list). Default: every `transforms_<split>.json` present.
    #[arg(long = "split", value_delimiter = ',', value_parser = parse_split)]
    splits: Vec<Split>,
    /// What transparent pixels of RGBA images are composited on: white (as NeRF-synthetic
    /// training does) or black.
    #[arg(long, default_value = "white", value_parser = parse_background)]
    background: Background,
    /// NeRF captures: turn each image's alpha into 2-class ground truth (--mask-classes; alpha
    /// 0 = background, 255 = object, boundary pixels between = void).
    #[arg(long)]
    alpha_gt: bool,
    #[command(flatten)]
    features: super::features::FeatureArgs,
    /// Bake no feature codes. Without it `pack` bakes the weight-free `baseline` codes unless
    /// `--features` names another extractor: the documented quality figures and the page use
    /// them, and training supervises with them.
    #[arg(long, conflicts_with = "features")]
    no_features: bool,
}

pub fn run(args: PackArgs) -> CliResult {
    check_output(&args.output)?;
    args.features.check()?;
    let mask_classes: [String; 2] = match <[String; 2]>::try_from(args.mask_classes) {
        Ok(names) if names.iter().all(|n| !n.trim().is_empty()) => names,
        _ => return Err("--mask-classes takes two non-empty names, background first: e.g. background,object".into()),
    };
    let opts = ImportOptions {
        max_size: args.max_size,
        every: args.every,
        max_frames: args.max_frames,
        masks: args.masks,
        mask_classes,
        allow_outside_paths: args.allow_outside_paths,
        splits: args.splits,
        background: args.background,
        alpha_gt: args.alpha_gt,
        only: None,
    };
    let bar = progress::bar("loading");
    let mut imported = import(&args.input, &opts, &mut |done, total| {
        bar.set_length(total as u64);
        bar.set_position(done as u64);
    })?;
    bar.finish_and_clear();
    for w in &imported.warnings {
        eprintln!("warning: {w}");
    }
    for line in &imported.report {
        println!("{line}");
    }
    let features = if args.no_features {
        args.features
    } else {
        args.features.or(super::features::FeatureKind::Baseline)
    };
    features.apply(&mut imported.scene)?;
    write_archive_path(&imported.scene, &args.output)?;
    println!(
        "packed {} ({} layout) into {}",
        args.input.display(),
        imported.layout.name(),
        args.output.display()
    );
    print!("{}", imported.scene.summary());
    Ok(())
}

fn parse_split(name: &str) -> Result<Split, String> {
    Split::parse(name).ok_or_else(|| {
        let names: Vec<&str> = Split::ALL.iter().map(|s| s.name()).collect();
        format!("unknown split {name:?}: one of {}", names.join(", "))
    })
}

fn parse_background(name: &str) -> Result<Background, String> {
    Background::parse(name).ok_or_else(|| format!("unknown background {name:?}: white or black"))
}
