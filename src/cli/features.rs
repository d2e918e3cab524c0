//! `--features` of `pack` and `demo-scene`: bake feature codes into the archive (DESIGN §4).
use std::path::PathBuf;

use clap::{Args, ValueEnum};
use scribblefield::features::{
    BakeOptions, BakeProgress, Baseline, Extractor, FeatureError, NpyLayout, bake, npy_path_of_frame, read_npy_map,
};
use scribblefield::scene::Scene;

use super::{CliResult, progress};

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum FeatureKind {
    /// Colour and gradient statistics at several scales; needs no weights.
    Baseline,
    /// Precomputed per-frame maps from `--features-from DIR` (.npy, any dimension and size).
    Import,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum LayoutArg {
    Hwc,
    Chw,
}

#[derive(Args, Debug)]
pub struct FeatureArgs {
    /// Bake 64-d feature codes into the archive from this extractor (an autoencoder compresses its features).
    #[arg(long, value_enum)]
    features: Option<FeatureKind>,
    /// With `--features import`: the folder of per-frame `.npy` maps (`<frame name>.npy` or `00000.npy`, ...).
    #[arg(long)]
    features_from: Option<PathBuf>,
    /// Axis order of the imported arrays.
    #[arg(long, value_enum, default_value = "hwc")]
    npy_layout: LayoutArg,
    /// Pixels per feature cell of the computed extractors.
    #[arg(long, default_value_t = 8, value_parser = clap::value_parser!(u32).range(1..=64))]
    feature_stride: u32,
    /// Training steps of the autoencoder.
    #[arg(long, default_value_t = 3000, value_parser = clap::value_parser!(u32).range(1..))]
    autoencoder_steps: u32,
}

impl FeatureArgs {
    /// Refuses combinations that cannot mean what the user wants, before any slow work.
    pub fn check(&self) -> CliResult {
        match (self.features, &self.features_from) {
            (Some(FeatureKind::Import), None) => {
                Err("--features import needs --features-from DIR (the folder of .npy maps)".into())
            }
            (Some(FeatureKind::Import), Some(dir)) if !dir.is_dir() => {
                Err(format!("--features-from {}: not a directory", dir.display()).into())
            }
            (k, Some(_)) if k != Some(FeatureKind::Import) => {
                Err("--features-from only goes with --features import".into())
            }
            _ => Ok(()),
        }
    }

    /// Bakes the codes into `scene` when `--features` was given.
    pub fn apply(&self, scene: &mut Scene) -> CliResult {
        let Some(kind) = self.features else { return Ok(()) };
        let mut opts = BakeOptions::default();
        opts.autoencoder.steps = self.autoencoder_steps;
        let started = std::time::Instant::now();
        let bar = progress::bar("features");
        let quiet = bar.is_hidden();
        let on_progress = |p: BakeProgress| match p {
            BakeProgress::Extracting { done, total } => {
                bar.set_length(total as u64);
                bar.set_position(done as u64);
            }
            BakeProgress::Fitting { step, steps, loss } => {
                if step == 100 {
                    bar.set_message("autoencoder");
                    bar.set_length(steps as u64);
                }
                bar.set_position(step as u64);
                bar.set_message(format!("loss {loss:.3}"));
                if quiet && step % 500 == 0 {
                    eprintln!("autoencoder step {step}/{steps}: loss {loss:.4}");
                }
            }
            BakeProgress::Encoding => bar.set_message("encoding"),
        };
        let frames = scene.frames.len();
        let baked = match kind {
            FeatureKind::Baseline => {
                let ex = Baseline::with_stride(self.feature_stride);
                bake(
                    frames,
                    |i| extract_frame(&ex, scene, i),
                    &ex.describe(),
                    &opts,
                    on_progress,
                )?
            }
            FeatureKind::Import => {
                let dir = self
                    .features_from
                    .as_ref()
                    .ok_or("--features import needs --features-from DIR")?;
                let layout = match self.npy_layout {
                    LayoutArg::Hwc => NpyLayout::Hwc,
                    LayoutArg::Chw => NpyLayout::Chw,
                };
                let load = |i: usize| {
                    let source = scene.frames[i].source.as_deref();
                    read_npy_map(&npy_path_of_frame(dir, i, source)?, layout)
                };
                bake(
                    frames,
                    load,
                    &format!("imported from {}", dir.display()),
                    &opts,
                    on_progress,
                )?
            }
        };
        bar.finish_and_clear();
        println!(
            "features: {} -> {} dims on a {} x {} grid in {:.1} s; autoencoder reconstruction MSE {:.3} (mean predictor: {:.3}), code sparsity {:.2}",
            baked.input_dim,
            baked.codes.dim,
            baked.codes.width,
            baked.codes.height,
            started.elapsed().as_secs_f64(),
            baked.fit.reconstruction_mse,
            baked.fit.baseline_mse,
            baked.fit.code_sparsity
        );
        scene.features = Some(baked.codes);
        Ok(())
    }
}

fn extract_frame(
    ex: &dyn Extractor,
    scene: &Scene,
    i: usize,
) -> Result<scribblefield::features::FeatureMap, FeatureError> {
    ex.extract(&scene.frames[i].rgb).map_err(|e| match e {
        FeatureError::Frame { problem, .. } => FeatureError::Frame { frame: i, problem },
        e => e,
    })
}
