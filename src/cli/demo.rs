use std::path::PathBuf;

use clap::Args;
use scribblefield::scene::demo::{DemoOptions, demo_scene};
use scribblefield::scene::write_archive_path;

use super::{CliResult, check_output};

#[derive(Args)]
pub struct DemoArgs {
    /// Output archive, e.g. `demo.scene.zip`.
    #[arg(short, long)]
    output: PathBuf,
    /// Seed for object placement, textures and colours; the same seed gives the same scene.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Frame size as WIDTHxHEIGHT.
    #[arg(long, default_value = "160x120", value_parser = parse_size)]
    size: (u32, u32),
    /// Number of frames on the orbit.
    #[arg(long, default_value_t = 36)]
    frames: u32,
    #[command(flatten)]
    features: super::features::FeatureArgs,
}

fn parse_size(s: &str) -> Result<(u32, u32), String> {
    let (w, h) = s
        .split_once(['x', 'X'])
        .ok_or_else(|| format!("size {s:?} is not WIDTHxHEIGHT, e.g. 160x120"))?;
    let parse = |v: &str| {
        v.trim()
            .parse::<u32>()
            .map_err(|_| format!("size {s:?}: {v:?} is not a whole number"))
    };
    Ok((parse(w)?, parse(h)?))
}

pub fn run(args: DemoArgs) -> CliResult {
    check_output(&args.output)?;
    args.features.check()?;
    let opts = DemoOptions {
        seed: args.seed,
        width: args.size.0,
        height: args.size.1,
        frames: args.frames,
    };
    let mut scene = demo_scene(&opts)?;
    args.features.apply(&mut scene)?;
    write_archive_path(&scene, &args.output)?;
    println!("wrote the demo scene to {}", args.output.display());
    print!("{}", scene.summary());
    Ok(())
}
