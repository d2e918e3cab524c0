//! Subcommands of the `scribblefield` binary, one module each.
mod ablate;
mod bench;
mod demo;
mod eval;
mod export;
mod features;
mod field_config;
mod info;
mod pack;
mod progress;
mod scribble;
mod segment;
mod simulate;
mod suite;

use std::path::PathBuf;

use clap::{Parser, Subcommand};

pub type CliResult = Result<(), Box<dyn std::error::Error>>;

#[derive(Parser)]
#[command(
    name = "scribblefield",
    version,
    about = "Scribbles on a few RGB-D frames, propagated to dense masks by a neural field"
)]
pub struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Pack a capture (autolabel scene, 7-Scenes/TUM, NeRF transforms.json or split folder, COLMAP, ScanNet export, ARKitScenes scene, Stray Scanner capture) into a scene archive.
    Pack(pack::PackArgs),
    /// Print what a scene archive holds.
    Info {
        /// The `*.scene.zip` to inspect.
        archive: PathBuf,
    },
    /// Render the built-in demo scene into a scene archive.
    DemoScene(demo::DemoArgs),
    /// Draw realistic synthetic scribbles from ground truth (to measure quality without a person).
    ScribbleFromGt(scribble::ScribbleArgs),
    /// Train the field on a scene's scribbles (headless, on the GPU) and write masks of every frame.
    Segment(segment::SegmentArgs),
    /// Write the masks again from a field `segment --save-checkpoint` saved, without training (another resolution with --source, other refinement).
    Export(export::ExportArgs),
    /// The paper's simulated user: click wrongly predicted pixels with their ground truth, train, score held-out frames; resumable.
    Simulate(simulate::SimulateArgs),
    /// Run the simulated user with each encoding (with and without feature supervision) and write a CSV, plots and tables.
    Ablate(ablate::AblateArgs),
    /// Measure the training step (steps/s, rays/s, samples/s) against a plain matmul on the same adapter.
    Bench(bench::BenchArgs),
    /// The quality suite: every capture with ground truth, scribbled from it over sets and seeds, trained at the budget preset and scored; the one way defaults are decided (docs/quality.md).
    Suite(suite::SuiteArgs),
    /// Score masks against the archive's ground truth: per-class IoU, mean IoU, pixel accuracy.
    Eval(eval::EvalArgs),
    /// Serve a directory (the web app) over HTTP on localhost.
    Serve {
        /// Directory to serve, e.g. `www`.
        dir: PathBuf,
        #[arg(long, default_value_t = 8080)]
        port: u16,
        /// Address to bind; the default only accepts connections from this machine.
        #[arg(long, default_value = "127.0.0.1")]
        bind: std::net::IpAddr,
    },
}

pub fn run(cli: Cli) -> CliResult {
    match cli.command {
        Command::Pack(args) => pack::run(args),
        Command::Info { archive } => info::run(&archive),
        Command::DemoScene(args) => demo::run(args),
        Command::ScribbleFromGt(args) => scribble::run(args),
        Command::Segment(args) => segment::run(args),
        Command::Export(args) => export::run(args),
        Command::Eval(args) => eval::run(args),
        Command::Simulate(args) => simulate::run(args),
        Command::Ablate(args) => ablate::run(args),
        Command::Bench(args) => bench::run(args),
        Command::Suite(args) => suite::run(args),
        Command::Serve { dir, port, bind } => {
            if !dir.is_dir() {
                return Err(format!("{}: not a directory to serve", dir.display()).into());
            }
            println!("serving {} at http://{}:{port}/", dir.display(), bind);
            scribblefield::serve::serve(&dir, std::net::SocketAddr::new(bind, port))
                .map_err(|e| format!("serving {} on {bind}:{port}: {e}", dir.display()))?;
            Ok(())
        }
    }
}

/// Refuses to overwrite an input or write an archive without the expected extension by mistake.
fn check_output(out: &std::path::Path) -> CliResult {
    let name = out.file_name().and_then(|n| n.to_str()).unwrap_or("");
    if !name.ends_with(".zip") {
        return Err(format!("{}: output must be a .scene.zip file", out.display()).into());
    }
    if let Some(parent) = out.parent().filter(|p| !p.as_os_str().is_empty())
        && !parent.is_dir()
    {
        return Err(format!("{}: output directory does not exist", parent.display()).into());
    }
    Ok(())
}
