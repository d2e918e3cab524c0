//! `--features` of `pack` and `demo-scene`: bake feature codes into the archive (docs/features.md).
use std::path::PathBuf;

use clap::{Args, ValueEnum};
use scribblefield::features::dino::{DinoExtractor, DinoModel, DinoOutput};
use scribblefield::features::{
    BakeOptions, BakeProgress, Baked, Baseline, EfficientNetConfig, EfficientNetExtractor, Extractor, FeatureError,
    NpyLayout, Upscaled, bake, efficientnet, npy_path_of_frame, read_npy_map, upscale_factor,
};
use scribblefield::scene::Scene;

use super::{CliResult, progress};

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum FeatureKind {
    /// Colour and gradient statistics at several scales; needs no weights.
    Baseline,
    /// ImageNet EfficientNet-Lite0 group outputs (weights: `--weights`, $SCRIBBLEFIELD_EFFICIENTNET or ../shared/models).
    EfficientnetLite0,
    /// DINO ViT-S/8 last-block keys at stride 8, from the official checkpoint you supply (.pth or
    /// safetensors: `--weights`, $SCRIBBLEFIELD_DINO); never run on real weights here, see docs/features.md.
    DinoVits8,
    /// DINOv2 ViT-S/14 last-block keys at stride 14, from the official checkpoint you supply (.pth or
    /// safetensors: `--weights`, $SCRIBBLEFIELD_DINOV2); never run on real weights here, see docs/features.md.
    Dinov2Vits14,
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
    /// Weights of the network: EfficientNet-Lite0 (safetensors) or DINO / DINOv2 (the official .pth or
    /// safetensors); see docs/features.md for where to get them.
    #[arg(long)]
    weights: Option<PathBuf>,
    /// EfficientNet-Lite0 groups (0-6, strides 2,4,8,16,16,32,32) whose outputs make the features.
    #[arg(long, value_delimiter = ',', default_value = "1,2,3")]
    groups: Vec<usize>,
    /// Frames whose shorter side is below this are upscaled by a whole factor before a network
    /// sees them (ImageNet networks expect objects of a certain size); the grid still follows
    /// `--feature-stride` in the frame's own pixels.
    #[arg(long, default_value_t = 224)]
    network_min_side: u32,
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
            (Some(FeatureKind::EfficientnetLite0), _) => {
                efficientnet::resolve_weights(self.weights.as_deref())?;
                Ok(())
            }
            (Some(kind @ (FeatureKind::DinoVits8 | FeatureKind::Dinov2Vits14)), _) => {
                dino_model(kind).resolve_weights(self.weights.as_deref())?;
                Ok(())
            }
            (k, Some(_)) if k != Some(FeatureKind::Import) => {
                Err("--features-from only goes with --features import".into())
            }
            _ => Ok(()),
        }
    }

    /// These arguments with `kind` where `--features` was not given.
    pub fn or(mut self, kind: FeatureKind) -> FeatureArgs {
        self.features.get_or_insert(kind);
        self
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
                bake_frames(scene, &Baseline::with_stride(self.feature_stride), &opts, on_progress)?
            }
            FeatureKind::EfficientnetLite0 => {
                let path = efficientnet::resolve_weights(self.weights.as_deref())?;
                let k = upscale_factor(scene.width, scene.height, self.network_min_side);
                let config = EfficientNetConfig {
                    groups: self.groups.clone(),
                    stride: self.feature_stride * k,
                    normalize: true,
                };
                let ex = Upscaled {
                    inner: EfficientNetExtractor::load(&path, config)?,
                    factor: k,
                };
                bake_frames(scene, &ex, &opts, on_progress)?
            }
            FeatureKind::DinoVits8 | FeatureKind::Dinov2Vits14 => {
                let model = dino_model(kind);
                let path = model.resolve_weights(self.weights.as_deref())?;
                let k = upscale_factor(scene.width, scene.height, self.network_min_side);
                let ex = Upscaled {
                    inner: DinoExtractor {
                        vit: model.load(&path)?,
                        output: DinoOutput::Keys,
                    },
                    factor: k,
                };
                bake_frames(scene, &ex, &opts, on_progress)?
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
                    // The folder's name only: the archive is shared, the packer's paths are not.
                    &format!(
                        "imported from {}",
                        scribblefield::scene::private_paths::folder_name(dir)
                    ),
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

/// The backbone behind a DINO `--features` choice.
fn dino_model(kind: FeatureKind) -> DinoModel {
    match kind {
        FeatureKind::Dinov2Vits14 => DinoModel::Dinov2Vits14,
        _ => DinoModel::DinoVits8,
    }
}

/// Bakes the codes `ex` extracts from every frame of `scene`.
fn bake_frames(
    scene: &Scene,
    ex: &dyn Extractor,
    opts: &BakeOptions,
    progress: impl FnMut(BakeProgress),
) -> Result<Baked, FeatureError> {
    bake(
        scene.frames.len(),
        |i| ex.extract(&scene.frames[i].rgb).map_err(|e| e.at_frame(i)),
        &ex.describe(),
        opts,
        progress,
    )
}
