//! The DINO extractors: DINO ViT-S/8 (Caron et al. 2021) and DINOv2 ViT-S/14 (Oquab et al. 2023)
//! on the CPU, dense features at the patch stride from the last block. Both are the one
//! [`DinoVit`] of `vit.rs`; this module knows which checkpoint is which: where its weights are,
//! and the shapes that make a file that model.
//!
//! **Neither has been run on the real weights** (none are available here). Both match the
//! official PyTorch code on random weights of the real shapes (`dino_vectors.rs`), which shows the
//! same computation, not feature quality. See `docs/features.md`.
use std::ffi::OsString;
use std::path::{Path, PathBuf};

use image::RgbImage;

use super::checkpoint::Checkpoint;
pub use super::vit::{DinoOutput, DinoVit, input_from_rgb};
use super::{Extractor, FeatureError, FeatureMap};

/// ViT-S: heads, width, MLP width.
pub const VITS_HEADS: usize = 6;
pub const VITS_DIM: usize = 384;
pub const VITS_MLP: usize = 1536;

/// The pretrained backbones this crate can load.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DinoModel {
    /// DINO ViT-S/8 (`dino_deitsmall8_pretrain.pth`): patch 8, 12 blocks, no LayerScale.
    DinoVits8,
    /// DINOv2 ViT-S/14 without registers (`dinov2_vits14_pretrain.pth`): patch 14, LayerScale,
    /// depth from the file (12 in the checkpoint).
    Dinov2Vits14,
}

impl DinoModel {
    /// The short name used in provenance and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            DinoModel::DinoVits8 => "dino-vits8",
            DinoModel::Dinov2Vits14 => "dinov2-vits14",
        }
    }

    fn title(self) -> &'static str {
        match self {
            DinoModel::DinoVits8 => "DINO ViT-S/8",
            DinoModel::Dinov2Vits14 => "DINOv2 ViT-S/14",
        }
    }

    /// The environment variable that names the weights file when no flag does.
    pub fn weights_env(self) -> &'static str {
        match self {
            DinoModel::DinoVits8 => "SCRIBBLEFIELD_DINO",
            DinoModel::Dinov2Vits14 => "SCRIBBLEFIELD_DINOV2",
        }
    }

    /// Where the weights are looked for last, relative to the working directory.
    pub fn default_weights(self) -> &'static str {
        match self {
            DinoModel::DinoVits8 => "../shared/models/dino-vits8/dino_deitsmall8_pretrain.pth",
            DinoModel::Dinov2Vits14 => "../shared/models/dinov2-vits14/dinov2_vits14_pretrain.pth",
        }
    }

    /// The official checkpoint's address.
    pub fn checkpoint_url(self) -> &'static str {
        match self {
            DinoModel::DinoVits8 => {
                "https://dl.fbaipublicfiles.com/dino/dino_deitsmall8_pretrain/dino_deitsmall8_pretrain.pth"
            }
            DinoModel::Dinov2Vits14 => "https://dl.fbaipublicfiles.com/dinov2/dinov2_vits14/dinov2_vits14_pretrain.pth",
        }
    }

    pub fn patch(self) -> usize {
        match self {
            DinoModel::DinoVits8 => 8,
            DinoModel::Dinov2Vits14 => 14,
        }
    }

    /// Where to get the weights, for [`FeatureError::Missing`].
    pub fn weights_hint(self) -> String {
        format!(
            "download the official {} checkpoint {} (the .pth is read directly; safetensors with the \
             same tensor names works too) and name the file with --weights or {}; note that this \
             extractor matches the official code on random weights but has never been run on the real \
             ones (docs/features.md)",
            self.title(),
            self.checkpoint_url(),
            self.weights_env()
        )
    }

    /// The weights file: `flag`, else the environment variable (if set and not empty), else
    /// [`DinoModel::default_weights`]; an error if that file is absent.
    pub fn resolve_weights(self, flag: Option<&Path>) -> Result<PathBuf, FeatureError> {
        self.resolve_weights_from(flag, std::env::var_os(self.weights_env()))
    }

    /// [`DinoModel::resolve_weights`] with the environment variable's value given.
    pub fn resolve_weights_from(self, flag: Option<&Path>, env: Option<OsString>) -> Result<PathBuf, FeatureError> {
        super::weights::resolve_weights_file(
            flag,
            env,
            self.weights_env(),
            self.default_weights(),
            &format!("{} weights", self.title()),
            || self.weights_hint(),
        )
    }

    /// Loads the model from `path` (safetensors or `.pth`), checking that the file is this model.
    pub fn load(self, path: &Path) -> Result<DinoVit, FeatureError> {
        let ck = Checkpoint::open(&self.resolve_weights_from(Some(path), None)?)?;
        self.from_checkpoint(&ck)
    }

    /// The model from an open checkpoint, checking that it is this model.
    pub fn from_checkpoint(self, ck: &Checkpoint) -> Result<DinoVit, FeatureError> {
        let mut vit = DinoVit::from_checkpoint(ck, VITS_HEADS)?;
        let mlp = vit.mlp_width();
        // DINO's ViT-S/8 checkpoint has 12 blocks; DINOv2's depth is taken from the file.
        let depth_ok = self == DinoModel::Dinov2Vits14 || vit.depth() == 12;
        let (want_ls, ls_word) = match self {
            DinoModel::DinoVits8 => (false, "without"),
            DinoModel::Dinov2Vits14 => (true, "with"),
        };
        if (vit.dim, vit.patch, mlp) != (VITS_DIM, self.patch(), VITS_MLP) || !depth_ok || vit.layer_scale != want_ls {
            return Err(FeatureError::invalid(
                ck.file(),
                format!(
                    "not {}: width {}, patch {}, {} blocks, MLP {}, {} LayerScale (expected {VITS_DIM}, {}, {}, \
                     {VITS_MLP}, {ls_word} LayerScale)",
                    self.title(),
                    vit.dim,
                    vit.patch,
                    vit.depth(),
                    mlp,
                    if vit.layer_scale { "with" } else { "without" },
                    self.patch(),
                    if self == DinoModel::DinoVits8 {
                        "12"
                    } else {
                        "any number of"
                    },
                ),
            ));
        }
        vit.name = self.name().to_string();
        Ok(vit)
    }
}

/// Dense DINO features of a frame at stride `patch` (8 or 14): `ceil(H/p) x ceil(W/p)` cells
/// (the frame is padded by repeating its last row and column).
pub struct DinoExtractor {
    pub vit: DinoVit,
    pub output: DinoOutput,
}

impl Extractor for DinoExtractor {
    fn describe(&self) -> String {
        let what = match self.output {
            DinoOutput::Tokens => "tokens",
            DinoOutput::Keys => "keys",
        };
        format!(
            "{} dim {} patch {} {what} stride {}",
            self.vit.name, self.vit.dim, self.vit.patch, self.vit.patch
        )
    }

    /// Errors with frame 0 for frames smaller than a patch (the caller knows the index).
    fn extract(&self, rgb: &RgbImage) -> Result<FeatureMap, FeatureError> {
        let (w, h) = rgb.dimensions();
        if (w.min(h) as usize) < self.vit.patch {
            return Err(FeatureError::Frame {
                frame: 0,
                problem: format!("{w}x{h} pixels, smaller than one {0}x{0} patch", self.vit.patch),
            });
        }
        Ok(self.vit.forward(&input_from_rgb(rgb, self.vit.patch), self.output))
    }
}
